"""The embedded fleet: N vehicles on one sim clock stepped as one batch, recorded and reviewed together."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from flight_stack.embedded import fly_embedded, fly_fleet
from flight_stack.fleet import fleet_layout
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.urdf import vehicle_urdf
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
PARAMS, DISTURBANCES = load_vehicle_file()
DURATION = 1.5


@pytest.mark.slow
def test_the_fleet_batch_equals_each_vehicle_flown_alone():
    vehicles = fleet_layout(3)
    trajectories = [make_scenario('paper', DURATION, offset=v.offset) for v in vehicles]
    fleet = fly_fleet('nnit2fsmc', trajectories, PARAMS, DISTURBANCES, load_gains(), DURATION, 1000.0)
    for trajectory, flown in zip(trajectories, fleet):
        alone = fly_embedded('nnit2fsmc', trajectory, PARAMS, DISTURBANCES, load_gains(), DURATION, 1000.0).record
        assert flown.record.time.shape == alone.time.shape == (1500,)
        assert np.abs(flown.record.position - alone.position).max() <= 1e-9
        assert np.abs(flown.record.forces - alone.forces).max() <= 1e-9
        np.testing.assert_array_equal(flown.record.reference_position, alone.reference_position)
    # three copies of the same flight, 3 m apart along y
    assert np.allclose(fleet[2].record.position[:, 1] - fleet[0].record.position[:, 1], 6.0, atol=1e-9)


@pytest.mark.slow
def test_run_stack_flies_records_and_reviews_an_embedded_fleet(tmp_path):
    out = tmp_path / 'fleet'
    done = subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), '--backend', 'embedded', '--vehicles', '2',
                           '--duration', '1', '--quiet', '--out', str(out)],
                          capture_output=True, text=True, timeout=HANG_TIMEOUT_S, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert 'uav1' in done.stdout and 'uav2' in done.stdout and 'result: OK' in done.stdout
    summary = json.loads((out / 'summary.json').read_text())
    assert sorted(summary['vehicles']) == ['uav1', 'uav2'] and summary['flight_ok']
    assert summary['vehicles']['uav2']['offset_m'] == [0.0, 3.0, 0.0]
    typestore = jazzy_typestore()
    with AnyReader([out / 'bag'], default_typestore=typestore) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        tf = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()
              if c.topic == '/tf']
        described = {c.topic: (t, reader.deserialize(raw, c.msgtype)) for c, t, raw in reader.messages()
                     if c.topic in ('/uav1/robot_description', '/uav2/robot_description', '/tf_static')}
    assert counts['/clock'] == counts['/uav1/odom'] == counts['/uav2/odom'] == counts['/tf'] == 1000
    # every vehicle's description once, at the first step: its URDF in its namespace, one /tf_static for all
    assert counts['/uav1/robot_description'] == counts['/uav2/robot_description'] == counts['/tf_static'] == 1
    assert {topic: t for topic, (t, _) in described.items()} == dict.fromkeys(described, 0) and len(described) == 3
    for name in ('uav1', 'uav2'):
        assert described[f'/{name}/robot_description'][1].data == vehicle_urdf(PARAMS, name)
    assert [t.child_frame_id for t in described['/tf_static'][1].transforms] == \
        [f'{name}/rotor_{i}' for name in ('uav1', 'uav2') for i in range(1, 5)]
    assert [t.child_frame_id for t in tf[-1].transforms] == ['uav1/base_link', 'uav2/base_link']
    uav1, uav2 = (t.transform.translation for t in tf[-1].transforms)
    assert abs(uav2.y - uav1.y - 3.0) < 1e-9 and abs(uav2.x - uav1.x) < 1e-9
    review = json.loads((out / 'review.json').read_text())
    assert [entry['label'] for entry in review] == ['uav1', 'uav2']
    for name, entry in zip(('uav1', 'uav2'), review):
        assert entry['rmse_position_m'] == summary['vehicles'][name]['rmse_position_m']
    assert (out / 'report.html').exists()


def test_a_fleet_says_when_its_kernels_compile_and_when_they_are_ready(capsys):
    """Issue 35: a fleet's first run compiled for a minute without a word. With progress it says so as a single
    flight does, before the first control step and after it."""
    vehicles = fleet_layout(2)
    fleet = fly_fleet('pid', [make_scenario('hover', 0.02, offset=v.offset) for v in vehicles], PARAMS, DISTURBANCES,
                      load_gains(), 0.02, 1000.0, progress=True)
    assert [result.steps for result in fleet] == [20, 20]
    lines = [line for line in capsys.readouterr().err.splitlines() if 'kernels' in line]
    assert lines[0] == '  compiling the kernels (numba; cached after the first run)'
    assert lines[1].startswith('  kernels ready in ') and lines[1].endswith(' s; flying') and len(lines) == 2
