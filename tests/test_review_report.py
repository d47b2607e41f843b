"""What the review and campaign reports show, on synthetic flights (nothing flown): the settled zoom of the
sliding surfaces, a failed flight's reason and time, the fuzzy share's rise back, the chattering split into
force and moment channels, and the campaign's failure plot with a controller that never finished."""
import json
import math
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use('Agg')
import matplotlib.figure  # noqa: E402

from flight_stack.campaign.batch import COLUMNS  # noqa: E402
from flight_stack.campaign.report import parameter_title, write_report  # noqa: E402
from flight_stack.campaign.results import summarize  # noqa: E402
from flight_stack.campaign.sampling import SAMPLED_COLUMNS  # noqa: E402
from flight_stack.summary import build_summary, format_summary  # noqa: E402
from quad_msgs_bridge.review import plots  # noqa: E402
from quad_msgs_bridge.review.command import review_flights  # noqa: E402
from quad_msgs_bridge.review.flight_from_bag import BagFlight  # noqa: E402
from quad_msgs_bridge.review.metrics import FlightRecord  # noqa: E402
from quad_msgs_bridge.review.report import text_table  # noqa: E402
from quad_msgs_bridge.vehicle_params import load_vehicle_file  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PARAMS, DISTURBANCES = load_vehicle_file()
SPIKE = 33.0          # [rad/s] the take-off spike of S_phi
SETTLED_PEAK = 0.02   # [rad/s] S after settling


def synthetic_record(duration: float, dt: float = 0.01) -> FlightRecord:
    """A hover record of ``duration`` [s]: S_phi spikes to SPIKE at 1 s, then every S is a slow wave of
    SETTLED_PEAK; the fuzzy term of phi falls, then climbs back at 35-40 s."""
    time = np.arange(0.0, duration + dt / 2, dt)
    n = len(time)
    surfaces = np.tile((SETTLED_PEAK * np.sin(time / 3.0))[:, None], (1, 6))
    surfaces[np.abs(time - 1.0) < dt / 2, 3] = SPIKE
    equivalent = np.ones((n, 6))
    corrective = np.full((n, 6), 0.05)
    corrective[time < 5.0] = 3.0
    corrective[(time >= 35.0) & (time < 40.0), 3] = 2.0     # phi: share 2 / 3 at 35-40 s
    hover = np.tile([0.0, 0.0, 1.0], (n, 1))
    forces = np.full((n, 4), 0.3 * 9.81 / 4)
    controls = np.column_stack([forces.sum(axis=1), np.zeros(n), np.zeros(n), np.zeros(n)])
    return FlightRecord(time, hover, np.zeros(n), hover.copy(), np.zeros(n), forces, controls, surfaces,
                        equivalent, corrective)


def flight(duration: float, **custom) -> BagFlight:
    data = {'controller': 'nnit2fsmc', 'scenario': 'hover', 'disturbances': 'enabled', 'backend': 'embedded',
            'seed': '7', **custom}
    return BagFlight(Path('/nowhere/bag'), 'nnit2fsmc', synthetic_record(duration), PARAMS, 5.0, data,
                     ended_early='failure' in custom)


def test_the_surfaces_plot_has_a_settled_panel_scaled_to_the_settled_window(tmp_path, monkeypatch):
    limits = {}
    real_save = plots._save

    def capture(fig, path):
        limits[path.name] = [ax.get_ylim() for ax in fig.axes]
        return real_save(fig, path)
    monkeypatch.setattr(plots, '_save', capture)
    plots.plot_surfaces(plots._pyplot(), [flight(20.0)], tmp_path / 'surfaces.png')
    panels = limits['surfaces.png']
    assert len(panels) == 12                             # per subsystem: whole flight, after settling
    whole_phi, settled_phi = panels[6], panels[7]
    assert whole_phi[1] >= SPIKE                         # the whole flight holds the spike
    low, high = settled_phi                              # the settled panel is scaled to the settled values
    settled = SETTLED_PEAK * np.sin(np.arange(5.0, 20.0, 0.01) / 3.0)
    assert settled.min() - 0.1 * np.ptp(settled) <= low <= settled.min()
    assert settled.max() <= high <= settled.max() + 0.1 * np.ptp(settled)
    assert (tmp_path / 'surfaces.png').stat().st_size > 0


def test_a_failed_flights_report_says_why_and_when_and_what_was_flown(tmp_path):
    failed = flight(1.472, failure='flipped over', failure_time_s='1.472')
    review = review_flights([failed], tmp_path, plots=False)
    report = (tmp_path / 'report.md').read_text()
    assert 'result: FAILED: the flight ended early: flipped over at 1.472 s' in report
    assert '| result | FAILED: the flight ended early: flipped over at 1.472 s |' in report
    assert ('nnit2fsmc FAILED: the flight ended early: flipped over at 1.472 s; its metrics: NaN: it failed before '
            'the settling window ended') in report
    assert 'disturbances (paper section IV): enabled' in report and 'NN seed: 7' in report
    assert 'not recorded' not in report
    assert 'FAILED: the flight ended early: flipped over at 1.472 s' in (tmp_path / 'report.html').read_text()
    [saved] = json.loads((tmp_path / 'review.json').read_text())
    assert saved['failure'] == 'flipped over' and saved['failure_time_s'] == 1.472
    assert math.isnan(review.metrics[0]['rmse_position_m'])
    assert 'FAILED: the flight ended early: flipped over at 1.472 s' in text_table(['nnit2fsmc'], review.metrics)


def test_a_finished_flights_report_gives_the_fuzzy_share_rise_and_every_window(tmp_path):
    review_flights([flight(60.0, duration_s='60.0')], tmp_path, plots=False)
    report = (tmp_path / 'report.md').read_text()
    [phi] = [line for line in report.splitlines() if line.startswith('| fuzzy share phi')]
    assert 'rises 0.05 (5-10 s) -> 0.67 (35-40 s)' in phi and 'last 0.05 at 55-60 s' in phi
    assert '| result | OK: flew its whole duration (60 s) |' in report
    assert '## Fuzzy share per window' in report
    assert '| 35 - 40 | 0.048 | 0.048 | 0.048 | 0.667 | 0.048 | 0.048 |' in report
    assert '| 0 - 5 (settling) |' in report


def test_the_report_gives_force_and_moment_chattering_apart(tmp_path):
    record = synthetic_record(10.0)
    record.controls[:, 0] += 0.1 * (np.arange(len(record.time)) % 2)           # U1 flips by 0.1 N every step
    record.controls[:, 3] += 0.01 * (np.arange(len(record.time)) % 2)          # U4 by 0.01 N m
    subject = BagFlight(Path('/nowhere/bag'), 'x', record, PARAMS, 5.0, {'controller': 'smc-sign'})
    review = review_flights([subject], tmp_path, plots=False)
    assert review.metrics[0]['chattering_force_n_per_s'] == pytest.approx(10.0, rel=1e-6)        # 0.1 N / 0.01 s
    assert review.metrics[0]['chattering_moment_nm_per_s'] == pytest.approx(1.0, rel=1e-6)       # 0.01 N m / 0.01 s
    report = (tmp_path / 'report.md').read_text()
    assert '| chattering, force: U1 [N/s] | 10 |' in report
    assert '| chattering, moments: d U2 + d U3 + U4 [N m/s] | 1 |' in report


def test_the_summary_says_why_and_when_the_flight_failed_and_splits_the_chattering():
    summary = build_summary(synthetic_record(60.0), backend='embedded', controller='nnit2fsmc', scenario='hover',
                            seed=7, settle_time=5.0, params=PARAMS, disturbances=DISTURBANCES, gains={},
                            physics_rate=1000.0, wall_time_s=1.0, max_error=1.0, failure='flipped over',
                            failure_time_s=1.472)
    assert summary['failure'] == 'flipped over' and summary['failure_time_s'] == 1.472
    assert summary['failures'] == ['the flight ended early: flipped over at 1.472 s']
    assert summary['chattering_moment_nm_per_s'] == 0.0 and summary['chattering_force_n_per_s'] == 0.0
    text = format_summary(summary)
    assert 'force (U1) 0 N/s, moments (d U2, d U3, U4) 0 N m/s' in text
    assert 'phi    0.75; min 0.05 at' in text and 'rises 0.05 (5-10 s) -> 0.67 (35-40 s)' in text
    assert 'FAILED: the flight ended early: flipped over at 1.472 s' in text


def campaign_rows() -> list[dict]:
    """Rows of flights.csv: nnit2fsmc finishes 90 % of its flights, smc-sign none."""
    rng = np.random.default_rng(0)
    rows = []
    for controller in ('nnit2fsmc', 'smc-sign'):
        for k in range(100):
            row = {name: float(rng.uniform(0.9, 1.1)) for name in COLUMNS}
            row.update(Ix_kgm2=float(rng.uniform(0.9e-3, 1.1e-3)), Kp1_Nss=float(rng.uniform(1.1e-5, 1.3e-5)),
                       flight=k, controller=controller, control_steps=100,
                       finished=bool(controller == 'nnit2fsmc' and rng.random() < 0.9))
            row['failure'] = '' if row['finished'] else 'flipped over'
            rows.append(row)
    return rows


@pytest.mark.slow
def test_the_campaign_plots_explain_a_controller_without_finished_flight_and_title_parameters(tmp_path,
                                                                                              monkeypatch):
    figures = {}
    real_savefig = matplotlib.figure.Figure.savefig

    def capture(fig, path, *args, **kwargs):
        fig.canvas.draw()
        figures[Path(path).name] = fig
        return real_savefig(fig, path, *args, **kwargs)
    monkeypatch.setattr(matplotlib.figure.Figure, 'savefig', capture)
    rows = campaign_rows()
    summary = {'controllers': summarize(rows, ['nnit2fsmc', 'smc-sign']),
               'spec': {'scenario': 'hover', 'duration': 10.0, 'settle_time': 5.0, 'flights': 100, 'seed': 1,
                        'max_error_m': 1.0, 'controllers': ['nnit2fsmc', 'smc-sign']}}
    page = write_report(rows, summary, tmp_path).read_text()
    assert 'chattering U1 p50 / p95 [N/s]' in page and 'chattering moments p50 / p95 [N m/s]' in page

    failure = figures['failure_vs_parameters.png']
    legend = [text.get_text() for legend in failure.legends for text in legend.get_texts()]
    assert legend == ['nnit2fsmc', 'smc-sign: no finished flight (100 % failed)']
    titles = [ax.get_title() for ax in failure.axes if ax.get_visible() and ax.axison]
    assert titles == [parameter_title(name) for name in SAMPLED_COLUMNS]
    assert 'mass [kg]' in titles and 'rotor 1 thrust factor Kp [N s^2]' in titles and 'Kp1_Nss' not in titles
    for ax in failure.axes:              # no two x tick labels of a panel overlap
        boxes = [label.get_window_extent() for label in ax.get_xticklabels()
                 if label.get_visible() and label.get_text()]
        assert all(a.x1 < b.x0 for a, b in zip(boxes, boxes[1:])), ax.get_title()

    boxes = [text.get_text() for ax in figures['boxplots.png'].axes for text in ax.texts]
    assert boxes == ['no finished\nflight'] * 3
    labels = [ax.get_ylabel() for ax in figures['boxplots.png'].axes]
    assert any('[N/s]' in label for label in labels) and any('[N m/s]' in label for label in labels)


def test_the_readme_compares_controllers_under_the_same_disturbances():
    for text in ((ROOT / 'README.md').read_text(), (ROOT / 'docs' / 'BAGS.md').read_text()):
        for line in text.splitlines():
            if '--out out/sign' in line:
                assert '--no-disturbances' not in line, line
