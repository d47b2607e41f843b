"""Fly the NNIT2FSMC flight stack: trajectory -> controller -> simulator, then summarise the flight.

Backends:
  embedded  the three cores stepped in lockstep in this process (no ROS needed)
  ros       each ROS 2 node in its own process, over real topics (needs rclpy)
The default (auto) is ros when rclpy can be imported, else embedded.

Every setting is checked before anything is flown or written. A run writes into a folder beside
OUT (OUT.incomplete-XXXXXXXX) and moves into OUT only once it is complete, so an interrupted or
broken run never touches an earlier result (what it wrote stays in that folder); an earlier run in
OUT is replaced only with --overwrite. A flight that fails its checks (result FAILED, exit 1) is a
complete run: its summary, bag and report are kept in OUT.

Examples:
  python3 run_stack.py                                   # the paper's flight, NNIT2FSMC
  python3 run_stack.py --controller smc-sign --out out/sign   # same disturbances, to compare
  python3 run_stack.py --backend ros --vehicles 3        # uav1..uav3 on one sim clock, 3 m apart along y

Subcommands (each has its own --help): campaign, tune, stress, study (the studies behind the docs' tables),
list (what can be named), and the bag tools review, recover, export, rosbag2-qos (below).
  python3 run_stack.py campaign SPEC.yaml --out DIR      # a robustness campaign (docs/CAMPAIGNS.md);
                                                         #   the shipped specs: run_stack.py campaign --list
  python3 run_stack.py tune SPEC.yaml --controller pid --trials 40 --flights 100 --out DIR   # docs/TUNING.md
  python3 run_stack.py stress SPEC.yaml --kind wind --controllers nnit2fsmc,pid --out DIR   # breaking points

From a clone, python3 runs the stack with the clone's .venv (bash scripts/fly.sh makes it).
Limits: --vehicles at most 20; --seed 0 to 2^31 - 1; --physics-rate a whole multiple of the
control rate; --speed-factor at most 1000; --extra-subscribers at most 100; --duration > 0.

Bag tools (docs/BAGS.md), the same as `ros2 run quad_msgs_bridge review|recover|rosbag2_qos`:
  python3 run_stack.py review out/paper-nnit2fsmc/bag --compare out/sign/bag
  python3 run_stack.py recover BAG                       # finalize the bag of a killed recording
  python3 run_stack.py export BAG --format csv --out flight.csv  # one row per step, columns with units
  python3 run_stack.py rosbag2-qos --namespace quad > qos.yaml   # for your own `ros2 bag record
                                                         #   --qos-profile-overrides-path qos.yaml`
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from flight_stack.interrupts import deferred, stop_signals
from flight_stack.runs import (Flown, FlightStopped, Launch, fly_fleet_here, fly_here, fly_on_ros, review_now,
                               summarize)

#: third-party modules the stack imports -> the distribution that provides them
DEPENDENCIES = {'numpy': 'numpy', 'numba': 'numba', 'yaml': 'PyYAML', 'rosbags': 'rosbags', 'mcap': 'mcap', 'zstandard': 'zstandard',
                'matplotlib': 'matplotlib'}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    from nnit2fsmc_controller.factory import CONTROLLERS
    from nnit2fsmc_controller.trajectory import SCENARIOS
    from flight_stack import __version__
    from quad_msgs_bridge.contract import RECORDED_TOPICS
    from quad_msgs_bridge.output_path import output_path
    from flight_stack.fleet import MAX_VEHICLES
    from quad_sim.plants import DEFAULT_PLANT, PLANTS

    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('--backend', choices=('auto', 'ros', 'embedded'), default='auto')
    parser.add_argument('--controller', default=None, metavar='KIND',
                        help='the control law: a built-in kind (' + ', '.join(CONTROLLERS) + '), an installed '
                             'controller\'s entry point, or module:Class (docs/CONTROLLERS.md; run_stack.py list '
                             'controllers). Default: the --gains file\'s controller: key, else nnit2fsmc')
    parser.add_argument('--scenario', choices=tuple(SCENARIOS), default='paper')
    parser.add_argument('--duration', type=float, default=None,
                        help='sim time to fly [s] (default: the scenario\'s length)')
    parser.add_argument('--disturbances', action=argparse.BooleanOptionalAction, default=None,
                        help='paper section IV disturbances (default: as in the vehicle file, on)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the NN initial weights, 0 to 2^31 - 1')
    parser.add_argument('--out', type=output_path, default=None,
                        help='output folder (default out/<scenario>-<controller>); see above for what a run leaves')
    parser.add_argument('--overwrite', action='store_true',
                        help='replace an earlier run in --out (its summary, bag, report, plots; other files stay) '
                             'and an existing --bag')
    parser.add_argument('--vehicle', type=Path, default=None,
                        help='vehicle YAML, or a shipped vehicle by name: paper (the default), crazyflie, hummingbird, x500')
    parser.add_argument('--gains', type=Path, default=None,
                        help='controller gains YAML, whole or only the gains it changes (merged over the packaged '
                             'set, or over the set its base: key names), or a named set: packaged (the default), '
                             'untuned, paper-faithful')
    parser.add_argument('--set', dest='gain_settings', action='append', default=[], metavar='KEY=VALUE',
                        help='change one gain, KEY dotted as the gains file nests it (e.g. --set pid.axes.x.kp=30); '
                             'repeatable; applied over --gains')
    parser.add_argument('--plant', choices=PLANTS, default=DEFAULT_PLANT,
                        help='what the simulator flies: our model of eq. (1), or RotorPy (docs/ROTORPY.md)')
    parser.add_argument('--px4-dir', type=Path, default=None,
                        help='--plant px4-sitl: the PX4-Autopilot folder holding build/px4_sitl_default (default: env '
                             'PX4_DIR; docs/PX4.md)')
    parser.add_argument('--xrce-agent', type=Path, default=None,
                        help='--plant px4-sitl: the Micro XRCE-DDS Agent executable (default: MicroXRCEAgent on PATH)')
    parser.add_argument('--px4-takeoff', choices=('px4', 'controller'), default=None,
                        help='--plant px4-sitl: who takes off: px4 (the default: PX4\'s position controller takes the '
                             'vehicle to the reference\'s first point, raised to 2.5 m above the ground, and the '
                             'controller flies the scenario from there) or controller (ours, from the ground; '
                             'docs/PX4.md, "Take-off")')
    parser.add_argument('--physics-rate', type=float, default=1000.0, help='RK4 rate [Hz], a multiple of the control rate')
    parser.add_argument('--settle-time', type=float, default=None,
                        help='metrics ignore the first S seconds (default: 5, or half of a flight shorter than 10 s)')
    parser.add_argument('--max-error', type=float, default=1.0,
                        help='the flight fails if the position error after settling exceeds this [m] (> 0)')
    parser.add_argument('--quiet', action='store_true', help='no progress lines')
    parser.add_argument('--namespace', default=None,
                        help='ROS backend: namespace of the vehicle (default quad), or of a fleet\'s vehicles '
                             '(default: the root namespace)')
    parser.add_argument('--vehicles', type=int, default=1, metavar='N',
                        help='fly N vehicles (at most %d) on one sim clock, uav1..uavN, each its own copy of the scenario '
                             'shifted 3 m along y from the previous one (ROS: one simulator, a controller and a '
                             'trajectory node per vehicle; embedded: the fleet stepped as one batch)' % MAX_VEHICLES)
    parser.add_argument('--mode', choices=('lockstep', 'realtime'), default=None,
                        help='ROS backend: lockstep (deterministic, the default) or realtime simulation')
    parser.add_argument('--speed-factor', type=float, default=None,
                        help='sim s per wall s (default 1: real time) of the ROS backend\'s realtime mode and of '
                             'the --live view; with --live 0 flies as fast as it can')
    parser.add_argument('--extra-subscribers', type=int, default=0, metavar='N',
                        help='ROS backend: the simulator also waits for N more odom subscribers before it starts '
                             '(your own `ros2 bag record`, RViz), so they miss nothing of a lockstep flight')
    parser.add_argument('--record-by', choices=('recorder', 'publishers'), default=None,
                        help='ROS backend: who writes the bag: each node logging what it publishes, merged into '
                             'the bag after the flight (the default), or the record node (one more DDS reader of '
                             'every topic: a lockstep step about 35 %% slower; docs/BAGS.md)')
    parser.add_argument('--bag', type=output_path, default=None,
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


def folder_name(kind: str) -> str:
    """``kind`` as a folder name: a module:Class kind's ':' and other characters a path should not hold become '_'."""
    import re
    return re.sub(r'[^\w.-]', '_', kind)


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


def check_count(option: str, value: int, low: int, high: int) -> int:
    """``value`` if it is a whole number in [low, high], else a ParameterError naming ``option`` and the range."""
    from quad_msgs_bridge.validation import ParameterError
    if not low <= value <= high:
        raise ParameterError(f'{option}: {value} is outside the valid range {low} to {high} (a whole number)')
    return value


def check_backend_options(args, backend: str) -> None:
    """The ROS backend can be started (rclpy imports), and no option of the other backend is given: each
    refused with a ParameterError naming it, before anything starts. Sets the ROS options' defaults."""
    from quad_msgs_bridge.validation import ParameterError
    if backend == 'ros':
        try:
            import rclpy  # noqa: F401
        except ImportError as error:
            raise ParameterError(f'--backend ros: rclpy cannot be imported ({error}); source '
                                 '/opt/ros/jazzy/setup.bash first, or fly with --backend embedded') from None
        args.mode = args.mode or 'lockstep'
        args.record_by = args.record_by or 'publishers'
        return
    ros_only = [(option, value) for option, value in (('--mode', args.mode), ('--record-by', args.record_by),
                                                      ('--extra-subscribers', args.extra_subscribers or None))
                if value is not None]
    if ros_only:
        option, value = ros_only[0]
        raise ParameterError(f'{option} {value}: an option of the ROS backend, which the embedded backend would '
                             'ignore; fly with --backend ros, or leave it out')


#: [Hz] the controller rate on PX4 SITL: our controllers answer each odometry, which PX4 1.15 sends at 100 Hz
#: (EKF2_PREDICT_US 10 ms; docs/PX4.md "Rates"); common.control_rate is set to it unless --set names it
PX4_CONTROL_RATE = 100.0


def check_px4_options(args):
    """For --plant px4-sitl: PX4, the Agent and px4_msgs found (flight_stack.px4_sitl.find_px4: one line naming what
    is missing) and the options it flies with checked and set (ROS backend, realtime, publication logs, one
    vehicle, no simulated disturbances, the controller at PX4's odometry rate); None for another plant."""
    from quad_msgs_bridge.validation import ParameterError
    from quad_sim.plants import PX4_SITL
    if args.plant != PX4_SITL:
        for option, value in (('--px4-dir', args.px4_dir), ('--xrce-agent', args.xrce_agent),
                              ('--px4-takeoff', args.px4_takeoff)):
            if value is not None:
                raise ParameterError(f'{option}: an option of --plant {PX4_SITL}')
        return None
    from flight_stack.px4_sitl import find_px4
    install = find_px4(args.px4_dir, args.xrce_agent)
    refused = [(args.backend == 'embedded', '--backend embedded: PX4 SITL is flown over ROS 2 (--backend ros)'),
               (args.mode == 'lockstep', '--mode lockstep: PX4 SITL runs in real time (--mode realtime)'),
               (args.record_by == 'recorder', '--record-by recorder: a PX4 flight is recorded by its publishers'),
               (args.vehicles != 1, '--vehicles: one PX4 SITL flies one vehicle'),
               (args.live, '--live: the live view serves the embedded flight'),
               (args.disturbances, '--disturbances: SIH cannot apply the paper\'s disturbances (PX4 flies its own '
                                   'plant as it is)'),
               (args.speed_factor not in (None, 1.0), '--speed-factor: PX4 SITL runs at 1x real time here')]
    for bad, why in refused:
        if bad:
            raise ParameterError(f'--plant {PX4_SITL}: {why}')
    args.backend, args.mode, args.record_by, args.disturbances = 'ros', 'realtime', 'publishers', False
    if not any(setting.startswith('common.control_rate=') for setting in args.gain_settings):
        args.gain_settings = [*args.gain_settings, f'common.control_rate={PX4_CONTROL_RATE:g}']
    return install


def check_live_options(args, backend: str) -> float:
    """The speed factor of an embedded flight (0: as fast as it can), after checking the live-view options."""
    from quad_msgs_bridge.validation import ParameterError, check_number
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
    check_count('--live-port', args.live_port, 0, 65535)
    return check_number('--speed-factor', 1.0 if args.speed_factor is None else args.speed_factor, 0.0, 1000.0)


def start_live_view(host: str, port: int, params, topics):
    """The live view of the flight (its ``server`` listening), or an exit code after saying why it cannot be served."""
    try:
        from flight_stack.live_view import LiveViewError, is_loopback, serve_live_view
    except ImportError as error:   # foxglove-sdk is in requirements.txt, not in the ROS path's requirements
        print(f'error: --live needs the foxglove-sdk package ({error}): pip install -r requirements.txt',
              file=sys.stderr)
        return 2
    try:
        view = serve_live_view(host, port, params, topics)
    except LiveViewError as error:
        print(f'error: {error} (--live-host, --live-port)', file=sys.stderr)
        return 2
    server = view.server
    print(f'live view: {server.url} (Foxglove: Open connection -> Foxglove WebSocket -> {server.url})', flush=True)
    if not is_loopback(host):
        print(f'warning: the live view listens on {host}: anyone who can reach this address can watch the flight '
              f'(there is no authentication)', flush=True)
    return view


def print_ros_lines(summary: dict) -> None:
    if 'ros' not in summary:
        return
    print(f'  ROS: {summary["ros"]["simulator"]}')
    timing = summary['ros'].get('timing', {})
    if 'latency_median_ms' in timing:
        print(f'  ROS: odometry at {timing["odometry_rate_hz"]:.1f} Hz, odom->forces latency median '
              f'{timing["latency_median_ms"]:.3f} ms, p99 {timing["latency_p99_ms"]:.3f} ms')


def main(argv: list[str] | None = None) -> int:
    """``run_stack.py`` (and the ``nnit2fsmc-stack`` command): a flight, or a bag tool; the exit status."""
    try:
        with stop_signals():
            code = run(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        code = 130
    except ModuleNotFoundError as error:
        top = (error.name or '').split('.')[0]
        if top not in DEPENDENCIES:
            raise
        print(f'error: the Python package {DEPENDENCIES[top]} (module {top}) is not installed for {sys.executable}.\n'
              '  From a clone, run the stack in its virtual environment: bash scripts/fly.sh [OPTIONS] (creates\n'
              '  .venv), or .venv/bin/python run_stack.py [OPTIONS] once `bash scripts/setup_venv.sh .venv\n'
              '  requirements.txt` made it; or install the stack: pip install .', file=sys.stderr)
        return 2
    if code == 130 and argv is None:   # the command was stopped: everything it wrote is closed by now, so end
        sys.stdout.flush()             # the process at once (the interpreter's own teardown of numba and
        sys.stderr.flush()             # matplotlib takes about a second more)
        os._exit(130)
    return code


def run(argv: list[str]) -> int:
    if argv[:1] == ['review']:
        from quad_msgs_bridge.review.command import main as review_main
        return review_main(argv[1:])
    if argv[:1] == ['recover']:
        from quad_msgs_bridge.bag.recover import recover_main
        return recover_main(argv[1:])
    if argv[:1] == ['rosbag2-qos']:
        from quad_msgs_bridge.bag.metadata import qos_overrides_main
        return qos_overrides_main(argv[1:])
    if argv[:1] == ['campaign']:
        from flight_stack.campaign.cli import main as campaign_main
        return campaign_main(argv[1:])
    if argv[:1] in (['tune'], ['stress']):
        from flight_stack.campaign import study_cli
        return (study_cli.tune_main if argv[0] == 'tune' else study_cli.stress_main)(argv[1:])
    if argv[:1] == ['export']:
        from flight_stack.export import main as export_main
        return export_main(argv[1:])
    if argv[:1] == ['list']:
        from flight_stack.listing import main as list_main
        return list_main(argv[1:])
    if argv[:1] == ['study']:
        from flight_stack.studies.cli import main as study_main
        return study_main(argv[1:])
    args = parse_args(argv)
    if not args.quiet:
        print('planning the flight', flush=True)
    from flight_stack.fleet import MAX_VEHICLES
    from flight_stack.output import RunOutput
    from flight_stack.plan import plan_flight
    from nnit2fsmc_controller.factory import choose_controller
    from quad_msgs_bridge.validation import ParameterError, check_number
    try:
        args.controller = choose_controller(args.controller, args.gains)
        px4 = check_px4_options(args)
        plan = plan_flight(args.controller, args.scenario, duration=args.duration, disturbances=args.disturbances,
                           seed=args.seed, vehicle_file=args.vehicle, gains_file=args.gains,
                           physics_rate=args.physics_rate, settle_time=args.settle_time, max_error=args.max_error,
                           topics=args.topics, plant=args.plant, gain_settings=args.gain_settings)
        check_count('--extra-subscribers', args.extra_subscribers, 0, 100)
        check_count('--vehicles', args.vehicles, 1, MAX_VEHICLES)
        backend = choose_backend(args.backend, args.live)
        if args.live and args.vehicles > 1:
            raise ParameterError('--live: the live view shows one vehicle; fly a fleet without --live')
        speed_factor = check_live_options(args, backend)
        check_backend_options(args, backend)
        if px4 is not None:
            args.px4 = px4
        if backend == 'ros':
            args.speed_factor = check_number('--speed-factor', 1.0 if args.speed_factor is None else args.speed_factor,
                                             0.0, low_inclusive=False)
        out_dir = args.out or Path('out') / f'{args.scenario}-{folder_name(args.controller)}'
        bag_shown = None if args.no_bag else args.bag or out_dir / 'bag'
        output = RunOutput(out_dir, bag_shown, args.overwrite)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    live_view = start_live_view(args.live_host, args.live_port, plan.params, plan.topics) if args.live else None
    if isinstance(live_view, int):
        return live_view
    try:
        output.create()
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    if output.leftovers:
        print(f'note: earlier runs into {output.out_dir} that did not finish left '
              + ', '.join(str(folder) for folder in output.leftovers)
              + ' (a bag there can be reviewed or recovered; remove them when no longer needed)', file=sys.stderr)
    print(f'flying {plan.controller} on "{plan.scenario}" for {plan.duration:g} s, vehicle {plan.vehicle_name} '
          f'(disturbances {"on" if plan.disturbances.enabled else "off"}), {backend} backend'
          + (f', {args.vehicles} vehicles' if args.vehicles > 1 else '')
          + (f', plant {plan.plant}' if plan.plant != 'quad_sim' else ''))
    try:
        return fly_and_report(args, plan, backend, output, bag_shown, live_view, speed_factor)
    except BaseException:
        output.keep_partial()
        raise


def launch_of(args: argparse.Namespace) -> Launch:
    """The backend options of the command line."""
    return Launch(vehicles=args.vehicles, namespace=args.namespace, quiet=args.quiet, mode=args.mode,
                  speed_factor=args.speed_factor, extra_subscribers=args.extra_subscribers, record_by=args.record_by,
                  vehicle_file=args.vehicle, px4=getattr(args, 'px4', None), px4_takeoff=args.px4_takeoff or 'px4')


def unfinished(output, message: str, code: int) -> int:
    """A run that did not finish: say why; what it wrote stays in its staging folder, OUT is unchanged."""
    kept = output.keep_partial()
    print(message + ''.join(f'\nthe unfinished run stays in {folder}' for folder in kept)
          + f'\n{output.out_dir} is unchanged', file=sys.stderr)
    return code


def fly_and_report(args, plan, backend: str, output, bag_shown: Path | None, live_view=None,
                   speed_factor: float = 0.0) -> int:
    """Fly, write summary and review into the staged output, then move it into place."""
    from flight_stack.summary import format_summary, write_summary
    from quad_msgs_bridge.bag.mcap_file import BagWriteError

    try:
        if backend == 'ros':
            with tempfile.TemporaryDirectory(prefix='nnit2fsmc-') as scratch:   # --no-bag: the bag is read, then goes
                flights = fly_on_ros(launch_of(args), plan, output.bag or Path(scratch) / 'bag', bag_shown)
        elif args.vehicles > 1:
            flights = fly_fleet_here(launch_of(args), plan, output.bag, bag_shown)
        else:
            flights = [(None, fly_here(plan, output.bag, bag_shown, not args.quiet, live_view, speed_factor,
                                       args.live_wait, args.namespace))]
    except KeyboardInterrupt:
        return unfinished(output, 'interrupted' + (f'; bag closed: {output.bag}' if output.bag else ''), 130)
    except FlightStopped as stopped:
        return unfinished(output, f'error: {stopped}', stopped.code)
    except BagWriteError as error:
        return unfinished(output, f'error: {error}', 1)
    if len(flights) > 1:
        return report_fleet(flights, plan, backend, output, bag_shown)
    [(_, flown)] = flights
    try:
        summary = summarize(flown, plan, backend)
        write_summary(summary, output.out)
        if flown.flight is not None and not args.quiet:
            print('reviewing the flight (report and plots)', file=sys.stderr, flush=True)
        review_lines, report = review_now(flown, plan, output.out) if flown.flight is not None else ([], None)
        with deferred():
            output.commit()
    except KeyboardInterrupt:
        return unfinished(output, 'interrupted' + (f' after the flight; bag closed: {output.bag}' if output.bag else ''),
                          130)
    print(format_summary(summary))
    print_ros_lines(summary)
    print(f'summary: {output.out_dir / "summary.json"}')
    if bag_shown:
        print(f'bag: {bag_shown}')
    for line in review_lines:
        print(line)
    if report:
        print(f'report: {output.out_dir / report}')
    return 0 if summary['flight_ok'] else 1


def report_fleet(flights: list[tuple[str, Flown]], plan, backend: str, output, bag_shown: Path | None) -> int:
    """A fleet's summary (one row per vehicle, summary.json ``vehicles.<name>``) and review (a column per
    vehicle, every path in one 3-D figure), moved into place; the exit status."""
    from flight_stack.fleet import fleet_summary, format_fleet_summary
    from flight_stack.summary import write_summary
    from quad_msgs_bridge.review.command import review_flights

    fleet = fleet_summary({name: summarize(flown, plan, backend) for name, flown in flights})
    write_summary(fleet, output.out)
    reviewed = [flown.flight for _, flown in flights if flown.flight is not None]
    for flight, (name, _) in zip(reviewed, flights):
        flight.label = name
    review = review_flights(reviewed, output.out) if len(reviewed) == len(flights) else None
    output.commit()
    print(format_fleet_summary(fleet))
    print(f'summary: {output.out_dir / "summary.json"}')
    if bag_shown:
        print(f'bag: {bag_shown} (every vehicle; `run_stack.py review BAG` reviews them all, '
              f'--namespace {flights[0][0]} one)')
    if review is not None:
        for note in review.notes:
            print(f'note: {note}')
        print(f'report: {output.out_dir / review.report.name}')
    return 0 if fleet['flight_ok'] else 1
