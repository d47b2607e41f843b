"""The bound of the networks' adaptation rate (issue 28 item 4a; neural_network module docstring).

On a fast reference the x, y networks integrated the fuzzy term 11-65 times per second (2.7 on the
paper's helix), and the y loop limit-cycled at 1.4 Hz: on the lemniscate, roll-rate RMS 0.41 -> 5 rad/s,
RMSE 21.6 cm. ``max_adaptation_rate`` normalises the learning step so that it never does faster than
the bound.
"""
from __future__ import annotations

import numpy as np
import pytest

from flight_stack.api import fly
from nnit2fsmc_controller.neural_network import EquivalentControlNetwork
from quad_msgs_bridge.frames import body_rates_from_euler_rates

INPUTS = (2.8, 4.0, 1.0)   #: (q_d', q_d'', 1) at the lemniscate's crossing


def trained(max_rate: float = 0.0) -> EquivalentControlNetwork:
    """A network whose output weights are no longer zero, at the lemniscate's inputs."""
    network = EquivalentControlNetwork(3, 5, output_gain=5.0, learning_rate=0.9e-3, initial_spread=1.0, seed=3,
                                       max_rate=max_rate)
    network.output_weights[:] = [0.8, -0.5, 0.3, 1.1, -0.7]
    network.forward(INPUTS)
    return network


def adaptation_rate(network: EquivalentControlNetwork, dt: float = 1e-3) -> float:
    """dU_eq_hat / (U_fuzzy dt) of one small learning step, measured [1/s]."""
    u_fuzzy = 1e-4
    before = network.forward(INPUTS)
    network.learn(u_fuzzy)
    return (network.forward(INPUTS) - before) / (u_fuzzy * dt)


def formula(network: EquivalentControlNetwork, dt: float = 1e-3) -> float:
    """k of the module docstring at the last forward pass [1/s]."""
    y, wy, z = network._hidden, network.output_weights, np.asarray(network._inputs)
    sensitivity = np.sum(y ** 2) / 4.0 + np.dot(z, z) * np.sum(wy ** 2 * (1.0 - y ** 2) ** 2) / 16.0
    return network.learning_rate / dt * network.output_gain ** 2 * (1.0 - network._output ** 2) ** 2 * sensitivity


def test_the_measured_adaptation_rate_is_the_formula_of_the_docstring():
    network = trained()
    expected = formula(network)
    assert expected > 10.0   # far above the 4 /s bound at these inputs
    assert adaptation_rate(network) == pytest.approx(expected, rel=1e-3)


def test_the_bound_caps_the_adaptation_rate_and_leaves_a_slower_one_alone():
    assert adaptation_rate(trained(max_rate=4.0e-3)) == pytest.approx(4.0, rel=1e-3)
    slow, unbounded = trained(max_rate=1.0), trained()
    assert adaptation_rate(slow) == adaptation_rate(unbounded)


def body_rates_after(flight, start: float) -> np.ndarray:
    """Body rates p, q, r [rad/s, body FLU] of the flight's rows from ``start`` [s] on."""
    late = flight.time >= start
    return np.array([body_rates_from_euler_rates(row[6:9], row[9:12]) for row in flight.state[late]])


@pytest.mark.parametrize('vehicle', ['paper', 'hummingbird'])
def test_no_roll_pitch_limit_cycle_on_the_fast_lemniscate(vehicle):
    """The lemniscate (2.8 m/s, 4 m/s^2) at 1 kHz on the paper's "+" vehicle and on an X frame: the body rates
    stay those of the path (about 0.56 rad/s roll, as every baseline flies it), not a growing limit cycle (5 rad/s
    before the bound on the paper's vehicle; 4.4 rad/s and 2.3 m RMSE on the hummingbird)."""
    flight = fly('nnit2fsmc', 'lemniscate', duration=20.0, vehicle=vehicle)
    roll_rms, pitch_rms = np.sqrt(np.mean(body_rates_after(flight, 5.0)[:, :2] ** 2, axis=0))
    assert roll_rms < 0.8 and pitch_rms < 0.3
    assert flight.summary['rmse_position_m'] < 0.03


def test_no_limit_cycle_on_the_fast_circle_on_an_x_frame():
    """``circle-fast`` (R = 2 m, 2.51 m/s, 3.16 m/s^2) on the hummingbird (X frame), 1 kHz: the body rates are
    those of the circle, |p, q, r| RMS 0.40 rad/s for every kind (docs/VEHICLES.md), not the limit cycle that the
    NNIT2FSMC's gains before issue 28 flew (bench/carry_over.py's ``before_gains``): as flown here, 5.2 rad/s and
    8.6 cm RMSE over 5-12 s against 0.40 rad/s and 1.5 cm; with 5 ms motor lag over 5-30 s, 6.1 rad/s and 59 cm."""
    flight = fly('nnit2fsmc', 'circle-fast', duration=12.0, vehicle='hummingbird')
    rates = body_rates_after(flight, 5.0)
    assert np.sqrt(np.mean(np.sum(rates ** 2, axis=1))) < 0.6
    assert flight.summary['rmse_position_m'] < 0.03
