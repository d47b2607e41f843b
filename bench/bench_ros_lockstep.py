#!/usr/bin/env python3
"""Lockstep rate of the ROS stack (every node its own process) next to a bare rclpy ping-pong, for fleets.

Prints: the ping-pong round trips/s (the ceiling of one simulator-controller pair); then, for each
fleet size of --vehicles (one simulator, a trajectory and a controller node per vehicle), the lockstep
paper flight's steps/s without the recorder, without the recorder and without TF (where tf2_msgs is
installed), with the recorder, and logged by its publishers (each node writes what it publishes, merged
after the flight: fly_ros record_by='publishers'), each as a share of that ceiling; for the first recorded flight,
each vehicle's odometry-to-force latency (median, p99, from the recorded publish times) and its
largest difference from the embedded flight of that vehicle alone (same offset copy of the scenario)
in any odometry value and in each summary metric.

--repeats N flies everything N times in turns (the ping-pong too) and ends with a table of the best
run of each (the least disturbed by other load on the machine) and the median, as shares of the
ceiling, with the recording overhead (1 - rate recorded / rate without recording). --against TREE
also flies every flight with the source tree at TREE (e.g. a checkout of an older commit), in turns
with this one: a before/after comparison side by side in one run. Each flight runs in its own Python
process with its tree's packages on the path.

Needs rclpy (a sourced ROS 2, or the ROS 2 wheels). Usage: python3 bench/bench_ros_lockstep.py
[--duration S] [--controller NAME] [--vehicles N [N ...]] [--repeats N] [--against TREE] [--skip-embedded]
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from mcap.reader import make_reader  # noqa: E402

import flight_stack  # noqa: E402,F401
from flight_stack.embedded import fly_embedded  # noqa: E402
from flight_stack.fleet import FleetVehicle, fleet_layout  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.bag.reader import mcap_file  # noqa: E402
from quad_msgs_bridge.bag.timing import message_timing  # noqa: E402
from quad_msgs_bridge.contract import ODOM, resolve  # noqa: E402
from quad_msgs_bridge.fast_cdr import decode_odometry  # noqa: E402
from quad_msgs_bridge.bag.flight_bag import FlightBag  # noqa: E402
from quad_msgs_bridge.review.flight_from_bag import read_flight  # noqa: E402
from quad_msgs_bridge.review.metrics import flight_metrics  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402

NAMESPACE = 'bench'
SETTLE_TIME = 5.0
RECORDED = {'recorder': 'with recorder', 'publishers': 'publishers log'}   #: fly_ros record_by -> flight label

#: one lockstep flight with the packages of the tree in argv[1]; argv[2]: its settings as JSON; prints its steps/s
FLIGHT = """
import json, re, sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
import flight_stack
from flight_stack.fleet import fleet_layout
from flight_stack.ros_backend import RosFlightConfig, fly_ros
from quad_msgs_bridge.contract import RECORDED_TOPICS
s = json.loads(sys.argv[2])
result = fly_ros(RosFlightConfig(
    vehicles=fleet_layout(s['vehicles'], s['namespace']), controller=s['controller'], scenario='paper',
    duration=s['duration'], disturbances=True, seed=0, physics_rate=1000.0, control_rate=1000.0, bag=Path(s['bag']),
    topics=[t.name for t in RECORDED_TOPICS], settle_time=s['settle_time'], quiet=True,
    record=s['record_by'] is not None, publish_tf=s['tf'], **({'record_by': s['record_by']} if s['record_by'] else {})))
if result.failed_node:
    sys.exit(f'flight failed: {result}')
print('RATE', re.search(r'([0-9.]+) steps/s', result.sim_report).group(1))
"""


def fly_lockstep(tree: Path, vehicles: int, controller: str, duration: float, bag: Path, record_by: str | None,
                 tf: bool) -> float:
    """Steps/s of one lockstep paper flight of ``vehicles`` flown with the source tree at ``tree``, its bag written
    by ``record_by`` (fly_ros: 'recorder', 'publishers'; None: no bag)."""
    settings = dict(vehicles=vehicles, namespace=NAMESPACE, controller=controller, duration=duration, bag=str(bag),
                    settle_time=SETTLE_TIME, record_by=record_by, tf=tf)
    done = subprocess.run([sys.executable, '-c', FLIGHT, str(tree), json.dumps(settings)], capture_output=True,
                          text=True)
    match = re.search(r'^RATE ([0-9.]+)$', done.stdout, re.MULTILINE)
    if done.returncode != 0 or not match:
        raise RuntimeError(f'flight with {tree} failed ({done.returncode}): {done.stdout[-2000:]}{done.stderr[-2000:]}')
    return float(match.group(1))


def pingpong_ceiling() -> float:
    """Round trips/s of the bare rclpy ping-pong (printed as it reports)."""
    pingpong = subprocess.run([sys.executable, str(ROOT / 'bench' / 'bench_ros_pingpong.py')],
                              capture_output=True, text=True, check=True).stdout
    print(pingpong.rstrip(), flush=True)
    return float(re.search(r'([0-9.]+) round trips/s', pingpong).group(1))


def odometry_values(bag: Path, namespace: str) -> np.ndarray:
    """Every recorded odometry of ``namespace`` as a row: stamp, position, orientation, linear and angular velocity."""
    with open(mcap_file(bag), 'rb') as stream:
        rows = [[sample.stamp, *sample.position, *sample.orientation, *sample.linear_velocity,
                 *sample.angular_velocity]
                for sample in (decode_odometry(message.data) for _, _, message in
                               make_reader(stream).iter_messages(topics=[resolve(ODOM, namespace)]))]
    return np.array(rows)


def compare_with_embedded(ros_bag: Path, vehicle: FleetVehicle, controller: str, duration: float,
                          scratch: Path) -> None:
    """Print the largest differences between ``vehicle``'s flight in ``ros_bag`` and the embedded flight of it alone."""
    params, disturbances = load_vehicle_file()
    embedded_bag = scratch / f'embedded-{vehicle.namespace.replace("/", "-")}'
    with FlightBag.create(embedded_bag, params, SETTLE_TIME, namespace=vehicle.namespace) as bag:
        fly_embedded(controller, make_scenario('paper', duration, vehicle.offset), params, disturbances, load_gains(),
                     duration, 1000.0, bag=bag)
    ros, embedded = odometry_values(ros_bag, vehicle.namespace), odometry_values(embedded_bag, vehicle.namespace)
    if ros.shape != embedded.shape:
        print(f'  {vehicle.namespace}: ROS flight has {len(ros)} odometry messages, the embedded one {len(embedded)}')
        return
    print(f'  {vehicle.namespace}: ROS lockstep vs embedded alone: {len(ros)} odometry messages, largest difference '
          f'in any value {np.abs(ros - embedded).max():.3g}')
    metrics = [flight_metrics(read_flight(bag, namespace=vehicle.namespace).record, SETTLE_TIME, params.F_min,
                              params.F_max) for bag in (ros_bag, embedded_bag)]
    for key in ('rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'saturation_fraction'):
        print(f'    {key:22s} ROS {metrics[0][key]:.12g}  embedded {metrics[1][key]:.12g}  '
              f'difference {abs(metrics[0][key] - metrics[1][key]):.3g}')
    for name, value in metrics[1]['chattering'].items():
        print(f'    chattering {name:11s} ROS {metrics[0]["chattering"][name]:.12g}  embedded {value:.12g}  '
              f'difference {abs(metrics[0]["chattering"][name] - value):.3g}')


def logs_publications(tree: Path) -> bool:
    """Whether the source tree at ``tree`` has the nodes' publication logs (fly_ros record_by)."""
    return 'record_by' in (tree / 'flight_stack' / 'ros_backend.py').read_text()


def print_table(ceilings: list[float], rates: dict, trees: list[tuple[str, Path]], repeats: int) -> None:
    """The best and median run of each flight against the best and median ceiling, with the recording overhead."""
    best_ceiling, median_ceiling = max(ceilings), statistics.median(ceilings)
    print(f'\nsummary of {repeats} run(s) in turns: best (least disturbed) and median; ping-pong ceiling best '
          f'{best_ceiling:.0f}, median {median_ceiling:.0f} round trips/s')
    print(f'{"vehicles":>8}  {"tree":<8} {"flight":<19} {"best steps/s":>12} {"% ceiling":>9} '
          f'{"median":>8} {"% ceiling":>9}  recording overhead best / median')
    for (count, tree, label), values in rates.items():
        best, median = max(values), statistics.median(values)
        line = (f'{count:>8}  {tree:<8} {label:<19} {best:12.0f} {100 * best / best_ceiling:8.1f}% '
                f'{median:8.0f} {100 * median / median_ceiling:8.1f}%')
        bare = rates.get((count, tree, 'no recorder'))
        if label in RECORDED.values() and bare:
            line += f'  {100 * (1 - best / max(bare)):5.1f} % / {100 * (1 - median / statistics.median(bare)):5.1f} %'
        print(line)
    if len(trees) > 1:
        print('trees: ' + ', '.join(f'{name} = {path}' for name, path in trees))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=10.0)
    parser.add_argument('--controller', default='nnit2fsmc')
    parser.add_argument('--vehicles', type=int, nargs='+', default=[1], metavar='N', help='fleet sizes to fly')
    parser.add_argument('--repeats', type=int, default=1, help='fly everything this many times, in turns')
    parser.add_argument('--against', type=Path, metavar='TREE',
                        help='also fly with the source tree at TREE, in turns with this one (before/after)')
    parser.add_argument('--skip-embedded', action='store_true',
                        help='no latency figures and no comparison with the embedded flight')
    args = parser.parse_args()
    trees = [('this', ROOT)] + ([('against', args.against.resolve())] if args.against else [])
    flights = [('no recorder', None, True)]
    if importlib.util.find_spec('tf2_msgs') is not None:   # without tf2_msgs no flight has TF: nothing to compare
        flights.append(('no recorder, no TF', None, False))
    flights += [(label, record_by, True) for record_by, label in RECORDED.items()]
    ceilings: list[float] = []
    rates: dict[tuple, list[float]] = {}
    for repeat in range(args.repeats):
        ceiling = pingpong_ceiling()
        ceilings.append(ceiling)
        for count in args.vehicles:
            vehicles = fleet_layout(count, NAMESPACE)
            for label, record_by, tf in flights:
                for tree_name, tree in trees:
                    if record_by == 'publishers' and tree_name == 'against' and not logs_publications(tree):
                        continue
                    with tempfile.TemporaryDirectory() as tmp:
                        bag = Path(tmp) / 'bag'
                        rate = fly_lockstep(tree, count, args.controller, args.duration, bag, record_by, tf)
                        rates.setdefault((count, tree_name, label), []).append(rate)
                        print(f'lockstep {args.controller}, {count} vehicle(s), {tree_name:<7} {label:18s}: '
                              f'{rate:7.0f} steps/s = {100 * rate / ceiling:5.1f} % of the ping-pong ceiling',
                              flush=True)
                        if record_by == 'recorder' and repeat == 0 and tree_name == 'this' \
                                and not args.skip_embedded:
                            for vehicle in vehicles:
                                timing = message_timing(bag, vehicle.namespace)
                                print(f'  {vehicle.namespace}: odom->forces latency median '
                                      f'{timing["latency_median_ms"]:.3f} ms, p99 {timing["latency_p99_ms"]:.3f} ms')
                            for vehicle in vehicles:
                                compare_with_embedded(bag, vehicle, args.controller, args.duration, Path(tmp))
    if args.repeats > 1 or args.against:
        print_table(ceilings, rates, trees, args.repeats)


if __name__ == '__main__':
    main()
