"""run_stack.py study px4-sih: the named gains set px4-sih written from each kind's PX4-tuned pick, and the table's
rows (the flights themselves need PX4 SITL: docs/PX4.md)."""
import pytest
import yaml

from flight_stack.studies import px4_sih
from nnit2fsmc_controller.factory import flatten_gains, load_gains
from nnit2fsmc_controller.search_spaces import search_space, values_in, with_values
from quad_msgs_bridge.validation import ParameterError


def _pick(root, kind, scale):
    """A tune's tail pick for ``kind``: the packaged point of its whole space (position and attitude) scaled."""
    packaged = load_gains()
    point = {name: value * scale for name, value in values_in(packaged, kind, attitude=True).items()}
    point = {d.name: min(max(point[d.name], d.low), d.high) for d in search_space(kind, attitude=True)}
    folder = root / kind
    folder.mkdir(parents=True)
    (folder / f'gains-{kind}-p95.yaml').write_text(f'# Tuned by run_stack.py tune for {kind}: trial 7\n'
                                                   + yaml.safe_dump(with_values(packaged, kind, point, True)))
    return point


def test_package_writes_every_kinds_point_and_100_hz_over_the_packaged_gains_and_nothing_else(tmp_path):
    points = {'se3': _pick(tmp_path, 'se3', 0.5), 'nnit2fsmc': _pick(tmp_path, 'nnit2fsmc', 0.8)}
    into = tmp_path / 'px4-sih.yaml'
    report = px4_sih.package(tmp_path, ['se3', 'nnit2fsmc'], into)
    written = load_gains(into)
    changed = {gain: value for gain, value in flatten_gains(written).items()
               if flatten_gains(load_gains())[gain] != value}
    expected = {'common.control_rate': 100.0}
    for kind, point in points.items():
        expected.update({gain: point[d.name] for d in search_space(kind, attitude=True) for gain in d.gains
                         if flatten_gains(load_gains())[gain] != point[d.name]})
    assert changed == pytest.approx(expected)
    assert values_in(written, 'se3', attitude=True) == pytest.approx(points['se3'])
    text = into.read_text()
    assert text.startswith('# The px4-sih gains') and '# se3: Tuned by run_stack.py tune for se3: trial 7' in text
    assert '# [Hz] controller update rate' in text                      # the packaged file's comments kept
    assert len(report) == 2 and report[0].startswith('se3: ')


def test_package_refuses_a_kind_without_its_pick_and_leaves_the_file_alone(tmp_path):
    _pick(tmp_path, 'se3', 0.5)
    into = tmp_path / 'px4-sih.yaml'
    into.write_text('before')
    with pytest.raises(ParameterError, match='pid/gains-pid-p95.yaml: missing'):
        px4_sih.package(tmp_path, ['se3', 'pid'], into)
    assert into.read_text() == 'before'


def test_a_row_counts_the_runs_that_flew_to_the_end_and_says_why_the_others_ended():
    flew = {'rmse_position_m': 0.02, 'max_position_error_m': 0.05, 'chattering_force_n_per_s': 1.5,
            'chattering_moment_nm_per_s': 0.5, 'saturation_fraction': 0.0, 'failure': None, 'failures': [],
            'flight_ok': True}
    better = {**flew, 'rmse_position_m': 0.01, 'max_position_error_m': 0.03}
    crashed = {**flew, 'failure': 'PX4 failsafe: PX4 left offboard by itself', 'failure_time_s': 3.25,
               'flight_ok': False}
    strayed = {**flew, 'rmse_position_m': 2.0, 'max_position_error_m': 3.0, 'flight_ok': False,
               'failures': ['max position error 3.000 m exceeds --max-error 1 m']}
    later = {**crashed, 'failure_time_s': 4.5}
    row = px4_sih.row('PX4 SIH', 'se3', [flew, crashed, better, strayed, later])
    assert row == ('| PX4 SIH | se3 | 5 | 2 | 2: PX4 failsafe: PX4 left offboard by itself at 3.2-4.5 s; 1: max position '
                   'error above 1 m | 1.5 (1.0-2.0) | 4.0 (3.0-5.0) | 1.50 (1.50-1.50) | 0.50 (0.50-0.50) '
                   '| 0.0 (0.0-0.0) |')
    own = {**flew, 'not_measured': ['chattering', 'saturation']}
    assert px4_sih.row('PX4 SIH', 'px4', [own]).endswith('| 2.0 | 5.0 | n/a | n/a | n/a |')
    assert px4_sih.row('PX4 SIH', 'pid', [crashed]).endswith('| n/a | n/a | n/a | n/a | n/a |')


def test_the_px4_flight_command_flies_the_named_set_except_px4s_own(tmp_path):
    ours = px4_sih.px4_command('se3', 'hover', 20.0, tmp_path)
    assert ours[ours.index('--gains') + 1] == 'px4-sih' and ours[ours.index('--duration') + 1] == '20'
    assert ours[ours.index('--plant') + 1] == 'px4-sitl' and ours[ours.index('--vehicle') + 1] == 'px4-sih-quadx'
    own = px4_sih.px4_command('px4', 'paper', 20.0, tmp_path)
    assert '--gains' not in own and '--duration' not in own
