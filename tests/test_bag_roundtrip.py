"""A recorded embedded flight read back by two independent readers (rosbags, mcap + mcap-ros2-support),
its metadata.yaml, and its conversion to a sqlite3 rosbag2 by rosbags-convert."""
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from bag_support import PARAMS, fly_recorded
from nnit2fsmc_controller.controller import AXES
from nnit2fsmc_controller.factory import load_gains
from quad_msgs_bridge.bag.reader import mcap_file
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.contract import (CLOCK, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, ODOM,
                                       RECORDED_TOPICS, REFERENCE_PATH, ROBOT_DESCRIPTION, ROTOR_FORCES, SETPOINTS,
                                       TF_STATIC, resolve)
from quad_msgs_bridge.conversions import (diagnostics_from_msg, odometry_from_msg, path_msg, rosbags_kit,
                                          rotor_forces_from_msg, setpoints_msg)
from quad_msgs_bridge.frames import quaternion_from_euler
from quad_msgs_bridge.review.flight_from_bag import read_flight
from quad_msgs_bridge.timebase import nanoseconds, stamp_fields
from quad_msgs_bridge.urdf import rotor_transforms_msg, vehicle_urdf

TYPESTORE = jazzy_typestore()
ONCE = (SETPOINTS, REFERENCE_PATH, ROBOT_DESCRIPTION, TF_STATIC)   # recorded once: the path at its start, the
                                                                   # vehicle's description at the first step
PER_STEP = tuple(t for t in RECORDED_TOPICS if t not in ONCE)


@pytest.fixture(scope='module')
def flight(tmp_path_factory):
    return fly_recorded(tmp_path_factory.mktemp('roundtrip') / 'bag', duration=1.5)


def name(topic) -> str:
    return resolve(topic, 'quad')


def step_stamps(flight) -> list[int]:
    return [nanoseconds(values[0].stamp) for values in flight.published.steps]


def test_rosbags_sees_the_contract_topics_types_qos_hashes_and_counts(flight):
    steps = flight.result.steps
    with AnyReader([flight.bag]) as reader:
        connections = {c.topic: c for c in reader.connections}
        assert set(connections) == {name(t) for t in RECORDED_TOPICS}
        for topic in RECORDED_TOPICS:
            connection = connections[name(topic)]
            assert connection.msgtype == topic.type
            assert connection.msgcount == (1 if topic in ONCE else steps)
            assert connection.digest == TYPESTORE.hash_rihs01(topic.type)
            assert connection.ext.serialization_format == 'cdr'
            [qos] = connection.ext.offered_qos_profiles
            assert qos.reliability.name.lower() == topic.qos.reliability
            assert qos.durability.name.lower() == topic.qos.durability
            assert qos.depth == topic.qos.depth


def test_log_times_are_the_sim_time_of_each_step(flight):
    stamps = step_stamps(flight)
    assert stamps == [round(k * 1e6) for k in range(flight.result.steps)]   # 1 kHz control from t = 0
    with AnyReader([flight.bag]) as reader:
        by_topic = {}
        for connection, timestamp, _ in reader.messages():
            by_topic.setdefault(connection.topic, []).append(timestamp)
    for topic in PER_STEP:
        assert by_topic[name(topic)] == stamps
    for topic in ONCE:
        assert by_topic[name(topic)] == [0]


def test_values_read_back_by_rosbags_equal_what_was_published(flight):
    kit = rosbags_kit()
    d = PARAMS.d
    decoded = {}
    with AnyReader([flight.bag]) as reader:
        for connection, _, raw in reader.messages():
            decoded.setdefault(connection.topic, []).append((reader.deserialize(raw, connection.msgtype), raw))
    [path] = flight.published.paths
    assert decoded[name(SETPOINTS)][0][1] == TYPESTORE.serialize_cdr(
        setpoints_msg(kit, path, child_frame_id='quad/base_link'), SETPOINTS.type)
    assert decoded[name(REFERENCE_PATH)][0][1] == TYPESTORE.serialize_cdr(path_msg(kit, path), REFERENCE_PATH.type)
    slopes = tuple(load_gains()['common']['lambda'][axis] for axis in AXES)
    for k, (odometry, forces, controls, position, yaw, surfaces, equivalent, corrective, recorded_slopes) in \
            enumerate(flight.published.steps):
        assert tuple(recorded_slopes) == slopes
        assert odometry_from_msg(decoded[name(ODOM)][k][0]) == odometry
        clock = decoded[name(CLOCK)][k][0].clock
        assert (clock.sec, clock.nanosec) == stamp_fields(odometry.stamp)
        assert rotor_forces_from_msg(decoded[name(ROTOR_FORCES)][k][0]) == tuple(forces)
        assert decoded[name(CONTROL_WRENCH)][k][0].header.frame_id == 'quad/base_link'
        wrench = decoded[name(CONTROL_WRENCH)][k][0].wrench
        u1, u2, u3, u4 = controls
        assert (wrench.force.x, wrench.force.y, wrench.force.z) == (0.0, 0.0, u1)
        assert (wrench.torque.x, wrench.torque.y, wrench.torque.z) == (d * u2, d * u3, u4)
        pose = decoded[name(CONTROL_REFERENCE)][k][0].pose
        assert (pose.position.x, pose.position.y, pose.position.z) == tuple(position)
        assert ((pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w)
                == quaternion_from_euler(0.0, 0.0, yaw))
        assert diagnostics_from_msg(decoded[name(CONTROL_DIAGNOSTICS)][k][0]) == (surfaces, equivalent, corrective,
                                                                                   list(slopes))


def test_tf_carries_odom_to_the_namespaced_base_link_at_every_odometry_stamp(flight):
    """One /tf message per step, stamped as the odometry of that step, logged at it, transform = odometry pose."""
    transforms, odometry = [], []
    with AnyReader([flight.bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            if connection.topic == '/tf':
                assert connection.msgtype == 'tf2_msgs/msg/TFMessage'
                transforms.append((timestamp, reader.deserialize(raw, connection.msgtype).transforms))
            elif connection.topic == name(ODOM):
                odometry.append(reader.deserialize(raw, connection.msgtype))
    assert len(transforms) == len(odometry) == flight.result.steps
    for (log_time, [tf]), odom in zip(transforms, odometry):
        assert (tf.header.frame_id, tf.child_frame_id) == ('odom', 'quad/base_link')
        assert (tf.header.frame_id, tf.child_frame_id) == (odom.header.frame_id, odom.child_frame_id)
        assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == (odom.header.stamp.sec, odom.header.stamp.nanosec)
        assert log_time == odom.header.stamp.sec * 1_000_000_000 + odom.header.stamp.nanosec
        t, r = tf.transform.translation, tf.transform.rotation
        p, q = odom.pose.pose.position, odom.pose.pose.orientation
        assert (t.x, t.y, t.z, r.x, r.y, r.z, r.w) == (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    assert transforms[-1][1][0].transform.translation.z > 0.0   # the pose moves: not a constant transform


def test_the_body_frame_of_a_nested_namespace_is_the_namespace_path(tmp_path):
    """Frame ids of the vehicle in namespace /fleet/uav2: every body-frame field says fleet/uav2/base_link."""
    recorded = fly_recorded(tmp_path / 'bag', duration=1.1, namespace='/fleet/uav2/')
    frames = {}
    with AnyReader([recorded.bag]) as reader:
        for connection, _, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            if connection.topic == '/tf':
                frames['tf'] = (msg.transforms[0].header.frame_id, msg.transforms[0].child_frame_id)
            elif connection.topic == '/fleet/uav2/odom':
                frames['odom'] = (msg.header.frame_id, msg.child_frame_id)
            elif connection.topic == '/fleet/uav2/control/wrench':
                frames['wrench'] = msg.header.frame_id
            elif connection.topic == '/fleet/uav2/setpoints':
                frames['setpoints'] = (msg.header.frame_id, list(msg.joint_names))
    assert frames == {'tf': ('odom', 'fleet/uav2/base_link'), 'odom': ('odom', 'fleet/uav2/base_link'),
                      'wrench': 'fleet/uav2/base_link', 'setpoints': ('odom', ['fleet/uav2/base_link'])}


def test_mcap_reader_sees_the_ros2_profile_schemas_channels_and_values(flight):
    with open(mcap_file(flight.bag), 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        assert {s.name for s in summary.schemas.values()} == {t.type for t in RECORDED_TOPICS}
        assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
        odometry_schema = next(s for s in summary.schemas.values() if s.name == ODOM.type).data.decode()
        assert 'MSG: geometry_msgs/PoseWithCovariance' in odometry_schema   # full definition, dependencies too
        channels = {c.topic: c for c in summary.channels.values()}
        assert set(channels) == {name(t) for t in RECORDED_TOPICS}
        for topic in RECORDED_TOPICS:
            channel = channels[name(topic)]
            assert channel.message_encoding == 'cdr'
            assert summary.schemas[channel.schema_id].name == topic.type
            assert channel.metadata['topic_type_hash'] == TYPESTORE.hash_rihs01(topic.type)
            [qos] = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            assert (qos['reliability'], qos['durability'], qos['depth']) == (
                topic.qos.reliability, topic.qos.durability, topic.qos.depth)
            expected = 1 if topic in ONCE else flight.result.steps
            assert summary.statistics.channel_message_counts[channel.id] == expected
        assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
        assert len(summary.chunk_indexes) >= 2
        odometry = [(message.log_time, decoded) for _, channel, message, decoded in reader.iter_decoded_messages()
                    if channel.topic == name(ODOM)]
    assert [t for t, _ in odometry] == step_stamps(flight)
    for (_, msg), values in zip(odometry, flight.published.steps):
        sample = values[0]
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        assert (p.x, p.y, p.z, q.x, q.y, q.z, q.w) == (*sample.position, *sample.orientation)
        assert msg.header.frame_id == 'odom' and msg.child_frame_id == 'quad/base_link'
        assert (msg.twist.twist.angular.x, msg.twist.twist.angular.y, msg.twist.twist.angular.z) == \
            sample.angular_velocity


def transform_values(transform) -> tuple:
    """A geometry_msgs/TransformStamped as plain values: frames, stamp [s, ns], translation [m], rotation (xyzw)."""
    t, r = transform.transform.translation, transform.transform.rotation
    return (transform.header.frame_id, transform.child_frame_id, transform.header.stamp.sec,
            transform.header.stamp.nanosec, t.x, t.y, t.z, r.x, r.y, r.z, r.w)


def test_the_bag_describes_the_vehicle_once_at_the_first_step_latched(flight):
    """robot_description (the URDF) and /tf_static (the rotor links), as the simulator publishes them, once each at
    the flight's first stamp, read by mcap + mcap-ros2-support as ROS 2 messages; offered transient local, so
    rosbag2 replays them latched; and the review still reads the bag."""
    described = {}
    with open(mcap_file(flight.bag), 'rb') as stream:
        reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
        channels = {c.topic: c for c in reader.get_summary().channels.values()}
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=['/quad/robot_description', '/tf_static']):
            described.setdefault(channel.topic, []).append((message.log_time, decoded))
    first_stamp = step_stamps(flight)[0]
    [(log_time, description)] = described['/quad/robot_description']
    assert log_time == first_stamp
    assert description.data == vehicle_urdf(PARAMS, 'quad')
    robot = ElementTree.fromstring(description.data)
    rotors = [f'quad/rotor_{i}' for i in range(1, 5)]
    assert [link.get('name') for link in robot.iter('link')] == ['quad/base_link', *rotors]
    joints = {joint.find('child').get('link'): joint for joint in robot.iter('joint')}
    assert sorted(joints) == rotors and {joint.get('type') for joint in joints.values()} == {'fixed'}
    [(log_time, tf_static)] = described['/tf_static']
    assert log_time == first_stamp
    assert [transform_values(t) for t in tf_static.transforms] == \
        [transform_values(t) for t in rotor_transforms_msg(rosbags_kit(), PARAMS, ['quad']).transforms]
    assert [(t.header.frame_id, t.child_frame_id) for t in tf_static.transforms] == \
        [('quad/base_link', rotor) for rotor in rotors]
    assert [(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z)
            for t in tf_static.transforms] == [tuple(position) for position in PARAMS.rotor_positions]
    topics = {entry['topic_metadata']['name']: entry['topic_metadata'] for entry in
              yaml.safe_load((flight.bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information'][
                  'topics_with_message_count']}
    for topic in ('/quad/robot_description', '/tf_static'):
        for [qos] in (yaml.safe_load(channels[topic].metadata['offered_qos_profiles']),
                      topics[topic]['offered_qos_profiles']):
            assert (qos['durability'], qos['reliability'], qos['depth']) == ('transient_local', 'reliable', 1)
    reviewed = read_flight(flight.bag)
    assert np.array_equal(reviewed.record.time, flight.result.record.time)
    assert np.array_equal(reviewed.record.position, flight.result.record.position)


def test_metadata_yaml_is_a_rosbag2_jazzy_bag(flight):
    information = yaml.safe_load((flight.bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    steps = flight.result.steps
    file_name = mcap_file(flight.bag).name
    assert information['version'] == 9
    assert information['storage_identifier'] == 'mcap'
    assert information['ros_distro'] == 'jazzy'
    assert information['relative_file_paths'] == [file_name]
    assert (information['compression_format'], information['compression_mode']) == ('', '')
    total = len(PER_STEP) * steps + len(ONCE)
    assert information['message_count'] == total
    assert information['starting_time'] == {'nanoseconds_since_epoch': 0}
    assert information['duration'] == {'nanoseconds': step_stamps(flight)[-1]}
    assert information['files'] == [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': 0},
                                     'duration': information['duration'], 'message_count': total}]
    topics = {entry['topic_metadata']['name']: entry for entry in information['topics_with_message_count']}
    for topic in RECORDED_TOPICS:
        entry = topics[name(topic)]
        assert entry['message_count'] == (1 if topic in ONCE else steps)
        metadata = entry['topic_metadata']
        assert metadata['type'] == topic.type and metadata['serialization_format'] == 'cdr'
        assert metadata['type_description_hash'] == TYPESTORE.hash_rihs01(topic.type)
        [qos] = metadata['offered_qos_profiles']
        assert qos['history'] == 'keep_last' and qos['reliability'] == topic.qos.reliability
    custom = information['custom_data']
    assert json.loads(custom['vehicle'])['d'] == PARAMS.d
    assert float(custom['settle_time_s']) == 1.0 and custom['controller'] == 'nnit2fsmc'


def ros_type_hashes() -> dict:
    """RIHS01 hashes of the installed ROS 2 interface packages (their share/<pkg>/msg/<Type>.json)."""
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p] + ['/opt/ros/jazzy']
    hashes = {}
    for topic in RECORDED_TOPICS:
        package, _, message = topic.type.split('/')
        for prefix in prefixes:
            description = Path(prefix) / 'share' / package / 'msg' / f'{message}.json'
            if description.is_file():
                entries = json.loads(description.read_text())['type_hashes']
                hashes[topic.type] = next(e['hash_string'] for e in entries if e['type_name'] == topic.type)
                break
    return hashes


@pytest.mark.skipif(not ros_type_hashes(), reason='no ROS 2 Jazzy interface packages installed')
def test_type_hashes_equal_those_of_ros_jazzy():
    hashes = ros_type_hashes()
    assert {t: TYPESTORE.hash_rihs01(t) for t in hashes} == hashes


def test_rosbags_convert_to_sqlite3_keeps_every_payload(flight, tmp_path):
    converted = tmp_path / 'sqlite_bag'
    subprocess.run([sys.executable, '-m', 'rosbags.convert', '--src', str(flight.bag), '--dst', str(converted),
                    '--dst-storage', 'sqlite3'], check=True, capture_output=True)
    assert list(converted.glob('*.db3'))

    def messages(bag):
        with AnyReader([bag]) as reader:
            return [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]
    original, copy = messages(flight.bag), messages(converted)
    assert len(original) == len(PER_STEP) * flight.result.steps + len(ONCE)
    assert sorted(copy) == sorted(original)
