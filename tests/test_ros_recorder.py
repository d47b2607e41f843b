"""The ROS recorder: raw bytes into the bag, log times in sim time, lost messages counted, a killed recording
readable (skipped without rclpy)."""
from __future__ import annotations

import signal
import threading
import time
from collections import defaultdict
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from ros_support import HAVE_RCLPY, node_process, requires_ros, spin_until
from hang_guard import HANG_TIMEOUT_S

pytestmark = [requires_ros, pytest.mark.ros]

if HAVE_RCLPY:
    import rclpy
    from rclpy.serialization import deserialize_message, serialize_message

    from quad_msgs_bridge.ros_helpers import subscription

from flight_stack.fleet import FleetVehicle
from flight_stack.processes import stop_all
from quad_msgs_bridge.bag.metadata import read_metadata
from quad_msgs_bridge.bag.reader import mcap_file
from quad_msgs_bridge.bag.recover import recover
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.contract import (CLOCK, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, LOCKSTEP, ODOM,
                                       RECORDED_TOPICS, ROTOR_FORCES, resolve_all)
from quad_msgs_bridge.conversions import rclpy_kit
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND
from nnit2fsmc_controller.trajectory import Hover

PER_STEP = (ODOM, ROTOR_FORCES, CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS, CLOCK)
STEP_NS = 1_000_000   #: [ns] one control step at the default 1 kHz


def bag_messages(bag: Path) -> dict[str, list]:
    """{topic: [mcap Message, ...]} in the file's order, read with the mcap package's reader."""
    messages = defaultdict(list)
    with open(mcap_file(bag), 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages(log_time_order=False):
            messages[channel.topic].append(message)
    return messages


def stamp_ns(cdr: bytes) -> int:
    """Stamp of a CDR message that begins with a std_msgs/Header or is a rosgraph_msgs/Clock."""
    return int.from_bytes(cdr[4:8], 'little', signed=True) * NANOSECONDS_PER_SECOND + \
        int.from_bytes(cdr[8:12], 'little')


@pytest.mark.parametrize('record_by', ['recorder', 'publishers'])
def test_a_recorded_flight_holds_exactly_the_bytes_that_were_published(ros_node, tmp_path, record_by):
    """Beside the bag's writer (the record node, or the nodes' own publication logs merged after the flight),
    this test subscribes to every recorded topic twice: raw (the bytes as sent) and the usual way (decoded
    messages). The bag holds the sent bytes, byte for byte, in order, and nothing is missing; decoded, they are
    the messages the decoding subscriber got. (Decoding and serializing again with rclpy on Fast DDS would not
    give the sent bytes back: its serializer leaves alignment padding uninitialised, which this test shows
    too.) Log times are the sim time of the step a message belongs to."""
    from flight_stack.ros_backend import RosFlightConfig, fly_ros

    # fewer steps than the publishers' history: this node's readers, which the lockstep does not wait for, can fall
    # any number of steps behind without losing one (on a loaded CI machine, 2,000 steps lost some of each topic)
    namespace, duration = 'rawcheck', 0.8
    assert duration * 1000 < LOCKSTEP.depth
    kit = rclpy_kit()
    topics = [t for t in RECORDED_TOPICS if t.name not in ('/tf', '/tf_static') or _installed('tf2_msgs')]
    sent: dict[str, list] = {}
    decoded: dict[str, list] = {}

    readers = {}

    def subscribe(name, topic):   # a history for the whole flight: the lockstep does not wait for this node
        sent[name], decoded[name] = [], []
        readers[name] = [subscription(ros_node, kit, topic, sent[name].append, raw=True, depth=100_000,
                                      namespace=namespace),
                         subscription(ros_node, kit, topic, decoded[name].append, depth=100_000, namespace=namespace)]

    for name, topic in resolve_all(topics, ['/' + namespace]):
        if topic is not ODOM:
            subscribe(name, topic)
    result = []
    flight = threading.Thread(target=lambda: result.append(fly_ros(RosFlightConfig(
        vehicles=[FleetVehicle(namespace)], controller='nnit2fsmc', scenario='paper', duration=duration,
        disturbances=True, seed=0, physics_rate=1000.0, control_rate=1000.0, bag=tmp_path / 'bag',
        topics=[t.name for t in topics], quiet=True, extra_recorders=2, record_by=record_by))))
    flight.start()
    # odom last, as the recorder does: the simulator starts once this node's odom subscriptions are there, and by
    # then this node's reader of every other per-step topic must have matched its publisher, or it misses the
    # first messages (a CI run on the wheels got 93 rotor_forces fewer than the bag when it waited for discovery)
    others = [name for name, topic in resolve_all(topics, ['/' + namespace])
              if topic.qos.durability == 'volatile' and topic is not ODOM]
    assert spin_until(ros_node, lambda: all(reader.get_publisher_count() for name in others
                                            for reader in readers[name]), timeout=HANG_TIMEOUT_S)
    subscribe(f'/{namespace}/odom', ODOM)
    spin_until(ros_node, lambda: not flight.is_alive(), timeout=HANG_TIMEOUT_S)
    flight.join()
    steps = round(duration * 1000)
    odom = f'/{namespace}/odom'
    per_step = [name for name, _ in resolve_all(PER_STEP, ['/' + namespace])]
    per_step += ['/tf'] if '/tf' in sent else []     # one transform message per step too, where TF exists
    got_all = spin_until(ros_node, lambda: min(len(got[name]) for got in (sent, decoded) for name in per_step)
                         >= steps, timeout=HANG_TIMEOUT_S)
    assert got_all, {name: (len(sent[name]), len(decoded[name])) for name in per_step}
    [flown] = result
    assert flown.failed_node is None, flown

    in_bag = bag_messages(tmp_path / 'bag')
    assert set(in_bag) == set(sent)
    reencoded_differ = 0
    for name, messages in sent.items():
        recorded = [m.data for m in in_bag[name]]
        assert recorded == messages, f'{name}: the bag does not hold the bytes that were sent'
        msg_type = type(decoded[name][0])
        assert [deserialize_message(data, msg_type) for data in recorded] == decoded[name], name
        reencoded_differ += sum(serialize_message(msg) != data for msg, data in zip(decoded[name], recorded))
    if rclpy.get_rmw_implementation_identifier() == 'rmw_fastrtps_cpp':
        # Fast DDS' serializer leaves alignment padding uninitialised: the decode-and-serialize path would have
        # changed bytes (Cyclone DDS' zeroes it, and gives the sent bytes back)
        assert reencoded_differ > 0
    for name, topic in resolve_all(PER_STEP, ['/' + namespace]):
        assert len(in_bag[name]) == steps, name
    assert 'lost_messages' not in read_metadata(tmp_path / 'bag')['custom_data']
    # the simulator's latched description of the vehicle: its one message, logged at the flight's start (sim time 0)
    described = [f'/{namespace}/robot_description'] + (['/tf_static'] if '/tf_static' in sent else [])
    assert [(len(in_bag[name]), in_bag[name][0].log_time) for name in described] == [(1, 0)] * len(described)

    # /clock and odom are logged at their own stamp; the controller's answers at the step they answer or, by the
    # recorder, where the simulator's next /clock went out before them, at the next one
    for name in ('/clock', odom, f'/{namespace}/control/wrench', f'/{namespace}/control/reference'):
        late = [m.log_time - stamp_ns(m.data) for m in in_bag[name]]
        assert set(late) <= ({0, STEP_NS} if name not in ('/clock', odom) and record_by == 'recorder' else {0}), name
    log_times = [m.log_time for messages in in_bag.values() for m in messages]
    with open(mcap_file(tmp_path / 'bag'), 'rb') as stream:
        in_file_order = [m.log_time for _, _, m in make_reader(stream).iter_messages(log_time_order=False)]
    assert in_file_order == sorted(log_times)   # written in log-time order


def recorded_hover(namespace: str, bag: Path, sim_params: dict) -> list:
    """The recorder (into ``bag``), a hover trajectory, the controller and the simulator (``sim_params`` beside the
    hover's initial state) of ``namespace``, each in its own process, on the wall clock; the recorder first."""
    return [
        node_process('recorder', 'quad_msgs_bridge.bag.recorder_node', namespace, {'bag': str(bag)}),
        node_process('trajectory', 'nnit2fsmc_controller.trajectory_node', namespace,
                     {'use_sim_time': False, 'scenario': 'hover', 'start_time': 0.0}),
        node_process('controller', 'nnit2fsmc_controller.controller_node', namespace, {'use_sim_time': False}),
        node_process('sim', 'quad_sim.sim_node', namespace, {'initial_state': Hover().initial_state, **sim_params}),
    ]


def test_a_killed_recorder_leaves_a_readable_prefix_of_the_flight(tmp_path):
    """SIGKILL the recorder process mid-flight: after ``recover``, rosbags reads the bag, and what it holds is the
    flight's beginning without a hole: every odometry step from the first, each per-step topic up to where the bag
    was cut."""
    namespace = 'killedrec'
    bag = tmp_path / 'bag'
    processes = recorded_hover(namespace, bag, {'duration': 600.0, 'wait_for_subscribers': 2})
    recorder = processes[0]
    try:
        deadline = time.monotonic() + HANG_TIMEOUT_S
        while time.monotonic() < deadline and mcap_size(bag) < 2 ** 20:   # chunks of 1 MiB before compression
            assert recorder.returncode is None, '\n'.join(recorder.lines)
            time.sleep(0.2)
        assert mcap_size(bag) >= 2 ** 20, 'the recording did not grow'
        recorder.process.kill()
        assert recorder.process.wait(timeout=HANG_TIMEOUT_S) == -9
    finally:
        codes = stop_all(processes[1:])
    assert all(code == 0 for code in codes.values()), codes

    recovered = recover(bag)
    assert recovered.messages > 0
    typestore = jazzy_typestore()
    counts: dict[str, int] = defaultdict(int)
    odometry_stamps = []
    with AnyReader([bag], default_typestore=typestore) as reader:
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)     # every message decodes
            counts[connection.topic] += 1
            if connection.topic == f'/{namespace}/odom':
                odometry_stamps.append(message.header.stamp.sec * NANOSECONDS_PER_SECOND
                                       + message.header.stamp.nanosec)
    steps = len(odometry_stamps)
    assert steps > 1000
    assert odometry_stamps == [k * STEP_NS for k in range(steps)]     # from the first step, no hole
    # written in the order of publication, the bag is cut at one message of the lockstep's order: odom k, rotor_forces
    # k, then odom k+1 (after the forces) and the controller's other answers to k (before its forces k+1) in any order
    answers = {CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS}
    for name, topic in resolve_all(PER_STEP, ['/' + namespace]):
        behind = 2 if topic in answers else 1
        assert steps - behind <= counts[name] <= steps + 1, (name, counts[name], steps)
    assert read_metadata(bag)['message_count'] == sum(counts.values())


def test_a_recorder_behind_at_the_end_of_a_flight_still_gets_every_step(ros_node, tmp_path):
    """A simulator that ends its flight (``exit_at_end``) waits for the recorder to acknowledge its last steps
    before it exits and takes them away, even when the recorder is seconds behind (a loaded machine starved one
    by 2 s): the recorder is frozen (SIGSTOP) from the flight's first step until 3 s after the simulator reached
    its end, then resumes; the bag holds every step of every per-step topic, nothing is counted lost."""
    namespace, steps = 'behindrec', 600
    bag = tmp_path / 'bag'
    first_step = []
    subscription(ros_node, rclpy_kit(), ODOM, first_step.append, namespace=namespace)
    processes = recorded_hover(namespace, bag, {'duration': steps / 1000.0, 'exit_at_end': True,
                                                'wait_for_subscribers': 3})
    recorder, sim = processes[0], processes[3]
    try:
        assert spin_until(ros_node, lambda: first_step, timeout=HANG_TIMEOUT_S), '\n'.join(sim.lines)
        recorder.process.send_signal(signal.SIGSTOP)
        assert wait_for_line(sim, 'reached duration', HANG_TIMEOUT_S), '\n'.join(sim.lines)
        time.sleep(3.0)                                  # longer than a node stopped by a signal waits
        assert sim.returncode is None, 'the simulator left before the recorder acknowledged its last steps'
        recorder.process.send_signal(signal.SIGCONT)
        assert sim.process.wait(timeout=HANG_TIMEOUT_S) == 0, '\n'.join(sim.lines)
    finally:
        recorder.process.send_signal(signal.SIGCONT)
        codes = stop_all(processes[1:])                  # the recorder last, as flight_stack.ros_backend does:
        codes.update(stop_all(processes[:1], grace=30.0))  # it drains what the others still send
    assert all(code == 0 for code in codes.values()), codes
    unacknowledged = [line for process in processes for line in process.lines if 'not acknowledged' in line]
    assert not unacknowledged, unacknowledged
    counts = {name: len(messages) for name, messages in bag_messages(bag).items()}
    for name, _ in resolve_all(PER_STEP, ['/' + namespace]):
        assert counts.get(name) == steps, (name, counts.get(name), steps)
    assert 'lost_messages' not in read_metadata(bag)['custom_data']


def wait_for_line(process, text: str, timeout: float) -> bool:
    """Whether ``process`` printed a line containing ``text`` within ``timeout`` [s, wall] (False if it ended)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.returncode is None:
        if any(text in line for line in process.lines):
            return True
        time.sleep(0.05)
    return any(text in line for line in process.lines)


def mcap_size(bag: Path) -> int:
    files = list(bag.glob('*.mcap'))
    return files[0].stat().st_size if files else 0


def _installed(module: str) -> bool:
    import importlib.util
    return importlib.util.find_spec(module) is not None


# --- a round of the recorder, on given messages --------------------------------------------------------------

class QueuedHandle:
    """Stands in for a subscription handle: take_message hands out the queued (data, info) pairs."""

    def __init__(self, messages):
        self.messages = list(messages)

    def take_message(self, msg_type, raw):
        assert raw
        return self.messages.pop(0) if self.messages else None


def info(published: int, sequence: int, publisher: bytes = b'p') -> dict:
    return {'source_timestamp': published, 'received_timestamp': published + 5,
            'publication_sequence_number': sequence, 'publisher_gid': {'data': publisher}}


def test_a_round_merges_by_publish_time_logs_at_the_latest_clock_and_counts_gaps(tmp_path):
    """Messages taken in one round are written in the order they were published (each topic in its own order),
    at the sim time of the /clock published before each, once a /clock published after them has come; a gap in a
    publisher's sequence numbers is counted."""
    from quad_msgs_bridge.bag.recorder_node import RecorderNode
    from quad_msgs_bridge.fast_cdr import clock_encoder

    rclpy.init(args=['--ros-args', '-r', '__ns:=/roundcheck', '-p', f'bag:={tmp_path / "bag"}',
                     '-p', 'topics:=["rotor_forces", "/clock"]'])
    node = None
    try:
        node = RecorderNode(rclpy_kit())
        clock = clock_encoder()
        forces = [b'forces-%d' % k for k in range(4)]
        handles = {'/clock': QueuedHandle([(clock(1, 0), info(100, 1)), (clock(2, 0), info(200, 2))]),
                   '/roundcheck/rotor_forces': QueuedHandle([(forces[0], info(50, 7, b'c')),
                                                             (forces[1], info(150, 8, b'c')),
                                                             (forces[2], info(250, 11, b'c')),
                                                             (forces[3], info(260, 1, b'other'))])}
        node._recorded = [(name, is_clock, handles[name], msg_type, delivered)
                          for name, is_clock, _, msg_type, delivered in node._recorded]
        assert node.take_round() == 6
        assert node.take_round() == 0
        assert node.lost == 2                        # 9 and 10 of publisher c never arrived
        assert node.received == 6
        # a message published 2 s ago, after the latest /clock taken, waits for a /clock published after it
        late_forces, late_clock = time.time_ns() - 2 * NANOSECONDS_PER_SECOND, time.time_ns() - 1_900_000_000
        handles['/roundcheck/rotor_forces'].messages.append((b'forces-4', info(late_forces, 12, b'c')))
        assert node.take_round() == 1 and node.received == 6
        handles['/clock'].messages.append((clock(3, 0), info(late_clock, 3)))
        assert node.take_round() == 1 and node.received == 7
        node.finish()                                # the rest is written at the end
        assert node.received == 8
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    with open(mcap_file(tmp_path / 'bag'), 'rb') as stream:
        written = [(channel.topic, message.log_time, message.publish_time, message.data)
                   for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]
    second = NANOSECONDS_PER_SECOND
    forces_topic = '/roundcheck/rotor_forces'
    assert written == [(forces_topic, 0, 50, forces[0]), ('/clock', second, 100, clock(1, 0)),
                       (forces_topic, second, 150, forces[1]), ('/clock', 2 * second, 200, clock(2, 0)),
                       (forces_topic, 2 * second, 250, forces[2]), (forces_topic, 2 * second, 260, forces[3]),
                       (forces_topic, 2 * second, late_forces, b'forces-4'),
                       ('/clock', 3 * second, late_clock, clock(3, 0))]
    assert read_metadata(tmp_path / 'bag')['custom_data']['lost_messages'] == '2'
    assert 'loss_check' not in read_metadata(tmp_path / 'bag')['custom_data']


def test_a_late_answer_is_logged_at_its_step_though_later_clocks_were_taken_first(tmp_path):
    """A starved recorder may take the simulator's later /clock messages before a controller's answer that was
    published between them (the answer came 200 ms late under load): the clocks after it wait until the
    answer's topic has brought something published after them, so the answer is logged at its own step."""
    from quad_msgs_bridge.bag.recorder_node import RecorderNode
    from quad_msgs_bridge.fast_cdr import clock_encoder

    rclpy.init(args=['--ros-args', '-r', '__ns:=/latecheck', '-p', f'bag:={tmp_path / "bag"}',
                     '-p', 'topics:=["rotor_forces", "/clock"]'])
    node = None
    ms = 1_000_000
    try:
        node = RecorderNode(rclpy_kit())
        clock = clock_encoder()
        start = time.time_ns() - 2 * NANOSECONDS_PER_SECOND    # within WAIT_LIMIT_NS: held messages may wait
        handles = {'/clock': QueuedHandle([(clock(1, 0), info(start, 1)), (clock(2, 0), info(start + 100 * ms, 2)),
                                           (clock(3, 0), info(start + 200 * ms, 3))]),
                   '/latecheck/rotor_forces': QueuedHandle([(b'answer-1', info(start + 50 * ms, 1))])}
        node._recorded = [(name, is_clock, handles[name], msg_type, delivered)
                          for name, is_clock, _, msg_type, delivered in node._recorded]
        assert node.take_round() == 4
        assert node.received == 2                    # clock 1 and answer 1; clock 2 may still have answers before it
        handles['/latecheck/rotor_forces'].messages.append((b'answer-1-late', info(start + 60 * ms, 2)))
        assert node.take_round() == 1
        assert node.received == 3
        node.finish()
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    with open(mcap_file(tmp_path / 'bag'), 'rb') as stream:
        logged = [(channel.topic, message.log_time) for _, channel, message in
                  make_reader(stream).iter_messages(log_time_order=False)]
    second = NANOSECONDS_PER_SECOND
    assert logged == [('/clock', second), ('/latecheck/rotor_forces', second), ('/latecheck/rotor_forces', second),
                      ('/clock', 2 * second), ('/clock', 3 * second)]


def test_without_sequence_numbers_the_bag_says_losses_were_not_counted(tmp_path):
    """An RMW that reports no publication sequence numbers (rmw_cyclonedds_cpp in Jazzy) leaves the recorder
    unable to count losses: the bag metadata says so (``loss_check``) instead of looking complete."""
    from quad_msgs_bridge.bag.recorder_node import RecorderNode
    from quad_msgs_bridge.fast_cdr import clock_encoder

    rclpy.init(args=['--ros-args', '-r', '__ns:=/unnumbered', '-p', f'bag:={tmp_path / "bag"}',
                     '-p', 'topics:=["/clock"]'])
    node = None
    try:
        node = RecorderNode(rclpy_kit())
        unnumbered = {'source_timestamp': 100, 'received_timestamp': 105, 'publication_sequence_number': None,
                      'publisher_gid': {'data': b'p'}}
        node._recorded = [(name, is_clock, QueuedHandle([(clock_encoder()(1, 0), unnumbered)]), msg_type, delivered)
                          for name, is_clock, _, msg_type, delivered in node._recorded]
        assert node.take_round() == 1
        node.finish()
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    custom = read_metadata(tmp_path / 'bag')['custom_data']
    assert custom['loss_check'].startswith('unavailable') and 'lost_messages' not in custom
