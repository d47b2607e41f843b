"""run_stack.py --plant px4-sitl (flight_stack.px4_sitl, ros_backend.fly_px4, quad_sim.px4_node).

Everywhere: the one-line refusal when PX4 SITL, the Agent or px4_msgs is missing (before anything starts or is
written), the options PX4 SITL refuses, --controller px4 elsewhere, the instance slots, the parameters PX4 gets, our
frame against PX4's (position and heading at arming) and PX4's own controller's setpoints.

Where PX4 SITL, the Agent and px4_msgs are found (env PX4_DIR, MicroXRCEAgent on PATH, px4_msgs importable;
``source /work/px4/env.sh``-like, docs/PX4.md), the tests marked ``px4`` fly PX4's SIH quadrotor in real time:
a short hover with one of our kinds and with PX4's own controller (the bag read back by read_flight and by the
``mcap`` package's reader, the summary), and our controller killed in flight. Elsewhere they skip saying what is
missing; scripts/test.sh runs them in its PX4 lane.
"""
from __future__ import annotations

import glob
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from quad_msgs_bridge import px4
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

ROOT = Path(__file__).resolve().parent.parent


def _px4_missing() -> str | None:
    from flight_stack.px4_sitl import find_px4
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return 'rclpy cannot be imported here'
    try:
        find_px4()
    except ParameterError as error:
        return str(error)
    return None


PX4_MISSING = _px4_missing()
requires_px4 = pytest.mark.skipif(PX4_MISSING is not None, reason=f'PX4 SITL lane: {PX4_MISSING}')


# ------------------------------------------------------------------ everywhere
def test_nothing_found_is_refused_in_one_line_naming_every_missing_piece(monkeypatch, tmp_path):
    from flight_stack import px4_sitl
    monkeypatch.delenv('PX4_DIR', raising=False)
    monkeypatch.setenv('PATH', str(tmp_path))
    monkeypatch.setattr('importlib.util.find_spec', lambda name: None)
    with pytest.raises(ParameterError) as raised:
        px4_sitl.find_px4()
    message = str(raised.value)
    assert '\n' not in message and message.startswith('--plant px4-sitl: missing PX4 SITL')
    assert 'PX4_DIR' in message and 'MicroXRCEAgent is not on PATH' in message and 'px4_msgs (not importable' in message


def _fake_px4(tmp_path: Path) -> Path:
    folder = tmp_path / 'PX4-Autopilot'
    binary = folder / 'build' / 'px4_sitl_default' / 'bin' / 'px4'
    rcs = folder / 'build' / 'px4_sitl_default' / 'etc' / 'init.d-posix' / 'rcS'
    for path in (binary, rcs):
        path.parent.mkdir(parents=True)
        path.write_text('#!/bin/sh\n')
    binary.chmod(0o755)
    return folder


def test_only_the_missing_agent_is_named_when_px4_is_there(monkeypatch, tmp_path):
    from flight_stack import px4_sitl
    folder = _fake_px4(tmp_path)
    monkeypatch.setenv('PX4_DIR', str(folder))
    monkeypatch.setenv('PATH', str(tmp_path / 'nothing'))
    monkeypatch.setattr('importlib.util.find_spec', lambda name: object())
    monkeypatch.setattr(px4, 'px4_msgs_definitions', lambda: tmp_path)
    with pytest.raises(ParameterError, match=r'^--plant px4-sitl: missing the Micro XRCE-DDS Agent \(MicroXRCEAgent '
                                             r'is not on PATH; or give --xrce-agent PATH\) \(docs/PX4.md\)$'):
        px4_sitl.find_px4()
    with pytest.raises(ParameterError, match=r'missing the Micro XRCE-DDS Agent \(/no/agent is not an executable\)'):
        px4_sitl.find_px4(agent='/no/agent')
    agent = tmp_path / 'MicroXRCEAgent'
    agent.write_text('#!/bin/sh\n')
    agent.chmod(0o755)
    install = px4_sitl.find_px4(agent=agent)
    assert install.binary == folder / 'build' / 'px4_sitl_default' / 'bin' / 'px4' and install.agent == agent


def test_a_px4_folder_without_its_build_is_named(monkeypatch, tmp_path):
    from flight_stack import px4_sitl
    with pytest.raises(ParameterError, match=r'missing PX4 SITL \(.*bin/px4 or .*rcS not found: build it with make '
                                             r'px4_sitl_default'):
        px4_sitl.find_px4(tmp_path, agent=sys.executable)


def test_the_command_refuses_before_anything_starts_or_is_written(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != 'PX4_DIR'}
    env['PATH'] = os.path.dirname(sys.executable)          # no MicroXRCEAgent
    out = tmp_path / 'out'
    started = time.monotonic()
    done = subprocess.run([sys.executable, 'run_stack.py', '--plant', 'px4-sitl', '--vehicle', 'px4-sih-quadx',
                           '--controller', 'pid', '--scenario', 'hover', '--out', str(out)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    errors = [line for line in done.stderr.splitlines() if line.startswith('error:')]
    assert done.returncode == 2 and len(errors) == 1 and 'missing PX4 SITL' in errors[0], done.stderr
    assert 'Micro XRCE-DDS Agent' in errors[0] and 'flying' not in done.stdout
    assert not out.exists() and not list(tmp_path.glob('out*'))
    assert time.monotonic() - started < 120


def test_px4s_own_controller_flies_only_on_px4_sitl():
    from flight_stack.plan import plan_flight
    with pytest.raises(ParameterError, match=r"--controller px4: PX4's own controller runs inside PX4; it flies only "
                                             r"with --plant px4-sitl"):
        plan_flight('px4', 'hover')
    plan = plan_flight('px4', 'hover', plant='px4-sitl', vehicle_file='px4-sih-quadx',
                       gain_settings=['common.control_rate=100'])
    assert plan.control_rate == 100.0 and plan.controller == 'px4'


def test_px4_sitl_is_no_simulator_plant():
    from quad_sim.plants import make_plant
    params, disturbances = load_vehicle_file('px4-sih-quadx')
    with pytest.raises(ParameterError, match='plant px4-sitl: PX4 SITL flies it, not a simulator here'):
        make_plant('px4-sitl', params, disturbances)


@pytest.mark.parametrize('options, refused', [
    (['--backend', 'embedded'], '--backend embedded: PX4 SITL is flown over ROS 2'),
    (['--mode', 'lockstep'], '--mode lockstep: PX4 SITL runs in real time'),
    (['--record-by', 'recorder'], '--record-by recorder'),
    (['--vehicles', '2'], '--vehicles: one PX4 SITL flies one vehicle'),
    (['--disturbances'], "--disturbances: SIH cannot apply the paper's disturbances"),
])
def test_options_px4_sitl_cannot_fly_are_refused(monkeypatch, options, refused):
    from flight_stack import cli, px4_sitl
    monkeypatch.setattr(px4_sitl, 'find_px4', lambda *args: 'found')
    args = cli.parse_args(['--plant', 'px4-sitl', '--controller', 'pid', *options])
    with pytest.raises(ParameterError, match=f'^--plant px4-sitl: {refused}'):
        cli.check_px4_options(args)


def test_px4_sitl_flies_realtime_on_its_publication_logs_at_px4s_odometry_rate(monkeypatch):
    from flight_stack import cli, px4_sitl
    monkeypatch.setattr(px4_sitl, 'find_px4', lambda *args: 'found')
    args = cli.parse_args(['--plant', 'px4-sitl', '--controller', 'pid'])
    assert cli.check_px4_options(args) == 'found'
    assert (args.backend, args.mode, args.record_by, args.disturbances) == ('ros', 'realtime', 'publishers', False)
    assert args.gain_settings == ['common.control_rate=100']
    args = cli.parse_args(['--plant', 'px4-sitl', '--controller', 'pid', '--set', 'common.control_rate=250'])
    cli.check_px4_options(args)
    assert args.gain_settings == ['common.control_rate=250']
    with pytest.raises(ParameterError, match='--px4-dir: an option of --plant px4-sitl'):
        cli.check_px4_options(cli.parse_args(['--px4-dir', '/x']))
    with pytest.raises(ParameterError, match='--px4-takeoff: an option of --plant px4-sitl'):
        cli.check_px4_options(cli.parse_args(['--px4-takeoff', 'px4']))
    assert cli.launch_of(cli.parse_args(['--plant', 'px4-sitl'])).px4_takeoff == 'px4'
    assert cli.launch_of(cli.parse_args(['--px4-takeoff', 'controller'])).px4_takeoff == 'controller'


@pytest.mark.parametrize('scenario, offset, takeoff, start', [
    # PX4 takes off to the reference's first point raised to 2.5 m: the hover holds there, the helix leaves from it
    ('hover', (0.0, 0.0, 0.0), 'px4', ((0.0, 0.0, 1.5), (0.0, 0.0, 2.5), 0.0)),
    ('paper', (0.0, 0.0, 0.0), 'px4', ((0.0, 0.0, 2.5), (1.0, 0.0, 2.5), 0.0)),
    ('paper', (0.0, 3.0, 0.5), 'px4', ((0.0, 3.0, 3.0), (1.0, 3.0, 3.0), 0.0)),
    # our controller takes off: on the ground below the first point, as on our simulator
    ('hover', (0.0, 0.0, 0.0), 'controller', ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)),
])
def test_a_px4_flight_starts_where_its_takeoff_leaves_the_vehicle(scenario, offset, takeoff, start):
    from flight_stack.ros_backend import PX4_TAKEOFF_ALTITUDE, px4_flight_start
    assert PX4_TAKEOFF_ALTITUDE == 2.5
    shift, position, yaw = px4_flight_start(scenario, offset, takeoff)
    assert shift == pytest.approx(start[0]) and position == pytest.approx(start[1]) and yaw == pytest.approx(start[2])


def test_each_run_holds_its_own_instance_domain_and_port(monkeypatch, tmp_path):
    from flight_stack import px4_sitl
    monkeypatch.setattr(px4_sitl, 'LOCK_DIR', tmp_path)
    monkeypatch.setattr(px4_sitl, '_px4_daemon_running', lambda instance: False)
    first, second = px4_sitl.take_slot(), px4_sitl.take_slot()
    assert first.instance != second.instance and first.domain_id != second.domain_id
    assert (first.target_system, first.namespace) == (first.instance + 1, f'px4_{first.instance}')
    first.release()
    third = px4_sitl.take_slot()
    assert third.instance == first.instance
    second.release()
    third.release()


def test_px4_gets_the_rc_less_offboard_parameters():
    from flight_stack.px4_sitl import parameters_script
    script = parameters_script()
    for line in ('param set COM_RC_IN_MODE 4', 'param set NAV_DLL_ACT 0', 'param set NAV_RCL_ACT 0',
                 'param set COM_OBL_RC_ACT 4'):
        assert line in script.splitlines()


def test_px4_message_definitions_come_from_the_px4_msgs_install(tmp_path, monkeypatch):
    folder = tmp_path / 'share' / 'px4_msgs' / 'msg'
    folder.mkdir(parents=True)
    (folder / 'VehicleOdometry.msg').write_text('uint64 timestamp\nfloat32[3] position\n')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    assert px4.px4_msgs_definitions() == folder
    types = px4.px4_types(['px4_msgs/msg/VehicleOdometry'], folder)
    assert [name for name, _ in types['px4_msgs/msg/VehicleOdometry'][1]] == ['timestamp', 'position']
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'none'))
    monkeypatch.setattr('importlib.util.find_spec', lambda name: None)
    with pytest.raises(FileNotFoundError, match='px4_msgs message definitions'):
        px4.px4_msgs_definitions()


# ------------------------------------------------------------------ our frame against PX4's
def _flying_core(level: str, initial_position, initial_yaw, px4_position, px4_yaw_enu):
    """An OffboardCore armed and flying, PX4's vehicle at ``px4_position`` [m, ENU] heading ``px4_yaw_enu``."""
    from quad_sim.px4_offboard import (ARMING_STATE_ARMED, NAVIGATION_STATE_OFFBOARD, OffboardConfig, OffboardCore,
                                       Phase, Px4Status)
    sih, _ = load_vehicle_file('px4-sih-quadx')
    core = OffboardCore(sih, OffboardConfig(control_level=level, initial_position=initial_position,
                                            initial_yaw=initial_yaw, settle_time=0.0))
    state = [*px4_position, 0.0, 0.0, 0.0, 0.0, 0.0, px4_yaw_enu, 0.0, 0.0, 0.0]
    t, stamp = 0.0, 1_000_000
    status = Px4Status(1, 4, True)
    while core.phase != Phase.FLYING and t < 5.0:
        if core.phase == Phase.REQUESTING:
            status = Px4Status(ARMING_STATE_ARMED, NAVIGATION_STATE_OFFBOARD, True)
        output = core.tick(t, px4.px4_odometry_from_state(stamp, state), status)
        t, stamp = t + 0.01, stamp + 10_000
    assert core.phase == Phase.FLYING
    return core, output, t, stamp


def test_our_frame_puts_the_vehicle_at_the_scenarios_start_position_and_heading():
    core, output, t, stamp = _flying_core('direct_actuator', (1.0, 0.0, 0.0), 0.0, (3.0, -2.0, 1.5), math.pi / 2)
    first = output.odometry
    assert first.stamp == 0.0 and first.position == pytest.approx((1.0, 0.0, 0.0), abs=1e-9)
    # PX4's vehicle moves 1 m north (ENU +y) at 2 m/s facing north: in our frame that is ahead along +x, heading 0
    state = [3.0, -1.0, 1.5, 0.0, 2.0, 0.0, 0.0, 0.0, math.pi / 2, 0.0, 0.0, 0.0]
    ours = core.tick(t, px4.px4_odometry_from_state(stamp, state)).odometry
    assert ours.position == pytest.approx((2.0, 0.0, 0.0), abs=1e-9)
    assert core.our_state()[3:6] == pytest.approx([2.0, 0.0, 0.0], abs=1e-9)
    assert core.our_state()[8] == pytest.approx(0.0, abs=1e-9)


def test_px4s_own_controller_gets_our_reference_in_its_frame():
    core, _, t, stamp = _flying_core('position', (1.0, 0.0, 0.0), 0.0, (3.0, -2.0, 1.5), math.pi / 2)
    assert core._mode(t).position and core._mode(t).velocity and core._mode(t).acceleration
    # our reference 1 m ahead (+x), 0.5 m/s ahead, heading 0: PX4's 1 m north of its arming point, heading north
    output = core.tick(t + 0.06, None, None, (2.0, 0.0, 1.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.1))
    setpoint = output.setpoint.trajectory
    assert setpoint.position == pytest.approx(px4.ned_from_enu((3.0, -1.0, 2.5)), abs=1e-9)
    assert setpoint.velocity == pytest.approx(px4.ned_from_enu((0.0, 0.5, 0.0)), abs=1e-9)
    assert setpoint.yaw == pytest.approx(0.0, abs=1e-9) and setpoint.yawspeed == pytest.approx(-0.1)


def test_arming_waits_for_pre_flight_checks_and_a_still_estimate():
    from quad_sim.px4_offboard import OffboardConfig, OffboardCore, Phase, Px4Status
    sih, _ = load_vehicle_file('px4-sih-quadx')
    core = OffboardCore(sih, OffboardConfig())
    moving = [0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    still = [0.0] * 12
    t, stamp, events = 0.0, 1, []
    for state, checks, until in ((still, False, 3.0), (moving, True, 6.0), (still, True, 7.9)):
        while t < until:
            output = core.tick(t, px4.px4_odometry_from_state(stamp, state), Px4Status(1, 4, checks))
            events += output.events
            t, stamp = t + 0.01, stamp + 10_000
        assert core.phase == Phase.STREAMING, events
    while core.phase == Phase.STREAMING and t < 9.0:
        core.tick(t, px4.px4_odometry_from_state(stamp, still), Px4Status(1, 4, True))
        t, stamp = t + 0.01, stamp + 10_000
    assert core.phase == Phase.REQUESTING and 7.9 < t <= 8.05
    assert any('pre-flight checks' in e for e in events) and any('to be still before arming' in e for e in events)


# ------------------------------------------------------------------ on PX4 SITL
def _run(args, tmp_path, name, **popen):
    out = tmp_path / name
    command = [sys.executable, 'run_stack.py', '--plant', 'px4-sitl', '--vehicle', 'px4-sih-quadx', '--out', str(out),
               *args]
    return out, subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                 start_new_session=True, **popen)


def _read_with_mcap(bag: Path) -> dict[str, int]:
    """Messages per topic by the ``mcap`` package's own reader (not ours), each PX4 one decoded by rosbags from the
    schema the bag carries."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg
    counts: dict[str, int] = {}
    store = get_typestore(Stores.ROS2_JAZZY)
    with open(glob.glob(str(bag / '*.mcap'))[0], 'rb') as handle:
        reader = make_reader(handle)
        for schema, channel, message in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == '/fmu/out/vehicle_odometry' and counts[channel.topic] == 1:
                assert schema.encoding == 'ros2msg' and schema.name == 'px4_msgs/msg/VehicleOdometry'
                store.register(get_types_from_msg(schema.data.decode(), schema.name))
                decoded = store.deserialize_cdr(message.data, schema.name)
                assert decoded.pose_frame == 1 and len(decoded.q) == 4
    return counts


@pytest.mark.px4
@pytest.mark.slow
@pytest.mark.exclusive
@requires_px4
@pytest.mark.parametrize('kind', ['px4', 'se3'])
def test_a_hover_on_px4_sih_is_recorded_read_back_and_summarised(tmp_path, kind):
    from quad_msgs_bridge.review.flight_from_bag import read_flight
    out, process = _run(['--controller', kind, '--scenario', 'hover', '--duration', '8', '--quiet'], tmp_path, kind)
    stdout, _ = process.communicate(timeout=400)
    summary = json.loads((out / 'summary.json').read_text())
    assert process.returncode in (0, 1), stdout
    assert summary['plant'] == 'px4-sitl' and summary['controller'] == kind and 'PX4 SITL' in summary['ros']['simulator']
    assert 80.0 < summary['ros']['timing']['odometry_rate_hz'] < 300.0
    flight = read_flight(out / 'bag', vehicle_file='px4-sih-quadx')
    assert flight.time[0] == 0.0 and flight.time[-1] > 0.5
    counts = _read_with_mcap(out / 'bag')
    assert counts['/quad/odom'] > 50 and counts['/fmu/out/vehicle_odometry'] > counts['/quad/odom']
    assert counts['/fmu/out/vehicle_status'] > 0 and counts['/fmu/in/offboard_control_mode'] > 20
    assert counts['/fmu/in/vehicle_command'] >= 2        # the offboard switch and arming
    assert counts['/fmu/in/trajectory_setpoint' if kind == 'px4' else '/fmu/in/actuator_motors'] > 50
    if kind == 'px4':     # PX4's own controller flies the whole hover, lands and disarms
        assert process.returncode == 0 and summary['flight_ok'] and summary['failure'] is None, stdout
        assert flight.time[-1] == pytest.approx(8.0, abs=0.05) and 'not_measured' in summary
    else:                 # ours may meet a PX4 failsafe on SIH (docs/PX4.md, "Measured"): then said so
        assert summary['flight_ok'] or 'PX4 failsafe' in (summary['failure'] or '') or summary['failures']
    assert (out / 'report.html').is_file()


@pytest.mark.px4
@pytest.mark.slow
@pytest.mark.exclusive
@requires_px4
def test_our_controller_killed_in_flight_hands_the_vehicle_to_px4s_land_mode(tmp_path):
    """SIGKILL to the controller node once PX4 flies in offboard: the bridge has no rotor forces for its
    forces_timeout and sends NAV_LAND, PX4 lands and disarms, the bridge exits; run_stack.py stops the rest, exits 1
    naming the controller, and the bag stays readable."""
    from quad_msgs_bridge.review.flight_from_bag import read_flight
    out, process = _run(['--controller', 'pid', '--scenario', 'hover', '--duration', '30'], tmp_path, 'killed')
    lines, killed = [], None
    deadline = time.monotonic() + 300
    for line in process.stdout:
        lines.append(line)
        if killed is None and 'our controller flies' in line:
            time.sleep(2.5)       # past its publication log's first complete chunks (a killed node keeps those)
            killed = _controller_pid(process.pid)
            os.kill(killed, signal.SIGKILL)
        assert time.monotonic() < deadline, ''.join(lines)
    process.wait(timeout=60)
    text = ''.join(lines)
    assert killed is not None, text
    assert process.returncode == 1 and 'the flight failed: controller' in text, text
    assert 'no rotor forces for 0.1 s: PX4 lands' in text and 'PX4 disarmed: the flight is over' in text, text
    bags = glob.glob(str(tmp_path / 'killed.incomplete-*' / 'bag'))
    assert bags, text
    counts = _read_with_mcap(Path(bags[0]))
    assert counts['/fmu/in/vehicle_command'] >= 3         # offboard, arm, land
    flight = read_flight(bags[0], vehicle_file='px4-sih-quadx')
    assert flight.time[-1] > 0.5


def _controller_pid(parent: int) -> int:
    """The controller node's process among ``parent``'s children (by its module in the command line)."""
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / 'stat').read_text()
            command = (entry / 'cmdline').read_bytes().replace(b'\0', b' ').decode()
        except OSError:
            continue
        if int(stat.rsplit(')', 1)[1].split()[1]) == parent and 'controller_node' in command:
            return int(entry.name)
    raise AssertionError(f'no controller node under process {parent}')


def test_a_vehicle_that_never_left_the_ground_is_disarmed_in_the_failsafe():
    """The controller never answers: NAV_LAND 1 s after arming; PX4's land mode would keep the vehicle on the
    ground armed (seen on SIH: until COM_DISARM_PRFLT), so once it is still the bridge disarms it."""
    from quad_sim.px4_offboard import (ARMING_STATE_ARMED, NAVIGATION_STATE_AUTO_LAND, VEHICLE_CMD_COMPONENT_ARM_DISARM,
                                       VEHICLE_CMD_NAV_LAND, Phase, Px4Status)
    core, _, t, stamp = _flying_core('direct_actuator', (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), 0.0)
    sent = []
    status = Px4Status(ARMING_STATE_ARMED, 14, True)
    while t < 5.0:
        output = core.tick(t, px4.px4_odometry_from_state(stamp, [0.0] * 12), status)
        sent += [(t, c.command, c.param1) for c in output.commands]
        if any(c.command == VEHICLE_CMD_NAV_LAND for c in output.commands):
            status = Px4Status(ARMING_STATE_ARMED, NAVIGATION_STATE_AUTO_LAND, True)
        t, stamp = t + 0.01, stamp + 10_000
    assert core.phase == Phase.FAILSAFE and 'no rotor forces within 1.0 s' in core.failed
    [land] = [s for s in sent if s[1] == VEHICLE_CMD_NAV_LAND]
    disarms = [s for s in sent if s[1] == VEHICLE_CMD_COMPONENT_ARM_DISARM and s[2] == 0.0]
    assert disarms and disarms[0][0] - land[0] == pytest.approx(1.0, abs=0.05)   # landed_hold after the NAV_LAND
