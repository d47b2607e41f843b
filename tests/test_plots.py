"""The review's figures say what they show: equal 3-D scales and a visible hold point, the settling time
marked and the settled error on its own scale, units on the sliding surfaces, the fuzzy-share windows."""
import numpy as np
import pytest

from bag_support import DISTURBANCES, PARAMS
from flight_stack.embedded import fly_embedded
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.review import plots
from quad_msgs_bridge.review.flight_from_bag import BagFlight

SETTLE = 1.0   # [s]


def flight(scenario: str, controller: str = 'nnit2fsmc', duration: float = 2.0) -> BagFlight:
    record = fly_embedded(controller, make_scenario(scenario, duration), PARAMS, DISTURBANCES, load_gains(), duration,
                          1000.0).record
    return BagFlight(None, controller, record, PARAMS, SETTLE, {'controller': controller})


@pytest.fixture(scope='module')
def hover():
    return flight('hover')


@pytest.fixture
def figures(monkeypatch):
    """The figures the plot functions make, kept open instead of saved."""
    made = {}
    monkeypatch.setattr(plots, '_save', lambda fig, path: made.setdefault(path.name, fig) and path)
    yield made
    plots._pyplot().close('all')


def test_equal_limits_make_a_cube_around_the_points():
    points = np.array([[0.0, 0.0, 0.0], [0.014, -0.01, 1.0]])
    limits = np.array(plots.equal_limits(points))
    assert limits == pytest.approx(np.array([(0.007 - 0.5, 0.007 + 0.5), (-0.005 - 0.5, -0.005 + 0.5), (0.0, 1.0)]))


def test_the_3d_path_of_a_hover_has_equal_scales_and_shows_the_hold_point(hover, figures, tmp_path):
    plots.plot_path_3d(plots._pyplot(), [hover], tmp_path / 'path_3d.png')
    ax = figures['path_3d.png'].axes[0]
    spans = [np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())]
    assert spans == pytest.approx([spans[2]] * 3) and spans[2] >= 1.0     # the 1 m climb sets every axis
    [marker] = [c for c in ax.collections if c.get_label() == 'hold point (reference)']
    assert np.asarray(marker._offsets3d).ravel() == pytest.approx([0.0, 0.0, 1.0])
    assert 'equal axis scales' in ax.get_title()


def test_tracking_marks_the_settling_time_and_shows_the_settled_error_in_millimetres(hover, figures, tmp_path):
    plots.plot_tracking(plots._pyplot(), [hover], tmp_path / 'tracking.png')
    axes = np.array(figures['tracking.png'].axes).reshape(4, 3)
    for row, unit in enumerate(('mm', 'mm', 'mm', 'mrad')):
        whole, settled = axes[row][1], axes[row][2]
        [marker] = [line for line in whole.get_lines() if line.get_label() == 'end of settling window']
        assert marker.get_xdata()[0] == pytest.approx(hover.record.time[0] + SETTLE)
        assert settled.get_ylabel().endswith(f'[{unit}]')
        [data] = [line for line in settled.get_lines() if line.get_label() == 'nnit2fsmc']
        assert min(data.get_xdata()) >= hover.record.time[0] + SETTLE
    x_error = hover.record.position[:, 0] - hover.record.reference_position[:, 0]
    [data] = [line for line in axes[0][2].get_lines() if line.get_label() == 'nnit2fsmc']
    assert np.abs(data.get_ydata()).max() == pytest.approx(1000.0 * np.abs(x_error[hover.record.time >= SETTLE]).max())


def test_sliding_surfaces_have_units(hover, figures, tmp_path):
    plots.plot_surfaces(plots._pyplot(), [hover], tmp_path / 'surfaces.png')
    labels = [ax.get_ylabel() for ax in figures['surfaces.png'].axes]
    # S = de/dt + lambda e: e in m for x, y, z and in rad for the angles; a row per subsystem, the whole
    # flight on the left and its settled zoom on the right, both labelled
    expected = ['S_x [m/s]', 'S_y [m/s]', 'S_z [m/s]', 'S_phi [rad/s]', 'S_theta [rad/s]', 'S_psi [rad/s]']
    assert labels == [label for label in expected for _column in ('whole flight', 'settled')]


def test_the_fuzzy_share_figure_names_both_windows_and_leaves_out_flights_without_a_fuzzy_term(hover, figures,
                                                                                              tmp_path):
    sign = flight('hover', 'smc-sign')
    assert plots.plot_fuzzy_share(plots._pyplot(), [sign], tmp_path / 'none.png') is None
    plots.plot_fuzzy_share(plots._pyplot(), [hover, sign], tmp_path / 'fuzzy_share.png')
    fig = figures['fuzzy_share.png']
    assert '0.5 s windows' in fig._suptitle.get_text() and 'the 5 s windows of the metrics' in fig._suptitle.get_text()
    labels = {artist.get_label() for ax in fig.axes for artist in ax.get_children()}
    assert 'nnit2fsmc' in labels and 'smc-sign' not in labels
