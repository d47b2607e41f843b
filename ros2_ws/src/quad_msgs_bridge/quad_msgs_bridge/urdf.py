"""The vehicle as a URDF robot description, made from its vehicle file, for RViz and Foxglove.

The simulator publishes it on ``robot_description`` (std_msgs/String, transient local: a tool that
starts later still gets it; contract.ROBOT_DESCRIPTION) in each vehicle's namespace, and on
``/tf_static`` the fixed transforms of its rotor links (as robot_state_publisher would for the
fixed joints), so a RobotModel display draws the quadrotor at the TF frame the simulator moves:
``odom -> <namespace>/base_link``. Every flight bag records both once, at the flight's first stamp
(:func:`description_messages`: the same messages for the simulator and the bags).

Links (frame ids as on TF, prefixed with the vehicle's namespace like its body frame,
contract.base_frame): ``<namespace>/base_link``, the body frame (FLU) at the geometric centre, with
the vehicle's mass and inertia (paper Table I), a hub and one arm from the centre to each rotor;
``<namespace>/rotor_<i>`` (i = 1..4, the order F1..F4 of ``rotor_forces``), fixed at rotor i's
position [m, body FLU] (``VehicleParams.rotor_positions``), drawn as a disc of the propeller's sweep,
rotor 1 red. Sizes are drawn in proportion to the arm length d [m]; they are pictures, not the
collision shape of the vehicle (the model has none).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from typing import Sequence

from quad_msgs_bridge.contract import ROBOT_DESCRIPTION, TF_STATIC, TopicSpec, base_frame
from quad_msgs_bridge.conversions import MessageKit, tf_msg
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.vehicle_params import VehicleParams

_COLOURS = {'body': '0.3 0.3 0.35 1', 'first_rotor': '0.9 0.15 0.1 0.8', 'rotor': '0.2 0.45 0.9 0.8'}


def rotor_frames(namespace: str) -> list[str]:
    """TF frame ids of the rotor links F1..F4 of the vehicle in ``namespace`` (``uav1/rotor_1``, ...; ``rotor_1``
    in the root namespace), prefixed as its body frame is (contract.base_frame)."""
    prefix = namespace.strip('/')
    return [f'{prefix}/rotor_{i}' if prefix else f'rotor_{i}' for i in range(1, 5)]


def _number(value: float) -> str:
    return repr(float(value))


def _numbers(values: Sequence[float]) -> str:
    return ' '.join(_number(v) for v in values)


def _visual(parent, name: str, geometry: str, size: dict, colour: str, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
    visual = ElementTree.SubElement(parent, 'visual', name=name)
    ElementTree.SubElement(visual, 'origin', xyz=_numbers(xyz), rpy=_numbers(rpy))
    shape = ElementTree.SubElement(visual, 'geometry')
    ElementTree.SubElement(shape, geometry, **{key: _number(value) if not isinstance(value, str) else value
                                               for key, value in size.items()})
    ElementTree.SubElement(visual, 'material', name=colour)


def vehicle_urdf(params: VehicleParams, namespace: str) -> str:
    """The URDF (an XML string) of the single vehicle ``params`` in ``namespace`` (see the module docstring)."""
    d = float(params.d)
    robot = ElementTree.Element('robot', name=(namespace.strip('/') or 'quadrotor').replace('/', '_'))
    for name, rgba in _COLOURS.items():
        ElementTree.SubElement(ElementTree.SubElement(robot, 'material', name=name), 'color', rgba=rgba)
    base = ElementTree.SubElement(robot, 'link', name=base_frame(namespace))
    inertial = ElementTree.SubElement(base, 'inertial')
    ElementTree.SubElement(inertial, 'origin', xyz='0 0 0', rpy='0 0 0')
    ElementTree.SubElement(inertial, 'mass', value=_number(params.m))
    ElementTree.SubElement(inertial, 'inertia', ixx=_number(params.Ix), iyy=_number(params.Iy), izz=_number(params.Iz),
                           ixy='0', ixz='0', iyz='0')
    _visual(base, 'hub', 'box', {'size': _numbers((0.5 * d, 0.5 * d, 0.15 * d))}, 'body')
    for i, ((x, y, z), name) in enumerate(zip(params.rotor_positions, params.rotor_names), start=1):
        reach = math.hypot(x, y)     # the arm: a rod from the centre to the rotor, in the x-y plane
        _visual(base, f'arm_{name}', 'cylinder', {'radius': 0.04 * d, 'length': reach}, 'body',
                xyz=(0.5 * x, 0.5 * y, 0.5 * z), rpy=(0.0, 0.5 * math.pi, math.atan2(y, x)))
        rotor = ElementTree.SubElement(robot, 'link', name=rotor_frames(namespace)[i - 1])
        _visual(rotor, name, 'cylinder', {'radius': 0.4 * d, 'length': 0.02 * d},
                'first_rotor' if i == 1 else 'rotor')
        joint = ElementTree.SubElement(robot, 'joint', name=f'{rotor_frames(namespace)[i - 1]}_joint', type='fixed')
        ElementTree.SubElement(joint, 'parent', link=base_frame(namespace))
        ElementTree.SubElement(joint, 'child', link=rotor_frames(namespace)[i - 1])
        ElementTree.SubElement(joint, 'origin', xyz=_numbers((x, y, z)), rpy='0 0 0')
    ElementTree.indent(robot)
    return '<?xml version="1.0"?>\n' + ElementTree.tostring(robot, encoding='unicode') + '\n'


def rotor_transforms_msg(kit: MessageKit, params: VehicleParams, namespaces: Sequence[str]):
    """tf2_msgs/TFMessage for ``/tf_static``: ``<namespace>/base_link -> <namespace>/rotor_<i>`` at rotor i's
    position [m, body FLU], unrotated, for every vehicle of ``namespaces`` (the URDF's fixed joints), stamped 0."""
    level, still = (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0)
    transforms = []
    for namespace in namespaces:
        rotors = [OdometrySample(0.0, position, level, still, still) for position in params.rotor_positions]
        transforms += tf_msg(kit, 0.0, rotors, rotor_frames(namespace), frame_id=base_frame(namespace)).transforms
    return kit['tf2_msgs/msg/TFMessage'](transforms=transforms)


def description_messages(kit: MessageKit, params: VehicleParams, namespaces: Sequence[str],
                         with_tf: bool = True) -> list[tuple[TopicSpec, str, object]]:
    """The latched messages that describe the vehicles ``params`` in ``namespaces``, as the simulator publishes them
    at its start and a flight bag records them: (contract topic, namespace it resolves in, message) for each
    vehicle's ``robot_description`` (its :func:`vehicle_urdf`), then, ``with_tf``, the one ``/tf_static`` of every
    vehicle's rotor links (:func:`rotor_transforms_msg`); nothing for no vehicle."""
    messages = [(ROBOT_DESCRIPTION, namespace, kit[ROBOT_DESCRIPTION.type](data=vehicle_urdf(params, namespace)))
                for namespace in namespaces]
    if with_tf and namespaces:
        messages.append((TF_STATIC, '', rotor_transforms_msg(kit, params, namespaces)))
    return messages
