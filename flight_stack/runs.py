"""A planned flight flown and written: the library's core of ``fly()`` and of ``run_stack.py``.

:func:`fly_here` flies a plan (flight_stack.plan) on the embedded backend, :func:`fly_fleet_here` a fleet
of it, :func:`fly_on_ros` every node in its own process; :func:`summarize` makes its summary.json content,
:func:`review_now` its report; :func:`run_flight` does all of it for ``flight_stack.api.fly``. The command
line (flight_stack.cli) parses its arguments into a plan and a :class:`Launch` and calls these.
"""
from __future__ import annotations

import contextlib
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from flight_stack.interrupts import deferred, stop_signals


@dataclass(frozen=True)
class Launch:
    """How a plan is flown beyond what the plan holds: the command line's fleet and ROS backend options."""

    vehicles: int = 1                   #: vehicles on one sim clock (flight_stack.fleet)
    namespace: str | None = None        #: ROS namespace of the vehicle, or of a fleet's vehicles
    quiet: bool = False                 #: no progress lines
    mode: str | None = None             #: ROS backend: lockstep or realtime
    speed_factor: float | None = None   #: ROS realtime: sim s per wall s
    extra_subscribers: int = 0          #: ROS lockstep: odom subscribers to wait for beyond ours
    record_by: str | None = None        #: ROS backend: who writes the bag (recorder or publishers)
    vehicle_file: Path | None = None    #: the nominal vehicle's file, as given (the ROS nodes read it)
    px4: object = None                  #: --plant px4-sitl: where PX4 SITL and the Agent are (flight_stack.px4_sitl)
    px4_takeoff: str = 'px4'            #: --plant px4-sitl: who takes off (RosFlightConfig.px4_takeoff)


def live_sinks(view, speed_factor: float) -> list:
    """The step sinks of a live flight: a pacer (unless as fast as possible), then the live view."""
    from flight_stack.pacing import Pacer
    return ([Pacer(speed_factor)] if speed_factor > 0.0 else []) + [view]


@contextlib.contextmanager
def closed_whole(recording):
    """``with recording`` whose closing (a bag's summary and metadata) a stop signal does not cut."""
    with deferred():
        entered = recording.__enter__()
    try:
        yield entered
    except BaseException as error:
        with deferred():
            if not recording.__exit__(type(error), error, error.__traceback__):
                raise
    else:
        with deferred():
            recording.__exit__(None, None, None)


class FlightStopped(Exception):
    """The flight did not finish; the message says why, ``code`` is the exit status."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


@dataclass
class Flown:
    """A finished flight: its data (time series and metrics, for the summary) and, with a bag, the flight to review."""

    data: object                    #: quad_msgs_bridge.review.flight_data.Flight
    wall_time_s: float
    flight: object = None           #: the same Flight when it has a bag to review; None without a bag
    extra: dict = field(default_factory=dict)
    failure: str | None = None      #: why the flight ended early (flight_stack.closed_loop.FAILURES), if it did
    failure_time_s: float | None = None   #: [s] sim time at which it failed


def planned_run(plan) -> dict[str, str]:
    """The bag's custom data of what the run planned (its length [s] and --max-error [m]), from which a review
    tells a flight that ended early or failed its checks (quad_msgs_bridge.review.verdict)."""
    from quad_msgs_bridge.bag.flight_bag import DURATION_KEY, MAX_ERROR_KEY
    return {DURATION_KEY: repr(float(plan.duration)), MAX_ERROR_KEY: repr(float(plan.max_error))}


def fly_here(plan, bag: Path | None, bag_shown: Path | None, progress: bool = False, live_view=None,
             speed_factor: float = 0.0, live_wait: bool = False, namespace: str | None = None) -> Flown:
    """The embedded backend; with ``bag`` (its topics under ``namespace``, None: the default one), the flight to
    review is the one in memory (what the bag holds)."""
    from flight_stack.closed_loop import FailureRules
    from flight_stack.embedded import fly_embedded
    from flight_stack.fleet import fleet_layout
    from quad_msgs_bridge.bag.flight_bag import FlightBag, disturbances_label

    with stop_signals(), live_view.server if live_view else contextlib.nullcontext():
        sinks = live_sinks(live_view, speed_factor) if live_view else []
        if live_view and live_wait:
            print('live view: waiting for a client to subscribe (Ctrl-C to stop)', flush=True)
            live_view.server.wait_for_subscriber(lambda: False)   # a stop signal raises KeyboardInterrupt meanwhile
        with deferred():
            recording = (FlightBag.create(bag, plan.params, plan.settle_time, topics=plan.topics,
                                          controller=plan.controller, scenario=plan.scenario, backend='embedded',
                                          seed=plan.seed, disturbances=disturbances_label(plan.disturbances.enabled),
                                          namespace=fleet_layout(1, namespace)[0].namespace,
                                          vehicle_name=plan.vehicle_name, **planned_run(plan))
                         if bag else contextlib.nullcontext())
        with closed_whole(recording) as written:
            result = fly_embedded(plan.controller, plan.trajectory, plan.params, plan.disturbances, plan.gains,
                                  plan.duration, plan.physics_rate, progress=progress, bag=written,
                                  sinks=sinks, perturbations=plan.perturbations,
                                  rules=FailureRules(plan.settle_time, max_error=math.inf), plant=plan.plant)
            for sink in sinks:
                sink.close()
    flight = result.flight
    if bag:
        flight.path, flight.custom_data = bag_shown, dict(written.writer.custom_data)
    return Flown(flight, result.wall_time_s, flight if bag else None, failure=result.failure,
                 failure_time_s=result.failure_time_s)


def fly_fleet_here(launch: 'Launch', plan, bag: Path | None, bag_shown: Path | None) -> list[tuple[str, Flown]]:
    """The embedded backend's fleet: every vehicle stepped together as one batch on one sim clock; per
    vehicle (its namespace, its flight), reviewed from the records in memory (what the bag holds)."""
    from flight_stack.closed_loop import FailureRules
    from flight_stack.embedded import fly_fleet
    from flight_stack.fleet import fleet_layout
    from nnit2fsmc_controller.trajectory import make_scenario
    from quad_msgs_bridge.bag.flight_bag import FleetBag, disturbances_label, vehicle_custom_data

    vehicles = fleet_layout(launch.vehicles, launch.namespace)
    trajectories = [make_scenario(plan.scenario, plan.duration, offset=vehicle.offset) for vehicle in vehicles]
    with stop_signals():
        with deferred():
            recording = (FleetBag.create(bag, plan.params, plan.settle_time, [v.namespace for v in vehicles],
                                         topics=plan.topics, controller=plan.controller, scenario=plan.scenario,
                                         backend='embedded', seed=plan.seed,
                                         disturbances=disturbances_label(plan.disturbances.enabled),
                                         vehicle_name=plan.vehicle_name,
                                         **planned_run(plan))
                         if bag else contextlib.nullcontext())
        with closed_whole(recording) as written:
            results = fly_fleet(plan.controller, trajectories, plan.params, plan.disturbances, plan.gains,
                                plan.duration, plan.physics_rate, progress=not launch.quiet, bag=written,
                                rules=FailureRules(plan.settle_time, max_error=math.inf), plant=plan.plant)
    flights = []
    for vehicle, result in zip(vehicles, results):
        flight = result.flight
        flight.label = vehicle.namespace
        if bag:
            flight.path = bag_shown
            flight.custom_data = vehicle_custom_data(written.writer.custom_data, vehicle.namespace)
        flights.append((vehicle.namespace, Flown(flight, result.wall_time_s, flight if bag else None,
                                                 {'offset_m': list(vehicle.offset)}, failure=result.failure,
                                                 failure_time_s=result.failure_time_s)))
    return flights


def fly_on_ros(launch: 'Launch', plan, bag: Path, bag_shown: Path | None) -> list[tuple[str, Flown]]:
    """Every node in its own process; per vehicle (its namespace, its flight) read from the bag the recorder
    node wrote: one, or a fleet (flight_stack.fleet)."""
    from flight_stack.fleet import fleet_layout
    from flight_stack.ros_backend import RosFlightConfig, fly_ros
    from quad_msgs_bridge.bag.timing import message_timing
    from quad_msgs_bridge.review.flight_from_bag import read_flight

    vehicles = fleet_layout(launch.vehicles, launch.namespace)
    with tempfile.TemporaryDirectory(prefix='nnit2fsmc-gains-') as scratch:
        gains_file = Path(scratch) / 'gains.yaml'   # the gains the plan flies, whole (--set included)
        gains_file.write_text(yaml.safe_dump(plan.gains, sort_keys=False))
        result = fly_ros(RosFlightConfig(
            vehicles=vehicles, controller=plan.controller, scenario=plan.scenario, duration=plan.duration,
            disturbances=plan.disturbances.enabled, seed=plan.seed, physics_rate=plan.physics_rate,
            control_rate=plan.control_rate, bag=bag,
            topics=[t.name for t in plan.topics], mode=launch.mode, speed_factor=launch.speed_factor,
            extra_odom_subscribers=launch.extra_subscribers, vehicle_file=launch.vehicle_file, gains_file=gains_file,
            settle_time=plan.settle_time, quiet=launch.quiet, record_by=launch.record_by, max_error=plan.max_error,
            plant=plan.plant, px4=launch.px4, px4_takeoff=launch.px4_takeoff))
    if result.failed_node:
        raise FlightStopped(f'the flight failed: {result.failed_node} (exit codes {result.exit_codes})'
                            + (f'; the bag is closed: {bag}' if bag_shown and bag.exists() else ''),
                            130 if result.failed_node == 'interrupted' else 1)
    flights = []
    for vehicle in vehicles:
        try:
            flight = read_flight(bag, namespace=vehicle.namespace, vehicle_file=launch.vehicle_file,
                                 settle_time=plan.settle_time)
            timing = message_timing(bag, vehicle.namespace)
        except ValueError as error:
            raise FlightStopped(f'cannot summarise the flight of {vehicle.namespace} from {bag}: {error}', 1) \
                from error
        flight.path = bag_shown
        extra = {'ros': {'namespace': vehicle.namespace, 'mode': launch.mode,
                         'simulator': result.sim_report.split('] ')[-1], 'timing': timing},
                 **({'offset_m': list(vehicle.offset)} if len(vehicles) > 1 else {})}
        if plan.controller == 'px4':   # PX4's own controller (quad_sim.px4_node: placeholders in the bag)
            extra['not_measured'] = ('chattering and rotor saturation: PX4 1.15 sends no actuator outputs over '
                                     'uXRCE-DDS; the bag\'s rotor_forces are hover-force placeholders')
        flights.append((vehicle.namespace, Flown(flight, result.wall_time_s, flight if bag_shown else None,
                                                 extra, failure=result.flight_failure)))
    return flights


def review_now(flown: Flown, plan, out: Path) -> tuple[list[str], str | None]:
    """Review the flight into ``out`` (staged): (lines to print, report name) or a reason it was skipped."""
    from quad_msgs_bridge.review.command import review_flights
    from quad_msgs_bridge.review.flight_from_bag import NEEDED_TOPICS

    missing = [spec.name for spec in NEEDED_TOPICS if spec not in plan.topics]
    if missing:   # the report must describe what `review BAG` finds in the bag
        return [f'review skipped: the bag does not record {", ".join(missing)}'], None
    review = review_flights([flown.flight], out)
    return [f'note: {note}' for note in review.notes], review.report.name


def summarize(flown: Flown, plan, backend: str) -> dict:
    """The summary of a flown flight (metrics, outcome, settings)."""
    from flight_stack.summary import build_summary
    summary = build_summary(flown.data.metrics(), backend=backend, controller=plan.controller, scenario=plan.scenario,
                            seed=plan.seed, settle_time=plan.settle_time, params=plan.params,
                            disturbances=plan.disturbances, gains=plan.gains, physics_rate=plan.physics_rate,
                            wall_time_s=flown.wall_time_s, max_error=plan.max_error, failure=flown.failure,
                            failure_time_s=flown.failure_time_s, planned_duration_s=plan.duration,
                            plant=plan.plant, vehicle=plan.vehicle_name)
    summary.update(flown.extra)
    return summary


def run_flight(controller: str, scenario: str, *, out=None, overwrite: bool = False, vehicle=None, gains=None,
               **settings):
    """One embedded flight without the command line (flight_stack.api.fly): its Flight, with the summary in
    ``flight.summary``; with ``out`` the run is written there as the command writes it. ParameterError before
    flying on a bad setting."""
    from flight_stack.output import RunOutput
    from flight_stack.plan import plan_flight
    from flight_stack.summary import write_summary
    from quad_msgs_bridge.validation import ParameterError
    plan = plan_flight(controller, scenario, vehicle_file=vehicle, gains_file=gains, **settings)
    if out is not None and (not isinstance(out, (str, Path)) or not str(out).strip()):
        raise ParameterError(f'out: expected a folder path (None: write nothing; \'.\': the current folder), got '
                             f'{out!r}')
    if out is None:
        flown = fly_here(plan, None, None)
        flown.data.summary = summarize(flown, plan, 'embedded')
        return flown.data
    out = Path(out)
    output = RunOutput(out, out / 'bag', overwrite)
    output.create()
    try:
        flown = fly_here(plan, output.bag, out / 'bag')
        flown.data.summary = summarize(flown, plan, 'embedded')
        write_summary(flown.data.summary, output.out)
        review_now(flown, plan, output.out)
        with deferred():
            output.commit()
    except BaseException:
        output.keep_partial()
        raise
    return flown.data
