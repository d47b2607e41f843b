"""The review's metrics table (text for the terminal) and one-page report (``report.md``, ``report.html``).

One column per flight, so a comparison (e.g. NNIT2FSMC against sign SMC) reads across a row. The
report also says what was flown (controller, scenario, vehicle, disturbances, seeds: from the bag's
custom data), whether and when the flight failed, and what each metric means.
"""
from __future__ import annotations

import html
from pathlib import Path
from typing import Sequence

from quad_msgs_bridge.conversions import SUBSYSTEM_NAMES
from quad_msgs_bridge.mixer import CONTROL_NAMES, CONTROL_UNITS
from quad_msgs_bridge.review.summary import recorded_vehicle

NOT_RECORDED = 'not recorded'
#: (custom data key, what it says) of the flight description
FLIGHT_FACTS = (('controller', 'controller'), ('scenario', 'scenario'),
                ('disturbances', 'disturbances (paper section IV)'), ('backend', 'backend'), ('seed', 'NN seed'))
#: (custom data key, what it says) shown only when the bag has them (a campaign flight's replay)
CAMPAIGN_FACTS = (('campaign_seed', 'campaign seed'), ('flight', 'campaign flight'))
#: (metric, what it means), in the order of the table
METRIC_MEANINGS = (
    ('result', 'OK when the flight flew its whole planned duration within its checks; else FAILED and why: it '
               'ended early (a failure rule stopped it, it was interrupted, or its bag was cut short: where), a '
               'state or force went non-finite, or its max position error exceeds the run\'s --max-error. The '
               'metrics of a flight that ended early cover the time it flew, and are NaN if it ended before '
               'settling'),
    ('settle time', 'the first seconds of the flight (take-off and convergence), left out of every metric below '
                    'unless said otherwise'),
    ('position RMSE', 'root mean square of the distance between the vehicle and the reference position'),
    ('max position error', 'largest distance between the vehicle and the reference position; the run fails '
                           '(flight_ok false) when it exceeds --max-error'),
    ('yaw RMSE', 'root mean square of the yaw error, wrapped to [-pi, pi)'),
    ('chattering', 'total variation of a control signal per second: sum of |U(k+1) - U(k)| over the steps, '
                   'divided by the time span; high values mean chattering (the paper\'s Fig. 9). The force '
                   'channel (thrust U1 [N/s]) and the moment channels (roll torque d U2, pitch torque d U3 and yaw '
                   'torque U4, d the arm length, summed [N m/s]) are given apart, then each U1..U4 in its own unit'),
    ('rotor saturation', 'share of control steps with a rotor thrust at its limit F_min or F_max (and the same '
                         'over the whole flight, take-off included)'),
    ('fuzzy share', 'per subsystem, mean |fuzzy term| / mean(|NN term| + |fuzzy term|) in consecutive windows of '
                    'the flight: the first window, then after settling the lowest and the highest window, the '
                    'largest rise (from a window to a later, higher one) and the last window, each with its time '
                    'span (every window: the table below); it falls as the network learns the equivalent control, '
                    'and a rise after settling shows; n/a for controllers without a fuzzy term (sliding mode '
                    'baselines, PID)'),
)


def describe_share(extremes: dict | None, shares: list[float]) -> str:
    """'0.91; min 0.04 at 50-55 s, max 0.76 at 5-10 s, rises 0.05 (20-25 s) -> 0.67 (35-40 s), last 0.19 at
    55-60 s': one subsystem's :func:`~quad_msgs_bridge.review.metrics.share_extremes` (times from the
    flight's first step); for a flight too short for a window after settling, the first of its ``shares``."""
    if extremes is None:
        return f'{shares[0]:.2f}; no window starts after settling' if shares else '-'
    def span(window: dict) -> str:
        return f'{window["from_s"]:g}-{window["to_s"]:.4g} s'

    def at(name: str) -> str:
        return f'{name} {extremes[name]["value"]:.2f} at {span(extremes[name])}'
    rise = extremes['rise']
    shown_rise = rise is not None and round(rise['to']['value'], 2) > round(rise['from']['value'], 2)
    rises = ('no rise' if not shown_rise else f'rises {rise["from"]["value"]:.2f} ({span(rise["from"])}) -> '
             f'{rise["to"]["value"]:.2f} ({span(rise["to"])})')
    return f'{extremes["first"]:.2f}; {at("min")}, {at("max")}, {rises}, {at("last")}'


def _share(metrics: dict, axis: str) -> str:
    if metrics['fuzzy_share'] is None:
        return 'n/a'
    return describe_share(metrics['fuzzy_share_settled'][axis], metrics['fuzzy_share'][axis])


def describe_result(metrics: dict) -> str:
    """'OK: flew its whole duration (60 s)', or 'FAILED: the flight ended early: flipped over at 1.472 s'
    (metrics with the flight's verdict, see quad_msgs_bridge.review.command.with_failure)."""
    if metrics['failures']:
        return 'FAILED: ' + '; '.join(metrics['failures'])
    if metrics.get('planned_duration_s') is None:
        return 'no failure recorded (the bag does not record the planned duration)'
    return f'OK: flew its whole duration ({metrics["planned_duration_s"]:g} s)'


def _moment(metrics: dict) -> str:
    moment = metrics['chattering_moment_nm_per_s']
    return 'n/a' if moment is None else f'{moment:.4g}'


def metric_rows(metrics: Sequence[dict]) -> list[tuple[str, list[str]]]:
    """(name, one formatted value per flight) for the table; ``metrics`` from ``flight_metrics``."""
    def row(name: str, value) -> tuple[str, list[str]]:
        return name, [value(m) for m in metrics]

    rows = [
        row('result', describe_result),
        row('sim time [s]', lambda m: f'{m["duration_s"]:.2f}'),
        row('control steps', lambda m: f'{m["control_steps"]}'),
        row('settle time [s]', lambda m: f'{m["settle_time_s"]:.1f}'),
        row('position RMSE [cm]', lambda m: f'{m["rmse_position_m"] * 100:.3f}'),
        row('max position error [cm]', lambda m: f'{m["max_position_error_m"] * 100:.3f}'),
        row('yaw RMSE [rad]', lambda m: f'{m["rmse_yaw_rad"]:.5f}'),
    ]
    rows.append(row('chattering, force: U1 [N/s]', lambda m: f'{m["chattering_force_n_per_s"]:.4g}'))
    rows.append(row('chattering, moments: d U2 + d U3 + U4 [N m/s]', _moment))
    for name, unit in zip(CONTROL_NAMES, CONTROL_UNITS):
        rows.append(row(f'  chattering {name} [{unit}/s]', lambda m, n=name: f'{m["chattering"][n]:.4g}'))
    rows.append(row('rotor saturation [% of steps]', lambda m: f'{m["saturation_fraction"] * 100:.2f}'))
    rows.append(row('  over the whole flight [%]', lambda m: f'{m["saturation_fraction_whole_flight"] * 100:.2f}'))
    window = metrics[0]['fuzzy_share_window_s']
    for axis in SUBSYSTEM_NAMES:
        rows.append(row(f'fuzzy share {axis} ({window:g} s windows)', lambda m, a=axis: _share(m, a)))
    return rows


def share_windows(flight_label: str, metrics: dict) -> tuple[list[str], list[list[str]]] | None:
    """(header, rows) of one flight's fuzzy share in every window: one row per window [s], one column per
    subsystem; None without a fuzzy term."""
    shares, window = metrics['fuzzy_share'], metrics['fuzzy_share_window_s']
    if shares is None:
        return None
    count = max(len(values) for values in shares.values())
    header = [f'{flight_label}: window [s]', *SUBSYSTEM_NAMES]
    rows = [[f'{k * window:g} - {min((k + 1) * window, metrics["duration_s"]):.4g}'
             + (' (settling)' if k * window < metrics['settle_time_s'] - 1e-9 else '')]
            + [f'{shares[axis][k]:.3f}' if k < len(shares[axis]) else '-' for axis in SUBSYSTEM_NAMES]
            for k in range(count)]
    return header, rows


def text_table(labels: Sequence[str], metrics: Sequence[dict]) -> str:
    """The metrics as an aligned plain-text table."""
    rows = [('', list(labels))] + metric_rows(metrics)
    name_width = max(len(name) for name, _ in rows)
    widths = [max(len(values[k]) for _, values in rows) for k in range(len(labels))]
    return '\n'.join(f'{name:<{name_width}}  ' + '  '.join(f'{v:>{w}}' for v, w in zip(values, widths))
                     for name, values in rows)


def flight_facts(flight, metrics: dict) -> list[tuple[str, str]]:
    """(what, value) describing a reviewed flight (a :class:`~quad_msgs_bridge.review.flight_from_bag.BagFlight`)
    with its ``metrics`` and verdict: what was flown (the bag's custom data; the vehicle by name,
    :func:`~quad_msgs_bridge.review.summary.recorded_vehicle`), whether and why it failed, and its bag."""
    custom = flight.custom_data
    return ([(name, str(custom.get(key) or NOT_RECORDED)) for key, name in FLIGHT_FACTS[:2]]
            + [('vehicle', recorded_vehicle(flight))]
            + [(name, str(custom.get(key) or NOT_RECORDED)) for key, name in FLIGHT_FACTS[2:]]
            + [(name, str(custom[key])) for key, name in CAMPAIGN_FACTS if key in custom]
            + [('result', describe_result(metrics))]
            + [('bag', str(flight.path))])


def _relative(path: Path, start: Path) -> str:
    return path.resolve().relative_to(start.resolve()).as_posix()


def write_markdown(path: Path, flights: Sequence, metrics: Sequence[dict], plots: Sequence[Path],
                   notes: Sequence[str]) -> Path:
    labels = [flight.label for flight in flights]
    lines = ['# Flight review', '']
    for flight, m in zip(flights, metrics):
        lines += [f'- **{flight.label}**: ' + '; '.join(f'{name}: {value}' for name, value in flight_facts(flight, m))]
    lines += ['', '## Metrics', '', '| metric | ' + ' | '.join(labels) + ' |',
              '|---|' + '---:|' * len(labels)]
    lines += [f'| {name} | ' + ' | '.join(values) + ' |' for name, values in metric_rows(metrics)]
    lines += ['', '### What the metrics mean', ''] + [f'- **{name}**: {meaning}' for name, meaning in METRIC_MEANINGS]
    tables = [table for flight, m in zip(flights, metrics) if (table := share_windows(flight.label, m))]
    if tables:
        lines += ['', '## Fuzzy share per window', '']
        for header, rows in tables:
            lines += ['| ' + ' | '.join(header) + ' |', '|---|' + '---:|' * (len(header) - 1)]
            lines += ['| ' + ' | '.join(row) + ' |' for row in rows] + ['']
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
                        + '; '.join(f'{esc(name)}: {esc(value)}' for name, value in flight_facts(flight, m))
                        + '</li>' for flight, m in zip(flights, metrics))
    meanings = ''.join(f'<li><b>{esc(name)}</b>: {esc(meaning)}</li>' for name, meaning in METRIC_MEANINGS)
    parts = ['<!DOCTYPE html><html><head><meta charset="utf-8"><title>Flight review</title><style>',
             'body{font-family:sans-serif;max-width:1200px;margin:auto}table{border-collapse:collapse}',
             'td,th{border:1px solid #ccc;padding:2px 8px}td+td{text-align:right}img{max-width:100%}',
             f'</style></head><body><h1>Flight review</h1><ul>{described}</ul>',
             f'<h2>Metrics</h2><table><tr><th>metric</th>{head}</tr>{body}</table>',
             f'<h3>What the metrics mean</h3><ul>{meanings}</ul>']
    tables = [table for flight, m in zip(flights, metrics) if (table := share_windows(flight.label, m))]
    if tables:
        parts.append('<h2>Fuzzy share per window</h2>')
        for header, rows in tables:
            parts.append('<table><tr>' + ''.join(f'<th>{esc(h)}</th>' for h in header) + '</tr>'
                         + ''.join('<tr>' + ''.join(f'<td>{esc(c)}</td>' for c in row) + '</tr>' for row in rows)
                         + '</table>')
    if notes:
        parts.append('<h2>Notes</h2><ul>' + ''.join(f'<li>{esc(n)}</li>' for n in notes) + '</ul>')
    if plots:
        parts.append('<h2>Plots</h2>' + ''.join(
            f'<p><img src="{esc(_relative(p, path.parent))}" alt="{esc(p.stem)}"></p>' for p in plots))
    path.write_text(''.join(parts) + '</body></html>\n')
    return path
