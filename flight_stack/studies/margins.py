"""The stability-margin tables of docs/PAPER.md 4.8.4: simulated delay and gain margins, linearised axis loops.

Stability margins of each controller: simulated (delay with and without motor lag, gain) and
linearised (phase, delay and gain margin of each axis loop).

    run_stack.py study margins --out DIR                   # nnit2fsmc, pid, se3, smc-integral
    run_stack.py study margins --out DIR --controllers pid --jobs 2 --duration 30
    run_stack.py study margins --out DIR --linear-only

**Simulated** (embedded flights of the paper helix with its section IV disturbances, the nominal
vehicle, the packaged gains, every controller through the same measurement stage; physics at
4 kHz, so that a delay is resolved to 0.25 ms: whole control steps of the transport delay plus a
fraction of a control step, paper_tables.py ``FractionalDelaySimulator``):

* delay margin without motor lag and with the example campaign's 30 ms motor lag: the smallest
  delay at which the flight is unstable, by bisection over 0..``--max-delay`` ms to 0.25 ms;
* gain margin: the smallest factor g > 1 on every rotor's thrust and reaction torque (a loop gain
  of g at the plant input) at which the flight is unstable, by bisection on log g over [1, 16]
  (``GAIN_STEPS`` steps: g to within a factor 16^(1/2^(GAIN_STEPS+1)), 1.4 % at 6 steps).

Criterion (paper_tables.py ``instability``): the flight fails (non-finite, flipped, crashed,
1 m from the reference after settling), or its position RMSE exceeds the absolute yardstick of
2 cm, or its attitude chattering TV(U2) + TV(U3) over the last 20 s (a limit cycle) or, for the delay
margins only, its RMSE exceeds 10x the flight without the perturbation (with the same motor lag).
The gain margin leaves the relative RMSE out: more thrust than the nominal model says is also a
model error of the hover feed-forward, whose transient multiplies a tiny nominal RMSE without any
oscillation.

**Linearised** (each axis loop alone, near its surface S = 0, as a continuous-time SISO loop
L(s) = C(s) P(s) in units of the subsystem's q''):

* P(s) = e^(-s dt/2) / (s^2 (tau_m s + 1)): a double integrator (the nominal model's known terms
  are fed forward or small), the zero-order hold of the control period dt as half a period of
  delay, and the first-order motor lag tau_m (0 or 30 ms);
* C(s): nnit2fsmc k (s F_v(s) + lambda) with k = (small-signal slope of the IT2 term at S = 0)
  x fuzzy_gain / input_scale x b (baseline_gains.py) and the network left out (it adapts
  slowly: an added slow integral); pid and se3 kp + kd s F_v(s) + ki / s; smc-integral inside its
  boundary layer slope (s F_v(s) + lambda + integral_gain / s); F_v(s) = 1 / (1 + s / (2 pi f_v)),
  the velocity filter of the measurement stage on x, y, z (the complementary filter of position
  and angles costs no phase with exact rates: left out);
* x and y are taken with an ideal attitude loop (the cascade's inner loop is some 3-4 times faster);
  the roll and pitch loops are the ones a delay destabilises.

From L(j w) on a log grid of 10^-2..10^4 rad/s (refined by bisection at each crossing): the phase
margin PM at each gain crossover w_c (|L| = 1), the delay margin min PM / w_c [s] (the extra pure
delay that brings the first crossover to -180 degrees), and the gain margin 1 / |L| at the first
phase crossover (-180 degrees). The controller's figure is its smallest axis figure.
"""
from __future__ import annotations

import argparse
import cmath
import json
import math
from dataclasses import replace

from nnit2fsmc_controller.controller import AXES
from nnit2fsmc_controller.factory import control_period, load_gains

from . import paper_tables
from .baseline_gains import fuzzy_slope
from .common import add_out, names, run_all, study_name, write_table

STUDY = study_name(__name__)

CONTROLLERS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral')
MOTOR_LAG = 0.030        #: [s] the example campaign's motor time constant
PHYSICS_RATE = 4000.0    #: [Hz] 0.25 ms delay resolution at 1 kHz control
GAIN_STEPS = 6
MAX_DELAY = 0.064        #: [s] the delay bisection's range is 0..MAX_DELAY (--max-delay)
MAX_GAIN = 16.0
POSITION_AXES = ('x', 'y', 'z')


# --- linearised loops --------------------------------------------------------------------------------

def axis_controller(kind: str, axis: str, gains):
    """C(s) of ``kind`` on ``axis`` (module docstring), as a function of the complex s."""
    lam = gains['common']['lambda'][axis]
    f_v = gains['common']['velocity_filter_hz'] if axis in POSITION_AXES else 0.0

    def derivative(s):
        return s if f_v <= 0.0 else s / (1.0 + s / (2.0 * math.pi * f_v))
    if kind == 'nnit2fsmc':
        a = gains['nnit2fsmc']['axes'][axis]
        k = fuzzy_slope(gains) * a['fuzzy_gain'] / a['input_scale']   # fuzzy_gain is in units of q'' (gain_units)
        return lambda s: k * (derivative(s) + lam)
    if kind in ('pid', 'se3'):
        names = ('kp', 'kd', 'ki') if kind == 'pid' else ('k_error', 'k_rate', 'k_integral')
        kp, kd, ki = (gains[kind]['axes'][axis][name] for name in names)
        return lambda s: kp + kd * derivative(s) + ki / s
    if kind == 'smc-integral':
        a = gains['smc_integral']['axes'][axis]
        return lambda s: a['slope'] * (derivative(s) + lam + a['integral_gain'] / s)
    raise ValueError(f'controller: no linearised loop for {kind!r}')


def plant(dt: float, motor_lag: float):
    """P(s) = e^(-s dt/2) / (s^2 (motor_lag s + 1))."""
    return lambda s: cmath.exp(-s * dt / 2.0) / (s * s * (motor_lag * s + 1.0))


def loop_margins(loop, low: float = 1e-2, high: float = 1e4, points: int = 20000) -> dict:
    """Margins of the loop transfer ``loop(s)`` (a function of the complex s): {'crossovers': [w_c],
    'phase_margin': PM [rad] at the first crossover, 'delay_margin': min over crossovers of PM / w_c [s],
    'gain_margin': 1 / |L| at the first -180 degree phase crossing above the first crossover (inf if none),
    'phase_crossover': its w [rad/s]}. The phase is unwrapped from the lowest frequency, where it is taken
    in (-2 pi, 0] (a loop with n integrators starts at -n 90 degrees)."""
    ws = [low * (high / low) ** (i / (points - 1)) for i in range(points)]
    values = [loop(1j * w) for w in ws]
    phases, previous = [], None
    for value in values:
        phase = cmath.phase(value)
        if previous is None:       # the lowest frequency in (-2 pi, 0]: n integrators start at -n 90 degrees
            phase -= 2.0 * math.pi if phase > 0.0 else 0.0
        else:
            phase += 2.0 * math.pi * round((previous - phase) / (2.0 * math.pi))
        phases.append(phase)
        previous = phase

    def refine(f, a, b):
        fa = f(a)
        for _ in range(80):
            m = math.sqrt(a * b)
            fm = f(m)
            if (fm > 0) == (fa > 0):
                a, fa = m, fm
            else:
                b = m
        return math.sqrt(a * b)

    def unwrapped(w, near):
        phase = cmath.phase(loop(1j * w))
        return phase + 2.0 * math.pi * round((near - phase) / (2.0 * math.pi))

    crossovers, margins = [], []
    for i in range(points - 1):
        if (abs(values[i]) - 1.0) * (abs(values[i + 1]) - 1.0) < 0.0:
            w = refine(lambda x: abs(loop(1j * x)) - 1.0, ws[i], ws[i + 1])
            crossovers.append(w)
            margins.append(math.pi + unwrapped(w, phases[i]))
    if not crossovers:
        return {'crossovers': [], 'phase_margin': math.inf, 'delay_margin': math.inf, 'gain_margin': math.inf,
                'phase_crossover': math.nan}
    delay = min(pm / w for pm, w in zip(margins, crossovers)) if min(margins) > 0.0 else 0.0
    gain, phase_crossover = math.inf, math.nan
    for i in range(points - 1):
        if ws[i] >= crossovers[0] and (phases[i] + math.pi) * (phases[i + 1] + math.pi) < 0.0:
            phase_crossover = refine(lambda x: unwrapped(x, phases[i]) + math.pi, ws[i], ws[i + 1])
            gain = 1.0 / abs(loop(1j * phase_crossover))
            break
    return {'crossovers': crossovers, 'phase_margin': margins[0], 'delay_margin': delay, 'gain_margin': gain,
            'phase_crossover': phase_crossover}


def linear_margins(kind: str, gains, motor_lag: float) -> dict:
    """{axis: loop_margins(...)} of ``kind``'s linearised axis loops."""
    p = plant(control_period(gains), motor_lag)
    out = {}
    for axis in AXES:
        c = axis_controller(kind, axis, gains)
        out[axis] = loop_margins(lambda s, c=c: c(s) * p(s))
    return out


# --- simulated margins -------------------------------------------------------------------------------

def gain_margin(flight, undelayed) -> tuple[float, dict]:
    """(smallest unstable thrust factor found, {factor: instability or None}), bisection on log g."""
    tried = {}

    def unstable(g):
        tried[g] = paper_tables.instability(paper_tables.fly(replace(flight, thrust_factor=g)), undelayed,
                                            relative_rmse=False)
        return tried[g] is not None
    if not unstable(MAX_GAIN):
        return math.inf, tried
    low, high = 0.0, math.log(MAX_GAIN)
    for _ in range(GAIN_STEPS):
        middle = 0.5 * (low + high)
        if unstable(math.exp(middle)):
            high = middle
        else:
            low = middle
    return math.exp(high), tried


def delay_margins(kind: str, duration: float, max_delay: float, filters: bool = True, with_gain: bool = False) -> dict:
    """The simulated delay margins of ``kind`` with ideal rotors and with the 30 ms motor lag
    (``delay_lag0``, ``delay_lag0.03``: seconds, text, the undelayed flight's RMSE [cm] and failure), and
    with ``with_gain`` the gain margin (``gain``) on the undelayed flight without lag."""
    out = {}
    for lag in (0.0, MOTOR_LAG):
        flight = paper_tables.Flight(kind, 'paper', duration, physics_rate=PHYSICS_RATE, motor_lag=lag,
                                     filters=filters)
        base = paper_tables.fly(flight)
        margin = paper_tables.delay_margin(flight, base, max_delay)
        out[f'delay_lag{lag:g}'] = {'seconds': margin.seconds, 'text': margin.text, 'rmse_cm': base.rmse_cm,
                                    'base_failure': base.failure}
        if lag == 0.0 and with_gain:
            factor, tried = gain_margin(flight, base)
            out['gain'] = {'factor': factor, 'why': tried.get(factor)}
    return out


def simulated(task) -> dict:
    """Every simulated figure of one (controller, duration, max_delay, filters, gain only)."""
    kind, duration, max_delay, filters, gain_only = task
    if gain_only:
        flight = paper_tables.Flight(kind, 'paper', duration, physics_rate=PHYSICS_RATE, filters=filters)
        factor, tried = gain_margin(flight, paper_tables.fly(flight))
        return {'gain': {'factor': factor, 'why': tried.get(factor)}}
    return delay_margins(kind, duration, max_delay, filters, with_gain=True)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--controllers', default=','.join(CONTROLLERS))
    parser.add_argument('--duration', type=float, default=30.0, help='[s] each simulated flight (default 30)')
    parser.add_argument('--max-delay', type=float, default=MAX_DELAY,
                        help=f'[s] delay bisection range (default {MAX_DELAY:g})')
    parser.add_argument('--no-filters', action='store_true', help='also every figure with the measurement stage off')
    parser.add_argument('--linear-only', action='store_true', help='only the linearised margins (no flight)')
    parser.add_argument('--gain-only', action='store_true', help='of the simulated margins, only the gain margin')
    parser.add_argument('--gains', help='gains file (default: the packaged one), e.g. DIR/gains.yaml of '
                                        'run_stack.py study baseline-gains --matching rmse --out DIR')
    parser.add_argument('--jobs', type=int, default=1)
    parser.add_argument('--json', action='store_true', help='also write the simulated figures to DIR/margins.json')


def run(args: argparse.Namespace) -> int:
    kinds = names(args.controllers)
    gains = load_gains(args.gains)
    if args.gains:
        paper_tables.OVERRIDES['gains_file'] = args.gains
    lines = ['### Linearised axis loops (near S = 0; run_stack.py study margins)', '',
             '| controller | motor lag | delay margin [ms] (axis) | phase margin [deg] (axis) | '
             'gain margin (axis) | crossover [rad/s] (axis) |', '|---|---:|---:|---:|---:|---:|']
    for kind in kinds:
        for lag in (0.0, MOTOR_LAG):
            m = linear_margins(kind, gains, lag)
            worst = min(AXES, key=lambda a: m[a]['delay_margin'])
            gm_axis = min(AXES, key=lambda a: m[a]['gain_margin'])
            pm_axis = min(AXES, key=lambda a: m[a]['phase_margin'])
            lines.append(f'| {kind} | {1e3 * lag:g} ms | {1e3 * m[worst]["delay_margin"]:.2f} ({worst}) | '
                         f'{math.degrees(m[pm_axis]["phase_margin"]):.1f} ({pm_axis}) | '
                         f'{m[gm_axis]["gain_margin"]:.3g} ({gm_axis}) | '
                         f'{m[worst]["crossovers"][0]:.4g} ({worst}) |')
    if not args.linear_only:
        tasks = [(kind, args.duration, args.max_delay, True, args.gain_only) for kind in kinds]
        if args.no_filters:
            tasks += [(kind, args.duration, args.max_delay, False, args.gain_only) for kind in kinds]
        results = dict(zip(tasks, run_all(simulated, tasks, max(1, args.jobs), STUDY,
                                          lambda t: f'the margins of {t[0]}{"" if t[3] else " (no filters)"}')))
        if args.json:
            args.out.mkdir(parents=True, exist_ok=True)
            (args.out / 'margins.json').write_text(json.dumps({f'{t[0]}{"" if t[3] else " (no filters)"}': r
                                                              for t, r in results.items()}, indent=1, default=str))
        lines += ['', f'### Simulated margins (paper helix, {args.duration:g} s, physics {PHYSICS_RATE:g} Hz; '
                  'run_stack.py study margins)', '',
                  '| controller | RMSE [cm] no lag | delay margin, no lag | RMSE [cm] 30 ms lag | '
                  'delay margin, 30 ms lag | gain margin |', '|---|---:|---:|---:|---:|---:|']
        for task, r in results.items():
            name = task[0] + ('' if task[3] else ' (no filters)')
            gain = r['gain']
            gain_text = f'> {MAX_GAIN:g}' if math.isinf(gain['factor']) else f'{gain["factor"]:.3g} ({gain["why"]})'
            if task[4]:
                lines.append(f'| {name} | | | | | {gain_text} |')
                continue
            no_lag, lag = r['delay_lag0'], r[f'delay_lag{MOTOR_LAG:g}']
            lines.append(f'| {name} | {no_lag["rmse_cm"]:.4g} | {no_lag["text"]} | {lag["rmse_cm"]:.4g} | '
                         f'{lag["text"]} | {gain_text} |')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
