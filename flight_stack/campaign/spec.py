"""The campaign specification (``SPEC.yaml``): what to fly, how often, under which perturbations.

Format (every key but ``scenario``, ``controllers`` and ``flights`` optional; a perturbation key
left out means no such perturbation; other tools write these files, so the names are stable)::

    scenario: paper            # any --scenario of run_stack.py
    duration: 60               # [s] sim time per flight (default: the scenario's length)
    settle_time: 5             # [s] metrics and failure checks start after it
    controllers: [nnit2fsmc, smc-sign]
    flights: 1000              # flights per controller; every controller flies the same ones
    seed: 1                    # campaign seed: flight k's randomness depends only on (seed, k)
    max_error_m: 1.0           # [m] a flight fails once its position error exceeds this after settling
    disturbances: true         # the paper's section IV disturbances (default: as in the vehicle file)
    vehicle:                   # true-vehicle perturbations (the controllers keep the nominal model)
      mass: 0.3                #   a number = relative, uniform +-0.3 around the nominal value
      inertia: {dist: normal, std: 0.1}   # or a relative normal (truncated at +-3 std)
      drag: 0.25               #   Kfx Kfy Kfz Kfphi Kftheta Kfpsi, each drawn on its own
      thrust_coefficient: 0.1  #   Kp of each rotor, on its own
      drag_coefficient: 0.1    #   Kd of each rotor, on its own
      cog_offset_m: 0.01       #   [m] absolute: centre of gravity uniform in +-0.01 m along body x and y
      rotor_efficiency_loss: 0.1   # absolute: each rotor loses uniform [0, 0.1] of its thrust
      one_rotor_efficiency_loss: {dist: fixed, value: 0.3}   # rotor 1 alone loses 0.3 of its thrust
    wind: {mean_speed_mps: 3.0, turbulence: moderate}   # none | light | moderate | severe
    sensor_noise: {position_m: 0.01, velocity_mps: 0.02, attitude_rad: 0.01, body_rate_radps: 0.02}
    delay_s: 0.004             # [s] transport delay, a whole number of control steps
    motor_time_constant_s: 0.03   # or, both: {low: 0.015, high: 0.045}, drawn per flight (quad_sim.world)
    control_rate_hz: 1000
    physics_rate_hz: 1000      # a whole multiple of control_rate_hz (default: equal to it)
    measurement_filters: true  # every controller reads through the gains file's measurement stage
                               # (common.measurement_filter_hz, common.velocity_filter_hz); false: none
    plant: quad_sim            # what the simulator flies: quad_sim (our model), rotorpy or rotorpy-bare (docs/ROTORPY.md)

``inertia`` draws Ix, Iy and Iz on their own. A distribution is a number (relative uniform half
width), ``{dist: uniform, half_width: x}``, ``{dist: normal, std: s}`` or ``{dist: fixed, value:
v}`` (every flight the same: for a relative key the true value is (1 + v) times the nominal one, v >
-1); relative draws must keep a parameter positive (half width < 1, 3 std < 1). ``wind`` takes an
optional ``direction_deg`` (the direction the wind blows towards, from +x (east) counter-clockwise;
default: drawn uniformly per flight). ``sensor_noise`` entries are white-noise standard deviations,
or ``{std: s, bias_std: b}`` with a constant bias drawn per flight from N(0, b^2). An unknown key, a
negative standard deviation, an empty controller list or ``flights: 0`` is refused before anything
flies, naming the key.
On ``plant: rotorpy`` a batch's vehicles are stepped one after the other by RotorPy (2-3 ms of wall
time per vehicle and physics step, bench/bench_plants.py), and ``vehicle.thrust_coefficient`` / ``drag_coefficient`` are
refused (RotorPy shares one torque-to-thrust ratio between its rotors).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from statistics import NormalDist
from typing import Any, Mapping

import yaml

from nnit2fsmc_controller.factory import CONTROLLERS
from nnit2fsmc_controller.registry import check_controller
from quad_sim.plants import DEFAULT_PLANT, check_plant
from nnit2fsmc_controller.trajectory import SCENARIOS, make_scenario
from quad_msgs_bridge.validation import ParameterError, check_keys, check_number
from quad_msgs_bridge.yaml_files import load_yaml
from quad_sim.world import NoiseLevel, World, parse_world

#: spec key -> what it perturbs (documentation of the vehicle section)
VEHICLE_KEYS = {
    'mass': 'm, relative',
    'inertia': 'Ix, Iy, Iz, each relative',
    'drag': 'Kfx, Kfy, Kfz, Kfphi, Kftheta, Kfpsi, each relative',
    'thrust_coefficient': 'Kp of each rotor, relative',
    'drag_coefficient': 'Kd of each rotor, relative',
    'cog_offset_m': 'centre of gravity along body x and y [m], absolute',
    'rotor_efficiency_loss': 'lost thrust fraction of each rotor, absolute, in [0, value]',
    'one_rotor_efficiency_loss': 'lost thrust fraction of rotor 1 alone, absolute, in [0, value]',
}
#: vehicle keys whose value is absolute (the others are relative to the nominal value)
ABSOLUTE_VEHICLE_KEYS = ('cog_offset_m', 'rotor_efficiency_loss', 'one_rotor_efficiency_loss')
#: vehicle keys that are a lost fraction of thrust, in [0, 1)
LOSS_KEYS = ('rotor_efficiency_loss', 'one_rotor_efficiency_loss')
DISTRIBUTIONS = ('uniform', 'normal', 'fixed')
#: the YAML key of each distribution's scale
SCALE_KEYS = {'uniform': 'half_width', 'normal': 'std', 'fixed': 'value'}
_STANDARD_NORMAL = NormalDist()
TOP_KEYS = ('scenario', 'duration', 'settle_time', 'controllers', 'flights', 'seed', 'max_error_m',
            'disturbances', 'vehicle', 'wind', 'sensor_noise', 'delay_s', 'motor_time_constant_s',
            'control_rate_hz', 'physics_rate_hz', 'measurement_filters', 'plant')


@dataclass(frozen=True)
class Distribution:
    """A random draw around a nominal value: uniform(-half_width, half_width), normal(0, std)
    truncated at +-3 std, or the same value for every flight (fixed)."""

    kind: str          #: 'uniform', 'normal' or 'fixed'
    scale: float       #: half width (uniform, >= 0), standard deviation (normal, >= 0) or the value (fixed)

    def value(self, u: float) -> float:
        """The draw for a standard uniform number u in [0, 1) (inverse transform sampling).

        Every parameter takes exactly one uniform number whatever its distribution, so what one
        spec key draws never shifts the draws of another.
        """
        if self.kind == 'fixed':
            return self.scale
        if self.kind == 'uniform':
            return self.scale * (2.0 * u - 1.0)
        low, high = _STANDARD_NORMAL.cdf(-3.0), _STANDARD_NORMAL.cdf(3.0)
        return self.scale * _STANDARD_NORMAL.inv_cdf(low + u * (high - low))

    @property
    def bound(self) -> float:
        """Largest magnitude a draw can have."""
        return 3.0 * self.scale if self.kind == 'normal' else abs(self.scale)


@dataclass(frozen=True)
class CampaignSpec:
    """A validated ``SPEC.yaml`` (see the module docstring); SI units throughout."""

    scenario: str
    controllers: tuple[str, ...]
    flights: int
    duration: float
    settle_time: float = 5.0
    seed: int = 0
    max_error_m: float = 1.0
    disturbances: bool | None = None
    vehicle: Mapping[str, Distribution] = field(default_factory=dict)
    wind_mean_speed_mps: float = 0.0
    wind_direction_deg: float | None = None
    turbulence: str = 'none'
    sensor_noise: Mapping[str, NoiseLevel] = field(default_factory=dict)
    delay_s: float = 0.0
    motor_time_constant_s: float = 0.0
    control_rate_hz: float | None = None
    physics_rate_hz: float | None = None
    measurement_filters: bool = True     #: False: every controller reads the measurement unfiltered
    plant: str = DEFAULT_PLANT           #: what the simulator flies (quad_sim.plants.PLANTS)
    source: str = ''                     #: the YAML text it was read from (kept with the results)

    @property
    def world(self) -> World:
        """The air, sensors and actuators every flight of the campaign flies in (quad_sim.world)."""
        return World(self.wind_mean_speed_mps, self.wind_direction_deg, self.turbulence, self.sensor_noise,
                     self.delay_s, self.motor_time_constant_s)

    @property
    def has_wind(self) -> bool:
        return self.world.has_wind

    def overridden(self, *, flights: int | None = None, seed: int | None = None,
                   duration: float | None = None, controllers: list[str] | None = None,
                   plant: str | None = None) -> 'CampaignSpec':
        """The spec with the command-line overrides applied and validated."""
        spec = self
        if plant is not None:
            spec = replace(spec, plant=check_plant(plant, '--plant'))
            _check_representable(spec)
        if flights is not None:
            spec = replace(spec, flights=_flights(flights, '--flights'))
        if seed is not None:
            spec = replace(spec, seed=_seed(seed, '--seed'))
        if controllers is not None:
            spec = replace(spec, controllers=_controllers(controllers, '--controllers'))
        if duration is not None:
            spec = replace(spec, duration=check_number('--duration', duration, 0.0, low_inclusive=False))
        _check_settling(spec, '--duration' if duration is not None else 'duration')
        return spec

    def to_mapping(self) -> dict:
        """The spec as the YAML mapping that reproduces it (overrides included)."""
        document: dict[str, Any] = {
            'scenario': self.scenario, 'duration': self.duration, 'settle_time': self.settle_time,
            'controllers': list(self.controllers), 'flights': self.flights, 'seed': self.seed,
            'max_error_m': self.max_error_m}
        if self.disturbances is not None:
            document['disturbances'] = self.disturbances
        if self.vehicle:
            document['vehicle'] = {key: {'dist': d.kind, SCALE_KEYS[d.kind]: d.scale}
                                   for key, d in self.vehicle.items()}
        document.update(self.world.to_mapping())
        for key in ('control_rate_hz', 'physics_rate_hz'):
            if getattr(self, key):
                document[key] = getattr(self, key)
        if self.plant != DEFAULT_PLANT:
            document['plant'] = self.plant
        return document


def _flights(value, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ParameterError(f'{key}: {value!r} is not a whole number of flights >= 1')
    return value


def _seed(value, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ParameterError(f'{key}: {value!r} is not a whole number >= 0')
    return value


def _controllers(value, key: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [name.strip() for name in value.split(',') if name.strip()]
    if not isinstance(value, (list, tuple)) or not value:
        raise ParameterError(f'{key}: expected a non-empty list of controllers ({", ".join(CONTROLLERS)}, an installed '
                             'controller\'s name or module:Class)')
    for name in value:
        check_controller(name, key)
    if len(set(value)) != len(value):
        raise ParameterError(f'{key}: a controller is listed twice in {list(value)}')
    return tuple(value)


def _distribution(value, key: str, relative: bool) -> Distribution:
    if isinstance(value, Mapping):
        kind = value.get('dist', 'uniform')
        if kind not in DISTRIBUTIONS:
            raise ParameterError(f'{key}.dist: {kind!r} is not one of {", ".join(DISTRIBUTIONS)}')
        scale_key = SCALE_KEYS[kind]
        check_keys(value, key, ('dist', scale_key))
        if scale_key not in value:
            raise ParameterError(f'{key}.{scale_key}: missing')
        if kind == 'fixed':
            fixed = check_number(f'{key}.value', value['value'], -1.0 if relative else -math.inf,
                                 low_inclusive=False)
            return Distribution(kind, fixed)
        distribution = Distribution(kind, check_number(f'{key}.{scale_key}', value[scale_key], 0.0))
    else:
        distribution = Distribution('uniform', check_number(key, value, 0.0))
    if relative and distribution.bound >= 1.0:
        raise ParameterError(f'{key}: draws of up to +-{distribution.bound:g} (relative) could make the '
                             'parameter zero or negative; keep the half width (or 3 std) below 1')
    return distribution


def _check_representable(spec: CampaignSpec) -> None:
    """ParameterError when the spec samples per-rotor coefficient errors and its plant is RotorPy's."""
    unrepresentable = [key for key in ('thrust_coefficient', 'drag_coefficient') if key in spec.vehicle]
    if spec.plant.startswith('rotorpy') and unrepresentable:
        raise ParameterError(f'vehicle.{unrepresentable[0]}: not with plant {spec.plant} (RotorPy has one thrust and '
                             'one torque coefficient for every rotor); leave it out or fly plant quad_sim')


def _check_settling(spec: CampaignSpec, key: str) -> None:
    if spec.duration <= spec.settle_time:
        raise ParameterError(f'{key}: {spec.duration:g} s leaves nothing after the settling window '
                             f'(settle_time {spec.settle_time:g} s)')


def parse_spec(document: Any, source: str = '') -> CampaignSpec:
    """Validate a spec mapping (see the module docstring); ParameterError names the offending key."""
    top = check_keys(document if document is not None else {}, '', TOP_KEYS)
    for required in ('scenario', 'controllers', 'flights'):
        if required not in top:
            raise ParameterError(f'{required}: missing (required keys: scenario, controllers, flights)')
    scenario = top['scenario']
    if scenario not in SCENARIOS:
        raise ParameterError(f'scenario: {scenario!r} is not one of {", ".join(SCENARIOS)}')
    duration = top.get('duration')
    trajectory = make_scenario(scenario, duration)
    vehicle = check_keys(top.get('vehicle', {}), 'vehicle', tuple(VEHICLE_KEYS))
    world = parse_world(top)
    disturbances = top.get('disturbances')
    if disturbances is not None and not isinstance(disturbances, bool):
        raise ParameterError(f'disturbances: expected true or false, got {disturbances!r}')
    measurement_filters = top.get('measurement_filters', True)
    if not isinstance(measurement_filters, bool):
        raise ParameterError(f'measurement_filters: expected true or false, got {measurement_filters!r}')
    spec = CampaignSpec(
        scenario=scenario,
        controllers=_controllers(top['controllers'], 'controllers'),
        flights=_flights(top['flights'], 'flights'),
        duration=trajectory.duration if duration is None else float(duration),
        settle_time=check_number('settle_time', top.get('settle_time', 5.0), 0.0),
        seed=_seed(top.get('seed', 0), 'seed'),
        max_error_m=check_number('max_error_m', top.get('max_error_m', 1.0), 0.0, low_inclusive=False),
        disturbances=disturbances,
        vehicle={key: _distribution(value, f'vehicle.{key}', relative=key not in ABSOLUTE_VEHICLE_KEYS)
                 for key, value in vehicle.items()},
        wind_mean_speed_mps=world.wind_mean_speed_mps, wind_direction_deg=world.wind_direction_deg,
        turbulence=world.turbulence, sensor_noise=world.sensor_noise, delay_s=world.delay_s,
        motor_time_constant_s=world.motor_time_constant_s,
        control_rate_hz=(None if 'control_rate_hz' not in top
                         else check_number('control_rate_hz', top['control_rate_hz'], 0.0, 1e5, low_inclusive=False)),
        physics_rate_hz=(None if 'physics_rate_hz' not in top
                         else check_number('physics_rate_hz', top['physics_rate_hz'], 0.0, 1e6, low_inclusive=False)),
        measurement_filters=measurement_filters,
        plant=check_plant(top.get('plant', DEFAULT_PLANT), 'plant'),
        source=source)
    _check_representable(spec)
    for key in LOSS_KEYS:
        if key in spec.vehicle and spec.vehicle[key].scale < 0.0:
            raise ParameterError(f'vehicle.{key}: a loss is a fraction in [0, 1), got {spec.vehicle[key].scale:g}')
        if key in spec.vehicle and spec.vehicle[key].bound >= 1.0:
            raise ParameterError(f'vehicle.{key}: a rotor cannot lose all of its thrust; keep it below 1')
    _check_settling(spec, 'duration')
    return spec


#: the specs shipped with the package (a clone's campaigns/ folder links here)
SHIPPED_SPECS = Path(__file__).resolve().parent / 'specs'


def shipped_specs() -> list[Path]:
    """The shipped spec files, by name."""
    return sorted(SHIPPED_SPECS.glob('*.yaml'))


def locate_spec(path: str | Path) -> Path:
    """``path`` if it exists, else the shipped spec of that name (``paper-robustness``,
    ``paper-robustness.yaml`` or ``campaigns/paper-robustness.yaml``), else ``path`` as given."""
    path = Path(path)
    if path.exists():
        return path
    name = path.name if path.suffix == '.yaml' else f'{path.name}.yaml'
    shipped = SHIPPED_SPECS / name
    return shipped if shipped.is_file() and path.parent in (Path('.'), Path('campaigns')) else path


def load_spec(path: str | Path) -> CampaignSpec:
    """Read and validate a ``SPEC.yaml`` (a file, or a shipped spec by name: :func:`locate_spec`); errors
    name the file and the key."""
    path = locate_spec(path)
    try:
        text = path.read_text()
        document = load_yaml(text)
    except OSError as error:
        raise ParameterError(f'campaign spec {path}: {error.strerror} (shipped specs: '
                             f'{", ".join(p.stem for p in shipped_specs())})') from error
    except yaml.YAMLError as error:
        raise ParameterError(f'campaign spec {path}: not valid YAML ({error})') from error
    try:
        return parse_spec(document, text)
    except ParameterError as error:
        raise ParameterError(f'campaign spec {path}: {error}') from error
