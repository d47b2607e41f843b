"""The baselines' derived gains and bound table of docs/BASELINES.md (and the matched gains of docs/PAPER.md 4.8.3).

Derive the gains of the fair baselines (pid, smc-integral, se3) from the NNIT2FSMC gains and a campaign.

The procedure of docs/BASELINES.md, written out so that it can be rerun after a change of the
NNIT2FSMC gains, of the vehicle or of the campaign:

1. Bandwidth match (``--matching``). ``slope`` (default): the small-signal slope of the IT2 term at
   S = 0, derived from the membership functions (:func:`small_signal_slope`): with u = S / input_scale
   small, ZE and PM fire, the upper grades are 1 - 2u and 2u, the lower ones H (1 - 2u/(2 w)) and 0
   (PM's lower function, of half-width w < 0.5, starts only at u = 1/2 - w), and the KM output is
   -gain u / (2 (H + 2u - 2u H / (2 w))), whose slope at u = 0 is gain / (2 H) per unit of u: the
   loop gain of the NNIT2FSMC near its surface, where a tracking flight lives. ``least-squares``: the
   slope of the best line through the whole universe (the earlier matching, about 1.005 gain /
   input_scale: stiffer than the IT2 term near S = 0 by about 21 %). ``rmse`` and ``chattering``:
   the slope matching scaled by the factor c per baseline kind (every axis alike) at which the
   baseline's nominal paper flight has the NNIT2FSMC's RMSE, or its total chattering (bisection
   on log c over [1/16, 16], ``MATCH_STEPS`` flights per kind). fuzzy_gain is stated in units of q''
   (nnit2fsmc_controller/gain_units.py), so the slope is already a gain on S in those units:
       k = c slope fuzzy_gain / input_scale    [1/s],   kd = k,   kp = lambda k,   ki = k lambda^2 / 4
   (the PID is then k (de + lambda e + lambda^2/4 int e): the NNIT2FSMC's surface plus an integral
   whose surface polynomial s^2 + lambda s + lambda^2/4 has a double root at lambda/2).
2. Uncertainty bound of the campaign, per subsystem, in units of q'' (docs/BASELINES.md, section 2).
3. smc-integral: slope k, integral_gain lambda^2/4, switching_gain = (F + eta)/r_min with eta = 0.1 F,
   gain_uncertainty = max(1/r_min - 1, 1 - 1/r_max).
4. Integral clamps (pid, smc-integral, se3): the integral alone may cancel the whole bound at hover,
   ki * integral_limit = switching_gain + gain_uncertainty * |u_eq at hover|.
5. se3: the same kp, kd, ki (multiplied by m or by Ix, Iy, Iz in the law) and clamps.

    run_stack.py study baseline-gains --out DIR [--gains FILE] [--vehicle FILE] [--campaign SPEC]
        [--matching slope|least-squares|rmse|chattering]

prints the slopes, the bound table and the three YAML sections of controller.yaml, writes them to
DIR/baseline-gains.md, and a whole gains file with those sections to DIR/gains.yaml (for
``run_stack.py study paper-tables --gains DIR/gains.yaml``).
"""
from __future__ import annotations

import argparse
import copy
import math
from pathlib import Path

import numpy as np
import yaml

from flight_stack.campaign.spec import load_spec
from nnit2fsmc_controller.controller import AXES
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.it2_fuzzy import IT2FuzzyCorrector
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.perturbations.wind import DEFAULT_ALTITUDE, low_altitude_scales

from .common import add_out, progress, study_name, write_table

STUDY = study_name(__name__)
#: [m/s] largest horizontal and vertical speed of the paper helix (R w = 0.5, climb 0.1)
HELIX_SPEED = (0.5, 0.1)
GUST_SIGMAS = 2.0     #: the turbulence bound: mean + 2 sigma (95 % of the time per axis)
MARGIN = 0.1          #: eta = MARGIN * F


def unit_corrector(gains) -> IT2FuzzyCorrector:
    """The IT2 term of the gains with input_scale 1 and output_gain 1."""
    n = gains['nnit2fsmc']
    return IT2FuzzyCorrector(input_scale=1.0, output_gain=1.0, lower_height=n['lower_height'],
                             lower_half_width=n['lower_half_width'], type_reducer=n['type_reducer'])


def small_signal_slope(lower_height: float, lower_half_width: float, type_reducer: str) -> float:
    """-d(IT2 term)/dS at S = 0 per unit of fuzzy_gain / input_scale, from the membership functions
    (step 1 of the module docstring). With lower half-width w < 0.5 only ZE's lower function fires
    near 0: KM gives 1 / (2 H), Nie-Tan 1 / (1 + H). With w = 0.5 PM's lower function fires too
    (H 2u): KM gives (H + 1 / H) / 2, Nie-Tan 1 (type 1 at H = 1: the line through the centres)."""
    h = lower_height
    if lower_half_width < 0.5:
        return 1.0 / (2.0 * h) if type_reducer == 'km' else 1.0 / (1.0 + h)
    return 0.5 * (h + 1.0 / h) if type_reducer == 'km' else 1.0


def least_squares_slope(gains) -> float:
    """Least-squares slope of the IT2 map over its universe, per unit of fuzzy_gain / input_scale."""
    fuzzy = unit_corrector(gains)
    u = np.linspace(-1.0, 1.0, 4001)
    y = np.array([fuzzy(float(v)) for v in u])
    return float(-np.dot(u, y) / np.dot(u, u))


def fuzzy_slope(gains, matching: str = 'slope') -> float:
    """The matched slope per unit of fuzzy_gain / input_scale: at S = 0 (``slope``, and the base of
    ``rmse`` and ``chattering``) or least squares over the universe (``least-squares``)."""
    if matching == 'least-squares':
        return least_squares_slope(gains)
    n = gains['nnit2fsmc']
    return small_signal_slope(n['lower_height'], n['lower_half_width'], n['type_reducer'])


def matched(gains, slope, scale: float = 1.0):
    """{axis: (k, kp, kd, ki)} of step 1, k scaled by ``scale`` (c)."""
    out = {}
    for axis in AXES:
        a = gains['nnit2fsmc']['axes'][axis]
        lam = gains['common']['lambda'][axis]
        k = scale * slope * a['fuzzy_gain'] / a['input_scale']
        out[axis] = (k, lam * k, k, k * lam * lam / 4.0)
    return out


def bounds(params, disturbances, spec):
    """(r_min, r_max, {axis: (F, terms)}) of step 2: F [units of q''] and its parts."""
    v = spec.vehicle
    rel = {key: (v[key].bound if key in v else 0.0) for key in ('mass', 'inertia', 'drag', 'thrust_coefficient',
                                                                 'drag_coefficient')}
    r_min = (1.0 - max(rel['thrust_coefficient'], rel['drag_coefficient'])) / (1.0 + max(rel['mass'], rel['inertia']))
    r_max = (1.0 + max(rel['thrust_coefficient'], rel['drag_coefficient'])) / (1.0 - max(rel['mass'], rel['inertia']))
    m_light, m_heavy = params.m * (1.0 - rel['mass']), params.m * (1.0 + rel['mass'])
    weight_heavy = m_heavy * params.g
    sigma = (low_altitude_scales(spec.turbulence, DEFAULT_ALTITUDE)
             if spec.turbulence != 'none' else (0.0, 0.0, 0.0))
    wind_h = (params.wind_drag * (spec.wind_mean_speed_mps + GUST_SIGMAS * sigma[0] + HELIX_SPEED[0])
              if spec.has_wind else 0.0)
    wind_v = params.wind_drag * (GUST_SIGMAS * sigma[2] + HELIX_SPEED[1]) if spec.has_wind else 0.0
    section4 = {name: abs(getattr(disturbances, name).bias) + abs(getattr(disturbances, name).amplitude)
                for name in ('A_x', 'A_y', 'A_z', 'A_phi', 'A_theta', 'A_psi')}
    drag_h = rel['drag'] * max(params.Kfx, params.Kfy) * HELIX_SPEED[0]
    drag_v = rel['drag'] * params.Kfz * HELIX_SPEED[1]
    # rotor spread: rotors 2 and 4 (1 and 3) thrust factors 1 -+ thrust_coefficient at the heavy hover
    roll_spread = rel['thrust_coefficient'] * weight_heavy / 2.0 * params.d          # [N m]
    yaw_spread = rel['drag_coefficient'] * weight_heavy * params.yaw_coefficient     # [N m]
    light = 1.0 - rel['inertia']
    terms = {
        'x': {'section IV': section4['A_x'], 'wind': wind_h, 'drag error': drag_h},
        'y': {'section IV': section4['A_y'], 'wind': wind_h, 'drag error': drag_h},
        'z': {'section IV': section4['A_z'], 'wind': wind_v, 'drag error': drag_v},
        'phi': {'section IV': section4['A_phi'], 'rotor spread': roll_spread},
        'theta': {'section IV': section4['A_theta'], 'rotor spread': roll_spread},
        'psi': {'section IV': section4['A_psi'], 'rotor spread': yaw_spread},
    }
    divisor = {'x': m_light, 'y': m_light, 'z': m_light, 'phi': params.Ix * light, 'theta': params.Iy * light,
               'psi': params.Iz * light}
    return r_min, r_max, {axis: (sum(terms[axis].values()) / divisor[axis], terms[axis]) for axis in AXES}


#: the gains section of each baseline kind
SECTIONS = {'pid': 'pid', 'smc-integral': 'smc_integral', 'se3': 'se3'}


def derive(gains, params, disturbances, spec, slope=None, scales=None):
    """(table rows, {'pid': ..., 'smc_integral': ..., 'se3': ...}): the gains sections of steps 1-5,
    each {axis: {key: value}} as in controller.yaml, at ``slope`` (default: the small-signal one)
    with k scaled by ``scales[kind]`` (default 1). The table rows are those of the pid's scale."""
    slope = fuzzy_slope(gains) if slope is None else slope
    scales = {kind: 1.0 for kind in SECTIONS} if scales is None else scales
    r_min, r_max, bound = bounds(params, disturbances, spec)
    delta = max(1.0 / r_min - 1.0, 1.0 - 1.0 / r_max)
    rows, sections = [], {section: {} for section in SECTIONS.values()}
    for kind, section in SECTIONS.items():
        gains_of = matched(gains, slope, scales[kind])
        for axis in AXES:
            k, kp, kd, ki = gains_of[axis]
            f, terms = bound[axis]
            switching = (1.0 + MARGIN) * f / r_min
            hover = params.g if axis == 'z' else 0.0
            limit = (switching + delta * hover) / ki
            mu = gains['common']['lambda'][axis] ** 2 / 4.0
            sections[section][axis] = {
                'pid': {'kp': kp, 'ki': ki, 'kd': kd, 'integral_limit': limit},
                'smc_integral': {'slope': k, 'integral_gain': mu, 'switching_gain': switching,
                                 'gain_uncertainty': delta, 'integral_limit': limit},
                'se3': {'k_error': kp, 'k_rate': kd, 'k_integral': ki, 'integral_limit': limit}}[section]
            if kind == 'pid':
                rows.append((axis, k, kp, kd, ki, terms, f, switching, hover, limit))
    return (r_min, r_max, delta, rows), sections


def with_sections(gains, sections) -> dict:
    """The gains with the baseline sections replaced (rounded as printed, so that a flight here flies
    what the printed YAML says)."""
    out = copy.deepcopy(gains)
    for section, per_axis in sections.items():
        out[section] = {'axes': {axis: {key: float(yaml_float(value)) for key, value in values.items()}
                                 for axis, values in per_axis.items()}}
    return out


def nominal_figure(kind: str, gains, metric: str) -> float:
    """The nominal paper flight's RMSE [cm] (``metric`` 'rmse') or total chattering [N/s] ('chattering')
    of ``kind`` with ``gains`` (the paper-tables study's flight)."""
    from . import paper_tables
    outcome = paper_tables.fly(paper_tables.Flight(kind, 'paper'), gains)
    if outcome.failure is not None:
        return math.inf
    return outcome.rmse_cm if metric == 'rmse' else outcome.total_chattering


def matched_scale(kind, gains, params, disturbances, spec, slope, metric: str, target: float) -> tuple[float, float]:
    """(c, figure): the scale c of ``kind``'s slope-matched gains at which its nominal ``metric`` equals
    ``target``, by bisection on log c over [1/16, 16] (both figures fall as c grows: a stiffer loop
    tracks closer and, against the section IV disturbances, moves its controls no more)."""
    def figure(c):
        scales = {name: c for name in SECTIONS}
        return nominal_figure(kind, with_sections(gains, derive(gains, params, disturbances, spec, slope, scales)[1]),
                              metric)
    low, high = math.log(1.0 / 16.0), math.log(16.0)
    value = math.nan
    for _ in range(MATCH_STEPS):
        middle = 0.5 * (low + high)
        value = figure(math.exp(middle))
        if (value > target) == (metric == 'rmse'):
            low = middle          # too loose (rmse) / too quiet (chattering): stiffer
        else:
            high = middle
    c = math.exp(0.5 * (low + high))
    return c, figure(c)


def yaml_float(value: float) -> str:
    """4 significant digits, always a YAML float (16.0, not 16: a ROS parameter keeps its first type)."""
    text = f'{value:.4g}'
    return text if any(c in text for c in '.e') else text + '.0'


MATCHINGS = ('slope', 'least-squares', 'rmse', 'chattering')
MATCH_STEPS = 8      #: bisection steps of the rmse and chattering matchings: c to within a factor 256^(1/512) = 1.011


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--gains', type=Path, default=None, help='NNIT2FSMC gains file (default: the packaged one)')
    parser.add_argument('--vehicle', type=Path, default=None, help='nominal vehicle file (default: the packaged one)')
    parser.add_argument('--campaign', type=Path, default=Path('campaigns/paper-robustness.yaml'))
    parser.add_argument('--matching', choices=MATCHINGS, default='slope',
                        help='slope: at S = 0 (default); least-squares: over the universe; rmse / chattering: '
                             'scaled until the nominal paper flight equals the NNIT2FSMC\'s (flies)')


def run(args: argparse.Namespace) -> int:
    params, disturbances = load_vehicle_file(args.vehicle)
    gains, spec = load_gains(args.gains), load_spec(args.campaign)
    n = gains['nnit2fsmc']
    slope = fuzzy_slope(gains, args.matching)
    lines = [f'IT2 small-signal slope at S = 0 (lower_height {n["lower_height"]}, lower_half_width '
             f'{n["lower_half_width"]}, {n["type_reducer"]}): '
             f'{small_signal_slope(n["lower_height"], n["lower_half_width"], n["type_reducer"]):.4f} x fuzzy_gain / '
             f'input_scale; least-squares slope over the universe: {least_squares_slope(gains):.4f}',
             f'matching: {args.matching}, slope {slope:.4f}']
    scales = {kind: 1.0 for kind in SECTIONS}
    if args.matching in ('rmse', 'chattering'):
        progress(STUDY, f'flying the nnit2fsmc nominal paper flight (the {args.matching} target)')
        target = nominal_figure('nnit2fsmc', gains, args.matching)
        unit = 'cm' if args.matching == 'rmse' else 'N/s'
        lines.append(f'target: nnit2fsmc nominal paper flight {args.matching} {target:.4g} {unit}')
        for kind in SECTIONS:
            progress(STUDY, f'{kind}: bisection on its scale c, {MATCH_STEPS + 1} nominal paper flights')
            scales[kind], reached = matched_scale(kind, gains, params, disturbances, spec, slope, args.matching,
                                                  target)
            lines.append(f'  {kind}: c = {scales[kind]:.4g} -> {args.matching} {reached:.4g} {unit}')
    (r_min, r_max, delta, rows), sections = derive(gains, params, disturbances, spec, slope, scales)
    lines += [f'gain ratio r = true/nominal in [{r_min:.4f}, {r_max:.4f}], gain_uncertainty = {delta:.4f}', '',
              '| axis | k [1/s] | kp | kd | ki | model error terms [N or N m] | F [q\'\' units] | switching_gain | '
              'u_eq at hover | integral_limit |',
              '|---|---:|---:|---:|---:|---|---:|---:|---:|---:|']
    for axis, k, kp, kd, ki, terms, f, switching, hover, limit in rows:
        parts = ', '.join(f'{name} {value:.4g}' for name, value in terms.items())
        lines.append(f'| {axis} | {k:.4g} | {kp:.4g} | {kd:.4g} | {ki:.4g} | {parts} | {f:.4g} | {switching:.4g} | '
                     f'{hover:.4g} | {limit:.4g} |')
    for section, per_axis in sections.items():
        lines += ['', f'    {section}:', '      axes:']
        for axis, values in per_axis.items():
            text = ', '.join(f'{key}: {yaml_float(value)}' for key, value in values.items())
            lines.append(f'        {axis + ":":6} {{{text}}}')
    write_table(STUDY, args.out, '\n'.join(lines))
    gains_file = args.out / 'gains.yaml'
    gains_file.write_text(yaml.safe_dump(with_sections(gains, sections), sort_keys=False))
    progress(STUDY, f'wrote the gains file with these sections {gains_file}')
    return 0
