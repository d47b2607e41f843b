"""The ablation tables of docs/PAPER.md 4.8.7 and 4.8.8: each change of the NNIT2FSMC defaults, one at a time.

One-at-a-time ablation of every change the defaults make to the paper's controller (NNIT2FSMC).

    run_stack.py study ablation --out DIR [--duration 60] [--campaign-flights 100] [--jobs 2]

The changes are the keys of ``factory.PAPER_FAITHFUL`` (docs/ADAPTIVE.md), grouped by what they do
(:data:`CHANGES`). Two directions:

* **reverted alone**: the defaults with one change set back to its paper-faithful value;
* **added alone**: the paper-faithful configuration with one change set to its default.

Per configuration: the nominal paper flight's RMSE [cm], the same with a 20 ms transport delay, with
the example campaign's sensor noise (paper_tables.py ``NOISE``), and with its 30 ms motor lag
(RMSE, or the failure), then a small example campaign (campaigns/paper-robustness.yaml,
``--campaign-flights`` flights of seed ``--campaign-seed``, a tuning seed: never a reported one):
finished flights and median RMSE. Every flight reads through the measurement stage of its gains
(the measurement-stage change switches it for the NNIT2FSMC as for every other kind).
"""
from __future__ import annotations

import argparse
import math
import statistics
import tempfile
from dataclasses import replace
from pathlib import Path

import yaml

from flight_stack.campaign.batch import BatchJob, fly_batch
from flight_stack.campaign.spec import load_spec
from nnit2fsmc_controller import factory

from . import paper_tables
from .common import add_out, run_all, study_name, write_table

STUDY = study_name(__name__)
LEARNING = tuple(key for key in factory.PAPER_FAITHFUL if key.endswith('learning_rate'))
WIDER = tuple(key for key in factory.PAPER_FAITHFUL if key.endswith(('input_scale', 'fuzzy_gain')))
#: change -> the PAPER_FAITHFUL keys it sets
CHANGES = {
    'flatness attitude rates': ('common.attitude_rates',),
    'tilt limit 0.8 rad above 0.15 m': ('common.max_tilt', 'common.low_altitude_height'),
    'priority allocation': ('common.allocation',),
    'roll/pitch lambda 8': ('common.lambda.phi', 'common.lambda.theta'),
    'wider fuzzy universes': WIDER,
    'learning rates per second (retuned)': ('nnit2fsmc.learning_rate_unit',) + LEARNING,
    'sigma-modification': ('nnit2fsmc.modification',),
    'measurement stage': ('common.measurement_filter_hz', 'common.velocity_filter_hz'),
    'take-off hold': ('common.takeoff_height',),
    'x, y acceleration feed-forward': ('nnit2fsmc.acceleration_feedforward',),
    'x, y network cap 5 m/s^2, initial weights +-1': ('nnit2fsmc.axes.x.nn_gain', 'nnit2fsmc.axes.y.nn_gain',
                                                      'nnit2fsmc.initial_weight_spread'),
    'x, y adaptation-rate bound 4 /s': ('nnit2fsmc.axes.x.max_adaptation_rate', 'nnit2fsmc.axes.y.max_adaptation_rate'),
}
DELAY_STEPS = 20          #: [control steps at 1 kHz] = 20 ms
MOTOR_LAG = 0.030         #: [s]


def configurations(gains_name: str | None = None) -> dict:
    """{name: flat gains}: defaults (the gains ``gains_name``, a file or a named set; None: the packaged ones),
    paper-faithful, and each change reverted alone and added alone."""
    defaults = factory.flatten_gains(factory.load_gains(gains_name))
    faithful = {**defaults, **factory.PAPER_FAITHFUL}
    missing = set(factory.PAPER_FAITHFUL) - {key for keys in CHANGES.values() for key in keys}
    if missing:
        raise ValueError(f'PAPER_FAITHFUL keys in no ablation change: {sorted(missing)}')
    out = {'defaults': defaults, 'paper-faithful': faithful}
    for change, keys in CHANGES.items():
        out[f'defaults without {change}'] = {**defaults, **{k: factory.PAPER_FAITHFUL[k] for k in keys}}
        out[f'paper-faithful with {change}'] = {**faithful, **{k: defaults[k] for k in keys}}
    return out


def single_flights(task) -> dict:
    """The four paper flights of one configuration (name, gains file, duration)."""
    name, gains_file, duration = task
    flight = paper_tables.Flight('nnit2fsmc', 'paper', duration, gains_file=gains_file)
    out = {}
    for label, variant in (('nominal', flight), ('delay 20 ms', replace(flight, delay_steps=DELAY_STEPS)),
                           ('noise', replace(flight, noise=True)), ('lag 30 ms', replace(flight, motor_lag=MOTOR_LAG))):
        o = paper_tables.fly(variant)
        out[label] = f'{o.rmse_cm:.3g}' if o.failure is None else f'{o.rmse_cm:.3g} (failed: {o.failure})'
    return out


def campaign(task) -> str:
    """'finished / flights, median RMSE [cm]' of one configuration's small campaign (name, gains file, flights,
    seed): one batch of the campaign's batch path."""
    _, gains_file, flights, seed = task
    spec = replace(load_spec('campaigns/paper-robustness.yaml'), seed=seed)
    rows = fly_batch(BatchJob(spec, 'nnit2fsmc', tuple(range(flights)), gains_file=gains_file))   # one batch
    finished = [row for row in rows if not row['failure']]
    rmse = [100.0 * row['rmse_position_m'] for row in finished]
    median = statistics.median(rmse) if rmse else math.nan
    return f'{len(finished)} / {flights}, {median:.3g}'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--duration', type=float, default=60.0, help='[s] the single flights (default 60)')
    parser.add_argument('--campaign-flights', type=int, default=100, help='0: no campaign column')
    parser.add_argument('--campaign-seed', type=int, default=2, help='a tuning seed (default 2)')
    parser.add_argument('--only', help='comma-separated configuration names (default: all)')
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--gains', default=None, help='the defaults\' gains file or named set (default: packaged; '
                                                      'docs/PAPER.md says which set each table flew)')


def run(args: argparse.Namespace) -> int:
    configs = configurations(args.gains)
    if args.only:
        configs = {name: configs[name.strip()] for name in args.only.split(',')}
    folder = Path(tempfile.mkdtemp(prefix='ablation-'))
    files = {}
    for i, (name, flat) in enumerate(configs.items()):
        files[name] = str(folder / f'gains-{i}.yaml')
        Path(files[name]).write_text(yaml.safe_dump(factory.unflatten_gains(flat)))
    singles = run_all(single_flights, [(n, files[n], args.duration) for n in configs], args.jobs, STUDY,
                      lambda task: f'{task[0]}: its 4 paper flights')
    campaigns = (run_all(campaign, [(n, files[n], args.campaign_flights, args.campaign_seed) for n in configs],
                         args.jobs, STUDY, lambda task: f'{task[0]}: its campaign of {task[2]} flights')
                 if args.campaign_flights else ['' for _ in configs])
    lines = [f'### Ablation of the NNIT2FSMC defaults (paper helix {args.duration:g} s; run_stack.py study ablation)',
             '',
             '| configuration | RMSE [cm] nominal | 20 ms delay | noise | 30 ms lag | '
             f'campaign: finished, median RMSE [cm] ({args.campaign_flights} flights, seed {args.campaign_seed}) |',
             '|---|---:|---:|---:|---:|---:|']
    for name, single, small in zip(configs, singles, campaigns):
        lines.append(f'| {name} | {single["nominal"]} | {single["delay 20 ms"]} | {single["noise"]} | '
                     f'{single["lag 30 ms"]} | {small} |')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
