"""The model flies the true vehicle: mass, rotor factors, efficiency loss, CoG offset, wind drag; batches."""
import dataclasses
import math

import numpy as np
import pytest

from quad_msgs_bridge.state import DPHI, DTHETA, PHI, STATE_SIZE, THETA, VX, VY, VZ, Z
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file
from quad_sim.model import QuadrotorModel
from quad_sim.simulator import Simulator

NOMINAL, DISTURBANCES = load_vehicle_file()
CALM = DISTURBANCES.switched(False)
DT = 1e-3
HOVERING = [0.0, 0.0, 3.0] + [0.0] * 9
# Rotor layout of the paper's plus frame (rotor_layout.py, body FLU): F1 front, F2 right, F3 back, F4 left; F2 and F4
# turn clockwise.
ROTOR_POSITIONS = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * NOMINAL.d
REACTION_SIGN = np.array([-1.0, 1.0, -1.0, 1.0])


def true_vehicle(**changes) -> VehicleParams:
    return dataclasses.replace(NOMINAL, **changes)


def test_heavier_true_vehicle_sinks_under_nominal_hover_thrust_and_hovers_with_its_own():
    heavy = true_vehicle(m=1.3 * NOMINAL.m)
    model = QuadrotorModel(heavy, CALM)
    nominal_hover = model.derivative(0.0, HOVERING, model.controls((NOMINAL.hover_force,) * 4))
    # 4 F = m_nom g against 1.3 m_nom g: a_z = g (1 / 1.3 - 1)
    assert nominal_hover[VZ] == pytest.approx(NOMINAL.g * (1.0 / 1.3 - 1.0), rel=1e-12)
    simulator = Simulator(model, DT, HOVERING)
    simulator.set_forces((1.3 * NOMINAL.m * NOMINAL.g / 4.0,) * 4)    # the true hover thrust, by hand
    simulator.advance(2000)
    np.testing.assert_allclose(simulator.state, HOVERING, atol=1e-12)


def test_weaker_rotors_need_more_commanded_thrust_to_hover():
    """Thrust factor 0.9 and 10 % efficiency loss on every rotor: hover needs m g / (4 x 0.9 x 0.9) per rotor."""
    weak = true_vehicle(rotor_thrust_factors=(0.9,) * 4, rotor_efficiency_loss=(0.1,) * 4)
    simulator = Simulator(QuadrotorModel(weak, CALM), DT, HOVERING)
    simulator.set_forces((NOMINAL.m * NOMINAL.g / (4.0 * 0.81),) * 4)
    simulator.advance(2000)
    np.testing.assert_allclose(simulator.state, HOVERING, atol=1e-12)


def test_rotor_factors_and_efficiency_loss_give_u1_to_u4_by_hand():
    vehicle = true_vehicle(rotor_thrust_factors=(1.1, 0.95, 1.0, 0.9), rotor_drag_factors=(0.8, 1.2, 1.05, 1.0),
                           rotor_efficiency_loss=(0.0, 0.2, 0.05, 0.1))
    u1, u2, u3, u4 = QuadrotorModel(vehicle, CALM).controls((1.0, 1.5, 3.0, -0.5))
    # the commands are clipped to [0, 2.6818] first: 3.0 -> 2.6818, -0.5 -> 0
    thrusts = (1.1 * 1.0, 0.95 * 0.8 * 1.5, 1.0 * 0.95 * 2.6818, 0.0)
    torques = (0.8 * 1.0, 1.2 * 0.8 * 1.5, 1.05 * 0.95 * 2.6818, 0.0)
    c = NOMINAL.Kd / NOMINAL.Kp
    assert u1 == pytest.approx(sum(thrusts), rel=1e-14)
    assert u2 == pytest.approx(thrusts[3] - thrusts[1], rel=1e-14)
    assert u3 == pytest.approx(thrusts[2] - thrusts[0], rel=1e-14)
    assert u4 == pytest.approx(c * (-torques[0] + torques[1] - torques[2] + torques[3]), rel=1e-14)


def test_a_stronger_front_rotor_pitches_the_vehicle():
    """Equal commands, rotor 1 (front, +x) 10 % stronger: a nose-up moment -d (T1 - T3) about body y."""
    vehicle = true_vehicle(rotor_thrust_factors=(1.1, 1.0, 1.0, 1.0))
    derivative = QuadrotorModel(vehicle, CALM).derivative(
        0.0, HOVERING, QuadrotorModel(vehicle, CALM).controls((1.2,) * 4))
    assert derivative[DTHETA] == pytest.approx(-NOMINAL.d * 0.1 * 1.2 / NOMINAL.Iy, rel=1e-12)
    assert derivative[DPHI] == 0.0


@pytest.mark.parametrize('offset', [(0.01, 0.0, 0.0), (0.0, -0.02, 0.0), (0.015, 0.008, 0.03)])
def test_cog_offset_moment_is_r_cross_f_about_the_centre_of_gravity(offset):
    vehicle = true_vehicle(cog_offset=offset)
    model = QuadrotorModel(vehicle, CALM)
    forces = (1.1, 1.3, 0.9, 1.25)
    derivative = model.derivative(0.0, HOVERING, model.controls(forces))
    # first principles: the moment of each vertical rotor force about the centre of gravity
    moment = sum(np.cross(r - np.array(offset), [0.0, 0.0, f]) for r, f in zip(ROTOR_POSITIONS, forces))
    assert derivative[DPHI] == pytest.approx(moment[0] / NOMINAL.Ix, rel=1e-12)
    assert derivative[DTHETA] == pytest.approx(moment[1] / NOMINAL.Iy, rel=1e-12)
    # and the formulas of the brief: roll d U2 - c_y U1, pitch d U3 + c_x U1
    u1 = sum(forces)
    assert moment[0] == pytest.approx(NOMINAL.d * (forces[3] - forces[1]) - offset[1] * u1, rel=1e-12)
    assert moment[1] == pytest.approx(NOMINAL.d * (forces[2] - forces[0]) + offset[0] * u1, rel=1e-12)


def test_cog_offset_hover_needs_the_forces_solved_by_hand():
    """With the CoG at (c_x, c_y), zero moment needs T3 - T1 = -c_x m g / d and T4 - T2 = c_y m g / d."""
    c_x, c_y = 0.012, -0.007
    vehicle = true_vehicle(cog_offset=(c_x, c_y, 0.0))
    w, d = NOMINAL.m * NOMINAL.g, NOMINAL.d
    balanced = (w / 4 + c_x * w / (2 * d), w / 4 - c_y * w / (2 * d), w / 4 - c_x * w / (2 * d),
                w / 4 + c_y * w / (2 * d))
    simulator = Simulator(QuadrotorModel(vehicle, CALM), DT, HOVERING)
    simulator.set_forces(balanced)
    simulator.advance(3000)
    np.testing.assert_allclose(simulator.state, HOVERING, atol=1e-11)
    simulator = Simulator(QuadrotorModel(vehicle, CALM), DT, HOVERING)
    simulator.set_forces((NOMINAL.hover_force,) * 4)              # what the nominal model would command
    simulator.advance(300)
    # CoG ahead (c_x > 0): the nose drops (pitch > 0 tilts thrust to +x); CoG to the right: roll > 0
    assert simulator.state[THETA] > 1e-3 and simulator.state[PHI] > 1e-3


def test_wind_drag_is_added_and_nothing_changes_without_air():
    model = QuadrotorModel(NOMINAL, DISTURBANCES)
    state = [0.0, 0.0, 2.0, 1.0, -0.5, 0.2, 0.1, -0.05, 0.3, 0.0, 0.0, 0.0]
    controls = model.controls((1.2, 1.1, 1.3, 1.0))
    still = model.derivative(1.0, state, controls)
    windy = model.derivative(1.0, state, controls, air_velocity=(4.0, 1.0, -0.5))
    c, m = NOMINAL.wind_drag, NOMINAL.m
    np.testing.assert_allclose(np.subtract(windy, still)[VX:VZ + 1],
                               [c * (4.0 - 1.0) / m, c * (1.0 + 0.5) / m, c * (-0.5 - 0.2) / m], rtol=1e-12)
    assert windy[:VX] == still[:VX] and windy[VZ + 1:] == still[VZ + 1:]
    no_drag = QuadrotorModel(true_vehicle(wind_drag=0.0), DISTURBANCES)
    assert no_drag.step(1.0, state, (1.2, 1.1, 1.3, 1.0), DT, (4.0, 1.0, -0.5)) == \
        no_drag.step(1.0, state, (1.2, 1.1, 1.3, 1.0), DT)


def test_steady_wind_carries_a_hovering_vehicle_to_its_terminal_velocity():
    """m v' = c (w - v) - Kf v: v(t) = c w / (c + Kf) (1 - exp(-(c + Kf) t / m)), checked every 0.5 s for 10 s."""
    model = QuadrotorModel(NOMINAL, CALM)
    wind = (3.0, -2.0, 0.0)
    state = list(HOVERING)
    c, m = NOMINAL.wind_drag, NOMINAL.m
    for step in range(1, 10001):
        state = model.step(step * DT, state, (NOMINAL.hover_force,) * 4, DT, wind)
        if step % 500 == 0:
            t = step * DT
            for axis, kf, w in ((VX, NOMINAL.Kfx, 3.0), (VY, NOMINAL.Kfy, -2.0)):
                rate = (c + kf) / m
                assert state[axis] == pytest.approx(c * w / (c + kf) * -math.expm1(-rate * t), abs=1e-10)
    assert state[Z] == pytest.approx(3.0, abs=1e-12)


def random_vehicle(rng) -> VehicleParams:
    return true_vehicle(m=NOMINAL.m * rng.uniform(0.7, 1.3), Ix=rng.uniform(3e-3, 5e-3), Iy=rng.uniform(3e-3, 5e-3),
                        Iz=rng.uniform(6e-3, 9e-3), Kfx=rng.uniform(1e-4, 1e-3), Kfy=rng.uniform(1e-4, 1e-3),
                        Kfz=rng.uniform(1e-4, 1e-3), cog_offset=tuple(rng.uniform(-0.01, 0.01, 3)),
                        rotor_thrust_factors=tuple(rng.uniform(0.9, 1.1, 4)),
                        rotor_drag_factors=tuple(rng.uniform(0.9, 1.1, 4)),
                        rotor_efficiency_loss=tuple(rng.uniform(0.0, 0.1, 4)), wind_drag=rng.uniform(0.1, 0.3))


def test_batch_of_true_vehicles_with_wind_equals_single_vehicle_runs():
    rng = np.random.default_rng(5)
    n = 7
    vehicles = [random_vehicle(rng) for _ in range(n)]
    states = [[*rng.normal(0, 1, 2), rng.uniform(1, 4), *rng.normal(0, 1, 3), *rng.uniform(-0.5, 0.5, 3),
               *rng.normal(0, 1, 3)] for _ in range(n)]
    states = [[float(v) for v in s] for s in states]
    forces = [tuple(float(f) for f in rng.uniform(0.5, 1.5, 4)) for _ in range(n)]
    air = [tuple(float(a) for a in rng.normal(0, 3, 3)) for _ in range(n)]
    batch_model = QuadrotorModel(VehicleParams.stack(vehicles), DISTURBANCES)
    models = [QuadrotorModel(v, DISTURBANCES) for v in vehicles]
    batch = [np.array(column) for column in zip(*states)]
    batch_forces = tuple(np.array(column) for column in zip(*forces))
    batch_air = tuple(np.array(column) for column in zip(*air))
    for k in range(200):
        batch = batch_model.step(k * DT, batch, batch_forces, DT, batch_air)
        states = [model.step(k * DT, s, f, DT, a) for model, s, f, a in zip(models, states, forces, air)]
    assert all(isinstance(component, np.ndarray) and component.shape == (n,) for component in batch)
    for i, single in enumerate(states):   # one kernel for both: the same numbers, bit for bit
        assert [float(component[i]) for component in batch] == single
    assert len(batch) == STATE_SIZE
