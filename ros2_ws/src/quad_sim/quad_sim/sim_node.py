"""quad_sim node: the simulator core behind ``/clock``, ``odom`` and ``rotor_forces``.

Modes:
* lockstep (default): publish ``/clock`` and ``odom`` for time t, wait for the ``rotor_forces``
  that answer them, integrate to the next odometry time, repeat. Sim time only advances when the
  controller has answered, so a run is deterministic and can be faster than real time. If no
  answer comes within ``input_timeout`` seconds of wall time the pending odometry is published
  again (a controller that restarted gets it; one that already answered ignores the repeat).
* realtime: a wall timer keeps sim time at ``speed_factor`` times the wall time elapsed, integrating
  the control steps that are due (those of missed ticks too) with the latest forces and publishing
  the newest odometry. Forces older than ``input_timeout`` are stale: the rotors go to hover thrust.

Non-finite or malformed forces are rejected (throttled error log), the last valid forces hold.
"""
from __future__ import annotations

import time

import rclpy
from rclpy.node import Node

from quad_msgs_bridge.contract import CLOCK, ODOM, ROTOR_FORCES
from quad_msgs_bridge.conversions import MessageKit
from quad_msgs_bridge.fast_cdr import clock_encoder, decode_rotor_forces, odometry_encoder
from quad_msgs_bridge.ros_helpers import declare, publisher, run_node, subscription
from quad_msgs_bridge.timebase import stamp_fields
from quad_msgs_bridge.vehicle_params import ParameterError, load_vehicle_file

from .model import QuadrotorModel
from .simulator import Simulator

MODES = ('lockstep', 'realtime')
MAX_CATCH_UP = 100   #: realtime: most control steps integrated in one timer tick after a stall


class SimNode(Node):
    def __init__(self, kit: MessageKit):
        super().__init__('quad_sim')
        self.kit = kit
        vehicle_file = declare(self, 'vehicle_file', '', 'vehicle YAML (Table I parameters); empty: the packaged one')
        params, disturbances = load_vehicle_file(vehicle_file or None)
        disturbances = disturbances.switched(declare(
            self, 'disturbances', disturbances.enabled, 'apply the paper section IV disturbances'))
        physics_rate = declare(self, 'physics_rate', 1000.0, 'RK4 integration rate [Hz]', (1.0, 1e6))
        odometry_rate = declare(self, 'odometry_rate', 1000.0,
                                'odometry, /clock and control rate [Hz]; physics_rate must be a whole multiple',
                                (1.0, 1e6))
        self.mode = declare(self, 'mode', 'lockstep', 'lockstep (wait for every answer) or realtime', choices=MODES)
        self.speed_factor = declare(self, 'speed_factor', 1.0, 'realtime: sim seconds per wall second', (0.01, 100.0))
        self.input_timeout = declare(self, 'input_timeout', 0.5,
                                     'wall seconds without rotor forces before the stale-input behaviour', (0.001, 60.0))
        self.duration = declare(self, 'duration', 0.0, 'stop stepping at this sim time [s]; 0: never', (0.0, 1e7))
        self.wait_for_subscribers = declare(
            self, 'wait_for_subscribers', 1,
            'start once odom has this many subscribers (the controller, plus any recorder)', (1, 1000))
        self.start_delay = declare(self, 'start_delay', 0.0,
                                   'wall seconds to wait once the subscribers are there, before the first step '
                                   '(a late recorder such as ros2 bag record then has all its topics matched)',
                                   (0.0, 60.0))
        self.exit_at_end = declare(self, 'exit_at_end', False, 'shut the node down once duration is reached')
        start = declare(self, 'initial_state', [0.0] * 12,
                        'x y z [m] vx vy vz [m/s] phi theta psi [rad] dphi dtheta dpsi [rad/s], world ENU')
        substeps = physics_rate / odometry_rate
        if abs(substeps - round(substeps)) > 1e-9:
            raise ParameterError(f'parameter physics_rate: {physics_rate} Hz is not a whole multiple of '
                                 f'odometry_rate {odometry_rate} Hz')
        self.substeps = int(round(substeps))
        try:
            self.sim = Simulator(QuadrotorModel(params, disturbances), 1.0 / physics_rate, list(start))
        except ValueError as error:
            raise ParameterError(f'parameter initial_state: {error}') from error
        self.hover_forces = (params.hover_force,) * 4
        self.clock_pub = publisher(self, kit, CLOCK)
        self.odom_pub = publisher(self, kit, ODOM)
        # the per-step messages go over the wire as CDR bytes made and read by the bridge's fast codecs
        self.encode_clock = clock_encoder()
        self.encode_odometry = odometry_encoder()
        self.forces_sub = subscription(self, kit, ROTOR_FORCES, self.on_forces, raw=True)
        self.last_forces_wall = time.monotonic()
        self.started = False
        self.subscribed_since: float | None = None   #: wall time the start condition first held
        self.stale = False
        self.finished = False
        self.first_publish_wall: float | None = None
        self.published = 0
        if self.mode == 'lockstep':
            self.watchdog = self.create_timer(min(0.05, self.input_timeout), self.lockstep_watchdog)
        else:
            self.odometry_rate = odometry_rate
            self.realtime_origin: float | None = None
            self.control_steps = 0
            self.step_timer = self.create_timer(1.0 / odometry_rate / self.speed_factor, self.realtime_step)
        self.get_logger().info(
            f'{self.mode} simulation: physics {physics_rate:g} Hz, odometry {odometry_rate:g} Hz, '
            f'disturbances {"on" if disturbances.enabled else "off"}')

    # --- shared -----------------------------------------------------------------------------
    def publish_odometry(self) -> None:
        sample = self.sim.odometry()
        sec, nanosec = stamp_fields(sample.stamp)
        self.clock_pub.publish(self.encode_clock(sec, nanosec))
        self.odom_pub.publish(self.encode_odometry(sec, nanosec, sample))
        now = time.monotonic()
        if self.first_publish_wall is None:
            self.first_publish_wall = now
        self.published += 1

    def timing_report(self) -> str:
        wall = time.monotonic() - (self.first_publish_wall or time.monotonic())
        rate = self.published / wall if wall > 0 else 0.0
        return f'{self.published} odometry steps in {wall:.3f} s wall: {rate:.1f} steps/s'

    def at_end(self) -> bool:
        if self.duration > 0.0 and self.sim.time >= self.duration - 1e-12:
            if not self.finished:
                self.finished = True
                self.get_logger().info(f'reached duration {self.duration:g} s of sim time; {self.timing_report()}')
                if self.exit_at_end:
                    rclpy.shutdown(context=self.context)
            return True
        return False

    def accept(self, data: bytes) -> bool:
        try:
            forces = decode_rotor_forces(data)
        except ValueError as error:
            self.get_logger().error(f'rejected rotor_forces: {error}', throttle_duration_sec=1.0)
            return False
        return self.sim.set_forces(forces)

    # --- lockstep ---------------------------------------------------------------------------
    def ready(self) -> bool:
        """Start ``start_delay`` after ``odom`` has its subscribers and a controller publishes ``rotor_forces``."""
        if self.started:
            return True
        now = time.monotonic()
        if not (self.count_subscribers(ODOM.name) >= self.wait_for_subscribers
                and self.count_publishers(ROTOR_FORCES.name) > 0):
            self.subscribed_since = None
        elif self.subscribed_since is None:
            self.subscribed_since = now
        if self.subscribed_since is not None and now - self.subscribed_since >= self.start_delay:
            self.started = True
            self.last_forces_wall = now
        return self.started

    def lockstep_watchdog(self) -> None:
        if not self.started:
            if self.ready():
                self.publish_odometry()
            return
        if self.finished or time.monotonic() - self.last_forces_wall < self.input_timeout:
            return
        if not self.stale:
            self.stale = True
            self.get_logger().warning(
                f'no rotor_forces for {self.input_timeout:g} s at sim time {self.sim.time:.3f} s; '
                'holding sim time and publishing the pending odometry again')
        self.last_forces_wall = time.monotonic()
        self.published -= 1       # a repeat is not a new step
        self.publish_odometry()

    def on_forces(self, data: bytes) -> None:
        if self.mode == 'realtime':
            if self.accept(data):
                self.last_forces_wall = time.monotonic()
                self.stale = False
            return
        if not self.started or self.finished:
            return
        self.accept(data)   # a rejected message still answers: the last valid forces hold
        self.last_forces_wall = time.monotonic()
        self.stale = False
        self.sim.advance(self.substeps)
        if not self.at_end():
            self.publish_odometry()

    # --- realtime ---------------------------------------------------------------------------
    def realtime_step(self) -> None:
        """Advance sim time to speed_factor x the wall time elapsed (catching up missed ticks), publish."""
        if self.at_end() or not self.ready():
            return
        now = time.monotonic()
        if self.realtime_origin is None:
            self.realtime_origin = now
        due = int((now - self.realtime_origin) * self.speed_factor * self.odometry_rate) - self.control_steps
        if due <= 0:
            return
        if now - self.last_forces_wall > self.input_timeout:
            if not self.stale:
                self.stale = True
                self.get_logger().warning(f'rotor_forces stale for {self.input_timeout:g} s: rotors at hover thrust')
            self.sim.set_forces(self.hover_forces)
        for _ in range(min(due, MAX_CATCH_UP)):
            self.sim.advance(self.substeps)
            self.control_steps += 1
            if self.at_end():
                return
        self.control_steps += max(0, due - MAX_CATCH_UP)   # a longer stall is not replayed: time is lost
        self.publish_odometry()


def main(argv: list[str] | None = None) -> int:
    return run_node(SimNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
