"""Reference trajectories: the paper's helix, hover, steps and waypoints."""
import math

import numpy as np
import pytest

from nnit2fsmc_controller.trajectory import SCENARIOS, Helix, Hover, Steps, Waypoints, make_scenario
from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.validation import ParameterError


def derivative_check(trajectory, t, h=1e-5):
    """Velocity and acceleration of a sample against central differences of position and velocity."""
    before, now, after = (trajectory.sample(t + d) for d in (-h, 0.0, h))
    velocity = [(b - a) / (2 * h) for a, b in zip(before.position, after.position)]
    acceleration = [(b - a) / (2 * h) for a, b in zip(before.velocity, after.velocity)]
    np.testing.assert_allclose(now.velocity, velocity, atol=1e-8)
    np.testing.assert_allclose(now.acceleration, acceleration, atol=1e-6)
    assert now.yaw_rate == pytest.approx(wrap_angle(after.yaw - before.yaw) / (2 * h), abs=1e-8)


@pytest.mark.parametrize('t', [0.0, 0.37, 3.0, 6.2832, 12.5, 31.0, 59.9, 60.0])
def test_helix_values(t):
    helix = Helix()
    sample = helix.sample(t)
    r, w, c = helix.radius, helix.angular_rate, helix.climb_rate
    np.testing.assert_allclose(sample.position, (r * math.cos(w * t), r * math.sin(w * t), c * t), atol=1e-15)
    assert math.hypot(*sample.position[:2]) == pytest.approx(r, abs=1e-15)
    assert -math.pi <= sample.yaw < math.pi
    assert wrap_angle(sample.yaw - w * t) == pytest.approx(0.0, abs=1e-12)   # nose turns with the circle
    assert sample.yaw_rate == w


@pytest.mark.parametrize('t', [0.5, 7.0, 13.0, 40.0, 59.0])
def test_helix_derivatives(t):
    derivative_check(Helix(), t)


def test_helix_yaw_is_continuous_across_the_wrap():
    helix = Helix()
    times = np.arange(0.0, helix.duration, 0.01)
    yaws = np.array([helix.sample(float(t)).yaw for t in times])
    assert yaws.max() - yaws.min() > 6.0                       # it does wrap (60 s at 0.5 rad/s)
    np.testing.assert_allclose(np.unwrap(yaws), helix.angular_rate * times, atol=1e-9)


def test_helix_holds_after_its_duration_and_starts_on_the_ground():
    helix = Helix(duration=10.0)
    end, later = helix.sample(10.0), helix.sample(15.0)
    assert later.position == end.position
    assert later.velocity == (0.0, 0.0, 0.0) and later.acceleration == (0.0, 0.0, 0.0)
    assert later.yaw_rate == 0.0
    start = helix.sample(0.0)
    assert helix.initial_state == [start.position[0], start.position[1], 0.0, 0.0, 0.0, 0.0,
                                   0.0, 0.0, start.yaw, 0.0, 0.0, 0.0]


def test_hover_is_constant():
    hover = Hover(position=(1.0, -2.0, 3.0), yaw=0.5)
    for t in (0.0, 7.0, 100.0):
        assert hover.sample(t) == ReferenceSample((1.0, -2.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5)
    assert hover.initial_state[:3] == [1.0, -2.0, 0.0]


def test_steps_hold_each_setpoint_and_move_smoothly_between_them():
    steps = Steps()
    previous = steps.steps[0]
    for start, position, yaw in steps.steps:
        reached = start + steps.rise_time if start > 0.0 else start
        for t in (reached, reached + 2.0):     # held from rise_time after the step time on
            sample = steps.sample(t)
            assert sample.position == pytest.approx(position, abs=1e-12) and sample.yaw == pytest.approx(yaw)
            assert sample.velocity == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
        if start > 0.0:
            assert steps.sample(start - 1e-6).position == pytest.approx(previous[1], abs=1e-9)
            middle = steps.sample(start + steps.rise_time / 2)
            halfway = [(a + b) / 2 for a, b in zip(previous[1], position)]
            assert middle.position == pytest.approx(halfway, abs=1e-12)   # the blend is symmetric
            # minimum-jerk peak speed: 15/8 of the mean speed, finite
            distance = math.dist(previous[1], position)
            assert math.hypot(*middle.velocity) == pytest.approx(1.875 * distance / steps.rise_time)
        previous = (start, position, yaw)


@pytest.mark.parametrize('steps', [(), ((1.0, (0, 0, 1), 0.0),), ((0.0, (0, 0, 1), 0.0), (-1.0, (0, 0, 2), 0.0))])
def test_invalid_steps_are_refused(steps):
    with pytest.raises(ParameterError, match='steps'):
        Steps(steps=steps)


def test_waypoints_are_reached_at_rest():
    waypoints = Waypoints()
    for t, position, yaw in waypoints.points:
        sample = waypoints.sample(t)
        np.testing.assert_allclose(sample.position, position, atol=1e-12)
        assert sample.yaw == pytest.approx(yaw, abs=1e-12)
        np.testing.assert_allclose(sample.velocity, 0.0, atol=1e-12)
        np.testing.assert_allclose(sample.acceleration, 0.0, atol=1e-12)
    assert waypoints.duration == waypoints.points[-1][0] + 4.0


@pytest.mark.parametrize('t', [0.5, 2.0, 3.999, 4.001, 6.3, 9.9, 13.1, 15.5])
def test_waypoints_derivatives(t):
    derivative_check(Waypoints(), t)


def test_waypoints_are_continuous():
    waypoints = Waypoints()
    samples = [waypoints.sample(float(t)) for t in np.arange(0.0, waypoints.duration, 0.001)]
    positions = np.array([s.position for s in samples])
    velocities = np.array([s.velocity for s in samples])
    # max speed of a 2 m minimum-jerk move in 4 s is 1.875 * 2 / 4 = 0.94 m/s: at most ~1 mm per ms
    assert np.abs(np.diff(positions, axis=0)).max() < 1.0e-3
    assert np.abs(np.diff(velocities, axis=0)).max() < 1.0e-3


@pytest.mark.parametrize('points', [((0.0, (0, 0, 1), 0.0),), ((1.0, (0, 0, 1), 0.0), (2.0, (0, 0, 2), 0.0)),
                                    ((0.0, (0, 0, 1), 0.0), (0.0, (0, 0, 2), 0.0))])
def test_invalid_waypoints_are_refused(points):
    with pytest.raises(ParameterError, match='waypoints'):
        Waypoints(points=points)


@pytest.mark.parametrize('name', sorted(SCENARIOS))
def test_every_scenario_is_made_by_name_and_starts_at_rest_on_the_ground(name):
    trajectory = make_scenario(name)
    state = trajectory.initial_state
    assert len(state) == 12 and state[2] == 0.0 and state[3:6] == [0.0, 0.0, 0.0] and state[9:] == [0.0] * 3
    assert trajectory.duration > 0.0


def test_scenario_errors_and_duration_override():
    assert make_scenario('paper', 12.0).duration == 12.0
    with pytest.raises(ParameterError, match='scenario'):
        make_scenario('loop')
    with pytest.raises(ParameterError, match='duration'):
        make_scenario('paper', -1.0)
    with pytest.raises(ParameterError, match='fixed duration of 20 s'):
        make_scenario('waypoints', 10.0)
    assert make_scenario('waypoints', 20.0) == Waypoints()    # its own length (last waypoint at 16 s, + 4 s hold)


def test_a_shifted_scenario_moves_positions_and_start_only():
    """Helix at t = pi s (w t = pi/2): (R cos, R sin, c t) = (0, 1, 0.1 pi) m, shifted by (1, 3, 0.5) m."""
    base, shifted = make_scenario('paper'), make_scenario('paper', offset=(1.0, 3.0, 0.5))
    t = math.pi
    sample = shifted.sample(t)
    assert sample.position == pytest.approx((1.0 + 0.0, 3.0 + 1.0, 0.5 + 0.1 * math.pi), abs=1e-12)
    assert sample._replace(position=None) == base.sample(t)._replace(position=None)   # rates and yaw as they were
    assert shifted.initial_state == [2.0, 3.0, 0.5] + base.initial_state[3:]        # helix start (R, 0, 0) + offset
    assert shifted.duration == base.duration


def test_a_zero_offset_is_the_scenario_itself_and_a_bad_offset_is_refused():
    assert make_scenario('hover', offset=(0.0, 0.0, 0.0)) == make_scenario('hover')
    with pytest.raises(ParameterError, match='offset'):
        make_scenario('hover', offset=(0.0, 1.0))
    with pytest.raises(ParameterError, match=r'offset\[1\]'):
        make_scenario('hover', offset=(0.0, math.inf, 0.0))
