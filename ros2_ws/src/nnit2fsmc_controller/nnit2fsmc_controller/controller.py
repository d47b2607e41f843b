"""The cascaded flight controller shared by the NNIT2FSMC and its baselines.

One law per subsystem (x, y, z, phi, theta, psi; :mod:`.axis_laws`) inside one structure:

1. Position loop: the x and y laws give horizontal accelerations v_x, v_y [m/s^2, world]; the z law
   gives the collective thrust U1 [N].
2. Desired roll and pitch (eq. 10 as it is meant, see below) from v_x, v_y and the measured yaw.
3. Attitude loop: the phi, theta, psi laws give U2 [N], U3 [N], U4 [N m] (eq. 1 and 2 units).
4. Rotor thrusts by the inverse of eq. (2) within the rotor limits: by thrust-priority allocation
   (U1 first, then U2 and U3, U4 last; ``allocation='priority'``) or by clipping each rotor
   (``'clip'``, paper-faithful); :func:`quad_msgs_bridge.mixer.allocate`.

Eq. (10) as printed, phi_d = U_eq_psi + U_fuzzy and theta_d = U_eq_phi + U_fuzzy, names the wrong
subsystems and drops the yaw. What it means: the y subsystem's output sets the roll and the x
subsystem's sets the pitch. Implemented exactly for any heading: with the thrust direction of
eq. (1) and a vertical specific force g,

    theta_d = atan2(v_x cos psi + v_y sin psi, g)
    phi_d   = atan((v_x sin psi - v_y cos psi) cos theta_d / g)

which reduces to theta_d = v_x / g, phi_d = -v_y / g at small angles and psi = 0. The tilt is
limited to ``max_tilt``. The desired angle rates and accelerations the attitude surfaces need
are obtained by first-order filtered differentiation of phi_d and theta_d (time constant
``angle_filter_tau``).

Nominal model used by the model-based baselines (the NNIT2FSMC ignores it): for each subsystem
q'' = drift + gain v with, from eq. (1),
  x, y:  drift = -Kf v / m,                                          gain = 1 (v is an acceleration)
  z:     drift = -g - Kfz vz / m,                                    gain = cos(phi) cos(theta) / m
  phi:   drift = (dtheta dpsi (Iy - Iz) - Kfphi dphi|dphi|) / Ix,    gain = d / Ix
  theta: drift = (dphi dpsi (Iz - Ix) - Kftheta dtheta|dtheta|) / Iy, gain = d / Iy
  psi:   drift = (dphi dtheta (Ix - Iy) - Kfpsi dpsi|dpsi|) / Iz,    gain = 1 / Iz

One controller steps one vehicle (every state component a float) or a batch of B vehicles (every
state component a numpy array of B values; build it with ``batch=B``): the same code, through the
elementwise namespace of :mod:`quad_msgs_bridge.numeric`. The reference may be floats shared by
every vehicle of a batch, or arrays.
"""
from __future__ import annotations

import math
from typing import NamedTuple, Sequence

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.mixer import ALLOCATIONS, allocate, controls_from_forces
from quad_msgs_bridge.vehicle_params import ParameterError, VehicleParams, check_number

from .axis_laws import AxisOutput

AXES = ('x', 'y', 'z', 'phi', 'theta', 'psi')


class ControlOutput(NamedTuple):
    """One controller update."""

    forces: tuple[float, float, float, float]     #: rotor thrusts F1..F4 [N], within limits
    controls: tuple[float, float, float, float]   #: U1 [N], U2 [N], U3 [N], U4 [N m] the thrusts realise
    axes: dict[str, AxisOutput]                   #: per-subsystem diagnostics, keys AXES
    attitude_reference: tuple[float, float, float]  #: phi_d, theta_d, psi_d [rad]


def check_finite(t: float, state: Sequence, reference: ReferenceSample):
    """The numeric namespace of ``state``; ValueError if any value of the state or the reference is not finite."""
    xp = namespace_for(state[0])
    values = (*state, *reference.position, *reference.velocity, *reference.acceleration,
              reference.yaw, reference.yaw_rate, reference.yaw_acceleration)
    if not xp.all_finite(values):
        raise ValueError(f'non-finite state or reference at t={t}')
    return xp


def check_allocation(allocation: str) -> str:
    """``allocation`` if it is one of mixer.ALLOCATIONS, else ParameterError naming common.allocation."""
    if allocation not in ALLOCATIONS:
        raise ParameterError(f'common.allocation: {allocation!r} is not one of {", ".join(ALLOCATIONS)}')
    return allocation


class RateFilter:
    """First-order filtered derivative of a signal sampled every dt [s], time constant tau [s].

    The first sample gives rate 0 (a batch starts all its vehicles together).
    """

    STATE = ('previous', 'rate')   #: what a retune keeps (nnit2fsmc_controller.tuning)

    def __init__(self, dt: float, tau: float):
        self.blend = dt / (tau + dt)
        self.dt = dt
        self.previous = None
        self.rate = 0.0

    def update(self, value):
        if self.previous is not None:
            self.rate = self.rate + self.blend * ((value - self.previous) / self.dt - self.rate)
        self.previous = value
        return self.rate


class CascadedController:
    """update(t, state, reference) -> rotor thrusts, for any set of per-axis laws."""

    STATE = ()   #: its state lives in its laws and rate filters (nnit2fsmc_controller.tuning)

    def __init__(self, name: str, params: VehicleParams, laws: dict, dt: float,
                 max_tilt: float = 0.6, angle_filter_tau: float = 0.02, allocation: str = 'priority'):
        missing = [axis for axis in AXES if axis not in laws]
        if missing:
            raise ValueError(f'controller {name}: no law for axes {missing}')
        self.name = name
        self.params = params
        self.laws = laws
        self.dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.max_tilt = check_number('max_tilt', max_tilt, 0.0, 1.4, low_inclusive=False)
        tau = check_number('angle_filter_tau', angle_filter_tau, 0.0, low_inclusive=False)
        self.allocation = check_allocation(allocation)
        self._max_horizontal = params.g * math.tan(self.max_tilt)
        self._filters = {name: RateFilter(self.dt, tau) for name in ('dphi', 'ddphi', 'dtheta', 'ddtheta')}

    def update(self, t: float, state: Sequence, reference: ReferenceSample) -> ControlOutput:
        """Rotor thrusts [N] for the 12-state ``state`` and the reference at the same instant t [s].

        Raises ValueError on a non-finite state or reference (of any vehicle of a batch), before any
        law (or its learning) runs.
        """
        xp = check_finite(t, state, reference)
        p = self.params
        x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = state
        (xd, yd, zd), (vxd, vyd, vzd), (axd, ayd, azd) = reference.position, reference.velocity, reference.acceleration
        laws = self.laws
        cphi, ctheta = xp.cos(phi), xp.cos(theta)

        out_x = laws['x'].update(x - xd, vx - vxd, vxd, axd, -p.Kfx * vx / p.m, 1.0)
        out_y = laws['y'].update(y - yd, vy - vyd, vyd, ayd, -p.Kfy * vy / p.m, 1.0)
        out_z = laws['z'].update(z - zd, vz - vzd, vzd, azd, -p.g - p.Kfz * vz / p.m, cphi * ctheta / p.m)

        phi_d, theta_d = self.attitude_from_accelerations(out_x.value, out_y.value, psi)
        f = self._filters
        dphi_d = f['dphi'].update(phi_d)
        ddphi_d = f['ddphi'].update(dphi_d)
        dtheta_d = f['dtheta'].update(theta_d)
        ddtheta_d = f['ddtheta'].update(dtheta_d)
        psi_d = reference.yaw

        out_phi = laws['phi'].update(phi - phi_d, dphi - dphi_d, dphi_d, ddphi_d,
                                     (dtheta * dpsi * (p.Iy - p.Iz) - p.Kfphi * xp.signed_square(dphi)) / p.Ix,
                                     p.d / p.Ix)
        out_theta = laws['theta'].update(theta - theta_d, dtheta - dtheta_d, dtheta_d, ddtheta_d,
                                         (dphi * dpsi * (p.Iz - p.Ix) - p.Kftheta * xp.signed_square(dtheta)) / p.Iy,
                                         p.d / p.Iy)
        out_psi = laws['psi'].update(wrap_angle(psi - psi_d), dpsi - reference.yaw_rate, reference.yaw_rate,
                                     reference.yaw_acceleration,
                                     (dphi * dtheta * (p.Ix - p.Iy) - p.Kfpsi * xp.signed_square(dpsi)) / p.Iz,
                                     1.0 / p.Iz)

        forces = allocate(self.allocation, out_z.value, out_phi.value, out_theta.value, out_psi.value,
                          p.yaw_coefficient, p.F_min, p.F_max)
        return ControlOutput(
            forces=forces,
            controls=controls_from_forces(*forces, p.yaw_coefficient),
            axes={'x': out_x, 'y': out_y, 'z': out_z, 'phi': out_phi, 'theta': out_theta, 'psi': out_psi},
            attitude_reference=(phi_d, theta_d, psi_d))

    def adapt(self) -> None:
        """Take the online learning of the last update now rather than at the start of the next one.

        The forces of an update do not depend on its learning step, so a caller that has sent them
        can learn while the vehicle moves: in lockstep this takes the learning off the critical path.
        """
        for law in self.laws.values():
            law.adapt()

    def surface_slopes(self) -> tuple[float, ...]:
        """The sliding-surface slopes lambda [1/s] of the subsystems, in AXES order (``control/diagnostics``)."""
        return tuple(self.laws[axis].lam for axis in AXES)

    def attitude_from_accelerations(self, ax, ay, psi):
        """Eq. (10) as meant: (phi_d, theta_d) [rad] realising horizontal accelerations [m/s^2, world] at yaw psi.

        Beyond the tilt limit the acceleration is scaled down to it, its direction kept.
        """
        xp = namespace_for(psi)
        limit = self._max_horizontal
        norm = xp.hypot(ax, ay)
        beyond = norm > limit
        divisor = xp.maximum(norm, limit)     # = norm wherever it is used: never a division by zero
        ax, ay = xp.where(beyond, ax * limit / divisor, ax), xp.where(beyond, ay * limit / divisor, ay)
        g = self.params.g
        cpsi, spsi = xp.cos(psi), xp.sin(psi)
        theta_d = xp.atan2(ax * cpsi + ay * spsi, g)
        phi_d = xp.atan((ax * spsi - ay * cpsi) * xp.cos(theta_d) / g)
        return phi_d, theta_d
