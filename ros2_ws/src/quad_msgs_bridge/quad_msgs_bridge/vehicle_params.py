"""Vehicle description (paper Table I) and section IV disturbances, loaded from one YAML file.

The same schema describes the simulated vehicle (the truth) and a controller's nominal model, so
both sides of the ``rotor_forces`` contract agree on geometry and rotor limits; a robustness
campaign flies a perturbed true vehicle against the nominal one. Beyond Table I the description
has optional entries that only the true vehicle needs (a centre-of-gravity offset, per-rotor thrust
and reaction-torque factors, a per-rotor efficiency loss and a wind drag coefficient); left out,
they take values that change nothing. Every value is validated: a missing, unknown, non-finite or
out-of-range entry raises :class:`ParameterError` naming the parameter and its valid range.

A :class:`VehicleParams` holds plain floats for one vehicle, or numpy arrays of shape (B,), one
element per vehicle, for a batch (see :meth:`VehicleParams.stack`); arrays are checked element by
element and an error names the vehicle index.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields
from pathlib import Path
from functools import cached_property
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import yaml

from quad_msgs_bridge.rotor_layout import (FRAMES, STANDARD_DIRECTIONS, frame_positions, layout_problem, rotor_mixer,
                                           rotor_names)
from quad_msgs_bridge.validation import ParameterError, check_number, check_values  # noqa: F401 (their home)
from quad_msgs_bridge.yaml_files import load_yaml

DEFAULT_VEHICLE_FILE = Path(__file__).resolve().parent / 'config' / 'vehicle.yaml'
#: the shipped vehicles of real quadrotors, by name (docs/VEHICLES.md); 'paper' is DEFAULT_VEHICLE_FILE
SHIPPED_VEHICLES = Path(__file__).resolve().parent / 'config' / 'vehicles'

#: [N s/m] Linear drag of the whole vehicle against the air, used when a wind model is on. RotorPy's
#: AscTec Hummingbird (0.500 kg; rotorpy/vehicles/hummingbird_params.py) has the rotor drag
#: coefficient k_d = 1.19e-4 kg/rad per rotor and the thrust coefficient k_eta = 5.57e-6 N s^2; at
#: hover each rotor turns at sqrt(m g / (4 k_eta)) = 469 rad/s, so the four rotors give
#: 4 k_d 469 = 0.223 N s/m, 0.447 (m/s^2)/(m/s) mass-normalised. Scaled to the 0.486 kg vehicle of
#: this stack: 0.447 x 0.486 = 0.217 N s/m (about 390 times the paper's Kfx). The linear law
#: F = c (w_air - v) is the rotor-drag model of Faessler, Franchi and Scaramuzza, IEEE RA-L 3(2), 2018.
DEFAULT_WIND_DRAG = 0.217


def _check_keys(section: str, given: Mapping[str, Any], expected: list[str], optional: Sequence[str] = ()) -> None:
    if not isinstance(given, Mapping):
        raise ParameterError(f'{section}: expected a mapping, got {type(given).__name__}')
    missing = [k for k in expected if k not in given]
    if missing:
        raise ParameterError(f'{section}.{missing[0]}: missing (required keys: {", ".join(expected)})')
    unknown = [k for k in given if k not in expected and k not in optional]
    if unknown:
        valid = ', '.join([*expected, *optional])
        raise ParameterError(f'{section}.{unknown[0]}: unknown parameter (valid keys: {valid})')


_POSITIVE = (0.0, math.inf, False, True)
_NON_NEGATIVE = (0.0, math.inf, True, True)
_ANY = (-math.inf, math.inf, True, True)
_FRACTION_BELOW_ONE = (0.0, 1.0, True, False)

#: Valid range (low, high, low inclusive, high inclusive) of each field, per element for the tuples.
_RANGES = {
    'm': _POSITIVE, 'd': _POSITIVE, 'Ix': _POSITIVE, 'Iy': _POSITIVE, 'Iz': _POSITIVE, 'Kp': _POSITIVE,
    'Kd': _NON_NEGATIVE, 'Kfx': _NON_NEGATIVE, 'Kfy': _NON_NEGATIVE, 'Kfz': _NON_NEGATIVE,
    'Kfphi': _NON_NEGATIVE, 'Kftheta': _NON_NEGATIVE, 'Kfpsi': _NON_NEGATIVE, 'g': _POSITIVE,
    'F_min': _NON_NEGATIVE, 'F_max': _NON_NEGATIVE,
    'cog_offset': _ANY, 'rotor_thrust_factors': _POSITIVE, 'rotor_drag_factors': _POSITIVE,
    'rotor_efficiency_loss': _FRACTION_BELOW_ONE, 'wind_drag': _NON_NEGATIVE,
}
#: Fields holding one value per body axis (3) or per rotor (4), in the rotor order of the mixer.
_VECTOR_LENGTHS = {'cog_offset': 3, 'rotor_thrust_factors': 4, 'rotor_drag_factors': 4, 'rotor_efficiency_loss': 4}
#: Keys a vehicle file may leave out (their defaults leave the vehicle unperturbed).
_OPTIONAL = ('cog_offset', 'rotor_thrust_factors', 'rotor_drag_factors', 'rotor_efficiency_loss', 'wind_drag',
             'frame', 'rotor_positions', 'rotor_directions')
#: the rotor layout's keys (quad_msgs_bridge.rotor_layout): one layout per description, also for a batch
_LAYOUT = ('frame', 'rotor_positions', 'rotor_directions')


def _pick(value, vehicle: int | None):
    """One vehicle's element of a float or per-vehicle array (the value itself for a float)."""
    return value if vehicle is None or not isinstance(value, np.ndarray) else float(value[vehicle])


def _require(ok, message: Callable[[int | None], str]) -> None:
    """Raise ParameterError(message) unless ``ok`` holds (for a batch: for every vehicle; the first
    vehicle where it fails is passed to ``message`` and named)."""
    if isinstance(ok, np.ndarray):
        if not ok.all():
            vehicle = int(np.argmin(ok))
            raise ParameterError(f'{message(vehicle)} (vehicle {vehicle})')
    elif not ok:
        raise ParameterError(message(None))


@dataclass(frozen=True)
class VehicleParams:
    """Physical parameters of paper Table I, rotor limits and true-vehicle perturbations, in SI units.

    Rotor model of the true vehicle: a rotor speed controller realises the commanded thrust F_i,
    clipped to [F_min, F_max], with the Kp of this description (w_i^2 = F_i / Kp). The rotor then
    gives the thrust f_i (1 - l_i) F_i and the reaction torque g_i (1 - l_i) (Kd / Kp) F_i, with
    f_i = ``rotor_thrust_factors[i]`` (its own Kp_i = f_i Kp), g_i = ``rotor_drag_factors[i]``
    (Kd_i = g_i Kd) and l_i = ``rotor_efficiency_loss[i]`` (the motor reaches only (1 - l_i) of the
    commanded w_i^2, so thrust and torque both shrink). The thrust acts through the geometric
    centre; with the centre of gravity at ``cog_offset`` = (c_x, c_y, c_z) from it, the moment
    about the centre of gravity is sum (r_i - c) x (0, 0, T_i), i.e. roll d U2 - c_y U1 and pitch
    d U3 + c_x U1 (c_z drops out: every thrust is parallel to body z).

    Rotor layout (:mod:`quad_msgs_bridge.rotor_layout`): ``frame`` 'plus' (the paper's, the default) or
    'x' places the rotors at the arm length d, in place of any ``rotor_positions`` given
    (``rotor_directions`` may mirror the spins); 'custom' takes ``rotor_positions`` and
    ``rotor_directions`` as given. After construction both hold the
    layout in use: ``rotor_positions`` four (x, y, z) [m, body FLU] from the geometric centre, in the
    order F1..F4 of ``rotor_forces``, and ``rotor_directions`` four +1 (counter-clockwise seen from
    above) or -1. A batch flies one layout.
    """

    m: float        #: [kg] total mass
    d: float        #: [m] rotor-to-centre distance
    Ix: float       #: [kg m^2] inertia about body x
    Iy: float       #: [kg m^2] inertia about body y
    Iz: float       #: [kg m^2] inertia about body z
    Kp: float       #: [N s^2] thrust factor
    Kd: float       #: [N m s^2] drag factor
    Kfx: float      #: [N s/m] translational drag x
    Kfy: float      #: [N s/m] translational drag y
    Kfz: float      #: [N s/m] translational drag z
    Kfphi: float    #: [N m s^2] rotational friction roll
    Kftheta: float  #: [N m s^2] rotational friction pitch
    Kfpsi: float    #: [N m s^2] rotational friction yaw
    g: float        #: [m/s^2] gravity
    F_min: float    #: [N] smallest rotor thrust
    F_max: float    #: [N] largest rotor thrust
    cog_offset: tuple = (0.0, 0.0, 0.0)                  #: [m, body FLU] centre of gravity from the geometric centre
    rotor_thrust_factors: tuple = (1.0, 1.0, 1.0, 1.0)   #: [-] Kp_i / Kp of rotors F1..F4
    rotor_drag_factors: tuple = (1.0, 1.0, 1.0, 1.0)     #: [-] Kd_i / Kd of rotors F1..F4
    rotor_efficiency_loss: tuple = (0.0, 0.0, 0.0, 0.0)  #: [-] in [0, 1): lost fraction of w_i^2 of F1..F4
    wind_drag: float = DEFAULT_WIND_DRAG                 #: [N s/m] drag against the air when wind is on
    frame: str = 'plus'                                  #: rotor layout: 'plus', 'x' or 'custom'
    rotor_positions: tuple | None = None                 #: [m, body FLU] (x, y, z) of F1..F4 (None: from frame, d)
    rotor_directions: tuple | None = None                #: [-] +1 CCW / -1 CW from above, F1..F4 (None: 1, -1, 1, -1)

    def __post_init__(self):
        """Check every value (element by element for a batch) and store floats, float arrays and tuples."""
        sizes = {}
        for name, (low, high, low_inclusive, high_inclusive) in _RANGES.items():
            value = getattr(self, name)
            if name in _VECTOR_LENGTHS:
                length = _VECTOR_LENGTHS[name]
                if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence) or len(value) != length:
                    raise ParameterError(f'vehicle.{name}: expected a list of {length} values, got {value!r}')
                checked = tuple(check_values(f'vehicle.{name}[{i}]', v, low, high, low_inclusive, high_inclusive)
                                for i, v in enumerate(value))
            else:
                checked = check_values(f'vehicle.{name}', value, low, high, low_inclusive, high_inclusive)
            for element in checked if name in _VECTOR_LENGTHS else (checked,):
                if isinstance(element, np.ndarray):
                    sizes[name] = element.size
            object.__setattr__(self, name, checked)
        if len(set(sizes.values())) > 1:
            first = next(iter(sizes))
            other = next(name for name, size in sizes.items() if size != sizes[first])
            raise ParameterError(f'vehicle.{other}: {sizes[other]} vehicles, but vehicle.{first} has {sizes[first]}')
        self._resolve_layout()
        self._check_limits()

    def _resolve_layout(self) -> None:
        """Check ``frame``, ``rotor_positions`` and ``rotor_directions`` and store the layout in use."""
        if self.frame not in FRAMES:
            raise ParameterError(f'vehicle.frame: {self.frame!r} is not one of {", ".join(FRAMES)}')
        directions = _rotor_directions(STANDARD_DIRECTIONS if self.rotor_directions is None else self.rotor_directions)
        if self.frame == 'custom':
            if self.rotor_positions is None:
                raise ParameterError('vehicle.rotor_positions: frame custom needs rotor_positions and rotor_directions')
            if self.rotor_directions is None:
                raise ParameterError('vehicle.rotor_directions: frame custom needs rotor_positions and '
                                     'rotor_directions')
            positions = _rotor_positions(self.rotor_positions)
        else:
            arm = self.d
            if isinstance(arm, np.ndarray):
                if np.any(arm != arm[0]):
                    raise ParameterError(f'vehicle.d: a batch flies one rotor layout, but frame {self.frame} places '
                                         f'the rotors at different arm lengths {arm.tolist()}')
                arm = float(arm[0])
            positions = frame_positions(self.frame, arm)     # replaces any given (dataclasses.replace carries them)
        problem = layout_problem(positions, directions)
        if problem:
            raise ParameterError(f'vehicle.rotor_positions: the mixer cannot allocate for this layout: {problem}')
        object.__setattr__(self, 'rotor_positions', positions)
        object.__setattr__(self, 'rotor_directions', directions)

    def _check_limits(self) -> None:
        weight = self.m * self.g
        _require(self.F_max > self.F_min,
                 lambda i: f'vehicle.F_max: {_pick(self.F_max, i)} must exceed F_min = {_pick(self.F_min, i)}')
        _require(4.0 * self.F_max > weight,
                 lambda i: f'vehicle.F_max: {_pick(self.F_max, i)} N cannot hover the vehicle of mass m = '
                           f'{_pick(self.m, i):g} kg (weight {_pick(weight, i):.4g} N): four rotors give '
                           f'{4.0 * _pick(self.F_max, i):.4g} N; valid range ({_pick(weight, i) / 4.0}, inf)')
        _require(4.0 * self.F_min < weight,
                 lambda i: f'vehicle.F_min: {_pick(self.F_min, i)} N cannot descend; valid range '
                           f'[0, {_pick(weight, i) / 4.0})')
        for axis, offset in zip('xyz', self.cog_offset):
            _require(abs(offset) < self.d,
                     lambda i: f'vehicle.cog_offset: {axis} = {_pick(offset, i)} m is not within the arm length, '
                               f'valid range (-{_pick(self.d, i)}, {_pick(self.d, i)})')

    @property
    def yaw_coefficient(self) -> float:
        """Kd / Kp [m]: rotor reaction torque per newton of thrust, eq. (2)."""
        return self.Kd / self.Kp

    @property
    def hover_force(self) -> float:
        """Per-rotor thrust [N] that balances gravity."""
        return self.m * self.g / 4.0

    @property
    def rotor_names(self) -> tuple[str, str, str, str]:
        """Labels of F1..F4 in this layout (e.g. 'F1_front' in the plus frame): plots, ``rotor_forces``."""
        return rotor_names(self.frame, self.rotor_positions)

    @cached_property
    def mixer(self) -> np.ndarray:
        """The layout as the mixer kernels read it (:mod:`quad_msgs_bridge.rotor_layout`, ROLL ... SPIN):
        MIXER_SIZE floats, or (B, MIXER_SIZE) for a batch (the model's constants take it row by row)."""
        return rotor_mixer(self.rotor_positions, self.rotor_directions, self.d, self.yaw_coefficient)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> 'VehicleParams':
        """The description in a YAML/JSON mapping: Table I keys required, the perturbation and layout keys
        optional (rotor positions without a frame make the frame custom; with frame plus or x they must
        be the frame's, as a description written by ``dataclasses.asdict`` has them)."""
        names = [f.name for f in fields(cls)]
        _check_keys('vehicle', values, [n for n in names if n not in _OPTIONAL], _OPTIONAL)
        chosen = {name: values[name] for name in names if name in values}
        if 'rotor_positions' in chosen:
            chosen.setdefault('frame', 'custom')
        params = cls(**chosen)
        if 'rotor_positions' in chosen and _rotor_positions(chosen['rotor_positions']) != params.rotor_positions:
            raise ParameterError(f'vehicle.rotor_positions: frame {params.frame} places the rotors itself (at '
                                 f'{params.rotor_positions}); leave out frame (or give frame: custom) to place them')
        return params

    @classmethod
    def stack(cls, vehicles: Sequence['VehicleParams']) -> 'VehicleParams':
        """One batch description of single vehicles: every value an array, one element per vehicle, in order."""
        vehicles = list(vehicles)
        if not vehicles:
            raise ParameterError('vehicles: a batch needs at least one vehicle')

        def column(name: str, index: int | None = None) -> np.ndarray:
            return np.array([getattr(v, name) if index is None else getattr(v, name)[index] for v in vehicles],
                            dtype=float)

        first = vehicles[0]
        for k, vehicle in enumerate(vehicles):
            for name in _LAYOUT:
                if getattr(vehicle, name) != getattr(first, name):
                    raise ParameterError(f'vehicles: a batch flies one rotor layout, but vehicle {k} has {name} '
                                         f'{getattr(vehicle, name)} and vehicle 0 {getattr(first, name)}')
        return cls(**{name: tuple(column(name, i) for i in range(_VECTOR_LENGTHS[name]))
                      if name in _VECTOR_LENGTHS else column(name) for name in _RANGES},
                   **{name: getattr(first, name) for name in _LAYOUT})


def _rotor_positions(value) -> tuple:
    """Four rotor positions (x, y, z) [m, body FLU] as float tuples, or ParameterError."""
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence) or len(value) != 4 or any(
            isinstance(p, (str, bytes, Mapping)) or not isinstance(p, Sequence) or len(p) != 3 for p in value):
        raise ParameterError(f'vehicle.rotor_positions: expected 4 positions [x, y, z] [m, body FLU], got {value!r}')
    return tuple(tuple(check_number(f'vehicle.rotor_positions[{i}][{k}]', c) for k, c in enumerate(p))
                 for i, p in enumerate(value))


def _rotor_directions(value) -> tuple:
    """Four spin directions, each +1 (counter-clockwise seen from above) or -1, as ints, or ParameterError."""
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence) or len(value) != 4:
        raise ParameterError(f'vehicle.rotor_directions: expected 4 values, each +1 (counter-clockwise seen from '
                             f'above) or -1, got {value!r}')
    for i, s in enumerate(value):
        if isinstance(s, bool) or s not in (1, -1):
            raise ParameterError(f'vehicle.rotor_directions[{i}]: {s!r} is not +1 (counter-clockwise seen from '
                                 f'above) or -1')
    return tuple(int(s) for s in value)


@dataclass(frozen=True)
class Disturbance:
    """One section IV disturbance channel: A(t) = bias + amplitude sin(omega t)."""

    bias: float       #: [N] or [N m]
    amplitude: float  #: [N] or [N m]
    omega: float      #: [rad/s]


DISTURBANCE_CHANNELS = ('A_x', 'A_y', 'A_z', 'A_phi', 'A_theta', 'A_psi')


@dataclass(frozen=True)
class Disturbances:
    """Paper section IV disturbances: forces [N, world ENU] and moments [N m, about the Euler axes]."""

    enabled: bool
    A_x: Disturbance
    A_y: Disturbance
    A_z: Disturbance
    A_phi: Disturbance
    A_theta: Disturbance
    A_psi: Disturbance

    def at(self, t: float) -> tuple[float, float, float, float, float, float]:
        """(A_x, A_y, A_z, A_phi, A_theta, A_psi) at time t [s]; all zero when disabled."""
        if not self.enabled:
            return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        sin = math.sin    # one comprehension: the model asks three times per RK4 step
        return tuple([c.bias + c.amplitude * sin(c.omega * t)
                      for c in (self.A_x, self.A_y, self.A_z, self.A_phi, self.A_theta, self.A_psi)])

    def switched(self, enabled: bool) -> 'Disturbances':
        return Disturbances(enabled, self.A_x, self.A_y, self.A_z, self.A_phi, self.A_theta, self.A_psi)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> 'Disturbances':
        _check_keys('disturbances', values, ['enabled', *DISTURBANCE_CHANNELS])
        enabled = values['enabled']
        if not isinstance(enabled, bool):
            raise ParameterError(f'disturbances.enabled: expected true or false, got {enabled!r}')
        channels = {}
        for name in DISTURBANCE_CHANNELS:
            section = f'disturbances.{name}'
            entry = values[name]
            _check_keys(section, entry, ['bias', 'amplitude', 'omega'])
            channels[name] = Disturbance(
                bias=check_number(f'{section}.bias', entry['bias']),
                amplitude=check_number(f'{section}.amplitude', entry['amplitude']),
                omega=check_number(f'{section}.omega', entry['omega'], 0.0))
        return cls(enabled=enabled, **channels)


def shipped_vehicles() -> dict[str, Path]:
    """The shipped vehicle files by name: 'paper' (the packaged default) and those of SHIPPED_VEHICLES."""
    return {'paper': DEFAULT_VEHICLE_FILE, **{p.stem: p for p in sorted(SHIPPED_VEHICLES.glob('*.yaml'))}}


def locate_vehicle(path: str | Path | None) -> Path:
    """The vehicle file of ``path``: a file that exists, else the shipped vehicle of that name
    (``x500`` or ``x500.yaml``), else ``path`` as given; None: the packaged default."""
    if path is None:
        return DEFAULT_VEHICLE_FILE
    path = Path(path)
    if path.exists() or path.parent != Path('.'):
        return path
    return shipped_vehicles().get(path.name[:-len('.yaml')] if path.suffix == '.yaml' else path.name, path)


def load_vehicle_file(path: str | Path | None = None) -> tuple[VehicleParams, Disturbances]:
    """Read and validate a vehicle YAML file, or a shipped vehicle by name (:func:`locate_vehicle`;
    default: the packaged ``config/vehicle.yaml``, the paper's)."""
    path = locate_vehicle(path)
    try:
        document = load_yaml(path.read_text())
    except OSError as error:
        raise ParameterError(f'vehicle file {path}: {error.strerror} (shipped vehicles: '
                             f'{", ".join(shipped_vehicles())})') from error
    except yaml.YAMLError as error:
        raise ParameterError(f'vehicle file {path}: not valid YAML ({error})') from error
    _check_keys(str(path), document or {}, ['vehicle', 'disturbances'])
    return VehicleParams.from_mapping(document['vehicle']), Disturbances.from_mapping(document['disturbances'])


@functools.lru_cache(maxsize=None)
def _shipped_params() -> tuple[tuple[str, VehicleParams], ...]:
    return tuple((name, load_vehicle_file(path)[0]) for name, path in shipped_vehicles().items())


def vehicle_name(params: VehicleParams | None = None, path: str | Path | None = None) -> str:
    """What to call a flight's vehicle in its summary, console and report: the shipped vehicle's name
    ('paper', 'crazyflie', 'hummingbird', 'x500') when ``path`` (a vehicle file or name, as ``--vehicle``
    takes it) is a shipped one, else the path as given; without a path, the name of the shipped vehicle
    whose parameters ``params`` are, else 'custom' (a batch's per-vehicle arrays: 'custom' too)."""
    if path is not None:
        located = locate_vehicle(path).resolve()
        return next((name for name, file in shipped_vehicles().items() if file.resolve() == located), str(path))
    if params is None:
        return 'paper'
    if isinstance(params.m, np.ndarray):
        return 'custom'
    return next((name for name, shipped in _shipped_params() if shipped == params), 'custom')
