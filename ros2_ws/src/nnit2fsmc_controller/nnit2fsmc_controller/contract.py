"""The controller contract: what a user's controller fills to fly in every command (docs/CONTROLLERS.md).

A controller is a class. The stack builds one per vehicle and steps it once per control period::

    class MyController:
        description = 'one line for run_stack.py list controllers'
        gains = {'kp': Gain(4.0, '1/s^2', 0.1, 100.0, 'position error gain'), ...}   # its gains schema
        gains_section = 'my_controller'   # optional: its section of the gains file (default: from its name)
        search = ('kp', ...)               # optional: the gains run_stack.py tune searches (default: every
                                           #   gain whose range is finite and positive, on a log scale)
        batched = False                    # optional: True if update takes a batch (below)

        def __init__(self, vehicle: VehicleParams, gains: dict, dt: float): ...
        def update(self, t: float, state, reference: ReferenceSample): ...   # -> 4 rotor thrusts [N]
        def adapt(self) -> None: ...       # optional: called after each update's forces are sent

* ``vehicle`` is the nominal model (paper Table I symbols, SI units; never the true vehicle flown);
  ``gains`` its section of the gains file, nested as the file nests it, every value checked against
  its :class:`Gain`; ``dt`` the control period [s] (``common.control_rate``).
* ``update(t, state, reference)``: ``t`` sim time [s]; ``state`` 12 floats ``x y z`` [m, world ENU],
  ``vx vy vz`` [m/s, world ENU], ``phi theta psi`` [rad, Z-Y-X Euler], ``dphi dtheta dpsi``
  [rad/s, Euler-angle rates], as read through the measurement stage every kind shares; ``reference`` a
  :class:`quad_msgs_bridge.reference.ReferenceSample` (position [m], velocity [m/s], acceleration
  [m/s^2], jerk, snap, world ENU; yaw [rad], its rate and acceleration). It returns the rotor thrusts
  F1..F4 [N] in the vehicle's rotor layout (``vehicle.rotor_names``), or a full
  :class:`.controller.ControlOutput`. Thrusts outside [F_min, F_max] are clipped; non-finite thrusts
  raise ValueError (the ROS node then holds the last valid ones).
* ``batched = True``: ``__init__`` also takes ``batch=B`` and ``update`` takes 12 numpy arrays of B
  values (a compiled kernel run vehicle by vehicle, as the built-in kinds do) and returns 4 arrays.
  Without it a campaign steps B instances one after the other: correct, and slower.

:class:`ContractController` wraps such a class into what the flight loops step (``dt``, ``params``,
``name``, ``update``, ``adapt``, ``surface_slopes``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from quad_msgs_bridge.mixer import controls_from_forces
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams

from .axis_laws import AxisOutput
from .controller import AXES, ControlOutput, check_inputs


@dataclass(frozen=True)
class Gain:
    """One gain of a user's controller: its default, unit, valid range [low, high] and meaning.

    A gains file's value outside [low, high] is refused naming the gain; ``run_stack.py tune`` searches
    [low, high] (on a log scale when ``log`` and low > 0). A gain whose default is a string or a bool
    is checked by type only and never searched.
    """

    default: Any
    unit: str = ''
    low: float = -math.inf
    high: float = math.inf
    description: str = ''
    log: bool = True

    def check(self, name: str, value: Any) -> Any:
        """``value`` if valid for this gain, else ParameterError naming ``name`` and the valid range."""
        if isinstance(self.default, (str, bool)):
            if type(value) is not type(self.default):
                raise ParameterError(f'{name}: expected a {type(self.default).__name__}, got {value!r}')
            return value
        checked = check_number(name, value, self.low, self.high)
        return int(checked) if isinstance(self.default, int) and checked.is_integer() else checked

    @property
    def searchable(self) -> bool:
        """Whether ``tune`` can search it by default: a number with a finite range."""
        return (not isinstance(self.default, (str, bool)) and math.isfinite(self.low) and math.isfinite(self.high)
                and self.high > self.low)


def flat_schema(schema: Mapping[str, Any], prefix: str = '') -> dict[str, Gain]:
    """A nested gains schema as {'axes.x.kp': Gain, ...}; ParameterError if a leaf is not a :class:`Gain`."""
    flat: dict[str, Gain] = {}
    for key, value in schema.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            flat.update(flat_schema(value, name + '.'))
        elif isinstance(value, Gain):
            flat[name] = value
        else:
            raise ParameterError(f'gains schema: {name} must be a Gain(default, unit, low, high, description), '
                                 f'got {value!r}')
    return flat


def _vehicle_value(value, k: int):
    """Vehicle ``k``'s float of a batch value (an array, or a float shared by every vehicle)."""
    return float(value[k]) if isinstance(value, np.ndarray) else value


def _vehicle_reference(reference: ReferenceSample, k: int) -> ReferenceSample:
    """Vehicle ``k``'s reference of a batch reference (fields of floats or of per-vehicle arrays)."""
    return ReferenceSample(*(tuple(_vehicle_value(v, k) for v in field) if isinstance(field, tuple)
                             else _vehicle_value(field, k) for field in reference))


class ContractController:
    """A user's controller class stepped as the built-in kinds are: for one vehicle or a batch of ``batch``.

    Its diagnostics per subsystem (surface, equivalent and corrective terms) are 0 unless ``update``
    returns a ControlOutput; its attitude reference is level at the reference yaw likewise.
    """

    def __init__(self, name: str, cls: type, params: VehicleParams, gains: Mapping[str, Any], dt: float,
                 batch: int | None = None):
        self.name, self.params, self.dt, self.batch = name, params, dt, batch
        self._mixer = params.mixer
        if batch is None or getattr(cls, 'batched', False):
            extra = {} if batch is None else {'batch': batch}
            self.instances = [cls(params, gains, dt, **extra)]
            self._per_vehicle = False
        else:
            self.instances = [cls(params, gains, dt) for _ in range(batch)]
            self._per_vehicle = True

    def update(self, t: float, state, reference: ReferenceSample) -> ControlOutput:
        """The rotor thrusts for ``state`` and ``reference`` at sim time ``t`` (see the module docstring)."""
        check_inputs(t, state, reference, self.batch)
        if self._per_vehicle:
            outputs = [instance.update(t, [float(value[k]) for value in state], _vehicle_reference(reference, k))
                       for k, instance in enumerate(self.instances)]
            forces = tuple(np.array(values, dtype=float) for values in zip(*(self._forces(o) for o in outputs)))
            return self._output(forces, reference)
        out = self.instances[0].update(t, state, reference)
        if isinstance(out, ControlOutput):
            self._check_finite(out.forces)
            forces = self._clipped(out.forces)
            return out._replace(forces=forces, controls=tuple(controls_from_forces(*forces, self._mixer)))
        return self._output(self._forces(out), reference)

    def _forces(self, out) -> tuple:
        forces = out.forces if isinstance(out, ControlOutput) else out
        try:
            forces = tuple(forces)
        except TypeError:
            forces = ()
        if len(forces) != 4:
            raise ValueError(f'{self.name}: update must return 4 rotor thrusts F1..F4 [N] or a ControlOutput, '
                             f'got {out!r}')
        self._check_finite(forces)
        return forces

    def _check_finite(self, forces) -> None:
        if not all(np.all(np.isfinite(np.asarray(f, dtype=float))) for f in forces):
            raise ValueError(f'{self.name}: update returned non-finite rotor thrusts {forces}')

    def _clipped(self, forces) -> tuple:
        low, high = self.params.F_min, self.params.F_max
        return tuple(np.minimum(np.maximum(f, low), high) if isinstance(f, np.ndarray) else min(max(float(f), low), high)
                     for f in forces)

    def _output(self, forces, reference: ReferenceSample) -> ControlOutput:
        forces = self._clipped(forces)
        controls = controls_from_forces(*forces, self._mixer)
        zero = np.zeros(self.batch) if self.batch is not None else 0.0
        axes = {axis: AxisOutput(zero, zero, zero, zero) for axis in AXES}
        return ControlOutput(forces, tuple(controls), axes, (zero, zero, reference.yaw))

    def adapt(self) -> None:
        """The user's ``adapt`` (learning after the forces are sent), if it has one."""
        for instance in self.instances:
            if hasattr(instance, 'adapt'):
                instance.adapt()

    def surface_slopes(self) -> tuple[float, ...]:
        """No sliding surfaces: zeros, one per subsystem (the diagnostics message's slopes)."""
        return (0.0,) * len(AXES)
