"""One set of elementwise math for a single vehicle (plain floats) and a batch (numpy arrays).

Equations are written once against a namespace ``xp`` with ``sin``, ``cos``, ``clip``, ``where``
and ``signed_square``; :func:`namespace_for` picks the fast plain-float one for a single vehicle
and the numpy one when the values are arrays of many vehicles.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _where(condition: bool, if_true: float, if_false: float) -> float:
    return if_true if condition else if_false


SCALAR = SimpleNamespace(sin=math.sin, cos=math.cos, clip=_clip, where=_where,
                         signed_square=lambda v: v * abs(v))
BATCH = SimpleNamespace(sin=np.sin, cos=np.cos, clip=np.clip, where=np.where,
                        signed_square=lambda v: v * np.abs(v))


def namespace_for(value) -> SimpleNamespace:
    """SCALAR for a plain number, BATCH for a numpy array (one element per vehicle)."""
    return BATCH if isinstance(value, np.ndarray) else SCALAR
