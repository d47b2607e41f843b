"""A flight's settings, every one checked before anything runs or is written.

:func:`plan_flight` loads the vehicle and the gains, builds the controller once (so a bad gain is
refused here, not in the middle of a flight), and checks the seed, the rates, the durations, the
error limit and the topics. Each problem raises :class:`ParameterError` naming the option or the
gains key and its valid range.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from nnit2fsmc_controller.factory import build_controller, control_period, load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.bag.flight_bag import select_topics
from quad_msgs_bridge.contract import TopicSpec
from quad_msgs_bridge.review.metrics import default_settle_time
from quad_msgs_bridge.vehicle_params import Disturbances, ParameterError, VehicleParams, check_number, load_vehicle_file

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
                disturbances: bool | None = None, seed: int = 0, vehicle_file: Path | None = None,
                gains_file: Path | None = None, physics_rate: float = 1000.0, settle_time: float | None = None,
                max_error: float = 1.0, topics: Sequence[str] | None = None) -> FlightPlan:
    """Every setting of a flight, checked; raises ParameterError (see the module doc).

    ``duration`` None: the scenario's length; ``disturbances`` None: as in the vehicle file;
    ``settle_time`` None: :func:`~quad_msgs_bridge.review.metrics.default_settle_time` of the duration;
    ``topics`` None: every recorded contract topic.
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ParameterError(f'--seed: {seed!r} is outside the valid range [0, {MAX_SEED}] (an integer)')
    if duration is not None:
        duration = check_number('--duration', duration, 0.0, low_inclusive=False)
    max_error = check_number('--max-error', max_error, 0.0, low_inclusive=False)
    params, vehicle_disturbances = load_vehicle_file(vehicle_file)
    if disturbances is not None:
        vehicle_disturbances = vehicle_disturbances.switched(disturbances)
    gains = load_gains(gains_file)
    gains.setdefault('nnit2fsmc', {})['seed'] = seed
    try:
        build_controller(controller, params, gains)
    except ParameterError as error:
        raise ParameterError(f'gains ({gains_file or "the packaged controller.yaml"}): {error}') from error
    control_rate = 1.0 / control_period(gains)
    trajectory = make_scenario(scenario, duration)
    duration = trajectory.duration if duration is None else duration
    return FlightPlan(
        controller=controller, scenario=scenario, trajectory=trajectory, params=params,
        disturbances=vehicle_disturbances, gains=gains, seed=seed, duration=duration,
        physics_rate=check_physics_rate(physics_rate, control_rate), control_rate=control_rate,
        settle_time=check_settle_time(settle_time, duration, control_rate), max_error=max_error,
        topics=select_topics(topics))

