"""A single vehicle's NNIT2FSMC law and controller keep their state in one store (kernel_state) that their
compiled updates (nnit2fsmc_law_step, cascade_step) read and write: the same numbers as the batch path, and the
same attributes."""
import numpy as np
import pytest

from nnit2fsmc_controller.axis_laws import NNIT2FSMCLaw
from nnit2fsmc_controller.factory import (PAPER_FAITHFUL, build_controller, flatten_gains, load_gains, nnit2fsmc_law,
                                          unflatten_gains)
from nnit2fsmc_controller.it2_fuzzy import IT2FuzzyCorrector
from nnit2fsmc_controller.kernel_state import BOOL, OPTIONAL, TUPLE, Slot
from nnit2fsmc_controller.neural_network import EquivalentControlNetwork
from nnit2fsmc_controller.tuning import retune
from quad_msgs_bridge.reference import SetpointPath, hold
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


def _variant(name):
    gains = load_gains()
    if name == 'paper-faithful':   # the filter's attitude rates, clipping allocation, no take-off hold
        gains = unflatten_gains({**flatten_gains(gains), **PAPER_FAITHFUL})
    return gains


@pytest.mark.parametrize('kind, variant', [('nnit2fsmc', 'packaged'), ('nnit2fsmc', 'paper-faithful'),
                                           ('nnit2fsmc-bias', 'packaged'), ('nnit2fsmc-type1', 'paper-faithful')])
def test_the_compiled_single_vehicle_update_equals_a_batch_of_one(kind, variant):
    """cascade_step (one compiled call on the controller's store) against the update written for arrays: the same
    forces, controls, subsystem outputs and attitude reference, to the bit, through take-off, learning and adapt."""
    gains = _variant(variant)
    single, batch = build_controller(kind, PARAMS, gains), build_controller(kind, PARAMS, gains, batch=1)
    assert single.store is not None and all(law.store.base is single.store for law in single.laws.values())
    rng = np.random.default_rng(7)
    path = SetpointPath([0.0, 1.0], [hold((0.0, 0.0, 1.0)), hold((0.5, -0.3, 1.4), yaw=0.4)])
    for k in range(400):
        t = k * single.dt
        state = [0.1 * rng.normal(), 0.1 * rng.normal(), max(0.0, 0.002 * k + 0.01 * rng.normal()),
                 *rng.normal(0.0, 0.2, 3), *rng.normal(0.0, 0.05, 3), *rng.normal(0.0, 0.3, 3)]
        reference = path.sample(t)
        a = single.update(t, state, reference)
        b = batch.update(t, [np.array([v]) for v in state], reference)
        assert a.forces == tuple(float(f[0]) for f in b.forces)
        assert a.controls == tuple(float(u[0]) for u in b.controls)
        assert a.attitude_reference == tuple(float(np.asarray(v).ravel()[0]) for v in b.attitude_reference)
        for axis in a.axes:
            assert tuple(a.axes[axis]) == tuple(float(np.asarray(v).ravel()[0]) for v in b.axes[axis])
        if k % 3 == 0:
            single.adapt(), batch.adapt()
    retuned = retune(single, gains)   # the state carried into a fresh store
    assert retuned.update(0.4, state, reference).forces == single.update(0.4, state, reference).forces


def test_a_law_refuses_a_network_whose_inputs_its_kernel_does_not_fill():
    """The kernel writes Z = (ref_vel, ref_acc, 1), or (1,) with bias_only, into the network's inputs."""
    fuzzy = IT2FuzzyCorrector(input_scale=1.0, output_gain=1.0)
    with pytest.raises(ValueError, match='network of 2 inputs'):
        NNIT2FSMCLaw(1.0, fuzzy, EquivalentControlNetwork(2, 4, output_gain=1.0, learning_rate=0.1))
    with pytest.raises(ValueError, match='network of 3 inputs'):
        NNIT2FSMCLaw(1.0, fuzzy, EquivalentControlNetwork(3, 4, output_gain=1.0, learning_rate=0.1), bias_only=True)
