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
"""
from __future__ import annotations

from quad_msgs_bridge.vehicle_params import ParameterError, check_number

LABELS = ('NB', 'NM', 'ZE', 'PM', 'PB')
CENTRES = (-1.0, -0.5, 0.0, 0.5, 1.0)
RULES = {'NB': 'PB', 'NM': 'PM', 'ZE': 'ZE', 'PM': 'NM', 'PB': 'NB'}  #: Table 2
CONSEQUENTS = {'NB': -1.0, 'NM': -0.5, 'ZE': 0.0, 'PM': 0.5, 'PB': 1.0}
TYPE_REDUCERS = ('km', 'nie-tan')


class IT2FuzzyCorrector:
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
        self._inverse_scale = 1.0 / self.input_scale
        self._lower_slope = 0.5 / self.lower_half_width
        #: rule consequent of each antecedent label, in label order
        self.consequents = tuple(CONSEQUENTS[RULES[label]] for label in LABELS)

    def segment(self, s: float) -> tuple[int, float, float, float, float, float]:
        """Where S falls: (k, f_k_lo, f_k_up, f_k1_lo, f_k1_up, u) for labels k and k+1 of the segment.

        Every label other than k and k+1 has firing interval [0, 0].
        """
        u = s * self._inverse_scale
        if u <= -1.0:
            u = -1.0
        elif u >= 1.0:
            u = 1.0
        position = (u + 1.0) * 2.0          # 0 .. 4, in units of label spacing
        k = int(position)
        if k > 3:
            k = 3
        frac = position - k                   # 0 at centre k, 1 at centre k + 1
        lower_k = self.lower_height * max(0.0, 1.0 - frac * self._lower_slope)
        lower_k1 = self.lower_height * max(0.0, 1.0 - (1.0 - frac) * self._lower_slope)
        return k, lower_k, 1.0 - frac, lower_k1, frac, u

    def firing_intervals(self, s: float) -> list[tuple[float, float]]:
        """(lower, upper) firing strength of every rule, in label order NB..PB."""
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        intervals = [(0.0, 0.0)] * len(LABELS)
        intervals[k] = (lower_k, upper_k)
        intervals[k + 1] = (lower_k1, upper_k1)
        return intervals

    def type_reduced(self, s: float) -> tuple[float, float]:
        """Exact KM type-reduced interval [y_l, y_r] of the normalised output for surface S."""
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        y_k, y_k1 = self.consequents[k], self.consequents[k + 1]
        if y_k <= y_k1:
            y_a, lo_a, up_a, y_b, lo_b, up_b = y_k, lower_k, upper_k, y_k1, lower_k1, upper_k1
        else:
            y_a, lo_a, up_a, y_b, lo_b, up_b = y_k1, lower_k1, upper_k1, y_k, lower_k, upper_k
        y_left = (up_a * y_a + lo_b * y_b) / (up_a + lo_b)
        y_right = (lo_a * y_a + up_b * y_b) / (lo_a + up_b)
        return y_left, y_right

    def __call__(self, s: float) -> float:
        """Corrective control u_fuzzy for surface S (units of the subsystem's control)."""
        if self.type_reducer == 'km':
            y_left, y_right = self.type_reduced(s)
            return self.output_gain * 0.5 * (y_left + y_right)
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        w_k, w_k1 = lower_k + upper_k, lower_k1 + upper_k1
        return self.output_gain * (w_k * self.consequents[k] + w_k1 * self.consequents[k + 1]) / (w_k + w_k1)
