"""RotorPy's ``Multirotor`` as a plant behind the interface of :class:`~quad_sim.model.QuadrotorModel`.

RotorPy (``pip install rotorpy==3.0.0``, Spencer Folk et al., University of Pennsylvania) is a
multirotor simulator nobody here wrote. Its ``Multirotor`` integrates the rigid body exactly (quaternion
attitude, body rates, Newton-Euler), first-order motors on the rotor speeds (tau_m), and, with ``aero``,
parasitic drag, rotor drag (H-force), induced inflow, translational lift and blade flapping, with the air
velocity of a wind model. Each step is ``scipy.integrate.solve_ivp`` (RK45 and its tolerances, RotorPy's
defaults, trying the whole step first) of one vehicle, in Python: 2-3 ms of wall time per physics step,
some 2000 times our compiled step (bench/bench_plants.py, docs/ROTORPY.md).

What is converted, and how, is :mod:`quad_msgs_bridge.rotorpy_conversion`; this module only drives RotorPy.
Three things are added around RotorPy's vehicle, so that the same world is flown on both plants:

* the paper's section IV disturbances: the forces (A_x, A_y, A_z) [N, world] and the moments
  (A_phi, A_theta, A_psi) [N m, taken about body x, y, z], at each instant RotorPy's integrator asks for;
* the ground of our model: a vehicle that ends a step below z = 0 is put on it at rest (RotorPy's own
  ground model is off: it holds the vehicle at z = 0 until it climbs 1 mm in one step);
* instant motors when ``motor_time_constant_s`` is 0: the rotor speeds are set to the commanded ones before
  each step (RotorPy's motor model needs tau_m > 0).
"""
from __future__ import annotations

from dataclasses import fields, replace
from typing import Sequence

import numpy as np

from quad_msgs_bridge.rotorpy_conversion import (ROTORPY_MOTOR_TIME_CONSTANT, aero_coefficients, motor_thrust_commands,
                                                 quad_params, rotor_speeds_of, rotor_thrust_scales, rotorpy_state,
                                                 state_from_rotorpy)
from quad_msgs_bridge.state import STATE_SIZE
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams

ROTORPY_VERSION = '3.0.0'   #: the pinned RotorPy (requirements-test.txt)


def import_multirotor():
    """RotorPy's ``Multirotor`` class; ParameterError naming the pip command when RotorPy is not installed."""
    try:
        from rotorpy.vehicles.multirotor import Multirotor
    except ImportError as error:
        raise ParameterError(f'plant rotorpy: RotorPy is not installed ({error}); '
                             f'pip install rotorpy=={ROTORPY_VERSION}') from error
    return Multirotor


def one_vehicle(params: VehicleParams, b: int) -> VehicleParams:
    """Vehicle b of a batch description (a value shared by all stays as it is)."""
    def pick(value):
        if isinstance(value, tuple):
            return tuple(pick(v) for v in value)
        return float(value[b]) if isinstance(value, np.ndarray) else value
    return replace(params, **{f.name: pick(getattr(params, f.name)) for f in fields(params)})


def batch_vehicles(params: VehicleParams) -> list[VehicleParams]:
    """The single vehicles of a batch description (arrays of B, see :meth:`VehicleParams.stack`): [params] for one."""
    sizes = {np.asarray(v).shape[0] for f in fields(params)
             for v in (getattr(params, f.name) if isinstance(getattr(params, f.name), tuple)
                       else (getattr(params, f.name),)) if isinstance(v, np.ndarray)}
    return [params] if not sizes else [one_vehicle(params, b) for b in range(sizes.pop())]


def disturbance_wrench(disturbances: Disturbances):
    """The section IV disturbance wrench as a function of time t [s]: (A_x, A_y, A_z) [N, world] and (A_phi,
    A_theta, A_psi) [N m, about body x, y, z], A(t) = bias + amplitude sin(omega t), one numpy expression (a
    RotorPy integrator asks for it several times per step)."""
    channels = [disturbances.A_x, disturbances.A_y, disturbances.A_z, disturbances.A_phi, disturbances.A_theta,
                disturbances.A_psi]
    bias, amplitude, omega = (np.array([getattr(c, name) for c in channels]) for name in ('bias', 'amplitude', 'omega'))
    return lambda t: bias + amplitude * np.sin(omega * t)


#: the state components a vehicle that ends a step below the ground has at rest on it: z, its velocity, the rates
_AT_REST_ON_GROUND = (2, 3, 4, 5, 9, 10, 11)


def put_on_ground(state: list) -> list:
    """Our 12-state (floats of one vehicle or arrays of a batch) with every vehicle below z = 0 put on the ground
    at rest, as our model does."""
    below = np.asarray(state[2]) < 0.0
    if not below.any():
        return state
    if below.ndim == 0:
        return [0.0 if i in _AT_REST_ON_GROUND else v for i, v in enumerate(state)]
    return [np.where(below, 0.0, v) if i in _AT_REST_ON_GROUND else v for i, v in enumerate(state)]


def _disturbed(multirotor_class, disturbances: Disturbances):
    """RotorPy's vehicle class plus the section IV disturbance wrench at time ``start`` + t (RotorPy's own class
    when the disturbances are off)."""
    if not disturbances.enabled:
        return multirotor_class
    wrench = disturbance_wrench(disturbances)

    class DisturbedMultirotor(multirotor_class):
        start = 0.0

        def _s_dot_fn(self, t, s, cmd_rotor_speeds):
            s_dot = super()._s_dot_fn(t, s, cmd_rotor_speeds)
            a = wrench(self.start + t)
            s_dot[3:6] += a[:3] / self.mass
            s_dot[10:13] += self.inv_inertia @ a[3:]
            return s_dot

    return DisturbedMultirotor


class _Vehicle:
    """One RotorPy vehicle: its ``Multirotor`` (with the section IV disturbances added) and its rotor speeds."""

    def __init__(self, params: VehicleParams, disturbances: Disturbances, aero: bool, motor_time_constant_s: float,
                 rotor_speeds: np.ndarray | None = None):
        self.params = params
        self.thrust_scales = rotor_thrust_scales(params)
        self.instant_motors = motor_time_constant_s == 0.0
        self.quad = quad_params(params, aero_coefficients(params), motor_time_constant_s)
        self.multirotor = _disturbed(import_multirotor(), disturbances)(
            self.quad, control_abstraction='cmd_motor_thrusts', aero=aero, enable_ground=False)
        self.rotor_speeds = (np.full(4, self.quad['rotor_speed_min']) if rotor_speeds is None
                             else np.array(rotor_speeds, dtype=float))

    def step(self, t: float, s: Sequence[float], forces: Sequence[float], dt: float,
             air_velocity: Sequence[float] | None) -> list[float]:
        thrusts = motor_thrust_commands(forces, self.params, self.thrust_scales)
        if self.instant_motors:
            self.rotor_speeds = np.clip(rotor_speeds_of(thrusts, self.quad['k_eta']), self.quad['rotor_speed_min'],
                                        self.quad['rotor_speed_max'])
        self.multirotor.start = t   # (an attribute of no use to RotorPy's own class, when the disturbances are off)
        # RotorPy's integrator (RK45, its tolerances) trying the whole step first: solve_ivp's own first guess
        # is tiny near an equilibrium (hover: 6 steps, 38 evaluations per 1 ms step instead of 1 step, 6)
        self.multirotor.integrator_kwargs = {'method': 'RK45', 'first_step': dt}
        after = self.multirotor.step(rotorpy_state(s, self.rotor_speeds, air_velocity),
                                     {'cmd_motor_thrusts': thrusts}, dt)
        self.rotor_speeds = after['rotor_speeds']
        return put_on_ground(state_from_rotorpy(after))


class RotorPyPlant:
    """RotorPy flying ``params`` (the true vehicle) under ``disturbances``: ``step`` as QuadrotorModel's.

    ``aero``: RotorPy's aerodynamic effects on (coefficients: :func:`~quad_msgs_bridge.rotorpy_conversion.
    aero_coefficients`). ``motor_time_constant_s`` [s]: RotorPy's motor model (first-order rotor speeds,
    tau_m; default that of RotorPy's hummingbird), 0 for motors that follow the command at once.
    A batch description (arrays of B, see :meth:`VehicleParams.stack`) gets one RotorPy vehicle per element,
    stepped one after the other. The rotor speeds are the plant's own state (they start at the slowest).
    """

    def __init__(self, params: VehicleParams, disturbances: Disturbances, *, aero: bool = True,
                 motor_time_constant_s: float = ROTORPY_MOTOR_TIME_CONSTANT, rotor_speeds: Sequence | None = None):
        if not isinstance(aero, bool):
            raise ParameterError(f'plant rotorpy: aero must be true or false, got {aero!r}')
        self.motor_time_constant_s = check_number('plant rotorpy: motor_time_constant_s', motor_time_constant_s, 0.0,
                                                  1.0)
        self.aero = aero
        self.params = params
        self.disturbances = disturbances
        singles = batch_vehicles(params)
        speeds = [None] * len(singles) if rotor_speeds is None else rotor_speeds
        self._vehicles = [_Vehicle(p, disturbances, aero, self.motor_time_constant_s, r)
                          for p, r in zip(singles, speeds)]

    @property
    def rotor_speeds(self) -> list[np.ndarray]:
        """Each vehicle's rotor speeds w1..w4 [rad/s]."""
        return [v.rotor_speeds for v in self._vehicles]

    def with_vehicle(self, params: VehicleParams) -> 'RotorPyPlant':
        """The same plant flying ``params`` from now on (a payload, a rotor loss), its rotors spinning on."""
        return RotorPyPlant(params, self.disturbances, aero=self.aero, motor_time_constant_s=self.motor_time_constant_s,
                            rotor_speeds=self.rotor_speeds)

    def step(self, t: float, s: Sequence, forces: Sequence, dt: float,
             air_velocity: Sequence | None = None) -> list:
        """State after RotorPy's step of dt [s] from time t [s] with the commanded thrusts F1..F4 [N] held and the
        air velocity [m/s, world ENU] (None: still air); one vehicle (12 floats) or a batch (12 arrays)."""
        if not isinstance(s[0], np.ndarray):
            return self._vehicles[0].step(t, s, forces, dt, air_velocity)
        count = s[0].shape[0]
        if count != len(self._vehicles):
            raise ValueError(f'plant rotorpy: a batch of {count} states for {len(self._vehicles)} vehicles')
        columns = [np.broadcast_to(np.asarray(v, dtype=float), (count,)) for v in (*s, *forces)]
        air = None if air_velocity is None else [np.broadcast_to(np.asarray(a, dtype=float), (count,))
                                                 for a in air_velocity]
        new = np.empty((STATE_SIZE, count))
        for b, vehicle in enumerate(self._vehicles):
            state = [c[b] for c in columns[:STATE_SIZE]]
            if not np.all(np.isfinite(state)):   # a vehicle a campaign has frozen after a failure
                new[:, b] = state
                continue
            try:
                new[:, b] = vehicle.step(t, state, [c[b] for c in columns[STATE_SIZE:]], dt,
                                         None if air is None else [a[b] for a in air])
            except ValueError:   # tumbled to gimbal lock: not finite, so the closed loop fails this vehicle alone
                new[:, b] = np.nan
        return list(new)
