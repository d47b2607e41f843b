"""What ``run_stack.py tune`` searches for each controller kind (docs/TUNING.md): the one place the
search spaces are declared.

A kind's space is a tuple of :class:`Dimension`: one searched number, the gains of the gains file
(``config/controller.yaml``, dotted names) that all take its value, its range and unit. x and y share
their gains (the helix and the campaigns are symmetric in x and y), so one dimension sets both.
Every kind gets the same number of dimensions (six), chosen in the position loops that the campaigns'
wind and mass perturbations load (and, for the adaptive kinds, their translational adaptation); the
attitude loops keep the packaged gains, unless ``run_stack.py tune --attitude`` adds each kind's roll and pitch
loop (:data:`ATTITUDE_SPACES`: the gains that set its stiffness, damping and integral action, roll and pitch sharing
them) for a world whose actuator and rate the packaged attitude loops were not made for (docs/PX4.md: PX4's SIH at
100 Hz with a 50 ms motor lag). Each range contains the packaged
value (so the packaged gains can be enqueued as the first trial) and spans it by about a decade on
a log scale. Adding a built-in kind is one entry of :data:`SEARCH_SPACES`; a user's kind's space comes from its gains
schema (:mod:`.registry`).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any, Mapping

from quad_msgs_bridge.validation import ParameterError


@dataclass(frozen=True)
class Dimension:
    """One searched number: ``gains`` (dotted names) all take its value, in [low, high] ``unit``."""

    name: str                  #: the search parameter's name (the trials table's column)
    gains: tuple[str, ...]     #: the gains file's entries it sets
    low: float
    high: float
    unit: str
    log: bool = True           #: sampled uniformly in log(value)


def _xy(section: str, gain: str, low: float, high: float, unit: str) -> Dimension:
    return Dimension(f'xy.{gain}', (f'{section}.axes.x.{gain}', f'{section}.axes.y.{gain}'), low, high, unit)


def _z(section: str, gain: str, low: float, high: float, unit: str) -> Dimension:
    return Dimension(f'z.{gain}', (f'{section}.axes.z.{gain}',), low, high, unit)


def _rp(section: str, gain: str, low: float, high: float, unit: str) -> Dimension:
    return Dimension(f'rp.{gain}', (f'{section}.axes.phi.{gain}', f'{section}.axes.theta.{gain}'), low, high, unit)


def _attitude_loop(section: str, error: str, integral: str | None, rate: str) -> tuple[Dimension, ...]:
    """The roll and pitch dimensions of a PID-shaped attitude loop (pid, se3, l1-se3, indi): the same ranges for
    every such law, a decade and more around the packaged 217.7 /s^2, 435.4 /s^3, 27.21 /s."""
    return tuple(dimension for dimension in (
        _rp(section, error, 10.0, 1000.0, '1/s^2'),
        _rp(section, integral, 5.0, 2000.0, '1/s^3') if integral else None,
        _rp(section, rate, 2.0, 80.0, '1/s')) if dimension is not None)


#: the ranges of a PID-shaped position loop (pid, se3, l1-se3, indi): role -> (x, y range), (z range), unit
_POSITION_RANGES = {
    'error': ((2.0, 80.0), (10.0, 200.0), '1/s^2'),
    'integral': ((1.0, 200.0), (5.0, 200.0), '1/s^3'),
    'rate': ((1.0, 20.0), (3.0, 40.0), '1/s'),
}


def _position_loop(section: str, error: str, integral: str | None, rate: str) -> tuple[Dimension, ...]:
    """The x, y dimensions, then the z ones, of a PID-shaped position loop whose gains are named ``error``,
    ``integral`` (None: it has none) and ``rate`` in ``section``; every such law searches the same ranges."""
    roles = [(role, gain) for role, gain in (('error', error), ('integral', integral), ('rate', rate)) if gain]
    xy = tuple(_xy(section, gain, *_POSITION_RANGES[role][0], _POSITION_RANGES[role][2]) for role, gain in roles)
    z = tuple(_z(section, gain, *_POSITION_RANGES[role][1], _POSITION_RANGES[role][2]) for role, gain in roles)
    return xy + z


#: controller kind -> its search space (units as the gains file states them)
SEARCH_SPACES: dict[str, tuple[Dimension, ...]] = {
    'nnit2fsmc': (
        _xy('nnit2fsmc', 'input_scale', 0.3, 6.0, 'm/s (S at which the fuzzy input saturates)'),
        _xy('nnit2fsmc', 'fuzzy_gain', 2.0, 40.0, 'm/s^2'),
        _xy('nnit2fsmc', 'nn_gain', 1.0, 20.0, 'm/s^2'),
        _xy('nnit2fsmc', 'learning_rate', 0.1, 10.0, '1/s per (m/s^2)^2'),
        # above g: per unit of mass, a z fuzzy gain below g cannot hold the vehicle in hover (refused when built)
        _z('nnit2fsmc', 'fuzzy_gain', 10.0, 80.0, 'm/s^2'),
        _z('nnit2fsmc', 'learning_rate', 0.01, 1.0, '1/s per (m/s^2)^2'),
    ),
    'pid': _position_loop('pid', 'kp', 'ki', 'kd'),
    'se3': _position_loop('se3', 'k_error', 'k_integral', 'k_rate'),
    'smc-integral': (
        _xy('smc_integral', 'slope', 1.0, 20.0, '1/s (boundary-layer slope)'),
        _xy('smc_integral', 'integral_gain', 0.2, 50.0, '1/s^2'),
        _xy('smc_integral', 'switching_gain', 1.0, 40.0, 'm/s^2'),
        _z('smc_integral', 'slope', 3.0, 40.0, '1/s'),
        _z('smc_integral', 'integral_gain', 0.2, 50.0, '1/s^2'),
        _z('smc_integral', 'switching_gain', 0.5, 20.0, 'm/s^2'),
    ),
    'l1-se3': (    # its own se3 law (l1_se3.axes, apart from se3's): its whole position loop; then its L1 loop, both
        # channels (predictor pole and low-pass), and the rotational channel's cascaded second low-pass (0: none)
        *_position_loop('l1_se3', 'k_error', 'k_integral', 'k_rate'),
        Dimension('l1.predictor_pole_translation', ('l1_se3.predictor_pole_translation',), 0.5, 50.0, '1/s'),
        Dimension('l1.cutoff_translation_hz', ('l1_se3.cutoff_translation_hz',), 0.5, 50.0, 'Hz'),
        Dimension('l1.predictor_pole_rotation', ('l1_se3.predictor_pole_rotation',), 0.5, 50.0, '1/s'),
        Dimension('l1.cutoff_rotation_hz', ('l1_se3.cutoff_rotation_hz',), 0.5, 50.0, 'Hz'),
        Dimension('l1.cutoff_rotation_second_hz', ('l1_se3.cutoff_rotation_second_hz',), 0.0, 10.0, 'Hz', log=False),
    ),
    'indi': (
        *_position_loop('indi', 'k_error', None, 'k_rate'),
        Dimension('indi.effectiveness_rate', ('indi.effectiveness_rate',), 0.005, 0.5, '- (normalised LMS step)'),
        # its modelled rotor response: the example campaign's 30 ms motor lag with 4 ms of delay crashes every
        # flight of the packaged 0 s (docs/ADAPTIVE_BASELINES.md), so tuning must be able to find it
        Dimension('indi.motor_time_constant', ('indi.motor_time_constant',), 0.0, 0.06, 's', log=False),
    ),
}


#: controller kind -> its roll and pitch loop's dimensions, added by ``tune --attitude`` (yaw keeps its gains)
ATTITUDE_SPACES: dict[str, tuple[Dimension, ...]] = {
    # the sliding kinds: their own roll and pitch gains (common.lambda, the surfaces' slope, is every sliding
    # kind's at once, so it stays: one gains file holds every kind's tuned point)
    'nnit2fsmc': (_rp('nnit2fsmc', 'input_scale', 0.5, 20.0, 'rad/s (S at which the fuzzy input saturates)'),
                  _rp('nnit2fsmc', 'fuzzy_gain', 10.0, 500.0, 'rad/s^2'),
                  _rp('nnit2fsmc', 'nn_gain', 2.0, 150.0, 'rad/s^2')),
    'smc-integral': (_rp('smc_integral', 'slope', 3.0, 100.0, '1/s (boundary-layer slope)'),
                     _rp('smc_integral', 'integral_gain', 1.0, 100.0, '1/s^2'),
                     _rp('smc_integral', 'switching_gain', 3.0, 200.0, 'rad/s^2')),
    'pid': _attitude_loop('pid', 'kp', 'ki', 'kd'),
    'se3': _attitude_loop('se3', 'k_error', 'k_integral', 'k_rate'),
    'l1-se3': _attitude_loop('l1_se3', 'k_error', 'k_integral', 'k_rate'),
    'indi': _attitude_loop('indi', 'k_error', None, 'k_rate'),
}


def search_space(kind: str, attitude: bool = False) -> tuple[Dimension, ...]:
    """The search space of ``kind`` (its :class:`.registry.ControllerKind`'s; a user's kind's from its gains
    schema), with its roll and pitch loop's dimensions if ``attitude``; ParameterError if it has none. An ablation
    of the NNIT2FSMC reads the same ``nnit2fsmc`` section and searches its space: tuned alone (``run_stack.py tune
    --controller nnit2fsmc-bias``), it gets the NNIT2FSMC's budget, and its point goes to its own gains file (it is
    not packaged: it would overwrite the NNIT2FSMC's)."""
    from .registry import controller_kind
    entry = controller_kind(kind)
    if not entry.search_space:
        raise ParameterError(f'--controller: {kind!r} has no search space (a built-in kind declares it in '
                             'nnit2fsmc_controller/search_spaces.py; a user\'s kind gives its gains a finite range, '
                             'docs/CONTROLLERS.md)')
    if attitude and not entry.attitude_space:
        raise ParameterError(f'--attitude: {kind!r} declares no attitude dimensions (nnit2fsmc_controller/'
                             'search_spaces.py, ATTITUDE_SPACES)')
    return entry.search_space + (entry.attitude_space if attitude else ())


#: a value this close to a bound of its dimension's range (a fraction of the range, of its log where the dimension is
#: sampled on a log scale) sits at that bound: the ranges rule of docs/TUNING.md widens such a range and searches on
BOUND_MARGIN = 0.02


def at_bounds(point: Mapping[str, float], dimensions) -> list[tuple[str, str]]:
    """(dimension name, 'low' or 'high') for each of ``dimensions`` whose value in ``point`` sits within
    BOUND_MARGIN of that bound of its range."""
    found = []
    for d in dimensions:
        scale = math.log if d.log else (lambda x: x)
        share = (scale(point[d.name]) - scale(d.low)) / (scale(d.high) - scale(d.low))
        if share <= BOUND_MARGIN:
            found.append((d.name, 'low'))
        elif share >= 1.0 - BOUND_MARGIN:
            found.append((d.name, 'high'))
    return found


def _node(tree: Mapping[str, Any], dotted: str) -> tuple[dict, str]:
    """The mapping that holds ``dotted``'s last key, and that key; ParameterError if a section is missing."""
    *sections, key = dotted.split('.')
    node = tree
    for section in sections:
        if not isinstance(node, Mapping) or section not in node:
            raise ParameterError(f'{dotted}: missing from the gains (its search dimension cannot be set)')
        node = node[section]
    if key not in node:
        raise ParameterError(f'{dotted}: missing from the gains (its search dimension cannot be set)')
    return node, key


def values_in(gains: Mapping[str, Any], kind: str, attitude: bool = False) -> dict[str, float]:
    """The point of ``kind``'s search space (with ``attitude``, :func:`search_space`) that ``gains`` (a gains tree)
    is: each dimension's value.

    ParameterError if the gains a dimension ties together differ (such gains are not a point of the
    space), or lie outside its range.
    """
    values = {}
    for dimension in search_space(kind, attitude):
        found = {float(node[key]) for node, key in (_node(gains, name) for name in dimension.gains)}
        if len(found) != 1:
            raise ParameterError(f'{", ".join(dimension.gains)}: tuning sets them to one value ({dimension.name}); '
                                 f'the gains give {sorted(found)}')
        value = found.pop()
        if not dimension.low <= value <= dimension.high:
            raise ParameterError(f'{dimension.gains[0]}: {value:g} is outside the search range of {dimension.name} '
                                 f'[{dimension.low:g}, {dimension.high:g}] {dimension.unit}')
        values[dimension.name] = value
    return values


def with_values(gains: Mapping[str, Any], kind: str, values: Mapping[str, float], attitude: bool = False) -> dict:
    """A copy of ``gains`` with every dimension of ``kind``'s space (with ``attitude``, :func:`search_space`) set to
    ``values[dimension.name]``."""
    tuned = copy.deepcopy(dict(gains))
    for dimension in search_space(kind, attitude):
        for name in dimension.gains:
            node, key = _node(tuned, name)
            node[key] = float(values[dimension.name])
    return tuned
