#!/usr/bin/env python3
"""Speed of the cores: RK4 step, controller update, IT2 fuzzy evaluation, batch RK4, embedded flight.

Budgets (issue 2): one controller update plus one RK4 step of a single vehicle at most 200 us
median; one IT2 fuzzy evaluation at most 5 us. pyit2fls is timed on the same 5-rule system for
comparison, and the real-time factor of the 60 s paper flight at a 1 kHz step (the median of three
flights) is reported.

Each figure is the median and the 90th percentile over many samples; a sample times a short
inner loop with time.perf_counter_ns after a warm-up, and is divided by the loop length (and by
N for the batch). Run from the repository root:

    .venv/bin/python bench/bench_core.py            # full run, about 20 s
    .venv/bin/python bench/bench_core.py --quick    # fewer samples, a 10 s flight
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack.embedded import fly_embedded  # noqa: E402
from nnit2fsmc_controller.factory import build_controller, load_gains  # noqa: E402
from nnit2fsmc_controller.it2_fuzzy import CENTRES, CONSEQUENTS, LABELS, RULES, IT2FuzzyCorrector  # noqa: E402
from nnit2fsmc_controller.trajectory import Helix  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
from quad_sim.model import QuadrotorModel  # noqa: E402

BUDGETS_US = {'controller update + RK4 step': 200.0, 'IT2 fuzzy evaluation (ours)': 5.0}


def samples_us(run_once, inner: int, repeats: int, warmup: int, per: int = 1) -> list[float]:
    """Per-call times [us]: ``repeats`` samples of ``inner`` calls each, after ``warmup`` calls."""
    for _ in range(warmup):
        run_once()
    clock = time.perf_counter_ns
    result = []
    for _ in range(repeats):
        start = clock()
        for _ in range(inner):
            run_once()
        result.append((clock() - start) / 1e3 / inner / per)
    return result


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def closed_loop_samples(params, disturbances, gains, steps: int):
    """(t, state, reference) of a real paper flight, so the controller sees realistic inputs."""
    helix = Helix()
    controller = build_controller('nnit2fsmc', params, gains)
    model = QuadrotorModel(params, disturbances)
    state = helix.initial_state
    inputs = []
    for k in range(steps):
        t = k * 1e-3
        reference = helix.sample(t)
        inputs.append((t, list(state), reference))
        state = model.step(t, state, controller.update(t, state, reference).forces, 1e-3)
    return inputs


def bench_rk4(params, disturbances, repeats):
    model = QuadrotorModel(params, disturbances)
    state = [0.3, -0.2, 1.5, 0.1, 0.2, 0.05, 0.05, -0.03, 0.7, 0.1, -0.1, 0.05]
    forces = (1.2, 1.25, 1.18, 1.22)
    return samples_us(lambda: model.step(1.0, state, forces, 1e-3), inner=20, repeats=repeats, warmup=200)


def bench_update(params, disturbances, gains, repeats):
    inputs = closed_loop_samples(params, disturbances, gains, 6000)[5000:]   # after take-off
    controller = build_controller('nnit2fsmc', params, gains)
    for t, state, reference in inputs:      # learn on the way like in flight
        controller.update(t, state, reference)
    cursor = iter(range(10 ** 12))
    n = len(inputs)

    def once():
        t, state, reference = inputs[next(cursor) % n]
        controller.update(t, state, reference)
    return samples_us(once, inner=10, repeats=repeats, warmup=100)


def bench_update_and_step(params, disturbances, gains, steps):
    """The closed loop itself: per control step, one update and one RK4 step of the paper flight."""
    helix = Helix()
    controller = build_controller('nnit2fsmc', params, gains)
    model = QuadrotorModel(params, disturbances)
    state = helix.initial_state
    references = [helix.sample(k * 1e-3) for k in range(steps)]
    clock = time.perf_counter_ns
    result = []
    for k, reference in enumerate(references):
        t = k * 1e-3
        start = clock()
        out = controller.update(t, state, reference)
        state = model.step(t, state, out.forces, 1e-3)
        result.append((clock() - start) / 1e3)
    return result[1000:]   # warm-up: the first second of flight


def bench_fuzzy(repeats):
    fuzzy = IT2FuzzyCorrector(input_scale=0.3, output_gain=3.0)
    surfaces = [float(s) for s in np.random.default_rng(0).uniform(-0.45, 0.45, 1000)]
    inner = len(surfaces)

    def sweep():
        for s in surfaces:
            fuzzy(s)
    return samples_us(sweep, inner=1, repeats=repeats, warmup=5, per=inner)


def pyit2fls_system(input_scale=0.3, lower_height=0.6, lower_half_width=0.35):
    """The same 5-rule IT2 system in pyit2fls: its MF functions, then its KM type reducer."""
    import pyit2fls as p
    c = [input_scale * v for v in CENTRES]
    spacing, half, far = 0.5 * input_scale, lower_half_width * input_scale, 1e6
    upper = ([(p.trapezoid_mf, [-far, -far, c[0], c[1], 1.0])]
             + [(p.tri_mf, [x - spacing, x, x + spacing, 1.0]) for x in c[1:-1]]
             + [(p.trapezoid_mf, [c[3], c[4], far, far, 1.0])])
    lower = ([(p.trapezoid_mf, [-far, -far, c[0], c[0] + half, lower_height])]
             + [(p.tri_mf, [x - half, x, x + half, lower_height]) for x in c[1:-1]]
             + [(p.trapezoid_mf, [c[4] - half, c[4], far, far, lower_height])])
    consequents = [CONSEQUENTS[RULES[label]] for label in LABELS]

    def evaluate(s: float) -> float:
        x = np.array([s])
        intervals = np.array([[y, y, float(lo_f(x, lo_p)[0]), float(up_f(x, up_p)[0])]
                              for y, (lo_f, lo_p), (up_f, up_p) in zip(consequents, lower, upper)])
        y_l, y_r = p.KM_algorithm(intervals)
        return 0.5 * (y_l + y_r)
    return evaluate


def bench_pyit2fls(repeats):
    try:
        evaluate = pyit2fls_system()
    except ImportError:
        return None
    surfaces = [float(s) for s in np.random.default_rng(0).uniform(-0.45, 0.45, 50)]
    ours = IT2FuzzyCorrector(input_scale=0.3, output_gain=1.0)
    worst = max(abs(evaluate(s) - ours(s)) for s in surfaces)
    if worst > 1e-9:
        raise SystemExit(f'pyit2fls and our corrector disagree by {worst}: not the same system')

    def sweep():
        for s in surfaces:
            evaluate(s)
    return samples_us(sweep, inner=1, repeats=repeats, warmup=2, per=len(surfaces))


def bench_batch_rk4(params, disturbances, n, repeats):
    model = QuadrotorModel(params, disturbances)
    rng = np.random.default_rng(1)
    state = [rng.normal(0.0, 0.1, n) for _ in range(12)]
    state[2] = rng.uniform(1.0, 2.0, n)
    forces = tuple(rng.uniform(1.0, 1.4, n) for _ in range(4))
    return samples_us(lambda: model.step(1.0, state, forces, 1e-3), inner=1, repeats=repeats, warmup=3, per=n)


#: how many times the embedded flight is flown (this machine is shared: one flight can land on a slow moment)
FLIGHTS = 3


def row(name, values, budget=None):
    if values is None:
        return f'| {name} | n/a | n/a | (pyit2fls not installed) |'
    median, p90 = statistics.median(values), percentile(values, 90)
    verdict = '' if budget is None else (f'<= {budget:g}: ' + ('OK' if median <= budget else 'OVER BUDGET'))
    return f'| {name} | {median:.2f} | {p90:.2f} | {verdict} |'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true', help='fewer samples and a 10 s flight')
    parser.add_argument('--batch', type=int, default=10_000, help='vehicles in the batch RK4 (default 10000)')
    args = parser.parse_args(argv)
    repeats = 300 if args.quick else 2000
    params, disturbances = load_vehicle_file()
    gains = load_gains()

    cpu = next((line.split(':', 1)[1].strip() for line in Path('/proc/cpuinfo').read_text().splitlines()
                if line.startswith('model name')), platform.processor()) if Path('/proc/cpuinfo').exists() \
        else platform.processor()
    print(f'python {platform.python_version()}, numpy {np.__version__}, {cpu}')
    print()
    rows = [
        ('RK4 step, 1 vehicle (compiled kernel)', bench_rk4(params, disturbances, repeats), None),
        ('controller update (nnit2fsmc)', bench_update(params, disturbances, gains, repeats), None),
        ('controller update + RK4 step', bench_update_and_step(params, disturbances, gains,
                                                               6000 if args.quick else 21000),
         BUDGETS_US['controller update + RK4 step']),
        ('IT2 fuzzy evaluation (ours)', bench_fuzzy(repeats // 4), BUDGETS_US['IT2 fuzzy evaluation (ours)']),
        ('IT2 fuzzy evaluation (pyit2fls MFs + KM)', bench_pyit2fls(20 if args.quick else 100), None),
        (f'RK4 step per vehicle, batch of {args.batch} (compiled loop)',
         bench_batch_rk4(params, disturbances, args.batch, 30 if args.quick else 200), None),
    ]
    print('| measurement | median [us] | p90 [us] | budget [us] |')
    print('|---|---:|---:|---|')
    over = False
    for name, values, budget in rows:
        print(row(name, values, budget))
        over |= budget is not None and statistics.median(values) > budget

    duration = 10.0 if args.quick else 60.0
    walls = sorted(fly_embedded('nnit2fsmc', Helix(), params, disturbances, gains, duration, 1000.0).wall_time_s
                   for _ in range(FLIGHTS))
    median = statistics.median(walls)
    print()
    print(f'embedded paper flight, nnit2fsmc, {duration:g} s at 1 kHz, flown {FLIGHTS} times: median {median:.2f} s '
          f'wall, {median / duration * 1e3:.0f} us per control step (odometry, setpoints, update, RK4, record), '
          f'real-time factor {duration / median:.1f} (the {FLIGHTS} flights: '
          f'{", ".join(f"{duration / wall:.1f}" for wall in walls[::-1])})')
    return 1 if over else 0


if __name__ == '__main__':
    sys.exit(main())
