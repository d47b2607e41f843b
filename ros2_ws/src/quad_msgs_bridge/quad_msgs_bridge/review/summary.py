"""A flight's summary (``summary.json``): its metrics, its verdict and what was flown, built by one function
for a flight just flown (``flight_stack.summary.build_summary``) and for a flight read from its bag
(:func:`bag_summary`, which :func:`~quad_msgs_bridge.review.flight_from_bag.read_flight` puts in
``Flight.summary``).

A bag records the metrics' inputs, the verdict's (planned duration, ``--max-error``, a failure), the
controller, scenario, backend, NN seed and vehicle; not the gains, the physics rate, the plant, the
wall time nor the disturbances' amplitudes. Those keys of ``summary.json`` are taken from the run's
``summary.json`` beside the bag (``OUT/summary.json`` of ``OUT/bag``) when it is the same flight's,
and left out otherwise.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from quad_msgs_bridge.review.verdict import failures, max_error_of, planned_duration
from quad_msgs_bridge.vehicle_params import VehicleParams, vehicle_name

#: keys of a run's summary.json that its bag does not record (see the module doc): those before the vehicle's,
#: and those after, in the order of summary.json
RUN_ONLY_KEYS = ('physics_rate_hz', 'plant', 'wall_time_s', 'real_time_factor'), ('disturbances', 'gains')

def flight_summary(metrics: dict, *, ended: str | None, max_error: float | None, failure: str | None = None,
                   failure_time_s: float | None = None, planned_duration_s: float | None = None,
                   **settings) -> dict:
    """``summary.json`` of a flight: its ``metrics`` (``Flight.metrics()``), then its verdict
    (:mod:`quad_msgs_bridge.review.verdict`): ``flight_ok`` and ``failures`` from ``ended`` (why and where
    it ended early, None if it did not) and the run's ``max_error`` [m] (None: not known), ``failure`` and
    ``failure_time_s`` [s, sim time] (why and when a failure rule stopped it), ``ended_early``,
    ``planned_duration_s`` [s]; then ``settings`` (backend, controller, scenario, seed, ...) in the
    order given (:func:`vehicle_settings`: the vehicle's)."""
    found = failures(metrics, ended, max_error)
    return {**metrics, 'flight_ok': not found, 'failures': found, 'failure': failure,
            'failure_time_s': failure_time_s, 'ended_early': ended, 'planned_duration_s': planned_duration_s,
            **settings}


def vehicle_settings(params: VehicleParams, name: str) -> dict:
    """A summary's ``vehicle`` (its name: :func:`~quad_msgs_bridge.vehicle_params.vehicle_name`) and
    ``vehicle_params`` (every parameter of ``params``, SI units as in VehicleParams)."""
    return {'vehicle': name, 'vehicle_params': dataclasses.asdict(params)}


def recorded_vehicle(flight) -> str:
    """The name of a recorded flight's vehicle: the bag's custom data ``vehicle_name``, else
    :func:`~quad_msgs_bridge.vehicle_params.vehicle_name` of its parameters."""
    return flight.custom_data.get('vehicle_name') or vehicle_name(flight.params)


def bag_summary(flight) -> dict:
    """``summary.json`` of a flight read from its bag (a Flight or BagFlight): every key the bag gives (see
    the module doc), and those it does not from the ``summary.json`` beside it when that is the same
    flight's (the same controller, scenario, seed, backend, planned duration and control steps)."""
    custom = flight.custom_data
    failure, metrics, planned = flight.failure, flight.metrics(), planned_duration(custom)
    seed = custom.get('seed')
    known = {'backend': custom.get('backend'), 'controller': custom.get('controller'),
             'scenario': custom.get('scenario'), 'seed': int(seed) if seed not in (None, '') else None}
    beside = _summary_beside(flight.path)
    same = {**known, 'planned_duration_s': planned, 'control_steps': metrics['control_steps']}
    run = beside if beside is not None and all(beside.get(key) == same[key] for key in same) else {}
    before, after = ({key: run[key] for key in keys if key in run} for keys in RUN_ONLY_KEYS)
    return flight_summary(metrics, ended=flight.ending, max_error=max_error_of(custom),
                          failure=None if failure is None else failure[0],
                          failure_time_s=None if failure is None else failure[1], planned_duration_s=planned,
                          **known, **before, **vehicle_settings(flight.params, recorded_vehicle(flight)), **after)


def _summary_beside(bag: Path | None) -> dict | None:
    """The one flight's summary.json of the run that wrote ``bag`` (OUT/summary.json of OUT/bag); None if there
    is none (or it is a fleet's, or not readable)."""
    if bag is None:
        return None
    path = Path(bag).parent / 'summary.json'
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return summary if isinstance(summary, dict) and 'vehicles' not in summary else None
