"""The built-in controller kinds, registered as a user's are (:mod:`.registry`): one :class:`ControllerKind` each.

Each reads the ``common`` section of the gains file (config/controller.yaml) and its own section, and
builds for one vehicle or a batch of B (every vehicle its own network weights and integrators).
"""
from __future__ import annotations

from typing import Any, Mapping

from quad_msgs_bridge.vehicle_params import VehicleParams

from .axis_laws import IntegralSlidingModeLaw, PIDLaw, SlidingModeLaw
from .controller import AXES, CascadedController
from .indi import INDIController
from .l1_adaptive import L1SE3Controller
from .registry import ControllerKind
from .se3 import SE3Controller
from .search_spaces import ATTITUDE_SPACES, SEARCH_SPACES

#: the NNIT2FSMC's ablations (docs/ADAPTIVE.md): the IT2 term replaced by -K sat(S / Phi), type-1 fuzzy
#: (lower membership functions = upper ones), learning off, and a network whose only input is the bias
ABLATIONS = {
    'nnit2fsmc-sat': 'ablation: the IT2 fuzzy term replaced by -K sat(S / Phi)',
    'nnit2fsmc-type1': 'ablation: type-1 fuzzy (lower membership functions equal to the upper ones)',
    'nnit2fsmc-nolearn': 'ablation: the network does not learn',
    'nnit2fsmc-bias': 'ablation: the network\'s only input is a constant (no reference inputs)',
}
#: the keys of the l1_se3 and indi sections (beside their axes), read as numbers
L1_KEYS = ('predictor_pole_translation', 'predictor_pole_rotation', 'cutoff_translation_hz', 'cutoff_rotation_hz',
           'cutoff_rotation_second_hz', 'estimate_limit_translation', 'estimate_limit_rotation')
INDI_KEYS = ('rate_filter_hz', 'acceleration_filter_hz', 'motor_time_constant', 'effectiveness_rate',
             'effectiveness_threshold', 'effectiveness_min', 'effectiveness_max')


def _structure(gains: Mapping[str, Any], batch: int | None) -> dict:
    """What every kind's structure reads of ``common``: tilt limits, the angle filter and the attitude rates, the
    allocation, the take-off."""
    from .factory import _get, _non_negative, _positive
    return dict(max_tilt=_positive(gains, 'common.max_tilt'),
                low_altitude_max_tilt=_positive(gains, 'common.low_altitude_max_tilt'),
                low_altitude_height=_non_negative(gains, 'common.low_altitude_height'),
                angle_filter_tau=_positive(gains, 'common.angle_filter_tau'),
                allocation=gains.get('common', {}).get('allocation', 'priority'),
                attitude_rates=_get(gains, 'common.attitude_rates'),
                takeoff_height=_non_negative(gains, 'common.takeoff_height'), batch=batch)


def _slopes(gains: Mapping[str, Any]) -> dict[str, float]:
    """lambda [1/s] of every subsystem (``common.lambda``)."""
    from .factory import _positive
    return {axis: _positive(gains, f'common.lambda.{axis}') for axis in AXES}


def _cascaded(laws):
    """The build of a cascaded kind whose law of each subsystem is ``laws(name, gains, axis, lambda, dt, batch,
    params)``."""
    def build(name: str, params: VehicleParams, gains: Mapping[str, Any], batch: int | None) -> CascadedController:
        from .factory import control_period
        dt = control_period(gains)
        lam = _slopes(gains)
        return CascadedController(name, params, {axis: laws(name, gains, axis, lam[axis], dt, batch, params)
                                                 for axis in AXES}, dt,
                                  **_structure(gains, batch))
    return build


def _nnit2fsmc(name, gains, axis, lam, dt, batch, params):
    from .factory import nnit2fsmc_law
    return nnit2fsmc_law(name, gains, axis, lam, dt, batch, params)


def _smc(name, gains, axis, lam, dt, batch, params):
    from .factory import _non_negative, _positive
    return SlidingModeLaw(lam, _non_negative(gains, f'smc.switching_gain.{axis}'),
                          _positive(gains, f'smc.boundary_layer.{axis}') if name == 'smc-sat' else 0.0)


def _smc_integral(name, gains, axis, lam, dt, batch, params):
    from .factory import _non_negative, _positive
    key = f'smc_integral.axes.{axis}'
    return IntegralSlidingModeLaw(lam, mu=_non_negative(gains, f'{key}.integral_gain'),
                                  slope=_positive(gains, f'{key}.slope'),
                                  switching_gain=_non_negative(gains, f'{key}.switching_gain'),
                                  gain_uncertainty=_non_negative(gains, f'{key}.gain_uncertainty'),
                                  integral_limit=_non_negative(gains, f'{key}.integral_limit'), dt=dt)


def _pid(name, gains, axis, lam, dt, batch, params):
    from .factory import _non_negative
    key = f'pid.axes.{axis}'
    return PIDLaw(lam, kp=_non_negative(gains, f'{key}.kp'), ki=_non_negative(gains, f'{key}.ki'),
                  kd=_non_negative(gains, f'{key}.kd'), integral_limit=_non_negative(gains, f'{key}.integral_limit'),
                  dt=dt)


def _se3_family(name: str, params: VehicleParams, gains: Mapping[str, Any], batch: int | None):
    """se3, or l1-se3 (se3 with L1 adaptive augmentation), from their sections."""
    from .factory import _get, _non_negative, control_period
    section = SE3Controller.GAINS_SECTION if name == 'se3' else L1SE3Controller.GAINS_SECTION
    axes = {axis: tuple(_non_negative(gains, f'{section}.axes.{axis}.{gain}')
                        for gain in ('k_error', 'k_rate', 'k_integral', 'integral_limit')) for axis in AXES}
    dt, structure = control_period(gains), _structure(gains, batch)
    if name == 'se3':
        return SE3Controller(name, params, axes, _slopes(gains), dt, **structure)
    return L1SE3Controller(name, params, axes, _slopes(gains), dt, {key: _get(gains, f'l1_se3.{key}') for key in L1_KEYS},
                           **structure)


def _indi(name: str, params: VehicleParams, gains: Mapping[str, Any], batch: int | None) -> INDIController:
    from .factory import _get, _non_negative, control_period
    axes = {axis: tuple(_non_negative(gains, f'indi.axes.{axis}.{gain}') for gain in ('k_error', 'k_rate'))
            for axis in AXES}
    return INDIController(name, params, axes, _slopes(gains), control_period(gains),
                          {key: _get(gains, f'indi.{key}') for key in INDI_KEYS},
                          velocity_filter_hz=_non_negative(gains, 'common.velocity_filter_hz'),
                          **_structure(gains, batch))


BUILT_IN = (
    ControllerKind('nnit2fsmc', 'the paper\'s NNIT2FSMC: IT2 fuzzy sliding mode with an online-learning network',
                   _cascaded(_nnit2fsmc), 'nnit2fsmc', search_space=SEARCH_SPACES['nnit2fsmc'],
                   attitude_space=ATTITUDE_SPACES['nnit2fsmc']),
    ControllerKind('smc-sign', 'sliding mode control with a sign switching term', _cascaded(_smc), 'smc'),
    ControllerKind('smc-sat', 'sliding mode control with a boundary layer', _cascaded(_smc), 'smc'),
    ControllerKind('smc-integral', 'integral sliding mode control with a boundary layer', _cascaded(_smc_integral),
                   'smc_integral', search_space=SEARCH_SPACES['smc-integral'],
                   attitude_space=ATTITUDE_SPACES['smc-integral']),
    ControllerKind('pid', 'PID on every subsystem', _cascaded(_pid), 'pid', search_space=SEARCH_SPACES['pid'],
                   attitude_space=ATTITUDE_SPACES['pid']),
    ControllerKind('se3', 'geometric tracking control on SE(3) (Lee et al.) with integral terms', _se3_family,
                   SE3Controller.GAINS_SECTION, search_space=SEARCH_SPACES['se3'],
                   attitude_space=ATTITUDE_SPACES['se3']),
    ControllerKind('l1-se3', 'se3 with L1 adaptive augmentation (L1Quad)', _se3_family, L1SE3Controller.GAINS_SECTION,
                   search_space=SEARCH_SPACES['l1-se3'],
                   attitude_space=ATTITUDE_SPACES['l1-se3']),
    ControllerKind('indi', 'incremental nonlinear dynamic inversion (Smeur et al.; Tal & Karaman)', _indi, 'indi',
                   search_space=SEARCH_SPACES['indi'],
                   attitude_space=ATTITUDE_SPACES['indi']),
    # an ablation reads the nnit2fsmc section and searches its space: tuned alone it gets the NNIT2FSMC's budget
    *(ControllerKind(name, description, _cascaded(_nnit2fsmc), 'nnit2fsmc', search_space=SEARCH_SPACES['nnit2fsmc'],
                   attitude_space=ATTITUDE_SPACES['nnit2fsmc'])
      for name, description in ABLATIONS.items()),
)
