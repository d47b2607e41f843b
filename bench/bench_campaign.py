#!/usr/bin/env python3
"""Speed of the campaign closed loop (issue 8): vehicle-steps per second, one and two cores, one vehicle.

What it measures (every figure the median of several repeats, the configurations taken in turns):

1. ``fly_batch`` (the NNIT2FSMC learning online, 1 kHz, the paper scenario) on one core for batch
   sizes N = 1 .. 10,000, without perturbations and with those of campaigns/paper-robustness.yaml.
   Flights are short (0.6 s or more: the vehicles leave the ground after about 0.35 s), with
   settle_time 20 ms before the end, so no vehicle is failed on the ground at take-off (the
   bookkeeping of settled steps, statistics and the crash and tracking checks, thus runs on the
   last 20 ms only: about 4 % of a step at N = 1,000 when it runs, not in these figures). "loop"
   counts the closed-loop steps only (first to last ClosedLoop.step); "end to end" is the whole
   fly_batch call (sampling the flights, building the batch, the rows). "failed" counts the flights
   a failure rule stopped (mostly perturbed vehicles flipping over or off track once the checks
   start): they stay in the batch, frozen, and the rates count the steps flown only.
2. N = 1,000 flights on both cores: two processes side by side, 500 flights each, started
   together after their imports, against one process flying all 1,000; and one ``run_campaign``
   with two workers (process start-up included).
3. The single-vehicle embedded flight without a bag (``fly_embedded``, paper scenario, 1 kHz): its
   real-time factor, and the cost of each part of a control step, each timed alone on the inputs of
   a real flight (the rest of the step is the loop's bookkeeping).
4. Where the time goes: a sampling profiler (a thread reading the flying thread's Python stack
   every millisecond) over one embedded flight and one batch of 1,000, each sample filed under the
   innermost part of :data:`PARTS` on the stack.
5. Where RotorPy is importable (not a dependency of this project): its batched closed loop
   (``simulate_batch``, BatchedMultirotor + BatchedSE3Control, Crazyflie parameters, rk4,
   N = 1,000, CPU, one torch thread), taken in turns with ours, and the ratio.

This 2-core machine is shared: every rate is given in wall time (what a run experiences) and in
CPU time of the flying thread (what the code costs; what the wall time would be on an idle
core). Ratios taken side by side in one run mean more than any lone figure.

Run from the repository root (not part of the test suite):

    .venv/bin/python bench/bench_campaign.py --quick    # about 5 minutes
    .venv/bin/python bench/bench_campaign.py            # about 11 minutes
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import multiprocessing
import os
import platform
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
import numpy as np  # noqa: E402

import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from flight_stack import closed_loop, embedded  # noqa: E402
from flight_stack.campaign import batch as batch_module  # noqa: E402
from flight_stack.campaign.batch import BatchJob, fly_batch  # noqa: E402
from flight_stack.campaign.runner import RunOptions, run_campaign  # noqa: E402
from flight_stack.campaign.spec import load_spec, parse_spec  # noqa: E402
from flight_stack.embedded import fly_embedded, published_path, setpoint_path, through_odometry  # noqa: E402
from nnit2fsmc_controller.factory import build_controller, load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import Helix  # noqa: E402
from quad_msgs_bridge.state import state_from_odometry  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
from quad_sim.model import QuadrotorModel  # noqa: E402

EXAMPLE_SPEC = ROOT / 'campaigns' / 'paper-robustness.yaml'
CONTROLLER = 'nnit2fsmc'
SIZES = (1, 10, 100, 1000, 10000)
SETTLED_S = 0.02   #: [s] flown after settling: the failure checks start then, and the metrics have data
TWO_CORE_TARGET = 500_000   #: [vehicle-steps/s] issue 8, N = 1,000 on both cores
RTF_TARGET = 20             #: issue 8, the single embedded flight at 1 kHz

#: (path fragment, qualified-name prefix or None, part): the profiler files a sample under the first
#: rule matched by the innermost frame that matches any; a part None passes the frame to its caller.
PARTS = (
    ('nnit2fsmc_controller/neural_network.py', 'EquivalentControlNetwork.forward', 'controller: NN forward'),
    ('nnit2fsmc_controller/neural_network.py', 'EquivalentControlNetwork.learn', 'controller: NN learning'),
    ('nnit2fsmc_controller/neural_network.py', None, None),
    ('nnit2fsmc_controller/it2_fuzzy.py', None, 'controller: IT2 fuzzy term'),
    ('nnit2fsmc_controller/', None, 'controller: cascade, laws, mixer'),
    ('quad_sim/model.py', None, 'model: RK4 of eq. (1)'),
    ('perturbations/streams.py', None, None),
    ('perturbations/sensor_noise.py', None, 'perturbations: sensor noise'),
    ('perturbations/wind.py', None, 'perturbations: wind (Dryden)'),
    ('perturbations/actuation.py', None, 'perturbations: delay, motor lag'),
    ('flight_stack/embedded.py', 'through_odometry', 'measurement: odometry round trip'),
    ('quad_msgs_bridge/reference.py', None, 'setpoint sampling'),
    ('quad_msgs_bridge/review/flight_data.py', None, 'bookkeeping: flight record (FlightLog)'),
    ('quad_msgs_bridge/review/metrics.py', None, 'bookkeeping: statistics, record rows'),
    ('flight_stack/closed_loop.py', 'ClosedLoop._check', 'bookkeeping: failure check'),
    ('flight_stack/closed_loop.py', None, 'bookkeeping: loop step'),
    ('quad_sim/simulator.py', None, 'bookkeeping: simulator (advance, set_forces)'),
    ('flight_stack/embedded.py', None, 'bookkeeping: embedded flight loop'),
    ('flight_stack/campaign/', None, 'campaign rows (after the loop)'),
)


class TimedLoop(closed_loop.ClosedLoop):
    """The closed loop, remembering when (wall and thread CPU time) its first step started and its
    last step ended, and starting the profiler's count at its first step."""

    latest = None
    sampler = None

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.started = self.ended = None
        TimedLoop.latest = self

    def step(self):
        if self.started is None:
            if TimedLoop.sampler is not None:
                TimedLoop.sampler.counting = True
            self.started = (time.perf_counter(), time.thread_time())
        done = super().step()
        self.ended = (time.perf_counter(), time.thread_time())
        return done


batch_module.ClosedLoop = TimedLoop    # fly_batch and fly_embedded build their loop from these names
embedded.ClosedLoop = TimedLoop


class StackSampler:
    """Counts, from a helper thread, under which part of :data:`PARTS` the calling thread is, once per
    ``interval`` [s], from the first step of a TimedLoop on (use as a context manager)."""

    def __init__(self, interval: float = 1e-3):
        self.interval = interval
        self.counts = collections.Counter()
        self.counting = False
        self._target = threading.get_ident()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(self.interval / 10)    # the flying thread hands the GIL over soon
        TimedLoop.sampler = self
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        TimedLoop.sampler = None
        sys.setswitchinterval(self._switch)

    def _run(self) -> None:
        while not self._stop.wait(self.interval):
            frame = sys._current_frames().get(self._target)
            if self.counting and frame is not None:
                self.counts[part_of(frame)] += 1

    def shares(self) -> dict[str, float]:
        total = sum(self.counts.values())
        return {part: count / total for part, count in self.counts.items()}


def part_of(frame) -> str:
    """The part of :data:`PARTS` the innermost matching frame of the stack belongs to."""
    while frame is not None:
        code = frame.f_code
        path = code.co_filename.replace(os.sep, '/')
        for fragment, prefix, part in PARTS:
            if fragment in path and (prefix is None or code.co_qualname.startswith(prefix)):
                if part is not None:
                    return part
                break
        frame = frame.f_back
    return 'other (the bench itself)'


@dataclasses.dataclass
class Run:
    """One timed fly_batch call (or several side by side)."""

    flights: int
    vehicle_steps: int          #: control steps flown, summed over the flights
    loop_s: float               #: [s] wall time, first step start to last step end
    loop_cpu_s: float           #: [s] CPU time of the flying thread over the same span
    total_s: float              #: [s] wall time of the whole fly_batch call
    failed: int                 #: flights that did not finish (should be 0)
    started: float = 0.0        #: perf_counter at the loop start (side-by-side runs)
    ended: float = 0.0
    cpu_rate: float | None = None   #: [vehicle-steps/s] of CPU time, when not steps / loop_cpu_s

    @property
    def loop_rate(self) -> float:
        return self.vehicle_steps / self.loop_s

    @property
    def loop_cpu_rate(self) -> float:
        return self.cpu_rate or self.vehicle_steps / self.loop_cpu_s

    @property
    def total_rate(self) -> float:
        return self.vehicle_steps / self.total_s


def short_spec(perturbed: bool, steps: int, flights: int):
    """The spec flown: the example spec's perturbations (or none), ``steps`` control steps at 1 kHz,
    settling :data:`SETTLED_S` before the end, one controller."""
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
    return Run(len(rows), sum(r['control_steps'] for r in rows), loop.ended[0] - loop.started[0],
               loop.ended[1] - loop.started[1], total, sum(not r['finished'] for r in rows),
               loop.started[0], loop.ended[0])


def steps_for(size: int, quick: bool) -> int:
    """Control steps per flight: 0.6 s at least (take-off); more in the full run where the batch
    is not too large to repeat."""
    return 600 if quick or size > 1000 else 1500


def median(values) -> float:
    return statistics.median(values)


def spread(values) -> str:
    """min and max of the repeats, relative to their median."""
    m = median(values)
    return f'{100 * (min(values) - m) / m:+.0f}/{100 * (max(values) - m) / m:+.0f} %'


def rate(value: float) -> str:
    return f'{value:,.0f}'


def rates(runs: list[Run]) -> str:
    """'wall / CPU' medians of the loop rates."""
    return f'{rate(median([r.loop_rate for r in runs]))} / {rate(median([r.loop_cpu_rate for r in runs]))}'


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
    print('### One core: fly_batch, nnit2fsmc learning online, 1 kHz: vehicle-steps/s of the loop, wall / CPU')
    print()
    print('| N | steps | no perturbation | example spec | example / none (CPU) | example spec, end to end (wall) '
          '| us per vehicle-step (example, CPU) | spread of repeats (example, wall) | failed |')
    print('|---:|---:|---:|---:|---:|---:|---:|---|---:|')
    for size in sizes:
        nominal, perturbed = runs[(size, False)], runs[(size, True)]
        ratio = median([p.loop_cpu_rate / n.loop_cpu_rate for n, p in zip(nominal, perturbed)])
        cpu = median([r.loop_cpu_rate for r in perturbed])
        print(f'| {size:,} | {perturbed[0].vehicle_steps // size} | {rates(nominal)} | {rates(perturbed)} '
              f'| {ratio:.2f} | {rate(median([r.total_rate for r in perturbed]))} | {1e6 / cpu:.2f} '
              f'| {spread([r.loop_rate for r in perturbed])} | {sum(r.failed for r in nominal + perturbed)} |')
    print()


# ---- 2. both cores --------------------------------------------------------------------------------

def _side_by_side_worker(perturbed: bool, flights, steps: int, barrier, results) -> None:
    timed_batch(perturbed, flights[:2], 5)      # imports and caches before the common start
    barrier.wait()
    results.put(timed_batch(perturbed, flights, steps))


def side_by_side(perturbed: bool, flights: int, steps: int, processes: int = 2) -> Run:
    """``flights`` split over ``processes`` processes flying at the same time, as one Run: its wall
    span runs from the first start to the last end; its CPU rate is the sum of the processes' own."""
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
    return Run(flights, sum(r.vehicle_steps for r in runs), ended - started, max(r.loop_cpu_s for r in runs),
               max(r.total_s for r in runs), sum(r.failed for r in runs), started, ended,
               cpu_rate=sum(r.loop_cpu_rate for r in runs))


def campaign_rate(flights: int, steps: int, workers: int = 2) -> float:
    """Vehicle-steps/s of one run_campaign of the example spec with ``workers`` processes (wall time
    from the pool's start to the last row written, as campaign.json reports it)."""
    spec = short_spec(True, steps, flights)
    with tempfile.TemporaryDirectory() as out:
        outcome = run_campaign(spec, Path(out) / 'campaign',
                               RunOptions(workers=workers, batch_size=flights // workers, progress=False))
    return outcome.vehicle_steps / outcome.wall_time_s


def bench_two_cores(quick: bool, repeats: int) -> dict:
    """Per condition: side-by-side Runs and one-process Runs of the same 1,000 flights, in turns."""
    steps = steps_for(1000, quick)
    results = {}
    for _ in range(repeats):
        for perturbed in (False, True):
            results.setdefault(('two', perturbed), []).append(side_by_side(perturbed, 1000, steps))
            results.setdefault(('one', perturbed), []).append(timed_batch(perturbed, range(1000), steps))
    results['campaign'] = campaign_rate(1000, steps)
    return results


def print_two_cores(results: dict) -> None:
    print(f'### Both cores: N = 1,000 flights (nnit2fsmc, 1 kHz): vehicle-steps/s of the loop, wall / CPU '
          f'(issue: >= {TWO_CORE_TARGET:,})')
    print()
    print('| condition | two processes of 500, side by side | one process of 1,000 | two / one (wall) | failed |')
    print('|---|---:|---:|---:|---:|')
    for perturbed in (False, True):
        two, one = results[('two', perturbed)], results[('one', perturbed)]
        ratio = median([t.loop_rate / o.loop_rate for t, o in zip(two, one)])
        print(f'| {"example spec" if perturbed else "no perturbation"} | {rates(two)} | {rates(one)} '
              f'| {ratio:.2f} | {sum(r.failed for r in two + one)} |')
    print()
    print('CPU of two processes = the sum of their own CPU rates: the rate with a whole core each.')
    print(f'run_campaign, example spec, 1,000 flights, 2 workers of 500 (process start-up and flights.csv '
          f'included, one run): {rate(results["campaign"])} vehicle-steps/s (wall)')
    print()


# ---- 3. one vehicle, embedded ---------------------------------------------------------------------

class CpuClock:
    """A sink of fly_embedded that notes the flying thread's CPU time when the loop starts."""

    def record_setpoints(self, path) -> None:
        self.started = time.thread_time()

    def record_step(self, *args, **kwargs) -> None:
        pass


class StepInputs:
    """A sink of fly_embedded that keeps (t, state the controller read, rotor forces) of every step."""

    def __init__(self):
        self.steps = []

    def record_setpoints(self, path) -> None:
        pass

    def record_step(self, observation, forces, *args, **kwargs) -> None:
        self.steps.append((observation.stamp, state_from_odometry(observation), forces))


def flight_inputs(params, disturbances, gains, duration: float):
    """The setpoint path of the paper flight, and (t, state, reference, forces) of each of its steps."""
    inputs = StepInputs()
    fly_embedded(CONTROLLER, Helix(), params, disturbances, gains, duration, 1000.0, sinks=[inputs])
    setpoints = setpoint_path(published_path(Helix(), 50.0))
    return setpoints, [(t, state, setpoints.sample(t), forces) for t, state, forces in inputs.steps]


def cpu_per_call_us(function, inputs, warmup: int = 50) -> float:
    """Mean CPU time [us] of ``function(*item)`` over the items, after ``warmup`` calls on the first ones."""
    for item in inputs[:warmup]:
        function(*item)
    started = time.thread_time()
    for item in inputs:
        function(*item)
    return (time.thread_time() - started) / len(inputs) * 1e6


def fly_paper(params, disturbances, gains, duration: float) -> tuple[float, float, int]:
    """One embedded paper flight: (wall [s], CPU [s] of the flying loop, steps)."""
    clock = CpuClock()
    result = fly_embedded(CONTROLLER, Helix(), params, disturbances, gains, duration, 1000.0, sinks=[clock])
    return result.wall_time_s, time.thread_time() - clock.started, result.steps


def bench_embedded(quick: bool, repeats: int) -> dict:
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    duration = 5.0 if quick else 20.0
    setpoints, inputs = flight_inputs(params, disturbances, gains, duration)
    model = QuadrotorModel(params, disturbances)
    parts = collections.defaultdict(list)
    for _ in range(repeats):
        wall, cpu, steps = fly_paper(params, disturbances, gains, duration)
        parts['wall'].append(wall / steps * 1e6)
        parts['cpu'].append(cpu / steps * 1e6)
        warm = build_controller(CONTROLLER, params, gains)             # warms the code up; a fresh one
        cpu_per_call_us(lambda t, s, r, f: warm.update(t, s, r), inputs[:500], warmup=0)   # then learns
        controller = build_controller(CONTROLLER, params, gains)       # along the recorded flight
        parts['controller update'].append(
            cpu_per_call_us(lambda t, s, r, f: controller.update(t, s, r), inputs, warmup=0))
        parts['RK4 step (model)'].append(cpu_per_call_us(lambda t, s, r, f: model.step(t, s, f, 1e-3), inputs))
        parts['odometry round trip'].append(cpu_per_call_us(lambda t, s, r, f: through_odometry(t, s), inputs))
        parts['setpoint sampling'].append(cpu_per_call_us(lambda t, s, r, f: setpoints.sample(t), inputs))
    parts['duration'] = duration
    return parts


def print_embedded(parts: dict) -> None:
    wall, cpu = median(parts['wall']), median(parts['cpu'])
    rtf_wall, rtf_cpu = 1e3 / wall, 1e3 / cpu
    print(f'### One vehicle: fly_embedded, paper scenario, {parts["duration"]:g} s at 1 kHz, no bag')
    print()
    print(f'real-time factor {rtf_wall:.1f} (wall), {rtf_cpu:.1f} (CPU) (issue: >= {RTF_TARGET}); '
          f'{wall:.1f} us (wall), {cpu:.1f} us (CPU) per control step; spread of repeats {spread(parts["wall"])} (wall)')
    print()
    print('| part of a control step (each timed alone on the inputs of a flight) | CPU us per step | share |')
    print('|---|---:|---:|')
    named = ('controller update', 'RK4 step (model)', 'odometry round trip', 'setpoint sampling')
    for name in named:
        value = median(parts[name])
        print(f'| {name} | {value:.1f} | {100 * value / cpu:.0f} % |')
    rest = cpu - sum(median(parts[name]) for name in named)
    print(f'| the rest: failure check, statistics, record, loop bookkeeping, and what the parts cost more '
          f'in the flight than alone | {rest:.1f} | {100 * rest / cpu:.0f} % |')
    print()


# ---- 4. where the time goes -----------------------------------------------------------------------

def bench_profile(quick: bool) -> dict:
    """Shares of the parts in one embedded flight and in one batch of 1,000 (example spec)."""
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    with StackSampler() as single:
        fly_paper(params, disturbances, gains, 5.0 if quick else 10.0)
    with StackSampler() as batch:
        timed_batch(True, range(1000), steps_for(1000, quick))
    return {'single': single, 'batch': batch}


def print_profile(samplers: dict, single_cpu_us: float, batch_cpu_us: float) -> None:
    single, batch = samplers['single'], samplers['batch']
    print('### Where the time goes (sampling profiler, shares of the samples; us = share x the CPU per step above)')
    print()
    print(f'| part | one vehicle: share | us per step | batch of 1,000, example spec: share | us per step |')
    print('|---|---:|---:|---:|---:|')
    one, many = single.shares(), batch.shares()
    names = [part for *_, part in PARTS if part is not None]
    for name in sorted(set(one) | set(many), key=lambda n: names.index(n) if n in names else len(names)):
        a, b = one.get(name, 0.0), many.get(name, 0.0)
        print(f'| {name} | {100 * a:.1f} % | {a * single_cpu_us:.1f} | {100 * b:.1f} % | {b * batch_cpu_us:,.0f} |')
    print(f'| samples | {sum(single.counts.values())} | | {sum(batch.counts.values())} | |')
    print()


# ---- 5. RotorPy -----------------------------------------------------------------------------------

class BatchedCircle:
    """A circle of radius 1 m at 0.5 rad/s through the origin (the paper helix without its climb) for
    every vehicle, evaluated once for the whole batch in torch (RotorPy's BatchedTrajectory calls
    each vehicle's trajectory in Python, its BatchedMinSnap loops over the vehicles per step)."""

    def __init__(self, flights: int, device, torch):
        self.flights, self.device, self.torch = flights, device, torch

    def update(self, t):
        torch = self.torch
        t = torch.as_tensor(np.asarray(t, dtype=float), device=self.device).reshape(-1).expand(self.flights)
        w = 0.5
        c, s = torch.cos(w * t), torch.sin(w * t)
        zero = torch.zeros_like(t)
        return {'x': torch.stack([c - 1.0, s, zero], dim=-1),
                'x_dot': torch.stack([-w * s, w * c, zero], dim=-1),
                'x_ddot': torch.stack([-w ** 2 * c, -w ** 2 * s, zero], dim=-1),
                'x_dddot': torch.stack([w ** 3 * s, -w ** 3 * c, zero], dim=-1),
                'x_ddddot': torch.stack([w ** 4 * c, w ** 4 * s, zero], dim=-1),
                'yaw': zero, 'yaw_dot': zero, 'yaw_ddot': zero}


def rotorpy_batch(flights: int, steps: int) -> Run | None:
    """RotorPy's batched closed loop for ``steps`` steps of 1 ms, timed; None without RotorPy."""
    try:
        import torch
        from rotorpy.controllers.quadrotor_control import BatchedSE3Control
        from rotorpy.sensors.imu import BatchedImu
        from rotorpy.simulate import simulate_batch
        from rotorpy.vehicles.crazyflie_params import quad_params
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams
        from rotorpy.wind.default_winds import BatchedNoWind
        from rotorpy.world import World
    except ImportError:
        return None
    torch.set_num_threads(1)
    device = torch.device('cpu')
    params = BatchedMultirotorParams([dict(quad_params) for _ in range(flights)], flights, device)
    hover_speed = 1788.53      # [rad/s] Crazyflie rotor speed at hover (RotorPy's own examples)
    zeros = torch.zeros(flights, 3, dtype=torch.double)
    start = {'x': zeros.clone(), 'v': zeros.clone(), 'w': zeros.clone(), 'wind': zeros.clone(),
             'q': torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.double).repeat(flights, 1),
             'rotor_speeds': torch.full((flights, 4), hover_speed, dtype=torch.double)}
    vehicle = BatchedMultirotor(params, flights, start, device=device, integrator='rk4')
    controller = BatchedSE3Control(params, flights, device=device)
    world = World({'bounds': {'extents': [-10, 10, -10, 10, -10, 10]}, 'blocks': []})
    started = (time.perf_counter(), time.thread_time())
    result = simulate_batch(world, start, vehicle, controller, BatchedCircle(flights, device, torch),
                            BatchedNoWind(flights), BatchedImu(flights, device=device),
                            np.full(flights, steps * 1e-3), 1e-3, 0.25, terminate=False)
    ended = (time.perf_counter(), time.thread_time())
    flown = int(np.sum(result[7]))      # exit_timesteps: the steps each vehicle flew
    return Run(flights, flown, ended[0] - started[0], ended[1] - started[1], ended[0] - started[0], 0)


def bench_rotorpy(quick: bool, repeats: int) -> dict | None:
    steps = steps_for(1000, quick)
    if rotorpy_batch(2, 3) is None:
        return None
    results = collections.defaultdict(list)
    for _ in range(repeats):
        results['rotorpy'].append(rotorpy_batch(1000, steps))
        for perturbed in (False, True):
            results[perturbed].append(timed_batch(perturbed, range(1000), steps))
    return results


def print_rotorpy(results: dict | None) -> None:
    print('### RotorPy batched closed loop, N = 1,000, one core (one torch thread), 1 kHz, rk4: '
          'vehicle-steps/s, wall / CPU')
    print()
    if results is None:
        print('RotorPy is not importable here (it is not a dependency of this project).')
        print()
        return
    import rotorpy  # noqa: F401
    import torch
    theirs = results['rotorpy']
    print(f'torch {torch.__version__}; simulate_batch (whole call) with BatchedMultirotor, BatchedSE3Control, '
          'Crazyflie parameters, BatchedNoWind, BatchedImu, terminate=False')
    print()
    print('| closed loop | vehicle-steps/s | ours / RotorPy (wall) | ours / RotorPy (CPU) |')
    print('|---|---:|---:|---:|')
    print(f'| RotorPy (SE3 control, no learning, no perturbation) | {rates(theirs)} | | |')
    for perturbed in (False, True):
        ours = results[perturbed]
        wall = median([r.loop_rate / t.loop_rate for r, t in zip(ours, theirs)])
        cpu = median([r.loop_cpu_rate / t.loop_cpu_rate for r, t in zip(ours, theirs)])
        name = 'the example spec' if perturbed else 'no perturbation'
        print(f'| ours (nnit2fsmc learning online, {name}; loop) | {rates(ours)} | {wall:.1f} | {cpu:.1f} |')
    print()


# ---- main -----------------------------------------------------------------------------------------

def machine() -> str:
    cpu = platform.processor()
    cpuinfo = Path('/proc/cpuinfo')
    if cpuinfo.exists():
        cpu = next((line.split(':', 1)[1].strip() for line in cpuinfo.read_text().splitlines()
                    if line.startswith('model name')), cpu)
    return f'python {platform.python_version()}, numpy {np.__version__}, {cpu}, {os.cpu_count()} cores'


def load() -> str:
    return ' / '.join(f'{v:.1f}' for v in os.getloadavg()) if hasattr(os, 'getloadavg') else 'n/a'


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true', help='shorter flights and fewer repeats')
    parser.add_argument('--repeats', type=int, default=None, help='repeats of every figure (default 3, quick 2)')
    parser.add_argument('--sizes', default=','.join(map(str, SIZES)),
                        help=f'batch sizes of the one-core scaling, among {SIZES} (default: all)')
    args = parser.parse_args(argv)
    repeats = args.repeats or (2 if args.quick else 3)
    sizes = tuple(int(size) for size in args.sizes.split(','))
    if not set(sizes) <= set(SIZES) or 1000 not in sizes:
        parser.error(f'--sizes: choose among {SIZES}, 1000 included')
    print(f'{machine()}; load average {load()} (1/5/15 min)')
    print()
    started = time.perf_counter()
    scaling = bench_scaling(args.quick, repeats, sizes)
    print_scaling(scaling, sizes)
    print_two_cores(bench_two_cores(args.quick, repeats))
    single = bench_embedded(args.quick, repeats)
    print_embedded(single)
    print_profile(bench_profile(args.quick), median(single['cpu']),
                  1000 * 1e6 / median([r.loop_cpu_rate for r in scaling[(1000, True)]]))
    print_rotorpy(bench_rotorpy(args.quick, repeats))
    print(f'bench wall time {time.perf_counter() - started:.0f} s; load average at the end {load()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
