"""run_stack.py as a newcomer meets it: bad settings refused before anything is flown or written, an
earlier run never lost (interrupted, failed or refused runs, both backends), help that works without
the bag libraries, errors that say what to do, one name for the fuzzy share, short flights."""
import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

import run_stack
from flight_stack import embedded, ros_backend
from flight_stack.output import RUN_ENTRIES, STAGING_MARK
from nnit2fsmc_controller.factory import DEFAULT_CONTROLLER_FILE, load_gains, locate_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.bag.flight_bag import FlightBag
from quad_msgs_bridge.bag.metadata import read_metadata
from quad_msgs_bridge.bag.reader import is_finalized, mcap_file
from quad_msgs_bridge.review.metrics import default_settle_time
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
PARAMS, DISTURBANCES = load_vehicle_file()


def snapshot(folder: Path) -> dict:
    """{relative path: bytes} of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob('*')) if p.is_file()}


def staging_folders(parent: Path) -> list[Path]:
    return sorted(p for p in parent.iterdir() if STAGING_MARK in p.name)


@pytest.fixture(scope='module')
def earlier_run_template(tmp_path_factory):
    """A real earlier run (2 s flight with bag and report, no plots), to be protected."""
    out = tmp_path_factory.mktemp('earlier') / 'run'
    sys.modules['matplotlib'], saved = None, sys.modules.get('matplotlib')
    try:
        assert run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '2', '--out', str(out)]) == 0
    finally:
        if saved is None:
            del sys.modules['matplotlib']
        else:
            sys.modules['matplotlib'] = saved
    return out


@pytest.fixture
def earlier_run(earlier_run_template, tmp_path):
    out = tmp_path / 'run'
    shutil.copytree(earlier_run_template, out)
    return out, snapshot(out)


def gains_file(tmp_path: Path, old: str, new: str, source: Path = DEFAULT_CONTROLLER_FILE) -> str:
    """A copy of the gains file ``source`` (default: the packaged one) with ``old`` replaced by ``new`` once."""
    text = source.read_text()
    assert old in text
    path = tmp_path / 'gains.yaml'
    path.write_text(text.replace(old, new, 1))
    return str(path)


BAD_SETTINGS = {   # the settings of issue 10 (and a few more) -> what the error must name
    'control_rate 0': (lambda tmp: ['--gains', gains_file(tmp, 'control_rate: 1000.0', 'control_rate: 0')],
                       'common.control_rate: 0.0 is outside the valid range (0.0, inf)'),
    'negative learning_rate': (lambda tmp: ['--gains', gains_file(tmp, 'learning_rate: 0.9,', 'learning_rate: -0.9,',
                                                                        locate_gains('untuned'))],
                               'nnit2fsmc.axes.x.learning_rate: -0.9 is outside the valid range [0.0, inf)'),
    'type_reducer kmx': (lambda tmp: ['--gains', gains_file(tmp, 'type_reducer: km ', 'type_reducer: kmx ')],
                         "type_reducer: 'kmx' is not one of km, nie-tan"),
    'unknown gain max_tlit': (lambda tmp: ['--gains', gains_file(tmp, 'max_tilt: 0.8 ', 'max_tlit: 0.3 ')],
                              'common.max_tlit: unknown gain (did you mean common.max_tilt?)'),
    'misspelt section lamda': (lambda tmp: ['--gains', gains_file(tmp, 'lambda:', 'lamda:')],
                               'common.lamda.x: unknown gain (did you mean common.lambda.x?)'),
    'seed -3': (lambda tmp: ['--seed', '-3'], '--seed: -3 is outside the valid range [0, 2147483647]'),
    'physics rate 1500': (lambda tmp: ['--physics-rate', '1500'],
                          '--physics-rate: 1500 Hz is not a whole multiple of the control rate 1000 Hz'),
    'max error -1': (lambda tmp: ['--max-error', '-1'], '--max-error: -1.0 is outside the valid range (0.0, inf)'),
    'max error nan': (lambda tmp: ['--max-error', 'nan'], '--max-error: must be finite, got nan'),
    'settle time inf': (lambda tmp: ['--settle-time', 'inf'], '--settle-time: must be finite, got inf'),
    'settle time = duration': (lambda tmp: ['--duration', '5', '--settle-time', '5'],
                               '--settle-time: 5 s leaves nothing of the 5 s flight for the metrics; pass a '
                               '--settle-time below 5 (e.g. --settle-time 2.5'),
    'unknown topic': (lambda tmp: ['--topics', 'odometry'], "'odometry' is not a recorded contract topic"),
    'negative duration': (lambda tmp: ['--duration', '-1'], '--duration: -1.0 is outside the valid range'),
}


@pytest.mark.parametrize('case', BAD_SETTINGS)
def test_bad_settings_are_refused_before_flying_and_the_earlier_run_is_untouched(case, earlier_run, tmp_path,
                                                                                  capsys):
    out, before = earlier_run
    options, expected = BAD_SETTINGS[case]
    # --overwrite: even a run allowed to replace the earlier one must not touch it when its settings are wrong
    status = run_stack.main(['--backend', 'embedded', '--quiet', '--out', str(out), '--overwrite', *options(tmp_path)])
    captured = capsys.readouterr()
    assert status == 2
    assert captured.err.startswith('error: ') and expected in captured.err, captured.err
    assert 'flying' not in captured.out
    assert snapshot(out) == before
    assert staging_folders(out.parent) == []


def test_an_earlier_run_is_replaced_only_with_overwrite(earlier_run, capsys, no_plots):
    out, before = earlier_run
    assert run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '1', '--out', str(out)]) == 2
    assert 'holds an earlier run' in capsys.readouterr().err and snapshot(out) == before
    assert run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '1', '--out', str(out),
                           '--overwrite', '--no-bag']) == 0
    # the new run wrote only a summary: the earlier bag and report went with the earlier summary
    assert sorted(p.name for p in out.iterdir()) == ['summary.json']
    assert json.loads((out / 'summary.json').read_text())['duration_s'] == pytest.approx(0.999)
    assert staging_folders(out.parent) == []


def test_an_interrupted_run_keeps_its_closed_bag_beside_the_untouched_earlier_run(earlier_run, monkeypatch, capsys):
    out, before = earlier_run
    real = embedded.fly_embedded

    def interrupted_after_300_steps(*args, stop=None, **kwargs):
        asked = iter(range(300))
        return real(*args, stop=lambda: next(asked, None) is None, **kwargs)

    monkeypatch.setattr(embedded, 'fly_embedded', interrupted_after_300_steps)
    status = run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '2', '--out', str(out), '--overwrite'])
    err = capsys.readouterr().err
    assert status == 130
    assert snapshot(out) == before
    [kept] = staging_folders(out.parent)
    assert f'interrupted; bag closed: {kept / "bag"}' in err and f'the unfinished run stays in {kept}' in err
    assert f'{out} is unchanged' in err
    assert is_finalized(mcap_file(kept / 'bag'))
    counts = {t['topic_metadata']['name']: t['message_count'] for t in read_metadata(kept / 'bag')['topics_with_message_count']}
    assert counts['/quad/odom'] == 300
    assert not (kept / 'summary.json').exists()


def test_a_flight_that_fails_its_checks_is_a_complete_run(earlier_run, capsys, no_plots):
    out, _ = earlier_run
    status = run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '2', '--out', str(out), '--overwrite',
                             '--max-error', '1e-9'])
    captured = capsys.readouterr()
    assert status == 1
    assert 'result: FAILED: max position error' in captured.out and 'exceeds --max-error 1e-09 m' in captured.out
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['flight_ok'] is False and summary['duration_s'] == pytest.approx(1.999)
    assert {p.name for p in out.iterdir()} <= set(RUN_ENTRIES) and (out / 'report.html').exists()
    assert is_finalized(mcap_file(out / 'bag'))
    assert staging_folders(out.parent) == []


def fake_ros_flight(failed_node):
    """A stand-in for flight_stack.ros_backend.fly_ros (no ROS here): the bag the recorder node would write at
    ``config.bag``, from the embedded loop; then the nodes' outcome: all well, or ``failed_node`` died."""
    def fly_ros(config):
        [vehicle] = config.vehicles
        with FlightBag.create(config.bag, PARAMS, config.settle_time, namespace=vehicle.namespace,
                              controller=config.controller, scenario=config.scenario, backend='ros',
                              seed=config.seed) as bag:
            embedded.fly_embedded(config.controller, make_scenario(config.scenario, config.duration), PARAMS,
                                  DISTURBANCES.switched(config.disturbances), load_gains(), config.duration,
                                  config.physics_rate, bag=bag)
        codes = {'recorder': 0, 'trajectory': 0, 'controller': -9 if failed_node else 0, 'sim': 0}
        return ros_backend.RosFlightResult(1.0, failed_node, codes, '[sim] 1000 steps/s')
    return fly_ros


def test_the_ros_backend_gets_the_same_guarantees(earlier_run, monkeypatch, capsys, no_plots):
    out, before = earlier_run
    options = ['--backend', 'ros', '--quiet', '--duration', '1.5', '--out', str(out), '--overwrite']
    monkeypatch.setitem(sys.modules, 'rclpy', types.ModuleType('rclpy'))   # as where ROS is installed
    monkeypatch.setattr(ros_backend, 'fly_ros', fake_ros_flight('controller'))
    assert run_stack.main(options) == 1
    err = capsys.readouterr().err
    assert snapshot(out) == before
    [kept] = staging_folders(out.parent)
    assert 'error: the flight failed: controller' in err and f'the bag is closed: {kept / "bag"}' in err
    assert is_finalized(mcap_file(kept / 'bag'))
    shutil.rmtree(kept)

    monkeypatch.setattr(ros_backend, 'fly_ros', fake_ros_flight(None))
    assert run_stack.main(options) == 0
    captured = capsys.readouterr()
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['backend'] == 'ros' and summary['ros']['timing']['answered'] == 1500
    assert f'bag: {out / "bag"}' in captured.out and f'report: {out / "report.html"}' in captured.out
    assert str(out / 'bag') in (out / 'report.md').read_text()        # the report names the bag where it is now
    assert staging_folders(out.parent) == []


def test_an_unwritable_output_folder_fails_before_flying(tmp_path, capsys):
    (tmp_path / 'a_file').write_text('')
    for out in [tmp_path / 'a_file' / 'x'] + ([Path('/sys/x')] if os.path.isdir('/sys/kernel') else []):
        assert run_stack.main(['--backend', 'embedded', '--no-bag', '--out', str(out)]) == 2
        captured = capsys.readouterr()
        assert captured.err.startswith('error: --out: ') and 'flying' not in captured.out


def test_a_5_s_flight_settles_for_half_of_it(tmp_path, capsys):
    assert run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '5', '--no-bag', '--out',
                           str(tmp_path / 'run')]) == 0
    summary = json.loads((tmp_path / 'run' / 'summary.json').read_text())
    assert summary['settle_time_s'] == 2.5 and summary['flight_ok']
    assert 'after settling (2.5 s)' in capsys.readouterr().out


def test_the_fuzzy_share_has_one_name_and_only_with_a_fuzzy_term(tmp_path, capsys):
    for controller in ('nnit2fsmc', 'smc-sign'):
        assert run_stack.main(['--backend', 'embedded', '--quiet', '--duration', '1.5', '--no-bag', '--controller',
                               controller, '--out', str(tmp_path / controller)]) == 0
    out = capsys.readouterr().out
    assert 'corrective share' not in out
    assert 'fuzzy share per 5 s window (first; after settling: min, max, largest rise, last):\n    x      0.' in out
    assert 'no window starts after settling' in out     # 1.5 s: the only window holds the take-off
    assert 'fuzzy share: n/a (smc-sign has no fuzzy term)' in out
    assert json.loads((tmp_path / 'smc-sign' / 'summary.json').read_text())['fuzzy_share'] is None
    assert set(json.loads((tmp_path / 'nnit2fsmc' / 'summary.json').read_text())['fuzzy_share']) == \
        {'x', 'y', 'z', 'phi', 'theta', 'psi'}


def run_without(module: str, *args: str) -> subprocess.CompletedProcess:
    """run_stack.py in a Python where ``module`` cannot be imported (as outside the virtual environment)."""
    code = (f'import runpy, sys; sys.modules[{module!r}] = None; sys.argv = ["run_stack.py", *{list(args)!r}]; '
            'runpy.run_path("run_stack.py", run_name="__main__")')
    return subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True, text=True,
                          timeout=HANG_TIMEOUT_S)


def test_help_works_without_the_bag_libraries():
    result = run_without('rosbags', '--help')
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith('usage: run_stack.py') and '--overwrite' in result.stdout


@pytest.mark.parametrize('module, distribution', [('rosbags', 'rosbags'), ('numpy', 'numpy')])
def test_a_missing_library_says_how_to_run_the_stack(module, distribution, tmp_path):
    result = run_without(module, '--backend', 'embedded', '--no-bag', '--out', str(tmp_path / 'run'))
    assert result.returncode == 2
    assert 'Traceback' not in result.stderr
    assert f'error: the Python package {distribution} (module {module}) is not installed' in result.stderr
    assert 'bash scripts/fly.sh' in result.stderr and '.venv/bin/python run_stack.py' in result.stderr
    assert not (tmp_path / 'run').exists()


@pytest.mark.parametrize('command', [[], ['review'], ['recover'], ['rosbag2-qos'], ['tune'], ['stress']])
def test_help_is_plain_text(command, capsys):
    with pytest.raises(SystemExit) as done:
        run_stack.main([*command, '--help'])
    assert done.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith('usage: ')
    for markup in (':mod:', ':func:', ':class:', ':meth:', '``'):
        assert markup not in text, markup


@pytest.mark.parametrize('duration, settle', [(60.0, 5.0), (10.0, 5.0), (5.0, 2.5), (1.0, 0.5)])
def test_the_default_settling_window_is_5_s_or_half_a_short_flight(duration, settle):
    assert default_settle_time(duration) == settle
