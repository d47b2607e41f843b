"""The flight metrics against values worked out by hand on a five-step synthetic record.

Every other test compares the metrics with themselves (live summary against bag review, ROS against
embedded); here each figure is computed on paper first. Both implementations are checked: the whole
record (:func:`flight_metrics`, the review and the single flight) and the step-by-step accumulator
(:class:`StatisticsAccumulator`, the batch and campaign flights).

The record: steps at t = 0, 1, 2, 3, 4 s, settling time 2 s, so steps 2, 3, 4 are settled
(t >= t_0 + 2 s) and the settled span is 2 s. The two take-off steps carry huge errors and control
jumps that must not reach any settled figure.
"""
import math

import numpy as np
import pytest

from quad_msgs_bridge.review.metrics import (FlightRecord, StatisticsAccumulator, flight_metrics, share_extremes,
                                             tracking_metrics)

F_MIN, F_MAX = 0.0, 2.5      # [N]
SETTLE = 2.0                 # [s]
TIME = [0.0, 1.0, 2.0, 3.0, 4.0]
REFERENCE = [(1.0, 2.0, 3.0)] * 5
# position errors [m]: 100 and 50 before settling; then (3, 4, 0), (0, 0, -1), (1, 2, 2): norms 5, 1, 3
ERRORS = [(100.0, 0.0, 0.0), (0.0, 50.0, 0.0), (3.0, 4.0, 0.0), (0.0, 0.0, -1.0), (1.0, 2.0, 2.0)]
# yaw and its reference [rad]: the settled errors wrap to 6.2 - 2 pi, 0.1 and -6 + 2 pi
YAW = [2.0, -2.0, 3.1, 0.1, -3.0]
REFERENCE_YAW = [0.0, 0.0, -3.1, 0.0, 3.0]
# U1 [N], U2 [N], U3 [N], U4 [N m]; the jump from step 1 to step 2 is not between settled steps
CONTROLS = [(0.0, 9.0, -9.0, 1.0), (20.0, -9.0, 9.0, -1.0),
            (5.0, 0.0, 1.0, 0.01), (6.0, 0.5, 1.0, -0.01), (4.0, -0.5, 1.0, 0.01)]
# rotor thrusts [N]: steps 0 (all at F_min), 2 (F4 at F_max) and 4 (F1 at F_min) have a rotor at a limit
FORCES = [(0.0, 0.0, 0.0, 0.0), (1.0, 1.2, 1.3, 1.1), (1.0, 1.1, 1.2, F_MAX),
          (0.5, 1.0, 1.5, 2.0), (F_MIN, 1.0, 1.0, 1.0)]

# the figures, by hand
RMSE = math.sqrt((25.0 + 1.0 + 9.0) / 3.0)                        # 3.416 m (the mean error would be 3)
MAX_ERROR = 5.0                                                   # [m]
YAW_ERRORS = (6.2 - 2.0 * math.pi, 0.1, -6.0 + 2.0 * math.pi)     # -0.083, 0.1, 0.283 rad
RMSE_YAW = math.sqrt(sum(e * e for e in YAW_ERRORS) / 3.0)        # 0.180 rad
# total variation over the settled steps / settled span of 2 s
CHATTERING = {'U1': (1.0 + 2.0) / 2.0, 'U2': (0.5 + 1.0) / 2.0, 'U3': 0.0, 'U4': (0.02 + 0.02) / 2.0}
SATURATION = 2.0 / 3.0                                            # settled steps 2 and 4 of 2, 3, 4
SATURATION_WHOLE = 3.0 / 5.0                                      # steps 0, 2, 4 of five


def positions():
    return [tuple(r + e for r, e in zip(ref, err)) for ref, err in zip(REFERENCE, ERRORS)]


def synthetic_record() -> FlightRecord:
    zeros = np.zeros((5, 6))
    return FlightRecord(time=np.array(TIME), position=np.array(positions()), yaw=np.array(YAW),
                        reference_position=np.array(REFERENCE), reference_yaw=np.array(REFERENCE_YAW),
                        forces=np.array(FORCES), controls=np.array(CONTROLS),
                        surfaces=zeros, equivalent=zeros, corrective=zeros)


def assert_hand_figures(metrics):
    assert metrics['rmse_position_m'] == pytest.approx(RMSE, rel=1e-12)
    assert metrics['max_position_error_m'] == pytest.approx(MAX_ERROR, rel=1e-12)
    assert metrics['rmse_yaw_rad'] == pytest.approx(RMSE_YAW, rel=1e-12)
    assert {k: float(v) for k, v in metrics['chattering'].items()} == pytest.approx(CHATTERING, rel=1e-12, abs=1e-15)
    assert metrics['saturation_fraction'] == pytest.approx(SATURATION, rel=1e-12)
    assert metrics['saturation_fraction_whole_flight'] == pytest.approx(SATURATION_WHOLE, rel=1e-12)


def test_flight_metrics_of_a_record_are_the_figures_computed_by_hand():
    metrics = flight_metrics(synthetic_record(), SETTLE, F_MIN, F_MAX, fuzzy_term=False)
    assert_hand_figures(metrics)
    assert metrics['duration_s'] == 4.0 and metrics['control_steps'] == 5 and metrics['all_finite']


def test_the_step_by_step_accumulator_gives_the_same_hand_figures():
    accumulator = StatisticsAccumulator(SETTLE, F_MIN, F_MAX)
    for row in zip(TIME, positions(), YAW, REFERENCE, REFERENCE_YAW, FORCES, CONTROLS):
        accumulator.add(*row)
    assert_hand_figures(tracking_metrics(accumulator.statistics()))


def test_a_batch_accumulator_gives_each_vehicle_its_own_hand_figures():
    """Two vehicles in one batch: the record above, and the same record with every error halved and
    every control variation doubled (RMSE and max error halve, chattering doubles)."""
    accumulator = StatisticsAccumulator(SETTLE, F_MIN, F_MAX)
    for t, position, yaw, reference, reference_yaw, forces, controls in zip(
            TIME, positions(), YAW, REFERENCE, REFERENCE_YAW, FORCES, CONTROLS):
        half = [r + 0.5 * (p - r) for p, r in zip(position, reference)]
        accumulator.add(t, [np.array([p, h]) for p, h in zip(position, half)], np.array([yaw, yaw]),
                        reference, reference_yaw, [np.array([f, f]) for f in forces],
                        [np.array([u, 2.0 * u]) for u in controls])
    metrics = tracking_metrics(accumulator.statistics())
    np.testing.assert_allclose(metrics['rmse_position_m'], [RMSE, 0.5 * RMSE], rtol=1e-12)
    np.testing.assert_allclose(metrics['max_position_error_m'], [MAX_ERROR, 0.5 * MAX_ERROR], rtol=1e-12)
    for name, value in CHATTERING.items():
        np.testing.assert_allclose(metrics['chattering'][name], [value, 2.0 * value], rtol=1e-12)
    np.testing.assert_allclose(metrics['saturation_fraction'], [SATURATION] * 2, rtol=1e-12)


def test_a_rotor_just_inside_its_limits_is_not_saturated():
    record = synthetic_record()
    record.forces[:] = [F_MIN + 1e-6, 1.0, 1.0, F_MAX - 1e-6]
    metrics = flight_metrics(record, SETTLE, F_MIN, F_MAX, fuzzy_term=False)
    assert metrics['saturation_fraction'] == 0.0 and metrics['saturation_fraction_whole_flight'] == 0.0


def test_chattering_is_split_into_the_force_channel_and_the_moment_channels():
    """Force: TV(U1)/s [N/s]. Moments: TV(d U2)/s + TV(d U3)/s + TV(U4)/s [N m/s] with the arm length d, never
    the N/s of U1 added to the N m/s of U4."""
    arm = 0.25    # [m]
    metrics = flight_metrics(synthetic_record(), SETTLE, F_MIN, F_MAX, fuzzy_term=False, arm_length=arm)
    assert metrics['chattering_force_n_per_s'] == pytest.approx(CHATTERING['U1'], rel=1e-12)
    moment = arm * (CHATTERING['U2'] + CHATTERING['U3']) + CHATTERING['U4']     # 0.25 * 0.75 + 0.02 N m/s
    assert metrics['chattering_moment_nm_per_s'] == pytest.approx(moment, rel=1e-12)
    assert metrics['chattering_moment_nm_per_s'] != pytest.approx(sum(CHATTERING.values()) - CHATTERING['U1'])
    assert flight_metrics(synthetic_record(), SETTLE, F_MIN, F_MAX, fuzzy_term=False)['chattering_moment_nm_per_s'] \
        is None   # without the arm length there is no moment figure, rather than a wrong one


def test_the_fuzzy_share_after_settling_reports_its_rise_back_with_times():
    """A share that falls to 0.05 at 15-20 s and climbs back to 0.67 at 25-30 s is not summarised as 0.9 -> 0.2."""
    shares = [0.9, 0.7, 0.3, 0.05, 0.3, 0.67, 0.2]          # 5 s windows of a 34 s flight
    extremes = share_extremes(shares, 5.0, settle_time=5.0, duration=34.0)
    assert extremes['first'] == 0.9
    assert extremes['min'] == {'value': 0.05, 'from_s': 15.0, 'to_s': 20.0}
    assert extremes['max'] == {'value': 0.7, 'from_s': 5.0, 'to_s': 10.0}
    assert extremes['rise'] == {'from': {'value': 0.05, 'from_s': 15.0, 'to_s': 20.0},
                                'to': {'value': 0.67, 'from_s': 25.0, 'to_s': 30.0}}
    assert extremes['last'] == {'value': 0.2, 'from_s': 30.0, 'to_s': 34.0}
    assert share_extremes([0.9, 0.5, 0.3], 5.0, settle_time=5.0, duration=15.0)['rise'] is None   # only falls
    assert share_extremes([0.9], 5.0, settle_time=5.0, duration=5.0) is None                     # never settled


def test_flight_metrics_give_the_fuzzy_share_after_settling_per_subsystem():
    record = synthetic_record()
    record.equivalent, record.corrective = np.ones((5, 6)), np.zeros((5, 6))
    record.corrective[:, 0] = [3.0, 3.0, 0.0, 1.0, 3.0]
    # x in 1 s windows: 0.75, 0.75, 0 and, the last window holding the steps at 3 s and 4 s, (1 + 3) / (2 + 4)
    metrics = flight_metrics(record, SETTLE, F_MIN, F_MAX, share_window=1.0)
    assert metrics['fuzzy_share']['x'] == pytest.approx([0.75, 0.75, 0.0, 4.0 / 6.0])
    x = metrics['fuzzy_share_settled']['x']
    assert x['min'] == {'value': 0.0, 'from_s': 2.0, 'to_s': 3.0}
    assert x['rise']['to'] == {'value': pytest.approx(4.0 / 6.0), 'from_s': 3.0, 'to_s': 4.0}
    assert x['first'] == 0.75
