"""trajectory node: publishes the chosen scenario as ``setpoints`` (for the controller) and ``reference_path``.

Both are latched (transient local), so a controller or an RViz started later still gets them.
The path starts at ``start_time`` [s] of the node clock (sim time under use_sim_time); -1 means now.
``offset`` [m, world ENU] shifts the whole scenario: a fleet flies one shifted copy per vehicle.
The setpoints' joint is the vehicle's body frame, ``<namespace>/base_link``.
"""
from __future__ import annotations

from rclpy.node import Node

from quad_msgs_bridge.contract import REFERENCE_PATH, SETPOINTS, base_frame
from quad_msgs_bridge.bag.writer import cdr_as_sent, jazzy_typestore
from quad_msgs_bridge.conversions import MessageKit, path_msg, rosbags_kit, setpoints_msg
from quad_msgs_bridge.reference import SetpointPath
from quad_msgs_bridge.ros_helpers import declare, publication_log, publisher, run_node
from quad_msgs_bridge.timebase import seconds
from quad_msgs_bridge.validation import ParameterError

from .trajectory import SCENARIOS, make_scenario


class TrajectoryNode(Node):
    def __init__(self, kit: MessageKit):
        super().__init__('trajectory')
        scenario = declare(self, 'scenario', 'paper', 'reference scenario', choices=tuple(SCENARIOS))
        duration = declare(self, 'duration', 0.0, 'path length [s]; 0: the scenario default', (0.0, 1e6))
        rate = declare(self, 'setpoint_rate', 50.0, 'points per second of the published path [Hz]', (0.1, 10000.0))
        start = declare(self, 'start_time', -1.0, 'sim time the path starts at [s]; -1: now', (-1.0, 1e9))
        offset = declare(self, 'offset', [0.0, 0.0, 0.0],
                         'x y z [m, world ENU] added to every position of the scenario')
        try:
            trajectory = make_scenario(scenario, duration or None, tuple(offset))
        except ParameterError as error:
            raise ParameterError(f'parameter {error}') from error   # it names scenario, duration or offset
        if start < 0.0:
            start = seconds(self.get_clock().now().nanoseconds)
        path = SetpointPath.sampled(trajectory, start, trajectory.duration, rate)
        body = base_frame(self.get_namespace())
        # logged at the node clock's time under use_sim_time, else at sim time 0: it publishes before the flight
        sim_time = self.get_parameter('use_sim_time').value
        self.publication_log = publication_log(self, lambda: self.get_clock().now().nanoseconds if sim_time else 0)
        # published as CDR bytes serialized by the rosbags Jazzy typestore, as the embedded flight's bag holds them
        # (rclpy's serialize_message on Fast DDS leaves the alignment padding uninitialised: a log of its bytes
        # would differ from flight to flight)
        messages, typestore = rosbags_kit(), jazzy_typestore()
        publisher(self, kit, SETPOINTS, log=self.publication_log).publish(
            cdr_as_sent(typestore, setpoints_msg(messages, path, child_frame_id=body), SETPOINTS.type))
        publisher(self, kit, REFERENCE_PATH, log=self.publication_log).publish(
            cdr_as_sent(typestore, path_msg(messages, path), REFERENCE_PATH.type))
        self.get_logger().info(f'{scenario}: {len(path.times)} setpoints from t={path.start:.3f} s '
                               f'to {path.end:.3f} s published')


def main(argv: list[str] | None = None) -> int:
    return run_node(TrajectoryNode, argv)


if __name__ == '__main__':
    raise SystemExit(main())
