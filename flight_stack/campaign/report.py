"""``report.html`` of a campaign: the per-controller table and the plots a reviewer expects.

Plots (PNG files in ``DIR/plots/``, shown in the page): the empirical CDF of the position RMSE
per controller, box plots of RMSE and of the force [N/s] and moment [N m/s] chattering, and the
failure rate against each sampled parameter (flights binned by quantiles of the parameter; one
panel per parameter, titled with its name and unit). Without matplotlib the page has the table
only and says how to get the plots.
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from .sampling import SAMPLED_COLUMNS

REPORT_FILE = 'report.html'
FAILURE_BINS = 5
#: what each sampled column of flights.csv is, with its unit (rotor columns: see parameter_title)
PARAMETER_TITLES = {
    'mass_kg': 'mass [kg]', 'Ix_kgm2': 'inertia Ix [kg m^2]', 'Iy_kgm2': 'inertia Iy [kg m^2]',
    'Iz_kgm2': 'inertia Iz [kg m^2]', 'Kfx': 'drag Kfx [N s/m]', 'Kfy': 'drag Kfy [N s/m]', 'Kfz': 'drag Kfz [N s/m]',
    'Kfphi': 'rotational drag Kfphi [N m s^2]', 'Kftheta': 'rotational drag Kftheta [N m s^2]',
    'Kfpsi': 'rotational drag Kfpsi [N m s^2]', 'cog_x_m': 'centre of gravity offset x [m]',
    'cog_y_m': 'centre of gravity offset y [m]', 'wind_direction_rad': 'mean wind direction [rad]'}
_ROTOR_TITLES = {'Kp': 'rotor {i} thrust factor Kp [N s^2]', 'Kd': 'rotor {i} drag factor Kd [N m s^2]',
                 'efficiency_loss': 'rotor {i} efficiency loss [fraction]'}


def parameter_title(column: str) -> str:
    """A panel title for a sampled column of flights.csv: what it is and its unit ('Kp2_Nss' -> 'rotor 2
    thrust factor Kp [N s^2]'); the column itself if unknown."""
    if column in PARAMETER_TITLES:
        return PARAMETER_TITLES[column]
    for prefix, title in _ROTOR_TITLES.items():
        rest = column[len(prefix):]
        if column.startswith(prefix) and rest[:1].isdigit():
            return title.format(i=rest[0])
    return column


def _fmt(value, scale: float = 1.0, digits: int = 3) -> str:
    return '-' if value is None else f'{value * scale:.{digits}g}'


def _table(summary: dict) -> str:
    head = ('controller', 'flights', 'finished [%]', '95 % interval [%]', 'failures',
            'RMSE p50 / p95 / p99 / max [cm]', 'max error p95 [cm]', 'chattering U1 p50 / p95 [N/s]',
            'chattering moments p50 / p95 [N m/s]')
    lines = ['<table><tr>' + ''.join(f'<th>{h}</th>' for h in head) + '</tr>']
    for name, entry in summary['controllers'].items():
        rmse, force, moment = (entry['rmse_position_m'], entry['chattering_force_n_per_s'],
                               entry['chattering_moment_nm_per_s'])
        low, high = entry['success_rate_wilson95']
        failures = ', '.join(f'{reason}: {count}' for reason, count in entry['failures'].items()) or 'none'
        cells = (name, entry['flights'], _fmt(entry['success_rate'], 100, 4), f'{low * 100:.2f} - {high * 100:.2f}',
                 failures, ' / '.join(_fmt(rmse[k], 100) for k in ('p50', 'p95', 'p99', 'max')),
                 _fmt(entry['max_position_error_m']['p95'], 100),
                 ' / '.join(_fmt(force[k]) for k in ('p50', 'p95')),
                 ' / '.join(_fmt(moment[k]) for k in ('p50', 'p95')))
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
        else:
            axes.plot([], [], label=f'{c}: no finished flight')
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

    figure, panels = plt.subplots(1, 3, figsize=(14, 4.5))
    for axes, key, title, label in zip(
            panels, ('rmse_position_m', 'chattering_force_n_per_s', 'chattering_moment_nm_per_s'),
            ('position RMSE', 'chattering, force: TV(U1) per s', 'chattering, moments: TV(d U2, d U3, U4) per s'),
            ('position RMSE [cm]', 'force chattering [N/s]', 'moment chattering [N m/s]')):
        axes.set_title(title, fontsize=10)
        data = [[r[key] * (100 if key == 'rmse_position_m' else 1) for r in finished[c]] or [np.nan]
                for c in controllers]
        axes.boxplot(data, whis=(1, 99), showfliers=True)
        axes.set_xticks(range(1, len(controllers) + 1), controllers, rotation=20)
        for position, c in enumerate(controllers, 1):
            if not finished[c]:
                axes.text(position, 0.5, 'no finished\nflight', transform=axes.get_xaxis_transform(),
                          ha='center', va='center', color='tab:red', fontsize=9)
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
    made.append(('boxplots.png', 'Box plots of RMSE and of the force and moment chattering per controller '
                                 '(finished flights).'))

    varying = [name for name in SAMPLED_COLUMNS if np.ptp([r[name] for r in rows]) > 0.0]
    if varying:
        plot_failure_vs_parameters(plt, rows, controllers, varying, plot_dir / 'failure_vs_parameters.png')
        made.append(('failure_vs_parameters.png', f'Failure rate against each sampled parameter '
                     f'(flights binned by {FAILURE_BINS} quantiles of the parameter; points at bin centres).'))
    return made


def plot_failure_vs_parameters(plt, rows: list[dict], controllers: list[str], varying: list[str],
                               path: Path) -> Path:
    """One panel per sampled parameter in ``varying``: the failure rate [%] of each controller against the
    parameter, flights binned by FAILURE_BINS quantiles of it (points at the bin centres). A controller
    none of whose flights finished says so in the legend (every rate 100 %) rather than left unexplained."""
    columns = 3
    lines = -(-len(varying) // columns)
    figure, grid = plt.subplots(lines, columns, figsize=(4.6 * columns, 3.2 * lines), squeeze=False)
    for axes, name in zip(grid.flat, varying):
        values = np.array([r[name] for r in rows])
        edges = np.unique(np.quantile(values, np.linspace(0.0, 1.0, FAILURE_BINS + 1)))
        centres = 0.5 * (edges[:-1] + edges[1:])
        for k, c in enumerate(controllers):
            mine = [r for r in rows if r['controller'] == c]
            x = np.array([r[name] for r in mine])
            failed = np.array([not r['finished'] for r in mine])
            index = np.clip(np.searchsorted(edges, x, side='right') - 1, 0, len(edges) - 2)
            rate = [failed[index == b].mean() * 100 if (index == b).any() else np.nan for b in range(len(edges) - 1)]
            axes.plot(centres, rate, marker='o', color=f'C{k}',
                      label=c if any(r['finished'] for r in mine) else f'{c}: no finished flight (100 % failed)')
        axes.set_title(parameter_title(name), fontsize=9)
        axes.set_ylabel('failed [%]', fontsize=8)
        axes.set_ylim(-5.0, 105.0)
        axes.locator_params(axis='x', nbins=4)
        axes.ticklabel_format(axis='x', style='sci', scilimits=(-3, 4), useOffset=False)
        axes.tick_params(labelsize=7)
        axes.grid(True, alpha=0.3)
    for axes in list(grid.flat)[len(varying):]:
        axes.axis('off')
    handles, labels = grid.flat[0].get_legend_handles_labels()
    figure.legend(handles, labels, loc='upper center', ncol=min(len(labels), 3), fontsize=9)
    figure.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.5 / figure.get_figheight()))
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


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
