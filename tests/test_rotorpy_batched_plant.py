"""RotorPy's BatchedMultirotor (torch) as the plant ``rotorpy-batched``: it steps a batch as RotorPy's Multirotor
(plant ``rotorpy``) steps each vehicle, freezes nothing it should fly, and a campaign flies the same flights on it.

These tests need torch, torchdiffeq and roma (requirements-rotorpy-batched.txt): scripts/test.sh runs them in
.venv-rotorpy-batched."""
from __future__ import annotations

import importlib.util
from dataclasses import replace

import numpy as np
import pytest

from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file

HAS_TORCH = all(importlib.util.find_spec(name) is not None for name in ('torch', 'torchdiffeq', 'roma', 'rotorpy'))
needs_torch = pytest.mark.skipif(not HAS_TORCH, reason='torch, torchdiffeq or roma is not installed (pip install -r '
                                 'requirements-rotorpy-batched.txt; scripts/test.sh runs these in .venv-rotorpy-batched)')
pytestmark = pytest.mark.rotorpy_batched

PARAMS, DISTURBANCES = load_vehicle_file(None)
#: three vehicles: the packaged one, a heavier one, and one whose rotor 2 has lost 20 % of its thrust
BATCH = VehicleParams.stack([PARAMS, replace(PARAMS, m=PARAMS.m * 1.3, Ix=PARAMS.Ix * 1.2),
                             replace(PARAMS, rotor_efficiency_loss=(0.0, 0.2, 0.0, 0.0))])
STATES = np.array([[0.1, 0.2, 1.0, 0.3, -0.2, 0.1, 0.05, -0.03, 0.7, 0.2, -0.1, 0.05],
                   [0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                   [-1.0, 0.5, 0.3, 1.0, 0.0, -0.5, -0.2, 0.1, -1.0, 0.5, 0.3, -0.2]]).T     # (12, 3)
FORCES = np.array([[1.3, 1.1, 1.0, 1.25], [1.6, 1.6, 1.6, 1.6], [1.0, 1.4, 1.2, 0.9]]).T       # (4, 3) [N]
AIR = [np.array([3.0, 0.0, -2.0]), np.array([0.0, 1.0, 0.0]), np.zeros(3)]                      # [m/s, world]


def _plants(**options):
    from quad_sim.rotorpy_batched_plant import BatchedRotorPyPlant
    from quad_sim.rotorpy_plant import RotorPyPlant
    return RotorPyPlant(BATCH, DISTURBANCES, **options), BatchedRotorPyPlant(BATCH, DISTURBANCES, **options)


@needs_torch
@pytest.mark.parametrize('options', [{}, {'aero': False, 'motor_time_constant_s': 0.0}])
def test_a_batch_steps_as_rotorpys_multirotor_steps_each_vehicle(options):
    """100 steps of 1 ms with the aerodynamics, the 5 ms motors, the section IV disturbances and a different air
    velocity per vehicle (and with all of them off). The two integrate the same equations with two integrators
    (solve_ivp's RK45 with its tolerances, torchdiffeq's RK4 at the step) and RotorPy's batched derivative is
    float32 (relative 6e-8): measured after 0.1 s, with the effects on (off), 7e-8 (6e-9) m, 7e-7 (3e-8) m/s,
    1.3e-7 (2e-8) rad and 1.1e-6 (3.5e-7) rad/s apart; the bounds are about 10 times the larger."""
    single, batched = _plants(**options)
    ours, theirs = list(STATES), list(STATES)
    for k in range(100):
        ours = single.step(0.5 + k * 1e-3, ours, list(FORCES), 1e-3, AIR)
        theirs = batched.step(0.5 + k * 1e-3, theirs, list(FORCES), 1e-3, AIR)
    difference = np.abs(np.array(ours) - np.array(theirs))
    assert difference[:3].max() < 1e-6 and difference[3:6].max() < 1e-5      # [m], [m/s]
    assert difference[6:9].max() < 1e-6 and difference[9:].max() < 1e-5     # [rad], [rad/s]
    np.testing.assert_allclose(np.array(batched.rotor_speeds), np.array(single.rotor_speeds), rtol=1e-6)
    assert np.abs(np.array(theirs) - STATES).max() > 0.05        # they did move


@needs_torch
def test_a_frozen_vehicle_stays_as_it_is_and_one_below_the_ground_lands():
    from quad_sim.rotorpy_batched_plant import BatchedRotorPyPlant
    plant = BatchedRotorPyPlant(BATCH, DISTURBANCES)
    states = STATES.copy()
    states[:, 1] = np.nan                            # frozen by the closed loop after a failure
    states[2, 2], states[5, 2] = 1e-4, -2.0          # falling onto the ground
    after = np.array(plant.step(0.0, list(states), list(FORCES * 0.1), 1e-3))
    assert np.isnan(after[:, 1]).all()
    assert after[2, 2] == 0.0 and after[5, 2] == 0.0 and after[9:, 2].tolist() == [0.0, 0.0, 0.0]
    assert after[2, 0] > 0.9 and np.isfinite(after).all(axis=0)[[0, 2]].all()


@needs_torch
def test_one_vehicle_steps_as_floats_and_a_wrong_batch_is_refused():
    from quad_sim.rotorpy_batched_plant import BatchedRotorPyPlant
    plant = BatchedRotorPyPlant(PARAMS, DISTURBANCES)
    after = plant.step(0.0, list(STATES[:, 1]), [1.6] * 4, 1e-3)
    assert len(after) == 12 and all(isinstance(v, float) for v in after)
    with pytest.raises(ValueError, match='a batch of 3 states for 1 vehicles'):
        plant.step(0.0, list(STATES), list(FORCES), 1e-3)


@needs_torch
def test_a_campaign_flies_the_same_flights_on_both_rotorpy_plants():
    """Two flights of the example campaign's perturbations (wind, noise, delay, motor lag, mass), 2 s of hover: the
    same outcome on both plants, finished or failed alike (the packaged NNIT2FSMC of issue 37's third round loses the
    second one, 1.5 s in, on this light vehicle), with the same RMSE."""
    from flight_stack.campaign.batch import BatchJob, fly_batch
    from flight_stack.campaign.spec import parse_spec
    raw = {'scenario': 'hover', 'duration': 2.0, 'settle_time': 1.0, 'controllers': ['nnit2fsmc'], 'flights': 2,
           'vehicle': {'mass': 0.3}, 'wind': {'mean_speed_mps': 3.0, 'turbulence': 'moderate'},
           'sensor_noise': {'position_m': 0.01}, 'delay_s': 0.004, 'motor_time_constant_s': 0.03}
    rows = {plant: fly_batch(BatchJob(parse_spec({**raw, 'plant': plant}), 'nnit2fsmc', (0, 1), None, None))
            for plant in ('rotorpy', 'rotorpy-batched')}
    for single, batched in zip(rows['rotorpy'], rows['rotorpy-batched']):
        assert (batched['finished'], batched['failure']) == (single['finished'], single['failure'])
        assert batched['rmse_position_m'] == pytest.approx(single['rmse_position_m'], rel=1e-4)
    assert any(row['finished'] for row in rows['rotorpy'])
    assert rows['rotorpy'][0]['rmse_position_m'] != rows['rotorpy'][1]['rmse_position_m']


@pytest.mark.skipif(HAS_TORCH, reason='torch is installed here: the error without it cannot be seen')
def test_without_torch_the_plant_says_what_to_install():
    from quad_sim.plants import make_plant
    with pytest.raises(ParameterError, match='requirements-rotorpy-batched.txt'):
        make_plant('rotorpy-batched', PARAMS, DISTURBANCES)
