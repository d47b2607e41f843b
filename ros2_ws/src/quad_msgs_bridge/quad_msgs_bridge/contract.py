"""The ROS contract of the stack: topic names, message types, QoS and frame ids, defined once.

Names are relative to the vehicle namespace (``/quad/odom`` for namespace ``quad``), except
``/clock`` and ``/tf``: one of each per ROS graph, shared by every vehicle of a fleet. Frame ids:
the world frame ``odom`` is shared too, each vehicle's body frame is prefixed with its namespace
(``uav1/base_link``, see :func:`base_frame`), as TF needs one name per frame. QoS is described as
plain data here (no rclpy import); the node modules turn it into ``rclpy.qos.QoSProfile`` and the
recorder writes it into the bag's channel metadata.

Per control update the controller publishes, in this order: ``rotor_forces``, ``control/wrench``,
``control/reference`` and ``control/diagnostics``. The stamped ones carry the stamp of the
odometry they answer; unstamped ones pair with them by order.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

from quad_msgs_bridge.validation import ParameterError

ODOM_FRAME = 'odom'           #: world frame, ENU (REP 103/105), shared by every vehicle
BASE_FRAME = 'base_link'      #: body frame, FLU; a vehicle's is prefixed with its namespace: base_frame()
DEFAULT_NAMESPACE = 'quad'
_NAMESPACE = re.compile(r'[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*')   #: ROS 2 name tokens


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
#: /tf as tf2 publishes it (tf2_ros' DynamicBroadcasterQoS, the Python TransformBroadcaster's default:
#: reliable, volatile, keep last 100) but with the lockstep topics' history: the simulator publishes one /tf per
#: step, and a recorder 100 steps behind (0.1 s of a lockstep flight on a loaded machine) lost the oldest ones
#: (556 of 600 in a test on Cyclone DDS). The depth does not affect matching with tf2's listeners
TF_QOS = QosSpec('reliable', 'volatile', LOCKSTEP.depth)

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
#: a per-step topic like odom: with keep-last 10, a third-party recorder (`ros2 bag record`) that the lockstep does
#: not wait for lost /clock messages on a loaded machine (5,967 of 6,000 kept, every other topic whole)
CLOCK = TopicSpec('/clock', 'rosgraph_msgs/msg/Clock', LOCKSTEP, 'quad_sim -> all')
TF = TopicSpec('/tf', 'tf2_msgs/msg/TFMessage', TF_QOS,
               'quad_sim -> tools: odom -> <namespace>/base_link of every vehicle, per odometry step')
#: the vehicle as URDF (quad_msgs_bridge.urdf), latched as robot_state_publisher offers it, for RViz and Foxglove
ROBOT_DESCRIPTION = TopicSpec('robot_description', 'std_msgs/msg/String', LATCHED,
                              'quad_sim -> tools: the vehicle as URDF, from its vehicle file')
#: as tf2's StaticBroadcasterQoS: reliable, transient local, keep last 1 (one message holds every vehicle's transforms)
TF_STATIC = TopicSpec('/tf_static', 'tf2_msgs/msg/TFMessage', LATCHED,
                      'quad_sim -> tools: <namespace>/base_link -> <namespace>/rotor_<i>, the URDF\'s fixed joints')

ALL_TOPICS = (ODOM, ROTOR_FORCES, SETPOINTS, REFERENCE_PATH, GOAL_POSE, CONTROL_WRENCH,
              CONTROL_REFERENCE, CONTROL_DIAGNOSTICS, CLOCK, TF, GROUND_TRUTH, ROBOT_DESCRIPTION, TF_STATIC)
#: what a flight bag records by default: the latched topics (the path, the vehicle's description) once, the others
#: per step
RECORDED_TOPICS = (ODOM, ROTOR_FORCES, SETPOINTS, REFERENCE_PATH, CONTROL_WRENCH, CONTROL_REFERENCE,
                   CONTROL_DIAGNOSTICS, CLOCK, TF, ROBOT_DESCRIPTION, TF_STATIC)
#: the simulator's topics (the others are the controller's, the trajectory's and the tools')
SIMULATOR_TOPICS = (ODOM, CLOCK, TF, GROUND_TRUTH)
#: published at every step of a flight (the simulator's and the controllers' answers), the others once or on demand
PER_STEP_TOPICS = (ODOM, ROTOR_FORCES, CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS, GROUND_TRUTH, CLOCK, TF)


def resolve(topic: TopicSpec, namespace: str) -> str:
    """Absolute topic name of ``topic`` in ``namespace`` ('' for the root namespace)."""
    if topic.name.startswith('/'):
        return topic.name
    namespace = namespace.strip('/')
    return f'/{namespace}/{topic.name}' if namespace else f'/{topic.name}'


def resolve_all(topics, namespaces) -> list[tuple[str, TopicSpec]]:
    """(absolute name, topic) of every topic in every namespace, each name once (``/clock`` and ``/tf``
    once for the whole fleet), in the order of ``namespaces`` then ``topics``."""
    names: dict[str, TopicSpec] = {}
    for namespace in namespaces:
        for topic in topics:
            names.setdefault(resolve(topic, namespace), topic)
    return list(names.items())


def base_frame(namespace: str) -> str:
    """Body frame id of the vehicle in ``namespace``: ``uav1/base_link`` for ``/uav1``, ``base_link`` in the
    root namespace (TF frame ids carry no leading '/')."""
    namespace = namespace.strip('/')
    return f'{namespace}/{BASE_FRAME}' if namespace else BASE_FRAME


def vehicle_namespaces(node_namespace: str, names: Sequence[str]) -> list[str]:
    """Absolute namespaces of the vehicles ``names``, each relative to ``node_namespace`` ('' is the node's own
    namespace, a leading '/' makes a name absolute); ParameterError for an invalid, repeated or missing name."""
    if not names:
        raise ParameterError('parameter vehicles: at least one vehicle is needed')
    base = node_namespace.strip('/')
    namespaces = []
    for name in names:
        relative = name.strip('/')
        if relative and not _NAMESPACE.fullmatch(relative):
            raise ParameterError(f'parameter vehicles: {name!r} is not a valid namespace (names of letters, digits '
                                 'and underscores, not starting with a digit, separated by /)')
        parts = [relative] if name.startswith('/') else [base, relative]
        namespaces.append('/' + '/'.join(p for p in parts if p))
    repeated = sorted({ns for ns in namespaces if namespaces.count(ns) > 1})
    if repeated:
        raise ParameterError(f'parameter vehicles: {repeated[0]} is given more than once')
    return namespaces
