"""quad_sim node: one or several vehicles on one sim clock, behind ``/clock``, ``/tf``, ``odom`` and ``rotor_forces``.

The vehicles are named by ``vehicles`` (namespaces relative to the node's; by default one vehicle,
in the node's own namespace) and start from their slices of ``initial_state``. The node publishes
one ``/clock`` for all, each vehicle's ``odom`` in that vehicle's namespace (child frame
``<namespace>/base_link``) and, with each odometry step, one ``/tf`` message holding every
vehicle's ``odom -> <namespace>/base_link`` (its odometry pose, same stamp). Where ``tf2_msgs`` is
not installed it says so once and runs without TF. At start it publishes each vehicle's URDF on its
latched ``robot_description`` and, with TF, the rotor links on ``/tf_static`` (quad_msgs_bridge.urdf),
logged with its other messages where it keeps a publication log (``record_dir``).

Modes:
* lockstep (default): publish ``/clock``, every ``odom`` and ``/tf`` for time t, wait until every
  vehicle's controller has answered with its ``rotor_forces`` (answers paired by vehicle), integrate
  every vehicle to the next odometry time, repeat. Sim time only advances when all have answered,
  so a run is deterministic and can be faster than real time, and each vehicle flies exactly the
  flight it would fly alone. If a vehicle's answer does not come within ``input_timeout`` seconds
  of wall time, the vehicle is named in a warning and sim time holds. Its pending odometry is
  published again only to reach a reader that subscribed to its ``odom`` after it was sent (a
  restarted controller: the topic is volatile); a controller that is merely slow has it already (the
  topic is reliable), so a late answer changes neither the flight nor what is published: a lockstep
  run publishes each step once, and ``/clock`` once per sim time, however loaded the machine.
* realtime: a wall timer keeps sim time at ``speed_factor`` times the wall time elapsed, integrating
  the control steps that are due (those of missed ticks too) with the latest forces and publishing
  the newest odometry. A vehicle whose forces are older than ``input_timeout`` goes to hover thrust.

Non-finite or malformed forces are rejected (throttled error log), the vehicle's last valid forces hold.
"""
from __future__ import annotations

import time
from functools import partial

import rclpy
from rclpy.node import Node

from quad_msgs_bridge.bag.writer import cdr_as_sent, jazzy_typestore
from quad_msgs_bridge.contract import (CLOCK, ODOM, ODOM_FRAME, ROTOR_FORCES, TF, TF_STATIC, base_frame, resolve,
                                      vehicle_namespaces)
from quad_msgs_bridge.conversions import MessageKit, rosbags_kit
from quad_msgs_bridge.fast_cdr import clock_encoder, decode_rotor_forces, odometry_encoder, tf_encoder
from quad_msgs_bridge.ros_helpers import (declare, publication_log, publisher, run_node, subscription, unmatched,
                                          wait_for_acknowledgements)
from quad_msgs_bridge.timebase import nanoseconds, stamp_fields
from quad_msgs_bridge.urdf import description_messages
from quad_msgs_bridge.validation import ParameterError
from quad_msgs_bridge.vehicle_params import load_vehicle_file

from .fleet import Fleet, LockstepAnswers, split_initial_states
from .plants import DEFAULT_PLANT, PLANTS, make_plant
from .simulator import compile_kernels

MODES = ('lockstep', 'realtime')
MAX_CATCH_UP = 100   #: realtime: most control steps integrated in one timer tick after a stall
#: [s, wall] at the end of a flight (``exit_at_end``), how long the node waits at most for its reliable subscribers
#: (a recorder) to acknowledge its last steps before it exits and takes them away: long enough for a recorder
#: starved by a loaded machine (one was 2 s behind), bounded for one that is gone (killed) and never acknowledges
END_ACKNOWLEDGEMENT_TIMEOUT = 30.0


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
            "start once each vehicle's odom has this many subscribers (its controller, plus any recorder)", (1, 1000))
        self.wait_for_recorders = declare(
            self, 'wait_for_recorders', 0,
            'start once /clock and /tf have this many subscribers each (recorders of every topic; their odom '
            'subscriptions count in wait_for_subscribers)', (0, 1000))
        self.start_delay = declare(self, 'start_delay', 0.0,
                                   'wall seconds to wait once the subscribers are there, before the first step '
                                   '(a late recorder such as ros2 bag record then has all its topics matched)',
                                   (0.0, 60.0))
        self.exit_at_end = declare(self, 'exit_at_end', False, 'shut the node down once duration is reached')
        names = declare(self, 'vehicles', [''],
                        "namespaces of the simulated vehicles, relative to the node's ('': the node's own, the "
                        "default; a leading / makes one absolute): each has odom, rotor_forces and the body frame "
                        '<namespace>/base_link')
        start = declare(self, 'initial_state', [0.0] * 12,
                        '12 values per vehicle, in the order of vehicles: x y z [m] vx vy vz [m/s] '
                        'phi theta psi [rad] dphi dtheta dpsi [rad/s], world ENU')
        publish_tf = declare(self, 'publish_tf', True,
                             'broadcast odom -> <namespace>/base_link of every vehicle on /tf with each odometry')
        substeps = physics_rate / odometry_rate
        if abs(substeps - round(substeps)) > 1e-9:
            raise ParameterError(f'parameter physics_rate: {physics_rate} Hz is not a whole multiple of '
                                 f'odometry_rate {odometry_rate} Hz')
        self.substeps = int(round(substeps))
        namespaces = vehicle_namespaces(self.get_namespace(), names)
        plant = declare(self, 'plant', DEFAULT_PLANT, "what the simulator flies: quad_sim (our model of the paper's "
                        'eq. 1) or rotorpy (RotorPy, its aerodynamics and motor model; docs/ROTORPY.md)',
                        choices=PLANTS, read_only='the plant is built at start')
        model = make_plant(plant, params, disturbances)
        compile_kernels(model, 1.0 / physics_rate)   # before publishing: the first step is not slower than the others
        try:
            self.fleet = Fleet(model, 1.0 / physics_rate, split_initial_states(start, len(namespaces)))
        except ParameterError:
            raise
        except ValueError as error:
            raise ParameterError(f'parameter initial_state: {error}') from error
        self.names = [namespace.strip('/') or '/' for namespace in namespaces]   #: for the logs
        self.hover_forces = (params.hover_force,) * 4
        frames = [base_frame(namespace) for namespace in namespaces]
        self.publication_log = publication_log(self, lambda: nanoseconds(self.fleet.time))
        self.clock_pub = publisher(self, kit, CLOCK, log=self.publication_log)
        self.odom_pubs = [publisher(self, kit, ODOM, namespace, log=self.publication_log) for namespace in namespaces]
        self.odom_names = [resolve(ODOM, namespace) for namespace in namespaces]
        self.tf_pub = self.tf_publisher(kit) if publish_tf else None
        self.publish_robot_description(kit, params, namespaces)
        # the per-step messages go over the wire as CDR bytes made and read by the bridge's fast codecs
        self.encode_clock = clock_encoder()
        self.encode_odometry = [odometry_encoder(ODOM_FRAME, frame) for frame in frames]
        self.encode_tf = tf_encoder(frames)
        self.forces_subs = [subscription(self, kit, ROTOR_FORCES, partial(self.on_forces, vehicle), raw=True,
                                         namespace=namespace) for vehicle, namespace in enumerate(namespaces)]
        self.answers = LockstepAnswers(len(namespaces))
        self.last_forces_wall = [time.monotonic()] * len(namespaces)   #: realtime: each vehicle's last forces
        self.last_publish_wall = time.monotonic()   #: lockstep: the pending odometry was (re)published then
        #: lockstep: each vehicle's odom readers (endpoint GIDs) known to have the pending odometry
        self.odom_readers: list[set[tuple[int, ...]]] = [set() for _ in namespaces]
        self.started = False
        self.subscribed_since: float | None = None   #: wall time the start condition first held
        self.stale: set[int] = set()                 #: vehicles in a stale-input episode
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
            f'{self.mode} simulation of {len(namespaces)} vehicle(s) ({", ".join(self.names)}): physics '
            f'{physics_rate:g} Hz, odometry {odometry_rate:g} Hz, disturbances '
            f'{"on" if disturbances.enabled else "off"}, TF {"on" if self.tf_pub else "off"}')

    def tf_publisher(self, kit: MessageKit):
        """The ``/tf`` publisher, or None (said once) where tf2_msgs is not installed."""
        try:
            return publisher(self, kit, TF, log=self.publication_log)
        except ImportError as error:
            self.get_logger().warning(f'{TF.type} is not installed ({error}): running without TF, nothing on '
                                      f'{TF.name} and {TF_STATIC.name}')
            return None

    def publish_robot_description(self, kit: MessageKit, params, namespaces) -> None:
        """Each vehicle's URDF on its latched ``robot_description`` and, with TF, the rotor links' fixed
        transforms on ``/tf_static`` (quad_msgs_bridge.urdf), once: RViz and Foxglove draw the vehicle at its TF.
        Sent as CDR bytes serialized by the rosbags Jazzy typestore, as an embedded flight's bag holds them (see
        the trajectory node), and logged at the first step's sim time."""
        typestore = jazzy_typestore()
        messages = description_messages(rosbags_kit(), params, namespaces, with_tf=self.tf_pub is not None)
        self.description_pubs = [publisher(self, kit, topic, namespace, log=self.publication_log)
                                 for topic, namespace, _ in messages]
        for pub, (topic, _, message) in zip(self.description_pubs, messages):
            pub.publish(cdr_as_sent(typestore, message, topic.type))

    # --- shared -----------------------------------------------------------------------------
    def publish_odometry(self, vehicles=None) -> None:
        """A new step: /clock, every vehicle's odometry and /tf; a repeat (``vehicles`` named): only their
        odometry (the clock has not moved, and a repeated TF is redundant: tf2 warns about it)."""
        samples = self.fleet.odometry()
        sec, nanosec = stamp_fields(samples[0].stamp)
        if vehicles is None:
            self.clock_pub.publish(self.encode_clock(sec, nanosec))
        for vehicle in range(len(samples)) if vehicles is None else vehicles:
            self.odom_pubs[vehicle].publish(self.encode_odometry[vehicle](sec, nanosec, samples[vehicle]))
        if vehicles is None and self.tf_pub is not None:
            self.tf_pub.publish(self.encode_tf(sec, nanosec, samples))
        now = time.monotonic()
        self.last_publish_wall = now
        if self.first_publish_wall is None:
            self.first_publish_wall = now
        if vehicles is None:      # a repeat is not a new step
            self.published += 1

    def timing_report(self) -> str:
        wall = time.monotonic() - (self.first_publish_wall or time.monotonic())
        rate = self.published / wall if wall > 0 else 0.0
        return (f'{self.published} odometry steps of {len(self.fleet)} vehicle(s) in {wall:.3f} s wall: '
                f'{rate:.1f} steps/s')

    def at_end(self) -> bool:
        if self.duration > 0.0 and self.fleet.time >= self.duration - 1e-12:
            if not self.finished:
                self.finished = True
                self.get_logger().info(f'reached duration {self.duration:g} s of sim time; {self.timing_report()}')
                if self.exit_at_end:
                    # a recorder gets the last steps before the node goes
                    wait_for_acknowledgements(self, END_ACKNOWLEDGEMENT_TIMEOUT)
                    rclpy.shutdown(context=self.context)
            return True
        return False

    def accept(self, vehicle: int, data: bytes) -> bool:
        try:
            forces = decode_rotor_forces(data)
        except ValueError as error:
            self.get_logger().error(f'{self.names[vehicle]}: rejected rotor_forces: {error}',
                                    throttle_duration_sec=1.0)
            return False
        return self.fleet.set_forces(vehicle, forces)

    def ready(self) -> bool:
        """Start ``start_delay`` after every vehicle's ``odom`` publisher has matched its ``wait_for_subscribers``
        subscribers, ``/clock`` and ``/tf`` each ``wait_for_recorders`` readers, and every ``rotor_forces``
        subscription a controller's publisher. Matched, not merely discovered (the ROS graph): a message sent to a
        discovered reader not yet matched is not delivered, and the lockstep then waits forever for its answer (seen
        with the simulator on Fast DDS and the controller on Cyclone DDS), or a recorder misses the first steps."""
        if self.started:
            return True
        now = time.monotonic()
        wanted = [(odom, self.wait_for_subscribers) for odom in self.odom_pubs] + [
            (pub, self.wait_for_recorders) for pub in (self.clock_pub, self.tf_pub) if pub is not None]
        if unmatched(wanted) or not all(forces.get_publisher_count() > 0 for forces in self.forces_subs):
            self.subscribed_since = None
        elif self.subscribed_since is None:
            self.subscribed_since = now
        if self.subscribed_since is not None and now - self.subscribed_since >= self.start_delay:
            self.started = True
            self.last_forces_wall = [now] * len(self.fleet)
        return self.started

    # --- lockstep ---------------------------------------------------------------------------
    def odom_reader_ids(self, vehicle: int) -> set[tuple[int, ...]]:
        """The endpoint GIDs of the readers of ``vehicle``'s odom now (from the ROS graph)."""
        return {tuple(info.endpoint_gid) for info in self.get_subscriptions_info_by_topic(self.odom_names[vehicle])}

    def note_odom_readers(self) -> None:
        for vehicle, readers in enumerate(self.odom_readers):
            readers.clear()
            readers.update(self.odom_reader_ids(vehicle))

    def lockstep_watchdog(self) -> None:
        """Start the flight; then, while the steps flow, note who reads each odom; when a vehicle's answer is
        ``input_timeout`` late, name it once, and send its pending odometry again to readers that joined since."""
        if not self.started:
            if self.ready():
                self.note_odom_readers()    # from the same graph that ready() checked: they get the first step
                self.publish_odometry()
            return
        if self.finished:
            return
        if time.monotonic() - self.last_publish_wall < self.input_timeout:
            self.note_odom_readers()        # a reader that joins from here on may have missed the pending step
            return
        rejoined = []
        for vehicle in sorted(self.answers.waiting):
            if vehicle not in self.stale:
                self.stale.add(vehicle)
                self.get_logger().warning(
                    f'{self.names[vehicle]}: no rotor_forces for {self.input_timeout:g} s at sim time '
                    f'{self.fleet.time:.3f} s; holding sim time (its pending odometry goes again to a new reader)')
            readers = self.odom_reader_ids(vehicle)
            if readers - self.odom_readers[vehicle]:
                rejoined.append(vehicle)
            self.odom_readers[vehicle] = readers
        if rejoined:
            self.publish_odometry(rejoined)

    def on_forces(self, vehicle: int, data: bytes) -> None:
        if self.mode == 'realtime':
            if self.accept(vehicle, data):
                self.last_forces_wall[vehicle] = time.monotonic()
                self.stale.discard(vehicle)
            return
        if not self.started or self.finished:
            return
        self.accept(vehicle, data)   # a rejected message still answers: the last valid forces hold
        self.stale.discard(vehicle)
        if not self.answers.answer(vehicle):
            return
        self.fleet.advance(self.substeps)
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
            self.get_logger().info(f'realtime: sim time {self.fleet.time:g} s is wall time {time.time():.6f} s, '
                                   f'speed factor {self.speed_factor:g}')
        due = int((now - self.realtime_origin) * self.speed_factor * self.odometry_rate) - self.control_steps
        if due <= 0:
            return
        for vehicle, last in enumerate(self.last_forces_wall):
            if now - last > self.input_timeout:
                if vehicle not in self.stale:
                    self.stale.add(vehicle)
                    self.get_logger().warning(f'{self.names[vehicle]}: rotor_forces stale for '
                                              f'{self.input_timeout:g} s: rotors at hover thrust')
                self.fleet.set_forces(vehicle, self.hover_forces)
        for _ in range(min(due, MAX_CATCH_UP)):
            self.fleet.advance(self.substeps)
            self.control_steps += 1
            if self.at_end():
                return
        self.control_steps += max(0, due - MAX_CATCH_UP)   # a longer stall is not replayed: time is lost
        self.publish_odometry()


def main(argv: list[str] | None = None) -> int:
    return run_node(SimNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
