"""Flight records and the metrics of a flight, one implementation for the live summary and for review.

A :class:`FlightRecord` holds, per control step, what the contract topics carry: the odometry the
controller answered, the reference for that instant, the rotor thrusts and U1..U4 it sent, and the
per-subsystem diagnostics. The live backends fill it step by step; the bag review rebuilds it from
the recorded topics. :func:`flight_metrics` turns either into the numbers of ``summary.json``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SUBSYSTEMS = ('x', 'y', 'z', 'phi', 'theta', 'psi')
SETTLE_TIME = 5.0           #: [s] take-off and convergence left out of the metrics (flights of 10 s or more)
SHARE_WINDOW = 5.0          #: [s] windows of the fuzzy share in the metrics
#: controllers whose corrective term (``control/diagnostics``) is the IT2 fuzzy term; that of the sliding
#: mode baselines is their switching term, that of the PID zero, so they have no fuzzy share
FUZZY_CONTROLLERS = ('nnit2fsmc',)


def default_settle_time(duration: float) -> float:
    """The settling window [s] of a flight of ``duration`` [s] when none is given: 5 s, or half the
    flight when it is shorter than 10 s (so a short flight keeps half of its steps for the metrics)."""
    return min(SETTLE_TIME, 0.5 * duration)


def has_fuzzy_term(controller: str | None) -> bool:
    """Whether the flight's corrective terms are fuzzy terms: true for the FUZZY_CONTROLLERS, and for a
    flight of unknown controller (the contract names the diagnostics' corrective column fuzzy)."""
    return controller is None or controller in FUZZY_CONTROLLERS


@dataclass
class FlightRecord:
    """Arrays over the N control steps of one flight (row i: step i)."""

    time: np.ndarray                 #: (N,) [s] sim time
    position: np.ndarray             #: (N, 3) [m, world ENU]
    yaw: np.ndarray                  #: (N,) [rad]
    reference_position: np.ndarray   #: (N, 3) [m, world ENU]
    reference_yaw: np.ndarray        #: (N,) [rad]
    forces: np.ndarray               #: (N, 4) rotor thrusts F1..F4 [N]
    controls: np.ndarray             #: (N, 4) U1 [N], U2 [N], U3 [N], U4 [N m]
    surfaces: np.ndarray             #: (N, 6) sliding surfaces S per subsystem
    equivalent: np.ndarray           #: (N, 6) NN (or model) equivalent-control term per subsystem
    corrective: np.ndarray           #: (N, 6) fuzzy (or switching) corrective term per subsystem


@dataclass
class FlightRecorder:
    """Collects one row per control step (cheap appends) and hands out a :class:`FlightRecord`."""

    rows: list = field(default_factory=list)

    def append(self, t: float, position, yaw: float, reference_position, reference_yaw: float,
               forces, controls, surfaces, equivalent, corrective) -> None:
        self.rows.append((t, position, yaw, reference_position, reference_yaw,
                          forces, controls, surfaces, equivalent, corrective))

    def record(self) -> FlightRecord:
        if not self.rows:
            raise ValueError('no control step was recorded')
        columns = list(zip(*self.rows))
        return FlightRecord(*(np.asarray(column, dtype=float) for column in columns))


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def fuzzy_share(record: FlightRecord, window: float) -> dict[str, list[float]]:
    """Per subsystem and per consecutive window of ``window`` [s]: mean|corrective| / mean(|equivalent| + |corrective|).

    For the NNIT2FSMC it is the share of the control carried by the fuzzy term; it falls as
    the network learns the equivalent control.
    """
    edges = np.arange(record.time[0], record.time[-1] + window, window)
    index = np.searchsorted(record.time, edges)
    shares = {}
    for k, name in enumerate(SUBSYSTEMS):
        corrective = np.abs(record.corrective[:, k])
        total = np.abs(record.equivalent[:, k]) + corrective
        shares[name] = [float(corrective[a:b].sum() / total[a:b].sum()) if total[a:b].sum() > 0 else 0.0
                        for a, b in zip(index[:-1], index[1:]) if b > a]
    return shares


def flight_metrics(record: FlightRecord, settle_time: float, f_min: float, f_max: float,
                   share_window: float = SHARE_WINDOW, fuzzy_term: bool = True) -> dict:
    """Tracking, chattering and saturation figures of a flight, after ``settle_time`` [s].

    * rmse_position_m, max_position_error_m: Euclidean position error [m];
    * rmse_yaw_rad: wrapped yaw error [rad];
    * chattering: total variation of each of U1..U4 per second of flight [N/s; U4: N m/s];
    * saturation_fraction: share of control steps with any rotor at F_min or F_max (and the same
      over the whole flight, saturation_fraction_whole_flight);
    * fuzzy_share: see :func:`fuzzy_share`, over the whole flight; None without a fuzzy term
      (``fuzzy_term`` false, see :func:`has_fuzzy_term`).
    """
    settled = record.time >= record.time[0] + settle_time
    if settled.sum() < 2:
        duration = record.time[-1] - record.time[0]
        raise ValueError(f'the flight of {duration:.3f} s is not longer than the settling window of {settle_time:g} s; '
                         f'pass a settle time below {duration:.3f} s (e.g. --settle-time '
                         f'{default_settle_time(duration):.3g})')
    error = np.linalg.norm(record.position - record.reference_position, axis=1)[settled]
    yaw_error = _wrap(record.yaw - record.reference_yaw)[settled]
    t = record.time[settled]
    span = t[-1] - t[0]
    controls = record.controls[settled]
    variation = np.abs(np.diff(controls, axis=0)).sum(axis=0) / span
    tolerance = 1e-9 * max(1.0, abs(f_max))
    at_limit = np.any((record.forces <= f_min + tolerance) | (record.forces >= f_max - tolerance), axis=1)
    return {
        'settle_time_s': float(settle_time),
        'duration_s': float(record.time[-1] - record.time[0]),
        'control_steps': int(len(record.time)),
        'rmse_position_m': float(np.sqrt(np.mean(error ** 2))),
        'max_position_error_m': float(error.max()),
        'rmse_yaw_rad': float(np.sqrt(np.mean(yaw_error ** 2))),
        'chattering': {f'U{i + 1}': float(v) for i, v in enumerate(variation)},
        'saturation_fraction': float(at_limit[settled].mean()),
        'saturation_fraction_whole_flight': float(at_limit.mean()),
        'all_finite': bool(np.isfinite(record.forces).all() and np.isfinite(record.position).all()),
        'fuzzy_share_window_s': float(share_window),
        'fuzzy_share': fuzzy_share(record, share_window) if fuzzy_term else None,
    }
