"""PX4's offboard protocol as a state machine, no ROS: what to send PX4 so that our controller flies it.

The PX4 node (:mod:`quad_sim.px4_node`) calls :meth:`OffboardCore.tick` with its clock and whatever arrived (PX4's
odometry and status, our controller's rotor forces) and publishes what the tick returns. Times are the caller's
clock [s] (the node: its ROS clock, which the uXRCE-DDS Agent's time sync maps to PX4's); every timeout counts
from when data *arrived*, so no PX4 and ROS clock offset enters a decision.

Phases (:class:`Phase`):

1. ``waiting``: no fresh, valid odometry yet (fresh: arrived within ``odom_timeout``; valid: finite, in a supported
   frame: :func:`quad_msgs_bridge.px4.state_from_px4_odometry`). Nothing is sent.
2. ``streaming``: the OffboardControlMode heartbeat every ``heartbeat_period`` with an idle setpoint (zero thrust),
   for ``prearm_stream`` s: PX4 switches to offboard only while the heartbeat is recent (its offboard check
   accepts a heartbeat younger than COM_OF_LOSS_T, commander/HealthAndArmingChecks/checks/offboardCheck.cpp), and
   PX4's guide asks for the stream (> 2 Hz) before the switch; its ROS 2 example streams 1 s (10 setpoints at
   10 Hz). Stale or invalid odometry sends the machine back to ``waiting``: it never asks to arm on it.
3. ``requesting``: VEHICLE_CMD_DO_SET_MODE (param1 1 = custom mode, param2 6 = PX4's offboard main mode) until
   VehicleStatus reports nav_state OFFBOARD, then VEHICLE_CMD_COMPONENT_ARM_DISARM (param1 1) until it reports
   arming_state ARMED, each repeated every ``command_retry`` s, while the heartbeat goes on. Not done within
   ``request_timeout`` s: ``failsafe`` (disarm if armed).
4. ``taking_off`` (``takeoff`` 'px4' only): PX4's own position controller climbs to ``takeoff_altitude`` above the
   arming point (the heartbeat at the position level, a TrajectorySetpoint holding that point at the arming
   heading). Once the odometry has been within ``handover_distance`` of it and slower than ``handover_speed`` for
   ``handover_hold`` s, the flight starts there. Why (docs/PX4.md, "Take-off"): on the ground SIH holds the vehicle
   level and still while PX4's EKF2 estimate of it wanders (tens of cm, tenths of m/s, its height too), so a
   controller flying from the ground sees a flight that is not happening, asks moments the ground absorbs, and
   gets them all at once at lift-off. With ``takeoff`` 'controller' the flight starts at arming instead.
5. ``flying``: our controller flies (with ``takeoff`` 'controller' from the ground up: the take-off is the first part
   of its reference). Our ``odom`` is published from here, stamped from 0 at the first sample (flight time, as the
   simulator's sim time), so the controller starts as it does on the simulator, and no control law winds up before
   it flies (nothing is published to it until then). The heartbeat names the control level: ``direct_actuator``
   (ActuatorMotors, each rotor's relative thrust F/F_max) or ``thrust_and_torque`` (VehicleThrustSetpoint and
   VehicleTorqueSetpoint, normalised: quad_msgs_bridge.px4); after PX4's take-off it changes to that level with
   the controller's first answer, in the same tick as that answer's setpoint, and holds the take-off point until
   then.
6. ``landing`` (after :meth:`OffboardCore.request_landing`): VEHICLE_CMD_NAV_LAND until nav_state AUTO_LAND, no
   more heartbeat; PX4 lands under its own controllers. Once the odometry shows the vehicle back at its take-off
   height (within ``landed_height``) and still (below ``landed_speed``) for ``landed_hold`` s, disarm
   (ARM_DISARM param1 0) until disarmed: ``done``. PX4 also disarms by itself 2 s after it detects the landing
   (COM_DISARM_LAND default 2.0, commander_params.c).
7. ``failsafe``: when our side fails in flight (no forces for ``forces_timeout`` s after the first ones, or none
   within ``first_forces_timeout`` s of the flight's start, or odometry stale or invalid; during PX4's take-off:
   odometry stale or invalid, or the take-off point not reached in ``takeoff_timeout`` s), the heartbeat stops and
   NAV_LAND hands the vehicle to PX4's land mode at once; when PX4 leaves offboard or disarms by itself (its failsafe, a
   pilot), nothing is sent: PX4 is in charge. ``done`` once disarmed.

When our controller (or this node) goes quiet without saying so, PX4 acts by itself: COM_OF_LOSS_T (default 1.0 s)
after the last OffboardControlMode heartbeat it takes the offboard-loss action COM_OBL_RC_ACT (default 0: Position
mode; 1 Altitude, 2 Manual, 3 Return, 4 Land, 5 Hold, 6 Terminate, 7 Disarm), commander_params.c and
commander/failsafe/failsafe.cpp (fromOffboardLossActParam). Position mode needs a manual control input (RC or
joystick); without one PX4's failsafe falls back further. Set COM_OBL_RC_ACT 4 (Land) for flights without RC.

Never sent: a non-finite used command (forces and odometry are checked when they arrive, a bad one is rejected with
one event per episode and the last valid one holds). ActuatorMotors' 8 unused controls are NaN, PX4's "disarmed"
(msg/ActuatorMotors.msg).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple, Sequence

from quad_msgs_bridge import px4
from quad_msgs_bridge.mixer import controls_from_forces
from quad_msgs_bridge.state import OdometrySample, odometry_from_state
from quad_msgs_bridge.validation import ParameterError, check_number
from quad_msgs_bridge.vehicle_params import VehicleParams

#: what the flight sends PX4: our rotor forces as ActuatorMotors, or as normalised thrust and torque; or
#: ``position``: our reference as TrajectorySetpoint (position, velocity, acceleration feed-forward, yaw), flown by
#: PX4's own cascaded position/velocity/attitude/rate controller (run_stack.py --controller px4)
CONTROL_LEVELS = ('direct_actuator', 'thrust_and_torque', 'position')
#: who takes off: ``controller`` (ours, from the ground: flight time 0 at arming) or ``px4`` (PX4's position
#: controller, then a hand-over in the air: flight time 0 there)
TAKEOFFS = ('controller', 'px4')

# msg/VehicleCommand.msg and msg/VehicleStatus.msg
VEHICLE_CMD_NAV_LAND = 21
VEHICLE_CMD_DO_SET_MODE = 176
VEHICLE_CMD_COMPONENT_ARM_DISARM = 400
ARMING_STATE_DISARMED = 1
ARMING_STATE_ARMED = 2
NAVIGATION_STATE_OFFBOARD = 14
NAVIGATION_STATE_AUTO_LAND = 18
#: DO_SET_MODE's param1 (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) and param2 (PX4's custom main mode OFFBOARD), as PX4's
#: ROS 2 offboard example sends them (docs.px4.io, "ROS 2 Offboard Control Example")
CUSTOM_MODE, PX4_OFFBOARD_MAIN_MODE = 1.0, 6.0


class Phase(str, Enum):
    WAITING = 'waiting'
    STREAMING = 'streaming'
    REQUESTING = 'requesting'
    TAKING_OFF = 'taking_off'
    FLYING = 'flying'
    LANDING = 'landing'
    FAILSAFE = 'failsafe'
    DONE = 'done'


class Px4Status(NamedTuple):
    """The fields of ``px4_msgs/VehicleStatus`` the machine reads."""

    arming_state: int     #: ARMING_STATE_DISARMED or ARMING_STATE_ARMED
    nav_state: int        #: NAVIGATION_STATE_OFFBOARD, NAVIGATION_STATE_AUTO_LAND, ...
    #: PX4's arming checks pass (EKF2 converged, GPS, sensors): a freshly started SITL needs ~10-20 s for them
    pre_flight_checks_pass: bool = True


class OffboardMode(NamedTuple):
    """``px4_msgs/OffboardControlMode``: which setpoints PX4 is to follow (msg/OffboardControlMode.msg)."""

    timestamp_us: int
    position: bool = False
    velocity: bool = False
    acceleration: bool = False
    attitude: bool = False
    body_rate: bool = False
    thrust_and_torque: bool = False
    direct_actuator: bool = False


class VehicleCommand(NamedTuple):
    """``px4_msgs/VehicleCommand``: the fields we set (the others zero)."""

    timestamp_us: int
    command: int
    param1: float
    param2: float
    target_system: int
    target_component: int
    source_system: int
    source_component: int
    from_external: bool = True


class Setpoint(NamedTuple):
    """The actuator-level setpoint of one tick: ``motors`` (ActuatorMotors.control, 12) for direct_actuator, or
    ``thrust`` and ``torque`` (VehicleThrustSetpoint.xyz, VehicleTorqueSetpoint.xyz, body FRD, normalised)."""

    timestamp_us: int
    motors: tuple | None = None
    thrust: tuple | None = None
    torque: tuple | None = None
    trajectory: px4.Px4TrajectorySetpoint | None = None   #: the ``position`` level's TrajectorySetpoint


class Output(NamedTuple):
    """What to publish after one tick (None / empty: nothing)."""

    phase: Phase
    mode: OffboardMode | None            #: the heartbeat
    setpoint: Setpoint | None
    commands: tuple                      #: VehicleCommand records, in order
    odometry: OdometrySample | None      #: our ``odom``, stamped in flight time [s]
    events: tuple                        #: log lines: phase changes and the start of a rejection episode


@dataclass(frozen=True)
class OffboardConfig:
    """Settings of the machine; times [s], of the caller's clock."""

    control_level: str = 'direct_actuator'
    odom_timeout: float = 0.1          #: odometry older than this is stale (PX4 sends it at up to 100 Hz)
    heartbeat_period: float = 0.05     #: OffboardControlMode every 50 ms: 20 Hz, PX4 needs > 2 Hz
    prearm_stream: float = 1.0         #: heartbeats before asking for offboard
    command_retry: float = 0.5         #: between repeats of an unanswered VehicleCommand
    request_timeout: float = 5.0       #: for PX4 to accept offboard and arm
    first_forces_timeout: float = 1.0  #: after the flight's start, for the controller's first rotor forces
    forces_timeout: float = 0.1        #: controller silence in flight before PX4's land mode takes over
    landed_height: float = 0.1         #: [m] above the take-off height: on the ground
    landed_speed: float = 0.1          #: [m/s] below: still
    landed_hold: float = 1.0           #: on the ground and still this long: disarm
    target_system: int = 1             #: MAV_SYS_ID of PX4 (1 for the first SITL instance)
    target_component: int = 1
    source_system: int = 1
    source_component: int = 1
    #: [m, world ENU] where our frame puts the vehicle at flight time 0 (the scenario's start): our ``odom`` is
    #: PX4's position less its position at arming plus this (PX4's EKF origin is not our scenario's; its height
    #: estimate on the ground also drifts by metres before take-off), and a ``position`` reference goes back the
    #: same way
    initial_position: tuple = (0.0, 0.0, 0.0)
    #: [rad, ENU] our frame's heading of the vehicle at flight time 0 (the scenario's start): our world is PX4's
    #: turned about the vertical so that the vehicle's heading at arming becomes this one (PX4's SIH vehicle starts
    #: facing north, psi = pi/2, where our scenarios start at their reference's yaw; a rigid turn of the world,
    #: which SIH's physics without wind does not notice)
    initial_yaw: float = 0.0
    #: before asking to arm, PX4's odometry must have been still (speed below ``still_speed``, position within
    #: ``still_distance`` of where the window began) this long after its pre-flight checks passed: PX4 SITL's EKF2
    #: dead-reckons before it fuses GPS (its estimate wandered tens of metres at up to 3 m/s on the ground here) and
    #: resets when it does (a 1.5 m/s velocity error at arming here); a controller armed on that chases an estimate
    #: running away
    settle_time: float = 2.0
    #: [m/s] (SIH's EKF2 estimate of the vehicle on the ground here: speeds of 0.2-0.6 m/s and +-0.5 m of position
    #: noise even once settled; the gate keeps out only the runaway before and at its GPS reset)
    still_speed: float = 0.6
    still_distance: float = 0.8            #: [m]
    takeoff: str = 'controller'            #: TAKEOFFS
    #: [m] above the arming point, where PX4 takes the vehicle before the hand-over (PX4's own take-off altitude,
    #: MIS_TAKEOFF_ALT, defaults to 2.5 m: navigator/mission_params.c)
    takeoff_altitude: float = 2.5
    #: the hand-over waits until the odometry has been within ``handover_distance`` [m] of the take-off point and
    #: slower than ``handover_speed`` [m/s] for ``handover_hold`` [s]; loose because PX4's own hold of SIH wanders as
    #: its estimate does (docs/PX4.md); not there within ``takeoff_timeout`` [s] of arming: PX4 lands
    handover_distance: float = 0.5
    handover_speed: float = 0.5
    handover_hold: float = 1.0
    takeoff_timeout: float = 30.0

    def __post_init__(self):
        if self.control_level not in CONTROL_LEVELS:
            raise ParameterError(f'control_level: {self.control_level!r} is not one of {", ".join(CONTROL_LEVELS)}')
        if self.takeoff not in TAKEOFFS:
            raise ParameterError(f'takeoff: {self.takeoff!r} is not one of {", ".join(TAKEOFFS)}')
        for name in ('takeoff_altitude', 'handover_distance', 'handover_speed', 'takeoff_timeout'):
            check_number(name, getattr(self, name), 0.0, math.inf, low_inclusive=False)
        check_number('handover_hold', self.handover_hold, 0.0)
        for name in ('odom_timeout', 'heartbeat_period', 'command_retry', 'request_timeout', 'first_forces_timeout',
                     'forces_timeout', 'landed_height', 'landed_speed'):
            check_number(name, getattr(self, name), 0.0, math.inf, low_inclusive=False)
        for name in ('prearm_stream', 'landed_hold', 'settle_time', 'still_speed', 'still_distance'):
            check_number(name, getattr(self, name), 0.0)
        check_number('initial_yaw', self.initial_yaw)
        if len(self.initial_position) != 3 or not all(math.isfinite(v) for v in self.initial_position):
            raise ParameterError(f'initial_position: {self.initial_position} is not 3 finite values [m]')
        if self.heartbeat_period >= 0.5:
            raise ParameterError(f'heartbeat_period: {self.heartbeat_period} s is not below 0.5 s (PX4 needs > 2 Hz)')


class OffboardCore:
    """The offboard state machine of one vehicle (module docstring). ``params``: the vehicle PX4 flies (F_max, the
    rotor layout); ``geometry``: PX4's CA_ROTOR* geometry of it (quad_msgs_bridge.px4)."""

    def __init__(self, params: VehicleParams, config: OffboardConfig = OffboardConfig(),
                 geometry: px4.Px4RotorGeometry = px4.SIH_QUADX):
        self.params, self.config = params, config
        self.order = px4.motor_order(params, geometry)                  # ValueError: PX4 flies another layout
        self.scales = px4.wrench_scales(params, geometry) if config.control_level == 'thrust_and_torque' else None
        self.phase = Phase.WAITING
        self.since = -math.inf             #: [s] when the phase began
        self.landing_requested = False
        self.status: Px4Status | None = None
        self.state: list[float] | None = None        #: the latest valid odometry, our 12 states
        self.odometry_us: int | None = None          #: [us] its PX4 sample time
        self.odometry_arrival = -math.inf            #: [s] when it arrived
        self.odometry_rejected = False
        self.flight_origin_us: int | None = None     #: [us] PX4 sample time of flight time 0
        self.publish_origin = False                  #: that sample is our first odom, sent when the flight starts
        self.ground_z: float | None = None           #: [m, ENU] height at flight time 0
        #: [m, ENU] PX4's position at flight time 0 (until then: the latest), our frame's initial_position
        self.origin: tuple | None = None
        self.turn = 0.0                              #: [rad] our world's heading less PX4's (ENU)
        self.still_since: float | None = None
        self.forces: tuple | None = None             #: the latest valid rotor forces [N]
        self.forces_arrival = -math.inf
        self.forces_rejected = False
        self.last_heartbeat = -math.inf
        self.last_command: dict[int, float] = {}     #: command -> when last sent
        self.failsafe_command: int | None = None
        self.waiting_for_checks = False
        self.waiting_for_still = False
        self.still_from: tuple | None = None          #: (since when, where) the odometry has been still
        #: [m, ENU of PX4's odometry] and [rad] where PX4 takes off to and its heading (``takeoff`` 'px4')
        self.takeoff_point: tuple | None = None
        self.takeoff_yaw = 0.0
        self.near_since: float | None = None          #: since when the vehicle has been at the take-off point
        self.sent_level: str | None = None            #: the control level the last heartbeat named
        self.failed: str | None = None               #: why the flight ended in a failsafe, if it did

    # --- inputs ---------------------------------------------------------------------------------------------
    def request_landing(self) -> None:
        """End the flight: land and disarm (before the flight: stop, disarming if PX4 armed)."""
        self.landing_requested = True

    def _take_odometry(self, now: float, odometry: px4.Px4Odometry, events: list) -> bool:
        """Accept a new sample (its PX4 time after the last one's); True if it is new and valid."""
        if self.odometry_us is not None and odometry.timestamp_us <= self.odometry_us:
            return False                  # a repeat or an older one
        try:
            state = px4.state_from_px4_odometry(odometry)
        except ValueError as error:
            if not self.odometry_rejected:
                events.append(f'odometry rejected: {error}')
            self.odometry_rejected = True
            return False
        self.odometry_rejected = False
        self.state, self.odometry_us, self.odometry_arrival = state, int(odometry.timestamp_us), now
        return True

    def _take_forces(self, now: float, forces: Sequence[float], events: list) -> bool:
        """Take rotor forces [N] (4), or at the ``position`` level a reference (11: position [m], velocity [m/s],
        acceleration [m/s^2], world ENU in our frame, yaw [rad], yaw rate [rad/s])."""
        values = tuple(float(f) for f in forces)
        size, what = (11, 'reference') if self.config.control_level == 'position' else (4, 'rotor forces')
        if len(values) != size or not all(math.isfinite(f) for f in values):
            if not self.forces_rejected:
                events.append(f'{what} rejected ({size} finite values needed): {values}')
            self.forces_rejected = True
            return False
        self.forces_rejected = False
        self.forces, self.forces_arrival = values, now
        return True

    def speed(self) -> float:
        """[m/s] of the latest odometry."""
        return math.sqrt(sum(v * v for v in self.state[3:6]))

    def _odometry_problem(self) -> str:
        """Why the odometry is not fresh and valid, for an event."""
        return 'odometry invalid' if self.odometry_rejected else f'odometry older than {self.config.odom_timeout} s'

    def odometry_fresh(self, now: float) -> bool:
        return self.state is not None and not self.odometry_rejected and now - self.odometry_arrival <= \
            self.config.odom_timeout

    # --- outputs --------------------------------------------------------------------------------------------
    def _holding(self) -> bool:
        """True while PX4 flies to or holds the take-off point (``takeoff`` 'px4': until the controller's first
        answer after the hand-over)."""
        return self.phase == Phase.TAKING_OFF or (self.phase == Phase.FLYING and self.takeoff_point is not None
                                                 and self.forces is None)

    def _level(self) -> str:
        """The control level the heartbeat names now."""
        return 'position' if self._holding() else self.config.control_level

    def _mode(self, now: float) -> OffboardMode:
        """The heartbeat, naming the control level from the first one (PX4's offboard check wants some flag set)."""
        level = self._level()
        self.sent_level = level
        if level == 'position':
            return OffboardMode(_us(now), position=True, velocity=True, acceleration=True)
        return OffboardMode(_us(now), thrust_and_torque=level == 'thrust_and_torque',
                            direct_actuator=level == 'direct_actuator')

    def _setpoint(self, now: float, forces: tuple | None) -> Setpoint:
        """The level's setpoint of rotor forces [N] (None: idle, zero thrust); at the ``position`` level of the
        reference (None: hold where the vehicle is, at its heading); while PX4 takes off, its take-off point."""
        if self._holding():
            return Setpoint(_us(now), trajectory=px4.trajectory_setpoint(self.takeoff_point, (0.0,) * 3, (0.0,) * 3,
                                                                         self.takeoff_yaw, 0.0))
        if self.config.control_level == 'position':
            return Setpoint(_us(now), trajectory=self._trajectory(forces))
        if self.config.control_level == 'direct_actuator':
            return Setpoint(_us(now), motors=px4.motor_controls(forces or (0.0,) * 4, self.params, self.order))
        if forces is None:
            return Setpoint(_us(now), thrust=(0.0, 0.0, 0.0), torque=(0.0, 0.0, 0.0))
        thrust, torque = px4.thrust_torque_setpoints(controls_from_forces(*forces, self.params.mixer), self.params,
                                                     self.scales)
        return Setpoint(_us(now), thrust=thrust, torque=torque)

    def _trajectory(self, reference: tuple | None) -> px4.Px4TrajectorySetpoint:
        """PX4's TrajectorySetpoint of a reference in our frame (None: hold the latest odometry's position and
        heading, at rest)."""
        state = self.state
        if reference is None:
            return px4.trajectory_setpoint(state[0:3], (0.0,) * 3, (0.0,) * 3, state[8], 0.0)
        relative = [r - i for r, i in zip(reference[0:3], self.config.initial_position)]
        position = [p + o for p, o in zip(_turned(relative, -self.turn), self.origin)]
        return px4.trajectory_setpoint(position, _turned(reference[3:6], -self.turn),
                                       _turned(reference[6:9], -self.turn), reference[9] - self.turn, reference[10])

    def our_state(self) -> list[float]:
        """The latest odometry in our frame: PX4's world (ENU) moved so that the vehicle's position and heading at
        flight time 0 become ``initial_position`` and ``initial_yaw``: position Rz(turn) (p - origin) +
        initial_position, velocity Rz(turn) v, psi + turn; roll, pitch and the Euler-angle rates as they are."""
        origin = self.origin if self.origin is not None else self.state[0:3]
        relative = _turned([p - o for p, o in zip(self.state[0:3], origin)], self.turn)
        psi = math.atan2(math.sin(self.state[8] + self.turn), math.cos(self.state[8] + self.turn))
        return [*(r + i for r, i in zip(relative, self.config.initial_position)), *_turned(self.state[3:6], self.turn),
                self.state[6], self.state[7], psi, *self.state[9:12]]

    def _command(self, now: float, command: int, param1: float = 0.0, param2: float = 0.0) -> VehicleCommand | None:
        """The command if it is due (never sent, or ``command_retry`` s ago), else None."""
        if now - self.last_command.get(command, -math.inf) < self.config.command_retry:
            return None
        self.last_command[command] = now
        c = self.config
        return VehicleCommand(_us(now), command, float(param1), float(param2), c.target_system, c.target_component,
                              c.source_system, c.source_component)

    def _enter(self, now: float, phase: Phase, events: list, why: str) -> None:
        events.append(f'{self.phase.value} -> {phase.value}: {why}')
        self.phase, self.since = phase, now
        self.last_command.clear()

    def _fail(self, now: float, events: list, why: str, command: int | None) -> None:
        self.failsafe_command = command
        self.failed = why
        self._enter(now, Phase.FAILSAFE, events, why)

    # --- the machine ----------------------------------------------------------------------------------------
    def tick(self, now: float, odometry: px4.Px4Odometry | None = None, status: Px4Status | None = None,
             forces: Sequence[float] | None = None) -> Output:
        """Advance to time ``now`` [s] with what arrived since the last tick (None: nothing); what to publish."""
        events: list[str] = []
        new_odometry = odometry is not None and self._take_odometry(now, odometry, events)
        new_forces = forces is not None and self._take_forces(now, forces, events)
        if status is not None:
            self.status = status
        commands: list = []
        mode = setpoint = None
        step = getattr(self, f'_{self.phase.value}')
        heartbeat = step(now, events, commands, new_forces)
        if heartbeat:
            # a change of control level (the hand-over's first answer) goes out at once, with its setpoint
            due = now - self.last_heartbeat >= self.config.heartbeat_period or self._level() != self.sent_level
            flying = self.phase == Phase.FLYING
            if due:
                mode = self._mode(now)
                self.last_heartbeat = now
            if flying and (new_forces or due):
                setpoint = self._setpoint(now, self.forces)
            elif not flying and due:
                setpoint = self._setpoint(now, None)
        our_odometry = None
        if self.flight_origin_us is not None and (new_odometry or self.publish_origin):
            our_odometry = odometry_from_state((self.odometry_us - self.flight_origin_us) * 1e-6, self.our_state())
            self.publish_origin = False
        return Output(self.phase, mode, setpoint, tuple(c for c in commands if c is not None), our_odometry,
                      tuple(events))

    def _armed(self) -> bool:
        return self.status is not None and self.status.arming_state == ARMING_STATE_ARMED

    def _waiting(self, now, events, commands, new_forces) -> bool:
        if self.landing_requested:
            self._enter(now, Phase.DONE, events, 'landing requested before the flight')
        elif self.odometry_fresh(now):
            self._enter(now, Phase.STREAMING, events, 'fresh, valid odometry')
            return True
        return False

    def _pre_flight_checks(self, now, events) -> bool:
        """False (and the phase left) when the flight must not go on: landing requested or bad odometry."""
        if self.landing_requested:
            if self._armed():
                self._fail(now, events, 'landing requested before the flight: disarming',
                           VEHICLE_CMD_COMPONENT_ARM_DISARM)
            else:
                self._enter(now, Phase.DONE, events, 'landing requested before the flight')
            return False
        if not self.odometry_fresh(now):
            why = self._odometry_problem()
            if self._armed():
                self._fail(now, events, f'{why}: disarming', VEHICLE_CMD_COMPONENT_ARM_DISARM)
            else:
                self._enter(now, Phase.WAITING, events, f'{why}: not arming')
            return False
        return True

    def _streaming(self, now, events, commands, new_forces) -> bool:
        if not self._pre_flight_checks(now, events):
            return False
        if now - self.since >= self.config.prearm_stream:
            if self.status is None or not self.status.pre_flight_checks_pass:
                if not self.waiting_for_checks:
                    events.append('waiting for PX4\'s pre-flight checks to pass (VehicleStatus.pre_flight_checks_pass)')
                self.waiting_for_checks = True
                self.still_from = None
                return True
            if not self._settled(now, events):
                return True
            self._enter(now, Phase.REQUESTING, events, f'{self.config.prearm_stream} s of heartbeats')
            return self._requesting(now, events, commands, new_forces)
        return True

    def _settled(self, now: float, events: list) -> bool:
        """True once the odometry has been still for ``settle_time`` s (config), the window restarting on a move."""
        c = self.config
        speed = self.speed()
        if self.still_from is not None:
            moved = math.dist(self.state[0:3], self.still_from[1])
            if speed > c.still_speed or moved > c.still_distance:
                self.still_from = None
        if self.still_from is None:
            if speed > c.still_speed:
                if not self.waiting_for_still:
                    events.append(f'waiting for PX4\'s odometry to be still before arming (speed {speed:.2f} m/s on '
                                  'the ground: EKF2 still settling)')
                self.waiting_for_still = True
                return False
            self.still_from = (now, tuple(self.state[0:3]))
        return now - self.still_from[0] >= c.settle_time

    def _requesting(self, now, events, commands, new_forces) -> bool:
        if not self._pre_flight_checks(now, events):
            return False
        if now - self.since > self.config.request_timeout:
            self._fail(now, events, f'PX4 did not accept offboard and arming within {self.config.request_timeout} s',
                       VEHICLE_CMD_COMPONENT_ARM_DISARM if self._armed() else None)
            return False
        status = self.status
        if status is None or status.nav_state != NAVIGATION_STATE_OFFBOARD:
            commands.append(self._command(now, VEHICLE_CMD_DO_SET_MODE, CUSTOM_MODE, PX4_OFFBOARD_MAIN_MODE))
        elif status.arming_state != ARMING_STATE_ARMED:
            commands.append(self._command(now, VEHICLE_CMD_COMPONENT_ARM_DISARM, 1.0))
        else:
            self.ground_z = self.state[2]
            if self.config.takeoff == 'px4':
                self.takeoff_point = (*self.state[0:2], self.state[2] + self.config.takeoff_altitude)
                self.takeoff_yaw = self.state[8]
                self._enter(now, Phase.TAKING_OFF, events, f'PX4 is in offboard and armed: PX4 takes off to '
                            f'{self.config.takeoff_altitude:g} m')
            else:
                self._start_flight(now, events, 'PX4 is in offboard and armed: our controller flies')
        return True

    def _start_flight(self, now: float, events: list, why: str) -> None:
        """Flight time 0: our frame's origin here, our ``odom`` from this sample on."""
        self._enter(now, Phase.FLYING, events, why)
        self.flight_origin_us, self.publish_origin = self.odometry_us, True
        self.origin = tuple(self.state[0:3])
        self.turn = self.config.initial_yaw - self.state[8]
        self.forces = None        # forces from before the flight are not flown

    def _airborne_checks(self, now, events, commands, new_forces, during: str = '') -> bool | None:
        """What every phase armed in offboard checks first (``during``: words for its events): PX4 left offboard or
        disarmed (``failsafe``, PX4 in charge), a landing requested (``landing``), the odometry stale or invalid
        (``failsafe``, PX4 lands). None if the phase goes on; else what its tick returns."""
        status = self.status
        if status.arming_state != ARMING_STATE_ARMED or status.nav_state != NAVIGATION_STATE_OFFBOARD:
            self._fail(now, events, f'PX4 left offboard by itself (arming_state {status.arming_state}, nav_state '
                       f'{status.nav_state}): PX4 is in charge', None)
            return False
        if self.landing_requested:
            self._enter(now, Phase.LANDING, events, f'landing requested{during}: PX4 lands')
            return self._landing(now, events, commands, new_forces)
        if not self.odometry_fresh(now):
            self._fail(now, events, f'{self._odometry_problem()}{during}: PX4 lands', VEHICLE_CMD_NAV_LAND)
            return self._failsafe(now, events, commands, new_forces)
        return None

    def _taking_off(self, now, events, commands, new_forces) -> bool:
        c = self.config
        ended = self._airborne_checks(now, events, commands, new_forces, ' during the take-off')
        if ended is not None:
            return ended
        if now - self.since > c.takeoff_timeout:
            self._fail(now, events, f'PX4 did not reach the take-off point within {c.takeoff_timeout:g} s: PX4 lands',
                       VEHICLE_CMD_NAV_LAND)
            return self._failsafe(now, events, commands, new_forces)
        near = (math.dist(self.state[0:3], self.takeoff_point) <= c.handover_distance
                and self.speed() <= c.handover_speed)
        if not near:
            self.near_since = None
        elif self.near_since is None:
            self.near_since = now
        if near and now - self.near_since >= c.handover_hold:
            self._start_flight(now, events, f'at the take-off point for {c.handover_hold:g} s: our controller flies')
        return True

    def _flying(self, now, events, commands, new_forces) -> bool:
        ended = self._airborne_checks(now, events, commands, new_forces)
        if ended is not None:
            return ended
        if self.forces is None and now - self.since > self.config.first_forces_timeout:
            self._fail(now, events, f'no rotor forces within {self.config.first_forces_timeout} s of the flight\'s '
                       'start: PX4 lands', VEHICLE_CMD_NAV_LAND)
            return self._failsafe(now, events, commands, new_forces)
        if self.forces is not None and now - self.forces_arrival > self.config.forces_timeout:
            self._fail(now, events, f'no rotor forces for {self.config.forces_timeout} s: PX4 lands',
                       VEHICLE_CMD_NAV_LAND)
            return self._failsafe(now, events, commands, new_forces)
        return True

    def _landed(self, now) -> bool:
        """On the ground and still for ``landed_hold`` s (from the odometry)."""
        c = self.config
        on_ground = (self.state is not None and self.state[2] - self.ground_z <= c.landed_height
                     and self.speed() <= c.landed_speed)
        if not on_ground:
            self.still_since = None
            return False
        if self.still_since is None:
            self.still_since = now
        return now - self.still_since >= c.landed_hold

    def _landing(self, now, events, commands, new_forces) -> bool:
        landed = self._landed(now)
        if self.status.arming_state != ARMING_STATE_ARMED:
            self._enter(now, Phase.DONE, events, 'disarmed')
        elif landed:
            commands.append(self._command(now, VEHICLE_CMD_COMPONENT_ARM_DISARM, 0.0))
        elif self.status.nav_state != NAVIGATION_STATE_AUTO_LAND:
            commands.append(self._command(now, VEHICLE_CMD_NAV_LAND))
        return False

    def _failsafe(self, now, events, commands, new_forces) -> bool:
        status = self.status
        if status is None or status.arming_state != ARMING_STATE_ARMED:
            self._enter(now, Phase.DONE, events, 'disarmed')
        elif self.failsafe_command == VEHICLE_CMD_NAV_LAND and status.nav_state != NAVIGATION_STATE_AUTO_LAND:
            commands.append(self._command(now, VEHICLE_CMD_NAV_LAND))
        elif (self.failsafe_command == VEHICLE_CMD_NAV_LAND and self.ground_z is not None
              and self.odometry_fresh(now) and self._landed(now)):
            # PX4's land mode keeps a vehicle that never left the ground armed (its land detector wants a descent;
            # seen here: 30 s, until COM_DISARM_PRFLT): on the ground and still, disarm as after a landing
            commands.append(self._command(now, VEHICLE_CMD_COMPONENT_ARM_DISARM, 0.0))
        elif self.failsafe_command == VEHICLE_CMD_COMPONENT_ARM_DISARM:
            commands.append(self._command(now, VEHICLE_CMD_COMPONENT_ARM_DISARM, 0.0))
        return False

    def _done(self, now, events, commands, new_forces) -> bool:
        return False


def _turned(vector, angle: float) -> list[float]:
    """A world vector [x, y, z] turned by ``angle`` [rad] about z (counter-clockwise seen from above)."""
    c, s = math.cos(angle), math.sin(angle)
    return [c * vector[0] - s * vector[1], s * vector[0] + c * vector[1], vector[2]]


def _us(seconds: float) -> int:
    """[us] of a time [s] (PX4's timestamps are microseconds)."""
    return int(round(seconds * 1e6))
