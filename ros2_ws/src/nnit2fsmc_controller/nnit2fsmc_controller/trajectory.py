"""Reference trajectories: sampled at time t into position, velocity, acceleration and yaw.

Every trajectory has ``initial_state`` (the rest state the vehicle starts from, on the ground
under the first reference point) and ``duration`` [s] (the length of the path; after it the
reference holds the last point).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from quad_msgs_bridge.reference import ReferenceSample, hold
from quad_msgs_bridge.vehicle_params import ParameterError, check_number

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
    ground at (R, 0, 0) and the reference leaves with velocity (0, R w, c).
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
            yaw_rate=w * moving)

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


def _quintic_blend(tau: float) -> tuple[float, float, float]:
    """Minimum-jerk blend s(tau) on [0, 1] with ds/dtau and d2s/dtau2; zero rate and acceleration at both ends."""
    s = tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    ds = 30.0 * tau * tau * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


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
                s, ds, dds = _quintic_blend((t - t0) / span)
                delta = [b - a for a, b in zip(p0, p1)]
                return ReferenceSample(
                    position=tuple(a + s * dp for a, dp in zip(p0, delta)),
                    velocity=tuple(ds / span * dp for dp in delta),
                    acceleration=tuple(dds / (span * span) * dp for dp in delta),
                    yaw=yaw0 + s * (yaw1 - yaw0),
                    yaw_rate=ds / span * (yaw1 - yaw0),
                    yaw_acceleration=dds / (span * span) * (yaw1 - yaw0))
        return hold(self.points[-1][1], self.points[-1][2])

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


SCENARIOS = {'paper': Helix, 'hover': Hover, 'steps': Steps, 'waypoints': Waypoints}


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
