#!/usr/bin/env python3
"""NNIT2FSMC against its baselines on the paper scenario, with and without the disturbances.

Flies every controller kind (factory.CONTROLLERS) on the paper's 60 s helix through the embedded backend
(the same code path as ``run_stack.py --backend embedded``), with the section IV disturbances on
and off, and prints a Markdown table of the metrics of :func:`quad_msgs_bridge.review.metrics.flight_metrics`
after the settling time, the ratios behind the paper's central claim and the issue's checks.

    .venv/bin/python bench/compare_controllers.py --out docs/results.md

Deterministic: the same command gives the same table (the network's initial weights are seeded).
``--allocation clip`` flies the paper's per-rotor clipping instead of thrust-priority allocation,
``--mass-factor 1.3`` a vehicle 30 % heavier than the controllers' nominal model (docs/BASELINES.md).
"""
from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack.embedded import Perturbations, fly_embedded  # noqa: E402
from nnit2fsmc_controller.factory import CONTROLLERS, load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.mixer import ALLOCATIONS  # noqa: E402
from quad_msgs_bridge.review.metrics import SUBSYSTEMS, flight_metrics  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402

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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--out', type=Path, default=None, help='also write the Markdown to this file')
    parser.add_argument('--duration', type=float, default=60.0, help='flight length [s] (default: 60, the paper)')
    parser.add_argument('--settle-time', type=float, default=5.0, help='metrics ignore the first S seconds')
    parser.add_argument('--physics-rate', type=float, default=1000.0, help='RK4 rate [Hz]')
    parser.add_argument('--jobs', type=int, default=2, help='parallel flights (default 2)')
    parser.add_argument('--allocation', choices=ALLOCATIONS, default='priority',
                        help='rotor-limit allocation of every controller (docs/BASELINES.md; clip: the paper\'s)')
    parser.add_argument('--mass-factor', type=float, default=1.0,
                        help='the flown vehicle\'s mass / the nominal one the controllers assume (default 1)')
    args = parser.parse_args(argv)

    cases = [(kind, disturbed, args.duration, args.settle_time, args.physics_rate, args.allocation, args.mass_factor)
             for disturbed in (True, False) for kind in CONTROLLERS]
    cases.sort(key=lambda case: case[0] != 'nnit2fsmc')   # the slowest flights first
    started = time.perf_counter()
    if args.jobs > 1:
        with multiprocessing.Pool(args.jobs) as pool:
            outcomes = pool.map(fly_case, cases, chunksize=1)
    else:
        outcomes = [fly_case(case) for case in cases]
    wall = time.perf_counter() - started
    results = {(case[0], case[1]): metrics for case, metrics, _ in outcomes}

    command = 'python bench/compare_controllers.py ' + ' '.join(argv if argv is not None else sys.argv[1:])
    lines = [f'## NNIT2FSMC and baselines on the paper scenario ({args.duration:g} s helix, '
             f'metrics after {args.settle_time:g} s, allocation {args.allocation}, '
             f'true mass {args.mass_factor:g} x nominal)', '',
             f'Produced by `{command.strip()}` ({len(cases)} flights, {wall:.0f} s wall with {args.jobs} processes).',
             '']
    for disturbed in (True, False):
        lines += main_table(results, disturbed) + ['']
    claim, claim_holds = claim_lines(results)
    accepted_lines, accepted = acceptance_lines(results)
    lines += claim + [''] + accepted_lines + ['']
    lines.append(f'Central claim with disturbances: {"HOLDS" if claim_holds else "DOES NOT HOLD"}; '
                 f'issue acceptance: {"PASS" if accepted else "FAIL"}.')
    text = '\n'.join(lines) + '\n'
    print(text, end='')
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    return 0 if accepted and claim_holds else 1


if __name__ == '__main__':
    sys.exit(main())
