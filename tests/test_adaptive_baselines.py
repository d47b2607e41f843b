"""The adaptive baselines l1-se3 and indi (docs/ADAPTIVE_BASELINES.md) against what their papers' laws
predict by hand, and the take-off hold every controller kind shares (common.takeoff_height)."""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest

from flight_stack.closed_loop import ClosedLoop, FailureRules
from flight_stack.embedded import published_path, setpoint_path
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller, build_measurement_stage, load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.reference import hold
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.model import QuadrotorModel
from quad_sim.perturbations.sensor_noise import SensorErrors, SensorNoise
from quad_sim.simulator import Simulator

VEHICLE, DISTURBANCES = load_vehicle_file()
GAINS = load_gains()
DT = 1.0 / GAINS['common']['control_rate']
HOVER = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]


def test_l1_estimate_of_a_constant_force_converges_as_its_bandwidths_predict():
    """A constant unknown acceleration d (a horizontal push, unmatched at level, and a vertical pull, matched)
    on a plant that integrates exactly v(k+1) = v(k) + T_s (f(k) + d), f = -g e3 + (U1 / m) R e3 the nominal
    model with the thrust the controller commanded, the attitude held level.

    By hand (l1_adaptive module docstring): the predictor error after a step is (Phi - T_s) f - T_s d, so from
    the first update after the force acts the estimate is sigma-hat = r d + mu (T_s - Phi) / Phi f, with
    r = mu T_s / Phi = a T_s / (exp(a T_s) - 1). Horizontally f = 0 at level: sigma_x = r d_x exactly, in one
    step. Vertically the compensation c_1 (thrust axis) is the low-pass C(s) = w / (s + w) of sigma_z,
    discretised exactly (b = 1 - exp(-w T_s)): after n steps |c_1 - d_z| <= (1 - b)^n |d_z| + (1 - r) |d_z|
    + max_k mu (T_s - Phi) / Phi |f_z(k)|; at t = 4 / w that is 1.8 % of d_z plus terms of order a T_s,
    while at t = 0.5 / w the filter has covered only 1 - exp(-0.5) = 39 % of it.
    """
    gains = copy.deepcopy(GAINS)     # the bandwidths of the derivation (the tuned ones give a bound of 3.1 %)
    gains['l1_se3'].update(predictor_pole_translation=5.0, cutoff_translation_hz=5.0)
    controller = build_controller('l1-se3', VEHICLE, gains)
    l1 = gains['l1_se3']
    a, w = l1['predictor_pole_translation'], 2.0 * math.pi * l1['cutoff_translation_hz']
    mu, phi = math.exp(-a * DT), -math.expm1(-a * DT) / a
    r = mu * DT / phi
    d = (0.4, 0.0, -1.5)                       # [m/s^2, world]
    state = list(HOVER)
    converged, early = int(math.ceil(4.0 / (w * DT))), int(0.5 / (w * DT))
    model_z, compensation = [], []
    for k in range(converged + 1):
        out = controller.update(k * DT, state, hold((0.0, 0.0, 1.0)))
        if k >= 1:
            assert controller.estimate[0] == pytest.approx(r * d[0], rel=1e-9, abs=1e-12)
        compensation.append(controller.compensation[0])
        f = (0.0, 0.0, out.controls[0] / VEHICLE.m - VEHICLE.g)
        model_z.append(f[2])
        for i in range(3):                     # exact: the acceleration is constant over the period
            state[i] += DT * state[3 + i] + 0.5 * DT * DT * (f[i] + d[i])
            state[3 + i] += DT * (f[i] + d[i])
    bound = (math.exp(-4.0) + (1.0 - r)) * abs(d[2]) + mu * (DT - phi) / phi * max(map(abs, model_z))
    assert abs(compensation[converged] - d[2]) <= bound
    assert bound < 0.03 * abs(d[2])
    assert abs(compensation[early] - d[2]) > 0.55 * abs(d[2])     # the filter, not the estimate, sets the time
    assert 0.0 < r < 1.0 and 1.0 - r < 0.01


@pytest.mark.parametrize('second_hz', [0.0, 0.5])
def test_l1_rotational_compensation_is_its_estimate_through_one_or_two_cascaded_low_passes(second_hz):
    """With ``cutoff_rotation_second_hz`` 0, c_2..c_4 is sigma_w through C(s) = w_1 / (s + w_1); above 0, through
    a second stage w_2 / (s + w_2) cascaded after it, each discretised exactly (b = 1 - exp(-w T_s)): recomputed
    here from the estimates the controller reports, step by step, while body rates it did not command move."""
    gains = copy.deepcopy(GAINS)
    gains['l1_se3'].update(cutoff_rotation_hz=8.0, cutoff_rotation_second_hz=second_hz)
    controller = build_controller('l1-se3', VEHICLE, gains)
    b1, b2 = (-math.expm1(-2.0 * math.pi * hz * DT) for hz in (8.0, second_hz))
    stage, expected = np.zeros(3), np.zeros(3)
    for k in range(400):
        state = list(HOVER)
        state[9:12] = [0.3 * math.sin(0.02 * k), -0.2 * math.cos(0.03 * k), 0.1 * math.sin(0.05 * k)]
        controller.update(k * DT, state, hold((0.0, 0.0, 1.0)))
        sigma_w = controller.estimate[3:6]
        if second_hz:
            stage += b1 * (sigma_w - stage)
            expected += b2 * (stage - expected)
        else:
            expected += b1 * (sigma_w - expected)
        assert controller.compensation[1:] == pytest.approx(expected, rel=1e-12, abs=1e-12), k
    assert np.abs(expected).max() > 0.1      # the estimate moved: the filters had something to filter


def test_l1_on_the_ground_estimates_nothing():
    """The ground's reaction is not an uncertainty to compensate: below takeoff_height the estimate stays 0."""
    controller = build_controller('l1-se3', VEHICLE, GAINS)
    ground = [0.0] * 12
    for k in range(50):
        controller.update(k * DT, ground, hold((0.0, 0.0, 1.0)))
    assert not np.any(controller.estimate) and not np.any(controller.compensation)


def indi_gains(**indi):
    """The gains with every indi feedback gain 0 (alpha_d = 0 at a level hover reference) and ``indi`` keys set."""
    gains = indi_gains_with(**indi)
    for axis in gains['indi']['axes'].values():
        axis.update(k_error=0.0, k_rate=0.0)
    return gains


def test_indi_rejects_a_moment_step_as_its_filter_predicts():
    """A step d in an unmodelled roll and pitch moment at step j, on a rigid body whose rates obey
    J dOmega/dt = M + d (rates small: no gyroscopic term), its translation and attitude read as held at a
    level hover (only the rates move: the desired attitude, and so its rates, stay 0).

    By hand (indi module docstring): with every feedback gain 0 and a level hover reference, alpha_d = 0, so
    M(k) = M_f(k) - J alpha_f(k) = -H[d](k) (the same filter H on both, the effectiveness nominal): the part of
    the disturbance left, M + d, is d (1 - b)^n n steps after the step (the update at j cannot know it),
    b = w T_s / (1 + w T_s), w = 2 pi rate_filter_hz. It falls below 5 % of d after
    N = ceil(ln 0.05 / ln(1 - b)) steps and not before.
    """
    gains = indi_gains(effectiveness_rate=0.0)
    controller = build_controller('indi', VEHICLE, gains)
    w = 2.0 * math.pi * gains['indi']['rate_filter_hz']
    b = w * DT / (1.0 + w * DT)
    steps = math.ceil(math.log(0.05) / math.log(1.0 - b))
    inertia = (VEHICLE.Ix, VEHICLE.Iy, VEHICLE.Iz)
    state, omega = list(HOVER), [0.0, 0.0, 0.0]
    j, disturbance = 20, (0.02, -0.015, 0.0)       # [N m, body]
    left = []
    for k in range(j + steps + 5):
        out = controller.update(k * DT, state, hold((0.0, 0.0, 1.0)))
        moment = (out.controls[1] * VEHICLE.d, out.controls[2] * VEHICLE.d, out.controls[3])
        d = disturbance if k >= j else (0.0, 0.0, 0.0)
        if k >= j:
            left.append([m + dk for m, dk in zip(moment, d)])
        omega = [o + DT * (m + dk) / i for o, m, dk, i in zip(omega, moment, d, inertia)]
        state[9:12] = omega          # the attitude reads level: at zero angles Euler rates are body rates
    left = np.array(left)
    for axis in (0, 1):
        fraction = left[:, axis] / disturbance[axis]
        expected = (1.0 - b) ** np.arange(len(fraction))
        np.testing.assert_allclose(fraction, expected, atol=0.01)
        assert abs(fraction[steps]) <= 0.05 + 0.01 and abs(fraction[steps - 2]) > 0.05



def first_order_step_response(blends, steps: int) -> np.ndarray:
    """The response to a unit step at sample 0 of the cascade of discrete first-order low-passes
    x(k) = x(k-1) + b (u(k) - x(k-1)), one per blend b, at samples 0 .. steps - 1."""
    states, response = [0.0] * len(blends), []
    for _ in range(steps):
        u = 1.0
        for i, b in enumerate(blends):
            states[i] += b * (u - states[i])
            u = states[i]
        response.append(u)
    return np.array(response)


def test_indi_rejects_a_vertical_force_step_through_the_measurement_stage_as_its_filters_predict():
    """A step d in an unmodelled vertical force at step j on a point mass m dv/dt = U1 + d - m g, the attitude
    level, every position gain 0 and a hover reference (a_c = 0), the velocity read through the measurement
    stage (its velocity filter S, common.velocity_filter_hz) as every kind reads it.

    By hand (indi module docstring): the velocity and the modelled thrust pass through the same S and the same
    acceleration filter H, so a_f(k) = SH[(U1 + d) / m - g](k - 1) and T_f(k) = SH[U1](k - 1) and
    U1(k) = T_f - m a_f = m g - SH[d](k - 1): the part of the disturbance left, U1 + d - m g, is
    d (1 - s(k - j - 1)) with s the step response of the cascade S H. With T_f through H alone (S left out of
    the modelled side) the increments are not synchronised and the rejection is not this one."""
    gains = indi_gains(effectiveness_rate=0.0)
    controller = build_controller('indi', VEHICLE, gains)
    stage = build_measurement_stage(gains)
    blends = [2.0 * math.pi * hz * DT / (1.0 + 2.0 * math.pi * hz * DT)
              for hz in (gains['common']['velocity_filter_hz'], gains['indi']['acceleration_filter_hz'])]
    assert gains['common']['velocity_filter_hz'] > 0.0
    j, d, steps = 20, -1.2, 300                    # [N] a downward pull
    state, left = list(HOVER), []
    for k in range(j + steps):
        out = controller.update(k * DT, stage(state), hold((0.0, 0.0, 1.0)))
        force = d if k >= j else 0.0
        if k >= j:
            left.append((out.controls[0] + force - VEHICLE.m * VEHICLE.g) / d)
        acceleration = (out.controls[0] + force) / VEHICLE.m - VEHICLE.g
        state[2] += DT * state[5] + 0.5 * DT * DT * acceleration
        state[5] += DT * acceleration
    expected = 1.0 - np.concatenate(([0.0], first_order_step_response(blends, steps - 1)))
    np.testing.assert_allclose(left, expected, atol=0.01)


def roll_pitch_command_spread(kind: str, velocity_noise: float, duration: float = 3.0,
                              attitude_rates: str | None = None) -> float:
    """The standard deviation of U2 and U3 [N] (the larger) over the last second of ``duration`` [s] of hover at
    1 m (from the ground) by ``kind`` on the nominal vehicle, its measured velocity carrying white noise of
    ``velocity_noise`` [m/s] (seeded), read through the measurement stage; the untuned gains (matched at the same
    small-signal slope: the laws compared, not two tunings), with their ``common.attitude_rates`` or the one given."""
    trajectory = make_scenario('hover', duration)
    gains = load_gains('untuned')
    if attitude_rates is not None:
        gains['common']['attitude_rates'] = attitude_rates
    controller = build_controller(kind, VEHICLE, gains)
    simulator = Simulator(QuadrotorModel(VEHICLE, DISTURBANCES), DT, trajectory.initial_state)
    noise = SensorNoise(SensorErrors(velocity=velocity_noise), SensorErrors(), np.random.default_rng(3),
                        np.random.default_rng(4))
    loop = ClosedLoop(controller, simulator, setpoint_path(published_path(trajectory, 50.0)).sample, 1,
                      FailureRules(settle_time=duration, max_error=1.0), sensor_noise=noise,
                      measurement=build_measurement_stage(GAINS))
    steps = int(round(duration / DT))
    commands = [loop.step().output.controls[1:3] for _ in range(steps)]
    assert loop.flying
    return float(np.max(np.std(np.array(commands[-int(round(1.0 / DT)):]), axis=0)))


def test_indi_attitude_loop_does_not_differentiate_the_velocity_noise_again():
    """INDI's desired attitude comes from T_c, which holds a_f, a filtered derivative of the measured velocity;
    its desired body rates and angular acceleration are the reference's (differential flatness, Tal & Karaman),
    not two more derivatives of that attitude. So 2 cm/s of velocity noise (the example campaign's) moves its
    roll and pitch commands about as much as it moves se3's, whose desired attitude holds the velocity itself
    (k_v v): within 3 times, where the third derivative of the noise put them at the rotor limits."""
    indi, se3 = roll_pitch_command_spread('indi', 0.02), roll_pitch_command_spread('se3', 0.02)
    assert indi <= 3.0 * se3, (indi, se3)


def test_common_attitude_rates_reaches_indi():
    """``common.attitude_rates: filter`` gives indi the filtered derivatives of its desired attitude, as it gives
    every kind: the derivatives of the velocity noise that flatness keeps out then move its roll and pitch
    commands several times more."""
    flat = roll_pitch_command_spread('indi', 0.02, attitude_rates='flatness')
    filtered = roll_pitch_command_spread('indi', 0.02, attitude_rates='filter')
    print(f'indi U2, U3 spread: {flat:.4f} N (flatness), {filtered:.4f} N (filter)')
    assert filtered > 3.0 * flat, (flat, filtered)

#: the LMS step of the effectiveness test: 20 times the packaged one, which is kept small so that campaign sensor
#: noise does not drive the estimate (docs/ADAPTIVE_BASELINES.md); the law is the same (stable for mu in (0, 2))
ADAPTATION_RATE = 1.0


def indi_gains_with(**indi):
    """The packaged gains with the untuned set's ``indi`` section (the filters, rotor model and gains these
    tests derive their predictions for) and the ``indi`` keys given."""
    gains = copy.deepcopy(GAINS)
    gains['indi'] = copy.deepcopy(load_gains('untuned')['indi'])
    gains['indi'].update(indi)
    return gains


def fly_indi_and_read_effectiveness(thrust_factor: float, duration: float = 12.0):
    """The effectiveness estimate after ``duration`` [s] of the position steps flown by indi on a vehicle whose
    rotors give ``thrust_factor`` times the thrust the nominal model expects (Kp off). Steps, not the paper
    helix: the normalised LMS learns only from angular accelerations well above its threshold (5 rad/s^2), which
    the smooth helix gives at take-off alone."""
    true = dataclasses.replace(VEHICLE, rotor_thrust_factors=(thrust_factor,) * 4)
    trajectory = make_scenario('steps', duration)
    controller = build_controller('indi', VEHICLE, indi_gains_with(effectiveness_rate=ADAPTATION_RATE))
    simulator = Simulator(QuadrotorModel(true, DISTURBANCES), DT, trajectory.initial_state)
    loop = ClosedLoop(controller, simulator, setpoint_path(published_path(trajectory, 50.0)).sample, 1,
                      FailureRules(settle_time=duration, max_error=1.0), measurement=build_measurement_stage(GAINS))
    for _ in range(int(round(duration / DT))):
        loop.step()
    assert loop.flying
    return controller.effectiveness


def test_indi_effectiveness_converges_on_a_vehicle_whose_rotor_coefficient_is_off_by_20_percent():
    """Rotors giving 80 % of the modelled thrust (Kp off by 20 %; the reaction torque is unchanged): the roll
    and pitch effectiveness the normalised LMS estimates is 0.8 times what it estimates on the nominal vehicle
    in the same flight (there about 1: the paper's eq. 1 drives Euler-angle accelerations, so in body axes the
    effectiveness is near, not at, the nominal), and the yaw effectiveness does not move with it."""
    nominal = fly_indi_and_read_effectiveness(1.0)
    weak = fly_indi_and_read_effectiveness(0.8)
    assert np.all(np.abs(nominal - 1.0) < 0.08)
    np.testing.assert_allclose(weak[:2] / nominal[:2], 0.8, atol=0.05)
    assert np.all(np.abs(weak[:2] - 0.8) < 0.05)
    assert abs(weak[2] / nominal[2] - 1.0) < 0.06


# ---------------------------------------------------------------- the same take-off for every kind
@pytest.mark.parametrize('kind', CONTROLLERS)
def test_every_kind_holds_its_horizontal_adaptation_on_the_ground_and_acts_on_the_error(kind):
    """common.takeoff_height is the take-off hold of every kind: on the ground (z below it) with a reference
    2 m to the side, nothing the x, y or attitude laws adapt or integrate moves, and the laws act on the error
    all the same (the desired tilt is not held at 0: a level lift-off handed every kind a large error at
    lift-off, docs/ADAPTIVE_BASELINES.md); above it the same error tilts the vehicle. Equal kinds, equal
    pipelines."""
    assert GAINS['common']['takeoff_height'] > 0.0
    reference = hold((2.0, -1.0, 1.0))
    controller = build_controller(kind, VEHICLE, GAINS)
    before = held_state(controller)
    ground = [0.0, 0.0, 0.5 * GAINS['common']['takeoff_height']] + [0.0] * 9
    for k in range(20):
        out = controller.update(k * DT, ground, reference)
        controller.adapt()
    assert abs(out.attitude_reference[0]) > 0.01 and abs(out.attitude_reference[1]) > 0.01
    np.testing.assert_array_equal(held_state(controller), before)
    airborne = [0.0, 0.0, 2.0 * GAINS['common']['takeoff_height']] + [0.0] * 9
    out = controller.update(20 * DT, airborne, reference)
    assert abs(out.attitude_reference[0]) > 0.01 and abs(out.attitude_reference[1]) > 0.01


def test_the_take_off_is_the_same_for_every_kind():
    """One common key sets the take-off hold of every kind (issue 26: before, the NNIT2FSMC kinds alone had it)."""
    heights = {build_controller(kind, VEHICLE, GAINS).takeoff_height for kind in CONTROLLERS}
    assert heights == {GAINS['common']['takeoff_height']}


def held_state(controller) -> np.ndarray:
    """What a kind adapts or integrates on x, y and the attitude: network weights, integrals, L1 estimates and
    INDI effectiveness (the z law and the filters may move on the ground)."""
    values = []
    laws = getattr(controller, 'laws', {})
    for axis in ('x', 'y', 'phi', 'theta', 'psi'):
        law = laws.get(axis)
        if law is None:
            continue
        network = getattr(law, 'network', None)
        if network is not None:
            values += [np.ravel(network.hidden_weights), np.ravel(network.output_weights)]
        if hasattr(law, 'integral'):
            values.append(np.ravel(law.integral))
    for name in ('estimate', 'compensation', 'effectiveness'):
        if hasattr(controller, name):
            values.append(np.ravel(getattr(controller, name)))
    if hasattr(controller, 'position_integral'):
        values += [np.ravel(controller.position_integral[:2]), np.ravel(controller.attitude_integral)]
    return np.concatenate(values) if values else np.zeros(0)


@pytest.mark.parametrize('kind, section, key, value', [
    ('l1-se3', 'l1_se3', 'predictor_pole_translation', 0.0),
    ('l1-se3', 'l1_se3', 'cutoff_rotation_hz', -1.0),
    ('l1-se3', 'l1_se3', 'cutoff_rotation_second_hz', -1.0),
    ('l1-se3', 'l1_se3', 'estimate_limit_translation', math.inf),
    ('indi', 'indi', 'rate_filter_hz', 0.0),
    ('indi', 'indi', 'effectiveness_rate', 2.0),
    ('indi', 'indi', 'effectiveness_min', 1.5),
    ('indi', 'indi', 'motor_time_constant', 'fast'),
])
def test_a_bad_adaptive_gain_is_refused_naming_it(kind, section, key, value):
    """An invalid l1_se3 or indi gain stops the build with a ParameterError naming it and its valid range."""
    gains = copy.deepcopy(GAINS)
    gains[section][key] = value
    with pytest.raises(ParameterError, match=rf'{section}\.{key}'):
        build_controller(kind, VEHICLE, gains)
