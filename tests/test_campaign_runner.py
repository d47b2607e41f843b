"""The campaign command: the same rows whatever the workers (local processes or a Dask cluster),
nothing lost on Ctrl-C, --resume flies only what is missing, --replay equals its row."""
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from flight_stack.campaign.replay import replay_flight
from flight_stack.campaign.results import read_flights, wilson_interval
from flight_stack.campaign.runner import RunOptions, run_campaign
from flight_stack.campaign.spec import parse_spec
from nnit2fsmc_controller.factory import load_gains
from quad_msgs_bridge.validation import ParameterError
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
DOCUMENT = {
    'scenario': 'paper', 'duration': 1.6, 'settle_time': 1.2, 'controllers': ['nnit2fsmc', 'pid'], 'flights': 5,
    'seed': 2, 'control_rate_hz': 250,
    'vehicle': {'mass': 0.05, 'inertia': 0.05, 'cog_offset_m': 0.0005},
    'wind': {'mean_speed_mps': 0.5, 'turbulence': 'light'},
    'sensor_noise': {'position_m': 0.0005, 'attitude_rad': 0.0005},
    'delay_s': 0.004, 'motor_time_constant_s': 0.01,
}
SPEC = parse_spec(DOCUMENT)


def rows_by_key(out_dir: Path) -> dict:
    return {(r['flight'], r['controller']): r for r in read_flights(out_dir / 'flights.csv')}


def assert_same_rows(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        for column, value in a[key].items():
            other = b[key][column]
            assert value == other or (isinstance(value, float) and math.isnan(value) and math.isnan(other)), \
                (key, column, value, other)


@pytest.fixture(scope='module')
def reference_run(tmp_path_factory):
    """The campaign on one local worker, one flight per batch."""
    out = tmp_path_factory.mktemp('one-worker')
    run_campaign(SPEC, out, RunOptions(workers=1, batch_size=1, progress=False))
    return out


def test_the_outputs_hold_every_flight_and_the_summary(reference_run):
    rows = rows_by_key(reference_run)
    assert set(rows) == {(k, c) for k in range(5) for c in ('nnit2fsmc', 'pid')}
    summary = json.loads((reference_run / 'campaign.json').read_text())
    for controller in ('nnit2fsmc', 'pid'):
        entry = summary['controllers'][controller]
        mine = [r for r in rows.values() if r['controller'] == controller]
        finished = [r['rmse_position_m'] for r in mine if r['finished']]
        assert entry['flights'] == 5 and entry['finished'] == len(finished)
        assert entry['success_rate_wilson95'] == pytest.approx(list(wilson_interval(len(finished), 5)))
        assert entry['rmse_position_m']['max'] == pytest.approx(max(finished))
    report = (reference_run / 'report.html').read_text()
    assert 'rmse_cdf.png' in report and (reference_run / 'plots' / 'rmse_cdf.png').exists()
    assert yaml.safe_load((reference_run / 'spec.yaml').read_text()) == SPEC.to_mapping()


def test_wilson_interval_matches_the_formula_by_hand():
    # 95 of 100, z = 1.96: centre (0.95 + 0.019208) / 1.038416 = 0.933352,
    # half 1.96 sqrt(0.000475 + 0.00009604) / 1.038416 = 0.045104
    low, high = wilson_interval(95, 100)
    assert low == pytest.approx(0.888248, abs=2e-5) and high == pytest.approx(0.978456, abs=2e-5)
    assert wilson_interval(0, 10)[0] == pytest.approx(0.0, abs=1e-15)
    assert wilson_interval(10, 10)[1] == pytest.approx(1.0, abs=1e-15)
    assert wilson_interval(10, 10)[0] == pytest.approx(10 / (10 + 1.96 ** 2), abs=1e-3)


@pytest.mark.slow
def test_two_workers_and_other_batches_give_the_same_rows(reference_run, tmp_path):
    run_campaign(SPEC, tmp_path, RunOptions(workers=2, batch_size=3, progress=False))
    assert_same_rows(rows_by_key(reference_run), rows_by_key(tmp_path))


@pytest.mark.slow
def test_a_dask_cluster_gives_the_same_rows(reference_run, tmp_path):
    distributed = pytest.importorskip('distributed')
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host='127.0.0.1',
                                  dashboard_address=None) as cluster:
        run_campaign(SPEC, tmp_path, RunOptions(scheduler=cluster.scheduler_address, batch_size=2, progress=False))
    assert_same_rows(rows_by_key(reference_run), rows_by_key(tmp_path))


def test_an_existing_campaign_is_only_continued_with_resume(reference_run, tmp_path):
    with pytest.raises(ParameterError, match='--resume'):
        run_campaign(SPEC, reference_run, RunOptions(workers=1, progress=False))
    other = SPEC.overridden(seed=3)
    with pytest.raises(ParameterError, match='another spec'):
        run_campaign(other, reference_run, RunOptions(workers=1, resume=True, progress=False))


def test_a_resume_with_other_gains_or_another_vehicle_is_refused_naming_the_first_difference(reference_run, tmp_path):
    """A resume that would mix two controllers under one name is refused; gains the campaign's controllers
    do not read (another kind's section) resume, and fly nothing more."""
    run = shutil.copytree(reference_run, tmp_path / 'run')
    gains = load_gains()
    gains['pid']['axes']['x']['kp'] *= 2.0
    other_pid = tmp_path / 'pid.yaml'
    other_pid.write_text(yaml.safe_dump(gains))
    with pytest.raises(ParameterError, match=r'flew pid with other gains \(pid\.axes\.x\.kp: '):
        run_campaign(SPEC, run, RunOptions(workers=1, resume=True, progress=False,
                                                     gains_file=str(other_pid)))
    with pytest.raises(ParameterError, match=r'flew pid with other gains'):             # nor replayed with them
        replay_flight(SPEC, run, 0, RunOptions(progress=False, gains_file=str(other_pid)))
    gains = load_gains()
    gains['se3']['axes']['x']['k_error'] *= 2.0
    other_se3 = tmp_path / 'se3.yaml'
    other_se3.write_text(yaml.safe_dump(gains))
    before = (run / 'flights.csv').read_text()
    outcome = run_campaign(SPEC, run, RunOptions(workers=1, resume=True, progress=False,
                                                           gains_file=str(other_se3)))
    assert outcome.flights_flown == 0 and (run / 'flights.csv').read_text() == before
    heavier = yaml.safe_load((ROOT / 'ros2_ws/src/quad_msgs_bridge/quad_msgs_bridge/config/vehicle.yaml').read_text())
    heavier['vehicle']['m'] = 0.5
    vehicle = tmp_path / 'vehicle.yaml'
    vehicle.write_text(yaml.safe_dump(heavier))
    with pytest.raises(ParameterError, match=r'another vehicle file \(vehicle\.m: 0\.486 there, 0\.5 now\)'):
        run_campaign(SPEC, run, RunOptions(workers=1, resume=True, progress=False, vehicle_file=str(vehicle)))


def run_cli(*args, **kwargs):
    """``run_stack.py campaign ARGS`` as from a terminal: Ctrl-C (SIGINT) at its default, also when this
    test runs in a background job of a shell (which starts it with SIGINT ignored)."""
    return subprocess.Popen([sys.executable, str(ROOT / 'run_stack.py'), 'campaign', *map(str, args)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **kwargs)


@pytest.mark.slow
def test_ctrl_c_keeps_every_finished_batch_and_resume_flies_the_rest(reference_run, tmp_path):
    spec_file = tmp_path / 'spec.yaml'
    spec_file.write_text(yaml.safe_dump(DOCUMENT))
    for attempt in range(5):      # on a loaded machine the short campaign may end before the signal lands
        out = tmp_path / f'out{attempt}'
        process = run_cli(spec_file, '--out', out, '--workers', 1, '--batch-size', 1, '--quiet')
        deadline = time.monotonic() + HANG_TIMEOUT_S
        while len(read_flights(out / 'flights.csv')) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
        if not (process.returncode == 0 and len(read_flights(out / 'flights.csv')) == 10):
            break                 # the signal landed while flying
    assert process.returncode == 130, stderr
    assert 'rerun with --resume' in stderr
    kept = rows_by_key(out)
    assert 2 <= len(kept) < 10
    reference = rows_by_key(reference_run)
    assert_same_rows(kept, {key: reference[key] for key in kept})
    resumed = run_cli(spec_file, '--out', out, '--workers', 2, '--resume', '--quiet')
    stdout, stderr = resumed.communicate(timeout=HANG_TIMEOUT_S)
    assert resumed.returncode == 0, stderr
    assert f'flew {10 - len(kept)} flights' in stderr
    assert_same_rows(reference, rows_by_key(out))


@pytest.mark.slow
def test_replay_flies_one_flight_on_the_embedded_path_with_its_row_s_metrics(reference_run):
    status = replay_flight(SPEC, reference_run, 3, RunOptions(progress=False))
    rows = rows_by_key(reference_run)
    for controller in ('nnit2fsmc', 'pid'):
        target = reference_run / 'replay-3' / controller
        summary = json.loads((target / 'summary.json').read_text())
        row = rows[(3, controller)]
        assert summary['flight_ok'] == row['finished']
        for key in ('rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'saturation_fraction'):
            assert summary[key] == pytest.approx(row[key], rel=1e-9, abs=1e-12), key
        for i in range(1, 5):
            assert summary['chattering'][f'U{i}'] == pytest.approx(row[f'chattering_U{i}'], rel=1e-9, abs=1e-12)
        assert (target / 'bag' / 'metadata.yaml').exists() and (target / 'report.html').exists()
        review = json.loads((target / 'review.json').read_text())[0]
        assert review['rmse_position_m'] == pytest.approx(summary['rmse_position_m'], rel=1e-12)
    assert status == (0 if all(rows[(3, c)]['finished'] for c in ('nnit2fsmc', 'pid')) else 1)


def test_a_second_campaign_writing_the_same_folder_is_refused_and_adds_no_row(reference_run, tmp_path):
    """A --resume started while the first run still flies would append its flights a second time."""
    from flight_stack.campaign.runner import LOCK_FILE, writing
    before = (reference_run / 'flights.csv').read_text()
    with writing(reference_run):
        assert (reference_run / LOCK_FILE).read_text().strip() == str(os.getpid())
        with pytest.raises(ParameterError, match=f'--out: another campaign is writing .*process {os.getpid()}'):
            run_campaign(SPEC, reference_run, RunOptions(workers=1, resume=True, progress=False))
    assert (reference_run / 'flights.csv').read_text() == before
    assert not (reference_run / LOCK_FILE).exists()
    fresh = tmp_path / 'fresh'
    run_campaign(parse_spec(DOCUMENT | {'controllers': ['pid'], 'flights': 1}), fresh,
                 RunOptions(workers=1, progress=False))   # held and released by the run itself
    assert not (fresh / LOCK_FILE).exists() and len(read_flights(fresh / 'flights.csv')) == 1


@pytest.mark.slow
def test_replay_reviews_a_flight_that_failed_before_settling(tmp_path):
    """A flight failed at the first settled check (its record ends before two settled steps) is replayed with
    its bag and review, tracking figures NaN as in its row, not refused as a flight too short to review."""
    from flight_stack.campaign.replay import replay_flight
    spec = parse_spec(DOCUMENT | {'controllers': ['nnit2fsmc'], 'flights': 1, 'max_error_m': 1e-6})
    run_campaign(spec, tmp_path, RunOptions(workers=1, progress=False))
    [row] = rows_by_key(tmp_path).values()
    assert not row['finished'] and row['failure'] == 'position error above max_error'
    assert math.isnan(row['rmse_position_m'])
    assert replay_flight(spec, tmp_path, 0, RunOptions(progress=False)) == 1
    target = tmp_path / 'replay-0' / 'nnit2fsmc'
    assert json.loads((target / 'summary.json').read_text())['flight_ok'] is False
    assert math.isnan(json.loads((target / 'review.json').read_text())[0]['rmse_position_m'])
    assert (target / 'bag' / 'metadata.yaml').exists() and (target / 'report.html').exists()
    report = (target / 'report.md').read_text()    # why and when it failed, and what was flown, from its bag
    assert 'result: FAILED: the flight ended early: position error above max_error at ' in report
    assert 'not recorded' not in report
    assert 'NN seed: 0' in report and f'campaign seed: {spec.seed}' in report and 'campaign flight: 0' in report


@pytest.mark.parametrize('args, message', [
    (['--flights', '0'], '--flights'), (['--workers', '0'], '--workers'), (['--batch-size', '-2'], '--batch-size'),
    (['--controllers', 'pid,lqr'], '--controllers'), (['--replay', '99'], '--replay')])
def test_bad_options_are_refused_before_flying(tmp_path, args, message):
    spec_file = tmp_path / 'spec.yaml'
    spec_file.write_text(yaml.safe_dump(DOCUMENT))
    process = run_cli(spec_file, '--out', tmp_path / 'out', *args)
    _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
    assert process.returncode == 2 and stderr.startswith(f'error: {message}'), stderr
    assert not (tmp_path / 'out' / 'flights.csv').exists()


def test_a_gains_file_wrong_for_a_controller_of_the_spec_is_refused_before_flying(tmp_path):
    spec_file = tmp_path / 'spec.yaml'
    spec_file.write_text(yaml.safe_dump(DOCUMENT))
    gains = load_gains()
    gains['common']['low_altitude_height'] = -1.0
    gains_file = tmp_path / 'gains.yaml'
    gains_file.write_text(yaml.safe_dump(gains))
    process = run_cli(spec_file, '--out', tmp_path / 'out', '--gains', gains_file)
    _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
    assert process.returncode == 2 and 'error: common.low_altitude_height: -1.0 is outside' in stderr, stderr
    assert not (tmp_path / 'out').exists()


def test_a_campaign_without_perturbations_reports_cleanly(tmp_path):
    """Every flight identical (nothing random): the summary and the plots still come out."""
    spec = parse_spec({'scenario': 'hover', 'duration': 1.0, 'settle_time': 0.6, 'controllers': ['pid'],
                       'flights': 2, 'control_rate_hz': 250})
    run_campaign(spec, tmp_path, RunOptions(workers=1, progress=False))
    rows = list(rows_by_key(tmp_path).values())
    assert rows[0]['rmse_position_m'] == rows[1]['rmse_position_m']
    summary = json.loads((tmp_path / 'campaign.json').read_text())
    assert summary['controllers']['pid']['rmse_position_m']['p50'] == pytest.approx(rows[0]['rmse_position_m'])
    assert (tmp_path / 'plots' / 'boxplots.png').exists()


def test_planning_is_lazy_a_billion_flights_plan_their_first_batch_alone():
    from flight_stack.campaign.runner import flights_to_fly, plan_jobs
    spec = parse_spec(DOCUMENT | {'flights': 1_000_000_000})
    jobs = plan_jobs(spec, set(), RunOptions(batch_size=4), workers=2)
    assert iter(jobs) is jobs and not isinstance(jobs, (list, tuple))   # a generator, not a list
    first, second = next(jobs), next(jobs)
    assert (first.controller, first.flights) == ('nnit2fsmc', (0, 1, 2, 3))
    assert second.flights == (4, 5, 6, 7)
    assert flights_to_fly(spec, set()) == 2_000_000_000
    default = next(plan_jobs(spec, set(), RunOptions(), workers=2))
    assert len(default.flights) == 1000      # the default batch size's cap


def test_planning_skips_the_flown_pairs_in_batches_of_the_batch_size():
    from flight_stack.campaign.runner import flights_to_fly, plan_jobs
    spec = parse_spec(DOCUMENT | {'flights': 7})
    done = {(1, 'pid'), (4, 'pid'), (6, 'nnit2fsmc'), (9, 'pid'), (2, 'smc-sign')}   # the last two: not of this spec
    jobs = [(job.controller, job.flights) for job in plan_jobs(spec, done, RunOptions(batch_size=2), workers=1)]
    assert jobs == [('nnit2fsmc', (0, 1)), ('nnit2fsmc', (2, 3)), ('nnit2fsmc', (4, 5)),
                    ('pid', (0, 2)), ('pid', (3, 5)), ('pid', (6,))]
    assert flights_to_fly(spec, done) == 14 - 3


def test_campaign_out_that_is_a_file_is_a_one_line_error(tmp_path):
    spec_file = tmp_path / 'spec.yaml'
    spec_file.write_text(yaml.safe_dump(DOCUMENT))
    a_file = tmp_path / 'results.txt'
    a_file.write_text('keep me\n')
    for out in (a_file, a_file / 'sub'):
        process = run_cli(spec_file, '--out', out, '--quiet')
        _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
        assert process.returncode == 2, stderr
        assert stderr.splitlines()[-1].startswith(f'error: --out: {a_file}') and 'Traceback' not in stderr, stderr
    assert a_file.read_text() == 'keep me\n'


SCRIPT = '''import sys
sys.path[:0] = {paths!r}
from flight_stack.api import run_campaign
print('the script runs', flush=True)
{call}
'''
TINY = {'scenario': 'hover', 'duration': 0.5, 'settle_time': 0.3, 'controllers': ['pid'], 'flights': 1,
        'control_rate_hz': 250}


def write_script(tmp_path: Path, guarded: bool) -> Path:
    import flight_stack
    spec_file = tmp_path / 'tiny.yaml'
    spec_file.write_text(yaml.safe_dump(TINY))
    call = f"summary = run_campaign({str(spec_file)!r}, {str(tmp_path / 'out')!r}, workers=1)\nprint('flown')"
    if guarded:
        call = "if __name__ == '__main__':\n" + ''.join(f'    {line}\n' for line in call.splitlines())
    paths = [str(ROOT)] + [str(ROOT / 'ros2_ws' / 'src' / name) for name in
                           ('quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller')]
    script = tmp_path / 'my_campaign.py'
    script.write_text(SCRIPT.format(paths=paths, call=call))
    assert Path(flight_stack.__file__).parent.parent == ROOT
    return script


def test_a_script_calling_run_campaign_without_the_main_guard_is_refused_before_anything_is_made(tmp_path):
    script = write_script(tmp_path, guarded=False)
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                            timeout=HANG_TIMEOUT_S)
    assert result.returncode == 1
    assert result.stdout.count('the script runs') == 1          # no worker ran it again
    last = result.stderr.strip().splitlines()
    assert f"ParameterError: run_campaign: {script} calls it outside `if __name__ == '__main__':` (line 5)" \
        in result.stderr, result.stderr
    assert last[-1].strip() == 'run_campaign(...)' and last[-2].strip() == "if __name__ == '__main__':"
    assert 'BrokenProcessPool' not in result.stderr and '--resume' not in result.stderr
    assert not (tmp_path / 'out').exists()


@pytest.mark.slow
def test_the_same_script_with_the_main_guard_flies(tmp_path):
    script = write_script(tmp_path, guarded=True)
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                            timeout=HANG_TIMEOUT_S)
    assert result.returncode == 0, result.stderr
    assert result.stdout.count('flown') == 1   # (its unguarded lines run again in the worker: spawn imports it)
    assert len(read_flights(tmp_path / 'out' / 'flights.csv')) == 1


def stderr_lines(process):
    """The lines the process writes to stderr, as they come (progress bars split at carriage returns)."""
    buffer = ''
    while True:
        chunk = process.stderr.read(1)
        if not chunk:
            if buffer:
                yield buffer
            return
        if chunk in '\r\n':
            yield buffer
            buffer = ''
        else:
            buffer += chunk


PHASES = {'planning': 'campaign: ', 'compiling': 'compiling kernels', 'flying': 'campaign:   0%'}


@pytest.mark.slow
@pytest.mark.parametrize('phase, signal_number', [('planning', signal.SIGINT), ('compiling', signal.SIGINT),
                                                  ('flying', signal.SIGINT), ('compiling', signal.SIGTERM),
                                                  ('flying', signal.SIGTERM)])
def test_a_signal_stops_a_campaign_in_every_phase_and_resume_still_works(tmp_path, phase, signal_number):
    """A campaign of 10^9 flights stopped after its first rows, continued with --resume and stopped again in
    a phase (told by what it has printed): it stops within seconds, exit 130, flights.csv keeps its rows."""
    spec_file = tmp_path / 'spec.yaml'
    spec_file.write_text(yaml.safe_dump(TINY | {'flights': 1_000_000_000, 'duration': 2.0, 'settle_time': 1.0}))
    out = tmp_path / 'out'
    earlier = run_cli(spec_file, '--out', out, '--workers', 1, '--batch-size', 1)
    for _ in stderr_lines(earlier):
        if len(read_flights(out / 'flights.csv')) >= 1:
            break
    earlier.send_signal(signal.SIGINT)
    _, stderr = earlier.communicate(timeout=HANG_TIMEOUT_S)
    assert earlier.returncode == 130 and 'rerun with --resume' in stderr, stderr
    before = (out / 'flights.csv').read_text()
    assert len(read_flights(out / 'flights.csv')) >= 1
    process = run_cli(spec_file, '--out', out, '--resume', '--workers', 1, '--batch-size', 1)
    for line in stderr_lines(process):
        if PHASES[phase] in line:
            break
    sent = time.monotonic()
    process.send_signal(signal_number)
    _, stderr = process.communicate(timeout=HANG_TIMEOUT_S)
    stopped_after = time.monotonic() - sent
    print(f'{phase}, signal {signal_number}: stopped {stopped_after:.2f} s after the signal')
    assert process.returncode == 130, stderr
    assert stopped_after < 10.0
    assert (out / 'flights.csv').read_text().startswith(before)   # nothing lost, at most rows added
    assert sorted(p.name for p in out.iterdir() if p.name.startswith('.')) == []   # the lock is released


def test_the_held_out_table_reads_a_campaign_folder(reference_run):
    """The heldout study reads the columns the campaign writes (it once asked for a column the campaign
    had renamed): one row per controller with its flights, finished share and the chattering of both channels."""
    from flight_stack.studies import heldout
    lines = heldout.table([reference_run])
    rows = {line.split('|')[1].strip(): [cell.strip() for cell in line.split('|')[2:-1]] for line in lines[2:]}
    assert set(rows) == {'nnit2fsmc', 'pid'}
    flights = rows_by_key(reference_run)
    for controller, cells in rows.items():
        mine = [r for r in flights.values() if r['controller'] == controller and r['finished']]
        assert cells[0] == '2' and cells[1] == '5'                   # seed, flights
        for printed, column in zip(cells[-1].split(' / '), ('chattering_force_n_per_s', 'chattering_moment_nm_per_s')):
            assert printed == f'{np.percentile([r[column] for r in mine], 50):.3g}', column


def test_a_local_pool_starts_its_workers_when_made_and_they_exit_once_closed():
    """The workers start at once (they import the stack while the kernels compile in the parent), and a closed
    pool's workers exit by themselves (the results are written meanwhile): join returns, every one exited 0."""
    from flight_stack.campaign.runner import _LocalPool
    pool = _LocalPool(2)
    assert len(pool.processes) == 2 and all(process.is_alive() for process in pool.processes)
    pool.close(cancel=False)
    pool.join()
    assert [process.exitcode for process in pool.processes] == [0, 0]
    pool.close(cancel=True)      # closing again (run_campaign's last word) changes nothing
