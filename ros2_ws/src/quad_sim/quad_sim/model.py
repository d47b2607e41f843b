"""The paper's 6-DOF quadrotor model, eq. (1) driven through eq. (2), integrated by fixed-step RK4.

State: the 12 paper states in the order of :mod:`quad_msgs_bridge.state` (position [m, world ENU],
velocity [m/s, world], Euler angles [rad], Euler rates [rad/s]). Every function here is written
once and works on a single vehicle (each state component a float: fast plain-Python arithmetic)
and on a batch (each component a numpy array with one element per vehicle).
"""
from __future__ import annotations

import math
from typing import Sequence

from quad_msgs_bridge.mixer import controls_from_forces, saturate_forces
from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.state import STATE_SIZE, Z
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams


class QuadrotorModel:
    """Eq. (1) with the section IV disturbances, rotor saturation and a ground plane at z = 0."""

    def __init__(self, params: VehicleParams, disturbances: Disturbances):
        self.params = params
        self.disturbances = disturbances

    def derivative(self, t: float, s: Sequence, controls: Sequence) -> list:
        """Time derivative of the state under virtual controls U1..U4 (eq. 1).

        The friction torques are written -Kf * rate * |rate|: the paper prints -Kf * rate^2, which
        would accelerate a negative rate; the sign-preserving form is what a friction means.
        On the ground (z <= 0 and pushed down) the ground's reaction cancels every acceleration.
        """
        p = self.params
        xp = namespace_for(s[0])
        u1, u2, u3, u4 = controls
        a_x, a_y, a_z, a_phi, a_theta, a_psi = self.disturbances.at(t)
        cf, sf = xp.cos(s[6]), xp.sin(s[6])
        ct, st = xp.cos(s[7]), xp.sin(s[7])
        cs, ss = xp.cos(s[8]), xp.sin(s[8])
        dphi, dtheta, dpsi = s[9], s[10], s[11]
        ax = ((cf * cs * st + ss * sf) * u1 - p.Kfx * s[3] + a_x) / p.m
        ay = ((cf * ss * st - cs * sf) * u1 - p.Kfy * s[4] + a_y) / p.m
        az = ((cf * ct) * u1 - p.Kfz * s[5] + a_z) / p.m - p.g
        ddphi = (dtheta * dpsi * (p.Iy - p.Iz) + p.d * u2 - p.Kfphi * xp.signed_square(dphi) + a_phi) / p.Ix
        ddtheta = (dphi * dpsi * (p.Iz - p.Ix) + p.d * u3 - p.Kftheta * xp.signed_square(dtheta) + a_theta) / p.Iy
        ddpsi = (dphi * dtheta * (p.Ix - p.Iy) + u4 - p.Kfpsi * xp.signed_square(dpsi) + a_psi) / p.Iz
        grounded = (s[2] <= 0.0) & (az <= 0.0)
        free = xp.where(grounded, 0.0, 1.0)
        return [s[3], s[4], s[5], free * ax, free * ay, free * az,
                dphi, dtheta, dpsi, free * ddphi, free * ddtheta, free * ddpsi]

    def step(self, t: float, s: Sequence, forces: Sequence, dt: float) -> list:
        """State after one RK4 step of dt [s] from time t [s], rotor thrusts [N] held constant.

        Thrusts are first clipped to [F_min, F_max]. A vehicle that ends the step below the ground
        is put on it at rest (an inelastic touchdown).
        """
        p = self.params
        controls = controls_from_forces(*saturate_forces(forces, p.F_min, p.F_max), p.yaw_coefficient)
        half = 0.5 * dt
        k1 = self.derivative(t, s, controls)
        k2 = self.derivative(t + half, [a + half * b for a, b in zip(s, k1)], controls)
        k3 = self.derivative(t + half, [a + half * b for a, b in zip(s, k2)], controls)
        k4 = self.derivative(t + dt, [a + dt * b for a, b in zip(s, k3)], controls)
        sixth = dt / 6.0
        new = [a + sixth * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
        xp = namespace_for(new[0])
        flying = xp.where(new[Z] < 0.0, 0.0, 1.0)
        new[Z] = new[Z] * flying
        for i in (3, 4, 5, 9, 10, 11):
            new[i] = new[i] * flying
        return new


def check_state(state: Sequence[float]) -> list[float]:
    """A single-vehicle state as 12 finite floats, or ValueError naming the bad component."""
    if len(state) != STATE_SIZE:
        raise ValueError(f'state has {len(state)} components, expected {STATE_SIZE}')
    values = [float(v) for v in state]
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise ValueError(f'state component {i} is {v}')
    return values
