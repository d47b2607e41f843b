"""Whether a flight passed, and if not why: the one rule that ``summary.json``, the terminal summary and
the review's report (``report.md``, ``report.html``, ``review.json``) all state.

A flight fails when

* it ended early: a failure rule stopped it (custom data ``failure`` and ``failure_time_s``), or its
  last control step lies before its planned length (custom data ``duration_s``): it was interrupted
  (Ctrl-C, a node died: custom data ``stopped``) or its bag was cut short (a recovered bag);
* a state or a rotor force went non-finite;
* its largest position error after settling exceeds the run's limit (``--max-error``, custom data
  ``max_error_m``).
"""
from __future__ import annotations

import math

from quad_msgs_bridge.bag.flight_bag import (DURATION_KEY, FAILURE_KEY, FAILURE_TIME_KEY, MAX_ERROR_KEY,
                                             STOPPED_KEY)

#: a flight whose last step comes this many control periods (or more) before its planned length ended early
EARLY_PERIODS = 1.5


def _number(custom: dict, key: str) -> float | None:
    try:
        value = float(custom[key])
    except (KeyError, TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def planned_duration(custom: dict) -> float | None:
    """[s] the length the flight was planned for, from its custom data; None if its bag does not say."""
    return _number(custom, DURATION_KEY)


def cut_short(custom: dict, end_time: float, period: float) -> float | None:
    """The planned length [s] of a flight whose last control step at ``end_time`` [s, sim time] comes before
    it (control period ``period`` [s]); None if the flight reached it or its length is not recorded."""
    planned = planned_duration(custom)
    if planned is None or end_time + EARLY_PERIODS * period > planned:
        return None
    return planned


def ending(custom: dict, end_time: float, period: float) -> str | None:
    """Why and where the flight ended early ('flipped over at 1.472 s', 'interrupted at 31.000 s of 60 s'),
    None if it flew its whole planned length (as far as its custom data says)."""
    reason = custom.get(FAILURE_KEY)
    if reason is not None:
        return f'{reason} at {float(custom.get(FAILURE_TIME_KEY, "nan")):.3f} s'
    planned = cut_short(custom, end_time, period)
    if planned is None:
        return None
    why = custom.get(STOPPED_KEY) or 'stopped (interrupted, or its bag was cut short)'
    return f'{why} at {end_time:.3f} s of {planned:g} s'


def failures(metrics: dict, ended: str | None, max_error: float | None) -> list[str]:
    """What failed (empty: the flight passed): ``ended`` from :func:`ending`, the ``metrics`` of
    ``flight_metrics`` and the run's ``max_error`` [m] (None: no limit known)."""
    found = [] if ended is None else [f'the flight ended early: {ended}']
    if not metrics['all_finite']:
        found.append('non-finite state or rotor force')
    if max_error is not None and metrics['max_position_error_m'] > max_error:
        found.append(f'max position error {metrics["max_position_error_m"]:.3f} m exceeds --max-error '
                     f'{max_error:g} m')
    return found


def max_error_of(custom: dict) -> float | None:
    """[m] the run's --max-error from its custom data; None if its bag does not say."""
    return _number(custom, MAX_ERROR_KEY)
