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
PX4 to its offboard-loss failsafe: see px4_offboard).
"""
from __future__ import annotations

import sys

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from quad_msgs_bridge import px4
from quad_msgs_bridge.contract import CLOCK, ODOM, ODOM_FRAME, ROTOR_FORCES, base_frame
from quad_msgs_bridge.conversions import MessageKit, odometry_msg, rotor_forces_from_msg, time_msg
from quad_msgs_bridge.ros_helpers import declare, publisher, run_node, subscription
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from .px4_offboard import CONTROL_LEVELS, OffboardConfig, OffboardCore, Phase, Px4Status

#: [s] the core's timer: heartbeats, timeouts (every message also ticks it)
TICK_PERIOD = 0.01


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
        config = OffboardConfig(
            control_level=declare(self, 'control_level', 'direct_actuator',
                                  'what our rotor forces become: ActuatorMotors, or normalised thrust and torque',
                                  choices=CONTROL_LEVELS),
            odom_timeout=declare(self, 'odom_timeout', 0.1, 'PX4 odometry older than this is stale [s]', (0.001, 10.0)),
            forces_timeout=declare(self, 'forces_timeout', 0.1,
                                   'controller silence in flight before PX4 lands the vehicle [s]', (0.001, 10.0)))
        try:
            self.core = OffboardCore(params, config)
        except ValueError as error:
            raise ParameterError(f'parameter vehicle_file: {error}') from error
        self.duration = declare(self, 'duration', 0.0, 'flight time before landing [s]; 0: fly until stopped',
                                (0.0, 1e6))
        self.exit_at_end = declare(self, 'exit_at_end', True, 'shut the node down once PX4 has disarmed')
        prefix = declare(self, 'px4_namespace', '', "PX4's topic prefix: '' for /fmu/..., 'px4_1' for /px4_1/fmu/...")
        prefix = '/' + prefix.strip('/') if prefix.strip('/') else ''
        status_topic = declare(self, 'vehicle_status_topic', '/fmu/out/vehicle_status',
                               'PX4 1.15: /fmu/out/vehicle_status; 1.16: /fmu/out/vehicle_status_v1')
        m = messages
        self.odom_pub = publisher(self, kit, ODOM)
        self.clock_pub = publisher(self, kit, CLOCK)
        self.child_frame = base_frame(self.get_namespace())
        out = px4_qos(DurabilityPolicy.VOLATILE)
        self.mode_pub = self.create_publisher(m.OffboardControlMode, f'{prefix}/fmu/in/offboard_control_mode', out)
        self.command_pub = self.create_publisher(m.VehicleCommand, f'{prefix}/fmu/in/vehicle_command', out)
        self.motors_pub = self.create_publisher(m.ActuatorMotors, f'{prefix}/fmu/in/actuator_motors', out)
        self.thrust_pub = self.create_publisher(m.VehicleThrustSetpoint, f'{prefix}/fmu/in/vehicle_thrust_setpoint',
                                                out)
        self.torque_pub = self.create_publisher(m.VehicleTorqueSetpoint, f'{prefix}/fmu/in/vehicle_torque_setpoint',
                                                out)
        latest = px4_qos(DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(m.VehicleOdometry, f'{prefix}/fmu/out/vehicle_odometry', self.on_odometry, latest)
        self.create_subscription(m.VehicleStatus, prefix + status_topic, self.on_status, latest)
        self.forces_sub = subscription(self, kit, ROTOR_FORCES, self.on_forces)
        self.create_timer(TICK_PERIOD, lambda: self.tick())
        self.get_logger().info(f'PX4 bridge: {config.control_level} for {vehicle_file}; PX4 topics under '
                               f'{prefix or ""}/fmu; waiting for odometry')

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    # --- PX4 -> core ----------------------------------------------------------------------------------------
    def on_odometry(self, msg) -> None:
        stamp = msg.timestamp_sample or msg.timestamp
        self.tick(odometry=px4.Px4Odometry(int(stamp), tuple(msg.position), tuple(msg.q), tuple(msg.velocity),
                                           int(msg.velocity_frame), tuple(msg.angular_velocity), int(msg.pose_frame)))

    def on_status(self, msg) -> None:
        self.tick(status=Px4Status(int(msg.arming_state), int(msg.nav_state)))

    def on_forces(self, msg) -> None:
        try:
            forces = rotor_forces_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'rejected rotor_forces: {error}', throttle_duration_sec=1.0)
            return
        self.tick(forces=forces)

    # --- core -> PX4 and our topics --------------------------------------------------------------------------
    def tick(self, odometry=None, status=None, forces=None) -> None:
        output = self.core.tick(self.now(), odometry, status, forces)
        for event in output.events:
            self.get_logger().info(event)
        m = self.messages
        if output.mode is not None:
            flags = output.mode._asdict()
            self.mode_pub.publish(m.OffboardControlMode(timestamp=flags.pop('timestamp_us'), **flags))
        setpoint = output.setpoint
        if setpoint is not None and setpoint.motors is not None:
            self.motors_pub.publish(m.ActuatorMotors(timestamp=setpoint.timestamp_us, control=list(setpoint.motors)))
        elif setpoint is not None:
            self.thrust_pub.publish(m.VehicleThrustSetpoint(timestamp=setpoint.timestamp_us, xyz=list(setpoint.thrust)))
            self.torque_pub.publish(m.VehicleTorqueSetpoint(timestamp=setpoint.timestamp_us, xyz=list(setpoint.torque)))
        for command in output.commands:
            fields = command._asdict()
            self.command_pub.publish(m.VehicleCommand(timestamp=fields.pop('timestamp_us'), **fields))
        if output.odometry is not None:
            sample = output.odometry
            self.clock_pub.publish(self.kit['rosgraph_msgs/msg/Clock'](clock=time_msg(self.kit, sample.stamp)))
            self.odom_pub.publish(odometry_msg(self.kit, sample, ODOM_FRAME, self.child_frame))
            if self.duration > 0.0 and sample.stamp >= self.duration and not self.core.landing_requested:
                self.get_logger().info(f'{self.duration:g} s of flight: landing')
                self.core.request_landing()
        if output.phase == Phase.DONE and self.exit_at_end:
            self.get_logger().info('PX4 disarmed: the flight is over')
            rclpy.shutdown(context=self.context)


def main(argv: list[str] | None = None) -> int:
    try:
        import px4_msgs.msg as messages
    except ImportError as error:
        print(f'px4_bridge: px4_msgs cannot be imported ({error}): build px4_msgs with colcon and source it '
              '(docs/PX4.md)', file=sys.stderr)
        return 1
    return run_node(lambda kit: Px4BridgeNode(kit, messages), argv)


if __name__ == '__main__':
    raise SystemExit(main())
