"""References: one instant (:class:`ReferenceSample`) and a timed path of them (:class:`SetpointPath`).

A ``setpoints`` message carries a SetpointPath: one point means "hold it"; several are a timed
path starting at the header stamp. Between points the reference is the quintic Hermite
interpolant of position, velocity and acceleration at both ends (exact for polynomials up to
degree five), so a path sampled at a modest rate reproduces a smooth trajectory to round-off.
The message carries no jerk or snap: a sampled path gives those of its interpolant (its third and
fourth derivatives), a held point zeros.
"""
from __future__ import annotations

import bisect
import math
from typing import NamedTuple, Sequence

import numpy as np
from numba import njit

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.validation import ParameterError, check_number

Vec3 = tuple[float, float, float]


#: the unit of each field of a ReferenceSample
REFERENCE_UNITS = {'position': 'm', 'velocity': 'm/s', 'acceleration': 'm/s^2', 'yaw': 'rad', 'yaw_rate': 'rad/s',
                   'yaw_acceleration': 'rad/s^2', 'jerk': 'm/s^3', 'snap': 'm/s^4'}


class ReferenceSample(NamedTuple):
    """Reference for one instant."""

    position: Vec3                 #: [m, world ENU]
    velocity: Vec3                 #: [m/s, world ENU]
    acceleration: Vec3             #: [m/s^2, world ENU]
    yaw: float                     #: [rad]
    yaw_rate: float = 0.0          #: [rad/s]
    yaw_acceleration: float = 0.0  #: [rad/s^2]
    jerk: Vec3 = (0.0, 0.0, 0.0)   #: [m/s^3, world ENU] (zeros where a source has none)
    snap: Vec3 = (0.0, 0.0, 0.0)   #: [m/s^4, world ENU] (zeros where a source has none)


_ZERO = (0.0, 0.0, 0.0)


def hold(position: Sequence[float], yaw: float = 0.0) -> ReferenceSample:
    """A reference that holds ``position`` [m, world ENU] at heading ``yaw`` [rad]; ParameterError (a
    ValueError) naming the argument unless ``position`` is 3 finite numbers and ``yaw`` one."""
    if type(position) is tuple and len(position) == 3 and type(yaw) is float:   # the usual case, per control step
        x, y, z = position
        if type(x) is float and type(y) is float and type(z) is float and math.isfinite(x + y + z + yaw):
            return ReferenceSample(position, _ZERO, _ZERO, yaw)
    if isinstance(position, (str, bytes)) or not isinstance(position, (Sequence, np.ndarray)) or len(position) != 3:
        raise ParameterError(f'position: expected 3 numbers x, y, z [m, world ENU], got {position!r}')

    def number(name: str, value) -> float:
        return check_number(name, value.item() if isinstance(value, np.generic) else value)
    point = tuple(number(f'position[{k}]', v) for k, v in enumerate(position))
    return ReferenceSample(point, _ZERO, _ZERO, number('yaw', yaw))


def _quintic_coefficients(p0, v0, a0, p1, v1, a1, h) -> tuple:
    """The quintic Hermite interpolant over a span h [s] matching value, rate and acceleration
    (p, v, a) at both ends, as (c0 .. c5, h): value = sum c_n s^n with s = (t - t0) / h in [0, 1].

    c0 .. c2 are p0, h v0 and h^2 a0 / 2; c3 .. c5 follow from the conditions at s = 1 (the classic
    Hermite basis functions, expanded in powers of s).
    """
    dp, hv0, hv1, h2a0, h2a1 = p1 - p0, h * v0, h * v1, h * h * a0, h * h * a1
    return (p0, hv0, 0.5 * h2a0,
            10.0 * dp - 6.0 * hv0 - 4.0 * hv1 - 1.5 * h2a0 + 0.5 * h2a1,
            -15.0 * dp + 8.0 * hv0 + 7.0 * hv1 + 1.5 * h2a0 - h2a1,
            6.0 * dp - 3.0 * hv0 - 3.0 * hv1 - 0.5 * h2a0 + 0.5 * h2a1, h)


@njit(cache=True, inline='always')
def _quintic(coefficients, s):
    """Value and first four time derivatives at s of the interpolant of :func:`_quintic_coefficients`
    (Horner's scheme; each s-derivative is divided by h per order)."""
    c0, c1, c2, c3, c4, c5, h = (coefficients[0], coefficients[1], coefficients[2], coefficients[3], coefficients[4],
                                 coefficients[5], coefficients[6])
    value = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
    rate = (c1 + s * (2.0 * c2 + s * (3.0 * c3 + s * (4.0 * c4 + s * 5.0 * c5)))) / h
    acceleration = (2.0 * c2 + s * (6.0 * c3 + s * (12.0 * c4 + s * 20.0 * c5))) / (h * h)
    jerk = (6.0 * c3 + s * (24.0 * c4 + s * 60.0 * c5)) / (h * h * h)
    snap = (24.0 * c4 + s * 120.0 * c5) / (h * h * h * h)
    return value, rate, acceleration, jerk, snap


@njit(cache=True)
def _quintic_channels(coefficients, s):
    """:func:`_quintic` of each channel x, y, z, yaw (the rows of ``coefficients``) at s, in one compiled
    call: a controller samples its path every control step."""
    return (_quintic(coefficients[0], s), _quintic(coefficients[1], s), _quintic(coefficients[2], s),
            _quintic(coefficients[3], s))


class SetpointPath:
    """Reference points at increasing sim times [s]; sampled at any time by quintic Hermite interpolation.

    Before the first point the first point is held (at rest), after the last the last one is;
    a path of a single point is held from the start.
    """

    def __init__(self, times: Sequence[float], points: Sequence[ReferenceSample]):
        if not points or len(times) != len(points):
            raise ValueError(f'a setpoint path needs as many times as points (got {len(times)}, {len(points)})')
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError('setpoint times must increase strictly')
        for point in points:
            values = (*point.position, *point.velocity, *point.acceleration,
                      point.yaw, point.yaw_rate, point.yaw_acceleration)
            if not all(map(math.isfinite, values)):
                raise ValueError(f'non-finite setpoint {point}')
        self.times = [float(t) for t in times]
        self.points = list(points)
        self._segment, self._coefficients = None, None   #: the last span sampled, and its interpolant

    @property
    def start(self) -> float:
        return self.times[0]

    @property
    def end(self) -> float:
        return self.times[-1]

    @classmethod
    def sampled(cls, trajectory, start: float, duration: float, rate: float) -> 'SetpointPath':
        """``trajectory`` (anything with ``sample(t)``) sampled every 1/rate [s] over [0, duration], shifted to ``start``."""
        count = max(1, int(math.floor(duration * rate + 1e-9))) + 1
        offsets = [k / rate for k in range(count)]
        if duration - offsets[-1] > 1e-9:   # more than a stamp's resolution (1 ns) short: add the end
            offsets.append(duration)
        else:                               # on it up to round-off (0.7 vs 700 * 0.001): end exactly there
            offsets[-1] = duration
        return cls([start + t for t in offsets], [trajectory.sample(t) for t in offsets])

    def sample(self, t: float) -> ReferenceSample:
        """The reference at sim time t [s]."""
        times, points = self.times, self.points
        if t < times[0] or len(times) == 1:
            return hold(points[0].position, points[0].yaw)
        if t >= times[-1]:
            return points[-1] if t == times[-1] else hold(points[-1].position, points[-1].yaw)
        i = bisect.bisect_right(times, t) - 1
        if i != self._segment:
            self._segment, self._coefficients = i, self._segment_coefficients(i)
        s = (t - times[i]) / (times[i + 1] - times[i])
        (x, vx, ax, jx, sx), (y, vy, ay, jy, sy), (z, vz, az, jz, sz), (yaw, yaw_rate, yaw_acc, _, _) = \
            _quintic_channels(self._coefficients, s)
        return ReferenceSample((x, y, z), (vx, vy, vz), (ax, ay, az), wrap_angle(yaw), yaw_rate, yaw_acc,
                               (jx, jy, jz), (sx, sy, sz))

    def _segment_coefficients(self, i: int) -> np.ndarray:
        """One row per channel x, y, z, yaw: the interpolant's coefficients between points i and i + 1
        (:func:`_quintic_coefficients`); the yaw takes the short way round."""
        a, b = self.points[i], self.points[i + 1]
        h = self.times[i + 1] - self.times[i]
        axes = tuple(_quintic_coefficients(a.position[k], a.velocity[k], a.acceleration[k],
                                           b.position[k], b.velocity[k], b.acceleration[k], h) for k in range(3))
        yaw = _quintic_coefficients(a.yaw, a.yaw_rate, a.yaw_acceleration, a.yaw + wrap_angle(b.yaw - a.yaw),
                                    b.yaw_rate, b.yaw_acceleration, h)
        return np.array((*axes, yaw))
