"""Wind: a mean wind plus Dryden turbulence, as the air velocity the vehicle flies in.

Air velocity [m/s, world ENU] = mean wind + turbulence, held over each physics step, turned into a
force by the vehicle's ``wind_drag`` coefficient (:class:`~quad_msgs_bridge.vehicle_params.VehicleParams`):
F = wind_drag (w_air - v) [N, world ENU] (:meth:`quad_sim.model.QuadrotorModel.step`).

Mean wind: speed U [m/s] and ``direction`` [rad], the direction the air moves *towards*, measured
in the world x-y plane from +x (east) towards +y (north); a meteorological "wind from" bearing is
a different convention. No vertical mean wind.

Turbulence: the Dryden model of MIL-F-8785C (also in MIL-HDBK-1797), low-altitude
form (below 1000 ft). The standard, with the altitude h and the scales L in feet:

- intensities from the wind speed at 20 ft, W20 = 15 / 30 / 45 knots (light / moderate / severe):
  sigma_w = 0.1 W20, sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4;
- scales L_w = h, L_u = L_v = h / (0.177 + 0.000823 h)^1.2;
- spectra over the circular frequency omega [rad/s], one-sided (their integral over [0, inf) is
  sigma^2), with the airspeed V:
  Phi_u(omega) = sigma_u^2 (2 L_u / (pi V)) / (1 + (L_u omega / V)^2),
  Phi_v(omega) = sigma_v^2 (L_v / (pi V)) (1 + 3 (L_v omega / V)^2) / (1 + (L_v omega / V)^2)^2,
  Phi_w likewise with sigma_w, L_w; i.e. white noise through the filters
  H_u = sigma_u sqrt(2 L_u / (pi V)) / (1 + (L_u / V) s) and
  H_v = sigma_v sqrt(L_v / (pi V)) (1 + sqrt(3) (L_v / V) s) / (1 + (L_v / V) s)^2.

In SI units (h in m, 1 ft = 0.3048 m exactly): L_w = h, L_u = L_v = h / (0.177 + 0.0027001 h)^1.2,
sigma_u = sigma_v = sigma_w / (0.177 + 0.0027001 h)^0.4, sigma_w = 0.1 W20 with 1 knot =
1852/3600 m/s (sigma_w = 0.772 / 1.543 / 2.315 m/s).

Choices made here:

- Reference altitude ``altitude`` [m] (default 5 m, a small quadrotor's working height), one value
  per flight, not the vehicle's changing height; clamped to the standard's low-altitude range
  [10 ft, 1000 ft] = [3.048 m, 304.8 m].
- Airspeed V that advects the frozen turbulence past the vehicle (Taylor's hypothesis): the mean
  wind speed, floored at ``min_advection_speed`` (default 1 m/s), below which the correlation
  times L/V grow without bound. The vehicle's own speed is not added.
- Axes: u along the mean wind direction, v horizontal to its left, w up (the standard's low-altitude
  turbulence is aligned with the mean wind; the sign of a zero-mean symmetric gust is immaterial).
- Discretisation: exact. Each filter is a linear stochastic differential equation driven by white
  noise; over a physics step dt its state transition is the matrix exponential and its added noise
  has the exact covariance integral (computed in closed form), so the samples at the physics
  instants have exactly the continuous process's autocovariance for any dt; the air velocity is
  then held over the step. The filters start in their stationary distribution (no transient).
"""
from __future__ import annotations

import math
from typing import NamedTuple

from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.validation import ParameterError, check_number, check_values

from .streams import StandardNormals, check_batch, check_rng

KNOT = 1852.0 / 3600.0   #: [m/s] one knot (exact)
FOOT = 0.3048            #: [m] one foot (exact)
#: MIL-F-8785C low-altitude turbulence: wind speed at 20 ft [knots] of each intensity.
W20_KNOTS = {'light': 15.0, 'moderate': 30.0, 'severe': 45.0}
TURBULENCE_LEVELS = ('none', *W20_KNOTS)
ALTITUDE_RANGE = (10.0 * FOOT, 1000.0 * FOOT)   #: [m] where the low-altitude form is defined
DEFAULT_ALTITUDE = 5.0                          #: [m]
DEFAULT_MIN_ADVECTION_SPEED = 1.0               #: [m/s]
_SQRT3 = math.sqrt(3.0)


class DrydenScales(NamedTuple):
    """Intensities [m/s] and scale lengths [m] of the three gust components."""

    sigma_u: float
    sigma_v: float
    sigma_w: float
    length_u: float
    length_v: float
    length_w: float


def low_altitude_scales(intensity: str, altitude) -> DrydenScales:
    """MIL-F-8785C low-altitude intensities and scales at ``altitude`` [m] (clamped to [10, 1000] ft)."""
    if intensity not in W20_KNOTS:
        raise ParameterError(f'turbulence: {intensity!r} is not an intensity (valid: {", ".join(W20_KNOTS)})')
    h = namespace_for(altitude).clip(altitude, *ALTITUDE_RANGE)
    base = 0.177 + 0.000823 * (h / FOOT)       # the standard's formula takes h in feet
    sigma_w = 0.1 * W20_KNOTS[intensity] * KNOT
    sigma_uv = sigma_w / base ** 0.4
    length_uv = h / base ** 1.2               # h / base^1.2 is in the unit of h
    return DrydenScales(sigma_uv, sigma_uv, sigma_w, length_uv, length_uv, h)


def _exponential_moments(x):
    """(g0, g1, g2) with g_n(x) = integral over [0, 1] of u^n exp(-x u) du, for x >= 0.

    A power series below x = 1 (where the closed forms cancel catastrophically), the closed forms
    g0 = (1 - e^-x) / x, g_n = (n g_(n-1) - e^-x) / x from x = 1 on.
    """
    xp = namespace_for(x)
    series = [0.0, 0.0, 0.0]
    term = 1.0                       # (-x)^k / k!
    for k in range(22):              # x < 1: the first omitted term is below 1 / 22! ~ 1e-21
        series = [total + term / (n + k + 1) for n, total in enumerate(series)]
        term = term * -x / (k + 1)
    small = x < 1.0
    y = xp.where(small, 1.0, x)
    decay = xp.exp(-y)
    g0 = -xp.expm1(-y) / y
    g1 = (g0 - decay) / y
    g2 = (2.0 * g1 - decay) / y
    return tuple(xp.where(small, s, c) for s, c in zip(series, (g0, g1, g2)))


def first_order_step(tau):
    """(decay, gain) of the unit-variance Dryden u filter over a step of tau = V dt / L:
    eta' = decay eta + gain z, z standard normal (exact: an Ornstein-Uhlenbeck process)."""
    xp = namespace_for(tau)
    return xp.exp(-tau), xp.sqrt(-xp.expm1(-2.0 * tau))


def second_order_step(tau):
    """Exact step of the Dryden v/w filter over tau = V dt / L, in unit-variance coordinates.

    Realisation: x1' = x2, x2' = -a^2 x1 - 2 a x2 + white noise (a = V / L), gust = sigma a^1.5
    (x1 + sqrt(3) x2 / a), i.e. sigma sqrt(L / V) (1 + sqrt(3) (L/V) s) / (1 + (L/V) s)^2. Scaled
    to xi1 = 2 a^1.5 x1, xi2 = 2 a^0.5 x2 the stationary covariance is the identity and the gust is
    sigma (xi1 + sqrt(3) xi2) / 2. Returns the transition exp(A dt) in these coordinates,
    M = e^-tau [[1 + tau, tau], [-tau, 1 - tau]], and the Cholesky factor (l11, l21, l22) of the
    added noise covariance Q = integral over [0, dt] of exp(A s) B B^T exp(A^T s) ds, written with
    the moments g_n(2 tau): Q11 = 4 tau^3 g2, Q12 = 4 (tau^2 g1 - tau^3 g2),
    Q22 = 4 (tau g0 - 2 tau^2 g1 + tau^3 g2).
    """
    xp = namespace_for(tau)
    decay = xp.exp(-tau)
    g0, g1, g2 = _exponential_moments(2.0 * tau)
    tau2, tau3 = tau * tau, tau * tau * tau
    q11 = 4.0 * tau3 * g2
    q12 = 4.0 * (tau2 * g1 - tau3 * g2)
    q22 = 4.0 * (tau * g0 - 2.0 * tau2 * g1 + tau3 * g2)
    l11 = xp.sqrt(q11)
    l21 = q12 / l11
    l22 = xp.sqrt(q22 - l21 * l21)
    transition = (decay * (1.0 + tau), decay * tau, -decay * tau, decay * (1.0 - tau))
    return transition, (l11, l21, l22)


class DrydenTurbulence:
    """Dryden gust velocities (u along the mean wind, v to its left, w up) [m/s], one value per step.

    ``rng``: a Generator (one vehicle: floats) or a list of B Generators (a batch: arrays of shape
    (B,)); ``airspeed`` V [m/s] (advects the turbulence) and ``altitude`` [m] may be floats or
    per-vehicle arrays. Five standard normals per step (u: 1, v: 2, w: 2).
    """

    def __init__(self, intensity: str, dt: float, rng, airspeed, altitude=DEFAULT_ALTITUDE):
        dt = check_number('dt', dt, 0.0, low_inclusive=False)
        altitude = check_values('altitude', altitude, 0.0, low_inclusive=False)
        airspeed = check_values('airspeed', airspeed, 0.0, low_inclusive=False)
        check_batch(rng=check_rng('rng', rng), altitude=altitude, airspeed=airspeed)
        self.scales = low_altitude_scales(intensity, altitude)
        self.airspeed = airspeed
        sc = self.scales
        self._u = first_order_step(airspeed * dt / sc.length_u)
        self._v = second_order_step(airspeed * dt / sc.length_v)
        self._w = second_order_step(airspeed * dt / sc.length_w)
        self._draws = StandardNormals(rng, 5)
        self._eta, xi_v1, xi_v2, xi_w1, xi_w2 = self._draws.next()   # stationary start: unit variances
        self._xi_v, self._xi_w = (xi_v1, xi_v2), (xi_w1, xi_w2)

    def step(self) -> tuple:
        """The gust (u, v, w) [m/s] to hold over the coming physics step; then advance by one step."""
        sc = self.scales
        gust = (sc.sigma_u * self._eta,
                0.5 * sc.sigma_v * (self._xi_v[0] + _SQRT3 * self._xi_v[1]),
                0.5 * sc.sigma_w * (self._xi_w[0] + _SQRT3 * self._xi_w[1]))
        z_u, z_v1, z_v2, z_w1, z_w2 = self._draws.next()
        decay, gain = self._u
        self._eta = decay * self._eta + gain * z_u
        self._xi_v = _advance(self._v, self._xi_v, z_v1, z_v2)
        self._xi_w = _advance(self._w, self._xi_w, z_w1, z_w2)
        return gust


def _advance(step, xi, z1, z2):
    (m11, m12, m21, m22), (l11, l21, l22) = step
    return (m11 * xi[0] + m12 * xi[1] + l11 * z1,
            m21 * xi[0] + m22 * xi[1] + l21 * z1 + l22 * z2)


class Wind:
    """Air velocity [m/s, world ENU] per physics step: mean wind plus optional Dryden turbulence.

    ``mean_speed`` [m/s] >= 0 and ``direction`` [rad] (towards which the air moves, from +x towards
    +y) may be floats or per-vehicle arrays. ``turbulence``: 'none', 'light', 'moderate' or
    'severe'; any but 'none' needs ``rng`` (one Generator, or a list of one per vehicle: use the
    ``turbulence`` stream of :func:`~.streams.flight_streams`). With turbulence 'none' and a zero
    mean the air is still, and the vehicle still feels the drag of moving through it.
    """

    def __init__(self, dt: float, mean_speed=0.0, direction=0.0, turbulence: str = 'none', rng=None,
                 altitude=DEFAULT_ALTITUDE, min_advection_speed: float = DEFAULT_MIN_ADVECTION_SPEED):
        check_number('wind.dt', dt, 0.0, low_inclusive=False)
        mean_speed = check_values('wind.mean_speed', mean_speed, 0.0)
        direction = check_values('wind.direction', direction)
        altitude = check_values('wind.altitude', altitude, 0.0, low_inclusive=False)
        min_advection_speed = check_number('wind.min_advection_speed', min_advection_speed, 0.0,
                                           low_inclusive=False)
        if turbulence not in TURBULENCE_LEVELS:
            raise ParameterError(f'wind.turbulence: {turbulence!r} is not a level '
                                 f'(valid: {", ".join(TURBULENCE_LEVELS)})')
        check_batch(mean_speed=mean_speed, direction=direction)
        xp = namespace_for(mean_speed, direction)
        self._along = (xp.cos(direction), xp.sin(direction))
        self.mean = (mean_speed * self._along[0], mean_speed * self._along[1], 0.0)
        self.turbulence = None
        if turbulence != 'none':
            if rng is None:
                raise ParameterError(f'wind.rng: turbulence {turbulence!r} needs a random generator (the flight\'s '
                                     f'turbulence stream)')
            check_batch(mean_speed=mean_speed, direction=direction, rng=check_rng('wind.rng', rng))
            airspeed = xp.where(mean_speed > min_advection_speed, mean_speed, min_advection_speed)
            self.turbulence = DrydenTurbulence(turbulence, dt, rng, airspeed, altitude)

    def step(self) -> tuple:
        """Air velocity (w_x, w_y, w_z) [m/s, world ENU] to hold over the coming physics step."""
        if self.turbulence is None:
            return self.mean
        u, v, w = self.turbulence.step()
        cos_d, sin_d = self._along
        return (self.mean[0] + cos_d * u - sin_d * v, self.mean[1] + sin_d * u + cos_d * v, w)
