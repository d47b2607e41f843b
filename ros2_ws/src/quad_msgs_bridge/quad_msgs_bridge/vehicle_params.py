"""Vehicle description (paper Table I) and section IV disturbances, loaded from one YAML file.

The same file describes the simulated vehicle (truth) and the controllers' nominal model, so
both sides of the ``rotor_forces`` contract agree on geometry and rotor limits. Every value is
validated on load: a missing, unknown, non-finite or out-of-range entry raises
:class:`ParameterError` naming the parameter and its valid range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import yaml

DEFAULT_VEHICLE_FILE = Path(__file__).resolve().parent / 'config' / 'vehicle.yaml'


class ParameterError(ValueError):
    """An invalid parameter value; the message names the parameter and its valid range."""


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
                 low_inclusive: bool = True) -> float:
    """Return ``value`` as a float, or raise ParameterError if it is not a finite number in range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f'{name}: expected a number, got {value!r}')
    value = float(value)
    interval = (f'{"[" if low_inclusive and math.isfinite(low) else "("}{low}, '
                f'{high}{"]" if math.isfinite(high) else ")"}')
    if not math.isfinite(value):
        bounded = math.isfinite(low) or math.isfinite(high)
        raise ParameterError(f'{name}: must be finite, got {value!r}' + (f' (valid range {interval})' if bounded else ''))
    if (value < low if low_inclusive else value <= low) or value > high:
        raise ParameterError(f'{name}: {value!r} is outside the valid range {interval}')
    return value


def _check_keys(section: str, given: Mapping[str, Any], expected: list[str]) -> None:
    if not isinstance(given, Mapping):
        raise ParameterError(f'{section}: expected a mapping, got {type(given).__name__}')
    missing = [k for k in expected if k not in given]
    if missing:
        raise ParameterError(f'{section}.{missing[0]}: missing (required keys: {", ".join(expected)})')
    unknown = [k for k in given if k not in expected]
    if unknown:
        raise ParameterError(f'{section}.{unknown[0]}: unknown parameter (valid keys: {", ".join(expected)})')


@dataclass(frozen=True)
class VehicleParams:
    """Physical parameters of paper Table I plus rotor limits, all in SI units."""

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

    @property
    def yaw_coefficient(self) -> float:
        """Kd / Kp [m]: rotor reaction torque per newton of thrust, eq. (2)."""
        return self.Kd / self.Kp

    @property
    def hover_force(self) -> float:
        """Per-rotor thrust [N] that balances gravity."""
        return self.m * self.g / 4.0

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> 'VehicleParams':
        names = [f.name for f in fields(cls)]
        _check_keys('vehicle', values, names)
        positive = {'m', 'd', 'Ix', 'Iy', 'Iz', 'Kp', 'g'}
        checked = {}
        for name in names:
            if name in positive:
                checked[name] = check_number(f'vehicle.{name}', values[name], 0.0, low_inclusive=False)
            else:
                checked[name] = check_number(f'vehicle.{name}', values[name], 0.0)
        if checked['F_max'] <= checked['F_min']:
            raise ParameterError(f'vehicle.F_max: {checked["F_max"]} must exceed F_min = {checked["F_min"]}')
        if 4.0 * checked['F_max'] <= checked['m'] * checked['g']:
            raise ParameterError(
                f'vehicle.F_max: {checked["F_max"]} N cannot hover the vehicle; valid range '
                f'({checked["m"] * checked["g"] / 4.0}, inf)')
        if checked['F_min'] * 4.0 >= checked['m'] * checked['g']:
            raise ParameterError(
                f'vehicle.F_min: {checked["F_min"]} N cannot descend; valid range '
                f'[0, {checked["m"] * checked["g"] / 4.0})')
        return cls(**checked)


@dataclass(frozen=True)
class Disturbance:
    """One section IV disturbance channel: A(t) = bias + amplitude sin(omega t)."""

    bias: float       #: [N] or [N m]
    amplitude: float  #: [N] or [N m]
    omega: float      #: [rad/s]

    def at(self, t: float) -> float:
        return self.bias + self.amplitude * math.sin(self.omega * t)


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
        return (self.A_x.at(t), self.A_y.at(t), self.A_z.at(t),
                self.A_phi.at(t), self.A_theta.at(t), self.A_psi.at(t))

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


def load_vehicle_file(path: str | Path | None = None) -> tuple[VehicleParams, Disturbances]:
    """Read and validate a vehicle YAML file (default: the packaged ``config/vehicle.yaml``)."""
    path = Path(path) if path is not None else DEFAULT_VEHICLE_FILE
    try:
        document = yaml.safe_load(path.read_text())
    except OSError as error:
        raise ParameterError(f'vehicle file {path}: {error.strerror}') from error
    except yaml.YAMLError as error:
        raise ParameterError(f'vehicle file {path}: not valid YAML ({error})') from error
    _check_keys(str(path), document or {}, ['vehicle', 'disturbances'])
    return VehicleParams.from_mapping(document['vehicle']), Disturbances.from_mapping(document['disturbances'])
