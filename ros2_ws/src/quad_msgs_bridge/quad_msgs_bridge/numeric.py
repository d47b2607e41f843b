"""One set of elementwise math for a single vehicle (plain floats) and a batch (numpy arrays).

Equations are written once against a namespace ``xp``; :func:`namespace_for` picks the fast
plain-float one for a single vehicle and the numpy one when the values are arrays with one
element per vehicle. Both namespaces offer the same primitives with the same meaning:

* ``sin cos atan2 hypot sqrt exp expm1 abs``: as in :mod:`math`, elementwise;
* ``minimum(a, b)``, ``maximum(a, b)``, ``clip(v, low, high)``, ``where(condition, a, b)``;
* ``sign(v)``: -1, 0 or +1; ``signed_square(v)``: v |v|;
* ``zeros_like(v)``: zero(s) of v's shape; ``copy(v)``: an independent copy of v;
* ``all_finite(values)``: whether every value of a sequence (of floats or arrays) is finite;
* ``finite_each(values)``: per vehicle, whether all its values in the sequence are finite;
* ``any(condition)``, ``all(condition)``: whether the condition holds for any, every vehicle (a plain bool).

A single vehicle runs on plain floats because numpy's per-call overhead (a microsecond) is far
larger than the arithmetic of one vehicle; a batch pays that overhead once for every vehicle.

The hot equations (model, frames, mixer, eq. 10, filters, failure rules, the NNIT2FSMC law) are
compiled kernels instead (numba), written once with ``numpy`` functions, which numba builds for
floats and for arrays alike; :func:`select` and :func:`every` are ``where`` and ``all`` above in a
form numba also compiles, for a plain bool and for a bool array.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from numba import types
from numba.extending import overload

import quad_msgs_bridge.kernel_cache  # noqa: F401  (every kernel module imports this module: its kernels' cache stamps)


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _where(condition: bool, if_true: float, if_false: float) -> float:
    return if_true if condition else if_false


def _sign(value: float) -> float:
    return 1.0 if value > 0.0 else -1.0 if value < 0.0 else 0.0


def _batch_all_finite(values) -> bool:
    """Whether every value of ``values`` (numbers and arrays) is finite. The arrays are joined and checked by one
    ``isfinite``: a batch runs this on its state at every control step, and a call per array costs ten times
    more. TypeError for a value that is not a number (as ``np.isfinite`` raises it)."""
    arrays = []
    for value in values:
        if isinstance(value, np.ndarray):
            arrays.append(value.ravel())
        elif isinstance(value, (float, int)):
            if not math.isfinite(value):
                return False
        else:
            arrays.append(np.ravel(value))
    return not arrays or bool(np.isfinite(np.concatenate(arrays)).all())


SCALAR = SimpleNamespace(
    sin=math.sin, cos=math.cos, atan2=math.atan2, hypot=math.hypot,
    sqrt=math.sqrt, exp=math.exp, expm1=math.expm1, abs=abs, minimum=min, maximum=max,
    clip=_clip, where=_where, sign=_sign, signed_square=lambda v: v * abs(v),
    all_finite=lambda values: all(map(math.isfinite, values)),
    finite_each=lambda values: all(map(math.isfinite, values)), any=bool, all=bool,
    zeros_like=lambda v: 0.0, copy=lambda v: v)
BATCH = SimpleNamespace(
    sin=np.sin, cos=np.cos, atan2=np.arctan2, hypot=np.hypot,
    sqrt=np.sqrt, exp=np.exp, expm1=np.expm1, abs=np.abs, minimum=np.minimum, maximum=np.maximum,
    clip=lambda v, low, high: np.minimum(np.maximum(v, low), high), where=np.where, sign=np.sign,
    signed_square=lambda v: v * np.abs(v),
    all_finite=_batch_all_finite,
    finite_each=lambda values: np.logical_and.reduce([np.isfinite(v) for v in values]),
    any=lambda condition: bool(np.any(condition)), all=lambda condition: bool(np.all(condition)),
    zeros_like=np.zeros_like, copy=np.copy)


def namespace_for(value, *more) -> SimpleNamespace:
    """SCALAR when every value is a plain number, BATCH when any is a numpy array (one element per vehicle)."""
    if isinstance(value, np.ndarray):
        return BATCH
    for other in more:       # a loop, not any(generator): this runs dozens of times per control step
        if isinstance(other, np.ndarray):
            return BATCH
    return SCALAR


def is_batch(value) -> bool:
    """Whether ``value`` holds a batch of vehicles (a numpy array) rather than one vehicle."""
    return isinstance(value, np.ndarray)


def select(condition, if_true, if_false):
    """``if_true`` where ``condition`` holds, else ``if_false``: a float for a plain bool, an array (elementwise)
    for a bool array. Also inside compiled kernels (numba), for the kernels that serve a vehicle and a batch."""
    return namespace_for(condition).where(condition, if_true, if_false)


@overload(select)
def _select_compiled(condition, if_true, if_false):
    if isinstance(condition, types.Array):
        return lambda condition, if_true, if_false: np.where(condition, if_true, if_false)
    return lambda condition, if_true, if_false: if_true if condition else if_false


def every(condition) -> bool:
    """Whether ``condition`` holds for every vehicle (a plain bool, or a bool array); also in compiled kernels."""
    return namespace_for(condition).all(condition)


@overload(every)
def _every_compiled(condition):
    if isinstance(condition, types.Array):
        return lambda condition: condition.all()
    return lambda condition: condition
