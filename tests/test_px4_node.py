"""The PX4 bridge node without px4_msgs: it says so in one line and exits 1 (it imports rclpy, so it runs where ROS 2
is: .venv-ros-wheels or a sourced Jazzy). Its logic is the core's (tests/test_px4_offboard.py)."""
import subprocess
import sys

import pytest

from ros_support import requires_ros
from hang_guard import HANG_TIMEOUT_S

pytestmark = [requires_ros, pytest.mark.ros]


def test_without_px4_msgs_the_node_says_so_in_one_line():
    try:
        import px4_msgs  # noqa: F401
        pytest.skip('px4_msgs is installed here')
    except ImportError:
        pass
    from flight_stack.processes import source_tree_environment
    done = subprocess.run([sys.executable, '-m', 'quad_sim.px4_node'], env=source_tree_environment(),
                          capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    assert done.returncode == 1
    [line] = done.stderr.strip().splitlines()
    assert line.startswith('px4_bridge: px4_msgs cannot be imported') and 'docs/PX4.md' in line
