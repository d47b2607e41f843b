"""colcon test: the installed simulator holds a hovering vehicle with the packaged parameters."""
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel
from quad_sim.simulator import Simulator


def test_hover_forces_hold_the_vehicle():
    params, disturbances = load_vehicle_file()
    sim = Simulator(QuadrotorModel(params, disturbances.switched(False)), 1e-3,
                    [0.0, 0.0, 1.0] + [0.0] * 9)
    sim.set_forces([params.hover_force] * 4)
    sim.advance(1000)
    assert abs(sim.state[2] - 1.0) < 1e-9
    assert sim.time == 1.0
