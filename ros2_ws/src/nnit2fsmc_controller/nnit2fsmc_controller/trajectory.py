"""Reference trajectories: sampled at time t into position, velocity, acceleration, jerk, snap and yaw.

Every trajectory has ``initial_state`` (the rest state the vehicle starts from, on the ground
under the first reference point) and ``duration`` [s] (the length of the path; after it the
reference holds the last point).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from quad_msgs_bridge.reference import ReferenceSample, hold
from quad_msgs_bridge.validation import ParameterError, check_number

Vec3 = tuple[float, float, float]


def _rest_state_below(sample: ReferenceSample) -> list[float]:
    x, y, _ = sample.position
    return [x, y, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, sample.yaw, 0.0, 0.0, 0.0]


@dataclass(frozen=True)
class Helix:
    """The paper's 3-D tracking scenario, a climbing helix with a turning heading.

    x_d = R cos(w t), y_d = R sin(w t), z_d = z0 + c t, psi_d = w t (wrapped to [-pi, pi)):
    the nose turns with the circle, so the position loop must account for yaw (eq. 10).
    Defaults: R = 1 m, w = 0.5 rad/s, z0 = 0 m, c = 0.1 m/s; the vehicle starts at rest on the
    ground at (R, 0, 0) and the reference leaves with velocity (0, R w, c). Jerk and snap are the
    analytic derivatives (R w^3 (sin, -cos), R w^4 (cos, sin)).
    """

    radius: float = 1.0        #: [m]
    angular_rate: float = 0.5  #: [rad/s]
    start_height: float = 0.0  #: [m]
    climb_rate: float = 0.1    #: [m/s]
    duration: float = 60.0     #: [s]

    def sample(self, t: float) -> ReferenceSample:
        moving = 1.0 if t <= self.duration else 0.0
        t = min(max(t, 0.0), self.duration)
        r, w = self.radius, self.angular_rate
        c, s = math.cos(w * t), math.sin(w * t)
        return ReferenceSample(
            position=(r * c, r * s, self.start_height + self.climb_rate * t),
            velocity=(-r * w * s * moving, r * w * c * moving, self.climb_rate * moving),
            acceleration=(-r * w * w * c * moving, -r * w * w * s * moving, 0.0),
            yaw=(w * t + math.pi) % (2.0 * math.pi) - math.pi,
            yaw_rate=w * moving,
            jerk=(r * w ** 3 * s * moving, -r * w ** 3 * c * moving, 0.0),
            snap=(r * w ** 4 * c * moving, r * w ** 4 * s * moving, 0.0))

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


@dataclass(frozen=True)
class Hover:
    """Take off from the ground below ``position`` and hold it [m, world ENU] at heading ``yaw`` [rad]."""

    position: Vec3 = (0.0, 0.0, 1.0)
    yaw: float = 0.0
    duration: float = 20.0

    def sample(self, t: float) -> ReferenceSample:
        return hold(self.position, self.yaw)

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


@dataclass(frozen=True)
class Steps:
    """Setpoint steps: (start time [s], position [m, world ENU], yaw [rad]) each.

    Each step is reached by a minimum-jerk transition of ``rise_time`` [s] from the previous
    setpoint: a true jump has no velocity or acceleration a controller (or a sampled setpoint
    path) could follow, a short smooth transition does.
    """

    steps: tuple[tuple[float, Vec3, float], ...] = (
        (0.0, (0.0, 0.0, 1.0), 0.0),
        (5.0, (1.0, 0.0, 1.0), 0.0),
        (10.0, (1.0, 1.0, 1.5), 0.5),
        (15.0, (0.0, 0.0, 1.0), 0.0))
    duration: float = 20.0
    rise_time: float = 2.0

    def __post_init__(self):
        times = [step[0] for step in self.steps]
        if not self.steps or times[0] != 0.0 or any(b - a <= self.rise_time for a, b in zip(times, times[1:])):
            raise ParameterError(f'steps: start times must begin at 0 and be more than rise_time '
                                 f'({self.rise_time} s) apart')
        points = [self.steps[0]]
        for (_, before, yaw_before), (t, after, yaw_after) in zip(self.steps, self.steps[1:]):
            points += [(t, before, yaw_before), (t + self.rise_time, after, yaw_after)]
        object.__setattr__(self, '_path', Waypoints(tuple(points)))

    def sample(self, t: float) -> ReferenceSample:
        return self._path.sample(t)

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


def _quintic_blend(tau: float) -> tuple[float, float, float, float, float]:
    """Minimum-jerk blend s(tau) on [0, 1] and its first four derivatives in tau; zero rate and
    acceleration at both ends."""
    s = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    ds = 30.0 * tau * tau * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    d3s = 60.0 + tau * (-360.0 + 360.0 * tau)
    d4s = -360.0 + 720.0 * tau
    return s, ds, dds, d3s, d4s


@dataclass(frozen=True)
class Waypoints:
    """Smooth minimum-jerk flight through waypoints (arrival time [s], position [m], yaw [rad]).

    Between consecutive waypoints position and yaw follow a quintic blend, so velocity and
    acceleration are continuous and zero at each waypoint.
    """

    points: tuple[tuple[float, Vec3, float], ...] = (
        (0.0, (0.0, 0.0, 1.0), 0.0),
        (4.0, (2.0, 0.0, 1.5), 0.0),
        (8.0, (2.0, 2.0, 2.0), 1.0),
        (12.0, (0.0, 2.0, 1.5), 1.5),
        (16.0, (0.0, 0.0, 1.0), 0.0))

    def __post_init__(self):
        times = [p[0] for p in self.points]
        if len(self.points) < 2 or times[0] != 0.0 or any(b <= a for a, b in zip(times, times[1:])):
            raise ParameterError('waypoints: need at least two, times starting at 0 and increasing')

    @property
    def duration(self) -> float:
        return self.points[-1][0] + 4.0

    def sample(self, t: float) -> ReferenceSample:
        if t <= self.points[0][0]:
            return hold(self.points[0][1], self.points[0][2])
        for (t0, p0, yaw0), (t1, p1, yaw1) in zip(self.points, self.points[1:]):
            if t < t1:
                span = t1 - t0
                s, ds, dds, d3s, d4s = _quintic_blend((t - t0) / span)
                delta = [b - a for a, b in zip(p0, p1)]
                return ReferenceSample(
                    position=tuple(a + s * dp for a, dp in zip(p0, delta)),
                    velocity=tuple(ds / span * dp for dp in delta),
                    acceleration=tuple(dds / (span * span) * dp for dp in delta),
                    yaw=yaw0 + s * (yaw1 - yaw0),
                    yaw_rate=ds / span * (yaw1 - yaw0),
                    yaw_acceleration=dds / (span * span) * (yaw1 - yaw0),
                    jerk=tuple(d3s / span ** 3 * dp for dp in delta),
                    snap=tuple(d4s / span ** 4 * dp for dp in delta))
        return hold(self.points[-1][1], self.points[-1][2])

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


def _compose(derivatives: tuple, phase: tuple) -> tuple:
    """Value and first four time derivatives of f(theta(t)) (Faa di Bruno's formula), from the
    derivatives (f, df, d2f, d3f, d4f) of f at theta and (theta, dtheta, ..., d4theta) at t."""
    f0, f1, f2, f3, f4 = derivatives
    _, t1, t2, t3, t4 = phase
    return (f0, f1 * t1, f2 * t1 ** 2 + f1 * t2, f3 * t1 ** 3 + 3.0 * f2 * t1 * t2 + f1 * t3,
            f4 * t1 ** 4 + 6.0 * f3 * t1 ** 2 * t2 + f2 * (3.0 * t2 ** 2 + 4.0 * t1 * t3) + f1 * t4)


def _ramped_phase(t: float, rate: float, ramp: float, duration: float) -> tuple:
    """The phase theta [rad] of a periodic path and its first four time derivatives at t [s]: the rate
    dtheta/dt rises from rest to ``rate`` w [rad/s] over ``ramp`` T [s] by a minimum-jerk profile
    (w s(t / T), s the quintic blend), then theta = w (t - T / 2); after ``duration`` [s] the phase holds."""
    held = t > duration
    t = min(max(t, 0.0), duration)
    if t >= ramp:
        phase = (rate * (t - 0.5 * ramp), rate, 0.0, 0.0, 0.0)
    else:
        tau = t / ramp
        s, ds, dds, d3s, _ = _quintic_blend(tau)
        integral = tau ** 4 * (2.5 + tau * (-3.0 + tau))     # int_0^tau s
        phase = (rate * ramp * integral, rate * s, rate * ds / ramp, rate * dds / ramp ** 2, rate * d3s / ramp ** 3)
    return (phase[0], 0.0, 0.0, 0.0, 0.0) if held else phase


@dataclass(frozen=True)
class Lemniscate:
    """An aggressive figure-eight (lemniscate of Gerono) at constant height and heading.

    x_d = a sin(theta), y_d = (a / 2) sin(2 theta), z_d = height, psi_d = yaw, with the phase theta(t)
    accelerating from rest to the rate w over ``ramp_time`` T by a minimum-jerk profile of the rate
    (:func:`_ramped_phase`), then theta = w (t - T / 2). Position, velocity,
    acceleration, jerk and snap are analytic (chain rule through the phase). Defaults: a = 2 m,
    w = 1 rad/s: peak speed a w sqrt(2) = 2.83 m/s (at the crossing), peak acceleration 2 a w^2
    = 4 m/s^2 on y. The vehicle starts at rest on the ground below (0, 0, height).
    """

    amplitude: float = 2.0      #: a [m]
    rate: float = 1.0           #: w [rad/s]
    height: float = 1.0         #: [m]
    yaw: float = 0.0            #: [rad]
    ramp_time: float = 4.0      #: T [s]
    duration: float = 40.0      #: [s]

    def sample(self, t: float) -> ReferenceSample:
        phase = _ramped_phase(t, self.rate, self.ramp_time, self.duration)
        a, theta = self.amplitude, phase[0]
        sin1, cos1, sin2, cos2 = math.sin(theta), math.cos(theta), math.sin(2.0 * theta), math.cos(2.0 * theta)
        x = _compose((a * sin1, a * cos1, -a * sin1, -a * cos1, a * sin1), phase)
        y = _compose((0.5 * a * sin2, a * cos2, -2.0 * a * sin2, -4.0 * a * cos2, 8.0 * a * sin2), phase)
        return ReferenceSample(
            position=(x[0], y[0], self.height), velocity=(x[1], y[1], 0.0), acceleration=(x[2], y[2], 0.0),
            yaw=self.yaw, jerk=(x[3], y[3], 0.0), snap=(x[4], y[4], 0.0))

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


@dataclass(frozen=True)
class Circle:
    """A fast horizontal circle at constant height and heading (the ``circle-fast`` scenario, issue 28).

    x_d = R cos(theta), y_d = R sin(theta), z_d = height, psi_d = yaw, with the phase theta(t) of
    :func:`_ramped_phase` (from rest to the rate w over ``ramp_time``). Defaults: R = 2 m,
    w = 2 pi 0.2 rad/s (one lap in 5 s): speed R w = 2.51 m/s and centripetal acceleration R w^2 = 3.16 m/s^2
    once the ramp is over, the circle of RotorPy's benchmark on which issue 28 saw a roll/pitch limit cycle
    (2.5 m/s). The heading stays at ``yaw`` (0: the nose points along world x), so every yaw error is
    a disturbance of the attitude loop. The vehicle starts at rest on the ground below (R, 0, height).
    """

    radius: float = 2.0                       #: R [m]
    rate: float = 2.0 * math.pi * 0.2         #: w [rad/s]
    height: float = 1.0                       #: [m]
    yaw: float = 0.0                          #: [rad]
    ramp_time: float = 4.0                    #: T [s]
    duration: float = 30.0                    #: [s]

    def sample(self, t: float) -> ReferenceSample:
        phase = _ramped_phase(t, self.rate, self.ramp_time, self.duration)
        r, theta = self.radius, phase[0]
        sin, cos = math.sin(theta), math.cos(theta)
        x = _compose((r * cos, -r * sin, -r * cos, r * sin, r * cos), phase)
        y = _compose((r * sin, r * cos, -r * sin, -r * cos, r * sin), phase)
        return ReferenceSample(
            position=(x[0], y[0], self.height), velocity=(x[1], y[1], 0.0), acceleration=(x[2], y[2], 0.0),
            yaw=self.yaw, jerk=(x[3], y[3], 0.0), snap=(x[4], y[4], 0.0))

    @property
    def initial_state(self) -> list[float]:
        return _rest_state_below(self.sample(0.0))


@dataclass(frozen=True)
class Shifted:
    """``trajectory`` moved by ``offset`` [m, world ENU]: every reference position and the start state's
    position shifted (a z offset starts the vehicle at rest in the air), velocities, accelerations and
    yaw unchanged. A fleet flies one shifted copy of its scenario per vehicle."""

    trajectory: object
    offset: Vec3

    @property
    def duration(self) -> float:
        return self.trajectory.duration

    def sample(self, t: float) -> ReferenceSample:
        sample = self.trajectory.sample(t)
        return sample._replace(position=tuple(p + d for p, d in zip(sample.position, self.offset)))

    @property
    def initial_state(self) -> list[float]:
        state = list(self.trajectory.initial_state)
        state[0:3] = [p + d for p, d in zip(state[0:3], self.offset)]
        return state


SCENARIOS = {'paper': Helix, 'hover': Hover, 'steps': Steps, 'waypoints': Waypoints, 'lemniscate': Lemniscate,
             'circle-fast': Circle}


def make_scenario(name: str, duration: float | None = None, offset: Vec3 = (0.0, 0.0, 0.0)):
    """The trajectory of a named scenario; ``duration`` [s] overrides the path length where it can (the
    waypoints' is fixed: only their own length is accepted, as the ROS backend passes it to every scenario);
    a non-zero ``offset`` [m, world ENU] shifts the whole scenario (see :class:`Shifted`)."""
    if name not in SCENARIOS:
        raise ParameterError(f'scenario: {name!r} is not one of {", ".join(SCENARIOS)}')
    offset = tuple(check_number(f'offset[{i}]', v) for i, v in enumerate(offset))
    if len(offset) != 3:
        raise ParameterError(f'offset: expected 3 values (x, y, z [m]), got {len(offset)}')
    if duration is None or (name == 'waypoints' and duration == Waypoints().duration):   # the length it has
        trajectory = SCENARIOS[name]()
    elif name == 'waypoints':
        raise ParameterError(f'duration: the waypoints scenario has a fixed duration of {Waypoints().duration:g} s '
                             '(set by its last waypoint)')
    else:
        trajectory = SCENARIOS[name](duration=check_number('duration', duration, 0.0, low_inclusive=False))
    return Shifted(trajectory, offset) if any(offset) else trajectory
