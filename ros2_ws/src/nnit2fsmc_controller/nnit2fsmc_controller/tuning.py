"""Changing gains in flight: a controller with the new gains that carries on from the running one's state.

:func:`retune` validates the new gains completely (by building a fresh controller of the same kind
from them), then moves the running controller's *state* into it: the network weights and the
learning step still pending, the rate filters, the integrators. What a class holds as state is
what its ``STATE`` attribute names; everything else of it is a parameter and comes from the new
gains. Gains that cannot change in flight (:data:`RESTART_GAINS`) are refused.
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from quad_msgs_bridge.validation import ParameterError

from .controller import CascadedController
from .estimation import MeasurementStage
from .factory import build_controller, build_measurement_stage

#: gains whose change needs a new controller (and their reason)
RESTART_GAINS = {
    'common.control_rate': 'the control rate is the simulator\'s odometry rate and every filter\'s sample time',
    'nnit2fsmc.hidden_units': 'the networks would change shape and lose what they learned',
    'nnit2fsmc.seed': 'it only seeds the initial weights',
}


def restart_reason(name: str) -> str | None:
    """Why gain ``name`` (flattened, e.g. 'common.control_rate') needs a restart, or None if it can change in flight."""
    return RESTART_GAINS.get(name)


def retune(controller: CascadedController, gains: Mapping[str, Any], batch: int | None = None) -> CascadedController:
    """A controller of the same kind for ``gains`` that goes on from ``controller``'s state.

    Raises ParameterError (naming the gain) if the gains are invalid, or if they change what cannot
    change in flight (the control period, the network sizes). A user's kind (nnit2fsmc_controller.contract)
    declares no STATE: its controller starts afresh with the new gains.
    """
    fresh = build_controller(controller.name, controller.params, gains, batch=batch)
    if fresh.dt != controller.dt:
        raise ParameterError(f'common.control_rate: cannot change in flight ({RESTART_GAINS["common.control_rate"]}); '
                             'restart the controller')
    if has_state(controller):   # a user's kind declares no state to carry: it starts afresh with the new gains
        _carry_state(controller, fresh, 'controller')
    return fresh


def retune_measurement(stage: MeasurementStage, gains: Mapping[str, Any]) -> MeasurementStage:
    """The measurement stage of ``gains`` going on from ``stage``'s filter estimates (a filter switched
    on in flight starts from the next measurement). Raises ParameterError naming an invalid gain."""
    fresh = build_measurement_stage(gains)
    for name in ('complementary', 'velocity'):
        old, new = getattr(stage, name), getattr(fresh, name)
        if old is not None and new is not None:
            _carry_state(old, new, f'measurement.{name}')
    return fresh


def has_state(value) -> bool:
    """Whether ``value`` is a part of a controller that declares what of it is state."""
    return getattr(type(value), 'STATE', None) is not None


def _carry_state(old, new, where: str) -> None:
    """Copy the STATE attributes of ``old`` into ``new``, recursing into the parts that declare STATE."""
    if type(old) is not type(new):
        raise ParameterError(f'{where}: the new gains change its structure ({type(old).__name__} -> '
                             f'{type(new).__name__}); restart the controller')
    for name in type(old).STATE:   # read and written as attributes: a single vehicle's may live in its store
        value, fresh = getattr(old, name), getattr(new, name)
        if None not in (_shape(value), _shape(fresh)) and _shape(value) != _shape(fresh):
            raise ParameterError(f'{where}.{name}: the new gains change its size; restart the controller')
        if isinstance(fresh, np.ndarray) and isinstance(value, np.ndarray):
            fresh[...] = value   # in place: the array may be a view of the new part's store (kernel_state)
        else:
            setattr(new, name, value)
    for name, value in vars(old).items():
        fresh = vars(new)[name]
        if name in type(old).STATE:
            continue
        if has_state(value):
            _carry_state(value, fresh, f'{where}.{name}')
        elif isinstance(value, dict):
            for key, part in value.items():
                if has_state(part):
                    _carry_state(part, fresh[key], f'{where}.{name}[{key!r}]')


def _shape(value):
    """The nesting lengths of a weight store (lists of lists, or an array), to catch a resized network;
    None for any other value."""
    if isinstance(value, np.ndarray):
        return value.shape
    if isinstance(value, list):
        return (len(value), *(_shape(value[0]) or () if value else ()))
    return None
