"""Interval type-2 fuzzy corrective term of the NNIT2FSMC (paper section III.A, Fig. 5, Table 2).

Single input, the sliding surface S, normalised to u = S / input_scale and clipped to [-1, 1].
Five labels NB NM ZE PM PB centred at -1, -0.5, 0, 0.5, 1.

* Upper membership functions: triangles (trapezoidal shoulders for NB and PB) of height 1 whose
  feet sit on the neighbouring centres, so the upper functions form a partition of unity.
* Lower membership functions: narrower triangles/shoulders of height ``lower_height`` with
  half-width ``lower_half_width`` (< 0.5) around the same centres; the footprint of uncertainty is
  the band between the two.

Rules (Table 2): NB -> PB, NM -> PM, ZE -> ZE, PM -> NM, PB -> NB, with crisp consequents
PB = +1, PM = +0.5, ZE = 0, NM = -0.5, NB = -1 (times ``output_gain``), so the output is odd in S.

Because neighbouring upper functions meet at the centres, at most two adjacent rules fire for
any input. The Karnik-Mendel type reduction then has an exact closed form: with firing intervals
[f_a_lo, f_a_up], [f_b_lo, f_b_up] and consequents y_a < y_b,

    y_l = (f_a_up y_a + f_b_lo y_b) / (f_a_up + f_b_lo),
    y_r = (f_a_lo y_a + f_b_up y_b) / (f_a_lo + f_b_up),

the switch points KM iterates to, and the defuzzified output is (y_l + y_r) / 2.
The Nie-Tan reducer, y = sum((f_lo + f_up) y) / sum(f_lo + f_up), is available as an option.

Every method takes S as a float (one vehicle) or as a numpy array (one element per vehicle). The
arithmetic is written once, for one value of S, in compiled kernels (numba; :func:`corrective_term`
is what a control step calls); an array runs them element by element.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from quad_msgs_bridge.numeric import is_batch
from quad_msgs_bridge.validation import ParameterError, check_number

LABELS = ('NB', 'NM', 'ZE', 'PM', 'PB')
CENTRES = (-1.0, -0.5, 0.0, 0.5, 1.0)
RULES = {'NB': 'PB', 'NM': 'PM', 'ZE': 'ZE', 'PM': 'NM', 'PB': 'NB'}  #: Table 2
CONSEQUENTS = {'NB': -1.0, 'NM': -0.5, 'ZE': 0.0, 'PM': 0.5, 'PB': 1.0}
TYPE_REDUCERS = ('km', 'nie-tan')

#: the kinds of corrective term a kernel evaluates, the first entry of ``kernel_parameters``
KM, NIE_TAN, SATURATION = 0.0, 1.0, 2.0
#: positions in ``kernel_parameters``: kind, input_scale, 1 / input_scale, lower_height, 0.5 / lower_half_width,
#: output_gain, 1.0 if the consequents decrease in label order, then the five consequents in label order
_KIND, _SCALE, _INVERSE_SCALE, _LOWER_HEIGHT, _LOWER_SLOPE, _GAIN, _DECREASING, _FIRST_CONSEQUENT = range(8)


@njit(cache=True, inline='always')
def input_scale_of(parameters):
    """The input scale [units of S] of a corrector's ``kernel_parameters``: |S| beyond it saturates the term."""
    return parameters[_SCALE]


@njit(cache=True, inline='always')
def segment_of(inverse_scale, lower_height, lower_slope, s):
    """(k, f_k_lo, f_k_up, f_k1_lo, f_k1_up, u) for surface S: labels k and k+1 fire (module docstring)."""
    u = s * inverse_scale
    u = -1.0 if u < -1.0 else 1.0 if u > 1.0 else u
    position = (u + 1.0) * 2.0          # 0 .. 4, in units of label spacing
    k = min(float(math.floor(position)), 3.0) if position == position else position   # NaN stays NaN
    frac = position - k                   # 0 at centre k, 1 at centre k + 1
    lower_k = lower_height * max(0.0, 1.0 - frac * lower_slope)
    lower_k1 = lower_height * max(0.0, 1.0 - (1.0 - frac) * lower_slope)
    return k, lower_k, 1.0 - frac, lower_k1, frac, u


@njit(cache=True, inline='always')
def _fired_consequents(parameters, k):
    """The consequents of labels k and k + 1 (NaN for a NaN k)."""
    if not 0.0 <= k <= 3.0:
        return math.nan, math.nan
    index = _FIRST_CONSEQUENT + int(k)
    return parameters[index], parameters[index + 1]


@njit(cache=True, inline='always')
def type_reduced_interval(parameters, s):
    """Exact KM type-reduced interval [y_l, y_r] of the normalised output for surface S.

    Of the two firing rules, a has the smaller consequent and b the larger one."""
    k, lower_k, upper_k, lower_k1, upper_k1, _ = segment_of(
        parameters[_INVERSE_SCALE], parameters[_LOWER_HEIGHT], parameters[_LOWER_SLOPE], s)
    y_k, y_k1 = _fired_consequents(parameters, k)
    if parameters[_DECREASING] == 1.0:
        y_a, lo_a, up_a, y_b, lo_b, up_b = y_k1, lower_k1, upper_k1, y_k, lower_k, upper_k
    else:
        y_a, lo_a, up_a, y_b, lo_b, up_b = y_k, lower_k, upper_k, y_k1, lower_k1, upper_k1
    y_left = (up_a * y_a + lo_b * y_b) / (up_a + lo_b)
    y_right = (lo_a * y_a + up_b * y_b) / (lo_a + up_b)
    return y_left, y_right


@njit(cache=True, inline='always')
def corrective_term(parameters, s):
    """The corrective control for surface S [units of the subsystem's control], of the kind
    ``parameters[0]``: KM (IT2, KM type reduction), NIE_TAN (IT2, Nie-Tan) or SATURATION."""
    kind, gain = parameters[_KIND], parameters[_GAIN]
    if kind == SATURATION:
        u = s / parameters[_SCALE]
        return -gain * (-1.0 if u < -1.0 else 1.0 if u > 1.0 else u)
    if kind == KM:
        y_left, y_right = type_reduced_interval(parameters, s)
        return gain * 0.5 * (y_left + y_right)
    k, lower_k, upper_k, lower_k1, upper_k1, _ = segment_of(
        parameters[_INVERSE_SCALE], parameters[_LOWER_HEIGHT], parameters[_LOWER_SLOPE], s)
    y_k, y_k1 = _fired_consequents(parameters, k)
    w_k, w_k1 = lower_k + upper_k, lower_k1 + upper_k1
    return gain * (w_k * y_k + w_k1 * y_k1) / (w_k + w_k1)


@njit(cache=True)
def _corrective_batch(parameters, surfaces):
    out = np.empty(surfaces.shape[0])
    for b in range(surfaces.shape[0]):
        out[b] = corrective_term(parameters, surfaces[b])
    return out


def _each(kernel, s, *arguments):
    """``kernel(*arguments, S)`` (a tuple) for S a float; for an array of S, the tuple of the arrays of its
    elements' results (outside a control step: diagnostics and tests)."""
    if not is_batch(s):
        return kernel(*arguments, float(s))
    return tuple(np.array(column) for column in zip(*(kernel(*arguments, float(v)) for v in s)))


class _Corrector:
    """A corrective term evaluated by :func:`corrective_term` with its ``kernel_parameters``."""

    STATE = ()   #: stateless: a retune takes the new one whole

    def __call__(self, s):
        """Corrective control u for surface S (units of the subsystem's control)."""
        if is_batch(s):
            return _corrective_batch(self.kernel_parameters, np.asarray(s, dtype=float))
        return corrective_term(self.kernel_parameters, float(s))


class IT2FuzzyCorrector(_Corrector):
    """u_fuzzy = output_gain * IT2FLS(S / input_scale); see the module docstring for the design."""

    def __init__(self, input_scale: float, output_gain: float, lower_height: float = 0.6,
                 lower_half_width: float = 0.35, type_reducer: str = 'km'):
        self.input_scale = check_number('input_scale', input_scale, 0.0, low_inclusive=False)
        self.output_gain = check_number('output_gain', output_gain, 0.0)
        self.lower_height = check_number('lower_height', lower_height, 0.0, 1.0, low_inclusive=False)
        self.lower_half_width = check_number('lower_half_width', lower_half_width, 0.0, 0.5,
                                             low_inclusive=False)
        if type_reducer not in TYPE_REDUCERS:
            raise ParameterError(f'type_reducer: {type_reducer!r} is not one of {", ".join(TYPE_REDUCERS)}')
        self.type_reducer = type_reducer
        #: rule consequent of each antecedent label, in label order
        self.consequents = tuple(CONSEQUENTS[RULES[label]] for label in LABELS)
        steps = [b - a for a, b in zip(self.consequents, self.consequents[1:])]
        if not (all(step < 0.0 for step in steps) or all(step > 0.0 for step in steps)):
            raise ParameterError(f'rule consequents {self.consequents}: the closed-form KM reduction needs them '
                                 'strictly monotone in label order')
        self.kernel_parameters = (KM if type_reducer == 'km' else NIE_TAN, self.input_scale, 1.0 / self.input_scale,
                                  self.lower_height, 0.5 / self.lower_half_width, self.output_gain,
                                  1.0 if steps[0] < 0.0 else 0.0, *self.consequents)   # Table 2: decreasing

    def segment(self, s):
        """Where S falls: (k, f_k_lo, f_k_up, f_k1_lo, f_k1_up, u) for labels k and k+1 of the segment.

        k is a whole number (as a float, or a float array for a batch). Every label other than k
        and k+1 has firing interval [0, 0].
        """
        p = self.kernel_parameters
        return _each(segment_of, s, p[_INVERSE_SCALE], p[_LOWER_HEIGHT], p[_LOWER_SLOPE])

    def firing_intervals(self, s: float) -> list[tuple[float, float]]:
        """(lower, upper) firing strength of every rule, in label order NB..PB (one vehicle)."""
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        k = int(k)
        intervals = [(0.0, 0.0)] * len(LABELS)
        intervals[k] = (lower_k, upper_k)
        intervals[k + 1] = (lower_k1, upper_k1)
        return intervals

    def type_reduced(self, s):
        """Exact KM type-reduced interval [y_l, y_r] of the normalised output for surface S."""
        return _each(type_reduced_interval, s, self.kernel_parameters)


class SaturationCorrector(_Corrector):
    """The linear saturation the IT2 term is compared with (ablation ``nnit2fsmc-sat``):
    u = -output_gain * sat(S / input_scale), sat(u) = clip(u, -1, 1)."""

    def __init__(self, input_scale: float, output_gain: float):
        self.input_scale = check_number('input_scale', input_scale, 0.0, low_inclusive=False)
        self.output_gain = check_number('output_gain', output_gain, 0.0)
        self.kernel_parameters = (SATURATION, self.input_scale, 0.0, 0.0, 0.0, self.output_gain, 0.0, 0.0, 0.0, 0.0,
                                  0.0, 0.0)
