"""The held-out campaign tables of docs/PAPER.md 4.8.6 and 4.8.8, from campaign folders (per kind, paired).

One row per (controller, seed) and pooled, and the paired comparison of every controller against a reference
(the NNIT2FSMC), from the campaign folders' flights.csv (it flies nothing: the campaigns are run_stack.py campaign's).

    python3 run_stack.py campaign campaigns/paper-robustness.yaml --seed 101 --flights 1000 \\
        --controllers nnit2fsmc,pid,se3,smc-integral --out out/heldout-101        # (and 102, 103)
    run_stack.py study heldout --out DIR out/heldout-101 out/heldout-102 out/heldout-103
    run_stack.py study heldout --out DIR --first 250 out/heldout-101     # flights 0..249 only
    run_stack.py study heldout --out DIR out/board/heldout/seed-*/*      # the scoreboard study's folders

A folder may hold one controller or several; folders of one seed must fly the same perturbed flights
(checked: the same spec apart from the controllers, and the same sampled vehicle and wind direction in
every row of a flight index), so flight k of seed s pairs the controllers (docs/SCOREBOARD.md).

Per controller (the statistics in flight_stack/campaign/paired.py; 95 % intervals): flights flown, finished
with its Wilson interval, finished with RMSE < 10 cm (of all flights, issue 21's target) with its Wilson
interval, RMSE p50 / p95 [cm] over **all** flights with a failed flight counted as +inf ("failed" where a
percentile falls on failures) with distribution-free order-statistic intervals, and the chattering p50 of
U1 [N/s] / of the moments [N m/s] over the finished flights. Paired against the reference, flight by
flight: the share each one has the lower RMSE (a finished flight beats a failed one; both failed is a tie),
the median paired difference RMSE(controller) - RMSE(reference) [cm] with its sign-test interval, and the
two-sided sign test's p-value. Where the flights drew their actuator (a motor time constant, a delay), the failed
flights by third of each drawn range (:func:`actuator_lines`). A folder still being flown gives the rows flown so far.
"""
from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

import numpy as np

from flight_stack.campaign.paired import paired, quantile, rmse_or_failed
from flight_stack.campaign.results import read_flights, wilson_interval
from flight_stack.campaign.sampling import SAMPLED_COLUMNS

from .common import add_out, progress, study_name, write_table

STUDY = study_name(__name__)

TARGET_RMSE_CM = 10.0
ALL_SEEDS = 'all'
REFERENCE = 'nnit2fsmc'


def rows_of(folder: Path) -> tuple[int, list[dict]]:
    """(campaign seed, rows) of a campaign folder."""
    import yaml
    seed = yaml.safe_load((folder / 'spec.yaml').read_text()).get('seed', 0)
    return seed, read_flights(folder / 'flights.csv')


def spec_without_controllers(folder: Path) -> dict:
    import yaml
    spec = yaml.safe_load((folder / 'spec.yaml').read_text())
    spec.pop('controllers', None)
    return spec


def load(folders, first: int | None = None) -> dict[int, list[dict]]:
    """{seed: rows of every folder of that seed} (``first``: only flights 0..first-1), after checking that
    the folders of a seed fly the same flights (:func:`check_paired`)."""
    by_seed: dict[int, list[dict]] = {}
    specs: dict[int, tuple[Path, dict]] = {}
    for folder in map(Path, folders):
        seed, rows = rows_of(folder)
        spec = spec_without_controllers(folder)
        if seed in specs and specs[seed][1] != spec:
            raise ValueError(f'{folder}: its spec differs from that of {specs[seed][0]} (seed {seed}) in more than '
                             'the controllers: their flights do not pair')
        specs.setdefault(seed, (folder, spec))
        by_seed.setdefault(seed, []).extend(row for row in rows if first is None or row['flight'] < first)
    for seed, rows in by_seed.items():
        check_paired(rows, seed)
    return by_seed


def check_paired(rows: list[dict], seed) -> None:
    """ValueError unless every row of a flight index has the same sampled vehicle and wind direction
    (the conditions flights.csv records; the rest comes from the same per-flight seed)."""
    seen: dict[int, dict] = {}
    for row in rows:
        conditions = {name: row[name] for name in SAMPLED_COLUMNS}
        first = seen.setdefault(row['flight'], {**conditions, 'controller': row['controller']})
        for name in SAMPLED_COLUMNS:
            if first[name] != conditions[name]:
                raise ValueError(f'seed {seed}, flight {row["flight"]}: {name} is {first[name]!r} for '
                                 f'{first["controller"]} but {conditions[name]!r} for {row["controller"]}: '
                                 'not the same perturbed flight')


def controllers_of(by_seed: dict[int, list[dict]]) -> list[str]:
    return list(dict.fromkeys(row['controller'] for rows in by_seed.values() for row in rows))


def groups(by_seed: dict[int, list[dict]]):
    """(seed or 'all', rows): every seed, then all seeds pooled when there is more than one."""
    for seed in sorted(by_seed):
        yield seed, by_seed[seed]
    if len(by_seed) > 1:
        yield ALL_SEEDS, [row for seed in sorted(by_seed) for row in by_seed[seed]]


def kind_record(controller: str, seed, mine: list[dict]) -> dict:
    """The figures of one controller's flights (module docstring); RMSE in cm."""
    finished = [row for row in mine if row['finished']]
    good = [row for row in finished if 100.0 * row['rmse_position_m'] < TARGET_RMSE_CM]
    rmse = [100.0 * rmse_or_failed(row) for row in mine]
    p50, p95 = quantile(rmse, 0.5), quantile(rmse, 0.95)
    force = [row['chattering_force_n_per_s'] for row in finished]
    moments = [row['chattering_moment_nm_per_s'] for row in finished]
    return {'controller': controller, 'seed': seed, 'flights': len(mine), 'finished': len(finished),
            'finished_share': len(finished) / len(mine), 'finished_wilson95': wilson_interval(len(finished), len(mine)),
            'under_10cm': len(good), 'under_10cm_share': len(good) / len(mine),
            'under_10cm_wilson95': wilson_interval(len(good), len(mine)),
            'rmse_p50_cm': p50.value, 'rmse_p50_ci95_cm': (p50.low, p50.high),
            'rmse_p95_cm': p95.value, 'rmse_p95_ci95_cm': (p95.low, p95.high),
            'chattering_force_p50': float(np.percentile(force, 50)) if force else math.nan,
            'chattering_moment_p50': float(np.percentile(moments, 50)) if moments else math.nan}


def kind_records(by_seed: dict[int, list[dict]]) -> list[dict]:
    return [kind_record(controller, seed, mine)
            for controller in controllers_of(by_seed) for seed, rows in groups(by_seed)
            if (mine := [row for row in rows if row['controller'] == controller])]


def paired_records(by_seed: dict[int, list[dict]], reference: str = REFERENCE) -> list[dict]:
    """Every other controller against ``reference``, per seed and pooled (pairs are within a seed)."""
    out = []
    for controller in controllers_of(by_seed):
        if controller == reference:
            continue
        for seed, rows in groups(by_seed):
            mine = [row for row in rows if row['controller'] == controller]
            theirs = [row for row in rows if row['controller'] == reference]
            if not mine or not theirs:
                continue
            if seed == ALL_SEEDS:     # a flight is (seed, index): keep the seeds apart while pairing
                mine = [{**row, 'flight': (row['_seed'], row['flight'])} for row in mine]
                theirs = [{**row, 'flight': (row['_seed'], row['flight'])} for row in theirs]
            p = paired(mine, theirs)
            out.append({'controller': controller, 'reference': reference, 'seed': seed, 'pairs': p.pairs,
                        'controller_better_share': p.kind_better_share,
                        'reference_better_share': p.reference_better_share, 'ties': p.ties,
                        'median_difference_cm': 100.0 * p.median_difference.value,
                        'median_difference_ci95_cm': (100.0 * p.median_difference.low,
                                                      100.0 * p.median_difference.high),
                        'sign_test_p': p.sign_test_p})
    return out


def cm(value: float, signed: bool = False) -> str:
    """A table cell of ``value`` [cm]: two decimals (with its sign if ``signed``: a paired difference), or why
    there is no number (too few flights for the interval, a failed flight)."""
    if math.isnan(value):
        return 'none (too few flights)'
    if math.isinf(value) and signed:
        return '+inf (it failed)' if value > 0 else '-inf (the reference failed)'
    if math.isinf(value):
        return 'failed' if value > 0 else '-inf'
    return f'{value:+.2f}' if signed else f'{value:.2f}'


def kind_lines(records: list[dict]) -> list[str]:
    lines = ['| controller | seed | flights | finished | 95 % interval | finished with RMSE < 10 cm | 95 % interval | '
             'RMSE p50 [cm] (95 % interval) | RMSE p95 [cm] (95 % interval) | '
             'chattering p50: U1 [N/s] / moments [N m/s] |',
             '|---|---:|---:|---:|---|---:|---|---|---|---|']
    for r in records:
        (low, high), (good_low, good_high) = r['finished_wilson95'], r['under_10cm_wilson95']
        chattering = ('-' if math.isnan(r['chattering_force_p50'])
                      else f'{r["chattering_force_p50"]:.3g} / {r["chattering_moment_p50"]:.3g}')
        lines.append(f'| {r["controller"]} | {r["seed"]} | {r["flights"]} | {100 * r["finished_share"]:.1f} % | '
                     f'{100 * low:.1f} - {100 * high:.1f} % | {100 * r["under_10cm_share"]:.1f} % | '
                     f'{100 * good_low:.1f} - {100 * good_high:.1f} % | '
                     f'{cm(r["rmse_p50_cm"])} ({cm(r["rmse_p50_ci95_cm"][0])} - {cm(r["rmse_p50_ci95_cm"][1])}) | '
                     f'{cm(r["rmse_p95_cm"])} ({cm(r["rmse_p95_ci95_cm"][0])} - {cm(r["rmse_p95_ci95_cm"][1])}) | '
                     f'{chattering} |')
    return lines


def p_value(p: float) -> str:
    """A p-value's cell: two significant digits, or '< 1e-300' where it is below what a float holds (0)."""
    return '< 1e-300' if p == 0.0 else f'{p:.2g}'


def paired_lines(records: list[dict]) -> list[str]:
    reference = records[0]['reference'] if records else REFERENCE
    lines = [f'| controller | seed | pairs | it beats {reference} | {reference} beats it | ties | '
             f'median of RMSE - RMSE({reference}) [cm] (95 % interval) | sign test p |',
             '|---|---:|---:|---:|---:|---:|---|---:|']
    for r in records:
        low, high = r['median_difference_ci95_cm']
        lines.append(f'| {r["controller"]} | {r["seed"]} | {r["pairs"]} | {100 * r["controller_better_share"]:.1f} % | '
                     f'{100 * r["reference_better_share"]:.1f} % | {r["ties"]} | '
                     f'{cm(r["median_difference_cm"], True)} ({cm(low, True)} - {cm(high, True)}) | '
                     f'{p_value(r["sign_test_p"])} |')
    return lines


#: the actuator columns a world may draw per flight: column, name, unit scale, unit
ACTUATOR_COLUMNS = (('motor_time_constant_s', 'motor time constant', 1000.0, 'ms'), ('delay_s', 'delay', 1000.0, 'ms'))


def actuator_lines(by_seed: dict[int, list[dict]]) -> list[str]:
    """Where the flights failed, by the actuator each drew (all seeds pooled): per controller, the failed flights
    of each third of the drawn range of every actuator column that varies, and of the flights in the top third
    of all of them (the slowest rotors with the longest delays). No lines if no column varies (one actuator)."""
    rows = [row for seed in sorted(by_seed) for row in by_seed[seed]]
    drawn = [c for c in ACTUATOR_COLUMNS if len({row.get(c[0]) for row in rows}) > 1 and all(c[0] in r for r in rows)]
    if not drawn:
        return []

    ranges = {column: (min(r[column] for r in rows), max(r[column] for r in rows)) for column, *_ in drawn}

    def third(column: str, value: float) -> int:
        low, high = ranges[column]
        return min(2, int(3 * (value - low) / (high - low)))
    bins = {}       # (column, third) -> its label from the values drawn in it
    for column, _, scale, unit in drawn:
        for index in range(3):
            values = [r[column] * scale for r in rows if third(column, r[column]) == index]
            bins[column, index] = f'{min(values):.3g}-{max(values):.3g} {unit}' if values else 'none'
    header = ['controller'] + [f'{name} {bins[column, i]}' for column, name, _, _ in drawn for i in range(3)]
    header.append('top third of ' + (' and '.join(name for _, name, _, _ in drawn)))
    lines = ['| ' + ' | '.join(header) + ' |', '|---|' + '---:|' * (len(header) - 1)]

    def failed(mine: list[dict]) -> str:
        return f'{sum(not r["finished"] for r in mine)}/{len(mine)}' if mine else '-'
    for controller in controllers_of(by_seed):
        mine = [r for r in rows if r['controller'] == controller]
        cells = [failed([r for r in mine if third(column, r[column]) == i]) for column, *_ in drawn for i in range(3)]
        cells.append(failed([r for r in mine if all(third(column, r[column]) == 2 for column, *_ in drawn)]))
        lines.append(f'| {controller} | ' + ' | '.join(cells) + ' |')
    return lines


def write_csv(records: list[dict], path: Path) -> Path:
    """The records as CSV, an interval as two columns (``_low``, ``_high``)."""
    flat = []
    for record in records:
        row = {}
        for key, value in record.items():
            if isinstance(value, tuple):
                row[f'{key}_low'], row[f'{key}_high'] = value
            else:
                row[key] = value
        flat.append(row)
    with path.open('w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=list(flat[0]) if flat else ['controller'], lineterminator='\n')
        writer.writeheader()
        writer.writerows(flat)
    return path


def read_all(folders, first: int | None = None) -> dict[int, list[dict]]:
    """:func:`load`, each row tagged with its seed (``_seed``) for pooling."""
    return {seed: [{**row, '_seed': seed} for row in rows] for seed, rows in load(folders, first).items()}


def table(folders, first: int | None = None) -> list[str]:
    """The per-controller table's lines; ``first``: only flights 0..first-1 of each folder (the same
    vehicles for every controller of a seed: a paired comparison with a campaign flown with fewer flights)."""
    return kind_lines(kind_records(read_all(folders, first)))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('folders', nargs='+', type=Path, help='campaign output folders')
    parser.add_argument('--first', type=int, default=None, help='only flights 0..N-1 of each folder')
    parser.add_argument('--reference', default=REFERENCE,
                        help=f'the paired comparison\'s reference (default {REFERENCE})')


def run(args: argparse.Namespace) -> int:
    progress(STUDY, f'reading {len(args.folders)} campaign folders')
    by_seed = read_all(args.folders, args.first)
    lines = kind_lines(kind_records(by_seed))
    pairs = paired_records(by_seed, args.reference)
    if pairs:
        lines += [''] + paired_lines(pairs)
    actuator = actuator_lines(by_seed)
    if actuator:
        lines += ['', 'Failed flights by the actuator each drew (failed/flights, all seeds):', ''] + actuator
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
