"""``run_stack.py campaign SPEC.yaml --out DIR``: the robustness campaign command."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .runner import MAX_BATCH_SIZE

from quad_msgs_bridge.output_path import output_path
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_sim.plants import PLANTS

DESCRIPTION = """Fly a robustness campaign: every controller of the spec flies the same perturbed flights
(true vehicle vs nominal model, wind, sensor noise, delay, motor lag), as numpy batches on local
worker processes or on a Dask cluster. Writes DIR/flights.csv (one row per flight and controller,
appended batch by batch), DIR/campaign.json (success rate with its 95 % Wilson interval, RMSE and
chattering percentiles per controller) and DIR/report.html. SPEC.yaml: see docs/CAMPAIGNS.md."""

EPILOG = """examples:
  python3 run_stack.py campaign campaigns/paper-robustness.yaml --out out/campaign
  python3 run_stack.py campaign campaigns/paper-robustness.yaml --out out/campaign --resume
  python3 run_stack.py campaign campaigns/paper-robustness.yaml --out out/campaign --replay 17
  python3 run_stack.py campaign SPEC.yaml --out DIR --scheduler tcp://127.0.0.1:8786

A Dask scheduler runs whatever code it is sent: start it on localhost or a trusted network only."""


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog='run_stack.py campaign', description=DESCRIPTION, epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('spec', type=Path, nargs='?',
                        help='campaign spec (YAML): a file, or the name of a shipped spec (see --list)')
    parser.add_argument('--list', action='store_true', help='list the shipped specs (where they are) and exit')
    parser.add_argument('--out', type=output_path, default=None,
                        help='output folder (default out/campaign-<spec name>)')
    parser.add_argument('--flights', type=int, default=None,
                        help='flights per controller, >= 1, no upper limit (overrides the spec)')
    parser.add_argument('--seed', type=int, default=None, help='campaign seed (overrides the spec)')
    parser.add_argument('--duration', type=float, default=None, help='sim time per flight [s] (overrides the spec)')
    parser.add_argument('--controllers', default=None, help='comma-separated controllers (overrides the spec)')
    parser.add_argument('--plant', choices=PLANTS, default=None,
                        help='what the simulator flies (overrides the spec\'s plant; docs/ROTORPY.md)')
    parser.add_argument('--workers', type=int, default=None, help='local worker processes (default: every core)')
    parser.add_argument('--batch-size', type=int, default=None,
                        help='flights stepped together per batch (default: an even share per worker, at most '
                             f'{MAX_BATCH_SIZE})')
    parser.add_argument('--scheduler', default=None, metavar='ADDRESS',
                        help='run the batches on this Dask distributed scheduler (e.g. tcp://127.0.0.1:8786)')
    parser.add_argument('--replay', type=int, default=None, metavar='K',
                        help='fly flight K alone on the ordinary embedded path, with its bag and review, '
                             'into DIR/replay-K/<controller>/')
    parser.add_argument('--resume', action='store_true', help='fly only the flights DIR/flights.csv lacks')
    parser.add_argument('--vehicle', type=Path, default=None,
                        help='nominal vehicle YAML, or a shipped vehicle by name: paper (the default), crazyflie, '
                             'hummingbird, x500')
    parser.add_argument('--gains', type=Path, default=None, help='controller gains YAML, or a named set: packaged (the default), untuned, paper-faithful')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.add_argument('--fail-below', type=float, default=None, metavar='FRACTION',
                        help='exit with status 1, naming them, when any controller finishes fewer than FRACTION '
                             '(0 to 1) of its flights (default: exit 0 whatever the success rates; a CI gate)')
    args = parser.parse_args(argv)
    if args.spec is None and not args.list:
        parser.error('the spec is required (a YAML file, or a shipped spec: --list)')
    return args


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    from .runner import RunOptions, check_output, run_campaign
    from .spec import load_spec, shipped_specs
    if args.list:
        for path in shipped_specs():
            print(f'{path.stem:28s} {path}')
        return 0
    try:
        if args.fail_below is not None:
            check_number('--fail-below', args.fail_below, 0.0, 1.0)
        spec = load_spec(args.spec).overridden(flights=args.flights, seed=args.seed, duration=args.duration,
                                               controllers=args.controllers, plant=args.plant)
        out_dir = args.out or Path('out') / f'campaign-{args.spec.stem}'
        options = RunOptions(workers=args.workers, batch_size=args.batch_size, scheduler=args.scheduler,
                             resume=args.resume, progress=not args.quiet,
                             vehicle_file=None if args.vehicle is None else str(args.vehicle),
                             gains_file=None if args.gains is None else str(args.gains))
        options.worker_count()
        if args.replay is not None:
            from .replay import replay_flight
            return replay_flight(spec, out_dir, args.replay, options)
        check_output(spec, out_dir, args.resume)
        print(f'campaign: {len(spec.controllers)} controller(s) x {spec.flights} flights of "{spec.scenario}", '
              f'{spec.duration:g} s each, seed {spec.seed} -> {out_dir}', file=sys.stderr)
        outcome = run_campaign(spec, out_dir, options)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if (out_dir / 'flights.csv').exists():
            print(f'interrupted: every finished batch is in {out_dir / "flights.csv"}; '
                  'rerun with --resume to fly the rest', file=sys.stderr)
        else:
            print(f'interrupted before the first batch; {out_dir} is unchanged', file=sys.stderr)
        return 130
    rate = outcome.vehicle_steps / outcome.wall_time_s if outcome.wall_time_s > 0 else float('nan')
    print(f'flew {outcome.flights_flown} flights in {outcome.wall_time_s:.1f} s '
          f'({rate:,.0f} vehicle-steps/s)', file=sys.stderr)
    print(format_table(outcome.summary_path))
    print(f'results: {outcome.summary_path}, {outcome.summary_path.parent / "flights.csv"}, '
          f'{outcome.summary_path.parent / "report.html"}')
    return 0 if args.fail_below is None else gate(outcome.summary_path, args.fail_below)


def gate(summary_path: Path, fraction: float) -> int:
    """--fail-below: 1 after naming every controller that finished fewer than ``fraction`` of its flights,
    else 0."""
    import json
    below = [(name, entry) for name, entry in json.loads(summary_path.read_text())['controllers'].items()
             if entry['flights'] and entry['finished'] < fraction * entry['flights']]
    for name, entry in below:
        print(f'FAILED: {name} finished {entry["finished"]} of {entry["flights"]} flights, below --fail-below '
              f'{fraction:g}', file=sys.stderr)
    return 1 if below else 0


def format_table(summary_path: Path) -> str:
    """The per-controller table of campaign.json, for the terminal."""
    import json
    summary = json.loads(summary_path.read_text())
    lines = [f'{"controller":20s} {"finished":>9s} {"95% interval":>15s} {"RMSE p50":>9s} {"p95":>8s} {"p99":>8s} '
             f'{"max":>8s} [cm]  {"chattering p50: U1 [N/s]":>24s}  {"moments [N m/s]":>15s}']
    for name, entry in summary['controllers'].items():
        rmse = entry['rmse_position_m']
        force, moment = entry['chattering_force_n_per_s']['p50'], entry['chattering_moment_nm_per_s']['p50']
        low, high = entry['success_rate_wilson95']
        cm = [f'{rmse[k] * 100:8.3f}' if rmse[k] is not None else '       -' for k in ('p50', 'p95', 'p99', 'max')]
        tvs = [f'{value:.3g}' if value is not None else '-' for value in (force, moment)]
        lines.append(f'{name:20s} {entry["finished"]:4d}/{entry["flights"]:<4d} '
                     f'{low * 100:6.2f}-{high * 100:6.2f}% {cm[0]} {cm[1]} {cm[2]} {cm[3]}       '
                     f'{tvs[0]:>24s}  {tvs[1]:>15s}')
    return '\n'.join(lines)
