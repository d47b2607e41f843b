"""`review`: the metrics of a recorded bag equal the live summary of the same flight; plots, report,
--compare, bags written by other tools, and what happens without matplotlib or without the topics."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

import run_stack
from bag_support import PARAMS, SETTLE_TIME, fly_recorded
from quad_msgs_bridge.bag.reader import BagReadError
from quad_msgs_bridge.bag.recover import recover_main
from quad_msgs_bridge.bag.writer import jazzy_typestore
from quad_msgs_bridge.contract import (CLOCK, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, ODOM,
                                       ROTOR_FORCES, resolve)
from quad_msgs_bridge.conversions import (clock_msg, diagnostics_msg, odometry_msg, pose_stamped_msg, rosbags_kit,
                                          rotor_forces_msg, wrench_msg)
from quad_msgs_bridge.review import command, flight_from_bag
from quad_msgs_bridge.review.command import PLOT_HINT, main as review_main, review_bags

ROOT = Path(__file__).resolve().parent.parent
PLOTS = {'path_3d.png', 'tracking.png', 'controls.png', 'controls_zoom.png', 'surfaces.png', 'fuzzy_share.png'}


def assert_same_metrics(actual: dict, expected: dict, tolerance: float = 1e-9) -> None:
    """Every metric of ``expected`` equals the one in ``actual`` (floats within a relative ``tolerance``)."""
    for key, value in expected.items():
        if value is None:
            assert actual[key] is None, key
        elif isinstance(value, dict):
            assert set(actual[key]) == set(value), key
            assert_same_metrics(actual[key], value, tolerance)
        elif isinstance(value, list):
            assert actual[key] == pytest.approx(value, rel=tolerance, abs=1e-15), key
        elif isinstance(value, float):
            assert actual[key] == pytest.approx(value, rel=tolerance, abs=1e-15), key
        else:
            assert actual[key] == value, key


@pytest.fixture(scope='module')
def flights(tmp_path_factory):
    base = tmp_path_factory.mktemp('review')
    return {kind: fly_recorded(base / kind, duration=2.0, controller=kind) for kind in ('nnit2fsmc', 'smc-sign')}


@pytest.mark.slow
def test_the_main_job_writes_bag_and_report_whose_metrics_equal_the_live_summary(tmp_path, capsys, monkeypatch):
    """The main job reviews the flight it just flew from its record in memory (it never reads its bag back);
    `review BAG` of the bag it wrote finds the same metrics and writes the same table."""
    def no_reading_back(*args, **kwargs):
        raise AssertionError('the main job read its bag back')

    monkeypatch.setattr(flight_from_bag, 'read_flight', no_reading_back)
    monkeypatch.setattr(command, 'read_flight', no_reading_back)
    out = tmp_path / 'run'
    status = run_stack.main(['--backend', 'embedded', '--duration', '6', '--out', str(out), '--quiet'])
    assert status == 0
    printed = capsys.readouterr().out
    assert f'bag: {out / "bag"}' in printed and f'report: {out / "report.html"}' in printed
    summary = json.loads((out / 'summary.json').read_text())
    [reviewed] = json.loads((out / 'review.json').read_text())
    assert reviewed['control_steps'] == 6000 and reviewed['bag'] == str(out / 'bag')
    metrics = {key: value for key, value in reviewed.items() if key not in ('label', 'bag')}
    assert_same_metrics(metrics, {key: summary[key] for key in metrics}, tolerance=0.0)
    assert {p.name for p in (out / 'plots').glob('*.png')} == PLOTS
    assert (out / 'report.md').read_text().count('![') == len(PLOTS)
    assert 'scenario: paper; vehicle: paper; disturbances (paper section IV): enabled' in (out / 'report.md').read_text()

    monkeypatch.undo()
    from_bag = review_bags([out / 'bag'], tmp_path / 'from-bag', plots=False)
    # the bag holds the reference yaw as a quaternion: read back, it may differ in the last bit
    assert_same_metrics(from_bag.metrics[0], metrics, tolerance=1e-12)
    table = [line for line in (out / 'report.md').read_text().splitlines() if line.startswith('| ')]
    assert table == [line for line in (tmp_path / 'from-bag' / 'report.md').read_text().splitlines()
                     if line.startswith('| ')]


@pytest.mark.slow
def test_compare_overlays_and_tabulates_several_flights(flights, tmp_path):
    out = tmp_path / 'compare'
    result = subprocess.run([sys.executable, str(ROOT / 'run_stack.py'), 'review', str(flights['nnit2fsmc'].bag),
                             '--compare', str(flights['smc-sign'].bag), '--out', str(out)],
                            cwd=ROOT, capture_output=True, text=True, check=True)
    assert 'nnit2fsmc' in result.stdout and 'smc-sign' in result.stdout and 'chattering U1' in result.stdout
    reviewed = json.loads((out / 'review.json').read_text())
    assert [r['label'] for r in reviewed] == ['nnit2fsmc', 'smc-sign']
    for entry, kind in zip(reviewed, ('nnit2fsmc', 'smc-sign')):
        assert_same_metrics(entry, flights[kind].metrics)
    page = (out / 'report.html').read_text()
    assert page.count('<img') == len(PLOTS) and 'smc-sign' in page
    assert {p.name for p in (out / 'plots').glob('*.png')} == PLOTS


def test_review_runs_as_a_module(flights, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT / 'ros2_ws' / 'src' / 'quad_msgs_bridge'))
    result = subprocess.run([sys.executable, '-m', 'quad_msgs_bridge.review', str(flights['nnit2fsmc'].bag),
                             '--no-plots', '--out', str(tmp_path)], capture_output=True, text=True, env=env,
                            check=True)
    assert 'position RMSE' in result.stdout
    assert not (tmp_path / 'plots').exists()


def test_without_matplotlib_review_prints_the_metrics_and_how_to_get_plots(flights, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, 'matplotlib', None)    # import matplotlib now raises ImportError
    assert review_main([str(flights['nnit2fsmc'].bag), '--out', str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert 'position RMSE' in out and PLOT_HINT in out
    assert not list(tmp_path.glob('plots/*.png'))
    assert PLOT_HINT in (tmp_path / 'report.md').read_text()


def write_foreign_bag(flight, path: Path, namespace: str) -> None:
    """The flight's messages as another tool records them: rosbags' own rosbag2 writer, the conversions'
    messages and rosbags' serializer, another namespace, no custom data (no vehicle parameters)."""
    kit, typestore = rosbags_kit(), jazzy_typestore()
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer:
        topics = (CLOCK, ODOM, ROTOR_FORCES, CONTROL_WRENCH, CONTROL_REFERENCE, CONTROL_DIAGNOSTICS)
        connections = {t: writer.add_connection(resolve(t, namespace), t.type, typestore=typestore) for t in topics}
        for odometry, forces, controls, position, yaw, surfaces, equivalent, corrective, slopes \
                in flight.published.steps:
            t = odometry.stamp
            stamp = round(t * 1e9) + 123   # a receive time: a little after the stamp
            messages = {CLOCK: clock_msg(kit, t),
                        ODOM: odometry_msg(kit, odometry), ROTOR_FORCES: rotor_forces_msg(kit, forces),
                        CONTROL_WRENCH: wrench_msg(kit, t, controls, PARAMS.d),
                        CONTROL_REFERENCE: pose_stamped_msg(kit, t, position, yaw),
                        CONTROL_DIAGNOSTICS: diagnostics_msg(kit, surfaces, equivalent, corrective, slopes)}
            for topic, msg in messages.items():
                writer.write(connections[topic], stamp, typestore.serialize_cdr(msg, topic.type))


def test_a_bag_recorded_by_another_tool_gives_the_same_metrics(flights, tmp_path):
    flight = flights['nnit2fsmc']
    write_foreign_bag(flight, tmp_path / 'foreign', 'uav7')
    review = review_bags([tmp_path / 'foreign'], tmp_path / 'out', settle_time=SETTLE_TIME, plots=False)
    assert any('packaged vehicle file' in note for note in review.notes)
    assert_same_metrics(review.metrics[0], flight.metrics)


def test_missing_topics_are_named(tmp_path):
    flight = fly_recorded(tmp_path / 'bag', duration=1.2, topics=(ODOM, CLOCK))
    with pytest.raises(BagReadError, match='no rotor_forces, control/wrench, control/reference'):
        review_bags([flight.bag], tmp_path / 'out', plots=False)


def test_an_unfinished_bag_is_sent_to_recover(flights, tmp_path):
    bag = tmp_path / 'bag'
    shutil.copytree(flights['nnit2fsmc'].bag, bag)
    storage = next(bag.glob('*.mcap'))
    os.truncate(storage, storage.stat().st_size // 2)
    with pytest.raises(BagReadError, match='recover'):
        review_bags([bag], tmp_path / 'out', plots=False)


def not_a_bag(kind: str, tmp_path: Path, flights) -> tuple[Path, str]:
    """A path that is not a bag, and what the error must say it is."""
    if kind == 'text file':
        path = tmp_path / 'README.md'
        shutil.copy(ROOT / 'README.md', path)
        return path, "a text file of {size} bytes (it begins '# "
    if kind == 'metadata file':
        return flights['nnit2fsmc'].bag / 'metadata.yaml', \
            f'the metadata file of a bag, not the bag; give its directory: {flights["nnit2fsmc"].bag}'
    if kind == 'renamed text file':
        path = tmp_path / 'flight.mcap'
        shutil.copy(ROOT / 'README.md', path)
        return path, 'a text file of {size} bytes'
    if kind == 'empty mcap':
        path = tmp_path / 'empty.mcap'
        path.write_bytes(b'')
        return path, 'an empty file (0 bytes)'
    path = tmp_path / 'folder'
    path.mkdir()
    (path / 'notes.txt').write_text('x')
    return path, 'a directory without metadata.yaml or .mcap file, not a bag'


@pytest.mark.parametrize('kind', ['text file', 'metadata file', 'renamed text file', 'empty mcap', 'directory'])
def test_review_of_what_is_not_a_bag_says_what_it_is(kind, flights, tmp_path, capsys):
    path, expected = not_a_bag(kind, tmp_path, flights)
    if path.is_file():
        expected = expected.format(size=path.stat().st_size)
    assert review_main([str(path), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f'error: {path}: ') and expected in err, err
    assert 'Traceback' not in err and 'killed' not in err and 'recover' not in err
    if kind != 'metadata file':
        assert 'expected a rosbag2 bag directory (holding metadata.yaml) or an MCAP file' in err


def test_a_bag_folder_of_random_bytes_is_not_an_mcap_file_and_recover_is_not_suggested(tmp_path, capsys):
    """Issue 35: a bag folder whose .mcap holds random bytes was 'not closed (killed?); run recover first'."""
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'rosbag.mcap').write_bytes(bytes(range(256)) * 16)
    expected = (f'{bag / "rosbag.mcap"}: a binary file of 4096 bytes without the MCAP magic, not an MCAP file '
                '(every MCAP file begins with its magic bytes, even a recording cut short: recover cannot make one of it)')
    assert review_main([str(bag), '--out', str(tmp_path / 'out')]) == 2
    assert capsys.readouterr().err == f'error: {expected}\n'
    with pytest.raises(BagReadError) as raised:
        flight_from_bag.read_flight(bag)
    assert str(raised.value) == expected and 'killed' not in expected
    assert not (tmp_path / 'out').exists()


@pytest.mark.parametrize('kind', ['text file', 'renamed text file', 'empty mcap'])
def test_recover_of_what_is_not_an_mcap_file_says_what_it_is_and_leaves_it(kind, flights, tmp_path, capsys):
    path, expected = not_a_bag(kind, tmp_path, flights)
    before = path.read_bytes()
    assert recover_main([str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f'error: {path}: ') and expected.format(size=len(before)) in err
    assert 'not an MCAP file; recover finalizes the MCAP file' in err and '.killed' not in err
    assert path.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_the_report_says_what_was_flown_and_what_each_metric_means(flights, tmp_path):
    review_bags([flights['nnit2fsmc'].bag], tmp_path, plots=False)
    report = (tmp_path / 'report.md').read_text()
    for fact in ('controller: nnit2fsmc', 'scenario: paper', 'disturbances (paper section IV): enabled',
                 'backend: embedded', 'NN seed: 0'):
        assert fact in report, fact
    assert '## Metrics' in report and '### What the metrics mean' in report
    for metric in ('result', 'settle time', 'position RMSE', 'max position error', 'yaw RMSE', 'chattering',
                   'rotor saturation', 'fuzzy share'):
        assert f'- **{metric}**: ' in report, metric
    html = (tmp_path / 'report.html').read_text()
    assert 'What the metrics mean' in html and 'scenario: paper' in html


@pytest.mark.slow
def test_a_flight_without_fuzzy_term_has_no_fuzzy_share(flights, tmp_path):
    review = review_bags([flights['smc-sign'].bag], tmp_path, plots=True)
    assert review.metrics[0]['fuzzy_share'] is None
    assert 'fuzzy_share.png' not in {p.name for p in review.plots} and len(review.plots) == len(PLOTS) - 1
    rows = [line for line in (tmp_path / 'report.md').read_text().splitlines() if line.startswith('| fuzzy share')]
    assert len(rows) == 6 and all(row.endswith('| n/a |') for row in rows)


def test_a_flight_that_failed_before_settling_is_recorded_as_failed_and_reviewed_from_its_bag(tmp_path, capsys):
    """The embedded flight writes why and when it failed into the bag (metadata.yaml and the MCAP file's last
    custom data record); `review BAG` then reviews the flight, NaN tracking figures, and says it failed,
    instead of refusing the bag as shorter than the settling window."""
    from flight_stack.closed_loop import FailureRules
    from flight_stack.embedded import fly_embedded
    from nnit2fsmc_controller.factory import load_gains
    from nnit2fsmc_controller.trajectory import make_scenario
    from quad_msgs_bridge.bag.flight_bag import FlightBag
    from quad_msgs_bridge.bag.reader import mcap_file, read_custom_data
    from bag_support import DISTURBANCES
    bag = tmp_path / 'bag'
    with FlightBag.create(bag, PARAMS, SETTLE_TIME, controller='nnit2fsmc', scenario='paper', backend='embedded',
                          seed=0, disturbances='enabled') as recording:
        result = fly_embedded('nnit2fsmc', make_scenario('paper'), PARAMS, DISTURBANCES, load_gains(), 2.0, 1000.0,
                              bag=recording, rules=FailureRules(settle_time=SETTLE_TIME, max_error=1e-6))
    assert result.failure == 'position error above max_error'
    when = f'{result.failure_time_s:.3f}'
    for source in (bag, mcap_file(bag)):          # the bag directory and its lone MCAP file
        custom = read_custom_data(source)
        assert custom['failure'] == result.failure and float(custom['failure_time_s']) == result.failure_time_s
    assert review_main([str(bag), '--out', str(tmp_path / 'review'), '--no-plots']) == 1   # a FAILED flight (issue 35)
    out = capsys.readouterr().out
    assert f'FAILED: the flight ended early: position error above max_error at {when} s' in out
    report = (tmp_path / 'review' / 'report.md').read_text()
    assert f'result: FAILED: the flight ended early: position error above max_error at {when} s' in report
    [saved] = json.loads((tmp_path / 'review' / 'review.json').read_text())
    assert saved['failure'] == result.failure and saved['rmse_position_m'] != saved['rmse_position_m']   # NaN


def test_each_vehicle_of_a_fleet_bag_records_its_own_failure(tmp_path):
    """A fleet's bag holds each failed vehicle's reason and time under keys of its own namespace; the review of
    the fleet's bag gives every vehicle its failure."""
    from flight_stack.closed_loop import FailureRules
    from flight_stack.embedded import fly_fleet
    from flight_stack.fleet import fleet_layout
    from nnit2fsmc_controller.factory import load_gains
    from nnit2fsmc_controller.trajectory import make_scenario
    from quad_msgs_bridge.bag.flight_bag import FleetBag
    from quad_msgs_bridge.bag.reader import read_custom_data
    from bag_support import DISTURBANCES
    vehicles = fleet_layout(2)
    namespaces = [v.namespace for v in vehicles]
    bag = tmp_path / 'bag'
    with FleetBag.create(bag, PARAMS, SETTLE_TIME, namespaces, controller='nnit2fsmc', scenario='paper',
                         backend='embedded', seed=0, disturbances='enabled') as recording:
        results = fly_fleet('nnit2fsmc', [make_scenario('paper', 2.0, offset=v.offset) for v in vehicles], PARAMS,
                            DISTURBANCES, load_gains(), 2.0, 1000.0, bag=recording,
                            rules=FailureRules(settle_time=SETTLE_TIME, max_error=1e-6))
    custom = read_custom_data(bag)
    assert 'failure' not in custom
    for namespace, result in zip(namespaces, results):
        assert custom[f'failure:{namespace}'] == result.failure == 'position error above max_error'
        assert float(custom[f'failure_time_s:{namespace}']) == result.failure_time_s
    review = review_bags([bag], tmp_path / 'review', plots=False)
    assert [m['failure'] for m in review.metrics] == ['position error above max_error'] * 2
    assert [f.label for f in review.flights] == namespaces
