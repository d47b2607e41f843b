"""record node: writes what goes over the contract topics into a rosbag2 MCAP bag, at little cost to the flight.

Every subscription is raw: the recorder gets the serialized CDR bytes that the publisher sent and
writes them into the MCAP file as they are, never decoding or re-encoding a message. Each has its
topic's contract QoS, with a deeper history: the latched topics (``setpoints``, ``reference_path``,
each vehicle's ``robot_description`` and ``/tf_static``) are read transient local, so the recorder
gets their one message, sent as the trajectory and simulator nodes start, even where that was before
its subscription matched. It does not wake per message either: every ``ROUND_PERIOD`` it takes what
waits in every subscription's history (``RECORD_DEPTH`` deep, reliable); the MCAP chunks are
compressed and written by the file's background thread. A lockstep flight never waits for the
recorder (the simulator waits for the controllers only), so the recorder's cost to the flight is the
CPU it takes from the simulator and the controllers, and the DDS delivery to one more reader.

Each message has two times. The publish time is the wall time the publisher sent it (DDS source
timestamp). The log time is the sim time of the latest ``/clock`` published before it (0 before the
first one, as a ROS clock under ``use_sim_time`` reads; the publish time if ``/clock`` is not
recorded). So the recorder writes what it took in the order of the source timestamps (each topic in
its own order), and holds a message until every per-step topic (``PER_STEP_TOPICS``: ``/clock``,
odom, the controllers' answers) that has delivered anything has delivered a message published after
it: a publisher's messages arrive in order, so nothing published before it can still come on those
topics. It holds a message ``HOLD_NS`` at least (for the other topics) and ``WAIT_LIMIT_NS`` at most
(a topic whose publisher stopped holds nothing longer). On a busy machine DDS repaired a message
560 ms late here, and a starved recorder took a controller's answer 200 ms after the simulator's
later ``/clock`` messages. So a control step's odometry is logged at its stamp, the controller's
answers at that stamp or, where the simulator's next ``/clock`` went out before them, at the next
one. Log times never decrease while /clock does not.

Nothing is lost unnoticed: each publisher numbers its messages (DDS publication sequence number),
and a gap in what the recorder took is counted, reported at the end, stored in the bag metadata
(``custom_data.lost_messages``) and makes the recorder exit 1. Where the RMW does not report those
numbers (rmw_cyclonedds_cpp in Jazzy) losses cannot be counted: the recorder says so once and stores
``custom_data.loss_check: unavailable``.

One recorder records a fleet: the contract topics of every vehicle of ``vehicles`` (namespaces
relative to the node's, by default its own), ``/clock`` and ``/tf`` once. Per-step topics published
by the controllers must be matched before ``odom`` is subscribed: a lockstep simulator that waits
for the recorder's ``odom`` subscriptions then starts only when nothing of the flight can be missed.
SIGINT/SIGTERM stop it cleanly: everything still arriving is taken and the bag is finalized. A
killed recorder leaves a bag readable up to its last complete chunk (``recover`` finalizes it).
"""
from __future__ import annotations

import bisect
import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import (CLOCK, ODOM, PER_STEP_TOPICS, RECORDED_TOPICS, SIMULATOR_TOPICS, TopicSpec,
                                       resolve_all, vehicle_namespaces)
from quad_msgs_bridge.conversions import MessageKit, rclpy_kit
from quad_msgs_bridge.bag.flight_bag import ros_flight_custom_data
from quad_msgs_bridge.ros_helpers import declare, init_ros, qos_profile
from quad_msgs_bridge.runtime import freeze_long_lived_objects
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

RECORD_DEPTH = 10000     #: reader history per topic: rounds ROUND_PERIOD apart never let it overflow
ROUND_PERIOD = 0.01      #: [s, wall] the recorder takes what waits this often
HOLD_NS = 500_000_000    #: [ns, wall] a message is written once it was published this long ago (a message
                         #: of another topic published before it may still be on its way) and every per-step
                         #: topic delivered one published after it ...
WAIT_LIMIT_NS = 5 * HOLD_NS   #: [ns, wall] ... or once it was published this long ago
SPIN_PERIOD = 0.05       #: [s, wall] timers, services and discovery are served this often
QUIET_TIME = 0.3         #: [s, wall] after SIGINT/SIGTERM, stop once nothing has arrived for this long

def _clock_ns(cdr: bytes) -> int:
    """Sim time [ns] of a rosgraph_msgs/Clock in CDR: 4-byte encapsulation header, int32 sec, uint32 nanosec."""
    return int.from_bytes(cdr[4:8], 'little', signed=True) * NANOSECONDS_PER_SECOND + \
        int.from_bytes(cdr[8:12], 'little')


class RecorderNode(Node):
    def __init__(self, kit: MessageKit):
        super().__init__('recorder')
        bag = declare(self, 'bag', '', 'bag directory to create (required)')
        topic_names = declare(self, 'topics', [t.name for t in RECORDED_TOPICS], 'contract topics to record')
        overwrite = declare(self, 'overwrite', False, 'replace an existing bag at the same path')
        labels = {key: declare(self, key, '', f'{key} stored in the bag metadata')
                  for key in ('controller', 'scenario', 'disturbances')}
        seed = declare(self, 'seed', 0, 'NN seed of the flight, stored in the bag metadata', (0, 2 ** 31 - 1))
        settle_time = declare(self, 'settle_time', 5.0, 'metrics settling window stored in the bag [s]', (0.0, 1e6))
        vehicle_file = declare(self, 'vehicle_file', '', 'vehicle YAML of the flight; empty: the packaged one')
        names = declare(self, 'vehicles', [''], "namespaces of the recorded vehicles, relative to the node's "
                        "('': its own, the default; a leading / makes one absolute)")
        params, _ = load_vehicle_file(vehicle_file or None)
        if not bag:
            raise ParameterError('parameter bag: a bag directory is required')
        known = {t.name: t for t in RECORDED_TOPICS}
        unknown = [n for n in topic_names if n not in known]
        if unknown:
            raise ParameterError(f'parameter topics: {unknown} are not contract topics ({", ".join(known)})')
        self.topics = [known[n] for n in topic_names if self.type_installed(kit, known[n])]
        self.namespaces = vehicle_namespaces(self.get_namespace(), names)
        custom = ros_flight_custom_data(params, settle_time, seed, self.namespaces, **labels)
        self.writer = BagWriter(bag, self.topics, self.namespaces, custom_data=custom, overwrite=overwrite)
        self.kit = kit
        self.clock_ns: int | None = 0 if CLOCK in self.topics else None    #: sim time of the latest /clock [ns]
        self.received = 0
        self.lost = 0                                 #: messages missing between publication sequence numbers
        self.numbered = True                          #: whether the RMW reports publication sequence numbers
        self._sequences: dict[tuple, int] = {}        #: (topic, publisher gid) -> last publication sequence number
        self._recorded: list[tuple] = []              #: (name, is_clock, subscription handle, type, delivered)
        self._readers: dict[str, object] = {}        #: topic -> its subscription
        self._published: dict[str, int] = {}          #: topic -> source timestamp of its latest message [ns]
        self._per_step = [name for name, topic in resolve_all(self.topics, self.namespaces)
                          if topic in PER_STEP_TOPICS]
        self._waiting: list[tuple] = []               #: taken, not yet written, in the order of publication
        self._arrivals = 0
        for name, topic in resolve_all(self.topics, self.namespaces):
            if topic is not ODOM:
                self.subscribe(name, topic)
        self.gate = self.create_timer(0.02, self.open_gate) if ODOM in self.topics else None
        self.get_logger().info(f'recording {len(self.topics)} topics of {", ".join(self.namespaces)} into {bag}')

    def type_installed(self, kit: MessageKit, topic: TopicSpec) -> bool:
        """Whether the message type of ``topic`` is installed (tf2_msgs may not be); if not, say so."""
        try:
            kit[topic.type]
        except ImportError as error:
            self.get_logger().warning(f'{topic.type} is not installed ({error}): {topic.name} is not recorded')
            return False
        return True

    def subscribe(self, name: str, topic: TopicSpec) -> None:
        """Record ``topic`` under its absolute ``name``: a raw subscription that the rounds take from."""
        qos = qos_profile(topic.qos)
        profile = QoSProfile(history=qos.history, depth=max(qos.depth, RECORD_DEPTH),
                             reliability=qos.reliability, durability=qos.durability)
        delivered: list = []   # what the executor hands over between rounds (when it spins for timers)
        subscription = self.create_subscription(self.kit[topic.type], name,
                                                lambda data, info: delivered.append((data, info)), profile, raw=True)
        self._readers[name] = subscription
        entry = (name, topic is CLOCK, subscription.handle, subscription.msg_type, delivered)
        # /clock first: of messages with the same source timestamp, a /clock is taken to come first
        self._recorded.insert(0 if topic is CLOCK else len(self._recorded), entry)

    def take_round(self) -> int:
        """Take every message waiting in any subscription; write, in the order they were published, those that
        nothing can precede any more (see the module docstring). Returns how many messages were taken."""
        taken = self.take()
        now = time.time_ns()
        # a publisher's messages arrive in order: on each per-step topic, all published before its latest are here
        latest = [self._published[name] for name in self._per_step if name in self._published]
        self.write_held(max(min(latest + [now - HOLD_NS]), now - WAIT_LIMIT_NS))
        return taken

    def take(self) -> int:
        """Take every message waiting in any subscription into the held messages; returns how many."""
        waiting, taken = self._waiting, 0
        for name, is_clock, handle, msg_type, delivered in self._recorded:
            messages = delivered[:]
            delivered.clear()
            while (message := handle.take_message(msg_type, True)) is not None:
                messages.append(message)
            if not messages:
                continue
            published = self._published.get(name, 0)
            order = 0 if is_clock else 1      # of messages published at the same instant, /clock comes first
            for data, info in messages:
                self.check_sequence(name, info)
                # never earlier than the topic's previous message: each topic keeps its own order
                published = max(published, info['source_timestamp'] or info['received_timestamp'])
                waiting.append((published, order, self._arrivals, name, is_clock, data))
                self._arrivals += 1
            self._published[name] = published
            taken += len(messages)
        if taken:
            waiting.sort()
        return taken

    def write_held(self, published_until: float) -> None:
        """Write the held messages published until ``published_until`` [ns, wall], in the order of publication."""
        waiting = self._waiting
        ready = bisect.bisect_right(waiting, (published_until, 2))   # 2: after every order of that instant
        if not ready:
            return
        write = self.writer.write_serialized
        for published, _, _, name, is_clock, data in waiting[:ready]:
            if is_clock:
                self.clock_ns = _clock_ns(data)
            write(name, data, published if self.clock_ns is None else self.clock_ns, published)
        del waiting[:ready]
        self.received += ready

    def check_sequence(self, name: str, info: dict) -> None:
        """Count the messages missing before this one of its publisher (a gap in its sequence numbers)."""
        sequence, publisher = info.get('publication_sequence_number'), info.get('publisher_gid')
        if sequence is None or publisher is None:   # an rmw that does not number its messages
            if self.numbered:
                self.numbered = False
                self.get_logger().warning('this RMW reports no publication sequence numbers: lost messages '
                                          'cannot be counted')
            return
        key = (name, publisher['data'])
        last = self._sequences.get(key)
        if last is not None and sequence > last + 1:
            self.lost += sequence - last - 1
        self._sequences[key] = sequence

    def open_gate(self) -> None:
        """Subscribe to every odom once this recorder's subscription to every recorded per-step topic of the
        controllers has matched a publisher, and each to a simulator topic that has a discovered publisher has
        matched it. Matched on the recorder's own side, not merely discovered (the ROS graph): a reader drops
        what a writer sends before the reader has matched that writer (seen across DDS vendors)."""
        for name, topic in resolve_all([t for t in self.topics if t.qos.durability == 'volatile' and t is not ODOM],
                                       self.namespaces):
            awaited = self.count_publishers(name) > 0 if topic in SIMULATOR_TOPICS else True
            if awaited and self._readers[name].get_publisher_count() == 0:
                return
        self.gate.cancel()
        for name, _ in resolve_all([ODOM], self.namespaces):
            self.subscribe(name, ODOM)
        self.get_logger().info('controller publishers matched; recording odom')

    def finish(self) -> None:
        """Write what is still held, finalize the bag (with the count of lost messages, if any), say what it holds."""
        if self.context.ok():
            self.take()
        self.write_held(float('inf'))
        if self.lost:
            self.writer.custom_data['lost_messages'] = str(self.lost)
        if not self.numbered:
            self.writer.custom_data['loss_check'] = 'unavailable: the RMW reports no publication sequence numbers'
        self.writer.close()
        lost = f', {self.lost} LOST (gaps in the publishers\' sequence numbers)' if self.lost else ''
        print(f'recorder: {self.received} messages written to {self.writer.path}{lost}', flush=True)


def main(argv: list[str] | None = None) -> int:
    """Take what waits every ROUND_PERIOD (see :meth:`RecorderNode.take_round`) until SIGINT/SIGTERM, then
    until nothing has arrived for QUIET_TIME, and finalize the bag; exit 1 if messages were lost."""
    signals = init_ros(argv)
    node = None
    try:
        node = RecorderNode(rclpy_kit())
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        freeze_long_lived_objects()     # no long garbage-collector pause while the flight runs
        next_spin = time.monotonic()
        stopping_since = None    # wall time of the signal, then of the latest message after it
        while executor.context.ok():
            time.sleep(ROUND_PERIOD)
            now = time.monotonic()
            if now >= next_spin:
                executor.spin_once(timeout_sec=0.0)
                next_spin = now + SPIN_PERIOD
            taken = node.take_round()
            if signals:
                if stopping_since is None or taken:
                    stopping_since = now
                elif now - stopping_since >= QUIET_TIME:
                    break
    except ParameterError as error:
        print(f'[FATAL] invalid parameter: {error}', file=sys.stderr, flush=True)
        return 2
    finally:
        if node is not None:
            node.finish()
            node.destroy_node()
        rclpy.try_shutdown()
    return 1 if node is not None and node.lost else 0


if __name__ == '__main__':
    raise SystemExit(main())
