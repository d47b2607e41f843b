"""Flight records and the metrics of a flight, one implementation for the live summary and for review.

A :class:`FlightRecord` holds, per control step, what the contract topics carry: the odometry the
controller answered, the reference for that instant, the rotor thrusts and U1..U4 it sent, and the
per-subsystem diagnostics (a :class:`~quad_msgs_bridge.review.flight_data.Flight`, flown or read from
a bag, gives one). :func:`flight_metrics` turns it into the numbers of ``summary.json``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.numeric import namespace_for

SUBSYSTEMS = ('x', 'y', 'z', 'phi', 'theta', 'psi')
SETTLE_TIME = 5.0           #: [s] take-off and convergence left out of the metrics (flights of 10 s or more)
SHARE_WINDOW = 5.0          #: [s] windows of the fuzzy share in the metrics
#: controllers whose corrective term (``control/diagnostics``) is the IT2 fuzzy term; that of the sliding
#: mode baselines is their switching term, that of the PID zero, so they have no fuzzy share
FUZZY_CONTROLLERS = ('nnit2fsmc', 'nnit2fsmc-type1', 'nnit2fsmc-nolearn', 'nnit2fsmc-bias')


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


def fuzzy_share(record: FlightRecord, window: float) -> dict[str, list[float]]:
    """Per subsystem and per consecutive window of ``window`` [s]: mean|corrective| / mean(|equivalent| + |corrective|).

    For the NNIT2FSMC it is the share of the control carried by the fuzzy term; it falls as
    the network learns the equivalent control.
    """
    edges = np.arange(record.time[0], record.time[-1] + window, window)
    index = np.searchsorted(record.time, edges)
    index[-1] = len(record.time)          # the last window holds the last step, also one at its very edge
    shares = {}
    for k, name in enumerate(SUBSYSTEMS):
        corrective = np.abs(record.corrective[:, k])
        total = np.abs(record.equivalent[:, k]) + corrective
        shares[name] = [float(corrective[a:b].sum() / total[a:b].sum()) if total[a:b].sum() > 0 else 0.0
                        for a, b in zip(index[:-1], index[1:]) if b > a]
    return shares


def share_extremes(shares: list[float], window: float, settle_time: float, duration: float) -> dict | None:
    """Where the fuzzy share of one subsystem (``shares``: one value per ``window`` [s], from the
    flight's first step) went after settling, so that a share which falls and rises again is reported
    with its rise, not only as first -> last.

    Only windows that start at or after ``settle_time`` [s] count (none: None). Returns ``first`` (the
    share of the flight's first window), ``min``, ``max`` and ``last`` (each ``{'value': share,
    'from_s': start, 'to_s': end}`` [s from the first step; the last window ends at ``duration`` at
    the latest]) and ``rise``: the largest increase from a window to a later one, ``{'from': window,
    'to': window}`` (None if the share never rises after settling).
    """
    settled = [{'value': float(value), 'from_s': k * window, 'to_s': min((k + 1) * window, duration)}
               for k, value in enumerate(shares) if k * window >= settle_time - 1e-9]
    if not settled:
        return None
    rise, lowest = None, settled[0]
    for entry in settled[1:]:
        if rise is None or entry['value'] - lowest['value'] > rise['to']['value'] - rise['from']['value']:
            if entry['value'] > lowest['value']:
                rise = {'from': lowest, 'to': entry}
        if entry['value'] < lowest['value']:
            lowest = entry
    return {'first': float(shares[0]), 'min': min(settled, key=lambda e: e['value']),
            'max': max(settled, key=lambda e: e['value']), 'last': settled[-1], 'rise': rise}


def chattering_force(chattering: dict):
    """The force channel's chattering [N/s]: total variation of the thrust U1 per second."""
    return chattering['U1']


def chattering_moment(chattering: dict, arm_length: float):
    """The moment channels' chattering [N m/s]: total variation per second of the roll torque d U2,
    the pitch torque d U3 and the yaw torque U4 (eq. 2), summed; ``arm_length`` d [m]."""
    return arm_length * (chattering['U2'] + chattering['U3']) + chattering['U4']


@dataclass
class TrackingStatistics:
    """The sums every tracking, chattering and saturation metric is made of (floats, or arrays over a batch).

    "Settled" steps are those at or after ``settle_time`` after the first step. A record sums
    them over its time axis (:func:`record_statistics`); a batch flight adds one step at a time
    (:class:`StatisticsAccumulator`); :func:`tracking_metrics` turns either into the same figures.
    """

    steps: object                    #: control steps flown
    settled_steps: object            #: of which settled
    squared_error_sum: object        #: [m^2] sum of squared Euclidean position errors, settled steps
    max_error: object                #: [m] largest Euclidean position error, settled steps
    squared_yaw_error_sum: object    #: [rad^2] sum of squared wrapped yaw errors, settled steps
    variation: tuple                 #: sum of |U_i(k) - U_i(k-1)| over consecutive settled steps, i = 1..4
    settled_span: object             #: [s] time from the first to the last settled step
    saturated_steps: object          #: steps with a rotor at a limit, whole flight
    saturated_settled_steps: object  #: the same, settled steps only
    first_time: object               #: [s] time of the first step
    last_time: object                #: [s] time of the last step


def rotor_at_limit(forces, f_min: float, f_max: float):
    """Whether any of the rotor thrusts F1..F4 [N] sits at F_min or F_max (to 1e-9 relative)."""
    tolerance = 1e-9 * max(1.0, abs(f_max))
    at_limit = False
    for force in forces:
        at_limit = at_limit | (force <= f_min + tolerance) | (force >= f_max - tolerance)
    return at_limit


class BlockStatistics:
    """:class:`TrackingStatistics` of one flight, summed a block of consecutive control steps at a time: each
    argument of :meth:`add` holds the block's steps along its first axis (time (N,) [s], position (N, 3) [m],
    yaw (N,) [rad], reference position (N, 3), reference yaw (N,), forces (N, 4) [N], U1..U4 (N, 4))."""

    def __init__(self, settle_time: float, f_min: float, f_max: float):
        self.settle_time, self.f_min, self.f_max = settle_time, f_min, f_max
        self.steps = self.settled_steps = self.saturated_steps = self.saturated_settled_steps = 0
        self.squared_error_sum = self.max_error = self.squared_yaw_error_sum = 0.0
        self.variation = np.zeros(4)
        self.first_time: float | None = None
        self.last_time = self.first_settled_time = self.last_settled_time = 0.0
        self._last_settled_controls: np.ndarray | None = None

    def add(self, time, position, yaw, reference_position, reference_yaw, forces, controls) -> None:
        """The next block of steps (at least one)."""
        if self.first_time is None:
            self.first_time = float(time[0])
        self.last_time = float(time[-1])
        self.steps += len(time)
        at_limit = rotor_at_limit(np.transpose(forces), self.f_min, self.f_max)
        self.saturated_steps += int(at_limit.sum())
        settled = time >= self.first_time + self.settle_time
        if not settled.any():
            return
        error = position[settled] - reference_position[settled]
        squared = (error * error).sum(axis=1)
        yaw_error = wrap_angle(yaw[settled] - reference_yaw[settled])
        settled_controls = controls[settled]
        if self._last_settled_controls is None:
            self.first_settled_time = float(time[settled][0])
        else:
            settled_controls = np.vstack((self._last_settled_controls, settled_controls))
        self.variation = self.variation + np.abs(np.diff(settled_controls, axis=0)).sum(axis=0)
        self._last_settled_controls = settled_controls[-1].copy()
        self.settled_steps += int(settled.sum())
        self.squared_error_sum += float(squared.sum())
        self.max_error = max(self.max_error, float(np.sqrt(squared.max())))
        self.squared_yaw_error_sum += float((yaw_error * yaw_error).sum())
        self.saturated_settled_steps += int(at_limit[settled].sum())
        self.last_settled_time = float(time[settled][-1])

    def statistics(self) -> TrackingStatistics:
        return TrackingStatistics(
            steps=self.steps, settled_steps=self.settled_steps, squared_error_sum=self.squared_error_sum,
            max_error=self.max_error, squared_yaw_error_sum=self.squared_yaw_error_sum,
            variation=tuple(float(v) for v in self.variation),
            settled_span=self.last_settled_time - self.first_settled_time, saturated_steps=self.saturated_steps,
            saturated_settled_steps=self.saturated_settled_steps, first_time=self.first_time,
            last_time=self.last_time)


def record_statistics(record: FlightRecord, settle_time: float, f_min: float, f_max: float) -> TrackingStatistics:
    """The statistics of a whole recorded flight."""
    statistics = BlockStatistics(settle_time, f_min, f_max)
    statistics.add(record.time, record.position, record.yaw, record.reference_position, record.reference_yaw,
                   record.forces, record.controls)
    return statistics.statistics()


class StatisticsAccumulator:
    """:class:`TrackingStatistics` of one flight or a batch of flights, one control step at a time.

    ``add`` takes the step's time [s], true position [m, world ENU], yaw [rad], reference position
    and yaw, commanded rotor thrusts [N] and U1..U4, and ``flying`` (which vehicles of a batch
    still fly; a failed vehicle's statistics stop at its last step). Values are floats for one
    vehicle or arrays (B,) for a batch, through the same code.
    """

    def __init__(self, settle_time: float, f_min: float, f_max: float):
        self.settle_time, self.f_min, self.f_max = settle_time, f_min, f_max
        self.steps = self.settled_steps = self.saturated_steps = self.saturated_settled_steps = 0
        self.squared_error_sum = self.max_error = self.squared_yaw_error_sum = 0.0
        self.variation = (0.0, 0.0, 0.0, 0.0)
        self.first_time = None
        self.first_settled_time = self.last_time = self.last_settled_time = 0.0
        self._previous_controls = None

    def add(self, t: float, position, yaw, reference_position, reference_yaw, forces, controls, flying=True) -> None:
        xp = namespace_for(position[0])
        if self.first_time is None:
            self.first_time = t
        settled = t >= self.first_time + self.settle_time
        count = xp.where(flying, 1, 0)
        self.steps = self.steps + count
        self.last_time = xp.where(flying, t, self.last_time)
        at_limit = xp.where(rotor_at_limit(forces, self.f_min, self.f_max), count, 0)
        self.saturated_steps = self.saturated_steps + at_limit
        if not settled:
            return
        squared = sum((p - r) * (p - r) for p, r in zip(position, reference_position))
        yaw_error = wrap_angle(yaw - reference_yaw)
        on = xp.where(flying, 1.0, 0.0)
        if self._previous_controls is not None:
            self.variation = tuple(v + on * xp.abs(u - u0)
                                   for v, u, u0 in zip(self.variation, controls, self._previous_controls))
        else:
            self.first_settled_time = t
        self._previous_controls = controls
        self.settled_steps = self.settled_steps + count
        self.squared_error_sum = self.squared_error_sum + on * squared
        self.max_error = xp.where(flying, xp.maximum(self.max_error, xp.sqrt(squared)), self.max_error)
        self.squared_yaw_error_sum = self.squared_yaw_error_sum + on * yaw_error * yaw_error
        self.saturated_settled_steps = self.saturated_settled_steps + at_limit
        self.last_settled_time = xp.where(flying, t, self.last_settled_time)

    def statistics(self) -> TrackingStatistics:
        return TrackingStatistics(
            steps=self.steps, settled_steps=self.settled_steps, squared_error_sum=self.squared_error_sum,
            max_error=self.max_error, squared_yaw_error_sum=self.squared_yaw_error_sum, variation=self.variation,
            settled_span=self.last_settled_time - self.first_settled_time,
            saturated_steps=self.saturated_steps, saturated_settled_steps=self.saturated_settled_steps,
            first_time=self.first_time, last_time=self.last_time)


def tracking_metrics(stats: TrackingStatistics) -> dict:
    """RMSE, max error, yaw RMSE, chattering and saturation from the statistics (floats or arrays).

    * rmse_position_m, max_position_error_m: Euclidean position error [m], settled steps;
    * rmse_yaw_rad: wrapped yaw error [rad], settled steps;
    * chattering: per channel, total variation of U1..U4 per second of settled flight, each in its own
      unit: U1, U2, U3 [N/s], U4 [N m/s] (never add them up: see :func:`chattering_force` and
      :func:`chattering_moment` for the force and moment figures);
    * saturation_fraction: share of settled control steps with any rotor at F_min or F_max
      (saturation_fraction_whole_flight: over every step).
    """
    settled = np.maximum(stats.settled_steps, 1)
    span = np.where(np.asarray(stats.settled_span) > 0.0, stats.settled_span, np.inf)
    return {
        'rmse_position_m': np.sqrt(stats.squared_error_sum / settled),
        'max_position_error_m': stats.max_error,
        'rmse_yaw_rad': np.sqrt(stats.squared_yaw_error_sum / settled),
        'chattering': {f'U{i + 1}': v / span for i, v in enumerate(stats.variation)},
        'saturation_fraction': stats.saturated_settled_steps / settled,
        'saturation_fraction_whole_flight': stats.saturated_steps / np.maximum(stats.steps, 1),
    }


def flight_metrics(record: FlightRecord, settle_time: float, f_min: float, f_max: float,
                   share_window: float = SHARE_WINDOW, fuzzy_term: bool = True, ended_early: bool = False,
                   arm_length: float | None = None) -> dict:
    """Tracking, chattering and saturation figures of a flight, after ``settle_time`` [s].

    The figures of :func:`tracking_metrics`, plus the flight's duration and step count, whether
    every force and position is finite, chattering_force_n_per_s (:func:`chattering_force`) and
    chattering_moment_nm_per_s (:func:`chattering_moment` with ``arm_length`` d [m]; None without
    it), and fuzzy_share (see :func:`fuzzy_share`, over the whole flight; None without a fuzzy term:
    ``fuzzy_term`` false, see :func:`has_fuzzy_term`) with fuzzy_share_settled (per subsystem, see
    :func:`share_extremes`). A flight that ``ended_early`` (failed) before two settled steps has NaN
    tracking figures; any other flight that short is refused (ValueError).
    """
    return metrics_from_statistics(
        record_statistics(record, settle_time, f_min, f_max), settle_time,
        bool(np.isfinite(record.forces).all() and np.isfinite(record.position).all()),
        fuzzy_share(record, share_window) if fuzzy_term else None, share_window, ended_early=ended_early,
        arm_length=arm_length)


def metrics_from_statistics(stats: TrackingStatistics, settle_time: float, all_finite: bool,
                            shares: dict | None, share_window: float = SHARE_WINDOW, ended_early: bool = False,
                            arm_length: float | None = None) -> dict:
    """The figures of :func:`flight_metrics` from a flight's statistics (of a record, or summed step by step),
    whether its forces and positions were all finite and its fuzzy shares (None: no fuzzy term); ``arm_length``
    d [m] for chattering_moment_nm_per_s (None without it)."""
    if stats.settled_steps < 2 and not ended_early:
        duration = stats.last_time - stats.first_time
        raise ValueError(f'the flight of {duration:.3f} s is not longer than the settling window of {settle_time:g} s; '
                         f'pass a settle time below {duration:.3f} s (e.g. --settle-time '
                         f'{default_settle_time(duration):.3g})')
    tracking = tracking_metrics(stats)
    if stats.settled_steps < 2:
        tracking = {key: ({k: math.nan for k in value} if isinstance(value, dict) else math.nan)
                    for key, value in tracking.items()}
    chattering = {name: float(value) for name, value in tracking['chattering'].items()}
    duration = float(stats.last_time - stats.first_time)
    return {
        'settle_time_s': float(settle_time),
        'duration_s': duration,
        'control_steps': int(stats.steps),
        'rmse_position_m': float(tracking['rmse_position_m']),
        'max_position_error_m': float(tracking['max_position_error_m']),
        'rmse_yaw_rad': float(tracking['rmse_yaw_rad']),
        'chattering': chattering,
        'chattering_force_n_per_s': float(chattering_force(chattering)),
        'chattering_moment_nm_per_s': (None if arm_length is None
                                       else float(chattering_moment(chattering, arm_length))),
        'saturation_fraction': float(tracking['saturation_fraction']),
        'saturation_fraction_whole_flight': float(tracking['saturation_fraction_whole_flight']),
        'all_finite': bool(all_finite),
        'fuzzy_share_window_s': float(share_window),
        'fuzzy_share': shares,
        'fuzzy_share_settled': None if shares is None else
        {name: share_extremes(values, share_window, settle_time, duration) for name, values in shares.items()},
    }
