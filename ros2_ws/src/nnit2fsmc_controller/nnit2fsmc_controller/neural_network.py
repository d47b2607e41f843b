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

Weights are lists (of lists) of plain floats for one vehicle: one network per subsystem is small
(a few dozen weights) and pure Python is faster than numpy at this size. For a batch of B vehicles
each weight is a numpy array of B values, one network per vehicle learning from its own fuzzy
term, through the same code.
"""
from __future__ import annotations

import math
import random
from operator import mul
from typing import Sequence

import numpy as np

from quad_msgs_bridge.numeric import BATCH, SCALAR, is_batch
from quad_msgs_bridge.vehicle_params import check_number


def bipolar_sigmoid(x: float) -> float:
    """Eq. (4): g(x) = 2 / (1 + e^-x) - 1 = tanh(x / 2), in (-1, 1)."""
    return math.tanh(0.5 * x)


class EquivalentControlNetwork:
    """U_eq_hat = K_eq g(Wy . g(Wz Z)); online gradient learning from the fuzzy term."""

    def __init__(self, n_inputs: int, n_hidden: int, output_gain: float, learning_rate: float,
                 weight_limit: float = 10.0, initial_spread: float = 0.5, seed: int = 0,
                 batch: int | None = None):
        """``batch``: None for one vehicle (float weights), else the number of vehicles B (array weights)."""
        self.output_gain = check_number('output_gain', output_gain, 0.0, low_inclusive=False)
        self.learning_rate = check_number('learning_rate', learning_rate, 0.0)
        self.weight_limit = check_number('weight_limit', weight_limit, 0.0, low_inclusive=False)
        if n_inputs < 1 or n_hidden < 1:
            raise ValueError(f'network needs at least one input and one hidden unit, got {n_inputs}, {n_hidden}')
        rng = random.Random(seed)
        self.xp = SCALAR if batch is None else BATCH
        weight = float if batch is None else (lambda value: np.full(batch, value))
        #: hidden weights Wz[j][i]: random, to break the symmetry between hidden units
        self.hidden_weights = [[weight(rng.uniform(-initial_spread, initial_spread)) for _ in range(n_inputs)]
                               for _ in range(n_hidden)]
        #: output weights Wy[j]: zero, so the network starts knowing nothing (U_eq_hat = 0)
        self.output_weights = [weight(0.0) for _ in range(n_hidden)]
        self._inputs: Sequence = (0.0,) * n_inputs
        self._hidden = [weight(0.0) for _ in range(n_hidden)]
        self._output = weight(0.0)

    def forward(self, inputs: Sequence) -> float:
        """U_eq_hat for input vector Z (eqs. 4 and the layer sums); remembers activations for learn().

        Each input is a float (shared by every vehicle of a batch) or an array of one per vehicle.
        """
        tanh = self.xp.tanh
        hidden = [tanh(0.5 * sum(map(mul, row, inputs))) for row in self.hidden_weights]
        output = tanh(0.5 * sum(map(mul, self.output_weights, hidden)))
        self._inputs, self._hidden, self._output = inputs, hidden, output
        return self.output_gain * output

    def gradients(self, u_fuzzy: float) -> tuple[list[float], list[list[float]]]:
        """(dE/dWy, dE/dWz) of eqs. (8) and (9) at the last forward pass, error measured by u_fuzzy."""
        common = u_fuzzy * self.output_gain * (1.0 - self._output * self._output)
        grad_output = [-0.5 * common * y for y in self._hidden]
        grad_hidden = [[-0.25 * common * wy * (1.0 - y * y) * z for z in self._inputs]
                       for wy, y in zip(self.output_weights, self._hidden)]
        return grad_output, grad_hidden

    def learn(self, u_fuzzy) -> None:
        """One gradient step, eqs. (6) and (7), then projection of every weight onto its bounds.

        The gradients of :meth:`gradients`, computed term by term in the same order (so to the same
        bits) inside the update: the step runs once per subsystem and control step, and building
        the gradient lists first cost a third of it. Every hidden-weight step uses the output
        weights from before this step, as eqs. (6)-(7) say. A zero teaching signal changes no
        weight (every gradient is proportional to it): one vehicle then skips the arithmetic.
        """
        if self.learning_rate == 0.0 or (not is_batch(u_fuzzy) and u_fuzzy == 0.0):
            return
        project = self.xp.project
        alpha, limit = self.learning_rate, self.weight_limit
        common = u_fuzzy * self.output_gain * (1.0 - self._output * self._output)
        inputs, output_weights = self._inputs, self.output_weights
        for y, row, wy in zip(self._hidden, self.hidden_weights, output_weights):
            hidden_factor = -0.25 * common * wy * (1.0 - y * y)     # dE/dWz[j][i] = hidden_factor * Z_i
            row[:] = project([w - alpha * (hidden_factor * z) for w, z in zip(row, inputs)], limit)
        output_weights[:] = project([wy - alpha * (-0.5 * common * y)
                                     for wy, y in zip(output_weights, self._hidden)], limit)
