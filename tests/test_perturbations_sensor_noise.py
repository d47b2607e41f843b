"""Sensor noise: white noise plus a per-flight bias on the controller's view of the state; batches."""
import math

import numpy as np
import pytest

from quad_msgs_bridge.frames import rotation_from_euler
from quad_msgs_bridge.validation import ParameterError
from quad_sim.perturbations import BLOCK_STEPS, SensorErrors, SensorNoise, flight_streams

STATE = [1.0, -2.0, 3.0, 0.5, -0.25, 0.1, 0.3, -0.4, 2.0, 0.7, -0.2, 1.1]


def noise_for(flight, noise, bias, seed=1):
    streams = flight_streams(seed, flight)
    return SensorNoise(noise, bias, streams.sensor_noise, streams.sensor_bias)


def body_rates_by_differentiation(euler, euler_rates, h=1e-6):
    """omega from skew(omega) = R^T dR/dt along the Euler-rate direction (central differences)."""
    plus = np.array(rotation_from_euler(*(a + h * r for a, r in zip(euler, euler_rates))))
    minus = np.array(rotation_from_euler(*(a - h * r for a, r in zip(euler, euler_rates))))
    skew = np.array(rotation_from_euler(*euler)).T @ (plus - minus) / (2 * h)
    return np.array([skew[2, 1], skew[0, 2], skew[1, 0]])


def test_without_errors_the_controller_sees_the_truth():
    measured = noise_for(0, SensorErrors(), SensorErrors()).measure(STATE)
    assert measured[:9] == STATE[:9]
    np.testing.assert_allclose(measured[9:], STATE[9:], atol=1e-15)


def test_bias_only_shifts_each_quantity_where_it_is_defined():
    sensor = noise_for(3, SensorErrors(), SensorErrors(position=0.05, velocity=0.1, attitude=0.02, body_rate=0.03))
    bias = np.array(sensor.bias)
    assert np.all(bias != 0.0) and len(bias) == 12
    for _ in range(3):          # constant over the flight
        measured = sensor.measure(STATE)
        np.testing.assert_allclose(measured[:9], np.add(STATE[:9], bias[:9]), rtol=0, atol=1e-15)
        # the body-rate bias is a gyro bias: body rates of the measured attitude and Euler rates
        # minus the true body rates equal it (rates computed independently from R^T dR/dt)
        error = (body_rates_by_differentiation(measured[6:9], measured[9:])
                 - body_rates_by_differentiation(STATE[6:9], STATE[9:]))
        np.testing.assert_allclose(error, bias[9:], atol=1e-8)


def test_noise_statistics_of_one_flight():
    std = SensorErrors(position=0.01, velocity=0.02, attitude=0.005, body_rate=0.0)
    sensor = noise_for(5, std, SensorErrors(position=0.03, velocity=0.03, attitude=0.03))
    n = 20000
    errors = np.array([sensor.measure(STATE)[:9] for _ in range(n)]) - np.array(STATE[:9])
    expected_std = np.repeat([0.01, 0.02, 0.005], 3)
    # mean = the flight's bias within 4.5 standard errors; std within 4 % (its std ~0.5 %)
    assert np.all(np.abs(errors.mean(axis=0) - sensor.bias[:9]) < 4.5 * expected_std / math.sqrt(n))
    np.testing.assert_allclose(errors.std(axis=0), expected_std, rtol=0.04)
    correlation = np.corrcoef(errors.T)
    assert np.all(np.abs(correlation - np.eye(9)) < 0.05)      # independent components


def test_biases_over_many_flights_have_the_bias_std():
    flights = 4000
    batch = SensorNoise(SensorErrors(), SensorErrors(position=0.02, velocity=0.0, attitude=0.01, body_rate=0.05),
                        [flight_streams(2, i).sensor_noise for i in range(flights)],
                        [flight_streams(2, i).sensor_bias for i in range(flights)])
    bias = np.array(batch.bias)
    expected = np.repeat([0.02, 0.0, 0.01, 0.05], 3)
    np.testing.assert_allclose(bias.std(axis=1), expected, rtol=0.06)     # std of the std ~1.1 %
    assert np.all(np.abs(bias.mean(axis=1)) <= 4.5 * expected / math.sqrt(flights))


def test_batch_equals_single_flights_across_block_refills():
    flights = [6, 0, 13, 2, 9, 4, 1]
    noise = SensorErrors(position=0.01, velocity=np.linspace(0.0, 0.03, 7), attitude=0.01, body_rate=0.02)
    bias = SensorErrors(position=0.005, velocity=0.0, attitude=np.full(7, 0.003), body_rate=0.01)
    batch = SensorNoise(noise, bias, [flight_streams(8, f).sensor_noise for f in flights],
                        [flight_streams(8, f).sensor_bias for f in flights])
    singles = [SensorNoise(SensorErrors(0.01, float(v), 0.01, 0.02), SensorErrors(0.005, 0.0, 0.003, 0.01),
                           flight_streams(8, f).sensor_noise, flight_streams(8, f).sensor_bias)
               for f, v in zip(flights, noise.velocity)]
    rng = np.random.default_rng(0)
    for _ in range(BLOCK_STEPS + 3):
        states = rng.uniform(-1.0, 1.0, (7, 12))
        measured = batch.measure([states[:, i] for i in range(12)])
        for i, single in enumerate(singles):
            np.testing.assert_allclose([m[i] for m in measured], single.measure(list(states[i])),
                                       rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize('errors, fragment', [
    (lambda: SensorErrors(position=-0.01), r'sensor_noise\.position'),
    (lambda: SensorErrors(body_rate=math.nan), r'sensor_noise\.body_rate'),
    (lambda: SensorErrors(velocity=np.array([0.1, -0.1])), r'sensor_noise\.velocity \(vehicle 1\)'),
    (lambda: SensorErrors(attitude='0.01'), r'sensor_noise\.attitude: expected a number'),
])
def test_invalid_standard_deviation_is_refused_by_name(errors, fragment):
    with pytest.raises(ParameterError, match=fragment):
        errors()


def test_invalid_generators_and_batch_sizes_are_refused():
    streams = flight_streams(0, 0)
    with pytest.raises(ParameterError, match=r'sensor_noise\.noise_rng'):
        SensorNoise(SensorErrors(), SensorErrors(), 7, streams.sensor_bias)
    with pytest.raises(ParameterError, match=r'sensor_noise\.bias_rng'):
        SensorNoise(SensorErrors(), SensorErrors(), streams.sensor_noise, [])
    with pytest.raises(ParameterError, match='vehicles'):
        SensorNoise(SensorErrors(position=np.array([0.1, 0.2, 0.3])), SensorErrors(),
                    [streams.sensor_noise] * 2, [streams.sensor_bias] * 2)
