"""An exclusive lock on a file, held by one process at a time (``flock``): a run that writes a folder takes
it so that a second run writing the same folder at once is refused by name instead of mixing the two.

The lock dies with its process (even on SIGKILL), so a crash never leaves a folder locked. The lock file
is removed when the lock is released; a run that opened it just before checks, once it holds the lock,
that the file is still the one at the path (else it tries again), so two runs never both hold it.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import Callable

from quad_msgs_bridge.validation import ParameterError

from .interrupts import deferred


class FileLock:
    """The lock on ``path``; ``busy(holder)`` is the ParameterError message when another process
    (``holder``: its pid as it wrote it, or '?') holds it."""

    def __init__(self, path: Path, busy: Callable[[str], str]):
        self.path, self.busy = Path(path), busy
        self._file = None

    def acquire(self) -> 'FileLock':
        """Take the lock, or raise ParameterError(busy(holder)); OSError if the file cannot be made.

        A stop signal (:mod:`flight_stack.interrupts`) does not cut it: it is raised once the lock is
        held, and then the lock is released (its file removed) before the KeyboardInterrupt goes on."""
        try:
            with deferred():
                self._take()
        except BaseException:
            self.release()
            raise
        return self

    def _take(self) -> None:
        while self._file is None:
            lock = open(self.path, 'a+')
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                lock.seek(0)
                holder = lock.read().strip() or '?'
                lock.close()
                raise ParameterError(self.busy(holder)) from None
            try:
                same = os.fstat(lock.fileno()).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False     # released and removed by its holder between our open and our flock
            if not same:
                lock.close()
                continue
            lock.truncate(0)
            lock.write(f'{os.getpid()}\n')
            lock.flush()
            self._file = lock

    def release(self) -> None:
        """Remove the lock file (still held: no other run took it in between), then release it."""
        if self._file is not None:
            self.path.unlink(missing_ok=True)
            self._file.close()
            self._file = None

    def __enter__(self) -> 'FileLock':
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
