"""run_stack.py tune and stress: clients of the campaign runner (docs/TUNING.md).

The campaigns fly on an in-process Dask cluster (what --scheduler names), so the tests pay no worker
start-up; the flights are few and short."""
import csv
import math
import subprocess
import sys
from pathlib import Path

import distributed
import numpy as np
import pytest
import yaml
from hang_guard import HANG_TIMEOUT_S

from flight_stack.campaign.results import read_flights, wilson_interval
from flight_stack.campaign.runner import RunOptions, run_campaign
from flight_stack.campaign.sampling import sample_conditions
from flight_stack.campaign.spec import parse_spec
from flight_stack.campaign.stress import (KINDS, BreakingPoint, StressSetup, Tally, describe, find_breaking_point,
                                          highest_intensity, read_tries, stress, write_breaking_points,
                                          write_tries)
from flight_stack.campaign.tune import TuneSetup, objective, tune
from nnit2fsmc_controller.factory import build_controller, load_gains
from nnit2fsmc_controller.search_spaces import (ATTITUDE_SPACES, SEARCH_SPACES, Dimension, at_bounds, search_space,
                                                values_in, with_values)
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

DOCUMENT = {'scenario': 'paper', 'duration': 2.0, 'settle_time': 1.2, 'controllers': ['pid'], 'flights': 3,
            'seed': 0, 'control_rate_hz': 250, 'physics_rate_hz': 500,
            'vehicle': {'mass': 0.1}, 'wind': {'mean_speed_mps': 1.0, 'turbulence': 'light'}}
SPEC = parse_spec(DOCUMENT)
ROOT = Path(__file__).resolve().parent.parent
#: the stress test's: no wind, settled longer (a 2 s flight's take-off transient is near 10 cm RMSE)
CALM = parse_spec({**{k: v for k, v in DOCUMENT.items() if k != 'wind'}, 'duration': 2.5, 'settle_time': 1.6})


@pytest.fixture(scope='module')
def scheduler():
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        yield cluster.scheduler_address


# --- search spaces and the objective -------------------------------------------------------------

@pytest.mark.parametrize('kind', sorted(SEARCH_SPACES))
def test_every_search_space_holds_the_packaged_gains_and_sets_what_it_names(kind):
    gains = load_gains()
    start = values_in(gains, kind)                       # refused if outside a range or x != y
    highs = {d.name: d.high for d in search_space(kind)}
    moved = {name: value * 1.1 if value * 1.1 <= highs[name] else value / 1.1 for name, value in start.items()}
    tuned = with_values(gains, kind, moved)
    assert values_in(tuned, kind) == pytest.approx(moved)
    assert values_in(gains, kind) == start               # the copy, not the packaged tree, changed
    build_controller(kind, load_vehicle_file()[0], tuned)


@pytest.mark.parametrize('kind', sorted(SEARCH_SPACES))
def test_every_kind_has_roll_and_pitch_dimensions_that_hold_the_packaged_gains(kind):
    """--attitude adds the kind's roll and pitch loop: every gain it names in phi and theta alike, the packaged
    values inside the ranges, and a point of it flies (builds) with both axes set."""
    gains = load_gains()
    whole = search_space(kind, attitude=True)
    position = search_space(kind)
    assert whole[:len(position)] == position and whole[len(position):] == ATTITUDE_SPACES[kind]
    added = ATTITUDE_SPACES[kind]
    assert 2 <= len(added) <= 3 and all(d.name.startswith('rp.') for d in added)
    assert all(len(d.gains) == 2 and d.gains[0].replace('phi', 'theta') == d.gains[1] for d in added)
    start = values_in(gains, kind, attitude=True)
    lowered = {**start, **{d.name: d.low for d in added}}
    tuned = with_values(gains, kind, lowered, attitude=True)
    assert values_in(tuned, kind, attitude=True) == pytest.approx(lowered)
    build_controller(kind, load_vehicle_file()[0], tuned)
    assert search_space('nnit2fsmc-bias', attitude=True) == search_space('nnit2fsmc', attitude=True)


@pytest.mark.parametrize('kind', sorted(SEARCH_SPACES))
def test_every_bound_of_every_range_is_gains_the_kind_accepts(kind):
    """A point the kind refuses scores as if every flight failed, which tells the sampler nothing: a range must
    not hold one (the NNIT2FSMC's z fuzzy gain once went down to 4 m/s^2, below g, and 30 of a study's 48 trials
    were refused)."""
    gains, params = load_gains(), load_vehicle_file()[0]
    start = values_in(gains, kind, attitude=True)
    for dimension in search_space(kind, attitude=True):
        for bound in (dimension.low, dimension.high):
            build_controller(kind, params, with_values(gains, kind, {**start, dimension.name: bound}, True))


def test_a_pick_within_2_percent_of_a_bound_of_its_range_sits_at_that_bound():
    """The ranges rule's test (docs/TUNING.md): 2 % of the range, of its log where the dimension is log-sampled."""
    log = Dimension('a', ('x.a',), 1.0, 100.0, '-')              # log range 0..ln 100: 2 % is a factor 100^0.02
    linear = Dimension('b', ('x.b',), 0.0, 10.0, '-', log=False)
    inside = 100.0 ** 0.021
    assert at_bounds({'a': 100.0 ** 0.019, 'b': 9.81}, (log, linear)) == [('a', 'low'), ('b', 'high')]
    assert at_bounds({'a': inside, 'b': 0.21}, (log, linear)) == []
    assert at_bounds({'a': 100.0 / inside, 'b': 9.79}, (log, linear)) == []
    assert at_bounds({'a': 100.0, 'b': 0.0}, (log, linear)) == [('a', 'high'), ('b', 'low')]


def test_no_two_kinds_tune_the_same_gain_so_every_tuned_point_fits_one_gains_file():
    owners = {}
    for kind, space in SEARCH_SPACES.items():
        for dimension in space + ATTITUDE_SPACES[kind]:
            for gain in dimension.gains:
                assert owners.setdefault(gain, kind) == kind, f'{gain}: tuned by {owners[gain]} and {kind}'


def test_an_ablation_searches_the_nnit2fsmc_space_and_its_point_is_the_nnit2fsmc_sections():
    assert search_space('nnit2fsmc-bias') == search_space('nnit2fsmc')
    point = {d.name: d.high for d in search_space('nnit2fsmc-bias')}
    gains = with_values(load_gains(), 'nnit2fsmc-bias', point)
    assert values_in(gains, 'nnit2fsmc') == point
    assert build_controller('nnit2fsmc-bias', load_vehicle_file()[0], gains).name == 'nnit2fsmc-bias'
    with pytest.raises(ParameterError, match="'smc-sat' has no search space"):
        search_space('smc-sat')


def test_l1_se3_flies_its_own_se3_gains_not_those_of_se3():
    params = load_vehicle_file()[0]
    assert load_gains('untuned')['l1_se3']['axes'] == load_gains('untuned')['se3']['axes']   # as they flew before
    gains = load_gains()
    gains['se3']['axes']['x']['k_error'] = 30.0
    gains['l1_se3']['axes']['x']['k_error'] = 20.0
    assert build_controller('se3', params, gains).gains['x'][0] == 30.0
    assert build_controller('l1-se3', params, gains).gains['x'][0] == 20.0
    gains['l1_se3']['axes']['x']['k_rate'] = -1.0
    with pytest.raises(ParameterError, match='l1_se3.axes.x.k_rate'):
        build_controller('l1-se3', params, gains)


def test_a_space_refuses_gains_it_cannot_express():
    gains = load_gains()
    gains['pid']['axes']['y']['kp'] = 13.0               # x and y share one dimension
    with pytest.raises(ParameterError, match='pid.axes.x.kp, pid.axes.y.kp'):
        values_in(gains, 'pid')
    with pytest.raises(ParameterError, match='no search space'):
        values_in(gains, 'smc-sign')


def test_the_objective_is_the_median_with_failures_and_penalises_below_99_percent():
    def rows(rmse, failed):
        return ([{'finished': True, 'rmse_position_m': r} for r in rmse]
                + [{'finished': False, 'rmse_position_m': math.nan}] * failed)
    assert objective(rows([0.01, 0.03, 0.02], 0), 1.0).objective_m == pytest.approx(0.02)
    # 1 failure in 200 (99.5 % finished): counted as max_error_m in the median, no penalty
    score = objective(rows([0.02] * 199, 1), 1.0)
    assert score.objective_m == pytest.approx(0.02) and score.finished == 199
    # 2 in 100 (98 %): worse than any gains that finish 99 %, ranked by the share finished
    assert objective(rows([0.02] * 98, 2), 1.0).objective_m == pytest.approx(1.02)
    assert objective(rows([0.02] * 97, 3), 1.0).objective_m > objective(rows([0.5] * 98, 2), 1.0).objective_m
    # most flights failed: the median is the failure value
    assert objective(rows([0.02], 2), 0.5).median_rmse_m == 0.5


def test_the_tail_objective_is_the_95th_percentile_under_the_same_finished_rule():
    def rows(rmse, failed):
        return ([{'finished': True, 'rmse_position_m': r} for r in rmse]
                + [{'finished': False, 'rmse_position_m': math.nan}] * failed)
    flights = rows([0.01] * 90 + [0.2] * 10, 0)      # a good median, a bad tail
    median, tail = objective(flights, 1.0), objective(flights, 1.0, 'p95')
    assert median.objective_m == pytest.approx(0.01) and tail.objective_m == pytest.approx(0.2)
    assert median.p95_rmse_m == tail.p95_rmse_m == pytest.approx(0.2)
    # a failure counts as max_error_m in the tail too; below 99 % finished the same penalty for both
    assert objective(rows([0.01] * 198, 2), 1.0, 'p95').objective_m == pytest.approx(0.01)
    assert objective(rows([0.01] * 98, 2), 1.0, 'p95').objective_m == pytest.approx(1.02)
    assert objective(rows([0.01] * 93, 6), 1.0, 'p95').p95_rmse_m == pytest.approx(1.0)
    with pytest.raises(ParameterError, match='--objective'):
        objective(flights, 1.0, 'p99')


# --- tune ----------------------------------------------------------------------------------------

def test_tune_writes_gains_no_worse_than_the_start_on_the_same_flights_and_resumes(scheduler, tmp_path):
    out = tmp_path / 'tune'
    options = RunOptions(scheduler=scheduler)
    setup = TuneSetup('pid', SPEC, seeds=(1,), trials=2, out_dir=out, options=options, sampler_seed=3)
    first = tune(setup, progress=False)
    assert first.trials == 2 and first.best_objective_m <= first.starting_objective_m

    gains_file = out / 'gains-pid.yaml'
    gains = load_gains(gains_file)                      # what --gains reads
    build_controller('pid', load_vehicle_file()[0], gains)
    with (out / 'trials-pid.csv').open() as stream:
        table = list(csv.DictReader(stream))
    assert [row['trial'] for row in table] == ['0', '1'] and table[0]['starting_gains'] == 'True'
    best = min((row for row in table if row['state'] == 'complete'), key=lambda row: float(row['objective_m']))
    assert values_in(gains, 'pid') == pytest.approx({name: float(best[name]) for name in values_in(gains, 'pid')})
    # the picks by each statistic from the same trials: the median's is the objective's, the tail's the trial with
    # the smallest p95 (the trials table's column), each a gains file
    assert first.picks['median'][0] == first.best_trial
    assert (out / 'gains-pid-median.yaml').read_text().split('\n', 1)[1] == gains_file.read_text().split('\n', 1)[1]
    tail = min((row for row in table if row['state'] == 'complete'), key=lambda row: float(row['p95_rmse_m']))
    assert first.picks['p95'][:2] == (int(tail['trial']), pytest.approx(float(tail['p95_rmse_m'])))
    assert first.picks['p95'][3] == at_bounds({name: float(tail[name]) for name in values_in(gains, 'pid')},
                                              search_space('pid'))
    tail_gains = load_gains(out / 'gains-pid-p95.yaml')
    assert values_in(tail_gains, 'pid') == pytest.approx({name: float(tail[name]) for name in values_in(gains, 'pid')})

    # the tuned gains and the packaged ones flown again, as plain campaigns on the same flights
    def flown(gains_path, folder):
        run_campaign(SPEC.overridden(seed=1), tmp_path / folder,
                     RunOptions(scheduler=scheduler, progress=False, report=False, gains_file=gains_path))
        return objective(read_flights(tmp_path / folder / 'flights.csv'), SPEC.max_error_m).objective_m
    tuned, packaged = flown(str(gains_file), 'tuned'), flown(None, 'packaged')
    assert tuned == pytest.approx(first.best_objective_m) and packaged == pytest.approx(first.starting_objective_m)
    assert tuned <= packaged

    # the same command again with a larger budget continues the study: one more trial, none flown again
    folders = set((out / 'campaigns').iterdir())
    second = tune(TuneSetup('pid', SPEC, seeds=(1,), trials=3, out_dir=out, options=options, sampler_seed=3),
                  progress=False)
    assert second.trials == 3 and second.starting_objective_m == first.starting_objective_m
    assert len(set((out / 'campaigns').iterdir()) - folders) == 1
    # another spec in the same folder is refused, and so is the same one searching the attitude loop too
    with pytest.raises(ParameterError, match='another spec'):
        tune(TuneSetup('pid', SPEC.overridden(flights=2), seeds=(1,), trials=3, out_dir=out, options=options),
             progress=False)
    with pytest.raises(ParameterError, match='another spec'):
        tune(TuneSetup('pid', SPEC, seeds=(1,), trials=3, out_dir=out, options=options, sampler_seed=3,
                       attitude=True), progress=False)


def test_tune_with_attitude_searches_and_writes_the_roll_and_pitch_loop(scheduler, tmp_path):
    out = tmp_path / 'tune'
    setup = TuneSetup('se3', SPEC, seeds=(1,), trials=2, out_dir=out, options=RunOptions(scheduler=scheduler),
                      attitude=True)
    tune(setup, progress=False)
    with (out / 'trials-se3.csv').open() as stream:
        table = list(csv.DictReader(stream))
    assert {'rp.k_error', 'rp.k_integral', 'rp.k_rate'} <= set(table[0])
    assert float(table[0]['rp.k_error']) == load_gains()['se3']['axes']['phi']['k_error']     # trial 0: the start
    picked = load_gains(out / 'gains-se3.yaml')['se3']['axes']
    best = min((row for row in table if row['state'] == 'complete'), key=lambda row: float(row['objective_m']))
    assert picked['phi']['k_rate'] == picked['theta']['k_rate'] == pytest.approx(float(best['rp.k_rate']))


# --- stress --------------------------------------------------------------------------------------

def synthetic(threshold: float, flights: int = 400):
    """A success share falling smoothly through 90 % at ``threshold``; the intensities it was asked for."""
    asked = []

    def rate_at(x: float) -> Tally:
        asked.append(x)
        share = 1.0 / (1.0 + math.exp((x - threshold) / 0.4 - math.log(9.0)))   # 0.9 exactly at threshold
        return Tally(int(math.floor(share * flights)), flights)
    return rate_at, asked


def test_the_bisection_finds_the_threshold_of_a_synthetic_curve():
    """Near the threshold the smooth curve's shares lie within their intervals' reach of 90 % even with 400
    flights: the bracket is found, but reported as a range (issue 35)."""
    rate_at, asked = synthetic(7.3)
    point = find_breaking_point(rate_at, 0.0, 20.0, 0.25)
    assert point.low < 7.3 <= point.high and point.high - point.low <= 0.25 + 1e-12
    assert len(asked) == len(set(asked)) <= 2 + math.ceil(math.log2(20.0 / 0.25))
    assert point.tries[point.low].share >= 0.9 > point.tries[point.high].share
    assert point.value == point.high
    assert point.status == 'range' and not point.tries[point.low].surely_holds
    sure_low, sure_high = point.bounds()
    assert sure_low < point.low and point.high <= sure_high     # the tries that are sure lie around the bracket
    assert point.tries[sure_low].interval[0] >= 0.9 > point.tries[sure_high].interval[1]


@pytest.mark.parametrize('flights, status', [(20, 'range'), (5, 'range'), (35, 'found'), (100, 'found')])
def test_a_breaking_point_is_found_only_when_the_intervals_at_its_bracket_do_not_straddle_90_percent(flights, status):
    """Issue 35: 5 flights per try reported 'found' where the Wilson interval (38-96 %) straddles 90 %. A step from
    every flight succeeding to none at 7.3: with n flights all n succeed below it, whose interval reaches below
    90 % up to n = 34 (20 of 20: 84-100 %), so only n >= 35 finds the point."""
    def rate_at(x: float) -> Tally:
        return Tally(flights if x < 7.3 else 0, flights)
    point = find_breaking_point(rate_at, 0.0, 20.0, 0.25)
    assert (point.low, point.high) == (7.25, 7.5) and point.status == status
    assert (wilson_interval(flights, flights)[0] >= 0.9) == (status == 'found')
    sure_low, sure_high = point.bounds()
    assert sure_high == 7.5 and (sure_low == 7.25 if status == 'found' else math.isnan(sure_low))
    text = describe(point, KINDS['wind'])
    if status == 'range':
        low, high = wilson_interval(flights, flights)
        assert text.startswith('a range, not a point: at or below 7.5 (steady wind speed [m/s]); the share falls '
                               f'below 90% between 7.25 and 7.5, but the 95 % intervals there ({low:.0%}-{high:.0%}, '
                               '0%-')
    else:
        assert text.startswith('breaking point 7.5 (steady wind speed [m/s])')


def test_breaking_points_csv_says_a_range_and_its_intervals(tmp_path):
    setup = StressSetup(CALM, KINDS['wind'], ('pid', 'se3'), tmp_path, RunOptions(), 0.0, 20.0, 0.25)
    results = {'pid': BreakingPoint('range', 5.0, 5.25, {0.0: Tally(20, 20), 5.0: Tally(5, 5), 5.25: Tally(3, 5),
                                                         20.0: Tally(0, 20)}),
               'se3': BreakingPoint('found', 5.0, 5.25, {5.0: Tally(100, 100), 5.25: Tally(50, 100)})}
    write_breaking_points(setup, results)
    with (tmp_path / 'breaking_points.csv').open() as stream:
        rows = {row['controller']: row for row in csv.DictReader(stream)}
    pid, se3 = rows['pid'], rows['se3']
    assert pid['status'] == 'range' and float(pid['breaking_point']) == 5.25
    assert math.isnan(float(pid['range_low'])) and float(pid['range_high']) == 5.25      # 3 of 5: 23-88 %
    assert (float(pid['holds_at_wilson95_low']), float(pid['holds_at_wilson95_high'])) \
        == pytest.approx(wilson_interval(5, 5))
    assert (float(pid['fails_at_wilson95_low']), float(pid['fails_at_wilson95_high'])) \
        == pytest.approx(wilson_interval(3, 5))
    assert pid['note'].startswith('a range, not a point: at or below 5.25')
    assert se3['status'] == 'found' and (float(se3['range_low']), float(se3['range_high'])) == (5.0, 5.25)


def test_the_bisection_says_when_the_range_holds_no_breaking_point():
    above, _ = synthetic(30.0)
    point = find_breaking_point(above, 0.0, 20.0, 0.25)
    assert point.status == 'above_range' and point.value == 20.0 and len(point.tries) == 2
    below, _ = synthetic(-1.0)
    point = find_breaking_point(below, 0.0, 20.0, 0.25)
    assert point.status == 'at_or_below_low' and point.value == 0.0 and len(point.tries) == 1


def test_a_fixed_disturbance_is_the_same_for_every_flight():
    nominal = load_vehicle_file()[0]
    spec = KINDS['mass'].fixed(SPEC, 1.4)
    assert {round(sample_conditions(spec, nominal, k).vehicle.m / nominal.m, 12) for k in range(5)} == {1.4}
    spec = KINDS['rotor-loss'].fixed(SPEC, 0.3)
    loss = sample_conditions(spec, nominal, 2).vehicle.rotor_efficiency_loss
    assert loss == pytest.approx((0.3, 0.0, 0.0, 0.0))
    # the spec as written to spec.yaml reads back the same
    assert parse_spec(spec.to_mapping()).vehicle == spec.vehicle
    # and the draws of every other key are unchanged by the new key
    assert sample_conditions(spec, nominal, 2).vehicle.Ix == sample_conditions(SPEC, nominal, 2).vehicle.Ix


def test_stress_runs_on_a_tiny_real_campaign(scheduler, tmp_path):
    kind = KINDS['mass']
    options = RunOptions(scheduler=scheduler)
    # the packaged vehicle's rotors hold up 2.25 times its mass: the highest try on a 0.6 grid is 1.8
    assert highest_intensity(kind, CALM, options, 0.6) == pytest.approx(1.8)
    setup = StressSetup(CALM, kind, ('pid',), tmp_path, options, 1.0, 2.2, 0.6)
    points = stress(setup, progress=False)
    point = points['pid']
    # nominal mass: every flight succeeds; 2.2 times the mass needs 98 % of full thrust to hover
    assert point.tries[1.0].successes == 3 and point.tries[2.2].successes == 0
    assert point.status == 'range' and sorted(point.tries) == [1.0, 1.6, 2.2]   # 3 flights: 3 of 3 is 44-100 %
    assert point.value == (1.6 if point.tries[1.6].share < 0.9 else 2.2)
    with (tmp_path / 'breaking_points.csv').open() as stream:
        rows = list(csv.DictReader(stream))
    assert [(r['kind'], r['controller'], r['status']) for r in rows] == [('mass', 'pid', 'range')]
    assert float(rows[0]['breaking_point']) == point.value
    with (tmp_path / 'stress-mass.csv').open() as stream:
        tries = list(csv.DictReader(stream))
    for row in tries:
        low, high = wilson_interval(int(row['successes']), int(row['flights']))
        assert (float(row['wilson95_low']), float(row['wilson95_high'])) == pytest.approx((low, high))
    assert (tmp_path / 'stress-mass.png').stat().st_size > 0


def test_a_search_controller_by_controller_keeps_every_controllers_rows(tmp_path):
    setup = StressSetup(CALM, KINDS['wind'], ('pid',), tmp_path, RunOptions(), 0.0, 20.0, 0.25)
    first = {'pid': BreakingPoint('found', 5.0, 10.0, {5.0: Tally(20, 20), 10.0: Tally(3, 20)})}
    second = {'se3': BreakingPoint('above_range', 20.0, math.nan, {20.0: Tally(19, 20)})}
    again = {'pid': BreakingPoint('found', 5.0, 7.5, {5.0: Tally(20, 20), 7.5: Tally(10, 20)})}
    for results in (first, second, again):
        write_tries(setup, results)
        write_breaking_points(setup, results)
    with (tmp_path / 'stress-wind.csv').open() as stream:
        tries = [(r['controller'], float(r['intensity']), int(r['successes'])) for r in csv.DictReader(stream)]
    assert sorted(tries) == [('pid', 5.0, 20), ('pid', 7.5, 10), ('se3', 20.0, 19)]   # pid's rows replaced
    assert read_tries(tmp_path / 'stress-wind.csv') == {'se3': {20.0: Tally(19, 20)}, 'pid': again['pid'].tries}
    with (tmp_path / 'breaking_points.csv').open() as stream:
        rows = {r['controller']: r['status'] for r in csv.DictReader(stream)}
    assert rows == {'pid': 'found', 'se3': 'above_range'}


@pytest.mark.parametrize('vehicle, message', [
    ({'mass': {'dist': 'fixed', 'value': -1.0}}, r'vehicle.mass.value: .*\(-1.0, inf'),
    ({'mass': {'dist': 'fixed'}}, 'vehicle.mass.value: missing'),
    ({'one_rotor_efficiency_loss': {'dist': 'fixed', 'value': -0.1}}, 'a loss is a fraction'),
    ({'one_rotor_efficiency_loss': {'dist': 'fixed', 'value': 1.0}}, 'cannot lose all of its thrust'),
    ({'mass': {'dist': 'constant', 'value': 0.2}}, 'uniform, normal, fixed'),
])
def test_a_fixed_value_the_vehicle_cannot_take_is_refused_naming_the_key(vehicle, message):
    with pytest.raises(ParameterError, match=message):
        parse_spec({**DOCUMENT, 'vehicle': vehicle})


@pytest.mark.parametrize('argv, message', [
    (['tune', '--controller', 'pid', '--trials', '2', '--seeds', '1,x'], '--seeds'),
    (['tune', '--controller', 'smc-sign', '--trials', '2'], 'no search space'),
    (['tune', '--controller', 'pid', '--trials', '0'], '--trials'),
    (['tune', '--controller', 'pid', '--trials', '2', '--sampler-seed', '-1'],
     'error: --sampler-seed: -1 is outside the valid range [0, 2147483647] (a whole number)\n'),   # issue 35
    (['stress', '--kind', 'mass', '--high', '2.5'], '--high: 2.5 is above'),
    (['stress', '--kind', 'wind', '--low', '5', '--high', '5'], '--low, --high'),
    # issue 35: these flew (30 s, then a traceback) before they were refused
    (['stress', '--kind', 'rotor-loss', '--high', '2'],
     "error: --high (--kind rotor-loss: one rotor's efficiency loss [-]): 2.0 is outside the valid range [0.0, 1.0)\n"),
    (['stress', '--kind', 'mass', '--low', '-1'],
     'error: --low (--kind mass: true mass / nominal mass [-]): -1.0 is outside the valid range (0.0, inf)\n'),
    (['stress', '--kind', 'delay', '--low', 'nan'], 'error: --low (--kind delay: transport delay [s]): must be finite'),
    (['stress', '--kind', 'noise', '--high', '-3'], 'error: --high (--kind noise: sensor noise scale [-]): -3.0 is'),
])
def test_the_commands_refuse_bad_options_before_flying(tmp_path, capsys, argv, message):
    from flight_stack.cli import run
    spec = tmp_path / 'spec.yaml'
    spec.write_text(yaml.safe_dump(DOCUMENT))
    assert run([*argv, str(spec), '--out', str(tmp_path / 'out')]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / 'out').exists()


def test_tune_refuses_an_out_that_is_a_file_in_one_line(tmp_path, capsys):
    """Issue 35: `tune --out FILE` raised FileExistsError (a traceback)."""
    from flight_stack.cli import run
    spec, out = tmp_path / 'spec.yaml', tmp_path / 'taken'
    spec.write_text(yaml.safe_dump(DOCUMENT))
    out.write_text('a file\n')
    assert run(['tune', str(spec), '--controller', 'pid', '--trials', '1', '--out', str(out)]) == 2
    assert capsys.readouterr().err == f'error: --out: {out} exists and is not a folder; choose another --out\n'
    assert out.read_text() == 'a file\n'


def test_ctrl_c_in_tune_says_how_to_continue_in_one_line_and_exits_130(tmp_path):
    """Issue 35: a Ctrl-C printed Optuna's 30-line traceback of the trial. A real process (Optuna's log handler
    writes to the process's stderr), whose trial is interrupted as Ctrl-C interrupts it."""
    spec, out = tmp_path / 'spec.yaml', tmp_path / 'out'
    spec.write_text(yaml.safe_dump(DOCUMENT))
    script = (f'import sys; sys.path.insert(0, {str(ROOT)!r})\n'
              'import flight_stack.campaign.tune as tune\n'
              'def interrupted(*args, **kwargs):\n    raise KeyboardInterrupt\n'
              'tune.fly_point = interrupted\n'
              'from flight_stack.cli import main\n'
              f'sys.exit(main(["tune", {str(spec)!r}, "--controller", "pid", "--trials", "2", "--out", {str(out)!r}]))\n')
    result = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True, timeout=HANG_TIMEOUT_S)
    assert result.returncode == 130, result.stderr
    lines = result.stderr.splitlines()
    assert lines[-1] == (f'interrupted; run the same command again to continue the study in {out} (the interrupted '
                         'trial is flown again, its finished flights kept)')
    assert 'Traceback' not in result.stderr and 'failed' not in result.stderr, result.stderr
    assert lines[:-1] == ['tune pid: 2 trials x 2 seed(s) 1,2 x 3 flights of "paper", 2 s each -> ' + str(out),
                          'tune pid: trial 0 (the starting gains): 2 seed(s) x 3 flights']


def test_tune_says_each_trial_its_seeds_and_its_objective(scheduler, tmp_path, capsys):
    """Issue 35: a trial (66 s) printed nothing until it ended. Now: its start, each seed's flights as they
    finish (the runner's bar) and its score, then the trial's objective."""
    setup = TuneSetup('pid', SPEC, seeds=(1, 2), trials=1, out_dir=tmp_path, options=RunOptions(scheduler=scheduler))
    outcome = tune(setup, progress=True)
    err = capsys.readouterr().err
    lines = [line for line in err.replace('\r', '\n').splitlines() if line.startswith('tune pid')]
    assert lines[0] == 'tune pid: trial 0 (the starting gains): 2 seed(s) x 3 flights'
    assert lines[1].startswith('tune pid: trial 0: seed 1 (1/2) flown: 3/3 finished so far, objective so far ')
    assert lines[2].startswith('tune pid: trial 0: seed 2 (2/2) flown: 6/6 finished so far, objective so far ')
    assert lines[3].startswith(f'tune pid: trial 0 (1/1) objective {outcome.best_objective_m * 100:.3f} cm, '
                               'finished 6/6 in ')
    assert 'trial 0 seed 1: 100%' in err and 'trial 0 seed 2: 100%' in err and '3/3' in err
    quiet = TuneSetup('pid', SPEC, seeds=(1,), trials=1, out_dir=tmp_path / 'quiet',
                      options=RunOptions(scheduler=scheduler))
    tune(quiet, progress=False)
    assert capsys.readouterr().err == ''


def test_every_search_space_is_a_controller_kind():
    from nnit2fsmc_controller.factory import CONTROLLERS
    assert set(SEARCH_SPACES) <= set(CONTROLLERS)
    assert {'nnit2fsmc', 'pid', 'se3', 'smc-integral'} <= set(SEARCH_SPACES)
    # equal effort is the same trials, seeds and flights (issue 37), with every gain a kind has in its space: the
    # PID-shaped position loops whole (x, y and z: error, integral, rate), l1-se3's L1 loop whole (both channels'
    # pole and low-pass, the rotational cascade's second stage)
    def keys(kind):
        return {gain for dimension in SEARCH_SPACES[kind] for gain in dimension.gains}
    for kind, section, gains in (('pid', 'pid', ('kp', 'ki', 'kd')), ('se3', 'se3', ('k_error', 'k_integral', 'k_rate')),
                                 ('l1-se3', 'l1_se3', ('k_error', 'k_integral', 'k_rate'))):
        assert {f'{section}.axes.{axis}.{gain}' for axis in 'xyz' for gain in gains} <= keys(kind), kind
    assert {f'l1_se3.{key}' for key in ('predictor_pole_translation', 'predictor_pole_rotation', 'cutoff_translation_hz',
                                        'cutoff_rotation_hz', 'cutoff_rotation_second_hz')} <= keys('l1-se3')
