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

Vec3 = tuple[float, float, float]


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


def hold(position: Sequence[float], yaw: float = 0.0) -> ReferenceSample:
    """A reference that holds ``position`` [m, world ENU] at heading ``yaw`` [rad]."""
    return ReferenceSample(tuple(float(v) for v in position), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), float(yaw))


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _quintic(p0, v0, a0, p1, v1, a1, h, s):
    """Value, rate and acceleration of the quintic Hermite interpolant at s in [0, 1] of a span h [s]."""
    s2 = s * s
    s3 = s2 * s
    s4 = s3 * s
    s5 = s4 * s
    value = ((1.0 - 10.0 * s3 + 15.0 * s4 - 6.0 * s5) * p0 + (s - 6.0 * s3 + 8.0 * s4 - 3.0 * s5) * h * v0
             + 0.5 * (s2 - 3.0 * s3 + 3.0 * s4 - s5) * h * h * a0 + 0.5 * (s3 - 2.0 * s4 + s5) * h * h * a1
             + (-4.0 * s3 + 7.0 * s4 - 3.0 * s5) * h * v1 + (10.0 * s3 - 15.0 * s4 + 6.0 * s5) * p1)
    rate = ((-30.0 * s2 + 60.0 * s3 - 30.0 * s4) * p0 / h + (1.0 - 18.0 * s2 + 32.0 * s3 - 15.0 * s4) * v0
            + 0.5 * (2.0 * s - 9.0 * s2 + 12.0 * s3 - 5.0 * s4) * h * a0 + 0.5 * (3.0 * s2 - 8.0 * s3 + 5.0 * s4) * h * a1
            + (-12.0 * s2 + 28.0 * s3 - 15.0 * s4) * v1 + (30.0 * s2 - 60.0 * s3 + 30.0 * s4) * p1 / h)
    accel = ((-60.0 * s + 180.0 * s2 - 120.0 * s3) * p0 / (h * h) + (-36.0 * s + 96.0 * s2 - 60.0 * s3) * v0 / h
             + 0.5 * (2.0 - 18.0 * s + 36.0 * s2 - 20.0 * s3) * a0 + 0.5 * (6.0 * s - 24.0 * s2 + 20.0 * s3) * a1
             + (-24.0 * s + 84.0 * s2 - 60.0 * s3) * v1 / h + (60.0 * s - 180.0 * s2 + 120.0 * s3) * p1 / (h * h))
    return value, rate, accel


def _quintic_jerk_snap(p0, v0, a0, p1, v1, a1, h, s):
    """Third and fourth time derivatives of the interpolant of :func:`_quintic` at s in [0, 1]."""
    s2 = s * s
    jerk = ((-60.0 + 360.0 * s - 360.0 * s2) * (p0 - p1) / h ** 3
            + (-36.0 + 192.0 * s - 180.0 * s2) * v0 / h ** 2 + (-24.0 + 168.0 * s - 180.0 * s2) * v1 / h ** 2
            + 0.5 * (-18.0 + 72.0 * s - 60.0 * s2) * a0 / h + 0.5 * (6.0 - 48.0 * s + 60.0 * s2) * a1 / h)
    snap = ((360.0 - 720.0 * s) * (p0 - p1) / h ** 4 + (192.0 - 360.0 * s) * v0 / h ** 3
            + (168.0 - 360.0 * s) * v1 / h ** 3 + 0.5 * (72.0 - 120.0 * s) * a0 / h ** 2
            + 0.5 * (-48.0 + 120.0 * s) * a1 / h ** 2)
    return jerk, snap


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
        if offsets[-1] < duration:
            offsets.append(duration)
        return cls([start + t for t in offsets], [trajectory.sample(t) for t in offsets])

    def sample(self, t: float) -> ReferenceSample:
        """The reference at sim time t [s]."""
        times, points = self.times, self.points
        if t < times[0] or len(times) == 1:
            return hold(points[0].position, points[0].yaw)
        if t >= times[-1]:
            return points[-1] if t == times[-1] else hold(points[-1].position, points[-1].yaw)
        i = bisect.bisect_right(times, t) - 1
        a, b = points[i], points[i + 1]
        h = times[i + 1] - times[i]
        s = (t - times[i]) / h
        ends = [(a.position[k], a.velocity[k], a.acceleration[k], b.position[k], b.velocity[k], b.acceleration[k])
                for k in range(3)]
        axes = [_quintic(*end, h, s) for end in ends]
        higher = [_quintic_jerk_snap(*end, h, s) for end in ends]
        yaw_end = a.yaw + _wrap(b.yaw - a.yaw)
        yaw, yaw_rate, yaw_acc = _quintic(a.yaw, a.yaw_rate, a.yaw_acceleration,
                                          yaw_end, b.yaw_rate, b.yaw_acceleration, h, s)
        return ReferenceSample(
            position=(axes[0][0], axes[1][0], axes[2][0]),
            velocity=(axes[0][1], axes[1][1], axes[2][1]),
            acceleration=(axes[0][2], axes[1][2], axes[2][2]),
            yaw=_wrap(yaw), yaw_rate=yaw_rate, yaw_acceleration=yaw_acc,
            jerk=(higher[0][0], higher[1][0], higher[2][0]), snap=(higher[0][1], higher[1][1], higher[2][1]))
