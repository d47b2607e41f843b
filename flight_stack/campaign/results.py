"""``flights.csv`` (one row per flight and controller, appended batch by batch) and ``campaign.json``.

The CSV is written with full float precision (``repr``), so a flight's metrics read back equal the
numbers that were computed; a campaign interrupted between two batches leaves every finished batch
in it, and ``--resume`` flies only the (flight, controller) pairs it lacks.
"""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

FLIGHTS_FILE = 'flights.csv'
SUMMARY_FILE = 'campaign.json'
PERCENTILES = (50, 95, 99)
WILSON_Z = 1.959963984540054   #: two-sided 95 % standard normal quantile
TEXT_COLUMNS = ('controller', 'failure')
BOOL_COLUMNS = ('finished',)
INT_COLUMNS = ('flight', 'control_steps')


class FlightsFile:
    """Appends rows to ``DIR/flights.csv``, each batch flushed and synced to disk before the next."""

    def __init__(self, path: Path, columns: Sequence[str]):
        self.path = path
        self.columns = list(columns)
        new = not path.exists() or path.stat().st_size == 0
        if not new:
            with path.open(newline='') as stream:
                header = next(csv.reader(stream), [])
            if header != self.columns:
                raise ValueError(f'{path}: its columns differ from this campaign\'s (another version or spec?); '
                                 'use another --out')
        self._stream = path.open('a', newline='')
        self._writer = csv.DictWriter(self._stream, fieldnames=self.columns, lineterminator='\n')
        if new:
            self._writer.writeheader()
            self._sync()

    def append(self, rows: Iterable[dict]) -> None:
        for row in rows:
            self._writer.writerow({key: repr(value) if isinstance(value, float) else value
                                   for key, value in row.items()})
        self._sync()

    def _sync(self) -> None:
        self._stream.flush()
        os.fsync(self._stream.fileno())

    def close(self) -> None:
        self._stream.close()


def read_flights(path: Path) -> list[dict]:
    """Rows of a flights.csv with their types back (floats, ints, bools, text); a torn last line
    (a campaign killed while writing) is left out."""
    if not path.exists():
        return []
    rows = []
    with path.open(newline='') as stream:
        reader = csv.DictReader(stream)
        for raw in reader:
            if None in raw.values() or None in raw:          # a line cut short by a kill
                continue
            rows.append({key: _typed(key, value) for key, value in raw.items()})
    return rows


def _typed(key: str, value: str):
    if key in TEXT_COLUMNS:
        return value
    if key in BOOL_COLUMNS:
        return value == 'True'
    if key in INT_COLUMNS:
        return int(value)
    return float(value)


def wilson_interval(successes: int, trials: int, z: float = WILSON_Z) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % by default); (0, 1) for no trial."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2.0 * trials)) / denominator
    half = z * math.sqrt(p * (1.0 - p) / trials + z * z / (4.0 * trials * trials)) / denominator
    return max(0.0, centre - half), min(1.0, centre + half)


def _percentiles(values: list[float]) -> dict:
    if not values:
        return {f'p{q}': None for q in PERCENTILES} | {'max': None}
    array = np.asarray(values, dtype=float)
    return {f'p{q}': float(np.percentile(array, q)) for q in PERCENTILES} | {'max': float(array.max())}


def summarize(rows: list[dict], controllers: Sequence[str]) -> dict:
    """Per controller: success rate with its 95 % Wilson interval, failures by reason, and the
    percentiles (p50, p95, p99, max) of RMSE, max error and the force [N/s] and moment [N m/s]
    chattering over finished flights."""
    table = {}
    for controller in controllers:
        mine = [r for r in rows if r['controller'] == controller]
        finished = [r for r in mine if r['finished']]
        low, high = wilson_interval(len(finished), len(mine))
        failures: dict[str, int] = {}
        for r in mine:
            if not r['finished']:
                failures[r['failure']] = failures.get(r['failure'], 0) + 1
        table[controller] = {
            'flights': len(mine),
            'finished': len(finished),
            'success_rate': len(finished) / len(mine) if mine else None,
            'success_rate_wilson95': [low, high],
            'failures': failures,
            'rmse_position_m': _percentiles([r['rmse_position_m'] for r in finished]),
            'max_position_error_m': _percentiles([r['max_position_error_m'] for r in finished]),
            'chattering_force_n_per_s': _percentiles([r['chattering_force_n_per_s'] for r in finished]),
            'chattering_moment_nm_per_s': _percentiles([r['chattering_moment_nm_per_s'] for r in finished]),
        }
    return table
