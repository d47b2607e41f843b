"""Fast CDR encoders for the fixed-layout messages published once per control step, and decoders of
the two the lockstep loop receives (odometry, rotor forces).

Each encoder is one precompiled :class:`struct.Struct`: the 4-byte CDR encapsulation header
(little endian), then the fields in message order: stamps, constant bytes (frame ids, array
layouts) made once, float64 fields, with CDR alignment padding and all-zero blocks (covariances)
as struct pad bytes. The bytes equal ``typestore.serialize_cdr(conversions.<x>_msg(rosbags_kit(), ...))``
for the same inputs (proved by the tests) at a small fraction of the cost; every value is packed
as the float64 the message would carry.

Stamps are passed as (sec, nanosec) of ``builtin_interfaces/Time``, see
:func:`quad_msgs_bridge.timebase.stamp_fields`.
"""
from __future__ import annotations

import struct
from itertools import chain
from typing import Callable, Sequence

from quad_msgs_bridge.contract import BASE_FRAME, ODOM_FRAME
from quad_msgs_bridge.conversions import DIAGNOSTICS_DIMS, multi_array_dimensions, rotor_forces_dims
from quad_msgs_bridge.mixer import ROTOR_NAMES
from quad_msgs_bridge.frames import quaternion_from_euler
from quad_msgs_bridge.state import OdometrySample
from quad_msgs_bridge.timebase import stamp_seconds

#: CDR encapsulation header: plain CDR, little endian, no options
ENCAPSULATION = b'\x00\x01\x00\x00'


class CdrLayout:
    """The layout of a fixed-size CDR message: constant bytes, stamps, float64 fields and zero blocks.

    Fields are added in message order; alignment is relative to the start of the CDR body (after
    the encapsulation header). The layout compiles into one struct: a constant (frame ids, array
    layouts, sequence lengths; adjacent ones merged) is an ``s`` field whose bytes :meth:`compile`
    returns, to be passed at encoding time; alignment padding and zero blocks are pad bytes.
    """

    def __init__(self):
        self._size = 0
        self._pieces: list[str | int] = []    # struct formats, or the index of a constant
        self._constants: list[bytearray] = []
        self._constant_open = False           # the last piece is a constant: padding and constants extend it

    def _pad(self, count: int) -> None:
        if self._constant_open:
            self._constants[-1] += bytes(count)
        else:
            self._pieces.append(f'{count}x')
        self._size += count

    def _align(self, alignment: int) -> None:
        pad = -self._size % alignment
        if pad:
            self._pad(pad)

    def _add_constant(self, data: bytes) -> None:
        if not self._constant_open:
            self._pieces.append(len(self._constants))
            self._constants.append(bytearray())
            self._constant_open = True
        self._constants[-1] += data
        self._size += len(data)

    def _add_variable(self, format_: str, size: int) -> None:
        self._pieces.append(format_)
        self._size += size
        self._constant_open = False

    def uint32(self, value: int) -> None:
        self._align(4)
        self._add_constant(struct.pack('<I', value))

    def string(self, text: str) -> None:
        data = text.encode() + b'\x00'
        self.uint32(len(data))
        self._add_constant(data)

    def stamp(self) -> None:
        """A ``builtin_interfaces/Time`` given at encoding time: int32 sec, uint32 nanosec."""
        self._align(4)
        self._add_variable('iI', 8)

    def float64(self, count: int) -> None:
        """``count`` float64 fields given at encoding time."""
        self._align(8)
        self._add_variable(f'{count}d', 8 * count)

    def zeros(self, count: int) -> None:
        """``count`` float64 fields that are always zero (e.g. a covariance the simulator leaves unset)."""
        self._align(8)
        self._add_variable(f'{8 * count}x', 8 * count)

    def compile(self) -> tuple[struct.Struct, tuple[bytes, ...]]:
        """(struct, constants): pack(ENCAPSULATION, *fields) is the message, with the fields in message
        order, each constant where it sits (the stamps and floats in between)."""
        pieces = ''.join(piece if isinstance(piece, str) else f'{len(self._constants[piece])}s'
                         for piece in self._pieces)
        return struct.Struct(f'<4s{pieces}'), tuple(bytes(c) for c in self._constants)


def _multi_array_layout(dims: Sequence[tuple[str, int]]) -> CdrLayout:
    """Layout of a std_msgs/Float64MultiArray with these (label, size) dimensions, row-major, data_offset 0."""
    layout = CdrLayout()
    layout.uint32(len(dims))
    count = 1
    for label, size, stride in multi_array_dimensions(dims):
        layout.string(label)
        layout.uint32(size)
        layout.uint32(stride)
        count *= size
    layout.uint32(0)
    layout.uint32(count)
    layout.float64(count)
    return layout


def odometry_encoder(frame_id: str = ODOM_FRAME, child_frame_id: str = BASE_FRAME
                     ) -> Callable[[int, int, OdometrySample], bytes]:
    """encode(sec, nanosec, sample) -> CDR of ``conversions.odometry_msg(kit, sample, frame_id, child_frame_id)``."""
    layout = CdrLayout()
    layout.stamp()
    layout.string(frame_id)
    layout.string(child_frame_id)
    layout.float64(7)      # pose: position [m], orientation (x, y, z, w)
    layout.zeros(36)       # pose covariance
    layout.float64(6)      # twist: linear [m/s], angular [rad/s], body frame
    layout.zeros(36)       # twist covariance
    pack, (constant,) = layout.compile()
    pack = pack.pack

    def encode(sec: int, nanosec: int, sample: OdometrySample) -> bytes:
        return pack(ENCAPSULATION, sec, nanosec, constant, *sample.position, *sample.orientation,
                    *sample.linear_velocity, *sample.angular_velocity)
    return encode


def rotor_forces_encoder(rotor_names: Sequence[str] = ROTOR_NAMES) -> Callable[[Sequence[float]], bytes]:
    """encode(forces) -> CDR of ``conversions.rotor_forces_msg(kit, forces, rotor_names)`` (four thrusts [N]).

    Unlike rotor_forces_msg it does not check the values: it records what was sent.
    """
    pack, (constant,) = _multi_array_layout(rotor_forces_dims(rotor_names)).compile()
    pack = pack.pack

    def encode(forces: Sequence[float]) -> bytes:
        return pack(ENCAPSULATION, constant, *forces)
    return encode


def diagnostics_encoder() -> Callable[[Sequence[float], Sequence[float], Sequence[float], Sequence[float]], bytes]:
    """encode(surfaces, equivalent, corrective, slopes) -> CDR of ``conversions.diagnostics_msg(kit, ...)``."""
    pack, (constant,) = _multi_array_layout(DIAGNOSTICS_DIMS).compile()
    pack = pack.pack
    interleave = chain.from_iterable

    def encode(surfaces: Sequence[float], equivalent: Sequence[float], corrective: Sequence[float],
               slopes: Sequence[float]) -> bytes:
        return pack(ENCAPSULATION, constant, *interleave(zip(surfaces, equivalent, corrective, slopes)))
    return encode


def wrench_encoder(arm_length: float, frame_id: str = BASE_FRAME
                   ) -> Callable[[int, int, Sequence[float]], bytes]:
    """encode(sec, nanosec, controls) -> CDR of ``conversions.wrench_msg(kit, t, controls, arm_length, frame_id)``.

    controls are U1 [N], U2 [N], U3 [N], U4 [N m]; the wrench is force (0, 0, U1) [N] and torque
    (d U2, d U3, U4) [N m] in the body frame, d = ``arm_length`` [m].
    """
    layout = CdrLayout()
    layout.stamp()
    layout.string(frame_id)
    layout.float64(6)      # force, torque
    pack, (constant,) = layout.compile()
    pack = pack.pack

    def encode(sec: int, nanosec: int, controls: Sequence[float]) -> bytes:
        u1, u2, u3, u4 = controls
        return pack(ENCAPSULATION, sec, nanosec, constant, 0.0, 0.0, u1, arm_length * u2, arm_length * u3, u4)
    return encode


def pose_stamped_encoder(frame_id: str = ODOM_FRAME) -> Callable[[int, int, Sequence[float], float], bytes]:
    """encode(sec, nanosec, position, yaw) -> CDR of ``conversions.pose_stamped_msg(kit, t, position, yaw, frame_id)``.

    position [m, ``frame_id``], yaw [rad] (orientation: roll and pitch zero).
    """
    layout = CdrLayout()
    layout.stamp()
    layout.string(frame_id)
    layout.float64(7)      # position, orientation
    pack, (constant,) = layout.compile()
    pack = pack.pack

    def encode(sec: int, nanosec: int, position: Sequence[float], yaw: float) -> bytes:
        return pack(ENCAPSULATION, sec, nanosec, constant, *position, *quaternion_from_euler(0.0, 0.0, yaw))
    return encode


def clock_encoder() -> Callable[[int, int], bytes]:
    """encode(sec, nanosec) -> CDR of ``conversions.clock_msg(kit, t)``."""
    layout = CdrLayout()
    layout.stamp()
    pack = layout.compile()[0].pack

    def encode(sec: int, nanosec: int) -> bytes:
        return pack(ENCAPSULATION, sec, nanosec)
    return encode


def tf_encoder(child_frame_ids: Sequence[str], frame_id: str = ODOM_FRAME
               ) -> Callable[[int, int, Sequence[OdometrySample]], bytes]:
    """encode(sec, nanosec, samples) -> CDR of ``conversions.tf_msg(kit, t, samples, child_frame_ids, frame_id)``.

    One tf2_msgs/TFMessage per odometry step: transform k is ``frame_id`` -> ``child_frame_ids[k]``,
    the pose of ``samples[k]`` (position [m], orientation of the body in ``frame_id``), all stamped
    (sec, nanosec).
    """
    layout = CdrLayout()
    layout.uint32(len(child_frame_ids))     # sequence length
    for child_frame_id in child_frame_ids:  # geometry_msgs/TransformStamped
        layout.stamp()
        layout.string(frame_id)
        layout.string(child_frame_id)
        layout.float64(7)                   # translation, rotation (x, y, z, w)
    pack, (count, *frames) = layout.compile()
    pack = pack.pack

    def encode(sec: int, nanosec: int, samples: Sequence[OdometrySample]) -> bytes:
        if len(samples) != len(frames):
            raise ValueError(f'tf: {len(samples)} poses for {len(frames)} child frames')
        fields = [ENCAPSULATION, count]
        for frame_ids, sample in zip(frames, samples):
            fields += (sec, nanosec, frame_ids, *sample.position, *sample.orientation)
        return pack(*fields)
    return encode


# --- decoders of the two messages the lockstep loop receives ----------------------------------
# They take any valid little-endian CDR of the type (any frame ids, any array layout) and check it
# exactly as the matching ``conversions.*_from_msg`` reader does.

_UINT32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
_POSE = struct.Struct('<7d')
_TWIST = struct.Struct('<6d')
_COVARIANCE_SIZE = 36 * 8


def _aligned(offset: int, alignment: int) -> int:
    """``offset`` (from the start of the data) moved up to ``alignment`` within the CDR body."""
    return offset + (-(offset - len(ENCAPSULATION)) % alignment)


def _after_string(data: bytes, offset: int) -> int:
    offset = _aligned(offset, 4)
    return offset + 4 + _UINT32.unpack_from(data, offset)[0]


def _check_encapsulation(data: bytes, what: str) -> None:
    if data[:2] != ENCAPSULATION[:2]:
        raise ValueError(f'{what}: not a little-endian CDR message (encapsulation {bytes(data[:4])!r})')


def _check_finite(values, what: str) -> None:
    if not all(v - v == 0.0 for v in values):   # false for nan and +-inf
        raise ValueError(f'non-finite value in {what}: {list(values)}')


def decode_odometry(data: bytes) -> OdometrySample:
    """OdometrySample of the CDR of a nav_msgs/Odometry, as ``conversions.odometry_from_msg`` gives it."""
    _check_encapsulation(data, 'odometry')
    try:
        sec, nanosec = _STAMP.unpack_from(data, len(ENCAPSULATION))
        offset = _after_string(data, len(ENCAPSULATION) + _STAMP.size)      # header.frame_id
        offset = _aligned(_after_string(data, offset), 8)                    # child_frame_id
        pose = _POSE.unpack_from(data, offset)
        twist = _TWIST.unpack_from(data, offset + _POSE.size + _COVARIANCE_SIZE)
    except struct.error as error:
        raise ValueError(f'odometry: truncated message ({error})') from error
    _check_finite(pose + twist, 'odometry')
    return OdometrySample(stamp_seconds(sec, nanosec), pose[:3], pose[3:], twist[:3], twist[3:])


def decode_rotor_forces(data: bytes) -> tuple[float, float, float, float]:
    """The four thrusts [N] of the CDR of a std_msgs/Float64MultiArray, as ``conversions.rotor_forces_from_msg``."""
    _check_encapsulation(data, 'rotor_forces')
    try:
        offset = len(ENCAPSULATION)
        dims = _UINT32.unpack_from(data, offset)[0]
        offset += 4
        for _ in range(dims):                                   # label, size, stride
            offset = _aligned(_after_string(data, offset), 4) + 8
        data_offset, count = struct.unpack_from('<2I', data, _aligned(offset, 4))
        values = struct.unpack_from(f'<{count}d', data, _aligned(_aligned(offset, 4) + 8, 8))[data_offset:]
    except struct.error as error:
        raise ValueError(f'rotor_forces: truncated message ({error})') from error
    if len(values) != 4:
        raise ValueError(f'rotor_forces: expected 4 values, got {len(values)}')
    _check_finite(values, 'rotor_forces')
    return values
