"""Vehicle parameters (paper Table I) and section IV disturbances: loading and validation."""
import dataclasses
import json
import math
import re

import numpy as np
import pytest
import yaml

from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import (DEFAULT_VEHICLE_FILE, Disturbance, Disturbances, VehicleParams,
                                             load_vehicle_file)


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
    """Each channel is bias + amplitude sin(omega t), in the order A_x .. A_psi."""
    channels = [Disturbance(bias=0.1 * k, amplitude=2.0 + k, omega=3.0 - 0.5 * k) for k in range(6)]
    values = Disturbances(True, *channels).at(0.7)
    assert values == pytest.approx([0.1 * k + (2.0 + k) * math.sin((3.0 - 0.5 * k) * 0.7) for k in range(6)],
                                   rel=1e-15)


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


# --- the true-vehicle entries (optional) and batches of vehicles ---------------------------------

def test_perturbation_entries_are_optional_and_default_to_an_unperturbed_vehicle(tmp_path):
    document = default_document()
    for key in ('cog_offset', 'rotor_thrust_factors', 'rotor_drag_factors', 'rotor_efficiency_loss', 'wind_drag'):
        del document['vehicle'][key]
    path = tmp_path / 'old.yaml'
    path.write_text(yaml.safe_dump(document))
    params, _ = load_vehicle_file(path)
    assert params == load_vehicle_file()[0]
    assert params.cog_offset == (0.0, 0.0, 0.0)
    assert params.rotor_thrust_factors == params.rotor_drag_factors == (1.0, 1.0, 1.0, 1.0)
    assert params.rotor_efficiency_loss == (0.0, 0.0, 0.0, 0.0)


def test_perturbation_entries_are_read(tmp_path):
    document = default_document()
    document['vehicle'].update(cog_offset=[0.01, -0.02, 0], rotor_thrust_factors=[1.1, 1, 0.9, 1],
                               rotor_efficiency_loss=[0, 0.25, 0, 0], wind_drag=0.3)
    path = tmp_path / 'true.yaml'
    path.write_text(yaml.safe_dump(document))
    params, _ = load_vehicle_file(path)
    assert params.cog_offset == (0.01, -0.02, 0.0)
    assert params.rotor_thrust_factors == (1.1, 1.0, 0.9, 1.0)
    assert params.rotor_efficiency_loss == (0.0, 0.25, 0.0, 0.0)
    assert params.wind_drag == 0.3
    assert all(type(v) is float for v in (*params.cog_offset, *params.rotor_thrust_factors))


def test_json_round_trip_of_a_perturbed_vehicle():
    """Bags and summaries store dataclasses.asdict(params) as JSON; it must load back identically."""
    params = dataclasses.replace(load_vehicle_file()[0], cog_offset=(0.01, 0.0, -0.01),
                                 rotor_drag_factors=(1.0, 1.1, 0.9, 1.0))
    assert VehicleParams.from_mapping(json.loads(json.dumps(dataclasses.asdict(params)))) == params


@pytest.mark.parametrize('name, value, fragment', [
    ('cog_offset', [0.0, 0.0], r'vehicle\.cog_offset: expected a list of 3'),
    ('cog_offset', 0.01, r'vehicle\.cog_offset: expected a list of 3'),
    ('cog_offset', [0.0, math.nan, 0.0], r'vehicle\.cog_offset\[1\]'),
    ('cog_offset', [0.3, 0.0, 0.0], r'vehicle\.cog_offset: x = 0\.3 m is not within the arm length'),
    ('rotor_thrust_factors', [1.0, 1.0, 0.0, 1.0],
     r'vehicle\.rotor_thrust_factors\[2\]: 0\.0 is outside the valid range \(0\.0, inf\)'),
    ('rotor_thrust_factors', [1.0, 1.0, 1.0], r'vehicle\.rotor_thrust_factors: expected a list of 4'),
    ('rotor_thrust_factors', 'strong', r'vehicle\.rotor_thrust_factors: expected a list of 4'),
    ('rotor_drag_factors', [1.0, -1.0, 1.0, 1.0], r'vehicle\.rotor_drag_factors\[1\]'),
    ('rotor_efficiency_loss', [0.0, 0.0, 0.0, 1.0],
     r'vehicle\.rotor_efficiency_loss\[3\]: 1\.0 is outside the valid range \[0\.0, 1\.0\)'),
    ('rotor_efficiency_loss', [-0.1, 0.0, 0.0, 0.0], r'vehicle\.rotor_efficiency_loss\[0\]'),
    ('rotor_efficiency_loss', [0.0, True, 0.0, 0.0], r'vehicle\.rotor_efficiency_loss\[1\]: expected a number'),
    ('wind_drag', -0.1, r'vehicle\.wind_drag'),
    ('wind_drag', math.inf, r'vehicle\.wind_drag'),
])
def test_invalid_perturbation_entry_is_named(name, value, fragment):
    values = default_document()['vehicle']
    values[name] = value
    with pytest.raises(ParameterError, match=fragment):
        VehicleParams.from_mapping(values)


def test_stack_makes_a_batch_with_one_element_per_vehicle():
    params = load_vehicle_file()[0]
    vehicles = [dataclasses.replace(params, m=(0.4, 0.5, 0.6)[i], cog_offset=(0.001 * i, 0.0, 0.0),
                                    rotor_efficiency_loss=(0.0, 0.01 * i, 0.0, 0.0)) for i in range(3)]
    batch = VehicleParams.stack(vehicles)
    np.testing.assert_array_equal(batch.m, [0.4, 0.5, 0.6])
    np.testing.assert_array_equal(batch.cog_offset[0], [0.0, 0.001, 0.002])
    np.testing.assert_array_equal(batch.rotor_efficiency_loss[1], [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(batch.Ix, [params.Ix] * 3)
    np.testing.assert_allclose(batch.hover_force, [0.4 * 9.81 / 4, 0.5 * 9.81 / 4, 0.6 * 9.81 / 4], rtol=1e-15)
    with pytest.raises(ParameterError, match='vehicles'):
        VehicleParams.stack([])


@pytest.mark.parametrize('changes, fragment', [
    ({'m': np.array([0.5, -0.5, 0.4])}, r'vehicle\.m \(vehicle 1\): -0\.5 is outside'),
    ({'Iz': np.array([7e-3, np.nan])}, r'vehicle\.Iz \(vehicle 1\)'),
    ({'m': np.array([0.5, 0.5]), 'Ix': np.array([3e-3, 3e-3, 3e-3])},
     r'vehicle\.Ix: 3 vehicles, but vehicle\.m has 2'),
    ({'m': np.array([[0.5, 0.5]])}, r'vehicle\.m: expected a number or a 1-D numeric array'),
    ({'m': np.array([True, False])}, r'vehicle\.m: expected a number or a 1-D numeric array'),
    ({'rotor_efficiency_loss': (0.0, np.array([0.0, 1.2]), 0.0, 0.0)},
     r'vehicle\.rotor_efficiency_loss\[1\] \(vehicle 1\)'),
    ({'m': np.array([0.4, 1.3])}, r'vehicle\.F_max: 2\.6818 N cannot hover the vehicle.*\(vehicle 1\)'),
    ({'cog_offset': (np.array([0.0, 0.0, 0.26]), 0.0, 0.0)}, r'vehicle\.cog_offset: x = 0\.26 m .*\(vehicle 2\)'),
])
def test_batch_values_are_checked_per_vehicle(changes, fragment):
    with pytest.raises(ParameterError, match=fragment):
        dataclasses.replace(load_vehicle_file()[0], **changes)


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


def test_vehicle_file_takes_yaml_1_2_floats(tmp_path):
    """Issue 35: `Kp: 3e-5` and `m: 1.0e30` are numbers (YAML 1.1 read them as strings: 'expected a number')."""
    text = DEFAULT_VEHICLE_FILE.read_text()
    path = tmp_path / 'vehicle.yaml'
    path.write_text(re.sub(r'(?m)^  Kp: \S+', '  Kp: 3e-5', text))
    assert yaml.safe_load(path.read_text())['vehicle']['Kp'] == '3e-5'     # a string by YAML 1.1
    assert load_vehicle_file(path)[0].Kp == 3e-5
    path.write_text(re.sub(r'(?m)^  m: \S+', '  m: 1.0e30', text))
    with pytest.raises(ParameterError, match=r'vehicle\.F_max: .* cannot hover the vehicle of mass m = 1e\+30 kg'):
        load_vehicle_file(path)


@pytest.mark.parametrize('written, value', [
    ('3e-5', 3e-5), ('1e30', 1e30), ('1.0e30', 1e30), ('.5', 0.5), ('-1E+3', -1000.0), ('1.', 1.0),
    ('1_000.5', 1000.5), ('-.inf', -math.inf), ('12', 12), ('0x1f', 31), ('+7', 7)])
def test_yaml_loader_reads_yaml_1_2_numbers(written, value):
    from quad_msgs_bridge.yaml_files import load_yaml
    read = load_yaml(f'v: {written}')['v']
    assert read == value and type(read) is type(value)


@pytest.mark.parametrize('written', ['1e', '.', 'e5', '1.2.3', 'nan', 'inf', '2001-12-14', 'yes'])
def test_yaml_loader_leaves_other_scalars_alone(written):
    from quad_msgs_bridge.yaml_files import load_yaml
    assert load_yaml(f'v: {written}')['v'] == yaml.safe_load(f'v: {written}')['v']
    assert yaml.safe_load('v: 3e-5')['v'] == '3e-5'     # PyYAML's own loader is left as it was
