"""Recording a flight computed in-process (embedded backend): the contract topics, one step at a time.

Per control step the bag gets what the ROS flight publishes, in the same order and with the same
sim-time stamps: ``/clock``, ``odom`` and ``/tf`` (simulator: one TFMessage, ``odom`` ->
``<namespace>/base_link``), then ``rotor_forces``, ``control/wrench``, ``control/reference`` and
``control/diagnostics`` (controller). The body frame is the namespaced one the nodes use. Every
message of a step is logged at that step's odometry stamp [ns]; ``setpoints`` and
``reference_path`` once, at the path start. What describes the vehicle, as the simulator publishes
it at its start (quad_msgs_bridge.urdf.description_messages), is logged once at the flight's first
stamp, before that step's messages: the latched ``robot_description`` of each vehicle (its URDF) and
``/tf_static`` (its rotor links), so a bag opened in Foxglove or replayed into RViz shows the vehicle.
The run's vehicle parameters and settings go into the bag's custom data, so a review finds the arm
length and the rotor limits without the vehicle file.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Sequence

from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import (CLOCK, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, DEFAULT_NAMESPACE,
                                       GROUND_TRUTH, ODOM, ODOM_FRAME, RECORDED_TOPICS, REFERENCE_PATH, ROTOR_FORCES,
                                       SETPOINTS, TF, TopicSpec, base_frame, resolve)
from quad_msgs_bridge.conversions import path_msg, rosbags_kit, setpoints_msg
from quad_msgs_bridge.fast_cdr import (clock_encoder, diagnostics_encoder, odometry_encoder, pose_stamped_encoder,
                                       rotor_forces_encoder, tf_encoder, wrench_encoder)
from quad_msgs_bridge.reference import SetpointPath
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND, nanoseconds
from quad_msgs_bridge.urdf import description_messages
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, vehicle_name


def select_topics(names: Sequence[str] | None) -> tuple[TopicSpec, ...]:
    """The recorded contract topics with these names (as in the contract: 'odom', '/clock'); None: all."""
    if names is None:
        return RECORDED_TOPICS
    by_name = {spec.name: spec for spec in RECORDED_TOPICS}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise ParameterError(f'topics: {unknown[0]!r} is not a recorded contract topic (valid: {", ".join(by_name)})')
    return tuple(by_name[name] for name in dict.fromkeys(names))


def disturbances_label(enabled: bool) -> str:
    """The bag's custom data ``disturbances`` of a flight (words a ROS string parameter keeps as a string)."""
    return 'enabled' if enabled else 'disabled'


#: custom data keys of a flight that failed: why (flight_stack.closed_loop.FAILURES) and when [s, sim time];
#: in a fleet's bag each vehicle's are suffixed with ':<namespace>' (see vehicle_custom_data)
FAILURE_KEY, FAILURE_TIME_KEY = 'failure', 'failure_time_s'
#: custom data keys of the run's plan: the flight's planned length [s] and its --max-error [m]; and why a
#: flight stopped before that length without failing (``interrupted``: Ctrl-C), see quad_msgs_bridge.review.verdict
DURATION_KEY, MAX_ERROR_KEY, STOPPED_KEY = 'duration_s', 'max_error_m', 'stopped'


def mark_interrupted(writer: BagWriter, exc_type) -> None:
    """Note in the bag's custom data (written when it closes) that a stop signal (KeyboardInterrupt) ended
    the flight, so its review says so."""
    if exc_type is not None and issubclass(exc_type, KeyboardInterrupt):
        writer.custom_data[STOPPED_KEY] = 'interrupted'


def recorded_failure(custom: dict) -> tuple[str, float] | None:
    """(why, when [s, sim time]) a flight failed, from its bag's custom data (as :func:`vehicle_custom_data`
    gives it); None if none is recorded."""
    reason = custom.get(FAILURE_KEY)
    return None if reason is None else (reason, float(custom.get(FAILURE_TIME_KEY, 'nan')))


def vehicle_custom_data(custom: dict, namespace: str | None) -> dict:
    """A bag's custom data as one vehicle's flight sees it: in a fleet's bag, the failure keys of vehicle
    ``namespace`` (FAILURE_KEY + ':' + namespace) under the plain FAILURE_KEY and FAILURE_TIME_KEY."""
    own = {key: custom[f'{key}:{namespace}'] for key in (FAILURE_KEY, FAILURE_TIME_KEY)
           if namespace is not None and f'{key}:{namespace}' in custom}
    return {**custom, **own}


def flight_custom_data(params: VehicleParams, settle_time: float, **info) -> dict[str, str]:
    """Bag custom data of a flight: vehicle parameters (JSON) and name (``vehicle_name``: the shipped vehicle
    whose parameters they are, else 'custom', unless ``info`` names it, e.g. by its file), settle time [s] and
    labels (controller, ...)."""
    return {'vehicle': json.dumps(dataclasses.asdict(params)), 'vehicle_name': vehicle_name(params),
            'settle_time_s': repr(float(settle_time)),
            **{key: str(value) for key, value in info.items()}}


def ros_flight_custom_data(params: VehicleParams, settle_time: float, seed: int, namespaces: Sequence[str],
                           **labels: str) -> dict[str, str]:
    """Custom data of a bag of a flight over ROS (recorded by the ``record`` node or merged from the nodes' own
    publication logs): ``flight_custom_data`` with the vehicles' absolute ``namespaces`` and the non-empty labels
    (controller, scenario, disturbances)."""
    vehicles = {'namespace': namespaces[0]} if len(namespaces) == 1 else {'vehicles': ','.join(namespaces)}
    return flight_custom_data(params, settle_time, backend='ros', seed=seed, **vehicles,
                              **{key: value for key, value in labels.items() if value})


class VehicleDescription:
    """What a bag records of its vehicles' description (quad_msgs_bridge.urdf.description_messages: each one's
    ``robot_description``, one ``/tf_static`` for all), held until the flight's first stamp."""

    def __init__(self, writer: BagWriter, params: VehicleParams, namespaces: Sequence[str]):
        self.writer = writer
        recorded = set(writer.topic_names())
        self._pending = [(resolve(spec, namespace), message)
                         for spec, namespace, message in description_messages(rosbags_kit(), params, namespaces)
                         if resolve(spec, namespace) in recorded]

    def record(self, stamp: int) -> None:
        """Write the description at log time ``stamp`` [ns], the first time only."""
        for topic, message in self._pending:
            self.writer.write_message(topic, message, stamp)
        self._pending = []


class FlightBag:
    """A bag fed by the embedded flight loop; a context manager that closes the bag.

    With ``shared_topics`` false it writes one vehicle's topics only, not ``/clock``, ``/tf`` and the
    vehicle's description (the fleet's :class:`FleetBag` writes those for every vehicle).
    """

    def __init__(self, writer: BagWriter, params: VehicleParams, namespace: str = DEFAULT_NAMESPACE,
                 shared_topics: bool = True):
        self.writer = writer
        recorded = set(writer.topic_names())

        def name(spec: TopicSpec) -> str | None:
            topic = resolve(spec, namespace)
            return topic if topic in recorded and (shared_topics or spec not in (CLOCK, TF)) else None

        self._clock, self._odom, self._forces = name(CLOCK), name(ODOM), name(ROTOR_FORCES)
        self._wrench, self._reference, self._diagnostics = name(CONTROL_WRENCH), name(CONTROL_REFERENCE), \
            name(CONTROL_DIAGNOSTICS)
        self._setpoints, self._path, self._tf = name(SETPOINTS), name(REFERENCE_PATH), name(TF)
        self._truth = name(GROUND_TRUTH)
        self._failure_suffix = '' if shared_topics else f':{namespace}'    # a fleet's vehicle: keys of its own
        self._base_frame = base_frame(namespace)
        self._encode_clock = clock_encoder()
        self._encode_odometry = odometry_encoder(ODOM_FRAME, self._base_frame)
        self._encode_tf = tf_encoder([self._base_frame])
        self._encode_forces = rotor_forces_encoder(params.rotor_names)     # the layout's labels
        self._encode_wrench = wrench_encoder(params.d, self._base_frame)
        self._encode_pose = pose_stamped_encoder()
        self._encode_diagnostics = diagnostics_encoder()
        self._description = VehicleDescription(writer, params, [namespace] if shared_topics else [])

    @classmethod
    def create(cls, path: str | Path, params: VehicleParams, settle_time: float, *,
               topics: Sequence[TopicSpec] = RECORDED_TOPICS, namespace: str = DEFAULT_NAMESPACE,
               overwrite: bool = False, **info) -> 'FlightBag':
        """A new bag at ``path`` for a flight of the vehicle ``params``; ``info`` labels the run."""
        custom_data = flight_custom_data(params, settle_time, namespace=namespace, **info)
        writer = BagWriter(path, topics, namespace, custom_data=custom_data, overwrite=overwrite)
        return cls(writer, params, namespace)

    def record_setpoints(self, path: SetpointPath) -> None:
        """The trajectory node's ``setpoints`` and ``reference_path`` for ``path``, at its start stamp."""
        kit = rosbags_kit()
        stamp = nanoseconds(path.start)
        if self._setpoints:
            self.writer.write_message(self._setpoints, setpoints_msg(kit, path, child_frame_id=self._base_frame),
                                      stamp)
        if self._path:
            self.writer.write_message(self._path, path_msg(kit, path), stamp)

    def record_step(self, odometry: OdometrySample, forces: Sequence[float], controls: Sequence[float],
                    reference_position: Sequence[float], reference_yaw: float, surfaces: Sequence[float],
                    equivalent: Sequence[float], corrective: Sequence[float], slopes: Sequence[float],
                    truth: OdometrySample | None = None) -> None:
        """One control step: the odometry answered, the thrusts [N] and U1..U4 sent, the reference
        [m, rad] used and the per-subsystem sliding surfaces, NN and fuzzy terms and surface slopes
        lambda [1/s]; with ``truth``
        (the true state when the odometry carries sensor noise) also ``ground_truth/odom``. The first step
        records the vehicle's description before it."""
        stamp = nanoseconds(odometry.stamp)
        sec, nanosec = divmod(stamp, NANOSECONDS_PER_SECOND)
        self._description.record(stamp)
        write = self.writer.write_serialized
        if self._clock:
            write(self._clock, self._encode_clock(sec, nanosec), stamp)
        if self._odom:
            write(self._odom, self._encode_odometry(sec, nanosec, odometry), stamp)
        if self._truth and truth is not None:
            write(self._truth, self._encode_odometry(sec, nanosec, truth), stamp)
        if self._tf:
            write(self._tf, self._encode_tf(sec, nanosec, (odometry,)), stamp)
        if self._forces:
            write(self._forces, self._encode_forces(forces), stamp)
        if self._wrench:
            write(self._wrench, self._encode_wrench(sec, nanosec, controls), stamp)
        if self._reference:
            write(self._reference, self._encode_pose(sec, nanosec, reference_position, reference_yaw), stamp)
        if self._diagnostics:
            write(self._diagnostics, self._encode_diagnostics(surfaces, equivalent, corrective, slopes), stamp)

    def record_failure(self, reason: str, time_s: float) -> None:
        """Note that the flight failed (``reason``, e.g. 'flipped over') at sim time ``time_s`` [s]: custom
        data FAILURE_KEY and FAILURE_TIME_KEY, written when the bag closes, so its review says so."""
        self.writer.custom_data.update({FAILURE_KEY + self._failure_suffix: str(reason),
                                        FAILURE_TIME_KEY + self._failure_suffix: repr(float(time_s))})

    def close(self) -> None:
        self.writer.close()

    def __enter__(self) -> 'FlightBag':
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        mark_interrupted(self.writer, exc_type)
        self.writer.__exit__(exc_type, exc, traceback)


class FleetBag:
    """The bag of a fleet flown by the embedded loop: every vehicle's topics in its namespace, and
    ``/clock`` and one ``/tf`` (a transform per vehicle) once per step, as the fleet simulator
    publishes them; every vehicle's description once, at the first step. ``vehicles[k]`` records vehicle k's
    own topics; a context manager that closes the bag.
    """

    def __init__(self, writer: BagWriter, params: VehicleParams, namespaces: Sequence[str]):
        self.writer = writer
        self.vehicles = [FlightBag(writer, params, namespace, shared_topics=False) for namespace in namespaces]
        recorded = set(writer.topic_names())
        self._clock = resolve(CLOCK, '') if resolve(CLOCK, '') in recorded else None
        self._tf = resolve(TF, '') if resolve(TF, '') in recorded else None
        self._encode_clock = clock_encoder()
        self._encode_tf = tf_encoder([base_frame(namespace) for namespace in namespaces])
        self._description = VehicleDescription(writer, params, namespaces)

    @classmethod
    def create(cls, path: str | Path, params: VehicleParams, settle_time: float, namespaces: Sequence[str], *,
               topics: Sequence[TopicSpec] = RECORDED_TOPICS, overwrite: bool = False, **info) -> 'FleetBag':
        """A new bag at ``path`` for a fleet of ``namespaces`` flying the vehicle ``params``."""
        custom_data = flight_custom_data(params, settle_time, vehicles=','.join(namespaces), **info)
        writer = BagWriter(path, topics, list(namespaces), custom_data=custom_data, overwrite=overwrite)
        return cls(writer, params, namespaces)

    def record_shared(self, odometries: Sequence[OdometrySample]) -> None:
        """``/clock`` and ``/tf`` of a step, from every vehicle's odometry (all of one stamp); at the first
        step, every vehicle's description before them."""
        stamp = nanoseconds(odometries[0].stamp)
        sec, nanosec = divmod(stamp, NANOSECONDS_PER_SECOND)
        self._description.record(stamp)
        if self._clock:
            self.writer.write_serialized(self._clock, self._encode_clock(sec, nanosec), stamp)
        if self._tf:
            self.writer.write_serialized(self._tf, self._encode_tf(sec, nanosec, odometries), stamp)

    def close(self) -> None:
        self.writer.close()

    def __enter__(self) -> 'FleetBag':
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        mark_interrupted(self.writer, exc_type)
        self.writer.__exit__(exc_type, exc, traceback)
