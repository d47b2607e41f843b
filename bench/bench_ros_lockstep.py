#!/usr/bin/env python3
"""Lockstep rate of the ROS stack (every node its own process) next to a bare rclpy ping-pong, for fleets.

Prints: the ping-pong round trips/s (the ceiling of one simulator-controller pair); then, for each
fleet size of --vehicles (one simulator, a trajectory and a controller node per vehicle), the lockstep
paper flight's steps/s without the recorder, without the recorder and without TF, and with the
recorder, each as a share of that ceiling; for the recorded flight, each vehicle's odometry-to-force
latency (median, p99, from the recorded publish times) and its largest difference from the embedded
flight of that vehicle alone (same offset copy of the scenario) in any odometry value and in each
summary metric.
Needs a sourced ROS 2. Usage: python3 bench/bench_ros_lockstep.py [--duration S] [--controller NAME]
[--vehicles N [N ...]]
"""
from __future__ import annotations

import argparse
import re
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
from flight_stack.ros_backend import RosFlightConfig, fly_ros  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.bag.reader import mcap_file  # noqa: E402
from quad_msgs_bridge.bag.timing import message_timing  # noqa: E402
from quad_msgs_bridge.contract import ODOM, RECORDED_TOPICS, resolve  # noqa: E402
from quad_msgs_bridge.fast_cdr import decode_odometry  # noqa: E402
from quad_msgs_bridge.bag.flight_bag import FlightBag  # noqa: E402
from quad_msgs_bridge.review.flight_from_bag import read_flight  # noqa: E402
from quad_msgs_bridge.review.metrics import flight_metrics  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402

NAMESPACE = 'bench'
SETTLE_TIME = 5.0


def steps_per_second(report: str) -> float:
    match = re.search(r'([0-9.]+) steps/s', report)
    if not match:
        raise RuntimeError(f'no rate in the simulator report: {report!r}')
    return float(match.group(1))


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=10.0)
    parser.add_argument('--controller', default='nnit2fsmc')
    parser.add_argument('--vehicles', type=int, nargs='+', default=[1], metavar='N', help='fleet sizes to fly')
    args = parser.parse_args()
    pingpong = subprocess.run([sys.executable, str(ROOT / 'bench' / 'bench_ros_pingpong.py')],
                              capture_output=True, text=True, check=True).stdout
    ceiling = float(re.search(r'([0-9.]+) round trips/s', pingpong).group(1))
    print(pingpong.rstrip())
    for count in args.vehicles:
        vehicles = fleet_layout(count, NAMESPACE)
        for label, record, tf in (('no recorder', False, True), ('no recorder, no TF', False, False),
                                  ('with recorder', True, True)):
            with tempfile.TemporaryDirectory() as tmp:
                result = fly_ros(RosFlightConfig(
                    vehicles=vehicles, controller=args.controller, scenario='paper', duration=args.duration,
                    disturbances=True, seed=0, physics_rate=1000.0, control_rate=1000.0, bag=Path(tmp) / 'bag',
                    topics=[t.name for t in RECORDED_TOPICS], settle_time=SETTLE_TIME, quiet=True, record=record,
                    publish_tf=tf))
                if result.failed_node:
                    raise RuntimeError(f'flight failed: {result}')
                rate = steps_per_second(result.sim_report)
                print(f'lockstep {args.controller}, {count} vehicle(s), {label:18s}: {rate:7.0f} steps/s = '
                      f'{100 * rate / ceiling:5.1f} % of the ping-pong ceiling')
                if record:
                    for vehicle in vehicles:
                        timing = message_timing(Path(tmp) / 'bag', vehicle.namespace)
                        print(f'  {vehicle.namespace}: odom->forces latency median {timing["latency_median_ms"]:.3f} '
                              f'ms, p99 {timing["latency_p99_ms"]:.3f} ms')
                    for vehicle in vehicles:
                        compare_with_embedded(Path(tmp) / 'bag', vehicle, args.controller, args.duration, Path(tmp))


if __name__ == '__main__':
    main()
