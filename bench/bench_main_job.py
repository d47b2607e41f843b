#!/usr/bin/env python3
"""The main job (scripts/fly.sh: the paper flight, bag, summary, review with plots) of two checkouts, side by side.

Runs ``python run_stack.py --backend embedded --quiet --out <fresh folder>`` of checkout A and of
checkout B alternately, ``--repeats`` times each, with the same interpreter, and prints each run's
wall time and CPU time (user + system of the child), the medians and the ratios B / A. Alternating
spreads the load of other work on the machine over both; CPU time is the steadier figure on a
shared machine. Extra arguments after ``--`` go to both commands.

Usage: python3 bench/bench_main_job.py BEFORE_CHECKOUT [AFTER_CHECKOUT] [--repeats 3] [-- --duration 20]
(AFTER_CHECKOUT defaults to this checkout). A checkout of an earlier commit:
    mkdir /tmp/before && git archive <commit> | tar -x -C /tmp/before
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_once(checkout: Path, extra: list[str]) -> tuple[float, float]:
    """(wall [s], CPU [s]) of one main job of ``checkout``."""
    with tempfile.TemporaryDirectory(prefix='bench-main-job-') as scratch:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        subprocess.run([sys.executable, 'run_stack.py', '--backend', 'embedded', '--quiet',
                        '--out', str(Path(scratch) / 'run'), *extra], cwd=checkout, check=True,
                       stdout=subprocess.DEVNULL, env={k: v for k, v in os.environ.items() if k != 'PYTHONPATH'})
        wall = time.perf_counter() - started
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    argv = sys.argv[1:]
    extra = argv[argv.index('--') + 1:] if '--' in argv else []
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('before', type=Path)
    parser.add_argument('after', type=Path, nargs='?', default=ROOT)
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args(argv[:argv.index('--')] if '--' in argv else argv)
    runs: dict[str, list[tuple[float, float]]] = {'A': [], 'B': []}
    for repeat in range(args.repeats):
        for name, checkout in (('A', args.before), ('B', args.after)):
            wall, cpu = run_once(checkout, extra)
            runs[name].append((wall, cpu))
            print(f'run {repeat + 1} {name}: wall {wall:6.2f} s  CPU {cpu:6.2f} s', flush=True)
    print(f'A = {args.before}\nB = {args.after}\nextra arguments: {" ".join(extra) or "none"}')
    medians = {name: (statistics.median(w for w, _ in values), statistics.median(c for _, c in values))
               for name, values in runs.items()}
    for name, (wall, cpu) in medians.items():
        print(f'median {name}: wall {wall:6.2f} s  CPU {cpu:6.2f} s')
    print(f'ratio B / A: wall {medians["B"][0] / medians["A"][0]:.3f}  CPU {medians["B"][1] / medians["A"][1]:.3f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
