"""The flight summary: ``summary.json`` and the table printed at the end of a run."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from quad_msgs_bridge.review.metrics import FlightRecord, flight_metrics, has_fuzzy_term
from quad_msgs_bridge.review.report import describe_share
from quad_msgs_bridge.review.summary import flight_summary, vehicle_settings
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams, vehicle_name


def build_summary(flight: FlightRecord | dict, *, backend: str, controller: str, scenario: str, seed: int,
                  settle_time: float, params: VehicleParams, disturbances: Disturbances, gains: dict,
                  physics_rate: float, wall_time_s: float, max_error: float, failure: str | None = None,
                  failure_time_s: float | None = None, planned_duration_s: float | None = None,
                  plant: str = 'quad_sim', vehicle: str | None = None) -> dict:
    """Metrics of the flight (its metrics dict, e.g. ``Flight.metrics()``, or a FlightRecord to compute them
    from) plus everything needed to reproduce it (:func:`quad_msgs_bridge.review.summary.flight_summary`,
    which also builds a bag's summary).

    ``flight_ok`` is false when the flight ended early (``failure``: why, see
    flight_stack.closed_loop.FAILURES, at sim time ``failure_time_s`` [s], as the flight result and
    the bag give it; without it, the time of the last step: of the record, or the metrics' duration), a state or force went
    non-finite or the largest position error after the settling window exceeds ``max_error`` [m];
    ``failures`` says which, ``failure`` and ``failure_time_s`` why and when it ended early (None if
    it did not), ``ended_early`` the two in words; ``planned_duration_s`` [s] the length flown for
    (None: not given), as the review gives them (quad_msgs_bridge.review.verdict); ``plant``: what
    the simulator flew (quad_sim.plants.PLANTS). ``vehicle`` names the vehicle (flight_stack.plan's
    ``FlightPlan.vehicle_name``: the shipped one of ``--vehicle``, or its path); None: the shipped vehicle whose
    parameters ``params`` are, else 'custom' (quad_msgs_bridge.vehicle_params.vehicle_name); ``vehicle_params``
    holds every parameter.
    """
    metrics = flight if isinstance(flight, dict) else flight_metrics(
        flight, settle_time, params.F_min, params.F_max, fuzzy_term=has_fuzzy_term(controller),
        ended_early=failure is not None, arm_length=params.d)
    sim_time = metrics['duration_s']
    if failure is not None and failure_time_s is None:
        failure_time_s = float(metrics['duration_s'] if isinstance(flight, dict) else flight.time[-1])
    ended = None if failure is None else f'{failure} at {failure_time_s:.3f} s'
    return flight_summary(
        metrics, ended=ended, max_error=max_error, failure=failure, failure_time_s=failure_time_s,
        planned_duration_s=planned_duration_s, backend=backend, controller=controller, scenario=scenario,
        seed=seed, physics_rate_hz=physics_rate, plant=plant, wall_time_s=wall_time_s,
        real_time_factor=sim_time / wall_time_s if wall_time_s > 0 else None,
        **vehicle_settings(params, vehicle or vehicle_name(params)),
        disturbances=dataclasses.asdict(disturbances), gains=gains)


def write_summary(summary: dict, out_dir: Path) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / 'summary.json'
    path.write_text(json.dumps(summary, indent=2) + '\n')
    return path


def _share_lines(summary: dict) -> list[str]:
    """The fuzzy share per subsystem: its first window, then after settling its lowest and highest window, its
    largest rise and its last window (see quad_msgs_bridge.review.metrics.share_extremes)."""
    if summary['fuzzy_share'] is None:
        return [f'  fuzzy share: n/a ({summary["controller"]} has no fuzzy term)']
    lines = [f'  fuzzy share per {summary["fuzzy_share_window_s"]:g} s window (first; after settling: min, max, '
                 'largest rise, last):']
    for axis, extremes in summary['fuzzy_share_settled'].items():
        lines.append(f'    {axis:<6s} ' + describe_share(extremes, summary['fuzzy_share'][axis]))
    return lines


def format_summary(summary: dict) -> str:
    """A short human-readable table of the main figures."""
    chattering = '  '.join(f'{name} {summary["chattering"][name]:.3g} {unit}/s'
                           for name, unit in zip(CONTROL_NAMES, CONTROL_UNITS))
    moment = summary.get('chattering_moment_nm_per_s')
    rtf = summary.get('real_time_factor')
    lines = [
        f'flight: {summary["controller"]} on "{summary["scenario"]}", vehicle {summary["vehicle"]} '
        f'({summary["backend"]} backend), '
        f'{summary["duration_s"]:.1f} s sim in {summary["wall_time_s"]:.1f} s wall'
        + (f' (real-time factor {rtf:.1f})' if rtf else ''),
        f'  after settling ({summary["settle_time_s"]:.1f} s):',
        f'    position RMSE     {summary["rmse_position_m"] * 100:8.3f} cm',
        f'    max position err  {summary["max_position_error_m"] * 100:8.3f} cm',
        f'    yaw RMSE          {summary["rmse_yaw_rad"]:8.5f} rad',
        f'    chattering        force (U1) {summary["chattering_force_n_per_s"]:.3g} N/s, moments (d U2, d U3, U4) '
        + ('n/a' if moment is None else f'{moment:.3g} N m/s'),
        f'      per channel     {chattering}',
        f'    rotor saturation  {summary["saturation_fraction"] * 100:.2f} % of steps '
        f'({summary["saturation_fraction_whole_flight"] * 100:.2f} % over the whole flight)',
        *_share_lines(summary),
        '  result: ' + ('OK' if summary['flight_ok'] else 'FAILED: ' + '; '.join(summary['failures'])),
    ]
    return '\n'.join(lines)
