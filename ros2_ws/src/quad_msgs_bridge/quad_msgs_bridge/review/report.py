"""The review's metrics table (text for the terminal) and one-page report (``report.md``, ``report.html``).

One column per flight, so a comparison (e.g. NNIT2FSMC against sign SMC) reads across a row.
"""
from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

from quad_msgs_bridge.conversions import SUBSYSTEM_NAMES
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS


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
    for axis in SUBSYSTEM_NAMES:
        rows.append(row(f'fuzzy share {axis} (first -> last window)',
                        lambda m, a=axis: (f'{m["fuzzy_share"][a][0]:.2f} -> {m["fuzzy_share"][a][-1]:.2f}'
                                           if m['fuzzy_share'][a] else '-')))
    return rows


def text_table(labels: Sequence[str], metrics: Sequence[dict]) -> str:
    """The metrics as an aligned plain-text table."""
    rows = [('', list(labels))] + metric_rows(metrics)
    name_width = max(len(name) for name, _ in rows)
    widths = [max(len(values[k]) for _, values in rows) for k in range(len(labels))]
    return '\n'.join(f'{name:<{name_width}}  ' + '  '.join(f'{v:>{w}}' for v, w in zip(values, widths))
                     for name, values in rows)


def _relative(path: Path, start: Path) -> str:
    return path.resolve().relative_to(start.resolve()).as_posix()


def write_markdown(path: Path, bags: Sequence[tuple[str, Path]], metrics: Sequence[dict],
                   plots: Sequence[Path], notes: Sequence[str]) -> Path:
    labels = [label for label, _ in bags]
    lines = ['# Flight review', '']
    lines += [f'- **{label}**: `{bag}`' for label, bag in bags]
    lines += ['', '## Metrics', '', '| metric | ' + ' | '.join(labels) + ' |',
              '|---|' + '---:|' * len(labels)]
    lines += [f'| {name} | ' + ' | '.join(values) + ' |' for name, values in metric_rows(metrics)]
    if notes:
        lines += ['', '## Notes', ''] + [f'- {note}' for note in notes]
    if plots:
        lines += ['', '## Plots', '']
        lines += [f'![{plot.stem}]({_relative(plot, path.parent)})\n' for plot in plots]
    path.write_text('\n'.join(lines) + '\n')
    return path


def write_html(path: Path, bags: Sequence[tuple[str, Path]], metrics: Sequence[dict],
               plots: Sequence[Path], notes: Sequence[str]) -> Path:
    esc = html.escape
    head = ''.join(f'<th>{esc(label)}</th>' for label, _ in bags)
    body = ''.join(f'<tr><td>{esc(name)}</td>' + ''.join(f'<td>{esc(v)}</td>' for v in values) + '</tr>'
                   for name, values in metric_rows(metrics))
    parts = ['<!DOCTYPE html><html><head><meta charset="utf-8"><title>Flight review</title><style>',
             'body{font-family:sans-serif;max-width:1200px;margin:auto}table{border-collapse:collapse}',
             'td,th{border:1px solid #ccc;padding:2px 8px}td+td{text-align:right}img{max-width:100%}',
             '</style></head><body><h1>Flight review</h1><ul>',
             ''.join(f'<li><b>{esc(label)}</b>: <code>{esc(str(bag))}</code></li>' for label, bag in bags),
             f'</ul><h2>Metrics</h2><table><tr><th>metric</th>{head}</tr>{body}</table>']
    if notes:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(n)}</li>' for n in notes) + '</ul>')
    if plots:
        parts.append('<h2>Plots</h2>' + ''.join(
            f'<p><img src="{esc(_relative(p, path.parent))}" alt="{esc(p.stem)}"></p>' for p in plots))
    path.write_text(''.join(parts) + '</body></html>\n')
    return path
