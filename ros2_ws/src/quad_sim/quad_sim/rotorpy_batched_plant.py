"""RotorPy's ``BatchedMultirotor`` (torch) as a plant: a whole campaign batch in one RotorPy step.

:class:`~quad_sim.rotorpy_plant.RotorPyPlant` steps RotorPy's ``Multirotor`` one vehicle after the other through
``scipy.integrate.solve_ivp``: about 1 s of CPU per simulated second and vehicle, so the example campaign (200
flights of 60 s per controller) costs hours per controller. RotorPy ships a batched twin of the same model,
``BatchedMultirotor``: the same rigid body, motors and aerodynamics, written by RotorPy's authors on torch
tensors with a batch dimension, integrated by ``torchdiffeq``. This plant flies it with the fixed-step
``'rk4'`` integrator at the physics step (RotorPy's own choice between ``'dopri5'`` and ``'rk4'``; dopri5 is
several times slower and 1 ms RK4 steps resolve RotorPy's 5 ms motors). bench/bench_plants.py measures both
plants; tests/test_rotorpy_batched_plant.py bounds the difference between them.

It needs torch, torchdiffeq and roma (``requirements-rotorpy-batched.txt``; RotorPy declares none of them).
The world around RotorPy's vehicles is the one :class:`RotorPyPlant` adds, with the same conversions
(:mod:`quad_msgs_bridge.rotorpy_conversion`): the section IV disturbance wrench, our ground, instant motors when
``motor_time_constant_s`` is 0, and a vehicle whose state is not finite (frozen by the closed loop) is not stepped.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from quad_msgs_bridge.rotorpy_conversion import (ROTORPY_MOTOR_TIME_CONSTANT, aero_coefficients,
                                                 motor_thrust_commands, quad_params, rotor_speeds_of,
                                                 rotor_thrust_scales, rotorpy_state, state_from_rotorpy)
from quad_msgs_bridge.state import STATE_SIZE
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams

from .rotorpy_plant import ROTORPY_VERSION, batch_vehicles, disturbance_wrench, put_on_ground

#: the torch packages RotorPy's BatchedMultirotor imports (pins: requirements-rotorpy-batched.txt)
BATCHED_REQUIREMENTS = 'requirements-rotorpy-batched.txt'


def import_batched():
    """(torch, RotorPy's BatchedMultirotor, BatchedMultirotorParams); ParameterError naming what to install."""
    try:
        import roma  # noqa: F401  (RotorPy's batched model needs it; its module swallows the ImportError)
        import torch
        import torchdiffeq  # noqa: F401
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
    except ImportError as error:
        raise ParameterError(f'plant rotorpy-batched: {error}; pip install rotorpy=={ROTORPY_VERSION} and '
                             f'pip install -r {BATCHED_REQUIREMENTS}') from error
    return torch, BatchedMultirotor, BatchedMultirotorParams


def _disturbed(batched_class, disturbances: Disturbances, torch):
    """RotorPy's batched vehicle class plus the section IV disturbance wrench (the same for every vehicle) at
    time ``start`` + t; RotorPy's own class when the disturbances are off."""
    if not disturbances.enabled:
        return batched_class
    wrench = disturbance_wrench(disturbances)

    class DisturbedBatchedMultirotor(batched_class):
        start = 0.0

        def _s_dot_fn(self, t, s, cmd_rotor_speeds, idxs):
            s_dot = super()._s_dot_fn(t, s, cmd_rotor_speeds, idxs)
            a = torch.from_numpy(wrench(self.start + float(t)))
            s_dot[:, 3:6] += a[:3] / self.params.mass[idxs]
            s_dot[:, 10:13] += (self.params.inv_inertia[idxs] @ a[3:]).to(s_dot.dtype)
            return s_dot

    return DisturbedBatchedMultirotor


class BatchedRotorPyPlant:
    """RotorPy's BatchedMultirotor flying ``params`` (the true vehicle, one or a batch) under ``disturbances``:
    ``step`` as :class:`~quad_sim.model.QuadrotorModel`'s; arguments as :class:`~quad_sim.rotorpy_plant.
    RotorPyPlant`'s. Runs on the CPU with torch's threads as torch sets them."""

    def __init__(self, params: VehicleParams, disturbances: Disturbances, *, aero: bool = True,
                 motor_time_constant_s: float = ROTORPY_MOTOR_TIME_CONSTANT, rotor_speeds: Sequence | None = None):
        if not isinstance(aero, bool):
            raise ParameterError(f'plant rotorpy-batched: aero must be true or false, got {aero!r}')
        self.motor_time_constant_s = check_number('plant rotorpy-batched: motor_time_constant_s',
                                                  motor_time_constant_s, 0.0, 1.0)
        self.aero = aero
        self.params = params
        self.disturbances = disturbances
        torch, batched_class, batched_params = import_batched()
        torch.set_num_threads(1)   # a campaign's workers are its parallelism; a batch's tensors are too small to split
        self._torch = torch
        singles = batch_vehicles(params)
        quads = [quad_params(p, aero_coefficients(p), self.motor_time_constant_s) for p in singles]
        count = len(singles)
        self._count = count
        self._scales = np.stack([rotor_thrust_scales(p) for p in singles])            # (B, 4)
        self._k_eta = np.array([q['k_eta'] for q in quads])[:, None]                   # (B, 1)
        self._speed_limits = np.array([[q['rotor_speed_min'], q['rotor_speed_max']] for q in quads])
        cpu = torch.device('cpu')
        zeros = torch.zeros(count, 3, dtype=torch.double)
        self.multirotor = _disturbed(batched_class, disturbances, torch)(
            batched_params(quads, count, cpu), count, {'x': zeros}, cpu, control_abstraction='cmd_motor_thrusts',
            aero=aero, integrator='rk4')
        self.rotor_speeds = (np.repeat(self._speed_limits[:, :1], 4, axis=1) if rotor_speeds is None
                             else np.array(rotor_speeds, dtype=float).reshape(count, 4))

    def with_vehicle(self, params: VehicleParams) -> 'BatchedRotorPyPlant':
        """The same plant flying ``params`` from now on (a payload, a rotor loss), its rotors spinning on."""
        return BatchedRotorPyPlant(params, self.disturbances, aero=self.aero,
                                   motor_time_constant_s=self.motor_time_constant_s, rotor_speeds=self.rotor_speeds)

    def step(self, t: float, s: Sequence, forces: Sequence, dt: float,
             air_velocity: Sequence | None = None) -> list:
        """State after one RotorPy step of dt [s] from time t [s], the commanded thrusts F1..F4 [N] held, in the
        air velocity [m/s, world ENU] (None: still air); one vehicle (12 floats) or a batch (12 arrays)."""
        single = not isinstance(s[0], np.ndarray)
        count = 1 if single else s[0].shape[0]
        if count != self._count:
            raise ValueError(f'plant rotorpy-batched: a batch of {count} states for {self._count} vehicles')
        states = np.array([np.broadcast_to(np.asarray(v, dtype=float), (count,)) for v in s])     # (12, B)
        commands = np.array([np.broadcast_to(np.asarray(f, dtype=float), (count,)) for f in forces]).T
        thrusts = motor_thrust_commands(commands, self.params, self._scales)                      # (B, 4) [N]
        flying = np.flatnonzero(np.all(np.isfinite(states), axis=0))
        new = states.copy()
        if flying.size:
            new[:, flying] = self._step(t, states, thrusts, dt, flying, air_velocity)
        return list(new[:, 0]) if single else list(new)

    def _step(self, t, states, thrusts, dt, flying, air_velocity):
        """The (12, n) states of the ``flying`` vehicles after RotorPy's step of the whole batch's (12, B) states and
        (B, 4) thrusts [N] (RotorPy steps the rows ``flying`` only; the others' values are not used)."""
        torch = self._torch
        if self.motor_time_constant_s == 0.0:
            self.rotor_speeds[flying] = np.clip(rotor_speeds_of(thrusts[flying], self._k_eta[flying]),
                                                self._speed_limits[flying, :1], self._speed_limits[flying, 1:])
        air = None if air_velocity is None else [np.broadcast_to(np.asarray(a, dtype=float), (self._count,))
                                                 for a in air_velocity]
        before = rotorpy_state(list(states), self.rotor_speeds, air)
        self.multirotor.start = t   # (of no use to RotorPy's own class, when the disturbances are off)
        after = self.multirotor.step({key: torch.from_numpy(value) for key, value in before.items()},
                                     {'cmd_motor_thrusts': torch.from_numpy(thrusts)}, dt, idxs=flying.tolist())
        after = {key: value.numpy()[flying] for key, value in after.items()}
        self.rotor_speeds[flying] = after['rotor_speeds']
        return np.array(put_on_ground(state_from_rotorpy(after)))
