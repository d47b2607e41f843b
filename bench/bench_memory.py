"""Peak resident memory of run_stack.py flights of growing length, without and with a bag.

    .venv/bin/python bench/bench_memory.py [--repo DIR] [--durations 60 600 3600] [--bag both|yes|no]

Each flight runs in its own process (the embedded backend, the paper scenario, ``--quiet``); its
peak resident set is the ``ru_maxrss`` that ``os.wait4`` returns for it. ``--repo`` flies another
checkout's run_stack.py (e.g. an untouched main, for a before/after comparison) with this Python.
Prints one line per flight: duration, bag, exit status, wall time, peak RSS [MB] and that peak per
simulated second.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def peak_rss_mb(repo: Path, duration: float, bag: bool) -> tuple[int, float, float]:
    """(exit status, wall time [s], peak RSS [MB]) of one flight of ``duration`` [s]."""
    with tempfile.TemporaryDirectory() as scratch:
        command = [sys.executable, str(repo / 'run_stack.py'), '--backend', 'embedded', '--quiet',
                   '--duration', repr(duration), '--out', str(Path(scratch) / 'run')] + ([] if bag else ['--no-bag'])
        started = time.monotonic()
        process = subprocess.Popen(command, cwd=repo, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        return process.returncode, time.monotonic() - started, usage.ru_maxrss / 1024.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repo', type=Path, default=ROOT)
    parser.add_argument('--durations', type=float, nargs='+', default=[60.0, 600.0, 3600.0])
    parser.add_argument('--bag', choices=('both', 'yes', 'no'), default='both')
    args = parser.parse_args()
    bags = {'both': (False, True), 'yes': (True,), 'no': (False,)}[args.bag]
    print(f'repo {args.repo.resolve()}', flush=True)
    for duration in args.durations:
        for bag in bags:
            code, wall, peak = peak_rss_mb(args.repo, duration, bag)
            print(f'{duration:7g} s  {"bag   " if bag else "no bag"}  exit {code}  wall {wall:7.1f} s  '
                  f'peak RSS {peak:8.1f} MB  ({1000 * peak / duration:7.1f} kB per simulated s)', flush=True)


if __name__ == '__main__':
    main()
