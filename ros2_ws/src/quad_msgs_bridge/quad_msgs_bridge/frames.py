"""Rotations between the paper's Euler angles, quaternions and body-frame vectors.

Convention (REP 103): world frame ``odom`` is ENU, body frame ``base_link`` is FLU. The attitude
is the Z-Y-X Euler sequence of the paper's eq. (1): body-to-world R = Rz(psi) Ry(theta) Rx(phi),
whose third column is the thrust direction used in eq. (1). Quaternions are (x, y, z, w), the
order of ``geometry_msgs/Quaternion``. All functions take and return plain floats; the two rate
conversions also take numpy arrays (one element per vehicle) through :mod:`quad_msgs_bridge.numeric`.
"""
from __future__ import annotations

import math

from quad_msgs_bridge.numeric import SCALAR, namespace_for

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quaternion_from_euler(phi: float, theta: float, psi: float) -> Quat:
    """Unit quaternion (x, y, z, w) of R = Rz(psi) Ry(theta) Rx(phi); angles [rad]."""
    xp = namespace_for(phi, theta, psi)
    cr, sr = xp.cos(phi / 2.0), xp.sin(phi / 2.0)
    cp, sp = xp.cos(theta / 2.0), xp.sin(theta / 2.0)
    cy, sy = xp.cos(psi / 2.0), xp.sin(psi / 2.0)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def euler_from_quaternion(q: Quat) -> Vec3:
    """(phi, theta, psi) [rad] of a quaternion (x, y, z, w); normalised first, theta in [-pi/2, pi/2]."""
    x, y, z, w = q
    xp = namespace_for(x, y, z, w)
    norm = xp.sqrt(x * x + y * y + z * z + w * w)
    if xp is SCALAR and (not norm > 0.0 or not math.isfinite(norm)):
        raise ValueError(f'quaternion {q} has no orientation (norm {norm})')   # a batch gets NaN there
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    phi = xp.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    theta = xp.asin(xp.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    psi = xp.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return phi, theta, psi


def rotation_from_euler(phi: float, theta: float, psi: float) -> tuple[Vec3, Vec3, Vec3]:
    """Rows of the body-to-world rotation matrix R = Rz(psi) Ry(theta) Rx(phi)."""
    xp = namespace_for(phi, theta, psi)
    cf, sf = xp.cos(phi), xp.sin(phi)
    ct, st = xp.cos(theta), xp.sin(theta)
    cs, ss = xp.cos(psi), xp.sin(psi)
    return ((ct * cs, sf * st * cs - cf * ss, cf * st * cs + sf * ss),
            (ct * ss, sf * st * ss + cf * cs, cf * st * ss - sf * cs),
            (-st, sf * ct, cf * ct))


def world_to_body(euler: Vec3, v_world: Vec3) -> Vec3:
    """Express a world-frame vector [.., world ENU] in the body frame [.., body FLU]: R^T v."""
    r = rotation_from_euler(*euler)
    return (r[0][0] * v_world[0] + r[1][0] * v_world[1] + r[2][0] * v_world[2],
            r[0][1] * v_world[0] + r[1][1] * v_world[1] + r[2][1] * v_world[2],
            r[0][2] * v_world[0] + r[1][2] * v_world[1] + r[2][2] * v_world[2])


def body_to_world(euler: Vec3, v_body: Vec3) -> Vec3:
    """Express a body-frame vector [.., body FLU] in the world frame [.., world ENU]: R v."""
    r = rotation_from_euler(*euler)
    return tuple(row[0] * v_body[0] + row[1] * v_body[1] + row[2] * v_body[2] for row in r)


def body_rates_from_euler_rates(euler: Vec3, euler_rates: Vec3) -> Vec3:
    """Exact body rates (p, q, r) [rad/s, body FLU] from Z-Y-X Euler rates [rad/s]."""
    phi, theta, _ = euler
    dphi, dtheta, dpsi = euler_rates
    xp = namespace_for(theta)
    cf, sf = xp.cos(phi), xp.sin(phi)
    ct, st = xp.cos(theta), xp.sin(theta)
    return (dphi - st * dpsi,
            cf * dtheta + sf * ct * dpsi,
            -sf * dtheta + cf * ct * dpsi)


def euler_rates_from_body_rates(euler: Vec3, body_rates: Vec3) -> Vec3:
    """Exact Z-Y-X Euler rates [rad/s] from body rates (p, q, r) [rad/s, body FLU].

    Singular at theta = +-pi/2 (gimbal lock), where it raises ValueError for a single vehicle; in a
    batch the rates of such a vehicle become NaN (the others are unaffected).
    """
    phi, theta, _ = euler
    p, q, r = body_rates
    xp = namespace_for(theta)
    ct = xp.cos(theta)
    locked = xp.abs(ct) < 1e-9
    if xp is SCALAR and locked:
        raise ValueError(f'Euler rates are undefined at pitch {theta} rad (gimbal lock)')
    ct = xp.where(locked, math.nan, ct)
    cf, sf = xp.cos(phi), xp.sin(phi)
    yaw_part = (q * sf + r * cf) / ct
    return (p + yaw_part * xp.sin(theta), q * cf - r * sf, yaw_part)


def wrap_angle(angle: float) -> float:
    """Angle [rad] wrapped into [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
