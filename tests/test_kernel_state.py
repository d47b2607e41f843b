"""A single vehicle's NNIT2FSMC law keeps its state in one store (kernel_state) that its compiled update
(nnit2fsmc_law_step) reads and writes: the same numbers as the batch path, and the same attributes."""
import numpy as np
import pytest

from nnit2fsmc_controller.factory import load_gains, nnit2fsmc_law
from nnit2fsmc_controller.kernel_state import BOOL, OPTIONAL, TUPLE, Slot
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, _ = load_vehicle_file()


class Part:
    flag = Slot(0, OPTIONAL)
    held = Slot(2, BOOL)
    values = Slot(3, TUPLE, length=lambda part: 2)

    def __init__(self, store):
        self.store = store


def test_a_slot_reads_and_writes_its_place_in_the_store_or_a_plain_attribute_without_one():
    stored, plain = Part(np.zeros(5)), Part(None)
    for part in (stored, plain):
        assert (setattr(part, 'flag', None), part.flag) == (None, None)
        part.flag, part.held, part.values = 0.0, True, (1.5, -2.0)
        assert (part.flag, part.held, part.values) == (0.0, True, (1.5, -2.0))
    assert stored.store.tolist() == [1.0, 0.0, 1.0, 1.5, -2.0]


@pytest.mark.parametrize('kind', ['nnit2fsmc', 'nnit2fsmc-bias', 'nnit2fsmc-sat'])
@pytest.mark.parametrize('axis', ['x', 'z', 'phi'])
def test_a_single_vehicle_law_on_its_store_equals_a_batch_of_one(kind, axis):
    gains = load_gains()
    single = nnit2fsmc_law(kind, gains, axis, 2.0, 0.001, None, PARAMS)
    batch = nnit2fsmc_law(kind, gains, axis, 2.0, 0.001, 1, PARAMS)
    network = single.network
    assert all(np.shares_memory(view, single.store) for view in (
        network.hidden_weights, network.output_weights, network._hidden))
    rng = np.random.default_rng(3)
    for k in range(200):
        e, de, ref_vel, ref_acc = rng.normal(0.0, 0.3, 4)
        learning = k % 7 != 0
        single.learning, batch.learning = learning, np.array([learning])
        a = single.update(e, de, ref_vel, ref_acc, 0.0, 1.0)
        b = batch.update(np.array([e]), np.array([de]), ref_vel, ref_acc, 0.0, 1.0)
        assert tuple(a) == tuple(float(v[0]) for v in b)
        if k % 5 == 0:
            single.adapt(), batch.adapt()
    assert single._teaching == float(batch._teaching[0])
    assert network._output == float(batch.network._output[0])
    assert network._inputs == tuple(batch.network._inputs[0])
    assert np.array_equal(network.hidden_weights, batch.network.hidden_weights[0])
    assert np.array_equal(network.output_weights, batch.network.output_weights[0])
    assert single.learning is True and network.output_weights.any()
