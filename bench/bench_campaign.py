#!/usr/bin/env python3
"""Speed of the campaign closed loop (issue 8): vehicle-steps per second, one and two cores, one vehicle.

What it measures, each figure the median of several repeats taken in turns (this 2-core machine is
shared: ratios measured side by side in one run mean more than any lone figure):

1. ``fly_batch`` (the NNIT2FSMC learning online, 1 kHz, the paper scenario) on one core for batch
   sizes N = 1 .. 10,000, without perturbations and with those of campaigns/paper-robustness.yaml.
   Flights are short, with settle_time 20 ms before the end (no vehicle is failed on the
   ground at take-off). "loop" counts the closed-loop steps only (first to last ClosedLoop.step);
   "end to end" is the whole fly_batch call (sampling the flights, building the batch, the rows).
2. N = 1,000 flights on both cores: two processes side by side, 500 flights each, started
   together after their imports (the sum of their steps over the wall time from the first start
   to the last end), and ``run_campaign`` with two workers (process start-up included).
3. The single-vehicle embedded flight without a bag (``fly_embedded``, paper scenario, 1 kHz):
   its real-time factor, and the cost of each part of a control step, each timed alone on the
   inputs of a real flight (the rest of the step is the loop's bookkeeping).
4. Where RotorPy is importable (not a dependency of this project): its batched closed loop
   (``simulate_batch``, BatchedMultirotor + BatchedSE3Control, Crazyflie parameters, rk4,
   N = 1,000, CPU, one torch thread), taken in turns with ours, and the ratio.

Run from the repository root (not part of the test suite):

    .venv/bin/python bench/bench_campaign.py --quick    # about 3 minutes
    .venv/bin/python bench/bench_campaign.py            # about 12 minutes
"""
from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
import numpy as np  # noqa: E402

import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack import closed_loop  # noqa: E402
from flight_stack.campaign import batch as batch_module  # noqa: E402
from flight_stack.campaign.batch import BatchJob, fly_batch  # noqa: E402
from flight_stack.campaign.runner import RunOptions, run_campaign  # noqa: E402
from flight_stack.campaign.spec import load_spec, parse_spec  # noqa: E402
from flight_stack.embedded import fly_embedded, published_path, setpoint_path, through_odometry  # noqa: E402
from nnit2fsmc_controller.factory import build_controller, load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import Helix  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
from quad_sim.model import QuadrotorModel  # noqa: E402

EXAMPLE_SPEC = ROOT / 'campaigns' / 'paper-robustness.yaml'
CONTROLLER = 'nnit2fsmc'
SIZES = (1, 10, 100, 1000, 10000)
SETTLED_S = 0.02   #: [s] flown after settling: the failure checks start then, and the metrics have data
ISSUE_TARGETS = {'two cores, N = 1,000 [vehicle-steps/s]': 500_000, 'embedded real-time factor': 20}


class TimedLoop(closed_loop.ClosedLoop):
    """The closed loop, remembering when its first step started and its last step ended."""

    latest = None

    def step(self):
        if self.started is None:
            self.started = time.perf_counter()
        done = super().step()
        self.ended = time.perf_counter()
        return done

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.started = self.ended = None
        TimedLoop.latest = self


batch_module.ClosedLoop = TimedLoop    # fly_batch builds its loop from this module's name


@dataclasses.dataclass
class Run:
    """One timed fly_batch call."""

    flights: int
    vehicle_steps: int          #: control steps flown, summed over the flights
    loop_s: float               #: [s] first step start to last step end
    total_s: float              #: [s] the whole fly_batch call
    failed: int                 #: flights that did not finish (should be 0)
    started: float = 0.0        #: perf_counter at the loop start (side-by-side runs)
    ended: float = 0.0

    @property
    def loop_rate(self) -> float:
        return self.vehicle_steps / self.loop_s

    @property
    def total_rate(self) -> float:
        return self.vehicle_steps / self.total_s


def short_spec(perturbed: bool, steps: int, flights: int):
    """The spec flown: the example spec's perturbations (or none), ``steps`` control steps at 1 kHz,
    settling :data:`SETTLED_S` before the end (no vehicle is failed on the ground at take-off), one controller."""
    if perturbed:
        spec = load_spec(EXAMPLE_SPEC)
    else:
        spec = parse_spec({'scenario': 'paper', 'controllers': [CONTROLLER], 'flights': 1, 'seed': 1})
    duration = steps * 1e-3
    return dataclasses.replace(spec, controllers=(CONTROLLER,), flights=flights, duration=duration,
                               settle_time=duration - SETTLED_S, control_rate_hz=1000.0)


def timed_batch(perturbed: bool, flights, steps: int) -> Run:
    """fly_batch of ``flights`` (indices) for ``steps`` control steps, timed."""
    spec = short_spec(perturbed, steps, len(flights))
    started = time.perf_counter()
    rows = fly_batch(BatchJob(spec, CONTROLLER, tuple(flights)))
    total = time.perf_counter() - started
    loop = TimedLoop.latest
    return Run(len(rows), sum(r['control_steps'] for r in rows), loop.ended - loop.started, total,
               sum(not r['finished'] for r in rows), loop.started, loop.ended)


def steps_for(size: int, quick: bool) -> int:
    """Control steps per flight: the vehicles take off after about 0.35 s (later when perturbed), so
    0.6 s at least; more in the full run, where the batch is not too large to repeat."""
    return 600 if quick or size > 1000 else 1500


def median(values) -> float:
    return statistics.median(values)


def spread(values) -> str:
    """min-max of the repeats, as a % of their median."""
    m = median(values)
    return f'{100 * (min(values) - m) / m:+.0f}/{100 * (max(values) - m) / m:+.0f} %'


def fmt_rate(value: float) -> str:
    return f'{value:,.0f}'


# ---- 1. one core, scaling -------------------------------------------------------------------------

def bench_scaling(quick: bool, repeats: int, sizes) -> dict:
    """{(N, perturbed): [Run, ...]}, the sizes and both conditions taken in turns in every repeat."""
    timed_batch(True, range(2), 5)          # imports, the bag type store, caches
    runs = {}
    for _ in range(repeats):
        for size in sizes:
            for perturbed in (False, True):
                runs.setdefault((size, perturbed), []).append(
                    timed_batch(perturbed, range(size), steps_for(size, quick)))
    return runs


def print_scaling(runs: dict, sizes) -> None:
    print('### One core: fly_batch, nnit2fsmc learning online, 1 kHz, vehicle-steps/s')
    print()
    print('| N | steps | nominal: loop | perturbed: loop | perturbed / nominal | perturbed: end to end '
          '| loop, per vehicle-step [us] | spread of repeats (perturbed loop) | failed |')
    print('|---:|---:|---:|---:|---:|---:|---:|---|---:|')
    for size in sizes:
        nominal, perturbed = runs[(size, False)], runs[(size, True)]
        ratio = median([p.loop_rate / n.loop_rate for n, p in zip(nominal, perturbed)])
        loop = median([r.loop_rate for r in perturbed])
        print(f'| {size:,} | {perturbed[0].vehicle_steps // size} | {fmt_rate(median([r.loop_rate for r in nominal]))} '
              f'| {fmt_rate(loop)} | {ratio:.2f} | {fmt_rate(median([r.total_rate for r in perturbed]))} '
              f'| {1e6 / loop:.2f} | {spread([r.loop_rate for r in perturbed])} '
              f'| {sum(r.failed for r in nominal + perturbed)} |')
    print()


# ---- 2. both cores --------------------------------------------------------------------------------

def _side_by_side_worker(perturbed: bool, flights, steps: int, barrier, results) -> None:
    timed_batch(perturbed, flights[:2], 5)      # imports and caches before the common start
    barrier.wait()
    results.put(timed_batch(perturbed, flights, steps))


def side_by_side(perturbed: bool, flights: int, steps: int, processes: int = 2) -> Run:
    """``flights`` split over ``processes`` processes flying at the same time; one Run for all of them."""
    context = multiprocessing.get_context('spawn')
    barrier, results = context.Barrier(processes), context.Queue()
    shares = np.array_split(np.arange(flights), processes)
    workers = [context.Process(target=_side_by_side_worker,
                               args=(perturbed, [int(k) for k in share], steps, barrier, results))
               for share in shares]
    for worker in workers:
        worker.start()
    runs = [results.get() for _ in workers]
    for worker in workers:
        worker.join()
    started, ended = min(r.started for r in runs), max(r.ended for r in runs)
    return Run(flights, sum(r.vehicle_steps for r in runs), ended - started,
               max(r.total_s for r in runs), sum(r.failed for r in runs), started, ended)


def campaign_run(perturbed: bool, flights: int, steps: int, workers: int = 2) -> tuple[float, int]:
    """run_campaign with ``workers`` processes: (wall time [s] of the flying, vehicle-steps)."""
    spec = short_spec(perturbed, steps, flights)
    with tempfile.TemporaryDirectory() as out:
        outcome = run_campaign(spec, Path(out) / 'campaign',
                               RunOptions(workers=workers, batch_size=flights // workers, progress=False))
    return outcome.wall_time_s, outcome.vehicle_steps


def bench_two_cores(quick: bool, repeats: int) -> dict:
    """Per condition: side-by-side Runs and one-core Runs of the same 1,000 flights, in turns."""
    steps = steps_for(1000, quick)
    results = {}
    for _ in range(repeats):
        for perturbed in (False, True):
            results.setdefault(('two', perturbed), []).append(side_by_side(perturbed, 1000, steps))
            results.setdefault(('one', perturbed), []).append(timed_batch(perturbed, range(1000), steps))
    wall, vehicle_steps = campaign_run(True, 1000, steps)
    results['campaign'] = vehicle_steps / wall
    return results


def print_two_cores(results: dict) -> None:
    target = ISSUE_TARGETS['two cores, N = 1,000 [vehicle-steps/s]']
    print(f'### Both cores: N = 1,000 flights (nnit2fsmc, 1 kHz), vehicle-steps/s (issue: >= {target:,})')
    print()
    print('| condition | two processes side by side (loop) | one core, one batch of 1,000 (loop) | two / one | failed |')
    print('|---|---:|---:|---:|---:|')
    for perturbed in (False, True):
        two, one = results[('two', perturbed)], results[('one', perturbed)]
        ratio = median([t.loop_rate / o.loop_rate for t, o in zip(two, one)])
        rate = median([r.loop_rate for r in two])
        verdict = 'OK' if rate >= target else 'below'
        print(f'| {"example spec" if perturbed else "no perturbation"} | {fmt_rate(rate)} ({verdict}) '
              f'| {fmt_rate(median([r.loop_rate for r in one]))} | {ratio:.2f} | {sum(r.failed for r in two + one)} |')
    print()
    print(f'run_campaign, example spec, 1,000 flights, 2 workers of 500 (process start-up and flights.csv '
          f'included, one run): {fmt_rate(results["campaign"])} vehicle-steps/s')
    print()


# ---- 3. one vehicle, embedded ---------------------------------------------------------------------

def flight_inputs(params, disturbances, gains, steps: int):
    """(t, state, reference, forces) of every control step of a paper flight on the ordinary path."""
    helix = Helix()
    setpoints = setpoint_path(published_path(helix, 50.0))
    controller = build_controller(CONTROLLER, params, gains)
    model = QuadrotorModel(params, disturbances)
    state = helix.initial_state
    inputs = []
    for k in range(steps):
        t = k * 1e-3
        reference = setpoints.sample(t)
        forces = controller.update(t, state, reference).forces
        inputs.append((t, state, reference, forces))
        state = model.step(t, state, forces, 1e-3)
    return setpoints, inputs


def per_call_us(function, inputs, warmup: int = 50) -> float:
    """Mean time [us] of ``function(*item)`` over the items, after ``warmup`` calls on the first ones."""
    for item in inputs[:warmup]:
        function(*item)
    clock = time.perf_counter
    started = clock()
    for item in inputs:
        function(*item)
    return (clock() - started) / len(inputs) * 1e6


def bench_embedded(quick: bool, repeats: int) -> dict:
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    duration = 5.0 if quick else 20.0
    steps = int(duration * 1000)
    setpoints, inputs = flight_inputs(params, disturbances, gains, steps)
    model = QuadrotorModel(params, disturbances)
    parts = {}
    for _ in range(repeats):
        result = fly_embedded(CONTROLLER, Helix(), params, disturbances, gains, duration, 1000.0)
        parts.setdefault('flight', []).append(result.wall_time_s / result.steps * 1e6)
        parts.setdefault('rtf', []).append(duration / result.wall_time_s)
        warm = build_controller(CONTROLLER, params, gains)          # warms the code up, then a fresh
        per_call_us(lambda t, s, r, f: warm.update(t, s, r), inputs[:500], warmup=0)   # one learns along
        controller = build_controller(CONTROLLER, params, gains)    # the recorded flight
        parts.setdefault('controller update', []).append(
            per_call_us(lambda t, s, r, f: controller.update(t, s, r), inputs, warmup=0))
        parts.setdefault('RK4 step (model)', []).append(
            per_call_us(lambda t, s, r, f: model.step(t, s, f, 1e-3), inputs))
        parts.setdefault('odometry round trip', []).append(
            per_call_us(lambda t, s, r, f: through_odometry(t, s), inputs))
        parts.setdefault('setpoint sampling', []).append(
            per_call_us(lambda t, s, r, f: setpoints.sample(t), inputs))
    parts['duration'] = duration
    return parts


def print_embedded(parts: dict) -> None:
    target = ISSUE_TARGETS['embedded real-time factor']
    rtf = median(parts['rtf'])
    flight = median(parts['flight'])
    print(f'### One vehicle: fly_embedded, paper scenario, {parts["duration"]:g} s at 1 kHz, no bag')
    print()
    print(f'real-time factor {rtf:.1f} (issue: >= {target}; {"OK" if rtf >= target else "below"}), '
          f'{flight:.1f} us per control step (spread of repeats {spread(parts["flight"])})')
    print()
    print('| part of a control step | us per step | share |')
    print('|---|---:|---:|')
    named = ('controller update', 'RK4 step (model)', 'odometry round trip', 'setpoint sampling')
    for name in named:
        value = median(parts[name])
        print(f'| {name} | {value:.1f} | {100 * value / flight:.0f} % |')
    rest = flight - sum(median(parts[name]) for name in named)
    print(f'| loop bookkeeping (the rest: failure check, statistics, record, sinks) | {rest:.1f} '
          f'| {100 * rest / flight:.0f} % |')
    print()


# ---- 4. RotorPy -----------------------------------------------------------------------------------

def rotorpy_batch(flights: int, steps: int):
    """RotorPy's batched closed loop: vehicle-steps/s of simulate_batch, or None without RotorPy."""
    try:
        import torch
        from rotorpy.controllers.quadrotor_control import BatchedSE3Control
        from rotorpy.simulate import simulate_batch
        from rotorpy.vehicles.crazyflie_params import quad_params
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
        from rotorpy.wind.default_winds import BatchedNoWind
        from rotorpy.sensors.imu import BatchedImu
        from rotorpy.world import World
    except ImportError:
        return None
    torch.set_num_threads(1)
    device = torch.device('cpu')
    params = BatchedMultirotorParams([dict(quad_params) for _ in range(flights)], flights, device)
    hover_speed = 1788.53      # [rad/s] Crazyflie rotor speed at hover (RotorPy's own examples)
    start = {'x': torch.zeros(flights, 3, dtype=torch.double), 'v': torch.zeros(flights, 3, dtype=torch.double),
             'q': torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.double).repeat(flights, 1),
             'w': torch.zeros(flights, 3, dtype=torch.double), 'wind': torch.zeros(flights, 3, dtype=torch.double),
             'rotor_speeds': torch.full((flights, 4), hover_speed, dtype=torch.double)}
    vehicle = BatchedMultirotor(params, flights, start, device=device, integrator='rk4')
    controller = BatchedSE3Control(params, flights, device=device)
    trajectory = BatchedCircle(flights, device, torch)
    world = World({'bounds': {'extents': [-10, 10, -10, 10, -10, 10]}, 'blocks': []})
    dt = 1e-3
    started = time.perf_counter()
    result = simulate_batch(world, start, vehicle, controller, trajectory, BatchedNoWind(flights),
                            BatchedImu(flights, device=device), np.full(flights, steps * dt), dt, 0.25,
                            terminate=False)
    wall = time.perf_counter() - started
    return float(np.sum(result[7])) / wall     # exit_timesteps: the steps each vehicle flew


class BatchedCircle:
    """A circle of radius 1 m at 0.5 rad/s (the paper helix without its climb), every vehicle the same,
    evaluated once for the whole batch (RotorPy's BatchedTrajectory calls each vehicle's in Python)."""

    def __init__(self, flights: int, device, torch):
        self.flights, self.device, self.torch = flights, device, torch

    def update(self, t):
        torch = self.torch
        t = torch.as_tensor(np.asarray(t, dtype=float), device=self.device).reshape(-1)
        t = t.expand(self.flights) if t.numel() == 1 else t
        w = 0.5
        c, s = torch.cos(w * t), torch.sin(w * t)
        zero = torch.zeros_like(t)
        x = torch.stack([c - 1.0, s, zero], dim=-1)
        x_dot = torch.stack([-w * s, w * c, zero], dim=-1)
        x_ddot = torch.stack([-w * w * c, -w * w * s, zero], dim=-1)
        x_dddot = torch.stack([w ** 3 * s, -w ** 3 * c, zero], dim=-1)
        x_ddddot = torch.stack([w ** 4 * c, w ** 4 * s, zero], dim=-1)
        return {'x': x, 'x_dot': x_dot, 'x_ddot': x_ddot, 'x_dddot': x_dddot, 'x_ddddot': x_ddddot,
                'yaw': zero, 'yaw_dot': zero, 'yaw_ddot': zero}


def bench_rotorpy(quick: bool, repeats: int) -> dict | None:
    steps = steps_for(1000, quick)
    if rotorpy_batch(2, 3) is None:
        return None
    results = {}
    for _ in range(repeats):
        results.setdefault('rotorpy', []).append(rotorpy_batch(1000, steps))
        for perturbed in (False, True):
            results.setdefault(perturbed, []).append(timed_batch(perturbed, range(1000), steps))
    return results


def print_rotorpy(results: dict | None) -> None:
    print('### RotorPy batched closed loop, N = 1,000, one core (one torch thread), 1 kHz, rk4')
    print()
    if results is None:
        print('RotorPy is not importable here (it is not a dependency; see the module docstring).')
        print()
        return
    import rotorpy  # noqa: F401
    import torch
    rotorpy_rate = median(results['rotorpy'])
    print(f'torch {torch.__version__}; simulate_batch with BatchedMultirotor, BatchedSE3Control, Crazyflie '
          'parameters, BatchedNoWind, BatchedImu, terminate=False')
    print()
    print('| closed loop | vehicle-steps/s | ours / RotorPy |')
    print('|---|---:|---:|')
    print(f'| RotorPy (SE3 control, no learning) | {fmt_rate(rotorpy_rate)} | |')
    for perturbed in (False, True):
        ours = results[perturbed]
        ratio = median([r.loop_rate / rp for r, rp in zip(ours, results['rotorpy'])])
        name = 'example spec perturbations' if perturbed else 'no perturbation'
        print(f'| ours, nnit2fsmc learning, {name} (loop) | {fmt_rate(median([r.loop_rate for r in ours]))} '
              f'| {ratio:.1f} |')
    print()


# ---- main -----------------------------------------------------------------------------------------

def machine() -> str:
    cpu = platform.processor()
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.exists():
        cpu = next((line.split(':', 1)[1].strip() for line in cpuinfo.read_text().splitlines()
                    if line.startswith('model name')), cpu)
    load = ' / '.join(f'{v:.1f}' for v in os.getloadavg()) if hasattr(os, 'getloadavg') else 'n/a'
    return (f'python {platform.python_version()}, numpy {np.__version__}, {cpu}, {os.cpu_count()} cores, '
            f'load average {load} (1/5/15 min)')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true', help='shorter flights and fewer repeats')
    parser.add_argument('--repeats', type=int, default=None, help='repeats of every figure (default 3, quick 2)')
    parser.add_argument('--sizes', default=','.join(map(str, SIZES)),
                        help=f'batch sizes of the one-core scaling, among {SIZES} (default: all)')
    args = parser.parse_args(argv)
    repeats = args.repeats or (2 if args.quick else 3)
    sizes = tuple(int(size) for size in args.sizes.split(','))
    if not set(sizes) <= set(SIZES):
        parser.error(f'--sizes: choose among {SIZES}')
    print(machine())
    print()
    started = time.perf_counter()
    print_scaling(bench_scaling(args.quick, repeats, sizes), sizes)
    print_two_cores(bench_two_cores(args.quick, repeats))
    print_embedded(bench_embedded(args.quick, repeats))
    print_rotorpy(bench_rotorpy(args.quick, repeats))
    print(f'bench wall time {time.perf_counter() - started:.0f} s; load average at the end '
          f'{" / ".join(f"{v:.1f}" for v in os.getloadavg())}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
