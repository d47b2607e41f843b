"""The off-nominal paper flights of docs/ADAPTIVE.md: delay, control rate and sensor noise.

Each row is one embedded paper flight (60 s helix, section IV disturbances, metrics after 5 s):

    .venv/bin/python bench/adaptive_study.py                       # every row, default gains
    .venv/bin/python bench/adaptive_study.py --rows nominal delay20 noise --faithful
    .venv/bin/python bench/adaptive_study.py --set nnit2fsmc.sigma=0 --rows delay20

``--faithful`` flies the paper-faithful settings (docs/ADAPTIVE.md); ``--set KEY=VALUE`` overrides
any gain (dotted name, YAML value).
"""
from __future__ import annotations

import argparse
import sys

import yaml

from study_flights import CAMPAIGN_NOISE, fly_case, unstable
from nnit2fsmc_controller.factory import PAPER_FAITHFUL, flatten_gains, load_gains, unflatten_gains
from quad_sim.perturbations.sensor_noise import SensorErrors

#: position 1 cm and attitude 0.01 rad only (the noise of issue 9, finding 6)
POSE_NOISE = SensorErrors(position=0.01, attitude=0.01)

ROWS = {   # name: (controller, keyword arguments of fly_case)
    'nominal': ('nnit2fsmc', {}),
    'delay10': ('nnit2fsmc', {'delay_s': 0.010}),
    'delay20': ('nnit2fsmc', {'delay_s': 0.020}),
    'delay40': ('nnit2fsmc', {'delay_s': 0.040}),
    'rate250': ('nnit2fsmc', {'control_rate': 250.0}),
    'rate100': ('nnit2fsmc', {'control_rate': 100.0}),
    'noise': ('nnit2fsmc', {'noise': POSE_NOISE}),
    'noise-campaign': ('nnit2fsmc', {'noise': CAMPAIGN_NOISE}),
    'lag30': ('nnit2fsmc', {'motor_lag_s': 0.030}),
    'sign': ('smc-sign', {}),
    'sign-noise': ('smc-sign', {'noise': POSE_NOISE}),
}


def row(label: str, kind: str, gains: dict, **kwargs) -> str:
    case = fly_case(kind, gains, **kwargs)
    m = case.metrics
    tv = m['chattering']
    return (f'| {label} | {kind} | {m["rmse_position_m"] * 100:.3g} | {m["max_position_error_m"] * 100:.3g} | '
            f'{tv["U1"]:.3g} | {tv["U2"]:.3g} | {tv["U3"]:.3g} | {tv["U4"]:.3g} | {sum(tv.values()):.3g} | '
            f'{case.oscillation[0]:.3g} / {case.oscillation[1]:.3g} | '
            f'{"UNSTABLE" if unstable(case) else "no"} | {case.failure or ""} |')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--rows', nargs='+', default=list(ROWS), choices=list(ROWS))
    parser.add_argument('--faithful', action='store_true', help='the paper-faithful settings of docs/ADAPTIVE.md')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    parser.add_argument('--controller', help='fly this kind instead of nnit2fsmc in the nnit2fsmc rows')
    parser.add_argument('--duration', type=float, default=60.0)
    args = parser.parse_args(argv)
    flat = flatten_gains(load_gains())
    if args.faithful:
        flat.update(PAPER_FAITHFUL)
    for item in args.set:
        key, _, value = item.partition('=')
        flat[key] = yaml.safe_load(value)
    gains = unflatten_gains(flat)
    print('| row | controller | RMSE [cm] | max [cm] | TV U1 [N/s] | TV U2 | TV U3 | TV U4 [N m/s] | TV sum | '
          'osc rms U2 / U3 [N] | limit cycle | failure |')
    print('|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|---|')
    for name in args.rows:
        kind, kwargs = ROWS[name]
        if args.controller and kind == 'nnit2fsmc':
            kind = args.controller
        print(row(name, kind, gains, duration=args.duration, **kwargs), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
