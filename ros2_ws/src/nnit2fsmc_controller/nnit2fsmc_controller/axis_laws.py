"""Per-subsystem control laws, one instance for each of x, y, z, phi, theta, psi.

Every law answers ``update(e, de, ref_vel, ref_acc, drift, gain)`` where, for the subsystem's
second-order dynamics  q'' = drift + gain * v  (drift and gain from the nominal model, see
:mod:`nnit2fsmc_controller.controller`), e = q - q_d, de = q' - q_d', ref_vel = q_d',
ref_acc = q_d'' and v is the virtual control the law returns. All laws use the paper's sliding
surface S = de + lambda e (eq. 3, 11). ``adapt()`` takes the online learning step of the last
update, if the law learns; ``update`` takes a step still pending first, so calling ``adapt`` only
moves the work to a moment of the caller's choosing (the controller node: after the rotor forces
are on their way).

* :class:`NNIT2FSMCLaw`: the paper's controller. Model-free: it ignores drift and gain;
  v = U_eq_hat (neural network) + U_fuzzy (IT2 fuzzy corrective term), the network learning online;
  with ``feedforward`` (x, y: v is an acceleration) v = q_d'' + U_eq_hat + U_fuzzy.
* :class:`SlidingModeLaw`: classic SMC, v = (ref_acc - lambda de - drift - K sw(S)) / gain, with
  sw = sign (``boundary_layer`` = 0) or sat(S / boundary_layer).
* :class:`IntegralSlidingModeLaw`: SMC on the integral surface S = de + lambda e + mu int(e), with a
  switching term sized for a disturbance bound and a gain uncertainty (docs/BASELINES.md).
* :class:`PIDLaw`: v = (ref_acc - kp e - ki int(e) - kd de - drift) / gain, anti-windup by clamping.

Every argument is a float (one vehicle) or a numpy array with one element per vehicle (a batch;
reference values may stay floats, shared by all vehicles); so is every output.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.validation import check_number

from .it2_fuzzy import IT2FuzzyCorrector, corrective_term, input_scale_of
from .kernel_state import BOOL, OPTIONAL, Slot
from .neural_network import EquivalentControlNetwork, forward_pass, learning_step, network_views


class AxisOutput(NamedTuple):
    """What one subsystem law computed in one update (units of its virtual control)."""

    value: float        #: v = equivalent + corrective
    surface: float      #: sliding surface S = de + lambda e (the PID reports the same S)
    equivalent: float   #: NN estimate (NNIT2FSMC) or model equivalent control (SMC) or PID feedback term
    corrective: float   #: fuzzy term (NNIT2FSMC), switching term (SMC) or 0 (PID)


@njit(cache=True, inline='always')
def nnit2fsmc_step(hidden_weights, output_weights, hidden_anchor, output_anchor, hidden, previous_inputs,
                   previous_output, pending, teaching, network, fuzzy, lam, e, de, inputs, learning):
    """One vehicle's NNIT2FSMC update in one compiled call: the learning step (eqs. 6-9) still pending
    from the last update (when ``pending``: the fuzzy term ``teaching``, at the last forward pass
    ``previous_inputs``, ``hidden``, ``previous_output``), then S = de + lambda e (eq. 3, 11), the
    corrective term U_fuzzy(S) and the network's U_eq_hat(Z) for ``inputs`` Z (writing ``hidden``).

    ``network`` is EquivalentControlNetwork.kernel_constants, ``fuzzy`` the corrector's kernel_parameters.
    Returns (v, S, U_eq_hat, U_fuzzy, the fuzzy term to learn from next, U_out): the network learns
    only while |S| is inside the fuzzy universe and ``learning`` holds (NNIT2FSMCLaw)."""
    learning_rate, output_gain, leakage, e_modification, limit, max_rate = network
    if pending:
        learning_step(hidden_weights, output_weights, hidden_anchor, output_anchor, previous_inputs, hidden,
                      previous_output, teaching, learning_rate, output_gain, leakage, e_modification, limit, max_rate)
    surface = de + lam * e
    corrective = corrective_term(fuzzy, surface)
    output = forward_pass(hidden_weights, output_weights, inputs, hidden)
    equivalent = output_gain * output
    to_learn = corrective if abs(surface) < input_scale_of(fuzzy) and learning else 0.0
    return equivalent + corrective, surface, equivalent, corrective, to_learn, output


@njit(cache=True)
def _nnit2fsmc_batch(hidden_weights, output_weights, hidden_anchor, output_anchor, hidden, previous_inputs,
                     previous_output, pending, teaching, network, fuzzy, lam, e, de, inputs, learning):
    """:func:`nnit2fsmc_step` for every vehicle of a batch (weights (B, H, I), (B, H); one row each):
    the rows (v, S, U_eq_hat, U_fuzzy, to learn) of a (5, B) array, and U_out (B,)."""
    count = e.shape[0]
    values, outputs = np.empty((5, count)), np.empty(count)
    for b in range(count):
        value, surface, equivalent, corrective, to_learn, output = nnit2fsmc_step(
            hidden_weights[b], output_weights[b], hidden_anchor[b], output_anchor[b], hidden[b], previous_inputs[b],
            previous_output[b], pending, teaching[b], network, fuzzy, lam, e[b], de[b], inputs[b], learning[b])
        values[0, b], values[1, b], values[2, b], values[3, b], values[4, b] = (value, surface, equivalent,
                                                                                 corrective, to_learn)
        outputs[b] = output
    return values, outputs


#: the law kinds that offer their update as a kernel of one vehicle (:func:`law_step`), the first of their
#: ``kernel_constants``
NNIT2FSMC_KERNEL = 0.0
#: positions in an NNIT2FSMC law's store: the teaching flag and value (``_teaching``), ``learning``, then its
#: network's store (:func:`.neural_network.network_views`)
_PENDING, _TEACHING, _LEARNING, _NETWORK = range(4)
#: positions in an NNIT2FSMC law's kernel_constants: kind, lambda, feedforward, bias_only, inputs I, hidden H,
#: then the network's kernel_constants (6) and the corrector's kernel_parameters
_LAMBDA, _FEEDFORWARD, _BIAS_ONLY, _INPUTS, _HIDDEN, _NETWORK_CONSTANTS = range(1, 7)
_FUZZY = _NETWORK_CONSTANTS + 6


@njit(cache=True)
def nnit2fsmc_law_step(store, constants, e, de, ref_vel, ref_acc):
    """One vehicle's :meth:`NNIT2FSMCLaw.update` on its ``store`` (state, in place: ``learning`` is read from
    it) and ``kernel_constants``: :func:`nnit2fsmc_step` with the network's views, then the teaching, U_out and
    Z of this update kept in the store. Returns (v, S, U_eq_hat, U_fuzzy)."""
    n_inputs, n_hidden = int(constants[_INPUTS]), int(constants[_HIDDEN])
    network = store[_NETWORK:]
    previous_inputs, hidden, output_weights, output_anchor, hidden_weights, hidden_anchor = network_views(
        network, n_inputs, n_hidden)
    inputs = np.empty(n_inputs)
    if constants[_BIAS_ONLY] != 0.0:
        inputs[0] = 1.0
    else:
        inputs[0], inputs[1], inputs[2] = ref_vel, ref_acc, 1.0
    c = constants[_NETWORK_CONSTANTS:_FUZZY]
    value, surface, equivalent, corrective, to_learn, output = nnit2fsmc_step(
        hidden_weights, output_weights, hidden_anchor, output_anchor, hidden, previous_inputs, network[0],
        store[_PENDING] != 0.0, store[_TEACHING], (c[0], c[1], c[2], c[3] != 0.0, c[4], c[5]), constants[_FUZZY:],
        constants[_LAMBDA], e, de, inputs, store[_LEARNING] != 0.0)
    store[_PENDING], store[_TEACHING], network[0] = 1.0, to_learn, output
    previous_inputs[:] = inputs
    return value + ref_acc if constants[_FEEDFORWARD] != 0.0 else value, surface, equivalent, corrective


@njit(cache=True)
def law_step(store, constants, e, de, ref_vel, ref_acc, drift, gain):
    """The update of one vehicle's law on its ``store`` with its ``kernel_constants``: (v, S, equivalent,
    corrective), as the law's ``update(e, de, ref_vel, ref_acc, drift, gain)``. The entry every law kind that
    offers a kernel goes through; today the NNIT2FSMC family alone (``constants[0]`` NNIT2FSMC_KERNEL;
    model-free: drift and gain unused). A kind added here branches on ``constants[0]``."""
    return nnit2fsmc_law_step(store, constants, e, de, ref_vel, ref_acc)


@njit(cache=True, inline='always')
def set_law_learning(store, constants, learning):
    """Set the ``learning`` flag (hold on the ground) of one vehicle's law in its ``store``."""
    store[_LEARNING] = 1.0 if learning else 0.0


def _per_vehicle(value, count: int) -> np.ndarray:
    """A contiguous float array of ``count`` elements (a float is shared by every vehicle): ``value`` itself when
    it already is one (the usual case, checked first: this runs several times per law and control step)."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (count,) \
            and value.flags.c_contiguous:
        return value
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=float), (count,)))


def _per_vehicle_flags(value, count: int) -> np.ndarray:
    """A bool array of ``count`` elements (a bool is shared by every vehicle): ``value`` itself when it is one."""
    if type(value) is np.ndarray and value.dtype == np.bool_ and value.shape == (count,) \
            and value.flags.c_contiguous:
        return value
    flags = np.empty(count, dtype=bool)
    flags[:] = value
    return flags


class NNIT2FSMCLaw:
    """One NNIT2FSMC subsystem: S = de + lambda e, v = NN(Z) + IT2FLS(S), NN learns from the fuzzy term.

    Network inputs Z = (q_d', q_d'', 1). On the sliding surface (S = 0, so e and de vanish) the
    equivalent control is a function of the reference motion and of slowly varying terms
    (gravity, drag, the section IV bias disturbances): the reference velocity and acceleration
    and a constant input are what it depends on. Tracking errors are deliberately not inputs:
    with e and de as inputs, online learning also adapts a feedback gain (the MIT-rule
    mechanism) and was seen to drive the position loop into a limit cycle at learning rates
    that are otherwise useful; the fuzzy term alone provides the feedback.

    The network learns only while |S| is inside the fuzzy universe (|S| < input_scale). Beyond
    it the fuzzy term is saturated: it then measures how far the state is from the surface
    (reaching phase), not the error of the equivalent control, and learning from it winds the
    network up (on a descending step the z estimate fell from +4.6 N to -6 N and the vehicle
    hit the ground).

    ``learning`` (a bool, or a bool array for a batch) clears the teaching of the vehicles where it
    is false: :class:`~.controller.CascadedController` clears it while a vehicle is on the ground
    (``takeoff_height``), where the error it would learn from cannot be corrected.

    ``feedforward`` adds the reference's own second derivative: v = q_d'' + U_eq_hat + U_fuzzy. It needs no
    vehicle parameter only where the virtual control is q'' itself (x, y: v is a horizontal acceleration
    [m/s^2], gain 1, as every baseline's feed-forward), so the law stays model-free; the network is then
    left with what the reference does not say (drag, wind, the section IV biases) instead of also having to
    learn the path's acceleration, within its output cap nn_gain (docs/PAPER.md 4.8.8).
    """

    STATE = ('_teaching',)   #: what a retune keeps (nnit2fsmc_controller.tuning); the network's is its own
    store = None   #: a single vehicle's state: _teaching, learning, then the network's store (kernel_state)
    _teaching = Slot(_PENDING, OPTIONAL)   #: fuzzy term the network has yet to learn from (0 where it must not learn)
    learning = Slot(_LEARNING, BOOL)    #: False (per vehicle) holds the network: set by the controller each update

    def __init__(self, lam: float, fuzzy: IT2FuzzyCorrector, network: EquivalentControlNetwork,
                 bias_only: bool = False, feedforward: bool = False):
        """``bias_only``: the network's only input is the constant 1 (ablation ``nnit2fsmc-bias``);
        ``feedforward``: v = q_d'' + U_eq_hat + U_fuzzy (class docstring)."""
        self.lam = check_number('lambda', lam, 0.0, low_inclusive=False)
        self.fuzzy = fuzzy
        self.network = network
        self.bias_only = bias_only
        self.feedforward = feedforward
        if network.n_inputs != (1 if bias_only else 3):
            raise ValueError(f'NNIT2FSMC law: its network takes (ref_vel, ref_acc, 1), or (1,) with bias_only; '
                             f'got a network of {network.n_inputs} inputs')
        if network.batch is None:
            store = np.zeros(_NETWORK + network.store.size)
            store[_NETWORK:] = network.store
            self.bind(store)
            #: (NNIT2FSMC_KERNEL, lambda, feedforward, bias_only, I, H, the network's and the corrector's constants)
            self.kernel_constants = np.array((NNIT2FSMC_KERNEL, self.lam, feedforward, bias_only, network.n_inputs,
                                              network.n_hidden, *network.kernel_constants,
                                              *fuzzy.kernel_parameters), dtype=float)
        self._teaching = None
        self.learning = True

    def bind(self, store) -> None:
        """Make ``store`` (holding this law's values) its store, the network's part of it the network's."""
        self.store = store
        self.network.bind(store[_NETWORK:])

    def update(self, e, de, ref_vel, ref_acc, drift, gain) -> AxisOutput:
        """Takes the learning step still pending, then S, U_fuzzy(S) and U_eq_hat(Z) (:func:`nnit2fsmc_step`)."""
        net = self.network
        if net.batch is None:
            return AxisOutput(*nnit2fsmc_law_step(self.store, self.kernel_constants, float(e), float(de),
                                                  float(ref_vel), float(ref_acc)))
        teaching = self._teaching
        pending = teaching is not None
        count = net.batch
        inputs = net.stacked_inputs((1.0,) if self.bias_only else (ref_vel, ref_acc, 1.0))
        teaching = teaching if pending else np.zeros(count)
        values, net._output = _nnit2fsmc_batch(
            net.hidden_weights, net.output_weights, net._hidden_anchor, net._output_anchor, net._hidden,
            net._inputs, net._output, pending, _per_vehicle(teaching, count), net.kernel_constants,
            self.fuzzy.kernel_parameters, self.lam, _per_vehicle(e, count), _per_vehicle(de, count), inputs,
            _per_vehicle_flags(self.learning, count))
        net._inputs = inputs
        value, surface, equivalent, corrective, self._teaching = values
        return AxisOutput(value + ref_acc if self.feedforward else value, surface, equivalent, corrective)

    def adapt(self) -> None:
        """The network's learning step (eqs. 6-9) from the last update's fuzzy term, if not taken yet."""
        if self._teaching is not None:
            self.network.learn(self._teaching)
            self._teaching = None


class SlidingModeLaw:
    """Classic SMC with the nominal model's equivalent control and a sign or saturated switching term."""

    STATE = ()

    def __init__(self, lam: float, switching_gain: float, boundary_layer: float = 0.0):
        self.lam = check_number('lambda', lam, 0.0, low_inclusive=False)
        self.switching_gain = check_number('switching_gain', switching_gain, 0.0)
        self.boundary_layer = check_number('boundary_layer', boundary_layer, 0.0)

    def switching(self, surface):
        """sign(S), or sat(S / boundary_layer) when a boundary layer is set."""
        xp = namespace_for(surface)
        if self.boundary_layer > 0.0:
            return xp.clip(surface / self.boundary_layer, -1.0, 1.0)
        return xp.sign(surface)

    def adapt(self) -> None:
        """Nothing to learn."""

    def update(self, e, de, ref_vel, ref_acc, drift, gain) -> AxisOutput:
        surface = de + self.lam * e
        equivalent = (ref_acc - self.lam * de - drift) / gain
        corrective = -self.switching_gain * self.switching(surface) / gain
        return AxisOutput(equivalent + corrective, surface, equivalent, corrective)


class IntegralSlidingModeLaw:
    """SMC on an integral sliding surface with a boundary layer, sized for bounded model errors.

    With I = int(e) dt (clamped to +-integral_limit) and the nominal model q'' = drift + gain v:

        S     = de + lambda e + mu I
        u_eq  = ref_acc - lambda de - mu e - drift          (makes dS/dt = 0 on the nominal model)
        K     = switching_gain + gain_uncertainty |u_eq|     (Slotine & Li, Applied Nonlinear Control, 7.1.3)
        v     = (u_eq - clip(slope S, -K, K)) / gain

    ``switching_gain`` = (F + eta) / r_min bounds the additive model error F [units of q''] with a
    margin eta, ``gain_uncertainty`` = max(1/r_min - 1, 1 - 1/r_max) the multiplicative one
    (true gain / nominal gain in [r_min, r_max]). clip(slope S, -K, K) = K sat(S / Phi) with the
    boundary layer Phi = K / slope: inside it the law is the linear -slope S (the bandwidth the
    other controllers are tuned to), outside it the full switching gain K.

    Anti-windup: the integral is clamped and moves only while the state is inside the boundary
    layer (conditional integration); in the reaching phase it is held.
    """

    STATE = ('integral',)

    def __init__(self, lam: float, mu: float, slope: float, switching_gain: float, gain_uncertainty: float,
                 integral_limit: float, dt: float):
        self.lam = check_number('lambda', lam, 0.0, low_inclusive=False)
        self.mu = check_number('integral_gain', mu, 0.0)
        self.slope = check_number('slope', slope, 0.0, low_inclusive=False)
        self.switching_gain = check_number('switching_gain', switching_gain, 0.0)
        self.gain_uncertainty = check_number('gain_uncertainty', gain_uncertainty, 0.0)
        self.integral_limit = check_number('integral_limit', integral_limit, 0.0)
        self.dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.integral = 0.0
        self.learning = True   #: False (or per vehicle): the integral holds (take-off hold, CascadedController)

    def adapt(self) -> None:
        """Nothing to learn (the integral is part of the update)."""

    def update(self, e, de, ref_vel, ref_acc, drift, gain) -> AxisOutput:
        xp = namespace_for(e)
        limit = self.integral_limit
        integral = xp.where(self.learning, xp.clip(self.integral + e * self.dt, -limit, limit), self.integral)
        surface = de + self.lam * e + self.mu * integral
        equivalent = ref_acc - self.lam * de - self.mu * e - drift
        bound = self.switching_gain + self.gain_uncertainty * xp.abs(equivalent)
        linear = self.slope * surface
        self.integral = xp.where(xp.abs(linear) < bound, integral, self.integral)
        corrective = -xp.clip(linear, -bound, bound)
        return AxisOutput((equivalent + corrective) / gain, surface, equivalent / gain, corrective / gain)


class PIDLaw:
    """PID on the error with feed-forward of the reference and of the nominal drift."""

    STATE = ('integral',)

    def __init__(self, lam: float, kp: float, ki: float, kd: float, integral_limit: float, dt: float):
        self.lam = check_number('lambda', lam, 0.0, low_inclusive=False)
        self.kp = check_number('kp', kp, 0.0)
        self.ki = check_number('ki', ki, 0.0)
        self.kd = check_number('kd', kd, 0.0)
        self.integral_limit = check_number('integral_limit', integral_limit, 0.0)
        self.dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.integral = 0.0
        self.learning = True   #: False (or per vehicle): the integral holds (take-off hold, CascadedController)

    def adapt(self) -> None:
        """Nothing to learn (the integral is part of the update)."""

    def update(self, e, de, ref_vel, ref_acc, drift, gain) -> AxisOutput:
        limit = self.integral_limit
        xp = namespace_for(e)
        self.integral = xp.where(self.learning, xp.clip(self.integral + e * self.dt, -limit, limit), self.integral)
        feedback = -(self.kp * e + self.ki * self.integral + self.kd * de)
        value = (ref_acc + feedback - drift) / gain
        return AxisOutput(value, de + self.lam * e, value, 0.0 * value)
