"""``report.html`` of a campaign: the per-controller table and the plots a reviewer expects.

Plots (PNG files in ``DIR/plots/``, shown in the page): the empirical CDF of the position RMSE
per controller, box plots of RMSE and total chattering, and the failure rate against each sampled
parameter (flights binned by quantiles of the parameter). Without matplotlib the page has the
table only and says how to get the plots.
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from .sampling import SAMPLED_COLUMNS

REPORT_FILE = 'report.html'
FAILURE_BINS = 5


def _fmt(value, scale: float = 1.0, digits: int = 3) -> str:
    return '-' if value is None else f'{value * scale:.{digits}g}'


def _table(summary: dict) -> str:
    head = ('controller', 'flights', 'finished [%]', '95 % interval [%]', 'failures',
            'RMSE p50 / p95 / p99 / max [cm]', 'max error p95 [cm]', 'chattering p50 / p95 [sum of TV/s]')
    lines = ['<table><tr>' + ''.join(f'<th>{h}</th>' for h in head) + '</tr>']
    for name, entry in summary['controllers'].items():
        rmse, chatter = entry['rmse_position_m'], entry['chattering_total']
        low, high = entry['success_rate_wilson95']
        failures = ', '.join(f'{reason}: {count}' for reason, count in entry['failures'].items()) or 'none'
        cells = (name, entry['flights'], _fmt(entry['success_rate'], 100, 4), f'{low * 100:.2f} - {high * 100:.2f}',
                 failures, ' / '.join(_fmt(rmse[k], 100) for k in ('p50', 'p95', 'p99', 'max')),
                 _fmt(entry['max_position_error_m']['p95'], 100),
                 ' / '.join(_fmt(chatter[k]) for k in ('p50', 'p95')))
        lines.append('<tr>' + ''.join(f'<td>{html.escape(str(c))}</td>' for c in cells) + '</tr>')
    return '\n'.join(lines + ['</table>'])


def _plots(rows: list[dict], controllers: list[str], plot_dir: Path) -> list[tuple[str, str]]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    plot_dir.mkdir(exist_ok=True)
    made = []
    finished = {c: [r for r in rows if r['controller'] == c and r['finished']] for c in controllers}

    figure, axes = plt.subplots(figsize=(7, 4.5))
    for c in controllers:
        values = np.sort([r['rmse_position_m'] * 100 for r in finished[c]])
        if values.size:
            axes.step(values, np.arange(1, values.size + 1) / values.size, where='post', label=c)
    spread = [r['rmse_position_m'] for c in controllers for r in finished[c]]
    logarithmic = bool(spread) and min(spread) > 0.0 and max(spread) > min(spread)
    if logarithmic:
        axes.set_xscale('log')
    axes.set_xlabel('position RMSE after settling [cm]' + (' (log)' if logarithmic else ''))
    axes.set_ylabel('fraction of finished flights')
    axes.set_title('RMSE CDF per controller (finished flights)')
    axes.grid(True, which='both', alpha=0.3)
    if spread:
        axes.legend()
    else:
        axes.text(0.5, 0.5, 'no finished flight', transform=axes.transAxes, ha='center', va='center')
    figure.tight_layout()
    figure.savefig(plot_dir / 'rmse_cdf.png', dpi=110)
    plt.close(figure)
    made.append(('rmse_cdf.png', 'Empirical CDF of the position RMSE of the finished flights.'))

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4.5))
    for axes, key, label in ((left, 'rmse_position_m', 'position RMSE [cm]'),
                             (right, 'chattering_total', 'chattering: sum of TV(U1..U4) per s')):
        data = [[r[key] * (100 if key == 'rmse_position_m' else 1) for r in finished[c]] or [np.nan]
                for c in controllers]
        axes.boxplot(data, whis=(1, 99), showfliers=True)
        axes.set_xticks(range(1, len(controllers) + 1), controllers, rotation=20)
        values = np.concatenate([np.asarray(d, dtype=float) for d in data])
        values = values[np.isfinite(values)]
        logarithmic = values.size > 0 and values.min() > 0.0 and values.max() > values.min()
        if logarithmic:
            axes.set_yscale('log')
        axes.set_ylabel(label + (' (log)' if logarithmic else ''))
        axes.grid(True, axis='y', which='both', alpha=0.3)
    figure.suptitle('finished flights; whiskers at p1 and p99')
    figure.tight_layout()
    figure.savefig(plot_dir / 'boxplots.png', dpi=110)
    plt.close(figure)
    made.append(('boxplots.png', 'Box plots of RMSE and total chattering per controller (finished flights).'))

    varying = [name for name in SAMPLED_COLUMNS if np.ptp([r[name] for r in rows]) > 0.0]
    if varying:
        columns = 4
        lines = -(-len(varying) // columns)
        figure, grid = plt.subplots(lines, columns, figsize=(3.2 * columns, 2.6 * lines), squeeze=False)
        for axes, name in zip(grid.flat, varying):
            values = np.array([r[name] for r in rows])
            edges = np.unique(np.quantile(values, np.linspace(0.0, 1.0, FAILURE_BINS + 1)))
            for c in controllers:
                mine = [r for r in rows if r['controller'] == c]
                x = np.array([r[name] for r in mine])
                failed = np.array([not r['finished'] for r in mine])
                index = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, len(edges) - 2)
                centres = 0.5 * (edges[:-1] + edges[1:])
                rate = [failed[index == b].mean() * 100 if (index == b).any() else np.nan
                        for b in range(len(edges) - 1)]
                axes.plot(centres, rate, marker='o', label=c)
            axes.set_title(name, fontsize=9)
            axes.set_ylabel('failed [%]', fontsize=8)
            axes.tick_params(labelsize=7)
            axes.grid(True, alpha=0.3)
        for axes in list(grid.flat)[len(varying):]:
            axes.axis('off')
        grid.flat[0].legend(fontsize=7)
        figure.tight_layout()
        figure.savefig(plot_dir / 'failure_vs_parameters.png', dpi=100)
        plt.close(figure)
        made.append(('failure_vs_parameters.png', f'Failure rate against each sampled parameter '
                     f'(flights binned by {FAILURE_BINS} quantiles of the parameter; points at bin centres).'))
    return made


def write_report(rows: list[dict], summary: dict, out_dir: Path) -> Path:
    """Write ``out_dir/report.html`` (and its plots) for the rows of flights.csv and campaign.json's content."""
    controllers = list(summary['controllers'])
    spec = summary['spec']
    parts = [
        '<!doctype html><html><head><meta charset="utf-8"><title>Robustness campaign</title>',
        '<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse}'
        'td,th{border:1px solid #aaa;padding:3px 8px;text-align:right}</style></head><body>',
        '<h1>Robustness campaign</h1>',
        f'<p>Scenario <b>{html.escape(str(spec["scenario"]))}</b>, {spec["duration"]:g} s per flight '
        f'(metrics after {spec["settle_time"]:g} s), {spec["flights"]} flights per controller, seed {spec["seed"]}. '
        'Every controller flies the same sampled vehicles in the same air with the same sensor errors. '
        'A flight <i>finishes</i> when it flies its whole duration without a non-finite state, without '
        'flipping over, without crashing and with its position error never above '
        f'{spec["max_error_m"]:g} m after settling; the percentiles are over finished flights.</p>',
        '<h2>Perturbations</h2><pre>' + html.escape(_spec_text(spec)) + '</pre>',
        '<h2>Results per controller</h2>', _table(summary),
    ]
    try:
        plots = _plots(rows, controllers, out_dir / 'plots')
    except ImportError:
        parts.append('<p>No plots: matplotlib is not installed (pip install matplotlib).</p>')
    else:
        for name, caption in plots:
            parts.append(f'<figure><img src="plots/{name}" style="max-width:100%"><figcaption>{html.escape(caption)}'
                         '</figcaption></figure>')
    parts.append('</body></html>')
    path = out_dir / 'report.html'
    path.write_text('\n'.join(parts))
    return path


def _spec_text(spec: dict) -> str:
    import yaml
    shown = {key: value for key, value in spec.items() if key not in ('scenario', 'controllers', 'flights', 'seed')}
    return yaml.safe_dump(shown, sort_keys=False)
