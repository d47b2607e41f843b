"""``run_stack.py list controllers|vehicles|scenarios|gains|plants|specs``: what can be named, a line each.

Each line is the name, a one-line description and, for files, where it is; a user's controller also says
where it came from (an installed package's entry point, or module:Class)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

WHAT = ('controllers', 'vehicles', 'scenarios', 'gains', 'plants', 'specs')


def first_comment_line(path: Path) -> str:
    """The first line of the leading comment of a YAML file (its one-line description), or ''."""
    for line in path.read_text().splitlines():
        if line.startswith('#'):
            return line.lstrip('#').strip()
        if line.strip():
            break
    return ''


def rows(what: str) -> list[tuple[str, str]]:
    """(name, description) of every thing of kind ``what`` (one of WHAT)."""
    if what == 'controllers':
        from nnit2fsmc_controller.registry import installed_kinds
        from quad_sim.plants import PX4_CONTROLLER, PX4_SITL
        return [(kind.name, kind.description + ('' if kind.source == 'built in' else f' [{kind.source}]'))
                for kind in installed_kinds()] + [
            (PX4_CONTROLLER, f'PX4\'s own cascaded position/velocity/attitude/rate controller, flown inside PX4 '
                             f'(--plant {PX4_SITL} only; docs/PX4.md)')]
    if what == 'vehicles':
        from quad_msgs_bridge.vehicle_params import shipped_vehicles
        return [(name, f'{first_comment_line(path)} ({path})') for name, path in shipped_vehicles().items()]
    if what == 'scenarios':
        from nnit2fsmc_controller.trajectory import SCENARIOS
        return [(name, (cls.__doc__ or '').strip().splitlines()[0]) for name, cls in SCENARIOS.items()]
    if what == 'gains':
        from nnit2fsmc_controller.factory import shipped_gains
        return [(name, f'{first_comment_line(path)} ({path})') for name, path in shipped_gains().items()]
    if what == 'plants':
        from quad_sim.plants import PLANT_DESCRIPTIONS
        return list(PLANT_DESCRIPTIONS.items())
    from flight_stack.campaign.spec import shipped_specs
    return [(path.stem, f'{first_comment_line(path)} ({path})') for path in shipped_specs()]


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='run_stack.py list', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('what', choices=WHAT)
    args = parser.parse_args(argv)
    from quad_msgs_bridge.validation import ParameterError
    try:
        listed = rows(args.what)
    except ParameterError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    width = max(len(name) for name, _ in listed)
    for name, description in listed:
        print(f'{name:{width}s}  {description}')
    return 0
