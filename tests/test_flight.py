"""Closed-loop flights through the embedded backend that fail when tracking degrades.

The simulation is deterministic (seeded network, fixed-step RK4), so each figure below is the
same on every run; the thresholds leave room for round-off differences between platforms and
numpy versions and for harmless retuning, and are tight enough that a real degradation (the
boundary-layer SMC or the PID on the same flight, 2.5 cm and 2.8 cm RMSE, would fail) is caught.
Each flight is flown once per module (module-scoped fixtures), two at a time on two cores.
"""
import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from flight_stack.embedded import fly_embedded
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.review.metrics import SUBSYSTEMS, flight_metrics
from quad_msgs_bridge.vehicle_params import load_vehicle_file

pytestmark = pytest.mark.slow

PARAMS, _ = load_vehicle_file()
PHYSICS_RATE = 1000.0     # [Hz] = the control rate of config/controller.yaml
SETTLE = 5.0              # [s] take-off and convergence, left out of the tracking figures
PAPER = 60.0              # [s] the paper scenario's length


def fly(case):
    """One flight: (controller, scenario, duration [s], disturbances on?) -> FlightRecord."""
    kind, scenario, duration, disturbed = case
    params, disturbances = load_vehicle_file()
    trajectory = make_scenario(scenario, None if scenario == 'waypoints' else duration)
    return fly_embedded(kind, trajectory, params, disturbances.switched(disturbed), load_gains(),
                        duration, PHYSICS_RATE).record


def fly_all(cases):
    """The flights of ``cases``, in parallel processes when the platform can fork."""
    workers = min(len(cases), os.cpu_count() or 1)
    if workers < 2 or 'fork' not in multiprocessing.get_all_start_methods():
        return [fly(case) for case in cases]
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context('fork')) as pool:
        return list(pool.map(fly, cases))


@pytest.fixture(scope='module')
def paper_flights():
    """The paper scenario (60 s helix) with the section IV disturbances: NNIT2FSMC and sign-SMC."""
    nn, sign = fly_all([('nnit2fsmc', 'paper', PAPER, True), ('smc-sign', 'paper', PAPER, True)])
    return {'nnit2fsmc': (nn, flight_metrics(nn, SETTLE, PARAMS.F_min, PARAMS.F_max)),
            'smc-sign': (sign, flight_metrics(sign, SETTLE, PARAMS.F_min, PARAMS.F_max))}


@pytest.fixture(scope='module')
def scenario_flights():
    cases = [('nnit2fsmc', 'steps', 20.0, True), ('nnit2fsmc', 'hover', 10.0, True),
             ('nnit2fsmc', 'waypoints', 20.0, True)]
    return {case[1]: record for case, record in zip(cases, fly_all(cases))}


def assert_physical(record):
    assert np.isfinite(record.forces).all() and np.isfinite(record.position).all()
    assert np.isfinite(record.controls).all()
    assert record.forces.min() >= PARAMS.F_min and record.forces.max() <= PARAMS.F_max


def test_nnit2fsmc_tracks_the_paper_helix_under_disturbances(paper_flights):
    record, metrics = paper_flights['nnit2fsmc']
    assert_physical(record)
    assert metrics['duration_s'] == pytest.approx(PAPER - 1e-3)
    # 4.1 mm RMSE with the defaults (1.7 mm paper-faithful; 3.9 mm before the wider x, y fuzzy universe of
    # docs/ADAPTIVE.md item 6). The issue asks for 5 cm / 15 cm; we hold the controller to what it does,
    # with room: 5 mm RMSE and 1 cm maximum after settling.
    assert metrics['rmse_position_m'] < 0.005
    assert metrics['max_position_error_m'] < 0.010
    assert metrics['rmse_yaw_rad'] < 0.003          # 0.9 mrad today
    # settled flight stays off the rotor limits (saturation only during the take-off)
    assert metrics['saturation_fraction'] == 0.0


#: Chattering (total variation per second of settled flight) on the paper flight, measured
#: (2026-12-02): NNIT2FSMC U1..U4 1.5e-3, 0.94e-3, 0.93e-3 N/s, 0.47e-3 N m/s; sign-SMC 133, 115,
#: 114 N/s, 11.8 N m/s. Absolute caps, so that a scale error common to both controllers (a ratio
#: cannot see it) fails: NNIT2FSMC below 0.01 (about 7x room), sign-SMC above 40 % of today's.
NN_CHATTERING_CAP = {'U1': 0.01, 'U2': 0.01, 'U3': 0.01, 'U4': 0.005}
SIGN_CHATTERING_FLOOR = {'U1': 50.0, 'U2': 45.0, 'U3': 45.0, 'U4': 4.5}


def test_nnit2fsmc_removes_the_chattering_of_sign_smc(paper_flights):
    """The paper's central claim: same sliding surfaces, >= 10x less total variation of U1..U4,
    at a position RMSE no worse than 1.2x that of the classic sign-SMC (thresholds of the issue);
    and each figure inside its absolute bound (NN_CHATTERING_CAP, SIGN_CHATTERING_FLOOR)."""
    (_, nn), (sign_record, sign) = paper_flights['nnit2fsmc'], paper_flights['smc-sign']
    assert_physical(sign_record)
    for control in ('U1', 'U2', 'U3', 'U4'):
        assert sign['chattering'][control] >= 10.0 * nn['chattering'][control], control
        assert nn['chattering'][control] < NN_CHATTERING_CAP[control], control
        # the sign-SMC really chatters (bang-bang at the control rate), or the comparison would be empty
        assert sign['chattering'][control] > SIGN_CHATTERING_FLOOR[control], control
    assert nn['rmse_position_m'] <= 1.2 * sign['rmse_position_m']


@pytest.mark.parametrize('subsystem', SUBSYSTEMS)
def test_the_network_learns_the_equivalent_control(paper_flights, subsystem):
    """The share of the control carried by the fuzzy term falls between the first and last 5 s windows
    (x 0.36 -> 0.17, z 0.02 -> 0.00, ... today): the network takes over what the fuzzy term had to do."""
    _, metrics = paper_flights['nnit2fsmc']
    shares = metrics['fuzzy_share'][subsystem]
    assert len(shares) == 12
    assert shares[-1] < 0.75 * shares[0]


def test_z_network_learns_the_weight(paper_flights):
    """On the helix (constant climb, no vertical acceleration) the z equivalent control is the weight plus
    the vertical disturbance and drag: U_eq_z ~ (m g - A_z + Kfz c) / (cos phi cos theta)."""
    record, _ = paper_flights['nnit2fsmc']
    late = record.time > PAPER - 5.0
    estimate = record.equivalent[late, SUBSYSTEMS.index('z')].mean()
    expected = PARAMS.m * PARAMS.g - 0.126 + PARAMS.Kfz * 0.1
    # the tilt of the 0.25 m/s^2 centripetal acceleration adds 1/cos(0.025) - 1 = 3e-4 relative
    assert estimate == pytest.approx(expected, rel=0.01)


def test_steps_are_flown_without_touching_the_ground(scenario_flights):
    record = scenario_flights['steps']
    assert_physical(record)
    airborne = record.time >= 3.0
    # lowest setpoint is 1 m: a sag below 0.5 m (or a ground contact) is a failed flight
    assert record.position[airborne, 2].min() > 0.5
    error = np.linalg.norm(record.position - record.reference_position, axis=1)
    for end_of_hold in (4.9, 9.9, 14.9, 19.9):   # each step has settled before the next one
        i = int(np.searchsorted(record.time, end_of_hold))
        assert error[i] < 0.01, f'error {error[i]:.4f} m at t = {record.time[i]:.2f} s'


def test_hover_holds_under_disturbances(scenario_flights):
    record = scenario_flights['hover']
    assert_physical(record)
    metrics = flight_metrics(record, SETTLE, PARAMS.F_min, PARAMS.F_max)
    # 5.2 mm today at 5 s, converging: the x, y networks with the larger output cap and the lower learning rate
    # learn the section IV bias after take-off more slowly (docs/PAPER.md 4.8.8; 1.3 mm before, 0.11 mm before
    # the retune for motor lag) ...
    assert metrics['max_position_error_m'] < 0.006
    # ... and hold it to the same 2 mm as before from 8 s on
    late = record.time >= 8.0
    error = np.linalg.norm(record.position[late] - record.reference_position[late], axis=1)
    assert error.max() < 0.002


def test_waypoints_are_followed(scenario_flights):
    record = scenario_flights['waypoints']
    assert_physical(record)
    metrics = flight_metrics(record, SETTLE, PARAMS.F_min, PARAMS.F_max)
    assert metrics['max_position_error_m'] < 0.05     # 1.4 cm on 2 m legs flown in 4 s with the third round's
    # gains (issue 37; 3.7 cm with the second round's)
    assert metrics['rmse_position_m'] < 0.01          # 6.1 mm (2.3 mm with the second round's gains)
    error = np.linalg.norm(record.position[-1] - record.reference_position[-1])
    assert error < 0.003    # 1.8 mm at 20 s (0.2 mm with the second round's: its x, y, z learning rates were higher)
    assert math.isfinite(metrics['rmse_yaw_rad']) and metrics['rmse_yaw_rad'] < 0.01


def test_pid_baseline_tracks_the_first_seconds_of_the_helix():
    """The PID flies 10 s of the paper helix (metrics after 5 s): 6.9 cm RMSE with the soft gains of
    2026-12-02, 0.67 m without its D term; the 20 cm bound leaves room for any retuning that tracks."""
    record = fly(('pid', 'paper', 10.0, True))
    assert_physical(record)
    metrics = flight_metrics(record, SETTLE, PARAMS.F_min, PARAMS.F_max)
    assert metrics['rmse_position_m'] < 0.2
