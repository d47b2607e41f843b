"""Vehicle parameters (paper Table I) and section IV disturbances: loading and validation."""
import math

import pytest
import yaml

from quad_msgs_bridge.vehicle_params import (DEFAULT_VEHICLE_FILE, Disturbance, ParameterError, VehicleParams,
                                             check_number, load_vehicle_file)


def default_document() -> dict:
    return yaml.safe_load(DEFAULT_VEHICLE_FILE.read_text())


def test_default_file_loads_with_derived_quantities():
    params, disturbances = load_vehicle_file()
    assert params.hover_force == pytest.approx(params.m * params.g / 4.0, rel=1e-15)
    assert params.yaw_coefficient == pytest.approx(params.Kd / params.Kp, rel=1e-15)
    # the rotors must be able to lift the vehicle with margin to manoeuvre
    assert 4.0 * params.F_max > params.m * params.g
    assert disturbances.enabled


def test_section_iv_disturbances():
    """Paper section IV: A_x = A_y = A_z = 0.126, A_psi = 0.008 sin(0.1 t), A_theta = A_phi = 0.004 sin(0.1 t)."""
    _, disturbances = load_vehicle_file()
    for t in (0.0, 1.3, 17.0, 42.5):
        a_x, a_y, a_z, a_phi, a_theta, a_psi = disturbances.at(t)
        assert (a_x, a_y, a_z) == (0.126, 0.126, 0.126)
        assert a_phi == pytest.approx(0.004 * math.sin(0.1 * t), abs=1e-15)
        assert a_theta == pytest.approx(0.004 * math.sin(0.1 * t), abs=1e-15)
        assert a_psi == pytest.approx(0.008 * math.sin(0.1 * t), abs=1e-15)
    off = disturbances.switched(False)
    assert off.at(3.0) == (0.0,) * 6
    assert off.switched(True).at(3.0) == disturbances.at(3.0)


def test_disturbance_channel():
    channel = Disturbance(bias=0.5, amplitude=2.0, omega=3.0)
    assert channel.at(0.7) == pytest.approx(0.5 + 2.0 * math.sin(2.1), rel=1e-15)


def test_file_round_trip(tmp_path):
    document = default_document()
    document['vehicle']['m'] = 0.75
    path = tmp_path / 'vehicle.yaml'
    path.write_text(yaml.safe_dump(document))
    params, _ = load_vehicle_file(path)
    assert params.m == 0.75


@pytest.mark.parametrize('name, value, fragment', [
    ('m', 0.0, 'vehicle.m'),
    ('m', -1.0, 'vehicle.m'),
    ('m', math.nan, 'vehicle.m'),
    ('m', math.inf, 'vehicle.m'),
    ('m', 'heavy', 'vehicle.m'),
    ('m', True, 'vehicle.m'),       # a YAML boolean is not a number
    ('d', 0.0, 'vehicle.d'),
    ('Iz', -3e-3, 'vehicle.Iz'),
    ('Kp', 0.0, 'vehicle.Kp'),
    ('Kd', -1e-7, 'vehicle.Kd'),
    ('Kfx', -1e-4, 'vehicle.Kfx'),
    ('Kfpsi', math.nan, 'vehicle.Kfpsi'),
    ('g', 0.0, 'vehicle.g'),
    ('F_min', -0.1, 'vehicle.F_min'),
    ('F_max', 0.0, 'vehicle.F_max'),         # not above F_min
    ('F_max', 1.0, 'vehicle.F_max'),         # 4 N < m g: cannot hover
    ('F_min', 1.3, 'vehicle.F_min'),         # 4 F_min > m g: cannot descend
])
def test_invalid_vehicle_parameter_is_named(name, value, fragment):
    values = default_document()['vehicle']
    values[name] = value
    with pytest.raises(ParameterError, match=fragment.replace('.', r'\.')):
        VehicleParams.from_mapping(values)


def test_missing_and_unknown_vehicle_keys_are_named():
    values = default_document()['vehicle']
    del values['Ix']
    with pytest.raises(ParameterError, match=r'vehicle\.Ix: missing'):
        VehicleParams.from_mapping(values)
    values = default_document()['vehicle']
    values['mass'] = 1.0
    with pytest.raises(ParameterError, match=r'vehicle\.mass: unknown'):
        VehicleParams.from_mapping(values)


@pytest.mark.parametrize('edit, fragment', [
    (lambda d: d.__setitem__('enabled', 'yes'), 'disturbances.enabled'),
    (lambda d: d['A_x'].__setitem__('bias', math.nan), 'disturbances.A_x.bias'),
    (lambda d: d['A_psi'].__setitem__('omega', -0.1), 'disturbances.A_psi.omega'),
    (lambda d: d['A_phi'].pop('amplitude'), 'disturbances.A_phi.amplitude'),
    (lambda d: d.pop('A_theta'), 'disturbances.A_theta'),
])
def test_invalid_disturbance_is_named(tmp_path, edit, fragment):
    document = default_document()
    edit(document['disturbances'])
    path = tmp_path / 'vehicle.yaml'
    path.write_text(yaml.safe_dump(document))
    with pytest.raises(ParameterError, match=fragment.replace('.', r'\.')):
        load_vehicle_file(path)


def test_unreadable_files_raise_parameter_error(tmp_path):
    with pytest.raises(ParameterError, match='vehicle file'):
        load_vehicle_file(tmp_path / 'absent.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('vehicle: [1, 2\n')
    with pytest.raises(ParameterError, match='not valid YAML'):
        load_vehicle_file(broken)
    empty = tmp_path / 'empty.yaml'
    empty.write_text('')
    with pytest.raises(ParameterError, match='vehicle: missing'):
        load_vehicle_file(empty)


def test_check_number_bounds():
    assert check_number('k', 0.0, 0.0) == 0.0
    with pytest.raises(ParameterError, match=r'k: 0.0 is outside the valid range \(0.0, 1.0\]'):
        check_number('k', 0.0, 0.0, 1.0, low_inclusive=False)
    with pytest.raises(ParameterError, match='k'):
        check_number('k', 1.5, 0.0, 1.0)
    assert isinstance(check_number('k', 3, 0.0), float)


@pytest.mark.parametrize('value, low, high, low_inclusive, message', [
    (math.inf, 0.0, math.inf, True, 'x: must be finite, got inf (valid range [0.0, inf))'),
    (math.nan, 0.0, math.inf, False, 'x: must be finite, got nan (valid range (0.0, inf))'),
    (-math.inf, -math.inf, math.inf, True, 'x: must be finite, got -inf'),
    (-1.0, 0.0, math.inf, False, 'x: -1.0 is outside the valid range (0.0, inf)'),
    (7.0, -math.inf, 5.0, True, 'x: 7.0 is outside the valid range (-inf, 5.0]'),
])
def test_range_errors_read_as_intervals(value, low, high, low_inclusive, message):
    """An infinite bound is an open end: never 'inf is outside the valid range (0.0, inf]'."""
    with pytest.raises(ParameterError) as error:
        check_number('x', value, low, high, low_inclusive=low_inclusive)
    assert str(error.value) == message
