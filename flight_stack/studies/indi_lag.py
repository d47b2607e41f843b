"""indi's sensitivity to the rotor lag it assumes: the table of docs/ADAPTIVE_BASELINES.md, its modelled motor
time constant against the true one.

``indi`` models the rotors' response as a first-order lag (``indi.motor_time_constant``, tau-hat [s]); the true
vehicle's rotors have their own (tau [s]). Each cell of the table is a campaign of ``--flights`` indi flights on
``--spec`` (every flight's world drawn as the spec says: vehicle, wind, noise, transport delay) with the true
motor time constant fixed at one of ``--lags`` and tau-hat set to a factor (``--factors``) of the gains' value,
or to the true lag itself (the column ``= true``). Every cell flies the same seed, so its flights differ only in
tau and tau-hat. Per cell: flights finished, and the median and 95th percentile of the position RMSE, failures
counted as the spec's ``max_error_m`` (as the tuning objective does).

    run_stack.py study indi-lag --out DIR --gains gains-indi.yaml --flights 100 --duration 30 --seed 101

Each campaign is kept in DIR/indi-lag/<tau>/<tau-hat>/ and reused when the command runs again (resumable).
Writes DIR/indi-lag.md.
"""
from __future__ import annotations

import argparse
from dataclasses import replace

import yaml

from flight_stack.campaign.results import FLIGHTS_FILE, read_flights
from flight_stack.campaign.runner import RunOptions, holds_campaign, run_campaign
from flight_stack.campaign.spec import load_spec
from flight_stack.campaign.tune import objective
from nnit2fsmc_controller.factory import load_gains
from quad_msgs_bridge.validation import ParameterError, check_number

from .common import add_out, names, progress, study_name, write_table

STUDY = study_name(__name__)
KIND = 'indi'
TRUE = 'true'   #: the column whose tau-hat is the true lag


def assumed(factor: str, tuned: float, true_lag: float) -> float:
    """tau-hat [s] of a column: ``factor`` times the gains' ``tuned`` value, or the ``true_lag`` itself."""
    return true_lag if factor == TRUE else float(factor) * tuned


def number(option: str, text: str) -> float:
    """``text`` of a comma-separated ``option`` as a number; ParameterError naming the option if it is not one."""
    try:
        return float(text)
    except ValueError:
        raise ParameterError(f'{option}: {text!r} is not a number') from None


def cell(flights: list[dict], max_error_m: float) -> str:
    """'finished/flights: p50 / p95 [cm]' of a cell's flights (failures counted as ``max_error_m``, as the
    tuning objective counts them: :func:`flight_stack.campaign.tune.objective`); a percentile that a failure
    enters (above every finished flight's RMSE) is said as 'failed', not as a number of centimetres."""
    score = objective(flights, max_error_m)
    worst_finished = max((f['rmse_position_m'] for f in flights if f['finished']), default=-1.0)

    def said(value: float) -> str:
        return 'failed' if value > worst_finished else f'{value * 100.0:.2f}'
    return f'{score.finished}/{score.flights}: {said(score.median_rmse_m)} / {said(score.p95_rmse_m)}'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--spec', default='paper-robustness-drawn-actuator', help='campaign spec (a file or a '
                        'shipped name; default paper-robustness-drawn-actuator); its motor lag is replaced per row')
    parser.add_argument('--gains', default=None, help='gains file (partial allowed; default: the packaged gains)')
    parser.add_argument('--lags', default='0.015,0.03,0.045', help='true motor time constants [s], comma-separated')
    parser.add_argument('--factors', default=f'0.5,1,2,{TRUE}',
                        help=f'tau-hat as factors of the gains\' value, or {TRUE} (the true lag), comma-separated')
    parser.add_argument('--flights', type=int, default=100, help='flights per cell')
    parser.add_argument('--duration', type=float, default=30.0, help='[s] every flight')
    parser.add_argument('--seed', type=int, default=101, help='the campaign seed of every cell (held-out: 101)')
    parser.add_argument('--workers', type=int, default=None, help='campaign worker processes (default: the CPUs)')


def run(args: argparse.Namespace) -> int:
    lags = [check_number('--lags', number('--lags', text), 0.0) for text in names(args.lags)]
    factors = names(args.factors)
    for factor in factors:
        if factor != TRUE:
            check_number('--factors', number('--factors', factor), 0.0)
    spec = load_spec(args.spec).overridden(flights=args.flights, duration=args.duration, seed=args.seed,
                                           controllers=[KIND])
    gains = load_gains(args.gains, kind=KIND)
    tuned = gains['indi']['motor_time_constant']
    root = args.out / STUDY
    lines = [f'indi, its gains\' tau-hat {tuned * 1000:.1f} ms; cells: finished/flights: median / p95 position RMSE '
             f'[cm] on {args.flights} flights of {args.duration:g} s, seed {args.seed}, spec {args.spec}', '',
             '| true tau [ms] | ' + ' | '.join(f'tau-hat = {f}' if f == TRUE else f'tau-hat x{f}' for f in factors)
             + ' |', '|---:|' + '---|' * len(factors)]
    for lag in lags:
        row = []
        for factor in factors:
            guess = assumed(factor, tuned, lag)
            folder = root / f'{lag:g}' / f'{guess:g}'
            folder.mkdir(parents=True, exist_ok=True)
            gains_path = folder / 'gains.yaml'
            cell_gains = {**gains, 'indi': {**gains['indi'], 'motor_time_constant': guess}}
            gains_path.write_text(yaml.safe_dump(cell_gains, sort_keys=False))
            run_campaign(replace(spec, motor_time_constant_s=lag), folder / 'campaign',
                         RunOptions(workers=args.workers, gains_file=str(gains_path), progress=False, report=False,
                                    resume=holds_campaign(folder / 'campaign')))
            row.append(cell(read_flights(folder / 'campaign' / FLIGHTS_FILE), spec.max_error_m))
            progress(STUDY, f'true tau {lag * 1000:g} ms, tau-hat {guess * 1000:.1f} ms: {row[-1]}')
        lines.append(f'| {lag * 1000:g} | ' + ' | '.join(row) + ' |')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
