#!/usr/bin/env python3
"""Fly the NNIT2FSMC flight stack: trajectory -> controller -> simulator, then summarise the flight.

Backends:
  embedded  the three cores stepped in lockstep in this process (no ROS needed)
  ros       each ROS 2 node in its own process, over real topics (needs rclpy)
The default (auto) is ros when rclpy can be imported, else embedded.

Examples:
  python3 run_stack.py                                   # the paper's flight, NNIT2FSMC
  python3 run_stack.py --controller smc-sign --no-disturbances --out out/sign

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
from flight_stack.ros_backend import RosFlightConfig, fly_ros
from flight_stack.summary import build_summary, format_summary, write_summary
from nnit2fsmc_controller.factory import CONTROLLERS, control_period, load_gains
from nnit2fsmc_controller.trajectory import SCENARIOS, make_scenario
from quad_msgs_bridge.bag.metadata import qos_overrides_main
from quad_msgs_bridge.bag.recover import recover_main
from quad_msgs_bridge.bag.timing import message_timing
from quad_msgs_bridge.contract import DEFAULT_NAMESPACE, RECORDED_TOPICS
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
    parser.add_argument('--namespace', default=DEFAULT_NAMESPACE, help='ROS backend: namespace of the vehicle')
    parser.add_argument('--mode', choices=('lockstep', 'realtime'), default='lockstep',
                        help='ROS backend: lockstep (deterministic) or realtime simulation')
    parser.add_argument('--speed-factor', type=float, default=None,
                        help='sim s per wall s (default 1: real time) of the ROS backend\'s realtime mode and of '
                             'the --live view; with --live 0 flies as fast as it can')
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
    live = parser.add_argument_group('live view (embedded backend; see the README, "Live view")')
    live.add_argument('--live', action='store_true',
                      help='serve the flight to Foxglove as it flies (Foxglove WebSocket protocol), paced at '
                           '--speed-factor')
    live.add_argument('--live-host', default='127.0.0.1',
                      help='address the live view listens on (default %(default)s: this machine only)')
    live.add_argument('--live-port', type=int, default=8765,
                      help='port of the live view (default %(default)s; 0: any free port)')
    live.add_argument('--live-wait', action='store_true',
                      help='start flying once a client has subscribed to a topic (so that it misses nothing)')
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


def choose_backend(requested: str, live: bool) -> str:
    if requested != 'auto':
        return requested
    if live:
        return 'embedded'
    try:
        import rclpy  # noqa: F401
    except ImportError:
        print('backend: embedded (rclpy cannot be imported: source /opt/ros/jazzy/setup.bash for the ROS backend)')
        return 'embedded'
    return 'ros'


def check_live_options(args, backend: str) -> float:
    """The speed factor of an embedded flight (0: as fast as it can), after checking the live-view options."""
    if backend == 'ros':
        if args.live:
            raise ParameterError('--live serves the embedded flight; for the ROS backend use Foxglove\'s ROS 2 '
                                 'bridge (sudo apt install ros-jazzy-foxglove-bridge; ros2 launch foxglove_bridge '
                                 'foxglove_bridge_launch.xml), or add --backend embedded')
        return 0.0
    if not args.live:
        if args.live_wait:
            raise ParameterError('--live-wait: waits for a client of the live view; add --live')
        if args.speed_factor is not None:
            raise ParameterError('--speed-factor: the embedded flight is paced only with --live (without it, it '
                                 'flies as fast as it can)')
        return 0.0
    check_number('--live-port', args.live_port, 0, 65535)
    return check_number('--speed-factor', 1.0 if args.speed_factor is None else args.speed_factor, 0.0, 1000.0)


def start_live_server(host: str, port: int):
    """The live view's server, or an exit code after saying why it cannot be served."""
    try:
        from flight_stack.live_view import LiveServer, LiveViewError, is_loopback
    except ImportError as error:   # foxglove-sdk is in requirements.txt, not in the ROS path's requirements
        print(f'error: --live needs the foxglove-sdk package ({error}): pip install -r requirements.txt',
              file=sys.stderr)
        return 2
    try:
        server = LiveServer(host, port)
    except LiveViewError as error:
        print(f'error: {error} (--live-host, --live-port)', file=sys.stderr)
        return 2
    print(f'live view: {server.url} (Foxglove: Open connection -> Foxglove WebSocket -> {server.url})', flush=True)
    if not is_loopback(host):
        print(f'warning: the live view listens on {host}: anyone who can reach this address can watch the flight '
              f'(there is no authentication)', flush=True)
    return server


def live_sinks(server, params, topics, speed_factor: float) -> list:
    """The step sinks of a live flight: a pacer (unless as fast as possible), then the live view."""
    from flight_stack.live_view import LiveView
    from flight_stack.pacing import Pacer
    return ([Pacer(speed_factor)] if speed_factor > 0.0 else []) + [LiveView(server, params, topics=topics)]


def fly_on_ros(args, trajectory, duration: float, disturbances: bool, physics_rate: float, gains: dict,
               settle_time: float, topics, bag_path: Path):
    """Fly with every node in its own process; (record, wall time, summary extras) read from the bag, or an exit code."""
    result = fly_ros(RosFlightConfig(
        namespace=args.namespace, controller=args.controller, scenario=args.scenario, duration=duration,
        disturbances=disturbances, seed=args.seed, physics_rate=physics_rate,
        control_rate=1.0 / control_period(gains), initial_state=trajectory.initial_state, bag=bag_path,
        topics=[t.name for t in topics], mode=args.mode,
        speed_factor=1.0 if args.speed_factor is None else args.speed_factor,
        extra_odom_subscribers=args.extra_subscribers,
        vehicle_file=args.vehicle, gains_file=args.gains, settle_time=settle_time, quiet=args.quiet))
    if result.failed_node:
        print(f'error: the flight failed: {result.failed_node} (exit codes {result.exit_codes}); '
              f'the bag is closed: {bag_path}', file=sys.stderr)
        return 130 if result.failed_node == 'interrupted' else 1
    try:
        flight = read_flight(bag_path, namespace=args.namespace, vehicle_file=args.vehicle, settle_time=settle_time)
        timing = message_timing(bag_path, args.namespace)
    except ValueError as error:
        print(f'error: cannot summarise the flight from {bag_path}: {error}', file=sys.stderr)
        return 1
    return flight.record, result.wall_time_s, {'ros': {'namespace': args.namespace, 'mode': args.mode,
                                                       'simulator': result.sim_report.split('] ')[-1],
                                                       'timing': timing}}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['review']:
        return review_main(argv[1:])
    if argv[:1] == ['recover']:
        return recover_main(argv[1:])
    if argv[:1] == ['rosbag2-qos']:
        return qos_overrides_main(argv[1:])
    if argv[:1] == ['campaign']:
        from flight_stack.campaign.cli import main as campaign_main
        return campaign_main(argv[1:])
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
        topics = select_topics(args.topics)
        if duration <= settle_time:
            raise ParameterError(f'--duration: {duration:g} s leaves nothing after the settling window '
                                 f'(--settle-time {settle_time:g} s)')
        backend = choose_backend(args.backend, args.live)
        speed_factor = check_live_options(args, backend)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    live_server = start_live_server(args.live_host, args.live_port) if args.live else None
    if isinstance(live_server, int):
        return live_server
    out_dir = args.out or Path('out') / f'{args.scenario}-{args.controller}'
    bag_path = None if args.no_bag else args.bag or out_dir / 'bag'
    print(f'flying {args.controller} on "{args.scenario}" for {duration:g} s '
          f'(disturbances {"on" if disturbances.enabled else "off"}), {backend} backend')
    extra = {}
    if backend == 'ros':
        with tempfile.TemporaryDirectory(prefix='nnit2fsmc-') as scratch:
            flown = fly_on_ros(args, trajectory, duration, disturbances.enabled, physics_rate, gains,
                               settle_time, topics, bag_path or Path(scratch) / 'bag')
        if isinstance(flown, int):
            return flown
        record, wall_time_s, extra = flown
    else:
        try:
            with stop_signals() as stop, live_server or contextlib.nullcontext():
                sinks = live_sinks(live_server, params, topics, speed_factor) if live_server else []
                if live_server and args.live_wait:
                    print('live view: waiting for a client to subscribe (Ctrl-C to stop)', flush=True)
                    if not live_server.wait_for_subscriber(stop):
                        print('interrupted before the flight', file=sys.stderr)
                        return 130
                recording = (FlightBag.create(bag_path, params, settle_time, topics=topics, overwrite=True,
                                              controller=args.controller, scenario=args.scenario, backend=backend,
                                              seed=args.seed)
                             if bag_path else contextlib.nullcontext())
                with recording as bag:
                    result = fly_embedded(args.controller, trajectory, params, disturbances, gains, duration,
                                          physics_rate, progress=not args.quiet, bag=bag, stop=stop, sinks=sinks)
                    for sink in sinks:
                        sink.close()
        except KeyboardInterrupt:
            print('interrupted' + (f'; bag closed: {bag_path}' if bag_path else ''), file=sys.stderr)
            return 130
        except BagWriteError as error:
            print(f'error: {error}', file=sys.stderr)
            return 1
        record, wall_time_s = result.record, result.wall_time_s
    summary = build_summary(record, backend=backend, controller=args.controller, scenario=args.scenario,
                            seed=args.seed, settle_time=settle_time, params=params, disturbances=disturbances,
                            gains=gains, physics_rate=physics_rate, wall_time_s=wall_time_s,
                            max_error=args.max_error)
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
