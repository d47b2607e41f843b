"""Gains that carry over between vehicles (issue 28 item 3; nnit2fsmc_controller/gain_units.py).

The gains file states every gain per unit of nominal mass and inertia; at build time the NNIT2FSMC's
authorities are multiplied by 1 / b (z: m, phi: Ix / d, theta: Iy / d, psi: Iz) and its learning rates
divided by its square. Checked here: the packaged file gives the packaged vehicle its former newton
values to the last bit, two vehicles that differ only in mass and inertia fly the same trajectory with
the one file, and a vehicle the z authorities cannot hold is refused, naming the gain and the vehicle.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from flight_stack.api import fly
from nnit2fsmc_controller.factory import CONTROLLERS, build_controller, flatten_gains, gain_names, load_gains, \
    unflatten_gains
from nnit2fsmc_controller.gain_units import GAIN_UNITS, UNITS, control_scale, gain_unit, in_vehicle_units
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file

PARAMS = load_vehicle_file()[0]
#: what the packaged file gave the packaged vehicle when it was written in newtons (z: N; phi, theta: N; psi: N m),
#: learning rates per second
NEWTON_GAINS = {'z': (8.0, 10.0, 0.5), 'phi': (2.0, 0.5, 50.0), 'theta': (2.0, 0.5, 50.0), 'psi': (0.03, 0.03, 30000.0)}
#: every field that is a mass, an inertia, a force or a drag coefficient (drag forces are m times an acceleration)
MASS_LIKE = ('m', 'Ix', 'Iy', 'Iz', 'F_min', 'F_max', 'Kfx', 'Kfy', 'Kfz', 'Kfphi', 'Kftheta', 'Kfpsi', 'wind_drag')


def scaled(params: VehicleParams, k: float) -> VehicleParams:
    """``params`` with every mass-like field x k: the same vehicle in acceleration units."""
    return dataclasses.replace(params, **{name: getattr(params, name) * k for name in MASS_LIKE})


def test_every_gain_declares_a_known_unit():
    assert set(GAIN_UNITS.values()) <= set(UNITS)
    assert {gain_unit(name) for name in gain_names()} == {'none', 'control', 'control^-2'}
    assert gain_unit('nnit2fsmc.axes.z.fuzzy_gain') == 'control'
    assert gain_unit('nnit2fsmc.axes.phi.learning_rate') == 'control^-2'
    assert gain_unit('nnit2fsmc.axes.z.input_scale') == 'none'
    assert gain_unit('pid.axes.z.kp') == 'none'   # the baselines' gains are per unit of q'' already


def test_control_scale_is_the_inverse_of_the_nominal_control_gain():
    p = PARAMS
    assert [control_scale(p, axis) for axis in ('x', 'y', 'z', 'phi', 'theta', 'psi')] == \
        [1.0, 1.0, p.m, p.Ix / p.d, p.Iy / p.d, p.Iz]


def test_untuned_gains_give_the_packaged_vehicle_its_newton_values_exactly():
    """The restatement in acceleration units is exact: the paper's vehicle flies bit-identically (the untuned set:
    the packaged gains before issue 26's tuning, whose newton values these were)."""
    controller = build_controller('nnit2fsmc', PARAMS, load_gains('untuned'))
    for axis, (fuzzy_gain, nn_gain, learning_rate) in NEWTON_GAINS.items():
        law = controller.laws[axis]
        assert law.fuzzy.output_gain == fuzzy_gain
        assert law.network.output_gain == nn_gain
        assert law.network.learning_rate == learning_rate * controller.dt


def test_the_law_gains_scale_with_mass_and_inertia():
    k = 1.7
    light, heavy = build_controller('nnit2fsmc', PARAMS), build_controller('nnit2fsmc', scaled(PARAMS, k))
    for axis in ('x', 'y', 'z', 'phi', 'theta', 'psi'):
        factor = 1.0 if axis in ('x', 'y') else k
        a, b = light.laws[axis], heavy.laws[axis]
        assert b.fuzzy.output_gain == pytest.approx(factor * a.fuzzy.output_gain, rel=1e-14)
        assert b.network.output_gain == pytest.approx(factor * a.network.output_gain, rel=1e-14)
        assert b.network.learning_rate == pytest.approx(a.network.learning_rate / factor ** 2, rel=1e-14)
    assert in_vehicle_units('nnit2fsmc.axes.z.lambda', 3.0, PARAMS, 'z') == 3.0


@pytest.mark.parametrize('kind', CONTROLLERS)
def test_two_vehicles_differing_only_in_mass_and_inertia_fly_the_same_trajectory(kind):
    """With one gains file, a vehicle 1.7 times heavier in every mass, inertia, rotor limit and drag flies the
    paper's helix (take-off included; the section IV disturbances, stated in newtons, off) along the same
    positions and angles: every gain carried over."""
    k = 1.7
    flights = [fly(kind, 'paper', duration=6.0, disturbances=False, vehicle=vehicle)
               for vehicle in (PARAMS, scaled(PARAMS, k))]
    light, heavy = (flight.state for flight in flights)
    assert np.abs(light[:, :3]).max() > 0.3   # it flew
    np.testing.assert_allclose(heavy[:, :3], light[:, :3], rtol=0, atol=1e-7)    # [m]
    np.testing.assert_allclose(heavy[:, 6:9], light[:, 6:9], rtol=0, atol=1e-7)  # [rad]
    np.testing.assert_allclose(flights[1].forces, k * flights[0].forces, rtol=1e-6, atol=1e-9)


def newton_gains() -> dict:
    """The packaged gains with the z authorities written in newtons of the paper's vehicle (8 N, 10 N), as the
    file was before: the heavier vehicle's weight is above the fuzzy term's."""
    flat = flatten_gains(load_gains())
    flat['nnit2fsmc.axes.z.fuzzy_gain'], flat['nnit2fsmc.axes.z.nn_gain'] = 8.0, 10.0
    return unflatten_gains(flat)


#: the issue's vehicle: 0.826 kg (weight 8.10 N), thrust-to-weight 3.8
HEAVY = dataclasses.replace(PARAMS, m=0.826, F_max=3.8 * 0.826 * 9.81 / 4.0)


@pytest.mark.parametrize('kind', ['nnit2fsmc', 'nnit2fsmc-sat', 'nnit2fsmc-bias'])
def test_a_z_authority_below_hover_need_is_refused_naming_the_gain_and_the_vehicle(kind):
    with pytest.raises(ParameterError, match=r'nnit2fsmc\.axes\.z\.fuzzy_gain: 8 m/s\^2 gives 6\.608 N on the '
                                             r'vehicle of mass m = 0\.826 kg.*weight m g = 8\.103 N'):
        build_controller(kind, HEAVY, newton_gains())
    flat = flatten_gains(newton_gains())
    flat['nnit2fsmc.axes.z.fuzzy_gain'], flat['nnit2fsmc.axes.z.nn_gain'] = 16.0, 9.0
    with pytest.raises(ParameterError, match=r'nnit2fsmc\.axes\.z\.nn_gain: 9 m/s\^2 .* m = 0\.826 kg.*'
                                             r'valid range \(9\.81, inf\)'):
        build_controller(kind, HEAVY, unflatten_gains(flat))
    build_controller(kind, HEAVY)   # the packaged gains fly it


def test_the_hover_check_names_the_vehicle_of_a_batch():
    batch = VehicleParams.stack([PARAMS, dataclasses.replace(PARAMS, g=12.0)])
    flat = flatten_gains(load_gains())
    flat['nnit2fsmc.axes.z.fuzzy_gain'] = 11.0
    with pytest.raises(ParameterError, match=r'fuzzy_gain: 11 m/s\^2 .*\(vehicle 1 of the batch\)'):
        build_controller('nnit2fsmc', batch, unflatten_gains(flat), batch=2)


def test_a_rotor_limit_below_the_weight_is_refused_naming_the_vehicle():
    with pytest.raises(ParameterError, match=r'vehicle\.F_max: 1\.5 N cannot hover the vehicle of mass m = 0\.826 kg '
                                             r'\(weight 8\.103 N\)'):
        dataclasses.replace(HEAVY, F_max=1.5)
