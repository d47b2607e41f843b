"""A flight as data: its time series as numpy arrays, the same object whether just flown or read from its bag.

:class:`Flight` holds one row per kept control step (see "Memory" below) of what the contract topics
carry: the state the odometry gives (the paper's 12 states), the reference, the rotor thrusts and
U1..U4 sent, and per subsystem x, y, z, phi, theta, psi the sliding surface, the NN (equivalent)
term and the fuzzy (corrective) term. ``flight_stack.api.fly`` returns one;
:func:`quad_msgs_bridge.review.flight_from_bag.read_flight` reads one from any bag with the contract
topics, so "fly, then analyse" and "read a bag, then analyse" are the same code.

Memory: a :class:`FlightLog` keeps every control step up to ``max_rows`` rows (:data:`MAX_ROWS`:
65.5 s at 1 kHz, 23 MB); when it is full it drops every other row and keeps every second step
from then on, then every fourth, and so on. So the rows are always the steps whose index is a
multiple of ``stride`` (step 0 first) and memory stays bounded however long the flight. The
metrics (``summary.json``, the review's table) never come from dropped rows: the log also sums
them over every step as it goes, and :meth:`Flight.metrics` uses those sums once rows were dropped
(from the rows themselves while none was, which is the same figure up to round-off).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from quad_msgs_bridge.bag.flight_bag import recorded_failure
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS
from quad_msgs_bridge.review.metrics import (SHARE_WINDOW, SUBSYSTEMS, BlockStatistics, FlightRecord,
                                             flight_metrics, has_fuzzy_term, metrics_from_statistics)
from quad_msgs_bridge.review.verdict import ending
from quad_msgs_bridge.state import PSI, STATE_NAMES, STATE_SIZE
from quad_msgs_bridge.vehicle_params import VehicleParams

MAX_ROWS = 1 << 16      #: rows a flight keeps at most before it thins them out (see the module doc)

#: the time series of a flight: name -> (columns, unit of each column)
SERIES = {
    'time': (1, 's'),                          # sim time
    'state': (STATE_SIZE, None),               # STATE_NAMES; units in STATE_UNITS
    'reference_position': (3, 'm'),            # world ENU
    'reference_yaw': (1, 'rad'),
    'forces': (4, 'N'),                        # rotor thrusts F1..F4 in the vehicle's layout (params.rotor_names)
    'controls': (4, None),                     # U1 [N], U2 [N], U3 [N], U4 [N m] of eq. (2)
    'surfaces': (6, None),                     # S = de + lambda e per subsystem (SURFACE_UNITS)
    'equivalent': (6, None),                   # NN equivalent-control term per subsystem
    'corrective': (6, None),                   # fuzzy (or switching) corrective term per subsystem
}
STATE_UNITS = ('m', 'm', 'm', 'm/s', 'm/s', 'm/s', 'rad', 'rad', 'rad', 'rad/s', 'rad/s', 'rad/s')
#: the sliding surfaces' units: of a velocity error (x, y, z) or an angular rate error (phi, theta, psi)
SURFACE_UNITS = ('m/s', 'm/s', 'm/s', 'rad/s', 'rad/s', 'rad/s')
#: the units of each subsystem's virtual control, and so of its NN (equivalent) and fuzzy (corrective) terms:
#: commanded accelerations (x, y), U1 (z), U2, U3 (phi, theta) and U4 (psi)
VIRTUAL_CONTROL_UNITS = ('m/s^2', 'm/s^2', 'N', 'N', 'N', 'N m')
#: a unit -> the suffix of a column name in that unit (:meth:`Flight.unit_names`: ``x`` [m] -> ``x_m``)
UNIT_SUFFIXES = {'s': 's', 'm': 'm', 'm/s': 'mps', 'm/s^2': 'mps2', 'rad': 'rad', 'rad/s': 'radps', 'N': 'N',
                 'N m': 'Nm'}
WIDTH = sum(columns for columns, _ in SERIES.values())   #: columns of a row of all SERIES side by side
_SLICES, _start = {}, 0
for _name, (_columns, _) in SERIES.items():
    _SLICES[_name], _start = slice(_start, _start + _columns), _start + _columns


@dataclass(eq=False)
class Flight:
    """One flight's time series (row i: control step ``i * stride``) and what its review needs.

    Arrays, N rows:

    * ``time`` (N,) [s] sim time;
    * ``state`` (N, 12): ``x y z`` [m, world ENU], ``vx vy vz`` [m/s, world ENU], ``phi theta psi``
      [rad] (Z-Y-X Euler angles), ``dphi dtheta dpsi`` [rad/s] (Euler-angle rates), as the odometry
      gives them (the true state; ``ground_truth/odom`` when the odometry carries sensor noise);
    * ``reference_position`` (N, 3) [m, world ENU], ``reference_yaw`` (N,) [rad];
    * ``forces`` (N, 4) rotor thrusts F1..F4 [N] in the order of the vehicle's layout (``params.rotor_names``;
      the paper's plus frame: F1 front, F2 right, F3 back, F4 left);
    * ``controls`` (N, 4) U1 [N], U2 [N], U3 [N], U4 [N m] (paper eq. (2));
    * ``surfaces``, ``equivalent``, ``corrective`` (N, 6) per subsystem x, y, z, phi, theta, psi: the
      sliding surface S [m/s or rad/s], the NN equivalent-control term and the fuzzy corrective term
      (eqs. (4)-(9); for the sliding-mode baselines their switching term, for the PID zero).
    """

    time: np.ndarray
    state: np.ndarray
    reference_position: np.ndarray
    reference_yaw: np.ndarray
    forces: np.ndarray
    controls: np.ndarray
    surfaces: np.ndarray
    equivalent: np.ndarray
    corrective: np.ndarray
    stride: int                       #: control steps per row (1: every step is kept)
    steps: int                        #: control steps flown
    params: VehicleParams             #: the vehicle (rotor limits, arm length) the flight was reviewed with
    settle_time: float                #: [s] left out of the metrics
    label: str = ''                   #: controller name, or the bag's name
    path: Path | None = None          #: its bag, if it has one
    custom_data: dict = field(default_factory=dict)   #: the bag's custom data (controller, scenario, ...)
    warnings: list = field(default_factory=list)      #: what reading the bag found odd
    #: the flight ended before its planned length: it failed, was interrupted or its bag was cut short
    #: (:attr:`ending` says why and where; see BagFlight.ended_early for what it does to the metrics)
    ended_early: bool = False
    summary: dict | None = None       #: the run's summary (``summary.json``), for a flight just flown
    _sums: 'StepSums | None' = field(default=None, repr=False, compare=False)

    @property
    def failure(self) -> tuple[str, float] | None:
        """(why, when [s, sim time]) the flight failed, from its bag's custom data; None if none is recorded."""
        return recorded_failure(self.custom_data)

    @property
    def end_time(self) -> float:
        """[s, sim time] of the last control step flown (also when rows were thinned out)."""
        if self._sums is not None and self._sums.first_time is not None:
            return float(self._sums.last_time)
        return float(self.time[-1])

    @property
    def ending(self) -> str | None:
        """Why and where the flight ended before its planned length ('interrupted at 31.000 s of 60 s',
        'flipped over at 1.472 s'); None if it flew all of it, as far as its custom data says
        (:func:`~quad_msgs_bridge.review.verdict.ending`)."""
        period = (self.end_time - float(self.time[0])) / max(self.steps - 1, 1)
        return ending(self.custom_data, self.end_time, period)

    @property
    def record(self) -> FlightRecord:
        """The rows as a :class:`~quad_msgs_bridge.review.metrics.FlightRecord` (true position and yaw)."""
        return FlightRecord(self.time, self.state[:, :3], self.state[:, PSI], self.reference_position,
                            self.reference_yaw, self.forces, self.controls, self.surfaces, self.equivalent,
                            self.corrective)

    def metrics(self) -> dict:
        """The flight's metrics, as ``summary.json`` has them (see the module doc on thinned-out rows)."""
        fuzzy = has_fuzzy_term(self.custom_data.get('controller') or None)
        if self.stride == 1 or self._sums is None:
            return flight_metrics(self.record, self.settle_time, self.params.F_min, self.params.F_max,
                                  fuzzy_term=fuzzy, ended_early=self.ended_early, arm_length=self.params.d)
        return self._sums.metrics(fuzzy, self.ended_early, self.params.d)

    def columns(self) -> dict[str, np.ndarray]:
        """Every time series as named 1-D columns: ``time``, the 12 state names, ``x_ref y_ref z_ref yaw_ref``,
        ``F1..F4``, ``U1..U4``, and per subsystem ``S_<axis>``, ``nn_<axis>``, ``fuzzy_<axis>``."""
        named = {'time': self.time}
        named.update(zip(STATE_NAMES, self.state.T))
        named.update(zip(('x_ref', 'y_ref', 'z_ref'), self.reference_position.T))
        named['yaw_ref'] = self.reference_yaw
        named.update(zip(('F1', 'F2', 'F3', 'F4'), self.forces.T))
        named.update(zip(CONTROL_NAMES, self.controls.T))
        for prefix, values in (('S', self.surfaces), ('nn', self.equivalent), ('fuzzy', self.corrective)):
            named.update(zip((f'{prefix}_{axis}' for axis in SUBSYSTEMS), values.T))
        return named

    def column_units(self) -> dict[str, str]:
        """The unit of each of :meth:`columns` ('s', 'm', 'm/s', 'rad', 'rad/s', 'N', 'N m', 'm/s^2')."""
        units = {'time': 's', **dict(zip(STATE_NAMES, STATE_UNITS)), 'x_ref': 'm', 'y_ref': 'm', 'z_ref': 'm',
                 'yaw_ref': 'rad', **{f'F{k}': 'N' for k in range(1, 5)}, **dict(zip(CONTROL_NAMES, CONTROL_UNITS))}
        units.update((f'S_{axis}', unit) for axis, unit in zip(SUBSYSTEMS, SURFACE_UNITS))
        for prefix in ('nn', 'fuzzy'):
            units.update((f'{prefix}_{axis}', unit) for axis, unit in zip(SUBSYSTEMS, VIRTUAL_CONTROL_UNITS))
        return units

    def unit_names(self) -> dict[str, str]:
        """Each of :meth:`columns` -> its name with its unit (UNIT_SUFFIXES): ``time`` -> ``time_s``, ``x`` ->
        ``x_m``, ``vx`` -> ``vx_mps``, ``U4`` -> ``U4_Nm``, ``nn_z`` -> ``nn_z_N``: the columns of
        :meth:`to_pandas` and of ``run_stack.py export``."""
        return {name: f'{name}_{UNIT_SUFFIXES[unit]}' for name, unit in self.column_units().items()}

    def to_pandas(self):
        """A pandas DataFrame of :meth:`columns` but ``time``, named with their units as ``run_stack.py export``
        names them (:meth:`unit_names`: ``x_m``, ``U1_N``, ...), one row per kept step, indexed by sim time
        (index ``time_s`` [s]). Needs pandas (not a dependency of the stack: ``pip install pandas``)."""
        try:
            import pandas
        except ImportError as error:
            raise ImportError('Flight.to_pandas needs pandas, which the flight stack does not install: '
                              'pip install pandas (or use Flight.columns(), numpy arrays)') from error
        names = self.unit_names()
        columns = {names[name]: values for name, values in self.columns().items()}
        index = pandas.Index(columns.pop(names['time']), name=names['time'])
        return pandas.DataFrame(columns, index=index)


class StepSums:
    """The metrics' sums over every control step of a flight, added a block of rows at a time (rows as
    :class:`FlightLog` keeps them: the SERIES side by side, in step order)."""

    def __init__(self, settle_time: float, f_min: float, f_max: float, share_window: float = SHARE_WINDOW):
        self.settle_time, self.share_window = settle_time, share_window
        self.statistics = BlockStatistics(settle_time, f_min, f_max)
        self.all_finite = True
        #: fuzzy share window k (steps with k <= (t - first time) / share_window < k + 1) -> per subsystem
        #: (sum |corrective|, sum |equivalent| + |corrective|)
        self.shares: dict[int, np.ndarray] = {}

    @property
    def first_time(self) -> float | None:
        """[s] sim time of the first step added (None before any)."""
        return self.statistics.first_time

    @property
    def last_time(self) -> float:
        """[s] sim time of the last step added."""
        return self.statistics.last_time

    def add_rows(self, rows: np.ndarray) -> None:
        """The next control steps, one row each (at least one)."""
        t, state = rows[:, _SLICES['time'].start], rows[:, _SLICES['state']]
        forces = rows[:, _SLICES['forces']]
        self.statistics.add(t, state[:, :3], state[:, PSI], rows[:, _SLICES['reference_position']],
                            rows[:, _SLICES['reference_yaw'].start], forces, rows[:, _SLICES['controls']])
        self.all_finite = self.all_finite and bool(np.isfinite(forces).all() and np.isfinite(state[:, :3]).all())
        windows = ((t - self.statistics.first_time) // self.share_window).astype(np.int64)
        fuzzy = np.abs(rows[:, _SLICES['corrective']])
        total = np.abs(rows[:, _SLICES['equivalent']]) + fuzzy
        for window in np.unique(windows):
            inside = windows == window
            sums = self.shares.setdefault(int(window), np.zeros((2, len(SUBSYSTEMS))))
            sums[0] += fuzzy[inside].sum(axis=0)
            sums[1] += total[inside].sum(axis=0)

    def fuzzy_share(self) -> dict[str, list[float]]:
        """As :func:`~quad_msgs_bridge.review.metrics.fuzzy_share`, from the sums."""
        ordered = [self.shares[k] for k in sorted(self.shares)]
        return {name: [float(s[0, i] / s[1, i]) if s[1, i] > 0 else 0.0 for s in ordered]
                for i, name in enumerate(SUBSYSTEMS)}

    def metrics(self, fuzzy_term: bool, ended_early: bool, arm_length: float | None = None) -> dict:
        return metrics_from_statistics(self.statistics.statistics(), self.settle_time, self.all_finite,
                                       self.fuzzy_share() if fuzzy_term else None, self.share_window,
                                       ended_early=ended_early, arm_length=arm_length)


#: rows a FlightLog collects before it sums and keeps them (a step's add is then one row written)
PENDING_ROWS = 1024


class FlightLog:
    """Collects a flight one control step (:meth:`add`) or a block of steps (:meth:`add_rows`) at a time,
    in bounded memory (see the module doc), and hands out the :class:`Flight`. ``settle_time`` [s] and the
    rotor limits ``f_min``, ``f_max`` [N] are those of the metrics."""

    def __init__(self, settle_time: float, f_min: float, f_max: float, max_rows: int = MAX_ROWS):
        if max_rows < 2 or max_rows % 2:
            raise ValueError(f'max_rows: {max_rows!r} must be an even number of at least 2')
        self.max_rows = max_rows
        self.sums = StepSums(settle_time, f_min, f_max)
        self.settle_time = settle_time
        self.steps = 0                   #: control steps added
        self.stride = 1
        self._rows = np.empty((min(4096, max_rows), WIDTH))
        self._count = 0                  #: rows kept
        self._taken = 0                  #: steps summed and kept (or dropped) so far
        self._pending = np.empty((PENDING_ROWS, WIDTH))
        self._filled = 0

    def add(self, t: float, state: Sequence[float], reference_position: Sequence[float], reference_yaw: float,
            forces: Sequence[float], controls: Sequence[float], surfaces: Sequence[float],
            equivalent: Sequence[float], corrective: Sequence[float]) -> None:
        """One control step (units as in :class:`Flight`)."""
        if self._filled == PENDING_ROWS:
            self._flush()
        self._pending[self._filled] = (t, *state, *reference_position, reference_yaw, *forces, *controls,
                                       *surfaces, *equivalent, *corrective)
        self._filled += 1
        self.steps += 1

    def add_rows(self, rows: np.ndarray) -> None:
        """Control steps as rows of the SERIES side by side (shape (N, WIDTH), units as in :class:`Flight`)."""
        self._flush()
        self.steps += len(rows)
        self._take(rows)

    def _flush(self) -> None:
        if self._filled:
            filled, self._filled = self._filled, 0
            self._take(self._pending[:filled])

    def _take(self, rows: np.ndarray) -> None:
        """Sum ``rows`` (the next steps) and keep those whose step is a multiple of the stride."""
        if not len(rows):
            return
        self.sums.add_rows(rows)
        base, self._taken = self._taken, self._taken + len(rows)
        i = (-base) % self.stride                      # the first of ``rows`` to keep
        while i < len(rows):
            if self._count == len(self._rows):
                self._make_room()
                i += (-(base + i)) % self.stride       # the next multiple of a doubled stride
                continue
            picked = rows[i::self.stride][:len(self._rows) - self._count]
            self._rows[self._count:self._count + len(picked)] = picked
            self._count += len(picked)
            i += len(picked) * self.stride

    def _make_room(self) -> None:
        if len(self._rows) < self.max_rows:      # grow up to max_rows
            grown = np.empty((min(2 * len(self._rows), self.max_rows), WIDTH))
            grown[:self._count] = self._rows[:self._count]
            self._rows = grown
            return
        kept = self._rows[:self._count:2]        # rows of steps that are multiples of the doubled stride
        self._count = len(kept)
        self._rows[:self._count] = kept.copy()
        self.stride *= 2

    def flight(self, params: VehicleParams, **about) -> Flight:
        """The flight so far (copies of the rows); ``about``: label, path, custom_data, warnings, ended_early,
        summary (see :class:`Flight`). ValueError if no step was added."""
        self._flush()
        if not self._count:
            raise ValueError('no control step was recorded')
        rows = self._rows[:self._count]
        series = {name: (rows[:, part].copy() if SERIES[name][0] > 1 else rows[:, part.start].copy())
                  for name, part in _SLICES.items()}
        return Flight(**series, stride=self.stride, steps=self.steps, params=params, settle_time=self.settle_time,
                      _sums=self.sums, **about)
