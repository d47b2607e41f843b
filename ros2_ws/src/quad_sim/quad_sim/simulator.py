"""A single simulated vehicle: sim time, state and the rotor thrusts it is flying with."""
from __future__ import annotations

import math
from typing import Sequence

from quad_msgs_bridge.state import OdometrySample, odometry_from_state
from quad_msgs_bridge.timebase import nanoseconds, seconds
from quad_msgs_bridge.vehicle_params import ParameterError, check_number

from .model import QuadrotorModel, check_state


class Simulator:
    """Steps :class:`QuadrotorModel` with a fixed physics step, holding the last accepted thrusts.

    Sim time is kept in integer nanoseconds (``steps * physics_dt_ns``), the resolution of a ROS
    stamp, so the time in a message and the time in the core are the same number. Thrusts start
    at zero: the vehicle sits on the ground until a controller answers.
    """

    def __init__(self, model: QuadrotorModel, physics_dt: float, initial_state: Sequence[float]):
        self.model = model
        check_number('physics_dt', physics_dt, 0.0, 0.1, low_inclusive=False)
        self.physics_dt_ns = nanoseconds(physics_dt)
        if self.physics_dt_ns < 1:
            raise ParameterError(f'physics_dt: {physics_dt} s is below one nanosecond')
        self.physics_dt = seconds(self.physics_dt_ns)
        self.state = check_state(initial_state)
        self.steps = 0
        self.forces: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    @property
    def time_ns(self) -> int:
        """Sim time [ns]."""
        return self.steps * self.physics_dt_ns

    @property
    def time(self) -> float:
        """Sim time [s]."""
        return seconds(self.time_ns)

    def set_forces(self, forces: Sequence[float]) -> bool:
        """Fly with rotor thrusts F1..F4 [N] from now on; refuse (keep the last) unless 4 finite values."""
        if len(forces) != 4 or not all(map(math.isfinite, forces)):
            return False
        self.forces = tuple(float(f) for f in forces)
        return True

    def advance(self, steps: int = 1) -> None:
        """Integrate ``steps`` physics steps with the current thrusts."""
        step, dt = self.model.step, self.physics_dt
        for _ in range(steps):
            self.state = step(self.time, self.state, self.forces, dt)
            self.steps += 1

    def odometry(self) -> OdometrySample:
        """The current state as an odometry sample stamped with sim time."""
        return odometry_from_state(self.time, self.state)
