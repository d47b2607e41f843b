"""Helpers of the ROS 2 integration tests: skip without rclpy, isolate the DDS domain, start nodes.

``python tests/ros_support.py`` prints which ROS 2 this interpreter sees (scripts/test.sh says so per run).
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
SKIP_REASON = ('rclpy cannot be imported here: the ROS 2 integration tests run in .venv-ros-wheels (bash '
               'scripts/test.sh builds it) and with ROS 2 Jazzy sourced (source /opt/ros/jazzy/setup.bash)')

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

#: the venv of the PyPI ROS 2 wheels that scripts/test.sh builds (ROS_WHEELS_VENV names another)
ROS_WHEELS_VENV = Path(os.environ.get('ROS_WHEELS_VENV', ROOT / '.venv-ros-wheels'))


def ros_wheels_python() -> list[str] | None:
    """The command that runs the ROS 2 wheels venv's Python with any sourced ROS 2 taken out of its environment
    (scripts/without_sourced_ros.sh), or None where that venv has not been built."""
    python = ROS_WHEELS_VENV / 'bin' / 'python'
    if not python.exists():
        return None
    return ['bash', str(ROOT / 'scripts' / 'without_sourced_ros.sh'), str(python)]

# Our own DDS domain, so these tests neither see nor disturb other ROS 2 processes on the machine. The workers
# of one pytest-xdist run (PYTEST_XDIST_WORKER gw0, gw1, ...: children of one process) take neighbouring domains.
_worker = os.environ.get('PYTEST_XDIST_WORKER', '')
if _worker.startswith('gw'):
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getppid() % 25 * 4 + int(_worker[2:]) % 4))
else:
    os.environ.setdefault('ROS_DOMAIN_ID', str(100 + os.getpid() % 100))


def node_process(name: str, module: str, namespace: str, params: dict, quiet: bool = True,
                 python: list[str] | None = None):
    """Start one node of this source tree in its own process, run by ``python`` (a command; default this
    interpreter)."""
    from flight_stack.processes import NodeProcess, source_tree_environment
    from flight_stack.ros_backend import _ros_args
    return NodeProcess(name, (python or [sys.executable]) + ['-m', module] + _ros_args(namespace, params),
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


def wait_until(condition, timeout: float) -> bool:
    """Whether ``condition()`` holds within ``timeout`` [s, wall] (it is asked every 10 ms)."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def odom_gate_once_matched(node, readers, namespace: str, timeout: float = HANG_TIMEOUT_S):
    """The gate of a lockstep flight that ``node`` must see whole: an odom subscription of ``node`` in ``namespace``,
    made once each of ``readers`` (subscriptions of ``node``) reports its publishers matched on its own side. Start
    the simulator with one more ``wait_for_subscribers`` than its real odom readers (and a ``start_delay`` for the
    writers' side, which a reader cannot see): it steps only once the gate exists. A writer and a reader match each
    on its own side, far apart across DDS vendors or on a loaded machine, and a reader drops what reaches it before
    it has matched the writer (a Cyclone reader missed odometry 0 of a Fast DDS simulator)."""
    from quad_msgs_bridge.contract import ODOM
    from quad_msgs_bridge.conversions import rclpy_kit
    from quad_msgs_bridge.ros_helpers import subscription
    assert wait_until(lambda: all(reader.get_publisher_count() >= 1 for reader in readers), timeout), \
        f'readers of {[reader.topic_name for reader in readers]} never matched their publishers'
    return subscription(node, rclpy_kit(), ODOM, lambda _: None, raw=True, depth=1, namespace=namespace)


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


def rclpy_version() -> str:
    """rclpy's version: from the PyPI wheel's metadata, else from the package.xml of the sourced ROS 2."""
    from importlib import metadata
    for distribution in ('ros-rclpy', 'rclpy'):
        try:
            return metadata.version(distribution)
        except metadata.PackageNotFoundError:
            pass
    try:
        import re
        from ament_index_python.packages import get_package_share_directory
        text = Path(get_package_share_directory('rclpy'), 'package.xml').read_text()
        return re.search(r'<version>([^<]+)</version>', text).group(1)
    except (ImportError, LookupError, OSError, AttributeError):
        return 'unknown'


WHEELS = 'wheels'


def ros_distribution() -> str | None:
    """Which ROS 2 this interpreter's rclpy belongs to: WHEELS where it is pip-installed in this venv (the PyPI
    ROS 2 wheels), else the sourced distribution's name (ROS_DISTRO: 'jazzy'); None without rclpy or ROS_DISTRO."""
    if not HAVE_RCLPY:
        return None
    import rclpy
    if Path(rclpy.__file__).resolve().is_relative_to(Path(sys.prefix).resolve()):
        return WHEELS
    return os.environ.get('ROS_DISTRO')


#: the ROS 2 series of an rclpy by its major version (the PyPI wheels carry both)
RCLPY_SERIES = {'7': 'jazzy', '9': 'kilted'}


def ros_series() -> str | None:
    """The ROS 2 series of this interpreter's rclpy: the sourced distribution's name, or for the PyPI wheels the
    series their rclpy belongs to ('jazzy' for rclpy 7.1, 'kilted' for 9.1); None where unknown."""
    distribution = ros_distribution()
    if distribution != WHEELS:
        return distribution
    return RCLPY_SERIES.get(rclpy_version().split('.')[0])


def describe_ros() -> str:
    """One line: which ROS 2 the ROS tests of this interpreter run against (distro, rclpy version, RMW)."""
    if not HAVE_RCLPY:
        return 'ROS 2: none (rclpy cannot be imported: the ROS tests skip)'
    from rclpy.utilities import get_rmw_implementation_identifier
    series = (ros_series() or 'unknown').capitalize()
    origin = {WHEELS: f'the PyPI ROS 2 wheels ({series} series)', None: '(distro unknown: ROS_DISTRO unset)'}.get(
        ros_distribution(), ros_distribution())
    return (f'ROS 2: {origin}, rclpy {rclpy_version()}, RMW {get_rmw_implementation_identifier()}, '
            f'tf2_msgs {"yes" if HAVE_TF2_MSGS else "no"}, Python {sys.version.split()[0]}')


if __name__ == '__main__':
    print(describe_ros())
