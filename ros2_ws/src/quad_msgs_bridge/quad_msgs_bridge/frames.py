"""Rotations between the paper's Euler angles, quaternions and body-frame vectors.

Convention (REP 103): world frame ``odom`` is ENU, body frame ``base_link`` is FLU. The attitude
is the Z-Y-X Euler sequence of the paper's eq. (1): body-to-world R = Rz(psi) Ry(theta) Rx(phi),
whose third column is the thrust direction used in eq. (1). Quaternions are (x, y, z, w), the
order of ``geometry_msgs/Quaternion``.

Each conversion is written once, as a compiled kernel (numba; the ``_``-prefixed functions) that
takes floats (one vehicle) or numpy arrays (one element per vehicle) alike, so that the odometry
conversions of :mod:`quad_msgs_bridge.state` run as one compiled call per message. The public
functions take any sequences and add the single-vehicle checks: a quaternion without orientation
and gimbal lock raise ValueError for one vehicle; in a batch such a vehicle's values become NaN
(the others are unaffected).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from quad_msgs_bridge.numeric import is_batch, select

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

#: |cos(theta)| below which the Euler rates are undefined (gimbal lock)
GIMBAL_LOCK_COSINE = 1e-9


@njit(cache=True, inline='always', error_model='numpy')
def _quaternion(phi, theta, psi):
    cr, sr = np.cos(phi / 2.0), np.sin(phi / 2.0)
    cp, sp = np.cos(theta / 2.0), np.sin(theta / 2.0)
    cy, sy = np.cos(psi / 2.0), np.sin(psi / 2.0)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


@njit(cache=True, inline='always', error_model='numpy')
def _euler(x, y, z, w):
    """(phi, theta, psi, norm of the quaternion): the angles NaN where the norm is 0 or not finite."""
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    phi = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    theta = np.arcsin(np.minimum(np.maximum(2.0 * (w * y - z * x), -1.0), 1.0))
    psi = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return phi, theta, psi, norm


@njit(cache=True, inline='always', error_model='numpy')
def _rotation(phi, theta, psi):
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    cs, ss = np.cos(psi), np.sin(psi)
    return ((ct * cs, sf * st * cs - cf * ss, cf * st * cs + sf * ss),
            (ct * ss, sf * st * ss + cf * cs, cf * st * ss - sf * cs),
            (-st, sf * ct, cf * ct))


@njit(cache=True, inline='always')
def _transposed(r):
    return (r[0][0], r[1][0], r[2][0]), (r[0][1], r[1][1], r[2][1]), (r[0][2], r[1][2], r[2][2])


@njit(cache=True, inline='always')
def _times(r, vx, vy, vz):
    """The matrix of rows ``r`` times the vector (vx, vy, vz)."""
    return (r[0][0] * vx + r[0][1] * vy + r[0][2] * vz,
            r[1][0] * vx + r[1][1] * vy + r[1][2] * vz,
            r[2][0] * vx + r[2][1] * vy + r[2][2] * vz)


@njit(cache=True, inline='always', error_model='numpy')
def _world_to_body(phi, theta, psi, vx, vy, vz):
    return _times(_transposed(_rotation(phi, theta, psi)), vx, vy, vz)


@njit(cache=True, inline='always', error_model='numpy')
def _body_to_world(phi, theta, psi, vx, vy, vz):
    return _times(_rotation(phi, theta, psi), vx, vy, vz)


@njit(cache=True, inline='always', error_model='numpy')
def _body_rates(phi, theta, dphi, dtheta, dpsi):
    cf, sf = np.cos(phi), np.sin(phi)
    ct, st = np.cos(theta), np.sin(theta)
    return (dphi - st * dpsi,
            cf * dtheta + sf * ct * dpsi,
            -sf * dtheta + cf * ct * dpsi)


@njit(cache=True, inline='always', error_model='numpy')
def _euler_rates(phi, theta, p, q, r):
    """(phi', theta', psi', cos theta): the rates NaN where |cos theta| < GIMBAL_LOCK_COSINE."""
    ct = np.cos(theta)
    ct = select(np.abs(ct) < GIMBAL_LOCK_COSINE, np.nan, ct)
    cf, sf = np.cos(phi), np.sin(phi)
    yaw_part = (q * sf + r * cf) / ct
    return p + yaw_part * np.sin(theta), q * cf - r * sf, yaw_part, ct


def kernel_numbers(*values) -> tuple:
    """The values as the kernels take them: plain numbers as they are (numba types a float, a numpy
    scalar or an int itself), arrays as float arrays, with every number a float once any value is an array."""
    for value in values:
        if isinstance(value, np.ndarray):
            return tuple([np.asarray(v, dtype=float) if is_batch(v) else float(v) for v in values])
    return values


def check_orientation(q, norm) -> None:
    """ValueError unless the quaternion ``q`` of one vehicle, of norm ``norm``, is an orientation (a batch:
    no check)."""
    if not is_batch(norm) and (not norm > 0.0 or not math.isfinite(norm)):
        raise ValueError(f'quaternion {tuple(q)} has no orientation (norm {norm})')   # a batch gets NaN there


def check_pitch(theta, cos_theta) -> None:
    """ValueError at gimbal lock of one vehicle: ``cos_theta`` as :func:`_euler_rates` returns it (a batch:
    no check)."""
    if not is_batch(cos_theta) and math.isnan(cos_theta) and math.isfinite(theta):
        raise ValueError(f'Euler rates are undefined at pitch {theta} rad (gimbal lock)')


def quaternion_from_euler(phi: float, theta: float, psi: float) -> Quat:
    """Unit quaternion (x, y, z, w) of R = Rz(psi) Ry(theta) Rx(phi); angles [rad]."""
    return _quaternion(*kernel_numbers(phi, theta, psi))


def euler_from_quaternion(q: Quat) -> Vec3:
    """(phi, theta, psi) [rad] of a quaternion (x, y, z, w); normalised first, theta in [-pi/2, pi/2].

    ValueError for one vehicle when the quaternion has no orientation (norm 0 or not finite)."""
    phi, theta, psi, norm = _euler(*kernel_numbers(*q))
    check_orientation(q, norm)
    return phi, theta, psi


@njit(cache=True, error_model='numpy')
def _yaw_rows(q):
    """psi [rad] and the norm of each row (x, y, z, w) of q (N, 4), by :func:`_euler` row after row."""
    out = np.empty((q.shape[0], 2))
    for i in range(q.shape[0]):
        out[i, 0], out[i, 1] = _euler(q[i, 0], q[i, 1], q[i, 2], q[i, 3])[2:]
    return out


def yaws_from_quaternions(q: np.ndarray) -> np.ndarray:
    """(N,) yaw psi [rad] of quaternions q (N, 4) (x, y, z, w), each equal to euler_from_quaternion's; ValueError
    as it gives for the first one without an orientation."""
    psi, norm = _yaw_rows(np.ascontiguousarray(q)).T
    bad = ~(norm > 0.0) | ~np.isfinite(norm)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        check_orientation(tuple(q[i]), float(norm[i]))
    return psi


def rotation_from_euler(phi: float, theta: float, psi: float) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of the body-to-world rotation matrix R = Rz(psi) Ry(theta) Rx(phi)."""
    return _rotation(*kernel_numbers(phi, theta, psi))


def world_to_body(euler: Vec3, v_world: Vec3) -> Vec3:
    """Express a world-frame vector [.., world ENU] in the body frame [.., body FLU]: R^T v."""
    return _world_to_body(*kernel_numbers(*euler, *v_world))


def body_to_world(euler: Vec3, v_body: Vec3) -> Vec3:
    """Express a body-frame vector [.., body FLU] in the world frame [.., world ENU]: R v."""
    return _body_to_world(*kernel_numbers(*euler, *v_body))


def body_rates_from_euler_rates(euler: Vec3, euler_rates: Vec3) -> Vec3:
    """Exact body rates (p, q, r) [rad/s, body FLU] from Z-Y-X Euler rates [rad/s]."""
    phi, theta, _ = euler
    return _body_rates(*kernel_numbers(phi, theta, *euler_rates))


def euler_rates_from_body_rates(euler: Vec3, body_rates: Vec3) -> Vec3:
    """Exact Z-Y-X Euler rates [rad/s] from body rates (p, q, r) [rad/s, body FLU].

    Singular at theta = +-pi/2 (gimbal lock), where it raises ValueError for a single vehicle; in a
    batch the rates of such a vehicle become NaN (the others are unaffected).
    """
    phi, theta, _ = euler
    dphi, dtheta, dpsi, cos_theta = _euler_rates(*kernel_numbers(phi, theta, *body_rates))
    check_pitch(theta, cos_theta)
    return dphi, dtheta, dpsi


@njit(cache=True, inline='always')
def wrap_angle(angle):
    """Angle [rad] wrapped into [-pi, pi) (a float, or elementwise an array)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
