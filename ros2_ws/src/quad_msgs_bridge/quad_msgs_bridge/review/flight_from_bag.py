"""A flight rebuilt from a bag: the :class:`~quad_msgs_bridge.review.metrics.FlightRecord` the live run kept.

Any rosbag2 bag with the contract topics works (ours, ``ros2 bag record -s mcap``, a sqlite3 copy):
it is read with ``rosbags``' AnyReader and decoded with the bridge's ``*_from_msg`` readers. One
control step per ``control/wrench`` message (stamped with the odometry it answered): the odometry
and ``control/reference`` with the same stamp give the state and the reference, ``rotor_forces``
and ``control/diagnostics`` (unstamped) pair with the wrenches by order, as the contract says.
U2 and U3 are read back from the wrench torques with the arm length d; d and the rotor limits come
from the bag's custom data, else from a vehicle file.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from rosbags.highlevel import AnyReader, AnyReaderError

from quad_msgs_bridge.bag.flight_bag import FAILURE_KEY, FAILURE_TIME_KEY, vehicle_custom_data
from quad_msgs_bridge.bag.reader import BagReadError, check_bag_path, is_finalized, mcap_file, read_custom_data
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.contract import (ALL_TOPICS, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, GROUND_TRUTH,
                                       ODOM, ROTOR_FORCES, TopicSpec, resolve)
from quad_msgs_bridge.conversions import (controls_from_wrench, diagnostics_from_msg, odometry_from_msg, pose_from_msg,
                          rotor_forces_from_msg)
from quad_msgs_bridge.review.metrics import (FlightRecord, FlightRecorder, default_settle_time, flight_metrics,
                                             has_fuzzy_term)
from quad_msgs_bridge.state import PSI, state_from_odometry
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file

#: the topics a flight record needs
NEEDED_TOPICS = (ODOM, ROTOR_FORCES, CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS)
#: read when present: the true state of a flight whose odometry carries sensor noise
OPTIONAL_TOPICS = (GROUND_TRUTH,)


@dataclass
class BagFlight:
    """A flight with what its review needs: read from a bag, or just flown (its record kept in memory)."""

    path: Path                    #: the bag of the flight
    label: str                    #: controller name (custom data) or the bag's name
    record: FlightRecord
    params: VehicleParams         #: from the bag's custom data, else the vehicle file
    settle_time: float            #: [s]
    custom_data: dict             #: the bag's custom data (controller, scenario, disturbances, ...)
    warnings: list = field(default_factory=list)
    #: the flight failed and ended there (known for a flight just flown, and from a bag that records its
    #: failure): if that was before two settled steps its tracking figures are NaN, as in its summary,
    #: rather than a too-short flight refused
    ended_early: bool = False

    @property
    def failure(self) -> tuple[str, float] | None:
        """(why, when [s, sim time]) the flight failed, from the bag's custom data; None if none is recorded."""
        reason = self.custom_data.get(FAILURE_KEY)
        return None if reason is None else (reason, float(self.custom_data.get(FAILURE_TIME_KEY, 'nan')))

    def metrics(self) -> dict:
        """The flight's metrics (:func:`~quad_msgs_bridge.review.metrics.flight_metrics`), as ``summary.json``."""
        return flight_metrics(self.record, self.settle_time, self.params.F_min, self.params.F_max,
                              fuzzy_term=has_fuzzy_term(self.custom_data.get('controller')),
                              ended_early=self.ended_early, arm_length=self.params.d)


def _stamp_ns(msg) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _find_connection(connections, spec: TopicSpec, namespace: str | None):
    """The connection carrying ``spec``: by its resolved name, or the one topic ending in its name."""
    typed = [c for c in connections if c.msgtype == spec.type]
    if namespace is not None:
        matches = [c for c in typed if c.topic == resolve(spec, namespace)]
    else:
        suffix = spec.name if spec.name.startswith('/') else '/' + spec.name
        longer = [other.name for other in ALL_TOPICS if other.name != spec.name and other.name.endswith(suffix)]
        matches = [c for c in typed if c.topic.endswith(suffix)
                   and not any(c.topic.endswith('/' + name) for name in longer)]
    if len({c.topic for c in matches}) > 1:
        raise BagReadError(f'several {spec.type} topics end in {spec.name!r}: '
                           f'{sorted({c.topic for c in matches})}; choose one with --namespace')
    return matches


def _vehicle(custom: dict, vehicle_file: str | Path | None, warnings: list) -> VehicleParams:
    """The given vehicle file, else the bag's parameters (custom data 'vehicle' JSON or 'vehicle_file'),
    else the packaged vehicle file."""
    if vehicle_file is None and custom.get('vehicle'):
        return VehicleParams.from_mapping(json.loads(custom['vehicle']))
    if vehicle_file is None and custom.get('vehicle_file'):
        vehicle_file = custom['vehicle_file']
    if vehicle_file is None:
        warnings.append('the bag has no vehicle parameters; using the packaged vehicle file')
    return load_vehicle_file(vehicle_file)[0]


@dataclass
class _Topics:
    """What the bag's contract topics carry, per message, in log-time order."""

    stamps: list = field(default_factory=list)        #: [ns] of each control/wrench
    controls: list = field(default_factory=list)      #: U1..U4 of each control/wrench
    forces: list = field(default_factory=list)        #: each rotor_forces
    diagnostics: list = field(default_factory=list)   #: each control/diagnostics
    odometry: dict = field(default_factory=dict)      #: stamp [ns] -> OdometrySample
    truth: dict = field(default_factory=dict)         #: stamp [ns] -> OdometrySample of ground_truth/odom
    references: dict = field(default_factory=dict)    #: stamp [ns] -> (position, yaw)


def _read_topics(bag: Path, namespace: str | None, arm_length: float) -> _Topics:
    try:
        return _read_contract_topics(bag, namespace, arm_length)
    except AnyReaderError as error:
        raise BagReadError(f'{bag}: not readable as a bag: {error}') from error


def _read_contract_topics(bag: Path, namespace: str | None, arm_length: float) -> _Topics:
    topics = _Topics()
    with AnyReader([bag], default_typestore=jazzy_typestore()) as reader:
        found = {spec: _find_connection(reader.connections, spec, namespace) for spec in NEEDED_TOPICS}
        missing = [spec.name for spec, connections in found.items() if not connections]
        if missing:
            raise BagReadError(f'{bag}: no {", ".join(missing)} topic (has: '
                               f'{", ".join(sorted({c.topic for c in reader.connections}))})')
        found.update({spec: _find_connection(reader.connections, spec, namespace) for spec in OPTIONAL_TOPICS})
        role = {c.id: spec for spec, connections in found.items() for c in connections}
        for connection, _, raw in reader.messages(connections=[c for cs in found.values() for c in cs]):
            msg = reader.deserialize(raw, connection.msgtype)
            spec = role[connection.id]
            if spec is ODOM:
                topics.odometry[_stamp_ns(msg)] = odometry_from_msg(msg)
            elif spec is GROUND_TRUTH:
                topics.truth[_stamp_ns(msg)] = odometry_from_msg(msg)
            elif spec is CONTROL_WRENCH:
                topics.stamps.append(_stamp_ns(msg))
                topics.controls.append(controls_from_wrench(msg, arm_length))
            elif spec is CONTROL_REFERENCE:
                topics.references[_stamp_ns(msg)] = pose_from_msg(msg)
            elif spec is ROTOR_FORCES:
                topics.forces.append(rotor_forces_from_msg(msg))
            else:
                topics.diagnostics.append(diagnostics_from_msg(msg))
    return topics


def _flight_record(topics: _Topics, warnings: list) -> FlightRecord | None:
    """One row per control step (see the module doc); None if there is no complete step.

    The position and yaw are the true ones: ``ground_truth/odom`` where the bag has it (the
    odometry then carries sensor noise), else ``odom``.
    """
    steps = min(len(topics.stamps), len(topics.forces), len(topics.diagnostics))
    if steps < max(len(topics.stamps), len(topics.forces), len(topics.diagnostics)):
        warnings.append(f'unequal counts: {len(topics.stamps)} wrenches, {len(topics.forces)} rotor_forces, '
                        f'{len(topics.diagnostics)} diagnostics; pairing the first {steps} by order')
    recorder = FlightRecorder()
    skipped = 0
    for stamp, controls, forces, (surfaces, equivalent, corrective, _) in zip(
            topics.stamps, topics.controls, topics.forces, topics.diagnostics):
        sample, reference = (topics.truth or topics.odometry).get(stamp), topics.references.get(stamp)
        if sample is None or reference is None:
            skipped += 1
            continue
        position, yaw = reference
        recorder.append(sample.stamp, sample.position, state_from_odometry(sample)[PSI], position, yaw,
                        forces, controls, surfaces, equivalent, corrective)
    if skipped:
        warnings.append(f'{skipped} control steps without odometry or reference of the same stamp were skipped')
    return recorder.record() if recorder.rows else None


def fleet_namespaces(bag: str | Path) -> list[str]:
    """The vehicles' namespaces of a fleet's bag (custom data ``vehicles``); [] for one vehicle's bag."""
    check_bag_path(Path(bag))
    listed = read_custom_data(Path(bag)).get('vehicles', '')
    return [name for name in listed.split(',') if name]


def read_flight(bag: str | Path, *, namespace: str | None = None, vehicle_file: str | Path | None = None,
                settle_time: float | None = None) -> BagFlight:
    """The flight recorded in ``bag``; raises BagReadError if it lacks what a flight record needs.

    ``namespace``, ``vehicle_file`` and ``settle_time`` [s] override what the bag says; without a
    settle time in either, :func:`~quad_msgs_bridge.review.metrics.default_settle_time` of the flight.
    """
    bag = Path(bag)
    check_bag_path(bag)
    has_mcap = bag.suffix == '.mcap' or (bag.is_dir() and any(bag.glob('*.mcap')))
    if has_mcap and not is_finalized(mcap_file(bag)):
        raise BagReadError(f'{bag}: the recording was not closed (killed?); run `recover {bag}` first')
    custom = read_custom_data(bag)
    warnings: list[str] = []
    params = _vehicle(custom, vehicle_file, warnings)
    if namespace is None:
        namespace = custom.get('namespace')
    custom = vehicle_custom_data(custom, namespace)
    record = _flight_record(_read_topics(bag, namespace, params.d), warnings)
    if record is None:
        raise BagReadError(f'{bag}: no complete control step')
    if settle_time is None:
        recorded = custom.get('settle_time_s')
        settle_time = float(recorded) if recorded else default_settle_time(record.time[-1] - record.time[0])
    return BagFlight(bag, custom.get('controller') or bag.name, record, params, float(settle_time), custom, warnings,
                     ended_early=FAILURE_KEY in custom)
