#!/usr/bin/env python3
"""Fly the NNIT2FSMC flight stack: trajectory -> controller -> simulator, then summarise the flight.

Backends:
  embedded  the three cores stepped in lockstep in this process (no ROS needed)
  ros       each ROS 2 node in its own process, over real topics (needs rclpy)
The default (auto) is ros when rclpy can be imported, else embedded.

Examples:
  python3 run_stack.py                                   # the paper's flight, NNIT2FSMC
  python3 run_stack.py --controller smc-sign --no-disturbances --out out/sign
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import flight_stack  # noqa: F401  (puts the three ROS package folders on the path)
from flight_stack.embedded import fly_embedded
from flight_stack.summary import build_summary, format_summary, write_summary
from nnit2fsmc_controller.factory import CONTROLLERS, load_gains
from nnit2fsmc_controller.trajectory import SCENARIOS, make_scenario
from quad_msgs_bridge.vehicle_params import ParameterError, check_number, load_vehicle_file


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--backend', choices=('auto', 'ros', 'embedded'), default='auto')
    parser.add_argument('--controller', choices=CONTROLLERS, default='nnit2fsmc')
    parser.add_argument('--scenario', choices=tuple(SCENARIOS), default='paper')
    parser.add_argument('--duration', type=float, default=None,
                        help='sim time to fly [s] (default: the scenario\'s length)')
    parser.add_argument('--disturbances', action=argparse.BooleanOptionalAction, default=None,
                        help='paper section IV disturbances (default: as in the vehicle file, on)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the NN initial weights')
    parser.add_argument('--out', type=Path, default=None, help='output folder (default out/<scenario>-<controller>)')
    parser.add_argument('--vehicle', type=Path, default=None, help='vehicle YAML (default: the packaged one)')
    parser.add_argument('--gains', type=Path, default=None, help='controller gains YAML (default: the packaged one)')
    parser.add_argument('--physics-rate', type=float, default=1000.0, help='RK4 rate [Hz], a multiple of the control rate')
    parser.add_argument('--settle-time', type=float, default=5.0, help='metrics ignore the first S seconds')
    parser.add_argument('--max-error', type=float, default=1.0,
                        help='the flight fails if the position error after settling exceeds this [m]')
    parser.add_argument('--quiet', action='store_true', help='no progress lines')
    return parser.parse_args(argv)


def choose_backend(requested: str) -> str:
    if requested != 'auto':
        return requested
    try:
        import rclpy  # noqa: F401
    except ImportError:
        print('backend: embedded (rclpy cannot be imported: source /opt/ros/jazzy/setup.bash for the ROS backend)')
        return 'embedded'
    return 'ros'


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        params, disturbances = load_vehicle_file(args.vehicle)
        if args.disturbances is not None:
            disturbances = disturbances.switched(args.disturbances)
        gains = load_gains(args.gains)
        gains.setdefault('nnit2fsmc', {})['seed'] = args.seed
        trajectory = make_scenario(args.scenario, args.duration)
        duration = trajectory.duration if args.duration is None else args.duration
        physics_rate = check_number('--physics-rate', args.physics_rate, 0.0, low_inclusive=False)
        settle_time = check_number('--settle-time', args.settle_time, 0.0)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    backend = choose_backend(args.backend)
    out_dir = args.out or Path('out') / f'{args.scenario}-{args.controller}'
    if backend == 'ros':
        print('error: the ROS backend is not available in this build yet; use --backend embedded', file=sys.stderr)
        return 2
    print(f'flying {args.controller} on "{args.scenario}" for {duration:g} s '
          f'(disturbances {"on" if disturbances.enabled else "off"}), embedded backend')
    result = fly_embedded(args.controller, trajectory, params, disturbances, gains, duration, physics_rate,
                          progress=not args.quiet)
    summary = build_summary(result.record, backend=backend, controller=args.controller, scenario=args.scenario,
                            seed=args.seed, settle_time=settle_time, params=params, disturbances=disturbances,
                            gains=gains, physics_rate=physics_rate, wall_time_s=result.wall_time_s,
                            max_error=args.max_error)
    path = write_summary(summary, out_dir)
    print(format_summary(summary))
    print(f'summary: {path}')
    return 0 if summary['flight_ok'] else 1


if __name__ == '__main__':
    sys.exit(main())
