"""The four-conditions and delay-margin table of docs/ADAPTIVE_BASELINES.md ("What they fly"), every kind.

Issue 26's four conditions and the delay margins, for every kind from one gains file.

    run_stack.py study conditions --out DIR                                 # the six kinds, packaged gains
    run_stack.py study conditions --out DIR --gains untuned --jobs 2
    run_stack.py study conditions --out DIR --kinds l1-se3,indi --no-margins

**Conditions** (``flight_stack.fly``, the paper helix with its section IV disturbances, ``--duration`` s, the
nominal vehicle model, one flight each): position RMSE / largest position error after the settling time
[mm] (or how the flight failed) under

* nominal: nothing more;
* wind: a steady 6 m/s wind along +x (``wind={'mean_speed_mps': 6.0, 'turbulence': 'none', 'direction_deg': 0.0}``);
* mass: a true vehicle 30 % heavier than the nominal model (``true_vehicle`` with m x 1.3);
* rotor loss: rotor 1 loses 30 % of its thrust at 10 s
  (``rotor_efficiency_loss={'at_s': 10.0, 'loss': [0.3, 0, 0, 0]}``).

**Delay margins** (the margins study's ``delay_margins``: the paper helix, ``--margin-duration`` s, physics at
4 kHz, to 0.25 ms): the smallest transport delay at which the flight is unstable, with ideal rotors and
with the example campaign's 30 ms motor lag.
"""
from __future__ import annotations

import argparse
import dataclasses

from flight_stack.api import fly
from nnit2fsmc_controller.factory import CONTROLLERS
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from . import margins, paper_tables
from .common import add_out, names, run_all, study_name, write_table

STUDY = study_name(__name__)

KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'l1-se3', 'indi')
CONDITIONS = ('nominal', 'wind 6 m/s', 'mass +30 %', 'rotor 1 -30 % at 10 s')


def world(condition: str) -> dict:
    """The ``fly`` keywords of one condition (module docstring)."""
    if condition == 'nominal':
        return {}
    if condition == 'wind 6 m/s':
        return {'wind': {'mean_speed_mps': 6.0, 'turbulence': 'none', 'direction_deg': 0.0}}
    if condition == 'mass +30 %':
        params = load_vehicle_file()[0]
        return {'true_vehicle': dataclasses.replace(params, m=params.m * 1.3)}
    if condition == 'rotor 1 -30 % at 10 s':
        return {'rotor_efficiency_loss': {'at_s': 10.0, 'loss': [0.3, 0.0, 0.0, 0.0]}}
    raise ValueError(f'condition: {condition!r} is not one of {", ".join(CONDITIONS)}')


def fly_condition(task) -> dict:
    """(kind, condition, duration, gains) -> {'rmse_mm', 'max_mm', 'failure'}."""
    kind, condition, duration, gains = task
    flight = fly(kind, 'paper', duration=duration, gains=gains, **world(condition))
    summary = flight.summary
    return {'rmse_mm': 1e3 * summary['rmse_position_m'], 'max_mm': 1e3 * summary['max_position_error_m'],
            'failure': summary['ended_early']}


def margin_task(task) -> dict:
    kind, duration, max_delay = task
    return margins.delay_margins(kind, duration, max_delay)


def cell(result: dict) -> str:
    if result['failure']:
        return f'failed ({result["failure"]})'
    return f'{result["rmse_mm"]:.3g} / {result["max_mm"]:.3g}'


def conditions_table(kinds, duration: float, gains, jobs: int, margin_duration: float | None,
                     max_delay: float = margins.MAX_DELAY) -> list[str]:
    tasks = [(kind, condition, duration, gains) for kind in kinds for condition in CONDITIONS]
    flown = dict(zip(tasks, run_all(fly_condition, tasks, jobs, STUDY, lambda t: f'{t[0]}: {t[1]}')))
    margin_of = {}
    if margin_duration is not None:
        if gains is not None:
            paper_tables.OVERRIDES['gains_file'] = str(gains)
        margin_tasks = [(kind, margin_duration, max_delay) for kind in kinds]
        margin_of = dict(zip(kinds, run_all(margin_task, margin_tasks, jobs, STUDY,
                                            lambda t: f'{t[0]}: its delay margins')))
    header = ['kind', *(f'{c}: RMSE / max [mm]' for c in CONDITIONS)]
    if margin_of:
        header += ['delay margin, ideal rotors', 'delay margin, 30 ms motor lag']
    lines = ['| ' + ' | '.join(header) + ' |', '|---|' + '---:|' * (len(header) - 1)]
    for kind in kinds:
        cells = [f'`{kind}`', *(cell(flown[(kind, c, duration, gains)]) for c in CONDITIONS)]
        if margin_of:
            m = margin_of[kind]
            cells += [m['delay_lag0']['text'], m[f'delay_lag{margins.MOTOR_LAG:g}']['text']]
        lines.append('| ' + ' | '.join(cells) + ' |')
    return lines


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--kinds', default=','.join(KINDS), help='comma-separated controller kinds')
    parser.add_argument('--gains', default=None, help='gains file or named set (default: the packaged one)')
    parser.add_argument('--duration', type=float, default=20.0, help='[s] each condition\'s flight (default 20)')
    parser.add_argument('--margin-duration', type=float, default=30.0,
                        help='[s] each delay-margin flight (default 30, as the margins study)')
    parser.add_argument('--no-margins', action='store_true', help='leave the delay margins out')
    parser.add_argument('--jobs', type=int, default=1, help='flights at a time (default 1)')


def run(args: argparse.Namespace) -> int:
    kinds = names(args.kinds)
    unknown = [k for k in kinds if k not in CONTROLLERS]
    if unknown:
        raise ParameterError(f'--kinds: unknown {", ".join(unknown)} (kinds: {", ".join(CONTROLLERS)})')
    lines = conditions_table(kinds, args.duration, args.gains, max(1, args.jobs),
                             None if args.no_margins else args.margin_duration)
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
