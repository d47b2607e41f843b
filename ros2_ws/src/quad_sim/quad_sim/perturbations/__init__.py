"""Perturbations between the nominal model and the flown truth (docs/PERTURBATIONS.md).

- :mod:`.wind`: mean wind plus Dryden turbulence (MIL-F-8785C low altitude) -> air velocity,
  which :meth:`quad_sim.model.QuadrotorModel.step` turns into drag;
- :mod:`.sensor_noise`: white noise plus a per-flight bias on the odometry the controller sees;
- :mod:`.actuation`: transport delay (whole control steps) and first-order motor lag;
- :mod:`.vehicle_change`: the true vehicle changes from a time t on (payload pick-up or drop, a rotor
  losing efficiency);
- :mod:`.streams`: one random stream per purpose and flight, from (campaign seed, flight index).

The true vehicle itself (mass, inertias, drag, CoG offset, per-rotor factors) is a
:class:`quad_msgs_bridge.vehicle_params.VehicleParams`. Every piece steps one vehicle (floats) or a
batch (numpy arrays of shape (B,)) with the same call.
"""
from .actuation import MotorLag, TransportDelay
from .sensor_noise import SensorErrors, SensorNoise
from .streams import BLOCK_STEPS, FlightStreams, flight_streams
from .vehicle_change import VehicleChange, vehicle_change
from .wind import DrydenTurbulence, Wind, low_altitude_scales

__all__ = ['BLOCK_STEPS', 'DrydenTurbulence', 'FlightStreams', 'MotorLag', 'SensorErrors', 'SensorNoise',
           'TransportDelay', 'VehicleChange', 'Wind', 'flight_streams', 'low_altitude_scales', 'vehicle_change']
