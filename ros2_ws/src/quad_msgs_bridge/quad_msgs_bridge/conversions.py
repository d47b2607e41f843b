"""Conversions between the cores' numbers and the contract's ROS 2 messages.

The same functions build messages from rclpy's generated classes (in the nodes) and from the
``rosbags`` ROS 2 Jazzy typestore (bag writing and tests without ROS): a :class:`MessageKit` says
where the classes come from. Messages are always built with every field given by keyword, which
both kinds of class accept. Readers (``*_from_msg``) only use attribute access, so they take
either kind, and raise ValueError on a malformed or non-finite message.
"""
from __future__ import annotations

import array
import importlib
import math
from typing import Callable, Sequence

import numpy as np

from quad_msgs_bridge.contract import BASE_FRAME, ODOM_FRAME
from quad_msgs_bridge.frames import euler_from_quaternion, quaternion_from_euler
from quad_msgs_bridge.mixer import ROTOR_NAMES
from quad_msgs_bridge.reference import ReferenceSample, SetpointPath, hold
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.timebase import stamp_fields, stamp_seconds

SUBSYSTEM_NAMES = ('x', 'y', 'z', 'phi', 'theta', 'psi')
DIAGNOSTIC_QUANTITIES = ('surface', 'nn_equivalent', 'fuzzy_corrective', 'lambda')


def rotor_forces_dims(rotor_names: Sequence[str] = ROTOR_NAMES) -> tuple:
    """The ``rotor_forces`` layout: one dimension labelled 'rotor_thrust_N:' and the rotor names F1..F4 of
    the vehicle's layout (``VehicleParams.rotor_names``, e.g. F1_front,F2_right,... in the plus frame)."""
    return (('rotor_thrust_N:' + ','.join(rotor_names), 4),)

DIAGNOSTICS_DIMS = (('subsystem:' + ','.join(SUBSYSTEM_NAMES), 6), ('quantity:' + ','.join(DIAGNOSTIC_QUANTITIES), 4))


class MessageKit:
    """Where message classes come from, and how each kind wants a float64 sequence."""

    def __init__(self, get_class: Callable[[str], type], float_sequence: Callable[[Sequence[float]], object]):
        self._get_class = get_class
        self._classes: dict[str, type] = {}
        self.float_sequence = float_sequence

    def __getitem__(self, type_name: str) -> type:
        """Message class of a ROS 2 type name such as 'nav_msgs/msg/Odometry'."""
        if type_name not in self._classes:
            self._classes[type_name] = self._get_class(type_name)
        return self._classes[type_name]


def rosbags_kit() -> MessageKit:
    """Message classes of the rosbags ROS 2 Jazzy typestore (no ROS installation needed)."""
    from rosbags.typesys import Stores, get_typestore
    typestore = get_typestore(Stores.ROS2_JAZZY)
    return MessageKit(lambda name: typestore.types[name], lambda values: np.asarray(values, dtype=np.float64))


def generated_message_class(type_name: str) -> type:
    """The rosidl-generated Python class of a ROS 2 type name: 'nav_msgs/msg/Odometry' -> ``nav_msgs.msg.Odometry``.

    What ``rosidl_runtime_py.utilities.get_message`` does, without needing that package (the PyPI ROS 2
    wheels lack it). ValueError for a name not of the form 'package/msg/Type'; ImportError (ModuleNotFoundError
    for a missing package) where the type is not installed.
    """
    parts = type_name.split('/') if isinstance(type_name, str) else []
    if len(parts) != 3 or parts[1] != 'msg' or not all(part.isidentifier() for part in parts):
        raise ValueError(f'type_name: {type_name!r} is not a message type name of the form package/msg/Type')
    package, interface, name = parts
    module = importlib.import_module(f'{package}.{interface}')
    try:
        return getattr(module, name)
    except AttributeError:
        raise ImportError(f'{package}.{interface} has no message {name}: {type_name} is not installed',
                          name=f'{package}.{interface}') from None


def rclpy_kit() -> MessageKit:
    """rclpy's generated message classes (needs a sourced ROS 2 or the ROS 2 wheels)."""
    return MessageKit(generated_message_class, lambda values: array.array('d', values))


def _finite(values: Sequence[float], what: str) -> None:
    if not all(map(math.isfinite, values)):
        raise ValueError(f'non-finite value in {what}: {list(values)}')


# --- building blocks ----------------------------------------------------------------------

def time_msg(kit: MessageKit, t: float):
    sec, nanosec = stamp_fields(t)
    return kit['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)


def duration_msg(kit: MessageKit, t: float):
    sec, nanosec = stamp_fields(t)
    return kit['builtin_interfaces/msg/Duration'](sec=sec, nanosec=nanosec)


def header_msg(kit: MessageKit, t: float, frame_id: str):
    return kit['std_msgs/msg/Header'](stamp=time_msg(kit, t), frame_id=frame_id)


def stamp_of(msg) -> float:
    """Time [s] of a message's header stamp."""
    return stamp_seconds(msg.header.stamp.sec, msg.header.stamp.nanosec)


def vector3_msg(kit: MessageKit, v: Sequence[float]):
    return kit['geometry_msgs/msg/Vector3'](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def point_msg(kit: MessageKit, p: Sequence[float]):
    return kit['geometry_msgs/msg/Point'](x=float(p[0]), y=float(p[1]), z=float(p[2]))


def quaternion_msg(kit: MessageKit, q: Sequence[float]):
    return kit['geometry_msgs/msg/Quaternion'](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def pose_msg(kit: MessageKit, position: Sequence[float], yaw: float):
    return kit['geometry_msgs/msg/Pose'](position=point_msg(kit, position),
                                         orientation=quaternion_msg(kit, quaternion_from_euler(0.0, 0.0, yaw)))


def _xyz(v) -> tuple[float, float, float]:
    return (float(v.x), float(v.y), float(v.z))


def _quat(q) -> tuple[float, float, float, float]:
    return (float(q.x), float(q.y), float(q.z), float(q.w))


def multi_array_dimensions(dims: Sequence[tuple[str, int]]) -> list[tuple[str, int, int]]:
    """(label, size, stride) of each dimension of a row-major std_msgs/MultiArrayLayout."""
    strides = []
    stride = 1
    for _, size in reversed(dims):
        stride *= size
        strides.append(stride)
    return [(label, size, s) for (label, size), s in zip(dims, reversed(strides))]


def _multi_array_msg(kit: MessageKit, dims: Sequence[tuple[str, int]], data: Sequence[float]):
    dim_cls = kit['std_msgs/msg/MultiArrayDimension']
    layout = kit['std_msgs/msg/MultiArrayLayout'](
        dim=[dim_cls(label=label, size=size, stride=stride) for label, size, stride in multi_array_dimensions(dims)],
        data_offset=0)
    return kit['std_msgs/msg/Float64MultiArray'](layout=layout, data=kit.float_sequence(data))


def _multi_array_data(msg, expected_size: int, what: str) -> list[float]:
    data = [float(v) for v in msg.data[msg.layout.data_offset:]]
    if len(data) != expected_size:
        raise ValueError(f'{what}: expected {expected_size} values, got {len(data)}')
    _finite(data, what)
    return data


# --- contract messages ---------------------------------------------------------------------

def odometry_msg(kit: MessageKit, sample: OdometrySample, frame_id: str = ODOM_FRAME,
                 child_frame_id: str = BASE_FRAME):
    """nav_msgs/Odometry: pose in ``frame_id`` (ENU), twist in ``child_frame_id`` (FLU), REP 105.

    The covariances are zero: the simulator publishes ground truth.
    """
    zeros = np.zeros(36, dtype=np.float64)
    pose = kit['geometry_msgs/msg/Pose'](position=point_msg(kit, sample.position),
                                         orientation=quaternion_msg(kit, sample.orientation))
    twist = kit['geometry_msgs/msg/Twist'](linear=vector3_msg(kit, sample.linear_velocity),
                                           angular=vector3_msg(kit, sample.angular_velocity))
    return kit['nav_msgs/msg/Odometry'](
        header=header_msg(kit, sample.stamp, frame_id), child_frame_id=child_frame_id,
        pose=kit['geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=zeros),
        twist=kit['geometry_msgs/msg/TwistWithCovariance'](twist=twist, covariance=zeros.copy()))


def odometry_from_msg(msg) -> OdometrySample:
    sample = OdometrySample(
        stamp=stamp_of(msg),
        position=_xyz(msg.pose.pose.position),
        orientation=_quat(msg.pose.pose.orientation),
        linear_velocity=_xyz(msg.twist.twist.linear),
        angular_velocity=_xyz(msg.twist.twist.angular))
    _finite((*sample.position, *sample.orientation, *sample.linear_velocity, *sample.angular_velocity),
            'odometry')
    return sample


def tf_msg(kit: MessageKit, t: float, samples: Sequence[OdometrySample], child_frame_ids: Sequence[str],
           frame_id: str = ODOM_FRAME):
    """tf2_msgs/TFMessage with one geometry_msgs/TransformStamped per vehicle, all stamped ``t`` [s]:
    ``frame_id`` -> ``child_frame_ids[k]`` is the pose of ``samples[k]`` (REP 105: odom -> base_link is
    the body's position [m] and orientation in the world frame, as the odometry's pose)."""
    if len(samples) != len(child_frame_ids):
        raise ValueError(f'tf: {len(samples)} poses for {len(child_frame_ids)} child frames')
    transform = kit['geometry_msgs/msg/Transform']
    stamped = kit['geometry_msgs/msg/TransformStamped']
    return kit['tf2_msgs/msg/TFMessage'](transforms=[
        stamped(header=header_msg(kit, t, frame_id), child_frame_id=child,
                transform=transform(translation=vector3_msg(kit, sample.position),
                                    rotation=quaternion_msg(kit, sample.orientation)))
        for sample, child in zip(samples, child_frame_ids)])


def rotor_forces_msg(kit: MessageKit, forces: Sequence[float], rotor_names: Sequence[str] = ROTOR_NAMES):
    """std_msgs/Float64MultiArray of the four rotor thrusts [N], layout labelled with the rotor order
    (``rotor_names`` of the vehicle's layout; default: the plus frame's)."""
    _finite(forces, 'rotor forces')
    return _multi_array_msg(kit, rotor_forces_dims(rotor_names), [float(f) for f in forces])


def rotor_forces_from_msg(msg) -> tuple[float, float, float, float]:
    return tuple(_multi_array_data(msg, 4, 'rotor_forces'))


def wrench_msg(kit: MessageKit, t: float, controls: Sequence[float], arm_length: float,
               frame_id: str = BASE_FRAME):
    """geometry_msgs/WrenchStamped of U1..U4: force (0, 0, U1) [N], torque (d U2, d U3, U4) [N m], body FLU."""
    u1, u2, u3, u4 = controls
    return kit['geometry_msgs/msg/WrenchStamped'](
        header=header_msg(kit, t, frame_id),
        wrench=kit['geometry_msgs/msg/Wrench'](force=vector3_msg(kit, (0.0, 0.0, u1)),
                                               torque=vector3_msg(kit, (arm_length * u2, arm_length * u3, u4))))


def controls_from_wrench(msg, arm_length: float) -> tuple[float, float, float, float]:
    """(U1, U2, U3, U4) of a control wrench, inverse of :func:`wrench_msg`."""
    force, torque = msg.wrench.force, msg.wrench.torque
    return (float(force.z), float(torque.x) / arm_length, float(torque.y) / arm_length, float(torque.z))


def diagnostics_msg(kit: MessageKit, surfaces: Sequence[float], equivalent: Sequence[float],
                    corrective: Sequence[float], slopes: Sequence[float]):
    """std_msgs/Float64MultiArray, 6 subsystems x (S, NN term, fuzzy term, lambda), row-major, labelled layout.

    ``slopes`` are the sliding-surface slopes lambda [1/s] in effect at this update (they change
    when the gains are tuned in flight).
    """
    data = [float(v) for row in zip(surfaces, equivalent, corrective, slopes) for v in row]
    return _multi_array_msg(kit, DIAGNOSTICS_DIMS, data)


def diagnostics_from_msg(msg) -> tuple[list[float], list[float], list[float], list[float] | None]:
    """(surfaces, equivalent terms, corrective terms, slopes lambda), one value per subsystem.

    Diagnostics recorded before the lambda column existed (6 x 3) give slopes None.
    """
    width = 3 if len(msg.data) == 18 else len(DIAGNOSTIC_QUANTITIES)
    data = _multi_array_data(msg, 6 * width, 'control/diagnostics')
    return data[0::width], data[1::width], data[2::width], (data[3::width] if width == 4 else None)


def pose_stamped_msg(kit: MessageKit, t: float, position: Sequence[float], yaw: float,
                     frame_id: str = ODOM_FRAME):
    return kit['geometry_msgs/msg/PoseStamped'](header=header_msg(kit, t, frame_id),
                                                pose=pose_msg(kit, position, yaw))


def pose_from_msg(msg) -> tuple[tuple[float, float, float], float]:
    """(position [m], yaw [rad]) of a geometry_msgs/PoseStamped."""
    position = _xyz(msg.pose.position)
    orientation = _quat(msg.pose.orientation)
    _finite((*position, *orientation), 'pose')
    return position, euler_from_quaternion(orientation)[2]


def goal_from_msg(msg, frame_id: str = ODOM_FRAME) -> ReferenceSample:
    """Hold reference of a ``goal_pose``; refuses a pose in another frame (no tf lookup here)."""
    if msg.header.frame_id not in ('', frame_id):
        raise ValueError(f'goal_pose in frame {msg.header.frame_id!r}; expected {frame_id!r}')
    position, yaw = pose_from_msg(msg)
    return hold(position, yaw)


def setpoints_msg(kit: MessageKit, path: SetpointPath, frame_id: str = ODOM_FRAME,
                  child_frame_id: str = BASE_FRAME, origin: float | None = None):
    """trajectory_msgs/MultiDOFJointTrajectory of a setpoint path (one joint, ``child_frame_id``).

    header.stamp is ``origin`` [s] (default: the path's start; a later part of a path keeps its
    path's origin, so its times read back as they were); each point's time_from_start is its time
    minus the origin. Transforms hold
    position and yaw; velocities and accelerations are world-frame (``frame_id``) linear rates and
    the yaw rate and yaw acceleration about z.
    """
    twist = kit['geometry_msgs/msg/Twist']
    transform = kit['geometry_msgs/msg/Transform']
    point_cls = kit['trajectory_msgs/msg/MultiDOFJointTrajectoryPoint']
    origin = path.start if origin is None else origin
    points = []
    for t, p in zip(path.times, path.points):
        points.append(point_cls(
            transforms=[transform(translation=vector3_msg(kit, p.position),
                                  rotation=quaternion_msg(kit, quaternion_from_euler(0.0, 0.0, p.yaw)))],
            velocities=[twist(linear=vector3_msg(kit, p.velocity), angular=vector3_msg(kit, (0.0, 0.0, p.yaw_rate)))],
            accelerations=[twist(linear=vector3_msg(kit, p.acceleration),
                                 angular=vector3_msg(kit, (0.0, 0.0, p.yaw_acceleration)))],
            time_from_start=duration_msg(kit, t - origin)))
    return kit['trajectory_msgs/msg/MultiDOFJointTrajectory'](
        header=header_msg(kit, origin, frame_id), joint_names=[child_frame_id], points=points)


def setpoints_from_msg(msg) -> SetpointPath:
    """The setpoint path of a MultiDOFJointTrajectory; missing velocities/accelerations count as zero."""
    start = stamp_of(msg)
    if not msg.points:
        raise ValueError('setpoints message has no point')
    times, points = [], []
    for point in msg.points:
        if len(point.transforms) != 1:
            raise ValueError(f'setpoint with {len(point.transforms)} transforms; expected one joint')
        transform = point.transforms[0]
        velocity = point.velocities[0] if len(point.velocities) else None
        acceleration = point.accelerations[0] if len(point.accelerations) else None
        orientation = _quat(transform.rotation)
        _finite(orientation, 'setpoint orientation')
        times.append(start + stamp_seconds(point.time_from_start.sec, point.time_from_start.nanosec))
        points.append(ReferenceSample(
            position=_xyz(transform.translation),
            velocity=_xyz(velocity.linear) if velocity else (0.0, 0.0, 0.0),
            acceleration=_xyz(acceleration.linear) if acceleration else (0.0, 0.0, 0.0),
            yaw=euler_from_quaternion(orientation)[2],
            yaw_rate=float(velocity.angular.z) if velocity else 0.0,
            yaw_acceleration=float(acceleration.angular.z) if acceleration else 0.0))
    return SetpointPath(times, points)


def path_msg(kit: MessageKit, path: SetpointPath, frame_id: str = ODOM_FRAME, max_poses: int = 2000):
    """nav_msgs/Path of a setpoint path for display (at most ``max_poses`` evenly spaced poses)."""
    step = max(1, math.ceil(len(path.times) / max_poses))
    indices = list(range(0, len(path.times), step))
    if indices[-1] != len(path.times) - 1:
        indices.append(len(path.times) - 1)
    poses = [pose_stamped_msg(kit, path.times[i], path.points[i].position, path.points[i].yaw, frame_id)
             for i in indices]
    return kit['nav_msgs/msg/Path'](header=header_msg(kit, path.start, frame_id), poses=poses)


def clock_msg(kit: MessageKit, t: float):
    return kit['rosgraph_msgs/msg/Clock'](clock=time_msg(kit, t))
