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
learning cannot diverge whatever the fuzzy term does. Plain-float lists: one network per
subsystem is small (a few dozen weights) and pure Python is faster than numpy at this size.
"""
from __future__ import annotations

import math
import random
from typing import Sequence

from quad_msgs_bridge.vehicle_params import check_number


def bipolar_sigmoid(x: float) -> float:
    """Eq. (4): g(x) = 2 / (1 + e^-x) - 1 = tanh(x / 2), in (-1, 1)."""
    return math.tanh(0.5 * x)


class EquivalentControlNetwork:
    """U_eq_hat = K_eq g(Wy . g(Wz Z)); online gradient learning from the fuzzy term."""

    def __init__(self, n_inputs: int, n_hidden: int, output_gain: float, learning_rate: float,
                 weight_limit: float = 10.0, initial_spread: float = 0.5, seed: int = 0):
        self.output_gain = check_number('output_gain', output_gain, 0.0, low_inclusive=False)
        self.learning_rate = check_number('learning_rate', learning_rate, 0.0)
        self.weight_limit = check_number('weight_limit', weight_limit, 0.0, low_inclusive=False)
        if n_inputs < 1 or n_hidden < 1:
            raise ValueError(f'network needs at least one input and one hidden unit, got {n_inputs}, {n_hidden}')
        rng = random.Random(seed)
        #: hidden weights Wz[j][i]: random, to break the symmetry between hidden units
        self.hidden_weights = [[rng.uniform(-initial_spread, initial_spread) for _ in range(n_inputs)]
                               for _ in range(n_hidden)]
        #: output weights Wy[j]: zero, so the network starts knowing nothing (U_eq_hat = 0)
        self.output_weights = [0.0] * n_hidden
        self._inputs: Sequence[float] = (0.0,) * n_inputs
        self._hidden = [0.0] * n_hidden
        self._output = 0.0

    def forward(self, inputs: Sequence[float]) -> float:
        """U_eq_hat for input vector Z (eqs. 4 and the layer sums); remembers activations for learn()."""
        tanh = math.tanh
        hidden = [tanh(0.5 * sum(w * z for w, z in zip(row, inputs))) for row in self.hidden_weights]
        output = tanh(0.5 * sum(w * y for w, y in zip(self.output_weights, hidden)))
        self._inputs, self._hidden, self._output = inputs, hidden, output
        return self.output_gain * output

    def gradients(self, u_fuzzy: float) -> tuple[list[float], list[list[float]]]:
        """(dE/dWy, dE/dWz) of eqs. (8) and (9) at the last forward pass, error measured by u_fuzzy."""
        common = u_fuzzy * self.output_gain * (1.0 - self._output * self._output)
        grad_output = [-0.5 * common * y for y in self._hidden]
        grad_hidden = [[-0.25 * common * wy * (1.0 - y * y) * z for z in self._inputs]
                       for wy, y in zip(self.output_weights, self._hidden)]
        return grad_output, grad_hidden

    def learn(self, u_fuzzy: float) -> None:
        """One gradient step, eqs. (6) and (7), then projection of every weight onto its bounds.

        The gradients of :meth:`gradients`, computed term by term in the same order (so to the same
        bits) inside the update loop: the step runs once per subsystem and control step, and building
        the gradient lists first cost a third of it.
        """
        if self.learning_rate == 0.0:
            return
        alpha, limit = self.learning_rate, self.weight_limit
        common = u_fuzzy * self.output_gain * (1.0 - self._output * self._output)
        inputs, output_weights = self._inputs, self.output_weights
        for j, (y, row) in enumerate(zip(self._hidden, self.hidden_weights)):
            wy = output_weights[j]
            hidden_factor = -0.25 * common * wy * (1.0 - y * y)     # dE/dWz[j][i] = hidden_factor * Z_i
            for i, z in enumerate(inputs):
                row[i] = min(limit, max(-limit, row[i] - alpha * (hidden_factor * z)))
            output_weights[j] = min(limit, max(-limit, wy - alpha * (-0.5 * common * y)))
