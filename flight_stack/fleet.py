"""A fleet on one sim clock: the vehicles' namespaces, their offset copies of the scenario, their summary.

Layout (:func:`fleet_layout`): a lone vehicle keeps the namespace ``quad`` (or the one given).
N > 1 vehicles are named ``uav1`` .. ``uavN`` (under the given namespace, else at the root), and
vehicle k flies the scenario shifted by (0, FLEET_SPACING_M * (k - 1), 0) [m, world ENU]: 3 m
apart along y, ``uav1`` on the scenario itself, each starting at rest under its own shifted path.
3 m leaves 1 m between the paper's helices (radius 1 m) and between the waypoint squares (2 m wide).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from quad_msgs_bridge.contract import DEFAULT_NAMESPACE

FLEET_SPACING_M = 3.0   #: [m] between neighbouring vehicles, along y
MAX_VEHICLES = 20       #: a sanity bound for --vehicles (each vehicle is two node processes)

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class FleetVehicle:
    """One vehicle of a flight: its namespace and where its copy of the scenario is."""

    namespace: str                       #: e.g. 'uav2' or 'team/uav2' (no leading '/')
    offset: Vec3 = (0.0, 0.0, 0.0)       #: [m, world ENU] added to every position of the scenario


def fleet_layout(count: int, namespace: str | None = None) -> tuple[FleetVehicle, ...]:
    """The vehicles of a flight of ``count`` vehicles (see the module doc)."""
    if count == 1:
        return (FleetVehicle((namespace or DEFAULT_NAMESPACE).strip('/')),)
    parent = (namespace or '').strip('/')
    return tuple(FleetVehicle(f'{parent}/uav{k}' if parent else f'uav{k}', (0.0, FLEET_SPACING_M * (k - 1), 0.0))
                 for k in range(1, count + 1))


def fleet_home(vehicles: Sequence[FleetVehicle]) -> tuple[str, list[str]]:
    """(namespace of the simulator and the recorder, the vehicles' namespaces relative to it).

    A lone vehicle: its own namespace (all its nodes together, as before fleets); a fleet: the
    vehicles' common parent namespace, else the root.
    """
    if len(vehicles) == 1:
        return vehicles[0].namespace, ['']
    parents = {vehicle.namespace.rpartition('/')[0] for vehicle in vehicles}
    if len(parents) == 1:
        return parents.pop(), [vehicle.namespace.rpartition('/')[2] for vehicle in vehicles]
    return '', [vehicle.namespace for vehicle in vehicles]


def fleet_summary(summaries: dict[str, dict]) -> dict:
    """summary.json of a fleet: every vehicle's summary under its namespace; OK when every vehicle's is."""
    return {
        'flight_ok': all(summary['flight_ok'] for summary in summaries.values()),
        'failures': [f'{name}: {failure}' for name, summary in summaries.items() for failure in summary['failures']],
        'vehicles': summaries,
    }


def format_fleet_summary(fleet: dict) -> str:
    """One row per vehicle of the main figures, then the result."""
    summaries = fleet['vehicles']
    first = next(iter(summaries.values()))
    width = max(7, *(len(name) for name in summaries))
    lines = [f'fleet: {first["controller"]} on "{first["scenario"]}", {len(summaries)} vehicles '
             f'({first["vehicle"]}) on one clock '
             f'({first["backend"]} backend), {first["duration_s"]:.1f} s sim in {first["wall_time_s"]:.1f} s wall',
             f'  after settling ({first["settle_time_s"]:.1f} s):',
             f'  {"vehicle":{width}s}  offset [m]         pos RMSE [cm]  max err [cm]  yaw RMSE [rad]  '
             f'saturation [%]  odom->forces p99 [ms]  result']
    for name, summary in summaries.items():
        offset = '(' + ', '.join(f'{v:g}' for v in summary.get('offset_m', (0.0, 0.0, 0.0))) + ')'
        latency = summary.get('ros', {}).get('timing', {}).get('latency_p99_ms')
        lines.append(f'  {name:{width}s}  {offset:17s}  {summary["rmse_position_m"] * 100:13.3f}  '
                     f'{summary["max_position_error_m"] * 100:12.3f}  {summary["rmse_yaw_rad"]:14.5f}  '
                     f'{summary["saturation_fraction"] * 100:14.2f}  '
                     + (f'{latency:21.3f}' if latency is not None else f'{"-":>21s}')
                     + f'  {"OK" if summary["flight_ok"] else "FAILED"}')
    lines.append('  result: ' + ('OK' if fleet['flight_ok'] else 'FAILED: ' + '; '.join(fleet['failures'])))
    return '\n'.join(lines)
