"""Flight k of a campaign: its sampled conditions, and the perturbation objects that fly them.

Everything random about flight k comes from the streams of
``quad_sim.perturbations.streams.flight_streams(seed, k)`` (each built alone, by ``flight_stream``, when
the spec draws from it): the true vehicle from ``vehicle``
(exactly :data:`VEHICLE_DRAWS` uniform numbers, one per perturbed value, in the order of
:data:`VEHICLE_DRAW_ORDER`, whether or not the spec perturbs it), the mean wind direction from
``wind``, the turbulence, the sensor noise and its bias from their own streams. A flight's result
therefore depends only on (seed, k), never on the batch it flies in, the worker or the machine,
and every controller of a campaign flies the same vehicles in the same air.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

from quad_msgs_bridge.vehicle_params import VehicleParams
from quad_sim.perturbations.streams import flight_stream
from quad_sim.world import Perturbations, build_perturbations as world_perturbations, wind_direction

from .spec import CampaignSpec

TRANSLATIONAL_DRAG = ('Kfx', 'Kfy', 'Kfz', 'Kfphi', 'Kftheta', 'Kfpsi')
#: (spec key, number of values) in the order the vehicle stream's uniform numbers are used
VEHICLE_DRAW_ORDER = (('mass', 1), ('inertia', 3), ('drag', 6), ('thrust_coefficient', 4),
                      ('drag_coefficient', 4), ('cog_offset_m', 2), ('rotor_efficiency_loss', 4),
                      ('one_rotor_efficiency_loss', 1))
VEHICLE_DRAWS = sum(count for _, count in VEHICLE_DRAW_ORDER)
#: the sampled values of a flight as flights.csv names them (SI units)
SAMPLED_COLUMNS = ('mass_kg', 'Ix_kgm2', 'Iy_kgm2', 'Iz_kgm2', *TRANSLATIONAL_DRAG,
                   *(f'{name}{i}{unit}' for i in range(1, 5)
                     for name, unit in (('Kp', '_Nss'), ('Kd', '_Nmss'), ('efficiency_loss', ''))),
                   'cog_x_m', 'cog_y_m', 'wind_direction_rad')


@dataclass(frozen=True)
class FlightConditions:
    """The sampled conditions of one flight (SI units)."""

    flight: int                   #: index in the campaign
    vehicle: VehicleParams        #: the true vehicle (the controllers keep the nominal one)
    wind_direction: float         #: [rad] towards which the mean wind blows, from +x towards +y

    def sampled_values(self, nominal: VehicleParams) -> dict[str, float]:
        """Every value that differs between flights, named with its unit, for ``flights.csv``."""
        v = self.vehicle
        values = {'mass_kg': v.m, 'Ix_kgm2': v.Ix, 'Iy_kgm2': v.Iy, 'Iz_kgm2': v.Iz}
        values.update({name: getattr(v, name) for name in TRANSLATIONAL_DRAG})
        for i in range(4):
            values[f'Kp{i + 1}_Nss'] = v.rotor_thrust_factors[i] * nominal.Kp
            values[f'Kd{i + 1}_Nmss'] = v.rotor_drag_factors[i] * nominal.Kd
            values[f'efficiency_loss{i + 1}'] = v.rotor_efficiency_loss[i]
        values['cog_x_m'], values['cog_y_m'] = v.cog_offset[0], v.cog_offset[1]
        values['wind_direction_rad'] = self.wind_direction
        return {name: values[name] for name in SAMPLED_COLUMNS}


def sample_conditions(spec: CampaignSpec, nominal: VehicleParams, flight: int) -> FlightConditions:
    """The conditions of flight ``flight`` of ``spec`` around the ``nominal`` vehicle."""
    uniforms = iter(flight_stream(spec.seed, flight, 'vehicle').random(VEHICLE_DRAWS).tolist())
    draws = {key: [next(uniforms) for _ in range(count)] for key, count in VEHICLE_DRAW_ORDER}

    def relative(key: str, index: int) -> float:
        distribution = spec.vehicle.get(key)
        return 1.0 + distribution.value(draws[key][index]) if distribution else 1.0

    def absolute(key: str, index: int) -> float:
        distribution = spec.vehicle.get(key)
        return distribution.value(draws[key][index]) if distribution else 0.0

    losses = [loss_draw(spec, 'rotor_efficiency_loss', draws, i) for i in range(4)]
    losses[0] = 1.0 - (1.0 - losses[0]) * (1.0 - loss_draw(spec, 'one_rotor_efficiency_loss', draws, 0))
    vehicle = replace(
        nominal,
        m=nominal.m * relative('mass', 0),
        Ix=nominal.Ix * relative('inertia', 0), Iy=nominal.Iy * relative('inertia', 1),
        Iz=nominal.Iz * relative('inertia', 2),
        **{name: getattr(nominal, name) * relative('drag', i) for i, name in enumerate(TRANSLATIONAL_DRAG)},
        rotor_thrust_factors=tuple(relative('thrust_coefficient', i) for i in range(4)),
        rotor_drag_factors=tuple(relative('drag_coefficient', i) for i in range(4)),
        cog_offset=(absolute('cog_offset_m', 0), absolute('cog_offset_m', 1), 0.0),
        rotor_efficiency_loss=tuple(losses))
    return FlightConditions(flight, vehicle, wind_direction(spec.world, spec.seed, flight))


def loss_draw(spec: CampaignSpec, key: str, draws: dict, index: int) -> float:
    """The lost thrust fraction of a loss key (:data:`.spec.LOSS_KEYS`) for its ``index``-th draw: 0 when
    the spec leaves the key out; a uniform half width x maps onto [0, x), a normal onto |N(0, s)|, a
    fixed value is that value."""
    loss = spec.vehicle.get(key)
    if loss is None:
        return 0.0
    return loss.scale * draws[key][index] if loss.kind == 'uniform' else abs(loss.value(draws[key][index]))


def build_perturbations(spec: CampaignSpec, conditions: Sequence[FlightConditions], control_dt: float,
                        physics_dt: float, batch: bool) -> Perturbations:
    """The perturbation objects that fly ``conditions`` in the spec's world (:func:`quad_sim.world.build_perturbations`):
    of one vehicle (``batch`` false, one condition) or of a batch (arrays, one element and one random stream per
    flight, in order)."""
    return world_perturbations(spec.world, spec.seed, [c.flight for c in conditions], [c.vehicle for c in conditions],
                               [c.wind_direction for c in conditions], control_dt, physics_dt, batch)
