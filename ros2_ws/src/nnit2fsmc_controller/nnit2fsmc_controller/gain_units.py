"""Gains that carry over between vehicles: each gain's unit, and the rule that turns the gains file's
values (stated per unit of nominal mass and inertia) into the units a law acts in on one vehicle.

Every subsystem q (x, y, z, phi, theta, psi) obeys q'' = drift + b v with the nominal control gain b
at level hover (paper eq. 1; :mod:`.controller`):

    x, y: b = 1 (v [m/s^2]);  z: b = 1 / m (v = U1 [N]);  phi: b = d / Ix, theta: b = d / Iy (U2, U3 [N]);
    psi: b = 1 / Iz (U4 [N m]).

The gains file states every gain in units of q'' (accelerations [m/s^2], [rad/s^2]) or of the
sliding surface, so that one file flies any vehicle. A gain declares its unit (GAIN_UNITS, by name):

* ``control``: an amount of the subsystem's virtual control, stated as the acceleration it gives;
  the law gets K / b (the NNIT2FSMC's fuzzy_gain and nn_gain K_eq: U_fuzzy and U_eq_hat of eqs.
  (3)-(9) stay in the paper's units, N or N m).
* ``control^-2``: a learning rate of eqs. (6)-(9); the law gets alpha b^2. Each weight step is
  alpha U_fuzzy K_eq x (factors of the weights and inputs only): with U_fuzzy and K_eq both 1 / b
  times their acceleration values, alpha b^2 takes the same step, so the network learns the same
  weights in acceleration units on every vehicle.
* ``none`` (every gain not listed): used as stated. lambda [1/s], input_scale [units of S] and the
  baselines' gains, which are already per unit of q'' (pid, smc, smc-integral divide by b in their
  laws; se3 multiplies by m and J).

A new gain in a law's own units plugs in by declaring its unit here. With these rules two vehicles
that differ only in m, Ix, Iy, Iz (and rotor limits and drag in proportion) fly the same trajectory
with one gains file (tests/test_gain_units.py).

Hover authority (docs/PAPER.md section 3): the z fuzzy term must lift the vehicle alone, and the z
network's cap must hold its weight, so both z authorities must exceed g (m g in newtons):
:func:`check_hover_authority`. The rotor limit against the weight is the vehicle file's own check
(``vehicle.F_max``, :class:`quad_msgs_bridge.vehicle_params.VehicleParams`).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams

#: the exponent of the control scale 1 / b each unit takes (module docstring)
UNITS = {'none': 0, 'control': 1, 'control^-2': -2}
#: the unit of every gain that is not 'none', by its name with the subsystem as '*'
GAIN_UNITS = {
    'nnit2fsmc.axes.*.fuzzy_gain': 'control',
    'nnit2fsmc.axes.*.nn_gain': 'control',
    'nnit2fsmc.axes.*.learning_rate': 'control^-2',
}
#: the z gains whose authority must carry the weight (check_hover_authority)
HOVER_AUTHORITIES = ('nnit2fsmc.axes.z.fuzzy_gain', 'nnit2fsmc.axes.z.nn_gain')


def control_scale(params: VehicleParams, axis: str):
    """1 / b: the subsystem's virtual control per unit of q'' at level hover (module docstring), [1] for x, y,
    [kg] for z, [kg m] for phi, theta (Ix / d, Iy / d), [kg m^2] for psi; a float, or an array for a batch."""
    return {'x': 1.0, 'y': 1.0, 'z': params.m, 'phi': params.Ix / params.d, 'theta': params.Iy / params.d,
            'psi': params.Iz}[axis]


def gain_unit(name: str) -> str:
    """The declared unit of the flattened gain ``name`` (e.g. 'nnit2fsmc.axes.z.nn_gain'): one of UNITS."""
    parts = name.split('.')
    for pattern, unit in GAIN_UNITS.items():
        pattern_parts = pattern.split('.')
        if len(parts) == len(pattern_parts) and all(p in ('*', q) for p, q in zip(pattern_parts, parts)):
            return unit
    return 'none'


def in_vehicle_units(name: str, value, params: VehicleParams, axis: str):
    """The gain ``name`` of subsystem ``axis``, stated as ``value`` in the gains file, in the units its law
    acts in on the nominal vehicle ``params``: value (1 / b)^power, power by its unit (module docstring).

    The square of a learning rate's scale is one product (s * s), so that the packaged gains, restated
    exactly, give the paper's vehicle the very numbers it had in newtons."""
    power = UNITS[gain_unit(name)]
    if power == 0:
        return value
    scale = control_scale(params, axis)
    return value * scale if power == 1 else value / (scale * scale)


def check_hover_authority(name: str, value: float, params: VehicleParams) -> None:
    """ParameterError naming the gain and the vehicle when ``name``, one of HOVER_AUTHORITIES (the z fuzzy
    term's or network's cap as stated, ``value`` [m/s^2]), is not above g: it then cannot hold the vehicle's
    weight m g (docs/PAPER.md section 3). Any other gain passes. A batch names its first such vehicle."""
    if name not in HOVER_AUTHORITIES:
        return
    masses = np.atleast_1d(np.asarray(params.m, dtype=float))
    gravity = np.broadcast_to(np.asarray(params.g, dtype=float), masses.shape)
    short = value <= gravity
    if short.any():
        i = int(np.argmax(short))
        m, g = float(masses[i]), float(gravity[i])
        which = f' (vehicle {i} of the batch)' if np.ndim(params.m) else ''
        raise ParameterError(
            f'{name}: {value:g} m/s^2 gives {value * m:.4g} N on the vehicle of mass m = {m:g} kg{which}, not '
            f'above its weight m g = {m * g:.4g} N: it cannot hold the vehicle in hover; valid range '
            f'({g:g}, inf) [m/s^2] (gains are stated per unit of mass: docs/PAPER.md section 3)')
