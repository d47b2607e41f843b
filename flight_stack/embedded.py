"""Embedded backend: trajectory -> controller -> simulator in lockstep, in one process.

Per control step it performs the calls the ROS lockstep flight performs, in the same order: the
simulator's state becomes an odometry sample stamped with sim time, the controller turns it back
into a state and answers it with the reference for that same instant, the simulator takes the
thrusts and integrates until the next odometry.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable, Sequence

from quad_msgs_bridge.conversions import rosbags_kit, setpoints_from_msg, setpoints_msg
from quad_msgs_bridge.bag.flight_bag import FlightBag
from quad_msgs_bridge.review.metrics import FlightRecord, FlightRecorder
from quad_msgs_bridge.reference import SetpointPath
from quad_msgs_bridge.state import PSI, state_from_odometry
from quad_msgs_bridge.vehicle_params import Disturbances, VehicleParams
from quad_sim.model import QuadrotorModel
from quad_sim.simulator import Simulator
from nnit2fsmc_controller.factory import build_controller


@dataclass
class FlightResult:
    record: FlightRecord
    wall_time_s: float
    steps: int


def published_path(trajectory, setpoint_rate: float) -> SetpointPath:
    """The setpoint path the trajectory node would publish."""
    return SetpointPath.sampled(trajectory, 0.0, trajectory.duration, setpoint_rate)


def setpoint_path(path: SetpointPath) -> SetpointPath:
    """``path`` as the controller reads it back from the setpoints message."""
    return setpoints_from_msg(setpoints_msg(rosbags_kit(), path))


def fly_embedded(controller_kind: str, trajectory, params: VehicleParams, disturbances: Disturbances,
                 gains: dict, duration: float, physics_rate: float, setpoint_rate: float = 50.0,
                 progress: bool = False, bag: FlightBag | None = None,
                 stop: Callable[[], bool] | None = None, sinks: Sequence = ()) -> FlightResult:
    """Fly ``trajectory`` for ``duration`` [s] of sim time; one record row per control step.

    With ``bag`` every step's contract messages are recorded too (the caller closes the bag).
    ``sinks`` get the same calls after the bag, in order: ``record_setpoints(path)`` once, then
    ``record_step(...)`` per step (e.g. a ``pacing.Pacer``, then a ``live_view.LiveView``).
    ``stop`` is asked between two control steps: once it returns true the flight raises
    KeyboardInterrupt, with every step so far complete in the bag.
    """
    controller = build_controller(controller_kind, params, gains)
    published = published_path(trajectory, setpoint_rate)
    setpoints = setpoint_path(published)
    physics_dt = 1.0 / physics_rate
    substeps = round(controller.dt / physics_dt)
    if substeps < 1 or abs(substeps * physics_dt - controller.dt) > 1e-12:
        raise ValueError(f'physics rate {physics_rate} Hz is not a whole multiple of the control rate '
                         f'{1.0 / controller.dt} Hz')
    simulator = Simulator(QuadrotorModel(params, disturbances), physics_dt, trajectory.initial_state)
    recorder = FlightRecorder()
    steps = int(round(duration / controller.dt))
    report_every = max(1, steps // 10)
    started = time.perf_counter()
    step_sinks = ([bag] if bag is not None else []) + list(sinks)
    for sink in step_sinks:
        sink.record_setpoints(published)
    for k in range(steps):
        if stop is not None and stop():
            raise KeyboardInterrupt(f'stopped after {k} control steps')
        odometry = simulator.odometry()
        t = odometry.stamp
        state = state_from_odometry(odometry)
        reference = setpoints.sample(t)
        out = controller.update(t, state, reference)
        simulator.set_forces(out.forces)
        axes = out.axes.values()
        surfaces, equivalent, corrective = ([a.surface for a in axes], [a.equivalent for a in axes],
                                            [a.corrective for a in axes])
        recorder.append(t, odometry.position, state[PSI], reference.position, reference.yaw,
                        out.forces, out.controls, surfaces, equivalent, corrective)
        for sink in step_sinks:
            sink.record_step(odometry, out.forces, out.controls, reference.position, reference.yaw,
                             surfaces, equivalent, corrective)
        simulator.advance(substeps)
        if progress and (k + 1) % report_every == 0:
            print(f'  {100 * (k + 1) // steps:3d}%  t = {simulator.time:6.2f} s', file=sys.stderr, flush=True)
    return FlightResult(recorder.record(), time.perf_counter() - started, steps)
