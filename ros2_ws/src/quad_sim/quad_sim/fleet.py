"""Several vehicles on one sim clock: the simulator node's fleet, without ROS.

Each vehicle has its own :class:`~quad_sim.simulator.Simulator` (state, thrusts) of one model and
physics step; they are always stepped together, so sim time is one for all. Every vehicle flies
exactly the arithmetic it would fly alone: a vehicle of a fleet equals its solo flight to the bit.
In lockstep a step is integrated only once every vehicle's controller has answered it
(:class:`LockstepAnswers`).
"""
from __future__ import annotations

from typing import Sequence

from quad_msgs_bridge.state import STATE_SIZE, OdometrySample
from quad_msgs_bridge.validation import ParameterError

from .model import QuadrotorModel
from .simulator import Simulator


def split_initial_states(values: Sequence[float], count: int) -> list[list[float]]:
    """The ``initial_state`` parameter (12 values per vehicle, in the order of the vehicles) split per vehicle."""
    if len(values) != STATE_SIZE * count:
        raise ParameterError(f'parameter initial_state: {len(values)} values for {count} vehicle(s); expected '
                             f'{STATE_SIZE * count} ({STATE_SIZE} per vehicle, in the order of vehicles)')
    return [[float(v) for v in values[STATE_SIZE * k:STATE_SIZE * (k + 1)]] for k in range(count)]


class Fleet:
    """Vehicles of one model stepped together, each from its own initial state."""

    def __init__(self, model: QuadrotorModel, physics_dt: float, initial_states: Sequence[Sequence[float]]):
        """ValueError naming the vehicle (1-based) of an invalid initial state. Each vehicle flies its own copy of
        ``model`` (a plant of :mod:`quad_sim.plants`; RotorPy's holds each vehicle's rotor speeds)."""
        self.simulators = []
        for number, state in enumerate(initial_states, start=1):
            try:
                self.simulators.append(Simulator(model.with_vehicle(model.params), physics_dt, state))
            except ParameterError:
                raise
            except ValueError as error:
                raise ValueError(f'vehicle {number}: {error}') from error

    def __len__(self) -> int:
        return len(self.simulators)

    @property
    def time(self) -> float:
        """Sim time [s], the same for every vehicle."""
        return self.simulators[0].time

    def set_forces(self, vehicle: int, forces: Sequence[float]) -> bool:
        """Rotor thrusts [N] of one vehicle from now on; False (the last ones kept) unless 4 finite values."""
        return self.simulators[vehicle].set_forces(forces)

    def advance(self, steps: int) -> None:
        """Integrate ``steps`` physics steps, every vehicle with its current thrusts."""
        for simulator in self.simulators:
            simulator.advance(steps)

    def odometry(self) -> list[OdometrySample]:
        """Every vehicle's state as an odometry sample stamped with sim time."""
        return [simulator.odometry() for simulator in self.simulators]


class LockstepAnswers:
    """Which vehicles' controllers have answered the pending odometry, paired by vehicle."""

    def __init__(self, count: int):
        self.count = count
        self.waiting = set(range(count))

    def answer(self, vehicle: int) -> bool:
        """Note vehicle ``vehicle``'s answer; True once every vehicle has answered (and then wait for all
        again: the next step). A second answer of the same vehicle to one step counts once."""
        self.waiting.discard(vehicle)
        if self.waiting:
            return False
        self.waiting = set(range(self.count))
        return True
