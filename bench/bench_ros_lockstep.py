#!/usr/bin/env python3
"""Lockstep rate of the ROS stack (three nodes, each its own process) next to a bare rclpy ping-pong.

Prints: the ping-pong round trips/s (the ceiling of a simulator-controller pair), then the lockstep
paper flight's steps/s without and with the recorder, each as a share of that ceiling.
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

import flight_stack  # noqa: E402,F401
from flight_stack.ros_backend import RosFlightConfig, fly_ros  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.contract import RECORDED_TOPICS  # noqa: E402


def steps_per_second(report: str) -> float:
    match = re.search(r'([0-9.]+) steps/s', report)
    if not match:
        raise RuntimeError(f'no rate in the simulator report: {report!r}')
    return float(match.group(1))


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
                namespace='bench', controller=args.controller, scenario='paper', duration=args.duration,
                disturbances=True, seed=0, physics_rate=1000.0, control_rate=1000.0,
                initial_state=trajectory.initial_state, bag=Path(tmp) / 'bag',
                topics=[t.name for t in RECORDED_TOPICS], quiet=True, record=record))
        if result.failed_node:
            raise RuntimeError(f'flight failed: {result}')
        rate = steps_per_second(result.sim_report)
        label = 'with recorder' if record else 'three nodes'
        print(f'lockstep {args.controller}, {label:13s}: {rate:7.0f} steps/s = {100 * rate / ceiling:5.1f} % of the ping-pong ceiling')


if __name__ == '__main__':
    main()
