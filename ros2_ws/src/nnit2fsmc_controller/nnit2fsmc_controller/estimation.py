"""The measurement stage: what every controller kind reads, the measured 12-state through the same filters.

:class:`MeasurementStage` passes a measured state through the complementary filter of position and
Euler angles (:class:`ComplementaryFilter`), then through the low-pass of the velocities
(:class:`VelocityFilter`), each only when its frequency is positive. It sits between the
measurement and the control law, in the closed loop and in the ROS controller node alike, with the
gains ``common.measurement_filter_hz`` and ``common.velocity_filter_hz`` for every controller kind:
a comparison of controllers is a comparison of control laws, not of pipelines.

Complementary filter of the measured position and Euler angles.

The sliding surfaces S = de + lambda e take the position and angle errors with gain lambda, so
white noise on the measured position [m] and angles [rad] reaches the controls at the full control
rate. The filter keeps the measured velocities and Euler rates as they are and replaces position
and angles by

    q_hat(k) = q_hat(k-1) + dt (dq(k-1) + dq(k)) / 2          (integrate the measured rate)
    q_hat(k) += b (q(k) - q_hat(k)),  b = w dt / (1 + w dt),   w = 2 pi crossover_hz

(a complementary filter: low frequencies from the position/angle measurement, high frequencies
from the integrated rate; with exact rates q_hat follows q without lag, so it costs no phase in
the loop, unlike a low-pass of the controls). The yaw innovation is wrapped to [-pi, pi).
Every state component is a float (one vehicle) or a numpy array (a batch).
"""
from __future__ import annotations

import math

from numba import njit

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.validation import check_number

#: (filtered component, its rate) in the controller's 12-state x y z vx vy vz phi theta psi dphi dtheta dpsi
PAIRS = ((0, 3), (1, 4), (2, 5), (6, 9), (7, 10), (8, 11))


def first_order_blend(dt: float, frequency_hz: float, key: str) -> tuple[float, float]:
    """(dt, b): the checked sample time dt [s] and the blend b = w dt / (1 + w dt), w = 2 pi frequency_hz,
    of a discrete first-order filter x(k) = x(k-1) + b (u(k) - x(k-1)); ``key`` names the frequency's gain."""
    dt = check_number('dt', dt, 0.0, low_inclusive=False)
    omega = 2.0 * math.pi * check_number(key, frequency_hz, 0.0, low_inclusive=False)
    return dt, omega * dt / (1.0 + omega * dt)


class ComplementaryFilter:
    """filter(state) -> the state with position and Euler angles filtered (see the module docstring)."""

    STATE = ('_estimate', '_rates')   #: what a retune keeps (nnit2fsmc_controller.tuning)

    def __init__(self, dt: float, crossover_hz: float):
        self.dt, self.blend = first_order_blend(dt, crossover_hz, 'measurement_filter_hz')
        self._estimate = None
        self._rates = None

    def __call__(self, state) -> list:
        state = tuple(state)
        if self._estimate is None:
            self._estimate, self._rates = tuple(state[q] for q, _ in PAIRS), tuple(state[rate] for _, rate in PAIRS)
            return list(state)
        filtered, self._estimate, self._rates = _complementary_step(state, self._estimate, self._rates, self.dt,
                                                                    self.blend)
        return list(filtered)


@njit(cache=True, inline='always')
def _blended(measured, previous, old_rate, rate, dt, blend, wrapped):
    """One filtered component: the estimate predicted by the trapezoid of the rates, corrected by ``blend``
    of the innovation (wrapped to [-pi, pi) for the yaw, and so is its estimate)."""
    predicted = previous + 0.5 * dt * (old_rate + rate)
    innovation = measured - predicted
    if wrapped:
        return wrap_angle(predicted + blend * wrap_angle(innovation))
    return predicted + blend * innovation


@njit(cache=True, error_model='numpy')
def _complementary_step(state, estimate, old_rates, dt, blend):
    """(filtered 12-state, new estimate of x y z phi theta psi, their rates) after one sample (floats, or
    arrays for a batch): the module docstring's filter."""
    rates = (state[3], state[4], state[5], state[9], state[10], state[11])
    x = _blended(state[0], estimate[0], old_rates[0], rates[0], dt, blend, False)
    y = _blended(state[1], estimate[1], old_rates[1], rates[1], dt, blend, False)
    z = _blended(state[2], estimate[2], old_rates[2], rates[2], dt, blend, False)
    phi = _blended(state[6], estimate[3], old_rates[3], rates[3], dt, blend, False)
    theta = _blended(state[7], estimate[4], old_rates[4], rates[4], dt, blend, False)
    psi = _blended(state[8], estimate[5], old_rates[5], rates[5], dt, blend, True)
    filtered = (x, y, z, state[3], state[4], state[5], phi, theta, psi, state[9], state[10], state[11])
    return filtered, (x, y, z, phi, theta, psi), rates


class VelocityFilter:
    """filter(state) -> the state with the measured world velocities vx, vy, vz [m/s] low-passed.

    In S = de + lambda e the velocity error is the derivative action of the position subsystems
    (x, y: the desired tilt, and through its filtered derivative the attitude surfaces; z: U1), so
    velocity noise reaches the controls at the full control rate. The first-order low-pass

        v_hat(k) = v_hat(k-1) + b (v(k) - v_hat(k-1)),  b = w dt / (1 + w dt),  w = 2 pi cutoff_hz

    is the usual filter of a derivative term (Astrom & Murray, *Feedback Systems*, 2008, sec. 10.5);
    at a cutoff well above the position loops' bandwidth (about 1 Hz) its lag costs them little
    phase. The Euler rates are not filtered: the attitude loops are faster, and their lag would cost
    delay margin. The first sample passes unchanged.
    """

    STATE = ('_velocity',)   #: what a retune keeps (nnit2fsmc_controller.tuning)

    def __init__(self, dt: float, cutoff_hz: float):
        self.dt, self.blend = first_order_blend(dt, cutoff_hz, 'velocity_filter_hz')
        self._velocity = None

    def __call__(self, state) -> list:
        state = tuple(state)
        if self._velocity is None:
            self._velocity = state[3:6]
            return list(state)
        filtered = _velocity_step(state, self._velocity, self.blend)
        self._velocity = filtered[3:6]
        return list(filtered)


@njit(cache=True, error_model='numpy')
def _velocity_step(state, velocity, blend):
    """The 12-state with vx, vy, vz low-passed from the last estimate ``velocity`` (floats, or arrays for a batch)."""
    vx = velocity[0] + blend * (state[3] - velocity[0])
    vy = velocity[1] + blend * (state[4] - velocity[1])
    vz = velocity[2] + blend * (state[5] - velocity[2])
    return (state[0], state[1], state[2], vx, vy, vz, state[6], state[7], state[8], state[9], state[10], state[11])


class MeasurementStage:
    """stage(state) -> the 12-state a controller reads: the measured ``state`` (x y z [m, world ENU],
    vx vy vz [m/s, world], phi theta psi [rad], their rates [rad/s]) through the complementary filter
    (crossover ``measurement_filter_hz`` [Hz], 0: none), then the velocity filter (cutoff
    ``velocity_filter_hz`` [Hz], 0: none), at the control period ``dt`` [s]. With both 0 it returns
    the measurement unchanged. The same stage serves every controller kind (module docstring).

    A non-finite measurement raises ValueError before any filter takes it in (their estimates stay
    as they were)."""

    STATE = ()   #: its state lives in its filters (nnit2fsmc_controller.tuning)

    def __init__(self, dt: float, measurement_filter_hz: float = 0.0, velocity_filter_hz: float = 0.0):
        dt = check_number('dt', dt, 0.0, low_inclusive=False)
        self.complementary = (ComplementaryFilter(dt, measurement_filter_hz)
                              if check_number('measurement_filter_hz', measurement_filter_hz, 0.0) > 0.0 else None)
        self.velocity = (VelocityFilter(dt, velocity_filter_hz)
                         if check_number('velocity_filter_hz', velocity_filter_hz, 0.0) > 0.0 else None)

    @property
    def filters(self) -> tuple:
        """The filters it applies, in order."""
        return tuple(f for f in (self.complementary, self.velocity) if f is not None)

    def __call__(self, state) -> list:
        filters = self.filters
        if not filters:
            return list(state)
        if not namespace_for(state[0]).all_finite(state):
            raise ValueError('measurement stage: non-finite measured state')
        for stage_filter in filters:
            state = stage_filter(state)
        return list(state)
