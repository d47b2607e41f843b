#!/usr/bin/env python3
"""Fly the NNIT2FSMC flight stack from a clone: ``python3 run_stack.py --help`` (see flight_stack/cli.py).

Installed with ``pip install .``, the same command is ``nnit2fsmc-stack``.
"""
import sys

from flight_stack.cli import main   # importing flight_stack puts a clone's three ROS package folders on the path

if __name__ == '__main__':
    sys.exit(main())
