"""Euler angles, rotation matrices, quaternions and exact Euler-rate <-> body-rate conversions."""
import math

import numpy as np
import pytest

from quad_msgs_bridge.frames import (body_rates_from_euler_rates, body_to_world, euler_from_quaternion,
                                     euler_rates_from_body_rates, quaternion_from_euler, rotation_from_euler,
                                     world_to_body, wrap_angle)
from quad_msgs_bridge.state import odometry_from_state, state_from_odometry

RNG = np.random.default_rng(20240611)
# Large attitudes on purpose (the small-angle shortcut would fail them); pitch stays off gimbal lock.
ATTITUDES = [(0.0, 0.0, 0.0), (0.3, -0.2, 1.0), (-2.9, 1.45, -3.1), (3.0, -1.5, 2.5), (1.2, 0.9, -0.4)] + [
    (float(RNG.uniform(-math.pi, math.pi)), float(RNG.uniform(-1.5, 1.5)), float(RNG.uniform(-math.pi, math.pi)))
    for _ in range(20)]


def rx(a):
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def ry(a):
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def rz(a):
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def quaternion_matrix(q):
    """Rotation matrix of a unit quaternion (x, y, z, w), textbook formula."""
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize('euler', ATTITUDES)
def test_rotation_is_zyx_and_its_third_column_is_the_thrust_direction_of_eq1(euler):
    phi, theta, psi = euler
    r = np.array(rotation_from_euler(*euler))
    np.testing.assert_allclose(r, rz(psi) @ ry(theta) @ rx(phi), atol=1e-15)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    # eq. (1): x'' ~ (cos phi cos psi sin theta + sin psi sin phi) U1, y'' ~ (cos phi sin psi sin theta
    # - cos psi sin phi) U1, z'' ~ cos phi cos theta U1
    cf, sf, ct, st, cs, ss = (math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta),
                              math.cos(psi), math.sin(psi))
    np.testing.assert_allclose(r[:, 2], [cf * cs * st + ss * sf, cf * ss * st - cs * sf, cf * ct], atol=1e-15)


@pytest.mark.parametrize('euler', ATTITUDES)
def test_quaternion_round_trip_and_matrix(euler):
    q = quaternion_from_euler(*euler)
    assert math.fsum(c * c for c in q) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(quaternion_matrix(q), np.array(rotation_from_euler(*euler)), atol=1e-15)
    back = euler_from_quaternion(q)
    # |theta| <= 1.5 rad keeps asin well conditioned: recovery to ~1e-14 is expected (near +-pi/2 it is not)
    np.testing.assert_allclose([wrap_angle(a - b) for a, b in zip(back, euler)], 0.0, atol=1e-13)
    # q and -q, and any positive multiple, are the same orientation
    for scaled in ([-c for c in q], [7.5 * c for c in q]):
        np.testing.assert_allclose([wrap_angle(a - b) for a, b in zip(euler_from_quaternion(scaled), back)],
                                   0.0, atol=1e-13)


@pytest.mark.parametrize('q', [(0.0, 0.0, 0.0, 0.0), (math.nan, 0.0, 0.0, 1.0), (math.inf, 0.0, 0.0, 1.0)])
def test_quaternion_without_orientation_is_rejected(q):
    with pytest.raises(ValueError):
        euler_from_quaternion(q)


def independent_body_rates(euler, euler_rates):
    """omega = psi' e_z + theta' Rz(psi) e_y + phi' Rz(psi) Ry(theta) e_x (world), then R^T omega."""
    phi, theta, psi = euler
    dphi, dtheta, dpsi = euler_rates
    omega_world = (dpsi * np.array([0.0, 0.0, 1.0]) + dtheta * rz(psi) @ np.array([0.0, 1.0, 0.0])
                   + dphi * rz(psi) @ ry(theta) @ np.array([1.0, 0.0, 0.0]))
    return (rz(psi) @ ry(theta) @ rx(phi)).T @ omega_world


def rng_for(euler):
    """A generator seeded by the case itself, so each test case draws the same numbers in any selection."""
    return np.random.default_rng(abs(hash(euler)) % 2 ** 32)


@pytest.mark.parametrize('euler', ATTITUDES)
def test_body_rates_are_exact(euler):
    rates = tuple(rng_for(euler).uniform(-3.0, 3.0, 3))
    body = body_rates_from_euler_rates(euler, rates)
    np.testing.assert_allclose(body, independent_body_rates(euler, rates), atol=1e-14)
    # and they are the angular velocity of the rotation matrix: skew(omega_body) = R^T dR/dt
    h = 1e-6
    plus = np.array(rotation_from_euler(*(a + h * r for a, r in zip(euler, rates))))
    minus = np.array(rotation_from_euler(*(a - h * r for a, r in zip(euler, rates))))
    skew = np.array(rotation_from_euler(*euler)).T @ (plus - minus) / (2 * h)
    np.testing.assert_allclose([skew[2, 1], skew[0, 2], skew[1, 0]], body, atol=1e-8)


@pytest.mark.parametrize('euler', ATTITUDES)
def test_euler_rates_round_trip(euler):
    rng = rng_for(euler)
    rates = tuple(rng.uniform(-3.0, 3.0, 3))
    # cos(theta) >= cos(1.5) = 0.07 amplifies round-off by at most ~15
    np.testing.assert_allclose(euler_rates_from_body_rates(euler, body_rates_from_euler_rates(euler, rates)),
                               rates, atol=1e-13)
    body = tuple(rng.uniform(-3.0, 3.0, 3))
    np.testing.assert_allclose(body_rates_from_euler_rates(euler, euler_rates_from_body_rates(euler, body)),
                               body, atol=1e-13)


def test_small_angle_shortcut_is_not_used():
    """At a 1 rad pitch, yaw rate alone shows up as a roll body rate -sin(theta) psi'."""
    p, q, r = body_rates_from_euler_rates((0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    assert p == pytest.approx(-math.sin(1.0), rel=1e-15)
    assert r == pytest.approx(math.cos(1.0), rel=1e-15)


def test_gimbal_lock_raises():
    with pytest.raises(ValueError, match='gimbal lock'):
        euler_rates_from_body_rates((0.2, math.pi / 2, 0.0), (0.1, 0.2, 0.3))


@pytest.mark.parametrize('euler', ATTITUDES[:8])
def test_vector_frame_changes(euler):
    v = tuple(rng_for(euler).normal(size=3))
    r = np.array(rotation_from_euler(*euler))
    np.testing.assert_allclose(body_to_world(euler, v), r @ v, atol=1e-14)
    np.testing.assert_allclose(world_to_body(euler, v), r.T @ v, atol=1e-14)
    np.testing.assert_allclose(body_to_world(euler, world_to_body(euler, v)), v, atol=1e-14)


@pytest.mark.parametrize('euler', ATTITUDES[:10])
def test_odometry_round_trip_of_the_12_states(euler):
    rng = rng_for(euler)
    state = [*rng.normal(size=6), *euler, *rng.uniform(-2, 2, 3)]
    back = state_from_odometry(odometry_from_state(3.25, state))
    np.testing.assert_allclose(back[:6], state[:6], atol=1e-13)
    np.testing.assert_allclose([wrap_angle(a - b) for a, b in zip(back[6:9], state[6:9])], 0.0, atol=1e-13)
    np.testing.assert_allclose(back[9:], state[9:], atol=1e-12)


@pytest.mark.parametrize('angle', [0.0, 1.0, math.pi, -math.pi, 3 * math.pi + 0.2, -7.0, 100.0, 1e-300])
def test_wrap_angle(angle):
    wrapped = wrap_angle(angle)
    assert -math.pi <= wrapped < math.pi
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-13)
    assert math.sin(wrapped) == pytest.approx(math.sin(angle), abs=1e-13)


def test_a_batch_of_odometry_conversions_equals_the_single_vehicle_ones_bit_for_bit():
    """One compiled kernel per conversion serves floats and arrays: vehicle k of a batch gets exactly the
    numbers it gets alone, and a bad vehicle (no orientation, gimbal lock) gets NaN without touching the others."""
    rng = np.random.default_rng(7)
    states = [[*rng.normal(size=6), *attitude, *rng.uniform(-2, 2, 3)] for attitude in ATTITUDES[:6]]
    batch = [np.array(column) for column in zip(*states)]
    odometry = odometry_from_state(1.5, batch)
    back = state_from_odometry(odometry)
    for k, state in enumerate(states):
        single = odometry_from_state(1.5, state)
        assert [float(v[k]) for field in odometry[1:] for v in field] == [v for field in single[1:] for v in field]
        assert [float(v[k]) for v in back] == state_from_odometry(single)
    orientation = [np.array(c) for c in odometry.orientation]
    for c in orientation:
        c[1] = 0.0                                                   # vehicle 1: no orientation
    pitched_up = (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5))           # pitch exactly pi/2
    locked = odometry_from_state(1.5, [*[np.zeros(2)] * 9, *[np.ones(2)] * 3])
    locked = locked._replace(orientation=tuple(np.array([level, up]) for level, up in zip((0.0, 0.0, 0.0, 1.0),
                                                                                            pitched_up)))
    bad = state_from_odometry(odometry._replace(orientation=tuple(orientation)))
    assert all(np.isnan(v[1]) for v in bad[3:]) and all(np.isfinite(v[[0, 2, 3, 4, 5]]).all() for v in bad)
    dphi, dtheta, dpsi = state_from_odometry(locked)[9:]     # vehicle 1 at gimbal lock: no roll and yaw rates
    assert np.isfinite([dphi[0], dtheta[0], dpsi[0], dtheta[1]]).all() and np.isnan([dphi[1], dpsi[1]]).all()


@pytest.mark.parametrize('orientation, message', [((0.0, 0.0, 0.0, 0.0), 'no orientation'),
                                                  ((math.nan, 0.0, 0.0, 1.0), 'no orientation'),
                                                  ((0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)), 'gimbal lock')])
def test_a_single_bad_odometry_is_refused_with_the_reason(orientation, message):
    sample = odometry_from_state(0.0, [0.0] * 12)._replace(orientation=orientation, angular_velocity=(0.1, 0.2, 0.3))
    with pytest.raises(ValueError, match=message):
        state_from_odometry(sample)
