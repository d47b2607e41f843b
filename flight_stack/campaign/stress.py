"""``run_stack.py stress SPEC --kind KIND --controllers LIST --flights M --out DIR``: each controller's
breaking point under one disturbance (docs/TUNING.md, "Breaking points").

A try is a campaign (flown by the campaign runner: its workers, or a Dask cluster with ``--scheduler``)
whose spec is SPEC with one disturbance fixed at an intensity, every flight the same:

========== ============================================== =========================================
kind       intensity                                      the spec it flies
========== ============================================== =========================================
wind       steady (mean) wind speed [m/s]                 ``wind.mean_speed_mps`` (turbulence, direction as SPEC)
mass       true mass / nominal mass [-]                   ``vehicle.mass: {dist: fixed, value: x - 1}``
rotor-loss one rotor's efficiency loss [-] (rotor 1)      ``vehicle.one_rotor_efficiency_loss: {dist: fixed, value: x}``
delay      transport delay [s] (whole control steps)      ``delay_s``
motor-lag  motor time constant [s]                        ``motor_time_constant_s``
noise      sensor noise scale [-]                         every ``sensor_noise`` std and bias std times x
                                                          (SPEC's; :data:`DEFAULT_NOISE` if it has none)
========== ============================================== =========================================

An intensity must mean something: at least 0 (wind, delay, motor lag, noise), above 0 (mass), in [0, 1)
(rotor loss); ``--low`` and ``--high`` outside are refused (:meth:`DisturbanceKind.check`) before any flight.

A flight succeeds when it finishes with a position RMSE below 10 cm. The breaking point is the
intensity where the success share falls below 90 %: found by bisection between the range's ends
(success assumed to fall as the intensity grows), to the kind's resolution. Each try's share comes
with its 95 % Wilson interval; the point is 'found' only when the intervals at the two bracketing
tries do not straddle 90 %, else it is a 'range' (:class:`BreakingPoint`). Tries are kept in ``DIR/<kind>/<controller>/<intensity>/`` (campaign
folders), so the same command again reuses every campaign it finished.
"""
from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from quad_msgs_bridge.validation import ParameterError, check_number

from .batch import CampaignSetup
from .results import FLIGHTS_FILE, read_flights, wilson_interval
from .runner import RunOptions, holds_campaign, run_campaign
from .spec import CampaignSpec, Distribution, NoiseLevel

SUCCESS_RMSE_M = 0.10           #: a flight succeeds when it finishes with a position RMSE below this [m]
BREAKING_SHARE = 0.90           #: the breaking point: where the success share falls below this
BREAKING_POINTS_FILE = 'breaking_points.csv'
#: the noise the ``noise`` kind scales when SPEC has none: campaigns/paper-robustness.yaml's std devs
DEFAULT_NOISE = {'position_m': NoiseLevel(0.01), 'velocity_mps': NoiseLevel(0.02),
                 'attitude_rad': NoiseLevel(0.01), 'body_rate_radps': NoiseLevel(0.02)}


def _wind(spec: CampaignSpec, x: float) -> CampaignSpec:
    return replace(spec, wind_mean_speed_mps=x)


def _vehicle(key: str, offset: float):
    return lambda spec, x: replace(spec, vehicle={**spec.vehicle, key: Distribution('fixed', x - offset)})


def _noise(spec: CampaignSpec, x: float) -> CampaignSpec:
    levels = spec.sensor_noise or DEFAULT_NOISE
    return replace(spec, sensor_noise={key: NoiseLevel(level.std * x, level.bias_std * x)
                                       for key, level in levels.items()})


@dataclass(frozen=True)
class DisturbanceKind:
    """One disturbance: what its intensity is, its default search range and resolution, its spec."""

    name: str
    intensity: str                  #: what the intensity is, with its unit
    low: float
    high: float
    resolution: float               #: bisection stops when the bracket is this narrow
    fixed: Callable[[CampaignSpec, float], CampaignSpec]
    #: the intensities that mean something: (lowest, highest, lowest included, highest included)
    valid: tuple[float, float, bool, bool] = (0.0, math.inf, True, True)

    def check(self, option: str, intensity: float) -> float:
        """``intensity`` if it lies in :attr:`valid`, else ParameterError naming ``option``, the kind and the
        valid range."""
        return check_number(f'{option} (--kind {self.name}: {self.intensity})', intensity, *self.valid)


KINDS = {kind.name: kind for kind in (
    DisturbanceKind('wind', 'steady wind speed [m/s]', 0.0, 20.0, 0.25, _wind),
    DisturbanceKind('mass', 'true mass / nominal mass [-]', 1.0, 3.0, 0.02, _vehicle('mass', 1.0),
                    (0.0, math.inf, False, True)),
    DisturbanceKind('rotor-loss', "one rotor's efficiency loss [-]", 0.0, 0.95, 0.01,
                    _vehicle('one_rotor_efficiency_loss', 0.0), (0.0, 1.0, True, False)),
    DisturbanceKind('delay', 'transport delay [s]', 0.0, 0.1, 0.001,
                    lambda spec, x: replace(spec, delay_s=x)),
    DisturbanceKind('motor-lag', 'motor time constant [s]', 0.0, 0.5, 0.005,
                    lambda spec, x: replace(spec, motor_time_constant_s=x)),
    DisturbanceKind('noise', 'sensor noise scale [-]', 0.0, 20.0, 0.1, _noise),
)}


@dataclass(frozen=True)
class Tally:
    """The flights of one try: how many, how many succeeded."""

    successes: int
    flights: int

    @property
    def share(self) -> float:
        return self.successes / self.flights if self.flights else 0.0

    @property
    def interval(self) -> tuple[float, float]:
        """95 % Wilson score interval of the success share."""
        return wilson_interval(self.successes, self.flights)

    @property
    def holds(self) -> bool:
        return self.share >= BREAKING_SHARE

    @property
    def surely_holds(self) -> bool:
        """The whole 95 % interval is at or above 90 %."""
        return self.interval[0] >= BREAKING_SHARE

    @property
    def surely_fails(self) -> bool:
        """The whole 95 % interval is below 90 %."""
        return self.interval[1] < BREAKING_SHARE


def tally(rows: list[dict]) -> Tally:
    """Success (finished with RMSE below 10 cm) over the flights.csv rows of one try."""
    return Tally(sum(1 for r in rows if r['finished'] and r['rmse_position_m'] < SUCCESS_RMSE_M), len(rows))


@dataclass(frozen=True)
class BreakingPoint:
    """Where the success share of one controller falls below 90 % (see :attr:`status`).

    ``status``: 'found' when the bisection's bracket is sure: the whole 95 % Wilson interval of the share at
    ``low`` is at or above 90 % and the whole one at ``high`` below it; 'range' when the bisection ended
    but one of those intervals straddles 90 % (too few flights per try to tell the point to the
    resolution: it lies in :meth:`bounds`); 'above_range' (none found: holds at ``high``) or
    'at_or_below_low' when the range's ends did not bracket it."""

    status: str        #: 'found' | 'range' | 'above_range' | 'at_or_below_low'
    low: float         #: the highest intensity tried where it holds (nan if none)
    high: float        #: the lowest intensity tried where it fails (nan if none)
    tries: dict        #: intensity -> Tally

    @property
    def value(self) -> float:
        """The breaking point: the lowest intensity tried where the share is below 90 % (a bound, not a
        value, unless ``status`` is 'found'; for 'range' the point estimate within :meth:`bounds`)."""
        return self.high if self.status != 'above_range' else self.low

    def bounds(self) -> tuple[float, float]:
        """Where the breaking point surely lies, as far as the tries tell: (the highest intensity tried whose
        whole 95 % interval is at or above 90 %, the lowest whose whole interval is below it), nan where no
        try is that sure (the point may then lie beyond the intensities tried)."""
        sure_holds = [x for x, t in self.tries.items() if t.surely_holds]
        sure_fails = [x for x, t in self.tries.items() if t.surely_fails]
        return (max(sure_holds) if sure_holds else math.nan, min(sure_fails) if sure_fails else math.nan)

    def interval_at(self, intensity: float) -> tuple[float, float]:
        """The 95 % Wilson interval of the share at a tried ``intensity`` ((nan, nan) for nan: none tried)."""
        return self.tries[intensity].interval if intensity in self.tries else (math.nan, math.nan)


def snap(value: float, resolution: float) -> float:
    """``value`` on the grid of ``resolution`` (so tries reuse folders and delays are whole steps)."""
    return round(round(value / resolution) * resolution, 12)


def find_breaking_point(rate_at: Callable[[float], Tally], low: float, high: float,
                        resolution: float) -> BreakingPoint:
    """Bisect [low, high] for the intensity where ``rate_at(x)`` falls below 90 %, to ``resolution``; the
    intensities tried lie on the grid low + k resolution (and at ``high``)."""
    if not low < high or resolution <= 0.0:
        raise ParameterError(f'stress range: need low < high and resolution > 0 (got {low:g}, {high:g}, '
                             f'{resolution:g})')
    tries = {}

    def tried(x: float) -> Tally:
        if x not in tries:
            tries[x] = rate_at(x)
        return tries[x]

    if not tried(low).holds:
        return BreakingPoint('at_or_below_low', math.nan, low, tries)
    if tried(high).holds:
        return BreakingPoint('above_range', high, math.nan, tries)
    start = low
    while high - low > resolution * (1.0 + 1e-9):
        middle = start + snap(0.5 * (low + high) - start, resolution)
        if not low < middle < high:
            break
        if tried(middle).holds:
            low = middle
        else:
            high = middle
    sure = tries[low].surely_holds and tries[high].surely_fails
    return BreakingPoint('found' if sure else 'range', low, high, tries)


@dataclass(frozen=True)
class StressSetup:
    spec: CampaignSpec               #: SPEC with the flights (and duration) overridden
    kind: DisturbanceKind
    controllers: tuple[str, ...]
    out_dir: Path
    options: RunOptions
    low: float
    high: float
    resolution: float


def try_folder(setup: StressSetup, controller: str, intensity: float) -> Path:
    return setup.out_dir / setup.kind.name / controller / f'{intensity:.6g}'


def fly_try(setup: StressSetup, controller: str, intensity: float) -> Tally:
    """One try: SPEC with the disturbance fixed at ``intensity``, flown by ``controller`` (resumed if its
    folder holds part of it)."""
    spec = replace(setup.kind.fixed(setup.spec, intensity), controllers=(controller,))
    folder = try_folder(setup, controller, intensity)
    run_campaign(spec, folder, replace(setup.options, resume=holds_campaign(folder), progress=False, report=False))
    return tally(read_flights(folder / FLIGHTS_FILE))


def stress(setup: StressSetup, progress: bool = True) -> dict[str, BreakingPoint]:
    """Every controller's breaking point; writes breaking_points.csv, the tries table and the plot."""
    say = (lambda text: print(text, file=sys.stderr, flush=True)) if progress else (lambda text: None)
    kind = setup.kind
    results = {}
    for controller in setup.controllers:
        def rate_at(x: float, controller=controller) -> Tally:
            result = fly_try(setup, controller, x)
            low, high = result.interval
            say(f'stress {kind.name}: {controller} at {x:g}: {result.successes}/{result.flights} succeed '
                f'({result.share:.0%}, 95 % {low:.0%}-{high:.0%})')
            return result
        results[controller] = find_breaking_point(rate_at, setup.low, setup.high, setup.resolution)
        say(f'stress {kind.name}: {controller}: {describe(results[controller], kind)}')
    tries = write_tries(setup, results)
    write_breaking_points(setup, results)
    plot_success(setup, read_tries(tries))
    return results


def _percent(interval: tuple[float, float]) -> str:
    return f'{interval[0]:.0%}-{interval[1]:.0%}'


def describe(point: BreakingPoint, kind: DisturbanceKind) -> str:
    if point.status == 'found':
        return (f'breaking point {point.high:g} ({kind.intensity}): below {BREAKING_SHARE:.0%} there, '
                f'at or above it at {point.low:g}')
    if point.status == 'range':
        sure_low, sure_high = point.bounds()
        where = ' and '.join([*([f'above {sure_low:g}'] if math.isfinite(sure_low) else []),
                              *([f'at or below {sure_high:g}'] if math.isfinite(sure_high) else [])])
        return (f'a range, not a point: {where or "no try is sure of either side"} ({kind.intensity}); the '
                f'share falls below {BREAKING_SHARE:.0%} between {point.low:g} and {point.high:g}, but the 95 % '
                f'intervals there ({_percent(point.interval_at(point.low))}, '
                f'{_percent(point.interval_at(point.high))}) straddle {BREAKING_SHARE:.0%}: more flights per try '
                'narrow it')
    if point.status == 'above_range':
        return f'no breaking point up to {point.low:g} ({kind.intensity}): a lower bound, none found'
    return f'already below {BREAKING_SHARE:.0%} at {point.high:g} ({kind.intensity}): an upper bound'


TRIES_COLUMNS = ('kind', 'controller', 'intensity', 'flights', 'successes', 'success_share', 'wilson95_low',
                 'wilson95_high')


def write_tries(setup: StressSetup, results: dict[str, BreakingPoint]) -> Path:
    """``DIR/stress-<kind>.csv``: every try (controller, intensity, flights, successes, share, interval); the
    rows of controllers not searched this time stay (a search run controller by controller keeps them all)."""
    path = setup.out_dir / f'stress-{setup.kind.name}.csv'
    kept = []
    if path.exists():
        with path.open(newline='') as stream:
            kept = [[row[c] for c in TRIES_COLUMNS] for row in csv.DictReader(stream)
                    if row['controller'] not in results]
    with path.open('w', newline='') as stream:
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(TRIES_COLUMNS)
        writer.writerows(kept)
        for controller, point in results.items():
            for x in sorted(point.tries):
                t = point.tries[x]
                writer.writerow([setup.kind.name, controller, x, t.flights, t.successes, t.share, *t.interval])
    return path


BREAKING_COLUMNS = ('kind', 'controller', 'intensity', 'status', 'breaking_point', 'holds_at', 'fails_at',
                    'range_low', 'range_high', 'holds_at_wilson95_low', 'holds_at_wilson95_high',
                    'fails_at_wilson95_low', 'fails_at_wilson95_high', 'flights_per_try', 'tries', 'success_rmse_m',
                    'breaking_share', 'note')


def write_breaking_points(setup: StressSetup, results: dict[str, BreakingPoint]) -> Path:
    """``DIR/breaking_points.csv``: a row per (kind, controller); rows of other kinds already there stay."""
    path = setup.out_dir / BREAKING_POINTS_FILE
    kept = []
    if path.exists():
        with path.open(newline='') as stream:
            kept = [row for row in csv.DictReader(stream)
                    if not (row.get('kind') == setup.kind.name and row.get('controller') in results)]
    rows = kept + [{
        'kind': setup.kind.name, 'controller': controller, 'intensity': setup.kind.intensity,
        'status': point.status, 'breaking_point': point.value,
        'holds_at': point.low, 'fails_at': point.high, **dict(zip(('range_low', 'range_high'), point.bounds())),
        **dict(zip(('holds_at_wilson95_low', 'holds_at_wilson95_high'), point.interval_at(point.low))),
        **dict(zip(('fails_at_wilson95_low', 'fails_at_wilson95_high'), point.interval_at(point.high))),
        'flights_per_try': setup.spec.flights,
        'tries': len(point.tries), 'success_rmse_m': SUCCESS_RMSE_M, 'breaking_share': BREAKING_SHARE,
        'note': describe(point, setup.kind)} for controller, point in results.items()]
    with path.open('w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=BREAKING_COLUMNS, lineterminator='\n')
        writer.writeheader()
        writer.writerows(rows)
    return path


def read_tries(path: Path) -> dict[str, dict[float, Tally]]:
    """{controller: {intensity: Tally}} from a ``DIR/stress-<kind>.csv`` (:func:`write_tries`)."""
    tries: dict[str, dict[float, Tally]] = {}
    with path.open(newline='') as stream:
        for row in csv.DictReader(stream):
            tries.setdefault(row['controller'], {})[float(row['intensity'])] = Tally(int(row['successes']),
                                                                                     int(row['flights']))
    return tries


def plot_success(setup: StressSetup, tries: dict[str, dict[float, Tally]]) -> Path | None:
    """``DIR/stress-<kind>.png``: success share against intensity, a curve per controller ({controller:
    {intensity: Tally}}, :func:`read_tries`) with its 95 % Wilson interval, the 90 % line; None (said)
    without matplotlib."""
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        print('stress: no plot (pip install matplotlib)', file=sys.stderr)
        return None
    figure, axes = plt.subplots(figsize=(7, 4.2))
    for controller, tried in tries.items():
        xs = sorted(tried)
        shares = [tried[x].share for x in xs]
        # the interval's ends as distances from the share (rounding may put an end a hair past it)
        below = [max(0.0, share - tried[x].interval[0]) for x, share in zip(xs, shares)]
        above = [max(0.0, tried[x].interval[1] - share) for x, share in zip(xs, shares)]
        axes.errorbar(xs, shares, yerr=[below, above], marker='o', capsize=3, label=controller)
    axes.axhline(BREAKING_SHARE, color='grey', linestyle='--', linewidth=1, label=f'{BREAKING_SHARE:.0%}')
    axes.set_xlabel(setup.kind.intensity)
    axes.set_ylabel(f'share finished with RMSE < {SUCCESS_RMSE_M * 100:g} cm')
    axes.set_ylim(-0.02, 1.02)
    axes.set_title(f'{setup.kind.name}: {setup.spec.flights} flights per point (95 % Wilson intervals)')
    axes.legend()
    figure.tight_layout()
    path = setup.out_dir / f'stress-{setup.kind.name}.png'
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def resolution_for(kind: DisturbanceKind, spec: CampaignSpec, options: RunOptions) -> float:
    """The kind's resolution; for the delay, a whole number of the campaign's control steps."""
    if kind.name != 'delay':
        return kind.resolution
    control_dt = CampaignSetup.of(spec, options.vehicle_file, options.gains_file).control_dt
    return max(1, round(kind.resolution / control_dt)) * control_dt


def highest_intensity(kind: DisturbanceKind, spec: CampaignSpec, options: RunOptions, resolution: float) -> float:
    """The highest intensity a try can fly: for the mass, the last grid point below the rotors' hover
    limit (a true vehicle the four rotors cannot hold up at full thrust, 4 F_max <= m g, is refused as a
    vehicle, not flown); the kind's range elsewhere."""
    if kind.name != 'mass':
        return math.inf
    nominal = CampaignSetup.of(spec, options.vehicle_file, options.gains_file).nominal
    ratio = 4.0 * nominal.F_max / (nominal.m * nominal.g)
    return math.ceil(ratio / resolution - 1.0) * resolution
