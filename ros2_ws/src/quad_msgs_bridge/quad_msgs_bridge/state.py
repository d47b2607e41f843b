"""The vehicle state as the cores see it, and as ``nav_msgs/Odometry`` carries it.

Core state: the paper's 12 states of eq. (1), a sequence indexed by the constants below:

==========  ======================================
X, Y, Z     position [m, world ENU]
VX, VY, VZ  velocity [m/s, world ENU]
PHI..PSI    Z-Y-X Euler angles roll, pitch, yaw [rad]
DPHI..DPSI  Euler angle rates [rad/s]
==========  ======================================

Odometry sample: what goes over the wire (REP 105): pose in ``odom``, twist in ``base_link``
(linear velocity and body rates [rad/s, body FLU]). Both backends turn the simulator state into
an odometry sample and the controller turns it back, so the embedded flight performs exactly the
arithmetic the ROS flight performs.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

from numba import njit

from quad_msgs_bridge.frames import (Quat, Vec3, _body_rates, _body_to_world, _euler, _euler_rates, _quaternion,
                                     _world_to_body, check_orientation, check_pitch)

X, Y, Z, VX, VY, VZ, PHI, THETA, PSI, DPHI, DTHETA, DPSI = range(12)
STATE_SIZE = 12
STATE_NAMES = ('x', 'y', 'z', 'vx', 'vy', 'vz', 'phi', 'theta', 'psi', 'dphi', 'dtheta', 'dpsi')
#: the 12 core states in words, as error messages and docs give them (the table above)
STATE_LAYOUT = ('x, y, z [m, world ENU], vx, vy, vz [m/s, world ENU], phi, theta, psi [rad] (Z-Y-X Euler angles), '
                'dphi, dtheta, dpsi [rad/s] (Euler-angle rates, not body rates)')


class OdometrySample(NamedTuple):
    """One odometry reading, the numeric content of ``nav_msgs/Odometry``."""

    stamp: float              #: [s] sim time
    position: Vec3            #: [m, odom ENU]
    orientation: Quat         #: (x, y, z, w), base_link in odom
    linear_velocity: Vec3     #: [m/s, base_link FLU]
    angular_velocity: Vec3    #: [rad/s, base_link FLU]


@njit(cache=True, error_model='numpy')
def _odometry_fields(x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi):
    """(position, orientation, linear velocity [body], body rates) of a core state (numbers, or arrays for a
    batch: numba builds one kernel per combination of argument types)."""
    return ((x, y, z), _quaternion(phi, theta, psi), _world_to_body(phi, theta, psi, vx, vy, vz),
            _body_rates(phi, theta, dphi, dtheta, dpsi))


@njit(cache=True, error_model='numpy')
def _state_fields(position, orientation, linear, angular):
    """The 12 core states of odometry fields (floats or arrays), then the quaternion's norm and cos(pitch)
    (NaN at gimbal lock), from which the caller tells a bad message."""
    phi, theta, psi, norm = _euler(orientation[0], orientation[1], orientation[2], orientation[3])
    vx, vy, vz = _body_to_world(phi, theta, psi, linear[0], linear[1], linear[2])
    dphi, dtheta, dpsi, cos_theta = _euler_rates(phi, theta, angular[0], angular[1], angular[2])
    return (position[0], position[1], position[2], vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi, norm, cos_theta)


def odometry_from_state(stamp: float, state: Sequence[float]) -> OdometrySample:
    """Odometry sample of a core state at sim time ``stamp`` [s] (floats, or arrays for a batch)."""
    if len(state) != STATE_SIZE:
        raise ValueError(f'state has {len(state)} components, expected {STATE_SIZE}')
    return OdometrySample(stamp, *_odometry_fields(*state))


def state_from_odometry(sample: OdometrySample) -> list[float]:
    """Core state (12 paper states) of an odometry sample.

    ValueError for one vehicle whose orientation is no rotation (quaternion norm 0 or not finite) or
    at gimbal lock (:mod:`quad_msgs_bridge.frames`); a batch's such vehicles get NaN instead."""
    *state, norm, cos_theta = _state_fields(tuple(sample.position), tuple(sample.orientation),
                                            tuple(sample.linear_velocity), tuple(sample.angular_velocity))
    check_orientation(sample.orientation, norm)
    check_pitch(state[THETA], cos_theta)
    return state
