"""Our state, rotor forces, U1..U4 and references <-> PX4's uORB/uXRCE-DDS messages (px4_msgs), written once.

Plain numbers, no px4_msgs import: the PX4 node (:mod:`quad_sim.px4_node`) copies fields between these records and
px4_msgs, and everything it converts goes through here. Facts are from PX4-Autopilot (release/1.15 era, read at
commit 4817c06 of 2024-11-06) and its ``msg/`` definitions, cited where used.

Frames on both sides:

====================  ==================================================  ==============================================
quantity              ours (:mod:`quad_msgs_bridge.state`)                 PX4 (``VehicleOdometry``, ``msg/``)
====================  ==================================================  ==============================================
position              x, y, z [m, world ENU]                               ``position`` [m, world NED] (pose_frame 1)
attitude              phi, theta, psi [rad], Z-Y-X, body FLU in ENU        ``q`` [w, x, y, z], body FRD -> world NED
velocity              vx, vy, vz [m/s, world ENU]                          ``velocity`` [m/s], NED (velocity_frame 1)
                                                                           or body FRD (velocity_frame 3)
angular velocity      dphi, dtheta, dpsi [rad/s], Euler-angle rates        ``angular_velocity`` [rad/s, body FRD]
====================  ==================================================  ==============================================

World: ENU (x east, y north, z up) <-> NED (x north, y east, z down): (e, n, u) = (y_ned, x_ned, -z_ned), a rotation
by 180 degrees about the axis (1, 1, 0)/sqrt 2. Body: FLU <-> FRD: (x, -y, -z), 180 degrees about x. Yaw: psi_ned =
pi/2 - psi_enu. Euler rates <-> body rates exactly, by :mod:`quad_msgs_bridge.frames`.

Actuators: PX4 quad X numbers its motors 1 front-right, 2 rear-left, 3 front-left, 4 rear-right
(``CA_ROTOR0..3_PX/PY`` of ROMFS/px4fmu_common/init.d-posix/airframes/10040_sihsim_quadx), the first two
counter-clockwise (``CA_ROTORn_KM`` > 0 is counter-clockwise, control_allocator/module.yaml). Our ``rotor_forces``
F1..F4 are matched to them by position and spin (:func:`motor_order`). ``ActuatorMotors.control`` is a *relative
thrust* in [0, 1] (msg/ActuatorMotors.msg: "1 means maximum positive thrust"); PX4's output stage turns it into the
motor signal u by inverting its thrust curve f u^2 + (1 - f) u = control with f = ``THR_MDL_FAC``
(src/lib/mixer_module/functions/FunctionMotors.hpp, ``updateValues``). So we send F / F_max, never u: solving the
curve here as well would invert it twice. :func:`motor_signal` gives the u PX4 computes (to check a hover throttle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from quad_msgs_bridge.frames import (body_rates_from_euler_rates, body_to_world, euler_from_quaternion,
                                     euler_rates_from_body_rates, quaternion_from_euler, world_to_body, wrap_angle)
from quad_msgs_bridge.state import STATE_SIZE
from quad_msgs_bridge.vehicle_params import VehicleParams

# msg/VehicleOdometry.msg
POSE_FRAME_NED = 1
VELOCITY_FRAME_NED = 1
VELOCITY_FRAME_BODY_FRD = 3
#: msg/ActuatorMotors.msg NUM_CONTROLS
MOTOR_CONTROLS = 12

_HALF = math.sqrt(0.5)
#: (w, x, y, z) of the rotation that takes NED coordinates to ENU ones (180 degrees about (1, 1, 0)/sqrt 2)
_NED_TO_ENU = (0.0, _HALF, _HALF, 0.0)
#: (w, x, y, z) of the rotation between FLU and FRD (180 degrees about x; its own inverse)
_FLU_TO_FRD = (0.0, 1.0, 0.0, 0.0)


class Px4Odometry(NamedTuple):
    """The fields of ``px4_msgs/VehicleOdometry`` we read and write (msg/VehicleOdometry.msg)."""

    timestamp_us: int              #: [us] time of the sample (``timestamp_sample``), agent time base
    position: tuple                #: [m, world NED] (pose_frame POSE_FRAME_NED)
    q: tuple                       #: (w, x, y, z): body FRD -> world NED
    velocity: tuple                #: [m/s] in ``velocity_frame``
    velocity_frame: int            #: VELOCITY_FRAME_NED or VELOCITY_FRAME_BODY_FRD
    angular_velocity: tuple        #: [rad/s, body FRD]
    pose_frame: int = POSE_FRAME_NED


class Px4TrajectorySetpoint(NamedTuple):
    """The fields of ``px4_msgs/TrajectorySetpoint`` (msg/TrajectorySetpoint.msg: NED local world frame)."""

    position: tuple        #: [m, world NED]
    velocity: tuple        #: [m/s, world NED]
    acceleration: tuple    #: [m/s^2, world NED]
    yaw: float             #: [rad] heading from north, clockwise seen from above, in [-pi, pi)
    yawspeed: float        #: [rad/s] about NED z (down)


def _finite(values: Sequence[float], what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f'{what}: non-finite value in {tuple(values)} (PX4 marks invalid fields NaN)')


def _product(a, b):
    """Hamilton product of quaternions (w, x, y, z)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def enu_from_ned(v: Sequence[float]) -> tuple[float, float, float]:
    """A world vector [.., NED] in ENU: (east, north, up) = (v_y, v_x, -v_z); its own inverse."""
    return (float(v[1]), float(v[0]), -float(v[2]))


def flu_from_frd(v: Sequence[float]) -> tuple[float, float, float]:
    """A body vector [.., FRD] in FLU: (x, -y, -z); its own inverse."""
    return (float(v[0]), -float(v[1]), -float(v[2]))


ned_from_enu = enu_from_ned
frd_from_flu = flu_from_frd


def ned_yaw(psi: float) -> float:
    """PX4's yaw [rad, NED: from north, clockwise seen from above] of our yaw psi [rad, ENU: from east,
    counter-clockwise], wrapped into [-pi, pi); its own inverse."""
    return float(wrap_angle(math.pi / 2.0 - psi))


def state_from_px4_odometry(odometry: Px4Odometry) -> list[float]:
    """Our 12 states (x y z [m, world ENU], vx vy vz [m/s, world ENU], phi theta psi [rad], Euler-angle rates
    [rad/s]) of a PX4 odometry sample.

    ValueError on a non-finite field (PX4 sends NaN for what it does not know), a pose frame other than NED or a
    velocity frame other than NED / body FRD (a world FRD frame of arbitrary heading cannot be placed in ENU),
    a quaternion of no orientation and at gimbal lock."""
    if odometry.pose_frame != POSE_FRAME_NED:
        raise ValueError(f'odometry pose_frame {odometry.pose_frame}: only NED ({POSE_FRAME_NED}) is supported')
    if odometry.velocity_frame not in (VELOCITY_FRAME_NED, VELOCITY_FRAME_BODY_FRD):
        raise ValueError(f'odometry velocity_frame {odometry.velocity_frame}: only NED ({VELOCITY_FRAME_NED}) and '
                         f'body FRD ({VELOCITY_FRAME_BODY_FRD}) are supported')
    for name in ('position', 'q', 'velocity', 'angular_velocity'):
        _finite(getattr(odometry, name), f'odometry {name}')
    # R_enu_flu = R(NED->ENU) R_ned_frd R(FLU->FRD), as quaternions (w, x, y, z)
    w, x, y, z = _product(_product(_NED_TO_ENU, tuple(map(float, odometry.q))), _FLU_TO_FRD)
    euler = euler_from_quaternion((x, y, z, w))
    if odometry.velocity_frame == VELOCITY_FRAME_NED:
        velocity = enu_from_ned(odometry.velocity)
    else:
        velocity = body_to_world(euler, flu_from_frd(odometry.velocity))
    rates = euler_rates_from_body_rates(euler, flu_from_frd(odometry.angular_velocity))
    return [*enu_from_ned(odometry.position), *map(float, velocity), *map(float, euler), *map(float, rates)]


def px4_odometry_from_state(timestamp_us: int, state: Sequence[float],
                            velocity_frame: int = VELOCITY_FRAME_NED) -> Px4Odometry:
    """The PX4 odometry fields of our 12 states (the inverse of :func:`state_from_px4_odometry`): position
    [m, world NED], q (w, x, y, z) body FRD -> NED, velocity [m/s] in ``velocity_frame`` (NED or body FRD),
    angular velocity [rad/s, body FRD]. ValueError on a non-finite state."""
    if len(state) != STATE_SIZE:
        raise ValueError(f'state has {len(state)} components, expected {STATE_SIZE}')
    _finite(state, 'state')
    x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = map(float, state)
    qx, qy, qz, qw = quaternion_from_euler(phi, theta, psi)
    # R_ned_frd = R(ENU->NED) R_enu_flu R(FRD->FLU); both fixed rotations are their own inverses (up to sign)
    q = _product(_product(_NED_TO_ENU, (qw, qx, qy, qz)), _FLU_TO_FRD)
    if q[0] < 0.0:
        q = tuple(-c for c in q)        # the same rotation, PX4's usual hemisphere (w >= 0)
    rates = frd_from_flu(body_rates_from_euler_rates((phi, theta, psi), (dphi, dtheta, dpsi)))
    if velocity_frame == VELOCITY_FRAME_NED:
        velocity = ned_from_enu((vx, vy, vz))
    elif velocity_frame == VELOCITY_FRAME_BODY_FRD:
        velocity = frd_from_flu(world_to_body((phi, theta, psi), (vx, vy, vz)))
    else:
        raise ValueError(f'velocity_frame {velocity_frame}: only NED ({VELOCITY_FRAME_NED}) and body FRD '
                         f'({VELOCITY_FRAME_BODY_FRD}) are supported')
    return Px4Odometry(int(timestamp_us), ned_from_enu((x, y, z)), tuple(map(float, q)), tuple(map(float, velocity)),
                       velocity_frame, tuple(map(float, rates)))


def trajectory_setpoint(position: Sequence[float], velocity: Sequence[float], acceleration: Sequence[float],
                        yaw: float, yaw_rate: float = 0.0) -> Px4TrajectorySetpoint:
    """PX4's TrajectorySetpoint of our reference: position [m], velocity [m/s], acceleration [m/s^2], all world ENU,
    yaw [rad, ENU] and yaw rate [rad/s, about up]; to NED, yaw pi/2 - psi wrapped, yawspeed -yaw_rate.
    ValueError on a non-finite value (PX4 reads NaN as "not controlled", which a reference never means here)."""
    values = (*position, *velocity, *acceleration, yaw, yaw_rate)
    _finite(values, 'reference')
    return Px4TrajectorySetpoint(ned_from_enu(position), ned_from_enu(velocity), ned_from_enu(acceleration),
                                 ned_yaw(yaw), -float(yaw_rate))


# --- actuators ------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Px4RotorGeometry:
    """PX4's control-allocation geometry of a multirotor (``CA_ROTORn_*`` parameters), rotors in PX4's motor order.

    positions [m, body FRD] (``CA_ROTORn_PX``, ``_PY``, ``_PZ``), moment ratios km [m] (``CA_ROTORn_KM``, > 0
    counter-clockwise seen from above), thrust coefficient ct (``CA_ROTORn_CT``; it cancels out of the normalised
    allocation), every rotor axis (0, 0, -1) (``CA_ROTORn_AX..AZ`` defaults): control_allocator/module.yaml."""

    positions: tuple
    km: tuple
    ct: float = 6.5       #: CA_ROTORn_CT default

    def effectiveness(self) -> np.ndarray:
        """(6, n): torque [x, y, z] and thrust [x, y, z] per unit of each rotor's relative thrust, body FRD, as
        PX4's ActuatorEffectivenessRotors builds it (thrust ct a, moment ct p x a - ct km a, a the rotor axis)."""
        axis = np.array([0.0, 0.0, -1.0])
        columns = [np.concatenate([self.ct * np.cross(p, axis) - self.ct * km * axis, self.ct * axis])
                   for p, km in zip(np.asarray(self.positions, dtype=float), self.km)]
        return np.array(columns).T

    def allocation(self) -> np.ndarray:
        """(n, 6): PX4's normalised allocation matrix: relative rotor thrusts per unit of normalised torque [x, y, z]
        and thrust [x, y, z] setpoint (VehicleTorqueSetpoint, VehicleThrustSetpoint), before saturation.

        Our reading of control_allocator/ControlAllocation/ControlAllocationPseudoInverse.cpp
        (updateControlAllocationMatrixScale, normalizeControlAllocationMatrix): the pseudo-inverse of
        :meth:`effectiveness`; roll and pitch columns divided by one common scale, the larger of
        sqrt(|column|^2 / (n_nonzero / 2)) of the two; the yaw column by its largest element; each thrust column by
        its mean absolute non-zero element (the z one's where a column is all zero); then entries below 1e-3 set
        to 0. For a symmetric quad X: roll and pitch +-1/sqrt 2, yaw +-1, thrust z -1 per rotor."""
        mix = np.linalg.pinv(self.effectiveness())
        def nonzero(column, floor):
            return int(np.count_nonzero(np.abs(column) > floor))
        scales = [math.sqrt(np.sum(mix[:, k] ** 2) / (nonzero(mix[:, k], 1e-3) / 2.0)) if nonzero(mix[:, k], 1e-3)
                  else 1.0 for k in (0, 1)]
        mix[:, 0:2] /= max(scales)
        yaw_scale = float(mix[:, 2].max())
        if yaw_scale > 0.0:
            mix[:, 2] /= yaw_scale
        thrust_scale = {}
        for k in (5, 4, 3):
            count = nonzero(mix[:, k], 0.0)
            thrust_scale[k] = float(np.sum(np.abs(mix[:, k]))) / count if count else thrust_scale.get(5, 1.0)
        for k in (3, 4, 5):
            mix[:, k] /= thrust_scale[k]
        mix[np.abs(mix) < 1e-3] = 0.0
        return mix


#: PX4 SIH quadrotor X (ROMFS/px4fmu_common/init.d-posix/airframes/10040_sihsim_quadx): CA_ROTOR0 (1, 1),
#: CA_ROTOR1 (-1, -1), CA_ROTOR2 (1, -1) KM -0.05, CA_ROTOR3 (-1, 1) KM -0.05; the others' KM the default 0.05
SIH_QUADX = Px4RotorGeometry(positions=((1.0, 1.0, 0.0), (-1.0, -1.0, 0.0), (1.0, -1.0, 0.0), (-1.0, 1.0, 0.0)),
                             km=(0.05, 0.05, -0.05, -0.05))


def motor_order(params: VehicleParams, geometry: Px4RotorGeometry = SIH_QUADX) -> tuple[int, int, int, int]:
    """PX4's motor index (0-based) of each of our rotors F1..F4: the PX4 rotor at the same bearing (our position
    [m, body FLU] in FRD, within 0.01 degree) turning the same way. ValueError where the layouts differ (our plus
    frame against PX4's quad X, or a spin the other way), naming the rotor."""
    if len(geometry.positions) != 4:
        raise ValueError(f'PX4 geometry has {len(geometry.positions)} rotors; our vehicles have 4')
    bearings = [math.atan2(p[1], p[0]) for p in geometry.positions]
    order = []
    for i, ((x, y, _), spin) in enumerate(zip(params.rotor_positions, params.rotor_directions)):
        bearing = math.atan2(-y, x)     # FLU -> FRD
        match = [k for k, b in enumerate(bearings) if abs(wrap_angle(bearing - b)) < math.radians(0.01)]
        if not match:
            raise ValueError(f'rotor F{i + 1} at ({x}, {y}) m (body FLU) has no PX4 rotor at its bearing '
                             f'(PX4 rotors at {geometry.positions} m, body FRD): the layouts differ')
        k = match[0]
        if (geometry.km[k] > 0.0) != (spin > 0):
            raise ValueError(f'rotor F{i + 1} turns {"counter-" if spin > 0 else ""}clockwise, PX4 motor {k + 1} at '
                             f'its place the other way (CA_ROTOR{k}_KM {geometry.km[k]})')
        order.append(k)
    return tuple(order)


def motor_controls(forces: Sequence[float], params: VehicleParams, order: Sequence[int]) -> tuple[float, ...]:
    """``ActuatorMotors.control`` (12 values) of our rotor thrusts F1..F4 [N]: PX4 motor ``order[i]`` gets
    F_i / F_max (relative thrust, clipped to [0, 1]); the unused 8 are NaN ("NaN maps to disarmed", ActuatorMotors.msg).
    ValueError on a non-finite force."""
    _finite(forces, 'rotor forces')
    controls = [math.nan] * MOTOR_CONTROLS
    for force, k in zip(forces, order):
        controls[k] = min(max(float(force) / params.F_max, 0.0), 1.0)
    return tuple(controls)


def motor_signal(relative_thrust: float, thr_mdl_fac: float = 0.0) -> float:
    """The motor signal u in [0, 1] PX4's output stage makes of a relative thrust c in [0, 1] (ActuatorMotors
    control): the root in [0, 1] of f u^2 + (1 - f) u = c with f = THR_MDL_FAC (default 0.0, motor_params.c:
    then u = c). What the motor (or SIH: thrust = SIH_T_MAX u, sih.cpp) receives; PX4 computes it itself."""
    c = min(max(float(relative_thrust), 0.0), 1.0)
    f = float(thr_mdl_fac)
    if not 0.0 <= f <= 1.0:
        raise ValueError(f'THR_MDL_FAC {f} is outside [0, 1]')
    if f == 0.0:
        return c
    b = 1.0 - f
    return (-b + math.sqrt(b * b + 4.0 * f * c)) / (2.0 * f)


def rotor_effectiveness(params: VehicleParams, order: Sequence[int]) -> np.ndarray:
    """(4, n): torque x, y, z [N m] and thrust z [N], body FRD, of our vehicle per unit of each PX4 motor's relative
    thrust (rotor thrust F_max control): moment r x (0, 0, -T) plus the reaction torque s (Kd/Kp) T about FRD z
    (a counter-clockwise rotor, s = +1, turns the body clockwise seen from above)."""
    n = max(order) + 1
    matrix = np.zeros((4, n))
    for (x, y, z), spin, k in zip(params.rotor_positions, params.rotor_directions, order):
        r = np.array(frd_from_flu((x, y, z)))
        thrust = np.array([0.0, 0.0, -params.F_max])
        matrix[:3, k] = np.cross(r, thrust) + np.array([0.0, 0.0, spin * params.yaw_coefficient * params.F_max])
        matrix[3, k] = -params.F_max
    return matrix


def wrench_scales(params: VehicleParams, geometry: Px4RotorGeometry = SIH_QUADX) -> tuple[float, float, float, float]:
    """What a unit normalised setpoint gives on our vehicle through PX4's allocation (before saturation): torque
    about FRD x, y, z [N m] per unit of VehicleTorqueSetpoint.xyz and thrust [N] per unit of -VehicleThrustSetpoint.z.

    It is the diagonal of (our rotors' effectiveness) x (PX4's normalised allocation,
    :meth:`Px4RotorGeometry.allocation`); ValueError where that product is not diagonal (PX4's geometry does not
    describe our vehicle: a roll setpoint would also pitch). For PX4's SIH vehicle: 2 sqrt 2 SIH_L_ROLL SIH_T_MAX
    roll and pitch, 4 SIH_Q_MAX yaw, 4 SIH_T_MAX thrust."""
    order = motor_order(params, geometry)
    mix = geometry.allocation()[:, [0, 1, 2, 5]]
    product = rotor_effectiveness(params, order) @ mix     # [3, 3]: thrust z [N] per unit of z setpoint, both down
    diagonal = np.diag(product).copy()
    off = product - np.diag(diagonal)
    if np.any(np.abs(off) > 1e-9 * np.max(np.abs(diagonal))) or np.any(diagonal <= 0.0):
        raise ValueError(f'PX4 geometry does not allocate our vehicle axis by axis: wrench per unit setpoint\n'
                         f'{product}')
    return tuple(float(v) for v in diagonal)


def thrust_torque_setpoints(controls: Sequence[float], params: VehicleParams,
                            scales: Sequence[float]) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(VehicleThrustSetpoint.xyz, VehicleTorqueSetpoint.xyz), body FRD, normalised, of U1 [N], U2 [N], U3 [N],
    U4 [N m] (eq. 2): thrust (0, 0, -U1 / thrust scale), the thrust scale n_rotors F_max; torque = our torque
    (d U2, d U3, U4) [N m, body FLU] in FRD, (d U2, -d U3, -U4), each divided by its axis' scale from
    :func:`wrench_scales` (the torque PX4 makes of a unit setpoint). Clipped to [-1, 1] as the fields' range;
    ValueError on a non-finite value."""
    _finite(controls, 'U1..U4')
    u1, u2, u3, u4 = map(float, controls)
    torque = frd_from_flu((params.d * u2, params.d * u3, u4))
    clip = lambda v: min(max(v, -1.0), 1.0)
    return ((0.0, 0.0, clip(-u1 / scales[3])),
            tuple(clip(t / s) for t, s in zip(torque, scales[:3])))


# --- PX4's topics in our bags ---------------------------------------------------------------------------------

from quad_msgs_bridge.contract import QosSpec, TopicSpec   # noqa: E402  (the contract's record type)

#: PX4's client writes /fmu/out best effort + transient local, reads /fmu/in best effort + volatile
#: (src/modules/uxrce_dds_client/utilities.hpp); keep last 1 as the node's publishers and subscriptions
_PX4_OUT_QOS = QosSpec('best_effort', 'transient_local', 1)
_PX4_IN_QOS = QosSpec('best_effort', 'volatile', 1)
PX4_ODOMETRY = TopicSpec('/fmu/out/vehicle_odometry', 'px4_msgs/msg/VehicleOdometry', _PX4_OUT_QOS,
                         'PX4 -> px4 bridge: EKF2 odometry, NED/FRD')
PX4_STATUS = TopicSpec('/fmu/out/vehicle_status', 'px4_msgs/msg/VehicleStatus', _PX4_OUT_QOS,
                       'PX4 -> px4 bridge: arming and navigation state')
PX4_OFFBOARD_MODE = TopicSpec('/fmu/in/offboard_control_mode', 'px4_msgs/msg/OffboardControlMode', _PX4_IN_QOS,
                              'px4 bridge -> PX4: the offboard heartbeat and control level')
PX4_COMMAND = TopicSpec('/fmu/in/vehicle_command', 'px4_msgs/msg/VehicleCommand', _PX4_IN_QOS,
                        'px4 bridge -> PX4: mode switch, arming, landing, disarming')
PX4_MOTORS = TopicSpec('/fmu/in/actuator_motors', 'px4_msgs/msg/ActuatorMotors', _PX4_IN_QOS,
                       'px4 bridge -> PX4: relative rotor thrusts (direct_actuator)')
PX4_THRUST = TopicSpec('/fmu/in/vehicle_thrust_setpoint', 'px4_msgs/msg/VehicleThrustSetpoint', _PX4_IN_QOS,
                       'px4 bridge -> PX4: normalised thrust (thrust_and_torque)')
PX4_TORQUE = TopicSpec('/fmu/in/vehicle_torque_setpoint', 'px4_msgs/msg/VehicleTorqueSetpoint', _PX4_IN_QOS,
                       'px4 bridge -> PX4: normalised torque (thrust_and_torque)')
PX4_TRAJECTORY = TopicSpec('/fmu/in/trajectory_setpoint', 'px4_msgs/msg/TrajectorySetpoint', _PX4_IN_QOS,
                           'px4 bridge -> PX4: our reference for PX4\'s own controller (--controller px4)')
#: what a PX4 flight's bag records of PX4's topics, beside the contract's (names for PX4's first instance; the
#: bridge's ``px4_namespace`` prefixes them)
PX4_RECORDED_TOPICS = (PX4_ODOMETRY, PX4_STATUS, PX4_OFFBOARD_MODE, PX4_COMMAND, PX4_MOTORS, PX4_THRUST, PX4_TORQUE,
                       PX4_TRAJECTORY)


def px4_msgs_definitions() -> Path:
    """The folder of px4_msgs' ``.msg`` files as its colcon install has them (``share/px4_msgs/msg``), found on
    AMENT_PREFIX_PATH, else beside the importable ``px4_msgs`` package (``<prefix>/lib/pythonX.Y/site-packages``).
    FileNotFoundError saying where it looked."""
    import os
    looked = []
    for prefix in filter(None, os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep)):
        folder = Path(prefix) / 'share' / 'px4_msgs' / 'msg'
        looked.append(str(folder))
        if (folder / 'VehicleOdometry.msg').is_file():
            return folder
    import importlib.util
    spec = importlib.util.find_spec('px4_msgs')
    if spec is not None and spec.submodule_search_locations:
        package = Path(next(iter(spec.submodule_search_locations)))
        folder = package.parents[3] / 'share' / 'px4_msgs' / 'msg'
        looked.append(str(folder))
        if (folder / 'VehicleOdometry.msg').is_file():
            return folder
    raise FileNotFoundError('px4_msgs message definitions (share/px4_msgs/msg/*.msg) not found; looked in '
                            + (', '.join(looked) or 'nothing: AMENT_PREFIX_PATH is empty and px4_msgs is not '
                               'importable'))


def px4_types(names: Sequence[str] | None = None, folder: Path | None = None) -> dict:
    """rosbags type definitions of the px4_msgs types ``names`` ('px4_msgs/msg/X'; None: those of
    PX4_RECORDED_TOPICS), parsed from the px4_msgs install's ``.msg`` files (:func:`px4_msgs_definitions`). Nothing
    of px4_msgs is copied into this stack: a bag gets its schemas from the px4_msgs the flight ran with."""
    from rosbags.typesys import get_types_from_msg
    folder = px4_msgs_definitions() if folder is None else Path(folder)
    types: dict = {}
    for name in names or sorted({spec.type for spec in PX4_RECORDED_TOPICS}):
        types.update(get_types_from_msg((folder / f'{name.rsplit("/", 1)[-1]}.msg').read_text(), name))
    return types


def install_px4_bag_types(names: Sequence[str] | None = None, folder: Path | None = None) -> None:
    """Teach this process's bag writers px4_msgs: the types are added to rosbags' ROS 2 Jazzy store module, so
    every typestore made from it (quad_msgs_bridge.bag.writer.jazzy_typestore: the publication logs, the merge,
    the recorder) writes their schemas (``ros2msg``, the px4_msgs ``.msg`` text) and RIHS01 hashes. Idempotent.
    FileNotFoundError when px4_msgs is not installed (:func:`px4_msgs_definitions`)."""
    import importlib
    from rosbags.typesys.store import Typestore
    store = importlib.import_module('rosbags.typesys.stores.ros2_jazzy')
    wanted = [n for n in (names or sorted({spec.type for spec in PX4_RECORDED_TOPICS})) if n not in store.FIELDDEFS]
    if not wanted:
        return
    scratch = Typestore(store)
    scratch.register(px4_types(wanted, folder))
    for name in scratch.fielddefs.keys() - store.FIELDDEFS.keys():
        store.FIELDDEFS[name] = scratch.fielddefs[name]
        setattr(store, name.replace('/', '__'), scratch.types[name])
