"""The fast per-step CDR encoders write exactly the bytes rosbags' serializer writes for the same message."""
import math

import numpy as np
import pytest

from quad_msgs_bridge import fast_cdr
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.conversions import (clock_msg, diagnostics_from_msg, diagnostics_msg, odometry_msg,
                                          pose_stamped_msg, rosbags_kit, rotor_forces_msg, tf_msg, wrench_msg)
from quad_msgs_bridge.frames import quaternion_from_euler
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.timebase import stamp_fields

KIT = rosbags_kit()
TYPESTORE = jazzy_typestore()
STAMPS = [0.0, 0.001, 12.345678901, 59.999, 2147483647.25]   # up to the largest int32 second


def serialized(msg, type_name: str) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(msg, type_name))


def random_values(seed: int, count: int) -> list[float]:
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.integers(-12, 12, count)
    return [float(v) for v in rng.normal(size=count) * scale]


@pytest.mark.parametrize('seed', range(5))
@pytest.mark.parametrize('t', STAMPS)
def test_odometry(seed, t):
    v = random_values(seed, 13)
    sample = OdometrySample(t, tuple(v[0:3]), quaternion_from_euler(*v[3:6]), tuple(v[6:9]), tuple(v[9:12]))
    sec, nanosec = stamp_fields(t)
    assert fast_cdr.odometry_encoder()(sec, nanosec, sample) == serialized(odometry_msg(KIT, sample),
                                                                            'nav_msgs/msg/Odometry')


@pytest.mark.parametrize('frames', [('world', 'quad1/base_link'), ('', 'x'), ('a' * 37, 'b' * 8)])
def test_odometry_with_other_frame_ids(frames):
    """Frame ids of any length: the string padding and the alignment of the float block move."""
    sample = OdometrySample(3.5, (1.0, 2.0, 3.0), (0.0, 0.0, 0.6, 0.8), (0.1, 0.2, 0.3), (-0.1, -0.2, -0.3))
    encode = fast_cdr.odometry_encoder(*frames)
    assert encode(3, 500000000, sample) == serialized(odometry_msg(KIT, sample, *frames), 'nav_msgs/msg/Odometry')


@pytest.mark.parametrize('seed', range(5))
def test_rotor_forces(seed):
    forces = random_values(seed, 4)
    assert fast_cdr.rotor_forces_encoder()(forces) == serialized(rotor_forces_msg(KIT, forces),
                                                                 'std_msgs/msg/Float64MultiArray')


@pytest.mark.parametrize('seed', range(5))
def test_diagnostics(seed):
    v = random_values(seed, 24)
    surfaces, equivalent, corrective, slopes = v[0:6], v[6:12], v[12:18], v[18:24]
    assert (fast_cdr.diagnostics_encoder()(surfaces, equivalent, corrective, slopes)
            == serialized(diagnostics_msg(KIT, surfaces, equivalent, corrective, slopes),
                          'std_msgs/msg/Float64MultiArray'))


def test_diagnostics_of_a_bag_recorded_before_the_lambda_column_still_decode():
    """6 x 3 diagnostics (surface, NN, fuzzy) of older bags: the three columns back, slopes None."""
    v = random_values(7, 18)
    msg = KIT['std_msgs/msg/Float64MultiArray'](
        layout=KIT['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0), data=np.array(v))
    assert diagnostics_from_msg(msg) == (v[0::3], v[1::3], v[2::3], None)


@pytest.mark.parametrize('seed', range(5))
@pytest.mark.parametrize('arm_length', [0.25, 0.2371, 1.0 / 3.0])
def test_wrench(seed, arm_length):
    controls = random_values(seed, 4)
    t = STAMPS[seed]
    sec, nanosec = stamp_fields(t)
    assert (fast_cdr.wrench_encoder(arm_length)(sec, nanosec, controls)
            == serialized(wrench_msg(KIT, t, controls, arm_length), 'geometry_msgs/msg/WrenchStamped'))


def test_wrench_with_another_frame_id():
    assert (fast_cdr.wrench_encoder(0.3, 'fc')(1, 2, (1.0, 2.0, 3.0, 4.0))
            == serialized(wrench_msg(KIT, 1.000000002, (1.0, 2.0, 3.0, 4.0), 0.3, 'fc'),
                          'geometry_msgs/msg/WrenchStamped'))


@pytest.mark.parametrize('seed', range(5))
@pytest.mark.parametrize('frame_id', ['odom', 'map_ned'])
def test_pose_stamped(seed, frame_id):
    v = random_values(seed, 4)
    yaw = math.atan2(v[3], 1.0) * 3.0
    t = STAMPS[seed]
    sec, nanosec = stamp_fields(t)
    assert (fast_cdr.pose_stamped_encoder(frame_id)(sec, nanosec, v[0:3], yaw)
            == serialized(pose_stamped_msg(KIT, t, v[0:3], yaw, frame_id), 'geometry_msgs/msg/PoseStamped'))


@pytest.mark.parametrize('t', STAMPS)
def test_clock(t):
    assert fast_cdr.clock_encoder()(*stamp_fields(t)) == serialized(clock_msg(KIT, t), 'rosgraph_msgs/msg/Clock')


def random_samples(seed: int, t: float, count: int) -> list[OdometrySample]:
    samples = []
    for k in range(count):
        v = random_values(100 * seed + k, 12)
        samples.append(OdometrySample(t, tuple(v[0:3]), quaternion_from_euler(*v[3:6]), tuple(v[6:9]),
                                      tuple(v[9:12])))
    return samples


@pytest.mark.parametrize('children', [['quad/base_link'], ['uav1/base_link', 'uav2/base_link', 'uav10/base_link'],
                                      ['a', 'bb', 'ccc', 'dddd', 'e' * 13], []])
@pytest.mark.parametrize('seed', range(2))
@pytest.mark.parametrize('t', STAMPS)
def test_tf(children, seed, t):
    """One TFMessage per step, one transform per vehicle: the frame ids' lengths move every later alignment."""
    samples = random_samples(seed, t, len(children))
    sec, nanosec = stamp_fields(t)
    assert (fast_cdr.tf_encoder(children)(sec, nanosec, samples)
            == serialized(tf_msg(KIT, t, samples, children), 'tf2_msgs/msg/TFMessage'))


def test_tf_with_another_parent_frame():
    samples = random_samples(3, 1.5, 2)
    children = ['fleet/uav1/base_link', 'fleet/uav2/base_link']
    assert (fast_cdr.tf_encoder(children, 'map')(1, 500000000, samples)
            == serialized(tf_msg(KIT, 1.5, samples, children, 'map'), 'tf2_msgs/msg/TFMessage'))


def test_tf_refuses_a_pose_count_other_than_the_frame_count():
    with pytest.raises(ValueError, match='2 poses for 3 child frames'):
        fast_cdr.tf_encoder(['a', 'b', 'c'])(0, 0, random_samples(0, 0.0, 2))
