"""Transport delay (whole control steps) and first-order motor lag (exact under a held command)."""
import math

import numpy as np
import pytest

from quad_msgs_bridge.validation import ParameterError
from quad_sim.perturbations import MotorLag, TransportDelay


def computed_at(n):
    return (1.0 + n, 2.0 + n, 0.5 * n, 3.0)


@pytest.mark.parametrize('k', [0, 1, 4, 7])
def test_applied_forces_are_those_computed_k_steps_earlier(k):
    delay = TransportDelay(k)
    for n in range(30):
        applied = delay(computed_at(n))
        assert applied == (computed_at(n - k) if n >= k else (0.0, 0.0, 0.0, 0.0))


def test_batch_delay_equals_single_vehicle_delays():
    batch, singles = TransportDelay(3), [TransportDelay(3) for _ in range(5)]
    rng = np.random.default_rng(2)
    for _ in range(20):
        forces = rng.uniform(0.0, 2.5, (4, 5))              # (rotor, vehicle)
        applied = batch(tuple(forces))
        for i, single in enumerate(singles):
            assert [a[i] for a in applied] == list(single(tuple(float(f) for f in forces[:, i])))


def test_batch_delay_copies_what_it_queues():
    delay = TransportDelay(2)
    forces = [np.array([1.0, 2.0]), np.array([3.0, 4.0]), np.array([5.0, 6.0]), np.array([7.0, 8.0])]
    first = delay(forces)
    np.testing.assert_array_equal(first, np.zeros((4, 2)))
    forces[0][:] = -1.0                         # the caller reuses its arrays
    delay([f + 1.0 for f in forces])
    np.testing.assert_array_equal(delay(forces)[0], [1.0, 2.0])


def test_delay_in_seconds_must_be_whole_control_steps():
    assert TransportDelay.from_seconds(0.004, 0.001).steps == 4
    assert TransportDelay.from_seconds(0.0, 0.001).steps == 0
    assert TransportDelay.from_seconds(0.012, 0.004).steps == 3
    with pytest.raises(ParameterError, match=r'delay_s: 0\.0045 s is not a whole number of control steps of 0\.001 s '
                                             r'\(nearest: 4 steps = 0\.004 s or 5 steps = 0\.005 s\)'):
        TransportDelay.from_seconds(0.0045, 0.001)
    with pytest.raises(ParameterError, match='delay_s'):
        TransportDelay.from_seconds(-0.001, 0.001)
    with pytest.raises(ParameterError, match='control_dt'):
        TransportDelay.from_seconds(0.004, 0.0)
    for steps in (-1, 1.5, True, '2'):
        with pytest.raises(ParameterError, match='delay_steps'):
            TransportDelay(steps)


@pytest.mark.parametrize('tau, dt', [(0.03, 1e-3), (0.005, 1e-3), (0.02, 4e-3)])
def test_motor_lag_step_response(tau, dt):
    """Unit step from rest: T(k dt) = 1 - exp(-k dt / tau); the value held over step k is the mean of T over it."""
    lag = MotorLag(tau, dt)
    for k in range(1, 200):
        held = lag.step((1.0, 2.0, 0.0, 0.5))
        t0, t1 = (k - 1) * dt, k * dt
        mean = 1.0 - tau / dt * (math.exp(-t0 / tau) - math.exp(-t1 / tau))
        np.testing.assert_allclose(lag.thrusts, np.array([1.0, 2.0, 0.0, 0.5]) * (1.0 - math.exp(-t1 / tau)),
                                   rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(held, np.array([1.0, 2.0, 0.0, 0.5]) * mean, rtol=1e-12, atol=1e-15)


def test_zero_time_constant_is_no_lag():
    lag = MotorLag(0.0, 1e-3)
    for forces in [(1.0, 2.0, 3.0, 4.0), (0.5, 0.0, 2.6, 1.2)]:
        assert lag.step(forces) == forces and lag.thrusts == forces


def test_batch_lag_with_one_time_constant_per_vehicle_equals_single_vehicles():
    taus = np.array([0.0, 0.005, 0.03, 0.1])
    batch = MotorLag(taus, 1e-3)
    singles = [MotorLag(float(tau), 1e-3) for tau in taus]
    rng = np.random.default_rng(1)
    for _ in range(100):
        commands = rng.uniform(0.0, 2.6, (4, 4))          # (rotor, vehicle)
        held = batch.step(tuple(commands))
        for i, single in enumerate(singles):
            np.testing.assert_allclose([h[i] for h in held], single.step(tuple(commands[:, i])), rtol=1e-13)


@pytest.mark.parametrize('tau, dt, fragment', [(-0.01, 1e-3, 'motor_time_constant_s'),
                                               (math.nan, 1e-3, 'motor_time_constant_s'),
                                               (np.array([0.01, -1.0]), 1e-3, r'motor_time_constant_s \(vehicle 1\)'),
                                               (0.01, 0.0, 'dt')])
def test_invalid_lag_is_refused_by_name(tau, dt, fragment):
    with pytest.raises(ParameterError, match=fragment):
        MotorLag(tau, dt)
