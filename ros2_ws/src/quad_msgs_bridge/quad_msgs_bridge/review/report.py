"""The review's metrics table (text for the terminal) and one-page report (``report.md``, ``report.html``).

One column per flight, so a comparison (e.g. NNIT2FSMC against sign SMC) reads across a row. The
report also says what was flown (controller, scenario, disturbances: from the bag's custom data) and
what each metric means.
"""
from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

from quad_msgs_bridge.conversions import SUBSYSTEM_NAMES
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS

NOT_RECORDED = 'not recorded'
#: (custom data key, what it says) of the flight description
FLIGHT_FACTS = (('controller', 'controller'), ('scenario', 'scenario'),
                ('disturbances', 'disturbances (paper section IV)'), ('backend', 'backend'), ('seed', 'NN seed'))
#: (metric, what it means), in the order of the table
METRIC_MEANINGS = (
    ('settle time', 'the first seconds of the flight (take-off and convergence), left out of every metric below '
                    'unless said otherwise'),
    ('position RMSE', 'root mean square of the distance between the vehicle and the reference position'),
    ('max position error', 'largest distance between the vehicle and the reference position; the run fails '
                           '(flight_ok false) when it exceeds --max-error'),
    ('yaw RMSE', 'root mean square of the yaw error, wrapped to [-pi, pi)'),
    ('chattering U1..U4', 'total variation of each control signal per second: sum of |U(k+1) - U(k)| over the '
                          'steps, divided by the time span; high values mean chattering (the paper\'s Fig. 9)'),
    ('rotor saturation', 'share of control steps with a rotor thrust at its limit F_min or F_max (and the same '
                         'over the whole flight, take-off included)'),
    ('fuzzy share', 'per subsystem, mean |fuzzy term| / mean(|NN term| + |fuzzy term|) over the whole flight in '
                    'windows (first and last window shown): it falls as the network learns the equivalent control; '
                    'n/a for controllers without a fuzzy term (sliding mode baselines, PID)'),
)


def _share(metrics: dict, axis: str) -> str:
    shares = metrics['fuzzy_share']
    if shares is None:
        return 'n/a'
    return f'{shares[axis][0]:.2f} -> {shares[axis][-1]:.2f}' if shares[axis] else '-'


def metric_rows(metrics: Sequence[dict]) -> list[tuple[str, list[str]]]:
    """(name, one formatted value per flight) for the table; ``metrics`` from ``flight_metrics``."""
    def row(name: str, value) -> tuple[str, list[str]]:
        return name, [value(m) for m in metrics]

    rows = [
        row('sim time [s]', lambda m: f'{m["duration_s"]:.2f}'),
        row('control steps', lambda m: f'{m["control_steps"]}'),
        row('settle time [s]', lambda m: f'{m["settle_time_s"]:.1f}'),
        row('position RMSE [cm]', lambda m: f'{m["rmse_position_m"] * 100:.3f}'),
        row('max position error [cm]', lambda m: f'{m["max_position_error_m"] * 100:.3f}'),
        row('yaw RMSE [rad]', lambda m: f'{m["rmse_yaw_rad"]:.5f}'),
    ]
    for name, unit in zip(CONTROL_NAMES, CONTROL_UNITS):
        rows.append(row(f'chattering {name} [{unit}/s]', lambda m, n=name: f'{m["chattering"][n]:.4g}'))
    rows.append(row('rotor saturation [% of steps]', lambda m: f'{m["saturation_fraction"] * 100:.2f}'))
    rows.append(row('  over the whole flight [%]', lambda m: f'{m["saturation_fraction_whole_flight"] * 100:.2f}'))
    window = metrics[0]['fuzzy_share_window_s']
    for axis in SUBSYSTEM_NAMES:
        rows.append(row(f'fuzzy share {axis} (first -> last {window:g} s window)', lambda m, a=axis: _share(m, a)))
    return rows


def text_table(labels: Sequence[str], metrics: Sequence[dict]) -> str:
    """The metrics as an aligned plain-text table."""
    rows = [('', list(labels))] + metric_rows(metrics)
    name_width = max(len(name) for name, _ in rows)
    widths = [max(len(values[k]) for _, values in rows) for k in range(len(labels))]
    return '\n'.join(f'{name:<{name_width}}  ' + '  '.join(f'{v:>{w}}' for v, w in zip(values, widths))
                     for name, values in rows)


def flight_facts(flight) -> list[tuple[str, str]]:
    """(what, value) describing a reviewed flight (a :class:`~quad_msgs_bridge.review.flight_from_bag.BagFlight`)."""
    custom = flight.custom_data
    return [(name, str(custom.get(key) or NOT_RECORDED)) for key, name in FLIGHT_FACTS] + [('bag', str(flight.path))]


def _relative(path: Path, start: Path) -> str:
    return path.resolve().relative_to(start.resolve()).as_posix()


def write_markdown(path: Path, flights: Sequence, metrics: Sequence[dict], plots: Sequence[Path],
                   notes: Sequence[str]) -> Path:
    labels = [flight.label for flight in flights]
    lines = ['# Flight review', '']
    for flight in flights:
        lines += [f'- **{flight.label}**: ' + '; '.join(f'{name}: {value}' for name, value in flight_facts(flight))]
    lines += ['', '## Metrics', '', '| metric | ' + ' | '.join(labels) + ' |',
              '|---|' + '---:|' * len(labels)]
    lines += [f'| {name} | ' + ' | '.join(values) + ' |' for name, values in metric_rows(metrics)]
    lines += ['', '### What the metrics mean', ''] + [f'- **{name}**: {meaning}' for name, meaning in METRIC_MEANINGS]
    if notes:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in notes]
    if plots:
        lines += ['', '## Plots', '']
        lines += [f'![{plot.stem}]({_relative(plot, path.parent)})\n' for plot in plots]
    path.write_text('\n'.join(lines) + '\n')
    return path


def write_html(path: Path, flights: Sequence, metrics: Sequence[dict], plots: Sequence[Path],
               notes: Sequence[str]) -> Path:
    esc = html.escape
    head = ''.join(f'<th>{esc(flight.label)}</th>' for flight in flights)
    body = ''.join(f'<tr><td>{esc(name)}</td>' + ''.join(f'<td>{esc(v)}</td>' for v in values) + '</tr>'
                   for name, values in metric_rows(metrics))
    described = ''.join(f'<li><b>{esc(flight.label)}</b>: '
                        + '; '.join(f'{esc(name)}: {esc(value)}' for name, value in flight_facts(flight)) + '</li>'
                        for flight in flights)
    meanings = ''.join(f'<li><b>{esc(name)}</b>: {esc(meaning)}</li>' for name, meaning in METRIC_MEANINGS)
    parts = ['<!DOCTYPE html><html><head><meta charset="utf-8"><title>Flight review</title><style>',
             'body{font-family:sans-serif;max-width:1200px;margin:auto}table{border-collapse:collapse}',
             'td,th{border:1px solid #ccc;padding:2px 8px}td+td{text-align:right}img{max-width:100%}',
             f'</style></head><body><h1>Flight review</h1><ul>{described}</ul>',
             f'<h2>Metrics</h2><table><tr><th>metric</th>{head}</tr>{body}</table>',
             f'<h3>What the metrics mean</h3><ul>{meanings}</ul>']
    if notes:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(n)}</li>' for n in notes) + '</ul>')
    if plots:
        parts.append('<h2>Plots</h2>' + ''.join(
            f'<p><img src="{esc(_relative(p, path.parent))}" alt="{esc(p.stem)}"></p>' for p in plots))
    path.write_text(''.join(parts) + '</body></html>\n')
    return path
