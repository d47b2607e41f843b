"""numeric.BATCH.all_finite: one isfinite over a batch's joined values, the same answer as value by value."""
import math

import numpy as np
import pytest

from quad_msgs_bridge.numeric import BATCH, SCALAR


@pytest.mark.parametrize('values, expected', [
    ([np.zeros(4), 1.0, np.float64(2.0), 3], True),
    ([np.zeros(4), np.array([0.0, np.inf, 0.0, 0.0])], False),
    ([np.zeros(4), math.nan], False),
    ([np.array([1.0, -np.inf])], False),
    ([np.full(3, np.nan), 1.0], False),
    ([np.array(2.0), [1.0, 2.0], np.ones((2, 2))], True),     # 0-d, a list, a 2-d array
    ([np.array([1, 2]), np.array([True, False]), np.zeros(2)], True),
    ([], True),
])
def test_a_batch_is_finite_exactly_when_every_value_is(values, expected):
    assert BATCH.all_finite(values) is expected
    assert expected == all(bool(np.isfinite(v).all()) for v in values)


@pytest.mark.parametrize('values', [['a', np.zeros(2)], [np.zeros(2), 'a'], [np.zeros(2), None],
                                    [np.zeros(2), np.array(['x'])]])
def test_a_value_that_is_not_a_number_raises_type_error(values):
    with pytest.raises(TypeError):
        BATCH.all_finite(values)


def test_the_scalar_namespace_agrees_on_floats():
    assert SCALAR.all_finite([1.0, 2.0]) and not SCALAR.all_finite([1.0, math.inf])
