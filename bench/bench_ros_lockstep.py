#!/usr/bin/env python3
"""Lockstep rate of the ROS stack (three nodes, each its own process) next to a bare rclpy ping-pong.

Prints: the ping-pong round trips/s (the ceiling of a simulator-controller pair), then the lockstep
paper flight's steps/s without and with the recorder, each as a share of that ceiling; then, for
the recorded flight, its largest difference from the embedded flight of the same scenario in any
odometry value and in each summary metric.
Needs a sourced ROS 2. Usage: python3 bench/bench_ros_lockstep.py [--duration S] [--controller NAME]
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
from flight_stack.ros_backend import RosFlightConfig, fly_ros  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.bag.reader import mcap_file  # noqa: E402
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


def odometry_values(bag: Path) -> np.ndarray:
    """Every recorded odometry as a row: stamp, position, orientation, linear and angular velocity."""
    with open(mcap_file(bag), 'rb') as stream:
        rows = [[sample.stamp, *sample.position, *sample.orientation, *sample.linear_velocity,
                 *sample.angular_velocity]
                for sample in (decode_odometry(message.data) for _, _, message in
                               make_reader(stream).iter_messages(topics=[resolve(ODOM, NAMESPACE)]))]
    return np.array(rows)


def compare_with_embedded(ros_bag: Path, controller: str, trajectory, duration: float, scratch: Path) -> None:
    """Print the largest differences between the ROS lockstep flight in ``ros_bag`` and the embedded one."""
    params, disturbances = load_vehicle_file()
    embedded_bag = scratch / 'embedded'
    with FlightBag.create(embedded_bag, params, SETTLE_TIME, namespace=NAMESPACE) as bag:
        fly_embedded(controller, trajectory, params, disturbances, load_gains(), duration, 1000.0, bag=bag)
    ros, embedded = odometry_values(ros_bag), odometry_values(embedded_bag)
    if ros.shape != embedded.shape:
        print(f'ROS flight has {len(ros)} odometry messages, the embedded one {len(embedded)}')
        return
    print(f'ROS lockstep vs embedded: {len(ros)} odometry messages, largest difference in any value '
          f'{np.abs(ros - embedded).max():.3g}')
    metrics = [flight_metrics(read_flight(bag).record, SETTLE_TIME, params.F_min, params.F_max)
               for bag in (ros_bag, embedded_bag)]
    for key in ('rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'saturation_fraction'):
        print(f'  {key:22s} ROS {metrics[0][key]:.12g}  embedded {metrics[1][key]:.12g}  '
              f'difference {abs(metrics[0][key] - metrics[1][key]):.3g}')
    for name, value in metrics[1]['chattering'].items():
        print(f'  chattering {name:11s} ROS {metrics[0]["chattering"][name]:.12g}  embedded {value:.12g}  '
              f'difference {abs(metrics[0]["chattering"][name] - value):.3g}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--duration', type=float, default=10.0)
    parser.add_argument('--controller', default='nnit2fsmc')
    args = parser.parse_args()
    pingpong = subprocess.run([sys.executable, str(ROOT / 'bench' / 'bench_ros_pingpong.py')],
                              capture_output=True, text=True, check=True).stdout
    ceiling = float(re.search(r'([0-9.]+) round trips/s', pingpong).group(1))
    print(pingpong.rstrip())
    trajectory = make_scenario('paper', args.duration)
    for record in (False, True):
        with tempfile.TemporaryDirectory() as tmp:
            result = fly_ros(RosFlightConfig(
                namespace=NAMESPACE, controller=args.controller, scenario='paper', duration=args.duration,
                disturbances=True, seed=0, physics_rate=1000.0, control_rate=1000.0,
                initial_state=trajectory.initial_state, bag=Path(tmp) / 'bag',
                topics=[t.name for t in RECORDED_TOPICS], settle_time=SETTLE_TIME, quiet=True, record=record))
            if result.failed_node:
                raise RuntimeError(f'flight failed: {result}')
            rate = steps_per_second(result.sim_report)
            label = 'with recorder' if record else 'three nodes'
            print(f'lockstep {args.controller}, {label:13s}: {rate:7.0f} steps/s = '
                  f'{100 * rate / ceiling:5.1f} % of the ping-pong ceiling')
            if record:
                compare_with_embedded(Path(tmp) / 'bag', args.controller, trajectory, args.duration, Path(tmp))


if __name__ == '__main__':
    main()
