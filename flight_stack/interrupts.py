"""SIGINT (Ctrl-C) and SIGTERM stop a run at once, in any phase: planning, compiling, flying, reviewing.

Inside :func:`stop_signals` either signal raises KeyboardInterrupt where the program is, except in a
:func:`deferred` block: there it is noted and raised when the block ends. A block that must not be
cut in two is deferred: the bag messages of one control step (a KeyboardInterrupt in the middle of
one once left a message counted in the bag's index that was not in its chunk), creating and closing
the bag (so an interrupted run's bag is always closed and readable), moving a finished run into
place. Each of those takes far less than a second, so a signal still stops the run within one.
"""
from __future__ import annotations

import contextlib
import signal
import threading

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_deferring = 0                    #: how many deferred blocks the program is in
_pending: int | None = None       #: a signal that came inside a deferred block


def _on_signal(signum: int, frame) -> None:
    global _pending
    if _deferring:
        _pending = signum
        return
    raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def stop_signals():
    """SIGINT and SIGTERM raise KeyboardInterrupt (after the current deferred block) while inside.

    Signals reach only the main thread: called from another thread it changes nothing (the
    signals keep whatever the program set for them).
    """
    global _pending
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _pending = None
    previous = {number: signal.signal(number, _on_signal) for number in _STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


@contextlib.contextmanager
def deferred():
    """A block that a stop signal does not cut: the KeyboardInterrupt comes when it ends (if the block
    raises nothing else)."""
    global _deferring, _pending
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    if not _deferring and _pending is not None:
        signum, _pending = _pending, None
        raise KeyboardInterrupt(signal.Signals(signum).name)
