"""The scoreboard tables of docs/SCOREBOARD.md and the README: tuned kinds on held-out seeds, breaking points.

Issue 26's scoreboard: every kind with its tuned gains, on the held-out seeds, under every disturbance, with
its nominal, noise and delay-margin figures.

    # 1. the tuned points (run_stack.py tune ... --out ROOT/tune-KIND) become the packaged gains
    run_stack.py study scoreboard package /work/scoreboard --trials-to docs/tuning
    # 2. what the run will cost on this machine, measured (a few flights per kind), and the plan
    run_stack.py study scoreboard plan
    # 3. fly it (resumable: the same command again continues), write the tables and docs/SCOREBOARD.md
    run_stack.py study scoreboard run --out out/scoreboard --markdown docs/SCOREBOARD.md
    # tables only, from what DIR holds
    run_stack.py study scoreboard tables out/scoreboard --markdown docs/SCOREBOARD.md

``run`` flies, with one gains file (default: the packaged one, which after ``package`` holds every kind's
tuned gains; they do not collide, tests/test_tune_stress.py):

* **held out**: ``SPEC`` (default campaigns/paper-robustness-drawn-actuator.yaml, the actuator drawn per flight,
  at ``--duration`` 30 s, the tuning's) on the seeds 101-103, ``--flights`` 1,000 each, one campaign folder per
  seed and kind (``DIR/heldout/seed-S/KIND``; checked to fly the same perturbed flights: the heldout study); the tables
  of the heldout study: per kind and the paired comparison against the NNIT2FSMC;
* **breaking points**: ``run_stack.py stress SPEC --kind D`` for every disturbance D of
  flight_stack/campaign/stress.py and every kind, ``--stress-flights`` flights of ``--stress-duration`` s per try
  (``DIR/stress``);
* **nominal and noise rows**: the paper-tables study's nominal and noise experiments on the paper helix
  (``--nominal-duration`` s);
* **delay margins**: the margins study's ``delay_margins`` (ideal rotors and 30 ms motor lag, to 0.25 ms).

Writes ``DIR/heldout.csv``, ``DIR/paired.csv``, ``DIR/stress/breaking_points.csv`` (and its tries and plots),
``DIR/margins.csv``, ``DIR/nominal_noise.md`` and ``DIR/SCOREBOARD.md``; ``--markdown FILE`` also puts the
tables between the generated-section markers of FILE. ``DIR/scoreboard.json`` keeps the settings and the
gains' digest: a run with other gains or settings in the same DIR is refused.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from flight_stack.campaign.results import FLIGHTS_FILE
from flight_stack.campaign.runner import RunOptions, holds_campaign, run_campaign
from flight_stack.campaign.spec import load_spec
from flight_stack.campaign.stress import BREAKING_POINTS_FILE, KINDS as DISTURBANCES
from flight_stack.campaign.tune import OBJECTIVES, REQUIRED_FINISHED_SHARE
from nnit2fsmc_controller.registry import check_controller
from nnit2fsmc_controller.factory import DEFAULT_CONTROLLER_FILE, flatten_gains, load_gains, locate_gains
from nnit2fsmc_controller.search_spaces import search_space, values_in, with_values
from quad_msgs_bridge.validation import ParameterError

from . import heldout, margins, paper_tables
from .common import add_out, names, progress, run_all, study_name

STUDY = study_name(__name__)

KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'l1-se3', 'indi')
#: the world: the example campaign with the actuator drawn per flight (issue 37; the fixed one is --spec
#: campaigns/paper-robustness.yaml)
SPEC = 'campaigns/paper-robustness-drawn-actuator.yaml'
HELDOUT_SEEDS = (101, 102, 103)
SETTINGS_FILE = 'scoreboard.json'
#: the header lines ``package`` writes (and replaces when run again): where each kind's tuned point came from
#: (as the packaged gains file holds them since issue 26: a changed prefix would no longer replace those lines)
PROVENANCE = '# Tuned (issue 26; bench/scoreboard.py package, docs/SCOREBOARD.md): '
MARKERS = ('<!-- scoreboard:begin (run_stack.py study scoreboard writes this section) -->', '<!-- scoreboard:end -->')
#: flights of a delay margin: the undelayed flight, the range's end, then bisection of 0.064 s to 0.25 ms
#: (8 halvings), for ideal rotors and the 30 ms lag
MARGIN_FLIGHTS = 2 * (2 + 8)


# --- 1. package: each kind's best accepted tuned point onto the packaged gains file ----------------------

def ranked_points(trials_csv: Path, kind: str, pick: str | None = None) -> list[tuple[dict, dict]]:
    """[(point {dimension: value}, its row)] of every complete trial of a ``run_stack.py tune`` trials table,
    best first, the earlier trial on a tie (as Optuna's best trial). ``pick`` None: by the study's objective;
    ``median`` or ``p95``: by that statistic under the tuning's rule (tune.penalised: a trial that finished
    99 % of its flights by the statistic, then the others by their finished share), among the trials flown on
    every seed, as ``tune`` writes ``gains-KIND-median.yaml`` and ``gains-KIND-p95.yaml``."""
    with trials_csv.open(newline='') as stream:
        rows = [row for row in csv.DictReader(stream) if row['state'] == 'complete']
    if pick is not None:
        rows = _flown_on_every_seed(trials_csv, rows, pick)
    if not rows:
        raise ParameterError(f'{trials_csv}: no complete trial')

    def rank(row: dict) -> tuple:
        if pick is None:
            return (float(row['objective_m']), int(row['trial']))
        share = int(row['finished']) / int(row['flights'])
        if share >= REQUIRED_FINISHED_SHARE:
            return (0, float(row[f'{pick}_rmse_m']), int(row['trial']))
        return (1, -share, int(row['trial']))
    rows.sort(key=rank)
    names = [d.name for d in search_space(kind)]
    missing = [name for name in names if name not in rows[0]]
    if missing:
        raise ParameterError(f'{trials_csv}: no column {missing[0]} ({kind}\'s search space: {", ".join(names)})')
    return [({name: float(row[name]) for name in names}, row) for row in rows]


def _flown_on_every_seed(trials_csv: Path, rows: list[dict], pick: str) -> list[dict]:
    """The ``rows`` flown on every seed that record the statistic ``pick`` (``median``, ``p95``)."""
    if pick not in OBJECTIVES:
        raise ParameterError(f'--pick: {pick!r} is not one of {", ".join(OBJECTIVES)}')
    if rows and f'{pick}_rmse_m' not in rows[0]:
        raise ParameterError(f'{trials_csv}: no column {pick}_rmse_m (--pick {pick} needs a table that records it)')
    seeds = max((int(row['seeds_flown'] or 0) for row in rows), default=0)
    return [row for row in rows if int(row['seeds_flown'] or 0) == seeds and row[f'{pick}_rmse_m'] not in ('', 'nan')]


#: what a tuned point must also do before it is packaged: the ``hover`` scenario (a 1 m take-off step,
#: which the campaign's slowly climbing helix never asks for) on every shipped vehicle, with its section IV
#: disturbances, for ACCEPTANCE_DURATION_S, ending within ACCEPTANCE_ERROR_M of the hover point and not failed
ACCEPTANCE_SCENARIO, ACCEPTANCE_DURATION_S, ACCEPTANCE_ERROR_M = 'hover', 14.0, 0.10


def hover_acceptance(kind: str, gains: dict) -> str | None:
    """None if ``kind`` with ``gains`` (a whole gains tree) passes the acceptance on every shipped vehicle,
    else what failed ('x500: flipped over at 0.31 s')."""
    from flight_stack.api import fly
    from quad_msgs_bridge.vehicle_params import shipped_vehicles
    for vehicle in shipped_vehicles():
        flight = fly(kind, ACCEPTANCE_SCENARIO, duration=ACCEPTANCE_DURATION_S, vehicle=vehicle, gains=gains)
        failure = flight.summary.get('failure')
        if failure:
            return f'{vehicle}: {failure} at {flight.time[-1]:.2f} s'
        error = math.dist(flight.state[-1][:3], flight.reference_position[-1])
        if error > ACCEPTANCE_ERROR_M:
            return f'{vehicle}: {100 * error:.1f} cm from the hover point at {ACCEPTANCE_DURATION_S:g} s'
    return None


def set_in_text(text: str, values: dict[str, float]) -> str:
    """The gains file ``text`` (config/controller.yaml's layout: block sections; leaves as ``key: value`` or in a
    flow mapping ``{key: value, ...}`` that may run over several lines) with each dotted gain of ``values`` set,
    comments and layout kept. ParameterError naming a gain the text does not hold."""
    import re
    lines = text.split('\n')
    stack: list[tuple[int, str]] = []
    left = dict(values)
    flow: tuple[str, int] | None = None          # (the open flow mapping's dotted name, its brace depth)

    def code_and_comment(line: str) -> tuple[str, str]:
        cut = line.find('#')
        return (line, '') if cut < 0 else (line[:cut], line[cut:])

    def set_leaves(index: int, dotted: str) -> None:
        code, comment = code_and_comment(lines[index])
        for name in [n for n in left if n.rpartition('.')[0] == dotted]:
            leaf = re.escape(name.rpartition('.')[2])
            code, count = re.subn(rf'((?:^\s*|[{{,]\s*){leaf}:\s*)([^,}}\s]+)', rf'\g<1>{left[name]!r}', code)
            if count == 1:
                del left[name]
        lines[index] = code + comment

    for index, line in enumerate(lines):
        code = code_and_comment(line)[0]
        if flow is not None:                       # a line of a flow mapping opened above
            set_leaves(index, flow[0])
            depth = flow[1] + code.count('{') - code.count('}')
            flow = (flow[0], depth) if depth > 0 else None
            continue
        match = re.match(r'^(\s*)([^\s:#][^:]*):\s*(.*?)\s*$', code)
        if not match:
            continue
        indent, key, value = len(match.group(1)), match.group(2).strip(), match.group(3)
        while stack and stack[-1][0] >= indent:
            stack.pop()
        dotted = '.'.join([k for _, k in stack if k not in ('/**', 'ros__parameters')] + [key])
        if value == '':
            stack.append((indent, key))
        elif value.startswith('{'):
            set_leaves(index, dotted)
            depth = value.count('{') - value.count('}')
            flow = (dotted, depth) if depth > 0 else None
        elif dotted in left:
            colon = line.index(':', indent) + 1
            old, comment = code_and_comment(line[colon:])
            padding = len(old) - len(old.lstrip())
            new_value = repr(float(left.pop(dotted)))
            gap = ' ' * max(1, len(old) - padding - len(new_value)) if comment else ''
            lines[index] = line[:colon] + ' ' * padding + new_value + gap + comment
    if left:
        raise ParameterError(f'{next(iter(left))}: not in the gains file (its search dimension cannot be set)')
    return '\n'.join(lines)


def package(root: Path, kinds, into: Path, trials_to: Path | None,
            accept: Callable[[str, dict], str | None] = hover_acceptance, pick: str | None = None) -> list[str]:
    """Apply each kind's best accepted point (``root/tune-KIND/trials-KIND.csv``: the first trial of
    :func:`ranked_points` by ``pick`` for which ``accept(kind, gains)`` says None, :func:`hover_acceptance`) to
    the gains file ``into`` by its dimension names; checks that the file then holds exactly those gains changed.
    The report's lines (each says which better trials failed the acceptance, and how)."""
    column = 'objective_m' if pick is None else f'{pick}_rmse_m'
    said = 'objective' if pick is None else pick
    base = load_gains(into)
    text = into.read_text()
    expected = base
    report = []
    for kind in kinds:
        trials = root / f'tune-{kind}' / f'trials-{kind}.csv'
        refused = []
        for point, row in ranked_points(trials, kind, pick):
            why = accept(kind, with_values(expected, kind, point))
            if why is None:
                break
            refused.append(f'trial {row["trial"]} ({100 * float(row[column]):.3f} cm): {why}')
        else:
            raise ParameterError(f'{trials}: no complete trial passes the acceptance ({"; ".join(refused)})')
        expected = with_values(expected, kind, point)
        text = set_in_text(text, {gain: point[d.name] for d in search_space(kind) for gain in d.gains})
        report.append(f'{kind}: trial {row["trial"]}, {said} {100 * float(row[column]):.3f} cm '
                      f'({row["finished"]}/{row["flights"]} finished): '
                      + ', '.join(f'{name} = {value:.4g}' for name, value in point.items())
                      + (f' (better trials failing the {ACCEPTANCE_SCENARIO} acceptance: {"; ".join(refused)})'
                         if refused else ''))
        if trials_to is not None:
            trials_to.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(trials, trials_to / trials.name)
    # the provenance lines: the kinds packaged now replace theirs, the others' stay, in the kinds' order
    lines = text.split('\n')
    provenance = {line[len(PROVENANCE):].split(':')[0]: line for line in lines if line.startswith(PROVENANCE)}
    provenance.update({kind: PROVENANCE + line for kind, line in zip(kinds, report)})
    ordered = [provenance.pop(kind) for kind in KINDS if kind in provenance] + list(provenance.values())
    text = '\n'.join(ordered + [line for line in lines if not line.startswith(PROVENANCE)])
    for kind in kinds:
        values_in(expected, kind)
    write_checked(into, text, flatten_gains(expected))
    return report


def write_checked(into: Path, text: str, expected: dict) -> None:
    """Write the gains file ``text`` to ``into`` if its gains, flattened, are ``expected``; else ParameterError, and
    ``into`` is left as it was."""
    with tempfile.TemporaryDirectory() as folder:
        check = Path(folder) / 'gains.yaml'
        check.write_text(text)
        if flatten_gains(load_gains(check)) != expected:
            raise ParameterError(f'{into}: writing the tuned points changed more than they hold (refused, unchanged)')
    into.write_text(text)


# --- 2. run: the flights -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Settings:
    spec: str = SPEC
    gains: str | None = None
    kinds: tuple[str, ...] = KINDS
    seeds: tuple[int, ...] = HELDOUT_SEEDS
    flights: int = 1000
    duration: float = 30.0
    disturbances: tuple[str, ...] = tuple(DISTURBANCES)
    stress_flights: int = 100
    stress_duration: float = 15.0
    nominal_duration: float = 60.0
    margin_duration: float = 30.0
    workers: int | None = None

    def gains_file(self) -> str:
        return str(locate_gains(self.gains))

    def identity(self) -> dict:
        """What must not change between two runs into one DIR (the workers may)."""
        document = {k: v for k, v in self.__dict__.items() if k != 'workers'}
        document['gains_digest'] = hashlib.sha256(
            json.dumps(flatten_gains(load_gains(self.gains)), sort_keys=True).encode()).hexdigest()[:16]
        return json.loads(json.dumps(document))


def heldout_folder(out: Path, seed: int, kind: str) -> Path:
    return out / 'heldout' / f'seed-{seed}' / kind


def fly_heldout(settings: Settings, out: Path) -> list[Path]:
    spec = load_spec(Path(settings.spec))
    folders = []
    for seed in settings.seeds:
        for kind in settings.kinds:
            folder = heldout_folder(out, seed, kind)
            campaign = spec.overridden(flights=settings.flights, seed=seed, duration=settings.duration,
                                       controllers=[kind])
            progress(STUDY, f'held out, seed {seed}, {kind}: {settings.flights} flights of {settings.duration:g} s '
                            f'-> {folder}')
            run_campaign(campaign, folder, RunOptions(workers=settings.workers, gains_file=settings.gains_file(),
                                                      resume=holds_campaign(folder), report=False))
            folders.append(folder)
    return folders


def fly_stress(settings: Settings, out: Path) -> None:
    from flight_stack.campaign.study_cli import stress_main
    for disturbance in settings.disturbances:
        argv = [settings.spec, '--kind', disturbance, '--controllers', ','.join(settings.kinds),
                '--flights', str(settings.stress_flights), '--duration', f'{settings.stress_duration:g}',
                '--out', str(out / 'stress'), '--gains', settings.gains_file()]
        if settings.workers:
            argv += ['--workers', str(settings.workers)]
        progress(STUDY, 'run_stack.py stress ' + ' '.join(argv))
        if stress_main(argv) != 0:
            raise ParameterError(f'stress --kind {disturbance} failed (its message is above)')


def jobs(settings: Settings) -> int:
    import os
    return settings.workers or os.cpu_count() or 1


def fly_nominal_noise(settings: Settings, out: Path) -> Path:
    path = out / 'nominal_noise.md'
    if path.exists():
        return path
    progress(STUDY, f'nominal and noise: {len(settings.kinds)} kinds x 2 flights of {settings.nominal_duration:g} s')
    paper_tables.OVERRIDES.clear()
    paper_tables.OVERRIDES['gains_file'] = settings.gains_file()
    lines = paper_tables.paper_tables(('nominal', 'noise'), list(settings.kinds),
                                      {'nominal': ('paper',), 'noise': ('paper',)}, settings.nominal_duration,
                                      [1000.0], jobs(settings))
    path.write_text('\n'.join(lines) + '\n')
    return path


def fly_margins(settings: Settings, out: Path) -> Path:
    """``DIR/margins.json`` {kind: the margins study's delay_margins}, kind by kind (a kind done is kept)."""
    path = out / 'margins.json'
    done = json.loads(path.read_text()) if path.exists() else {}
    todo = [kind for kind in settings.kinds if kind not in done]
    paper_tables.OVERRIDES.clear()
    paper_tables.OVERRIDES['gains_file'] = settings.gains_file()
    for kind, result in zip(todo, run_all(_margin_task, [(k, settings.margin_duration) for k in todo],
                                          jobs(settings), STUDY, lambda task: f'the delay margins of {task[0]}')):
        done[kind] = result
        path.write_text(json.dumps(done, indent=1, default=str))
    return path


def _margin_task(task) -> dict:
    kind, duration = task
    return margins.delay_margins(kind, duration, margins.MAX_DELAY)


# --- 3. tables ---------------------------------------------------------------------------------------------

def breaking_lines(path: Path, kinds, disturbances) -> list[str]:
    """Kind x disturbance: the breaking point (found: 'x (holds at y)'; a range, the 95 % intervals at x and y
    straddling 90 %: 'x? (holds at y; surely between a and b)', where the tries' intervals clear 90 %, see
    :func:`sure_range`; none up to the range's end: '> x';
    already below 90 % at the low end: '<= x'; no search yet: 'not flown'), from stress's breaking_points.csv."""
    if not path.exists():
        return ['(no breaking point flown yet)']
    with path.open(newline='') as stream:
        rows = {(row['kind'], row['controller']): row for row in csv.DictReader(stream)}
    intensities = {d: DISTURBANCES[d].intensity for d in disturbances}
    lines = ['| kind | ' + ' | '.join(f'{d}: {intensities[d]}' for d in disturbances) + ' |',
             '|---|' + '---:|' * len(disturbances)]
    for kind in kinds:
        cells = []
        for d in disturbances:
            row = rows.get((d, kind))
            if row is None:
                cells.append('not flown')
            elif row['status'] == 'found':
                cells.append(f'{float(row["fails_at"]):g} (holds at {float(row["holds_at"]):g})')
            elif row['status'] == 'range':
                cells.append(f'{float(row["fails_at"]):g}? (holds at {float(row["holds_at"]):g}; surely '
                             f'{sure_range(float(row["range_low"]), float(row["range_high"]))})')
            elif row['status'] == 'above_range':
                cells.append(f'> {float(row["holds_at"]):g}')
            else:
                cells.append(f'<= {float(row["fails_at"]):g}')
        lines.append(f'| {kind} | ' + ' | '.join(cells) + ' |')
    return lines


def sure_range(low: float, high: float) -> str:
    """Where a breaking point surely lies (stress's ``range_low``, ``range_high``: the highest try whose whole 95 %
    interval holds 90 %, the lowest whose whole interval is below it; nan where no try is that sure)."""
    if math.isnan(low) and math.isnan(high):
        return 'nowhere the tries tell'
    if math.isnan(low):
        return f'at or below {high:g}'
    if math.isnan(high):
        return f'above {low:g}'
    return f'between {low:g} and {high:g}'


def margin_records(path: Path, kinds) -> list[dict]:
    if not path.exists():
        return []
    done = json.loads(path.read_text())
    return [{'controller': kind, 'rmse_cm_no_lag': done[kind]['delay_lag0']['rmse_cm'],
             'delay_margin_s_no_lag': done[kind]['delay_lag0']['seconds'],
             'delay_margin_no_lag': done[kind]['delay_lag0']['text'],
             'rmse_cm_30ms_lag': done[kind][f'delay_lag{margins.MOTOR_LAG:g}']['rmse_cm'],
             'delay_margin_s_30ms_lag': done[kind][f'delay_lag{margins.MOTOR_LAG:g}']['seconds'],
             'delay_margin_30ms_lag': done[kind][f'delay_lag{margins.MOTOR_LAG:g}']['text']}
            for kind in kinds if kind in done]


def margin_lines(records: list[dict]) -> list[str]:
    lines = ['| kind | RMSE [cm], ideal rotors | delay margin, ideal rotors | RMSE [cm], 30 ms motor lag | '
             'delay margin, 30 ms motor lag |', '|---|---:|---:|---:|---:|']
    for r in records:
        lines.append(f'| {r["controller"]} | {r["rmse_cm_no_lag"]:.3g} | {r["delay_margin_no_lag"]} | '
                     f'{r["rmse_cm_30ms_lag"]:.3g} | {r["delay_margin_30ms_lag"]} |')
    return lines


def tables(out: Path, settings: Settings) -> str:
    """Every table from what DIR holds; writes the CSVs and DIR/SCOREBOARD.md; returns the markdown."""
    s = settings
    folders = [heldout_folder(out, seed, kind) for seed in s.seeds for kind in s.kinds
               if (heldout_folder(out, seed, kind) / FLIGHTS_FILE).exists()]
    parts = [f'Settings: spec `{s.spec}`, gains `{s.gains or "packaged"}` (digest {s.identity()["gains_digest"]}); '
             f'kinds {", ".join(s.kinds)}. Made by `run_stack.py study scoreboard` (docs/SCOREBOARD.md says how).', '']
    if folders:
        by_seed = heldout.read_all(folders)
        kinds = heldout.kind_records(by_seed)
        pairs = heldout.paired_records(by_seed, s.kinds[0])
        heldout.write_csv(kinds, out / 'heldout.csv')
        heldout.write_csv(pairs, out / 'paired.csv')
        flown = sorted({r['flights'] for r in kinds if r['seed'] != heldout.ALL_SEEDS})
        parts += [f'### Held out: seeds {", ".join(map(str, s.seeds))}, {"/".join(map(str, flown))} flights each of '
                  f'{s.duration:g} s', '',
                  'RMSE percentiles over all flights, a failed flight counted as worse than any (`failed` where a '
                  'percentile falls on failures); 95 % intervals: Wilson for shares, order statistics for '
                  'percentiles (flight_stack/campaign/paired.py).', '', *heldout.kind_lines(kinds), '',
                  f'### Paired against {s.kinds[0]} (flight k of seed s: the same perturbed vehicle, wind, noise)',
                  '',
                  'A finished flight beats a failed one; two failed flights tie. The median paired difference has '
                  'the sign test\'s order-statistic interval.', '', *heldout.paired_lines(pairs), '']
        actuator = heldout.actuator_lines(by_seed)
        if actuator:
            parts += ['### Where the held-out flights failed, by the actuator each drew', '',
                      'Failed flights / flights, all seeds, by third of the drawn range (the top third of both: '
                      'the slowest rotors with the longest delays).', '', *actuator, '']
    parts += [f'### Breaking points: the intensity where fewer than 90 % of {s.stress_flights} flights of '
              f'{s.stress_duration:g} s finish under 10 cm (`run_stack.py stress`)', '',
              *breaking_lines(out / 'stress' / BREAKING_POINTS_FILE, s.kinds, s.disturbances), '']
    nominal = out / 'nominal_noise.md'
    if nominal.exists():
        parts += [f'### Nominal and noise (paper helix, {s.nominal_duration:g} s; run_stack.py study paper-tables)', '',
                  nominal.read_text().strip(), '']
    margins = margin_records(out / 'margins.json', s.kinds)
    if margins:
        heldout.write_csv(margins, out / 'margins.csv')
        parts += [f'### Delay margins (paper helix, {s.margin_duration:g} s, to 0.25 ms; run_stack.py study margins)', '',
                  *margin_lines(margins), '']
    text = '\n'.join(parts)
    (out / 'SCOREBOARD.md').write_text(text + '\n')
    return text


def write_section(path: Path, text: str) -> None:
    """Replace the generated section of ``path`` (between MARKERS) with ``text``; ParameterError without markers."""
    document = path.read_text()
    begin, end = MARKERS
    if begin not in document or end not in document:
        raise ParameterError(f'--markdown: {path} has no generated section ({begin} ... {end})')
    head, rest = document.split(begin, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f'{head}{begin}\n{text}\n{end}{tail}')


# --- 4. plan: the cost, measured --------------------------------------------------------------------------

def stress_tries(disturbance: str) -> int:
    """The tries a bisection makes at most: the range's two ends, then halvings down to the resolution."""
    kind = DISTURBANCES[disturbance]
    return 2 + max(0, math.ceil(math.log2((kind.high - kind.low) / kind.resolution)))


def tuning_cost(root: Path, kind: str, duration: float) -> float | None:
    """Wall seconds per flight of ``duration`` s from the tuning's trials table (``root/tune-KIND``): the median
    over its complete trials of wall time / flights, scaled from its flight length; None without a table."""
    import statistics
    import yaml
    trials = root / f'tune-{kind}' / f'trials-{kind}.csv'
    campaigns = sorted((root / f'tune-{kind}' / 'campaigns').glob('*/seed-*/spec.yaml'))
    if not trials.exists() or not campaigns:
        return None
    flown = float(yaml.safe_load(campaigns[0].read_text())['duration'])
    with trials.open(newline='') as stream:
        costs = [float(row['wall_time_s']) / float(row['flights']) for row in csv.DictReader(stream)
                 if row['state'] == 'complete' and row['flights'] not in ('', '0')]
    return statistics.median(costs) * duration / flown if costs else None


def measure(settings: Settings, flights: int = 8) -> dict[str, float]:
    """{kind: wall seconds per flight of ``settings.duration`` s} on this machine now: the slope between a
    campaign of 2 flights and one of ``flights`` (so the workers' start-up and kernel loading, paid by both,
    drop out), after a flight that compiles or loads the kernels."""
    spec = load_spec(Path(settings.spec))
    cost = {}
    with tempfile.TemporaryDirectory() as folder:
        for kind in settings.kinds:
            options = RunOptions(workers=settings.workers, gains_file=settings.gains_file(), progress=False,
                                 report=False)
            progress(STUDY, f'plan: {kind}: a flight that compiles or loads its kernels')
            run_campaign(spec.overridden(flights=1, seed=0, duration=min(settings.duration, 6.0), controllers=[kind]),
                         Path(folder) / f'warm-{kind}', options)
            walls = []
            for count in (2, flights):
                progress(STUDY, f'plan: {kind}: timing a campaign of {count} flights of {settings.duration:g} s')
                start = time.perf_counter()
                run_campaign(spec.overridden(flights=count, seed=0, duration=settings.duration, controllers=[kind]),
                             Path(folder) / f'{kind}-{count}', options)
                walls.append(time.perf_counter() - start)
            cost[kind] = max(walls[1] - walls[0], 0.0) / (flights - 2)
            progress(STUDY, f'plan: {kind}: {cost[kind]:.3f} s wall per {settings.duration:g} s flight (measured)')
    return cost


def costs(settings: Settings, tune_root: Path | None, flights: int) -> dict[str, float]:
    """Each kind's wall seconds per flight: from its tuning's trials table when ``tune_root`` holds one,
    else measured (:func:`measure`)."""
    known = {kind: tuning_cost(tune_root, kind, settings.duration) for kind in settings.kinds} if tune_root else {}
    known = {kind: cost for kind, cost in known.items() if cost is not None}
    for kind, cost in known.items():
        progress(STUDY, f'plan: {kind}: {cost:.3f} s wall per {settings.duration:g} s flight (its tuning\'s trials)')
    missing = tuple(kind for kind in settings.kinds if kind not in known)
    if missing:
        known.update(measure(replace(settings, kinds=missing), flights))
    return {kind: known[kind] for kind in settings.kinds}


#: wall seconds per simulated second of one embedded flight (the paper-tables study, one process) at 4 kHz and
#: 1 kHz physics: the conditions study's run of 2026-12-04 (6 kinds: 24 flights of 20 s at 1 kHz and about
#: 120 delay-margin flights of 30 s at 4 kHz in 11 min on one shared core)
EMBEDDED_4KHZ_COST, EMBEDDED_1KHZ_COST = 0.15, 0.04
#: [s] wall time a campaign costs beyond its flights (workers start, kernels load, files): a stress try of 4
#: flights of 7 s took about 10 s in the validation run of 2026-12-04 on the shared machine
CAMPAIGN_OVERHEAD_S = 8.0


def plan(settings: Settings, cost: dict[str, float]) -> list[str]:
    """The run's parts with their flights and estimated wall time: a campaign flight's cost scales with its
    length, and each campaign costs CAMPAIGN_OVERHEAD_S more; the nominal, noise and delay-margin flights are single embedded flights (EMBEDDED_*_COST), run
    ``--workers`` at a time."""
    s = settings
    per_second = {kind: c / s.duration for kind, c in cost.items()}
    heldout = sum(len(s.seeds) * (s.flights * s.duration * per_second[k] + CAMPAIGN_OVERHEAD_S) for k in s.kinds)
    tries = sum(stress_tries(d) for d in s.disturbances)
    stress = sum(tries * (s.stress_flights * s.stress_duration * per_second[k] + CAMPAIGN_OVERHEAD_S)
                 for k in s.kinds)
    nominal = len(s.kinds) * 2 * s.nominal_duration * EMBEDDED_1KHZ_COST / jobs(s)
    margin = len(s.kinds) * MARGIN_FLIGHTS * s.margin_duration * EMBEDDED_4KHZ_COST / jobs(s)
    rows = [('held out', f'{len(s.kinds)} kinds x {len(s.seeds)} seeds x {s.flights} flights of {s.duration:g} s',
             heldout),
            ('breaking points', f'{len(s.kinds)} kinds x {tries} tries at most ({len(s.disturbances)} disturbances) x '
                                f'{s.stress_flights} flights of {s.stress_duration:g} s', stress),
            ('nominal, noise', f'{len(s.kinds)} kinds x 2 flights of {s.nominal_duration:g} s', nominal),
            ('delay margins', f'{len(s.kinds)} kinds x about {MARGIN_FLIGHTS} flights of {s.margin_duration:g} s '
                              'at 4 kHz', margin)]
    lines = ['| part | flights | estimated wall time [min] |', '|---|---|---:|']
    lines += [f'| {name} | {what} | {seconds / 60:.0f} |' for name, what, seconds in rows]
    lines.append(f'| total | | {sum(r[2] for r in rows) / 60:.0f} |')
    lines += ['', 'measured wall seconds per flight of {:g} s: '.format(s.duration)
              + ', '.join(f'{k} {c:.3f}' for k, c in cost.items())]
    return lines


# --- the command --------------------------------------------------------------------------------------------

def settings_of(args) -> Settings:
    unknown = [d for d in names(args.disturbances) if d not in DISTURBANCES]
    if unknown:
        raise ParameterError(f'--disturbances: unknown {", ".join(unknown)} (of {", ".join(DISTURBANCES)})')
    kinds = tuple(names(args.kinds))
    if not kinds:
        raise ParameterError('--kinds: give at least one controller kind (the first is the paired reference)')
    for kind in kinds:                     # any registered kind: a built-in one, an installed one, module:Class
        check_controller(kind, '--kinds')
    for name, value in (('--flights', args.flights), ('--stress-flights', args.stress_flights)):
        if value < 1:
            raise ParameterError(f'{name}: {value} must be a whole number >= 1')
    settings = Settings(args.spec, args.gains, kinds, tuple(int(s) for s in names(args.seeds)), args.flights,
                        args.duration, tuple(names(args.disturbances)), args.stress_flights, args.stress_duration,
                        args.nominal_duration, args.margin_duration, args.workers)
    load_gains(settings.gains)          # a named set or a file: refused here, before anything flies
    return settings


def _run_options(parser: argparse.ArgumentParser) -> None:
    d = Settings()
    parser.add_argument('--spec', default=d.spec, help=f'campaign spec (default {d.spec})')
    parser.add_argument('--gains', default=None, help='gains file or named set for every kind (default: packaged)')
    parser.add_argument('--kinds', default=','.join(d.kinds), help='controller kinds; the first is the paired '
                                                                  f'reference (default {",".join(d.kinds)})')
    parser.add_argument('--seeds', default=','.join(map(str, d.seeds)), help='held-out campaign seeds')
    parser.add_argument('--flights', type=int, default=d.flights, help='held-out flights per seed and kind')
    parser.add_argument('--duration', type=float, default=d.duration, help='[s] held-out flight (the tuning\'s)')
    parser.add_argument('--disturbances', default=','.join(d.disturbances), help='stress kinds')
    parser.add_argument('--stress-flights', type=int, default=d.stress_flights, help='flights per stress try')
    parser.add_argument('--stress-duration', type=float, default=d.stress_duration, help='[s] stress flight')
    parser.add_argument('--nominal-duration', type=float, default=d.nominal_duration,
                        help='[s] nominal and noise flights')
    parser.add_argument('--margin-duration', type=float, default=d.margin_duration, help='[s] delay-margin flights')
    parser.add_argument('--workers', type=int, default=None, help='local worker processes (default: every core)')


PARTS = ('heldout', 'stress', 'nominal', 'margins')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    commands = parser.add_subparsers(dest='command', required=True)
    p = commands.add_parser('package', help='each kind\'s best tuned point onto the packaged gains file')
    p.add_argument('root', type=Path, help='folder holding tune-KIND/trials-KIND.csv for each kind')
    p.add_argument('--kinds', default=','.join(KINDS))
    p.add_argument('--into', type=Path, default=DEFAULT_CONTROLLER_FILE,
                   help='the gains file to write the points into (default: the packaged one)')
    p.add_argument('--trials-to', type=Path, default=None, help='also copy every trials-KIND.csv into this folder')
    p.add_argument('--pick', choices=OBJECTIVES, default=None,
                   help='rank the trials by this statistic under the tuning\'s 99 %% finished rule (default: by '
                        'each study\'s own objective)')
    p = commands.add_parser('plan', help='measure the cost per flight now and print the run\'s plan')
    _run_options(p)
    p.add_argument('--tune-root', type=Path, default=None,
                   help='folder of the tuning (tune-KIND/): its trials tables give the cost per flight')
    p.add_argument('--measure-flights', type=int, default=8,
                   help='flights per kind to time where no trials table says (default 8, >= 3)')
    p = commands.add_parser('run', help='fly everything missing in DIR and write the tables')
    add_out(p)
    _run_options(p)
    p.add_argument('--skip', default='', help=f'parts left out this time: {",".join(PARTS)}')
    p.add_argument('--markdown', type=Path, default=None, help='also write the tables into this file\'s section')
    p = commands.add_parser('tables', help='the tables from what DIR holds')
    add_out(p)
    p.add_argument('--markdown', type=Path, default=None, help='also write the tables into this file\'s section')


def run(args: argparse.Namespace) -> int:
    if args.command == 'package':
        for line in package(args.root, names(args.kinds), args.into, args.trials_to, pick=args.pick):
            print(line)
        progress(STUDY, f'wrote the gains file {args.into}')
        return 0
    if args.command == 'plan':
        if args.measure_flights < 3:
            raise ParameterError(f'--measure-flights: {args.measure_flights} must be >= 3')
        settings = settings_of(args)
        print('\n'.join(plan(settings, costs(settings, args.tune_root, args.measure_flights))))
        return 0
    if args.command == 'tables':
        stored = json.loads((args.out / SETTINGS_FILE).read_text())
        settings = Settings(**{k: tuple(v) if isinstance(v, list) else v for k, v in stored.items()
                               if k in Settings.__dataclass_fields__})
    else:
        settings = settings_of(args)
        fly_all(settings, args.out, set(names(args.skip)))
    text = tables(args.out, settings)
    print(text)
    progress(STUDY, f'wrote the markdown tables {args.out / "SCOREBOARD.md"}')
    if args.markdown:
        write_section(args.markdown, text)
        progress(STUDY, f'wrote them into the generated section of {args.markdown}')
    return 0


#: settings every part depends on: a DIR's are never changed
COMMON_SETTINGS = ('spec', 'gains', 'gains_digest', 'kinds')
#: the settings of each part's flights: a run into a DIR refuses to fly a part whose stored settings differ, and
#: leaves a part it does not fly as it is (so more flights per stress try may follow a held-out part flown before)
PART_SETTINGS = {'heldout': ('seeds', 'flights', 'duration'),
                 'stress': ('disturbances', 'stress_flights', 'stress_duration'),
                 'nominal': ('nominal_duration',),
                 'margins': ('margin_duration',)}


def claim(settings: Settings, out: Path, parts: set[str]) -> None:
    """Record in ``out/scoreboard.json`` that ``parts`` are flown with ``settings``; ParameterError naming the
    settings if ``out`` holds a run with other common settings or gains, or with other settings of a part in
    ``parts`` that it flew (the file's ``flown``; a file without it, from before, flew every part)."""
    identity = settings.identity()
    path = out / SETTINGS_FILE
    stored = json.loads(path.read_text()) if path.exists() else {}
    flown = set(stored.get('flown', PARTS)) if stored else set()
    keys = list(COMMON_SETTINGS) + [key for part in PARTS if part in parts & flown for key in PART_SETTINGS[part]]
    differing = [key for key in keys if stored and stored.get(key) != identity[key]]
    if differing:
        raise ParameterError(f'--out: {out} holds a scoreboard flown with another {", ".join(differing)} '
                             f'({path}); use another --out')
    kept = {key: stored[key] for part in flown - parts for key in PART_SETTINGS[part]}
    path.write_text(json.dumps({**identity, **kept, 'flown': [p for p in PARTS if p in flown | parts]}, indent=1))


def fly_all(settings: Settings, out: Path, skip: set[str]) -> None:
    """Fly every part not in ``skip`` that ``out`` lacks (refused if ``out`` holds a run of other settings:
    :func:`claim`)."""
    if skip - set(PARTS):
        raise ParameterError(f'--skip: unknown {", ".join(sorted(skip - set(PARTS)))} (parts: {", ".join(PARTS)})')
    out.mkdir(parents=True, exist_ok=True)
    claim(settings, out, set(PARTS) - skip)
    if 'heldout' not in skip:
        fly_heldout(settings, out)
    if 'stress' not in skip:
        fly_stress(settings, out)
    if 'nominal' not in skip:
        fly_nominal_noise(settings, out)
    if 'margins' not in skip:
        fly_margins(settings, out)
