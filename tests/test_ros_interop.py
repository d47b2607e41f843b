"""Interoperability of two ROS 2 builds: nodes on the ROS 2 wheels venv ``ROS_WHEELS_VENV`` (.venv-ros-wheels built
by scripts/test.sh, or another, e.g. a venv of the Kilted-series wheels: rclpy 9.1, Fast DDS 3) and nodes on this
run's ROS 2 of the Jazzy series (a sourced ROS 2 Jazzy, or the Jazzy-series wheels) fly one lockstep flight together
over DDS on localhost (where that venv exists and is not this run's own; it skips, saying which is missing,
elsewhere), and the contract types of the wheels announce Jazzy's type hashes (wherever the wheels venv exists).
What is known and verified about the pairs: docs/ROS.md.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ros_support import (HAVE_RCLPY, ROS_WHEELS_VENV, describe_ros, node_process, odom_gate_once_matched,
                         requires_ros, ros_series, ros_wheels_python)
from hang_guard import HANG_TIMEOUT_S

WHEELS_PYTHON = ros_wheels_python()

NEEDS_THE_WHEELS = pytest.mark.skipif(
    WHEELS_PYTHON is None, reason=f'needs the ROS 2 wheels venv {ROS_WHEELS_VENV} (bash scripts/test.sh builds it)')
NEEDS_ANOTHER_ROS = pytest.mark.skipif(
    ROS_WHEELS_VENV.resolve() == Path(sys.prefix).resolve(),
    reason=f"the ROS 2 wheels venv {ROS_WHEELS_VENV} is this run's own: there is no second ROS 2 to fly with "
           '(ROS_WHEELS_VENV names another)')
NEEDS_JAZZY = pytest.mark.skipif(HAVE_RCLPY and ros_series() != 'jazzy',
                                 reason=f'needs a ROS 2 of the Jazzy series for this run (it has {describe_ros()})')

if HAVE_RCLPY:
    import rclpy

    from quad_msgs_bridge.ros_helpers import subscription

from flight_stack.processes import stop_all
from quad_msgs_bridge.contract import ALL_TOPICS, CLOCK, CONTROL_WRENCH, ODOM
from quad_msgs_bridge.conversions import rclpy_kit
from quad_msgs_bridge.fast_cdr import decode_odometry

DURATION = 2.0   #: [s, sim] of each flight
STEPS = 2000     #: odometry steps of a flight at the default 1 kHz


#: Fast DDS 2 (Jazzy: 2.14) and Fast DDS 3 (the wheels: 3.2) do not share shared-memory segments (their names
#: changed in 3.0), so same-host traffic between them goes over UDP: every process of these tests uses UDPv4 only
UDP_ONLY = {'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4'}


@pytest.fixture
def ros_node(monkeypatch):
    for name, value in UDP_ONLY.items():    # before rclpy.init: this node's participant, and every node started
        monkeypatch.setenv(name, value)
    rclpy.init()
    node = rclpy.create_node('interop_test')
    yield node
    node.destroy_node()
    rclpy.shutdown()


def fly(node, namespace: str, on_wheels: set[str]) -> dict:
    """A lockstep hover flight of the three nodes in ``namespace``, those named in ``on_wheels`` ('sim',
    'trajectory', 'controller') on the ROS 2 wheels, the others on this run's ROS 2; what this node (on this
    run's ROS 2) received: {'odom': [(stamp [s], position [m, world ENU])], 'wrench': count, 'clock': count}.

    The simulator starts once its odom publisher has matched its subscribers: the writer's side. A reader
    matches a writer on its own side too, and across DDS vendors the two sides may match far apart; a
    message that reaches a reader not yet matched on its side is lost to it (a Cyclone reader of a Fast DDS
    simulator never got odometry 0, and one of a Fast DDS controller missed its first 523 answers). So this
    node's readers are matched on their side before the flight can start: the simulator waits for one more
    odom subscriber, a gate this node opens only once its own readers report their publishers matched."""
    kit = rclpy_kit()
    received = {'odom': [], 'wrench': 0, 'clock': 0}

    def count(key):
        return lambda _: received.__setitem__(key, received[key] + 1)

    def odometry(data: bytes):
        sample = decode_odometry(data)
        received['odom'].append((sample.stamp, sample.position))

    def whole_flight(topic, callback):   # a history for every step: the lockstep does not wait for this node
        return subscription(node, kit, topic, callback, raw=True, depth=2 * STEPS, namespace=namespace)

    subscriptions = [whole_flight(ODOM, odometry), whole_flight(CONTROL_WRENCH, count('wrench')),
                     whole_flight(CLOCK, count('clock'))]
    start = [0.0, 0.0, 0.5] + [0.0] * 9          # at rest 0.5 m below the hover point: a flight, not a rest

    def python(name):
        return WHEELS_PYTHON if name in on_wheels else None

    processes = [
        node_process('trajectory', 'nnit2fsmc_controller.trajectory_node', namespace,
                     {'scenario': 'hover', 'start_time': 0.0}, python=python('trajectory')),
        node_process('controller', 'nnit2fsmc_controller.controller_node', namespace, {},
                     python=python('controller')),
        # it waits for the controller's odom subscription, this node's and the gate; it stops stepping at DURATION
        node_process('sim', 'quad_sim.sim_node', namespace,
                     # start_delay: a margin for the writers' side of this node's readers, which it cannot see
                     {'duration': DURATION, 'initial_state': start, 'wait_for_subscribers': 3, 'start_delay': 0.5},
                     python=python('sim'))]
    gate = None
    try:
        gate = odom_gate_once_matched(node, subscriptions, namespace)
        # take what arrives while the flight runs; the simulator stays up after the last step, so that nothing
        # it sent is lost with its publishers
        take_until(subscriptions, lambda: (received['odom'] and received['odom'][-1][0] >= DURATION - 0.0015
                                           and received['wrench'] >= STEPS and received['clock'] >= STEPS),
                   timeout=HANG_TIMEOUT_S)
    finally:
        codes = stop_all(processes)
        for taken in subscriptions + ([gate] if gate else []):
            node.destroy_subscription(taken)
    assert all(code == 0 for code in codes.values()), (codes, [p.lines for p in processes])
    return received


def take_until(subscriptions, condition, timeout: float) -> bool:
    """Take every waiting message of the raw ``subscriptions`` (handing each to its callback) every 5 ms until
    ``condition()`` holds or ``timeout`` [s, wall] passes. Taken straight from the subscriptions, as the recorder
    does, not one executor spin per message: the lockstep does not wait for this node, and on a loaded machine
    an executor fell more than the publishers' history (1,000 steps) behind and lost odometry."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for subscription in subscriptions:
            while (taken := subscription.handle.take_message(subscription.msg_type, True)) is not None:
                subscription.callback(taken[0])
        if condition():
            return True
        time.sleep(0.005)
    return False


@NEEDS_THE_WHEELS
def test_the_wheels_contract_types_have_the_jazzy_type_hashes():
    """Every contract type the wheels carry has the RIHS01 hash of ROS 2 Jazzy's (the rosbags Jazzy typestore's,
    which equal the Jazzy interface packages': tests/test_bag_writer.py): a Jazzy and a wheels endpoint announce
    the same type. Read from the wheels' interface descriptions, no ROS needed."""
    import json
    from quad_msgs_bridge.bag.writer import jazzy_typestore
    typestore = jazzy_typestore()
    compared = []
    for type_name in sorted({topic.type for topic in ALL_TOPICS}):
        package, _, name = type_name.split('/')
        description = ROS_WHEELS_VENV / 'share' / package / 'msg' / f'{name}.json'
        if not description.exists():     # tf2_msgs: not in the wheels
            continue
        hashes = {entry['type_name']: entry['hash_string'] for entry in json.loads(description.read_text())['type_hashes']}
        assert hashes[type_name] == typestore.hash_rihs01(type_name), type_name
        compared.append(type_name)
    assert len(compared) >= 7 and 'nav_msgs/msg/Odometry' in compared and 'rosgraph_msgs/msg/Clock' in compared


@pytest.mark.parametrize('on_wheels', [{'sim', 'trajectory'}, {'controller'}],
                         ids=['sim and trajectory on the wheels', 'controller on the wheels'])
@pytest.mark.ros
@requires_ros
@NEEDS_JAZZY
@NEEDS_THE_WHEELS
@NEEDS_ANOTHER_ROS
def test_nodes_on_the_ros2_wheels_and_on_jazzy_fly_the_flight_that_jazzy_flies_alone(ros_node, on_wheels):
    """Across the two, every contract topic of a flight crosses from one ROS 2 to the other in one of the two
    cases (odom, /clock, rotor_forces, setpoints, reference_path, control/*): the lockstep flight completes every
    step, and it is the flight the same nodes fly on Jazzy alone."""
    alone = fly(ros_node, 'interop_alone', set())
    across = fly(ros_node, 'interop_across', on_wheels)
    positions = {}
    for name, flight in (('alone', alone), ('across', across)):
        stamps = [round(stamp * 1e9) for stamp, _ in flight['odom']]     # [ns, sim]
        # every step once, in order (a late answer repeats nothing to a reader that has the step)
        assert stamps == [k * 1_000_000 for k in range(STEPS)], name
        positions[name] = np.array([position for _, position in flight['odom']])
        assert flight['wrench'] == STEPS and flight['clock'] == STEPS, name
    assert positions['alone'][-1][2] > 0.6          # it climbed toward the hover point
    assert np.abs(positions['across'] - positions['alone']).max() <= 1e-9
