"""Every controller kind, found through one registry: the built-in kinds and a user's alike (docs/CONTROLLERS.md).

A kind is named three ways, looked up in this order:

1. a built-in kind's name (``nnit2fsmc``, ``pid``, ...: :mod:`.kinds`);
2. the name of a Python entry point of the group :data:`ENTRY_POINT_GROUP` that an installed package declares
   (``[project.entry-points."nnit2fsmc_flight_stack.controllers"] my-law = "my_package.law:MyLaw"``);
3. ``module:Class``, a class (or a :class:`ControllerKind`) importable from Python's path.

Each resolves to a :class:`ControllerKind`: what the flight loops, campaigns, ``tune``, ``stress``, the
scoreboard and the ROS controller node build and search. An object of a built-in kind's module, an entry
point's and a ``module:Class`` go through the same :func:`kind_of`: a :class:`ControllerKind` as it is, a
class that fills the contract of :mod:`.contract` wrapped into one.
"""
from __future__ import annotations

import difflib
import functools
import importlib
import re
from dataclasses import dataclass, replace
from importlib import metadata
from typing import Any, Callable, Mapping

from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams

from .contract import ContractController, Gain, flat_schema
from .search_spaces import Dimension

#: the entry-point group a package declares its controllers in (the distribution's name, as a module name)
ENTRY_POINT_GROUP = 'nnit2fsmc_flight_stack.controllers'
#: the module that holds the built-in kinds (its BUILT_IN, a tuple of ControllerKind)
BUILT_IN_MODULE = 'nnit2fsmc_controller.kinds'


@dataclass(frozen=True)
class ControllerKind:
    """A controller kind as every command builds and tunes it."""

    name: str
    description: str
    #: (name, nominal vehicle, gains tree, batch size or None) -> a controller to step
    build: Callable[[str, VehicleParams, Mapping[str, Any], int | None], Any]
    gains_section: str               #: the section of the gains file it reads (beside ``common``)
    schema: Mapping[str, Gain] | None = None   #: its section's gains, flattened (None: the packaged file's)
    search_space: tuple[Dimension, ...] = ()   #: what ``run_stack.py tune`` searches
    attitude_space: tuple[Dimension, ...] = ()   #: what ``tune --attitude`` adds (search_spaces.ATTITUDE_SPACES)
    batched: bool = True             #: steps a batch in one call (False: vehicle by vehicle)
    source: str = 'built in'         #: where it came from (run_stack.py list controllers)

    def defaults(self) -> dict:
        """Its section's default gains, nested as a gains file nests them ({} for a built-in kind)."""
        tree: dict = {}
        for name, gain in (self.schema or {}).items():
            node = tree
            *parents, leaf = name.split('.')
            for key in parents:
                node = node.setdefault(key, {})
            node[leaf] = gain.default
        return tree


def section_name(name: str) -> str:
    """The gains section of a kind named ``name`` that does not name one: its last part as an identifier
    ('my_package.law:MyLaw' -> 'mylaw', 'my-law' -> 'my_law')."""
    return re.sub(r'\W', '_', name.rsplit(':', 1)[-1].rsplit('.', 1)[-1]).lower()


def _dimensions(section: str, schema: Mapping[str, Gain], searched) -> tuple[Dimension, ...]:
    names = [name for name, gain in schema.items() if gain.searchable] if searched is None else list(searched)
    dimensions = []
    for name in names:
        if name not in schema:
            raise ParameterError(f'search: {name!r} is not one of its gains ({", ".join(schema)})')
        gain = schema[name]
        if not gain.searchable:
            raise ParameterError(f'search: {name} has no finite numeric range to search')
        dimensions.append(Dimension(name, (f'{section}.{name}',), gain.low, gain.high, gain.unit,
                                    log=gain.log and gain.low > 0))
    return tuple(dimensions)


def section_gains(kind: ControllerKind, gains: Mapping[str, Any]) -> dict:
    """The kind's section of ``gains`` over its schema's defaults, every value checked (ParameterError naming
    the gain: unknown, with the closest valid name, or out of its range)."""
    from .factory import flatten_gains, unflatten_gains
    schema = kind.schema or {}
    given = flatten_gains(gains.get(kind.gains_section, {}) or {})
    for name in given:
        if name not in schema:
            close = difflib.get_close_matches(name, list(schema), n=1)
            hint = f' (did you mean {kind.gains_section}.{close[0]}?)' if close else ''
            raise ParameterError(f'{kind.gains_section}.{name}: unknown gain of {kind.name}{hint}')
    flat = {name: gain.check(f'{kind.gains_section}.{name}', given.get(name, gain.default))
            for name, gain in schema.items()}
    return unflatten_gains(flat)


def _contract_kind(name: str, cls: type, source: str) -> ControllerKind:
    """The kind of a class that fills the contract of :mod:`.contract`."""
    if not callable(getattr(cls, 'update', None)):
        raise ParameterError(f'controller {name!r} ({source}): {cls!r} has no update(t, state, reference) method '
                             '(docs/CONTROLLERS.md says what a controller class fills)')
    schema = flat_schema(getattr(cls, 'gains', None) or {})
    section = getattr(cls, 'gains_section', None) or section_name(name)
    description = getattr(cls, 'description', None) or (cls.__doc__ or '').strip().split('\n')[0]

    def build(kind_name: str, params: VehicleParams, gains: Mapping[str, Any], batch: int | None):
        from .factory import control_period
        return ContractController(kind_name, cls, params, section_gains(kind, gains), control_period(gains), batch)

    kind = ControllerKind(name, description or name, build, section, schema,   # build reads it when it is called
                          _dimensions(section, schema, getattr(cls, 'search', None)),
                          batched=bool(getattr(cls, 'batched', False)), source=source)
    return kind


def kind_of(name: str, value: Any, source: str) -> ControllerKind:
    """The ControllerKind named ``name`` of ``value``: a ControllerKind (renamed to ``name``), or a contract class."""
    if isinstance(value, ControllerKind):
        return value if value.name == name else _renamed(value, name, source)
    if isinstance(value, type):
        return _contract_kind(name, value, source)
    raise ParameterError(f'controller {name!r} ({source}): expected a controller class or a ControllerKind, '
                         f'got {value!r}')


def _renamed(kind: ControllerKind, name: str, source: str) -> ControllerKind:
    return replace(kind, name=name, source=source)


@functools.lru_cache(maxsize=1)
def built_in_kinds() -> dict[str, ControllerKind]:
    """The built-in kinds by name, in their listing order."""
    module = importlib.import_module(BUILT_IN_MODULE)
    return {kind.name: kind_of(kind.name, kind, 'built in') for kind in module.BUILT_IN}


def _entry_points() -> dict[str, metadata.EntryPoint]:
    return {point.name: point for point in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def _import(reference: str) -> Any:
    module_name, _, attribute = reference.partition(':')
    try:
        value = importlib.import_module(module_name)
    except ImportError as error:
        raise ParameterError(f'controller {reference!r}: cannot import {module_name} ({error})') from None
    for part in attribute.split('.'):
        try:
            value = getattr(value, part)
        except AttributeError:
            raise ParameterError(f'controller {reference!r}: {module_name} has no {attribute}') from None
    return value


#: the kinds resolved so far in this process, by name
_RESOLVED: dict[str, ControllerKind] = {}


def controller_kind(name: str) -> ControllerKind:
    """The kind named ``name`` (the module docstring's three ways); ParameterError naming the known kinds,
    with the closest, if there is none."""
    if not isinstance(name, str):
        raise ParameterError(f'controller: expected a kind name, got {name!r}')
    if name not in _RESOLVED:
        _RESOLVED[name] = _resolve(name)
    return _RESOLVED[name]


def _resolve(name: str) -> ControllerKind:
    built_in = built_in_kinds()
    if name in built_in:
        return built_in[name]
    points = _entry_points()
    if name in points:
        point = points[name]
        distribution = getattr(point, 'dist', None)
        source = f'entry point {point.value}' + (f' of {distribution.name} {distribution.version}'
                                                  if distribution is not None else '')
        try:
            value = point.load()
        except Exception as error:   # a broken plugin says so in one line instead of a traceback
            raise ParameterError(f'controller {name!r} ({source}): cannot be loaded: {error}') from None
        return kind_of(name, value, source)
    if re.fullmatch(r'[\w.]+:[\w.]+', name):
        return kind_of(name, _import(name), name)
    known = [*built_in, *points]
    close = difflib.get_close_matches(name, known, n=1)
    raise ParameterError(f'controller: {name!r} is not a known kind{f" (did you mean {close[0]}?)" if close else ""}; '
                         f'known: {", ".join(known)}; or name your own class as module:Class (docs/CONTROLLERS.md)')


def register(value: Any, name: str | None = None) -> str:
    """Register a contract class (or a ControllerKind) of this process under ``name`` (default
    ``module:Class``) and return the name to fly it by: for a class defined in a script or a notebook.
    Worker processes of a campaign import ``module:Class`` themselves, so a class of ``__main__`` flies
    single flights only; give a campaign a class of an importable module."""
    if name is None:
        name = value.name if isinstance(value, ControllerKind) else f'{value.__module__}:{value.__qualname__}'
    kind = kind_of(name, value, f'registered {name}')
    if name in built_in_kinds() or (name in _RESOLVED and _RESOLVED[name] != kind):
        raise ParameterError(f'controller {name!r}: a kind of that name exists already')
    _RESOLVED[name] = kind
    return name


def controller_name(value: Any) -> str:
    """The kind name of ``value``: a name as it is, a contract class or a ControllerKind registered
    (:func:`register`); a built controller is refused (a flight builds a fresh one)."""
    if isinstance(value, str):
        return value
    if isinstance(value, (type, ControllerKind)):
        name = value.name if isinstance(value, ControllerKind) else f'{value.__module__}:{value.__qualname__}'
        return name if name in _RESOLVED else register(value, name)
    if callable(getattr(value, 'update', None)) and isinstance(getattr(value, 'name', None), str):
        raise ParameterError(f'controller: got a built {value.name} controller; a flight builds a fresh one from its '
                             f'kind: pass controller={value.name!r} (or your controller class) and its gains=')
    raise ParameterError(f'controller: expected a kind name, a controller class or a ControllerKind, got {value!r}')


def check_controller(name: str, option: str = 'controller') -> str:
    """``name`` if it names a kind, else ParameterError saying so under ``option``."""
    try:
        controller_kind(name)
    except ParameterError as error:
        message = str(error)
        raise ParameterError(f'{option}{message[len("controller"):]}' if message.startswith('controller')
                             else f'{option}: {message}') from None
    return name


def installed_kinds() -> list[ControllerKind]:
    """The built-in kinds, then every installed entry point's (a broken one skipped: it errs when named)."""
    kinds = list(built_in_kinds().values())
    for name in _entry_points():
        try:
            kinds.append(controller_kind(name))
        except ParameterError:
            continue
    return kinds


def kind_for_section(section: str) -> ControllerKind | None:
    """The user kind (named so far in this process, or installed) that reads gains section ``section``, or None."""
    for kind in [*_RESOLVED.values(), *installed_kinds()]:
        if kind.schema is not None and kind.gains_section == section:
            return kind
    return None
