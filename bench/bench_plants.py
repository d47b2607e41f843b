#!/usr/bin/env python3
"""Speed of the plants side by side: one physics step of one vehicle on our model (compiled RK4) and on
RotorPy (solve_ivp in Python), with its effects off (rotorpy-bare) and on (rotorpy).

Each figure is the median over samples of a short inner loop of steps of a hovering vehicle (1 ms steps),
after a warm-up; the ratio to our model is printed beside it, and for RotorPy the part of it spent in
RotorPy's own ``Multirotor.step`` (the rest is our wrapper). Run from the repository root:

    .venv/bin/python bench/bench_plants.py            # about 10 s
    .venv/bin/python bench/bench_plants.py --quick
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import flight_stack  # noqa: E402,F401  (puts the three ROS package folders on the path)
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
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
    args = parser.parse_args()
    samples, loop = (5, 50) if args.quick else (15, 100)
    params, disturbances = load_vehicle_file(None)
    state = [0.0, 0.0, 1.0] + [0.0] * 9
    forces = (params.hover_force,) * 4
    ours = None
    for name in PLANTS:
        plant = make_plant(name, params, disturbances)
        seconds = step_time(plant, state, forces, samples, loop)
        ours = ours or seconds
        print(f'{name:13s} {seconds * 1e6:9.1f} us per vehicle and physics step   x{seconds / ours:7.1f}   '
              f'a 20 s flight at 1 kHz: {seconds * 20000:6.1f} s of plant time', flush=True)
        if name != 'quad_sim':
            alone = rotorpy_alone(plant, state, forces, samples, loop)
            print(f'{"":13s} {alone * 1e6:9.1f} us of it in RotorPy\'s own Multirotor.step (without the section IV '
                  f'disturbances): our wrapper {100.0 * (1.0 - alone / seconds):.0f} %', flush=True)


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
