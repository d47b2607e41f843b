"""``--replay K``: flight K of a campaign flown alone on the ordinary embedded path, with bag and review.

The flight has the same true vehicle, air, sensor errors, delay and motor lag as in the campaign
(the same random streams), but runs through the single-vehicle embedded flight: odometry
messages, a recorded bag, the summary and the review report, as ``run_stack.py`` writes them for
any flight. Its metrics equal its row of ``flights.csv`` (the batch arithmetic differs only in
rounding); the command prints the largest difference when the row is there.
"""
from __future__ import annotations

import sys
from pathlib import Path

from quad_msgs_bridge.bag.flight_bag import FlightBag, disturbances_label
from quad_msgs_bridge.contract import GROUND_TRUTH, RECORDED_TOPICS
from quad_msgs_bridge.review.command import review_flights
from quad_msgs_bridge.review.flight_from_bag import BagFlight
from quad_msgs_bridge.validation import ParameterError

from ..embedded import fly_embedded
from ..summary import build_summary, write_summary
from .batch import CampaignSetup
from .results import FLIGHTS_FILE, read_flights
from .runner import RunOptions, campaign_inputs, check_inputs
from .sampling import build_perturbations, sample_conditions
from .spec import CampaignSpec

#: summary key -> flights.csv column, for the comparison
COMPARED = {'rmse_position_m': 'rmse_position_m', 'max_position_error_m': 'max_position_error_m',
            'rmse_yaw_rad': 'rmse_yaw_rad', 'saturation_fraction': 'saturation_fraction'}


def replay_flight(spec: CampaignSpec, out_dir: Path, flight: int, options: RunOptions) -> int:
    """Fly flight ``flight`` with every controller of ``spec``; 0 when every replay flew (1 if one failed)."""
    if not 0 <= flight < spec.flights:
        raise ParameterError(f'--replay: flight {flight} is not in the campaign (0 .. {spec.flights - 1})')
    setup = CampaignSetup.of(spec, options.vehicle_file, options.gains_file)
    check_inputs(out_dir, campaign_inputs(spec, setup))   # the replay flies what the campaign flew
    rows = {(r['flight'], r['controller']): r for r in read_flights(out_dir / FLIGHTS_FILE)}
    status = 0
    nn_seed = int(setup.gains['nnit2fsmc']['seed'])   # the flights' NN seed (the campaign seed draws the conditions)
    for controller in spec.controllers:
        target = out_dir / f'replay-{flight}' / controller
        conditions = sample_conditions(spec, setup.nominal, flight)
        perturbations = build_perturbations(spec, [conditions], setup.control_dt, setup.physics_dt, batch=False)
        topics = RECORDED_TOPICS + ((GROUND_TRUTH,) if perturbations.sensor_noise is not None else ())
        print(f'replaying flight {flight} with {controller} -> {target}', file=sys.stderr)
        with FlightBag.create(target / 'bag', setup.nominal, spec.settle_time, topics=topics, overwrite=True,
                              controller=controller, scenario=spec.scenario, backend='embedded', seed=nn_seed,
                              disturbances=disturbances_label(setup.disturbances.enabled),
                              campaign_seed=spec.seed, flight=flight, duration_s=repr(float(spec.duration))) as bag:
            result = fly_embedded(controller, setup.trajectory, setup.nominal, setup.disturbances, setup.gains,
                                  spec.duration, 1.0 / setup.physics_dt, progress=options.progress, bag=bag,
                                  perturbations=perturbations, rules=setup.rules(spec), plant=spec.plant)
        summary = build_summary(result.record, backend='embedded', controller=controller, scenario=spec.scenario,
                                seed=nn_seed, settle_time=spec.settle_time, params=setup.nominal,
                                disturbances=setup.disturbances, gains=setup.gains,
                                physics_rate=1.0 / setup.physics_dt, wall_time_s=result.wall_time_s,
                                max_error=spec.max_error_m, failure=result.failure,
                                failure_time_s=result.failure_time_s, planned_duration_s=spec.duration,
                                plant=spec.plant)
        summary['campaign'] = {'seed': spec.seed, 'flight': flight, 'sampled': conditions.sampled_values(setup.nominal)}
        write_summary(summary, target)
        # reviewed from the record in memory (what the bag holds), as a single flight is: it knows whether
        # the flight ended early, so one that failed before settling is reviewed, not refused as too short
        review_flights([BagFlight(target / 'bag', controller, result.record, setup.nominal, spec.settle_time,
                                  dict(bag.writer.custom_data), ended_early=result.failure is not None)], target)
        outcome = 'finished' if result.failure is None else f'FAILED at {result.failure_time_s:.3f} s: {result.failure}'
        print(f'  {controller}: {outcome}; RMSE {summary["rmse_position_m"] * 100:.4f} cm; report {target / "report.html"}')
        row = rows.get((flight, controller))
        if row is not None:
            if row['finished'] != (result.failure is None):
                print(f'  differs from flights.csv: finished {row["finished"]} there', file=sys.stderr)
                status = 1
            elif row['finished']:
                worst = max(abs(summary[key] - row[column]) for key, column in COMPARED.items())
                worst = max(worst, *(abs(summary['chattering'][f'U{i}'] - row[f'chattering_U{i}']) for i in range(1, 5)))
                print(f'  largest difference from its flights.csv row: {worst:.3g}')
        if result.failure is not None:
            status = 1
    return status
