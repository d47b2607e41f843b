#!/usr/bin/env python3
"""The held-out campaign table: one row per (controller, campaign folder), from the folders' flights.csv.

    python3 run_stack.py campaign campaigns/paper-robustness.yaml --seed 101 --flights 1000 \\
        --controllers nnit2fsmc,pid,se3,smc-integral --out out/heldout-101        # (and 102, 103)
    .venv/bin/python bench/heldout_table.py out/heldout-101 out/heldout-102 out/heldout-103
    .venv/bin/python bench/heldout_table.py --first 250 out/heldout-101     # flights 0..249 only

Columns: flights flown, finished (with the 95 % Wilson interval), finished with RMSE < 10 cm (of all
flights flown, the target of issue 21, with its interval), RMSE p50 / p95 of the finished flights [cm],
chattering p50 of the force channel U1 [N/s] and of the moment channels [N m/s] (the campaign's
``chattering_force_n_per_s``, ``chattering_moment_nm_per_s``). A folder still being flown gives the rows flown so far (the column
``flights`` says how many).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack.campaign.results import read_flights, wilson_interval  # noqa: E402

TARGET_RMSE_CM = 10.0


def rows_of(folder: Path) -> tuple[int, list[dict]]:
    """(campaign seed, rows) of a campaign folder."""
    import yaml
    seed = yaml.safe_load((folder / 'spec.yaml').read_text()).get('seed', 0)
    return seed, read_flights(folder / 'flights.csv')


def table(folders, first: int | None = None) -> list[str]:
    """The table's lines; ``first``: only flights 0..first-1 of each folder (the same vehicles for every
    controller of a seed: a paired comparison with a campaign flown with fewer flights)."""
    lines = ['| controller | seed | flights | finished | 95 % interval | finished with RMSE < 10 cm | 95 % interval | '
             'RMSE p50 / p95 [cm] | chattering p50: U1 [N/s] / moments [N m/s] |',
             '|---|---:|---:|---:|---|---:|---|---|---|']
    for folder in folders:
        seed, rows = rows_of(Path(folder))
        rows = [row for row in rows if first is None or row['flight'] < first]
        for controller in dict.fromkeys(row['controller'] for row in rows):
            mine = [row for row in rows if row['controller'] == controller]
            finished = [row for row in mine if row['finished']]
            good = [row for row in finished if 100.0 * row['rmse_position_m'] < TARGET_RMSE_CM]
            low, high = wilson_interval(len(finished), len(mine))
            good_low, good_high = wilson_interval(len(good), len(mine))
            rmse = [100.0 * row['rmse_position_m'] for row in finished]
            force = [row['chattering_force_n_per_s'] for row in finished]
            moments = [row['chattering_moment_nm_per_s'] for row in finished]
            figures = (f'{np.percentile(rmse, 50):.2f} / {np.percentile(rmse, 95):.2f} | '
                       f'{np.percentile(force, 50):.3g} / {np.percentile(moments, 50):.3g}' if rmse else '- | -')
            lines.append(f'| {controller} | {seed} | {len(mine)} | {100.0 * len(finished) / len(mine):.1f} % | '
                         f'{100 * low:.1f} - {100 * high:.1f} % | {100.0 * len(good) / len(mine):.1f} % | '
                         f'{100 * good_low:.1f} - {100 * good_high:.1f} % | {figures} |')
    return lines


def main(argv=None) -> int:
    import argparse
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('folders', nargs='+', type=Path, help='campaign output folders')
    parser.add_argument('--first', type=int, default=None, help='only flights 0..N-1 of each folder')
    args = parser.parse_args(argv)
    print('\n'.join(table(args.folders, args.first)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
