"""Wind: MIL-F-8785C low-altitude Dryden scales, exact discretisation, variances and spectra, batches."""
import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from quad_msgs_bridge.validation import ParameterError
from quad_sim.perturbations import BLOCK_STEPS, DrydenTurbulence, Wind, flight_streams, low_altitude_scales
from quad_sim.perturbations.wind import first_order_step, second_order_step

KNOT = 0.514444   # m/s, rounded on purpose: an independent constant
FOOT = 0.3048


def standard_scales_in_feet(w20_knots, h_ft):
    """MIL-F-8785C low altitude, as printed: feet and feet per second."""
    sigma_w = 0.1 * w20_knots * KNOT / FOOT
    sigma_u = sigma_w / (0.177 + 0.000823 * h_ft) ** 0.4
    length_u = h_ft / (0.177 + 0.000823 * h_ft) ** 1.2
    return sigma_u, sigma_w, length_u, h_ft


@pytest.mark.parametrize('intensity, w20', [('light', 15), ('moderate', 30), ('severe', 45)])
@pytest.mark.parametrize('altitude', [3.048, 5.0, 50.0, 304.8])
def test_low_altitude_scales_are_the_standards_in_si(intensity, w20, altitude):
    sigma_u, sigma_w, length_u, length_w = standard_scales_in_feet(w20, altitude / FOOT)
    scales = low_altitude_scales(intensity, altitude)
    np.testing.assert_allclose([scales.sigma_u, scales.sigma_v, scales.sigma_w],
                               [sigma_u * FOOT, sigma_u * FOOT, sigma_w * FOOT], rtol=1e-5)
    np.testing.assert_allclose([scales.length_u, scales.length_v, scales.length_w],
                               [length_u * FOOT, length_u * FOOT, length_w * FOOT], rtol=1e-12)


def test_scales_at_1000_ft_are_isotropic_and_moderate_sigma_w_is_3_knots():
    """At h = 1000 ft, 0.177 + 0.000823 h = 1: sigma_u = sigma_w and L_u = L_w = h."""
    scales = low_altitude_scales('moderate', 304.8)
    assert scales.sigma_w == pytest.approx(3.0 * 1852.0 / 3600.0, rel=1e-15)
    assert scales.sigma_u == pytest.approx(scales.sigma_w, rel=1e-12)
    assert scales.length_u == pytest.approx(304.8, rel=1e-12) and scales.length_w == 304.8


def test_altitude_is_clamped_to_the_low_altitude_range():
    assert low_altitude_scales('light', 1.0) == low_altitude_scales('light', 10 * FOOT)
    assert low_altitude_scales('light', 2000.0) == low_altitude_scales('light', 1000 * FOOT)


def van_loan(a_matrix, b_vector, dt):
    """Exact discretisation of x' = A x + b w (unit white noise) by C. F. Van Loan's matrix exponential."""
    n = len(a_matrix)
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n], block[:n, n:], block[n:, n:] = -a_matrix, np.outer(b_vector, b_vector), a_matrix.T
    exp = scipy.linalg.expm(block * dt)
    transition = exp[n:, n:].T
    return transition, transition @ exp[:n, n:]


@pytest.mark.parametrize('tau', [1e-5, 2e-3, 0.1, 0.45, 0.6, 1.5])
def test_second_order_step_is_the_exact_discretisation(tau):
    """Against Van Loan, in the unit-variance coordinates xi1 = 2 a^1.5 x1, xi2 = 2 a^0.5 x2 (a = V/L = 1/s)."""
    a = 1.0
    transition, covariance = van_loan(np.array([[0.0, 1.0], [-a * a, -2.0 * a]]), np.array([0.0, 1.0]), tau)
    scale = np.diag([2.0 * a ** 1.5, 2.0 * a ** 0.5])
    expected_transition = scale @ transition @ np.linalg.inv(scale)
    expected_covariance = scale @ covariance @ scale
    (m11, m12, m21, m22), (l11, l21, l22) = second_order_step(tau)
    np.testing.assert_allclose([[m11, m12], [m21, m22]], expected_transition, rtol=1e-12, atol=1e-15)
    cholesky = np.array([[l11, 0.0], [l21, l22]])
    np.testing.assert_allclose(cholesky @ cholesky.T, expected_covariance, rtol=1e-9)


@pytest.mark.parametrize('tau', [0.3, 3.0, 12.0])
def test_discrete_filters_keep_unit_variance(tau):
    """Stationarity: M M^T + Q = I and decay^2 + gain^2 = 1 (a check that also holds for large steps)."""
    (m11, m12, m21, m22), (l11, l21, l22) = second_order_step(tau)
    m = np.array([[m11, m12], [m21, m22]])
    cholesky = np.array([[l11, 0.0], [l21, l22]])
    np.testing.assert_allclose(m @ m.T + cholesky @ cholesky.T, np.eye(2), atol=1e-14)
    decay, gain = first_order_step(tau)
    assert decay ** 2 + gain ** 2 == pytest.approx(1.0, abs=1e-15)
    assert decay == pytest.approx(math.exp(-tau), rel=1e-15)


def dryden_spectra(frequency_hz, scales, airspeed):
    """One-sided PSD per hertz, 2 pi Phi(2 pi f), of MIL-F-8785C's Phi_u, Phi_v, Phi_w."""
    omega = 2.0 * np.pi * frequency_hz
    spectra = []
    for sigma, length, first_order in ((scales.sigma_u, scales.length_u, True),
                                       (scales.sigma_v, scales.length_v, False),
                                       (scales.sigma_w, scales.length_w, False)):
        x = length * omega / airspeed
        if first_order:
            phi = sigma ** 2 * 2.0 * length / (np.pi * airspeed) / (1.0 + x ** 2)
        else:
            phi = sigma ** 2 * length / (np.pi * airspeed) * (1.0 + 3.0 * x ** 2) / (1.0 + x ** 2) ** 2
        spectra.append(2.0 * np.pi * phi)
    return spectra


@pytest.fixture(scope='module')
def long_sample():
    """200 flights x 100 s of moderate turbulence in a 20 m/s wind towards +x, at 100 Hz."""
    dt, flights, steps = 0.01, 200, 10000
    wind = Wind(dt, mean_speed=20.0, direction=0.0, turbulence='moderate', altitude=5.0,
                rng=[flight_streams(11, i).turbulence for i in range(flights)])
    samples = np.empty((3, flights, steps))
    for k in range(steps):
        samples[:, :, k] = wind.step()
    return dt, wind.turbulence.scales, samples


def test_dryden_variances_and_mean_over_a_long_sample(long_sample):
    _, scales, samples = long_sample
    assert samples[0].mean() == pytest.approx(20.0, abs=0.15)     # std of this mean ~ 0.04 m/s
    assert abs(samples[1].mean()) < 0.15 and abs(samples[2].mean()) < 0.03
    # relative std of the variance estimate: sqrt(2 L/V / T) = 1.9 % (u), 0.5 % (w)
    assert samples[0].var() == pytest.approx(scales.sigma_u ** 2, rel=0.08)
    assert samples[1].var() == pytest.approx(scales.sigma_v ** 2, rel=0.08)
    assert samples[2].var() == pytest.approx(scales.sigma_w ** 2, rel=0.03)
    # independent components
    for i, j in ((0, 1), (0, 2), (1, 2)):
        assert abs(np.corrcoef(samples[i].ravel(), samples[j].ravel())[0, 1]) < 0.05


def test_dryden_spectra_match_the_standard(long_sample):
    dt, scales, samples = long_sample
    frequency, psd = scipy.signal.welch(samples, fs=1.0 / dt, nperseg=4096, axis=-1)
    psd = psd.mean(axis=1)            # average over the flights
    expected = dryden_spectra(frequency, scales, 20.0)
    # corners at V / (2 pi L): u, v 0.09 Hz, w 0.64 Hz; below 3 Hz the aliasing of sampling at 100 Hz
    # adds < 0.3 %; over five seeds the estimates scatter by 1.7 % (std), so 8 % is a 4.5-sigma bound
    for target in (0.3, 0.6, 1.2, 2.5):
        band = np.abs(frequency - target) <= 0.15      # a dozen neighbouring bins
        for axis in range(3):
            measured, reference = psd[axis][band].mean(), expected[axis][band].mean()
            assert measured == pytest.approx(reference, rel=0.08), (axis, target)


def test_mean_wind_direction_and_turbulence_axes():
    """Towards +y (direction pi/2): the mean is (0, U, 0), u gusts move along y and v gusts along -x."""
    wind = Wind(0.01, mean_speed=5.0, direction=math.pi / 2, turbulence='light',
                rng=flight_streams(3, 0).turbulence)
    gusts = DrydenTurbulence('light', 0.01, flight_streams(3, 0).turbulence, airspeed=5.0, altitude=5.0)
    for _ in range(50):
        u, v, w = gusts.step()
        air = wind.step()
        np.testing.assert_allclose(air, (-v, 5.0 + u, w), atol=1e-12)
    calm = Wind(0.01, mean_speed=4.0, direction=math.radians(30.0))
    assert calm.step() == pytest.approx((4.0 * math.cos(math.radians(30.0)), 2.0, 0.0), rel=1e-15)


def test_airspeed_is_the_mean_wind_with_a_floor():
    calm = Wind(0.01, mean_speed=0.2, turbulence='light', rng=flight_streams(0, 0).turbulence)
    assert calm.turbulence.airspeed == 1.0
    assert Wind(0.01, mean_speed=6.0, turbulence='light', rng=flight_streams(0, 0).turbulence,
                min_advection_speed=2.0).turbulence.airspeed == 6.0


def test_batch_equals_single_flights_across_block_refills():
    flights = [4, 9, 0, 17, 2, 5, 8]
    speeds = np.array([0.0, 2.0, 5.0, 8.0, 3.5, 1.0, 12.0])
    directions = np.array([0.0, 1.0, -2.0, 3.0, 0.5, -0.7, 2.2])
    batch = Wind(1e-3, mean_speed=speeds, direction=directions, turbulence='severe',
                 rng=[flight_streams(7, f).turbulence for f in flights])
    singles = [Wind(1e-3, mean_speed=float(s), direction=float(d), turbulence='severe',
                    rng=flight_streams(7, f).turbulence) for f, s, d in zip(flights, speeds, directions)]
    for _ in range(2 * BLOCK_STEPS + 5):
        air = batch.step()
        for i, single in enumerate(singles):
            np.testing.assert_allclose([a[i] for a in air], single.step(), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize('kwargs, fragment', [
    ({'turbulence': 'gale', 'rng': None}, r"wind\.turbulence: 'gale' is not a level"),
    ({'turbulence': 'light', 'rng': None}, r'wind\.rng: turbulence .light. needs a random generator'),
    ({'turbulence': 'light', 'rng': 42}, r'wind\.rng: expected a numpy Generator'),
    ({'mean_speed': -1.0}, r'wind\.mean_speed'),
    ({'mean_speed': math.nan}, r'wind\.mean_speed'),
    ({'direction': math.inf}, r'wind\.direction'),
    ({'altitude': 0.0}, r'wind\.altitude'),
    ({'min_advection_speed': 0.0}, r'wind\.min_advection_speed'),
    ({'dt': 0.0}, r'wind\.dt'),
    ({'mean_speed': np.array([1.0, 2.0]), 'turbulence': 'light',
      'rng': [np.random.default_rng(i) for i in range(3)]}, r'rng: 3 vehicles, but mean_speed has 2'),
])
def test_invalid_wind_is_refused_by_name(kwargs, fragment):
    arguments = {'dt': 0.01, **kwargs}
    with pytest.raises(ParameterError, match=fragment):
        Wind(**arguments)


def test_unknown_intensity_is_refused_by_name():
    with pytest.raises(ParameterError, match=r"turbulence: 'strong' is not an intensity"):
        low_altitude_scales('strong', 5.0)
