"""The simulator's fleet core: vehicle namespaces, initial states, stepping together, answers paired by vehicle."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_msgs_bridge.contract import vehicle_namespaces
from quad_sim.fleet import Fleet, LockstepAnswers, split_initial_states
from quad_sim.model import QuadrotorModel
from quad_sim.simulator import Simulator
from hang_guard import HANG_TIMEOUT_S

PARAMS, DISTURBANCES = load_vehicle_file()


def test_vehicle_names_resolve_against_the_node_namespace():
    assert vehicle_namespaces('/', ['uav1', 'uav2']) == ['/uav1', '/uav2']
    assert vehicle_namespaces('/quad', ['']) == ['/quad']                      # the default: the node's own
    assert vehicle_namespaces('/team', ['uav1', 'red/uav2', '/solo']) == ['/team/uav1', '/team/red/uav2', '/solo']
    assert vehicle_namespaces('/', ['']) == ['/']


@pytest.mark.parametrize('names, message', [
    ([], 'at least one'),
    (['uav1', '2fast'], "'2fast' is not a valid namespace"),
    (['uav-1'], 'not a valid namespace'),
    (['a//b'], 'not a valid namespace'),
    (['uav1', '/team/uav1'], '/team/uav1 is given more than once'),
])
def test_invalid_vehicle_names_are_refused_naming_the_parameter(names, message):
    with pytest.raises(ParameterError, match='parameter vehicles') as error:
        vehicle_namespaces('/team', names)
    assert message in str(error.value)


def test_initial_states_are_twelve_values_per_vehicle_in_order():
    values = [float(v) for v in range(36)]
    assert split_initial_states(values, 3) == [values[0:12], values[12:24], values[24:36]]
    with pytest.raises(ParameterError, match=r'parameter initial_state: 12 values for 3 vehicle\(s\); expected 36'):
        split_initial_states(values[:12], 3)


def test_each_vehicle_of_a_fleet_flies_as_it_would_alone():
    """Three vehicles with their own starts and thrusts equal three lone simulators to the bit, on one clock."""
    model = QuadrotorModel(PARAMS, DISTURBANCES)
    starts = [[0.0, 3.0 * k, 0.5 * k] + [0.0] * 9 for k in range(3)]
    thrusts = [[PARAMS.hover_force * (1.0 + 0.05 * k + 0.01 * rotor) for rotor in range(4)] for k in range(3)]
    fleet = Fleet(model, 1e-3, starts)
    alone = [Simulator(model, 1e-3, start) for start in starts]
    for k in range(3):
        assert fleet.set_forces(k, thrusts[k]) and alone[k].set_forces(thrusts[k])
    for _ in range(50):
        fleet.advance(2)
        for simulator in alone:
            simulator.advance(2)
    assert len(fleet) == 3 and fleet.time == alone[0].time == 0.1
    assert fleet.odometry() == [simulator.odometry() for simulator in alone]
    assert fleet.odometry()[0] != fleet.odometry()[2]      # different vehicles, different flights


def test_a_non_finite_thrust_is_refused_for_that_vehicle_only():
    fleet = Fleet(QuadrotorModel(PARAMS, DISTURBANCES), 1e-3, [[0.0] * 12, [0.0] * 12])
    assert fleet.set_forces(0, [1.0, 2.0, 3.0, 4.0])
    assert not fleet.set_forces(1, [1.0, float('nan'), 3.0, 4.0])
    assert [s.forces for s in fleet.simulators] == [(1.0, 2.0, 3.0, 4.0), (0.0, 0.0, 0.0, 0.0)]


def test_a_step_completes_only_when_every_vehicle_has_answered():
    answers = LockstepAnswers(3)
    assert not answers.answer(2)
    assert not answers.answer(2)          # a second answer of the same vehicle counts once
    assert not answers.answer(0)
    assert answers.waiting == {1}
    assert answers.answer(1)              # the last one: integrate
    assert answers.waiting == {0, 1, 2}   # the next step waits for all again
    assert not answers.answer(1)


def test_a_lone_vehicle_completes_each_step_with_its_answer():
    answers = LockstepAnswers(1)
    assert answers.answer(0) and answers.answer(0)


def test_an_invalid_initial_state_names_the_vehicle():
    with pytest.raises(ValueError, match='vehicle 2: state component 4 is nan'):
        Fleet(QuadrotorModel(PARAMS, DISTURBANCES), 1e-3, [[0.0] * 12, [0.0] * 4 + [float('nan')] + [0.0] * 7])


COMPILED_KERNELS = '''
import json, sys
sys.path[:0] = sys.argv[1:]
from quad_msgs_bridge.state import _odometry_fields
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel, _step_one
from quad_sim.simulator import compile_kernels
kernels = (_step_one, _odometry_fields)
before = [len(kernel.signatures) for kernel in kernels]
compile_kernels(QuadrotorModel(*load_vehicle_file()), 1e-3)
print(json.dumps([before, [len(kernel.signatures) for kernel in kernels]]))
'''


def test_compile_kernels_builds_the_step_and_odometry_kernels_before_the_first_step():
    """What the ROS simulator node runs before publishing: afterwards its first steps need no compiling."""
    root = Path(__file__).resolve().parent.parent
    paths = [str(root / 'ros2_ws' / 'src' / package) for package in ('quad_msgs_bridge', 'quad_sim')]
    result = subprocess.run([sys.executable, '-c', COMPILED_KERNELS, *paths], capture_output=True, text=True,
                            timeout=HANG_TIMEOUT_S, check=True)
    before, after = json.loads(result.stdout)
    assert before == [0, 0] and all(count >= 1 for count in after)
