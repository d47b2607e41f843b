"""The paper's 6-DOF quadrotor model, eq. (1) driven through eq. (2), integrated by fixed-step RK4.

State: the 12 paper states in the order of :mod:`quad_msgs_bridge.state` (position [m, world ENU],
velocity [m/s, world], Euler angles [rad], Euler rates [rad/s]). Every function here is written
once and works on a single vehicle (each state component a float: fast plain-Python arithmetic)
and on a batch (each component a numpy array with one element per vehicle; the vehicle
parameters may be floats or such arrays too, see :meth:`VehicleParams.stack`).

The model flies the *true* vehicle of its :class:`VehicleParams`: commanded thrusts are clipped to
the rotor range, then each rotor's thrust and reaction torque follow its own factors and
efficiency loss, and a centre-of-gravity offset turns the total thrust into a moment (see
:class:`VehicleParams`). With an air velocity (a wind model, :mod:`quad_sim.perturbations.wind`)
the vehicle also feels the drag ``wind_drag (w_air - v)`` [N, world ENU]. With the defaults and no
air velocity the arithmetic is exactly that of eq. (1) and (2).
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
        efficiency = [1.0 - loss for loss in params.rotor_efficiency_loss]
        self._thrust_gains = [f * e for f, e in zip(params.rotor_thrust_factors, efficiency)]
        self._torque_gains = [g * e for g, e in zip(params.rotor_drag_factors, efficiency)]
        #: the inertia differences of the gyroscopic torques of eq. (1) [kg m^2]
        self._gyroscopic = (params.Iy - params.Iz, params.Iz - params.Ix, params.Ix - params.Iy)

    def controls(self, forces: Sequence) -> tuple:
        """Virtual controls (U1 [N], U2 [N], U3 [N], U4 [N m]) the true rotors give for commanded thrusts [N].

        Each command is clipped to [F_min, F_max] (what the rotor speed controller can realise),
        then rotor i gives the thrust T_i = f_i (1 - l_i) F_i and the reaction torque
        g_i (1 - l_i) (Kd/Kp) F_i; U1..U3 are eq. (2) of the thrusts, U4 the sum of the torques.
        """
        p = self.params
        commanded = saturate_forces(forces, p.F_min, p.F_max)
        u1, u2, u3, _ = controls_from_forces(*[f * k for f, k in zip(commanded, self._thrust_gains)],
                                             p.yaw_coefficient)
        u4 = controls_from_forces(*[f * k for f, k in zip(commanded, self._torque_gains)], p.yaw_coefficient)[3]
        return u1, u2, u3, u4

    def derivative(self, t: float, s: Sequence, controls: Sequence, air_velocity: Sequence | None = None) -> list:
        """Time derivative of the state under virtual controls U1..U4 (eq. 1).

        The friction torques are written -Kf * rate * |rate|: the paper prints -Kf * rate^2, which
        would accelerate a negative rate; the sign-preserving form is what a friction means.
        The roll and pitch torques are d U2 - c_y U1 and d U3 + c_x U1 (``cog_offset``). With
        ``air_velocity`` (w_x, w_y, w_z) [m/s, world ENU] the force wind_drag (w - v) [N, world] is
        added, evaluated with the velocity of each RK4 stage. On the ground (z <= 0 and pushed
        down) the ground's reaction cancels every acceleration.
        """
        return self._derivative(s, self._drive(controls), self.disturbances.at(t), air_velocity)

    def _drive(self, controls: Sequence) -> tuple:
        """What U1..U4 put into eq. (1), the same at every RK4 stage of a step:
        (U1 [N], d U2 [N m], c_y U1 [N m], d U3 [N m], c_x U1 [N m], U4 [N m])."""
        u1, u2, u3, u4 = controls
        p = self.params
        c_x, c_y, _ = p.cog_offset
        return u1, p.d * u2, c_y * u1, p.d * u3, c_x * u1, u4

    def _derivative(self, s: Sequence, drive: tuple, disturbance: tuple, air_velocity: Sequence | None) -> list:
        """:meth:`derivative` with the controls' terms (:meth:`_drive`) and the section IV
        disturbances at the stage's time given."""
        p = self.params
        xp = namespace_for(s[0])
        u1, roll, roll_offset, pitch, pitch_offset, u4 = drive
        a_x, a_y, a_z, a_phi, a_theta, a_psi = disturbance
        if air_velocity is not None:
            a_x = a_x + p.wind_drag * (air_velocity[0] - s[3])
            a_y = a_y + p.wind_drag * (air_velocity[1] - s[4])
            a_z = a_z + p.wind_drag * (air_velocity[2] - s[5])
        gyro_phi, gyro_theta, gyro_psi = self._gyroscopic
        cf, sf = xp.cos(s[6]), xp.sin(s[6])
        ct, st = xp.cos(s[7]), xp.sin(s[7])
        cs, ss = xp.cos(s[8]), xp.sin(s[8])
        dphi, dtheta, dpsi = s[9], s[10], s[11]
        ax = ((cf * cs * st + ss * sf) * u1 - p.Kfx * s[3] + a_x) / p.m
        ay = ((cf * ss * st - cs * sf) * u1 - p.Kfy * s[4] + a_y) / p.m
        az = ((cf * ct) * u1 - p.Kfz * s[5] + a_z) / p.m - p.g
        ddphi = (dtheta * dpsi * gyro_phi + roll - roll_offset - p.Kfphi * xp.signed_square(dphi) + a_phi) / p.Ix
        ddtheta = (dphi * dpsi * gyro_theta + pitch + pitch_offset - p.Kftheta * xp.signed_square(dtheta)
                   + a_theta) / p.Iy
        ddpsi = (dphi * dtheta * gyro_psi + u4 - p.Kfpsi * xp.signed_square(dpsi) + a_psi) / p.Iz
        grounded = (s[2] <= 0.0) & (az <= 0.0)
        if xp.any(grounded):     # only then: the airborne vehicles keep their accelerations exactly
            free = xp.where(grounded, 0.0, 1.0)
            ax, ay, az, ddphi, ddtheta, ddpsi = (free * ax, free * ay, free * az,
                                                 free * ddphi, free * ddtheta, free * ddpsi)
        return [s[3], s[4], s[5], ax, ay, az, dphi, dtheta, dpsi, ddphi, ddtheta, ddpsi]

    def step(self, t: float, s: Sequence, forces: Sequence, dt: float,
             air_velocity: Sequence | None = None) -> list:
        """State after one RK4 step of dt [s] from time t [s], commanded rotor thrusts [N] held constant.

        The true rotors turn the commands into U1..U4 (:meth:`controls`). ``air_velocity``
        [m/s, world ENU], held over the step, adds the wind drag (None: no air, no such force).
        A vehicle that ends the step below the ground is put on it at rest (an inelastic touchdown).
        The disturbances are evaluated once for each of the three stage times t, t + dt/2, t + dt.
        """
        drive = self._drive(self.controls(forces))
        half = 0.5 * dt
        at = self.disturbances.at
        start, middle, end = at(t), at(t + half), at(t + dt)
        k1 = self._derivative(s, drive, start, air_velocity)
        k2 = self._derivative([a + half * b for a, b in zip(s, k1)], drive, middle, air_velocity)
        k3 = self._derivative([a + half * b for a, b in zip(s, k2)], drive, middle, air_velocity)
        k4 = self._derivative([a + dt * b for a, b in zip(s, k3)], drive, end, air_velocity)
        sixth = dt / 6.0
        new = [a + sixth * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
        xp = namespace_for(new[0])
        below = new[Z] < 0.0
        if xp.any(below):
            flying = xp.where(below, 0.0, 1.0)
            for i in (Z, 3, 4, 5, 9, 10, 11):
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
