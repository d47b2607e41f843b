#!/usr/bin/env python3
"""Derive the gains of the fair baselines (pid, smc-integral, se3) from the NNIT2FSMC gains and a campaign.

The procedure of docs/BASELINES.md, written out so that it can be rerun after a change of the
NNIT2FSMC gains, of the vehicle or of the campaign:

1. Bandwidth match. The IT2 fuzzy term is, to 3.3 % of its gain, the linear saturation
   -fuzzy_gain sat(S / input_scale); its least-squares slope over the universe is
   fuzzy_gain / input_scale per unit of S (measured here). Divided into the units of q'' by the
   nominal control gain b of the subsystem (x, y: 1; z: 1/m; phi, theta: d/Ix, d/Iy; psi: 1/Iz):
       k = fuzzy_gain / input_scale * b    [1/s],   kd = k,   kp = lambda k,   ki = k lambda^2 / 4
   (the PID is then k (de + lambda e + lambda^2/4 int e): the NNIT2FSMC's surface plus an integral
   whose surface polynomial s^2 + lambda s + lambda^2/4 has a double root at lambda/2).
2. Uncertainty bound of the campaign, per subsystem, in units of q'' (docs/BASELINES.md, section 2).
3. smc-integral: slope k, integral_gain lambda^2/4, switching_gain = (F + eta)/r_min with eta = 0.1 F,
   gain_uncertainty = max(1/r_min - 1, 1 - 1/r_max).
4. Integral clamps (pid, smc-integral, se3): the integral alone may cancel the whole bound at hover,
   ki * integral_limit = switching_gain + gain_uncertainty * |u_eq at hover|.
5. se3: the same kp, kd, ki (multiplied by m or by Ix, Iy, Iz in the law) and clamps.

    .venv/bin/python bench/baseline_gains.py [--gains FILE] [--vehicle FILE] [--campaign SPEC]

prints the bound table and the three YAML sections of controller.yaml.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack.campaign.spec import load_spec  # noqa: E402
from nnit2fsmc_controller.controller import AXES  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.it2_fuzzy import IT2FuzzyCorrector  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
from quad_sim.perturbations.wind import DEFAULT_ALTITUDE, low_altitude_scales  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: [m/s] largest horizontal and vertical speed of the paper helix (R w = 0.5, climb 0.1)
HELIX_SPEED = (0.5, 0.1)
GUST_SIGMAS = 2.0     #: the turbulence bound: mean + 2 sigma (95 % of the time per axis)
MARGIN = 0.1          #: eta = MARGIN * F


def fuzzy_slope(gains) -> float:
    """Least-squares slope of the IT2 map over its universe, per unit of fuzzy_gain / input_scale."""
    n = gains['nnit2fsmc']
    fuzzy = IT2FuzzyCorrector(input_scale=1.0, output_gain=1.0, lower_height=n['lower_height'],
                              lower_half_width=n['lower_half_width'], type_reducer=n['type_reducer'])
    u = np.linspace(-1.0, 1.0, 4001)
    y = np.array([fuzzy(float(v)) for v in u])
    return float(-np.dot(u, y) / np.dot(u, u))


def matched(gains, params, slope):
    """{axis: (k, kp, kd, ki)} of step 1."""
    b = {'x': 1.0, 'y': 1.0, 'z': 1.0 / params.m, 'phi': params.d / params.Ix, 'theta': params.d / params.Iy,
         'psi': 1.0 / params.Iz}
    out = {}
    for axis in AXES:
        a = gains['nnit2fsmc']['axes'][axis]
        lam = gains['common']['lambda'][axis]
        k = slope * a['fuzzy_gain'] / a['input_scale'] * b[axis]
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


def derive(gains, params, disturbances, spec):
    """(table rows, {'pid': ..., 'smc_integral': ..., 'se3': ...}): the gains sections of steps 1-5,
    each {axis: {key: value}} as in controller.yaml."""
    slope = fuzzy_slope(gains)
    gains_of = matched(gains, params, slope)
    r_min, r_max, bound = bounds(params, disturbances, spec)
    delta = max(1.0 / r_min - 1.0, 1.0 - 1.0 / r_max)
    rows, sections = [], {'pid': {}, 'smc_integral': {}, 'se3': {}}
    for axis in AXES:
        k, kp, kd, ki = gains_of[axis]
        f, terms = bound[axis]
        switching = (1.0 + MARGIN) * f / r_min
        hover = params.g if axis == 'z' else 0.0
        limit = (switching + delta * hover) / ki
        mu = gains['common']['lambda'][axis] ** 2 / 4.0
        sections['pid'][axis] = {'kp': kp, 'ki': ki, 'kd': kd, 'integral_limit': limit}
        sections['smc_integral'][axis] = {'slope': k, 'integral_gain': mu, 'switching_gain': switching,
                                          'gain_uncertainty': delta, 'integral_limit': limit}
        sections['se3'][axis] = {'k_error': kp, 'k_rate': kd, 'k_integral': ki, 'integral_limit': limit}
        rows.append((axis, k, kp, kd, ki, terms, f, switching, hover, limit))
    return (slope, r_min, r_max, delta, rows), sections


def yaml_float(value: float) -> str:
    """4 significant digits, always a YAML float (16.0, not 16: a ROS parameter keeps its first type)."""
    text = f'{value:.4g}'
    return text if any(c in text for c in '.e') else text + '.0'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--gains', type=Path, default=None, help='NNIT2FSMC gains file (default: the packaged one)')
    parser.add_argument('--vehicle', type=Path, default=None, help='nominal vehicle file (default: the packaged one)')
    parser.add_argument('--campaign', type=Path, default=ROOT / 'campaigns' / 'paper-robustness.yaml')
    args = parser.parse_args(argv)
    params, disturbances = load_vehicle_file(args.vehicle)
    (slope, r_min, r_max, delta, rows), sections = derive(load_gains(args.gains), params, disturbances,
                                                          load_spec(args.campaign))
    print(f'IT2 least-squares slope: {slope:.4f} x fuzzy_gain / input_scale')
    print(f'gain ratio r = true/nominal in [{r_min:.4f}, {r_max:.4f}], gain_uncertainty = {delta:.4f}\n')
    print('| axis | k [1/s] | kp | kd | ki | model error terms [N or N m] | F [q\'\' units] | switching_gain | '
          'u_eq at hover | integral_limit |')
    print('|---|---:|---:|---:|---:|---|---:|---:|---:|---:|')
    for axis, k, kp, kd, ki, terms, f, switching, hover, limit in rows:
        parts = ', '.join(f'{name} {value:.4g}' for name, value in terms.items())
        print(f'| {axis} | {k:.4g} | {kp:.4g} | {kd:.4g} | {ki:.4g} | {parts} | {f:.4g} | {switching:.4g} | '
              f'{hover:.4g} | {limit:.4g} |')
    for section, per_axis in sections.items():
        print(f'\n    {section}:\n      axes:')
        for axis, values in per_axis.items():
            text = ', '.join(f'{key}: {yaml_float(value)}' for key, value in values.items())
            print(f'        {axis + ":":6} {{{text}}}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
