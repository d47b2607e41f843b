#!/usr/bin/env python3
"""Bare rclpy round trip between two processes: the ceiling of a lockstep simulator-controller pair.

Process A publishes nav_msgs/Odometry and waits for the std_msgs/Float64MultiArray (4 values) that
process B sends back for it, then sends the next: the same traffic pattern as one lockstep step,
with no simulation or control work. QoS: the contract's lockstep profile (`contract.LOCKSTEP`).

Needs rclpy (a sourced ROS 2, or the ROS 2 wheels). Usage: python3 bench/bench_ros_pingpong.py [--count N]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parent.parent / 'ros2_ws' / 'src' / 'quad_msgs_bridge')]

import rclpy  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from quad_msgs_bridge.contract import LOCKSTEP  # noqa: E402
from quad_msgs_bridge.ros_helpers import init_ros, qos_profile, spin_until_stopped  # noqa: E402


def pong() -> None:
    signals = init_ros()    # SIGTERM ends the spin, not rclpy's handler in the middle of a wait
    node = rclpy.create_node('pingpong_pong')
    publisher = node.create_publisher(Float64MultiArray, 'pong', qos_profile(LOCKSTEP))
    answer = Float64MultiArray(data=[1.0, 2.0, 3.0, 4.0])
    node.create_subscription(Odometry, 'ping', lambda msg: publisher.publish(answer), qos_profile(LOCKSTEP))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spin_until_stopped(executor, signals)
    node.destroy_node()
    rclpy.try_shutdown()


def ping(count: int, warmup: int) -> None:
    rclpy.init()
    node = rclpy.create_node('pingpong_ping')
    publisher = node.create_publisher(Odometry, 'ping', qos_profile(LOCKSTEP))
    received = []
    node.create_subscription(Float64MultiArray, 'pong', lambda msg: received.append(time.perf_counter()),
                             qos_profile(LOCKSTEP))
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    child = subprocess.Popen([sys.executable, __file__, '--role', 'pong'])
    try:
        deadline = time.monotonic() + 30.0
        while (node.count_subscribers('ping') < 1 or node.count_publishers('pong') < 1) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        message = Odometry()
        round_trips = []
        for k in range(warmup + count):
            before = len(received)
            sent = time.perf_counter()
            message.header.stamp.nanosec = k
            publisher.publish(message)
            while len(received) == before:
                executor.spin_once(timeout_sec=1.0)
            if k >= warmup:
                round_trips.append(received[-1] - sent)
        total = sum(round_trips)
        ordered = sorted(round_trips)
        print(f'{count} round trips (Odometry out, Float64MultiArray back), SingleThreadedExecutor.spin_once:')
        print(f'  {count / total:8.0f} round trips/s')
        print(f'  median {statistics.median(ordered) * 1e6:8.1f} us   p99 {ordered[int(0.99 * len(ordered))] * 1e6:8.1f} us')
    finally:
        child.terminate()
        child.wait()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--role', choices=('ping', 'pong'), default='ping')
    parser.add_argument('--count', type=int, default=5000)
    parser.add_argument('--warmup', type=int, default=200)
    args = parser.parse_args()
    if args.role == 'pong':
        pong()
    else:
        ping(args.count, args.warmup)


if __name__ == '__main__':
    main()
