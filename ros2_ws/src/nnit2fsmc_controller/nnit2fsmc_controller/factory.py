"""Building a controller by name from the gains file (``config/controller.yaml``)."""
from __future__ import annotations

import copy
import difflib
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import yaml

from quad_msgs_bridge.frames import quaternion_from_euler
from quad_msgs_bridge.mixer import ALLOCATIONS
from quad_msgs_bridge.reference import SetpointPath, hold
from quad_msgs_bridge.state import odometry_from_state, state_from_odometry
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams
from quad_msgs_bridge.yaml_files import load_yaml



from .axis_laws import NNIT2FSMCLaw
from .controller import ATTITUDE_RATES, AXES
from .estimation import MeasurementStage
from .gain_units import check_hover_authority, in_vehicle_units
from .it2_fuzzy import TYPE_REDUCERS, IT2FuzzyCorrector, SaturationCorrector
from .kinds import ABLATIONS as _ABLATIONS, BUILT_IN
from .neural_network import MODIFICATIONS, EquivalentControlNetwork
from .registry import controller_kind, kind_for_section, section_gains

DEFAULT_CONTROLLER_FILE = Path(__file__).resolve().parent / 'config' / 'controller.yaml'
#: the named gains sets (``--gains NAME``; docs/SCOREBOARD.md): 'untuned' (the packaged gains before issue 26's
#: tuning) and 'paper-faithful' (those with PAPER_FAITHFUL); 'packaged' is DEFAULT_CONTROLLER_FILE (every
#: kind's tuned point, as the scoreboard flew them)
SHIPPED_GAINS = Path(__file__).resolve().parent / 'config' / 'gains'
#: the NNIT2FSMC's ablations (docs/ADAPTIVE.md; :data:`.kinds.ABLATIONS`)
ABLATIONS = tuple(_ABLATIONS)
#: the built-in kinds' names (:mod:`.kinds`); a user's kind is named by an entry point or module:Class (:mod:`.registry`)
CONTROLLERS = tuple(kind.name for kind in BUILT_IN)
#: the largest network a subsystem may have (hidden neurons): a 500 Hz update stays cheap and planning instant
MAX_HIDDEN_UNITS = 1000
NN_INPUTS = 3   # (ref_vel, ref_acc, 1), see NNIT2FSMCLaw
FEEDFORWARD_AXES = ('x', 'y')   #: where the virtual control is the subsystem's acceleration (nnit2fsmc.acceleration_feedforward)
#: the paper-faithful value of every key that changes the controller away from the paper (docs/ADAPTIVE.md),
#: with the gains of the first tuning (docs/PAPER.md section 3; the defaults were retuned for motor lag):
#: together they fly the nominal tables' "paper-faithful" rows
PAPER_FAITHFUL: dict = {
    'common.attitude_rates': 'filter',
    'common.max_tilt': 0.6, 'common.low_altitude_height': 0.0,
    'common.allocation': 'clip',
    'common.lambda.phi': 12.0, 'common.lambda.theta': 12.0,
    'nnit2fsmc.axes.x.input_scale': 0.3, 'nnit2fsmc.axes.y.input_scale': 0.3,
    'nnit2fsmc.axes.x.fuzzy_gain': 3.0, 'nnit2fsmc.axes.y.fuzzy_gain': 3.0,
    'nnit2fsmc.axes.phi.input_scale': 2.0, 'nnit2fsmc.axes.theta.input_scale': 2.0,
    # [rad/s^2]: 1 N of U2, U3 on the packaged vehicle, restated exactly (gain_units; config/controller.yaml)
    'nnit2fsmc.axes.phi.fuzzy_gain': 65.31166727624223, 'nnit2fsmc.axes.theta.fuzzy_gain': 65.31166727624223,
    'nnit2fsmc.learning_rate_unit': 'per_update',
    'nnit2fsmc.modification': 'none',
    'common.measurement_filter_hz': 0.0, 'common.velocity_filter_hz': 0.0,
    'common.takeoff_height': 0.0,
    'nnit2fsmc.acceleration_feedforward': False,
    # the first tuning's x, y network (the paper gives no numbers): output cap and initial hidden weights
    'nnit2fsmc.axes.x.nn_gain': 1.5, 'nnit2fsmc.axes.y.nn_gain': 1.5, 'nnit2fsmc.initial_weight_spread': 0.5,
    'nnit2fsmc.axes.x.learning_rate': 0.01, 'nnit2fsmc.axes.y.learning_rate': 0.01,
    'nnit2fsmc.axes.x.max_adaptation_rate': 0.0, 'nnit2fsmc.axes.y.max_adaptation_rate': 0.0,
    # per update, in acceleration units: 0.002, 0.05, 0.05 and 30 in N (N m) on the packaged vehicle, restated exactly
    'nnit2fsmc.axes.z.learning_rate': 0.000472392, 'nnit2fsmc.axes.phi.learning_rate': 1.1721642272e-05,
    'nnit2fsmc.axes.theta.learning_rate': 1.1721642272e-05, 'nnit2fsmc.axes.psi.learning_rate': 0.0017587057068000002,
}


def shipped_gains() -> dict[str, Path]:
    """The named gains files: 'packaged' (the default) and those of SHIPPED_GAINS, by file stem."""
    return {'packaged': DEFAULT_CONTROLLER_FILE, **{p.stem: p for p in sorted(SHIPPED_GAINS.glob('*.yaml'))}}


def locate_gains(path: str | Path | None) -> Path:
    """The gains file of ``path``: a file that exists, else the named gains set of that name (``untuned`` or
    ``untuned.yaml``), else ``path`` as given; None: the packaged file."""
    if path is None:
        return DEFAULT_CONTROLLER_FILE
    path = Path(path)
    if path.exists() or path.parent != Path('.'):
        return path
    return shipped_gains().get(path.name[:-len('.yaml')] if path.suffix == '.yaml' else path.name, path)


@dataclass(frozen=True)
class GainsFile:
    """What a gains file says: its gains (all of them, or only those it changes), the kind it was made for
    (``controller:``, as ``tune`` writes it) and the gains it changes (``base:``, a named set or a file)."""

    path: Path
    gains: dict
    controller: str | None = None
    base: str | None = None


def read_gains_file(path: str | Path) -> GainsFile:
    """The gains file at ``path`` (or the named set of that name: :func:`locate_gains`), a plain gains mapping
    or a ROS 2 parameter file; errors name the file."""
    if not isinstance(path, (str, Path)):
        raise ParameterError(f'gains: expected a gains YAML path or a named set ({", ".join(shipped_gains())}), '
                             f'got {path!r}')
    path = locate_gains(path)
    try:
        document = load_yaml(path.read_text())
    except OSError as error:
        raise ParameterError(f'controller file {path}: {error.strerror} (named gains: '
                             f'{", ".join(shipped_gains())})') from error
    except yaml.YAMLError as error:
        raise ParameterError(f'controller file {path}: not valid YAML ({error})') from error
    if not isinstance(document, dict):
        raise ParameterError(f'controller file {path}: expected a mapping')
    declared = {key: document.pop(key) for key in ('controller', 'base') if key in document}
    node = ros_node_parameters(document)
    declared.update({key: node[key] for key in ('controller', 'base') if key in node})
    for key, value in declared.items():
        if not isinstance(value, str) or not value:
            raise ParameterError(f'controller file {path}: {key}: expected a name, got {value!r}')
    return GainsFile(path, ros_parameters(document), declared.get('controller'), declared.get('base'))


def load_gains(path: str | Path | Mapping[str, Any] | None = None, *,
               kind: str | Sequence[str] | None = None) -> dict:
    """The whole gains tree of ``path``: a gains file or a named set (:func:`locate_gains`), or a mapping,
    merged over the gains it changes (its ``base:``, else the packaged set), so a file may hold one key
    only; None: the packaged set. With ``kind``, a user's kind's section holds its defaults too. Errors
    name the file and the gain (an unknown one with the closest valid name). ``kind`` may list several kinds."""
    if path is None:
        tree = _read_tree(DEFAULT_CONTROLLER_FILE)
    elif isinstance(path, Mapping):
        tree = merged(_read_tree(DEFAULT_CONTROLLER_FILE), path)
    else:
        read = read_gains_file(path)
        base = DEFAULT_CONTROLLER_FILE if read.base is None else _base_path(read)
        tree = merged(load_gains(base) if base != read.path else {}, read.gains, f'controller file {read.path}: ')
    for name in [kind] if isinstance(kind, str) else kind or ():
        described = controller_kind(name)
        if described.schema is not None:
            tree[described.gains_section] = section_gains(described, tree)
    try:
        check_gain_names(tree)
    except ParameterError as error:
        where = '' if path is None or isinstance(path, Mapping) else f'controller file {locate_gains(path)}: '
        raise ParameterError(f'{where}{error}') from error
    return tree


def _read_tree(path: Path) -> dict:
    return read_gains_file(path).gains


def _base_path(read: GainsFile) -> Path:
    """The file that ``read``'s ``base:`` names: a named set, or a path relative to ``read``'s folder."""
    named = shipped_gains()
    if read.base in named:
        return named[read.base]
    base = Path(read.base)
    base = base if base.is_absolute() else read.path.parent / base
    if not base.exists():
        raise ParameterError(f'controller file {read.path}: base: {read.base!r} is neither a named set '
                             f'({", ".join(named)}) nor a file')
    return base


def merged(base: Mapping[str, Any], changes: Mapping[str, Any], where: str = '', prefix: str = '') -> dict:
    """A copy of the gains tree ``base`` with every gain of ``changes`` (a tree, or part of one) replacing its own."""
    if not isinstance(changes, Mapping):
        raise ParameterError(f'{where}gains: expected a mapping, got {type(changes).__name__}')
    tree = copy.deepcopy(dict(base))
    for key, value in changes.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            if key in tree and not isinstance(tree[key], Mapping):
                raise ParameterError(f'{where}{name}: is a gain, not a section of gains (got {dict(value)!r})')
            tree[key] = merged(tree.get(key, {}), value, where, name + '.')
        else:
            if isinstance(tree.get(key), Mapping):
                raise ParameterError(f'{where}{name}: is a section of gains ({", ".join(tree[key])}), not one value')
            tree[key] = copy.deepcopy(value)
    return tree


def with_settings(gains: Mapping[str, Any], settings: Sequence[str]) -> dict:
    """``gains`` with each ``KEY=VALUE`` of ``settings`` set (``--set pid.axes.x.kp=30``: KEY dotted as the gains
    file nests it, VALUE read as YAML); an unknown KEY is refused with the closest valid name."""
    changes: dict = {}
    for setting in settings:
        name, equals, text = setting.partition('=')
        name = name.strip()
        if not equals or not name:
            raise ParameterError(f'--set {setting!r}: expected KEY=VALUE (e.g. --set pid.axes.x.kp=30)')
        try:
            value = load_yaml(text) if text.strip() else None
        except yaml.YAMLError:
            value = text
        if value is None or isinstance(value, (dict, list)):
            raise ParameterError(f'--set {setting!r}: VALUE must be one number, word or true/false')
        changes[name] = value
    tree = merged(gains, unflatten_gains(changes), '--set ')
    try:
        check_gain_names(tree)
    except ParameterError as error:
        raise ParameterError(f'--set {error}') from error
    return tree


def declared_controller(path: str | Path | Mapping[str, Any] | None) -> str | None:
    """The kind a gains file says it was made for (its ``controller:``), or None (also for a mapping or None)."""
    if path is None or isinstance(path, Mapping):
        return None
    return read_gains_file(path).controller


def choose_controller(requested: str | None, gains: str | Path | Mapping[str, Any] | None,
                      default: str = 'nnit2fsmc') -> str:
    """The kind to fly: ``requested`` (``--controller``), which must agree with the gains file's ``controller:``;
    the file's alone selects it; neither: ``default``."""
    declared = declared_controller(gains)
    if requested is not None and declared is not None and requested != declared:
        raise ParameterError(f'--controller {requested}: the gains file {locate_gains(gains)} was made for '
                             f'controller {declared} (its controller: key); fly --controller {declared}, or drop '
                             'its controller: line')
    return requested or declared or default


@functools.lru_cache(maxsize=1)
def gain_names() -> frozenset[str]:
    """Every gain of the built-in kinds a gains file may hold, flattened ('common.lambda.x', ...): those of the
    packaged file."""
    document = load_yaml(DEFAULT_CONTROLLER_FILE.read_text())
    return frozenset(flatten_gains(ros_parameters(document)))


def _did_you_mean(name: str, candidates) -> str:
    """' (did you mean X?)' for the closest of ``candidates`` to ``name``, or ''."""
    close = difflib.get_close_matches(name, sorted(candidates), n=1)
    return f' (did you mean {close[0]}?)' if close else ''


def check_gain_names(gains: Mapping[str, Any]) -> None:
    """ParameterError naming the first gain of ``gains`` (a tree, as in the gains file) that is not a gain,
    with the closest valid name: a misspelt gain would otherwise fly silently with its default. A section
    no built-in kind reads is a user's kind's (:func:`.registry.kind_for_section`), checked against its schema."""
    if not isinstance(gains, Mapping):
        raise ParameterError(f'gains: expected a mapping, got {type(gains).__name__}')
    valid = gain_names()
    sections = {name.split('.')[0] for name in valid}
    for section, part in gains.items():
        if section not in sections:
            user = kind_for_section(str(section))
            if user is not None:
                section_gains(user, gains)
                continue
        for name in flatten_gains({section: part}):
            if name not in valid:
                raise ParameterError(f'{name}: unknown gain{_did_you_mean(name, valid)}')


NODE_PARAMETERS = ('controller', 'base', 'vehicle_file', 'gains_file', 'goal_speed', 'odom_timeout')


def ros_node_parameters(document: dict) -> dict:
    """The node-level parameters of a ROS 2 parameter file (``controller``, ...), {} for a plain gains mapping."""
    return {key: value for section in document.values() if isinstance(section, dict) and 'ros__parameters' in section
            for key, value in section['ros__parameters'].items() if key in NODE_PARAMETERS}


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
    parents: list[str] = []
    for key in dotted.split('.'):
        if not isinstance(node, Mapping) or key not in node:
            name = '.'.join([*parents, key])
            siblings = ['.'.join([*parents, str(k)]) for k in node] if isinstance(node, Mapping) else []
            unknown = [sibling for sibling in siblings if not _is_gain_prefix(sibling)]
            raise ParameterError(f'{name}: missing{_did_you_mean(name, unknown)}')
        node = node[key]
        parents.append(key)
    return node


def _is_gain_prefix(name: str) -> bool:
    """Whether ``name`` is a gain or a section of gains ('common.lambda')."""
    return any(valid == name or valid.startswith(name + '.') for valid in gain_names())


def _positive(tree, dotted: str) -> float:
    return check_number(dotted, _get(tree, dotted), 0.0, low_inclusive=False)


def _non_negative(tree, dotted: str) -> float:
    return check_number(dotted, _get(tree, dotted), 0.0)


def _flag(tree, dotted: str) -> bool:
    value = _get(tree, dotted)
    if not isinstance(value, bool):
        raise ParameterError(f'{dotted}: expected true or false, got {value!r}')
    return value


def control_period(gains: Mapping[str, Any]) -> float:
    """Controller update period [s] from ``common.control_rate`` [Hz]."""
    return 1.0 / _positive(gains, 'common.control_rate')


LEARNING_RATE_UNITS = ('per_second', 'per_update')


def learning_rate(gains: Mapping[str, Any], axis: str, dt: float, params: VehicleParams) -> float:
    """The network's rate alpha per update for subsystem ``axis`` at control period ``dt`` [s] on the nominal
    vehicle ``params`` (stated in acceleration units, :mod:`.gain_units`; the law's is alpha b^2).

    ``nnit2fsmc.learning_rate_unit``: ``per_second`` (alpha of eqs. 6-7 is a rate per second, the
    continuous-time adaptation gain; the step per update is alpha dt, so a change of control rate
    keeps the adaptation speed) or ``per_update`` (the paper's discrete alpha, taken as is).
    """
    unit = _get(gains, 'nnit2fsmc.learning_rate_unit')
    if unit not in LEARNING_RATE_UNITS:
        raise ParameterError(f'nnit2fsmc.learning_rate_unit: {unit!r} is not one of {", ".join(LEARNING_RATE_UNITS)}')
    name = f'nnit2fsmc.axes.{axis}.learning_rate'
    alpha = in_vehicle_units(name, _non_negative(gains, name), params, axis)
    return alpha * dt if unit == 'per_second' else alpha


def build_controller(kind: str, params: VehicleParams, gains: Mapping[str, Any] | None = None,
                     batch: int | None = None):
    """A fresh controller of ``kind`` (a built-in kind, an installed entry point's or ``module:Class``:
    :mod:`.registry`) for the nominal vehicle ``params``, from the gains tree ``gains`` (None: the packaged one).

    ``batch``: None for one vehicle (states of floats), or the number B of vehicles it steps at once
    (states of numpy arrays of B values; every vehicle has its own network weights).
    """
    gains = load_gains() if gains is None else gains
    check_gain_names(gains)
    return controller_kind(kind).build(kind, params, gains, batch)


def build_measurement_stage(gains: Mapping[str, Any] | None = None) -> MeasurementStage:
    """The measurement stage every controller kind reads through (:class:`.estimation.MeasurementStage`),
    from ``common.measurement_filter_hz`` and ``common.velocity_filter_hz`` at the control period; one
    stage serves one vehicle or a batch (its filters take floats or arrays)."""
    gains = load_gains() if gains is None else gains
    return MeasurementStage(control_period(gains),
                            measurement_filter_hz=_non_negative(gains, 'common.measurement_filter_hz'),
                            velocity_filter_hz=_non_negative(gains, 'common.velocity_filter_hz'))


def compile_kernels(kind: str, params: VehicleParams, gains: Mapping[str, Any] | None = None) -> None:
    """Have numba build, or load from its cache, the compiled kernels a ``kind`` controller node runs per
    step: the odometry conversion, the sampling of a setpoint path, two updates and learning steps of a
    throwaway controller hovering at 1 m, the reference pose's quaternion (0.3 s from the cache;
    seconds the first time after an install). A ROS controller node does this before it subscribes, so
    its first answer is as quick as the others (a lockstep simulator publishes an odometry again when
    the answer takes longer than its ``input_timeout``)."""
    controller = build_controller(kind, params, gains)
    hover = state_from_odometry(odometry_from_state(0.0, [0.0, 0.0, 1.0] + [0.0] * 9))
    path = SetpointPath([0.0, 1.0], [hold((0.0, 0.0, 1.0)), hold((0.0, 0.0, 1.0))])
    for t in (0.0, controller.dt):
        controller.update(t, hover, path.sample(t))
        controller.adapt()     # as the node does after publishing
    quaternion_from_euler(0.0, 0.0, 0.0)


def _authority(gains: Mapping[str, Any], name: str, params: VehicleParams, axis: str):
    """The output cap ``name`` (fuzzy_gain or nn_gain, stated in acceleration units) in the law's units on the
    nominal vehicle ``params``, after the hover check of :func:`.gain_units.check_hover_authority`."""
    stated = _positive(gains, name) if name.endswith('nn_gain') else _non_negative(gains, name)
    check_hover_authority(name, stated, params)
    return in_vehicle_units(name, stated, params, axis)


def nnit2fsmc_law(kind: str, gains: Mapping[str, Any], axis: str, lam: float, dt: float,
                  batch: int | None, params: VehicleParams) -> NNIT2FSMCLaw:
    """The NNIT2FSMC law of subsystem ``axis``, or of one of its ABLATIONS (``kind``), on the nominal vehicle
    ``params``: the gains file's acceleration units turned into the law's (:mod:`.gain_units`)."""
    key = f'nnit2fsmc.axes.{axis}'
    input_scale = _positive(gains, f'{key}.input_scale')
    fuzzy_gain = _authority(gains, f'{key}.fuzzy_gain', params, axis)
    if kind == 'nnit2fsmc-sat':
        fuzzy = SaturationCorrector(input_scale, fuzzy_gain)
    else:
        type1 = kind == 'nnit2fsmc-type1'   # lower MFs equal to the upper ones: height 1, half-width 0.5
        fuzzy = IT2FuzzyCorrector(
            input_scale=input_scale, output_gain=fuzzy_gain,
            lower_height=1.0 if type1 else _positive(gains, 'nnit2fsmc.lower_height'),
            lower_half_width=0.5 if type1 else _positive(gains, 'nnit2fsmc.lower_half_width'),
            type_reducer=_get(gains, 'nnit2fsmc.type_reducer'))
    modification = _get(gains, 'nnit2fsmc.modification')
    network = EquivalentControlNetwork(
        n_inputs=1 if kind == 'nnit2fsmc-bias' else NN_INPUTS,
        n_hidden=int(check_number('nnit2fsmc.hidden_units', _get(gains, 'nnit2fsmc.hidden_units'), 1, MAX_HIDDEN_UNITS)),
        output_gain=_authority(gains, f'{key}.nn_gain', params, axis),
        learning_rate=0.0 if kind == 'nnit2fsmc-nolearn' else learning_rate(gains, axis, dt, params),
        weight_limit=_positive(gains, 'nnit2fsmc.weight_limit'),
        initial_spread=_positive(gains, 'nnit2fsmc.initial_weight_spread'),
        seed=int(_non_negative(gains, 'nnit2fsmc.seed')) * len(AXES) + AXES.index(axis), batch=batch,
        modification=modification,
        leakage=_non_negative(gains, 'nnit2fsmc.leakage') * dt if modification != 'none' else 0.0,
        max_rate=_non_negative(gains, f'{key}.max_adaptation_rate') * dt)
    return NNIT2FSMCLaw(lam, fuzzy, network, bias_only=kind == 'nnit2fsmc-bias',
                        feedforward=axis in FEEDFORWARD_AXES and _flag(gains, 'nnit2fsmc.acceleration_feedforward'))


def gains_flown_by(kind: str, gains: Mapping[str, Any]) -> dict[str, Any]:
    """The gains ``kind`` flies, flattened ({'common.control_rate': 500.0, 'pid.axes.x.kp': ...}): the
    ``common`` section and the kind's own (its ``gains_section``; a user's kind's over its defaults), so two
    gains files that differ elsewhere fly it the same."""
    described = controller_kind(kind)
    flat = flatten_gains(gains)
    flown = {name: value for name, value in flat.items() if name.split('.')[0] == 'common'}
    if described.schema is None:
        flown.update({name: value for name, value in flat.items() if name.split('.')[0] == described.gains_section})
    else:
        flown.update(flatten_gains({described.gains_section: section_gains(described, gains)}))
    return flown


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
    'max_tilt': 'largest roll/pitch the position loop may ask for [rad] (at and above low_altitude_height)',
    'low_altitude_max_tilt': 'largest roll/pitch the position loop may ask for below low_altitude_height [rad]',
    'low_altitude_height': 'height [m, ground at z = 0] below which the tilt limit is low_altitude_max_tilt '
                           '(0: max_tilt at every height)',
    'angle_filter_tau': 'time constant of the desired-angle differentiation filter [s]',
    'allocation': 'rotor limits: priority (U1 kept, then roll/pitch scaled to fit, yaw last), airmode (airborne, '
                  'at a U1 too low for the moments: roll/pitch kept, then yaw, U1 raised to what they need; else '
                  'priority) or clip '
                  '(each rotor clipped, paper-faithful)',
    'attitude_rates': 'desired roll/pitch rates: flatness (from the reference jerk and snap) or filter (paper)',
    'measurement_filter_hz': 'crossover of the complementary filter of measured position and angles [Hz], the '
                             'measurement stage of every controller kind (0: none, paper)',
    'velocity_filter_hz': 'cutoff of the first-order low-pass of the measured velocities [Hz], the measurement '
                          'stage of every controller kind (0: none, paper)',
    'takeoff_height': 'height [m, ground at z = 0] below which every controller kind '
                      'holds what it adapts or integrates on the x, y and attitude axes (networks, integrators, L1 '
                      'estimates, INDI increments) (0: off, paper)',
    'acceleration_feedforward': 'x, y: add the reference acceleration to the NN and fuzzy terms (false: paper)',
    'modification': 'leakage of the NN learning: none (paper), sigma (sigma-modification) or e (e-modification)',
    'leakage': 'leakage rate sigma of the sigma- or e-modification [1/s]',
    'lambda': 'sliding-surface slope lambda of S = de + lambda e [1/s]',
    'type_reducer': 'IT2 type reduction: km (exact Karnik-Mendel) or nie-tan',
    'lower_height': 'height of the lower membership functions, in (0, 1]',
    'lower_half_width': 'half-width of the lower membership functions, in (0, 0.5] (label spacing 0.5)',
    'hidden_units': 'hidden neurons of each subsystem network',
    'weight_limit': 'every NN weight is kept within +-this',
    'seed': 'seed of the initial hidden weights',
    'initial_weight_spread': 'the initial hidden weights are drawn uniformly from +-this (seeded by seed)',
    'input_scale': 'sliding-surface value that saturates the fuzzy input [units of S]',
    'fuzzy_gain': 'IT2 fuzzy corrective output gain [m/s^2 or rad/s^2: the acceleration it gives; times m, Ix/d, '
                  'Iy/d or Iz on the vehicle]',
    'nn_gain': 'NN output gain K_eq [m/s^2 or rad/s^2: the acceleration it gives; times m, Ix/d, Iy/d or Iz on the '
               'vehicle]',
    'learning_rate': 'NN learning rate alpha of eqs. (6)-(7) in acceleration units, per second or per update '
                     '(learning_rate_unit); divided by the square of m, Ix/d, Iy/d or Iz on the vehicle',
    'max_adaptation_rate': 'largest adaptation rate of the NN [1/s]: the learning step is scaled down where the rate '
                           'at which U_eq_hat follows the fuzzy term would exceed it (0: no bound, paper)',
    'learning_rate_unit': 'unit of the learning rates: per_second (alpha dt per update) or per_update (paper)',
    'boundary_layer': 'smc-sat boundary-layer width [units of S]',
    'switching_gain': 'SMC switching gain [units of the second derivative of the subsystem]',
    'kp': 'PID proportional gain', 'ki': 'PID integral gain', 'kd': 'PID derivative gain',
    'integral_limit': 'integral clamp of pid, smc-integral, se3, l1-se3 [units of e * s]',
    'slope': 'smc-integral linear gain inside the boundary layer [units of q\'\' per unit of S]',
    'integral_gain': 'smc-integral surface S = de + lambda e + integral_gain int(e) [1/s^2]',
    'gain_uncertainty': 'smc-integral relative control-gain uncertainty: adds this times |u_eq| to the switching gain',
    'k_error': 'se3, l1-se3, indi attitude or position error gain, divided by J or m [1/s^2]',
    'k_rate': 'se3, l1-se3, indi angular or linear velocity error gain, divided by J or m [1/s]',
    'k_integral': 'se3, l1-se3 integral gain, divided by J or m [1/s^3]',
    'predictor_pole_translation': 'l1-se3: pole a_v of the velocity predictor, A_s = -a_v I [1/s]',
    'predictor_pole_rotation': 'l1-se3: pole a_w of the body-rate predictor, A_s = -a_w I [1/s]',
    'cutoff_translation_hz': 'l1-se3: cutoff of the low-pass C(s) of the thrust-axis compensation [Hz] (0: none)',
    'cutoff_rotation_hz': 'l1-se3: cutoff of the low-pass C(s) of the angular-acceleration compensation [Hz] (0: none)',
    'cutoff_rotation_second_hz': 'l1-se3: cutoff of a second low-pass cascaded after it [Hz] (0: one stage)',
    'estimate_limit_translation': 'l1-se3: bound on each component of the acceleration estimate sigma_v [m/s^2]',
    'estimate_limit_rotation': 'l1-se3: bound on each component of the angular-acceleration estimate sigma_w [rad/s^2]',
    'rate_filter_hz': 'indi: cutoff of the low-pass of the body rates and of the modelled moment [Hz]',
    'acceleration_filter_hz': 'indi: cutoff of the low-pass of the velocity and of the modelled thrust vector [Hz]',
    'motor_time_constant': 'indi: time constant of the modelled first-order rotor response [s] (0: instantaneous)',
    'effectiveness_rate': 'indi: normalised LMS step mu of the control-effectiveness estimate, in [0, 2) '
                          '(0: not adapted)',
    'effectiveness_threshold': 'indi: epsilon of the normalised LMS [rad/s^2]: increments well below it barely adapt',
    'effectiveness_min': 'indi: lower bound of the effectiveness ratio eta (estimated / nominal), in (0, 1]',
    'effectiveness_max': 'indi: upper bound of the effectiveness ratio eta (estimated / nominal), >= 1',
}


#: the valid values of each string gain, by the last component of its name
GAIN_CHOICES = {
    'type_reducer': TYPE_REDUCERS,
    'allocation': ALLOCATIONS,
    'attitude_rates': ATTITUDE_RATES,
    'learning_rate_unit': LEARNING_RATE_UNITS,
    'modification': MODIFICATIONS,
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
