#!/usr/bin/env python3
"""Fly the NNIT2FSMC flight stack from a clone: ``python3 run_stack.py --help`` (see flight_stack/cli.py).

Installed with ``pip install .``, the same command is ``nnit2fsmc-stack``. Run with a system Python that
lacks the stack's packages (numpy, numba, ...), it runs itself again with the clone's ``.venv`` (made by
``bash scripts/fly.sh`` or ``scripts/setup_venv.sh``) when there is one, else says so and exits 2.
"""
import importlib.util
import os
import sys
from pathlib import Path

#: modules every command needs -> the distribution that provides them
NEEDED = {'numpy': 'numpy', 'numba': 'numba', 'yaml': 'PyYAML', 'rosbags': 'rosbags', 'mcap': 'mcap'}


def missing_packages() -> list:
    return [package for module, package in NEEDED.items() if importlib.util.find_spec(module) is None]


def use_the_venv_or_exit() -> None:
    """Run again with the clone's .venv python if this Python, a system one (not a virtual environment),
    lacks a package; without a .venv, exit 2 saying how to run. Inside a virtual environment (the clone's
    or another) a missing package is named by the command: a venv a user chose is never swapped silently."""
    if sys.prefix != sys.base_prefix:
        return
    venv = Path(__file__).resolve().parent / '.venv'
    missing = missing_packages()
    if not missing:
        return
    python = venv / 'bin' / 'python'
    if python.exists():
        os.execv(str(python), [str(python), str(Path(__file__).resolve()), *sys.argv[1:]])
    print(f'error: {sys.executable} lacks {", ".join(missing)}; run `bash scripts/fly.sh [OPTIONS]` (it makes '
          f'.venv once), or `.venv/bin/python run_stack.py [OPTIONS]`, or `pip install .` and `nnit2fsmc-stack`',
          file=sys.stderr)
    sys.exit(2)


def main(argv=None) -> int:
    """The command (flight_stack.cli.main) with ``argv`` (default: the command line); its exit status."""
    use_the_venv_or_exit()
    from flight_stack.cli import main as run   # importing flight_stack puts a clone's ROS package folders on the path
    return run(argv)


if __name__ == '__main__':
    sys.exit(main())
