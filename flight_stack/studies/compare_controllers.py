"""The NNIT2FSMC-against-baselines tables of docs/BASELINES.md: the paper scenario, disturbances on and off.

Flies every controller kind (factory.CONTROLLERS) on the paper's 60 s helix through the embedded backend
(the same code path as ``run_stack.py --backend embedded``), with the section IV disturbances on
and off, and prints a Markdown table of the metrics of :func:`quad_msgs_bridge.review.metrics.flight_metrics`
after the settling time, the ratios behind the paper's central claim and the issue's checks.

    run_stack.py study compare-controllers --out DIR

Deterministic: the same command gives the same table (the network's initial weights are seeded).
``--allocation clip`` flies the paper's per-rotor clipping instead of thrust-priority allocation,
``--mass-factor 1.3`` a vehicle 30 % heavier than the controllers' nominal model (docs/BASELINES.md).
"""
from __future__ import annotations

import argparse
import dataclasses
import time

from flight_stack.embedded import Perturbations, fly_embedded
from nnit2fsmc_controller.factory import CONTROLLERS, load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.mixer import ALLOCATIONS
from quad_msgs_bridge.review.metrics import SUBSYSTEMS, flight_metrics
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from .common import add_out, run_all, study_name, write_table

STUDY = study_name(__name__)

CONTROLS = ('U1', 'U2', 'U3', 'U4')
# the acceptance figures
MAX_RMSE_M, MAX_ERROR_M, MIN_TV_RATIO, MAX_RMSE_RATIO = 0.05, 0.15, 10.0, 1.2


def fly_case(case):
    """(controller, disturbances on?, duration [s], settle [s], physics rate [Hz], allocation, true mass / nominal)
    -> (case, metrics, wall [s]); metrics are None for a flight that failed (FailureRules) before it settled,
    and name the failure of one that failed later (``failure``: None or 'reason at t s')."""
    kind, disturbed, duration, settle, physics_rate, allocation, mass_factor = case
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    gains['common']['allocation'] = allocation
    true_vehicle = dataclasses.replace(params, m=params.m * mass_factor) if mass_factor != 1.0 else None
    result = fly_embedded(kind, make_scenario('paper', duration), params, disturbances.switched(disturbed),
                          gains, duration, physics_rate, perturbations=Perturbations(true_vehicle=true_vehicle))
    record = result.record
    failure = None if result.failure is None else f'{result.failure} at {result.failure_time_s:.2f} s'
    if result.failure is not None and result.failure_time_s <= settle:
        return case, {'failure': failure}, result.wall_time_s
    metrics = flight_metrics(record, settle, params.F_min, params.F_max)
    metrics['failure'] = failure
    metrics['forces_within_limits'] = bool(record.forces.min() >= params.F_min
                                           and record.forces.max() <= params.F_max)
    return case, metrics, result.wall_time_s


def main_table(results, disturbed: bool) -> list[str]:
    lines = [f'### Paper scenario, disturbances {"on" if disturbed else "off"}', '',
             '| controller | RMSE [cm] | max error [cm] | yaw RMSE [mrad] | TV U1 [N/s] | TV U2 [N/s] | TV U3 [N/s] '
             '| TV U4 [N m/s] | saturated steps [%] | fuzzy share first -> last (x y z phi theta psi) |',
             '|---|---:|---:|---:|---:|---:|---:|---:|---:|---|']
    for kind in CONTROLLERS:
        m = results[(kind, disturbed)]
        if 'rmse_position_m' not in m:
            lines.append(f'| {kind} | FAILED: {m["failure"]} | | | | | | | | |')
            continue
        tv = ' | '.join(f'{m["chattering"][c]:.3g}' for c in CONTROLS)
        if kind == 'nnit2fsmc':
            share = ' '.join(f'{m["fuzzy_share"][s][0]:.2f}->{m["fuzzy_share"][s][-1]:.2f}' for s in SUBSYSTEMS)
        else:
            share = '(no fuzzy term)'
        if m['failure']:
            share += f' FAILED: {m["failure"]}'
        lines.append(f'| {kind} | {m["rmse_position_m"] * 100:.3f} | {m["max_position_error_m"] * 100:.3f} '
                     f'| {m["rmse_yaw_rad"] * 1e3:.3f} | {tv} | {m["saturation_fraction"] * 100:.2f} | {share} |')
    return lines


def claim_lines(results) -> tuple[list[str], bool]:
    lines = ['### The central claim: NNIT2FSMC vs classic sign-SMC (same sliding surfaces)', '',
             '| disturbances | TV ratio U1 | TV ratio U2 | TV ratio U3 | TV ratio U4 | RMSE ratio | '
             f'TV ratios >= {MIN_TV_RATIO:g} and RMSE ratio <= {MAX_RMSE_RATIO:g} |',
             '|---|---:|---:|---:|---:|---:|---|']
    holds = {}
    for disturbed in (True, False):
        nn, sign = results[('nnit2fsmc', disturbed)], results[('smc-sign', disturbed)]
        if 'rmse_position_m' not in nn or 'rmse_position_m' not in sign:
            holds[disturbed] = False
            lines.append(f'| {"on" if disturbed else "off"} | n/a (a flight failed before settling) | | | | | NO |')
            continue
        ratios = [sign['chattering'][c] / nn['chattering'][c] for c in CONTROLS]
        rmse_ratio = nn['rmse_position_m'] / sign['rmse_position_m']
        holds[disturbed] = min(ratios) >= MIN_TV_RATIO and rmse_ratio <= MAX_RMSE_RATIO
        lines.append(f'| {"on" if disturbed else "off"} | ' + ' | '.join(f'{r:.3g}' for r in ratios)
                     + f' | {rmse_ratio:.2f} | {"yes" if holds[disturbed] else "NO"} |')
    lines.append('')
    lines.append('TV ratio = total variation per second of U_i for smc-sign / for nnit2fsmc; '
                 'RMSE ratio = position RMSE of nnit2fsmc / of smc-sign.')
    return lines, holds[True]


def acceptance_lines(results) -> tuple[list[str], bool]:
    m = results[('nnit2fsmc', True)]
    if 'rmse_position_m' not in m:
        return ['### Issue 2 acceptance, NNIT2FSMC with disturbances', '', f'FAIL: {m["failure"]}'], False
    shares = m['fuzzy_share']
    checks = [
        (f'position RMSE after settling < {MAX_RMSE_M * 100:g} cm', m['rmse_position_m'] < MAX_RMSE_M,
         f'{m["rmse_position_m"] * 100:.3f} cm'),
        (f'max position error after settling < {MAX_ERROR_M * 100:g} cm', m['max_position_error_m'] < MAX_ERROR_M,
         f'{m["max_position_error_m"] * 100:.3f} cm'),
        ('no rotor force outside [F_min, F_max]', m['forces_within_limits'], 'checked on every step'),
        ('no NaN', m['all_finite'], 'forces and positions finite'),
        ('fuzzy share falls over the flight (every subsystem, first vs last window)',
         all(shares[s][-1] < shares[s][0] for s in SUBSYSTEMS),
         ', '.join(f'{s} {shares[s][0]:.2f}->{shares[s][-1]:.2f}' for s in SUBSYSTEMS)),
    ]
    lines = ['### Issue 2 acceptance, NNIT2FSMC with disturbances', '', '| check | result | value |', '|---|---|---|']
    lines += [f'| {name} | {"pass" if ok else "FAIL"} | {value} |' for name, ok, value in checks]
    return lines, all(ok for _, ok, _ in checks)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--duration', type=float, default=60.0, help='flight length [s] (default: 60, the paper)')
    parser.add_argument('--settle-time', type=float, default=5.0, help='metrics ignore the first S seconds')
    parser.add_argument('--physics-rate', type=float, default=1000.0, help='RK4 rate [Hz]')
    parser.add_argument('--jobs', type=int, default=2, help='parallel flights (default 2)')
    parser.add_argument('--allocation', choices=ALLOCATIONS, default='priority',
                        help='rotor-limit allocation of every controller (docs/BASELINES.md; clip: the paper\'s)')
    parser.add_argument('--mass-factor', type=float, default=1.0,
                        help='the flown vehicle\'s mass / the nominal one the controllers assume (default 1)')


def run(args: argparse.Namespace) -> int:
    """Exit status 0 when the central claim holds and the issue's acceptance passes, else 1."""
    cases = [(kind, disturbed, args.duration, args.settle_time, args.physics_rate, args.allocation, args.mass_factor)
             for disturbed in (True, False) for kind in CONTROLLERS]
    cases.sort(key=lambda case: case[0] != 'nnit2fsmc')   # the slowest flights first
    started = time.perf_counter()
    outcomes = run_all(fly_case, cases, args.jobs, STUDY,
                       lambda case: f'{case[0]}, disturbances {"on" if case[1] else "off"}')
    wall = time.perf_counter() - started
    results = {(case[0], case[1]): metrics for case, metrics, _ in outcomes}

    command = (f'run_stack.py study compare-controllers --duration {args.duration:g} --settle-time '
               f'{args.settle_time:g} --physics-rate {args.physics_rate:g} --allocation {args.allocation} '
               f'--mass-factor {args.mass_factor:g}')
    lines = [f'## NNIT2FSMC and baselines on the paper scenario ({args.duration:g} s helix, '
             f'metrics after {args.settle_time:g} s, allocation {args.allocation}, '
             f'true mass {args.mass_factor:g} x nominal)', '',
             f'Produced by `{command}` ({len(cases)} flights, {wall:.0f} s wall with {args.jobs} processes).',
             '']
    for disturbed in (True, False):
        lines += main_table(results, disturbed) + ['']
    claim, claim_holds = claim_lines(results)
    accepted_lines, accepted = acceptance_lines(results)
    lines += claim + [''] + accepted_lines + ['']
    lines.append(f'Central claim with disturbances: {"HOLDS" if claim_holds else "DOES NOT HOLD"}; '
                 f'issue acceptance: {"PASS" if accepted else "FAIL"}.')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0 if accepted and claim_holds else 1
