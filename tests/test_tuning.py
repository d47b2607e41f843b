"""Gains changed in flight: validated, applied from the next update, and the learned state kept."""
import copy
import inspect

import numpy as np
import pytest

import nnit2fsmc_controller
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller, build_measurement_stage, load_gains
from nnit2fsmc_controller.tuning import has_state, retune, retune_measurement
from quad_msgs_bridge.reference import ReferenceSample
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, _ = load_vehicle_file()
REFERENCE = ReferenceSample((1.0, 0.0, 1.0), (0.0, 0.5, 0.1), (-0.25, 0.0, 0.0), 0.3, 0.5, 0.0)


def states(count, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield [1.0, 0.0, 1.0, *rng.normal(0, 0.05, 3), *rng.normal(0, 0.02, 3), *rng.normal(0, 0.1, 3)]


def fly(controller, count, seed=0):
    return [controller.update(k * controller.dt, state, REFERENCE) for k, state in enumerate(states(count, seed))]


def parts(controller):
    """Every object of the controller package reachable from the controller."""
    found, stack = [], [controller]
    while stack:
        value = stack.pop()
        if type(value).__module__.startswith(nnit2fsmc_controller.__name__):
            found.append(value)
            stack.extend(vars(value).values())
        elif isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, (list, tuple)):
            stack.extend(v for v in value if hasattr(v, '__dict__'))
    return found


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_every_part_of_every_controller_declares_its_state(kind):
    """A part without STATE would have its state silently reset by a retune."""
    for part in parts(build_controller(kind, PARAMS, load_gains())):
        assert has_state(part), type(part).__name__


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_retuning_to_the_same_gains_changes_nothing(kind):
    gains = load_gains()
    running, untouched = build_controller(kind, PARAMS, gains), build_controller(kind, PARAMS, gains)
    fly(running, 50), fly(untouched, 50)
    retuned = retune(running, copy.deepcopy(gains))
    for a, b in zip(fly(retuned, 30, seed=1), fly(untouched, 30, seed=1)):
        assert a.forces == b.forces


def test_a_new_lambda_applies_from_the_next_update_and_the_network_keeps_what_it_learned():
    gains = load_gains()
    running = build_controller('nnit2fsmc', PARAMS, gains)
    fly(running, 200)
    learned = copy.deepcopy(running.laws['z'].network.output_weights)
    assert any(w != 0.0 for w in learned)                     # it did learn
    changed = copy.deepcopy(gains)
    changed['common']['lambda']['z'] = 2 * gains['common']['lambda']['z']
    retuned = retune(running, changed)
    np.testing.assert_array_equal(retuned.laws['z'].network.output_weights, learned)
    assert retuned.laws['z'].lam == 2 * running.laws['z'].lam
    e, de = 0.01, -0.02
    out = retuned.laws['z'].update(e, de, 0.1, 0.0, 0.0, 1.0)
    assert out.surface == pytest.approx(de + retuned.laws['z'].lam * e)


def test_pid_integral_survives_a_gain_change():
    gains = load_gains()
    running = build_controller('pid', PARAMS, gains)
    fly(running, 100)
    integral = running.laws['psi'].integral
    assert integral != 0.0
    changed = copy.deepcopy(gains)
    changed['pid']['axes']['psi']['kp'] = 2.0 * gains['pid']['axes']['psi']['kp']
    assert retune(running, changed).laws['psi'].integral == integral


@pytest.mark.parametrize('dotted, value, fragment', [
    ('common.lambda.z', -1.0, 'common.lambda.z'),
    ('nnit2fsmc.axes.x.learning_rate', -0.1, 'nnit2fsmc.axes.x.learning_rate'),
    ('nnit2fsmc.type_reducer', 'kmx', 'type_reducer'),
    ('common.control_rate', 500.0, 'common.control_rate: cannot change in flight'),
    ('nnit2fsmc.hidden_units', 7, 'restart'),
])
def test_invalid_or_restart_only_changes_are_refused_and_the_controller_is_untouched(dotted, value, fragment):
    gains = load_gains()
    running = build_controller('nnit2fsmc', PARAMS, gains)
    fly(running, 20)
    before = copy.deepcopy(running.laws['x'].network.hidden_weights)
    changed = copy.deepcopy(gains)
    node = changed
    *path, leaf = dotted.split('.')
    for key in path:
        node = node[key]
    node[leaf] = value
    with pytest.raises(ParameterError, match=fragment.replace('.', r'\.')):
        retune(running, changed)
    np.testing.assert_array_equal(running.laws['x'].network.hidden_weights, before)


def test_a_batch_controller_is_retuned_vehicle_by_vehicle():
    gains = load_gains()
    running = build_controller('nnit2fsmc', PARAMS, gains, batch=3)
    states_batch = [np.array(column) for column in zip(*states(3))]
    for k in range(20):
        running.update(k * running.dt, states_batch, REFERENCE)
    weights = running.laws['y'].network.hidden_weights.copy()
    retuned = retune(running, gains, batch=3)
    np.testing.assert_array_equal(retuned.laws['y'].network.hidden_weights, weights)


def test_tuning_module_is_documented():
    from nnit2fsmc_controller import tuning
    assert 'STATE' in inspect.getdoc(tuning)


def test_a_retuned_measurement_stage_keeps_its_filter_estimates():
    """Retuning the measurement stage to the same gains continues exactly as the running stage; a new
    crossover applies from the next sample with the estimate carried; a filter switched on starts afresh."""
    gains = load_gains()
    running, untouched = build_measurement_stage(gains), build_measurement_stage(gains)
    for state in states(50):
        running(state), untouched(state)
    retuned = retune_measurement(running, copy.deepcopy(gains))
    for state in states(20, seed=1):
        assert retuned(state) == untouched(state)
    faster = copy.deepcopy(gains)
    faster['common']['measurement_filter_hz'] = 20.0
    assert retune_measurement(retuned, faster).complementary._estimate == retuned.complementary._estimate
    off = copy.deepcopy(gains)
    off['common']['velocity_filter_hz'] = 0.0
    switched = retune_measurement(retune_measurement(retuned, off), gains)
    assert switched.velocity._velocity is None
    off['common']['velocity_filter_hz'] = -1.0
    with pytest.raises(ParameterError, match='velocity_filter_hz'):
        retune_measurement(retuned, off)
