"""Our vehicle, state and rotor thrusts <-> RotorPy's ``Multirotor`` (``rotorpy.vehicles.multirotor``).

Pure functions, no RotorPy import: the plants (:mod:`quad_sim.rotorpy_plant`, :mod:`quad_sim.rotorpy_batched_plant`)
are the only modules that import RotorPy, and everything they convert goes through here, once.

Frames and units on both sides:

=================  ===========================================  ==============================================
quantity           our core state (:mod:`quad_msgs_bridge.state`)  RotorPy's state dict
=================  ===========================================  ==============================================
position           x, y, z [m, world ENU]                        ``x`` (3,) [m, world, z up]
velocity           vx, vy, vz [m/s, world ENU]                   ``v`` (3,) [m/s, world]
attitude           phi, theta, psi [rad], Z-Y-X Euler angles     ``q`` (4,) unit quaternion (i, j, k, w),
                                                                 scalar last, body -> world
angular velocity   dphi, dtheta, dpsi [rad/s], *Euler rates*     ``w`` (3,) body rates p, q, r [rad/s, body FLU]
air                (the wind model's velocity, not in the state)  ``wind`` (3,) air velocity [m/s, world]
rotors             (our thrusts are held commands, no state)     ``rotor_speeds`` (4,) [rad/s]
=================  ===========================================  ==============================================

The Euler rates <-> body rates conversion is the exact one of :mod:`quad_msgs_bridge.frames`, not the
small-angle shortcut. Both worlds have z up and a body frame x forward, y left, z up (FLU), so
positions, velocities and vectors pass unchanged.

Rotor thrusts: our ``rotor_forces`` F1..F4 [N] (order and layout: :mod:`quad_msgs_bridge.mixer`) are
RotorPy's ``cmd_motor_thrusts`` [N], in the same order (RotorPy's rotors r1..r4 are ours, at the
positions :func:`rotor_layout` gives). RotorPy turns a thrust into a rotor speed through its thrust
coefficient k_eta = Kp [N/(rad/s)^2] (T = k_eta w^2) and the reaction torque is k_m w^2 with
k_m = Kd [N m/(rad/s)^2], so k_m / k_eta = Kd / Kp, the yaw coefficient of eq. (2).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from quad_msgs_bridge.frames import (_body_rates, _euler, _euler_rates, _quaternion, check_orientation, check_pitch,
                                     kernel_numbers)
from quad_msgs_bridge.state import STATE_SIZE
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams

#: RotorPy's aerodynamic coefficients of its packaged "hummingbird" vehicle (rotorpy 3.0.0,
#: ``rotorpy/vehicles/hummingbird_params.py``: an AscTec Hummingbird, 0.5 kg), from which
#: :func:`aero_coefficients` scales a vehicle's own. Units as RotorPy states them.
HUMMINGBIRD = {'mass': 0.5, 'k_eta': 5.57e-06, 'g': 9.81,
               'c_Dx': 0.5e-2, 'c_Dy': 0.5e-2, 'c_Dz': 1e-2,   # parasitic drag [N/(m/s)^2]
               'k_d': 1.19e-04, 'k_z': 2.32e-04,                # rotor drag, induced inflow [N/(rad/s * m/s)]
               'k_h': 3.39e-3,                                  # translational lift [N/(m/s)^2]
               'k_flap': 0.0}                                   # blade flapping [N m/(rad/s * m/s)]

#: RotorPy's motor time constant of the same vehicle [s]: the default of the RotorPy plant's motor model.
ROTORPY_MOTOR_TIME_CONSTANT = 0.005


def hover_rotor_speed(mass: float, g: float, k_eta: float) -> float:
    """Rotor speed [rad/s] at which four rotors of thrust coefficient k_eta [N/(rad/s)^2] carry mass [kg]."""
    return math.sqrt(mass * g / (4.0 * k_eta))


def aero_coefficients(params: VehicleParams) -> dict:
    """RotorPy's aerodynamic coefficients for ``params``: the hummingbird's, scaled so that each effect gives
    the same *acceleration* at the same airspeed (and, for the rotor terms, at hover rotor speed).

    Rule (m mass [kg], w_h hover rotor speed [rad/s], hb the hummingbird): parasitic drag
    D = -|v| c_D v and translational lift k_h v^2 per rotor scale with the mass, c_D = c_D,hb m / m_hb,
    k_h = k_h,hb m / m_hb; rotor drag and induced inflow H = -w k_d v per rotor scale with the mass over the
    hover speed, k_d = k_d,hb (m / m_hb) (w_h,hb / w_h), the same for k_z; the flapping moment is zero, as in
    the hummingbird. Our vehicle files carry no measured RotorPy coefficients, so this is a stand-in
    of the right size, not an identification."""
    hb = HUMMINGBIRD
    mass_ratio = params.m / hb['mass']
    speed_ratio = (hover_rotor_speed(hb['mass'], hb['g'], hb['k_eta'])
                   / hover_rotor_speed(params.m, params.g, params.Kp))
    return {'c_Dx': hb['c_Dx'] * mass_ratio, 'c_Dy': hb['c_Dy'] * mass_ratio, 'c_Dz': hb['c_Dz'] * mass_ratio,
            'k_d': hb['k_d'] * mass_ratio * speed_ratio, 'k_z': hb['k_z'] * mass_ratio * speed_ratio,
            'k_h': hb['k_h'] * mass_ratio, 'k_flap': hb['k_flap']}


def rotor_layout(params: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """(positions (4, 3) [m, body FLU] of rotors F1..F4 about the *centre of gravity*, RotorPy's rotor_directions (4,)).

    The vehicle's layout (:mod:`quad_msgs_bridge.rotor_layout`: ``rotor_positions`` from the geometric centre,
    ``rotor_directions`` +1 counter-clockwise seen from above). RotorPy's rotor_directions is the sign of a
    rotor's reaction torque about body +z, which turns the body against the rotor: a counter-clockwise rotor is
    -1. RotorPy takes positions about the centre of mass, so a centre-of-gravity offset c is subtracted: that is
    how our model's extra moments (-c_y U1 roll, c_x U1 pitch) arise in RotorPy.
    """
    positions = np.array(params.rotor_positions, dtype=float) - np.array(params.cog_offset, dtype=float)
    return positions, -np.array(params.rotor_directions, dtype=float)


def check_representable(params: VehicleParams) -> None:
    """ParameterError unless RotorPy can fly ``params`` as our model does: one thrust and one torque
    coefficient shared by every rotor, so per-rotor thrust and drag factors must be equal (a rotor's
    efficiency loss then scales its command, see :func:`motor_thrust_commands`)."""
    for name in ('m', 'Ix', 'Kp', 'F_max'):
        if isinstance(getattr(params, name), np.ndarray):
            raise ParameterError(f'plant rotorpy: one vehicle at a time, got an array for {name}')
    if any(abs(f - g) > 1e-12 for f, g in zip(params.rotor_thrust_factors, params.rotor_drag_factors)):
        raise ParameterError(f'plant rotorpy: rotor_thrust_factors {tuple(params.rotor_thrust_factors)} must equal '
                             f'rotor_drag_factors {tuple(params.rotor_drag_factors)} (RotorPy has one k_m/k_eta '
                             'for every rotor)')


def quad_params(params: VehicleParams, aero: dict, motor_time_constant_s: float) -> dict:
    """RotorPy's ``quad_params`` dict of our vehicle (SI units as in the vehicle file).

    mass, Ixx, Iyy, Izz [kg m^2] (no products of inertia), rotor_pos and rotor_directions of
    :func:`rotor_layout`, k_eta = Kp, k_m = Kd, rotor speeds [rad/s] from F_min, F_max [N] through k_eta,
    tau_m = ``motor_time_constant_s`` [s] (RotorPy divides by it: 0 becomes a placeholder the plant never
    integrates, see :class:`quad_sim.rotorpy_plant.RotorPyPlant`), the aerodynamic coefficients ``aero``
    (:func:`aero_coefficients`; they act only when the plant's aero is on). Our translational drag
    Kfx..Kfz and rotational friction Kfphi..Kfpsi have no counterpart in RotorPy and are not used.
    """
    check_representable(params)
    positions, signs = rotor_layout(params)
    return {'mass': params.m, 'Ixx': params.Ix, 'Iyy': params.Iy, 'Izz': params.Iz, 'Ixy': 0.0, 'Ixz': 0.0,
            'Iyz': 0.0, 'num_rotors': 4,
            'rotor_pos': {f'r{i + 1}': positions[i] for i in range(4)}, 'rotor_directions': signs,
            'k_eta': params.Kp, 'k_m': params.Kd,
            'rotor_speed_min': math.sqrt(params.F_min / params.Kp),
            'rotor_speed_max': math.sqrt(params.F_max / params.Kp),
            'tau_m': motor_time_constant_s if motor_time_constant_s > 0.0 else 1.0, 'motor_noise_std': 0.0,
            **aero}


def rotor_thrust_scales(params: VehicleParams) -> np.ndarray:
    """Each rotor's thrust per unit of command (4,): its thrust factor times its efficiency, f_i (1 - l_i)."""
    return np.array(params.rotor_thrust_factors, dtype=float) * (1.0 - np.array(params.rotor_efficiency_loss,
                                                                                 dtype=float))


def motor_thrust_commands(forces, params: VehicleParams, scales: np.ndarray | None = None) -> np.ndarray:
    """RotorPy's ``cmd_motor_thrusts`` [N] for our commanded rotor thrusts F1..F4 [N]: (4,) for one vehicle, (B, 4)
    for the (B, 4) commands of a batch description (F_min, F_max floats or arrays of B).

    Each command is clipped to [F_min, F_max] (as our model does), then scaled by the rotor's thrust
    factor and efficiency (f_i (1 - l_i)): a weaker rotor gives less thrust and reaction torque for the
    same command, as in our model. ``scales``: :func:`rotor_thrust_scales` of ``params`` ((B, 4) for a batch),
    when the caller keeps it (the plants do, once per vehicle)."""
    low, high = (np.asarray(limit, dtype=float)[..., None] for limit in (params.F_min, params.F_max))
    clipped = np.clip(np.asarray(forces, dtype=float), low, high)
    return clipped * (rotor_thrust_scales(params) if scales is None else scales)


def rotor_speeds_of(thrusts: np.ndarray, k_eta: float) -> np.ndarray:
    """Rotor speeds [rad/s] that give ``thrusts`` [N] (T = k_eta w^2; a negative thrust gives speed 0)."""
    return np.sqrt(np.maximum(thrusts, 0.0) / k_eta)


def rotorpy_state(state: Sequence, rotor_speeds: np.ndarray, air_velocity: Sequence | None) -> dict:
    """RotorPy's state dict of our 12-state ``state``, the rotor speeds [rad/s] and the air velocity [m/s, world ENU]
    (None: still air). One vehicle (12 floats: vectors of shape (3,), (4,)) or a batch (12 arrays of B, rotor
    speeds (B, 4), an air velocity of 3 floats or arrays of B: vectors of shape (B, 3), (B, 4), as RotorPy's
    ``BatchedMultirotor`` takes them)."""
    if len(state) != STATE_SIZE:
        raise ValueError(f'state has {len(state)} components, expected {STATE_SIZE}')
    x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = kernel_numbers(*state)
    position = np.stack([x, y, z], axis=-1)
    wind = (np.zeros_like(position) if air_velocity is None
            else np.stack([np.broadcast_to(np.asarray(a, dtype=float), np.shape(x)) for a in air_velocity], axis=-1))
    return {'x': position, 'v': np.stack([vx, vy, vz], axis=-1),
            'q': np.stack(_quaternion(phi, theta, psi), axis=-1),
            'w': np.stack(_body_rates(phi, theta, dphi, dtheta, dpsi), axis=-1),
            'wind': wind, 'rotor_speeds': np.array(rotor_speeds, dtype=float)}


def state_from_rotorpy(rotorpy: dict) -> list:
    """Our 12-state of RotorPy's state dict: 12 floats of one vehicle (ValueError if its quaternion is no rotation
    or at gimbal lock), or 12 arrays of a batch's (B, ...) vectors (NaN for a vehicle there)."""
    qx, qy, qz, qw = kernel_numbers(*np.asarray(rotorpy['q'], dtype=float).T)
    phi, theta, psi, norm = _euler(qx, qy, qz, qw)
    check_orientation((qx, qy, qz, qw), norm)
    p, q, r = kernel_numbers(*np.asarray(rotorpy['w'], dtype=float).T)
    dphi, dtheta, dpsi, cos_theta = _euler_rates(phi, theta, p, q, r)
    check_pitch(theta, cos_theta)
    return [*kernel_numbers(*np.asarray(rotorpy['x'], dtype=float).T),
            *kernel_numbers(*np.asarray(rotorpy['v'], dtype=float).T), phi, theta, psi, dphi, dtheta, dpsi]
