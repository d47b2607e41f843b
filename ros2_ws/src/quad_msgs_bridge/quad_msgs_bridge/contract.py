"""The ROS contract of the stack: topic names, message types, QoS and frame ids, defined once.

Names are relative to the vehicle namespace (``/quad/odom`` for namespace ``quad``), except
``/clock``. QoS is described as plain data here (no rclpy import); the node modules turn it into
``rclpy.qos.QoSProfile`` and the recorder writes it into the bag's channel metadata.

Per control update the controller publishes, in this order: ``rotor_forces``, ``control/wrench``,
``control/reference`` and ``control/diagnostics``. The stamped ones carry the stamp of the
odometry they answer; unstamped ones pair with them by order.
"""
from __future__ import annotations

from dataclasses import dataclass

ODOM_FRAME = 'odom'           #: world frame, ENU (REP 103/105)
BASE_FRAME = 'base_link'      #: body frame, FLU
DEFAULT_NAMESPACE = 'quad'


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile as plain data (the fields rosbag2 records as offered QoS)."""

    reliability: str = 'reliable'     #: 'reliable' or 'best_effort'
    durability: str = 'volatile'      #: 'volatile' or 'transient_local'
    depth: int = 10                   #: history keep_last depth


@dataclass(frozen=True)
class TopicSpec:
    """One topic of the contract."""

    name: str       #: relative to the vehicle namespace unless it starts with '/'
    type: str       #: ROS 2 type name, e.g. 'nav_msgs/msg/Odometry'
    qos: QosSpec
    role: str       #: who publishes it, for documentation


LOCKSTEP = QosSpec('reliable', 'volatile', 1000)   # history for a slow reader (a recorder) to catch up on
LATCHED = QosSpec('reliable', 'transient_local', 1)

ODOM = TopicSpec('odom', 'nav_msgs/msg/Odometry', LOCKSTEP, 'quad_sim -> controller, tools')
ROTOR_FORCES = TopicSpec('rotor_forces', 'std_msgs/msg/Float64MultiArray', LOCKSTEP, 'controller -> quad_sim')
SETPOINTS = TopicSpec('setpoints', 'trajectory_msgs/msg/MultiDOFJointTrajectory', LATCHED, 'trajectory -> controller')
REFERENCE_PATH = TopicSpec('reference_path', 'nav_msgs/msg/Path', LATCHED, 'trajectory -> tools (RViz, Foxglove)')
GOAL_POSE = TopicSpec('goal_pose', 'geometry_msgs/msg/PoseStamped', QosSpec(), 'any tool -> controller')
CONTROL_WRENCH = TopicSpec('control/wrench', 'geometry_msgs/msg/WrenchStamped', LOCKSTEP, 'controller -> tools')
CONTROL_REFERENCE = TopicSpec('control/reference', 'geometry_msgs/msg/PoseStamped', LOCKSTEP,
                              'controller -> tools: the reference each update used')
CONTROL_DIAGNOSTICS = TopicSpec('control/diagnostics', 'std_msgs/msg/Float64MultiArray', LOCKSTEP,
                                'controller -> tools: S, NN and fuzzy terms per subsystem')
GROUND_TRUTH = TopicSpec('ground_truth/odom', 'nav_msgs/msg/Odometry', LOCKSTEP,
                         'simulator -> tools: the true state, recorded when odom carries sensor noise')
CLOCK = TopicSpec('/clock', 'rosgraph_msgs/msg/Clock', QosSpec('reliable', 'volatile', 10), 'quad_sim -> all')

ALL_TOPICS = (ODOM, ROTOR_FORCES, SETPOINTS, REFERENCE_PATH, GOAL_POSE, CONTROL_WRENCH,
              CONTROL_REFERENCE, CONTROL_DIAGNOSTICS, CLOCK, GROUND_TRUTH)
#: what a flight bag records by default
RECORDED_TOPICS = (ODOM, ROTOR_FORCES, SETPOINTS, REFERENCE_PATH, CONTROL_WRENCH, CONTROL_REFERENCE,
                   CONTROL_DIAGNOSTICS, CLOCK)


def resolve(topic: TopicSpec, namespace: str) -> str:
    """Absolute topic name of ``topic`` in ``namespace`` ('' for the root namespace)."""
    if topic.name.startswith('/'):
        return topic.name
    namespace = namespace.strip('/')
    return f'/{namespace}/{topic.name}' if namespace else f'/{topic.name}'
