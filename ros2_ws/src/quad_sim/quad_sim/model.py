"""The paper's 6-DOF quadrotor model, eq. (1) driven through eq. (2), integrated by fixed-step RK4.

State: the 12 paper states in the order of :mod:`quad_msgs_bridge.state` (position [m, world ENU],
velocity [m/s, world], Euler angles [rad], Euler rates [rad/s]). A single vehicle's state is a
sequence of 12 floats; a batch's is 12 numpy arrays with one element per vehicle (the vehicle
parameters may be floats or such arrays too, see :meth:`VehicleParams.stack`).

The model flies the *true* vehicle of its :class:`VehicleParams`: commanded thrusts are clipped to
the rotor range, then each rotor's thrust and reaction torque follow its own factors and
efficiency loss, and a centre-of-gravity offset turns the total thrust into a moment (see
:class:`VehicleParams`). With an air velocity (a wind model, :mod:`quad_sim.perturbations.wind`)
the vehicle also feels the drag ``wind_drag (w_air - v)`` [N, world ENU]. With the defaults and no
air velocity the arithmetic is exactly that of eq. (1) and (2).

Each equation is written once, for one vehicle, in compiled kernels (numba; :func:`_rk4_step` and
the functions it calls): a step of one vehicle is a few hundred floating-point operations, which
the interpreter would take tens of microseconds to run. A batch runs the same kernel vehicle after
vehicle in a compiled loop (:func:`_rk4_batch`), so a vehicle of a batch and the same vehicle flown
alone get the same numbers, bit for bit.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit

from quad_msgs_bridge.mixer import controls_from_forces, saturated
from quad_msgs_bridge.rotor_layout import MIXER_SIZE
from quad_msgs_bridge.state import STATE_SIZE
from quad_msgs_bridge.vehicle_params import DISTURBANCE_CHANNELS, Disturbances, VehicleParams

#: the vehicle's constants as the kernels read them, one column each (:func:`vehicle_constants`)
CONSTANTS = ('m', 'g', 'Kfx', 'Kfy', 'Kfz', 'Kfphi', 'Kftheta', 'Kfpsi', 'Ix', 'Iy', 'Iz', 'd', 'c_x', 'c_y',
             'yaw_coefficient', 'F_min', 'F_max', 'wind_drag', 'thrust_gain_1', 'thrust_gain_2', 'thrust_gain_3',
             'thrust_gain_4', 'torque_gain_1', 'torque_gain_2', 'torque_gain_3', 'torque_gain_4',
             'Iy_minus_Iz', 'Iz_minus_Ix', 'Ix_minus_Iy') + tuple(f'mixer_{k}' for k in range(MIXER_SIZE))
(_M, _G, _KFX, _KFY, _KFZ, _KFPHI, _KFTHETA, _KFPSI, _IX, _IY, _IZ, _D, _CX, _CY, _YAW, _FMIN, _FMAX, _WIND,
 _THRUST, _, _, _, _TORQUE, _, _, _, _GYRO_PHI, _GYRO_THETA, _GYRO_PSI, _MIXER) = range(len(CONSTANTS) - MIXER_SIZE + 1)


def vehicle_constants(params: VehicleParams) -> np.ndarray:
    """The kernels' constants of ``params``: shape (1, C) for one vehicle's values, (B, C) when any value
    is a per-vehicle array of B (columns CONSTANTS; each rotor's thrust gain f_i (1 - l_i) and torque
    gain g_i (1 - l_i), the inertia differences of eq. (1)'s gyroscopic torques [kg m^2], and the rotor
    layout as the mixer reads it, ``params.mixer``: :mod:`quad_msgs_bridge.rotor_layout`)."""
    p = params
    efficiency = [1.0 - loss for loss in p.rotor_efficiency_loss]
    columns = [p.m, p.g, p.Kfx, p.Kfy, p.Kfz, p.Kfphi, p.Kftheta, p.Kfpsi, p.Ix, p.Iy, p.Iz, p.d,
               p.cog_offset[0], p.cog_offset[1], p.yaw_coefficient, p.F_min, p.F_max, p.wind_drag,
               *[f * e for f, e in zip(p.rotor_thrust_factors, efficiency)],
               *[g * e for g, e in zip(p.rotor_drag_factors, efficiency)],
               p.Iy - p.Iz, p.Iz - p.Ix, p.Ix - p.Iy, *np.moveaxis(p.mixer, -1, 0)]
    return np.ascontiguousarray(np.stack(np.broadcast_arrays(*[np.asarray(c, dtype=float) for c in columns]),
                                         axis=-1).reshape(-1, len(CONSTANTS)))


def disturbance_table(disturbances: Disturbances) -> np.ndarray:
    """The section IV disturbances as rows (bias, amplitude, omega) of A_x .. A_psi; all zero when disabled."""
    if not disturbances.enabled:
        return np.zeros((len(DISTURBANCE_CHANNELS), 3))
    channels = [getattr(disturbances, name) for name in DISTURBANCE_CHANNELS]
    return np.array([(c.bias, c.amplitude, c.omega) for c in channels], dtype=float)


@njit(cache=True, inline='always')
def _disturbance(table, t):
    """Section IV: A(t) = bias + amplitude sin(omega t) of each channel A_x .. A_psi at time t [s]."""
    return (table[0, 0] + table[0, 1] * math.sin(table[0, 2] * t),
            table[1, 0] + table[1, 1] * math.sin(table[1, 2] * t),
            table[2, 0] + table[2, 1] * math.sin(table[2, 2] * t),
            table[3, 0] + table[3, 1] * math.sin(table[3, 2] * t),
            table[4, 0] + table[4, 1] * math.sin(table[4, 2] * t),
            table[5, 0] + table[5, 1] * math.sin(table[5, 2] * t))


@njit(cache=True, inline='always')
def _controls(c, forces):
    """Virtual controls (U1 [N], U2 [N], U3 [N], U4 [N m]) the true rotors give for commanded thrusts [N].

    Each command is clipped to [F_min, F_max] (what the rotor speed controller can realise), then
    rotor i gives the thrust T_i = f_i (1 - l_i) F_i and the reaction torque g_i (1 - l_i) (Kd/Kp) F_i;
    U1..U3 are eq. (2) of the thrusts, U4 eq. (2) of the torques, in the vehicle's rotor layout (the
    mixer's columns of ``c``: :func:`quad_msgs_bridge.mixer.controls_from_forces`)."""
    f1, f2, f3, f4 = saturated(forces, c[_FMIN], c[_FMAX])
    mixer = c[_MIXER:_MIXER + MIXER_SIZE]
    u1, u2, u3, _ = controls_from_forces(f1 * c[_THRUST], f2 * c[_THRUST + 1], f3 * c[_THRUST + 2],
                                         f4 * c[_THRUST + 3], mixer)
    u4 = controls_from_forces(f1 * c[_TORQUE], f2 * c[_TORQUE + 1], f3 * c[_TORQUE + 2], f4 * c[_TORQUE + 3],
                              mixer)[3]
    return u1, u2, u3, u4


@njit(cache=True, inline='always')
def _derivative(c, s, controls, disturbance, air, windy):
    """Time derivative of the state s (12 floats) under the virtual controls U1..U4 (eq. 1).

    The friction torques are written -Kf * rate * |rate|: the paper prints -Kf * rate^2, which would
    accelerate a negative rate; the sign-preserving form is what a friction means. The roll and pitch
    torques are d U2 - c_y U1 and d U3 + c_x U1 (the centre-of-gravity offset). ``disturbance`` is
    (A_x, A_y, A_z [N, world], A_phi, A_theta, A_psi [N m]); when ``windy``, ``air`` (w_x, w_y, w_z)
    [m/s, world ENU] adds the force wind_drag (w - v) [N, world]. On the ground (z <= 0 and pushed
    down) the ground's reaction cancels every acceleration."""
    u1, u2, u3, u4 = controls
    a_x, a_y, a_z, a_phi, a_theta, a_psi = disturbance
    if windy:
        a_x = a_x + c[_WIND] * (air[0] - s[3])
        a_y = a_y + c[_WIND] * (air[1] - s[4])
        a_z = a_z + c[_WIND] * (air[2] - s[5])
    cf, sf = math.cos(s[6]), math.sin(s[6])
    ct, st = math.cos(s[7]), math.sin(s[7])
    cs, ss = math.cos(s[8]), math.sin(s[8])
    dphi, dtheta, dpsi = s[9], s[10], s[11]
    m = c[_M]
    ax = ((cf * cs * st + ss * sf) * u1 - c[_KFX] * s[3] + a_x) / m
    ay = ((cf * ss * st - cs * sf) * u1 - c[_KFY] * s[4] + a_y) / m
    az = ((cf * ct) * u1 - c[_KFZ] * s[5] + a_z) / m - c[_G]
    ddphi = (dtheta * dpsi * c[_GYRO_PHI] + c[_D] * u2 - c[_CY] * u1 - c[_KFPHI] * (dphi * abs(dphi)) + a_phi) / c[_IX]
    ddtheta = (dphi * dpsi * c[_GYRO_THETA] + c[_D] * u3 + c[_CX] * u1 - c[_KFTHETA] * (dtheta * abs(dtheta))
               + a_theta) / c[_IY]
    ddpsi = (dphi * dtheta * c[_GYRO_PSI] + u4 - c[_KFPSI] * (dpsi * abs(dpsi)) + a_psi) / c[_IZ]
    if s[2] <= 0.0 and az <= 0.0:
        ax, ay, az, ddphi, ddtheta, ddpsi = 0.0 * ax, 0.0 * ay, 0.0 * az, 0.0 * ddphi, 0.0 * ddtheta, 0.0 * ddpsi
    return (s[3], s[4], s[5], ax, ay, az, dphi, dtheta, dpsi, ddphi, ddtheta, ddpsi)


@njit(cache=True, inline='always')
def _stage(s, h, k):
    """s + h k for two 12-tuples."""
    return (s[0] + h * k[0], s[1] + h * k[1], s[2] + h * k[2], s[3] + h * k[3], s[4] + h * k[4], s[5] + h * k[5],
            s[6] + h * k[6], s[7] + h * k[7], s[8] + h * k[8], s[9] + h * k[9], s[10] + h * k[10],
            s[11] + h * k[11])


@njit(cache=True, inline='always')
def _rk4_step(c, table, t, s, forces, dt, air, windy):
    """One vehicle's state (12 floats) after one RK4 step of dt [s] from time t [s] (see QuadrotorModel.step)."""
    return _rk4_step_disturbed(c, _stage_disturbances(table, t, dt), s, forces, dt, air, windy)


@njit(cache=True, inline='always')
def _stage_disturbances(table, t, dt):
    """The disturbances (:func:`_disturbance`) at the RK4 stage times t, t + dt/2 and t + dt [s]."""
    return _disturbance(table, t), _disturbance(table, t + 0.5 * dt), _disturbance(table, t + dt)


@njit(cache=True, inline='always')
def _rk4_step_disturbed(c, disturbances, s, forces, dt, air, windy):
    """:func:`_rk4_step` with the disturbances at its stage times given (:func:`_stage_disturbances`: the same for
    every vehicle of a batch, so a batch evaluates them once per step)."""
    start, middle, end = disturbances
    controls = _controls(c, forces)
    half = 0.5 * dt
    k1 = _derivative(c, s, controls, start, air, windy)
    k2 = _derivative(c, _stage(s, half, k1), controls, middle, air, windy)
    k3 = _derivative(c, _stage(s, half, k2), controls, middle, air, windy)
    k4 = _derivative(c, _stage(s, dt, k3), controls, end, air, windy)
    sixth = dt / 6.0
    new = (s[0] + sixth * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]),
           s[1] + sixth * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]),
           s[2] + sixth * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]),
           s[3] + sixth * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]),
           s[4] + sixth * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]),
           s[5] + sixth * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]),
           s[6] + sixth * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]),
           s[7] + sixth * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]),
           s[8] + sixth * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]),
           s[9] + sixth * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]),
           s[10] + sixth * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]),
           s[11] + sixth * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]))
    if new[2] < 0.0:    # below the ground: put on it at rest (an inelastic touchdown)
        return (new[0], new[1], new[2] * 0.0, new[3] * 0.0, new[4] * 0.0, new[5] * 0.0, new[6], new[7], new[8],
                new[9] * 0.0, new[10] * 0.0, new[11] * 0.0)
    return new


@njit(cache=True)
def _step_one(c, table, t, s, forces, dt, air, windy):
    return _rk4_step(c[0], table, t, s, forces, dt, air, windy)


@njit(cache=True)
def _derivative_one(c, table, t, s, forces_or_controls, air, windy):
    return _derivative(c[0], s, forces_or_controls, _disturbance(table, t), air, windy)


@njit(cache=True)
def _controls_one(c, forces):
    return _controls(c[0], forces)


@njit(cache=True)
def _rk4_batch(c, table, t, states, forces, dt, air, windy):
    """Every vehicle of a batch one RK4 step: ``states`` 12 arrays (B,), ``forces`` 4, ``air`` 3 (when
    ``windy``); ``c`` one row of constants per vehicle, or one row shared by all. Returns 12 new arrays."""
    count = states[0].shape[0]
    shared = c.shape[0] == 1
    disturbances = _stage_disturbances(table, t, dt)
    new = np.empty((STATE_SIZE, count))
    for b in range(count):
        s = (states[0][b], states[1][b], states[2][b], states[3][b], states[4][b], states[5][b],
             states[6][b], states[7][b], states[8][b], states[9][b], states[10][b], states[11][b])
        vehicle_air = (air[0][b], air[1][b], air[2][b])
        result = _rk4_step_disturbed(c[0] if shared else c[b], disturbances, s,
                                     (forces[0][b], forces[1][b], forces[2][b], forces[3][b]), dt, vehicle_air, windy)
        for i in range(STATE_SIZE):
            new[i, b] = result[i]
    return new


class QuadrotorModel:
    """Eq. (1) with the section IV disturbances, rotor saturation and a ground plane at z = 0."""

    def __init__(self, params: VehicleParams, disturbances: Disturbances):
        self.params = params
        self.disturbances = disturbances
        self._constants = vehicle_constants(params)
        self._table = disturbance_table(disturbances)
        self._still = None

    def _still_air(self, count: int) -> tuple:
        """Three zero arrays of ``count`` elements: the air velocity a batch step is handed without wind (the
        kernel does not read it then), made once rather than at every step."""
        if self._still is None or self._still[0].shape[0] != count:
            self._still = _arrays((0.0, 0.0, 0.0), count)
        return self._still

    def with_vehicle(self, params: VehicleParams) -> 'QuadrotorModel':
        """The same model flying ``params`` from now on (a payload, a rotor loss: the simulator's vehicle changes)."""
        return QuadrotorModel(params, self.disturbances)

    def controls(self, forces: Sequence) -> tuple:
        """Virtual controls (U1 [N], U2 [N], U3 [N], U4 [N m]) the true rotors of one vehicle give for
        commanded thrusts F1..F4 [N] (clipped to the rotor range first)."""
        return _controls_one(self._constants, _floats(forces, 4))

    def derivative(self, t: float, s: Sequence, controls: Sequence, air_velocity: Sequence | None = None) -> list:
        """Time derivative of one vehicle's state at time t [s] under virtual controls U1..U4 (eq. 1),
        with the air velocity (w_x, w_y, w_z) [m/s, world ENU] if given (see :func:`_derivative`)."""
        windy = air_velocity is not None
        return list(_derivative_one(self._constants, self._table, float(t), _floats(s, STATE_SIZE),
                                    _floats(controls, 4), _floats(air_velocity if windy else (0.0,) * 3, 3), windy))

    def step(self, t: float, s: Sequence, forces: Sequence, dt: float,
             air_velocity: Sequence | None = None) -> list:
        """State after one RK4 step of dt [s] from time t [s], commanded rotor thrusts [N] held constant.

        The true rotors turn the commands into U1..U4 (:func:`_controls`). ``air_velocity``
        [m/s, world ENU], held over the step, adds the wind drag (None: no air, no such force).
        A vehicle that ends the step below the ground is put on it at rest (an inelastic touchdown).
        The disturbances are evaluated once for each of the three stage times t, t + dt/2, t + dt.
        One vehicle (12 floats) or a batch (12 arrays; forces, air velocities and the vehicle's
        parameters floats shared by all or arrays, one element per vehicle).
        """
        windy = air_velocity is not None
        if isinstance(s[0], np.ndarray):
            count = s[0].shape[0]
            air = _arrays(air_velocity, count) if windy else self._still_air(count)
            return list(_rk4_batch(self._constants, self._table, float(t), _arrays(s, count), _arrays(forces, count),
                                   float(dt), air, windy))
        return list(_step_one(self._constants, self._table, t, _floats(s, STATE_SIZE), _floats(forces, 4), dt,
                              _floats(air_velocity, 3) if windy else (0.0, 0.0, 0.0), windy))


def _floats(values: Sequence, size: int) -> tuple:
    """``size`` numbers as a tuple, the kernels' type for one vehicle (numba types a float, a numpy float
    and an int itself)."""
    if len(values) != size:
        raise ValueError(f'expected {size} values, got {len(values)}')
    return tuple(values)


def _arrays(values: Sequence, count: int) -> tuple:
    """A tuple of contiguous, writeable float arrays of ``count`` elements, one per value (a float is
    shared by every vehicle): one array type for the batch kernel, whatever the caller passes."""
    return tuple([v if type(v) is np.ndarray and v.dtype == np.float64 and v.shape == (count,)
                  and v.flags.c_contiguous and v.flags.writeable
                  else np.array(np.broadcast_to(np.asarray(v, dtype=float), (count,))) for v in values])


def check_state(state: Sequence[float]) -> list[float]:
    """A single-vehicle state as 12 finite floats, or ValueError naming the bad component."""
    if len(state) != STATE_SIZE:
        raise ValueError(f'state has {len(state)} components, expected {STATE_SIZE}')
    values = [float(v) for v in state]
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise ValueError(f'state component {i} is {v}')
    return values
