"""fly() with any vehicle and any world: a true vehicle apart from the nominal model, wind, sensor noise, delay,
motor lag, a mass change and a rotor efficiency loss from a time t, checked as the campaign spec checks them."""
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from flight_stack.api import fly, load_vehicle
from flight_stack.closed_loop import FailureRules
from flight_stack.embedded import Perturbations, fly_embedded
from nnit2fsmc_controller.factory import load_gains
from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.review.flight_data import SERIES
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.perturbations.streams import flight_streams
from quad_sim.perturbations.vehicle_change import VehicleChange
from quad_sim.perturbations.wind import Wind

ROOT = Path(__file__).resolve().parent.parent
NOMINAL = load_vehicle()
TRUE = replace(NOMINAL, m=1.1 * NOMINAL.m, Kfx=1.2 * NOMINAL.Kfx)
PICKED_UP = 1.3 * NOMINAL.m           #: [kg] after the payload is picked up
DURATION, CHANGE_AT, SEED = 3.0, 1.5, 3


@pytest.fixture(scope='module')
def by_fly():
    return fly('nnit2fsmc', 'hover', duration=DURATION, seed=SEED, true_vehicle=TRUE,
               wind={'mean_speed_mps': 2.0, 'turbulence': 'light', 'direction_deg': 30.0},
               mass_change={'at_s': CHANGE_AT, 'mass_kg': PICKED_UP})


def test_fly_with_a_true_vehicle_wind_and_a_mass_change_equals_the_flight_built_by_hand(by_fly):
    params, disturbances = load_vehicle_file()
    gains = load_gains()
    gains['nnit2fsmc']['seed'] = SEED
    wind = Wind(0.001, 2.0, math.radians(30.0), 'light', flight_streams(SEED, 0).turbulence)
    by_hand = fly_embedded('nnit2fsmc', make_scenario('hover', DURATION), params, disturbances, gains, DURATION,
                           1000.0, rules=FailureRules(settle_time=DURATION / 2, max_error=math.inf),
                           perturbations=Perturbations(true_vehicle=TRUE, wind=wind,
                                                       changes=(VehicleChange(CHANGE_AT, replace(TRUE, m=PICKED_UP)),)))
    assert by_hand.failure is None and by_hand.steps == by_fly.steps == 3000
    for name in SERIES:
        assert np.array_equal(getattr(by_hand.flight, name), getattr(by_fly, name)), name
    assert by_hand.flight.metrics() == by_fly.metrics()


def test_the_payload_pick_up_is_felt_from_its_time_on(by_fly):
    without = fly('nnit2fsmc', 'hover', duration=DURATION, seed=SEED, true_vehicle=TRUE,
                  wind={'mean_speed_mps': 2.0, 'turbulence': 'light', 'direction_deg': 30.0})
    before = by_fly.time < CHANGE_AT
    assert np.array_equal(by_fly.forces[before], without.forces[before])
    # the controller answers the extra weight: about (1.3 - 1.1) m g more collective thrust at the end
    extra = by_fly.controls[-1, 0] - without.controls[-1, 0]
    assert extra == pytest.approx((PICKED_UP - TRUE.m) * NOMINAL.g, rel=0.3)


def test_a_rotor_efficiency_loss_from_a_time_on_and_the_other_perturbations_fly():
    flight = fly('nnit2fsmc', 'hover', duration=DURATION, seed=SEED, sensor_noise={'position_m': 0.002},
                 delay_s=0.002, motor_time_constant_s=0.02, rotor_efficiency_loss={'at_s': 1.0, 'loss': [0.2, 0, 0, 0]})
    nominal = fly('nnit2fsmc', 'hover', duration=DURATION, seed=SEED, sensor_noise={'position_m': 0.002},
                  delay_s=0.002, motor_time_constant_s=0.02)
    assert flight.summary['flight_ok'] and np.isfinite(flight.forces).all()
    before = flight.time < 1.0
    assert np.array_equal(flight.forces[before], nominal.forces[before])
    # rotor 1 lost a fifth of its thrust: the controller asks more of it than of its opposite rotor 3
    assert flight.forces[-1, 0] - flight.forces[-1, 2] > nominal.forces[-1, 0] - nominal.forces[-1, 2] + 0.1


@pytest.mark.parametrize('setting,named', [
    ({'controller': 'nope'}, 'controller'),
    ({'scenario': 'nope'}, 'scenario'),
    ({'duration': -1.0}, 'duration'),
    ({'seed': -1}, 'seed'),
    ({'disturbances': 'yes'}, 'disturbances'),
    ({'vehicle': 123}, 'vehicle'),
    ({'gains': 123}, 'gains'),
    ({'physics_rate': 333.0}, 'physics-rate'),
    ({'settle_time': 100.0}, 'settle-time'),
    ({'max_error': 0.0}, 'max-error'),
    ({'out': 5}, 'out'),
    ({'true_vehicle': 123}, 'true_vehicle'),
    ({'true_vehicle': '/no/such/vehicle.yaml'}, 'true_vehicle'),
    ({'wind': 5}, 'wind'),
    ({'wind': {'speed': 3.0}}, r'wind\.speed'),
    ({'wind': {'turbulence': 'hurricane'}}, r'wind\.turbulence'),
    ({'sensor_noise': {'position_m': -1.0}}, r'sensor_noise\.position_m'),
    ({'delay_s': -0.1}, 'delay_s'),
    ({'delay_s': 0.0005}, 'delay_s'),
    ({'motor_time_constant_s': 'x'}, 'motor_time_constant_s'),
    ({'mass_change': [1, 2]}, 'mass_change'),
    ({'mass_change': {'at_s': 1.0}}, r'mass_change\.mass_kg'),
    ({'mass_change': {'at_s': -1.0, 'mass_kg': 1.0}}, r'mass_change\.at_s'),
    ({'mass_change': {'at_s': 1.0, 'mass_kg': 100.0}}, 'mass_change'),
    ({'mass_change': {'at_s': 1.0, 'mass': 1.0}}, r'mass_change\.mass'),
    ({'rotor_efficiency_loss': {'at_s': 1.0, 'loss': [1.0, 0, 0, 0]}}, 'rotor_efficiency_loss'),
    ({'rotor_efficiency_loss': {'at_s': 1.0, 'loss': [0.1]}}, r'rotor_efficiency_loss\.loss'),
])
def test_every_bad_input_is_a_value_error_naming_the_argument(setting, named, tmp_path):
    with pytest.raises(ValueError, match=named):
        fly(**{'scenario': 'hover', 'duration': 3.0, **setting})


def test_a_single_flight_reaches_its_world_without_the_campaign_package():
    """The world is described once, below both (quad_sim.world): a flight under wind, noise, delay, motor lag and a
    mid-flight change plans and flies without importing flight_stack.campaign."""
    script = ("import sys, flight_stack.api as api\n"
              "api.fly('pid', 'hover', duration=1.0, settle_time=0.5, wind={'mean_speed_mps': 2.0, 'turbulence': 'light'},"
              " sensor_noise={'position_m': 0.01}, delay_s=0.002, motor_time_constant_s=0.02,"
              " mass_change={'at_s': 0.5, 'mass_kg': 0.6})\n"
              "print(sorted(m for m in sys.modules if m.startswith('flight_stack.campaign')))\n")
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == '[]'
