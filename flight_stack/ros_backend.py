"""ROS backend: each node in its own process, in a namespace, like ``ros2 launch`` would start them.

One vehicle or a fleet on one sim clock (see :mod:`.fleet`): one simulator for all (a lone vehicle's in its
namespace, a fleet's in the vehicles' parent namespace), and per vehicle a trajectory node (its offset copy of
the scenario) and a controller node in the vehicle's namespace; each vehicle's trajectory and controller start
before the simulator. The flight ends when the simulator has reached the duration and exits; the others are then
stopped together with SIGINT (then SIGTERM, SIGKILL). If any node dies first (named with its vehicle in a fleet:
``controller uav2``), the rest are stopped the same way and the flight is reported as failed.

Who writes the bag (``record_by``):

- ``'publishers'`` (the default): every node logs what it publishes into its own part bag in ``BAG.parts``
  (quad_msgs_bridge.bag.publication_log); once every node has stopped, the parts are merged into the bag (a
  killed node's up to its last complete chunk) and removed.
- ``'recorder'``: one recorder for all, started first (it records what really goes over the topics). In lockstep
  the simulator waits for two subscribers of each vehicle's ``odom`` (its controller and the recorder), and the
  recorder only subscribes to ``odom`` once its subscriptions have matched every controller's publishers, so the
  bag holds every step. It is stopped last, so that it drains what is still in flight and finalizes the bag.

The summary is computed from the bag: what was observed on the topics.

PX4 SITL (``plant`` px4-sitl, ``px4`` where it is: flight_stack.px4_sitl): the Agent and PX4 SITL start first, in
their own instance, port and ROS domain (every node of the flight gets that ROS_DOMAIN_ID); the PX4 bridge node
(quad_sim.px4_node) takes the simulator's place and ends the flight: it arms PX4 in offboard, publishes ``odom``
in flight time from PX4's odometry, lands after ``duration`` and exits once PX4 has disarmed. The controller runs
in realtime (``latest_only``) and answers each odometry; with ``controller`` px4 there is no controller node and
the bridge sends our reference to PX4's own controller. If the controller or trajectory node dies in flight, the
bridge is left to hand the vehicle to PX4's land mode (its ``forces_timeout``) and to disarm before the rest is
stopped: the flight is still reported as failed. The bag holds PX4's messages too (the bridge logs them; their
schemas come from the px4_msgs install), under PX4's first-instance names ``/fmu/...``.
"""
from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import yaml

from nnit2fsmc_controller.trajectory import make_scenario
from quad_msgs_bridge.bag.flight_bag import DURATION_KEY, MAX_ERROR_KEY, disturbances_label, ros_flight_custom_data
from quad_msgs_bridge.bag.merge import merge_parts
from quad_msgs_bridge.contract import GROUND_TRUTH, PER_STEP_TOPICS, RECORDED_TOPICS, TF, vehicle_namespaces
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from quad_sim.plants import PX4_CONTROLLER, PX4_SITL

from .fleet import FleetVehicle, fleet_home
from .processes import NodeProcess, node_command, source_tree_environment, stop_all, wait_for_exit


EXTRA_SUBSCRIBER_DELAY = 1.0   #: [s, wall] the simulator waits once extra odom subscribers are there
#: the per-step topics of a flight's simulator and controllers (and /tf, where the simulator broadcasts it)
PER_STEP_FLOWN = tuple(t.name for t in PER_STEP_TOPICS if t not in (GROUND_TRUTH, TF))
RECORD_BY = ('recorder', 'publishers')   #: who writes a flight's bag (RosFlightConfig.record_by)


@dataclass
class RosFlightConfig:
    vehicles: Sequence[FleetVehicle]   #: one, or a fleet (each starts at rest under its shifted scenario)
    controller: str
    scenario: str
    duration: float
    disturbances: bool
    seed: int
    physics_rate: float
    control_rate: float
    bag: Path
    topics: list[str]
    mode: str = 'lockstep'
    speed_factor: float = 1.0
    setpoint_rate: float = 50.0
    vehicle_file: Path | None = None
    gains_file: Path | None = None
    settle_time: float = 5.0
    quiet: bool = False
    extra_odom_subscribers: int = 0   #: further odom subscribers the simulator waits for (e.g. a ros2 bag record)
    #: further readers of every per-step topic (a recorder of them all): the simulator and the controllers match
    #: them before the first step and the first answer, so they miss nothing
    extra_recorders: int = 0
    record: bool = True       #: False: no bag (for timing the bare three-node loop)
    #: who writes the bag: 'publishers' (each node logs what it publishes, merged into the bag after the flight:
    #: see quad_msgs_bridge.bag.publication_log) or 'recorder' (the record node, one more reader of every topic)
    record_by: str = 'publishers'
    publish_tf: bool = True   #: the simulator broadcasts every vehicle's odom -> <ns>/base_link on /tf
    plant: str = 'quad_sim'   #: what the simulator node flies (its parameter plant; quad_sim.plants.PLANTS)
    px4: object = None        #: plant px4-sitl: flight_stack.px4_sitl.Px4Install
    #: plant px4-sitl: who takes off, 'px4' (PX4's position controller to the reference's first point, the scenario
    #: shifted up to start PX4_TAKEOFF_ALTITUDE above the ground, and flown from there) or 'controller' (ours, from
    #: the ground); docs/PX4.md, "Take-off"
    px4_takeoff: str = 'px4'
    max_error: float | None = None   #: [m] the run's --max-error, noted in the bag for its review


@dataclass
class RosFlightResult:
    wall_time_s: float
    failed_node: str | None
    exit_codes: dict[str, int]
    sim_report: str
    sim_log: tuple[str, ...] = ()    #: every line the simulator printed
    #: PX4 SITL: why the flight ended in a failsafe (the PX4 bridge's, e.g. PX4 disarmed after a crash), if it did:
    #: an outcome of the flight (it is summarised and reviewed as failed), not a node failure
    flight_failure: str | None = None


def _ros_args(namespace: str, params: dict) -> list[str]:
    args = ['--ros-args', '-r', f'__ns:=/{namespace.strip("/")}']
    for name, value in params.items():
        if isinstance(value, bool):
            text = 'true' if value else 'false'
        elif isinstance(value, (list, tuple)):
            text = yaml.safe_dump(list(value), default_flow_style=True, width=10 ** 6).strip()
        else:
            text = str(value)
        args += ['-p', f'{name}:={text}']
    return args


#: [s, wall] after a dead controller, for the PX4 bridge to land and disarm the vehicle before it is stopped
PX4_LANDING_TIMEOUT = 60.0
#: [s] the bridge's odometry timeout when PX4's own controller flies (ours: the node's default, 0.1 s)
PX4_OWN_ODOM_TIMEOUT = 0.5
#: [s, wall] for PX4 SITL to start and pass its pre-flight checks, take off (px4_takeoff 'px4'), and to land after
#: the flight
PX4_OVERHEAD = 150.0
#: [m] PX4's take-off height above the arming point, where our controller takes over: PX4's own default take-off
#: altitude (MIS_TAKEOFF_ALT, navigator/mission_params.c)
PX4_TAKEOFF_ALTITUDE = 2.5


def fly_ros(config: RosFlightConfig) -> RosFlightResult:
    """Fly with every node in its own process; the bag at ``config.bag`` holds what went over the topics."""
    if config.plant == PX4_SITL:
        return fly_px4(config)
    env = source_tree_environment()
    vehicle = {'vehicle_file': str(config.vehicle_file)} if config.vehicle_file else {}
    home, names = fleet_home(config.vehicles)
    fleet = {'vehicles': names} if len(names) > 1 else {}   # one vehicle: the default, the node's namespace
    initial_states = [value for v in config.vehicles
                      for value in make_scenario(config.scenario, offset=v.offset).initial_state]
    if config.record_by not in RECORD_BY:
        raise ValueError(f'record_by {config.record_by!r}: one of {", ".join(RECORD_BY)}')
    recorder = config.record and config.record_by == 'recorder'
    parts = part_directory(config.bag) if config.record and config.record_by == 'publishers' else None
    logged = {'record_dir': str(parts)} if parts else {}    # each node's own publication log
    if parts is not None:
        shutil.rmtree(parts, ignore_errors=True)
    # readers of every per-step topic beside the flight's own: the writers wait for them (the recorder counts where
    # it records all; else its own gate, matched on its readers' side, is what it has)
    per_step = set(PER_STEP_FLOWN) | ({TF.name} if config.publish_tf else set())
    recorders = config.extra_recorders + (recorder and per_step <= set(config.topics))
    nodes = [('recorder', 'quad_msgs_bridge', 'record', 'quad_msgs_bridge.bag.recorder_node', home,
              {'bag': str(config.bag), 'overwrite': True, 'topics': config.topics, 'controller': config.controller,
               'scenario': config.scenario, 'seed': config.seed, 'settle_time': config.settle_time,
               'disturbances': disturbances_label(config.disturbances), **fleet, **vehicle})] if recorder else []
    for v in config.vehicles:
        label = f' {v.namespace}' if fleet else ''
        nodes += [
            (f'trajectory{label}', 'nnit2fsmc_controller', 'trajectory', 'nnit2fsmc_controller.trajectory_node',
             v.namespace,
             # the path start is given in sim time and the node reads no clock after it: no use_sim_time, so it
             # does not wake for every /clock message (that cost a third of the lockstep rate here)
             {'use_sim_time': False, 'scenario': config.scenario, 'duration': config.duration,
              'setpoint_rate': config.setpoint_rate, 'start_time': 0.0, 'offset': list(v.offset), **logged}),
            (f'controller{label}', 'nnit2fsmc_controller', 'nnit2fsmc_controller',
             'nnit2fsmc_controller.controller_node', v.namespace,
             # it stamps with the odometry's stamp and reads no clock (its odometry watchdog runs on the steady
             # clock): no use_sim_time either, which spares a /clock callback per step (11 % of the lockstep rate)
             {'use_sim_time': False, 'controller': config.controller, 'nnit2fsmc.seed': config.seed,
              'latest_only': config.mode == 'realtime', 'wait_for_recorders': recorders, **vehicle, **logged,
              **({'gains_file': str(config.gains_file)} if config.gains_file else {})})]
    nodes.append(
        ('sim', 'quad_sim', 'quad_sim', 'quad_sim.sim_node', home,
         {'duration': config.duration, 'exit_at_end': True, 'disturbances': config.disturbances,
          'physics_rate': config.physics_rate, 'odometry_rate': config.control_rate, 'mode': config.mode,
          'speed_factor': config.speed_factor, 'plant': config.plant,
          'wait_for_subscribers': (2 if recorder else 1) + config.extra_odom_subscribers + config.extra_recorders,
          'wait_for_recorders': recorders,
          # an outside recorder subscribes to odom among its other topics: give those time to match too
          'start_delay': EXTRA_SUBSCRIBER_DELAY if config.extra_odom_subscribers else 0.0,
          'initial_state': initial_states, 'publish_tf': config.publish_tf, **fleet, **vehicle, **logged}))
    processes: list[NodeProcess] = []
    started = time.monotonic()
    failed = None
    try:
        for name, package, executable, module, namespace, params in nodes:
            command = node_command(package, executable, module) + _ros_args(namespace, params)
            processes.append(NodeProcess(name, command, env, quiet=config.quiet))
        sim = processes[-1]
        # generous: start-up, discovery, and the flight at no less than a tenth of real time per vehicle
        timeout = 60.0 + 10.0 * len(config.vehicles) * config.duration / (
            config.speed_factor if config.mode == 'realtime' else 1.0)
        dead = wait_for_exit(processes, until=sim, timeout=timeout)
        if dead is not None:
            failed = dead.name
        elif sim.returncode != 0:
            failed = sim.name
    except (KeyboardInterrupt, TimeoutError) as stop:
        failed = 'interrupted' if isinstance(stop, KeyboardInterrupt) else f'timeout ({stop})'
    finally:
        if recorder:   # the recorder last: it drains what the others still send
            codes = stop_all(processes[1:])
            if processes:
                codes[processes[0].name] = processes[0].stop(grace=30.0)
        else:
            codes = stop_all(processes)
        if parts is not None and parts.is_dir():    # no directory: no node got as far as opening its log
            merge_publication_logs(config, parts, home, names)
    wall = time.monotonic() - started
    for name, code in codes.items():
        # a node stopped by our SIGINT exits 0; anything else (a crash, a kill) is a failure
        if failed is None and code != 0:
            failed = name
    report = next((line for line in reversed(processes[-1].lines) if 'steps/s' in line), '') if processes else ''
    return RosFlightResult(wall, failed, codes, report, tuple(processes[-1].lines) if processes else ())


def px4_flight_start(scenario: str, offset: Sequence[float], takeoff: str) -> tuple[list, list, float]:
    """Where a PX4 flight starts: the scenario's offset [m, world ENU], and our frame's position [m, world ENU] and
    heading [rad] of the vehicle at flight time 0 (the PX4 bridge's ``initial_position`` and ``initial_yaw``).

    ``takeoff`` 'px4': PX4 takes the vehicle to where the reference starts, raised to PX4_TAKEOFF_ALTITUDE above the
    arming point (so our heights stay heights above it), and the scenario is flown from its first reference point,
    at rest there; 'controller': from the ground below it, as on our simulator."""
    offset = [float(v) for v in offset]
    if takeoff == 'px4':
        offset[2] += PX4_TAKEOFF_ALTITUDE - make_scenario(scenario).sample(0.0).position[2]
        start = make_scenario(scenario, offset=offset).sample(0.0)
        return offset, [float(v) for v in start.position], float(start.yaw)
    initial = make_scenario(scenario, offset=offset).initial_state
    return offset, [float(v) for v in initial[0:3]], float(initial[8])


def fly_px4(config: RosFlightConfig) -> RosFlightResult:
    """A flight on PX4 SITL (module docstring): the Agent and PX4 first, then the trajectory node, the controller
    node (none for the px4 kind) and the PX4 bridge, which ends the flight."""
    from quad_msgs_bridge.px4 import PX4_RECORDED_TOPICS, install_px4_bag_types
    from .px4_sitl import Px4Sitl, take_slot
    if config.px4 is None or len(config.vehicles) != 1 or config.record_by != 'publishers' or not config.record:
        raise ValueError('a PX4 SITL flight needs px4 (find_px4), one vehicle and record_by publishers')
    [vehicle] = config.vehicles
    home = vehicle.namespace
    offset, initial_position, initial_yaw = px4_flight_start(config.scenario, vehicle.offset, config.px4_takeoff)
    parts = part_directory(config.bag)
    shutil.rmtree(parts, ignore_errors=True)
    logged = {'record_dir': str(parts)}
    vehicle_param = {'vehicle_file': str(config.vehicle_file)} if config.vehicle_file else {}
    slot = take_slot()
    sitl = Px4Sitl(config.px4, slot, source_tree_environment(), quiet=config.quiet)
    env = sitl.env
    own = config.controller == PX4_CONTROLLER
    nodes = [('trajectory', 'nnit2fsmc_controller', 'trajectory', 'nnit2fsmc_controller.trajectory_node',
              {'use_sim_time': False, 'scenario': config.scenario, 'duration': config.duration,
               'setpoint_rate': config.setpoint_rate, 'start_time': 0.0, 'offset': offset, **logged})]
    if not own:
        nodes.append(('controller', 'nnit2fsmc_controller', 'nnit2fsmc_controller',
                      'nnit2fsmc_controller.controller_node',
                      {'use_sim_time': False, 'controller': config.controller, 'nnit2fsmc.seed': config.seed,
                       'latest_only': True, **vehicle_param, **logged,
                       **({'gains_file': str(config.gains_file)} if config.gains_file else {})}))
    nodes.append(('px4_bridge', 'quad_sim', 'px4_bridge', 'quad_sim.px4_node',
                  {'control_level': 'position' if own else 'direct_actuator', 'duration': config.duration,
                   # PX4's own controller flies on its own estimate: a gap in the odometry we see is no reason to
                   # take the vehicle from it (a 0.1 s gap ended one such flight on this loaded machine)
                   **({'odom_timeout': PX4_OWN_ODOM_TIMEOUT} if own else {}),
                   'exit_at_end': True, 'initial_position': initial_position, 'initial_yaw': initial_yaw,
                   'takeoff': config.px4_takeoff, 'takeoff_altitude': PX4_TAKEOFF_ALTITUDE,
                   'target_system': slot.target_system, 'px4_namespace': slot.namespace,
                   'vehicle_file': str(config.vehicle_file) if config.vehicle_file else 'px4-sih-quadx', **logged}))
    processes: list[NodeProcess] = []
    px4_processes: list[NodeProcess] = []
    started = time.monotonic()
    failed = None
    if not config.quiet:
        print(f'starting {sitl.describe()}', flush=True)
    try:
        px4_processes = sitl.start()
        for name, package, executable, module, params in nodes:
            command = node_command(package, executable, module) + _ros_args(home, params)
            processes.append(NodeProcess(name, command, env, quiet=config.quiet))
        bridge = processes[-1]
        timeout = PX4_OVERHEAD + 2.0 * config.duration
        dead = wait_for_exit(processes + px4_processes, until=bridge, timeout=timeout)
        if dead is not None:
            failed = dead.name
            if dead.name in ('controller', 'trajectory') and bridge.returncode is None:
                print(f'[{dead.name}] exited (code {dead.returncode}) in flight: the PX4 bridge hands the vehicle to '
                      'PX4\'s land mode; waiting for it to land and disarm', flush=True)
                try:
                    wait_for_exit([bridge] + px4_processes, until=bridge, timeout=PX4_LANDING_TIMEOUT)
                except TimeoutError:
                    pass
        elif bridge.returncode != 0:
            failed = bridge.name
    except (KeyboardInterrupt, TimeoutError) as stop:
        failed = 'interrupted' if isinstance(stop, KeyboardInterrupt) else f'timeout ({stop})'
    finally:
        codes = stop_all(processes)
        px4_codes = stop_all(px4_processes)
        sitl.close()
        if parts.is_dir():
            install_px4_bag_types()
            merge_publication_logs(config, parts, home, [''], extra_topics=PX4_RECORDED_TOPICS)
    wall = time.monotonic() - started
    for name, code in codes.items():
        if failed is None and code != 0:
            failed = name
    flight_failure = None
    if processes and failed in (processes[-1].name, 'controller', 'trajectory'):
        bridge_lines = processes[-1].lines
        why = next((line.split('-> failsafe: ', 1)[1] for line in bridge_lines if '-> failsafe: ' in line), None)
        done = any('PX4 disarmed: the flight is over' in line for line in bridge_lines)
        if why is not None and done:     # the bridge ended the flight by a failsafe and saw PX4 disarm
            flight_failure = f'PX4 failsafe: {why}' + (f' ({failed} exited in flight)' if failed != 'px4_bridge'
                                                         else '')
            if failed == 'px4_bridge':
                failed = None
    codes.update({name: code for name, code in px4_codes.items()})
    return RosFlightResult(wall, failed, codes, sitl.describe(), tuple(processes[-1].lines) if processes else (),
                           flight_failure)


def part_directory(bag: Path) -> Path:
    """Where the nodes of a flight recorded by its publishers put their part bags: beside ``bag``."""
    return bag.with_name(f'{bag.name}.parts')


def merge_publication_logs(config: RosFlightConfig, parts: Path, home: str, names: list[str],
                           extra_topics=()) -> None:
    """The flight's bag at ``config.bag`` from the nodes' part bags in ``parts``, which then go. A part a killed
    node left unfinished is merged up to its last complete chunk, and said so."""
    params, _ = load_vehicle_file(config.vehicle_file)
    namespaces = vehicle_namespaces('/' + home.strip('/'), names)
    known = {topic.name: topic for topic in RECORDED_TOPICS}
    custom = ros_flight_custom_data(params, config.settle_time, config.seed, namespaces,
                                    controller=config.controller, scenario=config.scenario,
                                    disturbances=disturbances_label(config.disturbances),
                                    **{DURATION_KEY: repr(float(config.duration)),
                                       MAX_ERROR_KEY: '' if config.max_error is None else repr(config.max_error)})
    result = merge_parts(parts, config.bag, [known[name] for name in config.topics] + list(extra_topics), namespaces,
                         custom, overwrite=True)
    for part, reason in result.cut.items():
        print(f'publication log {part} ends early ({reason}): merged up to its last complete chunk', flush=True)
    shutil.rmtree(parts)
