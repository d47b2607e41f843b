#!/usr/bin/env python3
"""Batch equals scalar: N perturbed flights flown as one numpy batch and the same N flown one by one.

For every controller kind, the campaign's batch path (``flight_stack.campaign.batch.fly_batch``:
arrays of N vehicles, per-vehicle network weights, streams and perturbations) and the single
embedded flight (``fly_embedded``: one vehicle of floats, through odometry messages) fly flights
0..N-1 of a perturbed spec; the table gives the largest difference of every metric of a row.
The spec, campaigns/mild-every-perturbation.yaml (at 1 kHz here), has every perturbation on,
mild enough that every kind finishes; tests/test_campaign_batch.py checks 3 of its flights per
kind to 1e-9.

    .venv/bin/python bench/batch_equals_scalar.py [--flights 64] [--duration 3] [--controllers a,b]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack.campaign.batch import BatchJob, CampaignSetup, fly_batch  # noqa: E402
from flight_stack.campaign.sampling import build_perturbations, sample_conditions  # noqa: E402
from flight_stack.campaign.spec import parse_spec  # noqa: E402
from flight_stack.embedded import fly_embedded  # noqa: E402
from nnit2fsmc_controller.factory import CONTROLLERS  # noqa: E402
from quad_msgs_bridge.review.metrics import flight_metrics  # noqa: E402

#: every perturbation on, mild enough that every kind finishes (flown here at 1 kHz)
SPEC_FILE = Path(__file__).resolve().parent.parent / 'campaigns' / 'mild-every-perturbation.yaml'
METRICS = ('rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'saturation_fraction')


def single_row(spec, controller: str, flight: int) -> dict:
    """The metrics of flight ``flight`` flown alone on the embedded path, named as in flights.csv."""
    setup = CampaignSetup.of(spec)
    conditions = sample_conditions(spec, setup.nominal, flight)
    perturbations = build_perturbations(spec, [conditions], setup.control_dt, setup.physics_dt, batch=False)
    result = fly_embedded(controller, setup.trajectory, setup.nominal, setup.disturbances, setup.gains,
                          spec.duration, 1.0 / setup.physics_dt, perturbations=perturbations, rules=setup.rules(spec))
    metrics = flight_metrics(result.record, spec.settle_time, setup.nominal.F_min, setup.nominal.F_max)
    row = {key: metrics[key] for key in METRICS}
    row.update({f'chattering_U{i}': metrics['chattering'][f'U{i}'] for i in range(1, 5)})
    row['finished'] = result.failure is None
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--flights', type=int, default=64)
    parser.add_argument('--duration', type=float, default=3.0, help='[s] per flight')
    parser.add_argument('--controllers', help='comma-separated kinds (default: every kind)')
    args = parser.parse_args(argv)
    kinds = args.controllers.split(',') if args.controllers else list(CONTROLLERS)
    document = yaml.safe_load(SPEC_FILE.read_text())
    spec = parse_spec({**document, 'duration': args.duration, 'controllers': kinds, 'flights': args.flights,
                       'control_rate_hz': 1000, 'physics_rate_hz': 1000})
    keys = METRICS + tuple(f'chattering_U{i}' for i in range(1, 5))
    print(f'{args.flights} flights of {args.duration:g} s per controller, every perturbation on\n')
    print('| controller | finished (batch / one by one) | largest relative difference of any metric | '
          'largest absolute difference | batch [s] | one by one [s] |')
    print('|---|---|---:|---:|---:|---:|')
    for kind in kinds:
        started = time.perf_counter()
        rows = fly_batch(BatchJob(spec, kind, tuple(range(args.flights))))
        batch_time = time.perf_counter() - started
        started = time.perf_counter()
        singles = [single_row(spec, kind, row['flight']) for row in rows]
        single_time = time.perf_counter() - started
        relative = absolute = 0.0
        for row, single in zip(rows, singles):
            for key in keys:
                a, b = row[key], single[key]
                if math.isnan(a) and math.isnan(b):
                    continue
                absolute = max(absolute, abs(a - b))
                relative = max(relative, abs(a - b) / max(abs(b), 1e-300))
        print(f'| {kind} | {sum(r["finished"] for r in rows)} / {sum(s["finished"] for s in singles)} | '
              f'{relative:.2e} | {absolute:.2e} | {batch_time:.1f} | {single_time:.1f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
