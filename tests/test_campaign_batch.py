"""Campaign batches: a batch equals the same flights flown one by one on the embedded path, a flight's
row depends only on its index, and a failing vehicle is frozen without touching the others."""
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from flight_stack.campaign.batch import BIAS_COLUMNS, BatchJob, CampaignSetup, fly_batch
from flight_stack.campaign.sampling import SAMPLED_COLUMNS, build_perturbations, sample_conditions
from flight_stack.campaign.spec import parse_spec
from flight_stack.closed_loop import FAILURES, ClosedLoop, FailureRules
from flight_stack.embedded import fly_embedded
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller
from quad_msgs_bridge.review.metrics import flight_metrics
from quad_msgs_bridge.vehicle_params import VehicleParams
from quad_sim.model import QuadrotorModel
from quad_sim.simulator import Simulator

#: every perturbation on, mild enough that every controller kind finishes; 250 Hz keeps the test short
PERTURBED = {**yaml.safe_load((Path(__file__).resolve().parent.parent / 'campaigns' / 'mild-every-perturbation.yaml')
                              .read_text()), 'controllers': list(CONTROLLERS)}
SPEC = parse_spec(PERTURBED)
COMPARED = ('rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'saturation_fraction')


def single_flight(spec, controller, flight):
    """Flight ``flight`` alone on the embedded path (odometry messages, one vehicle of floats)."""
    setup = CampaignSetup.of(spec)
    conditions = sample_conditions(spec, setup.nominal, flight)
    perturbations = build_perturbations(spec, [conditions], setup.control_dt, setup.physics_dt, batch=False)
    return fly_embedded(controller, setup.trajectory, setup.nominal, setup.disturbances, setup.gains, spec.duration,
                        1.0 / setup.physics_dt, perturbations=perturbations, rules=setup.rules(spec)), setup


@pytest.mark.slow
@pytest.mark.parametrize('controller', CONTROLLERS)
def test_a_batch_equals_the_same_flights_one_by_one(controller):
    rows = fly_batch(BatchJob(SPEC, controller, (0, 1, 2)))
    for row in rows:
        result, setup = single_flight(SPEC, controller, row['flight'])
        assert row['finished'] and result.failure is None, (row['failure'], result.failure)
        metrics = flight_metrics(result.record, SPEC.settle_time, setup.nominal.F_min, setup.nominal.F_max)
        for key in COMPARED:
            assert row[key] == pytest.approx(metrics[key], rel=1e-9, abs=1e-12), key
        for i in range(1, 5):
            assert row[f'chattering_U{i}'] == pytest.approx(metrics['chattering'][f'U{i}'], rel=1e-9, abs=1e-12)
        assert row['control_steps'] == len(result.record.time)


def same(a: dict, b: dict) -> bool:
    """Rows equal value for value (NaN equal to NaN)."""
    return a.keys() == b.keys() and all(
        x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))
        for x, y in zip(a.values(), b.values()))


def test_a_flight_s_row_does_not_depend_on_its_batch():
    alone = fly_batch(BatchJob(SPEC, 'nnit2fsmc', (4,)))[0]
    among = {row['flight']: row for row in fly_batch(BatchJob(SPEC, 'nnit2fsmc', (2, 4, 7, 3)))}
    assert same(among[4], alone)
    assert not same(among[2], alone)


def test_every_controller_flies_the_same_sampled_conditions():
    rows = [fly_batch(BatchJob(dataclasses.replace(SPEC, duration=0.02, settle_time=0.0), kind, (1,)))[0]
            for kind in ('nnit2fsmc', 'pid')]
    sampled = [{k: row[k] for k in (*SAMPLED_COLUMNS, *BIAS_COLUMNS)} for row in rows]
    assert sampled[0] == sampled[1]
    assert sampled[0]['mass_kg'] != sampled[0]['Ix_kgm2'] and sampled[0]['bias_p_radps'] != 0.0


def _loop(vehicle, start, steps, rules):
    setup = CampaignSetup.of(SPEC)
    size = len(start[0])
    controller = build_controller('nnit2fsmc', setup.nominal, setup.gains, batch=size)
    simulator = Simulator(QuadrotorModel(vehicle, setup.disturbances), setup.physics_dt, start)
    hold = setup.trajectory.sample(0.0)._replace(position=(1.0, 0.0, 0.5))
    loop = ClosedLoop(controller, simulator, lambda t: hold, setup.substeps, rules)
    with np.errstate(all='ignore'):
        for _ in range(steps):
            loop.step()
    return loop


def test_a_failing_vehicle_is_frozen_and_never_poisons_the_batch():
    """Vehicle 1 starts upside down, vehicle 2 has an absurd yaw inertia that drives it to overflow;
    the two healthy vehicles fly exactly as they fly without them."""
    setup = CampaignSetup.of(SPEC)
    nominal = setup.nominal
    broken = dataclasses.replace(nominal, Iz=1e-300)
    vehicles = VehicleParams.stack([nominal, nominal, broken, nominal])
    start = [np.array([1.0, 1.0, 1.0, 1.0]) * v for v in setup.trajectory.initial_state]
    start[2] = np.full(4, 0.5)
    start[6] = np.array([0.0, 3.0, 0.0, 0.01])      # vehicle 1 upside down
    start[11] = np.array([0.0, 0.0, 1.0, 0.0])      # vehicle 2 spinning with no inertia
    rules = FailureRules(settle_time=0.0, max_error=5.0)
    loop = _loop(vehicles, start, 60, rules)
    assert list(loop.failure[:2]) == [-1, 1] and loop.failure[2] >= 0 and loop.failure[3] == -1
    assert loop.failure_time[1] == pytest.approx(setup.control_dt)
    assert all(np.isfinite(v).all() for v in loop.simulator.state)      # the frozen states are finite
    assert loop.simulator.state[6][1] == 3.0                            # frozen where it failed
    healthy = _loop(VehicleParams.stack([nominal, nominal]), [v[[0, 3]] for v in start], 60, rules)
    for mixed, alone in zip(loop.simulator.state, healthy.simulator.state):
        np.testing.assert_array_equal(mixed[[0, 3]], alone)


def test_an_unreadable_measurement_or_a_vehicle_leaving_the_arena_fails_only_that_vehicle():
    """A finite true state whose measurement is not finite (a diverging vehicle's odometry overflows)
    fails that vehicle as non-finite before the controller reads it; a vehicle 150 m from its
    reference has left the arena even while settling. The controller never refuses the batch."""
    setup = CampaignSetup.of(SPEC)
    start = [np.array([1.0, 1.0, 1.0]) * v for v in setup.trajectory.initial_state]
    start[2] = np.full(3, 0.5)
    start[0] = np.array([1.0, 1.0, 151.0])          # vehicle 2: far away
    controller = build_controller('nnit2fsmc', setup.nominal, setup.gains, batch=3)
    simulator = Simulator(QuadrotorModel(VehicleParams.stack([setup.nominal] * 3), setup.disturbances),
                          setup.physics_dt, start)
    hold = setup.trajectory.sample(0.0)._replace(position=(1.0, 0.0, 0.5))

    def observe(t, state):       # vehicle 1's sensor overflows
        return [np.where([False, True, False], np.inf, v) for v in state], None
    loop = ClosedLoop(controller, simulator, lambda t: hold, setup.substeps, FailureRules(5.0, 1.0), observe=observe)
    for _ in range(20):
        loop.step()
    assert list(loop.failure) == [-1, 0, 4]
    assert FAILURES[0] == 'non-finite state' and FAILURES[4] == 'left the arena'
    assert loop.failure_time[1] == 0.0 and loop.failure_time[2] == pytest.approx(setup.control_dt)
    assert all(np.isfinite(v).all() for v in loop.simulator.state)


def test_failed_flights_are_reported_with_a_reason_and_nan_metrics():
    spec = dataclasses.replace(SPEC, max_error_m=1e-4)      # a tube nobody can fly in
    row = fly_batch(BatchJob(spec, 'pid', (0,)))[0]
    assert not row['finished'] and row['failure'] == 'position error above max_error'
    assert row['failure_time_s'] == pytest.approx(spec.settle_time, abs=2 * 1 / 250)
    assert math.isnan(row['rmse_position_m'])
