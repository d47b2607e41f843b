"""One set of elementwise math for a single vehicle (plain floats) and a batch (numpy arrays).

Equations are written once against a namespace ``xp`` with ``sin``, ``cos``, ``exp``, ``expm1``,
``sqrt``, ``abs``, ``clip``, ``where``, ``signed_square``, ``zeros_like`` and ``copy``;
:func:`namespace_for` picks the fast plain-float one for a single vehicle and the numpy one when
the values are arrays of many vehicles.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _where(condition: bool, if_true: float, if_false: float) -> float:
    return if_true if condition else if_false


SCALAR = SimpleNamespace(sin=math.sin, cos=math.cos, exp=math.exp, expm1=math.expm1, sqrt=math.sqrt,
                         abs=abs, clip=_clip, where=_where, signed_square=lambda v: v * abs(v),
                         zeros_like=lambda v: 0.0, copy=lambda v: v)
BATCH = SimpleNamespace(sin=np.sin, cos=np.cos, exp=np.exp, expm1=np.expm1, sqrt=np.sqrt,
                        abs=np.abs, clip=np.clip, where=np.where, signed_square=lambda v: v * np.abs(v),
                        zeros_like=np.zeros_like, copy=np.copy)


def namespace_for(value, *more) -> SimpleNamespace:
    """SCALAR when every value is a plain number, BATCH when any is a numpy array (one element per vehicle)."""
    if isinstance(value, np.ndarray) or (more and any(isinstance(v, np.ndarray) for v in more)):
        return BATCH
    return SCALAR
