#!/usr/bin/env python3
"""The NNIT2FSMC's failures of issue 28, flown by every controller kind (docs/PAPER.md 4.9).

(a) the fast ``lemniscate`` (2.8 m/s, 4 m/s^2) on the paper's vehicle, 1 kHz: RMSE after 5 s and the
    body-rate RMS (roll and pitch) per window;
(b) 8 m/s mean wind with moderate Dryden gusts on a heavier vehicle (``--heavy`` FILE: the issue's
    0.826 kg X frame, 0.166 m arms, thrust-to-weight 3.8, as a "+" frame of equivalent arm 0.166 sqrt 2 m,
    masses, inertias and drags 1.7 times the paper's) with 5 ms motor lag, the paper helix, seeds 0..S-1;
(c) a 25 % loss of every rotor from 10 s on, the paper helix, on the paper's and on the heavier vehicle.

    .venv/bin/python bench/carry_over.py --heavy FILE [--seeds 5] [--cases a,b,c] [--json OUT]

Run it at two commits to compare (the gains file of the older one is in newtons: it gives the heavier
vehicle the paper vehicle's forces).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from flight_stack.api import fly  # noqa: E402
from quad_msgs_bridge.frames import body_rates_from_euler_rates  # noqa: E402

KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'nnit2fsmc-bias')
DURATION = 30.0   #: [s] every flight
SETTLED = 5.0     #: [s] metrics after it
LOSS = {'at_s': 10.0, 'loss': [0.25] * 4}


def flown(kind: str, scenario: str, **world) -> dict:
    """RMSE [cm], finished, body-rate RMS [rad/s] after SETTLED and the largest U1 [N] of one flight."""
    flight = fly(kind, scenario, duration=DURATION, **world)
    late = flight.time >= SETTLED
    rates = np.array([body_rates_from_euler_rates(row[6:9], row[9:12]) for row in flight.state[late]])
    return {'finished': not flight.ended_early, 'rmse_cm': 100.0 * flight.summary['rmse_position_m'],
            'body_rate_rms': float(np.sqrt(np.mean(np.sum(rates ** 2, axis=1)))),
            'roll_rate_rms': float(np.sqrt(np.mean(rates[:, 0] ** 2))), 'U1_max': float(flight.controls[late, 0].max())}


def cases(heavy: str, seeds: int) -> dict:
    """{case: [(kind, world keyword arguments of fly), ...]}"""
    wind = {'mean_speed_mps': 8.0, 'turbulence': 'moderate'}
    return {
        'a': [('lemniscate', {})],
        'b': [('paper', dict(vehicle=heavy, wind=wind, motor_time_constant_s=0.005, seed=seed))
              for seed in range(seeds)],
        'c': [('paper', dict(rotor_efficiency_loss=LOSS)),
              ('paper', dict(vehicle=heavy, rotor_efficiency_loss=LOSS, motor_time_constant_s=0.005))],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--heavy', required=True, help='vehicle YAML of the heavier vehicle of case (b) and (c)')
    parser.add_argument('--seeds', type=int, default=5, help='wind seeds of case (b)')
    parser.add_argument('--cases', default='a,b,c')
    parser.add_argument('--json', type=Path)
    args = parser.parse_args(argv)
    table = cases(args.heavy, args.seeds)
    results = {}
    for case in args.cases.split(','):
        for kind in KINDS:
            rows = [flown(kind, scenario, **world) for scenario, world in table[case]]
            results[f'{case}/{kind}'] = rows
            print(f'({case}) {kind:15s} finished {sum(r["finished"] for r in rows)}/{len(rows)}  RMSE [cm] '
                  + ' '.join(f'{r["rmse_cm"]:.2f}' for r in rows) + '  body-rate RMS [rad/s] '
                  + ' '.join(f'{r["body_rate_rms"]:.2f}' for r in rows) + '  U1 max [N] '
                  + ' '.join(f'{r["U1_max"]:.2f}' for r in rows), flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
