"""Every perturbation at once around a small feedback law: a batch of flights equals the same flights one by one."""
import dataclasses

import numpy as np

from quad_msgs_bridge.mixer import forces_from_controls
from quad_msgs_bridge.vehicle_params import VehicleParams, load_vehicle_file
from quad_sim.model import QuadrotorModel
from quad_sim.perturbations import MotorLag, SensorErrors, SensorNoise, TransportDelay, Wind, flight_streams

NOMINAL, DISTURBANCES = load_vehicle_file()
CONTROL_DT, SUBSTEPS = 1e-3, 2
PHYSICS_DT = CONTROL_DT / SUBSTEPS


def hold_altitude(state):
    """A PD law on the measured state (the test's stand-in for a controller): climb to 1.5 m and stay level."""
    z, vz, phi, theta, psi, dphi, dtheta, dpsi = (state[i] for i in (2, 5, 6, 7, 8, 9, 10, 11))
    u1 = NOMINAL.m * (NOMINAL.g + 25.0 * (1.5 - z) - 10.0 * vz)
    u2 = -(1.0 * phi + 0.1 * dphi) / NOMINAL.d
    u3 = -(1.0 * theta + 0.1 * dtheta) / NOMINAL.d
    u4 = -0.02 * psi - 0.005 * dpsi
    return forces_from_controls(u1, u2, u3, u4, NOMINAL.mixer)


START = (0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.05, -0.03, 0.2, 0.0, 0.0, 0.0)


def fly(vehicle, streams, wind_speed, tau, state, steps):
    """Sensor noise -> law -> 3-step delay -> (per physics step) motor lag, wind -> true-vehicle model."""
    sensor = SensorNoise(SensorErrors(0.01, 0.02, 0.005, 0.01), SensorErrors(0.005, 0.0, 0.002, 0.005),
                         streams['sensor_noise'], streams['sensor_bias'])
    delay = TransportDelay(3)
    lag = MotorLag(tau, PHYSICS_DT)
    wind = Wind(PHYSICS_DT, mean_speed=wind_speed, direction=0.7, turbulence='moderate', rng=streams['turbulence'])
    model = QuadrotorModel(vehicle, DISTURBANCES)
    t = 0.0
    for _ in range(steps):
        applied = delay(hold_altitude(sensor.measure(state)))
        for _ in range(SUBSTEPS):
            state = model.step(t, state, lag.step(applied), PHYSICS_DT, wind.step())
            t += PHYSICS_DT
    return state


def test_batch_with_every_perturbation_equals_single_flights():
    flights = [3, 0, 8, 5, 1, 13, 2]
    rng = np.random.default_rng(21)
    vehicles = [dataclasses.replace(NOMINAL, m=NOMINAL.m * rng.uniform(0.8, 1.2), Ix=rng.uniform(3e-3, 5e-3),
                                    cog_offset=tuple(rng.uniform(-0.005, 0.005, 3)),
                                    rotor_thrust_factors=tuple(rng.uniform(0.95, 1.05, 4)),
                                    rotor_efficiency_loss=tuple(rng.uniform(0.0, 0.05, 4))) for _ in flights]
    speeds, taus = rng.uniform(0.0, 6.0, len(flights)), rng.uniform(0.0, 0.04, len(flights))
    streams = [flight_streams(77, f)._asdict() for f in flights]
    steps = 400
    batch = fly(VehicleParams.stack(vehicles), {purpose: [s[purpose] for s in streams] for purpose in streams[0]},
                speeds, taus, [np.full(len(flights), v) for v in START], steps)
    for i, flight in enumerate(flights):
        single = fly(vehicles[i], flight_streams(77, flight)._asdict(), float(speeds[i]), float(taus[i]),
                     list(START), steps)
        np.testing.assert_allclose([component[i] for component in batch], single, rtol=1e-12, atol=1e-12)
        assert 1.1 < single[2] < 1.5 and abs(single[6]) < 0.1      # it climbed, level, under the law
