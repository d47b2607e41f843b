"""Every kind on PX4's SIH quadrotor, tuned for it, flown on PX4 SITL beside PX4's own controller and on our plant
with the same vehicle file: the tables of docs/PX4.md ("Measured").

    # 1. every kind tuned for PX4's SIH by one protocol (docs/PX4.md, "Tuned for PX4"), then its tail pick
    #    (ROOT/KIND/gains-KIND-p95.yaml) written into the named gains set px4-sih
    run_stack.py tune campaigns/px4-sih.yaml --vehicle px4-sih-quadx --controller KIND --attitude --trials 48 \\
        --flights 50 --duration 30 --seeds 1,2 --sampler-seed 0 --objective p95 --out ROOT/KIND
    run_stack.py study px4-sih package ROOT
    # 2. fly (PX4 SITL, the Agent and px4_msgs found as for --plant px4-sitl; resumable) and write the tables
    run_stack.py study px4-sih run --out DIR --repeats 5

``run`` flies every kind of ``--kinds`` and ``px4`` (PX4's own controller) on each scenario (``hover`` for
``--hover-duration`` s, ``paper``: the helix, 60 s) ``--repeats`` times with ``run_stack.py --plant px4-sitl
--vehicle px4-sih-quadx --gains px4-sih`` (PX4 takes off and hands over at the reference's first point, 2.5 m up),
``--jobs`` at a time, each into DIR/px4/SCENARIO/KIND/rN (a run with a summary there is not flown again); and each
kind once on our plant (``--plant quad_sim``: deterministic) with the same vehicle file and gains, SIH's motor lag
(SIH_T_TAU 0.05 s), ``--delay`` and no disturbances, from the ground as every flight there starts. Writes
DIR/px4-sih.md: per scenario, plant and kind the runs, how many finished (flew to the end with the position error
within 1 m after the 5 s settling window) and why the others failed, and over the finished ones the median
(min-max) of the position RMSE and max error after settling, chattering and rotor saturation.
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import sys
from pathlib import Path

from nnit2fsmc_controller.factory import DEFAULT_CONTROLLER_FILE, flatten_gains, load_gains, shipped_gains
from nnit2fsmc_controller.search_spaces import search_space, values_in
from quad_msgs_bridge.validation import ParameterError

from .common import add_out, names, progress, run_all, study_name, write_table

STUDY = study_name(__name__)
KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'l1-se3', 'indi')
PX4_OWN = 'px4'
VEHICLE = 'px4-sih-quadx'
GAINS_SET = 'px4-sih'
#: [Hz] the rate the kinds were tuned at and fly at on PX4 (its odometry over uXRCE-DDS, docs/PX4.md "Rates")
CONTROL_RATE = 100.0
SIH_MOTOR_TIME_CONSTANT = 0.05     #: [s] SIH_T_TAU (sih/sih_params.c)
ROOT = Path(__file__).resolve().parents[2]
HEADER = ('# The px4-sih gains: the packaged set with every kind tuned for PX4\'s SIH quadrotor X (--vehicle '
          'px4-sih-quadx)\n# at 100 Hz, written by `run_stack.py study px4-sih package` from each kind\'s tail pick '
          '(docs/PX4.md, "Tuned for PX4").\n# Fly it by name: --gains px4-sih. Units and meaning: as in '
          'config/controller.yaml.\n')


# --- package -----------------------------------------------------------------------------------------------------

def package(root: Path, kinds, into: Path) -> list[str]:
    """Write the complete gains file ``into``: the packaged one with each kind's point of its position and attitude
    space (``tune --attitude``) from ``root/KIND/gains-KIND-p95.yaml`` and ``common.control_rate`` 100 Hz, comments
    and layout kept; checked to change exactly those gains. The lines saying each kind's point."""
    from .scoreboard import set_in_text, write_checked
    values, report = {'common.control_rate': CONTROL_RATE}, []
    for kind in kinds:
        picked = root / kind / f'gains-{kind}-p95.yaml'
        if not picked.is_file():
            raise ParameterError(f'{picked}: missing (run the tune of docs/PX4.md for {kind} into {root / kind})')
        point = values_in(load_gains(picked, kind=kind), kind, attitude=True)
        values.update({gain: point[d.name] for d in search_space(kind, attitude=True) for gain in d.gains})
        # the tune's own words: trial, objective, median, p95 and the flights it finished (below 99 %: no trial
        # finished 99 % of its flights, and the pick is the penalised ranking's)
        header = ' '.join(line.lstrip('# ') for line in picked.read_text().split('\n')[:2])
        report.append(f'{kind}: {header} Point: ' + ', '.join(f'{name} = {value:.4g}' for name, value in point.items()))
    text = HEADER + ''.join(f'# {line}\n' for line in report) + _body(DEFAULT_CONTROLLER_FILE.read_text())
    write_checked(into, set_in_text(text, values), {**flatten_gains(load_gains(None)), **values})
    return report


def _body(text: str) -> str:
    """The packaged file without its leading comment lines (the named set has its own header)."""
    lines = text.split('\n')
    start = next(index for index, line in enumerate(lines) if line and not line.startswith('#'))
    return '\n'.join(lines[start:])


# --- run -----------------------------------------------------------------------------------------------------------

def px4_command(kind: str, scenario: str, hover_duration: float, out: Path) -> list[str]:
    """The run_stack.py command of one PX4 SITL flight."""
    command = [sys.executable, str(ROOT / 'run_stack.py'), '--plant', 'px4-sitl', '--vehicle', VEHICLE,
               '--controller', kind, '--scenario', scenario, '--out', str(out), '--overwrite', '--quiet']
    if kind != PX4_OWN:
        command += ['--gains', GAINS_SET]
    if scenario == 'hover':
        command += ['--duration', f'{hover_duration:g}']
    return command


def fly_px4(task) -> dict:
    """One PX4 SITL flight (its summary; flown only if DIR has none); a failed one's summary gets when its bag
    first shows the vehicle tilted past :data:`FLIPPED_TILT` (``tilted_s``; None: never)."""
    command, out = task
    summary = out / 'summary.json'
    if not summary.is_file():
        subprocess.run(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       check=False)
    if not summary.is_file():
        return {'failure': f'no summary (run it alone: {" ".join(command)})', 'flight_ok': False}
    result = json.loads(summary.read_text())
    if not result.get('flight_ok') and (out / 'bag').exists():
        result['tilted_s'] = tilted_at(out / 'bag')
    return result


FLIPPED_TILT_DEG = 60.0           #: [deg] tilt past which a PX4 flight is said to have flipped
FLIPPED_TILT = math.radians(FLIPPED_TILT_DEG)


def tilted_at(bag: Path) -> float | None:
    """The first flight time [s] at which the bag's odometry shows the vehicle tilted past FLIPPED_TILT (roll
    and pitch: the angle between its body z and the vertical), None if never."""
    import numpy as np
    from quad_msgs_bridge.review.flight_from_bag import read_flight
    flight = read_flight(bag, vehicle_file=VEHICLE)
    phi, theta = flight.state[:, 6], flight.state[:, 7]
    over = np.flatnonzero(np.arccos(np.clip(np.cos(phi) * np.cos(theta), -1.0, 1.0)) > FLIPPED_TILT)
    return float(flight.time[over[0]]) if over.size else None


def fly_ours(kind: str, scenario: str, hover_duration: float, delay: float) -> dict:
    """The same flight on our plant (deterministic: once), its summary."""
    from flight_stack.api import fly
    flight = fly(kind, scenario, duration=hover_duration if scenario == 'hover' else None, vehicle=VEHICLE,
                 gains=GAINS_SET, disturbances=False, motor_time_constant_s=SIH_MOTOR_TIME_CONSTANT, delay_s=delay,
                 max_error=1.0)
    return flight.summary


def failed(summary: dict) -> tuple[str, float | None] | None:
    """Why a run failed and when [s] (None: it finished: flew to its end within --max-error, ``flight_ok``): what
    ended it (a PX4 failsafe, a crash), else the failures its review found (the max error above 1 m)."""
    if summary.get('flight_ok'):
        return None
    if summary.get('failure'):
        return summary['failure'], summary.get('failure_time_s')
    if summary.get('tilted_s') is not None:
        return f'tilted past {FLIPPED_TILT_DEG:g} deg (flipped)', summary['tilted_s']
    failures = summary.get('failures') or ['failed']
    if all(text.startswith('max position error') for text in failures):
        return 'max position error above 1 m', None
    return '; '.join(failures), None


def reasons(summaries: list[dict]) -> str:
    """The failed runs' reasons, counted, with the span of their times: '2: crashed at 1.2-1.5 s; 1: ...'."""
    grouped: dict[str, list] = {}
    for why in (failed(s) for s in summaries):
        if why is not None:
            grouped.setdefault(why[0], []).append(why[1])
    parts = []
    for reason, times in grouped.items():
        known = [t for t in times if t is not None]
        span = '' if not known else (f' at {min(known):.1f} s' if min(known) == max(known)
                                     else f' at {min(known):.1f}-{max(known):.1f} s')
        parts.append(f'{len(times)}: {reason}{span}')
    return '; '.join(parts) if parts else '-'


def spread(values: list[float], scale: float = 100.0, digits: int = 1) -> str:
    """'median (min-max)' of ``values`` times ``scale``; 'n/a' for none."""
    if not values:
        return 'n/a'
    median = statistics.median(values) * scale
    if len(values) == 1:
        return f'{median:.{digits}f}'
    return f'{median:.{digits}f} ({min(values) * scale:.{digits}f}-{max(values) * scale:.{digits}f})'


def row(plant: str, kind: str, summaries: list[dict]) -> str:
    flew = [s for s in summaries if failed(s) is None]
    measured = [s for s in flew if 'not_measured' not in s]
    cells = [spread([s['rmse_position_m'] for s in flew]), spread([s['max_position_error_m'] for s in flew]),
             spread([s['chattering_force_n_per_s'] for s in measured], 1.0, 2),
             spread([s['chattering_moment_nm_per_s'] for s in measured], 1.0, 2),
             spread([s['saturation_fraction'] for s in measured], 100.0, 1)]
    return f'| {plant} | {kind} | {len(summaries)} | {len(flew)} | {reasons(summaries)} | ' + ' | '.join(cells) + ' |'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    commands = parser.add_subparsers(dest='command', required=True)
    p = commands.add_parser('package', help=f'each kind\'s tail pick into the named gains set {GAINS_SET}')
    p.add_argument('root', type=Path, help='folder holding KIND/gains-KIND-p95.yaml for each kind')
    p.add_argument('--kinds', default=','.join(KINDS))
    p.add_argument('--into', type=Path, default=None,
                   help=f'the gains file to write (default: the named set {GAINS_SET} in config/gains/)')
    p = commands.add_parser('run', help='fly PX4 SITL and our plant, write the tables')
    add_out(p)
    p.add_argument('--kinds', default=','.join(KINDS), help='our kinds (PX4\'s own controller flies as well)')
    p.add_argument('--scenarios', default='hover,paper')
    p.add_argument('--repeats', type=int, default=5, help='PX4 SITL flights per kind and scenario (default 5)')
    p.add_argument('--hover-duration', type=float, default=20.0, help='[s] of the hover (default 20)')
    p.add_argument('--delay', type=float, default=0.02,
                   help='[s] transport delay of our plant\'s flights (default 0.02: the tuning world\'s largest)')
    p.add_argument('--jobs', type=int, default=2, help='PX4 SITL flights at a time (default 2)')


def run(args: argparse.Namespace) -> int:
    if args.command == 'package':
        into = args.into or DEFAULT_CONTROLLER_FILE.parent / 'gains' / f'{GAINS_SET}.yaml'
        for line in package(args.root, names(args.kinds), into):
            print(line)
        progress(STUDY, f'wrote the gains file {into}')
        return 0
    if GAINS_SET not in shipped_gains():
        raise ParameterError(f'the named gains set {GAINS_SET} is missing: run_stack.py study px4-sih package ROOT')
    from flight_stack.cli import check_count
    from flight_stack.px4_sitl import find_px4
    find_px4()                       # refused in one line, before anything flies, if PX4 SITL cannot
    check_count('--repeats', args.repeats, 1, 100)
    check_count('--jobs', args.jobs, 1, 8)
    kinds, scenarios = names(args.kinds), names(args.scenarios)
    tasks = [(px4_command(kind, scenario, args.hover_duration, args.out / 'px4' / scenario / kind / f'r{rep}'),
              args.out / 'px4' / scenario / kind / f'r{rep}')
             for rep in range(1, args.repeats + 1) for scenario in scenarios for kind in [*kinds, PX4_OWN]]
    flown = run_all(fly_px4, tasks, args.jobs, STUDY, label=lambda task: str(task[1]))
    results = {}
    for (_, out), summary in zip(tasks, flown):
        scenario, kind = out.parts[-3], out.parts[-2]
        results.setdefault((scenario, kind), []).append(summary)
    lines = [f'PX4 SIH (`--plant px4-sitl`, {args.repeats} runs, PX4 taking off) and ours (`--plant quad_sim`, once: '
             f'SIH\'s 50 ms motor lag, {args.delay * 1000:g} ms delay, no disturbances, from the ground), '
             f'`--vehicle {VEHICLE} --gains {GAINS_SET}` at {CONTROL_RATE:g} Hz. RMSE and max error [cm] after 5 s, '
             'chattering U1 [N/s] and d U2 + d U3 + U4 [N m/s], rotor saturation [% of steps]: median (min-max) '
             'over the finished runs; PX4\'s own chattering and saturation are not on uXRCE-DDS (n/a).']
    for scenario in scenarios:
        lines += ['', f'**{scenario}**', '',
                  '| plant | kind | runs | finished | why the others failed | RMSE [cm] | max error [cm] '
                  '| chattering U1 | chattering moments | rotor saturation [%] |', '|---|---|---|---|---|---|---|---|---|---|']
        lines += [row('PX4 SIH', kind, results[(scenario, kind)]) for kind in [*kinds, PX4_OWN]]
        for kind in kinds:
            progress(STUDY, f'our plant: {kind}, {scenario}')
            lines.append(row('ours', kind, [fly_ours(kind, scenario, args.hover_duration, args.delay)]))
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
