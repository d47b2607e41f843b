"""``run_stack.py tune ...`` and ``run_stack.py stress ...``: the commands of the two campaign clients
(:mod:`.tune`, :mod:`.stress`; docs/TUNING.md)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from quad_msgs_bridge.validation import ParameterError

TUNE_DESCRIPTION = """Tune one controller kind on campaigns with Optuna (docs/TUNING.md): N trials, each the kind's
gains flown on M flights of every tuning seed (the campaign runner: local workers or a Dask cluster).
Objective: the median position RMSE over the tuning flights, a failed flight counted as max_error_m,
and worse than any gains that finish 99 % when fewer do. The first trial is the starting gains
(packaged, or --gains). The study lives in DIR/study.journal: the same command again continues it.
Writes DIR/gains-KIND.yaml (a --gains file) and DIR/trials-KIND.csv (every trial)."""

TUNE_EPILOG = """examples:
  python3 run_stack.py tune campaigns/paper-robustness.yaml --controller pid --trials 40 --flights 100 \\
      --seeds 1,2 --out out/tune-pid
  python3 run_stack.py --controller pid --gains out/tune-pid/gains-pid.yaml"""

STRESS_DESCRIPTION = """Find each controller's breaking point under one disturbance (docs/TUNING.md): the intensity
at which the share of flights that finish with a position RMSE below 10 cm falls below 90 %, by
bisection over campaigns of SPEC with that disturbance fixed. Writes DIR/breaking_points.csv (a row
per kind and controller), DIR/stress-KIND.csv (every intensity tried, with its 95 % Wilson interval)
and DIR/stress-KIND.png. Intensities: {kinds}."""

STRESS_EPILOG = """example:
  python3 run_stack.py stress campaigns/paper-robustness.yaml --kind wind --controllers nnit2fsmc,pid \\
      --flights 100 --out out/stress"""


def _campaign_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('spec', type=Path, help='campaign spec (YAML): a file or a shipped spec\'s name')
    parser.add_argument('--flights', type=int, default=None, help='flights per campaign (default: the spec\'s)')
    parser.add_argument('--duration', type=float, default=None, help='sim time per flight [s] (overrides the spec)')
    parser.add_argument('--out', type=Path, required=True, help='output folder (running again continues it)')
    parser.add_argument('--workers', type=int, default=None, help='local worker processes (default: every core)')
    parser.add_argument('--batch-size', type=int, default=None, help='flights stepped together per batch')
    parser.add_argument('--scheduler', default=None, metavar='ADDRESS',
                        help='fly the campaigns on this Dask distributed scheduler (e.g. tcp://127.0.0.1:8786)')
    parser.add_argument('--vehicle', type=Path, default=None, help='nominal vehicle YAML (default: the packaged one)')
    parser.add_argument('--gains', type=Path, default=None, help='gains YAML, or a named set: packaged (the default), untuned, '
                             'paper-faithful')
    parser.add_argument('--quiet', action='store_true', help='no progress lines')


def _run_options(args):
    from .runner import RunOptions
    options = RunOptions(workers=args.workers, batch_size=args.batch_size, scheduler=args.scheduler,
                         vehicle_file=None if args.vehicle is None else str(args.vehicle),
                         gains_file=None if args.gains is None else str(args.gains))
    options.worker_count()
    return options


def tune_main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='run_stack.py tune', description=TUNE_DESCRIPTION, epilog=TUNE_EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    _campaign_options(parser)
    parser.add_argument('--controller', required=True, help='the kind to tune (one with a search space)')
    parser.add_argument('--trials', type=int, required=True, help='trials in the study, >= 1 (the budget)')
    parser.add_argument('--seeds', default='1,2', help='tuning campaign seeds, comma-separated (default 1,2)')
    parser.add_argument('--sampler-seed', type=int, default=0, help='seed of the TPE sampler (default 0)')
    from .tune import OBJECTIVES
    parser.add_argument('--objective', choices=OBJECTIVES, default='median',
                        help="the statistic of the flights' position RMSE minimised, subject to 99 %% finished "
                             '(default median; p95: the tail). Either way gains-KIND-median.yaml and '
                             'gains-KIND-p95.yaml hold the pick of each from the same trials')
    parser.add_argument('--attitude', action='store_true',
                        help='search the kind\'s roll and pitch loop too (its stiffness, damping and integral gains, '
                             'nnit2fsmc_controller/search_spaces.py ATTITUDE_SPACES), for a world whose actuator or '
                             'control rate the packaged attitude loops were not made for (docs/PX4.md)')
    args = parser.parse_args(argv)
    from .spec import load_spec
    from .tune import TuneSetup, parse_seeds, tune
    try:
        if args.trials < 1:
            raise ParameterError(f'--trials: {args.trials} is not a whole number >= 1')
        spec = load_spec(args.spec).overridden(flights=args.flights, duration=args.duration,
                                               controllers=[args.controller])
        setup = TuneSetup(args.controller, spec, parse_seeds(args.seeds), args.trials, args.out,
                          _run_options(args), args.sampler_seed, args.objective, args.attitude)
        print(f'tune {setup.kind}: {setup.trials} trials x {len(setup.seeds)} seed(s) {args.seeds} x {spec.flights} '
              f'flights of "{spec.scenario}", {spec.duration:g} s each -> {args.out}', file=sys.stderr)
        outcome = tune(setup, progress=not args.quiet)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'interrupted; run the same command again to continue the study in {args.out} (the interrupted '
              'trial is flown again, its finished flights kept)', file=sys.stderr)
        return 130
    print(f'best: trial {outcome.best_trial}, objective ({setup.objective}) {outcome.best_objective_m * 100:.3f} cm '
          f'(starting gains: {outcome.starting_objective_m * 100:.3f} cm), {outcome.trials} trials')
    for statistic, (trial, value, path, bounds) in outcome.picks.items():
        print(f'pick by {statistic}: trial {trial}, {value * 100:.3f} cm: {path}; at a bound of its range: '
              + (', '.join(f'{name} ({side})' for name, side in bounds) or 'none'))
    print(f'gains: {outcome.gains_path}\ntrials: {outcome.table_path}')
    return 0


def stress_main(argv: list[str]) -> int:
    from .stress import KINDS
    kinds = '; '.join(f'{kind.name}: {kind.intensity}' for kind in KINDS.values())
    parser = argparse.ArgumentParser(prog='run_stack.py stress', description=STRESS_DESCRIPTION.format(kinds=kinds),
                                     epilog=STRESS_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    _campaign_options(parser)
    parser.add_argument('--kind', required=True, choices=tuple(KINDS), help='the disturbance')
    parser.add_argument('--controllers', default=None, help='comma-separated controllers (default: the spec\'s)')
    parser.add_argument('--low', type=float, default=None, help='lowest intensity tried (default: the kind\'s)')
    parser.add_argument('--high', type=float, default=None, help='highest intensity tried (default: the kind\'s)')
    parser.add_argument('--resolution', type=float, default=None,
                        help='stop bisecting when the bracket is this narrow (default: the kind\'s)')
    args = parser.parse_args(argv)
    from .spec import load_spec
    from .stress import StressSetup, describe, highest_intensity, resolution_for, snap, stress
    kind = KINDS[args.kind]
    try:
        spec = load_spec(args.spec).overridden(flights=args.flights, duration=args.duration,
                                               controllers=args.controllers)
        options = _run_options(args)
        resolution = args.resolution if args.resolution is not None else resolution_for(kind, spec, options)
        if not resolution > 0.0:
            raise ParameterError(f'--resolution: {resolution:g} must be > 0')
        low = kind.check('--low', snap(kind.check('--low', kind.low if args.low is None else args.low), resolution))
        high = kind.check('--high', snap(kind.check('--high', kind.high if args.high is None else args.high),
                                         resolution))
        limit = highest_intensity(kind, spec, options, resolution)
        if high > limit:
            if args.high is not None:
                raise ParameterError(f'--high: {high:g} is above what a {kind.name} try can fly ({limit:g}: the '
                                     'rotors cannot hover a heavier vehicle)')
            high = limit
        if not low < high:
            raise ParameterError(f'--low, --high: need low < high on the grid of {resolution:g} '
                                 f'(got {low:g}, {high:g})')
        setup = StressSetup(spec, kind, spec.controllers, args.out, options, low, high, resolution)
        print(f'stress {kind.name} ({kind.intensity}) in [{low:g}, {high:g}] to {resolution:g}: '
              f'{", ".join(spec.controllers)}, {spec.flights} flights of {spec.duration:g} s per try -> {args.out}',
              file=sys.stderr)
        results = stress(setup, progress=not args.quiet)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f'interrupted: the same command reuses every finished campaign in {args.out}', file=sys.stderr)
        return 130
    for controller, point in results.items():
        print(f'{controller:16s} {describe(point, kind)}')
    print(f'breaking points: {args.out / "breaking_points.csv"}')
    return 0
