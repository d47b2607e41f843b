#!/usr/bin/env python3
"""Fly the NNIT2FSMC flight stack: trajectory -> controller -> simulator, then summarise the flight.

Backends:
  embedded  the three cores stepped in lockstep in this process (no ROS needed)
  ros       each ROS 2 node in its own process, over real topics (needs rclpy)
The default (auto) is ros when rclpy can be imported, else embedded.

Examples:
  python3 run_stack.py                                   # the paper's flight, NNIT2FSMC
  python3 run_stack.py --controller smc-sign --no-disturbances --out out/sign
  python3 run_stack.py --backend ros --vehicles 3        # uav1..uav3 on one sim clock, 3 m apart along y

Bag tools (docs/BAGS.md), the same as `ros2 run quad_msgs_bridge review|recover|rosbag2_qos`:
  python3 run_stack.py review out/paper-nnit2fsmc/bag --compare out/sign/bag
  python3 run_stack.py recover BAG                       # finalize the bag of a killed recording
  python3 run_stack.py rosbag2-qos --namespace quad > qos.yaml   # for your own `ros2 bag record
                                                         #   --qos-profile-overrides-path qos.yaml`
"""
from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import tempfile
from pathlib import Path

import flight_stack  # noqa: F401  (puts the three ROS package folders on the path)
from flight_stack.embedded import fly_embedded
from flight_stack.fleet import MAX_VEHICLES, fleet_layout, report_fleet
from flight_stack.ros_backend import RosFlightConfig, fly_ros
from flight_stack.summary import build_summary, format_summary, write_summary
from nnit2fsmc_controller.factory import CONTROLLERS, control_period, load_gains
from nnit2fsmc_controller.trajectory import SCENARIOS, make_scenario
from quad_msgs_bridge.bag.metadata import qos_overrides_main
from quad_msgs_bridge.bag.recover import recover_main
from quad_msgs_bridge.bag.timing import message_timing
from quad_msgs_bridge.contract import RECORDED_TOPICS
from quad_msgs_bridge.bag.flight_bag import FlightBag, select_topics
from quad_msgs_bridge.review.flight_from_bag import read_flight
from quad_msgs_bridge.bag.mcap_file import BagWriteError
from quad_msgs_bridge.review.command import main as review_main, review_bags
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
    parser.add_argument('--namespace', default=None,
                        help='ROS backend: namespace of the vehicle (default quad), or of a fleet\'s vehicles '
                             '(default: the root namespace)')
    parser.add_argument('--vehicles', type=int, default=1, metavar='N',
                        help='ROS backend: fly N vehicles on one sim clock, uav1..uavN, each its own copy of the '
                             'scenario shifted 3 m along y from the previous one')
    parser.add_argument('--mode', choices=('lockstep', 'realtime'), default='lockstep',
                        help='ROS backend: lockstep (deterministic) or realtime simulation')
    parser.add_argument('--speed-factor', type=float, default=1.0, help='ROS backend, realtime: sim s per wall s')
    parser.add_argument('--extra-subscribers', type=int, default=0, metavar='N',
                        help='ROS backend: the simulator also waits for N more odom subscribers before it starts '
                             '(your own `ros2 bag record`, RViz), so they miss nothing of a lockstep flight')
    parser.add_argument('--bag', type=Path, default=None,
                        help='record the flight into this rosbag2 (MCAP) folder (default OUT/bag); '
                             'then review it into OUT (report.html, plots/)')
    parser.add_argument('--no-bag', action='store_true', help='record no bag (and write no report)')
    parser.add_argument('--topics', nargs='+', default=None, metavar='TOPIC',
                        help='contract topics to record (default: all of '
                             + ' '.join(t.name for t in RECORDED_TOPICS) + ')')
    return parser.parse_args(argv)


@contextlib.contextmanager
def stop_signals():
    """SIGINT (Ctrl-C) and SIGTERM, noted rather than raised: yields ``stop()``, true once one came.

    The embedded flight checks it between two control steps, so a signal never lands in the
    middle of a message being added to the bag (a KeyboardInterrupt there once left a message
    counted in the bag's index that was not in its chunk).
    """
    received: list[int] = []
    previous = {number: signal.signal(number, lambda signum, frame: received.append(signum))
                for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield lambda: bool(received)
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def choose_backend(requested: str) -> str:
    if requested != 'auto':
        return requested
    try:
        import rclpy  # noqa: F401
    except ImportError:
        print('backend: embedded (rclpy cannot be imported: source /opt/ros/jazzy/setup.bash for the ROS backend)')
        return 'embedded'
    return 'ros'


def fly_on_ros(args, duration: float, disturbances: bool, physics_rate: float, gains: dict, settle_time: float,
               topics, bag_path: Path):
    """Fly with every node in its own process; ([(namespace, record, summary extras) per vehicle], wall time),
    read from the bag, or an exit code."""
    vehicles = fleet_layout(args.vehicles, args.namespace)
    result = fly_ros(RosFlightConfig(
        vehicles=vehicles, controller=args.controller, scenario=args.scenario, duration=duration,
        disturbances=disturbances, seed=args.seed, physics_rate=physics_rate,
        control_rate=1.0 / control_period(gains), bag=bag_path,
        topics=[t.name for t in topics], mode=args.mode, speed_factor=args.speed_factor,
        extra_odom_subscribers=args.extra_subscribers,
        vehicle_file=args.vehicle, gains_file=args.gains, settle_time=settle_time, quiet=args.quiet))
    if result.failed_node:
        print(f'error: the flight failed: {result.failed_node} (exit codes {result.exit_codes}); '
              f'the bag is closed: {bag_path}', file=sys.stderr)
        return 130 if result.failed_node == 'interrupted' else 1
    flights = []
    try:
        for vehicle in vehicles:
            flight = read_flight(bag_path, namespace=vehicle.namespace, vehicle_file=args.vehicle,
                                 settle_time=settle_time)
            timing = message_timing(bag_path, vehicle.namespace)
            flights.append((vehicle.namespace, flight.record, {
                'offset_m': list(vehicle.offset),
                'ros': {'namespace': vehicle.namespace, 'mode': args.mode,
                        'simulator': result.sim_report.split('] ')[-1], 'timing': timing}}))
    except ValueError as error:
        print(f'error: cannot summarise the flight from {bag_path}: {error}', file=sys.stderr)
        return 1
    return flights, result.wall_time_s


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['review']:
        return review_main(argv[1:])
    if argv[:1] == ['recover']:
        return recover_main(argv[1:])
    if argv[:1] == ['rosbag2-qos']:
        return qos_overrides_main(argv[1:])
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
        check_number('--extra-subscribers', args.extra_subscribers, 0.0, 100.0)
        check_number('--vehicles', args.vehicles, 1.0, MAX_VEHICLES)
        topics = select_topics(args.topics)
        if duration <= settle_time:
            raise ParameterError(f'--duration: {duration:g} s leaves nothing after the settling window '
                                 f'(--settle-time {settle_time:g} s)')
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    backend = choose_backend(args.backend)
    if backend == 'embedded' and args.vehicles > 1:
        print('error: --vehicles: a fleet flies on the ROS backend (--backend ros)', file=sys.stderr)
        return 2
    out_dir = args.out or Path('out') / f'{args.scenario}-{args.controller}'
    bag_path = None if args.no_bag else args.bag or out_dir / 'bag'
    print(f'flying {args.controller} on "{args.scenario}" for {duration:g} s '
          f'(disturbances {"on" if disturbances.enabled else "off"}), {backend} backend'
          + (f', {args.vehicles} vehicles' if args.vehicles > 1 else ''))
    run = dict(backend=backend, controller=args.controller, scenario=args.scenario, seed=args.seed,
               settle_time=settle_time, params=params, disturbances=disturbances, gains=gains,
               physics_rate=physics_rate, max_error=args.max_error)
    extra = {}
    if backend == 'ros':
        with tempfile.TemporaryDirectory(prefix='nnit2fsmc-') as scratch:
            flown = fly_on_ros(args, duration, disturbances.enabled, physics_rate, gains, settle_time, topics,
                               bag_path or Path(scratch) / 'bag')
        if isinstance(flown, int):
            return flown
        flights, wall_time_s = flown
        if len(flights) > 1:
            return report_fleet({name: {**build_summary(record, wall_time_s=wall_time_s, **run), **extra}
                                 for name, record, extra in flights}, out_dir, bag_path)
        [(_, record, extra)] = flights
    else:
        try:
            with stop_signals() as stop:
                recording = (FlightBag.create(bag_path, params, settle_time, topics=topics, overwrite=True,
                                              controller=args.controller, scenario=args.scenario, backend=backend,
                                              seed=args.seed)
                             if bag_path else contextlib.nullcontext())
                with recording as bag:
                    result = fly_embedded(args.controller, trajectory, params, disturbances, gains, duration,
                                          physics_rate, progress=not args.quiet, bag=bag, stop=stop)
        except KeyboardInterrupt:
            print('interrupted' + (f'; bag closed: {bag_path}' if bag_path else ''), file=sys.stderr)
            return 130
        except BagWriteError as error:
            print(f'error: {error}', file=sys.stderr)
            return 1
        record, wall_time_s = result.record, result.wall_time_s
    summary = build_summary(record, wall_time_s=wall_time_s, **run)
    summary.update(extra)
    path = write_summary(summary, out_dir)
    print(format_summary(summary))
    if 'ros' in summary:
        print(f'  ROS: {summary["ros"]["simulator"]}')
        timing = summary['ros'].get('timing', {})
        if 'latency_median_ms' in timing:
            print(f'  ROS: odometry at {timing["odometry_rate_hz"]:.1f} Hz, odom->forces latency median '
                  f'{timing["latency_median_ms"]:.3f} ms, p99 {timing["latency_p99_ms"]:.3f} ms')
    print(f'summary: {path}')
    if bag_path:
        print(f'bag: {bag_path}')
        try:
            review = review_bags([bag_path], out_dir)
        except ValueError as error:   # e.g. --topics left out what the metrics need
            print(f'review skipped: {error}')
        else:
            for note in review.notes:
                print(f'note: {note}')
            print(f'report: {review.report}')
    return 0 if summary['flight_ok'] else 1


if __name__ == '__main__':
    sys.exit(main())
