"""PNG plots of one or several flights (overlaid), after the paper's Fig. 7-9.

* ``path_3d.png``: the 3-D path against the reference (Fig. 7), equal scales on the three axes
  (a hover's millimetre drift stays millimetres), a reference that does not move as a hold point;
* ``tracking.png``: x, y, z [m] and yaw [rad] against their references, the errors over the whole
  flight with the end of the settling window marked, and the errors after it on their own scale
  [mm, mrad] (Fig. 8);
* ``controls.png``: U1..U4 and the rotor thrusts F1..F4 against time (Fig. 9);
* ``controls_zoom.png``: U1..U4 over one second after settling, where chattering shows;
* ``surfaces.png``: the sliding surfaces S of the six subsystems [m/s, rad/s], over the whole flight
  (left) and after settling on the scale of that window (right: the take-off spike of S, tens of
  rad/s, would flatten them);
* ``fuzzy_share.png``: the fuzzy share of each subsystem's control over time,
  :func:`quad_msgs_bridge.review.metrics.fuzzy_share` on 0.5 s windows and on the windows of the
  metrics (5 s); only flights whose controller has a fuzzy term (no figure if none has).

Needs matplotlib (imported here only; the Agg backend, no display).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from quad_msgs_bridge.conversions import SUBSYSTEM_NAMES
from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.review.flight_from_bag import BagFlight
from quad_msgs_bridge.review.metrics import SHARE_WINDOW, fuzzy_share, has_fuzzy_term
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS

FINE_SHARE_WINDOW = 0.5   #: [s] short windows of the fuzzy-share plot (the metrics use SHARE_WINDOW)
ZOOM_SPAN = 1.0           #: [s] span of the control zoom
HOLD_TOLERANCE = 1e-6     #: [m] a reference that moves less is drawn as a hold point
#: unit of S = de/dt + lambda e per subsystem: e in m (x, y, z) or rad (phi, theta, psi)
SURFACE_UNITS = {'x': 'm/s', 'y': 'm/s', 'z': 'm/s', 'phi': 'rad/s', 'theta': 'rad/s', 'psi': 'rad/s'}
_REFERENCE_STYLE = dict(color='black', linestyle='--', linewidth=1.0)
_SETTLE_STYLE = dict(color='tab:red', linestyle=':', linewidth=1.0)


def _pyplot():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    fig.clf()
    return path


def _layer(index: int, flights: Sequence[BagFlight]) -> dict:
    """Line style of the ``index``-th flight: the first flight on top, so a quieter controller stays visible."""
    return dict(zorder=2 + len(flights) - index, label=flights[index].label)


def _legend(ax, flights: Sequence[BagFlight]) -> None:
    if len(flights) > 1 or ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize='small', loc='best')


def equal_limits(points: np.ndarray) -> list[tuple[float, float]]:
    """(low, high) [m] per axis of the cube centred on ``points`` (M, 3) that holds them all."""
    low, high = points.min(axis=0), points.max(axis=0)
    half = max(float((high - low).max()) / 2.0, 1e-3)
    return [(c - half, c + half) for c in (low + high) / 2.0]


def plot_path_3d(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection='3d')
    reference = flights[0].record.reference_position
    if np.ptp(reference, axis=0).max() > HOLD_TOLERANCE:
        ax.plot(reference[:, 0], reference[:, 1], reference[:, 2], label='reference', **_REFERENCE_STYLE)
    else:
        ax.scatter(*reference[0], marker='x', s=80, color='black', depthshade=False, label='hold point (reference)')
    for i, flight in enumerate(flights):
        p = flight.record.position
        ax.plot(p[:, 0], p[:, 1], p[:, 2], linewidth=1.2, **_layer(i, flights))
    limits = equal_limits(np.vstack([reference] + [f.record.position for f in flights]))
    ax.set(xlim=limits[0], ylim=limits[1], zlim=limits[2], xlabel='x [m]', ylabel='y [m]', zlabel='z [m]')
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_title('Path in 3-D against the reference (Fig. 7), equal axis scales')
    ax.legend(fontsize='small')
    return _save(fig, path)


def plot_tracking(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    """Per row (x, y, z, yaw): the value against the reference, the error over the whole flight (the end of
    the settling window marked), and the error after settling on its own scale [mm, mrad]."""
    fig, axes = plt.subplots(4, 3, figsize=(15, 10))
    names, units = ('x', 'y', 'z', 'yaw'), ('m', 'm', 'm', 'rad')   # yaw unwrapped for display
    first = flights[0].record
    settled_from = first.time[0] + flights[0].settle_time
    for row, (name, unit) in enumerate(zip(names, units)):
        value_ax, error_ax, settled_ax = axes[row]
        reference = np.unwrap(first.reference_yaw) if row == 3 else first.reference_position[:, row]
        value_ax.plot(first.time, reference, label='reference', **_REFERENCE_STYLE)
        for i, flight in enumerate(flights):
            r = flight.record
            if row == 3:
                value, error = np.unwrap(r.yaw), wrap_angle(r.yaw - r.reference_yaw)
            else:
                value, error = r.position[:, row], r.position[:, row] - r.reference_position[:, row]
            settled = r.time >= r.time[0] + flight.settle_time
            value_ax.plot(r.time, value, linewidth=1.0, **_layer(i, flights))
            error_ax.plot(r.time, error, linewidth=1.0, **_layer(i, flights))
            settled_ax.plot(r.time[settled], 1000.0 * error[settled], linewidth=1.0, **_layer(i, flights))
        value_ax.set_ylabel(f'{name} [{unit}]')
        error_ax.set_ylabel(f'error {name} [{unit}]')
        settled_ax.set_ylabel(f'error {name} [m{unit}]')
        error_ax.axvline(settled_from, label='end of settling window', **_SETTLE_STYLE)
        for ax in (error_ax, settled_ax):
            ax.axhline(0.0, color='grey', linewidth=0.5)
    axes[0][0].set_title('Tracking (Fig. 8)')
    axes[0][1].set_title('Tracking error, whole flight')
    axes[0][2].set_title(f'Tracking error after settling ({flights[0].settle_time:g} s)')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    for ax in axes[0]:
        _legend(ax, flights)
    return _save(fig, path)


def plot_controls(plt, flights: Sequence[BagFlight], path: Path, span: tuple[float, float] | None = None) -> Path:
    """U1..U4 (left) and F1..F4 (right), or with ``span`` = (t0, t1) [s] only U1..U4 in that window."""
    columns = 1 if span else 2
    fig, axes = plt.subplots(4, columns, figsize=(12 if columns == 2 else 8, 10), sharex=True, squeeze=False)
    for i, flight in enumerate(flights):
        r = flight.record
        shown = slice(None) if span is None else (r.time >= span[0]) & (r.time <= span[1])
        for k in range(4):
            axes[k][0].plot(r.time[shown], r.controls[shown, k], linewidth=0.8, **_layer(i, flights))
            if not span:
                axes[k][1].plot(r.time, r.forces[:, k], linewidth=0.8, **_layer(i, flights))
    for k in range(4):
        axes[k][0].set_ylabel(f'{CONTROL_NAMES[k]} [{CONTROL_UNITS[k]}]')
        if not span:
            axes[k][1].set_ylabel(f'{flights[0].params.rotor_names[k]} [N]')   # F1..F4 of the vehicle's layout
            axes[k][1].axhline(flights[0].params.F_max, color='grey', linewidth=0.5, linestyle=':')
            axes[k][1].axhline(flights[0].params.F_min, color='grey', linewidth=0.5, linestyle=':')
    title = ('Control signals (Fig. 9)' if not span
             else f'Control signals, {span[0]:.1f} s to {span[1]:.1f} s (chattering)')
    axes[0][0].set_title(title)
    if not span:
        axes[0][1].set_title('Rotor thrusts (dotted: limits)')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    _legend(axes[0][0], flights)
    return _save(fig, path)


def settled_limits(values: Sequence[np.ndarray], margin: float = 0.05) -> tuple[float, float] | None:
    """(low, high) that hold every finite value of ``values`` (arrays over the settled steps), widened by
    ``margin`` of their range (a flat line: by 1e-9 or 1e-6 of its level); None if there is none."""
    finite = np.concatenate([np.asarray(v, dtype=float).ravel() for v in values]) if values else np.empty(0)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return None
    low, high = float(finite.min()), float(finite.max())
    pad = margin * (high - low) if high > low else max(1e-9, 1e-6 * abs(high))
    return low - pad, high + pad


def plot_surfaces(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    """Per subsystem (rows): S over the whole flight (left, the end of the settling window marked) and S
    after settling with the y axis scaled to the settled values (right)."""
    fig, axes = plt.subplots(len(SUBSYSTEM_NAMES), 2, figsize=(13, 13))
    settled_from = flights[0].record.time[0] + flights[0].settle_time
    for k, name in enumerate(SUBSYSTEM_NAMES):
        whole_ax, settled_ax = axes[k]
        settled_values = []
        for i, flight in enumerate(flights):
            r = flight.record
            settled = r.time >= r.time[0] + flight.settle_time
            whole_ax.plot(r.time, r.surfaces[:, k], linewidth=0.8, **_layer(i, flights))
            settled_ax.plot(r.time[settled], r.surfaces[settled, k], linewidth=0.8, **_layer(i, flights))
            settled_values.append(r.surfaces[settled, k])
        limits = settled_limits(settled_values)
        if limits is None:
            settled_ax.text(0.5, 0.5, 'no settled step', transform=settled_ax.transAxes, ha='center', va='center')
        else:
            settled_ax.set_ylim(*limits)
        whole_ax.axvline(settled_from, label='end of settling window', **_SETTLE_STYLE)
        for ax in (whole_ax, settled_ax):
            ax.axhline(0.0, color='grey', linewidth=0.5)
            ax.set_ylabel(f'S_{name} [{SURFACE_UNITS[name]}]')
    axes[0][0].set_title('Sliding surfaces S = de/dt + lambda e, whole flight')
    axes[0][1].set_title(f'After settling ({flights[0].settle_time:g} s), scaled to that window')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    _legend(axes[0][0], flights)
    return _save(fig, path)


def plot_fuzzy_share(plt, flights: Sequence[BagFlight], path: Path) -> Path | None:
    """The fuzzy share on FINE_SHARE_WINDOW windows (thin lines) and on the SHARE_WINDOW windows of the
    metrics (steps), of the flights whose controller has a fuzzy term; None (no figure) if none has."""
    shown = [i for i, flight in enumerate(flights) if has_fuzzy_term(flight.custom_data.get('controller'))]
    if not shown:
        return None
    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True, sharey=True)
    for i in shown:
        time = flights[i].record.time
        fine, coarse = fuzzy_share(flights[i].record, FINE_SHARE_WINDOW), fuzzy_share(flights[i].record, SHARE_WINDOW)
        for k, name in enumerate(SUBSYSTEM_NAMES):
            ax = axes[k // 2][k % 2]
            centres = time[0] + FINE_SHARE_WINDOW * (np.arange(len(fine[name])) + 0.5)
            ax.plot(centres, fine[name], color=f'C{i}', linewidth=0.6, alpha=0.6, zorder=1)
            edges = np.minimum(time[0] + SHARE_WINDOW * np.arange(len(coarse[name]) + 1), time[-1])
            ax.stairs(coarse[name], edges, baseline=None, color=f'C{i}', linewidth=1.8, **_layer(i, flights))
    for k, name in enumerate(SUBSYSTEM_NAMES):
        axes[k // 2][k % 2].set_ylabel(f'fuzzy share {name}')
    axes[0][0].set_ylim(-0.02, 1.02)
    fig.suptitle('Fuzzy share |fuzzy term| / (|NN term| + |fuzzy term|): thin, '
                 f'{FINE_SHARE_WINDOW:g} s windows; steps, the {SHARE_WINDOW:g} s windows of the metrics')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    _legend(axes[0][0], flights)
    return _save(fig, path)


def plot_flights(flights: Sequence[BagFlight], out_dir: Path) -> list[Path]:
    """All plots of ``flights`` (overlaid) as PNG files in ``out_dir``; raises ImportError without matplotlib."""
    plt = _pyplot()
    out_dir.mkdir(parents=True, exist_ok=True)
    time, settle = flights[0].record.time, flights[0].settle_time
    zoom_start = max(time[0], min(time[0] + settle, time[-1] - ZOOM_SPAN))
    zoom = (zoom_start, min(zoom_start + ZOOM_SPAN, time[-1]))
    try:
        plots = [plot_path_3d(plt, flights, out_dir / 'path_3d.png'),
                 plot_tracking(plt, flights, out_dir / 'tracking.png'),
                 plot_controls(plt, flights, out_dir / 'controls.png'),
                 plot_controls(plt, flights, out_dir / 'controls_zoom.png', span=zoom),
                 plot_surfaces(plt, flights, out_dir / 'surfaces.png'),
                 plot_fuzzy_share(plt, flights, out_dir / 'fuzzy_share.png')]
        return [plot for plot in plots if plot is not None]
    finally:
        plt.close('all')
