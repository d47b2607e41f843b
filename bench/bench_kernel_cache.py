#!/usr/bin/env python3
"""What it costs that compiled kernels are never stale (quad_msgs_bridge.kernel_cache, issue 21).

Times the same command, ``run_stack.py --duration 1 --scenario hover --out OUT --overwrite`` (a whole
process: imports, kernels compiled or loaded, a 1 s flight, its bag and review), in temporary copies of
two trees, in turns:

* ``now``: this working tree (the kernels stamped with their module's import closure);
* ``before``: the tree of git revision ``--before`` (numba's own stamp: the defining file only).

In each copy, one after the other: ``cold`` (no cache file: every kernel compiles), ``warm`` (every kernel
loads from the cache), then after an edit (a comment appended) of ``it2_fuzzy.py``, of ``flight_stack/cli.py``
(which no kernel imports) and of ``quad_msgs_bridge/frames.py`` (which nearly every kernel reaches). The
``before`` tree recompiles only the kernels of the edited file and then flies the others stale: its
figures after an edit are what the stale cache cost, not what a correct one costs. Each round runs the
steps of the two trees alternately; the table gives, as medians over rounds, the CPU time of the process
(less disturbed by other load than its wall time, also given) and how many kernels numba compiled (it
prints a line for each kernel it saves to its cache, ``NUMBA_DEBUG_CACHE=1``), and the CPU ratio now/before.

Usage: python3 bench/bench_kernel_cache.py [--before 2ec9df6] [--rounds 2]
"""
from __future__ import annotations

import argparse
import io
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ('run_stack.py', 'flight_stack', 'ros2_ws/src')   # what run_stack.py needs from a tree
STEPS = (('cold', None),
         ('warm', None),
         ('after an edit of it2_fuzzy.py', 'ros2_ws/src/nnit2fsmc_controller/nnit2fsmc_controller/it2_fuzzy.py'),
         ('after an edit of flight_stack/cli.py', 'flight_stack/cli.py'),
         ('after an edit of frames.py', 'ros2_ws/src/quad_msgs_bridge/quad_msgs_bridge/frames.py'))


def copy_working_tree(target: Path) -> None:
    ignore = shutil.ignore_patterns('__pycache__', '*.nbi', '*.nbc', 'build', 'install', 'log')
    target.mkdir(parents=True)
    for source in SOURCES:
        if (ROOT / source).is_dir():
            shutil.copytree(ROOT / source, target / source, ignore=ignore)
        else:
            shutil.copy2(ROOT / source, target / source)


def copy_revision(revision: str, target: Path) -> None:
    archive = subprocess.run(['git', '-C', str(ROOT), 'archive', revision, *SOURCES], check=True,
                             capture_output=True).stdout
    target.mkdir(parents=True)
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(target, filter='data')


def run_step(tree: Path, step: int, edited: str | None, round_: int) -> tuple[float, float, int]:
    """(wall time [s], CPU time of the process [s], kernels compiled) of one run of the command in ``tree``."""
    if step == 0:
        for cached in [*tree.rglob('*.nbi'), *tree.rglob('*.nbc')]:
            cached.unlink()
    if edited is not None:
        with open(tree / edited, 'a') as source:
            source.write(f'# an edit (round {round_})\n')
    env = {**os.environ, 'NUMBA_DEBUG_CACHE': '1'}   # numba prints a line for each kernel it saves
    cpu_before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, 'run_stack.py', '--duration', '1', '--scenario', 'hover',
                           '--out', str(tree.parent / 'out'), '--overwrite', '--quiet'],
                          cwd=tree, env=env, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - started
    cpu_after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (cpu_after.ru_utime - cpu_before.ru_utime) + (cpu_after.ru_stime - cpu_before.ru_stime)
    return wall, cpu, done.stdout.count('[cache] data saved')


STAMP_COST = """
import time
import flight_stack
from quad_msgs_bridge import kernel_cache
started = time.perf_counter()
kernel_cache.closure_stamp('flight_stack.closed_loop')   # the flight's loop reaches every module a kernel reaches
print(time.perf_counter() - started, len(kernel_cache.import_closure('flight_stack.closed_loop')))
"""


def stamp_cost(tree: Path, processes: int = 5) -> tuple[float, int]:
    """(median time [s] a fresh process takes to stamp a flight's kernels, how many modules that reads)."""
    results = [subprocess.run([sys.executable, '-c', STAMP_COST], cwd=tree, check=True, capture_output=True,
                              text=True).stdout.split() for _ in range(processes)]
    return statistics.median(float(seconds) for seconds, _ in results), int(results[0][1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--before', default='2ec9df6', help='git revision before kernel_cache (default 2ec9df6)')
    parser.add_argument('--rounds', type=int, default=2, help='rounds of every step in both trees (default 2)')
    args = parser.parse_args(argv)

    runs: dict[tuple[str, int], list[tuple[float, float, int]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {'now': Path(tmp) / 'now' / 'tree', 'before': Path(tmp) / 'before' / 'tree'}
        copy_working_tree(trees['now'])
        copy_revision(args.before, trees['before'])
        for round_ in range(args.rounds):
            for step, (label, edited) in enumerate(STEPS):
                for name, tree in trees.items():
                    wall, cpu, compiled = run_step(tree, step, edited, round_)
                    runs.setdefault((name, step), []).append((wall, cpu, compiled))
                    print(f'round {round_ + 1}, {label}, {name}: {wall:.2f} s wall, {cpu:.2f} s CPU, '
                          f'{compiled} kernels compiled', flush=True)
        seconds, modules = stamp_cost(trees['now'])

    print(f'\nrun_stack.py --duration 1 --scenario hover, median of {args.rounds} round(s): CPU time of the process '
          f'[s] (wall time [s]), kernels compiled')
    print(f'| {"step":<36} | now | before ({args.before}) | now / before (CPU) |')
    print(f'|{"-" * 38}|----:|----:|----:|')
    for step, (label, _) in enumerate(STEPS):
        cells = []
        for name in ('now', 'before'):
            wall, cpu, compiled = (statistics.median(column) for column in zip(*runs[name, step]))
            cells.append((f'{cpu:.2f} ({wall:.2f}), {compiled:.0f}', cpu))
        print(f'| {label:<36} | {cells[0][0]} | {cells[1][0]} | {cells[0][1] / cells[1][1]:.2f} |')
    print(f"\nnow: the stamps of a flight's kernels cost a process {seconds * 1e3:.1f} ms ({modules} modules read; "
          f'median of 5 processes)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
