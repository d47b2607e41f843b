"""Outputs that never mislead and bad input refused before flying (issue 27's defects): a failed, an
interrupted and a truncated flight are each reviewed as such; an unwritable or empty --out, the ROS
backend without rclpy and ignored settings are refused before anything flies; review --out never
replaces a run silently; hold() and update() name what is wrong; the state layout is told one way."""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import run_stack
from flight_stack.api import fly, hold, make_controller
from flight_stack.output import STAGING_MARK, RunOutput
from nnit2fsmc_controller.controller import check_inputs
from quad_msgs_bridge.bag.reader import mcap_file
from quad_msgs_bridge.bag.recover import recover
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.review.command import main as review_main
from quad_msgs_bridge.review.flight_from_bag import read_flight
from quad_msgs_bridge.state import DPHI, DPSI, DTHETA, PHI, PSI, STATE_LAYOUT, STATE_NAMES, THETA
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
FLY = ['--backend', 'embedded', '--quiet', '--scenario', 'hover']


@pytest.fixture(scope='module')
def run_6s(tmp_path_factory):
    """A complete 6 s hover run (bag, summary, report), to cut short, review and export."""
    out = tmp_path_factory.mktemp('run') / 'run'
    saved = sys.modules.get('matplotlib')
    sys.modules['matplotlib'] = None
    try:
        assert run_stack.main([*FLY, '--duration', '6', '--out', str(out)]) == 0
    finally:
        if saved is None:
            del sys.modules['matplotlib']
        else:
            sys.modules['matplotlib'] = saved
    return out


def report_lines(folder: Path) -> tuple[str, str]:
    return (folder / 'report.md').read_text(), (folder / 'report.html').read_text()


# --- 1, 2: a failed, an interrupted and a truncated flight are reviewed as such ---------------------------------

def test_a_flight_that_fails_its_max_error_check_is_reviewed_as_failed(tmp_path, capsys, no_plots):
    out = tmp_path / 'failed'
    assert run_stack.main([*FLY, '--duration', '3', '--max-error', '0.0001', '--out', str(out)]) == 1
    assert 'result: FAILED: max position error' in capsys.readouterr().out
    assert json.loads((out / 'summary.json').read_text())['flight_ok'] is False
    for text in report_lines(out):
        assert 'FAILED: max position error' in text and 'exceeds --max-error 0.0001 m' in text
        assert 'no failure recorded' not in text and 'OK: flew its whole duration' not in text
    # the bag says so too: reviewed again later, the flight is still failed
    assert review_main([str(out / 'bag'), '--out', str(tmp_path / 'again')]) == 1     # it FAILED: review exits 1
    assert 'FAILED: max position error' in report_lines(tmp_path / 'again')[0]
    [reviewed] = json.loads((tmp_path / 'again' / 'review.json').read_text())
    assert reviewed['flight_ok'] is False and reviewed['ended_early'] is None


def test_a_complete_flight_is_reviewed_as_ok(run_6s, tmp_path):
    assert '| result | OK: flew its whole duration (6 s) |' in report_lines(run_6s)[0]
    flight = read_flight(run_6s / 'bag')
    assert not flight.ended_early and flight.ending is None


def test_a_truncated_bag_is_reviewed_as_ended_early_and_says_where(run_6s, tmp_path, no_plots):
    bag = tmp_path / 'bag'
    shutil.copytree(run_6s / 'bag', bag)
    storage = mcap_file(bag)
    os.truncate(storage, storage.stat().st_size // 2)
    recover(bag)
    flight = read_flight(bag)
    assert flight.ended_early
    assert flight.end_time < 5.0
    assert flight.ending == f'stopped (interrupted, or its bag was cut short) at {flight.end_time:.3f} s of 6 s'
    assert review_main([str(bag), '--out', str(tmp_path / 'review')]) == 1     # it FAILED: review exits 1
    for text in report_lines(tmp_path / 'review'):
        assert f'FAILED: the flight ended early: stopped (interrupted, or its bag was cut short) at ' \
               f'{flight.end_time:.3f} s of 6 s' in text
        assert 'OK: flew its whole duration' not in text


def test_an_interrupted_flight_is_reviewed_as_interrupted_and_says_where(tmp_path, no_plots):
    out = tmp_path / 'stopped'
    process = subprocess.Popen([sys.executable, str(ROOT / 'run_stack.py'), '--backend', 'embedded',
                                '--scenario', 'hover', '--duration', '1e6', '--out', str(out)], cwd=ROOT,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in process.stdout:
        if '; flying' in line:
            break
    time.sleep(1.0)
    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=HANG_TIMEOUT_S) == 130
    [staging] = [folder for folder in tmp_path.iterdir() if STAGING_MARK in folder.name]
    flight = read_flight(staging / 'bag')
    assert flight.ended_early
    assert flight.ending == f'interrupted at {flight.end_time:.3f} s of 1e+06 s'
    assert review_main([str(staging / 'bag'), '--out', str(tmp_path / 'review')]) == 1     # it FAILED: review exits 1
    for text in report_lines(tmp_path / 'review'):
        assert f'FAILED: the flight ended early: interrupted at {flight.end_time:.3f} s of 1e+06 s' in text


# --- 3, 4, 5: refused before flying ----------------------------------------------------------------------------

def test_a_read_only_out_folder_is_refused_before_flying(tmp_path):
    """A read-only --out (a read-only mount as root, who may write into any folder; a folder without write
    permission otherwise) is refused at once, exit 2, and nothing is left beside it."""
    folder = tmp_path / 'ro'
    folder.mkdir()
    command = [sys.executable, str(ROOT / 'run_stack.py'), *FLY, '--duration', '2', '--out', str(folder)]
    if os.geteuid() == 0:
        if shutil.which('unshare') is None:
            pytest.skip('as root, a read-only folder needs a read-only mount (unshare is not installed)')
        inner = ' '.join(f"'{part}'" for part in command)
        command = ['unshare', '-m', 'sh', '-c',
                   f"mount --bind '{folder}' '{folder}' && mount -o remount,ro,bind '{folder}' && exec {inner}"]
    else:
        folder.chmod(0o555)
    result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(f'error: --out: cannot write into {folder}')
    assert 'flying' not in result.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ['ro']      # no staging folder, no lock left over


def test_an_empty_out_is_refused(tmp_path, capsys):
    before = sorted(os.listdir(ROOT))
    with pytest.raises(SystemExit) as stopped:
        run_stack.main([*FLY, '--duration', '1', '--out', ''])
    assert stopped.value.code == 2
    assert "--out: an empty path" in capsys.readouterr().err
    with pytest.raises(ParameterError, match='out: expected a folder path'):
        fly('nnit2fsmc', 'hover', duration=1.0, out='')
    assert sorted(os.listdir(ROOT)) == before


def test_the_ros_backend_without_rclpy_is_refused_in_one_line_before_any_node_starts(tmp_path):
    script = ('import sys; sys.modules["rclpy"] = None\n'            # rclpy cannot be imported, as without ROS
              'import run_stack; sys.exit(run_stack.main(sys.argv[1:]))')
    result = subprocess.run([sys.executable, '-c', script, '--backend', 'ros', '--duration', '1', '--out',
                             str(tmp_path / 'o_ros')], cwd=ROOT, capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    assert result.returncode == 2
    assert result.stderr.count('\n') == 1 and result.stderr.startswith('error: --backend ros: rclpy cannot be '
                                                                       'imported')
    assert 'flying' not in result.stdout and not (tmp_path / 'o_ros').exists()


# --- 6: review --out over a run -------------------------------------------------------------------------------

def test_review_out_over_a_run_is_refused_without_overwrite(run_6s, tmp_path, capsys, no_plots):
    out = tmp_path / 'run'
    shutil.copytree(run_6s, out)
    report = (out / 'report.md').read_bytes()
    assert review_main([str(out / 'bag'), '--out', str(out)]) == 2
    assert f'--out: {out} holds an earlier review or run' in capsys.readouterr().err
    assert (out / 'report.md').read_bytes() == report
    (out / 'plots').mkdir()
    (out / 'plots' / 'old.png').write_bytes(b'')
    assert review_main([str(out / 'bag'), '--out', str(out), '--overwrite', '--no-plots']) == 0
    assert not (out / 'plots' / 'old.png').exists()          # no stale picture is taken for the new review's
    assert (out / 'summary.json').exists() and (out / 'bag' / 'metadata.yaml').exists()   # the run stays


# --- 7: the state layout -------------------------------------------------------------------------------------

def test_the_state_layout_text_is_what_update_and_the_model_read():
    """The last three states are Euler-angle rates: the model's eq. (1) integrates them into the angles,
    and every text that gives the layout says so."""
    names = re.sub(r'\[[^]]*\]|\([^)]*\)', '', STATE_LAYOUT)      # units and remarks out
    assert [name.strip() for name in names.split(',')] == list(STATE_NAMES)
    assert 'Euler-angle rates' in STATE_LAYOUT and 'body' not in STATE_LAYOUT.replace('not body rates', '')
    params, disturbances = load_vehicle_file()
    model = QuadrotorModel(params, disturbances.switched(False))
    state = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.3, -0.2, 0.5, 0.7, -0.4, 0.9]      # tilted: body rates differ
    derivative = model.derivative(0.0, state, model.controls([2.0] * 4))
    assert [derivative[i] for i in (PHI, THETA, PSI)] == [state[i] for i in (DPHI, DTHETA, DPSI)]
    with pytest.raises(ValueError) as refused:
        make_controller().update(0.0, state[:11], hold((0.0, 0.0, 1.0)))
    assert STATE_LAYOUT in str(refused.value)
    import flight_stack.api
    assert 'Euler-angle rates, not body rates' in ' '.join(flight_stack.api.__doc__.split())


# --- 8: hold() and update() ----------------------------------------------------------------------------------

@pytest.mark.parametrize('arguments, named', [
    (((0.0, 0.0),), 'position: expected 3 numbers'),
    (((0.0, 0.0, 'a'),), 'position[2]: expected a number'),
    (('abc',), 'position: expected 3 numbers'),
    (((0.0, 0.0, float('nan')),), 'position[2]: must be finite'),
    (((0.0, 0.0, 1.0), None), 'yaw: expected a number'),
])
def test_hold_refuses_a_bad_point_naming_the_argument(arguments, named):
    with pytest.raises(ParameterError, match=f'^{named}'.replace('[', r'\[').replace(']', r'\]')):
        hold(*arguments)


def test_hold_takes_numpy_numbers():
    assert hold(np.array([0.0, 1.0, 2.0]), np.float32(0.5)) == hold((0.0, 1.0, 2.0), 0.5)


@pytest.mark.parametrize('state, reference, named', [
    (['a'] * 12, hold((0.0, 0.0, 1.0)), "state[0] (x): expected a number, got 'a'"),
    ([0.0] * 11 + [None], hold((0.0, 0.0, 1.0)), 'state[11] (dpsi): expected a number, got None'),
    ([0.0] * 12, ReferenceSample((0.0, 0.0), (0.0,) * 3, (0.0,) * 3, 0.0), 'reference.position: expected 3 values'),
    ([0.0] * 12, ReferenceSample((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, 0.0, jerk=None), 'reference.jerk: expected 3'),
    ([0.0] * 12, ReferenceSample((0.0,) * 3, (0.0,) * 3, (0.0,) * 3, 'north'), "reference.yaw: expected a number"),
])
def test_update_refuses_non_numbers_and_bad_references_naming_the_argument(state, reference, named):
    controller = make_controller()
    with pytest.raises(ValueError) as refused:
        controller.update(0.0, state, reference)
    assert str(refused.value).startswith(named)
    assert check_inputs(0.0, [0.0] * 12, hold((0.0, 0.0, 1.0)), None) is not None   # a good one passes


# --- 9, 10: ignored settings and smaller ones ----------------------------------------------------------------

@pytest.mark.parametrize('options, message', [
    (['--mode', 'realtime'], '--mode realtime: an option of the ROS backend'),
    (['--record-by', 'recorder'], '--record-by recorder: an option of the ROS backend'),
    (['--extra-subscribers', '2'], '--extra-subscribers 2: an option of the ROS backend'),
    (['--vehicles', '0'], '--vehicles: 0 is outside the valid range 1 to 20'),
])
def test_settings_the_flight_would_ignore_are_refused(options, message, tmp_path, capsys):
    assert run_stack.main([*FLY, '--duration', '1', '--out', str(tmp_path / 'o'), *options]) == 2
    captured = capsys.readouterr()
    assert captured.err.startswith(f'error: {message}') and 'flying' not in captured.out
    assert not (tmp_path / 'o').exists()


@pytest.mark.parametrize('settings, message', [
    ({'mass_change': {'at_s': 50.0, 'mass_kg': 1.3}}, 'mass_change.at_s: 50 s is not before the end of the 1 s'),
    ({'rotor_efficiency_loss': {'at_s': 1.0, 'loss': [0.2, 0, 0, 0]}}, 'rotor_efficiency_loss.at_s: 1 s is not'),
])
def test_a_vehicle_change_after_the_flights_end_is_refused(settings, message):
    with pytest.raises(ParameterError, match=f'^{message}'):
        fly('nnit2fsmc', 'hover', duration=1.0, **settings)


def test_fly_names_an_unknown_controller_and_takes_a_gains_mapping():
    with pytest.raises(ParameterError, match="^controller: 'pidd' is not a known kind \\(did you mean pid\\?\\); known: "
                                             "nnit2fsmc"):
        fly('pidd', 'hover', duration=1.0)
    from nnit2fsmc_controller.factory import load_gains
    gains = load_gains()
    gains['common']['lambda']['z'] = 3.0
    given = json.dumps(gains, sort_keys=True)
    flown = fly('nnit2fsmc', 'hover', duration=0.5, gains=gains, settle_time=0.2, seed=5)
    assert flown.summary['gains']['common']['lambda']['z'] == 3.0 and flown.summary['gains']['nnit2fsmc']['seed'] == 5
    assert json.dumps(gains, sort_keys=True) == given                # the caller's mapping is not changed
    with pytest.raises(ParameterError, match=r'^gains: common\.lambda\.zz: unknown gain \(did you mean common\.lambda\.z\?\)'):
        fly('nnit2fsmc', 'hover', duration=0.5, gains={'common': {'lambda': {'zz': 3.0}}})
    one_key = fly('nnit2fsmc', 'hover', duration=0.5, gains={'common': {'lambda': {'z': 3.0}}}, settle_time=0.2, seed=5)
    assert one_key.summary['gains'] == flown.summary['gains']         # one key merged over the packaged set


def test_leftovers_of_unfinished_runs_are_cleared_or_named(tmp_path):
    out = tmp_path / 'run'
    empty, kept = tmp_path / f'run{STAGING_MARK}0000aaaa', tmp_path / f'run{STAGING_MARK}0000bbbb'
    empty.mkdir()
    (kept / 'bag').mkdir(parents=True)
    output = RunOutput(out, out / 'bag', overwrite=False)
    output.create()
    try:
        assert output.leftovers == [kept] and not empty.exists()
    finally:
        output.discard()


def test_the_run_command_names_the_leftovers(tmp_path, capsys):
    kept = tmp_path / f'run{STAGING_MARK}0000bbbb'
    (kept / 'bag').mkdir(parents=True)
    assert run_stack.main([*FLY, '--no-bag', '--duration', '0.5', '--settle-time', '0.2',
                           '--out', str(tmp_path / 'run')]) == 0
    assert f'note: earlier runs into {tmp_path / "run"} that did not finish left {kept}' in capsys.readouterr().err


# --- 10: the campaign's --resume and --fail-below ------------------------------------------------------------

def write_spec(folder: Path, **changes) -> Path:
    import yaml
    document = {'scenario': 'hover', 'duration': 1.0, 'settle_time': 0.5, 'controllers': ['nnit2fsmc', 'pid'],
                'flights': 2, 'seed': 1, **changes}
    path = folder / 'spec.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


def test_resume_on_a_folder_without_a_campaign_is_refused(tmp_path, capsys):
    spec = write_spec(tmp_path)
    assert run_stack.main(['campaign', str(spec), '--out', str(tmp_path / 'typo'), '--resume', '--quiet']) == 2
    assert capsys.readouterr().err.startswith(f'error: --resume: {tmp_path / "typo"} holds no campaign to resume')
    assert not (tmp_path / 'typo').exists()


def test_fail_below_exits_1_naming_each_controller_below_it(tmp_path, capsys):
    spec = write_spec(tmp_path, max_error_m=1e-6)          # no flight keeps within a micrometre: all fail
    out = tmp_path / 'campaign'
    assert run_stack.main(['campaign', str(spec), '--out', str(out), '--fail-below', '0.5', '--workers', '1',
                           '--quiet']) == 1
    err = capsys.readouterr().err
    for controller in ('nnit2fsmc', 'pid'):
        assert f'FAILED: {controller} finished 0 of 2 flights, below --fail-below 0.5' in err
    from flight_stack.campaign.cli import gate
    assert gate(out / 'campaign.json', 0.0) == 0
    assert run_stack.main(['campaign', str(spec), '--out', str(tmp_path / 'x'), '--fail-below', '1.5']) == 2
    assert 'error: --fail-below: 1.5 is outside the valid range' in capsys.readouterr().err


# --- also build: export --------------------------------------------------------------------------------------

@pytest.mark.parametrize('file_format', ['csv', 'parquet'])
def test_export_round_trips_a_flight_with_one_row_per_step_and_unit_names(run_6s, tmp_path, file_format, capsys):
    from flight_stack.export import read_table
    path = tmp_path / f'flight.{file_format}'
    assert run_stack.main(['export', str(run_6s / 'bag'), '--format', file_format, '--out', str(path)]) == 0
    assert capsys.readouterr().out == f'exported: {path}\n'
    table = read_table(path)
    flight = read_flight(run_6s / 'bag')
    assert len(table['time_s']) == flight.steps == 6000
    assert list(table)[:4] == ['time_s', 'x_m', 'y_m', 'z_m']
    assert {'vx_mps', 'phi_rad', 'dpsi_radps', 'F1_N', 'U1_N', 'U4_Nm', 'S_x_mps', 'S_phi_radps', 'nn_z_N',
            'fuzzy_x_mps2'} <= set(table)
    columns = flight.columns()
    assert len(table) == len(columns)
    for (name, values), (exported, back) in zip(columns.items(), table.items()):
        assert exported.startswith(name + '_') and np.array_equal(values, back), name   # exactly, every digit
    assert run_stack.main(['export', str(run_6s / 'bag'), '--out', str(path)]) == 2     # no silent overwrite
    assert f'--out: {path} exists; pass --overwrite' in capsys.readouterr().err


def test_export_keeps_every_step_of_a_flight_longer_than_the_rows_a_flight_keeps(tmp_path, monkeypatch):
    """A Flight thins its rows past MAX_ROWS; the export still has one row per control step."""
    from flight_stack.export import export_flight, read_table
    from quad_msgs_bridge.review import flight_data
    monkeypatch.setattr(flight_data.FlightLog.__init__, '__defaults__', (64,))     # thin past 64 rows
    flown = fly('nnit2fsmc', 'hover', duration=0.3, settle_time=0.1, out=tmp_path / 'run')
    assert flown.stride > 1
    table = read_table(export_flight(tmp_path / 'run' / 'bag', tmp_path / 'flight.csv'))
    assert len(table['time_s']) == flown.steps == 300
    assert np.array_equal(table['time_s'][::flown.stride], flown.time)


def test_export_parquet_without_pyarrow_says_how_to_get_it(run_6s, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, 'pyarrow', None)
    assert run_stack.main(['export', str(run_6s / 'bag'), '--format', 'parquet', '--out',
                           str(tmp_path / 'f.parquet')]) == 2
    assert 'pip install pyarrow==25.0.0' in capsys.readouterr().err and not (tmp_path / 'f.parquet').exists()
