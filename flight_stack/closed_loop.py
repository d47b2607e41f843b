"""The closed loop of one vehicle or of a batch: measure, control, actuate, integrate, check.

Per control step, in this order (the order of the ROS lockstep flight):

1. the simulator's true state at sim time t is measured: :class:`SensorNoise` adds noise and bias
   (if any), then ``observe`` turns the measurement into what the controller node receives (the
   embedded single flight passes it through an odometry message and back, as the ROS flight does),
   and the measurement stage (:class:`MeasurementStage`, the same for every controller kind, as in
   the ROS controller node) filters it into what the controller reads;
2. the controller answers it with the reference for the same instant t;
3. the forces go through the transport delay (if any) to the simulator, which integrates until
   the next control step (motor lag and wind act at every physics step, inside the simulator);
4. the new true state is checked: a vehicle that went non-finite, flipped over, crashed, left the
   tracking tube (:class:`FailureRules`) or the arena is failed and frozen where it was.

A measurement that is not finite although the true state is (a diverging vehicle whose huge
velocity overflows in the odometry conversion) fails that vehicle as non-finite before the
controller reads it; the controller then reads zeros in its place, so one vehicle never stops a
batch.

The same code steps one vehicle (every value a float) and a batch (arrays of shape (B,)): a
failed vehicle of a batch is frozen and never poisons the others; a single vehicle's flight ends.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple, Sequence

import numpy as np
from numba import njit

from nnit2fsmc_controller.controller import CascadedController, ControlOutput
from nnit2fsmc_controller.estimation import MeasurementStage
from quad_msgs_bridge.numeric import namespace_for, select
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.review.metrics import StatisticsAccumulator
from quad_msgs_bridge.state import PHI, PSI, THETA, Z
from quad_sim.perturbations.actuation import TransportDelay
from quad_sim.perturbations.sensor_noise import SensorNoise
from quad_sim.simulator import Simulator

#: failure codes, in the order they are checked (the first that applies is reported)
FAILURES = ('non-finite state', 'flipped over', 'crashed', 'position error above max_error', 'left the arena')


#: [m] a vehicle farther than this from its reference has left the arena, at any time (also while
#: settling, when max_error does not apply yet): it is diverging
ARENA_RADIUS = 100.0


#: [m] height above which a vehicle counts as airborne: once it was, touching the ground is a crash
AIRBORNE_HEIGHT = 0.05


@dataclass(frozen=True)
class FailureRules:
    """When a flight has failed: non-finite state, flipped over (thrust axis pointing down:
    cos(phi) cos(theta) <= 0), crashed (back on the ground, z <= 0, after having been above
    AIRBORNE_HEIGHT: a vehicle waiting on the ground to take off has not crashed), and, after
    ``settle_time`` [s], a position error above ``max_error`` [m]."""

    settle_time: float
    max_error: float


@njit(cache=True, error_model='numpy')
def failure_code(state, x_ref, y_ref, z_ref, airborne, tracking, max_error):
    """(the code of the first FAILURES rule the 12-state ``state`` breaks, -1 if none; whether the vehicle has
    been airborne) of one vehicle (floats) or per vehicle of a batch (arrays). ``tracking``: whether the
    position error to the reference (x_ref, y_ref, z_ref) [m] may exceed ``max_error`` [m] no more (after
    settling); ``airborne``: whether the vehicle had been above AIRBORNE_HEIGHT before (FailureRules)."""
    finite = np.isfinite(state[0])
    for i in range(1, 12):
        finite = finite & np.isfinite(state[i])
    code = select(finite, -1, 0)
    phi, theta = select(finite, state[PHI], 0.0), select(finite, state[THETA], 0.0)
    height = select(finite, state[Z], 0.0)
    code = select((code < 0) & (np.cos(phi) * np.cos(theta) <= 0.0), 1, code)
    code = select((code < 0) & airborne & (height <= 0.0), 2, code)
    x, y, z = state[0], state[1], state[2]
    error = np.sqrt((x - x_ref) * (x - x_ref) + (y - y_ref) * (y - y_ref) + (z - z_ref) * (z - z_ref))
    if tracking:
        code = select((code < 0) & (error > max_error), 3, code)
    code = select((code < 0) & (error > ARENA_RADIUS), 4, code)
    return code, airborne | (height > AIRBORNE_HEIGHT)


class LoopStep(NamedTuple):
    """What one control step did (floats for one vehicle, arrays for a batch)."""

    time: float                      #: [s] sim time of the measurement
    truth: list                      #: true 12-state at that time
    measured: list                   #: the measured 12-state (the odometry's), before the measurement stage
    seen: list                       #: the 12-state the controller read (after the measurement stage)
    observation: object              #: what ``observe`` returned beside the state (an odometry sample, or None)
    reference: ReferenceSample       #: the reference the controller answered
    output: ControlOutput            #: the controller's answer
    applied: tuple                   #: the commanded thrusts [N] sent to the simulator (after the delay)


def shifted(reference: ReferenceSample, offset: Sequence) -> ReferenceSample:
    """``reference`` moved by ``offset`` [m, world ENU] (floats, or per-vehicle arrays)."""
    return reference._replace(position=tuple(p + o for p, o in zip(reference.position, offset)))


class ClosedLoop:
    """Steps ``controller`` and ``simulator`` together, one control step per :meth:`step`.

    ``reference(t)`` gives the reference at sim time t [s]; ``observe(t, state)`` returns
    (state the controller reads, observation) for a measured state (default: the state itself).
    ``measurement``: the measurement stage every controller kind reads through
    (``factory.build_measurement_stage(gains)``; None: the measurement as it is).
    ``substeps`` physics steps are integrated per control step. With ``statistics`` the loop sums
    each vehicle's tracking statistics as it goes (:attr:`statistics`; a batch keeps no record).
    """

    def __init__(self, controller: CascadedController, simulator: Simulator,
                 reference: Callable[[float], ReferenceSample], substeps: int, rules: FailureRules,
                 sensor_noise: SensorNoise | None = None, delay: TransportDelay | None = None,
                 observe: Callable | None = None, statistics: bool = False,
                 measurement: MeasurementStage | None = None):
        self.controller = controller
        self.measurement = measurement
        self.simulator = simulator
        self.reference = reference
        self.substeps = substeps
        self.rules = rules
        self.sensor_noise = sensor_noise
        self.delay = delay
        self.observe = observe
        params = controller.params
        self.statistics = StatisticsAccumulator(rules.settle_time, params.F_min, params.F_max) if statistics else None
        batch = isinstance(simulator.state[0], np.ndarray)
        shape = simulator.state[0].shape if batch else ()
        #: a batch's diverging vehicle may overflow before it is frozen; plain floats never warn
        self._quiet = (lambda: np.errstate(over='ignore', invalid='ignore')) if batch else None
        #: failure code per vehicle: -1 while flying, else an index into FAILURES
        self.failure = np.full(shape, -1) if batch else -1
        #: [s] sim time at which each vehicle failed (nan while flying)
        self.failure_time = np.full(shape, np.nan) if batch else float('nan')
        #: whether each vehicle has been above AIRBORNE_HEIGHT
        self.airborne = np.zeros(shape, dtype=bool) if batch else False

    @property
    def flying(self):
        """Which vehicles still fly (a bool, or a bool array for a batch)."""
        return self.failure < 0

    def step(self) -> LoopStep:
        """One control step (see the module docstring)."""
        sim = self.simulator
        t = sim.time
        truth = sim.state
        measured = truth if self.sensor_noise is None else self.sensor_noise.measure(truth)
        if self.observe is None:
            received, observation = measured, None
        elif self._quiet is None:
            received, observation = self.observe(t, measured)
        else:
            with self._quiet():
                received, observation = self.observe(t, measured)
        xp = namespace_for(received[0])
        if not xp.all_finite(received):
            unreadable = xp.where(xp.finite_each(received), False, True)
            self._fail(unreadable, 0, t)
            received = [xp.where(unreadable, 0.0, value) for value in received]
        seen = received if self.measurement is None else self.measurement(received)
        reference = self.reference(t)
        out = self.controller.update(t, seen, reference)
        applied = out.forces if self.delay is None else self.delay(out.forces)
        sim.set_forces(applied)
        if self.statistics is not None:
            self.statistics.add(t, truth[:3], truth[PSI], reference.position, reference.yaw, out.forces,
                                out.controls, self.flying)
        sim.advance(self.substeps)
        self._check(sim.time, truth, reference)
        return LoopStep(t, truth, received, seen, observation, reference, out, applied)

    def _fail(self, which, code, t: float) -> None:
        """Fail the vehicles ``which`` (a bool or bool array) that still fly, with failure ``code`` at t [s]."""
        xp = namespace_for(self.failure)
        new = (self.failure < 0) & which
        if xp.any(new):
            self.failure = xp.where(new, code, self.failure)
            self.failure_time = xp.where(new, t, self.failure_time)

    def _check(self, t: float, previous: list, reference: ReferenceSample) -> None:
        """Fail the vehicles that broke a rule at sim time t [s]; a failed vehicle stays where it was."""
        state = self.simulator.state
        x_ref, y_ref, z_ref = reference.position
        code, self.airborne = failure_code(tuple(state), x_ref, y_ref, z_ref, self.airborne,
                                           t >= self.rules.settle_time, self.rules.max_error)
        xp = namespace_for(code)
        self._fail(code >= 0, code, t)
        frozen = self.failure >= 0
        if xp.any(frozen):
            self.simulator.state = [xp.where(frozen, old, value) for old, value in zip(previous, state)]
