"""colcon test: the installed gains file (also the node's parameter file) builds every controller."""
import pytest

from nnit2fsmc_controller.factory import CONTROLLERS, DEFAULT_CONTROLLER_FILE, build_controller, load_gains
from quad_msgs_bridge.vehicle_params import load_vehicle_file


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_every_controller_builds_from_the_packaged_gains(kind):
    params, _ = load_vehicle_file()
    controller = build_controller(kind, params, load_gains())
    assert controller.dt == pytest.approx(1e-3)
    assert DEFAULT_CONTROLLER_FILE.read_text().count('ros__parameters') == 1
