"""rclpy side of the contract, shared by the three nodes: QoS profiles, validated parameters, main().

The bridge's node-side modules (this one, bag.recorder_node) import rclpy; the cores never do.
"""
from __future__ import annotations

import math
import signal
import sys
import time
from dataclasses import replace
from typing import Any, Callable, Sequence

import rclpy
from rclpy.duration import Duration
from rclpy.exceptions import InvalidParameterValueException, ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

from quad_msgs_bridge.bag.publication_log import PublicationLog, part_path
from quad_msgs_bridge.contract import QosSpec, TopicSpec, resolve
from quad_msgs_bridge.conversions import MessageKit, rclpy_kit
from quad_msgs_bridge.runtime import freeze_long_lived_objects
from quad_msgs_bridge.validation import ParameterError

_RELIABILITY = {'reliable': ReliabilityPolicy.RELIABLE, 'best_effort': ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {'volatile': DurabilityPolicy.VOLATILE, 'transient_local': DurabilityPolicy.TRANSIENT_LOCAL}


def qos_profile(spec: QosSpec) -> QoSProfile:
    """rclpy QoSProfile of a contract QoS description."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=spec.depth,
                      reliability=_RELIABILITY[spec.reliability], durability=_DURABILITY[spec.durability])


def _topic_name(topic: TopicSpec, namespace: str | None) -> str:
    return topic.name if namespace is None else resolve(topic, namespace)


def publisher(node: Node, kit: MessageKit, topic: TopicSpec, namespace: str | None = None,
              log: PublicationLog | None = None):
    """A publisher of a contract topic, relative names resolved in ``namespace`` (default: the node's); with a
    ``log`` (see :func:`publication_log`), one that records what it publishes there."""
    created = node.create_publisher(kit[topic.type], _topic_name(topic, namespace), qos_profile(topic.qos))
    return created if log is None else log.recording(created, topic)


def unmatched(wanted: Sequence[tuple[Any, int]]) -> list[str]:
    """The topics of the (publisher, readers) pairs in ``wanted`` whose publisher has matched fewer readers than
    that, on its own side (rclpy's matched count). A writer and a reader match each on its own side: a reader that
    has matched the writer still misses what the writer sends before the writer has matched it (a test's reader of
    the controller's rotor_forces missed the first answers on a loaded CI machine). The ROS graph shows
    discovered endpoints, not matches, and can lag behind them: counts, not the graph."""
    return [pub.topic_name for pub, readers in wanted if pub.get_subscription_count() < readers]


def publication_log(node: Node, sim_time_ns: Callable[[], int]) -> PublicationLog | None:
    """Declare the node's ``record_dir`` parameter; if set, the log its publishers record into (its part bag in
    that directory: see quad_msgs_bridge.bag.publication_log), else None. ``sim_time_ns()``: the log time [ns,
    sim] of a message published now. :func:`run_node` closes the log of a node that keeps it as
    ``node.publication_log``."""
    record_dir = declare(node, 'record_dir', '', 'directory for this node to record what it publishes into, as '
                         'its own part bag (merged after the flight by `ros2 run quad_msgs_bridge merge`); empty: none',
                         read_only='the part bag is opened when the node starts')
    if not record_dir:
        return None
    try:
        return PublicationLog(part_path(record_dir, node.get_fully_qualified_name()), sim_time_ns)
    except OSError as error:
        raise ParameterError(f'parameter record_dir: {error}') from error


def subscription(node: Node, kit: MessageKit, topic: TopicSpec, callback: Callable, raw: bool = False,
                 depth: int | None = None, namespace: str | None = None):
    """A subscription to a contract topic, relative names resolved in ``namespace`` (default: the node's);
    ``raw``: the callback gets the CDR bytes; ``depth`` overrides the history."""
    qos = topic.qos if depth is None else replace(topic.qos, depth=depth)
    return node.create_subscription(kit[topic.type], _topic_name(topic, namespace), callback, qos_profile(qos),
                                    raw=raw)


def declare(node: Node, name: str, default: Any, description: str,
            bounds: tuple[float, float] | None = None, choices: Sequence[str] | None = None,
            read_only: str | None = None) -> Any:
    """Declare a parameter with its description and valid range, return its (validated) value.

    An out-of-range or wrong-typed value (from a params file or --ros-args -p) raises
    ParameterError naming the parameter and its valid range. ``read_only``: why the parameter cannot
    change while the node runs (it is then declared read-only and its description says so).
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only is not None)
    range_text = ''
    if bounds is not None:
        low, high = bounds
        range_text = f' valid range [{low}, {high}]'
        if isinstance(default, int) and not isinstance(default, bool):
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=0)]
        else:
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high) if math.isfinite(high) else sys.float_info.max, step=0.0)]
    if choices is not None:
        range_text = f' valid values {", ".join(choices)}'
        descriptor.additional_constraints = 'one of: ' + ', '.join(choices)
    descriptor.description += f' ({range_text.strip()})' if range_text else ''
    if read_only is not None:
        descriptor.description += f' [read-only: {read_only}]'
    try:
        value = node.declare_parameter(name, default, descriptor).value
    except (InvalidParameterValueException, ParameterException, TypeError) as error:
        raise ParameterError(f'parameter {name}: {error};{range_text}') from error
    if choices is not None and value not in choices:
        raise ParameterError(f'parameter {name}: {value!r} is not valid;{range_text}')
    if bounds is not None and isinstance(value, float) and not math.isfinite(value):
        raise ParameterError(f'parameter {name}: {value} is not finite;{range_text}')
    return value


#: [s, wall] how long a node stopped by a signal waits for its reliable subscribers' acknowledgements: above Fast
#: DDS' 3 s heartbeat period (a message a starved reader's transport dropped is repaired after the next heartbeat:
#: with 2 s a controller left a recorder SIGSTOPped through a flight 257 of its 600 answers), inside the 5 s grace
#: a node stopped by a signal is given (flight_stack.processes.stop_all)
ACKNOWLEDGEMENT_TIMEOUT = 4.0


def wait_for_acknowledgements(node: Node, timeout: float = ACKNOWLEDGEMENT_TIMEOUT) -> bool:
    """Wait until every reliable subscriber (a recorder) has acknowledged all that ``node`` published, at most
    ``timeout`` [s, wall] in all: a node that exits right after its last message would otherwise take it away
    from a subscriber that has not yet read it (Fast DDS' shared memory belongs to the publisher). It returns as
    soon as all is acknowledged; the limit is for a subscriber that is gone (a killed recorder never acknowledges).
    A simulator that ends its flight itself waits longer (sim_node.END_ACKNOWLEDGEMENT_TIMEOUT). Returns whether
    all was acknowledged; if not, the node warns (which topic), so a subscriber's missing messages are not silent."""
    deadline = time.monotonic() + timeout
    for publisher in node.publishers:
        left = deadline - time.monotonic()
        if left <= 0.0 or not publisher.wait_for_all_acked(Duration(seconds=left)):
            node.get_logger().warning(f'{publisher.topic_name}: not acknowledged by every reliable subscriber within '
                                      f'{timeout:g} s: a subscriber (a recorder) may miss the last messages')
            return False
    return True


def init_ros(argv: list[str] | None = None) -> list[int]:
    """``rclpy.init`` with our own SIGINT/SIGTERM handling; returns the list the signals are appended to.

    rclpy's own handler both shuts the context down and chains to Python's, which raises
    KeyboardInterrupt at an arbitrary point, also in the middle of the cleanup after the spin: a
    simulator stopped mid-flight then died by its SIGINT (exit code -2) instead of exiting 0. Here a
    signal only ends :func:`spin_until_stopped`, and the cleanup runs undisturbed.
    """
    rclpy.init(args=argv if argv is not None else sys.argv, signal_handler_options=SignalHandlerOptions.NO)
    signals: list[int] = []
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, lambda received, frame: signals.append(received))
    return signals


def spin_until_stopped(executor: Executor, signals: list[int]) -> None:
    """Spin until a signal arrives (within 0.1 s) or the context is shut down (e.g. by the node itself)."""
    try:
        while not signals and executor.context.ok():
            executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass


def run_node(make_node: Callable[[MessageKit], Node], argv: list[str] | None = None) -> int:
    """Init rclpy, build the node, spin until SIGINT/SIGTERM or shutdown; invalid parameters end it with exit code 2."""
    signals = init_ros(argv)
    node = None
    code = 0
    try:
        node = make_node(rclpy_kit())
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        freeze_long_lived_objects()     # no 80 ms garbage-collector pause in the middle of a flight
        spin_until_stopped(executor, signals)
    except ParameterError as error:
        print(f'[FATAL] invalid parameter: {error}', file=sys.stderr, flush=True)
        code = 2
    finally:
        if node is not None:
            if node.context.ok():
                wait_for_acknowledgements(node)
            node.destroy_node()
            if getattr(node, 'publication_log', None) is not None:
                node.publication_log.close()
        rclpy.try_shutdown()
    return code
