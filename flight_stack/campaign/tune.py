"""``run_stack.py tune SPEC --controller KIND --trials N --flights M --seeds 1,2 --out DIR``: equal-effort
tuning of one controller kind on campaigns (docs/TUNING.md).

A trial is one point of the kind's search space (nnit2fsmc_controller/search_spaces.py), flown as one
campaign per tuning seed by the campaign runner (its workers, or a Dask cluster with ``--scheduler``);
this module only chooses the gains and scores the flights. Optuna chooses them: a seeded TPE sampler,
a study kept in ``DIR/study.journal`` (running the same command again continues it), and pruning after
each seed's campaign. The first trial is the gains the tuning starts from (the packaged ones, or
``--gains``), flown on every seed and never pruned, so the best trial is never worse than they are
on the same flights.

The objective (:func:`objective`), in metres, smaller is better: over every tuning flight, a statistic of
the position RMSE (``--objective``: ``median``, the default, or ``p95``, its 95th percentile: the tail), where
a flight that failed counts as ``max_error_m`` (no finished flight is worse: its error stayed below it after
settling); if fewer than 99 % of the flights finished, it is ``max_error_m * (2 - finished share)`` instead,
which is worse than any gains that finish 99 %. A point whose gains the controller refuses for the nominal
vehicle scores ``2 max_error_m``, as bad as gains whose every flight fails.

Every trial records both statistics, so one study gives two picks by the same rule (each statistic subject to
99 % finished, among the trials flown on every seed): ``gains-KIND-median.yaml`` and ``gains-KIND-p95.yaml``
beside ``gains-KIND.yaml`` (the objective's pick, the study's best). Pruning follows the objective: the other
statistic's pick is among the trials the objective let finish.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.search_spaces import at_bounds, search_space, values_in, with_values
from quad_msgs_bridge.validation import ParameterError

from ..locking import FileLock
from .batch import CampaignSetup
from .results import FLIGHTS_FILE, read_flights
from .runner import RunOptions, holds_campaign, run_campaign
from .spec import CampaignSpec

STUDY_FILE = 'study.journal'
LOCK_FILE = '.tune.lock'
REQUIRED_FINISHED_SHARE = 0.99
#: the statistics of the flights' RMSE a study can minimise (--objective); every trial records each
OBJECTIVES = ('median', 'p95')
#: TPE's random start: trials sampled at random before it models the objective
STARTUP_TRIALS = 5
#: the largest --sampler-seed: the sampler's seed is it plus the trials already made, which numpy takes below 2^32
MAX_SAMPLER_SEED = 2 ** 31 - 1


@dataclass(frozen=True)
class Score:
    """The objective of a set of flights and what it is made of."""

    objective_m: float         #: see :func:`objective`
    median_rmse_m: float       #: median RMSE with failures counted as max_error_m
    p95_rmse_m: float          #: its 95th percentile (numpy's linear interpolation), failures likewise
    finished: int
    flights: int

    @property
    def finished_share(self) -> float:
        return self.finished / self.flights if self.flights else 0.0


def objective(rows: list[dict], max_error_m: float, statistic: str = 'median') -> Score:
    """The tuning objective [m] of the flights ``rows`` (flights.csv rows) by ``statistic`` (one of
    OBJECTIVES; see the module docstring)."""
    if not rows:
        raise ValueError('objective: no flight to score')
    if statistic not in OBJECTIVES:
        raise ParameterError(f'--objective: {statistic!r} is not one of {", ".join(OBJECTIVES)}')
    rmse = [r['rmse_position_m'] if r['finished'] else max_error_m for r in rows]
    finished = sum(1 for r in rows if r['finished'])
    median, p95 = (float(v) for v in np.percentile(rmse, [50.0, 95.0]))
    value = penalised(median if statistic == 'median' else p95, finished, len(rows), max_error_m)
    return Score(value, median, p95, finished, len(rows))


def penalised(value: float, finished: int, flights: int, max_error_m: float) -> float:
    """``value`` [m] if ``finished`` of ``flights`` is at least the required share, else the penalty
    ``max_error_m * (2 - finished share)`` (the module docstring)."""
    share = finished / flights
    return value if share >= REQUIRED_FINISHED_SHARE else max_error_m * (2.0 - share)


def pick_value(attrs: dict, statistic: str, max_error_m: float) -> float:
    """A finished trial's objective by ``statistic`` from what it recorded (its user attributes): the statistic
    if it finished 99 % of its flights, else the penalty of :func:`objective`; nan if it did not record it."""
    recorded = attrs.get(f'{statistic}_rmse_m', math.nan)
    flights = attrs.get('flights') or 0
    if not flights or math.isnan(recorded):
        return math.nan
    return penalised(recorded, attrs['finished'], flights, max_error_m)


def cannot_reach_required_share(failed: int, total_flights: int) -> bool:
    """Whether ``failed`` failures already keep ``total_flights`` flights below the required finished share."""
    return failed > (1.0 - REQUIRED_FINISHED_SHARE) * total_flights + 1e-9


@dataclass(frozen=True)
class TuneSetup:
    """One tuning: the kind, the campaign every trial flies (per seed), the budget, where it goes."""

    kind: str
    spec: CampaignSpec             #: controllers = (kind,), flights = M; its seed is replaced by each tuning seed
    seeds: tuple[int, ...]
    trials: int
    out_dir: Path
    options: RunOptions            #: workers, scheduler, batch size, vehicle file; gains_file: the starting gains
    sampler_seed: int = 0
    objective: str = 'median'      #: the statistic minimised (OBJECTIVES)
    attitude: bool = False         #: the kind's roll and pitch loop searched too (search_spaces.ATTITUDE_SPACES)

    def __post_init__(self):
        seed = self.sampler_seed
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SAMPLER_SEED:
            raise ParameterError(f'--sampler-seed: {seed!r} is outside the valid range [0, {MAX_SAMPLER_SEED}] '
                                 '(a whole number)')
        if self.objective not in OBJECTIVES:
            raise ParameterError(f'--objective: {self.objective!r} is not one of {", ".join(OBJECTIVES)}')
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise ParameterError(f'--out: {self.out_dir} exists and is not a folder; choose another --out')

    def identity(self) -> dict:
        """What makes two runs the same study (kept in the study; a resume must match it)."""
        identity = {'kind': self.kind, 'spec': self.spec.to_mapping(), 'seeds': list(self.seeds),
                    'vehicle_file': self.options.vehicle_file, 'starting_gains': _digest(self.starting_gains())}
        # the median's position-loop studies were made before there was a choice: their identity stays what it was
        if self.objective != 'median':
            identity['objective'] = self.objective
        if self.attitude:
            identity['attitude'] = True
        return identity

    def space(self) -> tuple:
        """The dimensions it searches."""
        return search_space(self.kind, self.attitude)

    def starting_gains(self) -> dict:
        return load_gains(self.options.gains_file, kind=self.kind)


def _digest(document) -> str:
    return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()[:16]


def parse_seeds(text: str) -> tuple[int, ...]:
    """'1,2' -> (1, 2); ParameterError naming --seeds otherwise."""
    try:
        seeds = tuple(int(part) for part in text.split(',') if part.strip())
    except ValueError:
        raise ParameterError(f'--seeds: {text!r} is not a comma-separated list of whole numbers >= 0') from None
    if not seeds or any(seed < 0 for seed in seeds) or len(set(seeds)) != len(seeds):
        raise ParameterError(f'--seeds: {text!r}: give one or more distinct whole numbers >= 0')
    return seeds


def _optuna():
    try:
        import optuna
    except ImportError as error:   # pragma: no cover - optuna is a pinned dependency
        raise ParameterError('tune needs optuna (pip install -r requirements.txt)') from error
    # its warnings are of trials that raised, which re-raise the error anyway (a Ctrl-C printed 30 lines of
    # traceback before the command's one line: interrupted); tune says what each trial did itself
    optuna.logging.set_verbosity(optuna.logging.ERROR)
    return optuna


def open_study(setup: TuneSetup):
    """The study in ``DIR/study.journal``: created (with the starting gains enqueued as trial 0) or
    continued. A trial an interrupted (or killed) run left unfinished is marked failed and enqueued
    again, once (its campaigns resume from their flights.csv). ParameterError if DIR holds another tuning."""
    optuna = _optuna()
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend
    storage = JournalStorage(JournalFileBackend(str(setup.out_dir / STUDY_FILE)))
    name = f'tune-{setup.kind}'
    existing = {summary.study_name: summary.n_trials for summary in optuna.get_all_study_summaries(storage)}
    # the sampler's seed moves on by the trials already made, so a resumed study does not draw its
    # random start again (a fresh sampler with the same seed would propose the same points)
    study = optuna.create_study(
        study_name=name, storage=storage, direction='minimize', load_if_exists=True,
        sampler=optuna.samplers.TPESampler(seed=setup.sampler_seed + existing.get(name, 0),
                                           n_startup_trials=STARTUP_TRIALS),
        pruner=optuna.pruners.MedianPruner(n_startup_trials=STARTUP_TRIALS, n_warmup_steps=0))
    identity = setup.identity()
    stored = study.user_attrs.get('identity')
    if stored is None:
        study.set_user_attr('identity', identity)
        study.enqueue_trial(values_in(setup.starting_gains(), setup.kind, setup.attitude),
                            user_attrs={'starting_gains': True})
    elif stored != identity:
        raise ParameterError(f'--out: {setup.out_dir} holds a tuning of another spec, kind, seeds or starting '
                             f'gains ({json.dumps(stored)}); use another --out')
    state = optuna.trial.TrialState
    for trial in study.get_trials(deepcopy=False, states=(state.RUNNING,)):   # a run that was killed
        study.tell(trial.number, state=state.FAIL)
    requeued = list(study.user_attrs.get('requeued', []))
    for trial in study.get_trials(deepcopy=False, states=(state.FAIL,)):       # interrupted (or killed)
        if trial.number not in requeued:
            study.enqueue_trial(trial.params, user_attrs={k: v for k, v in trial.user_attrs.items()
                                                          if k == 'starting_gains'})
            requeued.append(trial.number)
    study.set_user_attr('requeued', requeued)
    return study


def trial_folder(setup: TuneSetup, values: dict) -> Path:
    """The folder of a point's campaigns: named by the point, so a trial flown again resumes them."""
    return setup.out_dir / 'campaigns' / _digest({k: repr(float(v)) for k, v in values.items()})


class RefusedGains(Exception):
    """The controller refuses a point's gains for the nominal vehicle (e.g. too little authority)."""


def fly_point(setup: TuneSetup, values: dict, after_seed=None, label: str | None = None) -> Score:
    """Fly the gains of ``values`` on every tuning seed (one campaign each, via the campaign runner) and
    score all their flights. ``after_seed(index, score_so_far, rows_so_far)`` runs after each seed's
    campaign (pruning raises from it). With ``label`` (e.g. 'trial 3') each campaign shows its flights as
    they finish on stderr (the runner's progress bar, named by it and the seed). :class:`RefusedGains` if
    the controller refuses these gains."""
    folder = trial_folder(setup, values)
    folder.mkdir(parents=True, exist_ok=True)
    gains_path = folder / 'gains.yaml'
    gains_path.write_text(yaml.safe_dump(with_values(setup.starting_gains(), setup.kind, values, setup.attitude), sort_keys=False))
    try:
        CampaignSetup.of(setup.spec, setup.options.vehicle_file, gains_path).check_controllers((setup.kind,))
    except ParameterError as error:
        raise RefusedGains(str(error)) from error
    options = replace(setup.options, gains_file=str(gains_path), progress=label is not None, report=False)
    rows: list[dict] = []
    score = None
    for index, seed in enumerate(setup.seeds):
        campaign_dir = folder / f'seed-{seed}'
        run_campaign(replace(setup.spec, seed=seed), campaign_dir,
                     replace(options, resume=holds_campaign(campaign_dir), progress_label=f'{label} seed {seed}'))
        rows += read_flights(campaign_dir / FLIGHTS_FILE)
        score = objective(rows, setup.spec.max_error_m, setup.objective)
        if after_seed is not None:
            after_seed(index, score, rows)
    return score


def make_objective(setup: TuneSetup, say=None):
    """The function Optuna minimises: suggest a point, fly it, prune a hopeless one after a seed. With ``say``
    (a function of a line of text), it says when a trial starts, shows each seed's flights as they finish
    and says each seed's score."""
    optuna = _optuna()
    dimensions = setup.space()
    total_flights = setup.spec.flights * len(setup.seeds)

    def run(trial) -> float:
        values = {d.name: trial.suggest_float(d.name, d.low, d.high, log=d.log) for d in dimensions}
        starting = bool(trial.user_attrs.get('starting_gains'))
        name = f'tune {setup.kind}: trial {trial.number}'
        if say is not None:
            say(f'{name}{" (the starting gains)" if starting else ""}: {len(setup.seeds)} seed(s) x '
                f'{setup.spec.flights} flights')

        def after_seed(index: int, score: Score, rows: list[dict]) -> None:
            trial.set_user_attr('seeds_flown', index + 1)
            _record(trial, score)
            if say is not None:
                say(f'{name}: seed {setup.seeds[index]} ({index + 1}/{len(setup.seeds)}) flown: '
                    f'{score.finished}/{score.flights} finished so far, objective so far '
                    f'{score.objective_m * 100:.3f} cm')
            if starting or index == len(setup.seeds) - 1:
                return
            if cannot_reach_required_share(score.flights - score.finished, total_flights):
                trial.set_user_attr('pruned_because', f'{score.flights - score.finished} failures: below '
                                                      f'{REQUIRED_FINISHED_SHARE:.0%} finished whatever follows')
                raise optuna.TrialPruned()
            trial.report(score.objective_m, index)
            if trial.should_prune():
                trial.set_user_attr('pruned_because', 'worse than the median trial after the same seeds')
                raise optuna.TrialPruned()

        try:
            label = None if say is None else f'trial {trial.number}'
            return fly_point(setup, values, after_seed, label).objective_m
        except RefusedGains as error:     # scored as if every flight failed
            trial.set_user_attr('refused', str(error))
            return 2.0 * setup.spec.max_error_m

    return run


def _record(trial, score: Score) -> None:
    trial.set_user_attr('median_rmse_m', score.median_rmse_m)
    trial.set_user_attr('p95_rmse_m', score.p95_rmse_m)
    trial.set_user_attr('finished', score.finished)
    trial.set_user_attr('flights', score.flights)
    trial.set_user_attr('objective_m', score.objective_m)


def trials_table(study, dimensions) -> list[dict]:
    """One row per trial of ``study``: state, objective and its parts, the point (search names)."""
    rows = []
    for trial in study.get_trials(deepcopy=False):
        attrs = trial.user_attrs
        duration = trial.duration.total_seconds() if trial.duration is not None else math.nan
        rows.append({
            'trial': trial.number, 'state': trial.state.name.lower(),
            'starting_gains': bool(attrs.get('starting_gains')),
            'objective_m': trial.value if trial.value is not None else attrs.get('objective_m', math.nan),
            'median_rmse_m': attrs.get('median_rmse_m', math.nan),
            'p95_rmse_m': attrs.get('p95_rmse_m', math.nan),
            'finished': attrs.get('finished', ''), 'flights': attrs.get('flights', ''),
            'seeds_flown': attrs.get('seeds_flown', 0),
            'pruned_because': attrs.get('pruned_because', '') or attrs.get('refused', ''),
            'wall_time_s': duration,
            **{d.name: trial.params.get(d.name, math.nan) for d in dimensions}})
    return rows


def write_trials_table(study, setup: TuneSetup) -> Path:
    path = setup.out_dir / f'trials-{setup.kind}.csv'
    rows = trials_table(study, setup.space())
    columns = list(rows[0]) if rows else ['trial']
    with path.open('w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=columns, lineterminator='\n')
        writer.writeheader()
        writer.writerows(rows)
    return path


def picks(study, setup: TuneSetup) -> dict[str, object]:
    """{statistic: the finished trial, flown on every seed, with the smallest :func:`pick_value` by it} for each
    statistic of OBJECTIVES that some such trial recorded."""
    optuna = _optuna()
    whole = [t for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
             if t.user_attrs.get('seeds_flown') == len(setup.seeds) and 'refused' not in t.user_attrs]
    chosen = {}
    for statistic in OBJECTIVES:
        scored = [(pick_value(t.user_attrs, statistic, setup.spec.max_error_m), t.number, t) for t in whole]
        scored = [entry for entry in scored if not math.isnan(entry[0])]
        if scored:
            chosen[statistic] = min(scored, key=lambda entry: entry[:2])[2]
    return chosen


def write_gains(study, setup: TuneSetup, trial=None, suffix: str = '') -> Path:
    """``DIR/gains-KIND{suffix}.yaml``: the starting gains with ``trial``'s point (default: the study's best), as
    a ROS 2 parameter file (what ``--gains`` and the controller node's ``--params-file`` read), its provenance in
    the header."""
    best = study.best_trial if trial is None else trial
    gains = with_values(setup.starting_gains(), setup.kind, best.params, setup.attitude)
    attrs = best.user_attrs
    p95 = f', p95 {attrs["p95_rmse_m"] * 100:.3f} cm' if 'p95_rmse_m' in attrs else ''
    lines = [f'# Tuned by run_stack.py tune for {setup.kind} (docs/TUNING.md): trial {best.number} of '
             f'{len(study.trials)}, objective ({setup.objective}) {best.value * 100:.3f} cm'
             + (f'; the pick by {suffix[1:]}' if suffix else ''),
             f'# (median RMSE {attrs["median_rmse_m"] * 100:.3f} cm{p95}, {attrs["finished"]}/{attrs["flights"]} '
             f'finished) on seeds {",".join(map(str, setup.seeds))} x {setup.spec.flights} flights of '
             f'"{setup.spec.scenario}", {setup.spec.duration:g} s each.',
             '# Searched: ' + ', '.join(f'{d.name} = {best.params[d.name]:.4g} {d.unit.split(" (")[0]}'
                                        for d in setup.space())]
    document = {'/**': {'ros__parameters': {'controller': setup.kind, **gains}}}
    path = setup.out_dir / f'gains-{setup.kind}{suffix}.yaml'
    path.write_text('\n'.join(lines) + '\n' + yaml.safe_dump(document, sort_keys=False))
    return path


def make_out_dir(out_dir: Path) -> None:
    """Create ``out_dir`` (or keep it); ParameterError naming --out if it cannot be created (a file on its path,
    no permission)."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ParameterError(f'--out: cannot create {out_dir}: {error.strerror}') from error


@dataclass(frozen=True)
class TuneOutcome:
    best_trial: int
    best_objective_m: float
    starting_objective_m: float
    trials: int
    gains_path: Path
    table_path: Path
    #: {statistic: (trial number, its value [m], gains path, the dimensions at a bound of their range:
    #: search_spaces.at_bounds)} (:func:`picks`)
    picks: dict = None


def tune(setup: TuneSetup, progress: bool = True) -> TuneOutcome:
    """Run (or continue) the tuning of ``setup`` until it holds ``setup.trials`` finished trials; write
    the gains file and the trials table. ParameterError on invalid options, before anything flies."""
    optuna = _optuna()
    say = (lambda text: print(text, file=sys.stderr, flush=True)) if progress else (lambda text: None)
    values_in(setup.starting_gains(), setup.kind, setup.attitude)     # the starting point lies in the space
    make_out_dir(setup.out_dir)
    with FileLock(setup.out_dir / LOCK_FILE,
                  lambda holder: f'--out: another tune is writing {setup.out_dir} (process {holder})'):
        study = open_study(setup)
        done_states = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
        done = len(study.get_trials(deepcopy=False, states=done_states))
        if done:
            say(f'tune {setup.kind}: {done} trial(s) already in {setup.out_dir / STUDY_FILE}, continuing')

        def report(study, trial) -> None:
            write_trials_table(study, setup)
            finished = len(study.get_trials(deepcopy=False, states=done_states))
            attrs = trial.user_attrs
            what = (f'objective {trial.value * 100:.3f} cm' if trial.state == optuna.trial.TrialState.COMPLETE
                    else f'pruned after {attrs.get("seeds_flown", 0)} seed(s): {attrs.get("pruned_because", "")}'
                    if trial.state == optuna.trial.TrialState.PRUNED else trial.state.name.lower())
            share = f', finished {attrs["finished"]}/{attrs["flights"]}' if 'flights' in attrs else ''
            best = (f'; best {study.best_value * 100:.3f} cm (trial {study.best_trial.number})'
                    if any(t.state == optuna.trial.TrialState.COMPLETE for t in study.get_trials(deepcopy=False))
                    else '')
            duration = trial.duration.total_seconds() if trial.duration is not None else 0.0
            say(f'tune {setup.kind}: trial {trial.number} ({finished}/{setup.trials}) {what}{share} '
                f'in {duration:.1f} s{best}')

        remaining = max(0, setup.trials - done)
        if remaining:
            study.optimize(make_objective(setup, say if progress else None), n_trials=remaining,
                           callbacks=[report])
        starting = [t for t in study.get_trials(deepcopy=False) if t.user_attrs.get('starting_gains')
                    and t.state == optuna.trial.TrialState.COMPLETE]
        table = write_trials_table(study, setup)
        gains = write_gains(study, setup)
        chosen = {statistic: (trial.number, pick_value(trial.user_attrs, statistic, setup.spec.max_error_m),
                              write_gains(study, setup, trial, f'-{statistic}'), at_bounds(trial.params, setup.space()))
                  for statistic, trial in picks(study, setup).items()}
    return TuneOutcome(study.best_trial.number, study.best_value, starting[0].value if starting else math.nan,
                       len(study.trials), gains, table, chosen)
