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

Optional leakage (robust adaptive control; docs/ADAPTIVE.md) of every weight W towards its initial
value W0 (Wz: the seeded values, Wy: 0), with ``leakage`` l the share per update (sigma dt for a
leakage rate sigma [1/s]):

    sigma-modification (Ioannou & Kokotovic 1983):   W -= l * (W - W0)
    e-modification (Narendra & Annaswamy 1987):      W -= l * |U_fuzzy| / K_eq * (W - W0)

so that, without persistent teaching, the weights relax back instead of drifting. (The classical
forms scale the leakage by the adaptation gain too; here it is a rate of its own, because the
per-subsystem rates alpha span four decades and alpha sigma > 1 would make the leakage unstable.)

Each equation is written once, in :class:`EquivalentControlNetwork`, on top of a small layer
algebra with two implementations of the same six operations: :class:`ListLayers` for one vehicle
(lists of plain floats: one network per subsystem has a few dozen weights, and pure Python is far
faster than numpy at this size) and :class:`ArrayLayers` for a batch of B vehicles (hidden weights
an array (H, I, B), output weights (H, B): one network per vehicle, each learning from its own
fuzzy term, at numpy speed whatever H and I).
"""
from __future__ import annotations

import math
import random
from operator import mul
from typing import Sequence

import numpy as np

from quad_msgs_bridge.numeric import BATCH, SCALAR, is_batch
from quad_msgs_bridge.vehicle_params import ParameterError, check_number

MODIFICATIONS = ('none', 'sigma', 'e')   #: leakage of the learning law (module docstring)


def bipolar_sigmoid(x: float) -> float:
    """Eq. (4): g(x) = 2 / (1 + e^-x) - 1 = tanh(x / 2), in (-1, 1)."""
    return math.tanh(0.5 * x)


class ListLayers:
    """Layer operations of one vehicle's network: vectors are lists of floats, matrices lists of rows.

    Written as comprehensions over plain floats: at a few dozen weights the interpreter's cost per
    call, not the arithmetic, is what a control step pays for, so each operation is one pass.
    """

    @staticmethod
    def weights(values: list, batch: int | None) -> list:
        return [list(map(float, row)) if isinstance(row, list) else float(row) for row in values]

    @staticmethod
    def activations(matrix: list, inputs: Sequence) -> list:
        """g(sum_i W[j][i] x_i) for every row j, g the bipolar sigmoid of eq. (4) (= tanh(x / 2))."""
        tanh = math.tanh
        return [tanh(0.5 * sum(map(mul, row, inputs))) for row in matrix]

    @staticmethod
    def dot(vector: list, other: list):
        return sum(map(mul, vector, other))

    @staticmethod
    def elementwise(function, *vectors) -> list:
        """function applied to the j-th elements of the vectors, for every j."""
        return list(map(function, *vectors))

    @staticmethod
    def leaky_outer_step(matrix: list, anchor: list, leak, steps: list, inputs: Sequence, limit: float) -> list:
        """W[j][i] - leak (W[j][i] - W0[j][i]) - step_j x_i, every weight clipped to [-limit, limit]."""
        rows = [[w - leak * (w - w0) - step * x for w, w0, x in zip(row, anchor_row, inputs)]
                for row, anchor_row, step in zip(matrix, anchor, steps)]
        if -limit <= min(map(min, rows)) and max(map(max, rows)) <= limit:   # the common case: no copy
            return rows
        return [SCALAR.project(row, limit) for row in rows]

    @staticmethod
    def leaky_step(vector: list, anchor: list, leak, steps: list, limit: float) -> list:
        """w_j - leak (w_j - w0_j) - step_j, clipped to [-limit, limit]."""
        return SCALAR.project([w - leak * (w - w0) - step for w, w0, step in zip(vector, anchor, steps)], limit)


class ArrayLayers:
    """The same operations for B vehicles: the last axis of every array is the vehicle."""

    @staticmethod
    def weights(values: list, batch: int) -> np.ndarray:
        return np.repeat(np.asarray(values, dtype=float)[..., None], batch, axis=-1)

    @staticmethod
    def activations(matrix: np.ndarray, inputs: Sequence) -> np.ndarray:
        return np.tanh(0.5 * sum(matrix[:, i] * x for i, x in enumerate(inputs)))

    @staticmethod
    def dot(vector: np.ndarray, other: np.ndarray):
        return (vector * other).sum(axis=0)

    @staticmethod
    def elementwise(function, *vectors):
        return function(*vectors)

    @staticmethod
    def leaky_outer_step(matrix: np.ndarray, anchor: np.ndarray, leak, steps: np.ndarray, inputs: Sequence,
                         limit: float) -> np.ndarray:
        updated = matrix - leak * (matrix - anchor)
        for i, x in enumerate(inputs):
            np.subtract(updated[:, i], steps * x, out=updated[:, i])
        return np.clip(updated, -limit, limit, out=updated)

    @staticmethod
    def leaky_step(vector: np.ndarray, anchor: np.ndarray, leak, steps: np.ndarray, limit: float) -> np.ndarray:
        return np.clip(vector - leak * (vector - anchor) - steps, -limit, limit)


class EquivalentControlNetwork:
    """U_eq_hat = K_eq g(Wy . g(Wz Z)); online gradient learning from the fuzzy term."""

    #: what a retune keeps (nnit2fsmc_controller.tuning): the weights and the last forward pass
    STATE = ('hidden_weights', 'output_weights', '_inputs', '_hidden', '_output')

    def __init__(self, n_inputs: int, n_hidden: int, output_gain: float, learning_rate: float,
                 weight_limit: float = 10.0, initial_spread: float = 0.5, seed: int = 0,
                 batch: int | None = None, modification: str = 'none', leakage: float = 0.0):
        """``batch``: None for one vehicle (float weights), else the number of vehicles B (array weights).
        ``modification``: one of MODIFICATIONS, with ``leakage`` the share per update, in [0, 1) (module docstring)."""
        self.output_gain = check_number('output_gain', output_gain, 0.0, low_inclusive=False)
        self.learning_rate = check_number('learning_rate', learning_rate, 0.0)
        self.weight_limit = check_number('weight_limit', weight_limit, 0.0, low_inclusive=False)
        if modification not in MODIFICATIONS:
            raise ParameterError(f'modification: {modification!r} is not one of {", ".join(MODIFICATIONS)}')
        self.modification = modification
        self.leakage = check_number('leakage', leakage, 0.0, 1.0, high_inclusive=False) if modification != 'none' else 0.0
        if n_inputs < 1 or n_hidden < 1:
            raise ValueError(f'network needs at least one input and one hidden unit, got {n_inputs}, {n_hidden}')
        rng = random.Random(seed)
        self.xp = SCALAR if batch is None else BATCH
        self.layers = ListLayers if batch is None else ArrayLayers
        initial_hidden = [[rng.uniform(-initial_spread, initial_spread) for _ in range(n_inputs)]
                          for _ in range(n_hidden)]
        #: hidden weights Wz[j][i]: random, to break the symmetry between hidden units
        self.hidden_weights = self.layers.weights(initial_hidden, batch)
        #: output weights Wy[j]: zero, so the network starts knowing nothing (U_eq_hat = 0)
        self.output_weights = self.layers.weights([0.0] * n_hidden, batch)
        #: anchors W0 of the leakage: the initial weights
        self._hidden_anchor, self._output_anchor = self.hidden_weights, self.output_weights
        self._inputs: Sequence = (0.0,) * n_inputs
        self._hidden = self.layers.weights([0.0] * n_hidden, batch)
        self._output = 0.0 if batch is None else np.zeros(batch)

    def forward(self, inputs: Sequence) -> float:
        """U_eq_hat for input vector Z (eqs. 4 and the layer sums); remembers activations for learn().

        Each input is a float (shared by every vehicle of a batch) or an array of one per vehicle.
        """
        hidden = self.layers.activations(self.hidden_weights, inputs)
        output = self.xp.tanh(0.5 * self.layers.dot(self.output_weights, hidden))
        self._inputs, self._hidden, self._output = inputs, hidden, output
        return self.output_gain * output

    def _error_factors(self, u_fuzzy):
        """Per hidden unit j: (dE/dWy[j], dE/dWz[j][i] / Z_i) of eqs. (8) and (9) at the last forward pass,
        times any factor ``u_fuzzy`` carries (learn() passes alpha U_fuzzy: the steps of eqs. 6-7)."""
        common = u_fuzzy * self.output_gain * (1.0 - self._output * self._output)
        output_factors = self.layers.elementwise(lambda y: -0.5 * common * y, self._hidden)
        hidden_factors = self.layers.elementwise(lambda wy, y: -0.25 * common * wy * (1.0 - y * y),
                                                 self.output_weights, self._hidden)
        return output_factors, hidden_factors

    def gradients(self, u_fuzzy: float) -> tuple[list[float], list[list[float]]]:
        """(dE/dWy, dE/dWz) of eqs. (8) and (9) at the last forward pass, error measured by u_fuzzy (one vehicle)."""
        grad_output, hidden_factors = self._error_factors(u_fuzzy)
        return grad_output, [[factor * z for z in self._inputs] for factor in hidden_factors]

    def learn(self, u_fuzzy) -> None:
        """One gradient step, eqs. (6) and (7), then projection of every weight onto its bounds.

        Both steps use the weights of the last forward pass, as eqs. (6)-(7) say. A zero teaching
        signal changes no weight (every gradient is proportional to it): one vehicle then skips the
        arithmetic.
        """
        sigma = self.leakage
        if self.learning_rate == 0.0 or (not is_batch(u_fuzzy) and u_fuzzy == 0.0
                                         and (sigma == 0.0 or self.modification == 'e')):
            return
        output_steps, hidden_steps = self._error_factors(self.learning_rate * u_fuzzy)
        leak = sigma * (abs(u_fuzzy) / self.output_gain if self.modification == 'e' else 1.0) if sigma > 0.0 else 0.0
        layers, limit = self.layers, self.weight_limit
        self.hidden_weights = layers.leaky_outer_step(self.hidden_weights, self._hidden_anchor, leak, hidden_steps,
                                                      self._inputs, limit)
        self.output_weights = layers.leaky_step(self.output_weights, self._output_anchor, leak, output_steps, limit)
