"""The time from SIGINT (or SIGTERM) to the exit of run_stack.py in each phase of a flight.

    .venv/bin/python bench/bench_interrupts.py [--repeat N]

Each phase is entered as tests/test_interrupt_phases.py enters it (the line the command prints on
entering it; an empty numba cache for the compiling phase), then the signal is sent. Prints one
line per phase and signal: the median and largest time to exit [s] over the repeats.
"""
import argparse
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT / 'tests'), str(ROOT)] + [str(ROOT / 'ros2_ws' / 'src' / package) for package in
                                                  ('quad_msgs_bridge', 'quad_sim', 'nnit2fsmc_controller')]
from test_interrupt_phases import PHASES, Run, earlier_run  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--repeat', type=int, default=3)
    args = parser.parse_args()
    for phase, (line, options) in PHASES.items():
        for number in (signal.SIGINT, signal.SIGTERM):
            times, codes = [], set()
            for _ in range(args.repeat):
                with tempfile.TemporaryDirectory() as scratch:
                    out = Path(scratch) / 'run'
                    earlier_run(out)
                    env = dict(os.environ)
                    if phase == 'compiling':
                        env['NUMBA_CACHE_DIR'] = str(Path(scratch) / 'numba-cache')
                    run = Run(out, options, env)
                    run.wait_for(line)
                    if phase == 'flying':
                        time.sleep(1.0)
                    times.append(run.stop(number))
                    codes.add(run.process.returncode)
            print(f'{phase:10s} {signal.Signals(number).name:8s} exit {sorted(codes)}: median {statistics.median(times):.3f} s, '
                  f'max {max(times):.3f} s ({args.repeat} runs)', flush=True)


if __name__ == '__main__':
    main()
