"""The cascaded controller: eq. (10) as meant, input checks, rotor limits, building from the gains file."""
import copy
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nnit2fsmc_controller.axis_laws import AxisOutput, NNIT2FSMCLaw, PIDLaw, SlidingModeLaw
from nnit2fsmc_controller.controller import AXES, CascadedController, RateFilter, TiltLimit
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller, control_period, load_gains
from quad_msgs_bridge.frames import rotation_from_euler
from quad_msgs_bridge.mixer import controls_from_forces
from quad_msgs_bridge.reference import ReferenceSample, hold
from quad_msgs_bridge.state import DPHI, DPSI, DTHETA, VX, VY, VZ
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from vehicle_support import ASYMMETRIC, paper_eq1
from hang_guard import HANG_TIMEOUT_S

PARAMS, _ = load_vehicle_file()
GAINS = load_gains()


def realised_horizontal_acceleration(phi, theta, psi):
    """Horizontal acceleration [m/s^2] of eq. (1) when U1 is chosen to hold the vertical (specific force g)."""
    thrust_direction = np.array(rotation_from_euler(phi, theta, psi))[:, 2]
    return PARAMS.g * thrust_direction[:2] / thrust_direction[2]


@pytest.mark.parametrize('seed', range(12))
def test_eq10_attitude_realises_the_commanded_acceleration_at_any_heading(seed):
    rng = np.random.default_rng(seed)
    controller = build_controller('nnit2fsmc', PARAMS, GAINS)
    limit = PARAMS.g * math.tan(controller.tilt_limit.max_tilt)
    ax, ay = rng.uniform(-1.0, 1.0, 2) * limit / math.sqrt(2.0)   # inside the tilt limit
    psi = float(rng.uniform(-math.pi, math.pi))
    phi_d, theta_d = controller.attitude_from_accelerations(ax, ay, psi, 1.0)
    np.testing.assert_allclose(realised_horizontal_acceleration(phi_d, theta_d, psi), (ax, ay), atol=1e-12)


def test_eq10_small_angle_form_at_zero_yaw():
    """theta_d ~ v_x / g and phi_d ~ -v_y / g: the x law drives the pitch, the y law the roll."""
    controller = build_controller('nnit2fsmc', PARAMS, GAINS)
    phi_d, theta_d = controller.attitude_from_accelerations(0.01, 0.02, 0.0, 1.0)
    # the exact form differs from the linear one at second order: (0.02 / g)^2 ~ 4e-6 relative
    assert theta_d == pytest.approx(0.01 / PARAMS.g, rel=1e-4)
    assert phi_d == pytest.approx(-0.02 / PARAMS.g, rel=1e-4)


def tilt_of(phi, theta):
    """Angle [rad] between the thrust axis and the vertical."""
    return math.acos(math.cos(phi) * math.cos(theta))


@pytest.mark.parametrize('psi', [0.0, 1.0, -2.8])
@pytest.mark.parametrize('height, tilt', [(1.0, 0.8), (0.15, 0.8), (0.149, 0.6), (0.0, 0.6), (-0.01, 0.6)])
def test_eq10_tilt_limit_keeps_the_direction(psi, height, tilt):
    """The packaged limit: 0.8 rad from 0.15 m up, 0.6 rad below."""
    assert (GAINS['common']['max_tilt'], GAINS['common']['low_altitude_max_tilt'],
            GAINS['common']['low_altitude_height']) == (0.8, 0.6, 0.15)
    controller = build_controller('nnit2fsmc', PARAMS, GAINS)
    ax, ay = 30.0, -40.0          # 50 m/s^2: far beyond g tan(0.8)
    phi_d, theta_d = controller.attitude_from_accelerations(ax, ay, psi, height)
    realised = realised_horizontal_acceleration(phi_d, theta_d, psi)
    np.testing.assert_allclose(realised, np.array([ax, ay]) / 50.0 * PARAMS.g * math.tan(tilt), atol=1e-12)
    assert tilt_of(phi_d, theta_d) == pytest.approx(tilt, abs=1e-12)


@pytest.mark.parametrize('kind', [k for k in CONTROLLERS if k not in ('smc-sign', 'smc-sat')])
@pytest.mark.parametrize('height, tilt', [(1.0, 0.8), (0.1, 0.6)])
def test_every_controller_asks_for_the_tilt_limit_of_its_height(kind, height, tilt):
    """50 m off in x and y: the controller asks for the largest tilt, the limit at the vehicle's height (above the
    take-off height of 0.05 m every kind shares, so the x, y laws act). (The paper-style SMCs' switching gain,
    0.3 m/s^2, never reaches the limit.)"""
    far = ReferenceSample((50.0, 50.0, height), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)
    out = build_controller(kind, PARAMS, GAINS).update(0.0, [0.0, 0.0, height] + [0.0] * 9, far)
    phi_d, theta_d, _ = out.attitude_reference
    assert tilt_of(phi_d, theta_d) == pytest.approx(tilt, abs=1e-9)


def test_tilt_limit_batch_equals_single_vehicles_and_switches_off():
    limit = TiltLimit(0.8, 0.6, 0.15)
    heights = np.array([-1.0, 0.0, 0.1, 0.15, 7.0])
    np.testing.assert_array_equal(limit.tangent(heights), [limit.tangent(float(z)) for z in heights])
    np.testing.assert_array_equal(limit.tangent(heights), [math.tan(0.6)] * 3 + [math.tan(0.8)] * 2)
    for off in (TiltLimit(0.8, 0.6, 0.0), TiltLimit(0.8, 0.9, 0.15), TiltLimit(0.8)):
        assert off.tangent(0.0) == off.tangent(0.05) == math.tan(0.8)   # max_tilt at every height


def network_weights(controller):
    """Every network weight of the controller, axis by axis, as a tuple of floats (a copy)."""
    return tuple(w for law in controller.laws.values()
                 for w in [*np.ravel(law.network.hidden_weights).tolist(), *law.network.output_weights.tolist()])


@pytest.mark.parametrize('where', ['state', 'reference'])
@pytest.mark.parametrize('bad', [math.nan, math.inf])
def test_non_finite_input_is_refused_before_any_learning(where, bad):
    controller = build_controller('nnit2fsmc', PARAMS, GAINS)
    fresh = build_controller('nnit2fsmc', PARAMS, GAINS)
    state = [0.1, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    reference = hold((0.0, 0.0, 1.2))
    before = network_weights(controller)
    bad_state, bad_reference = list(state), reference
    if where == 'state':
        bad_state[7] = bad
    else:
        bad_reference = reference._replace(acceleration=(0.0, bad, 0.0))
    with pytest.raises(ValueError, match='non-finite'):
        controller.update(0.0, bad_state, bad_reference)
    assert network_weights(controller) == before
    # nothing else moved either (rate filters): the next valid update is that of a fresh controller
    assert controller.update(0.0, state, reference) == fresh.update(0.0, state, reference)


HOVER_STATE = [0.0, 0.0, 1.0] + [0.0] * 9
BAD_UPDATE_INPUTS = {   # (batch of the controller, t, state, reference) -> what the ValueError must say
    '(B, 12) state, single vehicle': (None, 0.0, np.zeros((4, 12)), hold((0.0, 0.0, 1.0)),
                                      r'state: expected 12 numbers .*got an array of shape \(4, 12\)'),
    '(12, B) state, single vehicle': (None, 0.0, np.zeros((12, 4)), hold((0.0, 0.0, 1.0)),
                                      r'state: a single-vehicle controller takes 12 numbers .*batch=B'),
    '11-value state': (None, 0.0, HOVER_STATE[:11], hold((0.0, 0.0, 1.0)),
                       r'state: expected 12 numbers \(x, y, z \[m, world ENU\].*got 11 values'),
    'state not a sequence': (None, 0.0, 1.0, hold((0.0, 0.0, 1.0)), r'state: expected a sequence of 12 values'),
    'batch of the wrong length': (3, 0.0, [np.full(4, v) for v in HOVER_STATE], hold((0.0, 0.0, 1.0)),
                                  r'state: a controller of a batch of 3 vehicles takes 12 arrays of 3 values '
                                  r'\(shape \(12, 3\)\), got an array of shape \(4,\)'),
    'floats for a batch': (3, 0.0, HOVER_STATE, hold((0.0, 0.0, 1.0)), r'state: .*batch of 3 .*got a number'),
    'non-finite time': (None, math.nan, HOVER_STATE, hold((0.0, 0.0, 1.0)), r't: the time must be finite'),
    'time not a number': (None, '0.1', HOVER_STATE, hold((0.0, 0.0, 1.0)), r't: expected a number of seconds, got str'),
    'reference a tuple': (None, 0.0, HOVER_STATE, ((0.0, 0.0, 1.0), (0, 0, 0), (0, 0, 0), 0.0),
                          r'reference: expected a quad_msgs_bridge\.reference\.ReferenceSample, got tuple'),
}


@pytest.mark.parametrize('kind', ['nnit2fsmc', 'pid', 'se3'])
@pytest.mark.parametrize('case', BAD_UPDATE_INPUTS)
def test_bad_update_arguments_are_refused_naming_the_argument(kind, case):
    batch, t, state, reference, message = BAD_UPDATE_INPUTS[case]
    controller = build_controller(kind, PARAMS, GAINS, batch=batch)
    fresh = build_controller(kind, PARAMS, GAINS, batch=batch)
    with pytest.raises(ValueError, match=message):
        controller.update(t, state, reference)
    good = HOVER_STATE if batch is None else [np.full(batch, v) for v in HOVER_STATE]
    first, untouched = controller.update(0.0, good, hold((0.0, 0.0, 1.0))), fresh.update(0.0, good, hold((0.0, 0.0, 1.0)))
    np.testing.assert_array_equal(np.asarray(first.forces), np.asarray(untouched.forces))   # nothing moved


def test_a_batch_of_12_vehicles_as_a_12_by_12_array_flies():
    """(12, B) is the batch layout; with B = 12 the shape alone is ambiguous, and a batch controller takes it."""
    controller = build_controller('pid', PARAMS, GAINS, batch=12)
    state = np.tile(np.array(HOVER_STATE)[:, None], (1, 12))
    out = controller.update(0.0, state, hold((0.0, 0.0, 1.0)))
    assert np.shape(out.forces) == (4, 12) and np.isfinite(out.forces).all()


def wild_input(rng):
    """A state far from any equilibrium and an unrelated reference, as plain floats."""
    state = [*rng.normal(0, 3, 6), *rng.uniform(-1.0, 1.0, 2), rng.uniform(-math.pi, math.pi), *rng.normal(0, 5, 3)]
    reference = ReferenceSample(tuple(map(float, rng.normal(0, 3, 3))), tuple(map(float, rng.normal(0, 2, 3))),
                                tuple(map(float, rng.normal(0, 5, 3))), float(rng.uniform(-math.pi, math.pi)))
    return [float(v) for v in state], reference


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_numpy_scalars_are_accepted_like_floats(kind):
    """A node may hand over numpy float64 values (message arrays); the result must not change."""
    rng = np.random.default_rng(4)
    plain, as_numpy = build_controller(kind, PARAMS, GAINS), build_controller(kind, PARAMS, GAINS)
    for k in range(20):
        state, reference = wild_input(rng)
        expected = plain.update(k * 1e-3, state, reference)
        got = as_numpy.update(k * 1e-3, list(np.array(state)), reference)
        np.testing.assert_allclose(got.forces, expected.forces, rtol=0, atol=1e-15)


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_every_kind_builds_and_keeps_rotor_forces_within_limits(kind):
    controller = build_controller(kind, PARAMS, GAINS)
    assert controller.name == kind
    assert controller.dt == control_period(GAINS)
    rng = np.random.default_rng(1)
    for k in range(300):
        state, reference = wild_input(rng)
        out = controller.update(k * controller.dt, state, reference)
        assert set(out.axes) == set(AXES)     # per-subsystem diagnostics for the recording and the review
        assert all(PARAMS.F_min <= f <= PARAMS.F_max for f in out.forces)
        np.testing.assert_allclose(out.controls, controls_from_forces(*out.forces, PARAMS.mixer),
                                   atol=1e-15)
        assert all(math.isfinite(a.value) for a in out.axes.values())


@pytest.mark.parametrize('params', [PARAMS, ASYMMETRIC], ids=['paper', 'asymmetric'])
@pytest.mark.parametrize('kind', ['smc-sign', 'smc-sat', 'smc-integral', 'pid', 'se3'])
@pytest.mark.parametrize('yaw', [0.0, 2.0])
def test_model_based_controllers_command_the_hover_forces_at_equilibrium(kind, yaw, params):
    controller = build_controller(kind, params, GAINS)
    state = [0.5, -1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, yaw, 0.0, 0.0, 0.0]
    out = controller.update(0.0, state, hold((0.5, -1.0, 2.0), yaw))
    np.testing.assert_allclose(out.forces, (params.hover_force,) * 4, rtol=1e-14)


def test_nnit2fsmc_starts_knowing_nothing():
    """The network starts at zero and the fuzzy term is zero on the surface: the thrust must be learned."""
    controller = build_controller('nnit2fsmc', PARAMS, GAINS)
    out = controller.update(0.0, [0.0, 0.0, 1.0] + [0.0] * 9, hold((0.0, 0.0, 1.0)))
    assert out.forces == (0.0, 0.0, 0.0, 0.0)
    assert all(isinstance(law, NNIT2FSMCLaw) for law in controller.laws.values())


@pytest.mark.parametrize('batch', [None, 3])
def test_acceleration_feedforward_adds_the_reference_acceleration_to_x_and_y_only(batch):
    """nnit2fsmc.acceleration_feedforward: the x and y laws answer x_d'' + U_eq_hat + U_fuzzy (their virtual
    control is the acceleration itself, so no vehicle parameter enters), with the same network and fuzzy terms;
    z and psi, whose virtual controls are a thrust and a moment, are unchanged; false is the paper's law."""
    state = [0.1, -0.2, 1.1, 0.3, 0.0, -0.1, 0.02, -0.01, 0.1, 0.0, 0.1, 0.0]
    if batch is not None:
        state = [np.full(batch, value) for value in state]
    reference = ReferenceSample((0.0, 0.0, 1.0), (0.5, 0.0, 0.1), (0.7, -0.4, 0.3), 0.0)
    outputs = {}
    for feedforward in (True, False):
        gains = edited('nnit2fsmc.acceleration_feedforward', feedforward)
        controller = build_controller('nnit2fsmc', PARAMS, gains, batch=batch)
        for step in range(3):   # the networks learn from the first update on, the same way in both
            out = controller.update(0.001 * step, state, reference)
            controller.adapt()
        outputs[feedforward] = out.axes
    on, off = outputs[True], outputs[False]
    for axis, acceleration in (('x', 0.7), ('y', -0.4)):
        np.testing.assert_allclose(on[axis].value - off[axis].value, acceleration, rtol=1e-12)
        np.testing.assert_array_equal(on[axis].equivalent, off[axis].equivalent)
        np.testing.assert_array_equal(on[axis].corrective, off[axis].corrective)
    for axis in ('z', 'psi'):
        np.testing.assert_array_equal(on[axis].value, off[axis].value)


@pytest.mark.parametrize('spread', [0.25, 1.0, 3.0])
def test_initial_hidden_weights_are_seeded_within_the_spread(spread):
    """nnit2fsmc.initial_weight_spread: every subsystem network starts with hidden weights drawn from
    U(-spread, spread) by its seed (the same draw scaled), and output weights zero (it knows nothing)."""
    gains = edited('nnit2fsmc.initial_weight_spread', spread)
    unit = build_controller('nnit2fsmc', PARAMS, edited('nnit2fsmc.initial_weight_spread', 1.0))
    controller = build_controller('nnit2fsmc', PARAMS, gains)
    for axis in AXES:
        network = controller.laws[axis].network
        assert np.abs(network.hidden_weights).max() <= spread
        np.testing.assert_allclose(network.hidden_weights, spread * unit.laws[axis].network.hidden_weights, rtol=1e-12)
        assert not network.output_weights.any()


class SpyLaw:
    """Records what the cascade hands a law and answers a fixed virtual control."""

    def __init__(self, value):
        self.value, self.calls = value, []

    def update(self, e, de, ref_vel, ref_acc, drift, gain):
        self.calls.append((e, de, ref_vel, ref_acc, drift, gain))
        return AxisOutput(self.value, de, self.value, 0.0)


@pytest.mark.parametrize('params', [PARAMS, ASYMMETRIC], ids=['paper', 'asymmetric'])
def test_nominal_model_of_the_baselines_is_eq1(params):
    """q'' = drift + gain * v, as the cascade hands it to each law, is eq. (1) written out in the test
    (vehicle_support.paper_eq1), on the paper's vehicle and on one with every inertia and drag different.

    z, phi, theta, psi: drift + gain * v is the acceleration the realised U1..U4 give. x, y: v is an
    acceleration (gain 1) and the drift is the acceleration of eq. (1) without thrust (the drag).
    """
    values = {'x': 0.0, 'y': 0.0, 'z': 5.1, 'phi': 0.05, 'theta': -0.04, 'psi': 0.002}
    laws = {axis: SpyLaw(v) for axis, v in values.items()}
    controller = CascadedController('spy', params, laws, dt=1e-3)
    state = [0.1, 0.2, 1.5, 0.3, -0.2, 0.1, 0.1, -0.05, 0.4, 0.5, -0.7, 0.9]
    out = controller.update(0.0, state, hold((0.0, 0.0, 1.5), 0.4))
    # inside the rotor limits, so the U1..U4 asked for are realised exactly
    assert all(params.F_min < f < params.F_max for f in out.forces), out.forces
    np.testing.assert_allclose(out.controls, [values['z'], values['phi'], values['theta'], values['psi']],
                               atol=1e-12)
    calm = (0.0,) * 6
    driven, unpowered = paper_eq1(params, state, out.controls, calm), paper_eq1(params, state, (0.0,) * 4, calm)
    for axis, index, expected in (('x', VX, unpowered[VX]), ('y', VY, unpowered[VY]), ('z', VZ, driven[VZ]),
                                  ('phi', DPHI, driven[DPHI]), ('theta', DTHETA, driven[DTHETA]),
                                  ('psi', DPSI, driven[DPSI])):
        *_, drift, gain = laws[axis].calls[0]
        assert drift + gain * values[axis] == pytest.approx(expected, rel=1e-12, abs=1e-15), axis
    assert [laws[axis].calls[0][-1] for axis in ('x', 'y')] == [1.0, 1.0]


def test_yaw_error_is_wrapped():
    laws = {axis: SpyLaw(0.0) for axis in AXES}
    controller = CascadedController('spy', PARAMS, laws, dt=1e-3)
    state = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.1, 0.0, 0.0, 0.0]
    controller.update(0.0, state, hold((0.0, 0.0, 1.0), -3.1))
    e_psi = laws['psi'].calls[0][0]
    assert e_psi == pytest.approx(6.2 - 2 * math.pi, abs=1e-12)   # -0.083 rad, not 6.2 rad


def test_rate_filter_follows_a_ramp():
    rate_filter = RateFilter(dt=1e-3, tau=0.02)
    for k in range(1000):
        rate = rate_filter.update(0.3 * k * 1e-3)
    assert rate == pytest.approx(0.3, rel=1e-9)   # first-order lag: error decays as exp(-t/tau)


def test_missing_law_is_refused():
    with pytest.raises(ValueError, match='psi'):
        CascadedController('partial', PARAMS, {axis: SpyLaw(0.0) for axis in AXES[:5]}, dt=1e-3)


def edited(dotted, value):
    gains = copy.deepcopy(GAINS)
    *path, last = dotted.split('.')
    node = gains
    for key in path:
        node = node[key]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return gains


@pytest.mark.parametrize('kind, dotted, value, fragment', [
    ('nnit2fsmc', 'common.control_rate', 0.0, 'common.control_rate'),
    ('nnit2fsmc', 'common.lambda.z', -3.0, 'common.lambda.z'),
    ('pid', 'common.lambda.psi', math.nan, 'common.lambda.psi'),
    ('nnit2fsmc', 'common.max_tilt', 2.0, 'max_tilt'),
    ('pid', 'common.low_altitude_max_tilt', 0.0, 'common.low_altitude_max_tilt'),
    ('se3', 'common.low_altitude_height', -0.1, 'common.low_altitude_height'),
    ('nnit2fsmc', 'common.low_altitude_height', KeyError, 'common.low_altitude_height'),
    ('smc-sat', 'common.angle_filter_tau', 0.0, 'common.angle_filter_tau'),
    ('nnit2fsmc', 'nnit2fsmc.axes.x.input_scale', 0.0, 'nnit2fsmc.axes.x.input_scale'),
    ('nnit2fsmc', 'nnit2fsmc.axes.theta.fuzzy_gain', -1.0, 'nnit2fsmc.axes.theta.fuzzy_gain'),
    ('nnit2fsmc', 'nnit2fsmc.axes.z.nn_gain', 0.0, 'nnit2fsmc.axes.z.nn_gain'),
    ('nnit2fsmc', 'nnit2fsmc.axes.psi.learning_rate', 'fast', 'nnit2fsmc.axes.psi.learning_rate'),
    ('nnit2fsmc', 'nnit2fsmc.axes.y', KeyError, 'nnit2fsmc.axes.y'),
    ('nnit2fsmc', 'nnit2fsmc.lower_height', 1.5, 'lower_height'),
    ('nnit2fsmc', 'nnit2fsmc.type_reducer', 'centroid', 'type_reducer'),
    ('nnit2fsmc', 'nnit2fsmc.weight_limit', 0.0, 'nnit2fsmc.weight_limit'),
    ('nnit2fsmc', 'nnit2fsmc.acceleration_feedforward', 1, 'nnit2fsmc.acceleration_feedforward: expected true or false'),
    ('nnit2fsmc', 'nnit2fsmc.initial_weight_spread', 0.0, 'nnit2fsmc.initial_weight_spread'),
    ('nnit2fsmc', 'nnit2fsmc.acceleration_feedforward', KeyError, 'nnit2fsmc.acceleration_feedforward: missing'),
    ('smc-sign', 'smc.switching_gain.phi', -5.0, 'smc.switching_gain.phi'),
    ('smc-sat', 'smc.boundary_layer.x', 0.0, 'smc.boundary_layer.x'),
    ('pid', 'pid.axes.z.kp', -9.0, 'pid.axes.z.kp'),
    ('pid', 'pid.axes.phi.integral_limit', math.inf, 'pid.axes.phi.integral_limit'),
])
def test_invalid_gains_are_named(kind, dotted, value, fragment):
    with pytest.raises(ParameterError, match=fragment.replace('.', r'\.')):
        build_controller(kind, PARAMS, edited(dotted, value))


@pytest.mark.parametrize('kind', ['nnit2fsmc', 'pid'])
def test_unknown_gain_is_refused_with_the_closest_name(kind):
    gains = edited('common.max_tlit', 0.3)
    with pytest.raises(ParameterError, match=r'common\.max_tlit: unknown gain \(did you mean common\.max_tilt\?\)'):
        build_controller(kind, PARAMS, gains)
    gains = edited('nnit2fsmc.axes.phi.learnig_rate', 5.0)
    with pytest.raises(ParameterError, match=r'nnit2fsmc\.axes\.phi\.learnig_rate: unknown gain '
                                             r'\(did you mean nnit2fsmc\.axes\.phi\.learning_rate\?\)'):
        build_controller(kind, PARAMS, gains)


def test_missing_gain_names_the_close_unknown_key():
    from nnit2fsmc_controller.factory import control_period as period   # reads common.control_rate
    gains = copy.deepcopy(GAINS)
    gains['common']['control_rat'] = gains['common'].pop('control_rate')
    with pytest.raises(ParameterError, match=r'common\.control_rate: missing \(did you mean common\.control_rat\?\)'):
        period(gains)
    del gains['common']['control_rat']
    with pytest.raises(ParameterError, match=r'common\.control_rate: missing$'):
        period(gains)


def test_gains_file_with_an_unknown_key_is_refused_naming_the_file(tmp_path):
    from nnit2fsmc_controller.factory import DEFAULT_CONTROLLER_FILE
    path = tmp_path / 'gains.yaml'
    path.write_text(DEFAULT_CONTROLLER_FILE.read_text().replace('max_tilt: 0.8 ', 'max_tlit: 0.3 ', 1))
    with pytest.raises(ParameterError, match=f'controller file {path}: common.max_tlit: unknown gain '
                                             r'\(did you mean common\.max_tilt\?\)'):
        load_gains(path)


def test_unknown_controller_kind_is_named():
    with pytest.raises(ParameterError, match="controller: 'lqr'"):
        build_controller('lqr', PARAMS, GAINS)


def test_unreadable_gains_files(tmp_path):
    with pytest.raises(ParameterError, match='controller file'):
        load_gains(tmp_path / 'absent.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('common: {control_rate: [\n')
    with pytest.raises(ParameterError, match='not valid YAML'):
        load_gains(broken)
    scalar = tmp_path / 'scalar.yaml'
    scalar.write_text('42\n')
    with pytest.raises(ParameterError, match='expected a mapping'):
        load_gains(scalar)


def test_law_classes_validate_lambda():
    for make in (lambda: SlidingModeLaw(0.0, 1.0), lambda: PIDLaw(-1.0, 1, 1, 1, 1, 1e-3)):
        with pytest.raises(ParameterError, match='lambda'):
            make()


def test_sign_and_saturated_switching():
    sign = SlidingModeLaw(2.0, 1.0)
    assert [sign.switching(s) for s in (-0.5, 0.0, 1e-12)] == [-1, 0, 1]
    saturated = SlidingModeLaw(2.0, 1.0, boundary_layer=0.1)
    assert [saturated.switching(s) for s in (-1.0, -0.05, 0.0, 0.02, 3.0)] == pytest.approx([-1, -0.5, 0, 0.2, 1])


def test_adapt_only_moves_the_learning_step():
    """Taking the learning with adapt() right after an update (the node does, after sending the forces)
    gives the same flight as leaving it to the next update; and the step is really taken by adapt()."""
    rng = np.random.default_rng(11)
    deferred, eager = build_controller('nnit2fsmc', PARAMS, GAINS), build_controller('nnit2fsmc', PARAMS, GAINS)
    state = [0.02, -0.01, 0.99, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    reference = hold((0.0, 0.0, 1.0))
    for k in range(200):
        noisy = [v + float(rng.normal(0.0, 1e-3)) for v in state]
        expected = deferred.update(k * 1e-3, noisy, reference)
        got = eager.update(k * 1e-3, noisy, reference)
        assert got == expected
        before = network_weights(eager)
        eager.adapt()
        if any(abs(a.surface) < deferred.laws[axis].fuzzy.input_scale for axis, a in got.axes.items()):
            assert network_weights(eager) != before, f'step {k}: adapt() learned nothing'
        learned = network_weights(eager)
        eager.adapt()                                  # a second call has nothing left to learn
        assert network_weights(eager) == learned
    assert network_weights(eager) != network_weights(deferred)   # eager is one learning step ahead
    deferred.adapt()
    assert network_weights(eager) == network_weights(deferred)


COMPILED_KERNELS = '''
import json, sys
sys.path[:0] = sys.argv[1:]
from nnit2fsmc_controller.factory import compile_kernels, load_gains
from nnit2fsmc_controller.controller import cascade_step
from nnit2fsmc_controller.neural_network import learning_step
from quad_msgs_bridge.frames import _quaternion
from quad_msgs_bridge.reference import _quintic_channels
from quad_msgs_bridge.state import _state_fields
from quad_msgs_bridge.vehicle_params import load_vehicle_file
kernels = (_state_fields, _quintic_channels, cascade_step, learning_step, _quaternion)
before = [len(kernel.signatures) for kernel in kernels]
compile_kernels('nnit2fsmc', load_vehicle_file()[0], load_gains())
print(json.dumps([before, [len(kernel.signatures) for kernel in kernels]]))
'''


def test_compile_kernels_builds_every_kernel_of_a_single_vehicle_before_its_first_update():
    """What the ROS controller node runs before subscribing: afterwards the first answer (odometry, path
    sample, update, learning step, reference pose) needs no compiling."""
    root = Path(__file__).resolve().parent.parent
    paths = [str(root / 'ros2_ws' / 'src' / package) for package in ('quad_msgs_bridge', 'nnit2fsmc_controller')]
    result = subprocess.run([sys.executable, '-c', COMPILED_KERNELS, *paths], capture_output=True, text=True,
                            timeout=HANG_TIMEOUT_S, check=True)
    before, after = json.loads(result.stdout)
    assert before == [0] * 5 and all(count >= 1 for count in after)
