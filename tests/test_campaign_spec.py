"""The campaign spec: the documented format, overrides, and every bad key refused before anything flies."""
import copy
import statistics
from pathlib import Path

import numpy as np
import pytest
import yaml

from flight_stack.campaign.sampling import VEHICLE_DRAWS, sample_conditions
from flight_stack.campaign.spec import Distribution, load_spec, parse_spec
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / 'campaigns' / 'paper-robustness.yaml'
NOMINAL, _ = load_vehicle_file()
BASE = {'scenario': 'hover', 'duration': 4.0, 'settle_time': 2.0, 'controllers': ['nnit2fsmc'], 'flights': 3}


def test_the_example_spec_is_the_issue_s_campaign():
    spec = load_spec(EXAMPLE)
    assert (spec.scenario, spec.duration, spec.settle_time, spec.flights) == ('paper', 60.0, 5.0, 1000)
    assert spec.vehicle['mass'] == Distribution('uniform', 0.3) and spec.vehicle['inertia'].scale == 0.3
    assert spec.vehicle['drag'].scale == 0.25
    assert spec.vehicle['thrust_coefficient'].scale == spec.vehicle['drag_coefficient'].scale == 0.1
    assert (spec.wind_mean_speed_mps, spec.turbulence) == (3.0, 'moderate')
    assert spec.sensor_noise['position_m'].std == 0.01 and spec.sensor_noise['attitude_rad'].std == 0.01
    assert (spec.delay_s, spec.motor_time_constant_s, spec.control_rate_hz) == (0.004, 0.03, 1000.0)


def test_overrides_replace_the_spec_values():
    spec = parse_spec(BASE).overridden(flights=7, seed=4, duration=5.0, controllers='pid,smc-sign')
    assert (spec.flights, spec.seed, spec.duration, spec.controllers) == (7, 4, 5.0, ('pid', 'smc-sign'))
    assert parse_spec(spec.to_mapping()) == spec    # what spec.yaml stores reproduces it


BAD = [
    ({'colour': 'red'}, 'colour'),
    ({'vehicle': {'mass': 0.1, 'wings': 0.2}}, 'vehicle.wings'),
    ({'vehicle': {'mass': -0.1}}, 'vehicle.mass'),
    ({'vehicle': {'inertia': {'dist': 'normal', 'std': -0.1}}}, 'vehicle.inertia.std'),
    ({'vehicle': {'inertia': {'dist': 'normal', 'std': 0.4}}}, 'vehicle.inertia'),     # 3 std >= 1
    ({'vehicle': {'mass': 1.0}}, 'vehicle.mass'),                                    # could reach zero mass
    ({'vehicle': {'mass': {'dist': 'cauchy', 'std': 0.1}}}, 'vehicle.mass.dist'),
    ({'vehicle': {'rotor_efficiency_loss': 1.0}}, 'vehicle.rotor_efficiency_loss'),
    ({'sensor_noise': {'position_m': -0.01}}, 'sensor_noise.position_m'),
    ({'sensor_noise': {'position_m': {'std': 0.01, 'bias_std': -1.0}}}, 'sensor_noise.position_m.bias_std'),
    ({'sensor_noise': {'altitude_m': 0.01}}, 'sensor_noise.altitude_m'),
    ({'wind': {'mean_speed_mps': -3.0}}, 'wind.mean_speed_mps'),
    ({'wind': {'turbulence': 'hurricane'}}, 'wind.turbulence'),
    ({'wind': {'gusts': True}}, 'wind.gusts'),
    ({'controllers': []}, 'controllers'),
    ({'controllers': ['lqr']}, 'controllers'),
    ({'controllers': ['pid', 'pid']}, 'controllers'),
    ({'flights': 0}, 'flights'),
    ({'flights': 2.5}, 'flights'),
    ({'seed': -1}, 'seed'),
    ({'scenario': 'loop'}, 'scenario'),
    ({'duration': 2.0}, 'duration'),                      # nothing after the 2 s settling window
    ({'delay_s': -0.001}, 'delay_s'),
    ({'motor_time_constant_s': float('nan')}, 'motor_time_constant_s'),
    ({'control_rate_hz': 0}, 'control_rate_hz'),
    ({'max_error_m': 0.0}, 'max_error_m'),
    ({'disturbances': 'yes'}, 'disturbances'),
]


@pytest.mark.parametrize('change, key', BAD, ids=[key for _, key in BAD])
def test_every_bad_key_is_refused_naming_it(change, key):
    document = copy.deepcopy(BASE) | change
    with pytest.raises(ParameterError) as error:
        parse_spec(document)
    assert str(error.value).startswith(key), str(error.value)


@pytest.mark.parametrize('override, key', [({'flights': 0}, '--flights'), ({'seed': -3}, '--seed'),
                                           ({'controllers': ''}, '--controllers'), ({'duration': 1.0}, '--duration')])
def test_bad_overrides_are_refused_naming_the_option(override, key):
    with pytest.raises(ParameterError, match=f'^{key}'):
        parse_spec(BASE).overridden(**override)


def test_missing_file_and_bad_yaml_name_the_file(tmp_path):
    with pytest.raises(ParameterError, match='nowhere.yaml'):
        load_spec(tmp_path / 'nowhere.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('scenario: [paper\n')
    with pytest.raises(ParameterError, match='broken.yaml: not valid YAML'):
        load_spec(broken)


def test_uniform_and_truncated_normal_draws_by_inverse_transform():
    uniform, normal = Distribution('uniform', 0.3), Distribution('normal', 0.1)
    assert uniform.value(0.0) == pytest.approx(-0.3) and uniform.value(0.5) == 0.0
    assert normal.value(0.5) == pytest.approx(0.0, abs=1e-15)
    assert normal.value(0.0) == pytest.approx(-0.3) and normal.value(1.0 - 1e-16) == pytest.approx(0.3)
    draws = [normal.value(u) for u in np.random.default_rng(0).random(20000)]
    # a normal truncated at 3 std has std 0.9866 sigma (1 - 2*3*phi(3)/(2*Phi(3)-1))^0.5
    assert statistics.pstdev(draws) == pytest.approx(0.1 * 0.98658, rel=0.02)


def test_sampling_uses_one_uniform_per_value_whatever_the_spec_perturbs():
    """Adding a perturbation to the spec never changes what the others draw for the same flight."""
    only_mass = parse_spec(BASE | {'vehicle': {'mass': 0.3}, 'seed': 9})
    everything = parse_spec(BASE | {'vehicle': {'mass': 0.3, 'inertia': {'dist': 'normal', 'std': 0.2},
                                                'cog_offset_m': 0.01}, 'seed': 9})
    a, b = (sample_conditions(spec, NOMINAL, 5).vehicle for spec in (only_mass, everything))
    assert a.m == b.m != NOMINAL.m
    assert a.Ix == NOMINAL.Ix != b.Ix
    assert VEHICLE_DRAWS == 25     # 1 + 3 + 6 + 4 + 4 + 2 + 4 + 1 (one_rotor_efficiency_loss)


def test_sampled_values_lie_in_their_ranges():
    spec = parse_spec(BASE | {'vehicle': {'mass': 0.3, 'drag': 0.25, 'thrust_coefficient': 0.1,
                                          'cog_offset_m': 0.01, 'rotor_efficiency_loss': 0.1}})
    for flight in range(40):
        v = sample_conditions(spec, NOMINAL, flight).vehicle
        assert 0.7 * NOMINAL.m <= v.m <= 1.3 * NOMINAL.m
        assert 0.75 * NOMINAL.Kfz <= v.Kfz <= 1.25 * NOMINAL.Kfz
        assert all(0.9 <= f <= 1.1 for f in v.rotor_thrust_factors)
        assert all(abs(c) <= 0.01 for c in v.cog_offset[:2]) and v.cog_offset[2] == 0.0
        assert all(0.0 <= loss <= 0.1 for loss in v.rotor_efficiency_loss)
        assert v.Ix == NOMINAL.Ix       # not perturbed by this spec


def test_the_spec_file_keys_are_documented():
    """Every key the parser takes appears in the documented format (docs/CAMPAIGNS.md)."""
    documented = (ROOT / 'docs' / 'CAMPAIGNS.md').read_text()
    example = yaml.safe_load(EXAMPLE.read_text())
    for key in [*example, *example['vehicle'], 'cog_offset_m', 'rotor_efficiency_loss', 'bias_std', 'direction_deg',
                'max_error_m', 'physics_rate_hz', 'disturbances']:
        assert key in documented, key


def test_shipped_specs_are_found_by_name_from_anywhere(tmp_path, monkeypatch):
    from flight_stack.campaign.spec import SHIPPED_SPECS, shipped_specs
    assert EXAMPLE.resolve().parent == SHIPPED_SPECS           # campaigns/ of a clone is the packaged folder
    assert 'paper-robustness' in [path.stem for path in shipped_specs()]
    monkeypatch.chdir(tmp_path)                                  # no campaigns/ here
    expected = load_spec(EXAMPLE)
    for name in ('campaigns/paper-robustness.yaml', 'paper-robustness.yaml', 'paper-robustness'):
        assert load_spec(name) == expected, name
    with pytest.raises(ParameterError, match=r'campaign spec paper-robustnes: .*\(shipped specs: .*paper-robustness'):
        load_spec('paper-robustnes')


def test_the_packaged_specs_are_package_data():
    import tomllib
    document = tomllib.loads((ROOT / 'pyproject.toml').read_text())
    assert 'campaign/specs/*.yaml' in document['tool']['setuptools']['package-data']['flight_stack']


def test_a_world_that_draws_its_actuator_per_flight_records_it_and_flies_it(tmp_path):
    """motor_time_constant_s and delay_s as {low, high}: each flight draws its own from its actuator stream (the
    delay in whole control steps, every one in the range), flights.csv records them, and flight k flies its own
    whatever batch it is in; a range with no whole control step, or low > high, is refused by name."""
    from flight_stack.campaign.batch import BatchJob, fly_batch
    from quad_sim.world import Range, parse_world
    world = parse_world({'motor_time_constant_s': {'low': 0.015, 'high': 0.045}, 'delay_s': {'low': 0.0, 'high': 0.008}})
    assert world.motor_time_constant_s == Range(0.015, 0.045) and not world.is_nominal
    draws = [world.actuator(5, k, 0.001) for k in range(400)]
    lags, delays = zip(*draws)
    assert 0.015 <= min(lags) < 0.017 and 0.043 < max(lags) <= 0.045
    steps = sorted({round(d / 0.001) for d in delays})
    assert steps == list(range(9)) and all(abs(d / 0.001 - round(d / 0.001)) < 1e-9 for d in delays)
    assert draws == [world.actuator(5, k, 0.001) for k in range(400)]          # reproducible by (seed, flight)
    with pytest.raises(ParameterError, match=r'delay_s: \[0.0001, 0.0002\] s holds no whole number of control steps'):
        parse_world({'delay_s': {'low': 0.0001, 'high': 0.0002}}).actuator(0, 0, 0.001)
    with pytest.raises(ParameterError, match=r'motor_time_constant_s.high: 0.01 is outside the valid range \[0.02, 1.0\]'):
        parse_world({'motor_time_constant_s': {'low': 0.02, 'high': 0.01}})

    spec = parse_spec({'scenario': 'hover', 'duration': 2.0, 'settle_time': 1.0, 'controllers': ['pid'], 'flights': 3,
                       'seed': 5, 'motor_time_constant_s': {'low': 0.015, 'high': 0.045},
                       'delay_s': {'low': 0.0, 'high': 0.008}})
    together = fly_batch(BatchJob(spec, 'pid', (0, 1, 2)))
    alone = [fly_batch(BatchJob(spec, 'pid', (k,)))[0] for k in range(3)]
    assert repr(together) == repr(alone)                   # nan-safe: an unfailed flight's failure_time_s is nan
    for k, row in enumerate(together):
        assert (row['motor_time_constant_s'], row['delay_s']) == world.actuator(5, k, 0.001)
    assert len({row['rmse_position_m'] for row in together}) == 3
