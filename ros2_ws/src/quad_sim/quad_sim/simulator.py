"""Simulated vehicles: sim time, state and the rotor thrusts they are flying with.

One :class:`Simulator` flies one vehicle (state components plain floats) or a batch of vehicles
(components numpy arrays of shape (B,), one element per vehicle), through the same code.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from quad_msgs_bridge.state import OdometrySample, odometry_from_state
from quad_msgs_bridge.timebase import nanoseconds, seconds
from quad_msgs_bridge.validation import ParameterError, check_number

from .model import QuadrotorModel, check_state
from .perturbations.actuation import MotorLag
from .perturbations.vehicle_change import VehicleChange, check_changes
from .perturbations.wind import Wind


class Simulator:
    """Steps a plant (:class:`QuadrotorModel`, or another of :mod:`quad_sim.plants`) with a fixed physics step,
    holding the last accepted thrusts.

    Sim time is kept in integer nanoseconds (``steps * physics_dt_ns``), the resolution of a ROS
    stamp, so the time in a message and the time in the core are the same number. Thrusts start
    at zero: the vehicle sits on the ground until a controller answers.

    Optional physics between the commanded thrusts and the vehicle, advanced every physics step:
    ``motor_lag`` (:class:`~quad_sim.perturbations.actuation.MotorLag`: the rotors follow the
    commands with a first-order lag) and ``wind`` (:class:`~quad_sim.perturbations.wind.Wind`: the
    air velocity the vehicle feels, through the vehicle's wind drag). ``changes``
    (:class:`~quad_sim.perturbations.vehicle_change.VehicleChange`, in time order): from each one's
    time on (the first physics step that starts at or after it) the model flies its vehicle (a
    payload picked up or dropped, a rotor losing efficiency).
    """

    def __init__(self, model: QuadrotorModel, physics_dt: float, initial_state: Sequence,
                 motor_lag: MotorLag | None = None, wind: Wind | None = None,
                 changes: Sequence[VehicleChange] = ()):
        self.model = model
        self._changes = list(check_changes(changes))
        check_number('physics_dt', physics_dt, 0.0, 0.1, low_inclusive=False)
        self.physics_dt_ns = nanoseconds(physics_dt)
        if self.physics_dt_ns < 1:
            raise ParameterError(f'physics_dt: {physics_dt} s is below one nanosecond')
        self.physics_dt = seconds(self.physics_dt_ns)
        if isinstance(initial_state[0], np.ndarray):
            self.state = [np.array(v, dtype=float) for v in initial_state]
            if not all(np.isfinite(v).all() for v in self.state):
                raise ValueError('initial state: a component is not finite')
            zero = np.zeros_like(self.state[0])
        else:
            self.state = check_state(initial_state)
            zero = 0.0
        self.steps = 0
        self.forces: tuple = (zero, zero, zero, zero)
        self.motor_lag = motor_lag
        self.wind = wind

    @property
    def time_ns(self) -> int:
        """Sim time [ns]."""
        return self.steps * self.physics_dt_ns

    @property
    def time(self) -> float:
        """Sim time [s]."""
        return seconds(self.time_ns)

    def set_forces(self, forces: Sequence[float]) -> bool:
        """Fly with rotor thrusts F1..F4 [N] from now on; refuse (keep the last) unless 4 finite values.

        For a batch each vehicle's four values are checked on their own: a vehicle with a
        non-finite command keeps its last thrusts, the others take theirs.
        """
        if len(forces) != 4:
            return False
        if isinstance(self.state[0], np.ndarray):
            valid = np.isfinite(forces[0]) & np.isfinite(forces[1]) & np.isfinite(forces[2]) & np.isfinite(forces[3])
            self.forces = tuple(np.where(valid, f, old) for f, old in zip(forces, self.forces))
            return bool(valid.all())
        f1, f2, f3, f4 = forces
        if not (math.isfinite(f1) and math.isfinite(f2) and math.isfinite(f3) and math.isfinite(f4)):
            return False
        self.forces = (float(f1), float(f2), float(f3), float(f4))
        return True

    def advance(self, steps: int = 1) -> None:
        """Integrate ``steps`` physics steps with the current thrust commands."""
        step, dt, lag, wind = self.model.step, self.physics_dt, self.motor_lag, self.wind
        for _ in range(steps):
            if self._changes and self.time >= self._changes[0].at_s:
                self.model = self.model.with_vehicle(self._changes.pop(0).vehicle)
                step = self.model.step
            thrusts = self.forces if lag is None else lag.step(self.forces)
            air = None if wind is None else wind.step()
            self.state = step(self.time, self.state, thrusts, dt, air)
            self.steps += 1

    def odometry(self) -> OdometrySample:
        """The current state of one vehicle as an odometry sample stamped with sim time."""
        return odometry_from_state(self.time, self.state)


def compile_kernels(model: QuadrotorModel, physics_dt: float) -> None:
    """Have numba build, or load from its cache, the compiled kernels a simulated vehicle runs per step (its
    RK4 step and odometry; 0.1 s from the cache, seconds the first time after an install): one throwaway
    step of a vehicle at rest on the ground. A ROS simulator node does this before it publishes, so its
    first steps are as quick as the others (a real-time simulator would otherwise run late, then catch up)."""
    simulator = Simulator(model, physics_dt, [0.0] * 12)
    simulator.advance(1)
    simulator.odometry()
