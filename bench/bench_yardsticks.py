#!/usr/bin/env python3
"""What users wait for, each beside its yardstick in the same process (issue 27): three ratios.

1. ``read``: ``read_flight`` of the bag of a D s paper flight, against flying that flight with its
   bag (``fly_embedded`` writing the bag, as ``run_stack.py`` flies it). Ratio = read wall time /
   fly wall time (goal: at most 0.15).
2. ``single``: one embedded paper flight (``fly_embedded``, nnit2fsmc, 1 kHz, no bag), in control
   steps per second, against a plain-float RK4 of eq. (1) (pure Python floats and :mod:`math`, one
   vehicle, the same 1 kHz step, hovering thrust) in steps per second. Ratio = flight / yardstick
   (goal: at least 0.33; the flight's real-time factor is printed too).
3. ``campaign``: a campaign (``run_campaign``, the paper scenario under its disturbances, nnit2fsmc,
   N flights of D s, every core as its default) end to end in vehicle-steps per second, against a
   bare numpy RK4 of eq. (1) over arrays of N vehicles (one process) in vehicle-steps per second.
   Ratio = campaign / yardstick (goal: at least 0.33).

The yardsticks are this file's own arithmetic of eq. (1) (the stack's kernels are not used), so
they cost the same whatever the stack does: they turn figures from a busy, shared machine into
ratios that compare between runs. Each is taken just before and just after the thing it measures
(the mean of the two).

``--root`` (repeatable) names a checkout whose code is measured (default: this one); each
measurement runs in a fresh process importing that checkout, the checkouts taken in turns, so
"before" (e.g. an untouched main) and "after" are measured side by side in one run:

    .venv/bin/python bench/bench_yardsticks.py --root /work/main --root . --quick
    .venv/bin/python bench/bench_yardsticks.py                 # this checkout, full sizes

Full sizes: a 600 s bag, a 20 s flight, 2,000 flights x 10 s. --quick: a 60 s bag, a 10 s flight,
1,000 flights x 4 s. The campaign is timed after a tiny one has filled numba's cache.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve()
G = 9.81


# --- the yardsticks: eq. (1) as plain floats and as numpy arrays --------------------------------

#: m [kg], Ix, Iy, Iz [kg m^2], d [m], translational and rotational drag
VEHICLE = dict(m=1.0, Ix=0.0075, Iy=0.0075, Iz=0.013, d=0.23, kt=0.01, kr=0.012)


def _derivative_floats(s, u1, u2, u3, u4, v=VEHICLE):
    """Eq. (1) for one vehicle: every value a Python float."""
    cf, sf = math.cos(s[6]), math.sin(s[6])
    ct, st = math.cos(s[7]), math.sin(s[7])
    cs, ss = math.cos(s[8]), math.sin(s[8])
    dphi, dtheta, dpsi = s[9], s[10], s[11]
    m = v['m']
    return (s[3], s[4], s[5],
            ((cf * cs * st + ss * sf) * u1 - v['kt'] * s[3]) / m,
            ((cf * ss * st - cs * sf) * u1 - v['kt'] * s[4]) / m,
            (cf * ct * u1 - v['kt'] * s[5]) / m - G,
            dphi, dtheta, dpsi,
            (dtheta * dpsi * (v['Iy'] - v['Iz']) + v['d'] * u2 - v['kr'] * dphi * abs(dphi)) / v['Ix'],
            (dphi * dpsi * (v['Iz'] - v['Ix']) + v['d'] * u3 - v['kr'] * dtheta * abs(dtheta)) / v['Iy'],
            (dphi * dtheta * (v['Ix'] - v['Iy']) + u4 - v['kr'] * dpsi * abs(dpsi)) / v['Iz'])


def plain_float_rk4(steps: int, dt: float = 1e-3) -> float:
    """Steps per second of a plain-float RK4 of eq. (1), one vehicle hovering."""
    s = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, -0.01, 0.1, 0.0, 0.0, 0.0)
    u = (VEHICLE['m'] * G, 0.0, 0.0, 0.0)
    started = time.perf_counter()
    for _ in range(steps):
        k1 = _derivative_floats(s, *u)
        k2 = _derivative_floats(tuple(a + 0.5 * dt * b for a, b in zip(s, k1)), *u)
        k3 = _derivative_floats(tuple(a + 0.5 * dt * b for a, b in zip(s, k2)), *u)
        k4 = _derivative_floats(tuple(a + dt * b for a, b in zip(s, k3)), *u)
        s = tuple(a + dt / 6.0 * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4))
    return steps / (time.perf_counter() - started)


def numpy_rk4(vehicles: int, steps: int, dt: float = 1e-3) -> float:
    """Vehicle-steps per second of a bare numpy RK4 of eq. (1) over arrays of ``vehicles`` vehicles."""
    import numpy as np
    rng = np.random.default_rng(0)
    s = [rng.normal(0.0, 0.05, vehicles) for _ in range(12)]
    s[2] = s[2] + 1.0
    u = (np.full(vehicles, VEHICLE['m'] * G), np.zeros(vehicles), np.zeros(vehicles), np.zeros(vehicles))
    v = VEHICLE

    def derivative(s):
        cf, sf, ct, st, cs, ss = np.cos(s[6]), np.sin(s[6]), np.cos(s[7]), np.sin(s[7]), np.cos(s[8]), np.sin(s[8])
        dphi, dtheta, dpsi = s[9], s[10], s[11]
        u1, u2, u3, u4 = u
        return (s[3], s[4], s[5],
                ((cf * cs * st + ss * sf) * u1 - v['kt'] * s[3]) / v['m'],
                ((cf * ss * st - cs * sf) * u1 - v['kt'] * s[4]) / v['m'],
                (cf * ct * u1 - v['kt'] * s[5]) / v['m'] - G,
                dphi, dtheta, dpsi,
                (dtheta * dpsi * (v['Iy'] - v['Iz']) + v['d'] * u2 - v['kr'] * dphi * np.abs(dphi)) / v['Ix'],
                (dphi * dpsi * (v['Iz'] - v['Ix']) + v['d'] * u3 - v['kr'] * dtheta * np.abs(dtheta)) / v['Iy'],
                (dphi * dtheta * (v['Ix'] - v['Iy']) + u4 - v['kr'] * dpsi * np.abs(dpsi)) / v['Iz'])
    started = time.perf_counter()
    for _ in range(steps):
        k1 = derivative(s)
        k2 = derivative([a + 0.5 * dt * b for a, b in zip(s, k1)])
        k3 = derivative([a + 0.5 * dt * b for a, b in zip(s, k2)])
        k4 = derivative([a + dt * b for a, b in zip(s, k3)])
        s = [a + dt / 6.0 * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4)]
    return vehicles * steps / (time.perf_counter() - started)


# --- the things measured (run inside a process importing one checkout) -------------------------

def _stack(root: Path):
    sys.path.insert(0, str(root))
    import flight_stack  # noqa: F401  (puts the three ROS package folders on the path)


def measure_read(duration: float) -> dict:
    from flight_stack.closed_loop import FailureRules
    from flight_stack.embedded import fly_embedded
    from nnit2fsmc_controller.factory import load_gains
    from nnit2fsmc_controller.trajectory import make_scenario
    from quad_msgs_bridge.bag.flight_bag import FlightBag
    from quad_msgs_bridge.review.flight_from_bag import read_flight
    from quad_msgs_bridge.vehicle_params import load_vehicle_file
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    fly_embedded('nnit2fsmc', make_scenario('paper', 0.1), params, disturbances, gains, 0.1, 1000.0)  # compile
    with tempfile.TemporaryDirectory() as folder:
        bag_path = Path(folder) / 'bag'
        started = time.perf_counter()
        with FlightBag.create(bag_path, params, 5.0, controller='nnit2fsmc', scenario='paper') as bag:
            fly_embedded('nnit2fsmc', make_scenario('paper', duration), params, disturbances, gains, duration,
                         1000.0, bag=bag, rules=FailureRules(5.0, math.inf))
        fly = time.perf_counter() - started
        read_flight(bag_path)  # warm (imports, kernels): a user's second read
        started = time.perf_counter()
        flight = read_flight(bag_path)
        read = time.perf_counter() - started
    return {'fly_s': fly, 'read_s': read, 'steps': flight.steps, 'ratio': read / fly}


def measure_single(duration: float) -> dict:
    from flight_stack.embedded import fly_embedded
    from nnit2fsmc_controller.factory import load_gains
    from nnit2fsmc_controller.trajectory import make_scenario
    from quad_msgs_bridge.vehicle_params import load_vehicle_file
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    fly_embedded('nnit2fsmc', make_scenario('paper', 0.1), params, disturbances, gains, 0.1, 1000.0)  # compile
    steps = round(duration * 1000)
    before = plain_float_rk4(steps)
    result = fly_embedded('nnit2fsmc', make_scenario('paper', duration), params, disturbances, gains, duration,
                          1000.0)
    flight_rate = result.steps / result.wall_time_s
    yardstick = 0.5 * (before + plain_float_rk4(steps))     # taken just before and just after the flight
    return {'steps_per_s': flight_rate, 'rtf': duration / result.wall_time_s, 'yardstick_steps_per_s': yardstick,
            'ratio': flight_rate / yardstick}


def measure_campaign(flights: int, duration: float) -> dict:
    from flight_stack.campaign.runner import RunOptions, run_campaign
    from flight_stack.campaign.spec import parse_spec

    def spec_of(flights: int, duration: float):
        return parse_spec({'scenario': 'paper', 'duration': duration, 'settle_time': min(5.0, duration / 2),
                           'controllers': ['nnit2fsmc'], 'flights': flights, 'seed': 1, 'control_rate_hz': 1000})
    spec = spec_of(flights, duration)
    yardstick_steps = max(50, min(2000, round(4_000_000 / flights)))
    with tempfile.TemporaryDirectory() as folder:
        # numba's cache filled first (a user's second campaign): a first run after an edit compiles for minutes
        run_campaign(spec_of(2, 0.2), Path(folder) / 'warm-up', RunOptions(progress=False))
        before = numpy_rk4(flights, yardstick_steps)
        started = time.perf_counter()
        run_campaign(spec, Path(folder) / 'campaign', RunOptions(progress=False))
        wall = time.perf_counter() - started
    vehicle_steps = flights * round(duration * 1000)
    rate = vehicle_steps / wall
    yardstick = 0.5 * (before + numpy_rk4(flights, yardstick_steps))     # just before and just after
    return {'wall_s': wall, 'vehicle_steps_per_s': rate, 'yardstick_vehicle_steps_per_s': yardstick,
            'ratio': rate / yardstick}


MEASURES = ('read', 'single', 'campaign')


def measure(kind: str, root: Path, quick: bool) -> dict:
    _stack(root)
    if kind == 'read':
        return measure_read(60.0 if quick else 600.0)
    if kind == 'single':
        return measure_single(10.0 if quick else 20.0)
    return measure_campaign(1000, 4.0) if quick else measure_campaign(2000, 10.0)


def describe(kind: str, m: dict) -> str:
    if kind == 'read':
        return (f'read {m["read_s"]:7.2f} s / fly with bag {m["fly_s"]:7.2f} s ({m["steps"]} steps) '
                f'= {m["ratio"]:.3f}  (goal <= 0.15)')
    if kind == 'single':
        return (f'flight {m["steps_per_s"]:8.0f} steps/s (RTF {m["rtf"]:5.1f}) / plain-float RK4 '
                f'{m["yardstick_steps_per_s"]:8.0f} steps/s = {m["ratio"]:.3f}  (goal >= 0.33)')
    return (f'campaign {m["vehicle_steps_per_s"]:10.0f} vehicle-steps/s ({m["wall_s"]:.1f} s) / numpy RK4 '
            f'{m["yardstick_vehicle_steps_per_s"]:10.0f} vehicle-steps/s = {m["ratio"]:.3f}  (goal >= 0.33)')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--root', action='append', type=Path,
                        help='a checkout to measure (repeat to compare; default: this one)')
    parser.add_argument('--only', choices=MEASURES, action='append', help='measure only this (repeatable)')
    parser.add_argument('--repeats', type=int, default=2, help='times each measurement is taken (default 2)')
    parser.add_argument('--quick', action='store_true', help='smaller sizes (see above)')
    parser.add_argument('--measure', choices=MEASURES, help=argparse.SUPPRESS)   # one measurement, in a child
    args = parser.parse_args(argv)
    roots = [root.resolve() for root in (args.root or [HERE.parent.parent])]
    if args.measure:
        print(json.dumps(measure(args.measure, roots[0], args.quick)))
        return 0
    results = {}
    for kind in args.only or MEASURES:
        for repeat in range(args.repeats):
            for root in roots:    # in turns, so a slow moment of the shared machine hits every checkout
                command = [sys.executable, str(HERE), '--measure', kind, '--root', str(root)] + \
                    (['--quick'] if args.quick else [])
                done = subprocess.run(command, capture_output=True, text=True, cwd=root,
                                      env={**os.environ, 'PYTHONHASHSEED': '0'})
                if done.returncode:
                    print(done.stderr[-3000:], file=sys.stderr)
                    return 1
                m = json.loads(done.stdout.strip().splitlines()[-1])
                results.setdefault((kind, root), []).append(m)
                print(f'{kind:8s} {str(root):24s} #{repeat + 1}: {describe(kind, m)}', flush=True)
    print()
    print('| measure | checkout | ratio (median of repeats) | goal |')
    print('|---|---|---:|---|')
    for (kind, root), ms in results.items():
        goal = '<= 0.15' if kind == 'read' else '>= 0.33'
        print(f'| {kind} | {root} | {statistics.median(m["ratio"] for m in ms):.3f} | {goal} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
