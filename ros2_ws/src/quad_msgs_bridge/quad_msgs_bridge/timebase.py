"""Sim time at the resolution of a ROS stamp: integer nanoseconds, with one conversion each way.

The cores use float seconds; messages carry (sec, nanosec). Converting only through these
functions makes a stamp that went through a message identical, to the bit, to the one that did not.
"""
from __future__ import annotations

NANOSECONDS_PER_SECOND = 1_000_000_000


def nanoseconds(t: float) -> int:
    """Time t [s] as whole nanoseconds (rounded)."""
    return int(round(t * 1e9))


def seconds(ns: int) -> float:
    """Whole nanoseconds as time [s]."""
    return ns / 1e9


def stamp_fields(t: float) -> tuple[int, int]:
    """(sec, nanosec) of a ``builtin_interfaces/Time`` for time t [s] (t >= 0)."""
    return divmod(nanoseconds(t), NANOSECONDS_PER_SECOND)


def stamp_seconds(sec: int, nanosec: int) -> float:
    """Time [s] of a ``builtin_interfaces/Time`` or ``Duration``."""
    return seconds(sec * NANOSECONDS_PER_SECOND + nanosec)
