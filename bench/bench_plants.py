#!/usr/bin/env python3
"""Speed of the plants side by side: one physics step per vehicle on our model (compiled RK4), on RotorPy's
Multirotor (solve_ivp in Python) with its effects off (rotorpy-bare) and on (rotorpy), and on RotorPy's
BatchedMultirotor (torch, rotorpy-batched; needs requirements-rotorpy-batched.txt), for one vehicle and for a
batch of ``--batch`` vehicles stepped together (as a campaign worker steps them).

Each figure is the median over samples of a short inner loop of steps of hovering vehicles (1 ms steps), after a
warm-up, divided by the vehicles; the ratio to our model is printed beside it, and for RotorPy's Multirotor the
part of it spent in RotorPy's own ``Multirotor.step`` (the rest is our wrapper). Run from the repository root:

    .venv/bin/python bench/bench_plants.py            # about 1 min
    .venv-rotorpy-batched/bin/python bench/bench_plants.py --quick     # with rotorpy-batched
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import numpy as np  # noqa: E402

import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file  # noqa: E402
from quad_sim.plants import PLANTS, make_plant  # noqa: E402


def step_time(plant, state, forces, samples: int, loop: int) -> float:
    """Median wall time [s] of one step of ``plant`` from ``state`` under ``forces``."""
    for _ in range(loop):
        plant.step(0.0, state, forces, 1e-3)
    times = []
    for _ in range(samples):
        started = time.perf_counter_ns()
        for _ in range(loop):
            plant.step(0.0, state, forces, 1e-3)
        times.append((time.perf_counter_ns() - started) * 1e-9 / loop)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--quick', action='store_true', help='fewer samples')
    parser.add_argument('--batch', type=int, default=100, help='vehicles stepped together in the batch rows (100)')
    args = parser.parse_args()
    samples, loop = (5, 20) if args.quick else (11, 50)
    params, disturbances = load_vehicle_file(None)
    ours = {}
    for size in (1, args.batch):
        vehicle = params if size == 1 else VehicleParams.stack([params] * size)
        state = [0.0, 0.0, 1.0] + [0.0] * 9
        forces = [params.hover_force] * 4
        if size > 1:
            state, forces = [np.full(size, v) for v in state], [np.full(size, f) for f in forces]
        for name in PLANTS:
            if size > 1 and name == 'rotorpy-bare':
                continue
            try:
                plant = make_plant(name, vehicle, disturbances)
            except ParameterError as error:
                print(f'{name:15s} batch {size:4d}: not measured ({error})', flush=True)
                continue
            seconds = step_time(plant, state, forces, max(3, samples // size), max(2, loop // size)) / size
            ours.setdefault(size, seconds)
            print(f'{name:15s} batch {size:4d}: {seconds * 1e6:9.1f} us per vehicle and physics step   '
                  f'x{seconds / ours[size]:8.1f}   a 20 s flight at 1 kHz: {seconds * 20000:7.2f} s of plant time',
                  flush=True)
            if size == 1 and name in ('rotorpy', 'rotorpy-bare'):
                alone = rotorpy_alone(plant, state, forces, samples, loop)
                print(f'{"":15s} {alone * 1e6:9.1f} us of it in RotorPy\'s own Multirotor.step (without the section '
                      f'IV disturbances): our wrapper {100.0 * (1.0 - alone / seconds):.0f} %', flush=True)


def rotorpy_alone(plant, state, forces, samples: int, loop: int) -> float:
    """Median wall time [s] of RotorPy's own ``Multirotor.step`` of the plant's vehicle (a plain Multirotor of the
    same parameters, the same integrator settings), from the plant's converted state and thrusts: what is left
    of a step without our wrapper (conversions, section IV disturbances)."""
    from quad_msgs_bridge.rotorpy_conversion import motor_thrust_commands, rotorpy_state
    from quad_sim.rotorpy_plant import import_multirotor
    vehicle = plant._vehicles[0]
    multirotor = import_multirotor()(vehicle.quad, control_abstraction='cmd_motor_thrusts', aero=plant.aero,
                                     enable_ground=False)
    multirotor.integrator_kwargs = {'method': 'RK45', 'first_step': 1e-3}
    rotorpy = rotorpy_state(state, vehicle.rotor_speeds, None)
    control = {'cmd_motor_thrusts': motor_thrust_commands(forces, vehicle.params)}

    class Alone:
        def step(self, *_):
            multirotor.step(rotorpy, control, 1e-3)
    return step_time(Alone(), state, forces, samples, loop)


if __name__ == '__main__':
    main()
