"""Pacing an embedded flight against the wall clock, for watching it live.

:class:`Pacer` is a step sink (the per-flight calls of ``FlightBag``): put first among the sinks
of a flight, it sleeps before a control step is handed to the next sinks until the wall clock has
caught up with that step's sim time divided by the speed factor. The sleep falls between two
control steps, never inside a bag write, and a flight that runs late never sleeps.
"""
from __future__ import annotations

import time
from typing import Callable

from quad_msgs_bridge.state import OdometrySample

#: [s, wall] a flight later than this behind its schedule (a slow machine, a suspended process)
#: restarts the schedule from now instead of rushing to catch up
MAX_LAG = 0.25


class Pacer:
    """Sim time runs at ``speed_factor`` sim seconds per wall second (> 0)."""

    def __init__(self, speed_factor: float, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        if not speed_factor > 0.0:
            raise ValueError(f'speed factor {speed_factor!r} must be > 0')
        self.speed_factor = speed_factor
        self._clock, self._sleep = clock, sleep
        self._origin: tuple[float, float] | None = None     # (sim time [s], wall time [s]) of the schedule

    def record_setpoints(self, path) -> None:
        """Nothing to pace."""

    def record_step(self, odometry: OdometrySample, *rest, **named) -> None:
        """Wait until the wall time of the step at ``odometry.stamp`` [s, sim]."""
        t, now = odometry.stamp, self._clock()
        if self._origin is None:
            self._origin = (t, now)
            return
        due = self._origin[1] + (t - self._origin[0]) / self.speed_factor
        if now < due:
            self._sleep(due - now)
        elif now - due > MAX_LAG:
            self._origin = (t, now)

    def close(self) -> None:
        """Nothing to finish."""
