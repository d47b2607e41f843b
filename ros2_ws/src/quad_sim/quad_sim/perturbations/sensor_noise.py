"""Sensor noise: white Gaussian noise plus a constant per-flight bias on the odometry the controller sees.

Defined on the controller's 12-state (:mod:`quad_msgs_bridge.state`), component by component:

==============  ==============================  ==========================================
quantity        where the error is added        unit
==============  ==============================  ==========================================
position        x, y, z                         [m, world ENU]
velocity        vx, vy, vz                      [m/s, world ENU]
attitude        phi, theta, psi (Euler angles)  [rad]
body rate       p, q, r                         [rad/s, body FLU], like a gyro
==============  ==============================  ==========================================

The state carries Euler-angle rates (indices 9-11), not body rates, so the body-rate error goes
where a gyro's goes: the true Euler rates become body rates with the true attitude, the error is
added to those, and they become Euler rates again with the *measured* attitude, exactly as the
controller turns a noisy ``nav_msgs/Odometry`` into its state (``state_from_odometry``,
exact conversions of :mod:`quad_msgs_bridge.frames`). Velocity errors are in the world frame (for
isotropic white noise the frame does not matter; a velocity bias is then a world-frame bias).
The yaw angle is not re-wrapped (the controllers wrap the yaw error).

Each error of each component is independent: the noise is N(0, std^2) drawn anew at every
measurement (every control step), the bias N(0, bias_std^2) drawn once per flight. The noise and
the bias draw from two separate streams (``sensor_noise`` and ``sensor_bias`` of
:func:`~.streams.flight_streams`). Standard deviations are a modelling input, no standard: the
campaign spec gives them (e.g. 1 cm, 0.01 rad, a motion-capture or VIO grade).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

from quad_msgs_bridge.frames import body_rates_from_euler_rates, euler_rates_from_body_rates
from quad_msgs_bridge.validation import check_values

from .streams import StandardNormals, check_batch, check_rng


@dataclass(frozen=True)
class SensorErrors:
    """One standard deviation per measured quantity, the same on each of its three axes.

    Each may be a float or an array of shape (B,) (one value per vehicle); all >= 0.
    """

    position: float = 0.0    #: [m]
    velocity: float = 0.0    #: [m/s]
    attitude: float = 0.0    #: [rad]
    body_rate: float = 0.0   #: [rad/s]

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, check_values(f'sensor_noise.{f.name}', getattr(self, f.name), 0.0))

    def per_component(self) -> tuple:
        """The 12 standard deviations in the order x, y, z, vx, vy, vz, phi, theta, psi, p, q, r."""
        return tuple(value for value in (self.position, self.velocity, self.attitude, self.body_rate)
                     for _ in range(3))


class SensorNoise:
    """What the controller sees of the true state: ``measure(state)`` adds noise and bias.

    ``noise_rng``, ``bias_rng``: one Generator each for one vehicle (the state's components are
    floats), or a list of B Generators each for a batch (components are arrays of shape (B,)).
    ``bias`` holds the 12 drawn biases (floats, or arrays for a batch). 12 standard normals per call.
    """

    def __init__(self, noise: SensorErrors, bias: SensorErrors, noise_rng, bias_rng):
        noise_rng = check_rng('sensor_noise.noise_rng', noise_rng)
        bias_rng = check_rng('sensor_noise.bias_rng', bias_rng)
        stds = {f'{kind}.{f.name}': getattr(errors, f.name)
                for kind, errors in (('noise', noise), ('bias', bias)) for f in fields(errors)}
        check_batch(noise_rng=noise_rng, bias_rng=bias_rng, **stds)
        self._std = noise.per_component()
        bias_draws = StandardNormals(bias_rng, 12).next()
        self.bias = tuple(std * z for std, z in zip(bias.per_component(), bias_draws))
        self._draws = StandardNormals(noise_rng, 12)

    def measure(self, state) -> list:
        """The state as measured: position, velocity and Euler angles plus error; Euler rates from the
        true body rates plus error, converted with the measured attitude."""
        z = self._draws.next()
        error = [b + std * n for b, std, n in zip(self.bias, self._std, z)]
        measured = [state[i] + error[i] for i in range(9)]
        body = body_rates_from_euler_rates(state[6:9], state[9:12])
        measured_body = [rate + e for rate, e in zip(body, error[9:])]
        return measured + list(euler_rates_from_body_rates(measured[6:9], measured_body))
