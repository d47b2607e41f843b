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

Every method takes S as a float (one vehicle) or as a numpy array (one element per vehicle).
"""
from __future__ import annotations

from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.vehicle_params import ParameterError, check_number

LABELS = ('NB', 'NM', 'ZE', 'PM', 'PB')
CENTRES = (-1.0, -0.5, 0.0, 0.5, 1.0)
RULES = {'NB': 'PB', 'NM': 'PM', 'ZE': 'ZE', 'PM': 'NM', 'PB': 'NB'}  #: Table 2
CONSEQUENTS = {'NB': -1.0, 'NM': -0.5, 'ZE': 0.0, 'PM': 0.5, 'PB': 1.0}
TYPE_REDUCERS = ('km', 'nie-tan')


class IT2FuzzyCorrector:
    """u_fuzzy = output_gain * IT2FLS(S / input_scale); see the module docstring for the design."""

    STATE = ()   #: stateless: a retune takes the new one whole

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
        steps = [b - a for a, b in zip(self.consequents, self.consequents[1:])]
        if not (all(step < 0.0 for step in steps) or all(step > 0.0 for step in steps)):
            raise ParameterError(f'rule consequents {self.consequents}: the closed-form KM reduction needs them '
                                 'strictly monotone in label order')
        self._decreasing = steps[0] < 0.0   # Table 2: PB, PM, ZE, NM, NB for NB..PB

    def segment(self, s):
        """Where S falls: (k, f_k_lo, f_k_up, f_k1_lo, f_k1_up, u) for labels k and k+1 of the segment.

        k is a whole number (as a float, or a float array for a batch). Every label other than k
        and k+1 has firing interval [0, 0].
        """
        xp = namespace_for(s)
        u = xp.clip(s * self._inverse_scale, -1.0, 1.0)
        position = (u + 1.0) * 2.0          # 0 .. 4, in units of label spacing
        k = xp.minimum(xp.floor(position), 3.0)
        frac = position - k                   # 0 at centre k, 1 at centre k + 1
        lower_k = self.lower_height * xp.maximum(0.0, 1.0 - frac * self._lower_slope)
        lower_k1 = self.lower_height * xp.maximum(0.0, 1.0 - (1.0 - frac) * self._lower_slope)
        return k, lower_k, 1.0 - frac, lower_k1, frac, u

    def firing_intervals(self, s: float) -> list[tuple[float, float]]:
        """(lower, upper) firing strength of every rule, in label order NB..PB (one vehicle)."""
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        k = int(k)
        intervals = [(0.0, 0.0)] * len(LABELS)
        intervals[k] = (lower_k, upper_k)
        intervals[k + 1] = (lower_k1, upper_k1)
        return intervals

    def type_reduced(self, s):
        """Exact KM type-reduced interval [y_l, y_r] of the normalised output for surface S.

        Of the two firing rules, a has the smaller consequent and b the larger one.
        """
        xp = namespace_for(s)
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        y_k, y_k1 = xp.take(self.consequents, k), xp.take(self.consequents, k + 1.0)
        if self._decreasing:
            y_a, lo_a, up_a, y_b, lo_b, up_b = y_k1, lower_k1, upper_k1, y_k, lower_k, upper_k
        else:
            y_a, lo_a, up_a, y_b, lo_b, up_b = y_k, lower_k, upper_k, y_k1, lower_k1, upper_k1
        y_left = (up_a * y_a + lo_b * y_b) / (up_a + lo_b)
        y_right = (lo_a * y_a + up_b * y_b) / (lo_a + up_b)
        return y_left, y_right

    def __call__(self, s):
        """Corrective control u_fuzzy for surface S (units of the subsystem's control)."""
        if self.type_reducer == 'km':
            y_left, y_right = self.type_reduced(s)
            return self.output_gain * 0.5 * (y_left + y_right)
        xp = namespace_for(s)
        k, lower_k, upper_k, lower_k1, upper_k1, _ = self.segment(s)
        w_k, w_k1 = lower_k + upper_k, lower_k1 + upper_k1
        return self.output_gain * (w_k * xp.take(self.consequents, k) + w_k1 * xp.take(self.consequents, k + 1.0)) \
            / (w_k + w_k1)


class SaturationCorrector:
    """The linear saturation the IT2 term is compared with (ablation ``nnit2fsmc-sat``):
    u = -output_gain * sat(S / input_scale), sat(u) = clip(u, -1, 1)."""

    STATE = ()

    def __init__(self, input_scale: float, output_gain: float):
        self.input_scale = check_number('input_scale', input_scale, 0.0, low_inclusive=False)
        self.output_gain = check_number('output_gain', output_gain, 0.0)

    def __call__(self, s):
        return -self.output_gain * namespace_for(s).clip(s / self.input_scale, -1.0, 1.0)
