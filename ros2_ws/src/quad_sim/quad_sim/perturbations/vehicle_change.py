"""A change of the true vehicle during a flight: a payload picked up or dropped (another mass), a rotor
that loses efficiency, from sim time t on.

:class:`VehicleChange` is data: from ``at_s`` [s] on the simulator flies ``vehicle`` instead of the
vehicle it flew until then (the controller keeps its nominal model, as for every perturbation). It
is made with :func:`vehicle_change`, which checks the new values as a vehicle file's are checked
(:class:`~quad_msgs_bridge.vehicle_params.VehicleParams`: a mass the rotors can still lift, losses in
[0, 1)) and names the argument that is wrong.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams


@dataclass(frozen=True)
class VehicleChange:
    """From sim time ``at_s`` [s] on, the simulator flies ``vehicle``."""

    at_s: float
    vehicle: VehicleParams


def vehicle_change(name: str, before: VehicleParams, at_s, **changed) -> VehicleChange:
    """``before`` with ``changed`` (VehicleParams fields, e.g. ``m`` [kg] or ``rotor_efficiency_loss``
    (4 lost fractions in [0, 1) of F1..F4)) from ``at_s`` [s] on; ParameterError naming ``name``."""
    at_s = check_number(f'{name}.at_s', at_s, 0.0)
    try:
        return VehicleChange(at_s, replace(before, **changed))
    except ParameterError as error:
        raise ParameterError(f'{name}: {error}') from error


def check_changes(changes: Sequence[VehicleChange]) -> tuple[VehicleChange, ...]:
    """``changes`` in time order; ParameterError if two happen at the same time."""
    ordered = tuple(sorted(changes, key=lambda change: change.at_s))
    for a, b in zip(ordered, ordered[1:]):
        if a.at_s == b.at_s:
            raise ParameterError(f'vehicle changes: two at the same time ({a.at_s:g} s); merge them into one')
    return ordered
