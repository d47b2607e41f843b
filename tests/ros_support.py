"""Helpers of the ROS 2 integration tests: skip without rclpy, isolate the DDS domain, start nodes."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SKIP_REASON = ('rclpy cannot be imported: source /opt/ros/jazzy/setup.bash (ROS 2 Jazzy) to run the ROS 2 '
               'integration tests')

try:
    import rclpy  # noqa: F401
    HAVE_RCLPY = True
except ImportError:
    HAVE_RCLPY = False

requires_ros = pytest.mark.skipif(not HAVE_RCLPY, reason=SKIP_REASON)


def importable(module: str) -> bool:
    """Whether ``module`` imports here (the PyPI ROS 2 wheels lack tf2_msgs and tf2_ros, for example)."""
    try:
        __import__(module)
    except ImportError:
        return False
    return True


#: tf2_msgs is installed: the simulator broadcasts /tf (without it, it flies on without /tf)
HAVE_TF2_MSGS = HAVE_RCLPY and importable('tf2_msgs.msg')

# Our own DDS domain, so these tests neither see nor disturb other ROS 2 processes on the machine.
os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))


def node_process(name: str, module: str, namespace: str, params: dict, quiet: bool = True):
    """Start one node of this source tree in its own process."""
    from flight_stack.processes import NodeProcess, source_tree_environment
    from flight_stack.ros_backend import _ros_args
    return NodeProcess(name, [sys.executable, '-m', module] + _ros_args(namespace, params),
                       source_tree_environment(), quiet=quiet)


def spin_until(node, condition, timeout: float) -> bool:
    """Spin ``node`` until ``condition()`` holds or ``timeout`` [s, wall] passes."""
    import rclpy
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
        if condition():
            return True
    return False


@contextmanager
def cpu_hogs(count: int | None = None):
    """A loaded machine while the block runs: ``count`` busy-loop processes (default one per CPU)."""
    hogs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'], stdin=subprocess.DEVNULL)
            for _ in range(count or os.cpu_count() or 1)]
    try:
        yield hogs
    finally:
        for hog in hogs:
            hog.kill()
        for hog in hogs:
            hog.wait()
