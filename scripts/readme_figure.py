#!/usr/bin/env python3
"""Make docs/readme_figure.png: the NNIT2FSMC against the classic sign-SMC on the paper's flight.

Left: the 3-D path of the NNIT2FSMC against the reference (paper Fig. 7). Middle: the position
error of both after the settling window. Right: the roll control U2 of both over one second
(paper Fig. 9; the chattering the paper's title is about). Both fly the paper's helix with the
section IV disturbances on the embedded backend, default gains.

    .venv/bin/python scripts/readme_figure.py [--out docs/readme_figure.png] [--duration 60]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import flight_stack  # noqa: E402,F401  (the package folders on the path)
import numpy as np  # noqa: E402

from flight_stack.embedded import fly_embedded  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.review.metrics import SETTLE_TIME  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402

COLOURS = {'nnit2fsmc': 'tab:blue', 'smc-sign': 'tab:red'}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--out', type=Path, default=ROOT / 'docs' / 'readme_figure.png')
    parser.add_argument('--duration', type=float, default=60.0, help='sim time of each flight [s]')
    args = parser.parse_args()
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    params, disturbances = load_vehicle_file()
    trajectory = make_scenario('paper', args.duration)
    records = {kind: fly_embedded(kind, trajectory, params, disturbances, load_gains(), args.duration, 1000.0).record
               for kind in COLOURS}
    figure = plt.figure(figsize=(12.0, 3.6), dpi=80)
    path = figure.add_subplot(1, 3, 1, projection='3d')
    nn = records['nnit2fsmc']
    path.plot(*nn.reference_position.T, color='black', linestyle='--', linewidth=1.0, label='reference')
    path.plot(*nn.position.T, color=COLOURS['nnit2fsmc'], linewidth=1.0, label='NNIT2FSMC')
    path.set_xlabel('x [m]')
    path.set_ylabel('y [m]')
    path.set_zlabel('z [m]')
    path.set_title('paper helix with disturbances', fontsize=10)
    path.legend(fontsize=7, loc='upper left')

    error = figure.add_subplot(1, 3, 2)
    for kind, record in records.items():
        settled = record.time >= SETTLE_TIME
        distance = np.linalg.norm(record.position - record.reference_position, axis=1)[settled]
        error.plot(record.time[settled], distance * 1000.0, color=COLOURS[kind], linewidth=0.8, label=kind)
    error.set_xlabel('t [s]')
    error.set_ylabel('position error [mm]')
    error.set_title(f'tracking error after {SETTLE_TIME:g} s', fontsize=10)
    error.legend(fontsize=7)
    error.grid(alpha=0.3)

    control = figure.add_subplot(1, 3, 3)
    start = min(30.0, args.duration - 1.0)
    for kind, record in records.items():
        window = (record.time >= start) & (record.time < start + 1.0)
        control.plot(record.time[window], record.controls[window, 1], color=COLOURS[kind], linewidth=0.8, label=kind)
    control.set_xlabel('t [s]')
    control.set_ylabel('U2 (roll) [N]')
    control.set_title('roll control over one second', fontsize=10)
    control.legend(fontsize=7)
    control.grid(alpha=0.3)
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=80)
    print(f'wrote {args.out} ({args.out.stat().st_size // 1024} kB)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
