"""``run_stack.py study NAME --out DIR [options]``: the command of every study; ``run_stack.py study --list``."""
from __future__ import annotations

import argparse
import ast
import importlib
import pkgutil
import sys
from pathlib import Path

from quad_msgs_bridge.validation import ParameterError

#: the modules of flight_stack/studies/ that are not studies
HELPERS = ('cli', 'common')
USAGE = 'usage: run_stack.py study --list | run_stack.py study NAME --out DIR [options] (NAME --help: its options)'


def studies() -> dict[str, str]:
    """{study name: the first paragraph of its module's docstring, on one line}, without importing the studies."""
    folder = Path(__file__).parent
    found = {}
    for info in sorted(pkgutil.iter_modules([str(folder)]), key=lambda info: info.name):
        if info.ispkg or info.name in HELPERS:
            continue
        doc = ast.get_docstring(ast.parse((folder / f'{info.name}.py').read_text())) or ''
        found[info.name.replace('_', '-')] = ' '.join(doc.split('\n\n')[0].split())
    return found


def listing() -> str:
    known = studies()
    width = max(map(len, known))
    return '\n'.join(f'{name:{width}s}  {description}' for name, description in known.items())


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ('-h', '--help'):
        print(f'{USAGE}\n\nThe studies (each makes the tables of a doc; docs/ names the command):\n{listing()}')
        return 0
    if argv[0] == '--list':
        print(listing())
        return 0
    name = argv[0]
    if name not in studies():
        print(f'{USAGE}\nerror: no study {name!r}; the studies:\n{listing()}', file=sys.stderr)
        return 2
    study = importlib.import_module(f'{__package__}.{name.replace("-", "_")}')
    parser = argparse.ArgumentParser(prog=f'run_stack.py study {name}', description=study.__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    study.add_arguments(parser)
    args = parser.parse_args(argv[1:])
    try:
        return study.run(args)
    except (ParameterError, ValueError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
