"""PNG plots of one or several flights (overlaid), after the paper's Fig. 7-9.

* ``path_3d.png``: the 3-D path against the reference (Fig. 7);
* ``tracking.png``: x, y, z [m] and yaw [rad] against their references, and the errors (Fig. 8);
* ``controls.png``: U1..U4 and the rotor thrusts F1..F4 against time (Fig. 9);
* ``controls_zoom.png``: U1..U4 over one second after settling, where chattering shows;
* ``surfaces.png``: the sliding surfaces S of the six subsystems;
* ``fuzzy_share.png``: the fuzzy (corrective) share of each subsystem's control over time,
  :func:`quad_msgs_bridge.review.metrics.fuzzy_share` on short windows.

Needs matplotlib (imported here only; the Agg backend, no display).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from quad_msgs_bridge.conversions import SUBSYSTEM_NAMES
from quad_msgs_bridge.review.flight_from_bag import BagFlight
from quad_msgs_bridge.review.metrics import _wrap, fuzzy_share
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS, ROTOR_NAMES

SHARE_WINDOW = 0.5        #: [s] window of the fuzzy-share plot
ZOOM_SPAN = 1.0           #: [s] span of the control zoom
_REFERENCE_STYLE = dict(color='black', linestyle='--', linewidth=1.0)


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


def plot_path_3d(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection='3d')
    reference = flights[0].record.reference_position
    ax.plot(reference[:, 0], reference[:, 1], reference[:, 2], label='reference', **_REFERENCE_STYLE)
    for i, flight in enumerate(flights):
        p = flight.record.position
        ax.plot(p[:, 0], p[:, 1], p[:, 2], linewidth=1.2, **_layer(i, flights))
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_zlabel('z [m]')
    ax.set_title('Path in 3-D against the reference (Fig. 7)')
    ax.legend(fontsize='small')
    return _save(fig, path)


def plot_tracking(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    fig, axes = plt.subplots(4, 2, figsize=(12, 10), sharex=True)
    names = ('x [m]', 'y [m]', 'z [m]', 'yaw [rad]')   # yaw unwrapped for display
    first = flights[0].record
    for row, name in enumerate(names):
        value_ax, error_ax = axes[row]
        reference = np.unwrap(first.reference_yaw) if row == 3 else first.reference_position[:, row]
        value_ax.plot(first.time, reference, label='reference', **_REFERENCE_STYLE)
        for i, flight in enumerate(flights):
            r = flight.record
            if row == 3:
                value, error = np.unwrap(r.yaw), _wrap(r.yaw - r.reference_yaw)
            else:
                value, error = r.position[:, row], r.position[:, row] - r.reference_position[:, row]
            value_ax.plot(r.time, value, linewidth=1.0, **_layer(i, flights))
            error_ax.plot(r.time, error, linewidth=1.0, **_layer(i, flights))
        value_ax.set_ylabel(name)
        error_ax.set_ylabel('error ' + name)
        error_ax.axhline(0.0, color='grey', linewidth=0.5)
    axes[0][0].set_title('Tracking (Fig. 8)')
    axes[0][1].set_title('Tracking error')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    _legend(axes[0][0], flights)
    _legend(axes[0][1], flights)
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
            axes[k][1].set_ylabel(f'{ROTOR_NAMES[k]} [N]')
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


def plot_surfaces(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True)
    for k, name in enumerate(SUBSYSTEM_NAMES):
        ax = axes[k // 2][k % 2]
        for i, flight in enumerate(flights):
            ax.plot(flight.record.time, flight.record.surfaces[:, k], linewidth=0.8, **_layer(i, flights))
        ax.axhline(0.0, color='grey', linewidth=0.5)
        ax.set_ylabel(f'S_{name}')
    axes[0][0].set_title('Sliding surfaces S = de/dt + lambda e')
    for ax in axes[-1]:
        ax.set_xlabel('t [s]')
    _legend(axes[0][0], flights)
    return _save(fig, path)


def plot_fuzzy_share(plt, flights: Sequence[BagFlight], path: Path) -> Path:
    fig, axes = plt.subplots(3, 2, figsize=(12, 8), sharex=True, sharey=True)
    for i, flight in enumerate(flights):
        shares = fuzzy_share(flight.record, SHARE_WINDOW)
        start = flight.record.time[0]
        for k, name in enumerate(SUBSYSTEM_NAMES):
            values = shares[name]
            centres = start + SHARE_WINDOW * (np.arange(len(values)) + 0.5)
            axes[k // 2][k % 2].plot(centres, values, linewidth=1.0, **_layer(i, flights))
    for k, name in enumerate(SUBSYSTEM_NAMES):
        axes[k // 2][k % 2].set_ylabel(f'corrective share {name}')
    axes[0][0].set_ylim(-0.02, 1.02)
    fig.suptitle('Share of the corrective term (NNIT2FSMC: fuzzy vs NN): |corrective| / (|equivalent| + '
                 f'|corrective|), {SHARE_WINDOW:g} s windows')
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
        return [plot_path_3d(plt, flights, out_dir / 'path_3d.png'),
                plot_tracking(plt, flights, out_dir / 'tracking.png'),
                plot_controls(plt, flights, out_dir / 'controls.png'),
                plot_controls(plt, flights, out_dir / 'controls_zoom.png', span=zoom),
                plot_surfaces(plt, flights, out_dir / 'surfaces.png'),
                plot_fuzzy_share(plt, flights, out_dir / 'fuzzy_share.png')]
    finally:
        plt.close('all')
