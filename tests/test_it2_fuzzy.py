"""The IT2 fuzzy corrective term (paper III.A, Fig. 5, Table 2) against an independent reference, pyit2fls."""
import itertools
import math

import numpy as np
import pytest

pyit2fls = pytest.importorskip('pyit2fls')

from nnit2fsmc_controller.it2_fuzzy import CONSEQUENTS, RULES, IT2FuzzyCorrector  # noqa: E402
from quad_msgs_bridge.validation import ParameterError

SCALE = 0.7          # input_scale [units of S]: the universe of S is [-0.7, 0.7]
HEIGHT = 0.6         # lower membership height (the packaged default)
HALF_WIDTH = 0.35    # lower membership half-width in normalised units
FAR = 1e6            # the outer shoulders of NB and PB reach this far in S
# The reference's own labels and rule base, Table 2 as the paper prints it, never the implementation's
# RULES, so that an error in its rule table shows up against pyit2fls. The paper gives no numbers for
# the label positions: evenly spaced centres and output levels are this project's design (docs/PAPER.md).
LABELS = ('NB', 'NM', 'ZE', 'PM', 'PB')
CENTRES = (-1.0, -0.5, 0.0, 0.5, 1.0)            # of the input labels, in units of the universe
LEVELS = {'NB': -1.0, 'NM': -0.5, 'ZE': 0.0, 'PM': 0.5, 'PB': 1.0}     # crisp output levels
TABLE_2 = {'NB': 'PB', 'NM': 'PM', 'ZE': 'ZE', 'PM': 'NM', 'PB': 'NB'}   # surface -> U_fuzzy


def reference_memberships(s: float):
    """(lower, upper) membership of S in each label, built with pyit2fls' own MF functions in S units.

    Upper MFs: triangles between the neighbouring centres, shoulders (trapezoids) for NB and PB.
    Lower MFs: triangles of height HEIGHT and half-width HALF_WIDTH around the same centres, shoulders
    at the ends. Parameters follow pyit2fls' conventions: tri_mf [left, centre, right, height],
    trapezoid_mf [left, left top, right top, right, height].
    """
    x = np.array([s])
    c = [SCALE * v for v in CENTRES]
    spacing, half = SCALE * 0.5, SCALE * HALF_WIDTH
    upper = [pyit2fls.trapezoid_mf(x, [-FAR, -FAR, c[0], c[1], 1.0])]
    lower = [pyit2fls.trapezoid_mf(x, [-FAR, -FAR, c[0], c[0] + half, HEIGHT])]
    for centre in c[1:-1]:
        upper.append(pyit2fls.tri_mf(x, [centre - spacing, centre, centre + spacing, 1.0]))
        lower.append(pyit2fls.tri_mf(x, [centre - half, centre, centre + half, HEIGHT]))
    upper.append(pyit2fls.trapezoid_mf(x, [c[3], c[4], FAR, FAR, 1.0]))
    lower.append(pyit2fls.trapezoid_mf(x, [c[4] - half, c[4], FAR, FAR, HEIGHT]))
    return [(float(lo[0]), float(up[0])) for lo, up in zip(lower, upper)]


def reference_intervals(s: float) -> np.ndarray:
    """Rows [y, y, f_lower, f_upper] per rule of Table 2 (single antecedent: firing = membership)."""
    rows = [[LEVELS[TABLE_2[label]]] * 2 + list(firing)
            for label, firing in zip(LABELS, reference_memberships(s))]
    return np.array(rows, dtype=float)


def vertex_search(intervals: np.ndarray) -> tuple[float, float]:
    """Type reduction by brute force: the centroid bounds are attained at endpoint weight choices."""
    ys, lower, upper = intervals[:, 0], intervals[:, 2], intervals[:, 3]
    values = []
    for choice in itertools.product((0, 1), repeat=len(ys)):
        w = np.where(np.array(choice) == 1, upper, lower)
        if w.sum() > 0:
            values.append(float(np.dot(w, ys) / w.sum()))
    return min(values), max(values)


def special_inputs():
    """Centres, the feet of the lower MFs, the universe's edges and points beyond it."""
    points = [SCALE * v for v in CENTRES]
    points += [SCALE * (c + sign * HALF_WIDTH) for c in CENTRES for sign in (-1, 1)]
    points += [SCALE * v for v in (-3.0, -1.0001, 1.0001, 3.0, 100.0)]
    return points


INPUTS = sorted(set(special_inputs() + list(np.linspace(-1.6 * SCALE, 1.6 * SCALE, 401))))


@pytest.fixture(scope='module')
def corrector():
    return IT2FuzzyCorrector(SCALE, output_gain=1.0, lower_height=HEIGHT, lower_half_width=HALF_WIDTH)


def test_memberships_match_pyit2fls(corrector):
    for s in INPUTS:
        np.testing.assert_allclose(corrector.firing_intervals(s), reference_memberships(s), atol=1e-12,
                                   err_msg=f'S = {s}')


@pytest.mark.parametrize('algorithm', ['KM_algorithm', 'EIASC_algorithm'])
def test_type_reduction_matches_pyit2fls(corrector, algorithm):
    reduce = getattr(pyit2fls, algorithm)
    worst = 0.0
    for s in INPUTS:
        y_l, y_r = reduce(reference_intervals(s))
        ours = corrector.type_reduced(s)
        worst = max(worst, abs(ours[0] - y_l), abs(ours[1] - y_r))
    assert worst < 1e-9


def test_type_reduction_matches_vertex_search(corrector):
    for s in INPUTS:
        np.testing.assert_allclose(corrector.type_reduced(s), vertex_search(reference_intervals(s)), atol=1e-12,
                                   err_msg=f'S = {s}')


def test_nie_tan_matches_pyit2fls_and_lies_in_the_km_interval(corrector):
    nie_tan = IT2FuzzyCorrector(SCALE, output_gain=1.0, lower_height=HEIGHT, lower_half_width=HALF_WIDTH,
                                type_reducer='nie-tan')
    for s in INPUTS:
        expected = pyit2fls.NT_algorithm(reference_intervals(s))
        assert nie_tan(s) == pytest.approx(expected, abs=1e-9)
        y_l, y_r = corrector.type_reduced(s)
        assert y_l - 1e-12 <= nie_tan(s) <= y_r + 1e-12


def test_output_is_the_centre_of_the_type_reduced_interval_times_the_gain():
    gain = 2.5
    scaled = IT2FuzzyCorrector(SCALE, output_gain=gain, lower_height=HEIGHT, lower_half_width=HALF_WIDTH)
    for s in INPUTS:
        y_l, y_r = scaled.type_reduced(s)
        assert y_l <= y_r + 1e-15
        assert scaled(s) == pytest.approx(gain * 0.5 * (y_l + y_r), abs=1e-15)


def test_rule_table_is_table_2():
    """The implementation's rule base is Table 2 as printed, with the output levels of the labels."""
    assert RULES == TABLE_2
    assert CONSEQUENTS == LEVELS
    corrector = IT2FuzzyCorrector(SCALE, output_gain=1.0)
    for label, centre in zip(LABELS, CENTRES):     # at a label's centre only its rule fires
        assert corrector(SCALE * centre) == pytest.approx(LEVELS[TABLE_2[label]], abs=1e-15), label


@pytest.mark.parametrize('reducer', ['km', 'nie-tan'])
@pytest.mark.parametrize('height, half_width', [(0.6, 0.35), (0.2, 0.1), (1.0, 0.49)])
def test_output_is_odd_monotone_and_saturates(reducer, height, half_width):
    fuzzy = IT2FuzzyCorrector(SCALE, output_gain=3.0, lower_height=height, lower_half_width=half_width,
                              type_reducer=reducer)
    grid = np.linspace(-2.0 * SCALE, 2.0 * SCALE, 2001)
    values = np.array([fuzzy(float(s)) for s in grid])
    np.testing.assert_allclose(values, -values[::-1], atol=1e-14)           # odd: u(-S) = -u(S)
    assert fuzzy(0.0) == 0.0
    assert np.all(np.diff(values) <= 1e-14)                                 # non-increasing in S
    np.testing.assert_allclose(values[grid >= SCALE], -3.0, rtol=0, atol=1e-12)    # saturated beyond
    np.testing.assert_allclose(values[grid <= -SCALE], 3.0, rtol=0, atol=1e-12)    # the universe
    # and it really moves inside the universe: the corrective term opposes the surface
    assert fuzzy(0.5 * SCALE) < -0.5 and fuzzy(-0.5 * SCALE) > 0.5


def test_zero_gain_gives_no_correction():
    assert IT2FuzzyCorrector(SCALE, output_gain=0.0)(0.3) == 0.0


@pytest.mark.parametrize('kwargs, name', [
    (dict(input_scale=0.0), 'input_scale'),
    (dict(input_scale=-1.0), 'input_scale'),
    (dict(input_scale=math.nan), 'input_scale'),
    (dict(output_gain=-1.0), 'output_gain'),
    (dict(output_gain=math.inf), 'output_gain'),
    (dict(lower_height=0.0), 'lower_height'),
    (dict(lower_height=1.2), 'lower_height'),
    (dict(lower_half_width=0.0), 'lower_half_width'),
    (dict(lower_half_width=0.6), 'lower_half_width'),
    (dict(type_reducer='centroid'), 'type_reducer'),
])
def test_invalid_parameters_are_named(kwargs, name):
    arguments = dict(input_scale=1.0, output_gain=1.0) | kwargs
    with pytest.raises(ParameterError, match=name):
        IT2FuzzyCorrector(**arguments)


@pytest.mark.parametrize('reducer', ['km', 'nie-tan'])
def test_a_nan_surface_gives_nan_for_that_vehicle_only(reducer):
    """The compiled kernel indexes the rule table by the segment: a NaN surface must not read outside it."""
    fuzzy = IT2FuzzyCorrector(SCALE, output_gain=2.0, type_reducer=reducer)
    assert math.isnan(fuzzy(math.nan))
    values = fuzzy(np.array([0.1, math.nan, -0.1]))
    assert math.isnan(values[1]) and values[0] == fuzzy(0.1) and values[2] == fuzzy(-0.1)
