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

from quad_msgs_bridge.frames import (Quat, Vec3, body_rates_from_euler_rates, euler_from_quaternion,
                     euler_rates_from_body_rates, quaternion_from_euler, body_to_world,
                     world_to_body)

X, Y, Z, VX, VY, VZ, PHI, THETA, PSI, DPHI, DTHETA, DPSI = range(12)
STATE_SIZE = 12
STATE_NAMES = ('x', 'y', 'z', 'vx', 'vy', 'vz', 'phi', 'theta', 'psi', 'dphi', 'dtheta', 'dpsi')


class OdometrySample(NamedTuple):
    """One odometry reading, the numeric content of ``nav_msgs/Odometry``."""

    stamp: float              #: [s] sim time
    position: Vec3            #: [m, odom ENU]
    orientation: Quat         #: (x, y, z, w), base_link in odom
    linear_velocity: Vec3     #: [m/s, base_link FLU]
    angular_velocity: Vec3    #: [rad/s, base_link FLU]


def odometry_from_state(stamp: float, state: Sequence[float]) -> OdometrySample:
    """Odometry sample of a core state at sim time ``stamp`` [s]."""
    euler = (state[PHI], state[THETA], state[PSI])
    return OdometrySample(
        stamp=stamp,
        position=(state[X], state[Y], state[Z]),
        orientation=quaternion_from_euler(*euler),
        linear_velocity=world_to_body(euler, (state[VX], state[VY], state[VZ])),
        angular_velocity=body_rates_from_euler_rates(euler, (state[DPHI], state[DTHETA], state[DPSI])))


def state_from_odometry(sample: OdometrySample) -> list[float]:
    """Core state (12 paper states) of an odometry sample."""
    euler = euler_from_quaternion(sample.orientation)
    velocity = body_to_world(euler, sample.linear_velocity)
    rates = euler_rates_from_body_rates(euler, sample.angular_velocity)
    return [*sample.position, *velocity, *euler, *rates]
