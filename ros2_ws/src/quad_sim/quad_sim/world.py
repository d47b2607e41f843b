"""The world a flight flies in, described once for a single flight and for a campaign alike
(docs/PERTURBATIONS.md): the air (mean wind, the direction it blows towards, Dryden turbulence), the
sensors (white noise and a per-flight bias on what the controller reads), the actuators (transport delay,
first-order motor lag) and the true vehicle with its changes in flight.

:func:`parse_world` checks the world's keys, as a campaign spec and ``fly()`` both write them (``wind``,
``sensor_noise``, ``delay_s``, ``motor_time_constant_s``), into a :class:`World`. :func:`build_perturbations`
turns a world and the true vehicles of one flight or of a batch into the :class:`Perturbations` the simulator
and the closed loop step. Everything random about flight k of seed s comes from the streams of
``quad_sim.perturbations.streams.flight_stream(s, k, purpose)``: a flight's world depends on (s, k) only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from quad_msgs_bridge.validation import ParameterError, check_keys, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams

from .perturbations.actuation import MotorLag, TransportDelay
from .perturbations.sensor_noise import SensorErrors, SensorNoise
from .perturbations.streams import flight_stream
from .perturbations.vehicle_change import VehicleChange, vehicle_change
from .perturbations.wind import Wind

#: the keys of fly()'s mid-flight vehicle changes -> (VehicleParams field, how to check the value)
CHANGE_KEYS = {'mass_change': ('mass_kg', 'm'), 'rotor_efficiency_loss': ('loss', 'rotor_efficiency_loss')}
#: the keys that describe the world, in a campaign spec and among fly()'s arguments
WORLD_KEYS = ('wind', 'sensor_noise', 'delay_s', 'motor_time_constant_s')
TURBULENCE = ('none', 'light', 'moderate', 'severe')
WIND_KEYS = ('mean_speed_mps', 'turbulence', 'direction_deg')
#: sensor_noise key -> the odometry part it perturbs (SensorErrors field)
NOISE_FIELDS = {'position_m': 'position', 'velocity_mps': 'velocity', 'attitude_rad': 'attitude',
                'body_rate_radps': 'body_rate'}
NOISE_KEYS = tuple(NOISE_FIELDS)


@dataclass(frozen=True)
class NoiseLevel:
    """White-noise standard deviation and per-flight bias standard deviation of one odometry part."""

    std: float = 0.0
    bias_std: float = 0.0


@dataclass(frozen=True)
class Range:
    """A value drawn per flight, uniformly in [low, high] (SI units)."""

    low: float
    high: float

    def draw(self, u: float) -> float:
        """The value of a standard uniform number u in [0, 1)."""
        return self.low + u * (self.high - self.low)


@dataclass(frozen=True)
class World:
    """The air, sensors and actuators of a flight (SI units); the defaults are the nominal world."""

    wind_mean_speed_mps: float = 0.0          #: [m/s] mean wind speed
    wind_direction_deg: float | None = None   #: [deg] towards which it blows, from +x (east) counter-clockwise;
                                              #: None: drawn per flight
    turbulence: str = 'none'                  #: Dryden turbulence level (TURBULENCE)
    sensor_noise: Mapping[str, NoiseLevel] = field(default_factory=dict)   #: NOISE_KEYS -> level
    delay_s: float | Range = 0.0              #: [s] transport delay of the rotor commands (a Range: drawn per flight)
    motor_time_constant_s: float | Range = 0.0   #: [s] first-order lag of every rotor's thrust (likewise)

    @property
    def has_wind(self) -> bool:
        return self.wind_mean_speed_mps > 0.0 or self.turbulence != 'none'

    @property
    def is_nominal(self) -> bool:
        """Whether nothing perturbs the air, the sensors or the actuators."""
        return not (self.has_wind or self.sensor_noise or _largest(self.delay_s) or _largest(self.motor_time_constant_s))

    def actuator(self, seed: int, flight: int, control_dt: float) -> tuple[float, float]:
        """Flight ``flight``'s motor time constant [s] and transport delay [s, a whole number of control steps of
        ``control_dt`` s]: the world's, or drawn from the flight's ``actuator`` stream when a :class:`Range` (two
        uniform numbers, lag then delay, whichever is drawn; the delay's whole steps equally likely)."""
        u_lag, u_delay = (flight_stream(seed, flight, 'actuator').random(2).tolist()
                          if isinstance(self.delay_s, Range) or isinstance(self.motor_time_constant_s, Range)
                          else (0.0, 0.0))
        lag = self.motor_time_constant_s
        lag = lag.draw(u_lag) if isinstance(lag, Range) else lag
        delay = self.delay_s
        if isinstance(delay, Range):
            fewest = math.ceil(delay.low / control_dt - 1e-6)
            most = math.floor(delay.high / control_dt + 1e-6)
            if most < fewest:
                raise ParameterError(f'delay_s: [{delay.low:g}, {delay.high:g}] s holds no whole number of control '
                                     f'steps of {control_dt:g} s')
            delay = (fewest + min(int(u_delay * (most - fewest + 1)), most - fewest)) * control_dt
        return lag, delay

    def to_mapping(self) -> dict:
        """The world keys that reproduce it (those left at their nominal value left out)."""
        document: dict[str, Any] = {}
        if self.has_wind:
            document['wind'] = {'mean_speed_mps': self.wind_mean_speed_mps, 'turbulence': self.turbulence}
            if self.wind_direction_deg is not None:
                document['wind']['direction_deg'] = self.wind_direction_deg
        if self.sensor_noise:
            document['sensor_noise'] = {key: {'std': n.std, 'bias_std': n.bias_std}
                                        for key, n in self.sensor_noise.items()}
        for key in ('delay_s', 'motor_time_constant_s'):
            value = getattr(self, key)
            if isinstance(value, Range):
                document[key] = {'low': value.low, 'high': value.high}
            elif value:
                document[key] = value
        return document


def _largest(value: float | Range) -> float:
    return value.high if isinstance(value, Range) else value


def _actuator(value, key: str) -> float | Range:
    """A number [s] in [0, 1], or ``{low: a, high: b}``: drawn per flight, uniformly in [a, b]."""
    if isinstance(value, Mapping):
        check_keys(value, key, ('low', 'high'))
        for bound in ('low', 'high'):
            if bound not in value:
                raise ParameterError(f'{key}.{bound}: missing (a range is {{low: a, high: b}} [s])')
        low = check_number(f'{key}.low', value['low'], 0.0, 1.0)
        high = check_number(f'{key}.high', value['high'], low, 1.0)
        return Range(low, high)
    return check_number(key, 0.0 if value is None else value, 0.0, 1.0)


def _noise(value, key: str) -> NoiseLevel:
    if isinstance(value, Mapping):
        check_keys(value, key, ('std', 'bias_std'))
        return NoiseLevel(check_number(f'{key}.std', value.get('std', 0.0), 0.0),
                          check_number(f'{key}.bias_std', value.get('bias_std', 0.0), 0.0))
    return NoiseLevel(check_number(key, value, 0.0))


def parse_world(document: Mapping[str, Any]) -> World:
    """The world of the :data:`WORLD_KEYS` of ``document`` (other keys are the caller's to check); a key left
    out or None is nominal. ParameterError names the key and its valid range::

        wind: {mean_speed_mps: 3.0, turbulence: moderate, direction_deg: 90}
        sensor_noise: {position_m: 0.01, velocity_mps: {std: 0.02, bias_std: 0.01}, attitude_rad: 0.01,
                       body_rate_radps: 0.02}
        delay_s: 0.004              # [s] a whole number of control steps
        motor_time_constant_s: {low: 0.015, high: 0.045}   # [s] drawn per flight (delay_s too)
    """
    wind = check_keys(document.get('wind') or {}, 'wind', WIND_KEYS)
    turbulence = wind.get('turbulence', 'none')
    if turbulence not in TURBULENCE:
        raise ParameterError(f'wind.turbulence: {turbulence!r} is not one of {", ".join(TURBULENCE)}')
    direction = wind.get('direction_deg')
    noise = check_keys(document.get('sensor_noise') or {}, 'sensor_noise', NOISE_KEYS)
    return World(
        wind_mean_speed_mps=check_number('wind.mean_speed_mps', wind.get('mean_speed_mps', 0.0), 0.0),
        wind_direction_deg=None if direction is None else check_number('wind.direction_deg', direction),
        turbulence=turbulence,
        sensor_noise={key: _noise(value, f'sensor_noise.{key}') for key, value in noise.items()},
        delay_s=_actuator(document.get('delay_s'), 'delay_s'),
        motor_time_constant_s=_actuator(document.get('motor_time_constant_s'), 'motor_time_constant_s'))


@dataclass
class Perturbations:
    """What makes a flight differ from the nominal one (for one vehicle, or a batch: then arrays
    and per-vehicle random streams). Left at None, a part is off."""

    true_vehicle: VehicleParams | None = None   #: the vehicle the simulator flies (default: the nominal one)
    sensor_noise: SensorNoise | None = None
    delay: TransportDelay | None = None
    motor_lag: MotorLag | None = None
    wind: Wind | None = None
    changes: tuple[VehicleChange, ...] = ()     #: the true vehicle changing mid-flight (payload, rotor loss)
    #: (motor time constant [s], transport delay [s]) of each flight, as :func:`build_perturbations` had the world
    #: give them (:meth:`World.actuator`); empty when the perturbations were put together by hand
    actuators: tuple[tuple[float, float], ...] = ()


def wind_direction(world: World, seed: int, flight: int) -> float:
    """[rad] towards which flight ``flight``'s mean wind blows: the world's, else drawn from the flight's stream."""
    if world.wind_direction_deg is not None:
        return math.radians(world.wind_direction_deg)
    return float(flight_stream(seed, flight, 'wind').uniform(0.0, 2.0 * math.pi))


def _noise_levels(world: World, attribute: str) -> SensorErrors:
    return SensorErrors(**{name: getattr(world.sensor_noise[key], attribute)
                           for key, name in NOISE_FIELDS.items() if key in world.sensor_noise})


def build_perturbations(world: World, seed: int, flights: Sequence[int], vehicles: Sequence[VehicleParams],
                        directions: Sequence[float], control_dt: float, physics_dt: float,
                        batch: bool) -> Perturbations:
    """The perturbation objects that fly ``world`` for ``flights`` of ``seed`` with their true ``vehicles`` and
    mean-wind ``directions`` [rad]: of one vehicle (``batch`` false, one flight) or of a batch (arrays, one
    element and one random stream per flight, in order). ``control_dt``, ``physics_dt`` [s]. An actuator the
    world draws per flight (:meth:`World.actuator`) is one value per vehicle; a fixed one, one for all."""
    def rngs(purpose: str):
        chosen = [flight_stream(seed, flight, purpose) for flight in flights]
        return chosen if batch else chosen[0]

    vehicle = VehicleParams.stack(list(vehicles)) if batch else vehicles[0]
    direction = np.array(directions) if batch else directions[0]
    mean_speed = np.full(len(flights), world.wind_mean_speed_mps) if batch else world.wind_mean_speed_mps
    noise = None
    if world.sensor_noise:
        noise = SensorNoise(_noise_levels(world, 'std'), _noise_levels(world, 'bias_std'),
                            rngs('sensor_noise'), rngs('sensor_bias'))
    wind = None
    if world.has_wind:
        wind = Wind(physics_dt, mean_speed, direction, world.turbulence,
                    rngs('turbulence') if world.turbulence != 'none' else None)
    return Perturbations(true_vehicle=vehicle, sensor_noise=noise, wind=wind,
                         **_actuators(world, seed, flights, control_dt, physics_dt, batch))


def _actuators(world: World, seed: int, flights: Sequence[int], control_dt: float, physics_dt: float,
               batch: bool) -> dict:
    """The delay and motor lag of ``flights`` (one for all when the world fixes them, else one per flight), and each
    flight's (lag, delay) [s]."""
    actuators = tuple(world.actuator(seed, flight, control_dt) for flight in flights)
    delay, lag = world.delay_s, world.motor_time_constant_s
    if isinstance(delay, Range) or isinstance(lag, Range):
        lags, delays = zip(*actuators)
        steps = np.array([round(d / control_dt) for d in delays])
        lag = np.array(lags) if batch else lags[0]
        return {'delay': (TransportDelay(steps) if batch else TransportDelay(int(steps[0]))) if steps.any() else None,
                'motor_lag': MotorLag(lag, physics_dt) if np.any(np.asarray(lag) > 0.0) else None,
                'actuators': actuators}
    return {'delay': TransportDelay.from_seconds(delay, control_dt) if delay > 0.0 else None,
            'motor_lag': MotorLag(lag, physics_dt) if lag > 0.0 else None, 'actuators': actuators}


def vehicle_changes(true_vehicle: VehicleParams, events: Mapping[str, Any], duration: float) -> tuple[VehicleChange, ...]:
    """The true vehicle's changes of ``events`` (argument -> {'at_s': t, value key: value}), each applied on
    top of the earlier ones; each must happen within the flight's ``duration`` [s]."""
    timed = []
    for argument, event in events.items():
        key, field_name = CHANGE_KEYS[argument]
        if not isinstance(event, Mapping):
            raise ParameterError(f'{argument}: expected a mapping {{at_s: t, {key}: value}}, got {event!r}')
        for name in event:
            if name not in ('at_s', key):
                raise ParameterError(f'{argument}.{name}: unknown key (valid keys: at_s, {key})')
        for name in ('at_s', key):
            if name not in event:
                raise ParameterError(f'{argument}.{name}: missing')
        value = event[key]
        if field_name == 'rotor_efficiency_loss':
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 4:
                raise ParameterError(f'{argument}.{key}: expected 4 lost fractions in [0, 1) of F1..F4, '
                                     f'got {value!r}')
            value = tuple(value)
        at_s = check_number(f'{argument}.at_s', event['at_s'], 0.0)
        if at_s >= duration:
            raise ParameterError(f'{argument}.at_s: {at_s:g} s is not before the end of the {duration:g} s flight, so '
                                 f'the change would never happen (valid: 0 <= at_s < {duration:g})')
        timed.append((at_s, argument, field_name, value))
    changes, vehicle = [], true_vehicle
    for at_s, argument, field_name, value in sorted(timed, key=lambda event: event[0]):
        change = vehicle_change(argument, vehicle, at_s, **{field_name: value})
        vehicle = change.vehicle
        changes = [c for c in changes if c.at_s != at_s] + [change]    # one time: the later event includes it
    return tuple(changes)
