"""Issue 26's scoreboard (docs/SCOREBOARD.md): its statistics on synthetic data, the pairing of separate
campaigns, the named gains sets, and the packaging of tuned points into one gains file."""
import csv
import json
import math
import random
from dataclasses import replace
from pathlib import Path

import distributed
import pytest
import yaml

from flight_stack.campaign.paired import binomial_cdfs, paired, quantile, quantile_ranks, sign_test
from flight_stack.campaign.results import wilson_interval
from flight_stack.campaign.runner import RunOptions, run_campaign
from flight_stack.campaign.spec import parse_spec
from nnit2fsmc_controller.factory import (DEFAULT_CONTROLLER_FILE, PAPER_FAITHFUL, flatten_gains, gain_names,
                                          load_gains, locate_gains, shipped_gains, unflatten_gains)
from nnit2fsmc_controller.search_spaces import SEARCH_SPACES, search_space, values_in, with_values
from quad_msgs_bridge.validation import ParameterError

from flight_stack.studies import heldout, paper_tables, scoreboard

ROOT = Path(__file__).resolve().parent.parent


# --- statistics on synthetic data ----------------------------------------------------------------------------

def test_the_wilson_interval_of_none_and_all_of_ten():
    z2 = 1.959963984540054 ** 2
    assert wilson_interval(0, 10) == pytest.approx((0.0, z2 / (10 + z2)))     # the closed form at p = 0
    assert wilson_interval(10, 10) == pytest.approx((10 / (10 + z2), 1.0))


def test_quantile_ranks_are_the_sign_test_interval_and_cover_95_percent():
    assert quantile_ranks(10, 0.5) == (2, 9)           # the tabulated sign-test interval for n = 10
    assert quantile_ranks(5, 0.5) == (None, None)      # 1 - 2 / 32 < 95 %: unbounded both sides
    for n, q in ((10, 0.5), (100, 0.5), (1000, 0.5), (1000, 0.95), (3000, 0.95), (60, 0.95)):
        low, high = quantile_ranks(n, q)
        cdf = binomial_cdfs(n, q)
        coverage = (cdf[high - 1] if high else 1.0) - (cdf[low - 1] if low else 0.0)
        assert coverage >= 0.95
        # each end as far in as it may be: one rank further in would leave more than 2.5 % on that side
        if low:
            assert cdf[low] > 0.025
        if high:
            assert 1.0 - cdf[high - 2] > 0.025


def test_the_quantile_interval_covers_the_true_quantile_of_synthetic_samples():
    rng = random.Random(7)
    true_median, true_p95 = math.log(2.0), -math.log(0.05)          # of the unit exponential
    hits = {0.5: 0, 0.95: 0}
    repeats = 400
    for _ in range(repeats):
        sample = [rng.expovariate(1.0) for _ in range(200)]
        for q, truth in ((0.5, true_median), (0.95, true_p95)):
            interval = quantile(sample, q)
            hits[q] += interval.low <= truth <= interval.high
    assert hits[0.5] / repeats >= 0.93 and hits[0.95] / repeats >= 0.93     # 95 % nominal, 400 repeats
    assert quantile([3.0, 1.0, 2.0, math.inf], 0.5).value == 2.0
    assert quantile([1.0, math.inf, math.inf, math.inf], 0.5).value == math.inf   # on the failures
    few = quantile([1.0, 2.0, 3.0, 4.0, 5.0], 0.5)
    assert math.isnan(few.low) and math.isnan(few.high)                 # 5 values bound no 95 % interval
    assert heldout.cm(few.high) == 'none (too few flights)' and heldout.cm(math.inf) == 'failed'


def rows(rmse_cm, finished=None, chattering=1.0):
    finished = finished or [True] * len(rmse_cm)
    return [{'flight': k, 'controller': 'c', 'finished': ok, 'rmse_position_m': r / 100.0,
             'chattering_force_n_per_s': chattering, 'chattering_moment_nm_per_s': chattering}
            for k, (r, ok) in enumerate(zip(rmse_cm, finished))]


def test_the_paired_comparison_counts_failures_as_losses_and_two_failures_as_a_tie():
    reference = rows([2.0] * 10, [True] * 8 + [False] * 2)
    kind = rows([1.0] * 6 + [3.0, math.nan, 5.0, math.nan], [True] * 7 + [False, True, False])
    p = paired(kind, reference)
    # flights 0-5 it is better; 6 worse; 7 it failed, the reference finished: worse;
    # 8 it finished, the reference failed: better; 9 both failed: a tie
    assert (p.pairs, p.kind_better, p.reference_better, p.ties) == (10, 7, 2, 1)
    assert p.kind_better_share == 0.7
    assert p.median_difference.value == pytest.approx(-0.01)      # [m]: 1 cm - 2 cm
    # sorted: -inf (flight 8), six -1 cm, 0 (tie), +1 cm, +inf (flight 7): ranks 2 and 9 of 10
    assert (p.median_difference.low, p.median_difference.high) == pytest.approx((-0.01, 0.01))
    assert p.sign_test_p == pytest.approx(sign_test(7, 2))
    with pytest.raises(ValueError, match='different flights'):
        paired(kind[:9], reference)


def test_the_median_paired_difference_interval_on_a_synthetic_shift():
    rng = random.Random(3)
    reference = [rng.uniform(2.0, 6.0) for _ in range(1000)]
    kind = [r - 0.5 + rng.gauss(0.0, 0.3) for r in reference]        # 0.5 cm better, symmetric noise
    p = paired(rows(kind), rows(reference))
    low, high = p.median_difference.low * 100, p.median_difference.high * 100
    assert low < -0.5 < high and high - low < 0.1
    assert p.kind_better_share > 0.9 and p.sign_test_p < 1e-100


def test_the_10_cm_threshold_is_strict_and_a_failure_is_never_under_it():
    record = heldout.kind_record('c', 1, rows([9.99, 10.0, 3.0, 3.0], [True, True, True, False]))
    assert record['under_10cm'] == 2 and record['finished'] == 3 and record['flights'] == 4
    assert record['under_10cm_wilson95'] == pytest.approx(wilson_interval(2, 4))
    assert record['rmse_p95_cm'] == math.inf                      # the failed flight is the worst


# --- pairing separate campaigns -----------------------------------------------------------------------------

DOCUMENT = {'scenario': 'paper', 'duration': 1.5, 'settle_time': 1.0, 'controllers': ['pid'], 'flights': 3,
            'seed': 5, 'control_rate_hz': 250, 'physics_rate_hz': 500,
            'vehicle': {'mass': 0.2, 'thrust_coefficient': 0.1},
            'wind': {'mean_speed_mps': 1.0, 'turbulence': 'light'}}


@pytest.fixture(scope='module')
def scheduler():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        yield cluster.scheduler_address


def test_each_kinds_own_campaign_flies_the_same_perturbed_flights(scheduler, tmp_path):
    """Campaigns of one seed flown apart, by different kinds with different gains files, pair flight by flight:
    the same sampled vehicle and wind direction; another seed does not, and is refused."""
    spec = parse_spec(DOCUMENT)
    tuned = tmp_path / 'tuned.yaml'
    tuned.write_text(yaml.safe_dump(with_values(load_gains(), 'se3', {d.name: d.low * 1.5 for d in search_space('se3')})))
    folders = {}
    for kind, gains in (('pid', None), ('se3', tuned), ('l1-se3', 'untuned')):
        folders[kind] = tmp_path / kind
        run_campaign(spec.overridden(controllers=[kind]), folders[kind],
                     RunOptions(scheduler=scheduler, progress=False, report=False,
                                gains_file=None if gains is None else str(gains)))
    by_seed = heldout.read_all(folders.values())
    assert list(by_seed) == [5] and len(by_seed[5]) == 9
    first = {(row['controller'], row['flight']): row['mass_kg'] for row in by_seed[5]}
    assert all(first[('se3', k)] == first[('pid', k)] == first[('l1-se3', k)] for k in range(3))
    assert len({first[('pid', k)] for k in range(3)}) == 3             # and the flights do differ
    other = tmp_path / 'other-seed'
    run_campaign(spec.overridden(controllers=['pid'], seed=6), other,
                 RunOptions(scheduler=scheduler, progress=False, report=False))
    mixed = [dict(row, controller='se3') for row in heldout.read_all([other])[6]]
    with pytest.raises(ValueError, match='not the same perturbed flight'):
        heldout.check_paired(by_seed[5] + mixed, 5)
    longer = tmp_path / 'longer'
    run_campaign(spec.overridden(controllers=['pid'], duration=2.0, flights=1), longer,
                 RunOptions(scheduler=scheduler, progress=False, report=False))
    with pytest.raises(ValueError, match='spec differs'):
        heldout.load([folders['pid'], longer])
    lines = heldout.paired_lines(heldout.paired_records(by_seed, 'pid'))
    assert [line.split('|')[1].strip() for line in lines[2:]] == ['se3', 'l1-se3']


# --- named gains sets --------------------------------------------------------------------------------------

def test_the_named_gains_sets_are_found_by_name_and_hold_every_gain(tmp_path, monkeypatch):
    assert set(shipped_gains()) == {'packaged', 'untuned', 'paper-faithful', 'px4-sih', 'second-round', 'median-tuned'}
    assert locate_gains('packaged') == locate_gains(None) == DEFAULT_CONTROLLER_FILE
    assert locate_gains('untuned.yaml') == shipped_gains()['untuned']
    for name in shipped_gains():
        assert set(flatten_gains(load_gains(name))) == set(gain_names()), name   # complete: nothing falls back
    with pytest.raises(ParameterError, match='named gains: packaged, median-tuned, paper-faithful, px4-sih, second-round, untuned'):
        load_gains('nope')
    monkeypatch.chdir(tmp_path)
    (tmp_path / 'untuned').write_text(yaml.safe_dump({'common': {'control_rate': 500.0}}))
    assert flatten_gains(load_gains('untuned')) == {**flatten_gains(load_gains()),   # a file of that name wins,
                                                    'common.control_rate': 500.0}  # merged over the packaged set


def test_paper_faithful_is_the_untuned_set_with_the_paper_faithful_keys():
    untuned = load_gains('untuned')
    assert flatten_gains(load_gains('paper-faithful')) == {**flatten_gains(untuned), **PAPER_FAITHFUL}
    assert untuned['l1_se3']['axes'] == untuned['se3']['axes']      # l1-se3 flew se3's law before it had its own
    # the tables' paper-faithful rows fly the named set, whatever the packaged gains become after tuning
    assert paper_tables.gains_for(None, faithful=True) == load_gains('paper-faithful')
    assert unflatten_gains(flatten_gains(untuned)) == untuned


# --- packaging the tuned points ----------------------------------------------------------------------------

def write_trials(folder: Path, kind: str, points: list[tuple[str, float, dict]]) -> None:
    names = [d.name for d in search_space(kind)]
    (folder / f'tune-{kind}').mkdir(parents=True)
    with (folder / f'tune-{kind}' / f'trials-{kind}.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['trial', 'state', 'objective_m', 'finished', 'flights', 'wall_time_s', *names])
        for trial, (state, objective, point) in enumerate(points):
            writer.writerow([trial, state, objective, 100, 100, 30.0, *(point[n] for n in names)])


def test_package_puts_every_kinds_best_point_into_one_gains_file_keeping_its_comments(tmp_path):
    into = tmp_path / 'controller.yaml'
    into.write_text(DEFAULT_CONTROLLER_FILE.read_text())
    expected = load_gains()
    for kind, space in SEARCH_SPACES.items():
        best = {d.name: d.low + (d.high - d.low) / 3.0 for d in space}
        worse = {d.name: d.high for d in space}
        pruned = {d.name: d.low for d in space}
        write_trials(tmp_path, kind, [('complete', 0.05, worse), ('pruned', 0.001, pruned), ('complete', 0.03, best)])
        expected = with_values(expected, kind, best)
    report = scoreboard.package(tmp_path, tuple(SEARCH_SPACES), into, tmp_path / 'kept', accept=accept_every)
    assert flatten_gains(load_gains(into)) == flatten_gains(expected)
    assert values_in(load_gains(into), 'se3') != values_in(load_gains(into), 'l1-se3')   # each its own
    text = into.read_text()
    untagged = [line for line in DEFAULT_CONTROLLER_FILE.read_text().split('\n')
                if not line.startswith(scoreboard.PROVENANCE)]
    assert text.count('\n') == len(untagged) - 1 + len(SEARCH_SPACES)      # its provenance lines replaced
    assert text.startswith(scoreboard.PROVENANCE) and 'trial 2' in report[0]
    assert '# [Hz] controller update rate' in text
    assert sorted(p.name for p in (tmp_path / 'kept').iterdir()) == sorted(f'trials-{k}.csv' for k in SEARCH_SPACES)
    write_trials(tmp_path / 'again', 'pid', [('complete', 0.02, {d.name: d.high for d in search_space('pid')})])
    scoreboard.package(tmp_path / 'again', ('pid',), into, None, accept=accept_every)
    headers = [line for line in into.read_text().split('\n') if line.startswith(scoreboard.PROVENANCE)]
    assert [h[len(scoreboard.PROVENANCE):].split(':')[0] for h in headers] == list(scoreboard.KINDS)
    assert headers[1] == scoreboard.PROVENANCE + 'pid: trial 0, objective 2.000 cm (100/100 finished): ' + ', '.join(
        f'{d.name} = {d.high:.4g}' for d in search_space('pid'))   # its header replaced, the others kept


def accept_every(kind, gains):
    """An acceptance that passes every point (the tests of packaging alone)."""
    return None


def test_package_takes_the_best_trial_that_passes_the_acceptance_and_says_which_failed(tmp_path):
    space = search_space('pid')
    best, second = ({d.name: d.low + (d.high - d.low) * f for d in space} for f in (0.25, 0.5))
    write_trials(tmp_path, 'pid', [('complete', 0.03, second), ('complete', 0.02, best)])
    into = tmp_path / 'controller.yaml'
    into.write_text(DEFAULT_CONTROLLER_FILE.read_text())

    def refuse_the_best(kind, gains):
        return 'paper: flipped over at 0.5 s' if values_in(gains, kind) == pytest.approx(best) else None

    report = scoreboard.package(tmp_path, ('pid',), into, None, accept=refuse_the_best)
    assert values_in(load_gains(into), 'pid') == pytest.approx(second)
    assert report[0].startswith('pid: trial 0, objective 3.000 cm')
    assert 'failing the hover acceptance: trial 1 (2.000 cm): paper: flipped over at 0.5 s' in report[0]
    with pytest.raises(ParameterError, match='no complete trial passes the acceptance'):
        scoreboard.package(tmp_path, ('pid',), into, None, accept=lambda kind, gains: 'x500: crashed')
    assert values_in(load_gains(into), 'pid') == pytest.approx(second)         # a refusal leaves it unchanged


def test_package_by_median_or_p95_takes_that_statistics_pick_under_the_99_percent_rule(tmp_path):
    """``--pick``: the trials flown on every seed that finished 99 %, by the statistic; as ``tune`` picks."""
    space = search_space('pid')
    points = [{d.name: d.low + (d.high - d.low) * f for d in space} for f in (0.1, 0.3, 0.5, 0.7, 0.9)]
    rows = [  # trial, state, objective (p95), median, p95, finished, flights, seeds flown
        (0, 'complete', 0.030, 0.020, 0.030, 100, 100, 2),      # the p95 pick
        (1, 'complete', 0.040, 0.015, 0.040, 99, 100, 2),       # the median pick
        (2, 'complete', 1.020, 0.010, 1.000, 98, 100, 2),       # the lowest median, below 99 % finished
        (3, 'pruned', 0.010, 0.005, 0.010, 50, 50, 1),          # one seed only
        (4, 'complete', 2.000, 'nan', 'nan', '', '', 0)]        # refused gains
    (tmp_path / 'tune-pid').mkdir()
    with (tmp_path / 'tune-pid' / 'trials-pid.csv').open('w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['trial', 'state', 'objective_m', 'median_rmse_m', 'p95_rmse_m', 'finished', 'flights',
                         'seeds_flown', *(d.name for d in space)])
        for row, point in zip(rows, points):
            writer.writerow([*row, *(point[d.name] for d in space)])
    trials = tmp_path / 'tune-pid' / 'trials-pid.csv'
    assert [r['trial'] for _, r in scoreboard.ranked_points(trials, 'pid', 'median')] == ['1', '0', '2']
    assert [r['trial'] for _, r in scoreboard.ranked_points(trials, 'pid', 'p95')] == ['0', '1', '2']
    into = tmp_path / 'controller.yaml'
    into.write_text(DEFAULT_CONTROLLER_FILE.read_text())
    report = scoreboard.package(tmp_path, ('pid',), into, None, accept=accept_every, pick='median')
    assert values_in(load_gains(into), 'pid') == pytest.approx(points[1])
    assert report[0].startswith('pid: trial 1, median 1.500 cm (99/100 finished)')
    with pytest.raises(ParameterError, match='--pick'):
        scoreboard.ranked_points(trials, 'pid', 'mean')
    write_trials(tmp_path / 'old', 'pid', [('complete', 0.02, points[0])])       # a table before the statistics
    with pytest.raises(ParameterError, match='no column p95_rmse_m'):
        scoreboard.ranked_points(tmp_path / 'old' / 'tune-pid' / 'trials-pid.csv', 'pid', 'p95')


def test_the_hover_acceptance_refuses_the_se3_point_that_flips_on_the_take_off_step():
    """The second round's best se3 trial (docs/tuning/2026-12-05, trial 12) flips on the 1 m take-off step
    of the paper's vehicle; the packaged se3 point (its best trial that does not) holds every vehicle."""
    ranked = scoreboard.ranked_points(ROOT / 'docs' / 'tuning' / '2026-12-05' / 'trials-se3.csv', 'se3')
    trial_12 = next(point for point, row in ranked if row['trial'] == '12')
    assert 'flipped over' in scoreboard.hover_acceptance('se3', with_values(load_gains(), 'se3', trial_12))
    assert scoreboard.hover_acceptance('se3', load_gains()) is None


def test_package_refuses_a_table_without_a_complete_trial(tmp_path):
    write_trials(tmp_path, 'pid', [('pruned', 0.01, {d.name: d.low for d in search_space('pid')})])
    into = tmp_path / 'controller.yaml'
    into.write_text(DEFAULT_CONTROLLER_FILE.read_text())
    with pytest.raises(ParameterError, match='no complete trial'):
        scoreboard.package(tmp_path, ('pid',), into, None, accept=accept_every)
    assert into.read_text() == DEFAULT_CONTROLLER_FILE.read_text()


def test_the_generated_section_is_replaced_between_its_markers(tmp_path):
    path = tmp_path / 'doc.md'
    begin, end = scoreboard.MARKERS
    path.write_text(f'intro\n{begin}\nold\n{end}\nafter\n')
    scoreboard.write_section(path, 'new table')
    assert path.read_text() == f'intro\n{begin}\nnew table\n{end}\nafter\n'
    path.write_text('no markers')
    with pytest.raises(ParameterError, match='generated section'):
        scoreboard.write_section(path, 'x')


def test_a_dir_refuses_other_settings_for_the_parts_it_flew_and_keeps_those_of_parts_not_flown_now(tmp_path):
    """scoreboard.json: a part flown before keeps its settings; another setting of a part flown now is refused
    only if that part was flown; the common settings (spec, gains, kinds) never change."""
    first = scoreboard.Settings(stress_flights=20)
    scoreboard.claim(first, tmp_path, {'heldout'})
    stored = json.loads((tmp_path / scoreboard.SETTINGS_FILE).read_text())
    assert stored['flown'] == ['heldout'] and stored['flights'] == 1000
    more = scoreboard.Settings(stress_flights=100)                 # stress not flown yet: may change
    scoreboard.claim(more, tmp_path, {'stress'})
    stored = json.loads((tmp_path / scoreboard.SETTINGS_FILE).read_text())
    assert stored['flown'] == ['heldout', 'stress'] and stored['stress_flights'] == 100
    with pytest.raises(ParameterError, match='another stress_flights'):
        scoreboard.claim(first, tmp_path, {'stress'})
    with pytest.raises(ParameterError, match='another flights'):
        scoreboard.claim(replace(more, flights=50), tmp_path, {'heldout', 'stress'})
    scoreboard.claim(replace(more, flights=50), tmp_path, {'margins'})    # held out not flown now: kept as it was
    assert json.loads((tmp_path / scoreboard.SETTINGS_FILE).read_text())['flights'] == 1000
    with pytest.raises(ParameterError, match='another spec'):
        scoreboard.claim(replace(more, spec='campaigns/paper-robustness.yaml'), tmp_path, {'nominal'})
    (tmp_path / scoreboard.SETTINGS_FILE).write_text(json.dumps(first.identity()))     # from before: every part
    with pytest.raises(ParameterError, match='another stress_flights'):
        scoreboard.claim(more, tmp_path, {'stress'})


def test_failures_by_the_drawn_actuator_count_each_third_of_each_drawn_range_and_their_top_corner():
    """Two controllers on nine flights drawing a motor time constant (15-45 ms) and a delay (0-8 ms): the failed
    flights of each third, and of the top third of both; one actuator for every flight gives no table."""
    lags, delays = (0.015, 0.030, 0.045), (0.0, 0.004, 0.008)
    flights = [(lag, delay) for lag in lags for delay in delays]
    rows = [{'controller': kind, 'flight': k, 'motor_time_constant_s': lag, 'delay_s': delay,
             'finished': not (kind == 'slow' and lag == 0.045 and delay > 0.0)}
            for kind in ('fast', 'slow') for k, (lag, delay) in enumerate(flights)]
    lines = heldout.actuator_lines({1: rows})
    assert lines[0] == ('| controller | motor time constant 15-15 ms | motor time constant 30-30 ms | '
                        'motor time constant 45-45 ms | delay 0-0 ms | delay 4-4 ms | delay 8-8 ms | '
                        'top third of motor time constant and delay |')
    assert lines[2] == '| fast | 0/3 | 0/3 | 0/3 | 0/3 | 0/3 | 0/3 | 0/1 |'
    assert lines[3] == '| slow | 0/3 | 0/3 | 2/3 | 0/3 | 1/3 | 1/3 | 1/1 |'
    assert heldout.actuator_lines({1: [dict(r, motor_time_constant_s=0.03, delay_s=0.004) for r in rows]}) == []


def test_a_p_value_below_what_a_float_holds_is_said_as_such_not_as_zero():
    assert heldout.p_value(0.0) == '< 1e-300' and heldout.p_value(1.2345e-155) == '1.2e-155'


def test_a_breaking_point_whose_intervals_straddle_90_percent_is_shown_with_where_it_surely_lies(tmp_path):
    path = tmp_path / 'breaking_points.csv'
    header = 'kind,controller,status,holds_at,fails_at,range_low,range_high\n'
    path.write_text(header + 'wind,pid,range,7.25,7.5,5.0,10.0\nwind,se3,range,10.25,10.5,nan,12.5\n'
                    'wind,indi,found,9,9.25,9,9.25\n')
    lines = scoreboard.breaking_lines(path, ('pid', 'se3', 'indi', 'l1-se3'), ('wind',))
    assert lines[2] == '| pid | 7.5? (holds at 7.25; surely between 5 and 10) |'
    assert lines[3] == '| se3 | 10.5? (holds at 10.25; surely at or below 12.5) |'
    assert lines[4] == '| indi | 9.25 (holds at 9) |' and lines[5] == '| l1-se3 | not flown |'
