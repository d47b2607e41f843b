"""record node: writes what goes over the contract topics into a rosbag2 MCAP bag.

Messages are recorded as the serialized CDR bytes that arrived, with two times: the log time is
the sim time of the latest ``/clock`` the recorder had taken when it took the message (0 before the
first one, as a ROS clock under ``use_sim_time`` reads; wall time if ``/clock`` is not recorded;
it takes what waits in rounds, ``/clock`` first, so log times never decrease), the publish time is
the wall time the publisher sent it (DDS source timestamp), so a bag shows both the flight in sim
time and the real message latencies.

One recorder records a fleet: the contract topics of every vehicle of ``vehicles`` (namespaces
relative to the node's, by default its own), ``/clock`` and ``/tf`` once. Per-step topics published
by the controllers must be discovered before ``odom`` is subscribed: a lockstep simulator that waits
for the recorder's ``odom`` subscriptions then starts only when nothing of the flight can be missed.
SIGINT/SIGTERM stop it cleanly: everything already received is drained and the bag is finalized.
"""
from __future__ import annotations

import sys
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile

from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import (CLOCK, ODOM, RECORDED_TOPICS, SIMULATOR_TOPICS, TopicSpec, resolve_all,
                                       vehicle_namespaces)
from quad_msgs_bridge.conversions import MessageKit, rclpy_kit
from quad_msgs_bridge.bag.flight_bag import flight_custom_data
from quad_msgs_bridge.ros_helpers import declare, init_ros, qos_profile
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND
from quad_msgs_bridge.vehicle_params import ParameterError, load_vehicle_file

RECORD_DEPTH = 10000   #: reader history: the recorder never drops a message it was sent
BATCH_PERIOD = 0.002   #: [s, wall] the recorder wakes at most this often and takes everything waiting


class RecorderNode(Node):
    def __init__(self, kit: MessageKit):
        super().__init__('recorder')
        bag = declare(self, 'bag', '', 'bag directory to create (required)')
        topic_names = declare(self, 'topics', [t.name for t in RECORDED_TOPICS], 'contract topics to record')
        queue_size = declare(self, 'queue_size', 100000, 'messages buffered for the writer thread', (1, 10 ** 7))
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
        vehicles = {'namespace': self.namespaces[0]} if len(self.namespaces) == 1 else \
            {'vehicles': ','.join(self.namespaces)}
        custom = flight_custom_data(params, settle_time, backend='ros', seed=seed, **vehicles,
                                    **{k: v for k, v in labels.items() if v})
        self.writer = BagWriter(bag, self.topics, self.namespaces, custom_data=custom, overwrite=overwrite,
                                queue_size=queue_size)
        self.kit = kit
        self.clock_ns: int | None = 0 if CLOCK in self.topics else None    #: sim time of the latest /clock [ns]
        self.received = 0
        self.recorded: list = []
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
        """Record ``topic`` under its absolute ``name``."""
        qos = qos_profile(topic.qos)
        profile = QoSProfile(history=qos.history, depth=max(qos.depth, RECORD_DEPTH),
                             reliability=qos.reliability, durability=qos.durability)
        is_clock = topic is CLOCK

        def record(data: bytes, info) -> None:
            now = time.time_ns()
            if is_clock:   # CDR: 4-byte encapsulation header, then int32 sec, uint32 nanosec
                sec = int.from_bytes(data[4:8], 'little', signed=True)
                self.clock_ns = sec * NANOSECONDS_PER_SECOND + int.from_bytes(data[8:12], 'little')
            log_time = self.clock_ns if self.clock_ns is not None else now
            self.writer.write_serialized(name, data, log_time, info.get('source_timestamp', now) or now)
            self.received += 1

        def on_message(data: bytes, info) -> None:
            record(data, info)
            self.take_waiting()

        subscription = self.create_subscription(self.kit[topic.type], name, on_message, profile, raw=True)
        self.recorded.append((topic, subscription, record))
        # /clock first, then odom: every message taken in a round is logged at the newest sim time
        self.recorded.sort(key=lambda entry: (entry[0] is not CLOCK, entry[0] is not ODOM))

    def take_waiting(self) -> None:
        """Record every message already waiting in any subscription, /clock and odom first.

        A control step brings seven messages; taking all that wait per wake-up, and waking at most
        every BATCH_PERIOD, keeps the recorder's cost per message low (on two cores it competes with
        the simulator and the controller for the CPU). Log times stay non-decreasing in the bag.
        """
        for _, subscription, record in self.recorded:
            while (taken := subscription.handle.take_message(subscription.msg_type, True)) is not None:
                record(*taken)

    def open_gate(self) -> None:
        """Subscribe to every odom once every recorded per-step topic of the controllers has a discovered publisher."""
        per_step = [t for t in self.topics if t.qos.durability == 'volatile' and t not in SIMULATOR_TOPICS]
        if any(self.count_publishers(name) == 0 for name, _ in resolve_all(per_step, self.namespaces)):
            return
        self.gate.cancel()
        for name, _ in resolve_all([ODOM], self.namespaces):
            self.subscribe(name, ODOM)
        self.get_logger().info('controller publishers discovered; recording odom')


def main(argv: list[str] | None = None) -> int:
    """Take what arrives (in rounds, see :meth:`RecorderNode.take_waiting`) until SIGINT/SIGTERM, then
    drain what is still arriving and finalize the bag."""
    signals = init_ros(argv)
    node = None
    try:
        node = RecorderNode(rclpy_kit())
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while not signals and executor.context.ok():
            executor.spin_once(timeout_sec=0.0)
            time.sleep(BATCH_PERIOD)
        quiet_since = time.monotonic()
        while time.monotonic() - quiet_since < 0.3:
            before = node.received
            executor.spin_once(timeout_sec=0.05)
            if node.received != before:
                quiet_since = time.monotonic()
    except ParameterError as error:
        print(f'[FATAL] invalid parameter: {error}', file=sys.stderr, flush=True)
        return 2
    finally:
        if node is not None:
            node.writer.close()
            dropped = f', {node.writer.dropped} DROPPED (writer queue full)' if node.writer.dropped else ''
            print(f'recorder: {node.received} messages written to {node.writer.path}{dropped}', flush=True)
            node.destroy_node()
        rclpy.try_shutdown()
    return 1 if node is not None and node.writer.dropped else 0


if __name__ == '__main__':
    raise SystemExit(main())
