"""nnit2fsmc_controller node: answers every odometry with rotor forces from the NNIT2FSMC (or a baseline).

Each odometry at sim time t is answered once, with the reference for that same instant t taken
from the ``setpoints`` path (or from the transfer to the last ``goal_pose``). Per answer it
publishes ``rotor_forces`` first (the simulator can go on integrating), then ``control/wrench``,
``control/reference`` and ``control/diagnostics``, all stamped t, and only then takes the NN's
learning step of that update (the forces do not depend on it).

Live tuning: every gain of the gains file is a parameter (``common.lambda.z``, ...). A change with
``ros2 param set`` is checked against the parameter's declared range, then validated by building
the controller anew with it (:func:`nnit2fsmc_controller.tuning.retune`); a refused change answers
with the reason, an accepted one is logged and applies from the next control update, the network
weights, filters and integrators carried over. ``control/diagnostics`` carries the surface slopes
lambda in effect at each update. Gains that need a restart (and the node parameters) are read-only.

Failure behaviour: odometry that arrives before any setpoint is held and answered when the first
setpoints arrive, and until every output has matched ``wait_for_recorders`` readers besides the
simulator (recorders: none of the first answers is lost to them); a repeated odometry (the stamp
last answered) is ignored; an older stamp means the simulator restarted, and the controller starts
afresh (NN weights, filters) and answers it; non-finite odometry or setpoints are rejected with a
throttled error, and the last valid forces (hover thrust if none) are published instead, so a
non-finite force is never published.
"""
from __future__ import annotations

import math
import time

from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from quad_msgs_bridge.contract import (CONTROL_DIAGNOSTICS, CONTROL_REFERENCE, CONTROL_WRENCH, GOAL_POSE, ODOM,
                                       ROTOR_FORCES, SETPOINTS, base_frame)
from quad_msgs_bridge.conversions import MessageKit, goal_from_msg, setpoints_from_msg
from quad_msgs_bridge.fast_cdr import (decode_odometry, diagnostics_encoder, pose_stamped_encoder, rotor_forces_encoder,
                                       wrench_encoder)
from quad_msgs_bridge.frames import wrap_angle
from quad_msgs_bridge.reference import SetpointPath
from quad_msgs_bridge.ros_helpers import declare, publication_log, publisher, run_node, subscription, unmatched
from quad_msgs_bridge.state import PSI, state_from_odometry
from quad_msgs_bridge.timebase import nanoseconds, seconds, stamp_fields
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from .factory import (CONTROLLERS, build_controller, build_measurement_stage, compile_kernels, flatten_gains,
                      gain_choices, gain_description, load_gains, unflatten_gains)
from .registry import check_controller, controller_kind
from .tuning import restart_reason, retune, retune_measurement
from .trajectory import Waypoints

_UNBOUNDED = (0.0, math.inf)


class ControllerNode(Node):
    def __init__(self, kit: MessageKit):
        super().__init__('nnit2fsmc_controller')
        self.kit = kit
        restart = 'read when the node starts'
        kind = check_controller(declare(self, 'controller', 'nnit2fsmc',
                                        'control law: a built-in kind (' + ', '.join(CONTROLLERS) + '), an installed '
                                        'controller\'s entry point, or module:Class', read_only=restart),
                                'parameter controller')
        vehicle_file = declare(self, 'vehicle_file', '', 'vehicle YAML (nominal model); empty: the packaged one',
                               read_only=restart)
        gains_file = declare(self, 'gains_file', '', 'gains YAML used as defaults; empty: the packaged one',
                             read_only=restart)
        self.goal_speed = declare(self, 'goal_speed', 0.5, 'mean speed of the transfer to a goal_pose [m/s]',
                                  (0.01, 10.0))
        self.odom_timeout = declare(self, 'odom_timeout', 0.5, 'wall seconds without odometry before warning',
                                    (0.001, 60.0), read_only=restart)
        latest_only = declare(self, 'latest_only', False,
                              'answer only the newest odometry (realtime); false: answer every one in order (lockstep)',
                              read_only=restart)
        self.params, _ = load_vehicle_file(vehicle_file or None)
        self.flat_gains = {}
        schema = controller_kind(kind).schema or {}
        section = controller_kind(kind).gains_section
        for name, default in flatten_gains(load_gains(gains_file or None, kind=kind)).items():
            gain = schema.get(name[len(section) + 1:]) if name.startswith(section + '.') else None
            if gain is not None:   # a user kind's gain: its schema's range and meaning
                finite = math.isfinite(gain.low) and math.isfinite(gain.high) and isinstance(default, float)
                bounds = (gain.low, gain.high) if finite else None
                self.flat_gains[name] = declare(self, name, default, f'{gain.description} [{gain.unit}]', bounds,
                                                read_only=None)
                continue
            if isinstance(default, str):
                bounds, choices = None, gain_choices(name)
            else:
                bounds, choices = (0, 2 ** 31 - 1) if isinstance(default, int) else _UNBOUNDED, None
            self.flat_gains[name] = declare(self, name, default, gain_description(name), bounds, choices,
                                            read_only=restart_reason(name))
        self.kind, self.gains = kind, unflatten_gains(self.flat_gains)
        try:
            self.controller = build_controller(kind, self.params, self.gains)
            self.measurement = build_measurement_stage(self.gains)   # the closed loop's stage, for every kind
        except (ParameterError, ValueError) as error:
            raise ParameterError(f'controller gains: {error}') from error
        compile_kernels(kind, self.params, self.gains)   # before subscribing: the first answer is not slower
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.odometry_ns = 0     #: [ns, sim] stamp of the latest odometry taken: its answers are logged at it
        self.publication_log = publication_log(self, lambda: self.odometry_ns)
        self.forces_pub = publisher(self, kit, ROTOR_FORCES, log=self.publication_log)
        self.wrench_pub = publisher(self, kit, CONTROL_WRENCH, log=self.publication_log)
        self.reference_pub = publisher(self, kit, CONTROL_REFERENCE, log=self.publication_log)
        self.diagnostics_pub = publisher(self, kit, CONTROL_DIAGNOSTICS, log=self.publication_log)
        recorders = declare(self, 'wait_for_recorders', 0,
                            'answer once rotor_forces and control/* have matched this many subscribers each beside '
                            'the simulator (recorders of every topic); 0: answer at once', (0, 1000),
                            read_only='checked before the first answer')
        #: (publisher, readers it must have matched before the first answer)
        self.wanted_readers = ([(self.forces_pub, recorders + 1)] + [
            (pub, recorders) for pub in (self.wrench_pub, self.reference_pub, self.diagnostics_pub)]
            if recorders else [])
        self.match_retry = None     #: a timer that retries the pending odometry while the outputs match
        # the per-step messages go over the wire as CDR bytes made and read by the bridge's fast codecs;
        # in realtime (latest_only) a controller that falls behind skips to the newest odometry
        self.encode_forces = rotor_forces_encoder(self.params.rotor_names)
        self.encode_wrench = wrench_encoder(self.params.d, base_frame(self.get_namespace()))
        self.encode_reference = pose_stamped_encoder()
        self.encode_diagnostics = diagnostics_encoder()
        subscription(self, kit, ODOM, self.on_odometry, raw=True, depth=1 if latest_only else None)
        subscription(self, kit, SETPOINTS, self.on_setpoints)
        subscription(self, kit, GOAL_POSE, self.on_goal)
        self.path: SetpointPath | None = None
        self.pending = None
        self.last_answered_ns = -1
        self.last_forces = (self.params.hover_force,) * 4
        self.last_position = None
        self.last_odom_wall: float | None = None
        self.odom_stale = False
        # a wall-clock timer: under use_sim_time a stalled simulation would also stall a sim-time timer
        self.create_timer(self.odom_timeout, self.check_odometry_age, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'{kind} controller ready at {1.0 / self.controller.dt:g} Hz')

    def publish_forces(self, forces) -> None:
        self.forces_pub.publish(self.encode_forces(forces))

    def on_odometry(self, data: bytes) -> None:
        self.last_odom_wall = time.monotonic()
        self.odom_stale = False
        try:
            sample = decode_odometry(data)
            state = state_from_odometry(sample)
        except ValueError as error:
            self.get_logger().error(f'rejected odometry: {error}; holding the last forces', throttle_duration_sec=1.0)
            self.publish_forces(self.last_forces)
            return
        stamp_ns = nanoseconds(sample.stamp)
        self.odometry_ns = stamp_ns
        if stamp_ns == self.last_answered_ns:
            return      # a repeat of the odometry already answered
        if stamp_ns < self.last_answered_ns:
            self.restart(stamp_ns)
        if self.path is None or not self.outputs_matched():
            if self.pending is None and self.path is None:
                self.get_logger().info('odometry received; waiting for setpoints or a goal_pose before answering')
            self.pending = (sample, state)
            return
        self.answer(sample, state)

    def outputs_matched(self) -> bool:
        """Whether every output has matched its ``wait_for_recorders`` readers, on its own side
        (ros_helpers.unmatched); checked from the first odometry until it holds, meanwhile a steady timer retries
        the pending odometry."""
        if not self.wanted_readers:
            return True
        missing = unmatched(self.wanted_readers)
        if missing:
            if self.match_retry is None:
                self.match_retry = self.create_timer(0.01, self.answer_pending,
                                                     clock=Clock(clock_type=ClockType.STEADY_TIME))
            self.get_logger().info(f'holding the first answer until {", ".join(missing)} matched their readers',
                                   throttle_duration_sec=5.0)
            return False
        self.wanted_readers = []
        if self.match_retry is not None:
            self.match_retry.cancel()
        return True

    def answer(self, sample, state) -> None:
        t = sample.stamp
        reference = self.path.sample(t)
        try:
            out = self.controller.update(t, self.measurement(state), reference)
        except ValueError as error:
            self.get_logger().error(f'controller refused its input: {error}; holding the last forces',
                                    throttle_duration_sec=1.0)
            self.publish_forces(self.last_forces)
            return
        if not all(map(math.isfinite, out.forces)):
            self.get_logger().error(f'non-finite forces {out.forces}; holding the last forces', throttle_duration_sec=1.0)
            self.publish_forces(self.last_forces)
            return
        self.last_answered_ns = nanoseconds(t)
        self.last_forces = out.forces
        self.last_position = (sample.position, state[PSI], t)
        self.publish_forces(out.forces)
        sec, nanosec = stamp_fields(t)
        axes = out.axes.values()
        self.wrench_pub.publish(self.encode_wrench(sec, nanosec, out.controls))
        self.reference_pub.publish(self.encode_reference(sec, nanosec, reference.position, reference.yaw))
        self.diagnostics_pub.publish(self.encode_diagnostics(
            [a.surface for a in axes], [a.equivalent for a in axes], [a.corrective for a in axes],
            self.controller.surface_slopes()))
        self.controller.adapt()   # learn while the simulator integrates, not when the next odometry waits

    def on_set_parameters(self, parameters) -> SetParametersResult:
        """Gains changed in flight (ros2 param set): validated by a retune, applied from the next update."""
        changes = {p.name: p.value for p in parameters if p.name in self.flat_gains}
        goal_speed = next((p.value for p in parameters if p.name == 'goal_speed'), None)
        if changes:
            flat = {**self.flat_gains, **changes}
            try:
                tuned = retune(self.controller, unflatten_gains(flat))
                measurement = retune_measurement(self.measurement, unflatten_gains(flat))
            except (ParameterError, ValueError) as error:
                self.get_logger().warning(f'refused gains {changes}: {error}')
                return SetParametersResult(successful=False, reason=str(error))
            said = ', '.join(f'{name} {self.flat_gains[name]} -> {value}' for name, value in changes.items())
            self.controller, self.measurement = tuned, measurement
            self.flat_gains, self.gains = flat, unflatten_gains(flat)
            self.get_logger().info(f'gains changed in flight: {said}; applied from the next control update '
                                   f'(after t={seconds(max(self.last_answered_ns, 0)):.3f} s), learned state kept')
        if goal_speed is not None:
            self.goal_speed = goal_speed
        return SetParametersResult(successful=True)

    def restart(self, stamp_ns: int) -> None:
        """Sim time went back (a restarted or reset simulator): a new flight gets a fresh controller."""
        self.get_logger().warning(f'odometry time jumped back from {seconds(self.last_answered_ns):.3f} s to '
                                  f'{seconds(stamp_ns):.3f} s (simulator restarted?): restarting the controller')
        self.controller = build_controller(self.kind, self.params, self.gains)
        self.measurement = build_measurement_stage(self.gains)
        self.last_answered_ns = -1

    def on_setpoints(self, msg) -> None:
        try:
            path = setpoints_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'rejected setpoints: {error}', throttle_duration_sec=1.0)
            return
        self.path = path
        self.get_logger().info(f'setpoints: {len(path.times)} points from t={path.start:.3f} s to {path.end:.3f} s')
        self.answer_pending()

    def on_goal(self, msg) -> None:
        try:
            goal = goal_from_msg(msg)
        except ValueError as error:
            self.get_logger().error(f'rejected goal_pose: {error}', throttle_duration_sec=1.0)
            return
        if self.last_position is None:
            self.path = SetpointPath([0.0], [goal])
        else:
            position, yaw, t = self.last_position
            distance = math.dist(position, goal.position)
            span = max(2.0, distance / self.goal_speed)
            goal_yaw = yaw + wrap_angle(goal.yaw - yaw)
            transfer = Waypoints(((0.0, position, yaw), (span, goal.position, goal_yaw)))
            self.path = SetpointPath.sampled(transfer, t, transfer.duration, 50.0)
        self.get_logger().info(f'goal_pose: flying to {goal.position} at yaw {goal.yaw:.3f} rad and holding')
        self.answer_pending()

    def answer_pending(self) -> None:
        if self.pending is not None and self.path is not None and self.outputs_matched():
            pending, self.pending = self.pending, None
            self.answer(*pending)

    def check_odometry_age(self) -> None:
        if self.last_odom_wall is None or self.odom_stale:
            return
        if time.monotonic() - self.last_odom_wall > self.odom_timeout:
            self.odom_stale = True
            self.get_logger().warning(f'no odometry for {self.odom_timeout:g} s')


def main(argv: list[str] | None = None) -> int:
    return run_node(ControllerNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
