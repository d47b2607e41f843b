"""Checking a user's values: the one error every package raises for them and the number checks, used by
every package (vehicle files, gains, campaign specs, the world of a flight, command-line options)."""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np


class ParameterError(ValueError):
    """An invalid parameter value; the message names the parameter and its valid range."""


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
                 low_inclusive: bool = True, high_inclusive: bool = True) -> float:
    """Return ``value`` as a float, or raise ParameterError if it is not a finite number in range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f'{name}: expected a number, got {value!r}')
    value = float(value)
    closed_low, closed_high = low_inclusive and math.isfinite(low), high_inclusive and math.isfinite(high)
    interval = f'{"[" if closed_low else "("}{low}, {high}{"]" if closed_high else ")"}'
    if not math.isfinite(value):
        bounded = math.isfinite(low) or math.isfinite(high)
        raise ParameterError(f'{name}: must be finite, got {value!r}' + (f' (valid range {interval})' if bounded else ''))
    below = value < low if low_inclusive else value <= low
    above = value > high if high_inclusive else value >= high
    if below or above:
        raise ParameterError(f'{name}: {value!r} is outside the valid range {interval}')
    return value


def check_values(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
                 low_inclusive: bool = True, high_inclusive: bool = True):
    """:func:`check_number` for one vehicle; for a batch, a 1-D numpy array checked element by element.

    Returns a float, or a float64 array of shape (B,); the error names the first bad vehicle.
    """
    if not isinstance(value, np.ndarray):
        return check_number(name, value, low, high, low_inclusive, high_inclusive)
    if value.ndim != 1 or value.size == 0 or value.dtype.kind not in 'iuf':
        raise ParameterError(f'{name}: expected a number or a 1-D numeric array with one element per vehicle, '
                             f'got an array of shape {value.shape} and dtype {value.dtype}')
    values = value.astype(float)
    below = values < low if low_inclusive else values <= low
    above = values > high if high_inclusive else values >= high
    bad = ~np.isfinite(values) | below | above
    if bad.any():
        vehicle = int(np.argmax(bad))
        check_number(f'{name} (vehicle {vehicle})', float(values[vehicle]), low, high, low_inclusive, high_inclusive)
    return values


def check_keys(value: Any, key: str, allowed: Sequence[str]) -> Mapping:
    """``value`` checked to be a mapping of keys among ``allowed``; ``key`` is its place ('' at the top of a
    file), named by the error with the valid keys."""
    if not isinstance(value, Mapping):
        raise ParameterError(f'{key or "spec"}: expected a mapping, got {value!r}')
    for name in value:
        if name not in allowed:
            raise ParameterError(f'{key + "." if key else ""}{name}: unknown key (valid keys: {", ".join(allowed)})')
    return value
