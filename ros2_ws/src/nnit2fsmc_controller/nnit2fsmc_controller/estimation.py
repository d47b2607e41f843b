"""Complementary filter of the measured position and Euler angles (controller-side measurement filtering).

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

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.vehicle_params import check_number

#: (filtered component, its rate) in the controller's 12-state x y z vx vy vz phi theta psi dphi dtheta dpsi
PAIRS = ((0, 3), (1, 4), (2, 5), (6, 9), (7, 10), (8, 11))
YAW = 8


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
        state = list(state)
        rates = [state[rate] for _, rate in PAIRS]
        if self._estimate is None:
            estimate = [state[q] for q, _ in PAIRS]
        else:
            estimate = []
            for (q, _), previous, old_rate, rate in zip(PAIRS, self._estimate, self._rates, rates):
                predicted = previous + 0.5 * self.dt * (old_rate + rate)
                innovation = state[q] - predicted
                if q == YAW:
                    innovation = wrap_angle(innovation)
                estimate.append(predicted + self.blend * innovation)
            estimate[-1] = wrap_angle(estimate[-1])
        self._estimate, self._rates = estimate, rates
        for (q, _), value in zip(PAIRS, estimate):
            state[q] = value
        return state


#: the measured world velocities vx, vy, vz [m/s] in the controller's 12-state
VELOCITIES = (3, 4, 5)


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
        state = list(state)
        measured = [state[i] for i in VELOCITIES]
        if self._velocity is None:
            velocity = measured
        else:
            velocity = [old + self.blend * (new - old) for old, new in zip(self._velocity, measured)]
        self._velocity = velocity
        for i, value in zip(VELOCITIES, velocity):
            state[i] = value
        return state
