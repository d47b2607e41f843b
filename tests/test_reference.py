"""Reference samples and the setpoints path (quintic Hermite interpolation between timed points)."""
import math

import numpy as np
import pytest

from nnit2fsmc_controller.trajectory import Helix
from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.reference import ReferenceSample, SetpointPath, hold


def quintic(rng):
    """A random degree-5 polynomial per axis, with its first four derivatives."""
    coefficients = rng.normal(0.0, 1.0, (3, 6))
    polys = [np.polynomial.Polynomial(c) for c in coefficients]
    return [(p, p.deriv(), p.deriv(2), p.deriv(3), p.deriv(4)) for p in polys]


def sample_polys(polys, t):
    return tuple(tuple(float(f(t)) for f in column) for column in zip(*polys))


@pytest.mark.parametrize('seed', range(5))
def test_path_reproduces_a_quintic_exactly(seed):
    rng = np.random.default_rng(seed)
    polys = quintic(rng)
    times = np.sort(rng.uniform(0.0, 2.0, 6))
    points = []
    for t in times:
        position, velocity, acceleration, _, _ = sample_polys(polys, t)
        points.append(ReferenceSample(position, velocity, acceleration, 0.0))
    path = SetpointPath(times, points)
    for t in np.linspace(times[0], times[-1], 97):
        sample = path.sample(float(t))
        expected = sample_polys(polys, t)
        # a quintic Hermite interpolant of a quintic is the quintic itself: round-off only
        np.testing.assert_allclose(sample.position, expected[0], atol=1e-9)
        np.testing.assert_allclose(sample.velocity, expected[1], atol=1e-8)
        np.testing.assert_allclose(sample.acceleration, expected[2], atol=1e-6)
        if t < times[-1]:   # the last point is returned as published: a message carries no jerk or snap
            np.testing.assert_allclose(sample.jerk, expected[3], atol=1e-4)
            np.testing.assert_allclose(sample.snap, expected[4], atol=1e-2)


def test_path_passes_through_its_points():
    rng = np.random.default_rng(9)
    times = [0.5, 0.7, 1.4, 2.0]
    points = [ReferenceSample(tuple(rng.normal(size=3)), tuple(rng.normal(size=3)), tuple(rng.normal(size=3)),
                              float(rng.uniform(-3, 3)), float(rng.normal()), float(rng.normal()))
              for _ in times]
    path = SetpointPath(times, points)
    for t, point in zip(times, points):
        sample = path.sample(t)
        np.testing.assert_allclose(sample.position, point.position, atol=1e-12)
        np.testing.assert_allclose(sample.velocity, point.velocity, atol=1e-12)
        np.testing.assert_allclose(sample.acceleration, point.acceleration, atol=1e-10)
        assert wrap_angle(sample.yaw - point.yaw) == pytest.approx(0.0, abs=1e-12)
        assert sample.yaw_rate == pytest.approx(point.yaw_rate, abs=1e-12)


def test_hold_before_and_after():
    first = ReferenceSample((1.0, 2.0, 3.0), (0.5, 0.0, 0.0), (0.1, 0.0, 0.0), 0.4, 0.2)
    last = ReferenceSample((2.0, 2.0, 3.0), (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), 0.6, 0.2)
    path = SetpointPath([10.0, 12.0], [first, last])
    assert path.start == 10.0 and path.end == 12.0
    assert path.sample(0.0) == hold(first.position, first.yaw)      # at rest before the path starts
    assert path.sample(9.999) == hold(first.position, first.yaw)
    assert path.sample(12.0) == last                                   # the last point itself at its time
    assert path.sample(12.001) == hold(last.position, last.yaw)       # then held at rest
    assert hold(last.position, last.yaw).velocity == (0.0, 0.0, 0.0)


def test_single_point_is_held_from_the_start():
    point = ReferenceSample((1.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), -1.0)
    path = SetpointPath([5.0], [point])
    for t in (0.0, 5.0, 100.0):
        assert path.sample(t) == hold(point.position, point.yaw)


def test_yaw_crosses_pi_the_short_way():
    """Yaw 3.0 -> -3.0 rad is a turn of 0.28 rad through +-pi, not a 6 rad swing back through zero."""
    rate = (2 * math.pi - 6.0) / 1.0
    a = ReferenceSample((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 3.0, rate)
    b = ReferenceSample((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), -3.0, rate)
    path = SetpointPath([0.0, 1.0], [a, b])
    samples = [path.sample(float(t)) for t in np.linspace(0.0, 1.0, 201)]
    yaws = np.array([s.yaw for s in samples])
    assert np.all((yaws >= -math.pi) & (yaws < math.pi))
    unwrapped = np.unwrap(yaws)
    assert np.abs(np.diff(unwrapped)).max() < 0.01                    # continuous once unwrapped
    np.testing.assert_allclose(unwrapped, 3.0 + rate * np.linspace(0.0, 1.0, 201), atol=1e-12)
    assert all(s.yaw_rate == pytest.approx(rate, abs=1e-12) for s in samples)


def test_sampled_helix_matches_the_helix():
    """50 Hz setpoints of the paper's helix: the interpolation error is ~h^6 w^6 R, far below 1e-9 m."""
    helix = Helix()
    path = SetpointPath.sampled(helix, 0.0, helix.duration, 50.0)
    assert path.start == 0.0 and path.end == helix.duration
    assert len(path.times) == int(helix.duration * 50) + 1
    for t in np.random.default_rng(2).uniform(0.0, helix.duration, 300):
        got, expected = path.sample(float(t)), helix.sample(float(t))
        np.testing.assert_allclose(got.position, expected.position, atol=1e-9)
        np.testing.assert_allclose(got.velocity, expected.velocity, atol=1e-8)
        np.testing.assert_allclose(got.acceleration, expected.acceleration, atol=1e-6)
        assert wrap_angle(got.yaw - expected.yaw) == pytest.approx(0.0, abs=1e-9)
        assert got.yaw_rate == pytest.approx(expected.yaw_rate, abs=1e-8)


def test_sampled_path_is_shifted_to_its_start_and_ends_on_the_duration():
    helix = Helix(duration=1.01)
    path = SetpointPath.sampled(helix, 100.0, 1.01, 10.0)
    assert path.times[0] == 100.0 and path.times[-1] == pytest.approx(101.01)
    assert path.times[-2] == pytest.approx(101.0)     # the short last span up to the duration is kept
    np.testing.assert_allclose(path.sample(100.5).position, helix.sample(0.5).position, atol=1e-6)


def test_a_duration_off_by_round_off_ends_the_path_once():
    """700 control steps of 1 ms make 0.7000000000000001 s: the 50 Hz path ends there, without a second
    point 1e-16 s after the sample at 0.7 s (as stamps in nanoseconds they would coincide)."""
    duration = 700 * 0.001
    path = SetpointPath.sampled(Helix(), 2.0, duration, 50.0)
    assert path.end == 2.0 + duration and len(path.times) == 36
    assert min(b - a for a, b in zip(path.times, path.times[1:])) > 0.019


@pytest.mark.parametrize('times, points, fragment', [
    ([0.0, 1.0], [hold((0, 0, 1))], 'as many times as points'),
    ([], [], 'as many times as points'),
    ([1.0, 1.0], [hold((0, 0, 1)), hold((0, 0, 2))], 'increase strictly'),
    ([2.0, 1.0], [hold((0, 0, 1)), hold((0, 0, 2))], 'increase strictly'),
    ([0.0], [ReferenceSample((0, math.nan, 1), (0, 0, 0), (0, 0, 0), 0.0)], 'non-finite'),   # hold() refuses it
    ([0.0], [ReferenceSample((0, 0, 1), (0, 0, 0), (0, 0, 0), math.inf)], 'non-finite'),
])
def test_invalid_paths_are_refused(times, points, fragment):
    with pytest.raises(ValueError, match=fragment):
        SetpointPath(times, points)
