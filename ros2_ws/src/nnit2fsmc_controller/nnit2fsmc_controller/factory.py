"""Building a controller by name from the gains file (``config/controller.yaml``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import yaml

from quad_msgs_bridge.mixer import ALLOCATIONS
from quad_msgs_bridge.vehicle_params import ParameterError, VehicleParams, check_number

from .axis_laws import IntegralSlidingModeLaw, NNIT2FSMCLaw, PIDLaw, SlidingModeLaw
from .controller import AXES, CascadedController
from .it2_fuzzy import TYPE_REDUCERS, IT2FuzzyCorrector
from .neural_network import EquivalentControlNetwork
from .se3 import SE3Controller

DEFAULT_CONTROLLER_FILE = Path(__file__).resolve().parent / 'config' / 'controller.yaml'
CONTROLLERS = ('nnit2fsmc', 'smc-sign', 'smc-sat', 'smc-integral', 'pid', 'se3')
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
    return ros_parameters(gains)


NODE_PARAMETERS = ('controller', 'vehicle_file', 'gains_file', 'goal_speed', 'odom_timeout')


def ros_parameters(document: dict) -> dict:
    """The gains of a ROS 2 parameter file (``<node>: ros__parameters: ...``), node-level parameters removed.

    A plain gains mapping (no ``ros__parameters``) is returned unchanged.
    """
    sections = [value['ros__parameters'] for value in document.values()
                if isinstance(value, dict) and 'ros__parameters' in value]
    if not sections:
        return document
    gains: dict = {}
    for section in sections:
        gains.update({k: v for k, v in section.items() if k not in NODE_PARAMETERS})
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


def build_controller(kind: str, params: VehicleParams, gains: Mapping[str, Any] | None = None,
                     batch: int | None = None) -> CascadedController | SE3Controller:
    """A fresh controller of ``kind`` (one of CONTROLLERS) for the nominal vehicle ``params``.

    ``batch``: None for one vehicle (states of floats), or the number B of vehicles it steps at once
    (states of numpy arrays of B values; every vehicle has its own network weights).
    """
    gains = load_gains() if gains is None else gains
    dt = control_period(gains)
    lam = {axis: _positive(gains, f'common.lambda.{axis}') for axis in AXES}
    structure = dict(max_tilt=_positive(gains, 'common.max_tilt'),
                     angle_filter_tau=_positive(gains, 'common.angle_filter_tau'),
                     allocation=gains.get('common', {}).get('allocation', 'priority'))
    if kind == 'se3':
        se3_gains = {axis: tuple(_non_negative(gains, f'se3.axes.{axis}.{name}')
                                 for name in ('k_error', 'k_rate', 'k_integral', 'integral_limit')) for axis in AXES}
        return SE3Controller(kind, params, se3_gains, lam, dt, **structure)
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
                seed=seed * len(AXES) + index, batch=batch)
            laws[axis] = NNIT2FSMCLaw(lam[axis], fuzzy, network)
    elif kind in ('smc-sign', 'smc-sat'):
        laws = {axis: SlidingModeLaw(
            lam[axis], _non_negative(gains, f'smc.switching_gain.{axis}'),
            _positive(gains, f'smc.boundary_layer.{axis}') if kind == 'smc-sat' else 0.0)
            for axis in AXES}
    elif kind == 'smc-integral':
        laws = {axis: IntegralSlidingModeLaw(
            lam[axis],
            mu=_non_negative(gains, f'smc_integral.axes.{axis}.integral_gain'),
            slope=_positive(gains, f'smc_integral.axes.{axis}.slope'),
            switching_gain=_non_negative(gains, f'smc_integral.axes.{axis}.switching_gain'),
            gain_uncertainty=_non_negative(gains, f'smc_integral.axes.{axis}.gain_uncertainty'),
            integral_limit=_non_negative(gains, f'smc_integral.axes.{axis}.integral_limit'),
            dt=dt) for axis in AXES}
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
    return CascadedController(kind, params, laws, dt, **structure)


def flatten_gains(gains: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """The gains tree as {'nnit2fsmc.axes.x.fuzzy_gain': 3.0, ...} (ROS parameter names)."""
    flat = {}
    for key, value in gains.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(flatten_gains(value, name + '.'))
        else:
            flat[name] = value
    return flat


def unflatten_gains(flat: Mapping[str, Any]) -> dict:
    """Inverse of :func:`flatten_gains`."""
    tree: dict = {}
    for name, value in flat.items():
        node = tree
        *parents, leaf = name.split('.')
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = value
    return tree


#: what each gain means, by the last non-axis component of its name
GAIN_DESCRIPTIONS = {
    'control_rate': 'controller update rate [Hz] (equals the simulator odometry rate)',
    'max_tilt': 'largest roll/pitch the position loop may ask for [rad]',
    'angle_filter_tau': 'time constant of the desired-angle differentiation filter [s]',
    'allocation': 'rotor limits: priority (U1 kept, then roll/pitch scaled to fit, yaw last) or clip (each rotor '
                  'clipped, paper-faithful)',
    'lambda': 'sliding-surface slope lambda of S = de + lambda e [1/s]',
    'type_reducer': 'IT2 type reduction: km (exact Karnik-Mendel) or nie-tan',
    'lower_height': 'height of the lower membership functions, in (0, 1]',
    'lower_half_width': 'half-width of the lower membership functions, in (0, 0.5] (label spacing 0.5)',
    'hidden_units': 'hidden neurons of each subsystem network',
    'weight_limit': 'every NN weight is kept within +-this',
    'seed': 'seed of the initial hidden weights',
    'input_scale': 'sliding-surface value that saturates the fuzzy input [units of S]',
    'fuzzy_gain': 'IT2 fuzzy corrective output gain [units of the subsystem control]',
    'nn_gain': 'NN output gain K_eq [units of the subsystem control]',
    'learning_rate': 'NN learning rate alpha of eqs. (6)-(7), per update',
    'boundary_layer': 'smc-sat boundary-layer width [units of S]',
    'switching_gain': 'SMC switching gain [units of the second derivative of the subsystem]',
    'kp': 'PID proportional gain', 'ki': 'PID integral gain', 'kd': 'PID derivative gain',
    'integral_limit': 'integral clamp of pid, smc-integral, se3 [units of e * s]',
    'slope': 'smc-integral linear gain inside the boundary layer [units of q\'\' per unit of S]',
    'integral_gain': 'smc-integral surface S = de + lambda e + integral_gain int(e) [1/s^2]',
    'gain_uncertainty': 'smc-integral relative control-gain uncertainty: adds this times |u_eq| to the switching gain',
    'k_error': 'se3 attitude or position error gain, divided by J or m [1/s^2]',
    'k_rate': 'se3 angular or linear velocity error gain, divided by J or m [1/s]',
    'k_integral': 'se3 integral gain, divided by J or m [1/s^3]',
}


#: the valid values of each string gain, by the last component of its name
GAIN_CHOICES = {
    'type_reducer': TYPE_REDUCERS,
    'allocation': ALLOCATIONS,
}


def gain_choices(name: str) -> tuple[str, ...]:
    """Valid values of the string gain ``name`` (flattened, e.g. 'nnit2fsmc.type_reducer')."""
    return GAIN_CHOICES[name.split('.')[-1]]


def gain_description(name: str) -> str:
    """Human description of a flattened gain name such as 'nnit2fsmc.axes.x.fuzzy_gain'."""
    parts = name.split('.')
    axis = next((p for p in parts if p in AXES), None)
    meaning = next(GAIN_DESCRIPTIONS[p] for p in reversed(parts) if p in GAIN_DESCRIPTIONS)
    return f'{meaning}, {axis} subsystem' if axis else meaning
