"""The PX4 conversions of quad_msgs_bridge.px4: frames (NED/FRD <-> ENU/FLU), motor order and normalisation, the
SIH vehicle's hover throttle, U1..U4 to PX4's normalised thrust and torque, references to TrajectorySetpoint.

The checks are against independent arithmetic: rotation matrices built here (not the module's quaternion products),
and SIH's own force and torque equations (src/modules/simulation/simulator_sih/sih.cpp, generate_force_and_torques)."""
import math

import numpy as np
import pytest

from quad_msgs_bridge import px4
from quad_msgs_bridge.frames import rotation_from_euler
from quad_msgs_bridge.mixer import controls_from_forces
from quad_msgs_bridge.vehicle_params import load_vehicle_file

SIH, _ = load_vehicle_file('px4-sih-quadx')
#: SIH's parameter defaults (sih_params.c) and gravity (CONSTANTS_ONE_G)
SIH_T_MAX, SIH_Q_MAX, SIH_L_ROLL, SIH_L_PITCH, SIH_MASS, ONE_G = 5.0, 0.1, 0.2, 0.2, 1.0, 9.80665
NED_FROM_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_FROM_FLU = np.diag([1.0, -1.0, -1.0])


def random_states(seed: int, count: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    states = rng.uniform(-3.0, 3.0, size=(count, 12))
    states[:, 6] = rng.uniform(-math.pi, math.pi, count)          # roll, any
    states[:, 7] = rng.uniform(-1.5, 1.5, count)                  # pitch, away from gimbal lock
    states[:, 8] = rng.uniform(-math.pi, math.pi, count)          # yaw, any
    return states


def matrix_of(q_wxyz) -> np.ndarray:
    w, x, y, z = q_wxyz
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


# ---------------------------------------------------------------- frames
@pytest.mark.parametrize('velocity_frame', [px4.VELOCITY_FRAME_NED, px4.VELOCITY_FRAME_BODY_FRD])
def test_odometry_round_trips_at_random_attitudes(velocity_frame):
    for state in random_states(seed=38, count=300):
        odometry = px4.px4_odometry_from_state(123, state, velocity_frame)
        np.testing.assert_allclose(px4.state_from_px4_odometry(odometry), state, rtol=0, atol=1e-9)


def test_the_px4_fields_are_ned_and_frd_by_independent_matrices():
    """q is body FRD -> world NED: R_ned_frd = N R_enu_flu F with the axis swaps N (ENU -> NED) and F (FRD -> FLU);
    velocity NED = N v; body rates FRD = F (body rates FLU), from the rotation matrix and its derivative."""
    for state in random_states(seed=7, count=100):
        phi, theta, psi = state[6:9]
        r_enu_flu = np.array(rotation_from_euler(phi, theta, psi))
        odometry = px4.px4_odometry_from_state(0, state)
        np.testing.assert_allclose(matrix_of(odometry.q), NED_FROM_ENU @ r_enu_flu @ FRD_FROM_FLU, atol=1e-12)
        assert odometry.q[0] >= 0.0 and math.isclose(np.linalg.norm(odometry.q), 1.0)
        np.testing.assert_allclose(odometry.position, NED_FROM_ENU @ state[:3], atol=1e-15)
        np.testing.assert_allclose(odometry.velocity, NED_FROM_ENU @ state[3:6], atol=1e-15)
        # the body rates by finite differences of R: skew(w_body) = R^T dR/dt
        h = 1e-6
        ahead = np.array(rotation_from_euler(*(state[6:9] + h * state[9:12])))
        behind = np.array(rotation_from_euler(*(state[6:9] - h * state[9:12])))
        skew = r_enu_flu.T @ (ahead - behind) / (2 * h)
        rates_flu = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
        np.testing.assert_allclose(odometry.angular_velocity, FRD_FROM_FLU @ rates_flu, atol=1e-6)


def test_a_level_vehicle_facing_north_is_px4s_identity():
    """Our yaw pi/2 (x to the north) is PX4's yaw 0: the identity quaternion; 1 m up is z = -1 in NED."""
    odometry = px4.px4_odometry_from_state(0, [0, 0, 1, 0, 0, 0, 0, 0, math.pi / 2, 0, 0, 0])
    np.testing.assert_allclose(odometry.q, (1, 0, 0, 0), atol=1e-15)
    assert odometry.position == (0.0, 0.0, -1.0)
    assert px4.ned_yaw(math.pi / 2) == 0.0 and px4.ned_yaw(0.0) == pytest.approx(math.pi / 2)
    assert px4.ned_yaw(-math.pi / 2) == pytest.approx(-math.pi)          # wrapped into [-pi, pi)


@pytest.mark.parametrize('field, index', [('position', 2), ('q', 0), ('velocity', 1), ('angular_velocity', 0)])
def test_nan_in_an_odometry_field_is_named(field, index):
    odometry = px4.px4_odometry_from_state(0, random_states(1, 1)[0])
    values = list(getattr(odometry, field))
    values[index] = math.nan
    with pytest.raises(ValueError, match=f'odometry {field}: non-finite'):
        px4.state_from_px4_odometry(odometry._replace(**{field: tuple(values)}))


def test_unsupported_frames_and_nan_states_are_refused():
    odometry = px4.px4_odometry_from_state(0, random_states(2, 1)[0])
    with pytest.raises(ValueError, match='velocity_frame 2'):
        px4.state_from_px4_odometry(odometry._replace(velocity_frame=2))      # world FRD: heading unknown
    with pytest.raises(ValueError, match='pose_frame 2'):
        px4.state_from_px4_odometry(odometry._replace(pose_frame=2))
    with pytest.raises(ValueError, match='state: non-finite'):
        px4.px4_odometry_from_state(0, [math.nan] + [0.0] * 11)


def test_a_reference_becomes_a_ned_trajectory_setpoint():
    setpoint = px4.trajectory_setpoint((1, 2, 3), (0.1, 0.2, 0.3), (0.01, 0.02, 0.03), 0.25, 0.5)
    assert setpoint.position == (2.0, 1.0, -3.0) and setpoint.velocity == (0.2, 0.1, -0.3)
    assert setpoint.acceleration == (0.02, 0.01, -0.03)
    assert setpoint.yaw == pytest.approx(math.pi / 2 - 0.25) and setpoint.yawspeed == -0.5
    with pytest.raises(ValueError, match='reference: non-finite'):
        px4.trajectory_setpoint((1, 2, math.nan), (0, 0, 0), (0, 0, 0), 0.0)


# ---------------------------------------------------------------- motors
def sih_wrench(u) -> np.ndarray:
    """SIH's thrust and torques [N, N m, body FRD] of motor signals u0..u3 (sih.cpp generate_force_and_torques)."""
    u0, u1, u2, u3 = u
    return np.array([-SIH_T_MAX * (u0 + u1 + u2 + u3),
                     SIH_L_ROLL * SIH_T_MAX * (-u0 + u1 + u2 - u3),
                     SIH_L_PITCH * SIH_T_MAX * (u0 - u1 + u2 - u3),
                     SIH_Q_MAX * (u0 + u1 - u2 - u3)])


def our_wrench_frd(forces) -> np.ndarray:
    """Our eq. (2) wrench of rotor thrusts, in body FRD: (thrust z, roll, pitch, yaw) = (-U1, d U2, -d U3, -U4)."""
    u1, u2, u3, u4 = controls_from_forces(*forces, SIH.mixer)
    return np.array([-u1, SIH.d * u2, -SIH.d * u3, -u4])


def test_px4_numbers_the_sih_motors_front_right_rear_left_front_left_rear_right():
    assert px4.motor_order(SIH) == (0, 3, 1, 2)      # F1 front-right -> motor 1, F2 back-right -> motor 4, ...
    assert SIH.rotor_names == ('F1_front_right', 'F2_back_right', 'F3_back_left', 'F4_front_left')


def test_our_forces_through_px4s_controls_and_sih_give_our_wrench():
    """Forces -> ActuatorMotors control -> PX4's output stage (THR_MDL_FAC 0, SIH's) -> SIH's equations: the wrench
    our model computes for the same forces."""
    order = px4.motor_order(SIH)
    rng = np.random.default_rng(15)
    for forces in rng.uniform(0.0, SIH.F_max, size=(200, 4)):
        controls = px4.motor_controls(forces, SIH, order)
        assert all(math.isnan(c) for c in controls[4:])
        u = [px4.motor_signal(c) for c in controls[:4]]
        np.testing.assert_allclose(sih_wrench(u), our_wrench_frd(forces), rtol=1e-9, atol=1e-12)


def test_the_plus_frame_and_a_wrong_spin_are_refused():
    paper, _ = load_vehicle_file('paper')
    with pytest.raises(ValueError, match='F1 at .* has no PX4 rotor at its bearing'):
        px4.motor_order(paper)
    from dataclasses import replace
    mirrored = replace(SIH, rotor_directions=(-1, 1, -1, 1))
    with pytest.raises(ValueError, match='F1 turns clockwise, PX4 motor 1 at its place the other way'):
        px4.motor_order(mirrored)


def test_nan_forces_are_refused():
    with pytest.raises(ValueError, match='rotor forces: non-finite'):
        px4.motor_controls([1.0, math.nan, 1.0, 1.0], SIH, px4.motor_order(SIH))


def test_the_thrust_curve_is_inverted_as_px4s_output_stage_does():
    for factor in (0.0, 0.3, 1.0):
        for u in np.linspace(0.0, 1.0, 11):
            thrust = factor * u * u + (1 - factor) * u
            assert px4.motor_signal(thrust, factor) == pytest.approx(u, abs=1e-12)
    with pytest.raises(ValueError, match='THR_MDL_FAC 1.5'):
        px4.motor_signal(0.5, 1.5)


def test_hover_is_sihs_hover_throttle():
    """mg/4 per rotor gives the control m g / (4 SIH_T_MAX) = 0.490, SIH's hover signal (THR_MDL_FAC 0: signal =
    control); PX4's default MPC_THR_HOVER 0.5 (mc_pos_control params) is within 0.01 of it."""
    controls = px4.motor_controls([SIH.hover_force] * 4, SIH, px4.motor_order(SIH))
    hover = SIH_MASS * ONE_G / (4 * SIH_T_MAX)
    assert controls[:4] == pytest.approx([hover] * 4, abs=1e-12)
    assert sih_wrench([px4.motor_signal(c) for c in controls[:4]])[0] == pytest.approx(-SIH_MASS * ONE_G)
    assert abs(hover - 0.5) < 0.01


# ---------------------------------------------------------------- thrust and torque setpoints
def test_the_normalised_allocation_of_the_sih_geometry():
    """PX4's normalised quad-X allocation: roll and pitch +-1/sqrt 2 per motor, yaw +-1, thrust z -1."""
    mix = px4.SIH_QUADX.allocation()
    s = math.sqrt(0.5)
    np.testing.assert_allclose(mix[:, [0, 1, 2, 5]], [[-s, s, 1, -1], [s, -s, 1, -1], [s, s, -1, -1],
                                                      [-s, -s, -1, -1]], atol=1e-12)
    np.testing.assert_allclose(px4.wrench_scales(SIH), (2 * math.sqrt(2) * SIH_L_ROLL * SIH_T_MAX,
                                                        2 * math.sqrt(2) * SIH_L_PITCH * SIH_T_MAX,
                                                        4 * SIH_Q_MAX, 4 * SIH_T_MAX), rtol=1e-9)


def test_u1_to_u4_through_px4s_allocation_and_sih_give_our_wrench():
    """U1..U4 -> normalised thrust and torque -> PX4's allocation (our reading of it) -> SIH's equations: the wrench
    our eq. (2) gives for the same U1..U4, while no rotor saturates."""
    scales = px4.wrench_scales(SIH)
    mix = px4.SIH_QUADX.allocation()
    rng = np.random.default_rng(3)
    for forces in rng.uniform(1.5, 3.5, size=(100, 4)):
        controls = controls_from_forces(*forces, SIH.mixer)
        thrust, torque = px4.thrust_torque_setpoints(controls, SIH, scales)
        assert thrust[:2] == (0.0, 0.0)
        u = mix @ np.array([*torque, *thrust])
        np.testing.assert_allclose(sih_wrench(u), our_wrench_frd(forces), rtol=1e-9, atol=1e-9)
    with pytest.raises(ValueError, match='U1..U4: non-finite'):
        px4.thrust_torque_setpoints((math.inf, 0, 0, 0), SIH, scales)


def test_hover_thrust_setpoint_is_the_hover_throttle():
    thrust, torque = px4.thrust_torque_setpoints((SIH.m * SIH.g, 0.0, 0.0, 0.0), SIH, px4.wrench_scales(SIH))
    assert thrust[2] == pytest.approx(-SIH_MASS * ONE_G / (4 * SIH_T_MAX)) and torque == (0.0, 0.0, 0.0)
