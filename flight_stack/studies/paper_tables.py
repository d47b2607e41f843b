"""The nominal, delay, control-rate and sensor-noise tables of docs/PAPER.md 4.1-4.5 and 4.8.1-4.8.3.

    run_stack.py study paper-tables --out DIR                  # every experiment, every controller
    run_stack.py study paper-tables --out DIR --experiments delay --controllers nnit2fsmc,pid
    run_stack.py study paper-tables --out DIR --duration 20 --jobs 2
    run_stack.py study paper-tables --out DIR --no-filters     # every controller without the measurement stage
    run_stack.py study paper-tables --out DIR --gains FILE     # e.g. baselines matched at equal nominal RMSE

Every flight is an embedded flight (:func:`flight_stack.embedded.fly_embedded`, the code path of
``run_stack.py --backend embedded``) of the nominal vehicle with the section IV disturbances, the
packaged gains file (every controller through its measurement stage), physics at 1 kHz; its figures are those of the review
(:func:`quad_msgs_bridge.review.metrics.flight_metrics`) after the settling time (5 s, or half a
flight shorter than 10 s). A flight fails (and its row says so) when the vehicle goes non-finite,
flips, crashes or strays more than 1 m from the reference after settling (``api.fly``'s default).

Controllers: ``--controllers a,b`` or every kind of ``nnit2fsmc_controller.factory.CONTROLLERS``
at run time; ``KIND:faithful`` flies a kind with the paper-faithful settings of
``factory.PAPER_FAITHFUL`` (docs/ADAPTIVE.md) applied to the packaged gains. Scenarios: names of ``nnit2fsmc_controller.trajectory.SCENARIOS`` (``paper`` is the
60 s helix); a name not known there is skipped with a note under its table. ``--duration``
shortens every flight (default: each scenario's own length).

Experiments (``--experiments``, default all; ``--scenarios`` applies to each chosen one, default
``paper``, and ``paper,lemniscate`` for noise):

* ``nominal``: RMSE and max position error [cm], total variation per second of U1..U4 [N/s; U4
  N m/s] and their sum, share of settled steps with a rotor at a limit.
* ``delay``: the delay margin, by bisection on the transport delay in whole control steps over
  0..100 ms; and the flight with 20 ms beside the flight without delay.
  **Criterion.** A delay is *unstable* when the flight fails (divergence: see above), or when its
  position RMSE exceeds the absolute yardstick of 2 cm (``ABSOLUTE_RMSE_CM``: a controller whose
  error is already large is not called stable), or when the attitude chattering TV(U2) + TV(U3) over the last 20 s of the flight (the settled part if that is
  shorter) exceeds 10 times its value without delay (a limit cycle), or when the position RMSE
  exceeds 10 times its value without delay. The margin is the smallest unstable delay; the
  bisection assumes that every longer delay is unstable too. Why these numbers: a limit cycle of
  amplitude A at frequency f adds 4 A f of variation per second, so an oscillation shows up as a
  jump in TV while a slow tracking change does not; the last 20 s leave the take-off and the
  reaching transient (which any delay lengthens) out, so a decaying transient is not a limit cycle;
  10x is the bound of the issue's delay check (TV within 10x of no delay), and, for the RMSE, far
  beyond the few-percent changes a delay of a step or two makes. Relative thresholds make the
  criterion fair to controllers that chatter (sign-SMC) or track loosely (a soft PID) by design.
* ``rate``: the same gains file at control rates of 1000, 250 and 100 Hz (``--rates``): RMSE and
  its ratio to the 1 kHz flight.
* ``noise``: sensor noise of the example campaign (campaigns/paper-robustness.yaml: position 1 cm,
  velocity 2 cm/s, attitude 0.01 rad, body rate 0.02 rad/s, white, no bias, flight streams of
  seed 1, flight 0): RMSE and total chattering, beside the sign-SMC's noise-free total chattering
  on the same scenario.

``--jobs N`` flies N flights at a time in a process pool (default 1: in this process), with a progress line per
flight (a delay margin's bisection is one). Deterministic: the same command gives the same tables (seeded network
and noise). The tables go to stdout and to DIR/paper-tables.md.
"""
from __future__ import annotations

import argparse
import copy
import math
from dataclasses import dataclass, fields, replace

from flight_stack import embedded
from flight_stack.closed_loop import FailureRules
from flight_stack.embedded import Perturbations, fly_embedded
from nnit2fsmc_controller import factory
from nnit2fsmc_controller.registry import check_controller
from nnit2fsmc_controller import trajectory as trajectories
from quad_msgs_bridge.review.metrics import default_settle_time, flight_metrics, has_fuzzy_term
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.perturbations.actuation import MotorLag, TransportDelay
from quad_sim.perturbations.sensor_noise import SensorErrors, SensorNoise
from quad_sim.perturbations.streams import flight_streams
from quad_sim.simulator import Simulator

from .common import add_out, names, run_all, study_name, write_table

STUDY = study_name(__name__)

EXPERIMENTS = ('nominal', 'delay', 'rate', 'noise')
DEFAULT_SCENARIOS = {'nominal': ('paper',), 'delay': ('paper',), 'rate': ('paper',), 'noise': ('paper', 'lemniscate')}
MAX_ERROR = 1.0              #: [m] position error after settling beyond which a flight has failed
CONTROLS = ('U1', 'U2', 'U3', 'U4')
MAX_DELAY = 0.100            #: [s] the delay bisection's range is 0..MAX_DELAY
DELAY_ROW = 0.020            #: [s] the delay of the side-by-side row
TAIL = 20.0                  #: [s] the delay criterion's chattering window: the end of the flight
INSTABILITY_FACTOR = 10.0    #: growth of TV(U2) + TV(U3) or of the RMSE that counts as unstable
ABSOLUTE_RMSE_CM = 2.0       #: [cm] the absolute yardstick: a flight with a larger position RMSE is not stable
DEFAULT_RATES = (1000.0, 250.0, 100.0)   #: [Hz]
NOISE = SensorErrors(position=0.01, velocity=0.02, attitude=0.01, body_rate=0.02)   #: the example campaign's
NOISE_SEED = 1
CHATTERING_REFERENCE = 'smc-sign'


@dataclass(frozen=True)
class Flight:
    """One flight of the tables: what differs from the nominal paper flight."""

    controller: str
    scenario: str
    duration: float | None = None      #: [s] None: the scenario's own
    delay_steps: int = 0               #: transport delay [control steps]
    control_rate: float | None = None  #: [Hz] None: the gains file's
    noise: bool = False                #: the example campaign's sensor noise
    delay_substeps: int = 0            #: a further delay of this many physics steps (a fraction of a control step)
    physics_rate: float = 1000.0       #: [Hz] RK4 rate (a whole multiple of the control rate)
    motor_lag: float = 0.0             #: [s] first-order motor time constant (0: ideal rotors)
    thrust_factor: float = 1.0         #: every rotor gives this times its command: a loop-gain change
    filters: bool = True               #: False: the measurement stage off (common.*_filter_hz 0) for every kind
    gains_file: str | None = None      #: a gains file instead of the packaged one

    @property
    def label(self) -> str:
        """The controller and scenario, then every field that differs from the nominal flight (a progress line)."""
        changed = [f'{field.name} {getattr(self, field.name)}' for field in fields(self)[2:]
                   if getattr(self, field.name) != field.default]
        return ', '.join([f'{self.controller} on {self.scenario}', *changed])


@dataclass(frozen=True)
class Outcome:
    """The figures of a flight."""

    metrics: dict               #: flight_metrics(...) after the settling time
    tail_chattering: dict       #: TV per second of U1..U4 over the last TAIL s (settled part if shorter)
    failure: str | None         #: why the flight ended early, or None
    failure_time: float | None  #: [s]

    @property
    def rmse_cm(self) -> float:
        return 100.0 * self.metrics['rmse_position_m']

    @property
    def total_chattering(self) -> float:
        """TV(U1) + TV(U2) + TV(U3) + TV(U4) per second [N/s, U4 N m/s], settled flight."""
        return sum(self.metrics['chattering'][c] for c in CONTROLS)

    @property
    def attitude_tail_chattering(self) -> float:
        """TV(U2) + TV(U3) per second over the last TAIL s [N/s]."""
        return self.tail_chattering['U2'] + self.tail_chattering['U3']


FAITHFUL = ':faithful'   #: controller suffix: the paper-faithful settings


def gains_for(control_rate: float | None, faithful: bool = False, gains: dict | None = None,
              filters: bool = True) -> dict:
    """The packaged gains (the named set paper-faithful if ``faithful``), or ``gains`` (with
    factory.PAPER_FAITHFUL if ``faithful``); with the measurement stage off if not ``filters``; at
    ``control_rate`` [Hz] if given."""
    gains = copy.deepcopy(gains) if gains is not None else factory.load_gains('paper-faithful' if faithful else None)
    if not filters:
        gains['common'] = {**gains['common'], 'measurement_filter_hz': 0.0, 'velocity_filter_hz': 0.0}
    if faithful:
        gains = factory.unflatten_gains({**factory.flatten_gains(gains), **factory.PAPER_FAITHFUL})
    if control_rate is not None:
        gains['common'] = {**gains['common'], 'control_rate': float(control_rate)}
    return gains


def kind_of(controller: str) -> str:
    """The controller kind of a table row (``nnit2fsmc:faithful`` -> ``nnit2fsmc``)."""
    return controller.removesuffix(FAITHFUL)


class FractionalDelaySimulator(Simulator):
    """A simulator whose thrust commands take effect ``lead`` physics steps into the next control step
    (:meth:`advance` integrates the first ``lead`` physics steps with the previous command): with the
    transport delay of whole control steps, a delay resolved to one physics step."""

    lead = 0

    def set_forces(self, forces) -> bool:
        self._previous = self.forces
        return super().set_forces(forces)

    def advance(self, steps: int = 1) -> None:
        lead = min(self.lead, steps)
        if lead and hasattr(self, '_previous'):
            commanded, self.forces = self.forces, self._previous
            super().advance(lead)
            self.forces = commanded
            steps -= lead
        super().advance(steps)


#: Flight fields that every flight of a run takes (main's --gains and --no-filters)
OVERRIDES: dict = {}


def fly(flight: Flight, gains: dict | None = None) -> Outcome:
    """Fly ``flight`` (with OVERRIDES) on the embedded backend and take its figures; ``gains``: instead of
    the packaged gains (or of ``flight.gains_file``)."""
    flight = replace(flight, **OVERRIDES)
    params, disturbances = load_vehicle_file()
    kind, faithful = kind_of(flight.controller), flight.controller.endswith(FAITHFUL)
    if gains is None and flight.gains_file is not None:
        gains = factory.load_gains(flight.gains_file)
    gains = gains_for(flight.control_rate, faithful, gains, flight.filters)
    control_dt = factory.control_period(gains)
    path = trajectories.make_scenario(flight.scenario, flight.duration)
    duration = path.duration if flight.duration is None else flight.duration
    settle = default_settle_time(duration)
    noise = None
    if flight.noise:
        streams = flight_streams(NOISE_SEED, 0)
        noise = SensorNoise(NOISE, SensorErrors(), streams.sensor_noise, streams.sensor_bias)
    true_vehicle = (replace(params,   # thrust and reaction torque alike: every control times thrust_factor
                            rotor_thrust_factors=tuple(f * flight.thrust_factor for f in params.rotor_thrust_factors),
                            rotor_drag_factors=tuple(g * flight.thrust_factor for g in params.rotor_drag_factors))
                    if flight.thrust_factor != 1.0 else None)
    perturbations = Perturbations(sensor_noise=noise, true_vehicle=true_vehicle,
                                  delay=TransportDelay(flight.delay_steps) if flight.delay_steps else None,
                                  motor_lag=(MotorLag(flight.motor_lag, 1.0 / flight.physics_rate)
                                             if flight.motor_lag > 0.0 else None))
    FractionalDelaySimulator.lead = flight.delay_substeps
    embedded.Simulator = FractionalDelaySimulator if flight.delay_substeps else Simulator
    try:
        result = fly_embedded(kind, path, params, disturbances, gains, duration, flight.physics_rate,
                              perturbations=perturbations, rules=FailureRules(settle, MAX_ERROR))
    finally:
        embedded.Simulator = Simulator
    failed = result.failure is not None
    figures = dict(f_min=params.F_min, f_max=params.F_max, fuzzy_term=has_fuzzy_term(kind),
                   ended_early=failed)
    metrics = flight_metrics(result.record, settle, **figures)
    tail = flight_metrics(result.record, max(settle, duration - control_dt - TAIL), **figures)
    return Outcome(metrics, tail['chattering'], result.failure, result.failure_time_s)


def instability(outcome: Outcome, undelayed: Outcome, relative_rmse: bool = True) -> str | None:
    """Why ``outcome`` is unstable by the delay criterion of the module docstring (failed, or a 10x
    growth of the attitude chattering over the last 20 s or of the RMSE against the flight without
    delay, ``undelayed``, or an RMSE above the absolute yardstick), or None when it is not.
    ``relative_rmse`` False leaves the 10x RMSE growth out (the gain margin: a thrust factor is also a
    model error of the hover feed-forward, whose transient is not an instability)."""
    if outcome.failure is not None:
        return outcome.failure
    growths = (('TV(U2)+TV(U3)', outcome.attitude_tail_chattering, undelayed.attitude_tail_chattering),
               ('RMSE', outcome.rmse_cm, undelayed.rmse_cm))
    for name, delayed, without in growths[:2 if relative_rmse else 1]:
        if not delayed <= INSTABILITY_FACTOR * without:      # (NaN, of a failed flight, is unstable)
            return (f'{name} x{delayed / without:.3g}' if without > 0.0
                    else f'{name} {delayed:.3g}, no delay {without:.3g}')
    if not outcome.rmse_cm <= ABSOLUTE_RMSE_CM:
        return f'RMSE {outcome.rmse_cm:.3g} cm > {ABSOLUTE_RMSE_CM:g} cm'
    return None


def unstable(outcome: Outcome, undelayed: Outcome) -> bool:
    return instability(outcome, undelayed) is not None


@dataclass(frozen=True)
class DelayMargin:
    """The result of :func:`delay_margin`."""

    control_dt: float        #: [s] the resolution of the search: one physics step (a control step at equal rates)
    margin_steps: int | None  #: smallest unstable delay [steps of control_dt]; None: none up to max_steps
    max_steps: int           #: the range searched, 0..max_steps
    tried: dict              #: delay [steps] -> why it is unstable (:func:`instability`), None if stable

    @property
    def seconds(self) -> float:
        """The margin [s] (inf: none found up to max_steps)."""
        return math.inf if self.margin_steps is None else self.margin_steps * self.control_dt

    @property
    def text(self) -> str:
        """The margin [ms] and what made it unstable."""
        if self.margin_steps is None:
            return f'> {1e3 * self.max_steps * self.control_dt:g} ms'
        return f'{1e3 * self.margin_steps * self.control_dt:g} ms ({self.tried[self.margin_steps]})'


def delayed(flight: Flight, physics_steps: int) -> Flight:
    """``flight`` with a transport delay of ``physics_steps`` physics steps: whole control steps, and the
    rest as a fractional delay (:class:`FractionalDelaySimulator`)."""
    per_control = int(round(flight.physics_rate * factory.control_period(gains_for(flight.control_rate))))
    return replace(flight, delay_steps=physics_steps // per_control, delay_substeps=physics_steps % per_control)


def delay_margin(flight: Flight, undelayed: Outcome | None = None, max_delay: float = MAX_DELAY) -> DelayMargin:
    """The smallest transport delay (whole physics steps in 0..``max_delay`` [s]: control steps when the
    physics runs at the control rate) at which ``flight`` is :func:`unstable`, by bisection;
    ``undelayed`` is the flight without delay (flown if None)."""
    step = 1.0 / flight.physics_rate
    undelayed = undelayed if undelayed is not None else fly(replace(flight, delay_steps=0, delay_substeps=0))
    max_steps = int(round(max_delay / step))
    tried = {}

    def is_unstable(steps: int) -> bool:
        tried[steps] = instability(fly(delayed(flight, steps)), undelayed)
        return tried[steps] is not None

    if not is_unstable(max_steps):
        return DelayMargin(step, None, max_steps, tried)
    stable, failing = 0, max_steps          # invariant: stable is stable, failing is unstable
    while failing - stable > 1:
        middle = (stable + failing) // 2
        if is_unstable(middle):
            failing = middle
        else:
            stable = middle
    return DelayMargin(step, failing, max_steps, tried)


def monotone(instabilities: dict) -> bool:
    """Whether {delay [steps]: instability or None} never has a stable delay above an unstable one."""
    verdicts = [instabilities[steps] is not None for steps in sorted(instabilities)]
    return all(not (earlier and not later) for earlier, later in zip(verdicts, verdicts[1:]))


def _delay_margin_task(task):
    return delay_margin(*task)


# --- tables ------------------------------------------------------------------------------------------

def number(value: float) -> str:
    """Four significant digits (a table cell)."""
    return 'nan' if math.isnan(value) else f'{value:.4g}'


def failure_note(outcome: Outcome) -> str:
    return '' if outcome.failure is None else f'failed: {outcome.failure} at {outcome.failure_time:.2f} s'


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table: names and notes left-aligned, numbers right-aligned."""
    align = ['---' if name == 'controller' or name.startswith('note') else '---:' for name in header]
    return ['| ' + ' | '.join(header) + ' |', '|' + '|'.join(align) + '|'] + ['| ' + ' | '.join(r) + ' |' for r in rows]


def scenario_label(scenario: str, duration: float | None) -> str:
    return scenario if duration is None else f'{scenario}, {duration:g} s'


def nominal_table(controllers, scenario, duration, flown) -> list[str]:
    rows = []
    for kind in controllers:
        o = flown[Flight(kind, scenario, duration)]
        m = o.metrics
        rows.append([kind, number(o.rmse_cm), number(100.0 * m['max_position_error_m']),
                     *(number(m['chattering'][c]) for c in CONTROLS), number(o.total_chattering),
                     number(m['saturation_fraction']), failure_note(o)])
    return [f'### Nominal flight ({scenario_label(scenario, duration)}, section IV disturbances)', ''] + table(
        ['controller', 'RMSE [cm]', 'max error [cm]', 'TV(U1) [N/s]', 'TV(U2) [N/s]', 'TV(U3) [N/s]',
         'TV(U4) [N m/s]', 'TV total', 'saturation', 'note'], rows)


def delay_steps_of(seconds: float, control_rate: float | None = None) -> int:
    return TransportDelay.from_seconds(seconds, factory.control_period(gains_for(control_rate))).steps


def delay_table(controllers, scenario, duration, flown, margins) -> list[str]:
    row_steps = delay_steps_of(DELAY_ROW)
    rows = []
    for kind in controllers:
        base, delayed = flown[Flight(kind, scenario, duration)], flown[Flight(kind, scenario, duration, row_steps)]
        known = {**margins[kind].tried, 0: None, row_steps: instability(delayed, base)}
        rows.append([kind, margins[kind].text + ('' if monotone(known) else ' (not monotone)'),
                     number(base.rmse_cm), number(delayed.rmse_cm),
                     number(base.tail_chattering['U2']), number(delayed.tail_chattering['U2']),
                     number(base.tail_chattering['U3']), number(delayed.tail_chattering['U3']),
                     failure_note(delayed)])
    ms = f'{1e3 * DELAY_ROW:g} ms'
    return [f'### Transport delay ({scenario_label(scenario, duration)})', ''] + table(
        ['controller', 'delay margin', 'RMSE [cm] no delay', f'RMSE [cm] {ms}', 'TV(U2) [N/s] no delay',
         f'TV(U2) {ms}', 'TV(U3) [N/s] no delay', f'TV(U3) {ms}', f'note ({ms})'], rows) + [
        '', f'Delay margin: smallest delay (bisection over 0..{1e3 * MAX_DELAY:g} ms in control steps) at which the '
        f'flight fails, its RMSE exceeds {ABSOLUTE_RMSE_CM:g} cm, or TV(U2) + TV(U3) over its last {TAIL:g} s or its '
        f'RMSE exceeds {INSTABILITY_FACTOR:g}x the no-delay value (run_stack.py study paper-tables); "not monotone": a flight flown here with a longer delay than '
        'an unstable one was stable, so the bisection may have missed a smaller unstable delay. TV columns: '
        f'the last {TAIL:g} s of the flight (its settled part if that is shorter).']


def rate_table(controllers, scenario, duration, rates, flown) -> list[str]:
    rows = []
    for kind in controllers:
        outcomes = [flown[Flight(kind, scenario, duration, control_rate=rate)] for rate in rates]
        first = outcomes[0].rmse_cm
        rows.append([kind, *(number(o.rmse_cm) for o in outcomes), *(number(o.rmse_cm / first) for o in outcomes[1:]),
                     '; '.join(f'{rate:g} Hz {failure_note(o)}' for rate, o in zip(rates, outcomes) if o.failure)])
    return [f'### Control rate ({scenario_label(scenario, duration)}, the same gains file)', ''] + table(
        ['controller', *(f'RMSE [cm] {r:g} Hz' for r in rates), *(f'ratio {r:g}/{rates[0]:g} Hz' for r in rates[1:]),
         'note'], rows)


def noise_table(controllers, scenario, duration, flown) -> list[str]:
    reference = flown[Flight(CHATTERING_REFERENCE, scenario, duration)].total_chattering
    rows = []
    for kind in controllers:
        o = flown[Flight(kind, scenario, duration, noise=True)]
        rows.append([kind, number(o.rmse_cm), number(o.total_chattering), number(o.total_chattering / reference),
                     failure_note(o)])
    return [f'### Sensor noise ({scenario_label(scenario, duration)}; position 1 cm, velocity 2 cm/s, '
            'attitude 0.01 rad, body rate 0.02 rad/s)', ''] + table(
        ['controller', 'RMSE [cm]', 'TV total [N/s]', f'TV total / {CHATTERING_REFERENCE} without noise', 'note'],
        rows) + ['', f'{CHATTERING_REFERENCE} without noise: TV total {number(reference)} N/s '
                     '(TV total: TV(U1) + TV(U2) + TV(U3) + TV(U4) per second of settled flight).']


def flights_needed(experiment: str, controllers, scenario, duration, rates) -> list[Flight]:
    """The plain flights (no bisection) an experiment's table reads."""
    base = [Flight(kind, scenario, duration) for kind in controllers]
    if experiment == 'nominal':
        return base
    if experiment == 'delay':
        return base + [Flight(kind, scenario, duration, delay_steps_of(DELAY_ROW)) for kind in controllers]
    if experiment == 'rate':
        return [Flight(kind, scenario, duration, control_rate=rate) for kind in controllers for rate in rates]
    return [Flight(CHATTERING_REFERENCE, scenario, duration)] + [
        Flight(kind, scenario, duration, noise=True) for kind in controllers]


def paper_tables(experiments, controllers, scenarios: dict, duration: float | None, rates, jobs: int = 1) -> list[str]:
    """The Markdown lines of the chosen experiments' tables. ``scenarios``: experiment -> scenario names."""
    skipped, plan = [], []
    for experiment in experiments:
        for scenario in scenarios[experiment]:
            if scenario not in trajectories.SCENARIOS:
                skipped.append((experiment, scenario))
            else:
                plan.append((experiment, scenario))
    needed = list(dict.fromkeys(f for experiment, scenario in plan
                                for f in flights_needed(experiment, controllers, scenario, duration, rates)))
    flown = dict(zip(needed, run_all(fly, needed, jobs, STUDY, lambda flight: flight.label)))
    margin_tasks = [(Flight(kind, scenario, duration), flown[Flight(kind, scenario, duration)])
                    for experiment, scenario in plan if experiment == 'delay' for kind in controllers]
    margins = {(task[0].controller, task[0].scenario): margin
               for task, margin in zip(margin_tasks, run_all(_delay_margin_task, margin_tasks, jobs, STUDY,
                                                             lambda task: f'the delay margin of {task[0].label}'))}
    out = []
    for experiment, scenario in plan:
        if experiment == 'nominal':
            out += nominal_table(controllers, scenario, duration, flown)
        elif experiment == 'delay':
            out += delay_table(controllers, scenario, duration, flown,
                               {kind: margins[kind, scenario] for kind in controllers})
        elif experiment == 'rate':
            out += rate_table(controllers, scenario, duration, rates, flown)
        else:
            out += noise_table(controllers, scenario, duration, flown)
        out.append('')
    for experiment, scenario in skipped:
        out += [f'Note: {experiment} on {scenario!r} skipped: not a known scenario '
                f'(known: {", ".join(trajectories.SCENARIOS)}).', '']
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--experiments', default=','.join(EXPERIMENTS), help=f'comma-separated of {", ".join(EXPERIMENTS)}')
    parser.add_argument('--controllers', help='comma-separated controller kinds (default: every kind)')
    parser.add_argument('--scenarios', help='comma-separated scenario names for every chosen experiment '
                                            '(default: paper; paper,lemniscate for noise)')
    parser.add_argument('--duration', type=float, help='[s] every flight this long (default: the scenario length)')
    parser.add_argument('--rates', default=','.join(f'{r:g}' for r in DEFAULT_RATES), help='[Hz] control rates')
    parser.add_argument('--jobs', type=int, default=1, help='flights at a time (process pool; default 1)')
    parser.add_argument('--gains', help='gains file for every flight (default: the packaged one), e.g. one of '
                                        'run_stack.py study baseline-gains --matching rmse --out DIR')
    parser.add_argument('--no-filters', action='store_true',
                        help='every controller without its measurement stage (common.*_filter_hz 0)')


def run(args: argparse.Namespace) -> int:
    OVERRIDES.clear()
    if args.gains:
        OVERRIDES['gains_file'] = args.gains
    if args.no_filters:
        OVERRIDES['filters'] = False
    experiments = names(args.experiments)
    unknown = [e for e in experiments if e not in EXPERIMENTS]
    controllers = names(args.controllers) if args.controllers else list(factory.CONTROLLERS)
    if unknown:
        raise ParameterError(f'unknown experiment: {", ".join(unknown)} (experiments: {", ".join(EXPERIMENTS)})')
    for controller in controllers:         # any registered kind: a built-in one, an installed one, module:Class
        check_controller(kind_of(controller), '--controllers')
    if args.duration is not None and not args.duration > 0.0:
        raise ParameterError('--duration must be positive')
    scenarios = {e: tuple(names(args.scenarios)) if args.scenarios else DEFAULT_SCENARIOS[e] for e in experiments}
    rates = [float(r) for r in names(args.rates)]
    text = '\n'.join(paper_tables(experiments, controllers, scenarios, args.duration, rates, max(1, args.jobs)))
    write_table(STUDY, args.out, text)
    return 0
