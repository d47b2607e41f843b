"""One batch of a campaign: B flights of one controller stepped together as numpy arrays.

A :class:`BatchJob` is plain data (it travels to a worker process or a Dask worker);
:func:`fly_batch` flies it and returns one ``flights.csv`` row per flight. Flight k's row depends
only on (spec, controller, k): the same whether it flies alone, in any batch, on any worker.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nnit2fsmc_controller.factory import build_controller, build_measurement_stage, load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.review.metrics import chattering_force, chattering_moment, tracking_metrics
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file
from quad_sim.plants import make_plant
from quad_sim.simulator import Simulator

from ..closed_loop import FAILURES, ClosedLoop, FailureRules
from ..embedded import physics_substeps, published_path, setpoint_path
from .sampling import SAMPLED_COLUMNS, FlightConditions, build_perturbations, sample_conditions
from .spec import CampaignSpec

BIAS_COLUMNS = tuple(f'bias_{name}' for name in ('x_m', 'y_m', 'z_m', 'vx_mps', 'vy_mps', 'vz_mps', 'phi_rad',
                                                 'theta_rad', 'psi_rad', 'p_radps', 'q_radps', 'r_radps'))
#: each flight's actuator (quad_sim.world.World.actuator): drawn per flight, or the spec's fixed values
ACTUATOR_COLUMNS = ('motor_time_constant_s', 'delay_s')
#: the columns of flights.csv, in order
COLUMNS = ('flight', 'controller', 'finished', 'failure', 'failure_time_s',
           'rmse_position_m', 'max_position_error_m', 'rmse_yaw_rad', 'chattering_force_n_per_s',
           'chattering_moment_nm_per_s',
           'chattering_U1', 'chattering_U2', 'chattering_U3', 'chattering_U4', 'saturation_fraction',
           'control_steps', *SAMPLED_COLUMNS, *BIAS_COLUMNS, *ACTUATOR_COLUMNS)


@dataclass(frozen=True)
class BatchJob:
    """Flights ``flights`` of ``spec`` flown by ``controller`` (files: None = the packaged ones)."""

    spec: CampaignSpec
    controller: str
    flights: tuple[int, ...]
    vehicle_file: str | None = None
    gains_file: str | None = None


@dataclass(frozen=True)
class CampaignSetup:
    """What every flight of a campaign shares: nominal vehicle, disturbances, gains, reference, rates."""

    nominal: VehicleParams
    disturbances: object
    gains: dict
    control_dt: float
    physics_dt: float
    substeps: int
    trajectory: object

    @classmethod
    def of(cls, spec: CampaignSpec, vehicle_file: str | Path | None = None,
           gains_file: str | Path | None = None) -> 'CampaignSetup':
        """The shared setup; ParameterError/ValueError on an invalid file or rate."""
        nominal, disturbances = load_vehicle_file(vehicle_file)
        if spec.disturbances is not None:
            disturbances = disturbances.switched(spec.disturbances)
        gains = load_gains(gains_file, kind=spec.controllers)
        if spec.control_rate_hz is not None:
            gains.setdefault('common', {})['control_rate'] = spec.control_rate_hz
        if not spec.measurement_filters:
            gains.setdefault('common', {}).update(measurement_filter_hz=0.0, velocity_filter_hz=0.0)
        control_dt = 1.0 / gains['common']['control_rate']
        physics_rate = spec.physics_rate_hz or 1.0 / control_dt
        substeps = physics_substeps(control_dt, physics_rate)
        return cls(nominal, disturbances, gains, control_dt, 1.0 / physics_rate, substeps,
                   make_scenario(spec.scenario, spec.duration))

    def check_controllers(self, controllers) -> None:
        """ParameterError naming the first gain the gains file gets wrong for one of ``controllers``
        (each is built once for the nominal vehicle), so that a campaign fails before it flies."""
        for kind in controllers:
            build_controller(kind, self.nominal, self.gains)

    def rules(self, spec: CampaignSpec) -> FailureRules:
        return FailureRules(settle_time=spec.settle_time, max_error=spec.max_error_m)

    def steps(self, spec: CampaignSpec) -> int:
        return int(round(spec.duration / self.control_dt))


def compile_kernels(spec: CampaignSpec, vehicle_file: str | None = None, gains_file: str | None = None) -> None:
    """Have numba compile (or load from its cache) every kernel a batch of each controller of ``spec``
    runs: flight 0 flown for two control steps, then summarised. A worker process that starts later
    loads them from numba's cache instead of compiling them again."""
    for controller in spec.controllers:
        _fly(BatchJob(spec, controller, (0,), vehicle_file, gains_file), steps=2)


def fly_batch(job: BatchJob) -> list[dict]:
    """Fly the job's flights together; one row (a dict, see :func:`row`) per flight, in order."""
    return _fly(job, steps=None)


def _fly(job: BatchJob, steps: int | None) -> list[dict]:
    """The rows of the job's flights flown together for ``steps`` control steps (None: the whole duration)."""
    spec = job.spec
    setup = CampaignSetup.of(spec, job.vehicle_file, job.gains_file)
    size = len(job.flights)
    conditions = [sample_conditions(spec, setup.nominal, k) for k in job.flights]
    perturbations = build_perturbations(spec, conditions, setup.control_dt, setup.physics_dt, batch=True)
    controller = build_controller(job.controller, setup.nominal, setup.gains, batch=size)
    model = make_plant(spec.plant, perturbations.true_vehicle, setup.disturbances)
    start = [np.full(size, value) for value in setup.trajectory.initial_state]
    simulator = Simulator(model, setup.physics_dt, start, motor_lag=perturbations.motor_lag, wind=perturbations.wind)
    setpoints = setpoint_path(published_path(setup.trajectory, 50.0))
    loop = ClosedLoop(controller, simulator, setpoints.sample, setup.substeps, setup.rules(spec),
                      sensor_noise=perturbations.sensor_noise, delay=perturbations.delay, statistics=True,
                      measurement=build_measurement_stage(setup.gains))
    with np.errstate(all='ignore'):      # a failing vehicle may overflow before it is frozen
        for _ in range(setup.steps(spec) if steps is None else steps):
            loop.step()
            if not loop.flying.any():
                break
    statistics = loop.statistics.statistics()
    metrics = tracking_metrics(statistics)
    biases = perturbations.sensor_noise.bias if perturbations.sensor_noise is not None else (0.0,) * 12
    return [row(job.controller, conditions[i], setup.nominal,
                outcome={**{key: _element(value, i) for key, value in metrics.items() if key != 'chattering'},
                         **{f'chattering_{name}': _element(value, i) for name, value in metrics['chattering'].items()},
                         'control_steps': int(_element(statistics.steps, i)),
                         'settled_steps': int(_element(statistics.settled_steps, i))},
                failure=int(loop.failure[i]), failure_time=float(loop.failure_time[i]),
                biases=[_element(b, i) for b in biases],
                actuator=perturbations.actuators[i])
            for i in range(size)]


def _element(value, index: int) -> float:
    """Vehicle ``index``'s value of a per-vehicle array (or the shared float)."""
    return float(np.asarray(value)[index]) if np.ndim(value) else float(value)


def row(controller: str, conditions: FlightConditions, nominal: VehicleParams, outcome: dict,
        failure: int, failure_time: float, biases, actuator: tuple[float, float]) -> dict:
    """The flights.csv row of one flight: identity, outcome, metrics, every sampled value (SI units).

    A flight is ``finished`` when it flew its whole duration without breaking a failure rule (no
    crash, no non-finite state, position error never above max_error after settling). Its metrics
    cover the steps it flew; they are NaN when it failed before two settled steps. ``actuator``: its motor time
    constant and transport delay [s].
    """
    chattering = {f'U{i}': outcome[f'chattering_U{i}'] for i in range(1, 5)}
    values = {
        'rmse_position_m': outcome['rmse_position_m'],
        'max_position_error_m': outcome['max_position_error_m'],
        'rmse_yaw_rad': outcome['rmse_yaw_rad'],
        'chattering_force_n_per_s': chattering_force(chattering),
        'chattering_moment_nm_per_s': chattering_moment(chattering, nominal.d),
        **{f'chattering_{name}': value for name, value in chattering.items()},
        'saturation_fraction': outcome['saturation_fraction'],
    }
    if outcome['settled_steps'] < 2:
        values = {key: math.nan for key in values}
    return {
        'flight': conditions.flight, 'controller': controller, 'finished': failure < 0,
        'failure': '' if failure < 0 else FAILURES[failure],
        'failure_time_s': failure_time,
        **values,
        'control_steps': outcome['control_steps'],
        **conditions.sampled_values(nominal),
        **dict(zip(BIAS_COLUMNS, biases)),
        **dict(zip(ACTUATOR_COLUMNS, actuator)),
    }
