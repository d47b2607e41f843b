"""A flight rebuilt from a bag: :func:`read_flight` gives the :class:`~quad_msgs_bridge.review.flight_data.Flight`
the live run kept.

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
import os
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from tqdm import tqdm

from quad_msgs_bridge.bag.flight_bag import recorded_failure, vehicle_custom_data
from quad_msgs_bridge.bag.mcap_blocks import MessageBlock, UnsupportedLayout, message_blocks
from quad_msgs_bridge.bag.mcap_blocks import channels as mcap_channels
from quad_msgs_bridge.bag.reader import BagReadError, check_bag_path, is_finalized, mcap_file, read_custom_data
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.contract import (ALL_TOPICS, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, GROUND_TRUTH,
                                       ODOM, ROTOR_FORCES, TopicSpec, resolve)
from quad_msgs_bridge.conversions import (DIAGNOSTIC_QUANTITIES, controls_from_wrench, diagnostics_from_msg,
                                          odometry_from_msg, pose_from_msg, rotor_forces_from_msg)
from quad_msgs_bridge.fast_cdr import (LayoutMismatch, decode_multi_array_rows, decode_odometry_rows,
                                       decode_stamped_floats_rows)
from quad_msgs_bridge.frames import yaws_from_quaternions
from quad_msgs_bridge.review.flight_data import MAX_ROWS, Flight, FlightLog
from quad_msgs_bridge.review.metrics import FlightRecord, default_settle_time, flight_metrics, has_fuzzy_term
from quad_msgs_bridge.review.summary import bag_summary
from quad_msgs_bridge.review.verdict import ending
from quad_msgs_bridge.state import state_from_odometry, states_from_odometry_rows
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file

#: FlightLog rows that no flight reaches: every control step kept
EVERY_STEP = 1 << 62
#: the topics a flight record needs
NEEDED_TOPICS = (ODOM, ROTOR_FORCES, CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS)
#: read when present: the true state of a flight whose odometry carries sensor noise
OPTIONAL_TOPICS = (GROUND_TRUTH,)


@dataclass
class BagFlight:
    """A flight with what its review needs, made from a FlightRecord in memory (a campaign's replay, a test);
    :class:`~quad_msgs_bridge.review.flight_data.Flight` (what :func:`read_flight` and ``fly()`` give) has the
    same attributes."""

    path: Path                    #: the bag of the flight
    label: str                    #: controller name (custom data) or the bag's name
    record: FlightRecord
    params: VehicleParams         #: from the bag's custom data, else the vehicle file
    settle_time: float            #: [s]
    custom_data: dict             #: the bag's custom data (controller, scenario, disturbances, ...)
    warnings: list = field(default_factory=list)
    #: the flight ended before its planned length (it failed, known for a flight just flown and from a bag
    #: that records its failure; or it was interrupted, or its bag cut short): if that was before two settled
    #: steps its tracking figures are NaN, as in its summary, rather than a too-short flight refused
    ended_early: bool = False

    @property
    def ending(self) -> str | None:
        """Why and where the flight ended before its planned length; None if it did not (see
        :attr:`quad_msgs_bridge.review.flight_data.Flight.ending`)."""
        time = self.record.time
        return ending(self.custom_data, float(time[-1]), float(time[-1] - time[0]) / max(len(time) - 1, 1))

    @property
    def failure(self) -> tuple[str, float] | None:
        """(why, when [s, sim time]) the flight failed, from the bag's custom data; None if none is recorded."""
        return recorded_failure(self.custom_data)

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


#: control steps a wrench waits for the odometry and reference of its stamp (the recorder of a ROS flight
#: may log a step's messages out of order); the read holds at most about this many steps at once
PAIRING_LAG = 256


class _StepPairing:
    """Rebuilds the control steps from the contract messages as they come, in log-time order (see the
    module doc), and adds each complete one to ``log``; holds only the few steps not yet complete."""

    def __init__(self, log: FlightLog, use_truth: bool):
        self.log, self.use_truth = log, use_truth
        self.wrenches, self.forces, self.diagnostics = deque(), deque(), deque()   #: in message order
        self.odometry, self.truth, self.references = {}, {}, {}                     #: by stamp [ns]
        self.counts = {'wrenches': 0, 'rotor_forces': 0, 'diagnostics': 0}
        self.skipped = 0

    def pair(self, final: bool = False) -> None:
        """Add the steps whose messages have all come (with ``final``: every step that can be paired)."""
        while self.wrenches and self.forces and self.diagnostics and (final or len(self.wrenches) > PAIRING_LAG):
            stamp, controls = self.wrenches.popleft()
            forces, (surfaces, equivalent, corrective, _) = self.forces.popleft(), self.diagnostics.popleft()
            states = self.truth if self.use_truth else self.odometry
            sample, reference = states.pop(stamp, None), self.references.pop(stamp, None)
            for earlier in (self.odometry, self.truth, self.references):   # no later wrench has their stamps
                while earlier and next(iter(earlier)) < stamp:
                    del earlier[next(iter(earlier))]
            if sample is None or reference is None:
                self.skipped += 1
                continue
            position, yaw = reference
            self.log.add(sample.stamp, state_from_odometry(sample), position, yaw, forces, controls, surfaces,
                         equivalent, corrective)

    def notes(self) -> list[str]:
        counts = self.counts
        notes = []
        if len(set(counts.values())) > 1:
            notes.append(f'unequal counts: {counts["wrenches"]} wrenches, {counts["rotor_forces"]} rotor_forces, '
                         f'{counts["diagnostics"]} diagnostics; pairing the first {min(counts.values())} by order')
        if self.skipped:
            notes.append(f'{self.skipped} control steps without odometry or reference of the same stamp were skipped')
        return notes


def _topic_connections(connections, namespace: str | None, bag: Path) -> dict:
    """The connections of each NEEDED_TOPICS and OPTIONAL_TOPICS spec; BagReadError naming a missing one."""
    found = {spec: _find_connection(connections, spec, namespace) for spec in NEEDED_TOPICS}
    missing = [spec.name for spec, matches in found.items() if not matches]
    if missing:
        raise BagReadError(f'{bag}: no {", ".join(missing)} topic (has: '
                           f'{", ".join(sorted({c.topic for c in connections}))})')
    found.update({spec: _find_connection(connections, spec, namespace) for spec in OPTIONAL_TOPICS})
    return found


def _read_steps(bag: Path, namespace: str | None, params: VehicleParams, settle_time: float | None,
                warnings: list, max_rows: int = MAX_ROWS) -> FlightLog:
    """The bag's control steps in a FlightLog of ``max_rows`` rows, message by message (any rosbag2 storage);
    the settle time [s] None: the default one for the bag's span."""
    with AnyReader([bag], default_typestore=jazzy_typestore()) as reader:
        found = _topic_connections(reader.connections, namespace, bag)
        if settle_time is None:
            settle_time = default_settle_time((reader.end_time - reader.start_time) / 1e9)
        log = FlightLog(float(settle_time), params.F_min, params.F_max, max_rows)
        steps = _StepPairing(log, use_truth=any(c.msgcount for c in found[GROUND_TRUTH]))
        role = {c.id: spec for spec, connections in found.items() for c in connections}
        for connection, _, raw in reader.messages(connections=[c for cs in found.values() for c in cs]):
            msg = reader.deserialize(raw, connection.msgtype)
            spec = role[connection.id]
            if spec is ODOM:
                steps.odometry[_stamp_ns(msg)] = odometry_from_msg(msg)
            elif spec is GROUND_TRUTH:
                steps.truth[_stamp_ns(msg)] = odometry_from_msg(msg)
            elif spec is CONTROL_WRENCH:
                steps.wrenches.append((_stamp_ns(msg), controls_from_wrench(msg, params.d)))
                steps.counts['wrenches'] += 1
            elif spec is CONTROL_REFERENCE:
                steps.references[_stamp_ns(msg)] = pose_from_msg(msg)
            elif spec is ROTOR_FORCES:
                steps.forces.append(rotor_forces_from_msg(msg))
                steps.counts['rotor_forces'] += 1
            else:
                steps.diagnostics.append(diagnostics_from_msg(msg))
                steps.counts['diagnostics'] += 1
            steps.pair()
        steps.pair(final=True)
    warnings.extend(steps.notes())
    return log


def _latest_index(stamps: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Per wanted stamp, the index of the last entry of ``stamps`` with it (a later message of a stamp
    replaces an earlier one), or -1."""
    if not len(stamps):                 # e.g. a killed controller's last references, which the recorder never got
        return np.full(len(wanted), -1)
    order = np.argsort(stamps, kind='stable')
    ordered = stamps[order]
    last = np.append(ordered[1:] != ordered[:-1], True)
    unique, index = ordered[last], order[last]
    at = np.minimum(np.searchsorted(unique, wanted), len(unique) - 1)
    return np.where(unique[at] == wanted, index[at], -1)


class _BlockPairing:
    """:class:`_StepPairing` for decoded arrays of many messages at once: the same pairing (by order, and by
    stamp within PAIRING_LAG steps), holding only the steps not yet complete."""

    def __init__(self, log: FlightLog, use_truth: bool, arm_length: float):
        self.log, self.use_truth, self.arm_length = log, use_truth, arm_length
        self.wrench_stamps, self.controls = np.empty(0, np.int64), np.empty((0, 4))
        self.forces, self.diagnostics = np.empty((0, 4)), None
        self.state_stamps, self.states = np.empty(0, np.int64), np.empty((0, 12))
        self.reference_stamps, self.references = np.empty(0, np.int64), np.empty((0, 4))   # x, y, z [m], yaw
        self.counts = {'wrenches': 0, 'rotor_forces': 0, 'diagnostics': 0}
        self.skipped = 0

    def add(self, block: MessageBlock, found: dict) -> None:
        """Decode the contract messages of ``block`` and add the steps that are complete."""
        states = GROUND_TRUTH if self.use_truth else ODOM
        for spec, connections in found.items():
            for connection in connections:
                rows = block.rows(connection.id)
                if not len(rows):
                    continue
                if spec is states:
                    stamps, pose, twist = decode_odometry_rows(rows)
                    self.state_stamps = np.append(self.state_stamps, stamps)
                    self.states = np.vstack((self.states, states_from_odometry_rows(pose, twist)))
                elif spec is CONTROL_WRENCH:
                    stamps, wrench = decode_stamped_floats_rows(rows, 6, 'wrench')
                    d = self.arm_length
                    controls = np.column_stack((wrench[:, 2], wrench[:, 3] / d, wrench[:, 4] / d, wrench[:, 5]))
                    self.wrench_stamps = np.append(self.wrench_stamps, stamps)
                    self.controls = np.vstack((self.controls, controls))
                    self.counts['wrenches'] += len(rows)
                elif spec is CONTROL_REFERENCE:
                    stamps, pose = decode_stamped_floats_rows(rows, 7, 'pose')
                    reference = np.column_stack((pose[:, :3], yaws_from_quaternions(pose[:, 3:])))
                    self.reference_stamps = np.append(self.reference_stamps, stamps)
                    self.references = np.vstack((self.references, reference))
                elif spec is ROTOR_FORCES:
                    forces = decode_multi_array_rows(rows, 'rotor_forces')
                    if forces.shape[1] != 4:
                        raise ValueError(f'rotor_forces: expected 4 values, got {forces.shape[1]}')
                    self.forces = np.vstack((self.forces, forces))
                    self.counts['rotor_forces'] += len(rows)
                elif spec is CONTROL_DIAGNOSTICS:
                    values = decode_multi_array_rows(rows, 'control/diagnostics')
                    if values.shape[1] not in (18, 6 * len(DIAGNOSTIC_QUANTITIES)):
                        raise ValueError(f'control/diagnostics: expected 18 or {6 * len(DIAGNOSTIC_QUANTITIES)} '
                                         f'values, got {values.shape[1]}')
                    width = values.shape[1] // 6
                    kept = np.hstack((values[:, 0::width], values[:, 1::width], values[:, 2::width]))
                    self.diagnostics = kept if self.diagnostics is None else np.vstack((self.diagnostics, kept))
                    self.counts['diagnostics'] += len(rows)
        self.pair()

    def pair(self, final: bool = False) -> None:
        """Add the steps whose messages have all come (with ``final``: every step that can be paired)."""
        diagnostics = 0 if self.diagnostics is None else len(self.diagnostics)
        count = min(len(self.wrench_stamps), len(self.forces), diagnostics)
        if not final:
            count = min(count, len(self.wrench_stamps) - PAIRING_LAG)
        if count <= 0:
            return
        stamps = self.wrench_stamps[:count]
        state_at, reference_at = (_latest_index(self.state_stamps, stamps),
                                  _latest_index(self.reference_stamps, stamps))
        whole = (state_at >= 0) & (reference_at >= 0)
        self.skipped += int(np.count_nonzero(~whole))
        state_at, reference_at = state_at[whole], reference_at[whole]
        if len(state_at):
            self.log.add_rows(np.hstack((self.state_stamps[state_at, None] / 1e9, self.states[state_at],
                                         self.references[reference_at], self.forces[:count][whole],
                                         self.controls[:count][whole], self.diagnostics[:count][whole])))
        self.wrench_stamps, self.controls = self.wrench_stamps[count:], self.controls[count:]
        self.forces, self.diagnostics = self.forces[count:], self.diagnostics[count:]
        paired = stamps.max()         # no later wrench pairs with these (as _StepPairing)
        later = self.state_stamps > paired
        self.state_stamps, self.states = self.state_stamps[later], self.states[later]
        later = self.reference_stamps > paired
        self.reference_stamps, self.references = self.reference_stamps[later], self.references[later]

    notes = _StepPairing.notes


#: [bytes] bags larger than this (about two minutes of a flight) show a progress bar while read, unless told
PROGRESS_BYTES = 64 << 20


def _read_blocks(path: Path, bag: Path, namespace: str | None, params: VehicleParams, settle_time: float | None,
                 warnings: list, progress: bool | None, max_rows: int = MAX_ROWS) -> FlightLog:
    """:func:`_read_steps` of the finalized MCAP file ``path`` of ``bag``, decoded many messages at once;
    UnsupportedLayout or LayoutMismatch when the file or its messages are not in the layout that allows it."""
    connections, start, end = mcap_channels(path)
    found = _topic_connections(connections, namespace, bag)
    if any(len(matches) > 1 for matches in found.values()):
        raise UnsupportedLayout('a topic on several channels: their messages interleave by time')
    if settle_time is None:
        settle_time = default_settle_time((end - start) / 1e9)
    log = FlightLog(float(settle_time), params.F_min, params.F_max, max_rows)
    steps = _BlockPairing(log, any(c.msgcount for c in found[GROUND_TRUTH]), params.d)
    size = path.stat().st_size
    shown = size > PROGRESS_BYTES if progress is None else progress
    with tqdm(total=size, unit='B', unit_scale=True, desc=f'reading {bag.name}', disable=not shown,
              leave=False) as bar:
        for block in message_blocks(path, on_bytes=bar.update):
            steps.add(block, found)
        steps.pair(final=True)
    warnings.extend(steps.notes())
    return log


def fleet_namespaces(bag: str | Path) -> list[str]:
    """The vehicles' namespaces of a fleet's bag (custom data ``vehicles``); [] for one vehicle's bag."""
    check_bag_path(Path(bag))
    listed = read_custom_data(Path(bag)).get('vehicles', '')
    return [name for name in listed.split(',') if name]


def read_flight(bag: str | Path, *, namespace: str | None = None, vehicle_file: str | Path | None = None,
                settle_time: float | None = None, every_step: bool = False, progress: bool | None = None) -> Flight:
    """The flight recorded in ``bag`` (a :class:`~quad_msgs_bridge.review.flight_data.Flight`, the object
    ``flight_stack.api.fly`` returns); raises BagReadError if it lacks what a flight needs.

    ``namespace``, ``vehicle_file`` and ``settle_time`` [s] override what the bag says; without a
    settle time in either, :func:`~quad_msgs_bridge.review.metrics.default_settle_time` of the bag's
    span. Memory stays bounded however long the flight, unless ``every_step`` keeps a row for every control
    step (no thinning, see flight_data: about 0.5 kB per step): an MCAP bag of one file (ours, ``ros2 bag
    record -s mcap``) is read a block of chunks at a time, each block's messages decoded together as arrays
    (where a topic's messages share one layout; else, and for other storage, message by message). With
    ``progress`` (None: for a bag file over PROGRESS_BYTES) a progress bar on stderr shows the bytes read.
    Its ``summary`` is :func:`~quad_msgs_bridge.review.summary.bag_summary`: the keys of ``fly()``'s summary
    that the bag (or the run's summary.json beside it) gives; None, with a warning saying why, for a flight too short
    for metrics (no longer than its settling window). ParameterError if ``bag`` is not a path.
    """
    if not isinstance(bag, (str, os.PathLike)) or not str(bag).strip():
        raise ParameterError(f'read_flight: bag: expected the path of a bag folder or .mcap file (a str or Path), '
                             f'got {bag!r}')
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
    if settle_time is None and custom.get('settle_time_s'):
        settle_time = float(custom['settle_time_s'])
    try:
        max_rows = EVERY_STEP if every_step else MAX_ROWS
        log = None
        if has_mcap and (bag.is_file() or len(list(bag.glob('*.mcap'))) == 1):
            try:
                log = _read_blocks(mcap_file(bag), bag, namespace, params, settle_time, warnings, progress, max_rows)
            except (UnsupportedLayout, LayoutMismatch):
                pass          # read message by message instead
        if log is None:
            log = _read_steps(bag, namespace, params, settle_time, warnings, max_rows)
    except AnyReaderError as error:
        raise BagReadError(f'{bag}: not readable as a bag: {error}') from error
    if not log.steps:
        raise BagReadError(f'{bag}: no complete control step')
    flight = log.flight(params, label=custom.get('controller') or bag.name, path=bag, custom_data=custom,
                        warnings=warnings)
    flight.ended_early = flight.ending is not None
    try:
        flight.summary = bag_summary(flight)
    except ValueError as error:    # no metrics: e.g. a flight no longer than its settling window
        flight.warnings.append(f'no summary: {error}')
    return flight
