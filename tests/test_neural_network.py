"""The equivalent-control network, paper eqs. (4)-(9): activation, gradients, projection, learning."""
import copy
import math

import numpy as np
import pytest

from nnit2fsmc_controller.it2_fuzzy import IT2FuzzyCorrector
from nnit2fsmc_controller.neural_network import EquivalentControlNetwork, bipolar_sigmoid


@pytest.mark.parametrize('x', [-40.0, -3.0, -0.5, 0.0, 1e-8, 0.7, 5.0, 40.0])
def test_activation_is_eq4(x):
    assert bipolar_sigmoid(x) == pytest.approx(2.0 / (1.0 + math.exp(-x)) - 1.0, abs=1e-15)
    # g' = (1 - g^2) / 2, the factor behind the 1/2 and 1/4 of eqs. (8) and (9)
    h = 1e-5
    slope = (bipolar_sigmoid(x + h) - bipolar_sigmoid(x - h)) / (2 * h)
    assert slope == pytest.approx(0.5 * (1.0 - bipolar_sigmoid(x) ** 2), abs=1e-10)


def random_network(seed, n_inputs=3, n_hidden=5):
    rng = np.random.default_rng(seed)
    network = EquivalentControlNetwork(n_inputs, n_hidden, output_gain=float(rng.uniform(0.5, 10.0)),
                                       learning_rate=0.01, weight_limit=10.0, seed=seed)
    # non-zero output weights: with the default zero start the hidden-layer gradient would vanish trivially
    network.output_weights = rng.uniform(-2.0, 2.0, n_hidden)
    inputs = tuple(float(z) for z in rng.uniform(-2.0, 2.0, n_inputs))
    return network, inputs, float(rng.uniform(-3.0, 3.0))


def error_function(network, inputs, target):
    """E = 1/2 (U_eq - U_eq_hat)^2, eq. (5), with the unknown U_eq fixed at ``target``."""
    return 0.5 * (target - network.forward(inputs)) ** 2


@pytest.mark.parametrize('seed', range(6))
def test_gradients_of_eqs_8_and_9_match_finite_differences(seed):
    network, inputs, u_fuzzy = random_network(seed)
    # The fuzzy term measures the error: target = U_eq_hat + u_fuzzy at the current weights.
    target = network.forward(inputs) + u_fuzzy
    grad_output, grad_hidden = network.gradients(u_fuzzy)
    h = 1e-6

    def central(read, write):
        saved = read()
        write(saved + h)
        plus = error_function(network, inputs, target)
        write(saved - h)
        minus = error_function(network, inputs, target)
        write(saved)
        return (plus - minus) / (2 * h)

    scale = max(1.0, abs(u_fuzzy) * network.output_gain)
    for j in range(len(network.output_weights)):
        numeric = central(lambda: network.output_weights[j],
                          lambda v: network.output_weights.__setitem__(j, v))
        assert grad_output[j] == pytest.approx(numeric, abs=1e-7 * scale), f'dE/dWy[{j}]'
        for i in range(len(inputs)):
            numeric = central(lambda: network.hidden_weights[j][i],
                              lambda v: network.hidden_weights[j].__setitem__(i, v))
            assert grad_hidden[j][i] == pytest.approx(numeric, abs=1e-7 * scale), f'dE/dWz[{j}][{i}]'
    network.forward(inputs)   # the gradients refer to the last forward pass; restore it


def test_learn_is_one_gradient_step_eqs_6_and_7():
    network, inputs, u_fuzzy = random_network(42)
    network.forward(inputs)
    grad_output, grad_hidden = network.gradients(u_fuzzy)
    before = copy.deepcopy((network.output_weights, network.hidden_weights))
    network.learn(u_fuzzy)
    alpha = network.learning_rate
    np.testing.assert_allclose(network.output_weights, np.array(before[0]) - alpha * np.array(grad_output),
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(network.hidden_weights, np.array(before[1]) - alpha * np.array(grad_hidden),
                               rtol=0, atol=1e-15)


def test_a_step_reduces_the_error_it_was_told_about():
    network, inputs, u_fuzzy = random_network(5)
    target = network.forward(inputs) + u_fuzzy
    before = error_function(network, inputs, target)
    network.forward(inputs)
    network.learn(u_fuzzy)
    assert error_function(network, inputs, target) < before


def test_zero_learning_rate_freezes_the_weights():
    network = EquivalentControlNetwork(3, 4, output_gain=1.0, learning_rate=0.0)
    before = copy.deepcopy((network.output_weights, network.hidden_weights))
    network.forward((0.3, -0.2, 1.0))
    network.learn(5.0)
    assert np.array_equal(network.output_weights, before[0]) and np.array_equal(network.hidden_weights, before[1])


def test_projection_keeps_weights_bounded_under_adversarial_fuzzy_terms():
    limit = 2.0
    network = EquivalentControlNetwork(3, 5, output_gain=4.0, learning_rate=50.0, weight_limit=limit, seed=3)
    rng = np.random.default_rng(0)
    for k in range(3000):
        inputs = tuple(float(z) for z in rng.normal(0.0, 100.0, 3))
        output = network.forward(inputs)
        assert math.isfinite(output) and abs(output) <= 4.0
        network.learn((1e6 if k % 3 else -1e9) * rng.choice([-1.0, 1.0]))
        weights = np.array([*network.output_weights, *np.ravel(network.hidden_weights)])
        assert np.all(np.isfinite(weights))
        assert np.all(np.abs(weights) <= limit)
    assert np.abs(weights).max() == limit     # the adversary did push weights to the bound


def test_network_starts_at_zero_and_is_seeded():
    a = EquivalentControlNetwork(3, 5, output_gain=2.0, learning_rate=0.1, seed=7)
    b = EquivalentControlNetwork(3, 5, output_gain=2.0, learning_rate=0.1, seed=7)
    c = EquivalentControlNetwork(3, 5, output_gain=2.0, learning_rate=0.1, seed=8)
    assert a.forward((1.0, 2.0, 1.0)) == 0.0          # zero output weights: knows nothing yet
    assert np.array_equal(a.hidden_weights, b.hidden_weights) and not np.array_equal(a.hidden_weights, c.hidden_weights)


@pytest.mark.parametrize('measure', ['ideal', 'it2-fuzzy'])
def test_learning_removes_a_constant_offset(measure):
    """An unknown constant equivalent control (e.g. the hover thrust) is learned from the corrective term."""
    true_equivalent = 0.7
    network = EquivalentControlNetwork(3, 5, output_gain=1.5, learning_rate=0.05, seed=1)
    fuzzy = IT2FuzzyCorrector(input_scale=1.0, output_gain=0.5)
    inputs = (0.0, 0.0, 1.0)   # at rest: reference velocity and acceleration zero, bias input one
    errors = []
    for _ in range(4000):
        error = true_equivalent - network.forward(inputs)
        # the corrective term is what the SMC needs on top of the estimate; the IT2 FLS gives it from
        # the surface, which here we take as minus the error (S > 0 when the estimate is too low)
        u_fuzzy = error if measure == 'ideal' else fuzzy(-error)
        network.learn(u_fuzzy)
        errors.append(abs(error))
    assert errors[0] == pytest.approx(true_equivalent)
    assert errors[-1] < 0.01 * errors[0]
    assert max(errors[-100:]) < 0.01


@pytest.mark.parametrize('kwargs', [dict(output_gain=0.0), dict(output_gain=-1.0), dict(learning_rate=-0.1),
                                    dict(weight_limit=0.0), dict(learning_rate=math.nan)])
def test_invalid_parameters_are_named(kwargs):
    arguments = dict(n_inputs=3, n_hidden=5, output_gain=1.0, learning_rate=0.01) | kwargs
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        EquivalentControlNetwork(**arguments)


@pytest.mark.parametrize('n_inputs, n_hidden', [(0, 5), (3, 0)])
def test_empty_layers_are_refused(n_inputs, n_hidden):
    with pytest.raises(ValueError, match='at least one'):
        EquivalentControlNetwork(n_inputs, n_hidden, output_gain=1.0, learning_rate=0.01)
