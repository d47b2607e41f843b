#!/usr/bin/env python3
"""Peak memory (resident set) of a campaign's planning, up to its first batch.

    .venv/bin/python bench/bench_campaign_planning.py --flights 1000000000

Loads the spec (campaigns/paper-robustness.yaml with --flights), plans its batches as the runner does
and takes the first one, then prints the peak RSS of this process (resource.getrusage) before and after.
Run it from another checkout (PYTHONPATH) to compare the planning of two versions side by side.
"""
import argparse
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--flights', type=int, default=1_000_000_000)
    parser.add_argument('--workers', type=int, default=2)
    args = parser.parse_args()
    from flight_stack.campaign.runner import RunOptions, plan_jobs
    from flight_stack.campaign.spec import load_spec
    spec = load_spec(ROOT / 'campaigns' / 'paper-robustness.yaml').overridden(flights=args.flights)
    before = peak_rss_mb()
    started = time.perf_counter()
    first = next(iter(plan_jobs(spec, set(), RunOptions(), args.workers)))
    print(f'{args.flights} flights x {len(spec.controllers)} controllers: first batch of {len(first.flights)} '
          f'flights after {time.perf_counter() - started:.3f} s; peak RSS {before:.0f} MB before planning, '
          f'{peak_rss_mb():.0f} MB at the first batch')
    return 0


if __name__ == '__main__':
    sys.exit(main())
