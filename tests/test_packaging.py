"""`pip install .`: the wheel of the repository root holds the three packages and flight_stack with their
package data, installs with its dependencies into a clean virtual environment (no system site packages),
and every module imports there (the ROS node modules only fail on the ROS 2 modules they need);
the `nnit2fsmc-stack` command flies from the installed files, away from the clone."""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ('flight_stack', 'quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller')
#: modules that import rclpy (the node modules and their helpers): importable only with ROS 2
ROS_ONLY = {'quad_msgs_bridge.ros_helpers', 'quad_msgs_bridge.bag.recorder_node', 'quad_sim.sim_node',
            'quad_sim.px4_node', 'nnit2fsmc_controller.controller_node', 'nnit2fsmc_controller.trajectory_node'}
ROS_MODULES = {'rclpy', 'rcl_interfaces'}
PIP = [sys.executable, '-m', 'pip', '--disable-pip-version-check', '--quiet']

IMPORT_ALL = f'''
import importlib, json, pkgutil
found, failed = [], {{}}
for name in {PACKAGES!r}:
    package = importlib.import_module(name)
    found.append(package.__file__)
    for module in pkgutil.walk_packages(package.__path__, name + '.'):
        if module.name.endswith('.__main__'):   # a command (python -m ...), run rather than imported
            continue
        try:
            importlib.import_module(module.name)
        except ModuleNotFoundError as error:
            failed[module.name] = error.name.split('.')[0]
print(json.dumps({{'files': found, 'failed': failed}}))
'''


def pinned(tmp_path: Path) -> Path:
    """The exact versions of requirements*.txt as a constraints file (the wheel's own ranges allow them)."""
    pins = [line.split('#')[0].strip() for name in ('requirements.txt', 'requirements-bags.txt')
            for line in (ROOT / name).read_text().splitlines() if '==' in line]
    path = tmp_path / 'constraints.txt'
    path.write_text('\n'.join(pins) + '\n')
    return path


def source_copy(tmp_path: Path) -> Path:
    """What `pip install .` reads, copied, so the build leaves nothing in the clone."""
    source = tmp_path / 'source'
    source.mkdir()
    ignore = shutil.ignore_patterns('__pycache__', '*.egg-info')
    for name in ('pyproject.toml', 'README.md'):
        shutil.copy(ROOT / name, source / name)
    shutil.copytree(ROOT / 'flight_stack', source / 'flight_stack', ignore=ignore)
    for package in PACKAGES[1:]:
        folder = Path('ros2_ws') / 'src' / package / package
        shutil.copytree(ROOT / folder, source / folder, ignore=ignore)
    return source


@pytest.fixture(scope='module')
def installed(tmp_path_factory):
    """A clean virtual environment with the wheel of the repository root installed: its python."""
    tmp_path = tmp_path_factory.mktemp('pip-install')
    wheels = tmp_path / 'wheels'
    subprocess.run([*PIP, 'wheel', '--no-deps', '--wheel-dir', str(wheels), str(source_copy(tmp_path))],
                   check=True, timeout=HANG_TIMEOUT_S)
    [wheel] = wheels.glob('*.whl')
    venv = tmp_path / 'venv'
    subprocess.run([sys.executable, '-m', 'venv', '--without-pip', str(venv)], check=True, timeout=HANG_TIMEOUT_S)
    python = venv / 'bin' / 'python'
    subprocess.run([*PIP, '--python', str(python), 'install', '--no-compile', str(wheel), '-c', str(pinned(tmp_path))],
                   check=True, timeout=HANG_TIMEOUT_S)
    return python, wheel


@pytest.mark.slow
def test_the_wheel_holds_the_packages_and_their_configuration(installed):
    _, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    for path in ('flight_stack/cli.py', 'quad_msgs_bridge/bag/reader.py', 'quad_msgs_bridge/review/plots.py',
                 'quad_sim/model.py', 'nnit2fsmc_controller/factory.py', 'quad_msgs_bridge/config/vehicle.yaml',
                 'quad_sim/config/quad_sim.yaml', 'nnit2fsmc_controller/config/controller.yaml',
                 'nnit2fsmc_controller/config/trajectory.yaml', 'flight_stack/campaign/specs/paper-robustness.yaml'):
        assert path in names, path
    assert not [name for name in names if name.startswith(('tests/', 'bench/', 'test/'))]


@pytest.mark.slow
def test_every_module_imports_from_a_clean_environment(installed, tmp_path):
    python, _ = installed
    result = subprocess.run([str(python), '-c', IMPORT_ALL], cwd=tmp_path, capture_output=True, text=True,
                            timeout=HANG_TIMEOUT_S, env={k: v for k, v in os.environ.items() if k != 'PYTHONPATH'})
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert all('site-packages' in path for path in report['files']), report['files']   # not the clone
    assert set(report['failed']) == ROS_ONLY and set(report['failed'].values()) <= ROS_MODULES


@pytest.mark.slow
def test_the_console_script_flies_from_the_installed_files(installed, tmp_path):
    python, _ = installed
    command = python.parent / 'nnit2fsmc-stack'
    env = {k: v for k, v in os.environ.items() if k != 'PYTHONPATH'}
    shown = subprocess.run([str(command), '--help'], cwd=tmp_path, capture_output=True, text=True,
                           timeout=HANG_TIMEOUT_S, env=env)
    assert shown.returncode == 0 and shown.stdout.startswith('usage: nnit2fsmc-stack'), shown.stderr
    flown = subprocess.run([str(command), '--backend', 'embedded', '--quiet', '--duration', '0.5', '--out', 'run'],
                           cwd=tmp_path, capture_output=True, text=True, timeout=HANG_TIMEOUT_S, env=env)
    assert flown.returncode == 0, flown.stderr
    assert json.loads((tmp_path / 'run' / 'summary.json').read_text())['control_steps'] == 500
    # matplotlib is an extra (pip install .[plots]): without it the review says how to get the plots
    assert 'plots skipped: matplotlib is not installed' in flown.stdout and (tmp_path / 'run' / 'report.html').exists()
