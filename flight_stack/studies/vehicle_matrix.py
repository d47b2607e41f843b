"""The every-kind-on-every-vehicle table of docs/VEHICLES.md and docs/ROTORPY.md (issue 28), packaged gains.

Flies each kind on each shipped vehicle (its own file: layout, mass, inertia, its section IV disturbances
scaled to them) on our plant, 20 s of ``hover`` and of the ``paper`` helix, and writes a Markdown table of
the position RMSE after the settling time [cm] and any failure. The example campaign's rows of the same
table come from the campaign command, one run per vehicle:

    run_stack.py study vehicle-matrix --out DIR
    .venv/bin/python run_stack.py campaign campaigns/paper-robustness.yaml --flights 200 --seed 1 \\
        --vehicle NAME --controllers nnit2fsmc,pid,se3,smc-integral,l1-se3,indi --out out/vehicles/NAME

Deterministic: the same command gives the same table. ``--plant rotorpy`` flies RotorPy instead (about 1 s of
CPU per simulated second: ``--plant rotorpy --duration 10``, the table of docs/VEHICLES.md, took 453 s here).
"""
from __future__ import annotations

import argparse

from flight_stack.api import fly
from quad_msgs_bridge.vehicle_params import shipped_vehicles

from .common import add_out, progress, study_name, write_table

STUDY = study_name(__name__)

KINDS = ('nnit2fsmc', 'pid', 'se3', 'smc-integral', 'l1-se3', 'indi')
SCENARIOS = ('hover', 'paper')


def cell(kind: str, scenario: str, vehicle: str, duration: float, plant: str) -> str:
    """'RMSE [cm]' of one flight, or 'failed: why'."""
    summary = fly(kind, scenario, duration=duration, vehicle=vehicle, plant=plant).summary
    if summary.get('failure'):
        return f"failed: {summary['failure']}"
    return f"{100.0 * summary['rmse_position_m']:.3f}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_out(parser)
    parser.add_argument('--duration', type=float, default=20.0, help='[s] per flight')
    parser.add_argument('--plant', default='quad_sim', help='quad_sim (our model), rotorpy or rotorpy-bare')


def run(args: argparse.Namespace) -> int:
    lines = [f'| vehicle | scenario | {" | ".join(KINDS)} |', f'|---|---|{"---:|" * len(KINDS)}']
    for vehicle in shipped_vehicles():
        for scenario in SCENARIOS:
            cells = [cell(kind, scenario, vehicle, args.duration, args.plant) for kind in KINDS]
            lines.append(f'| {vehicle} | {scenario} | {" | ".join(cells)} |')
            progress(STUDY, f'{vehicle}, {scenario}: {len(KINDS)} kinds flown')
    write_table(STUDY, args.out, '\n'.join(lines))
    return 0
