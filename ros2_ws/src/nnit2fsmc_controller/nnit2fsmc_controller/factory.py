"""Building a controller by name from the gains file (``config/controller.yaml``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import yaml

from quad_msgs_bridge.vehicle_params import ParameterError, VehicleParams, check_number

from .axis_laws import NNIT2FSMCLaw, PIDLaw, SlidingModeLaw
from .controller import AXES, CascadedController
from .it2_fuzzy import IT2FuzzyCorrector
from .neural_network import EquivalentControlNetwork

DEFAULT_CONTROLLER_FILE = Path(__file__).resolve().parent / 'config' / 'controller.yaml'
CONTROLLERS = ('nnit2fsmc', 'smc-sign', 'smc-sat', 'pid')
NN_INPUTS = 3   # (ref_vel, ref_acc, 1), see NNIT2FSMCLaw


def load_gains(path: str | Path | None = None) -> dict:
    """The gains file as a dict (default: the packaged one); errors name the file."""
    path = Path(path) if path is not None else DEFAULT_CONTROLLER_FILE
    try:
        gains = yaml.safe_load(path.read_text())
    except OSError as error:
        raise ParameterError(f'controller file {path}: {error.strerror}') from error
    except yaml.YAMLError as error:
        raise ParameterError(f'controller file {path}: not valid YAML ({error})') from error
    if not isinstance(gains, dict):
        raise ParameterError(f'controller file {path}: expected a mapping')
    return gains


def _get(tree: Mapping[str, Any], dotted: str) -> Any:
    node: Any = tree
    for key in dotted.split('.'):
        if not isinstance(node, Mapping) or key not in node:
            raise ParameterError(f'{dotted}: missing')
        node = node[key]
    return node


def _positive(tree, dotted: str) -> float:
    return check_number(dotted, _get(tree, dotted), 0.0, low_inclusive=False)


def _non_negative(tree, dotted: str) -> float:
    return check_number(dotted, _get(tree, dotted), 0.0)


def control_period(gains: Mapping[str, Any]) -> float:
    """Controller update period [s] from ``common.control_rate`` [Hz]."""
    return 1.0 / _positive(gains, 'common.control_rate')


def build_controller(kind: str, params: VehicleParams, gains: Mapping[str, Any] | None = None) -> CascadedController:
    """A fresh controller of ``kind`` (one of CONTROLLERS) for the vehicle ``params``."""
    gains = load_gains() if gains is None else gains
    dt = control_period(gains)
    lam = {axis: _positive(gains, f'common.lambda.{axis}') for axis in AXES}
    if kind == 'nnit2fsmc':
        hidden = int(_positive(gains, 'nnit2fsmc.hidden_units'))
        seed = int(_non_negative(gains, 'nnit2fsmc.seed'))
        laws = {}
        for index, axis in enumerate(AXES):
            key = f'nnit2fsmc.axes.{axis}'
            fuzzy = IT2FuzzyCorrector(
                input_scale=_positive(gains, f'{key}.input_scale'),
                output_gain=_non_negative(gains, f'{key}.fuzzy_gain'),
                lower_height=_positive(gains, 'nnit2fsmc.lower_height'),
                lower_half_width=_positive(gains, 'nnit2fsmc.lower_half_width'),
                type_reducer=_get(gains, 'nnit2fsmc.type_reducer'))
            network = EquivalentControlNetwork(
                n_inputs=NN_INPUTS, n_hidden=hidden,
                output_gain=_positive(gains, f'{key}.nn_gain'),
                learning_rate=_non_negative(gains, f'{key}.learning_rate'),
                weight_limit=_positive(gains, 'nnit2fsmc.weight_limit'),
                seed=seed * len(AXES) + index)
            laws[axis] = NNIT2FSMCLaw(lam[axis], fuzzy, network)
    elif kind in ('smc-sign', 'smc-sat'):
        laws = {axis: SlidingModeLaw(
            lam[axis], _non_negative(gains, f'smc.switching_gain.{axis}'),
            _positive(gains, f'smc.boundary_layer.{axis}') if kind == 'smc-sat' else 0.0)
            for axis in AXES}
    elif kind == 'pid':
        laws = {axis: PIDLaw(
            lam[axis],
            kp=_non_negative(gains, f'pid.axes.{axis}.kp'),
            ki=_non_negative(gains, f'pid.axes.{axis}.ki'),
            kd=_non_negative(gains, f'pid.axes.{axis}.kd'),
            integral_limit=_non_negative(gains, f'pid.axes.{axis}.integral_limit'),
            dt=dt) for axis in AXES}
    else:
        raise ParameterError(f'controller: {kind!r} is not one of {", ".join(CONTROLLERS)}')
    return CascadedController(
        kind, params, laws, dt,
        max_tilt=_positive(gains, 'common.max_tilt'),
        angle_filter_tau=_positive(gains, 'common.angle_filter_tau'))
