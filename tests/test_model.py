"""The vehicle model, paper eq. (1) through eq. (2), integrated by RK4; single vehicle and batch."""
import math

import numpy as np
import pytest

from quad_msgs_bridge.mixer import controls_from_forces
from quad_msgs_bridge.state import DPHI, DPSI, DTHETA, PSI, STATE_SIZE, VX, VZ, X, Z
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel, check_state
from quad_sim.simulator import Simulator
from vehicle_support import ASYMMETRIC, paper_eq1

PARAMS, DISTURBANCES = load_vehicle_file()
CALM = DISTURBANCES.switched(False)
DT = 1e-3


def random_state(rng, airborne=True):
    state = [*rng.normal(0, 1, 2), rng.uniform(0.5, 5.0) if airborne else 0.0, *rng.normal(0, 1, 3),
             *rng.uniform(-0.8, 0.8, 2), rng.uniform(-math.pi, math.pi), *rng.normal(0, 2, 3)]
    return [float(v) for v in state]


@pytest.mark.parametrize('params', [PARAMS, ASYMMETRIC], ids=['paper', 'asymmetric'])
@pytest.mark.parametrize('seed', range(8))
def test_derivative_is_eq1(seed, params):
    rng = np.random.default_rng(seed)
    model = QuadrotorModel(params, DISTURBANCES)
    state, controls, t = random_state(rng), tuple(rng.uniform(-2, 8, 4)), float(rng.uniform(0, 60))
    np.testing.assert_allclose(model.derivative(t, state, controls),
                               paper_eq1(params, state, controls, DISTURBANCES.at(t)), rtol=1e-14, atol=1e-12)


def test_asymmetric_vehicle_uses_each_axis_own_inertia_and_drag():
    """One excitation at a time, level attitude, no rates: each acceleration is its own axis' value by hand."""
    model = QuadrotorModel(ASYMMETRIC, CALM)
    p = ASYMMETRIC
    weight = (p.m * p.g, 0.0, 0.0, 0.0)
    level = [0.0, 0.0, 2.0, 1.5, -2.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    d = model.derivative(0.0, level, weight)
    assert d[3] == pytest.approx(-2.1e-3 * 1.5 / p.m, rel=1e-12)
    assert d[4] == pytest.approx(-3.7e-3 * -2.5 / p.m, rel=1e-12)
    assert d[5] == pytest.approx(-5.3e-3 * 0.5 / p.m, rel=1e-12)
    at_rest = [0.0, 0.0, 2.0] + [0.0] * 9
    roll, pitch, yaw = (model.derivative(0.0, at_rest, (p.m * p.g, *torques))
                        for torques in [(0.2, 0.0, 0.0), (0.0, 0.2, 0.0), (0.0, 0.0, 0.01)])
    assert roll[DPHI:] == [pytest.approx(0.25 * 0.2 / 3.1e-3, rel=1e-12), 0.0, 0.0]
    assert pitch[DPHI:] == [0.0, pytest.approx(0.25 * 0.2 / 4.7e-3, rel=1e-12), 0.0]
    assert yaw[DPHI:] == [0.0, 0.0, pytest.approx(0.01 / 8.3e-3, rel=1e-12)]
    spinning = at_rest[:DPHI] + [2.0, -3.0, 1.5]
    friction = model.derivative(0.0, spinning, weight)[DPHI:]
    gyroscopic = (-3.0 * 1.5 * (4.7e-3 - 8.3e-3), 2.0 * 1.5 * (8.3e-3 - 3.1e-3), 2.0 * -3.0 * (3.1e-3 - 4.7e-3))
    np.testing.assert_allclose(friction, [(gyroscopic[0] - 1.3e-3 * 4.0) / 3.1e-3,
                                          (gyroscopic[1] + 2.9e-3 * 9.0) / 4.7e-3,
                                          (gyroscopic[2] - 4.1e-3 * 2.25) / 8.3e-3], rtol=1e-12)


@pytest.mark.parametrize('axis', [DPHI, DTHETA, DPSI])
@pytest.mark.parametrize('rate', [-3.0, 3.0])
def test_rotational_friction_opposes_the_rate(axis, rate):
    """The printed -Kf rate^2 would speed up a negative rate; friction must always brake."""
    state = [0.0, 0.0, 2.0] + [0.0] * 9
    state[axis] = rate
    derivative = QuadrotorModel(PARAMS, CALM).derivative(0.0, state, (PARAMS.m * PARAMS.g, 0.0, 0.0, 0.0))
    assert derivative[axis] * rate < 0.0


@pytest.mark.parametrize('params', [PARAMS, ASYMMETRIC], ids=['paper', 'asymmetric'])
@pytest.mark.parametrize('yaw', [0.0, 1.0, -2.5])
def test_hover_equilibrium(yaw, params):
    """The mixer's hover forces hold the vehicle still: nothing moves by more than round-off in 5 s."""
    state = [0.3, -0.2, 1.5, 0.0, 0.0, 0.0, 0.0, 0.0, yaw, 0.0, 0.0, 0.0]
    simulator = Simulator(QuadrotorModel(params, CALM), DT, state)
    simulator.set_forces((params.hover_force,) * 4)
    simulator.advance(5000)
    np.testing.assert_allclose(simulator.state, state, rtol=0, atol=1e-12)


def test_hover_forces_drift_under_the_section_iv_disturbances():
    """With the disturbances on, the same forces no longer hold: A/m acts on the translation."""
    state = [0.0, 0.0, 1.5] + [0.0] * 9
    derivative = QuadrotorModel(PARAMS, DISTURBANCES).derivative(
        0.0, state, controls_from_forces(*(PARAMS.hover_force,) * 4, PARAMS.mixer))
    np.testing.assert_allclose(derivative[VX:VZ + 1], [0.126 / PARAMS.m] * 3, rtol=1e-12)


def drag_fall(z0, t):
    """z(t) of a fall from rest under gravity and linear drag: z'' = -g - (Kfz/m) z'."""
    k, g = PARAMS.Kfz / PARAMS.m, PARAMS.g
    return z0 - g / k * t + g / k ** 2 * (-math.expm1(-k * t)), -g / k * (-math.expm1(-k * t))


def test_free_fall_with_zero_thrust_then_rests_on_the_ground():
    z0 = 20.0
    state = [1.0, 2.0, z0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.7, 0.0, 0.0, 0.0]
    simulator = Simulator(QuadrotorModel(PARAMS, CALM), DT, state)    # thrusts start at zero
    for step in range(1, 2001):                       # 2 s: still in the air (impact after ~2.02 s)
        simulator.advance()
        z, vz = drag_fall(z0, step * DT)
        # RK4 on a linear ODE: error ~ (k dt)^5, far below the 1e-9 asked here
        assert simulator.state[Z] == pytest.approx(z, abs=1e-9)
        assert simulator.state[VZ] == pytest.approx(vz, abs=1e-9)
    assert simulator.state[Z] > 0.0
    # the drag is tiny at these speeds (Kfz/m ~ 1.3e-3 1/s) but measurable against the vacuum fall
    assert abs(simulator.state[Z] - (z0 - 0.5 * PARAMS.g * 2.0 ** 2)) > 1e-4
    simulator.advance(3000)
    assert simulator.state[Z] == 0.0
    assert simulator.state[VZ] == 0.0
    assert simulator.state[:2] == [1.0, 2.0] and simulator.state[PSI] == 0.7


def test_ground_holds_a_vehicle_with_too_little_thrust_and_releases_it_with_enough():
    ground = [0.0] * STATE_SIZE
    simulator = Simulator(QuadrotorModel(PARAMS, DISTURBANCES), DT, ground)
    simulator.set_forces((0.9 * PARAMS.hover_force,) * 4)
    simulator.advance(1000)
    assert simulator.state == ground
    simulator.set_forces((1.2 * PARAMS.hover_force,) * 4)
    simulator.advance(1000)
    assert simulator.state[Z] > 0.1


def test_rotor_limits_are_applied_by_the_model():
    state = [0.0, 0.0, 5.0] + [0.0] * 9
    model = QuadrotorModel(PARAMS, CALM)
    too_much = model.step(0.0, state, (10.0, 10.0, 10.0, 10.0), DT)
    at_max = model.step(0.0, state, (PARAMS.F_max,) * 4, DT)
    assert too_much == at_max


def test_rk4_is_fourth_order():
    rng = np.random.default_rng(3)
    state, forces = random_state(rng), tuple(rng.uniform(0.5, 2.0, 4))
    model = QuadrotorModel(PARAMS, DISTURBANCES)

    def fly(dt, duration=0.2):
        s = state
        for k in range(round(duration / dt)):
            s = model.step(k * dt, s, forces, dt)
        return np.array(s)

    reference = fly(1e-4)
    coarse, fine = (np.abs(fly(dt) - reference).max() for dt in (8e-3, 4e-3))
    assert 10.0 < coarse / fine < 22.0      # halving dt divides the error by ~2^4 = 16


@pytest.mark.parametrize('params', [PARAMS, ASYMMETRIC], ids=['paper', 'asymmetric'])
def test_batch_equals_scalar_runs(params):
    """Numpy arrays of N vehicles give what N single-vehicle runs give, bit for bit (one kernel of the physics)."""
    rng = np.random.default_rng(11)
    n = 7
    states = [random_state(rng, airborne=i != 0) for i in range(n)]
    # some thrusts outside the limits, one vehicle on the ground with too little thrust
    forces = [tuple(float(f) for f in rng.uniform(-0.5, 1.2 * PARAMS.F_max, 4)) for _ in range(n)]
    forces[0] = (0.5,) * 4
    states[1][Z], states[1][VZ], forces[1] = 0.05, -0.2, (0.0,) * 4    # touches down during the run
    model = QuadrotorModel(params, DISTURBANCES)
    batch = [np.array([s[i] for s in states]) for i in range(STATE_SIZE)]
    batch_forces = tuple(np.array([f[i] for f in forces]) for i in range(4))
    singles = [list(s) for s in states]
    for k in range(300):
        t = k * DT
        batch = model.step(t, batch, batch_forces, DT)
        singles = [model.step(t, s, f, DT) for s, f in zip(singles, forces)]
    assert all(isinstance(component, np.ndarray) for component in batch)
    for i, single in enumerate(singles):
        assert [float(component[i]) for component in batch] == single
    assert singles[0][Z] == 0.0 and singles[1][Z] == 0.0    # ground contact is covered too
    assert all(s[Z] > 0.0 for s in singles[2:])


@pytest.mark.parametrize('bad', [[0.0] * 11, [0.0] * 11 + [math.nan], [math.inf] + [0.0] * 11])
def test_check_state_rejects_malformed_states(bad):
    with pytest.raises(ValueError):
        check_state(bad)


def test_simulator_refuses_non_finite_forces_and_keeps_the_last():
    simulator = Simulator(QuadrotorModel(PARAMS, CALM), DT, [0.0, 0.0, 1.0] + [0.0] * 9)
    assert simulator.set_forces((1.0, 1.0, 1.0, 1.0))
    assert not simulator.set_forces((1.0, math.nan, 1.0, 1.0))
    assert not simulator.set_forces((1.0, 1.0, 1.0))
    assert simulator.forces == (1.0, 1.0, 1.0, 1.0)
    simulator.advance(10)
    assert simulator.time_ns == 10 * 1_000_000
    assert all(map(math.isfinite, simulator.state))
    assert simulator.odometry().stamp == pytest.approx(0.01, abs=1e-15)
    assert simulator.state[X] == 0.0


def test_a_batch_takes_floats_for_shared_values_and_refuses_a_wrong_length():
    """Forces and air velocities may be one float shared by every vehicle; an array of another length is an error
    (the compiled kernel never reads past a vehicle's arrays)."""
    model = QuadrotorModel(PARAMS, DISTURBANCES)
    batch = [np.full(3, v) for v in [0.0, 0.0, 2.0] + [0.0] * 9]
    shared = model.step(0.5, batch, (1.2, 1.2, 1.2, 1.2), DT, (1.0, 0.0, 0.0))
    single = model.step(0.5, [0.0, 0.0, 2.0] + [0.0] * 9, (1.2,) * 4, DT, (1.0, 0.0, 0.0))
    assert all(list(component) == [value] * 3 for component, value in zip(shared, single))
    with pytest.raises(ValueError):
        model.step(0.5, batch, (np.ones(2),) * 4, DT)
