"""The cascaded flight controller shared by the NNIT2FSMC and its baselines.

One law per subsystem (x, y, z, phi, theta, psi; :mod:`.axis_laws`) inside one structure:

1. Position loop: the x and y laws give horizontal accelerations v_x, v_y [m/s^2, world]; the z law
   gives the collective thrust U1 [N].
2. Desired roll and pitch (eq. 10 as it is meant, see below) from v_x, v_y and the measured yaw.
3. Attitude loop: the phi, theta, psi laws give U2 [N], U3 [N], U4 [N m] (eq. 1 and 2 units).
4. Rotor thrusts by the inverse of eq. (2) within the rotor limits: by thrust-priority allocation
   (U1 first, then U2 and U3, U4 last; ``allocation='priority'``), by airmode allocation (above the take-off
   height, when U1 is too low for the moments: U2 and U3 first, then U4, U1 raised to what they need; otherwise
   thrust first; ``'airmode'``) or by clipping each rotor
   (``'clip'``, paper-faithful); :func:`quad_msgs_bridge.mixer.allocate`.

Eq. (10) as printed, phi_d = U_eq_psi + U_fuzzy and theta_d = U_eq_phi + U_fuzzy, names the wrong
subsystems and drops the yaw. What it means: the y subsystem's output sets the roll and the x
subsystem's sets the pitch. Implemented exactly for any heading: with the thrust direction of
eq. (1) and a vertical specific force g,

    theta_d = atan2(v_x cos psi + v_y sin psi, g)
    phi_d   = atan((v_x sin psi - v_y cos psi) cos theta_d / g)

which reduces to theta_d = v_x / g, phi_d = -v_y / g at small angles and psi = 0. The tilt is
limited to ``max_tilt``, and to less near the ground (:class:`TiltLimit`). The desired angle rates
and accelerations the attitude surfaces need come from one of two sources (``attitude_rates``):

* ``filter`` (the paper's structure): first-order filtered differentiation of phi_d and theta_d
  (time constant ``angle_filter_tau``). phi_d and theta_d carry the position loop's feedback, so
  sensor noise is differentiated twice.
* ``flatness`` (differential flatness, Mellinger & Kumar 2011): split the desired attitude into
  the attitude of the reference acceleration, phi_r = eq. (10) at (x_d'', y_d''), and the feedback
  residual phi_d - phi_r. The rate and acceleration of phi_r are the exact time derivatives of
  eq. (10) along the reference (reference jerk and snap, reference yaw rate and acceleration;
  :meth:`CascadedController.flat_attitude`); the residual, small and slow except while the
  position loop corrects an error, is differentiated once by the filter. The surface uses
  dphi_r + filtered d(residual)/dt; the law's reference inputs (the network's inputs, the
  model-based equivalent control) are dphi_r and ddphi_r only: the network then sees the
  reference motion, as in the position subsystems, and no feedback signal (with the filter's
  derivatives of phi_d as inputs, learning adapts a feedback gain and limit-cycles under delay,
  like the error inputs of docs/PAPER.md item 13).

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

import numpy as np
from numba import njit

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.numeric import BATCH, namespace_for, select
from quad_msgs_bridge.reference import REFERENCE_UNITS, ReferenceSample
from quad_msgs_bridge.state import STATE_LAYOUT, STATE_NAMES
from quad_msgs_bridge.mixer import ALLOCATIONS, allocate, allocate_by_index, controls_from_forces
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams

from .axis_laws import AxisOutput, law_step, set_law_learning
from .kernel_state import OPTIONAL, Slot

AXES = ('x', 'y', 'z', 'phi', 'theta', 'psi')
ATTITUDE_RATES = ('flatness', 'filter')   #: sources of the desired roll/pitch rates (module docstring)
#: the subsystems whose networks learn only once airborne (``takeoff_height``): on the ground the vehicle can
#: neither move horizontally nor tilt, so their errors teach nothing; z learns throughout (its network lifts the
#: vehicle). Their laws act below that height all the same (no level lift-off: docs/ADAPTIVE_BASELINES.md)
HELD_ON_GROUND = ('x', 'y', 'phi', 'theta', 'psi')


class ControlOutput(NamedTuple):
    """One controller update."""

    forces: tuple[float, float, float, float]     #: rotor thrusts F1..F4 [N], within limits
    controls: tuple[float, float, float, float]   #: U1 [N], U2 [N], U3 [N], U4 [N m] the thrusts realise
    axes: dict[str, AxisOutput]                   #: per-subsystem diagnostics, keys AXES
    attitude_reference: tuple[float, float, float]  #: phi_d, theta_d, psi_d [rad]


def check_inputs(t: float, state: Sequence, reference: ReferenceSample, batch: int | None):
    """The numeric namespace of ``state``, after checking the arguments of ``update``: ValueError naming
    the argument and what it should be (``t`` a finite time [s]; ``state`` 12 numbers for one vehicle,
    12 arrays of ``batch`` values for a batch; ``reference`` a ReferenceSample), or if any value of the
    state or the reference is not finite. Cheap: it runs at every control step."""
    if not isinstance(reference, ReferenceSample):
        raise ValueError(f'reference: expected a quad_msgs_bridge.reference.ReferenceSample, '
                         f'got {type(reference).__name__}')
    try:
        if not math.isfinite(t):
            raise ValueError(f't: the time must be finite [s], got {t}')
    except TypeError:
        raise ValueError(f't: expected a number of seconds, got {type(t).__name__}') from None
    shape = np.shape(state) if isinstance(state, np.ndarray) else None
    try:
        count = len(state)
    except TypeError:
        raise ValueError(f'state: expected a sequence of 12 values ({STATE_LAYOUT}), '
                         f'got {type(state).__name__}') from None
    expected = ('12 numbers' if batch is None else f'12 arrays of {batch} values (shape (12, {batch}))')
    if count != 12:
        got = f'an array of shape {shape}' if shape is not None else f'{count} values'
        raise ValueError(f'state: expected {expected} ({STATE_LAYOUT}), got {got}')
    xp = namespace_for(*state)
    if batch is None:
        if xp is BATCH:
            raise ValueError(f'state: a single-vehicle controller takes 12 numbers ({STATE_LAYOUT}), got arrays '
                             f'(shape {np.shape(state)}); for a batch of B vehicles build it with batch=B and pass '
                             '12 arrays of B values')
    else:
        for value in state:
            if not isinstance(value, np.ndarray) or value.shape != (batch,):
                raise ValueError(f'state: a controller of a batch of {batch} vehicles takes {expected}, got '
                                 f'{"a number" if np.ndim(value) == 0 else f"an array of shape {np.shape(value)}"} '
                                 'among them')
        xp = BATCH
    try:
        sized = (len(reference.position) == len(reference.velocity) == len(reference.acceleration)
                 == len(reference.jerk) == len(reference.snap) == 3)
    except TypeError:
        sized = False
    if not sized:
        raise ValueError(_not_a_vector(reference))
    values = (*state, *reference.position, *reference.velocity, *reference.acceleration,
              reference.yaw, reference.yaw_rate, reference.yaw_acceleration, *reference.jerk, *reference.snap)
    try:
        finite = xp.all_finite(values)
    except TypeError:
        raise ValueError(_not_a_number(state, reference)) from None
    if not finite:
        raise ValueError(f'non-finite state or reference at t={t}')
    return xp


def finite_output(out: ControlOutput, batch: int | None) -> ControlOutput:
    """``out``, or ValueError if a single vehicle's rotor thrusts are not finite: a finite state far beyond
    any flight (|values| near 1e300) overflows the laws. A batch's diverging vehicle is the closed loop's to
    fail and freeze (flight_stack.closed_loop), so a batch is passed as it is."""
    if batch is None and not all(map(math.isfinite, out.forces)):
        raise ValueError(f'the rotor thrusts came out non-finite {tuple(out.forces)}: the state or reference is '
                         'beyond what the laws can compute (overflow)')
    return out


def _not_a_vector(reference: ReferenceSample) -> str:
    """What names the first vector field of ``reference`` that is not 3 values."""
    for name in ('position', 'velocity', 'acceleration', 'jerk', 'snap'):
        vector = getattr(reference, name)
        if not hasattr(vector, '__len__') or len(vector) != 3:
            return f'reference.{name}: expected 3 values [{REFERENCE_UNITS[name]}, world ENU], got {vector!r}'
    return 'reference: a vector field is not 3 values'


def _not_a_number(state: Sequence, reference: ReferenceSample) -> str:
    """What names the first value of ``state`` or ``reference`` that is not a number (or array of numbers)."""
    def numeric(value) -> bool:
        try:
            return np.asarray(value).dtype.kind in 'biuf' and not isinstance(value, (str, bytes))
        except (TypeError, ValueError):
            return False
    named = [(f'state[{k}] ({name})', value) for k, (name, value) in enumerate(zip(STATE_NAMES, state))]
    for field_name in ReferenceSample._fields:
        value = getattr(reference, field_name)
        named += ([(f'reference.{field_name}[{k}]', v) for k, v in enumerate(value)] if isinstance(value, tuple)
                  else [(f'reference.{field_name}', value)])
    for name, value in named:
        if not numeric(value):
            return f'{name}: expected a number, got {value!r} ({type(value).__name__})'
    return 'state or reference: a value is not a number'


def check_allocation(allocation: str) -> str:
    """``allocation`` if it is one of mixer.ALLOCATIONS, else ParameterError naming common.allocation."""
    if allocation not in ALLOCATIONS:
        raise ParameterError(f'common.allocation: {allocation!r} is not one of {", ".join(ALLOCATIONS)}')
    return allocation


@njit(cache=True, inline='always', error_model='numpy')
def filtered_rate(rate, previous, value, blend, dt):
    """The next rate of :class:`RateFilter` from its last ``rate``, the ``previous`` and the new sample ``value``."""
    return rate + blend * ((value - previous) / dt - rate)


class RateFilter:
    """First-order filtered derivative of a signal sampled every dt [s], time constant tau [s].

    The first sample gives rate 0 (a batch starts all its vehicles together). ``store`` (3 floats): a single
    vehicle's state kept there (:mod:`.kernel_state`), as the controller's kernel reads it (:func:`rate_of`).
    """

    STATE = ('previous', 'rate')   #: what a retune keeps (nnit2fsmc_controller.tuning)
    STORE_SIZE = 3
    previous = Slot(0, OPTIONAL)   #: the last sample (None before the first)
    rate = Slot(2)                 #: the filtered derivative

    def __init__(self, dt: float, tau: float, store=None):
        self.blend = dt / (tau + dt)
        self.dt = dt
        self.store = store
        self.previous = None
        self.rate = 0.0

    def update(self, value):
        if self.previous is not None:
            self.rate = filtered_rate(self.rate, self.previous, value, self.blend, self.dt)
        self.previous = value
        return self.rate


@njit(cache=True, inline='always', error_model='numpy')
def rate_of(store, value, blend, dt):
    """:meth:`RateFilter.update` of a single vehicle's filter with ``store`` (3 floats: RateFilter's slots)."""
    if store[0] != 0.0:
        store[2] = filtered_rate(store[2], store[1], value, blend, dt)
    store[0], store[1] = 1.0, value
    return store[2]


class TiltLimit:
    """The tilt limit by height: tan of the largest roll/pitch (tilt of the thrust axis) the position
    loop may ask for at height z [m, world; the ground is z = 0].

    ``max_tilt`` [rad] at and above ``low_altitude_height`` [m], ``low_altitude_max_tilt`` [rad] below
    it. Near the ground a tilted vehicle trades lift for a horizontal push it has no height to spend
    on, and a large tilt just after lift-off tips it over (docs/ADAPTIVE.md item 8).
    ``low_altitude_height`` 0, or a ``low_altitude_max_tilt`` not below ``max_tilt``: ``max_tilt`` at every
    height.
    """

    STATE = ()   #: stateless: a retune takes the new one whole (nnit2fsmc_controller.tuning)

    def __init__(self, max_tilt: float, low_altitude_max_tilt: float | None = None, low_altitude_height: float = 0.0):
        self.max_tilt = max_tilt = check_number('max_tilt', max_tilt, 0.0, 1.4, low_inclusive=False)
        low = max_tilt if low_altitude_max_tilt is None else check_number(
            'low_altitude_max_tilt', low_altitude_max_tilt, 0.0, 1.4, low_inclusive=False)
        self.height = check_number('low_altitude_height', low_altitude_height, 0.0)
        self.high_tangent = math.tan(max_tilt)
        self.low_tangent = math.tan(min(low, max_tilt))
        constant = self.height == 0.0 or self.low_tangent == self.high_tangent
        #: (tan of the limit above the height, tan below it, the height [m]) as :func:`tilt_tangent` takes them
        self.kernel_parameters = (self.high_tangent, self.high_tangent if constant else self.low_tangent, self.height)

    def tangent(self, z):
        """tan(limit) at height z [m] (a float, or one per vehicle of a batch)."""
        return tilt_tangent(self.kernel_parameters, z)


@njit(cache=True, inline='always')
def tilt_tangent(limit, z):
    """tan of the tilt limit at height z [m] (TiltLimit.kernel_parameters ``limit``)."""
    return select(z < limit[2], limit[1], limit[0])


@njit(cache=True, inline='always', error_model='numpy')
def _tilt_scale(ax, ay, z, g, limit):
    """Factor (<= 1) that brings the horizontal acceleration (ax, ay) [m/s^2] within the tilt limit at height z [m]."""
    bound = g * tilt_tangent(limit, z)
    return bound / np.maximum(np.hypot(ax, ay), bound)


@njit(cache=True, error_model='numpy')
def attitude_of_accelerations(ax, ay, psi, z, g, limit):
    """Eq. (10) as meant: (phi_d, theta_d) [rad] realising horizontal accelerations [m/s^2, world] at yaw psi,
    the acceleration first scaled down to the tilt limit at height z [m] (:class:`TiltLimit`), direction kept."""
    scale = _tilt_scale(ax, ay, z, g, limit)
    ax, ay = ax * scale, ay * scale
    cpsi, spsi = np.cos(psi), np.sin(psi)
    theta_d = np.arctan2(ax * cpsi + ay * spsi, g)
    phi_d = np.arctan((ax * spsi - ay * cpsi) * np.cos(theta_d) / g)
    return phi_d, theta_d


@njit(cache=True, error_model='numpy')
def flat_attitude_of(ax, ay, jx, jy, sx, sy, psi, dpsi, ddpsi, z, g, limit):
    """(phi_d, dphi_d, ddphi_d, theta_d, dtheta_d, ddtheta_d): :meth:`CascadedController.flat_attitude`."""
    scale = _tilt_scale(ax, ay, z, g, limit)
    ax, ay = ax * scale, ay * scale
    jx, jy, sx, sy = jx * scale, jy * scale, sx * scale, sy * scale
    c, s = np.cos(psi), np.sin(psi)
    a_, b_ = ax * c + ay * s, ax * s - ay * c
    ja, jb = jx * c + jy * s, jx * s - jy * c
    sa, sb = sx * c + sy * s, sx * s - sy * c
    da, db = ja - dpsi * b_, jb + dpsi * a_
    dda = sa - 2.0 * dpsi * jb - ddpsi * b_ - dpsi * dpsi * a_
    ddb = sb + 2.0 * dpsi * ja + ddpsi * a_ - dpsi * dpsi * b_
    q = g * g + a_ * a_
    theta = np.arctan2(a_, g)
    dtheta = g * da / q
    ddtheta = g * dda / q - 2.0 * g * a_ * da * da / (q * q)
    ct, st = np.cos(theta), np.sin(theta)
    cc = b_ * ct / g
    dc = (db * ct - b_ * st * dtheta) / g
    ddc = (ddb * ct - 2.0 * db * st * dtheta - b_ * ct * dtheta * dtheta - b_ * st * ddtheta) / g
    r = 1.0 + cc * cc
    return np.arctan(cc), dc / r, ddc / r - 2.0 * cc * dc * dc / (r * r), theta, dtheta, ddtheta


#: positions in a CascadedController's kernel constants (:func:`cascade_step`)
(_M, _G, _KFX, _KFY, _KFZ, _IX, _IY, _IZ, _KFPHI, _KFTHETA, _KFPSI, _D, _F_MIN, _F_MAX, _TAKEOFF, _FLATNESS, _ALLOCATION,
 _BLEND, _DT, _TILT, _HELD, _LAW_STORES, _LAW_CONSTANTS, _FILTERS) = (*range(20), 22, 28, 34, 40)
_CONSTANTS_SIZE = 41
#: positions of the reference in the inputs of :func:`cascade_step` (after the 12-state)
_POSITION, _VELOCITY, _ACCELERATION, _YAW, _YAW_RATE, _YAW_ACCELERATION, _JERK, _SNAP = 12, 15, 18, 21, 22, 23, 24, 27


@njit(cache=True, inline='always')
def _law(k, store, law_constants, c, e, de, ref_vel, ref_acc, drift, gain):
    """Law k (AXES order) of the controller: its (v, S, equivalent, corrective)."""
    first, constants = int(c[_LAW_STORES + k]), int(c[_LAW_CONSTANTS + k])
    last = int(c[_LAW_STORES + k + 1]) if k < 5 else int(c[_FILTERS])
    return law_step(store[first:last], law_constants[constants:], e, de, ref_vel, ref_acc, drift, gain)


@njit(cache=True, error_model='numpy')
def cascade_step(store, law_constants, c, mixer, inputs):
    """:meth:`CascadedController.update` of one vehicle whose six laws offer a kernel (:func:`.axis_laws.law_step`),
    in one compiled call: ``inputs`` the 12-state then the reference (_POSITION ...), ``store`` the state of the
    laws and the rate filters (in place), ``law_constants`` the laws' kernel constants, ``c`` the controller's
    (_M ...), ``mixer`` the vehicle's. Returns (forces, controls, each law's (v, S, equivalent, corrective) in
    AXES order, (phi_d, theta_d, psi_d)). The same equations, in the same order, as the update written for floats
    and arrays."""
    x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = (
        inputs[0], inputs[1], inputs[2], inputs[3], inputs[4], inputs[5], inputs[6], inputs[7], inputs[8], inputs[9],
        inputs[10], inputs[11])
    xd, yd, zd = inputs[_POSITION], inputs[_POSITION + 1], inputs[_POSITION + 2]
    vxd, vyd, vzd = inputs[_VELOCITY], inputs[_VELOCITY + 1], inputs[_VELOCITY + 2]
    axd, ayd, azd = inputs[_ACCELERATION], inputs[_ACCELERATION + 1], inputs[_ACCELERATION + 2]
    m, g, ix, iy, iz = c[_M], c[_G], c[_IX], c[_IY], c[_IZ]
    airborne = True
    if c[_TAKEOFF] > 0.0:
        airborne = z > c[_TAKEOFF]
        for k in range(6):
            if c[_HELD + k] != 0.0:
                first = int(c[_LAW_STORES + k])
                set_law_learning(store[first:], law_constants[int(c[_LAW_CONSTANTS + k]):], airborne)
    cphi, ctheta = np.cos(phi), np.cos(theta)
    out_x = _law(0, store, law_constants, c, x - xd, vx - vxd, vxd, axd, -c[_KFX] * vx / m, 1.0)
    out_y = _law(1, store, law_constants, c, y - yd, vy - vyd, vyd, ayd, -c[_KFY] * vy / m, 1.0)
    out_z = _law(2, store, law_constants, c, z - zd, vz - vzd, vzd, azd, -g - c[_KFZ] * vz / m, cphi * ctheta / m)
    ax_cmd, ay_cmd = out_x[0], out_y[0]
    limit = (c[_TILT], c[_TILT + 1], c[_TILT + 2])
    phi_d, theta_d = attitude_of_accelerations(ax_cmd, ay_cmd, psi, z, g, limit)
    filters, blend, dt = int(c[_FILTERS]), c[_BLEND], c[_DT]
    yaw_rate, yaw_acceleration = inputs[_YAW_RATE], inputs[_YAW_ACCELERATION]
    if c[_FLATNESS] != 0.0:
        phi_r, dphi_r, ddphi_r, theta_r, dtheta_r, ddtheta_r = flat_attitude_of(
            axd, ayd, inputs[_JERK], inputs[_JERK + 1], inputs[_SNAP], inputs[_SNAP + 1], psi, yaw_rate,
            yaw_acceleration, z, g, limit)
        dphi_d = dphi_r + rate_of(store[filters:filters + 3], phi_d - phi_r, blend, dt)
        dtheta_d = dtheta_r + rate_of(store[filters + 6:filters + 9], theta_d - theta_r, blend, dt)
    else:
        dphi_d = dphi_r = rate_of(store[filters:filters + 3], phi_d, blend, dt)
        ddphi_r = rate_of(store[filters + 3:filters + 6], dphi_d, blend, dt)
        dtheta_d = dtheta_r = rate_of(store[filters + 6:filters + 9], theta_d, blend, dt)
        ddtheta_r = rate_of(store[filters + 9:filters + 12], dtheta_d, blend, dt)
    psi_d = inputs[_YAW]
    out_phi = _law(3, store, law_constants, c, phi - phi_d, dphi - dphi_d, dphi_r, ddphi_r,
                   (dtheta * dpsi * (iy - iz) - c[_KFPHI] * (dphi * abs(dphi))) / ix, c[_D] / ix)
    out_theta = _law(4, store, law_constants, c, theta - theta_d, dtheta - dtheta_d, dtheta_r, ddtheta_r,
                     (dphi * dpsi * (iz - ix) - c[_KFTHETA] * (dtheta * abs(dtheta))) / iy, c[_D] / iy)
    out_psi = _law(5, store, law_constants, c, wrap_angle(psi - psi_d), dpsi - yaw_rate, yaw_rate, yaw_acceleration,
                   (dphi * dtheta * (ix - iy) - c[_KFPSI] * (dpsi * abs(dpsi))) / iz, 1.0 / iz)
    forces = allocate_by_index(int(c[_ALLOCATION]), out_z[0], out_phi[0], out_theta[0], out_psi[0], mixer, c[_F_MIN],
                               c[_F_MAX], not (c[_TAKEOFF] > 0.0 and z <= c[_TAKEOFF]))
    controls = controls_from_forces(forces[0], forces[1], forces[2], forces[3], mixer)
    return forces, controls, (out_x, out_y, out_z, out_phi, out_theta, out_psi), (phi_d, theta_d, psi_d)


class CascadedController:
    """update(t, state, reference) -> rotor thrusts, for any set of per-axis laws.

    A single vehicle whose six laws offer a kernel (``kernel_constants`` and a ``store``, today the NNIT2FSMC
    family) is updated by one compiled call, :func:`cascade_step`, on one store holding the state of its laws
    and rate filters (:mod:`.kernel_state`); any other (a batch, other laws) by the same equations written
    for floats and arrays below."""

    STATE = ()   #: its state lives in its laws and rate filters (nnit2fsmc_controller.tuning)

    def __init__(self, name: str, params: VehicleParams, laws: dict, dt: float,
                 max_tilt: float = 0.6, angle_filter_tau: float = 0.02, allocation: str = 'priority',
                 attitude_rates: str = 'filter', takeoff_height: float = 0.0,
                 low_altitude_max_tilt: float | None = None, low_altitude_height: float = 0.0,
                 batch: int | None = None):
        """The state it reads has passed the measurement stage of every controller kind
        (:class:`.estimation.MeasurementStage`, applied by the closed loop and the controller node).

        ``takeoff_height`` > 0 [m, world z; the ground is z = 0]: while a vehicle's (filtered) height is
        not above it, the networks and integrators of HELD_ON_GROUND hold (the laws' ``learning`` flag; the
        sliding-mode laws have no state to hold); the laws act all the same. 0: the laws learn from the first
        update (paper).

        ``max_tilt``, ``low_altitude_max_tilt`` [rad], ``low_altitude_height`` [m]: the tilt limit by
        (filtered) height, :class:`TiltLimit`. ``batch``: None for one vehicle, or the number of
        vehicles B it steps at once (what :meth:`update` accepts)."""
        missing = [axis for axis in AXES if axis not in laws]
        if missing:
            raise ValueError(f'controller {name}: no law for axes {missing}')
        self.name = name
        self.params = params
        self.laws = laws
        self.batch = batch
        self.dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.tilt_limit = TiltLimit(max_tilt, low_altitude_max_tilt, low_altitude_height)
        tau = check_number('angle_filter_tau', angle_filter_tau, 0.0, low_inclusive=False)
        self.allocation = check_allocation(allocation)
        if attitude_rates not in ATTITUDE_RATES:
            raise ParameterError(f'common.attitude_rates: {attitude_rates!r} is not one of {", ".join(ATTITUDE_RATES)}')
        self.attitude_rates = attitude_rates
        self.takeoff_height = check_number('takeoff_height', takeoff_height, 0.0)
        self._held_on_ground = ([laws[axis] for axis in HELD_ON_GROUND if hasattr(laws[axis], 'learning')]
                                if self.takeoff_height > 0.0 else [])   #: the laws with a state to hold
        self._filters = {name: RateFilter(self.dt, tau) for name in ('dphi', 'ddphi', 'dtheta', 'ddtheta')}
        self._kernel = None
        if batch is None and all(hasattr(laws[axis], 'kernel_constants') for axis in AXES):
            self._bind_kernel(tau)

    def _bind_kernel(self, tau: float) -> None:
        """One store for the laws and rate filters (their values kept) and the constants of :func:`cascade_step`."""
        laws = [self.laws[axis] for axis in AXES]
        sizes = [law.store.size for law in laws] + [RateFilter.STORE_SIZE] * 4
        offsets = np.concatenate(([0], np.cumsum(sizes))).astype(int)
        store = np.zeros(offsets[-1])
        for law, start, end in zip(laws, offsets, offsets[1:]):
            store[start:end] = law.store
            law.bind(store[start:end])
        self._filters = {name: RateFilter(self.dt, tau, store[offsets[6 + k]:offsets[7 + k]])
                         for k, name in enumerate(('dphi', 'ddphi', 'dtheta', 'ddtheta'))}
        law_constants = [law.kernel_constants for law in laws]
        constant_offsets = np.concatenate(([0], np.cumsum([len(c) for c in law_constants])))
        p = self.params
        constants = np.zeros(_CONSTANTS_SIZE)
        constants[:_TILT + 3] = (p.m, p.g, p.Kfx, p.Kfy, p.Kfz, p.Ix, p.Iy, p.Iz, p.Kfphi, p.Kftheta, p.Kfpsi, p.d,
                                 p.F_min, p.F_max, self.takeoff_height, self.attitude_rates == 'flatness',
                                 ALLOCATIONS.index(self.allocation), self._filters['dphi'].blend, self.dt,
                                 *self.tilt_limit.kernel_parameters)
        constants[_HELD:_HELD + 6] = [law in self._held_on_ground for law in laws]
        constants[_LAW_STORES:_LAW_STORES + 6] = offsets[:6]
        constants[_LAW_CONSTANTS:_LAW_CONSTANTS + 6] = constant_offsets[:6]
        constants[_FILTERS] = offsets[6]
        self.store = store
        self._kernel = (store, np.concatenate(law_constants), constants, np.ascontiguousarray(p.mixer))

    def update(self, t: float, state: Sequence, reference: ReferenceSample) -> ControlOutput:
        """Rotor thrusts [N] for the 12-state ``state`` and the reference at the same instant t [s].

        Raises ValueError on a state of the wrong shape (see :func:`check_inputs`), a time or a reference
        that is not one, or a non-finite state or reference (of any vehicle of a batch), before any law (or
        its learning) runs; and on non-finite thrusts of a single vehicle (:func:`finite_output`).
        """
        xp = check_inputs(t, state, reference, self.batch)
        if self._kernel is not None:
            return finite_output(self._kernel_update(state, reference), self.batch)
        p = self.params
        x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = state
        laws = self.laws
        if self.takeoff_height > 0.0:
            airborne = z > self.takeoff_height
            for law in self._held_on_ground:
                law.learning = airborne
        (xd, yd, zd), (vxd, vyd, vzd), (axd, ayd, azd) = reference.position, reference.velocity, reference.acceleration
        cphi, ctheta = xp.cos(phi), xp.cos(theta)

        out_x = laws['x'].update(x - xd, vx - vxd, vxd, axd, -p.Kfx * vx / p.m, 1.0)
        out_y = laws['y'].update(y - yd, vy - vyd, vyd, ayd, -p.Kfy * vy / p.m, 1.0)
        out_z = laws['z'].update(z - zd, vz - vzd, vzd, azd, -p.g - p.Kfz * vz / p.m, cphi * ctheta / p.m)

        ax_cmd, ay_cmd = out_x.value, out_y.value
        phi_d, theta_d = self.attitude_from_accelerations(ax_cmd, ay_cmd, psi, z)
        f = self._filters
        if self.attitude_rates == 'flatness':
            phi_r, dphi_r, ddphi_r, theta_r, dtheta_r, ddtheta_r = self.flat_attitude(
                axd, ayd, reference.jerk[:2], reference.snap[:2], psi, reference.yaw_rate, reference.yaw_acceleration,
                z)
            dphi_d = dphi_r + f['dphi'].update(phi_d - phi_r)
            dtheta_d = dtheta_r + f['dtheta'].update(theta_d - theta_r)
        else:
            dphi_d = dphi_r = f['dphi'].update(phi_d)
            ddphi_r = f['ddphi'].update(dphi_d)
            dtheta_d = dtheta_r = f['dtheta'].update(theta_d)
            ddtheta_r = f['ddtheta'].update(dtheta_d)
        psi_d = reference.yaw

        out_phi = laws['phi'].update(phi - phi_d, dphi - dphi_d, dphi_r, ddphi_r,
                                     (dtheta * dpsi * (p.Iy - p.Iz) - p.Kfphi * xp.signed_square(dphi)) / p.Ix,
                                     p.d / p.Ix)
        out_theta = laws['theta'].update(theta - theta_d, dtheta - dtheta_d, dtheta_r, ddtheta_r,
                                         (dphi * dpsi * (p.Iz - p.Ix) - p.Kftheta * xp.signed_square(dtheta)) / p.Iy,
                                         p.d / p.Iy)
        out_psi = laws['psi'].update(wrap_angle(psi - psi_d), dpsi - reference.yaw_rate, reference.yaw_rate,
                                     reference.yaw_acceleration,
                                     (dphi * dtheta * (p.Ix - p.Iy) - p.Kfpsi * xp.signed_square(dpsi)) / p.Iz,
                                     1.0 / p.Iz)

        forces = allocate(self.allocation, out_z.value, out_phi.value, out_theta.value, out_psi.value,
                          p.mixer, p.F_min, p.F_max, airborne=(z > self.takeoff_height) | (self.takeoff_height <= 0.0))
        return finite_output(ControlOutput(
            forces=forces,
            controls=controls_from_forces(*forces, p.mixer),
            axes={'x': out_x, 'y': out_y, 'z': out_z, 'phi': out_phi, 'theta': out_theta, 'psi': out_psi},
            attitude_reference=(phi_d, theta_d, psi_d)), self.batch)

    def _kernel_update(self, state: Sequence, reference: ReferenceSample) -> ControlOutput:
        """:meth:`update` of a single vehicle by :func:`cascade_step` (inputs checked)."""
        store, law_constants, constants, mixer = self._kernel
        inputs = np.array((*state, *reference.position, *reference.velocity, *reference.acceleration, reference.yaw,
                           reference.yaw_rate, reference.yaw_acceleration, *reference.jerk, *reference.snap),
                          dtype=float)
        forces, controls, axes, attitude = cascade_step(store, law_constants, constants, mixer, inputs)
        return ControlOutput(forces, controls, dict(zip(AXES, map(AxisOutput._make, axes))), attitude)

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

    def flat_attitude(self, ax, ay, jerk, snap, psi, dpsi, ddpsi, z):
        """(phi_d, dphi_d, ddphi_d, theta_d, dtheta_d, ddtheta_d) [rad, rad/s, rad/s^2]: eq. (10) at
        (ax, ay) [m/s^2] and yaw psi [rad] (:meth:`attitude_from_accelerations`, the same arithmetic)
        and its time derivatives when the acceleration changes with ``jerk`` (jx, jy) [m/s^3] and
        ``snap`` (sx, sy) [m/s^4] and the yaw with dpsi [rad/s], ddpsi [rad/s^2] (differential
        flatness). Beyond the tilt limit at height z [m] the three are scaled like the acceleration.

        With A = ax cos psi + ay sin psi, B = ax sin psi - ay cos psi, theta_d = atan(A / g) and
        phi_d = atan(C), C = B cos(theta_d) / g:
          A' = jA - dpsi B,  B' = jB + dpsi A  (jA, jB: the jerk rotated like (ax, ay))
          A'' = sA - 2 dpsi jB - ddpsi B - dpsi^2 A,  B'' = sB + 2 dpsi jA + ddpsi A - dpsi^2 B
          theta' = g A' / (g^2 + A^2),  theta'' = g A'' / (g^2 + A^2) - 2 g A A'^2 / (g^2 + A^2)^2
          C' = (B' cos - B sin theta') / g,  C'' = (B'' cos - 2 B' sin theta' - B cos theta'^2 - B sin theta'') / g
          phi' = C' / (1 + C^2),  phi'' = C'' / (1 + C^2) - 2 C C'^2 / (1 + C^2)^2
        """
        (jx, jy), (sx, sy) = jerk, snap
        return flat_attitude_of(ax, ay, jx, jy, sx, sy, psi, dpsi, ddpsi, z, self.params.g,
                                self.tilt_limit.kernel_parameters)

    def attitude_from_accelerations(self, ax, ay, psi, z):
        """Eq. (10) as meant: (phi_d, theta_d) [rad] realising horizontal accelerations [m/s^2, world] at yaw psi.

        Beyond the tilt limit at height z [m, world] the acceleration is scaled down to it, its direction kept.
        """
        return attitude_of_accelerations(ax, ay, psi, z, self.params.g, self.tilt_limit.kernel_parameters)
