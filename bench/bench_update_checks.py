#!/usr/bin/env python3
"""What the argument checks of ``controller.update`` cost: check_inputs alone against a whole update, for
one vehicle and a batch, side by side in one run (the best of several repeats of each).

    .venv/bin/python bench/bench_update_checks.py
"""
import sys
import timeit

import numpy as np

from nnit2fsmc_controller.controller import check_inputs
from nnit2fsmc_controller.factory import build_controller, load_gains
from quad_msgs_bridge.reference import hold
from quad_msgs_bridge.vehicle_params import load_vehicle_file


def best_us(function, number: int, repeat: int = 7) -> float:
    return min(timeit.repeat(function, number=number, repeat=repeat)) / number * 1e6


def main() -> int:
    params, _ = load_vehicle_file(None)
    gains = load_gains()
    reference = hold((0.1, 0.0, 1.0))
    for kind in ('nnit2fsmc', 'pid'):
        for batch in (None, 64):
            controller = build_controller(kind, params, gains, batch=batch)
            state = [0.0, 0.0, 1.0] + [0.0] * 9
            if batch is not None:
                state = [np.full(batch, value) for value in state]
            controller.update(0.0, state, reference)
            number = 2000 if batch is None else 300
            update = best_us(lambda: controller.update(1e-3, state, reference), number)
            check = best_us(lambda: check_inputs(1e-3, state, reference, batch), number * 10)
            print(f'{kind:10s} {"one vehicle" if batch is None else f"batch of {batch}":12s} update {update:8.1f} us, '
                  f'its argument checks {check:6.2f} us ({100 * check / update:.1f} % of the update)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
