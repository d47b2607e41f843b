"""Live view of the embedded flight in Foxglove, without ROS (``run_stack.py --live``).

A Foxglove WebSocket server (``foxglove-sdk``) serves, per vehicle:

* the contract topics the bag records, under the same names (``/quad/odom``, ..., ``/clock``), with
  the same schemas (``ros2msg``: the full ROS 2 Jazzy message definition) and the same CDR bytes: a
  :class:`LiveView` feeds a :class:`~quad_msgs_bridge.bag.flight_bag.FlightBag` whose writer is the
  server instead of an MCAP file (:class:`LiveTopics`), so the messages are made by the one code that
  makes the bag's;
* a 3-D scene, ``/<namespace>/scene`` (``foxglove.SceneUpdate``, frame ``odom``): the body (arms and
  rotors of the vehicle's layout, rotor F1 red, thrust vectors), the flown path, the reference path
  and the reference point of the current step.

Log times are sim time [ns], as in the bag, and the server announces sim time (Foxglove's Time
capability), so the app's clock follows the flight. Latched topics (transient local in the contract:
``setpoints``, ``reference_path``; and the scene's reference path) are sent again once a client
subscribes to them later. A slow client loses its oldest messages (the server's per-client queue)
and a client that leaves changes nothing: logging never waits for a client.

The server has no authentication: whoever can reach its address can watch the flight. It binds to
127.0.0.1 (this machine only) unless the caller names another host.
"""
from __future__ import annotations

import ipaddress
import threading
import time
from typing import Callable, Sequence

import foxglove
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import (Color, CylinderPrimitive, LinePrimitive, LinePrimitiveLineType, Point3,
                               Pose, Quaternion, SceneEntity, SceneUpdate, SpherePrimitive, Timestamp, Vector3)
from foxglove.websocket import ServerListener

from quad_msgs_bridge.bag.flight_bag import FlightBag
from quad_msgs_bridge.bag.writer import cdr_as_sent, jazzy_typestore
from quad_msgs_bridge.contract import DEFAULT_NAMESPACE, ODOM_FRAME, RECORDED_TOPICS, QosSpec, TopicSpec, resolve
from quad_msgs_bridge.frames import Vec3, euler_from_quaternion, rotation_from_euler
from quad_msgs_bridge.reference import SetpointPath
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.timebase import NANOSECONDS_PER_SECOND, nanoseconds
from quad_msgs_bridge.vehicle_params import VehicleParams

#: the WebSocket subprotocol the foxglove-sdk server speaks (the Foxglove app requests it)
SUBPROTOCOL = 'foxglove.sdk.v1'
#: the live view's own topic (not a contract topic): the vehicle's 3-D scene
SCENE = TopicSpec('scene', 'foxglove.SceneUpdate', QosSpec(), 'live view -> Foxglove: body, flown path, reference')
SCENE_PERIOD = 1.0 / 30.0          #: [s, wall] at most one scene update (and time broadcast) per period
PATH_SPACING = 0.02                #: [s, sim] first spacing of the flown path's points
PATH_MAX_POINTS = 4000             #: beyond this, every second point is dropped and the spacing doubles


class LiveViewError(Exception):
    """The live view cannot be served (the port is taken, the host cannot be bound)."""


def is_loopback(host: str) -> bool:
    """True if ``host`` is reachable from this machine only (127.0.0.0/8, ::1, localhost)."""
    if host == 'localhost':
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Subscriptions(ServerListener):
    """Notes client subscriptions; called on the server's threads."""

    def __init__(self):
        self.active: set[tuple[int, int]] = set()   # (client id, channel id)
        self.fresh: list[int] = []                  # channel ids subscribed since the last look
        self.first = threading.Event()

    def on_subscribe(self, client, channel) -> None:
        self.active.add((client.id, channel.id))
        self.fresh.append(channel.id)
        self.first.set()

    def on_unsubscribe(self, client, channel) -> None:
        self.active.discard((client.id, channel.id))


class LiveServer:
    """A Foxglove WebSocket server on ``host``:``port`` (0: any free port) and its channels.

    One server serves every vehicle of a flight: channels are made once per topic (so ``/clock``
    is shared). A context manager that stops the server.

    Every channel is made before the server listens (:meth:`listen`; a channel made later raises). The
    channels that exist when a client connects are advertised to it before its first request is read. A
    channel made while a client is connected is not: foxglove-sdk sends the advertisement first and
    only then notes the channel as advertised to that client. A client that subscribed at once was
    refused ("unknown channel"), so nothing came; ``--live-wait`` then waited forever (a test client
    on a loaded machine, 1 run in 11; the Foxglove app reconnecting to a restarted run would race too).
    """

    def __init__(self, host: str, port: int, name: str = 'NNIT2FSMC flight'):
        """Not listening yet: make the channels, then :meth:`listen`."""
        self._context = foxglove.Context()
        self._subscriptions = _Subscriptions()
        self._server = None
        self.host, self.port, self.name = host, port, name
        self.typestore = jazzy_typestore()
        self._channels: dict[str, object] = {}
        self._latched: dict[int, tuple[object, object, int]] = {}   # channel id -> (channel, message, log time)

    def listen(self) -> None:
        """Start serving (with port 0, ``port`` is then the one taken); LiveViewError if it cannot."""
        try:
            self._server = foxglove.start_server(name=self.name, host=self.host, port=self.port,
                                                 context=self._context, server_listener=self._subscriptions,
                                                 capabilities=[foxglove.Capability.Time])
        except RuntimeError as error:
            raise LiveViewError(f'cannot serve the live view on {self.host}:{self.port}: {error}') from error
        self.port = self._server.port

    @property
    def url(self) -> str:
        host = f'[{self.host}]' if ':' in self.host else self.host
        return f'ws://{host}:{self.port}'

    # --- channels -------------------------------------------------------------------------------
    def _check_not_listening(self, topic: str) -> None:
        if self._server is not None:
            raise RuntimeError(f'live view channel {topic} made after the server started listening (see LiveServer)')

    def ros_channel(self, topic: str, type_name: str) -> foxglove.Channel:
        """The channel of contract topic ``topic`` (absolute name): CDR messages of ROS 2 type ``type_name``."""
        if topic not in self._channels:
            self._check_not_listening(topic)
            msgdef, _ = self.typestore.generate_msgdef(type_name, ros_version=2)
            schema = foxglove.Schema(name=type_name, encoding='ros2msg', data=msgdef.encode())
            self._channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding='cdr',
                                                     context=self._context)
        return self._channels[topic]

    def scene_channel(self, topic: str) -> SceneUpdateChannel:
        """The ``foxglove.SceneUpdate`` channel ``topic``."""
        if topic not in self._channels:
            self._check_not_listening(topic)
            self._channels[topic] = SceneUpdateChannel(topic, context=self._context)
        return self._channels[topic]

    # --- serving --------------------------------------------------------------------------------
    def log(self, channel, message, log_time_ns: int, latched: bool = False) -> None:
        """Send ``message`` on ``channel`` to its subscribers; a latched one also to later subscribers."""
        channel.log(message, log_time=log_time_ns)
        if latched:
            self._latched[channel.id()] = (channel, message, log_time_ns)

    def send_latched(self) -> None:
        """Send the latched messages of the channels subscribed to since the last call (to all of
        their subscribers: a latched message sent twice is the same message)."""
        fresh = self._subscriptions.fresh
        while fresh:
            latched = self._latched.get(fresh.pop())
            if latched is not None:
                channel, message, log_time = latched
                channel.log(message, log_time=log_time)

    def broadcast_time(self, t_ns: int) -> None:
        """Announce the current sim time [ns] to every client."""
        self._server.broadcast_time(t_ns)

    def subscribed(self) -> bool:
        """True while some client is subscribed to some channel."""
        return bool(self._subscriptions.active)

    def wait_for_subscriber(self, stop: Callable[[], bool], poll: float = 0.05) -> bool:
        """Block until a client subscribes to a channel (true) or ``stop()`` returns true (false)."""
        while not self._subscriptions.first.wait(poll):
            if stop():
                return False
        return True

    def close(self) -> None:
        if self._server is not None:
            self._server.stop()

    def __enter__(self) -> 'LiveServer':
        return self

    def __exit__(self, exc_type, exc, traceback) -> None:
        self.close()


class LiveTopics:
    """The contract topics of one vehicle on a :class:`LiveServer`, with the writing calls of a
    :class:`~quad_msgs_bridge.bag.writer.BagWriter`, so that a ``FlightBag`` feeds them."""

    def __init__(self, server: LiveServer, topics: Sequence[TopicSpec], namespace: str):
        self._server = server
        self._channels = {resolve(spec, namespace): server.ros_channel(resolve(spec, namespace), spec.type)
                          for spec in topics}
        self._types = {resolve(spec, namespace): spec.type for spec in topics}
        self._latched = {resolve(spec, namespace) for spec in topics if spec.qos.durability == 'transient_local'}

    def topic_names(self) -> list[str]:
        return list(self._channels)

    def write_serialized(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        self._server.log(self._channels[topic], data, log_time_ns, latched=topic in self._latched)

    def write_message(self, topic: str, msg, log_time_ns: int, publish_time_ns: int | None = None) -> None:
        self.write_serialized(topic, cdr_as_sent(self._server.typestore, msg, self._types[topic]), log_time_ns)

    def close(self) -> None:
        """Nothing to finish: the server outlives the topics of one vehicle."""


# --- the 3-D scene ----------------------------------------------------------------------------
_GREY, _RED, _BLUE = Color(r=0.3, g=0.3, b=0.35, a=1.0), Color(r=0.9, g=0.15, b=0.1, a=0.9), \
    Color(r=0.2, g=0.45, b=0.9, a=0.9)
_PATH_COLOR, _REFERENCE_COLOR, _THRUST_COLOR = Color(r=0.1, g=0.5, b=1.0, a=1.0), \
    Color(r=1.0, g=0.6, b=0.0, a=0.8), Color(r=1.0, g=0.85, b=0.1, a=1.0)


def _timestamp(t_ns: int) -> Timestamp:
    sec, nanosec = divmod(t_ns, NANOSECONDS_PER_SECOND)
    return Timestamp(sec, nanosec)


def _point(v: Sequence[float]) -> Point3:
    return Point3(x=v[0], y=v[1], z=v[2])


def _pose(position: Sequence[float], orientation: Sequence[float]) -> Pose:
    return Pose(position=Vector3(x=position[0], y=position[1], z=position[2]),
                orientation=Quaternion(x=orientation[0], y=orientation[1], z=orientation[2], w=orientation[3]))


_IDENTITY = (0.0, 0.0, 0.0, 1.0)


class VehicleScene:
    """The scene of one vehicle: body, flown path and reference, as ``foxglove.SceneEntity`` in ``odom``.

    Rotors where the vehicle's layout puts them (``VehicleParams.rotor_positions`` [m, body FLU], F1
    first; in the paper's plus frame F1 front (+x), F2 right (-y), F3 back (-x), F4 left (+y)), an arm
    from the centre to each. A thrust vector is drawn along the body z axis from its rotor, d long at
    hover thrust m g / 4 [N].
    """

    def __init__(self, params: VehicleParams, namespace: str):
        d = params.d
        self._prefix = namespace.strip('/') or 'vehicle'
        self._arm_length = d
        self._rotors = params.rotor_positions                                            # [m, body FLU]
        self._thrust_scale = d / (params.m * params.g / 4.0)                             # [m/N]
        self.path: list[Point3] = []            #: flown positions [m, odom], decimated
        self._path_spacing = PATH_SPACING
        self._path_next = -float('inf')

    def add_path_point(self, t: float, position: Sequence[float]) -> None:
        """Keep the flown position [m, odom] at sim time ``t`` [s] if it is due (decimated, bounded)."""
        if t < self._path_next:
            return
        self.path.append(_point(position))
        self._path_next = t + self._path_spacing
        if len(self.path) > PATH_MAX_POINTS:
            self.path = self.path[::2]
            self._path_spacing *= 2.0

    def reference_entity(self, t_ns: int, path: SetpointPath) -> SceneEntity:
        """The reference path as a line through its setpoints [m, odom]."""
        points = [_point(p.position) for p in path.points]
        return SceneEntity(timestamp=_timestamp(t_ns), frame_id=ODOM_FRAME, id=f'{self._prefix}/reference_path',
                           lines=[LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=2.0,
                                                scale_invariant=True, points=points, color=_REFERENCE_COLOR)])

    def rotor_geometry(self, odometry: OdometrySample, forces: Sequence[float]) -> list[tuple[Vec3, Vec3]]:
        """Per rotor (F1..F4): its hub and the tip of its thrust vector [m, odom], at the odometry pose."""
        p = odometry.position
        rows = rotation_from_euler(*euler_from_quaternion(odometry.orientation))     # body -> odom

        def in_odom(v: Sequence[float]) -> Vec3:
            return tuple(p[i] + rows[i][0] * v[0] + rows[i][1] * v[1] + rows[i][2] * v[2] for i in range(3))

        return [(in_odom((x, y, z)), in_odom((x, y, z + self._thrust_scale * force)))
                for (x, y, z), force in zip(self._rotors, forces)]

    def entities(self, t_ns: int, odometry: OdometrySample, forces: Sequence[float],
                 reference_position: Sequence[float]) -> list[SceneEntity]:
        """Body at the odometry pose, thrust vectors of ``forces`` [N], flown path, reference point."""
        stamp = _timestamp(t_ns)
        p, q = odometry.position, odometry.orientation
        d, width = self._arm_length, 0.1 * self._arm_length
        rotor_size = Vector3(x=0.8 * d, y=0.8 * d, z=0.2 * width)
        geometry = self.rotor_geometry(odometry, forces)
        centre = _point(p)
        arms = LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=width, scale_invariant=False,
                             points=[point for hub, _ in geometry for point in (centre, _point(hub))], color=_GREY)
        rotors = [CylinderPrimitive(pose=_pose(hub, q), size=rotor_size, bottom_scale=1.0, top_scale=1.0,
                                    color=_RED if k == 0 else _BLUE) for k, (hub, _) in enumerate(geometry)]
        thrust = [_point(end) for segment in geometry for end in segment]
        body = SceneEntity(timestamp=stamp, frame_id=ODOM_FRAME, id=f'{self._prefix}/body', cylinders=rotors,
                           lines=[arms, LinePrimitive(type=LinePrimitiveLineType.LineList, thickness=3.0,
                                                      scale_invariant=True, points=thrust, color=_THRUST_COLOR)])
        path = SceneEntity(timestamp=stamp, frame_id=ODOM_FRAME, id=f'{self._prefix}/path',
                           lines=[LinePrimitive(type=LinePrimitiveLineType.LineStrip, thickness=2.0,
                                                scale_invariant=True, points=[*self.path, _point(p)],
                                                color=_PATH_COLOR)])
        marker = SceneEntity(timestamp=stamp, frame_id=ODOM_FRAME, id=f'{self._prefix}/reference',
                             spheres=[SpherePrimitive(pose=_pose(reference_position, _IDENTITY),
                                                      size=Vector3(x=width * 2, y=width * 2, z=width * 2),
                                                      color=_REFERENCE_COLOR)])
        return [body, path, marker]


class LiveView:
    """One vehicle's flight served live: a step sink with the per-flight calls of ``FlightBag``.

    ``record_setpoints(path)`` once, ``record_step(...)`` per control step, ``close()``. The contract
    messages of every step go out while a client is subscribed (none are made otherwise); the scene
    and the sim time at most every ``SCENE_PERIOD`` of wall time, and once more at ``close()`` (so the
    whole flown path stays on screen).
    """

    def __init__(self, server: LiveServer, params: VehicleParams, namespace: str = DEFAULT_NAMESPACE,
                 topics: Sequence[TopicSpec] = RECORDED_TOPICS):
        self.server = server
        self._contract = FlightBag(LiveTopics(server, topics, namespace), params, namespace)
        self._scene_channel = server.scene_channel(resolve(SCENE, namespace))
        self._scene = VehicleScene(params, namespace)
        self._next_scene = 0.0          # [s, wall, perf_counter]
        self._last = None               # (stamp [ns], odometry, forces, reference position) of the last step

    def record_setpoints(self, path: SetpointPath) -> None:
        self._contract.record_setpoints(path)
        stamp = nanoseconds(path.start)
        self.server.log(self._scene_channel, SceneUpdate(entities=[self._scene.reference_entity(stamp, path)]),
                        stamp, latched=True)

    def record_step(self, odometry: OdometrySample, forces: Sequence[float], controls: Sequence[float],
                    reference_position: Sequence[float], reference_yaw: float, surfaces: Sequence[float],
                    equivalent: Sequence[float], corrective: Sequence[float], slopes: Sequence[float],
                    truth: OdometrySample | None = None) -> None:
        """The arguments of :meth:`FlightBag.record_step` (same units); the scene shows the true pose."""
        self.server.send_latched()
        if self.server.subscribed():       # nobody listening: no message to make
            self._contract.record_step(odometry, forces, controls, reference_position, reference_yaw,
                                       surfaces, equivalent, corrective, slopes, truth=truth)
        pose = truth or odometry
        self._scene.add_path_point(pose.stamp, pose.position)
        self._last = (nanoseconds(pose.stamp), pose, forces, reference_position)
        now = time.perf_counter()
        if now >= self._next_scene:
            self._next_scene = now + SCENE_PERIOD
            self._show()

    def _show(self) -> None:
        stamp, odometry, forces, reference_position = self._last
        self.server.broadcast_time(stamp)
        if self._scene_channel.has_sinks():
            update = SceneUpdate(entities=self._scene.entities(stamp, odometry, forces, reference_position))
            self.server.log(self._scene_channel, update, stamp)

    def close(self) -> None:
        """Show the last step (the server stays up for the other vehicles; its owner stops it)."""
        if self._last is not None:
            self._show()


def serve_live_view(host: str, port: int, params: VehicleParams, topics: Sequence[TopicSpec] = RECORDED_TOPICS,
                    namespace: str = DEFAULT_NAMESPACE) -> LiveView:
    """The live view of one vehicle on a new :class:`LiveServer` listening on ``host``:``port``, its channels
    made before it listens; LiveViewError if it cannot listen. Its ``server`` is the context manager."""
    server = LiveServer(host, port)
    view = LiveView(server, params, namespace, topics)
    server.listen()
    return view
