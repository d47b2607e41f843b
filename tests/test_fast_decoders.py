"""The fast CDR decoders read exactly what the conversions readers read, and refuse what they refuse."""
from __future__ import annotations

import math

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from quad_msgs_bridge.conversions import (odometry_from_msg, odometry_msg, rosbags_kit, rotor_forces_from_msg,
                                          rotor_forces_msg)
from quad_msgs_bridge.fast_cdr import decode_odometry, decode_rotor_forces, odometry_encoder, rotor_forces_encoder
from quad_msgs_bridge.state import odometry_from_state
from quad_msgs_bridge.timebase import stamp_fields

KIT = rosbags_kit()
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def serialize(msg, type_name):
    return bytes(TYPESTORE.serialize_cdr(msg, type_name))


def random_sample(rng, stamp):
    state = list(rng.uniform(-3, 3, 12))
    state[7] = rng.uniform(-1.4, 1.4)     # pitch away from gimbal lock
    return odometry_from_state(stamp, state)


@pytest.mark.parametrize('frame_id, child_frame_id', [('odom', 'base_link'), ('map', 'uav7/base_link'), ('', ''),
                                                       ('w', 'abc')])
def test_odometry_decoder_reads_any_frames_like_the_message_reader(frame_id, child_frame_id):
    rng = np.random.default_rng(len(frame_id) + 7 * len(child_frame_id))
    for stamp in (0.0, 1.001, 12345.678901234):
        msg = odometry_msg(KIT, random_sample(rng, stamp), frame_id, child_frame_id)
        assert decode_odometry(serialize(msg, 'nav_msgs/msg/Odometry')) == odometry_from_msg(msg)


def test_odometry_decoder_inverts_the_encoder():
    sample = random_sample(np.random.default_rng(3), 42.5)
    assert decode_odometry(odometry_encoder()(*stamp_fields(sample.stamp), sample)) == sample


def test_rotor_forces_decoder_reads_the_contract_layout_and_a_foreign_one():
    forces = (1.25, 0.5, 2.0, 1.0)
    assert decode_rotor_forces(rotor_forces_encoder()(forces)) == forces
    assert decode_rotor_forces(serialize(rotor_forces_msg(KIT, forces), 'std_msgs/msg/Float64MultiArray')) == forces
    # a tool publishing a bare array (no layout) and one with an offset both decode like the reader
    for dims, offset, data in (([], 0, [1.0, 2.0, 3.0, 4.0]), ([('x', 5, 5)], 1, [9.0, 1.0, 2.0, 3.0, 4.0])):
        dim = [KIT['std_msgs/msg/MultiArrayDimension'](label=a, size=b, stride=c) for a, b, c in dims]
        msg = KIT['std_msgs/msg/Float64MultiArray'](
            layout=KIT['std_msgs/msg/MultiArrayLayout'](dim=dim, data_offset=offset), data=np.array(data))
        assert decode_rotor_forces(serialize(msg, 'std_msgs/msg/Float64MultiArray')) == rotor_forces_from_msg(msg)


@pytest.mark.parametrize('bad', [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0, 4.0, 5.0], [1.0, math.nan, 3.0, 4.0],
                                 [1.0, 2.0, math.inf, 4.0]])
def test_rotor_forces_decoder_refuses_what_the_reader_refuses(bad):
    msg = KIT['std_msgs/msg/Float64MultiArray'](
        layout=KIT['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0), data=np.array(bad))
    with pytest.raises(ValueError):
        rotor_forces_from_msg(msg)
    with pytest.raises(ValueError):
        decode_rotor_forces(serialize(msg, 'std_msgs/msg/Float64MultiArray'))


def test_decoders_refuse_non_finite_truncated_and_big_endian_data():
    sample = random_sample(np.random.default_rng(5), 1.0)
    good = odometry_encoder()(*stamp_fields(sample.stamp), sample)
    nan_sample = sample._replace(position=(math.nan, 0.0, 0.0))
    with pytest.raises(ValueError, match='non-finite'):
        decode_odometry(odometry_encoder()(1, 0, nan_sample))
    with pytest.raises(ValueError, match='truncated'):
        decode_odometry(good[:200])
    with pytest.raises(ValueError, match='little-endian'):
        decode_odometry(b'\x00\x00' + good[2:])
    with pytest.raises(ValueError, match='truncated'):
        decode_rotor_forces(rotor_forces_encoder()((1.0, 2.0, 3.0, 4.0))[:-8])
