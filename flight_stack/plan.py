"""A flight's settings, every one checked before anything runs or is written.

:func:`plan_flight` loads the vehicle and the gains, builds the controller once (so a bad gain is
refused here, not in the middle of a flight), and checks the seed, the rates, the durations, the
error limit and the topics. Each problem raises :class:`ParameterError` naming the option or the
gains key and its valid range.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping, Sequence

from nnit2fsmc_controller.factory import build_controller, control_period, load_gains, with_settings
from nnit2fsmc_controller.registry import check_controller
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.bag.flight_bag import select_topics
from quad_msgs_bridge.contract import TopicSpec
from quad_msgs_bridge.review.metrics import default_settle_time
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import vehicle_name, Disturbances, VehicleParams, load_vehicle_file
from quad_sim.plants import DEFAULT_PLANT, PX4_CONTROLLER, PX4_SITL, check_plant, check_plant_installed
from quad_sim.world import Perturbations, build_perturbations, parse_world, vehicle_changes, wind_direction


MAX_SEED = 2 ** 31 - 1      #: largest NN seed (a ROS integer parameter of the recorder)


@dataclass
class FlightPlan:
    """What to fly, validated."""

    controller: str
    scenario: str
    trajectory: object          #: the scenario's reference (nnit2fsmc_controller.trajectory)
    params: VehicleParams
    disturbances: Disturbances
    gains: dict                 #: the gains tree, with ``nnit2fsmc.seed`` set
    seed: int
    duration: float             #: [s] sim time flown
    physics_rate: float         #: [Hz] RK4 rate, a whole multiple of the control rate
    control_rate: float         #: [Hz] controller rate (``common.control_rate``)
    settle_time: float          #: [s] left out of the metrics
    max_error: float            #: [m] largest position error after settling of a flight that passes
    topics: tuple[TopicSpec, ...]
    perturbations: Perturbations | None = None   #: the flown world, when it differs from the nominal one
    plant: str = DEFAULT_PLANT   #: what the simulator flies (quad_sim.plants.PLANTS)
    vehicle_name: str = 'paper'  #: what summaries, consoles and reports call the nominal vehicle (vehicle_name)


def _vehicle(argument: str, value) -> VehicleParams:
    """A VehicleParams, or the vehicle of a vehicle YAML path (None: the packaged one)."""
    if isinstance(value, VehicleParams):
        return value
    if value is not None and not isinstance(value, (str, Path)):
        raise ParameterError(f'{argument}: expected a VehicleParams or a vehicle YAML path, got {value!r}')
    try:
        return load_vehicle_file(value)[0]
    except ParameterError as error:
        raise ParameterError(f'{argument}: {error}') from error


def plan_perturbations(seed: int, duration: float, control_rate: float, physics_rate: float,
                       nominal: VehicleParams, *, true_vehicle=None, wind: Mapping | None = None,
                       sensor_noise: Mapping | None = None, delay_s: float = 0.0, motor_time_constant_s: float = 0.0,
                       mass_change: Mapping | None = None,
                       rotor_efficiency_loss: Mapping | None = None) -> Perturbations | None:
    """The world of one flight (quad_sim.world), None when it is the nominal one.

    ``wind``, ``sensor_noise``, ``delay_s`` and ``motor_time_constant_s`` are the world's keys, as a campaign
    spec writes them and checked by the same code (:func:`quad_sim.world.parse_world`: a wind without
    ``direction_deg`` blows in a direction drawn from the flight's stream); the random streams are those of
    flight 0 of seed ``seed``. ``true_vehicle`` (a VehicleParams or a vehicle YAML; None: the nominal one)
    is what the simulator flies; ``mass_change`` ``{at_s: t, mass_kg: m}`` and ``rotor_efficiency_loss``
    ``{at_s: t, loss: [l1, l2, l3, l4]}`` change it from sim time t [s] on, before ``duration`` [s].
    ParameterError names the argument (and its key).
    """
    world = parse_world({'wind': wind, 'sensor_noise': sensor_noise, 'delay_s': delay_s,
                         'motor_time_constant_s': motor_time_constant_s})
    true = nominal if true_vehicle is None else _vehicle('true_vehicle', true_vehicle)
    events = {key: value for key, value in (('mass_change', mass_change),
                                            ('rotor_efficiency_loss', rotor_efficiency_loss)) if value is not None}
    changes = vehicle_changes(true, events, duration)
    if true_vehicle is None and not changes and world.is_nominal:
        return None
    perturbations = build_perturbations(world, seed, [0], [true], [wind_direction(world, seed, 0)],
                                        1.0 / control_rate, 1.0 / physics_rate, batch=False)
    return replace(perturbations, changes=changes)


def check_physics_rate(physics_rate: float, control_rate: float) -> float:
    """``physics_rate`` [Hz] if it is a whole multiple of ``control_rate`` [Hz] (RK4 steps per control step)."""
    physics_rate = check_number('--physics-rate', physics_rate, 0.0, low_inclusive=False)
    substeps = round(physics_rate / control_rate)
    if substeps < 1 or abs(substeps / physics_rate - 1.0 / control_rate) > 1e-12:
        raise ParameterError(f'--physics-rate: {physics_rate:g} Hz is not a whole multiple of the control rate '
                             f'{control_rate:g} Hz (common.control_rate of the gains); valid: '
                             f'{control_rate:g}, {2 * control_rate:g}, {3 * control_rate:g}, ... Hz')
    return physics_rate


def check_settle_time(settle_time: float | None, duration: float, control_rate: float) -> float:
    """The settling window [s]: ``settle_time``, or the default rule for ``duration`` [s]; at least two control
    steps must follow it."""
    if settle_time is None:
        return default_settle_time(duration)
    settle_time = check_number('--settle-time', settle_time, 0.0)
    if settle_time > duration - 2.0 / control_rate:
        raise ParameterError(f'--settle-time: {settle_time:g} s leaves nothing of the {duration:g} s flight for the '
                             f'metrics; pass a --settle-time below {duration:g} (e.g. --settle-time '
                             f'{default_settle_time(duration):g}, the default) or a longer --duration')
    return settle_time


def plan_flight(controller: str = 'nnit2fsmc', scenario: str = 'paper', *, duration: float | None = None,
                disturbances: bool | None = None, seed: int = 0, vehicle_file: Path | VehicleParams | None = None,
                gains_file: Path | Mapping | None = None, physics_rate: float = 1000.0,
                settle_time: float | None = None,
                max_error: float = 1.0, topics: Sequence[str] | None = None, plant: str = DEFAULT_PLANT,
                gain_settings: Sequence[str] = (), **world) -> FlightPlan:
    """Every setting of a flight, checked; raises ParameterError (see the module doc).

    ``duration`` None: the scenario's length; ``disturbances`` None: as in the vehicle file (for a
    VehicleParams ``vehicle_file``: as in the packaged one); ``settle_time`` None:
    :func:`~quad_msgs_bridge.review.metrics.default_settle_time` of the duration; ``topics`` None: every
    recorded contract topic; ``plant``: what the simulator flies (``--plant``: quad_sim or rotorpy), its packages
    installed; ``gain_settings``: ``KEY=VALUE`` changes of one gain each (``--set``); ``world``: the keyword
    arguments of :func:`plan_perturbations`. ``controller`` is any kind the registry names (a built-in one, an
    installed entry point's, or ``module:Class``: nnit2fsmc_controller.registry); ``gains_file`` a gains file,
    a named set or a mapping, whole or of only the gains it changes.
    """
    check_plant_installed(check_plant(plant, '--plant'), '--plant')
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ParameterError(f'--seed: {seed!r} is outside the valid range [0, {MAX_SEED}] (an integer)')
    if duration is not None:
        duration = check_number('--duration', duration, 0.0, low_inclusive=False)
    max_error = check_number('--max-error', max_error, 0.0, low_inclusive=False)
    if disturbances is not None and not isinstance(disturbances, bool):
        raise ParameterError(f'disturbances: expected True, False or None (as in the vehicle file), got {disturbances!r}')
    if isinstance(vehicle_file, VehicleParams):
        params, vehicle_disturbances = vehicle_file, load_vehicle_file(None)[1]
    elif vehicle_file is None or isinstance(vehicle_file, (str, Path)):
        params, vehicle_disturbances = load_vehicle_file(vehicle_file)
    else:
        raise ParameterError(f'vehicle: expected a VehicleParams or a vehicle YAML path, got {vehicle_file!r}')
    if disturbances is not None:
        vehicle_disturbances = vehicle_disturbances.switched(disturbances)
    if controller == PX4_CONTROLLER:   # PX4's own controller, inside PX4: no kind of the registry builds it
        if plant != PX4_SITL:
            raise ParameterError(f'--controller {PX4_CONTROLLER}: PX4\'s own controller runs inside PX4; it flies only '
                                 f'with --plant {PX4_SITL}')
    else:
        check_controller(controller)
    if not (gains_file is None or isinstance(gains_file, (str, Path, Mapping))):
        raise ParameterError(f'gains: expected a gains mapping or a gains YAML path, got {gains_file!r}')
    try:
        gains = with_settings(load_gains(gains_file, kind=None if controller == PX4_CONTROLLER else controller),
                              gain_settings)
    except ParameterError as error:
        raise ParameterError(f'gains: {error}') from error
    gains.setdefault('nnit2fsmc', {})['seed'] = seed
    source = ('the given mapping' if isinstance(gains_file, Mapping) else gains_file
              or 'the packaged controller.yaml')
    try:
        if controller != PX4_CONTROLLER:
            build_controller(controller, params, gains)
    except ParameterError as error:
        raise ParameterError(f'gains ({source}): {error}') from error
    control_rate = 1.0 / control_period(gains)
    trajectory = make_scenario(scenario, duration)
    duration = trajectory.duration if duration is None else duration
    if duration < 2.0 / control_rate:
        raise ParameterError(f'--duration: {duration:g} s is shorter than two control steps ({2.0 / control_rate:g} s '
                             f'at common.control_rate {control_rate:g} Hz), so nothing would be flown or measured')
    physics_rate = check_physics_rate(physics_rate, control_rate)
    perturbations = plan_perturbations(seed, duration, control_rate, physics_rate, params,
                                       **world)
    return FlightPlan(
        controller=controller, scenario=scenario, trajectory=trajectory, params=params,
        disturbances=vehicle_disturbances, gains=gains, seed=seed, duration=duration,
        physics_rate=physics_rate, control_rate=control_rate,
        settle_time=check_settle_time(settle_time, duration, control_rate), max_error=max_error,
        topics=select_topics(topics), perturbations=perturbations, plant=plant,
        vehicle_name=vehicle_name(params, vehicle_file if isinstance(vehicle_file, (str, Path)) else None))

