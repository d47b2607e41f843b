"""Three-layer network estimating a subsystem's equivalent control, paper eqs. (4)-(9).

    Y_j   = g(sum_i Wz[j][i] Z_i)          hidden layer
    U_out = g(sum_j Wy[j] Y_j)             output layer
    U_eq  = K_eq U_out                     equivalent-control estimate
    g(x)  = 2 / (1 + exp(-x)) - 1          eq. (4), bipolar sigmoid, g' = (1 - g^2) / 2

Learning (eqs. 5-9): E = 1/2 (U_eq - U_eq_hat)^2 with the unknown error U_eq - U_eq_hat measured by
the fuzzy corrective term, so gradient descent with rate alpha gives

    Wy[j]    += alpha * 1/2 * U_fuzzy K_eq (1 - U_out^2) Y_j                      (6), (8)
    Wz[j][i] += alpha * 1/4 * U_fuzzy K_eq (1 - U_out^2) Wy[j] (1 - Y_j^2) Z_i   (7), (9)

Every weight is projected back onto [-weight_limit, weight_limit] after each update, so online
learning cannot diverge whatever the fuzzy term does.

Adaptation rate (docs/PAPER.md section 3, item (a) of issue 28). To first order one step moves the
estimate by dU_eq_hat = k U_fuzzy dt, with the network's adaptation rate [1/s]

    k = alpha K_eq^2 (1 - U_out^2)^2 (sum_j Y_j^2 / 4 + |Z|^2 sum_j Wy[j]^2 (1 - Y_j^2)^2 / 16)

(the squared gradient of U_eq_hat over the weights): the network integrates the fuzzy term at rate
k, which grows with its input power |Z|^2 and with the hidden activations. On a fast reference
(large q_d', q_d'') k rises far above its value on a slow one, and an integral term that fast in
the loop of the fuzzy term limit-cycles. ``max_rate`` k_max [per update; k_max dt for a rate per
second] normalises the step (the normalised adaptive laws of Ioannou & Sun, *Robust Adaptive
Control*, 1996, 4.3.3): every gradient is multiplied by min(1, k_max / k); 0 leaves it (paper).

Optional leakage (robust adaptive control; docs/ADAPTIVE.md) of every weight W towards its initial
value W0 (Wz: the seeded values, Wy: 0), with ``leakage`` l the share per update (sigma dt for a
leakage rate sigma [1/s]):

    sigma-modification (Ioannou & Kokotovic 1983):   W -= l * (W - W0)
    e-modification (Narendra & Annaswamy 1987):      W -= l * |U_fuzzy| / K_eq * (W - W0)

so that, without persistent teaching, the weights relax back instead of drifting. (The classical
forms scale the leakage by the adaptation gain too; here it is a rate of its own, because the
per-subsystem rates alpha span four decades and alpha sigma > 1 would make the leakage unstable.)

Each equation is written once, for one vehicle, in the compiled kernels :func:`forward_pass` and
:func:`learning_step` (numba: a network of a few dozen weights costs the interpreter far more than
its arithmetic, and a control step runs six of them); :meth:`EquivalentControlNetwork.gradients`
reports the gradient factors the learning step uses, from the same helpers. A batch of B
vehicles (one network per vehicle, each learning from its own fuzzy term) runs the same kernels
vehicle after vehicle, in compiled loops: weights (B, H, I) and (B, H), one row per vehicle.

A single-vehicle network keeps all its state in one flat float array, its ``store``
(:mod:`.kernel_state`; layout :func:`network_views`), so that a compiled law or controller step reaches
it through one argument; its weight arrays are views of the store.
"""
from __future__ import annotations

import math
import random
from typing import Sequence

import numpy as np
from numba import njit

import quad_msgs_bridge.kernel_cache  # noqa: F401  (the cache stamps of the kernels below)
from quad_msgs_bridge.validation import ParameterError, check_number

from .kernel_state import TUPLE, Slot

MODIFICATIONS = ('none', 'sigma', 'e')   #: leakage of the learning law (module docstring)


def bipolar_sigmoid(x: float) -> float:
    """Eq. (4): g(x) = 2 / (1 + e^-x) - 1 = tanh(x / 2), in (-1, 1)."""
    return math.tanh(0.5 * x)


@njit(cache=True, inline='always')
def forward_pass(hidden_weights, output_weights, inputs, hidden):
    """One vehicle: U_out = g(sum_j Wy[j] Y_j), with Y_j = g(sum_i Wz[j, i] Z_i) written into ``hidden``.

    g is eq. (4) as tanh(x / 2); ``inputs`` Z is a sequence of I floats, the weights (H, I) and (H,)."""
    n_hidden, n_inputs = hidden_weights.shape
    total = 0.0
    for j in range(n_hidden):
        activation = 0.0
        for i in range(n_inputs):
            activation += hidden_weights[j, i] * inputs[i]
        hidden[j] = math.tanh(0.5 * activation)
        total += output_weights[j] * hidden[j]
    return math.tanh(0.5 * total)


@njit(cache=True, inline='always')
def _common_factor(error, output_gain, output):
    """error K_eq (1 - U_out^2): the factor every gradient of eqs. (8), (9) shares."""
    return error * output_gain * (1.0 - output * output)


@njit(cache=True, inline='always')
def _unit_factors(common, output_weight, y):
    """Hidden unit j's (dE/dWy[j], dE/dWz[j][i] / Z_i) of eqs. (8), (9), from the shared factor, Wy[j] and Y_j."""
    return -0.5 * common * y, -0.25 * common * output_weight * (1.0 - y * y)


@njit(cache=True, inline='always')
def _clipped(value, limit):
    return -limit if value < -limit else limit if value > limit else value


@njit(cache=True, inline='always')
def _rate_factor(hidden_weights, output_weights, inputs, hidden, output, learning_rate, output_gain, max_rate):
    """min(1, max_rate / k), k the adaptation rate per update at the forward pass (module docstring)."""
    power = 0.0
    for i in range(hidden_weights.shape[1]):
        power += inputs[i] * inputs[i]
    sensitivity = 0.0
    for j in range(hidden_weights.shape[0]):
        y = hidden[j]
        slope = output_weights[j] * (1.0 - y * y)
        sensitivity += 0.25 * y * y + power * slope * slope / 16.0
    squashing = 1.0 - output * output
    rate = learning_rate * output_gain * output_gain * squashing * squashing * sensitivity
    return max_rate / rate if rate > max_rate else 1.0


@njit(cache=True, inline='always')
def learning_step(hidden_weights, output_weights, hidden_anchor, output_anchor, inputs, hidden, output, u_fuzzy,
                  learning_rate, output_gain, leakage, e_modification, limit, max_rate):
    """One vehicle's gradient step, eqs. (6) and (7), with leakage, the adaptation-rate bound ``max_rate``
    (per update, 0: none; module docstring) and projection, in place.

    Both steps use the weights of the forward pass (``hidden``, ``output`` at ``inputs``), as eqs.
    (6)-(7) say: unit j's factors are taken before its output weight moves. A zero teaching signal
    changes no weight (every gradient is proportional to it), so unless a sigma-modification leaks
    the arithmetic is skipped."""
    if learning_rate == 0.0 or (u_fuzzy == 0.0 and (leakage == 0.0 or e_modification)):
        return
    common = _common_factor(learning_rate * u_fuzzy, output_gain, output)
    if max_rate > 0.0:
        common *= _rate_factor(hidden_weights, output_weights, inputs, hidden, output, learning_rate, output_gain,
                               max_rate)
    leak = 0.0
    if leakage > 0.0:
        leak = leakage * (abs(u_fuzzy) / output_gain if e_modification else 1.0)
    n_hidden, n_inputs = hidden_weights.shape
    for j in range(n_hidden):
        output_step, hidden_step = _unit_factors(common, output_weights[j], hidden[j])
        for i in range(n_inputs):
            w = hidden_weights[j, i]
            hidden_weights[j, i] = _clipped(w - leak * (w - hidden_anchor[j, i]) - hidden_step * inputs[i], limit)
        w = output_weights[j]
        output_weights[j] = _clipped(w - leak * (w - output_anchor[j]) - output_step, limit)


def network_store_size(n_inputs: int, n_hidden: int) -> int:
    """Floats in a single-vehicle network's store (:func:`network_views`)."""
    return 1 + n_inputs + 3 * n_hidden + 2 * n_hidden * n_inputs


@njit(cache=True, inline='always')
def network_views(store, n_inputs, n_hidden):
    """The views of a single-vehicle network's ``store`` (U_out is ``store[0]``): the inputs Z of the last
    forward pass (I,), the hidden outputs Y (H,), the output weights Wy and their anchors (H,), the hidden
    weights Wz and their anchors (H, I)."""
    i, h = n_inputs, n_hidden
    start = 1 + i + 3 * h
    return (store[1:1 + i], store[1 + i:1 + i + h], store[1 + i + h:1 + i + 2 * h], store[1 + i + 2 * h:start],
            store[start:start + h * i].reshape((h, i)), store[start + h * i:start + 2 * h * i].reshape((h, i)))


@njit(cache=True)
def _forward_batch(hidden_weights, output_weights, inputs, hidden, output):
    for b in range(output.shape[0]):
        output[b] = forward_pass(hidden_weights[b], output_weights[b], inputs[b], hidden[b])


@njit(cache=True)
def _learning_batch(hidden_weights, output_weights, hidden_anchor, output_anchor, inputs, hidden, output, u_fuzzy,
                    learning_rate, output_gain, leakage, e_modification, limit, max_rate):
    for b in range(output.shape[0]):
        learning_step(hidden_weights[b], output_weights[b], hidden_anchor[b], output_anchor[b], inputs[b], hidden[b],
                      output[b], u_fuzzy[b], learning_rate, output_gain, leakage, e_modification, limit, max_rate)


class EquivalentControlNetwork:
    """U_eq_hat = K_eq g(Wy . g(Wz Z)); online gradient learning from the fuzzy term."""

    #: what a retune keeps (nnit2fsmc_controller.tuning): the weights and the last forward pass
    STATE = ('hidden_weights', 'output_weights', '_inputs', '_hidden', '_output')
    store = None   #: a single vehicle's state (module docstring); None for a batch
    _output = Slot(0)   #: U_out of the last forward pass (a float; (B,) for a batch)
    _inputs = Slot(1, TUPLE, length=lambda network: network.n_inputs)   #: its Z (a tuple; (B, I) for a batch)

    def __init__(self, n_inputs: int, n_hidden: int, output_gain: float, learning_rate: float,
                 weight_limit: float = 10.0, initial_spread: float = 0.5, seed: int = 0,
                 batch: int | None = None, modification: str = 'none', leakage: float = 0.0,
                 max_rate: float = 0.0):
        """``batch``: None for one vehicle (float inputs and output), else the number of vehicles B.
        ``modification``: one of MODIFICATIONS, with ``leakage`` the share per update, in [0, 1) (module docstring).
        ``max_rate``: the bound of the adaptation rate per update (module docstring; 0: none)."""
        self.output_gain = check_number('output_gain', output_gain, 0.0, low_inclusive=False)
        self.learning_rate = check_number('learning_rate', learning_rate, 0.0)
        self.weight_limit = check_number('weight_limit', weight_limit, 0.0, low_inclusive=False)
        if modification not in MODIFICATIONS:
            raise ParameterError(f'modification: {modification!r} is not one of {", ".join(MODIFICATIONS)}')
        self.modification = modification
        self.leakage = check_number('leakage', leakage, 0.0, 1.0, high_inclusive=False) if modification != 'none' else 0.0
        self.max_rate = check_number('max_rate', max_rate, 0.0)
        if n_inputs < 1 or n_hidden < 1:
            raise ValueError(f'network needs at least one input and one hidden unit, got {n_inputs}, {n_hidden}')
        rng = random.Random(seed)
        initial_hidden = [[rng.uniform(-initial_spread, initial_spread) for _ in range(n_inputs)]
                          for _ in range(n_hidden)]
        self.batch = batch
        self.n_inputs, self.n_hidden = n_inputs, n_hidden
        # hidden weights Wz[j][i], (H, I) or (B, H, I): random, to break the symmetry between hidden units;
        # output weights Wy[j], (H,) or (B, H): zero, so the network starts knowing nothing (U_eq_hat = 0);
        # their anchors W0 (of the leakage): the initial weights
        if batch is None:   # every array a view of the store, zeros at first
            self.bind(np.zeros(network_store_size(n_inputs, n_hidden)))
            self.hidden_weights[:] = self._hidden_anchor[:] = initial_hidden
        else:
            self.hidden_weights = np.tile(np.array(initial_hidden), (batch, 1, 1))
            self.output_weights = np.zeros((batch, n_hidden))
            self._hidden_anchor, self._output_anchor = self.hidden_weights.copy(), self.output_weights.copy()
            self._inputs, self._hidden, self._output = np.zeros((batch, n_inputs)), np.zeros((batch, n_hidden)), \
                np.zeros(batch)
        #: (learning rate, K_eq, leakage, e-modification?, weight limit, adaptation-rate bound): the learning
        #: step's constants, in :func:`learning_step`'s order (a network's constants are fixed when it is built;
        #: a retune builds a new one)
        self.kernel_constants = (self.learning_rate, self.output_gain, self.leakage, self.modification == 'e',
                                 self.weight_limit, self.max_rate)

    def bind(self, store: np.ndarray) -> None:
        """Make ``store`` (of :func:`network_store_size` floats, holding this network's values) its store."""
        self.store = store
        (_, self._hidden, self.output_weights, self._output_anchor, self.hidden_weights,
         self._hidden_anchor) = network_views(store, self.n_inputs, self.n_hidden)

    def forward(self, inputs: Sequence) -> float:
        """U_eq_hat for input vector Z (eqs. 4 and the layer sums); remembers activations for learn().

        Each input is a float (shared by every vehicle of a batch) or an array of one per vehicle.
        """
        if self.batch is None:
            self._inputs = inputs = tuple([float(z) for z in inputs])
            self._output = output = forward_pass(self.hidden_weights, self.output_weights, inputs, self._hidden)
            return self.output_gain * output
        stacked = self.stacked_inputs(inputs)
        self._inputs, self._output = stacked, np.empty(self.batch)
        _forward_batch(self.hidden_weights, self.output_weights, stacked, self._hidden, self._output)
        return self.output_gain * self._output

    def stacked_inputs(self, inputs: Sequence) -> np.ndarray:
        """A batch's input vectors Z as a (B, I) array, one row per vehicle (a float input is shared by all)."""
        stacked = np.empty((self.batch, len(inputs)))
        for i, z in enumerate(inputs):
            stacked[:, i] = z
        return stacked

    def gradients(self, u_fuzzy: float) -> tuple[np.ndarray, np.ndarray]:
        """(dE/dWy, dE/dWz) of eqs. (8) and (9) at the last forward pass, error measured by u_fuzzy (one vehicle)."""
        common = _common_factor(float(u_fuzzy), self.output_gain, self._output)
        output_factors, hidden_factors = np.array([_unit_factors(common, wy, y)
                                                   for wy, y in zip(self.output_weights, self._hidden)]).T
        return output_factors, np.outer(hidden_factors, self._inputs)

    def learn(self, u_fuzzy) -> None:
        """One gradient step, eqs. (6) and (7), then projection of every weight onto its bounds
        (:func:`learning_step`; ``u_fuzzy`` a float, or one per vehicle of a batch)."""
        step = learning_step if self.batch is None else _learning_batch
        u_fuzzy = float(u_fuzzy) if self.batch is None else np.broadcast_to(np.asarray(u_fuzzy, dtype=float),
                                                                             (self.batch,))
        step(self.hidden_weights, self.output_weights, self._hidden_anchor, self._output_anchor, self._inputs,
             self._hidden, self._output, u_fuzzy, *self.kernel_constants)
