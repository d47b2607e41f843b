"""The gyro-bias and authority tables of docs/PAPER.md 4.8.5 and 4.8.8: the NNIT2FSMC's structural limits.

The structural limits of the NNIT2FSMC beside the baselines, with their figures.

    run_stack.py study limits --out DIR [--duration 30] [--jobs 2]

1. **Gyro bias.** A constant bias b on the measured yaw rate, hover at 1 m for 20 s (no disturbance),
   every controller through the default measurement stage: the mean true yaw error of the last 5 s
   beside the formula. The NNIT2FSMC's adaptive action (network and fuzzy term) acts on the measured
   surface S = de + lambda e and drives it to 0, leaving the estimated error -b / lambda; an integral
   of the error (pid, se3, smc-integral) drives the estimated error to 0. The complementary filter's
   yaw estimate leads the true yaw by b / w (w = 2 pi measurement_filter_hz). Formula: nnit2fsmc
   -b / lambda_psi - b / w; pid, se3 and smc-integral -b / w (tests/test_science_regressions.py checks
   nnit2fsmc and pid to 5 %).
2. **Authority against wind.** The paper helix (``--duration`` s, section IV disturbances) in a
   steady 6 m/s wind along +x: RMSE per controller. The network's output is capped at nn_gain
   (x, y: 1.5 m/s^2) and the fuzzy term at fuzzy_gain; the integral action of the baselines has no
   such cap below its clamp. ``nnit2fsmc, previous x, y network``: the same with the x, y network of the
   defaults before issue 21's improvement (:data:`PREVIOUS`; docs/PAPER.md 4.8.8).
3. **Authority against path speed.** The helix three times faster (0.5 -> 1.5 rad/s: 1.5 m/s,
   2.25 m/s^2 centripetal), no wind: RMSE per controller, and the same previous-network row.
"""
from __future__ import annotations

import argparse
import math

import numpy as np

from flight_stack.closed_loop import ClosedLoop, FailureRules
from flight_stack.embedded import Perturbations, fly_embedded
from nnit2fsmc_controller.factory import (build_controller, build_measurement_stage, flatten_gains, load_gains,
                                          unflatten_gains)
from nnit2fsmc_controller.trajectory import Helix, make_scenario
from quad_msgs_bridge.review.metrics import flight_metrics
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel
from quad_sim.perturbations.wind import Wind
from quad_sim.simulator import Simulator

from .common import add_out, run_all, study_name, write_table

STUDY = study_name(__name__)

CONTROLLERS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral')
BIAS = 0.05          #: [rad/s] on the measured yaw rate
WIND = 6.0           #: [m/s] along +x
FAST = 1.5           #: [rad/s] helix angular rate (paper: 0.5)
HOVER = 20.0         #: [s]
#: the x, y network of the defaults before issue 21's improvement (flat gain names -> values)
PREVIOUS = {'nnit2fsmc.acceleration_feedforward': False, 'nnit2fsmc.initial_weight_spread': 0.5,
            'nnit2fsmc.leakage': 0.02, 'nnit2fsmc.axes.x.nn_gain': 1.5, 'nnit2fsmc.axes.y.nn_gain': 1.5,
            'nnit2fsmc.axes.x.learning_rate': 10.0, 'nnit2fsmc.axes.y.learning_rate': 10.0}


def yaw_error_under_bias(kind: str, gains_name: str | None = None) -> tuple[float, float]:
    """(mean true yaw error [rad] of the last 5 s, the formula's) for a hover with BIAS on the yaw rate, with the
    gains ``gains_name`` (a gains file or a named set; None: the packaged ones)."""
    params, disturbances = load_vehicle_file()
    gains = load_gains(gains_name)
    controller = build_controller(kind, params, gains)
    simulator = Simulator(QuadrotorModel(params, disturbances.switched(False)), controller.dt,
                          [0.0, 0.0, 1.0] + [0.0] * 9)
    simulator.forces = (params.hover_force,) * 4
    hold = make_scenario('hover', HOVER).sample(0.0)._replace(position=(0.0, 0.0, 1.0))
    loop = ClosedLoop(controller, simulator, lambda t: hold, 1, FailureRules(HOVER, 1.0),
                      observe=lambda t, s: ([*s[:11], s[11] + BIAS], None), measurement=build_measurement_stage(gains))
    errors = []
    for _ in range(int(round(HOVER / controller.dt))):
        step = loop.step()
        if step.time >= HOVER - 5.0:
            errors.append(step.truth[8] - hold.yaw)
    w = 2.0 * math.pi * gains['common']['measurement_filter_hz']
    formula = -BIAS / w - (BIAS / gains['common']['lambda']['psi'] if kind == 'nnit2fsmc' else 0.0)
    return float(np.mean(errors)), formula


def helix_rmse(task) -> tuple[float, str | None]:
    """(RMSE [cm] after 5 s, failure) of (kind, previous network?, wind [m/s], angular rate [rad/s], duration,
    gains file or named set)."""
    kind, previous, wind, rate, duration, gains_name = task
    params, disturbances = load_vehicle_file()
    gains = load_gains(gains_name)
    if previous:
        gains = unflatten_gains({**flatten_gains(gains), **PREVIOUS})
    perturbations = Perturbations(wind=Wind(1e-3, mean_speed=wind, direction=0.0) if wind else None)
    result = fly_embedded(kind, Helix(angular_rate=rate, duration=duration), params, disturbances, gains, duration,
                          1000.0, perturbations=perturbations, rules=FailureRules(5.0, 1.0))
    if result.failure is not None and result.failure_time_s <= 5.0:
        return math.nan, result.failure
    metrics = flight_metrics(result.record, 5.0, params.F_min, params.F_max)
    return 100.0 * metrics['rmse_position_m'], result.failure


def _bias_task(task):
    return yaw_error_under_bias(*task)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--duration', type=float, default=30.0, help='[s] helix flights (default 30)')
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--gains', default=None, help='gains file or named set (default: packaged; docs/PAPER.md '
                                                      'says which set each table flew)')


def run(args: argparse.Namespace) -> int:
    load_gains(args.gains)     # a named set or a file: refused here, before anything flies
    rows = [(kind, False) for kind in CONTROLLERS] + [('nnit2fsmc', True)]
    bias = run_all(_bias_task, [(kind, args.gains) for kind in CONTROLLERS], args.jobs, STUDY,
                   lambda task: f'{task[0]}: hover with a gyro bias')
    tasks = [(kind, nn, WIND, 0.5, args.duration, args.gains) for kind, nn in rows] + \
            [(kind, nn, 0.0, FAST, args.duration, args.gains) for kind, nn in rows]
    flown = dict(zip(tasks, run_all(helix_rmse, tasks, args.jobs, STUDY,
                                    lambda t: f'{t[0]}{", previous network" if t[1] else ""}: helix at {t[3]:g} '
                                              f'rad/s in {t[2]:g} m/s wind')))
    lines = [f'### Constant yaw-rate bias {BIAS:g} rad/s, hover {HOVER:g} s (run_stack.py study limits)', '',
             '| controller | steady yaw error [mrad] | formula [mrad] |', '|---|---:|---:|']
    lines += [f'| {kind} | {1e3 * e:.2f} | {1e3 * f:.2f} |' for kind, (e, f) in zip(CONTROLLERS, bias)]
    lines += ['', f'### Authority: helix ({args.duration:g} s) in a {WIND:g} m/s wind, and {FAST / 0.5:g}x faster '
              '(run_stack.py study limits)', '',
              f'| controller | RMSE [cm] wind {WIND:g} m/s | RMSE [cm] helix x{FAST / 0.5:g} |', '|---|---:|---:|']
    for kind, nn in rows:
        name = f'{kind}, previous x, y network' if nn else kind
        cells = []
        for task in ((kind, nn, WIND, 0.5, args.duration, args.gains), (kind, nn, 0.0, FAST, args.duration, args.gains)):
            rmse, failure = flown[task]
            cells.append(f'{rmse:.3g}' + (f' ({failure})' if failure else ''))
        lines.append(f'| {name} | {cells[0]} | {cells[1]} |')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
