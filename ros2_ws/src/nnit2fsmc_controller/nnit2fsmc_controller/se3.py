"""Geometric tracking control on SE(3) (Lee, Leok, McClamroch, "Geometric tracking control of a
quadrotor UAV on SE(3)", CDC 2010), as a baseline with the interface of the cascaded controller.

Frames: world ENU (e3 up), body FLU; R = Rz(psi) Ry(theta) Rx(phi) body-to-world (the paper's
eq. 1 attitude); Omega = body rates [rad/s, body FLU] from the Euler rates of the state
(:func:`quad_msgs_bridge.frames.body_rates_from_euler_rates`). Lee et al. write z down; with z up
the thrust acts along +R e3 and gravity along -e3, so their signs of g e3 flip. With
e_x = x - x_d, e_v = v - v_d [m, m/s, world], I_x = int(e_x) dt (clamped) and mass-normalised gains:

    F_d   = m (-k_x e_x - k_v e_v - k_i I_x + g e3 + xdd_d)                          [N, world]
    f     = F_d . R e3                                                                 (U1 [N])
    b3_d  = F_d / |F_d|  (horizontal part limited to the tilt limit at the height z, TiltLimit; vertical part >= 0.1 m g)
    R_d   = Rz(psi_d) Ry(theta_d) Rx(phi_d) with R_d e3 = b3_d and the reference heading psi_d
    e_R   = 1/2 vee(R_d^T R - R^T R_d),   e_W = Omega - R^T R_d Omega_d,   I_R = int(e_R) dt (clamped)
    M     = -J (k_R e_R + k_W e_W + k_I I_R) + Omega x J Omega
            - J (hat(Omega) R^T R_d Omega_d - R^T R_d dOmega_d)                        [N m, body]
    U2 = M_x / d,  U3 = M_y / d,  U4 = M_z                                             (eq. 1, 2)

Choices (docs/BASELINES.md):

* Diagonal gains: k_x, k_v, k_i per world axis and k_R, k_W, k_I per body axis, normalised by m and
  by J = diag(Ix, Iy, Iz) (Lee et al. use scalars; a positive diagonal gain keeps the structure and
  lets the roll/pitch and yaw bandwidths differ, as Ix != Iz asks).
* Integral terms on e_x and e_R (the integral extension of Goodarzi, Lee, Lee 2013): the section IV
  forces and moments are constant biases, which the 2010 law leaves as a steady error.
* b1_d: Lee et al. leave the heading direction free (b1_d not parallel to b3_d, projected). Here
  R_d is the Z-Y-X attitude with the reference yaw psi_d and thrust axis b3_d, so that the heading
  is the paper's yaw angle psi, the one the metrics and the other controllers track.
* Omega_d and dOmega_d: from the Euler rates of (phi_d, theta_d, psi_d): psi_d' and psi_d'' are the
  reference's; phi_d', theta_d' and their derivatives come from ``common.attitude_rates``, as in every
  kind (:class:`.controller.CascadedController`): ``filter``, filtered derivatives of phi_d, theta_d (time
  constant ``angle_filter_tau``), as in the cascade's eq. (10); ``flatness``, the rates of the reference's
  flat attitude (phi_r, theta_r from its acceleration, jerk, snap and yaw motion) plus the filtered
  derivative of the feedback's part phi_d - phi_r, and the flat attitude's second derivative. Omega_d is the
  exact body-rate map of those rates and dOmega_d its exact time derivative.
* The nominal model's drag terms (translational 5.6e-4 N s/m, rotational friction) are not fed
  forward: Lee et al. have none, and they are below 1e-3 of the weight on the paper flight.

Take-off (``takeoff_height``, the hold every kind shares, docs/ADAPTIVE_BASELINES.md): below it I_x (x, y)
and I_R hold; F_d is the law's.

The adaptive kinds keep this structure and replace its parts (:mod:`.l1_adaptive`, :mod:`.indi`):
:meth:`SE3Controller.desired_force` (F_d), :meth:`SE3Controller.moment` (M of the desired angular
acceleration), :meth:`SE3Controller.compensated` (an augmentation of U1..U4) and
:meth:`SE3Controller.applied` (what the rotors were commanded, for a predictor).

One controller steps one vehicle (floats) or a batch (numpy arrays, ``batch=B``), through the
namespace of :mod:`quad_msgs_bridge.numeric`.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from quad_msgs_bridge.frames import body_rates_from_euler_rates, rotation_from_euler
from quad_msgs_bridge.mixer import allocate, controls_from_forces
from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams

from .axis_laws import AxisOutput
from .controller import (AXES, ATTITUDE_RATES, ControlOutput, RateFilter, TiltLimit, check_allocation, check_inputs,
                         finite_output, flat_attitude_of)

#: minimum vertical part of the desired force, in units of m g (keeps b3_d pointing up)
MIN_LIFT = 0.1


def _transpose(a):
    return tuple(zip(*a))


def _matmul(a, b):
    """Product of two 3x3 matrices given as rows."""
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)) for i in range(3))


def _matvec(a, v):
    return tuple(a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2] for i in range(3))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _vee_of_antisymmetric_part(a):
    """vee(a - a^T) / 2 for a 3x3 matrix a: the e_R of Lee et al. when a = R_d^T R."""
    return (0.5 * (a[2][1] - a[1][2]), 0.5 * (a[0][2] - a[2][0]), 0.5 * (a[1][0] - a[0][1]))


def euler_rate_derivative_to_body(euler, rates, accelerations):
    """d/dt of the body rates (p, q, r) [rad/s^2] of Z-Y-X Euler angles with the given rates and
    accelerations (the time derivative of :func:`body_rates_from_euler_rates`)."""
    phi, theta, _ = euler
    dphi, dtheta, dpsi = rates
    ddphi, ddtheta, ddpsi = accelerations
    xp = namespace_for(phi, theta)
    cf, sf, ct, st = xp.cos(phi), xp.sin(phi), xp.cos(theta), xp.sin(theta)
    return (ddphi - ct * dtheta * dpsi - st * ddpsi,
            -sf * dphi * dtheta + cf * ddtheta + cf * ct * dphi * dpsi - sf * st * dtheta * dpsi + sf * ct * ddpsi,
            -cf * dphi * dtheta - sf * ddtheta - sf * ct * dphi * dpsi - cf * st * dtheta * dpsi + cf * ct * ddpsi)


class SE3Controller:
    """update(t, state, reference) -> rotor thrusts, by the geometric SE(3) law (module docstring).

    ``gains[axis]`` = (k_error, k_rate, k_integral, integral_limit) for the AXES: x, y, z are
    k_x [1/s^2], k_v [1/s], k_i [1/s^3] (multiplied by m) and the clamp of I_x [m s]; phi, theta,
    psi are k_R [1/s^2], k_W [1/s], k_I [1/s^3] about body x, y, z (multiplied by Ix, Iy, Iz) and
    the clamp of I_R [rad s]. ``lam`` (the common sliding-surface slopes) only sets the surfaces it
    reports, S = de + lambda e, so that its records compare with the other controllers'.
    """

    STATE = ('position_integral', 'attitude_integral')   #: with its rate filters' (nnit2fsmc_controller.tuning)
    GAINS_SECTION = 'se3'   #: the gains file's section of ``gains`` (``se3.axes``)

    def __init__(self, name: str, params: VehicleParams, gains: dict, lam: dict, dt: float,
                 max_tilt: float = 0.6, angle_filter_tau: float = 0.02, allocation: str = 'priority',
                 attitude_rates: str = 'filter', low_altitude_max_tilt: float | None = None,
                 low_altitude_height: float = 0.0, takeoff_height: float = 0.0, batch: int | None = None):
        self.name = name
        self.params = params
        self.batch = batch   #: None: one vehicle; B: update takes 12 arrays of B values
        self.gains = {axis: tuple(check_number(f'{self.GAINS_SECTION}.axes.{axis}', value, 0.0)
                                  for value in gains[axis])
                      for axis in AXES}
        self.lam = {axis: check_number('lambda', lam[axis], 0.0, low_inclusive=False) for axis in AXES}
        self.dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.tilt_limit = TiltLimit(max_tilt, low_altitude_max_tilt, low_altitude_height)
        tau = check_number('angle_filter_tau', angle_filter_tau, 0.0, low_inclusive=False)
        self.allocation = check_allocation(allocation)
        if attitude_rates not in ATTITUDE_RATES:
            raise ParameterError(f'common.attitude_rates: {attitude_rates!r} is not one of {", ".join(ATTITUDE_RATES)}')
        self.attitude_rates = attitude_rates
        self._filters = {name: RateFilter(self.dt, tau) for name in ('dphi', 'ddphi', 'dtheta', 'ddtheta')}
        #: [m, world z] below it the vehicle lifts off level and the x, y and attitude integrals hold (0: off);
        #: the take-off hold every controller kind shares (:class:`.controller.CascadedController`)
        self.takeoff_height = check_number('takeoff_height', takeoff_height, 0.0)
        self.position_integral = (0.0, 0.0, 0.0)    #: I_x [m s, world]
        self.attitude_integral = (0.0, 0.0, 0.0)    #: I_R [rad s, body]

    def adapt(self) -> None:
        """Nothing to learn."""

    def surface_slopes(self) -> tuple[float, ...]:
        """The slopes lambda [1/s] of the surfaces it reports, in AXES order (``control/diagnostics``)."""
        return tuple(self.lam[axis] for axis in AXES)

    def _integrate(self, integral, error, axes, held):
        """The integrals of ``error`` over one period, clamped; those of the axes ``held`` (x, y and the attitude
        on the ground, ``held`` the take-off hold) keep their value."""
        xp = namespace_for(*error)
        return tuple(xp.where(held & (a != 'z'), i, xp.clip(i + e * self.dt, -self.gains[a][3], self.gains[a][3]))
                     for i, e, a in zip(integral, error, axes))

    def on_ground(self, z):
        """Whether the take-off hold applies at height z [m] (a bool, or one per vehicle of a batch)."""
        return (z <= self.takeoff_height) & (self.takeoff_height > 0.0)

    def desired_force(self, state, reference: ReferenceSample, acceleration, held) -> list:
        """F_d [N, world] for the feedback acceleration ``acceleration`` [m/s^2, world]: m (feedback + xdd_d + g e3).
        The adaptive kinds replace this (:mod:`.indi`)."""
        p = self.params
        force = [p.m * (fb + acc) for fb, acc in zip(acceleration, reference.acceleration)]
        force[2] = force[2] + p.m * p.g
        return force

    def desired_attitude_rates(self, phi_d, theta_d, reference: ReferenceSample, z) -> tuple:
        """(dphi_d, ddphi_d, dtheta_d, ddtheta_d) [rad/s, rad/s^2] of the desired roll and pitch phi_d, theta_d [rad]
        by ``attitude_rates`` (module docstring): their filtered derivatives (``angle_filter_tau``), or the flat
        attitude of the reference at its yaw and the height z [m] (tilt limit) plus the filtered derivative of
        the feedback's part."""
        f = self._filters
        if self.attitude_rates == 'flatness':
            (ax, ay, _), (jx, jy, _), (sx, sy, _) = reference.acceleration, reference.jerk, reference.snap
            phi_r, dphi_r, ddphi_r, theta_r, dtheta_r, ddtheta_r = flat_attitude_of(
                ax, ay, jx, jy, sx, sy, reference.yaw, reference.yaw_rate, reference.yaw_acceleration, z,
                self.params.g, self.tilt_limit.kernel_parameters)
            return (dphi_r + f['dphi'].update(phi_d - phi_r), ddphi_r,
                    dtheta_r + f['dtheta'].update(theta_d - theta_r), ddtheta_r)
        dphi_d = f['dphi'].update(phi_d)
        dtheta_d = f['dtheta'].update(theta_d)
        return dphi_d, f['ddphi'].update(dphi_d), dtheta_d, f['ddtheta'].update(dtheta_d)

    def moment(self, state, angular_acceleration, gyroscopic, held):
        """M [N m, body] realising the desired angular acceleration [rad/s^2, body] on the nominal model:
        J angular_acceleration + Omega x J Omega. The adaptive kinds replace this."""
        p = self.params
        return tuple(j * a + g for j, a, g in zip((p.Ix, p.Iy, p.Iz), angular_acceleration, gyroscopic))

    def compensated(self, state, rotation, thrust, controls, held):
        """(U1 [N], (U2 [N], U3 [N], U4 [N m])) after an adaptive augmentation (:mod:`.l1_adaptive`); none here."""
        return thrust, controls

    def applied(self, state, controls, held) -> None:
        """What the rotors were commanded (U1 [N], U2, U3 [N], U4 [N m], after the allocation), for the kinds
        that predict with it; nothing to do here."""

    def update(self, t: float, state: Sequence, reference: ReferenceSample) -> ControlOutput:
        """Rotor thrusts [N] for the 12-state ``state`` and the reference at the same instant t [s].

        Raises ValueError on a state of the wrong shape, a time or a reference that is not one, or a
        non-finite state or reference, before any state changes (:func:`.controller.check_inputs`); and on
        non-finite thrusts of a single vehicle (:func:`.controller.finite_output`).
        """
        xp = check_inputs(t, state, reference, self.batch)
        p = self.params
        x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = state
        position_axes, attitude_axes = AXES[:3], AXES[3:]
        ex = tuple(q - qd for q, qd in zip((x, y, z), reference.position))
        ev = tuple(v - vd for v, vd in zip((vx, vy, vz), reference.velocity))
        held = self.on_ground(z)
        self.position_integral = self._integrate(self.position_integral, ex, position_axes, held)
        acceleration = tuple(-(self.gains[a][0] * e + self.gains[a][1] * de + self.gains[a][2] * i)
                             for a, e, de, i in zip(position_axes, ex, ev, self.position_integral))
        feedback = tuple(p.m * a for a in acceleration)
        force = self.desired_force(state, reference, acceleration, held)
        lift = xp.maximum(force[2], MIN_LIFT * p.m * p.g)
        horizontal = xp.hypot(force[0], force[1])
        allowed = lift * self.tilt_limit.tangent(z)
        shrink = xp.minimum(1.0, allowed / xp.maximum(horizontal, 1e-12 * p.m * p.g))
        force[0], force[1] = force[0] * shrink, force[1] * shrink

        rotation = rotation_from_euler(phi, theta, psi)
        thrust_axis = tuple(row[2] for row in rotation)
        thrust = force[0] * thrust_axis[0] + force[1] * thrust_axis[1] + force[2] * thrust_axis[2]

        psi_d = reference.yaw
        cpsi, spsi = xp.cos(psi_d), xp.sin(psi_d)
        heading_x = cpsi * force[0] + spsi * force[1]        # b3_d (unnormalised, vertical part >= lift)
        heading_y = -spsi * force[0] + cpsi * force[1]       # in the frame turned by -psi_d
        theta_d = xp.atan2(heading_x, lift)
        phi_d = xp.atan2(-heading_y, xp.hypot(heading_x, lift))
        dphi_d, ddphi_d, dtheta_d, ddtheta_d = self.desired_attitude_rates(phi_d, theta_d, reference, z)
        desired = (phi_d, theta_d, psi_d)
        desired_rates = (dphi_d, dtheta_d, reference.yaw_rate)
        omega_d = body_rates_from_euler_rates(desired, desired_rates)
        domega_d = euler_rate_derivative_to_body(desired, desired_rates,
                                                 (ddphi_d, ddtheta_d, reference.yaw_acceleration))

        omega = body_rates_from_euler_rates((phi, theta, psi), (dphi, dtheta, dpsi))
        rotation_d = rotation_from_euler(*desired)
        relative = _matmul(_transpose(rotation), rotation_d)           # R^T R_d
        e_r = _vee_of_antisymmetric_part(_transpose(relative))          # 1/2 vee(R_d^T R - R^T R_d)
        omega_d_body = _matvec(relative, omega_d)                       # R^T R_d Omega_d
        e_w = tuple(w - wd for w, wd in zip(omega, omega_d_body))
        self.attitude_integral = self._integrate(self.attitude_integral, e_r, attitude_axes, held)
        inertia = (p.Ix, p.Iy, p.Iz)
        momentum = tuple(j * w for j, w in zip(inertia, omega))
        gyroscopic = _cross(omega, momentum)
        turning = _cross(omega, omega_d_body)
        feedforward_d = _matvec(relative, domega_d)
        angular_feedback = tuple(-(self.gains[a][0] * er + self.gains[a][1] * ew + self.gains[a][2] * i)
                                 for a, er, ew, i in zip(attitude_axes, e_r, e_w, self.attitude_integral))
        angular_acceleration = tuple(fb - (w - a) for fb, w, a in zip(angular_feedback, turning, feedforward_d))
        moment = self.moment(state, angular_acceleration, gyroscopic, held)
        moment_feedback = tuple(j * fb for j, fb in zip(inertia, angular_feedback))
        scale = (p.d, p.d, 1.0)                                  # U2 = M_x / d, U3 = M_y / d, U4 = M_z
        u2, u3, u4 = (m / s for m, s in zip(moment, scale))
        thrust, (u2, u3, u4) = self.compensated(state, rotation, thrust, (u2, u3, u4), held)

        forces = allocate(self.allocation, thrust, u2, u3, u4, p.mixer, p.F_min, p.F_max, airborne=np.logical_not(held))
        controls = controls_from_forces(*forces, p.mixer)
        self.applied(state, controls, held)
        lam = self.lam
        axes = {a: AxisOutput(force[k] / p.m, ev[k] + lam[a] * ex[k], reference.acceleration[k],
                              force[k] / p.m - reference.acceleration[k])     # feedback, after the tilt limit
                for k, a in enumerate(AXES[:2])}
        axes['z'] = AxisOutput(thrust, ev[2] + lam['z'] * ex[2], thrust - feedback[2], feedback[2])
        axes.update({a: AxisOutput(u, e_w[k] + lam[a] * e_r[k], u - fb / s, fb / s) for k, (a, u, fb, s)
                     in enumerate(zip(attitude_axes, (u2, u3, u4), moment_feedback, scale))})
        return finite_output(ControlOutput(forces=forces, controls=controls, axes=axes, attitude_reference=desired),
                             self.batch)
