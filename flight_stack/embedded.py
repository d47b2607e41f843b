"""Embedded backend: trajectory -> controller -> simulator in lockstep, in one process.

Per control step it performs the calls the ROS lockstep flight performs, in the same order: the
simulator's state becomes an odometry sample stamped with sim time, the controller turns it back
into a state and answers it with the reference for that same instant, the simulator takes the
thrusts and integrates until the next odometry. The stepping itself is the closed loop of
:mod:`flight_stack.closed_loop`, the one a campaign batch runs; with ``perturbations`` the flight
flies a perturbed true vehicle with sensor noise, delay, motor lag and wind.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from quad_msgs_bridge.conversions import rosbags_kit, setpoints_from_msg, setpoints_msg
from quad_msgs_bridge.bag.flight_bag import FAILURE_KEY, FAILURE_TIME_KEY, FlightBag
from quad_msgs_bridge.review.flight_data import Flight, FlightLog
from quad_msgs_bridge.review.metrics import FlightRecord
from quad_msgs_bridge.reference import ReferenceSample, SetpointPath
from quad_msgs_bridge.runtime import freeze_long_lived_objects
from quad_msgs_bridge.state import OdometrySample, odometry_from_state, state_from_odometry
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams
from quad_sim.plants import DEFAULT_PLANT, make_plant
from quad_sim.simulator import Simulator
from quad_sim.world import Perturbations
from nnit2fsmc_controller.factory import build_controller, build_measurement_stage

from .closed_loop import FAILURES, ClosedLoop, FailureRules
from .interrupts import deferred


@dataclass
class FlightResult:
    flight: Flight                     #: the flight's time series (bounded in memory: see flight_data)
    wall_time_s: float
    steps: int
    failure: str | None = None         #: None, or why the flight ended early (one of closed_loop.FAILURES)
    failure_time_s: float | None = None

    @property
    def record(self) -> FlightRecord:
        return self.flight.record


def published_path(trajectory, setpoint_rate: float) -> SetpointPath:
    """The setpoint path the trajectory node would publish (the whole path at once: see :class:`SetpointStream`
    for a flight of any length)."""
    return SetpointPath.sampled(trajectory, 0.0, trajectory.duration, setpoint_rate)


def setpoint_path(path: SetpointPath, origin: float | None = None) -> SetpointPath:
    """``path`` as the controller reads it back from the setpoints message (stamped at ``origin`` [s],
    default: the path's start)."""
    return setpoints_from_msg(setpoints_msg(rosbags_kit(), path, origin=origin))


SETPOINT_WINDOW = 10.0    #: [s] of the path one setpoints message of a :class:`SetpointStream` covers


class SetpointStream:
    """The setpoints of ``trajectory`` over [0, ``duration``] [s], sampled as the flight goes.

    The whole path is ``SetpointPath.sampled(trajectory, 0, duration, rate)``: a sample every 1/rate
    [s] and one at the end. The stream holds one window of it at a time: ``window`` [s] of samples
    (neighbouring windows share their boundary sample), made when the flight reaches it and read
    back from a setpoints message stamped at the path's start, so every sample time is the one of
    the whole path to the bit and :meth:`sample` gives the reference the whole path gives, at any
    time. ``on_window(path)`` gets each window as it is made (what the trajectory node publishes
    then). Memory holds one window, however long the flight.
    """

    def __init__(self, trajectory, duration: float, rate: float, window: float = SETPOINT_WINDOW,
                 on_window: Callable[[SetpointPath], None] = lambda path: None):
        self.trajectory, self.duration, self.rate = trajectory, float(duration), float(rate)
        count = max(1, int(math.floor(self.duration * self.rate + 1e-9))) + 1   # as SetpointPath.sampled
        self._last = count if self.duration - (count - 1) / self.rate > 1e-9 else count - 1   #: the end sample
        self._per_window = max(1, round(window * self.rate))
        self._windows = -(-self._last // self._per_window)
        self._on_window = on_window
        self._index, self._path = -1, None

    def _offset(self, k: int) -> float:
        """Time [s] of sample k of the whole path."""
        return self.duration if k == self._last else k / self.rate

    def _window_of(self, t: float) -> int:
        j = min(self._windows - 1, max(0, int(t * self.rate) // self._per_window))
        while j > 0 and t < self._offset(j * self._per_window):
            j -= 1
        while j < self._windows - 1 and t >= self._offset((j + 1) * self._per_window):
            j += 1
        return j

    def sample(self, t: float) -> ReferenceSample:
        """The reference at sim time t [s] (as the controller reads it from the setpoints)."""
        if self._path is None or not (self._index == 0 or t >= self._path.start) \
                or (self._index < self._windows - 1 and t >= self._path.end):
            self._move_to(self._window_of(t))
        return self._path.sample(t)

    def _move_to(self, j: int) -> None:
        first, last = j * self._per_window, min((j + 1) * self._per_window, self._last)
        offsets = [self._offset(k) for k in range(first, last + 1)]
        window = SetpointPath(offsets, [self.trajectory.sample(t) for t in offsets])
        self._index, self._path = j, setpoint_path(window, origin=0.0)
        self._on_window(window)


def flown_custom_data(controller_kind: str, failure: str | None, failure_time: float | None) -> dict:
    """What a flight just flown knows of itself, under the keys its bag's custom data uses (controller, and
    why and when [s] it failed, if it did), so that ``Flight.failure`` reads the same from either."""
    custom = {'controller': controller_kind}
    if failure is not None:
        custom.update({FAILURE_KEY: failure, FAILURE_TIME_KEY: repr(failure_time)})
    return custom


def physics_substeps(control_dt: float, physics_rate: float) -> int:
    """Physics steps per control step; ValueError unless the physics rate is a whole multiple."""
    physics_dt = 1.0 / physics_rate
    substeps = round(control_dt / physics_dt)
    if substeps < 1 or abs(substeps * physics_dt - control_dt) > 1e-12:
        raise ValueError(f'physics rate {physics_rate} Hz is not a whole multiple of the control rate '
                         f'{1.0 / control_dt} Hz')
    return substeps


def say_compiling(progress: bool) -> None:
    """With ``progress``, say on stderr that the kernels compile before the first control step (numba: about 20 s
    on an idle core the first time, a minute on a loaded one; loaded from its cache after)."""
    if progress:
        print('  compiling the kernels (numba; cached after the first run)', file=sys.stderr, flush=True)


def say_ready(progress: bool, started: float) -> None:
    """With ``progress``, say how long the first control step took since ``started`` [s, perf_counter]."""
    if progress:
        print(f'  kernels ready in {time.perf_counter() - started:.1f} s; flying', file=sys.stderr, flush=True)


def through_odometry(t: float, state: list):
    """The state as the controller reads it from an odometry message of it, and that message's content."""
    odometry = odometry_from_state(t, state)
    return state_from_odometry(odometry), odometry


def fly_embedded(controller_kind: str, trajectory, params: VehicleParams, disturbances: Disturbances,
                 gains: dict, duration: float, physics_rate: float, setpoint_rate: float = 50.0,
                 progress: bool = False, bag: FlightBag | None = None,
                 stop: Callable[[], bool] | None = None, sinks: Sequence = (),
                 perturbations: Perturbations | None = None,
                 rules: FailureRules = FailureRules(settle_time=5.0, max_error=math.inf),
                 plant: str = DEFAULT_PLANT) -> FlightResult:
    """Fly ``trajectory`` for ``duration`` [s] of sim time; one record row per control step.

    ``params`` is the controller's nominal model, and the vehicle flown unless ``perturbations``
    says otherwise. The record holds the true position; with sensor noise the bag's ``odom`` is
    what the controller read. With ``bag`` every step's contract messages are recorded too (the
    caller closes the bag). ``sinks`` get the same calls after the bag, in order:
    ``record_setpoints(path)`` once, then ``record_step(...)`` per step (e.g. a ``pacing.Pacer``,
    then a ``live_view.LiveView``). ``stop`` is asked between two control steps: once it returns
    true the flight raises KeyboardInterrupt, with every step so far complete in the bag. A flight
    that breaks one of ``rules`` ends there (``FlightResult.failure`` says why). ``plant`` is what the
    simulator flies (:data:`quad_sim.plants.PLANTS`: our model, or RotorPy's).
    """
    perturbations = perturbations or Perturbations()
    controller = build_controller(controller_kind, params, gains)
    step_sinks = ([bag] if bag is not None else []) + list(sinks)

    def publish(window: SetpointPath) -> None:
        with deferred():
            for sink in step_sinks:
                sink.record_setpoints(window)

    setpoints = SetpointStream(trajectory, trajectory.duration, setpoint_rate, on_window=publish)
    substeps = physics_substeps(controller.dt, physics_rate)
    model = make_plant(plant, perturbations.true_vehicle or params, disturbances)
    simulator = Simulator(model, 1.0 / physics_rate, trajectory.initial_state,
                          motor_lag=perturbations.motor_lag, wind=perturbations.wind, changes=perturbations.changes)
    loop = ClosedLoop(controller, simulator, setpoints.sample, substeps, rules,
                      sensor_noise=perturbations.sensor_noise, delay=perturbations.delay, observe=through_odometry,
                      measurement=build_measurement_stage(gains))
    log = FlightLog(rules.settle_time, params.F_min, params.F_max)
    steps = int(round(duration / controller.dt))
    report_every = max(1, steps // 10)
    freeze_long_lived_objects()
    started = time.perf_counter()
    slopes = controller.surface_slopes()   # the gains do not change during an embedded flight
    say_compiling(progress)
    for k in range(steps):
        if stop is not None and stop():
            raise KeyboardInterrupt(f'stopped after {k} control steps')
        done = loop.step()
        if k == 0:
            say_ready(progress, started)
        out, reference, truth = done.output, done.reference, done.truth
        surfaces, equivalent, corrective = [list(field) for field in zip(*out.axes.values())][1:]   # per subsystem
        truth_odometry = None if perturbations.sensor_noise is None else odometry_from_state(done.time, truth)
        # the state as the bag gives it back: the odometry read, or ground_truth/odom under sensor noise
        log.add(done.time, done.measured if truth_odometry is None else state_from_odometry(truth_odometry),
                reference.position, reference.yaw, out.forces, out.controls, surfaces, equivalent, corrective)
        if step_sinks:
            with deferred():
                for sink in step_sinks:
                    sink.record_step(done.observation, out.forces, out.controls, reference.position, reference.yaw,
                                     surfaces, equivalent, corrective, slopes, truth=truth_odometry)
        if not loop.flying:
            break
        if progress and (k + 1) % report_every == 0:
            print(f'  {100 * (k + 1) // steps:3d}%  t = {simulator.time:6.2f} s', file=sys.stderr, flush=True)
    failure = None if loop.flying else FAILURES[loop.failure]
    failure_time = None if loop.flying else float(loop.failure_time)
    if bag is not None and failure is not None:
        bag.record_failure(failure, failure_time)
    return FlightResult(log.flight(params, label=controller_kind,
                                   custom_data=flown_custom_data(controller_kind, failure, failure_time),
                                   ended_early=failure is not None),
                        time.perf_counter() - started, log.steps, failure, failure_time)


def _stacked(samples: Sequence[ReferenceSample]) -> ReferenceSample:
    """One reference of a batch from one sample per vehicle (each field an array, one element per vehicle)."""
    return ReferenceSample(*(tuple(np.array(values) for values in zip(*field_values))
                             if isinstance(field_values[0], tuple) else np.array(field_values)
                             for field_values in zip(*samples)))


def _vehicle(values, k: int):
    """Vehicle k's floats of a batch value: an array, a float shared by all, or a tuple, list or
    OdometrySample of those."""
    if isinstance(values, np.ndarray):
        return float(values[k])
    if isinstance(values, OdometrySample):
        return OdometrySample(*(_vehicle(v, k) for v in values))
    if isinstance(values, (tuple, list)):
        return type(values)(_vehicle(v, k) for v in values)
    return values


def fly_fleet(controller_kind: str, trajectories: Sequence, params: VehicleParams, disturbances: Disturbances,
              gains: dict, duration: float, physics_rate: float, setpoint_rate: float = 50.0,
              progress: bool = False, bag=None, stop: Callable[[], bool] | None = None,
              rules: FailureRules = FailureRules(settle_time=5.0, max_error=math.inf),
              plant: str = DEFAULT_PLANT) -> list[FlightResult]:
    """Fly a fleet on one sim clock: vehicle k flies ``trajectories[k]`` (its own, e.g. offset, copy of
    the scenario), all stepped together as one batch; one FlightResult per vehicle.

    Each vehicle's controller reads its state through an odometry message of it and answers it with
    the reference sampled from its own setpoint path, as its controller node does in a ROS fleet.
    With ``bag`` (a FleetBag) every vehicle's topics are recorded in its namespace, ``/clock`` and
    ``/tf`` once per step. A vehicle that breaks one of ``rules`` is frozen; the others fly on. ``plant``:
    as for :func:`fly_embedded` (RotorPy steps the vehicles one after the other).
    """
    count = len(trajectories)
    controller = build_controller(controller_kind, params, gains, batch=count)
    def publisher(v: int) -> Callable[[SetpointPath], None]:
        def publish(window: SetpointPath) -> None:
            if bag is not None:
                with deferred():
                    bag.vehicles[v].record_setpoints(window)
        return publish

    paths = [SetpointStream(trajectory, trajectory.duration, setpoint_rate, on_window=publisher(v))
             for v, trajectory in enumerate(trajectories)]
    substeps = physics_substeps(controller.dt, physics_rate)
    start = [np.array(values) for values in zip(*(trajectory.initial_state for trajectory in trajectories))]
    simulator = Simulator(make_plant(plant, params, disturbances), 1.0 / physics_rate, start)
    loop = ClosedLoop(controller, simulator, lambda t: _stacked([path.sample(t) for path in paths]), substeps,
                      rules, observe=through_odometry, measurement=build_measurement_stage(gains))
    slopes = controller.surface_slopes()
    logs = [FlightLog(rules.settle_time, params.F_min, params.F_max) for _ in trajectories]
    steps = int(round(duration / controller.dt))
    report_every = max(1, steps // 10)
    freeze_long_lived_objects()
    started = time.perf_counter()
    say_compiling(progress)
    with np.errstate(all='ignore'):          # a failing vehicle may overflow before it is frozen
        for k in range(steps):
            if stop is not None and stop():
                raise KeyboardInterrupt(f'stopped after {k} control steps')
            flying = loop.flying.copy()
            done = loop.step()
            if k == 0:
                say_ready(progress, started)
            out, reference = done.output, done.reference
            axes = list(out.axes.values())
            odometries = [_vehicle(done.observation, v) for v in range(count)]
            with deferred():     # the step's messages of every vehicle, whole
                if bag is not None:
                    bag.record_shared(odometries)
                for v in range(count):
                    if not flying[v]:
                        continue
                    forces, controls = _vehicle(out.forces, v), _vehicle(out.controls, v)
                    surfaces, equivalent, corrective = ([_vehicle(a.surface, v) for a in axes],
                                                        [_vehicle(a.equivalent, v) for a in axes],
                                                        [_vehicle(a.corrective, v) for a in axes])
                    position, yaw = _vehicle(reference.position, v), _vehicle(reference.yaw, v)
                    logs[v].add(done.time, state_from_odometry(odometries[v]), position, yaw, forces, controls,
                                surfaces, equivalent, corrective)
                    if bag is not None:
                        bag.vehicles[v].record_step(odometries[v], forces, controls, position, yaw, surfaces,
                                                    equivalent, corrective, slopes)
            if not loop.flying.any():
                break
            if progress and (k + 1) % report_every == 0:
                print(f'  {100 * (k + 1) // steps:3d}%  t = {simulator.time:6.2f} s', file=sys.stderr, flush=True)
    wall = time.perf_counter() - started
    failures = [None if loop.failure[v] < 0 else FAILURES[loop.failure[v]] for v in range(count)]
    times = [None if failure is None else float(loop.failure_time[v]) for v, failure in enumerate(failures)]
    for v, (failure, failure_time) in enumerate(zip(failures, times)):
        if bag is not None and failure is not None:
            bag.vehicles[v].record_failure(failure, failure_time)
    return [FlightResult(log.flight(params, label=controller_kind,
                                    custom_data=flown_custom_data(controller_kind, failure, failure_time),
                                    ended_early=failure is not None), wall, log.steps, failure, failure_time)
            for log, failure, failure_time in zip(logs, failures, times)]
