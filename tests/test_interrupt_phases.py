"""SIGINT and SIGTERM stop run_stack.py in every phase of a flight (planning, compiling, flying, reviewing):
exit 130, the earlier --out untouched, the interrupted run's bag (if it has one yet) closed and readable.

Each test starts the command in its own process with SIGINT and SIGTERM at their default disposition,
waits for the line it prints when it enters the phase, sends the signal and waits for the exit
(bench/bench_interrupts.py measures the time from signal to exit in each phase)."""
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from flight_stack.output import STAGING_MARK
from quad_msgs_bridge.bag.reader import is_finalized, mcap_file
from quad_msgs_bridge.review.flight_from_bag import read_flight
from hang_guard import HANG_TIMEOUT_S

ROOT = Path(__file__).resolve().parent.parent
#: [s] to reach a phase, and from the signal to the exit: only a hang takes that long (a first compile on a loaded
#: machine takes a minute; the exit about 0.1 s, bench/bench_interrupts.py measures it)
PHASE_TIMEOUT = EXIT_TIMEOUT = HANG_TIMEOUT_S

#: phase -> (the line the command prints on entering it, the options that make the phase last)
PHASES = {
    'planning': ('planning the flight', ['--duration', '1e9']),
    'compiling': ('compiling the kernels', ['--duration', '1e9']),
    'flying': ('; flying', ['--duration', '1e9']),
    'reviewing': ('reviewing the flight', ['--duration', '1']),
}


def default_disposition() -> None:
    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, signal.SIG_DFL)


class Run:
    """run_stack.py in a child process, its merged output read line by line on a thread."""

    def __init__(self, out: Path, options, env=None):
        self.process = subprocess.Popen(
            [sys.executable, str(ROOT / 'run_stack.py'), '--backend', 'embedded', '--overwrite', '--out', str(out),
             *options], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            preexec_fn=default_disposition, env=env)
        self.lines: list[str] = []
        self._queue: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str) -> None:
        deadline = time.monotonic() + PHASE_TIMEOUT
        while True:
            line = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            assert line is not None, f'exited before {text!r}:\n' + ''.join(self.lines)
            self.lines.append(line)
            if text in line:
                return

    def stop(self, number: int) -> float:
        """Send signal ``number``; the time [s] until the process exited."""
        sent = time.monotonic()
        self.process.send_signal(number)
        self.process.wait(timeout=EXIT_TIMEOUT)
        elapsed = time.monotonic() - sent
        while (line := self._queue.get(timeout=HANG_TIMEOUT_S)) is not None:
            self.lines.append(line)
        return elapsed


def earlier_run(out: Path) -> dict:
    """A stand-in earlier run in ``out`` (its files' bytes, to compare with afterwards)."""
    out.mkdir(parents=True)
    (out / 'summary.json').write_text('{"earlier": true}\n')
    (out / 'report.html').write_text('<p>earlier</p>\n')
    return snapshot(out)


def snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob('*')) if p.is_file()}


@pytest.mark.slow
@pytest.mark.parametrize('phase,number', [('planning', signal.SIGINT), ('compiling', signal.SIGINT),
                                          ('flying', signal.SIGTERM), ('flying', signal.SIGINT),
                                          ('reviewing', signal.SIGINT)])
def test_a_stop_signal_ends_the_run_in_every_phase(tmp_path, phase, number):
    out = tmp_path / 'run'
    before = earlier_run(out)
    env = dict(os.environ)
    if phase == 'compiling':    # an empty kernel cache: the kernels compile for as long as that takes
        env['NUMBA_CACHE_DIR'] = str(tmp_path / 'numba-cache')
    line, options = PHASES[phase]
    run = Run(out, options, env)
    run.wait_for(line)
    if phase == 'flying':
        time.sleep(1.0)          # a few hundred control steps into the bag
    run.stop(number)
    output = ''.join(run.lines)
    assert run.process.returncode == 130, output
    assert 'Traceback' not in output, output
    assert snapshot(out) == before, output
    assert f'{out} is unchanged' in output or phase == 'planning', output
    staged = sorted(p for p in tmp_path.iterdir() if STAGING_MARK in p.name)
    bags = [folder / 'bag' for folder in staged if (folder / 'bag').exists()]
    if phase in ('flying', 'reviewing'):
        assert bags, output
    for bag in bags:                       # closed, and readable as a flight if a step was flown
        assert is_finalized(mcap_file(bag)), output
        if phase in ('flying', 'reviewing'):
            flight = read_flight(bag)
            assert flight.record.time[0] == 0.0 and len(flight.record.time) > 10
            if phase == 'reviewing':
                assert flight.record.time[-1] == pytest.approx(0.999)
