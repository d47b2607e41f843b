"""The issue-28 before-and-after tables of docs/VEHICLES.md and docs/PAPER.md 4.9, flown by every controller kind.

The NNIT2FSMC's failures of issue 28, flown by every controller kind, before and after.

Cases (``--cases``), each on ``--vehicle`` (a shipped name or a file) and ``--plant`` (quad_sim or rotorpy):

* ``lemniscate``: the fast figure-eight (2.8 m/s, 4 m/s^2), section IV disturbances;
* ``circle``: the ``circle-fast`` scenario (R = 2 m, 2.51 m/s, 3.16 m/s^2, heading held at 0), section IV
  disturbances: the circle on which issue 28 saw a roll/pitch limit cycle in RotorPy;
* ``wind``: the paper helix in 8 m/s mean wind with moderate Dryden gusts, seeds F..F+S-1 (``--first-seed``, ``--seeds``);
* ``loss``: the paper helix with a 25 % loss of every rotor from 10 s on.

Every flight has 5 ms of motor lag (``motor_time_constant_s`` on our plant; RotorPy's own motors on
``rotorpy``). Per flight: finished, position RMSE [cm], body-rate RMS [rad/s] (|p, q, r|), roll-rate RMS,
heading error RMS [deg] and the largest U1 [N], all after SETTLED.

``--gains``: ``after`` is today's packaged file; ``before`` the NNIT2FSMC's gains as they were before issue 28:
stated in newtons for every vehicle (z fuzzy_gain 8 N, nn_gain 10 N, ...: ``git show
478b307:ros2_ws/src/nnit2fsmc_controller/nnit2fsmc_controller/config/controller.yaml``) and no bound of the
networks' adaptation rate (max_adaptation_rate 0). The baselines' gains did not change in issue 28 (the
same commit's file has the same pid, smc_integral and se3 sections; l1-se3 and indi came later), so a
baseline is flown once and its row stands for both.

    run_stack.py study carry-over --out DIR --cases circle --vehicle hummingbird
    run_stack.py study carry-over --out DIR --cases wind,loss --plant rotorpy --seeds 2 --duration 20

The vehicle defaults to the heavier X frame of issue 28 (HEAVY_X, beside this module in vehicles/). Writes a row per
case, plant, kind and gains with the figures of every flight (one per wind seed) to DIR/carry-over.md, and with
``--json`` the figures to DIR/carry-over.jsonl (appended, one JSON object per row).
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import json
from pathlib import Path
from unittest import mock

import numpy as np

from flight_stack.api import fly, load_gains, load_vehicle
from nnit2fsmc_controller.gain_units import control_scale
from quad_msgs_bridge.frames import body_rates_from_euler_rates

from .common import add_out, names, progress, study_name, write_table

STUDY = study_name(__name__)
#: the peer's 0.826 kg X frame of issue 28 (docs/VEHICLES.md)
HEAVY_X = Path(__file__).resolve().parent / 'vehicles' / 'issue28-heavy-x.yaml'

KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'l1-se3', 'indi')
SETTLED = 5.0     #: [s] metrics after it
MOTOR_LAG = 0.005   #: [s] the heavier vehicle's (issue 28); RotorPy's motors have it already
LOSS = {'at_s': 10.0, 'loss': [0.25] * 4}
WIND = {'mean_speed_mps': 8.0, 'turbulence': 'moderate'}
#: the NNIT2FSMC's gains before issue 28, in the law's units on every vehicle: (fuzzy_gain, nn_gain [N or N m],
#: learning_rate [1/s per (N or N m)^2]) of commit 478b307 (x, y were in m/s^2 already and are unchanged)
NEWTON_GAINS = {'z': (8.0, 10.0, 0.5), 'phi': (2.0, 0.5, 50.0), 'theta': (2.0, 0.5, 50.0),
                'psi': (0.03, 0.03, 30000.0)}


def before_gains(vehicle) -> dict:
    """The packaged gains with the NNIT2FSMC's as they were before issue 28 (module docstring), restated in the
    file's per-unit units for ``vehicle`` so that its law gets the former newton numbers."""
    gains = copy.deepcopy(load_gains())
    params = load_vehicle(vehicle)
    for axis, settings in gains['nnit2fsmc']['axes'].items():
        settings['max_adaptation_rate'] = 0.0
        if axis in NEWTON_GAINS:
            scale = control_scale(params, axis)
            fuzzy, network, rate = NEWTON_GAINS[axis]
            settings.update(fuzzy_gain=fuzzy / scale, nn_gain=network / scale, learning_rate=rate * scale * scale)
    return gains


@contextlib.contextmanager
def gains_of(which: str, vehicle):
    """(gains mapping or None for the packaged file) for ``which``; the former gains fly without today's load-time
    hover check, which did not exist before issue 28 and refuses them on a vehicle heavier than 0.815 kg."""
    if which == 'after':
        yield None
        return
    with mock.patch('nnit2fsmc_controller.factory.check_hover_authority', lambda *args: None):
        yield before_gains(vehicle)


def flown(kind: str, scenario: str, duration: float, gains, **world) -> dict:
    """The figures of one flight (module docstring)."""
    flight = fly(kind, scenario, duration=duration, gains=gains, **world)
    late = flight.time >= SETTLED
    if not late.any():   # ended before SETTLED
        return {'finished': False, 'ended_s': float(flight.time[-1]), 'rmse_cm': np.nan, 'body_rate_rms': np.nan,
                'roll_rate_rms': np.nan, 'heading_rms_deg': np.nan, 'U1_max': np.nan}
    rates = np.array([body_rates_from_euler_rates(row[6:9], row[9:12]) for row in flight.state[late]])
    heading = np.angle(np.exp(1j * (flight.state[late, 8] - flight.reference_yaw[late])))
    return {'finished': not flight.ended_early, 'ended_s': float(flight.time[-1]),
            'rmse_cm': 100.0 * flight.summary['rmse_position_m'],
            'body_rate_rms': float(np.sqrt(np.mean(np.sum(rates ** 2, axis=1)))),
            'roll_rate_rms': float(np.sqrt(np.mean(rates[:, 0] ** 2))),
            'heading_rms_deg': float(np.degrees(np.sqrt(np.mean(heading ** 2)))),
            'U1_max': float(flight.controls[late, 0].max())}


def worlds(case: str, vehicle, plant: str, seeds: range) -> list[tuple[str, dict]]:
    """[(scenario, world keyword arguments of fly), ...] of a case."""
    common = dict(vehicle=vehicle, plant=plant, motor_time_constant_s=MOTOR_LAG if plant == 'quad_sim' else 0.0)
    if case == 'wind':
        return [('paper', dict(common, wind=WIND, seed=seed)) for seed in seeds]
    if case == 'loss':
        return [('paper', dict(common, rotor_efficiency_loss=LOSS))]
    return [({'circle': 'circle-fast'}.get(case, case), common)]


#: the columns of a row: the figure, how a flight's value is written
COLUMNS = (('RMSE [cm]', 'rmse_cm'), ('body-rate RMS [rad/s]', 'body_rate_rms'),
           ('heading RMS [deg]', 'heading_rms_deg'), ('U1 max [N]', 'U1_max'), ('ended [s]', 'ended_s'))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--cases', default='circle,wind,loss', help='comma-separated: lemniscate, circle, wind, loss')
    parser.add_argument('--vehicle', default=str(HEAVY_X), help='shipped name or file (default: the heavier X frame)')
    parser.add_argument('--plant', default='quad_sim', help='quad_sim or rotorpy')
    parser.add_argument('--gains', default='before,after', help='before, after or both (comma-separated)')
    parser.add_argument('--kinds', default=','.join(KINDS))
    parser.add_argument('--seeds', type=int, default=3, help='wind seeds: how many')
    parser.add_argument('--first-seed', type=int, default=0, help='wind seeds: the first')
    parser.add_argument('--duration', type=float, default=30.0, help='[s] every flight')
    parser.add_argument('--json', action='store_true', help='also append the figures to DIR/carry-over.jsonl')


def run(args: argparse.Namespace) -> int:
    lines = ['| case | plant | kind | gains | finished | ' + ' | '.join(title for title, _ in COLUMNS) + ' |',
             '|---|---|---|---|---:|' + '---|' * len(COLUMNS)]
    for case in names(args.cases):
        for kind in names(args.kinds):
            for which in names(args.gains):
                if which == 'before' and not kind.startswith('nnit2fsmc'):
                    continue   # the baselines' gains are the same before and after: flown once, as 'after'
                with gains_of(which, args.vehicle) as gains:
                    rows = [flown(kind, scenario, args.duration, gains, **world)
                            for scenario, world in worlds(case, args.vehicle, args.plant,
                                                          range(args.first_seed, args.first_seed + args.seeds))]
                label = which if kind.startswith('nnit2fsmc') else 'both'
                finished = f'{sum(r["finished"] for r in rows)}/{len(rows)}'
                lines.append(f'| {case} | {args.plant} | {kind} | {label} | {finished} | '
                             + ' | '.join(' '.join(f'{r[key]:.2f}' for r in rows) for _, key in COLUMNS) + ' |')
                progress(STUDY, f'{case}, {kind}, gains {label}: {len(rows)} flights, finished {finished}')
                if args.json:
                    args.out.mkdir(parents=True, exist_ok=True)
                    with (args.out / f'{STUDY}.jsonl').open('a') as out:
                        out.write(json.dumps({'case': case, 'vehicle': str(args.vehicle), 'plant': args.plant,
                                              'kind': kind, 'gains': label, 'rows': rows}) + '\n')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
