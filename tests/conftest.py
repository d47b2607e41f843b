"""Fixtures shared by the test modules."""
from __future__ import annotations

import pytest


@pytest.fixture
def ros_node(request):
    """rclpy initialised for one test, and a node of the test process named after its module (e.g.
    ``test_ros_nodes``): to subscribe to what the nodes under test publish, or to publish to them."""
    import rclpy     # here, not at the top: the modules without ROS tests run where rclpy is missing
    rclpy.init()
    node = rclpy.create_node(request.module.__name__.rpartition('.')[2])
    yield node
    node.destroy_node()
    rclpy.shutdown()
