"""The one-flight harness of the adaptive-control study (bench/adaptive_study.py, docs/ADAPTIVE.md).

``fly_case`` flies a paper flight (or any scenario) with a transport delay [s], sensor noise, a
control rate and a motor lag; ``oscillation`` and ``unstable`` judge it. (The delay margins of
docs/PAPER.md come from bench/paper_tables.py --experiments delay.)

A flight is *unstable* when it fails outright (non-finite, flipped, crashed, or a position
error above ``max_error`` after settling), when its position RMSE exceeds both 1 cm and 10 times
its RMSE without delay (a degraded, oscillating flight that has not crashed yet), or when it shows
a sustained oscillation: the rms of U2 or U3 about its own 0.5 s moving mean, over the last
``window`` seconds, above both ``threshold`` [N] and 3 times its value without delay (a sign-SMC
chatters at rms ~0.5 N without any delay: that is its nominal behaviour, not a limit cycle). A
smooth controller's stable flight follows the slow helix and disturbance moments (detrended rms
~1e-6 N); the limit cycles of issue 9 swing U2 by +-1 N (rms ~0.7 N). The default threshold,
0.05 N, is 2 % of the rotor limit F_max = 2.68 N.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
for package in ('nnit2fsmc_controller', 'quad_msgs_bridge', 'quad_sim'):
    sys.path.insert(0, str(ROOT / 'ros2_ws' / 'src' / package))
sys.path.insert(0, str(ROOT))

from flight_stack.closed_loop import FailureRules  # noqa: E402
from flight_stack.embedded import Perturbations, fly_embedded  # noqa: E402
from nnit2fsmc_controller.factory import load_gains  # noqa: E402
from nnit2fsmc_controller.trajectory import make_scenario  # noqa: E402
from quad_msgs_bridge.review.metrics import flight_metrics  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402
from quad_sim.perturbations.actuation import MotorLag, TransportDelay  # noqa: E402
from quad_sim.perturbations.sensor_noise import SensorErrors, SensorNoise  # noqa: E402
from quad_sim.perturbations.streams import flight_streams  # noqa: E402

SETTLE = 5.0   #: [s] take-off, left out of every figure
#: the sensor noise of the example campaign (campaigns/paper-robustness.yaml): position [m],
#: velocity [m/s], attitude [rad], body rate [rad/s]
CAMPAIGN_NOISE = SensorErrors(position=0.01, velocity=0.02, attitude=0.01, body_rate=0.02)


class Case(NamedTuple):
    """One flight's figures: metrics of flight_metrics plus the oscillation measure and failure."""

    metrics: dict
    oscillation: tuple   #: detrended rms of (U2, U3) [N] over the last window
    failure: str | None
    record: object


def oscillation(record, window: float = 10.0, smooth: float = 0.5) -> tuple[float, float]:
    """rms [N] of U2 and U3 about their ``smooth``-second moving mean over the last ``window`` seconds."""
    t = np.asarray(record.time)
    dt = float(np.median(np.diff(t)))
    span = max(1, int(round(smooth / dt)))
    last = t >= t[-1] - window
    result = []
    for column in (1, 2):
        u = np.asarray(record.controls)[:, column]
        kernel = np.ones(span) / span
        mean = np.convolve(u, kernel, mode='same')
        tail = (u - mean)[last][span:-span] if last.sum() > 3 * span else (u - mean)[last]
        result.append(float(np.sqrt(np.mean(tail * tail))))
    return result[0], result[1]


def fly_case(kind: str, gains: dict | None = None, *, delay_s: float = 0.0, noise: SensorErrors | None = None,
             control_rate: float | None = None, duration: float = 60.0, scenario: str = 'paper', motor_lag_s: float = 0.0,
             disturbances: bool = True, seed: int = 1, max_error: float = 1.0, window: float = 10.0) -> Case:
    """One embedded flight of ``kind`` with the given transport delay [s], sensor noise, control rate [Hz] and
    motor time constant [s] (physics at the control rate)."""
    params, dist = load_vehicle_file()
    gains = load_gains() if gains is None else gains
    if control_rate is not None:
        gains = {**gains, 'common': {**gains['common'], 'control_rate': float(control_rate)}}
    rate = float(gains['common']['control_rate'])
    streams = flight_streams(seed, 0)
    perturbations = Perturbations(
        delay=TransportDelay.from_seconds(delay_s, 1.0 / rate) if delay_s > 0.0 else None,
        motor_lag=MotorLag(motor_lag_s, 1.0 / rate) if motor_lag_s > 0.0 else None,
        sensor_noise=None if noise is None else SensorNoise(noise, SensorErrors(), streams.sensor_noise,
                                                            streams.sensor_bias))
    trajectory = make_scenario(scenario, None if scenario == 'waypoints' else duration)
    result = fly_embedded(kind, trajectory, params, dist.switched(disturbances), gains, duration, rate,
                          perturbations=perturbations, rules=FailureRules(SETTLE, max_error))
    metrics = flight_metrics(result.record, SETTLE, params.F_min, params.F_max, fuzzy_term=False,
                             ended_early=result.failure is not None)
    return Case(metrics, oscillation(result.record, window), result.failure, result.record)


def unstable(case: Case, threshold: float = 0.05, reference: Case | None = None) -> bool:
    """Whether a flight diverged, degraded or limit-cycles (see the module docstring); ``reference``: the
    same flight without delay (its oscillation x 3 raises the threshold, its RMSE x 10 bounds the RMSE)."""
    level = threshold if reference is None else max(threshold, 3.0 * max(reference.oscillation))
    degraded = reference is not None and case.metrics['rmse_position_m'] > max(
        0.01, 10.0 * reference.metrics['rmse_position_m'])
    return (case.failure is not None or max(case.oscillation) > level or not case.metrics['all_finite']
            or degraded)
