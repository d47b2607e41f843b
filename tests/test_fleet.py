"""The fleet of run_stack.py --vehicles N without ROS: names, offset copies of the scenario, where the shared
nodes run, the per-vehicle summary, the refusals, and the bag and rosbag2 QoS overrides of several vehicles."""
import subprocess
import sys

import pytest
import yaml
from rosbags.highlevel import AnyReader

from flight_stack.fleet import (FLEET_SPACING_M, FleetVehicle, fleet_home, fleet_layout, fleet_summary,
                                format_fleet_summary)
from quad_msgs_bridge.bag.metadata import rosbag2_qos_overrides
from quad_msgs_bridge.bag.writer import BagWriter
from quad_msgs_bridge.contract import RECORDED_TOPICS
from ros_support import ROOT
from hang_guard import HANG_TIMEOUT_S


def test_a_lone_vehicle_keeps_its_namespace_and_the_scenario():
    assert fleet_layout(1) == (FleetVehicle('quad', (0.0, 0.0, 0.0)),)
    assert fleet_layout(1, '/uav7') == (FleetVehicle('uav7', (0.0, 0.0, 0.0)),)


def test_a_fleet_is_uav1_to_uavN_three_metres_apart_along_y():
    assert FLEET_SPACING_M == 3.0
    assert fleet_layout(3) == (FleetVehicle('uav1', (0.0, 0.0, 0.0)), FleetVehicle('uav2', (0.0, 3.0, 0.0)),
                               FleetVehicle('uav3', (0.0, 6.0, 0.0)))
    assert [v.namespace for v in fleet_layout(2, 'team')] == ['team/uav1', 'team/uav2']


def test_the_simulator_and_recorder_run_beside_a_lone_vehicle_or_in_the_fleets_parent():
    assert fleet_home(fleet_layout(1)) == ('quad', [''])
    assert fleet_home(fleet_layout(3)) == ('', ['uav1', 'uav2', 'uav3'])
    assert fleet_home(fleet_layout(2, '/team/')) == ('team', ['uav1', 'uav2'])
    assert fleet_home([FleetVehicle('a/uav1'), FleetVehicle('b/uav2')]) == ('', ['a/uav1', 'b/uav2'])


def vehicle_summary(rmse: float, ok: bool = True) -> dict:
    return {'controller': 'nnit2fsmc', 'scenario': 'paper', 'vehicle': 'x500', 'backend': 'ros', 'duration_s': 7.0,
            'wall_time_s': 20.0,
            'settle_time_s': 5.0, 'rmse_position_m': rmse, 'max_position_error_m': 2 * rmse, 'rmse_yaw_rad': 0.001,
            'saturation_fraction': 0.0, 'flight_ok': ok, 'failures': [] if ok else ['max position error too big'],
            'offset_m': [0.0, 3.0, 0.0], 'ros': {'timing': {'latency_p99_ms': 1.25}}}


def test_the_fleet_fails_when_one_vehicle_fails_and_the_table_names_it():
    fleet = fleet_summary({'uav1': vehicle_summary(0.01), 'uav2': vehicle_summary(0.02, ok=False)})
    assert not fleet['flight_ok']
    assert fleet['failures'] == ['uav2: max position error too big']
    assert list(fleet['vehicles']) == ['uav1', 'uav2']
    table = format_fleet_summary(fleet).splitlines()
    assert table[0].startswith('fleet: nnit2fsmc on "paper", 2 vehicles (x500) on one clock')
    uav1 = next(line for line in table if line.strip().startswith('uav1'))
    uav2 = next(line for line in table if line.strip().startswith('uav2'))
    assert '1.000' in uav1 and '2.000' in uav1 and '1.250' in uav1 and uav1.endswith('OK')   # cm, cm, ms
    assert uav2.endswith('FAILED') and '(0, 3, 0)' in uav2
    assert table[-1] == '  result: FAILED: uav2: max position error too big'
    assert fleet_summary({'uav1': vehicle_summary(0.01), 'uav2': vehicle_summary(0.02)})['flight_ok']


@pytest.mark.parametrize('arguments, message', [
    (['--vehicles', '0'], '--vehicles: 0 is outside the valid range 1 to 20 (a whole number)'),
    (['--vehicles', '2', '--backend', 'embedded', '--live'], '--live: the live view shows one vehicle'),
])
def test_run_stack_refuses_a_bad_fleet_before_flying(arguments, message, tmp_path):
    done = subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), *arguments, '--out', str(tmp_path)],
                          capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    assert done.returncode == 2
    assert f'error: {message}' in done.stderr
    assert 'Traceback' not in done.stderr and not (tmp_path / 'bag').exists()


PER_VEHICLE = ['odom', 'rotor_forces', 'setpoints', 'reference_path', 'control/wrench', 'control/reference',
               'control/diagnostics', 'robot_description']


def test_a_fleet_bag_has_each_vehicles_topics_and_one_clock_tf_and_tf_static(tmp_path):
    with BagWriter(tmp_path / 'bag', RECORDED_TOPICS, ['uav1', '/team/uav2']):
        pass
    with AnyReader([tmp_path / 'bag']) as reader:
        topics = sorted(c.topic for c in reader.connections)
    assert topics == sorted([f'/uav1/{name}' for name in PER_VEHICLE] + [f'/team/uav2/{name}' for name in PER_VEHICLE]
                            + ['/clock', '/tf', '/tf_static'])


def test_rosbag2_qos_overrides_cover_every_vehicle():
    overrides = yaml.safe_load(rosbag2_qos_overrides(['uav1', 'uav2']))
    assert sorted(overrides) == sorted([f'/uav{k}/{name}' for k in (1, 2) for name in PER_VEHICLE]
                                       + ['/clock', '/tf', '/tf_static'])
    assert overrides['/uav2/odom']['depth'] == 1000
    # /tf as tf2 publishes it (reliable, volatile), with the lockstep topics' history (contract.TF_QOS)
    assert (overrides['/tf']['reliability'], overrides['/tf']['durability'], overrides['/tf']['depth']) == \
        ('reliable', 'volatile', 1000)
    # the vehicle's description latched, as the simulator offers it: `ros2 bag record` started late still gets it
    for latched in ('/uav1/robot_description', '/tf_static'):
        assert (overrides[latched]['durability'], overrides[latched]['depth']) == ('transient_local', 1)
