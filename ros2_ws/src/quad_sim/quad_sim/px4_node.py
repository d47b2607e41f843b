"""PX4 bridge node: PX4 (SITL or a vehicle, over the uXRCE-DDS Agent) behind our ``odom`` and ``rotor_forces``.

Receive, convert, call the core (:mod:`quad_sim.px4_offboard`), convert, publish; every conversion is
:mod:`quad_msgs_bridge.px4`'s. Subscribes PX4's ``/fmu/out/vehicle_odometry`` and ``/fmu/out/vehicle_status``
(release 1.15 names; from 1.16 the status topic is ``vehicle_status_v1``: parameter ``vehicle_status_topic``) and
our ``rotor_forces``; publishes our ``odom`` (child frame ``<namespace>/base_link``) and ``/clock``, and to PX4
``/fmu/in/offboard_control_mode``, ``vehicle_command`` and, by ``control_level``, ``actuator_motors`` or
``vehicle_thrust_setpoint`` + ``vehicle_torque_setpoint``.

QoS to PX4: best effort, keep last 1. PX4's client writes ``/fmu/out`` best effort and transient local and reads
``/fmu/in`` best effort and volatile (src/modules/uxrce_dds_client/utilities.hpp); we read transient local (the
latest status at once, as PX4's ROS 2 offboard example does) and write volatile (a late reader gets no stale
arming command).

Time: PX4 SITL runs in real time, so nothing here waits for anyone. The ROS clock (system time, use_sim_time
false) stamps what goes to PX4 in microseconds, as PX4's example does; the Agent's time sync maps it to PX4's
clock. Our ``odom`` and ``/clock`` carry *flight time*: 0 at the first odometry after PX4 armed in offboard, then
PX4's sample times, so the controller and trajectory nodes (which read only the stamps and run with use_sim_time
false under run_stack.py) see the same time base as on our simulator, and a recorder with use_sim_time follows it.
After ``duration`` s of flight time it lands (0: when stopped by a signal, which ends the node at once and leaves
PX4 to its offboard-loss failsafe: see px4_offboard); our ``odom`` ends there (the flight measured is the
scenario's), PX4's odometry goes on into the bag until PX4 has landed and disarmed.

``control_level`` ``position`` (run_stack.py --controller px4): no controller of ours; the node samples our
``setpoints`` path at each odometry's flight time and sends it as TrajectorySetpoint (position, velocity,
acceleration feed-forward, yaw, yaw rate), so PX4's own cascaded controller flies the same reference. It then
publishes for the bag, stamped as the odometry, what a controller node would: ``control/reference``; and, as
placeholders, ``rotor_forces`` at the vehicle's hover force, ``control/wrench`` at its hover thrust and
``control/diagnostics`` zero: PX4 1.15's client sends no actuator outputs over uXRCE-DDS, so PX4's rotor commands
are not known here; a bag's review needs finite values, and the summary of such a flight marks its chattering and
saturation as not measured (flight_stack.runs).

With ``record_dir`` (run_stack.py's publication logs) the node logs what it publishes, and PX4's messages it
reads and writes (/fmu/out/vehicle_odometry, vehicle_status, /fmu/in/...), as CDR; their schemas come from the
px4_msgs install (quad_msgs_bridge.px4.install_px4_bag_types).
"""
from __future__ import annotations

import math
import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from quad_msgs_bridge import px4
from quad_msgs_bridge.contract import (CLOCK, CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, ODOM, ODOM_FRAME,
                                       ROTOR_FORCES, SETPOINTS, base_frame)
from quad_msgs_bridge.conversions import MessageKit, rotor_forces_from_msg, setpoints_from_msg
from quad_msgs_bridge.fast_cdr import (clock_encoder, diagnostics_encoder, odometry_encoder, pose_stamped_encoder,
                                       rotor_forces_encoder, wrench_encoder)
from quad_msgs_bridge.ros_helpers import declare, publication_log, publisher, run_node, subscription
from quad_msgs_bridge.timebase import nanoseconds, stamp_fields
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from .px4_offboard import CONTROL_LEVELS, TAKEOFFS, OffboardConfig, OffboardCore, Phase, Px4Status

#: [s] the core's timer: heartbeats, timeouts (every message also ticks it)
TICK_PERIOD = 0.01
#: subsystems of control/diagnostics (x, y, z, phi, theta, psi)
SUBSYSTEMS = 6


def px4_qos(durability: DurabilityPolicy) -> QoSProfile:
    return QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, durability=durability,
                      history=HistoryPolicy.KEEP_LAST, depth=1)


class Px4BridgeNode(Node):
    def __init__(self, kit: MessageKit, messages):
        super().__init__('px4_bridge')
        self.kit, self.messages = kit, messages
        vehicle_file = declare(self, 'vehicle_file', 'px4-sih-quadx',
                               'the vehicle PX4 flies (its F_max and rotor layout), a file or a shipped name')
        params, _ = load_vehicle_file(vehicle_file)
        initial = declare(self, 'initial_position', [0.0, 0.0, 0.0],
                          'where our frame puts the vehicle at flight time 0 [m, world ENU] (the scenario\'s start)')
        config = OffboardConfig(
            control_level=declare(self, 'control_level', 'direct_actuator',
                                  'what goes to PX4: our rotor forces as ActuatorMotors, or as normalised thrust and '
                                  'torque; or position: our reference as TrajectorySetpoint for PX4\'s own controller',
                                  choices=CONTROL_LEVELS),
            odom_timeout=declare(self, 'odom_timeout', 0.1, 'PX4 odometry older than this is stale [s]', (0.001, 10.0)),
            forces_timeout=declare(self, 'forces_timeout', 0.1,
                                   'controller silence in flight before PX4 lands the vehicle [s]', (0.001, 10.0)),
            target_system=declare(self, 'target_system', 1, 'MAV_SYS_ID of PX4 (its instance + 1 in SITL)', (1, 255)),
            initial_position=tuple(float(v) for v in initial),
            initial_yaw=declare(self, 'initial_yaw', 0.0, 'our frame\'s heading of the vehicle at flight time 0 [rad, '
                                'ENU] (the scenario\'s start)', (-10.0, 10.0)),
            takeoff=declare(self, 'takeoff', 'controller',
                            'who takes off: controller (ours, from the ground) or px4 (PX4\'s position controller to '
                            'takeoff_altitude, then our controller from there)', choices=TAKEOFFS),
            takeoff_altitude=declare(self, 'takeoff_altitude', 2.5,
                                     'PX4\'s take-off: height above the arming point of the hand-over [m]',
                                     (0.1, 100.0)))
        try:
            self.core = OffboardCore(params, config)
        except ValueError as error:
            raise ParameterError(f'parameter vehicle_file: {error}') from error
        self.level = config.control_level
        self.failed = False      #: the flight ended by a failsafe (ours or PX4's): the node exits with code 1
        self.duration = declare(self, 'duration', 0.0, 'flight time before landing [s]; 0: fly until stopped',
                                (0.0, 1e6))
        self.exit_at_end = declare(self, 'exit_at_end', True, 'shut the node down once PX4 has disarmed')
        prefix = declare(self, 'px4_namespace', '', "PX4's topic prefix: '' for /fmu/..., 'px4_1' for /px4_1/fmu/...")
        prefix = '/' + prefix.strip('/') if prefix.strip('/') else ''
        status_topic = declare(self, 'vehicle_status_topic', '/fmu/out/vehicle_status',
                               'PX4 1.15: /fmu/out/vehicle_status; 1.16: /fmu/out/vehicle_status_v1')
        self.flight_ns = 0      #: [ns] flight time of the latest odometry we published: the log time
        try:      # before the log's writer makes its typestore
            px4.install_px4_bag_types()
            definitions = None
        except FileNotFoundError as error:
            definitions = error
        self.publication_log = publication_log(self, lambda: self.flight_ns)
        log = self.publication_log
        if log is not None and definitions is not None:
            raise ParameterError(f'parameter record_dir: cannot record PX4\'s messages: {definitions}')
        m = messages
        self.odom_pub = publisher(self, kit, ODOM, log=log)
        self.clock_pub = publisher(self, kit, CLOCK, log=log)
        self.encode_odometry = odometry_encoder(ODOM_FRAME, base_frame(self.get_namespace()))
        self.encode_clock = clock_encoder()
        out = px4_qos(DurabilityPolicy.VOLATILE)
        # PX4's messages are logged under PX4's first-instance names (/fmu/...) whatever px4_namespace is, so that
        # every PX4 flight's bag names them alike
        if log is not None:
            for spec in px4.PX4_RECORDED_TOPICS:
                log.writer.add_topic(spec.name, spec)

        def px4_pub(msg_type, spec):
            return self.create_publisher(msg_type, prefix + spec.name, out)
        self.mode_pub = px4_pub(m.OffboardControlMode, px4.PX4_OFFBOARD_MODE)
        self.command_pub = px4_pub(m.VehicleCommand, px4.PX4_COMMAND)
        if self.level == 'direct_actuator':
            self.motors_pub = px4_pub(m.ActuatorMotors, px4.PX4_MOTORS)
        elif self.level == 'thrust_and_torque':
            self.thrust_pub = px4_pub(m.VehicleThrustSetpoint, px4.PX4_THRUST)
            self.torque_pub = px4_pub(m.VehicleTorqueSetpoint, px4.PX4_TORQUE)
        if self.level == 'position' or config.takeoff == 'px4':
            self.trajectory_pub = px4_pub(m.TrajectorySetpoint, px4.PX4_TRAJECTORY)
        latest = px4_qos(DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(m.VehicleOdometry, f'{prefix}/fmu/out/vehicle_odometry', self.on_odometry, latest)
        self.create_subscription(m.VehicleStatus, prefix + status_topic, self.on_status, latest)
        self.path = None
        if self.level == 'position':
            # what a controller node publishes per step, for the bag and the review (PX4's own values unknown)
            self.reference_pub = publisher(self, kit, CONTROL_REFERENCE, log=log)
            self.forces_pub = publisher(self, kit, ROTOR_FORCES, log=log)
            self.wrench_pub = publisher(self, kit, CONTROL_WRENCH, log=log)
            self.diagnostics_pub = publisher(self, kit, CONTROL_DIAGNOSTICS, log=log)
            self.encode_reference = pose_stamped_encoder()
            self.encode_forces = rotor_forces_encoder(params.rotor_names)
            self.encode_wrench = wrench_encoder(params.d, base_frame(self.get_namespace()))
            self.encode_diagnostics = diagnostics_encoder()
            subscription(self, kit, SETPOINTS, self.on_setpoints)
        else:
            self.forces_sub = subscription(self, kit, ROTOR_FORCES, self.on_forces)
        self.create_timer(TICK_PERIOD, lambda: self.tick())
        self.get_logger().info(f'PX4 bridge: {config.control_level} for {vehicle_file}; PX4 topics under '
                               f'{prefix or ""}/fmu; waiting for odometry')

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def log_px4(self, spec, msg) -> None:
        """Log a px4_msgs message read or written (its CDR as rclpy makes it) at the current flight time."""
        if self.publication_log is not None:
            from rclpy.serialization import serialize_message
            self.publication_log.writer.write_serialized(spec.name, serialize_message(msg),
                                                         self.flight_ns, time.time_ns())

    def send(self, publisher, spec, msg) -> None:
        publisher.publish(msg)
        self.log_px4(spec, msg)

    # --- PX4 -> core ----------------------------------------------------------------------------------------
    def on_odometry(self, msg) -> None:
        self.log_px4(px4.PX4_ODOMETRY, msg)
        stamp = msg.timestamp_sample or msg.timestamp
        self.tick(odometry=px4.Px4Odometry(int(stamp), tuple(msg.position), tuple(msg.q), tuple(msg.velocity),
                                           int(msg.velocity_frame), tuple(msg.angular_velocity), int(msg.pose_frame)))

    def on_status(self, msg) -> None:
        self.log_px4(px4.PX4_STATUS, msg)
        self.tick(status=Px4Status(int(msg.arming_state), int(msg.nav_state), bool(msg.pre_flight_checks_pass)))

    def on_forces(self, msg) -> None:
        try:
            forces = rotor_forces_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'rejected rotor_forces: {error}', throttle_duration_sec=1.0)
            return
        self.tick(forces=forces)

    def on_setpoints(self, msg) -> None:
        try:
            self.path = setpoints_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'rejected setpoints: {error}', throttle_duration_sec=1.0)

    # --- core -> PX4 and our topics --------------------------------------------------------------------------
    def tick(self, odometry=None, status=None, forces=None) -> None:
        output = self.core.tick(self.now(), odometry, status, forces)
        for event in output.events:
            self.get_logger().info(event)
        m = self.messages
        if output.mode is not None:
            flags = output.mode._asdict()
            self.send(self.mode_pub, px4.PX4_OFFBOARD_MODE,
                      m.OffboardControlMode(timestamp=flags.pop('timestamp_us'), **flags))
        setpoint = output.setpoint
        if setpoint is not None and setpoint.trajectory is not None:
            t = setpoint.trajectory
            self.send(self.trajectory_pub, px4.PX4_TRAJECTORY, m.TrajectorySetpoint(
                timestamp=setpoint.timestamp_us, position=list(map(float, t.position)),
                velocity=list(map(float, t.velocity)), acceleration=list(map(float, t.acceleration)),
                jerk=[math.nan] * 3, yaw=float(t.yaw), yawspeed=float(t.yawspeed)))
        elif setpoint is not None and setpoint.motors is not None:
            self.send(self.motors_pub, px4.PX4_MOTORS,
                      m.ActuatorMotors(timestamp=setpoint.timestamp_us, control=list(setpoint.motors)))
        elif setpoint is not None:
            self.send(self.thrust_pub, px4.PX4_THRUST,
                      m.VehicleThrustSetpoint(timestamp=setpoint.timestamp_us, xyz=list(setpoint.thrust)))
            self.send(self.torque_pub, px4.PX4_TORQUE,
                      m.VehicleTorqueSetpoint(timestamp=setpoint.timestamp_us, xyz=list(setpoint.torque)))
        for command in output.commands:
            fields = command._asdict()
            self.send(self.command_pub, px4.PX4_COMMAND,
                      m.VehicleCommand(timestamp=fields.pop('timestamp_us'), **fields))
        if output.odometry is not None and not self.core.landing_requested:
            self.publish_odometry(output.odometry)
        self.failed = self.core.failed is not None
        if output.phase == Phase.DONE and self.exit_at_end:
            self.get_logger().info('PX4 disarmed: the flight is over' + (' (after a failsafe: exit code 1)'
                                                                          if self.failed else ''))
            rclpy.shutdown(context=self.context)

    def publish_odometry(self, sample) -> None:
        """Our ``odom`` and ``/clock`` of a sample in flight time; at the position level also the reference PX4
        gets for it (and the step's other controller topics); landing once ``duration`` is reached."""
        self.flight_ns = nanoseconds(sample.stamp)
        sec, nanosec = stamp_fields(sample.stamp)
        self.clock_pub.publish(self.encode_clock(sec, nanosec))
        self.odom_pub.publish(self.encode_odometry(sec, nanosec, sample))
        if self.level == 'position' and self.path is not None:
            r = self.path.sample(sample.stamp)
            reference = (*r.position, *r.velocity, *r.acceleration, r.yaw, r.yaw_rate)
            self.tick(forces=reference)
            hover = self.core.params.hover_force
            self.forces_pub.publish(self.encode_forces((hover,) * 4))
            self.wrench_pub.publish(self.encode_wrench(sec, nanosec, (4.0 * hover, 0.0, 0.0, 0.0)))
            self.reference_pub.publish(self.encode_reference(sec, nanosec, r.position, r.yaw))
            zero = [0.0] * SUBSYSTEMS
            self.diagnostics_pub.publish(self.encode_diagnostics(zero, zero, zero, zero))
        if self.duration > 0.0 and sample.stamp >= self.duration and not self.core.landing_requested:
            self.get_logger().info(f'{self.duration:g} s of flight: landing')
            self.core.request_landing()


def main(argv: list[str] | None = None) -> int:
    try:
        import px4_msgs.msg as messages
    except ImportError as error:
        print(f'px4_bridge: px4_msgs cannot be imported ({error}): build px4_msgs with colcon and source it '
              '(docs/PX4.md)', file=sys.stderr)
        return 1
    made = []

    def make(kit):
        made.append(Px4BridgeNode(kit, messages))
        return made[-1]
    code = run_node(make, argv)
    return 1 if code == 0 and made and made[-1].failed else code


if __name__ == '__main__':
    raise SystemExit(main())
