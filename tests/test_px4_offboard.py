"""The offboard state machine (quad_sim.px4_offboard) against a scripted PX4 stand-in: heartbeat, arming only on
fresh valid odometry, the order of mode switch and arming, landing and disarming, failsafes."""
import math

import pytest

from quad_msgs_bridge import px4
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file
from quad_sim.px4_offboard import (ARMING_STATE_ARMED, ARMING_STATE_DISARMED, NAVIGATION_STATE_AUTO_LAND,
                                   NAVIGATION_STATE_OFFBOARD, VEHICLE_CMD_COMPONENT_ARM_DISARM, VEHICLE_CMD_DO_SET_MODE,
                                   VEHICLE_CMD_NAV_LAND, OffboardConfig, OffboardCore, Phase, Px4Status)

SIH, _ = load_vehicle_file('px4-sih-quadx')
#: the machine without its settling wait before arming (tested on its own below), so these timings stay PX4's
NO_SETTLE = OffboardConfig(settle_time=0.0)
DT = 0.002                      #: [s] the tick (the node runs the core with every message and on a timer)
NAVIGATION_STATE_POSCTL = 2     #: msg/VehicleStatus.msg; COM_OBL_RC_ACT 0 (default): Position mode
COM_OF_LOSS_T = 1.0             #: [s] default, commander_params.c
COM_DISARM_LAND = 2.0           #: [s] default, commander_params.c


class FakePx4:
    """PX4's side, scripted: odometry at 100 Hz from a kinematic vehicle (offboard and armed: it climbs to 1 m at
    0.5 m/s, as our controller would fly it, or while the heartbeat names the position level, to the height of the
    latest TrajectorySetpoint as PX4's position controller would, up to ``ceiling``; AUTO_LAND: it descends to the
    ground at 0.5 m/s), VehicleStatus with every tick; accepts offboard only after >= 1 s of heartbeats, arms only
    in offboard; leaves offboard for Position mode COM_OF_LOSS_T after the last heartbeat; disarms COM_DISARM_LAND
    after touching down."""

    def __init__(self, odometry_period=0.01, bad_odometry=None, ceiling=math.inf):
        """``odometry_period`` [s] (None: no odometry at all)."""
        self.armed, self.nav_state = False, NAVIGATION_STATE_POSCTL
        self.z, self.vz = 0.0, 0.0
        self.ceiling = ceiling                    #: [m] the highest it climbs (a take-off that stalls)
        self.target_z = None                      #: [m, ENU] while PX4's position controller flies: its setpoint
        self.stream_start = self.last_heartbeat = None
        self.last_odometry = -math.inf
        self.odometry_period = odometry_period
        self.bad_odometry = bad_odometry          #: a function of time: True where the odometry is NaN
        self.landed_since = None
        self.received = []                        #: (time, VehicleCommand) in order
        self.setpoints = []                       #: (time, Setpoint)
        self.modes = []                           #: (time, OffboardMode)
        self.offboard_losses = 0

    def heartbeat_recent(self, now):
        return self.last_heartbeat is not None and now - self.last_heartbeat <= COM_OF_LOSS_T

    def receive(self, now, output):
        if output.mode is not None:
            if not self.heartbeat_recent(now):
                self.stream_start = now
            self.last_heartbeat = now
            self.modes.append((now, output.mode))
            if not output.mode.position:
                self.target_z = None
        if output.setpoint is not None:
            self.setpoints.append((now, output.setpoint))
            if output.setpoint.trajectory is not None and self.modes and self.modes[-1][1].position:
                self.target_z = -output.setpoint.trajectory.position[2]        # NED -> ENU
        for command in output.commands:
            self.received.append((now, command))
            if command.command == VEHICLE_CMD_DO_SET_MODE and command.param2 == 6.0:
                if self.heartbeat_recent(now) and now - self.stream_start >= 1.0:
                    self.nav_state = NAVIGATION_STATE_OFFBOARD
            elif command.command == VEHICLE_CMD_COMPONENT_ARM_DISARM:
                if command.param1 == 1.0 and self.nav_state == NAVIGATION_STATE_OFFBOARD:
                    self.armed = True
                elif command.param1 == 0.0 and self.z <= 0.0:
                    self.armed = False
            elif command.command == VEHICLE_CMD_NAV_LAND and self.armed:
                self.nav_state = NAVIGATION_STATE_AUTO_LAND

    def step(self, now):
        """Advance the vehicle to ``now``; (odometry or None, status)."""
        if self.armed and self.nav_state == NAVIGATION_STATE_OFFBOARD and not self.heartbeat_recent(now):
            self.nav_state = NAVIGATION_STATE_POSCTL          # offboard loss: COM_OBL_RC_ACT 0
            self.offboard_losses += 1
        if self.armed and self.nav_state == NAVIGATION_STATE_OFFBOARD and self.target_z is not None:
            target = min(self.target_z, self.ceiling)
            self.vz = math.copysign(min(0.5, abs(target - self.z) / DT), target - self.z)
        elif self.armed and self.nav_state == NAVIGATION_STATE_OFFBOARD:
            self.vz = 0.5 if self.z < 1.0 else 0.0
        elif self.armed and self.nav_state == NAVIGATION_STATE_AUTO_LAND:
            self.vz = -0.5 if self.z > 0.0 else 0.0
        else:
            self.vz = 0.0
        self.z = max(0.0, self.z + self.vz * DT)
        if self.armed and self.z <= 0.0 and self.nav_state == NAVIGATION_STATE_AUTO_LAND:
            self.landed_since = now if self.landed_since is None else self.landed_since
            if now - self.landed_since >= COM_DISARM_LAND:
                self.armed = False
        odometry = None
        if self.odometry_period is not None and now - self.last_odometry >= self.odometry_period - 1e-9:
            self.last_odometry = now
            state = [0.0, 0.0, self.z, 0.0, 0.0, self.vz, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0]
            odometry = px4.px4_odometry_from_state(round(now * 1e6), state)
            if self.bad_odometry is not None and self.bad_odometry(now):
                odometry = odometry._replace(position=(math.nan, 0.0, 0.0))
        return odometry, Px4Status(ARMING_STATE_ARMED if self.armed else ARMING_STATE_DISARMED, self.nav_state)


class Controller:
    """Our controller, scripted: it answers each odometry with hover forces on the next tick (unless silent)."""

    def __init__(self, silent_from=math.inf, forces=None):
        self.pending = False
        self.silent_from = silent_from
        self.forces = forces or (SIH.hover_force,) * 4
        self.stamps = []
        self.samples = []                         #: every odometry sample it got
        self.last_answer = None

    def answer(self, now):
        if self.pending and now < self.silent_from:
            self.pending = False
            self.last_answer = now
            return self.forces
        return None

    def take(self, odometry):
        if odometry is not None:
            self.stamps.append(odometry.stamp)
            self.samples.append(odometry)
            self.pending = True


def fly(core, fake, controller, until, start=0.0, land_at=math.inf, frozen=None):
    """Tick from ``start`` to ``until`` [s]; ``frozen`` (t0, t1): the core is not ticked (our node stalls). Returns the
    phases seen, in order, and the events."""
    phases, events = [core.phase], []
    steps = int(round((until - start) / DT))
    for k in range(steps):
        now = start + k * DT
        if now >= land_at and not core.landing_requested:
            core.request_landing()
        odometry, status = fake.step(now)
        if frozen is not None and frozen[0] <= now < frozen[1]:
            continue
        output = core.tick(now, odometry, status, controller.answer(now))
        controller.take(output.odometry)
        fake.receive(now, output)
        events.extend(output.events)
        if output.phase != phases[-1]:
            phases.append(output.phase)
    return phases, events


def commands_of(fake, command=None):
    return [(t, c) for t, c in fake.received if command is None or c.command == command]


# ---------------------------------------------------------------- a whole flight
@pytest.mark.parametrize('level', ['direct_actuator', 'thrust_and_torque'])
def test_a_whole_flight_takes_off_lands_and_disarms(level):
    core, fake, controller = OffboardCore(SIH, OffboardConfig(control_level=level)), FakePx4(), Controller()
    phases, events = fly(core, fake, controller, until=12.0, land_at=5.0)
    assert phases == [Phase.WAITING, Phase.STREAMING, Phase.REQUESTING, Phase.FLYING, Phase.LANDING, Phase.DONE]
    assert not fake.armed and fake.z == 0.0 and fake.offboard_losses == 0
    modes = [m for _, m in fake.modes]
    assert all(m.direct_actuator == (level == 'direct_actuator') and m.thrust_and_torque == (level != 'direct_actuator')
               and not (m.position or m.velocity or m.acceleration or m.attitude or m.body_rate) for m in modes)
    # the mode switch first, arming only once PX4 reports offboard, landing, then our disarm after touchdown
    kinds = [(c.command, c.param1) for _, c in commands_of(fake)]
    assert kinds[0] == (VEHICLE_CMD_DO_SET_MODE, 1.0) and kinds[-1] == (VEHICLE_CMD_COMPONENT_ARM_DISARM, 0.0)
    assert kinds.index((VEHICLE_CMD_COMPONENT_ARM_DISARM, 1.0)) < kinds.index((VEHICLE_CMD_NAV_LAND, 0.0))
    [(armed_at, arm)] = commands_of(fake, VEHICLE_CMD_COMPONENT_ARM_DISARM)[:1]
    assert arm.param1 == 1.0 and arm.target_system == 1 and arm.target_component == 1 and arm.from_external
    first_heartbeat = fake.modes[0][0]
    assert armed_at - first_heartbeat >= 1.0      # PX4 took offboard only after >= 1 s of heartbeats
    # our odom starts at flight time 0 when the flight does, and then follows PX4's sample times
    assert controller.stamps[0] == 0.0 and all(b - a == pytest.approx(0.01) for a, b in
                                               zip(controller.stamps, controller.stamps[1:]))
    # the flight's setpoints: the hover command, finite on every used channel
    flown = [s for t, s in fake.setpoints if t > armed_at + 0.1 and t < 5.0]
    if level == 'direct_actuator':
        assert all(s.motors[:4] == pytest.approx((SIH.hover_force / SIH.F_max,) * 4) for s in flown)
        assert all(math.isnan(c) for s in flown for c in s.motors[4:])           # unused: PX4's "disarmed"
    else:
        hover = -SIH.m * SIH.g / (4 * SIH.F_max)
        assert all(s.thrust == pytest.approx((0, 0, hover)) and s.torque == pytest.approx((0, 0, 0)) for s in flown)
    # no heartbeat after the landing command: PX4's land mode is in charge
    [(land_at, _)] = commands_of(fake, VEHICLE_CMD_NAV_LAND)
    assert all(t < land_at for t, _ in fake.modes)


def test_the_heartbeat_runs_at_20_hz_from_the_first_fresh_odometry():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4()
    fly(core, fake, Controller(), until=3.0)
    times = [t for t, _ in fake.modes]
    gaps = [b - a for a, b in zip(times, times[1:])]
    assert max(gaps) <= 0.05 + DT + 1e-9 and min(gaps) >= 0.05 - 1e-9    # every 50 ms: 20 Hz, PX4 needs > 2 Hz
    assert times[0] == pytest.approx(0.0, abs=DT)
    assert len(times) == pytest.approx(3.0 / 0.05, abs=2)


# ---------------------------------------------------------------- PX4's take-off and the hand-over
@pytest.mark.parametrize('level', ['direct_actuator', 'thrust_and_torque'])
def test_px4_takes_off_and_hands_over_to_our_controller_at_the_takeoff_point(level):
    config = OffboardConfig(control_level=level, takeoff='px4', takeoff_altitude=2.5, initial_position=(1.0, 0.0, 2.5),
                            handover_speed=0.3)
    core, fake, controller = OffboardCore(SIH, config), FakePx4(), Controller()
    phases, events = fly(core, fake, controller, until=20.0, land_at=12.0)
    assert phases == [Phase.WAITING, Phase.STREAMING, Phase.REQUESTING, Phase.TAKING_OFF, Phase.FLYING,
                      Phase.LANDING, Phase.DONE]
    assert not fake.armed and fake.z == 0.0 and fake.offboard_losses == 0
    [(armed_at, _)] = [(t, c) for t, c in commands_of(fake, VEHICLE_CMD_COMPONENT_ARM_DISARM) if c.param1 == 1.0]
    [handover] = [e for e in events if e.startswith('taking_off -> flying')]
    # up to the controller's first answer: the position level, PX4 holding the take-off point 2.5 m up at the
    # arming heading (the fake's psi 0.3 rad ENU: pi/2 - 0.3 in NED)
    first_motor = next(t for t, sp in fake.setpoints if sp.trajectory is None and t > armed_at)
    held = [sp.trajectory for t, sp in fake.setpoints if armed_at <= t < first_motor]
    assert held and all(tr.position == pytest.approx((0.0, 0.0, -2.5)) and tr.velocity == pytest.approx((0, 0, 0))
                        and tr.yaw == pytest.approx(math.pi / 2 - 0.3) for tr in held)
    assert all(m.position and not (m.direct_actuator or m.thrust_and_torque) for t, m in fake.modes
               if armed_at <= t < first_motor)
    # the flight starts once at the take-off point and slower than handover_speed for handover_hold: the fake climbs
    # at 0.5 m/s (too fast to hand over) for 5 s, then holds
    flight_start = first_motor - DT
    assert 5.0 + 1.0 <= flight_start - armed_at <= 5.0 + 1.0 + 0.05 and 'for 1 s: our controller flies' in handover
    # our odom: from flight time 0 there, the vehicle at initial_position (the take-off point moved to it)
    assert controller.stamps[0] == 0.0
    before_landing = [stamp for stamp in controller.stamps if stamp < 12.0 - flight_start]
    assert len(before_landing) == pytest.approx((12.0 - flight_start) / 0.01, abs=2)
    # the level changes with the controller's first answer, heartbeat and setpoint in one tick, and stays
    switch_at, switch = next((t, m) for t, m in fake.modes if t >= first_motor)
    assert switch_at == first_motor and switch.direct_actuator == (level == 'direct_actuator')
    assert all(not m.position for t, m in fake.modes if t >= first_motor)
    assert fake.target_z is None and fake.z == 0.0


def test_the_first_odometry_after_the_handover_puts_the_vehicle_at_the_scenarios_start():
    config = OffboardConfig(takeoff='px4', takeoff_altitude=2.5, initial_position=(1.0, -2.0, 2.5), initial_yaw=0.4)
    core, fake, controller = OffboardCore(SIH, config), FakePx4(), Controller()
    fly(core, fake, controller, until=10.0)
    first = controller.samples[0]
    x, y, z, w = first.orientation
    assert first.stamp == 0.0 and first.position == pytest.approx((1.0, -2.0, 2.5))
    assert math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)) == pytest.approx(0.4)


def test_a_takeoff_that_does_not_reach_its_point_hands_the_vehicle_to_px4s_land_mode():
    config = OffboardConfig(takeoff='px4', takeoff_altitude=2.5, takeoff_timeout=8.0)
    core, fake, controller = OffboardCore(SIH, config), FakePx4(ceiling=1.5), Controller()
    phases, events = fly(core, fake, controller, until=20.0)
    assert phases[-3:] == [Phase.TAKING_OFF, Phase.FAILSAFE, Phase.DONE] and controller.stamps == []
    assert any('did not reach the take-off point within 8 s: PX4 lands' in e for e in events)
    assert commands_of(fake, VEHICLE_CMD_NAV_LAND) and not fake.armed and fake.z == 0.0


# ---------------------------------------------------------------- refusing to arm
def test_no_odometry_no_heartbeat_no_arming():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4(odometry_period=None)
    phases, _ = fly(core, fake, Controller(), until=3.0)
    assert phases == [Phase.WAITING] and fake.received == [] and fake.modes == []


def test_nan_odometry_is_refused_once_per_episode_and_never_armed_on():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4(bad_odometry=lambda t: True)
    phases, events = fly(core, fake, Controller(), until=3.0)
    assert phases == [Phase.WAITING] and commands_of(fake) == [] and not fake.armed
    assert len([e for e in events if e.startswith('odometry rejected: odometry position: non-finite')]) == 1


def test_odometry_that_goes_nan_or_stale_before_arming_stops_the_request():
    """NaN from 1.5 s (inside the request): back to waiting, no arming; good again from 2.5 s: it starts over."""
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4(bad_odometry=lambda t: 0.9 <= t < 2.5)
    phases, events = fly(core, fake, Controller(), until=2.4)
    assert phases == [Phase.WAITING, Phase.STREAMING, Phase.WAITING] and commands_of(fake) == []
    assert any('odometry invalid: not arming' in e for e in events)
    phases, _ = fly(core, fake, Controller(), start=2.4, until=6.0)
    assert phases == [Phase.WAITING, Phase.STREAMING, Phase.REQUESTING, Phase.FLYING] and fake.armed
    [(armed_at, _)] = [(t, c) for t, c in commands_of(fake, VEHICLE_CMD_COMPONENT_ARM_DISARM) if c.param1 == 1.0]
    assert armed_at >= 2.5 + 1.0


def test_stale_odometry_is_not_armed_on():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4(odometry_period=0.2)     # every sample 0.2 s apart, timeout 0.1 s
    phases, events = fly(core, fake, Controller(), until=4.0)
    assert not fake.armed and commands_of(fake, VEHICLE_CMD_COMPONENT_ARM_DISARM) == []
    assert Phase.REQUESTING not in phases and any('odometry older than 0.1 s: not arming' in e for e in events)


def test_px4_refusing_offboard_ends_in_failsafe_without_arming():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4()
    fake.receive = lambda now, output, receive=fake.receive: receive(now, output._replace(commands=()))  # deaf PX4
    phases, events = fly(core, fake, Controller(), until=8.0)
    assert phases[-1] == Phase.DONE and Phase.FAILSAFE in phases and not fake.armed
    assert any('did not accept offboard and arming within 5.0 s' in e for e in events)


# ---------------------------------------------------------------- in flight
def test_non_finite_forces_are_rejected_and_the_last_valid_ones_hold():
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4()
    fly(core, fake, Controller(), until=3.0)
    assert core.phase == Phase.FLYING
    output = core.tick(3.06, None, None, (1.0, math.nan, 1.0, 1.0))     # a heartbeat is due: the setpoint goes too
    assert output.setpoint.motors[:4] == pytest.approx((SIH.hover_force / SIH.F_max,) * 4)
    assert [e for e in output.events if 'rotor forces rejected' in e]
    assert not core.tick(3.061, None, None, (1.0, math.inf, 1.0, 1.0)).events          # once per episode


def test_a_silent_controller_hands_the_vehicle_to_px4s_land_mode_at_once():
    """The controller stops answering at 3 s: NAV_LAND forces_timeout (0.1 s) later, long before PX4's own offboard
    loss (COM_OF_LOSS_T 1 s) would switch to Position mode; PX4 lands and disarms."""
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4()
    controller = Controller(silent_from=3.0)
    phases, events = fly(core, fake, controller, until=10.0)
    assert phases[-3:] == [Phase.FLYING, Phase.FAILSAFE, Phase.DONE]
    [(land_at, _)] = commands_of(fake, VEHICLE_CMD_NAV_LAND)
    assert 2.99 <= controller.last_answer < 3.0 and 0.1 < land_at - controller.last_answer <= 0.1 + DT + 1e-9
    assert fake.offboard_losses == 0 and not fake.armed and fake.z == 0.0
    assert any('no rotor forces for 0.1 s: PX4 lands' in e for e in events)


def test_a_stalled_node_meets_px4s_offboard_loss_failsafe():
    """Our node stalls from 3 s to 4.5 s (no heartbeat): PX4 leaves offboard after COM_OF_LOSS_T, for Position mode;
    when the node runs again it sees that and sends nothing more: PX4 is in charge."""
    core, fake = OffboardCore(SIH, NO_SETTLE), FakePx4()
    phases, events = fly(core, fake, Controller(), until=6.0, frozen=(3.0, 4.5))
    assert fake.offboard_losses == 1 and fake.nav_state == NAVIGATION_STATE_POSCTL and fake.armed
    assert phases[-2:] == [Phase.FLYING, Phase.FAILSAFE]
    assert any('PX4 left offboard by itself' in e for e in events)
    assert not [t for t, _ in fake.modes if t >= 3.0] and not [t for t, _ in fake.received if t >= 3.0]


def test_bad_settings_are_refused_with_their_name():
    with pytest.raises(ParameterError, match="control_level: 'rates' is not one of direct_actuator, thrust_and_torque, position"):
        OffboardConfig(control_level='rates')
    with pytest.raises(ParameterError, match='heartbeat_period: 0.5 s is not below 0.5 s'):
        OffboardConfig(heartbeat_period=0.5)
    with pytest.raises(ParameterError, match='odom_timeout'):
        OffboardConfig(odom_timeout=0.0)
    with pytest.raises(ParameterError, match="takeoff: 'rocket' is not one of controller, px4"):
        OffboardConfig(takeoff='rocket')
    with pytest.raises(ParameterError, match='takeoff_altitude'):
        OffboardConfig(takeoff_altitude=-1.0)
    paper, _ = load_vehicle_file('paper')
    with pytest.raises(ValueError, match='no PX4 rotor at its bearing'):
        OffboardCore(paper)
