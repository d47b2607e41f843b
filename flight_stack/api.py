"""The flight stack as a Python library: a few stable names for people who bring their own simulator,
their own vehicle, or want a flight or a campaign from a script.

    from flight_stack.api import make_controller, hold, fly, read_flight, run_campaign

Conventions (the paper's, REP 103):

* state: 12 values ``x y z`` [m, world ENU], ``vx vy vz`` [m/s, world ENU], ``phi theta psi``
  (roll, pitch, yaw; Z-Y-X Euler angles) [rad], and their rates ``dphi dtheta dpsi`` [rad/s]
  (Euler-angle rates, not body rates: :func:`quad_msgs_bridge.frames.euler_rates_from_body_rates`
  converts a gyro's body rates exactly);
* reference: :class:`Reference` (position [m], velocity [m/s], acceleration [m/s^2], all world
  ENU; yaw [rad], yaw rate [rad/s], yaw acceleration [rad/s^2]; jerk [m/s^3] and snap [m/s^4],
  zeros if left out, which the default flatness attitude rates use); :func:`hold` holds a point;
* output: rotor thrusts F1..F4 [N] in the vehicle's rotor layout (``VehicleParams.rotor_names``; the
  paper's plus frame: F1 front, F2 right, F3 back, F4 left) within the rotor limits, the
  virtual controls U1 [N], U2 [N], U3 [N], U4 [N m] of the paper's eq. (2) they realise, and per
  subsystem (x, y, z, phi, theta, psi) the sliding surface, equivalent and corrective terms.

Call ``update`` once per control period (``controller.dt`` [s]) with a state and the reference
for the same instant. The same controller steps a batch of vehicles when built with ``batch=B``
(then every state value is a numpy array of B values).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from nnit2fsmc_controller.controller import CascadedController, ControlOutput
from nnit2fsmc_controller.contract import Gain
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller, choose_controller, load_gains
from nnit2fsmc_controller.registry import ControllerKind, controller_name, register
from nnit2fsmc_controller.se3 import SE3Controller
from nnit2fsmc_controller.trajectory import SCENARIOS
from quad_msgs_bridge.reference import ReferenceSample as Reference, hold
from quad_msgs_bridge.review.flight_data import Flight
from quad_msgs_bridge.review.flight_from_bag import read_flight
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file

__all__ = ['CONTROLLERS', 'SCENARIOS', 'CascadedController', 'ControlOutput', 'ControllerKind', 'Flight', 'Gain',
           'ParameterError', 'Reference', 'SE3Controller', 'VehicleParams', 'fly', 'hold', 'load_gains',
           'load_vehicle', 'make_controller', 'read_flight', 'register', 'run_campaign']


def load_vehicle(path: str | Path | None = None) -> VehicleParams:
    """The vehicle description (paper Table I, SI units) of a vehicle YAML or of a shipped vehicle by name
    ('paper', 'crazyflie', 'hummingbird', 'x500', 'px4-sih-quadx': docs/VEHICLES.md); None: the packaged one
    (the paper's). ParameterError on anything else."""
    if path is not None and not isinstance(path, (str, Path)):
        raise ParameterError(f'vehicle: expected a vehicle YAML path or a shipped vehicle\'s name, got {path!r}')
    return load_vehicle_file(path)[0]


def make_controller(kind='nnit2fsmc', vehicle: VehicleParams | str | Path | None = None,
                    gains: Mapping[str, Any] | str | Path | None = None, batch: int | None = None):
    """A fresh controller of ``kind`` for the nominal ``vehicle`` (a VehicleParams, a vehicle YAML or a
    shipped vehicle's name; None: the packaged one) with ``gains`` (a gains mapping or YAML, whole or only
    the gains it changes over the packaged set; None: the packaged ones). ``kind``: a built-in kind
    (CONTROLLERS), an installed controller's entry point, ``module:Class``, or your controller class itself
    (docs/CONTROLLERS.md). Raises ParameterError naming an invalid value."""
    kind = controller_name(kind)
    if not isinstance(vehicle, VehicleParams):
        vehicle = load_vehicle(vehicle)
    return build_controller(kind, vehicle, load_gains(gains, kind=kind), batch=batch)


def fly(controller=None, scenario: str = 'paper', *, duration: float | None = None,
        disturbances: bool | None = None, seed: int = 0, vehicle: VehicleParams | str | Path | None = None,
        gains: Mapping[str, Any] | str | Path | None = None, physics_rate: float = 1000.0,
        settle_time: float | None = None,
        max_error: float = 1.0, out: str | Path | None = None, overwrite: bool = False,
        true_vehicle: VehicleParams | str | Path | None = None, wind: Mapping | None = None,
        sensor_noise: Mapping | None = None, delay_s: float = 0.0, motor_time_constant_s: float = 0.0,
        mass_change: Mapping | None = None, rotor_efficiency_loss: Mapping | None = None,
        plant: str = 'quad_sim') -> Flight:
    """Fly a whole scenario on the embedded backend (no ROS) and return the :class:`Flight`: its time
    series as numpy arrays with units (``time``, ``state``, ``reference_position``, ``forces``,
    ``controls``, ``surfaces``, ``equivalent``, ``corrective``; ``to_pandas()``), ``metrics()``, and
    ``summary``, the content of ``summary.json`` (rmse_position_m, max_position_error_m, chattering, ...).

    ``controller`` is what :func:`make_controller` takes as ``kind`` (a name, or your controller class); None:
    the gains file's ``controller:``, else nnit2fsmc. ``vehicle`` is the controller's nominal model (a
    VehicleParams or a vehicle YAML; None: the packaged one); ``gains`` a gains mapping or YAML, whole or only
    the gains it changes over the packaged set (None: the packaged one). The world, as a campaign spec's keys of the same names mean it (docs/CAMPAIGNS.md), checked by
    the same code:

    * ``true_vehicle``: the vehicle the simulator flies (VehicleParams or YAML; None: the nominal one);
    * ``wind``: ``{mean_speed_mps: 3.0, turbulence: moderate, direction_deg: 90}`` (Dryden turbulence
      none | light | moderate | severe; without ``direction_deg`` a direction drawn from ``seed``);
    * ``sensor_noise``: ``{position_m: 0.01, velocity_mps: 0.02, attitude_rad: 0.01, body_rate_radps: 0.02}``
      (white-noise standard deviations, or ``{std: s, bias_std: b}``);
    * ``delay_s`` [s] (whole control steps) and ``motor_time_constant_s`` [s] (first-order motor lag);
    * ``mass_change``: ``{at_s: 20.0, mass_kg: 1.3}``, a payload picked up or dropped at sim time at_s
      (before the flight's end);
    * ``rotor_efficiency_loss``: ``{at_s: 10.0, loss: [0.2, 0, 0, 0]}``, lost thrust fractions of F1..F4
      from at_s on (before the flight's end).

    ``plant`` is what the simulator flies: ``quad_sim`` (our model of eq. 1) or ``rotorpy`` (RotorPy's
    ``Multirotor`` with its aerodynamics and motor model, docs/ROTORPY.md).

    With ``out`` the run is written as ``run_stack.py --out`` writes it (summary, bag, review), and
    ``read_flight(out / 'bag')`` gives the same flight back; without it nothing is written. Raises
    ParameterError (a ValueError) naming the argument before flying on any invalid setting.
    """
    from .runs import run_flight
    controller = choose_controller(None if controller is None else controller_name(controller), gains)
    return run_flight(controller, scenario, duration=duration, disturbances=disturbances, seed=seed,
                      vehicle=vehicle, gains=gains, physics_rate=physics_rate, settle_time=settle_time,
                      max_error=max_error, out=out, overwrite=overwrite, true_vehicle=true_vehicle, wind=wind,
                      sensor_noise=sensor_noise, delay_s=delay_s, motor_time_constant_s=motor_time_constant_s,
                      mass_change=mass_change, rotor_efficiency_loss=rotor_efficiency_loss, plant=plant)


def run_campaign(spec: str | Path, out: str | Path, *, flights: int | None = None, seed: int | None = None,
                 duration: float | None = None, controllers: list[str] | None = None, workers: int | None = None,
                 batch_size: int | None = None, scheduler: str | None = None, resume: bool = False,
                 progress: bool = False) -> dict:
    """Run the robustness campaign of ``spec`` (a SPEC.yaml, docs/CAMPAIGNS.md) into ``out`` and
    return the content of ``campaign.json`` (per controller: success rate and its 95 % Wilson
    interval, RMSE and chattering percentiles). The keyword arguments are the command's options."""
    import json

    from .campaign.runner import RunOptions, run_campaign as run
    from .campaign.spec import load_spec
    campaign = load_spec(spec).overridden(flights=flights, seed=seed, duration=duration, controllers=controllers)
    outcome = run(campaign, Path(out), RunOptions(workers=workers, batch_size=batch_size, scheduler=scheduler,
                                                  resume=resume, progress=progress))
    return json.loads(outcome.summary_path.read_text())
