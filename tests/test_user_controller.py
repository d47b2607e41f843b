"""A user's controller in every command (docs/CONTROLLERS.md): the example package of examples/pd_controller
installed as a user installs it, then flown by fly(), listed, flown in a campaign beside a built-in kind,
tuned, stressed and run by the ROS controller node; the contract's checks; gains one key at a time."""
import csv
import importlib
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from flight_stack.api import ParameterError, fly, hold, make_controller
from nnit2fsmc_controller.contract import ContractController, Gain
from nnit2fsmc_controller.factory import choose_controller, load_gains, with_settings
from nnit2fsmc_controller.registry import controller_kind, register
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from ros_support import requires_ros

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / 'examples' / 'pd_controller'
PARAMS = load_vehicle_file()[0]


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """The example package installed by pip into a folder of its own (as `pip install` puts it in a venv),
    that folder put on this process's path and on its children's (PYTHONPATH)."""
    target = tmp_path_factory.mktemp('site')
    subprocess.run([sys.executable, '-m', 'pip', 'install', '--quiet', '--disable-pip-version-check', '--no-deps',
                    '--target', str(target), str(EXAMPLE)], check=True)
    sys.path.insert(0, str(target))
    importlib.invalidate_caches()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(target), *filter(None, [os.environ.get('PYTHONPATH')])]))
    yield target, env
    sys.path.remove(str(target))


def run_stack(env, *arguments, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), *arguments], env=env, cwd=cwd,
                          capture_output=True, text=True)


def test_the_installed_example_is_found_by_its_entry_point_and_said_where_it_came_from(installed):
    _, env = installed
    done = run_stack(env, 'list', 'controllers')
    assert done.returncode == 0, done.stderr
    line = next(line for line in done.stdout.splitlines() if line.startswith('geometric-pd '))
    assert 'entry point quad_pd_example:GeometricPD of quad-pd-example 0.1.0' in line
    assert 'cascaded PID/PD' in line
    kind = controller_kind('geometric-pd')
    assert kind.gains_section == 'geometric_pd' and not kind.batched
    assert [d.name for d in kind.search_space] == ['position.kp', 'position.ki', 'position.kd', 'height.kp', 'height.ki',
                                                   'height.kd']


def test_fly_flies_it_by_entry_point_by_module_class_and_by_class_alike(installed):
    from quad_pd_example import GeometricPD
    flights = [fly(name, 'hover', duration=8.0, disturbances=False)
               for name in ('geometric-pd', 'quad_pd_example:GeometricPD', GeometricPD)]
    rmse = [flight.summary['rmse_position_m'] for flight in flights]
    assert all(flight.summary['flight_ok'] for flight in flights)
    assert rmse[0] == rmse[1] == rmse[2] < 0.01    # the same law, however it is named; no disturbance to fight
    assert flights[0].summary['controller'] == 'geometric-pd'
    assert flights[0].summary['gains']['geometric_pd']['position'] == {'kp': 25.0, 'ki': 15.0, 'kd': 10.0}


def test_one_of_its_gains_changes_by_mapping_and_by_set_and_a_bad_one_is_refused_by_name(installed):
    one_key = {'geometric_pd': {'position': {'kp': 12.0}}}
    by_mapping = fly('geometric-pd', 'hover', duration=3.0, gains=one_key)
    tree = load_gains(None, kind='geometric-pd')
    by_set = fly('geometric-pd', 'hover', duration=3.0, gains=with_settings(tree, ['geometric_pd.position.kp=12']))
    assert by_mapping.summary['gains']['geometric_pd']['position'] == {'kp': 12.0, 'ki': 15.0, 'kd': 10.0}
    assert by_mapping.summary['rmse_position_m'] == by_set.summary['rmse_position_m']
    assert by_mapping.summary['rmse_position_m'] != fly('geometric-pd', 'hover', duration=3.0).summary['rmse_position_m']
    with pytest.raises(ParameterError, match=r'geometric_pd\.position\.kpp: unknown gain .*did you mean '
                                             r'geometric_pd\.position\.kp'):
        fly('geometric-pd', 'hover', duration=3.0, gains={'geometric_pd': {'position': {'kpp': 1.0}}})
    with pytest.raises(ParameterError, match=r'geometric_pd\.attitude\.kp: 1000000.0 is outside the valid range \[20.0, 800.0\]'):
        make_controller('geometric-pd', gains={'geometric_pd': {'attitude': {'kp': 1e6}}})


class Silly:
    """returns what the contract forbids: first NaN thrusts, then three values"""

    def __init__(self, vehicle, gains, dt):
        self.calls = 0

    def update(self, t, state, reference):
        self.calls += 1
        return (math.nan,) * 4 if self.calls == 1 else (1.0, 1.0, 1.0)


class Constant:
    """thrusts far beyond the rotor limits, the same each update"""

    def __init__(self, vehicle, gains, dt):
        self.vehicle = vehicle

    def update(self, t, state, reference):
        return (-5.0, 1e6, self.vehicle.hover_force, 0.0)


def test_the_contract_refuses_non_finite_or_malformed_thrusts_and_clips_the_rest():
    state = [0.0, 0.0, 1.0] + [0.0] * 9
    silly = make_controller(Silly)
    with pytest.raises(ValueError, match='non-finite rotor thrusts'):
        silly.update(0.0, state, hold((0.0, 0.0, 1.0)))
    with pytest.raises(ValueError, match='must return 4 rotor thrusts'):
        silly.update(0.0, state, hold((0.0, 0.0, 1.0)))
    out = make_controller(Constant).update(0.0, state, hold((0.0, 0.0, 1.0)))
    assert out.forces == (PARAMS.F_min, PARAMS.F_max, PARAMS.hover_force, 0.0)
    assert out.controls[0] == pytest.approx(PARAMS.F_min + PARAMS.F_max + PARAMS.hover_force)

    class NoUpdate:
        pass
    with pytest.raises(ParameterError, match='has no update'):
        make_controller(NoUpdate)


def test_a_batch_of_a_kind_without_a_batched_update_is_its_vehicles_one_by_one(installed):
    kind = controller_kind('geometric-pd')
    gains = load_gains(None, kind='geometric-pd')
    batch = kind.build('geometric-pd', PARAMS, gains, 3)
    rng = np.random.default_rng(7)
    states = rng.normal(0.0, 0.1, (12, 3)) + np.array([0, 0, 1.0] + [0] * 9)[:, None]
    reference = hold((0.1, -0.2, 1.0))
    together = batch.update(0.0, list(states), reference)
    for k in range(3):
        alone = make_controller('geometric-pd').update(0.0, list(states[:, k]), reference)
        assert tuple(float(f[k]) for f in together.forces) == alone.forces


def test_a_gains_file_made_for_a_kind_flies_that_kind_and_disagreeing_is_refused(tmp_path):
    tuned = tmp_path / 'gains-pid.yaml'
    tuned.write_text(yaml.safe_dump({'/**': {'ros__parameters': {'controller': 'pid',
                                                                  'pid': {'axes': {'x': {'kp': 30.0}}}}}}))
    assert choose_controller(None, tuned) == 'pid'
    assert choose_controller('pid', tuned) == 'pid'
    with pytest.raises(ParameterError, match='was made for controller pid'):
        choose_controller('nnit2fsmc', tuned)
    banana = tmp_path / 'banana.yaml'
    banana.write_text('controller: banana\n')
    flight = run_stack(dict(os.environ), '--gains', str(banana), '--quiet', '--no-bag', '--out', str(tmp_path / 'b'))
    assert flight.returncode == 2 and "'banana' is not a known kind" in flight.stderr


def test_a_registered_class_of_a_script_flies_by_its_name():
    name = register(Constant, 'constant-test')
    assert make_controller(name).name == name
    with pytest.raises(ParameterError, match='exists already'):
        register(Silly, 'pid')


SPEC = {'scenario': 'hover', 'duration': 3.0, 'settle_time': 1.0, 'flights': 4, 'seed': 3,
        'controllers': ['geometric-pd', 'pid'], 'vehicle': {'mass': 0.2}, 'wind': {'mean_speed_mps': 2.0}}


@pytest.mark.slow
def test_a_campaign_tune_and_stress_take_it_beside_the_built_in_kinds(installed, tmp_path):
    _, env = installed
    spec = tmp_path / 'spec.yaml'
    spec.write_text(yaml.safe_dump(SPEC))
    campaign = run_stack(env, 'campaign', str(spec), '--out', str(tmp_path / 'campaign'), '--workers', '2')
    assert campaign.returncode == 0, campaign.stderr
    assert 'geometric-pd steps a batch vehicle by vehicle' in campaign.stderr
    with (tmp_path / 'campaign' / 'flights.csv').open() as stream:
        rows = list(csv.DictReader(stream))
    assert sorted({row['controller'] for row in rows}) == ['geometric-pd', 'pid'] and len(rows) == 8
    assert all(row['finished'] == 'True' for row in rows if row['controller'] == 'geometric-pd')

    tune = run_stack(env, 'tune', str(spec), '--controller', 'geometric-pd', '--trials', '2', '--flights', '2',
                     '--seeds', '1', '--out', str(tmp_path / 'tune'))
    assert tune.returncode == 0, tune.stderr
    tuned = tmp_path / 'tune' / 'gains-geometric-pd.yaml'
    document = yaml.safe_load(tuned.read_text())['/**']['ros__parameters']
    assert document['controller'] == 'geometric-pd' and set(document['geometric_pd']) == {'position', 'height',
                                                                                           'attitude', 'yaw'}
    flown = run_stack(env, '--gains', str(tuned), '--scenario', 'hover', '--duration', '3', '--quiet', '--no-bag',
                      '--out', str(tmp_path / 'tuned-flight'))
    assert flown.returncode == 0, flown.stderr
    assert json.loads((tmp_path / 'tuned-flight' / 'summary.json').read_text())['controller'] == 'geometric-pd'

    stress = run_stack(env, 'stress', str(spec), '--kind', 'wind', '--controllers', 'geometric-pd', '--flights', '4',
                       '--low', '0', '--high', '4', '--resolution', '2', '--out', str(tmp_path / 'stress'))
    assert stress.returncode == 0, stress.stderr
    assert 'geometric-pd' in (tmp_path / 'stress' / 'breaking_points.csv').read_text()


@requires_ros
@pytest.mark.ros
@pytest.mark.slow
def test_the_ros_controller_node_runs_it(installed, tmp_path):
    _, env = installed
    done = run_stack(env, '--backend', 'ros', '--controller', 'geometric-pd', '--scenario', 'hover', '--duration', '3',
                     '--no-bag', '--quiet', '--out', str(tmp_path / 'ros'))
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((tmp_path / 'ros' / 'summary.json').read_text())
    assert summary['controller'] == 'geometric-pd' and summary['backend'] == 'ros' and summary['flight_ok']
