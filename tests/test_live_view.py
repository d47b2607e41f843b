"""The live view without ROS (`run_stack.py --live`): a Foxglove WebSocket client sees the contract
topics with their ROS 2 schemas, decodes the odometry with the rosbags Jazzy typestore, gets a latched
topic it subscribed to late, and leaves mid-flight without stopping it; the bag of a live flight equals
the bag of the same flight without --live; the live options fail cleanly."""
import json
import re
import math
import signal
import socket
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_typestore
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

import run_stack
from flight_stack.live_view import VehicleScene, is_loopback, serve_live_view, PATH_MAX_POINTS
from flight_stack.pacing import MAX_LAG, Pacer
from quad_msgs_bridge.bag.metadata import read_metadata
from quad_msgs_bridge.bag.reader import is_finalized, mcap_file
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
# 3 s of sim time at 1000 Hz control (controller.yaml: control_rate 1000.0): 3000 control steps
FLIGHT = ['--backend', 'embedded', '--duration', '3', '--settle-time', '0', '--quiet']
STEPS = 3000
# as recorded in a bag of namespace quad (docs/BAGS.md), with the ROS 2 type of each
CONTRACT = {'/quad/odom': 'nav_msgs/msg/Odometry', '/quad/rotor_forces': 'std_msgs/msg/Float64MultiArray',
            '/quad/setpoints': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
            '/quad/reference_path': 'nav_msgs/msg/Path', '/quad/control/wrench': 'geometry_msgs/msg/WrenchStamped',
            '/quad/control/reference': 'geometry_msgs/msg/PoseStamped',
            '/quad/control/diagnostics': 'std_msgs/msg/Float64MultiArray', '/clock': 'rosgraph_msgs/msg/Clock',
            '/tf': 'tf2_msgs/msg/TFMessage', '/quad/robot_description': 'std_msgs/msg/String',
            '/tf_static': 'tf2_msgs/msg/TFMessage'}
SCENE_TOPIC = '/quad/scene'
TIMEOUT = HANG_TIMEOUT_S      #: [s] for a message, a connection or the command to end: only a hang takes that long


def message_data(frame: bytes) -> tuple[int, int, bytes]:
    """(subscription id, log time [ns], payload) of a Foxglove WebSocket "Message Data" frame
    (opcode 0x01, then uint32 subscription id and uint64 timestamp, little endian)."""
    assert frame[0] == 0x01, f'not a message data frame: opcode {frame[0]}'
    subscription, log_time = struct.unpack_from('<IQ', frame, 1)
    return subscription, log_time, frame[13:]


def watch_live_flight(url: str) -> dict:
    """Connect to the live view, subscribe, take a few messages, leave while the flight goes on."""
    seen = {'channels': {}}
    with connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=TIMEOUT) as client:
        seen['subprotocol'] = client.subprotocol
        while not set(CONTRACT) | {SCENE_TOPIC} <= set(seen['channels']):
            message = json.loads(client.recv(timeout=TIMEOUT))
            if message['op'] == 'serverInfo':
                seen['capabilities'] = message['capabilities']
            elif message['op'] == 'advertise':
                seen['channels'].update({channel['topic']: channel for channel in message['channels']})
        ids = {topic: channel['id'] for topic, channel in seen['channels'].items()}
        client.send(json.dumps({'op': 'subscribe', 'subscriptions': [
            {'id': 1, 'channelId': ids['/quad/odom']}, {'id': 2, 'channelId': ids[SCENE_TOPIC]}]}))
        received: dict[int, list] = {1: [], 2: [], 3: []}
        while not (received[1] and received[2] and received[3]):
            frame = client.recv(timeout=TIMEOUT)
            if isinstance(frame, str) or frame[0] != 0x01:      # status, time, ... frames
                continue
            subscription, log_time, payload = message_data(frame)
            received[subscription].append((log_time, payload))
            if subscription == 1 and len(received[1]) == 1:     # subscribed after it was sent: latched
                client.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                    {'id': 3, 'channelId': ids['/quad/reference_path']}]}))
        seen['odometry'], seen['scene'], seen['reference_path'] = received[1], received[2], received[3]
    return seen


def start_live_flight(out: Path, *options: str) -> tuple[subprocess.Popen, str]:
    """run_stack.py flying FLIGHT live on a free port; (process, the URL it serves on)."""
    process = subprocess.Popen([sys.executable, str(ROOT / 'run_stack.py'), *FLIGHT, '--out', str(out), '--live',
                                '--live-port', '0', *options],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    while line and not line.startswith('live view: ws://'):
        line = process.stdout.readline()
    assert line, process.communicate(timeout=TIMEOUT)
    return process, line.split()[2]


@pytest.fixture(scope='module')
def live_flight(tmp_path_factory):
    """A live flight (paced at real time, waiting for its client) watched by a client that leaves
    early, and the same flight without --live."""
    out = tmp_path_factory.mktemp('live')
    process, url = start_live_flight(out, '--live-wait', '--speed-factor', '1')
    try:
        seen = watch_live_flight(url)
        stdout, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
    finally:
        if process.poll() is None:
            process.kill()
    plain = tmp_path_factory.mktemp('plain')
    plain_status = run_stack.main([*FLIGHT, '--out', str(plain)])
    return {'url': url, 'seen': seen, 'status': process.returncode, 'stdout': stdout, 'stderr': stderr,
            'bag': out / 'bag', 'plain_status': plain_status, 'plain_bag': plain / 'bag'}


@pytest.mark.slow
def test_the_client_sees_the_contract_topics_with_the_bags_schemas(live_flight):
    seen = live_flight['seen']
    assert live_flight['url'].startswith('ws://127.0.0.1:')
    assert seen['subprotocol'] == 'foxglove.sdk.v1'
    assert 'time' in seen['capabilities']
    with open(mcap_file(live_flight['bag']), 'rb') as stream:
        summary = make_reader(stream).get_summary()
    bag_schemas = {channel.topic: summary.schemas[channel.schema_id] for channel in summary.channels.values()}
    for topic, type_name in CONTRACT.items():
        channel = seen['channels'][topic]
        assert (channel['encoding'], channel['schemaName'], channel['schemaEncoding']) == ('cdr', type_name, 'ros2msg')
        assert channel['schema'] == bag_schemas[topic].data.decode()
    scene = seen['channels'][SCENE_TOPIC]
    assert (scene['encoding'], scene['schemaName']) == ('protobuf', 'foxglove.SceneUpdate')
    print(f'\nlive view {live_flight["url"]} ({seen["subprotocol"]}), capabilities {seen["capabilities"]}:')
    for topic, channel in sorted(seen['channels'].items()):
        print(f'  {topic:28s} {channel["schemaName"]:45s} {channel["encoding"]}')


@pytest.mark.slow
def test_the_client_decodes_the_odometry_with_the_jazzy_typestore(live_flight):
    typestore = get_typestore(Stores.ROS2_JAZZY)
    stamps = []
    for log_time, payload in live_flight['seen']['odometry']:
        odometry = typestore.deserialize_cdr(payload, 'nav_msgs/msg/Odometry')
        assert (odometry.header.frame_id, odometry.child_frame_id) == ('odom', 'quad/base_link')
        stamp = odometry.header.stamp
        assert stamp.sec * 1_000_000_000 + stamp.nanosec == log_time       # log time = sim time, as in the bag
        position, q = odometry.pose.pose.position, odometry.pose.pose.orientation
        assert all(math.isfinite(v) for v in (position.x, position.y, position.z))
        assert math.isclose(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0, abs_tol=1e-9)
        stamps.append(log_time)
    assert stamps == sorted(set(stamps)) and stamps[0] == 0                # in order, from the first step
    assert live_flight['seen']['scene'][0][1]                             # a non-empty SceneUpdate
    path = typestore.deserialize_cdr(live_flight['seen']['reference_path'][0][1], 'nav_msgs/msg/Path')
    assert path.header.frame_id == 'odom' and len(path.poses) == 151      # 3 s at 50 Hz, both ends
    print(f'\nlast odometry taken, t = {log_time / 1e9:.3f} s: {odometry.header.frame_id} -> '
          f'{odometry.child_frame_id}, position ({position.x:.4f}, {position.y:.4f}, {position.z:.4f}) m, '
          f'orientation ({q.x:.5f}, {q.y:.5f}, {q.z:.5f}, {q.w:.5f}); {len(stamps)} odometry messages decoded, '
          f'{len(live_flight["seen"]["scene"])} scene updates; reference_path (subscribed late) with '
          f'{len(path.poses)} poses')


@pytest.mark.slow
def test_a_client_that_leaves_mid_flight_does_not_stop_it(live_flight):
    assert live_flight['status'] == 0, live_flight['stderr']
    assert 'Traceback' not in live_flight['stderr']
    assert len(live_flight['seen']['odometry']) < STEPS                    # it left before the end


def messages(bag: Path) -> list[tuple[str, int, int, bytes]]:
    with open(mcap_file(bag), 'rb') as stream:
        return [(channel.topic, message.log_time, message.publish_time, message.data)
                for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]


@pytest.mark.slow
def test_the_bag_of_a_live_flight_equals_the_bag_without_live(live_flight):
    assert live_flight['plain_status'] == 0
    live, plain = messages(live_flight['bag']), messages(live_flight['plain_bag'])
    # 7 topics per step; setpoints, reference_path, robot_description and /tf_static once
    assert len(live) == len(plain) == 7 * STEPS + 4
    assert live == plain
    counts = [{t['topic_metadata']['name']: t['message_count'] for t in read_metadata(bag)['topics_with_message_count']}
              for bag in (live_flight['bag'], live_flight['plain_bag'])]
    assert counts[0] == counts[1] and counts[0]['/quad/odom'] == STEPS


@pytest.mark.slow
def test_ctrl_c_closes_the_server_and_the_bag(tmp_path):
    process, url = start_live_flight(tmp_path, '--live-wait', '--speed-factor', '1')   # 3 s of wall time
    try:
        with connect(url, subprotocols=['foxglove.sdk.v1'], open_timeout=TIMEOUT) as client:
            channels = {}
            while '/quad/odom' not in channels:
                message = json.loads(client.recv(timeout=TIMEOUT))
                if message['op'] == 'advertise':
                    channels.update({channel['topic']: channel['id'] for channel in message['channels']})
            client.send(json.dumps({'op': 'subscribe',
                                    'subscriptions': [{'id': 1, 'channelId': channels['/quad/odom']}]}))
            frame = client.recv(timeout=TIMEOUT)
            while isinstance(frame, str) or frame[0] != 0x01:
                frame = client.recv(timeout=TIMEOUT)                       # flying: odometry comes
            process.send_signal(signal.SIGINT)
            with pytest.raises(ConnectionClosed):                          # the server went away
                while True:
                    client.recv(timeout=TIMEOUT)
        _, stderr = process.communicate(timeout=TIMEOUT)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130 and 'interrupted; bag closed' in stderr
    bag = Path(re.search(r'bag closed: (\S+)', stderr).group(1))     # kept in the unfinished run's folder
    assert not (tmp_path / 'bag').exists()                              # --out holds no partial run
    assert is_finalized(mcap_file(bag))
    recorded = messages(bag)
    counts = {t['topic_metadata']['name']: t['message_count'] for t in read_metadata(bag)['topics_with_message_count']}
    assert counts == {topic: sum(m[0] == topic for m in recorded) for topic in CONTRACT}
    per_step = [n for topic, n in counts.items()
                if not topic.endswith(('setpoints', 'reference_path', 'robot_description', '/tf_static'))]
    assert 0 < min(per_step) == max(per_step) < STEPS                     # stopped between two steps, mid-flight


def test_every_channel_is_advertised_when_a_client_connects_and_none_can_be_made_later():
    """A client that connects at once gets every channel of the flight in its first messages (they exist before
    the server listens), and a subscription to them is taken; a channel made after the server listens is refused
    (foxglove-sdk could refuse a client's subscription to it: LiveServer)."""
    params, _ = load_vehicle_file()
    view = serve_live_view('127.0.0.1', 0, params)
    with view.server as server, connect(server.url, subprotocols=['foxglove.sdk.v1'], open_timeout=TIMEOUT) as client:
        advertised = {}
        while len(advertised) < len(server._channels):
            message = json.loads(client.recv(timeout=TIMEOUT))
            assert message['op'] in ('serverInfo', 'advertise', 'advertiseServices'), message
            advertised.update({c['topic']: c['id'] for c in message.get('channels', [])})
        assert set(advertised) == set(server._channels) and '/quad/odom' in advertised
        subscription = {'id': 1, 'channelId': advertised['/quad/odom']}
        client.send(json.dumps({'op': 'subscribe', 'subscriptions': [subscription]}))
        assert server.wait_for_subscriber(lambda: True, poll=TIMEOUT)     # taken within TIMEOUT
        with pytest.raises(RuntimeError, match='/later'):
            server.ros_channel('/later', 'nav_msgs/msg/Odometry')


def test_a_port_in_use_is_a_clean_error_before_flying(tmp_path, capsys):
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        status = run_stack.main([*FLIGHT, '--out', str(tmp_path), '--live', '--live-port', str(port)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith('error: ') and f'127.0.0.1:{port}' in err and 'Traceback' not in err
    assert list(tmp_path.iterdir()) == []                                  # nothing flown, no bag


@pytest.mark.parametrize('argv, says', [
    (['--backend', 'ros', '--live'], 'foxglove_bridge'),
    (['--backend', 'embedded', '--speed-factor', '2'], '--speed-factor'),
    (['--backend', 'embedded', '--live', '--speed-factor', '-1'], '--speed-factor'),
    (['--backend', 'embedded', '--live', '--live-port', '70000'], '--live-port'),
    (['--backend', 'embedded', '--live-wait'], '--live-wait'),
])
def test_live_options_are_checked_before_anything_runs(tmp_path, capsys, argv, says):
    assert run_stack.main([*argv, '--out', str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: ') and says in err
    assert list(tmp_path.iterdir()) == []


def test_loopback_hosts():
    assert is_loopback('127.0.0.1') and is_loopback('127.1.2.3') and is_loopback('::1') and is_loopback('localhost')
    assert not is_loopback('0.0.0.0') and not is_loopback('192.168.1.5') and not is_loopback('example.org')


class FakeClock:
    def __init__(self, now: float):
        self.now, self.sleeps = now, []

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds


def at(t: float) -> OdometrySample:
    return OdometrySample(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_the_pacer_sleeps_until_sim_time_over_speed_factor():
    clock = FakeClock(100.0)
    pacer = Pacer(2.0, clock=clock, sleep=clock.sleep)
    pacer.record_step(at(5.0))          # the schedule starts: sim 5.0 s at wall 100.0 s
    assert clock.sleeps == []
    pacer.record_step(at(5.01))         # due at 100.0 + 0.01 / 2
    assert clock.sleeps == [pytest.approx(0.005)]
    clock.now += 0.02                   # a slow step: 0.015 s late, under MAX_LAG: no sleep, no rush
    pacer.record_step(at(5.02))
    assert len(clock.sleeps) == 1
    pacer.record_step(at(5.07))         # due at 100.0 + 0.07 / 2 = 100.035; now 100.025
    assert clock.sleeps[-1] == pytest.approx(0.01)


def test_the_pacer_restarts_its_schedule_after_a_long_stall():
    clock = FakeClock(0.0)
    pacer = Pacer(1.0, clock=clock, sleep=clock.sleep)
    pacer.record_step(at(0.0))
    clock.now += MAX_LAG + 1.0          # e.g. the process was suspended
    pacer.record_step(at(0.01))         # late: no sleep, and the schedule starts again from here
    pacer.record_step(at(0.02))         # due 0.01 s after the restart
    assert clock.sleeps == [pytest.approx(0.01)]
    with pytest.raises(ValueError):
        Pacer(0.0)


def test_the_scene_puts_rotors_and_thrust_vectors_on_the_body():
    params, _ = load_vehicle_file(None)
    scene = VehicleScene(params, 'quad')
    d, hover = params.d, params.m * params.g / 4.0
    yaw_90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))      # body x along odom y
    odometry = OdometrySample(1.0, (1.0, 2.0, 3.0), yaw_90, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    geometry = scene.rotor_geometry(odometry, (hover, 2 * hover, 0.0, hover))
    # front (+x body) -> +y odom; right (-y body) -> +x odom; back -> -y; left -> -x
    expected = [((1.0, 2.0 + d, 3.0), (1.0, 2.0 + d, 3.0 + d)), ((1.0 + d, 2.0, 3.0), (1.0 + d, 2.0, 3.0 + 2 * d)),
                ((1.0, 2.0 - d, 3.0), (1.0, 2.0 - d, 3.0)), ((1.0 - d, 2.0, 3.0), (1.0 - d, 2.0, 3.0 + d))]
    for (hub, tip), (hub_expected, tip_expected) in zip(geometry, expected):
        assert hub == pytest.approx(hub_expected, abs=1e-12) and tip == pytest.approx(tip_expected, abs=1e-12)
    roll_90 = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))     # body z along odom -y
    (_, tip), *_ = scene.rotor_geometry(OdometrySample(0.0, (0.0, 0.0, 0.0), roll_90, (0,) * 3, (0,) * 3),
                                        (hover, 0.0, 0.0, 0.0))
    assert tip == pytest.approx((d, -d, 0.0), abs=1e-12)


def test_the_flown_path_stays_bounded():
    params, _ = load_vehicle_file(None)
    scene = VehicleScene(params, 'quad')
    for k in range(100_000):                # 1000 s at 100 Hz
        scene.add_path_point(k * 0.01, (k * 0.01, 0.0, 0.0))
    assert PATH_MAX_POINTS // 2 <= len(scene.path) <= PATH_MAX_POINTS
