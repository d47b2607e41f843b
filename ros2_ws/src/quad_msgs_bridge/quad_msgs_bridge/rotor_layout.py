"""Where the four rotors sit and which way they spin: the layout behind eq. (2) and ``rotor_forces``.

A layout is four rotor positions r_i = (x_i, y_i, z_i) [m, body FLU, from the geometric centre] and
four spin directions s_i (+1: counter-clockwise seen from above, -1: clockwise), in the order of the
``rotor_forces`` array (F1..F4). Three kinds (``frame`` in a vehicle file):

* ``plus`` (the paper's, the default): F1 front (+x), F2 right (-y), F3 back (-x), F4 left (+y), each
  at the arm length d; F1 and F3 turn counter-clockwise, F2 and F4 clockwise. This is the layout that
  eq. (2) implies (docs/PAPER.md, "Rotor layout").
* ``x``: the "+" layout turned by 45 degrees clockwise seen from above: F1 front-right, F2 back-right,
  F3 back-left, F4 front-left, each at d from the centre (PX4's and Betaflight's "quad X" geometry;
  F1 and F3 counter-clockwise, as PX4's front-right and back-left motors).
* ``custom``: positions and directions given in the vehicle file. The allocation (:mod:`.mixer`)
  pairs opposite rotors, so a custom layout must list the rotors in order around the frame, with
  rotor 3 opposite rotor 1 and rotor 4 opposite rotor 2 (r_3 = -r_1, r_4 = -r_2 in x, y), the two
  rotors of a pair turning the same way and the two pairs opposite ways. That covers "+", X, H and
  wide (rectangular) frames and skewed ones; other layouts are refused with the reason.

Eq. (2) for any layout (a rotor's thrust T_i acts along body +z at r_i, its reaction torque is
-s_i (Kd/Kp) T_i about +z):

    U1 = sum T_i,   d U2 = sum y_i T_i (roll),   d U3 = -sum x_i T_i (pitch),   U4 = (Kd/Kp) sum -s_i T_i (yaw)

so U2 and U3 keep the paper's unit [N] (a torque over the arm length d) for every layout, and the
controllers' laws are unchanged. For "+" the coefficients are the paper's 0 and +-1.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

FRAMES = ('plus', 'x', 'custom')

_NAMES = {'plus': ('F1_front', 'F2_right', 'F3_back', 'F4_left'),
          'x': ('F1_front_right', 'F2_back_right', 'F3_back_left', 'F4_front_left')}
#: the bearing of a rotor, atan2(y, x) in multiples of 45 degrees from +x (front), as a word
_BEARINGS = ('front', 'front_left', 'left', 'back_left', 'back', 'back_right', 'right', 'front_right')

#: spin of F1..F4 in the plus and x frames (+1 counter-clockwise seen from above)
STANDARD_DIRECTIONS = (1, -1, 1, -1)

#: [-] relative tolerance of the point symmetry of a custom layout (to its largest rotor distance)
SYMMETRY_TOLERANCE = 1e-9


# A layout as the mixer kernels read it (:mod:`quad_msgs_bridge.mixer`): one float64 array of MIXER_SIZE
# values per vehicle (an array, not a tuple: numba dispatches a call with an array argument in under a
# microsecond, with a named tuple of tuples in about five).
# Forward (eq. 2): U2 = sum roll_i T_i, U3 = sum pitch_i T_i, U4 = Kd/Kp sum yaw_i T_i, with
# roll_i = y_i / d, pitch_i = -x_i / d, yaw_i = -s_i [-] at ROLL, PITCH, YAW (F1..F4 each) and Kd/Kp [m]
# at YAW_COEFFICIENT. Inverse: the pair torques t13 = T3 - T1 and t24 = T4 - T2 are (K11, K12, K21, K22)
# at PAIRS times (U2, U3): t13 = K11 U2 + K12 U3, t24 = K21 U2 + K22 U3; SPIN holds s_1 (the yaw shift of
# U4 moves thrust from the pair (1, 3) to (2, 4) when s_1 = +1).
ROLL, PITCH, YAW, YAW_COEFFICIENT, PAIRS, SPIN = 0, 4, 8, 12, 13, 17
MIXER_SIZE = 18


def rotor_names(frame: str, positions: Sequence[Sequence[float]] | None = None) -> tuple[str, str, str, str]:
    """Labels of F1..F4 (the ``rotor_forces`` layout label, plot labels): 'F1_front' ... in the plus
    frame, 'F1_front_right' ... in the x frame; in a custom layout (``positions`` [m, body FLU]) the
    rotor's bearing when it lies within 0.5 degrees of one of the eight compass directions, else 'F<i>'."""
    if frame != 'custom':
        return _NAMES[frame]
    names = []
    for i, (x, y, _) in enumerate(positions):
        eighths = math.atan2(y, x) / (math.pi / 4.0)
        near = round(eighths)
        names.append(f'F{i + 1}_{_BEARINGS[near % 8]}' if abs(eighths - near) * 45.0 < 0.5 else f'F{i + 1}')
    return tuple(names)


def frame_positions(frame: str, d: float) -> tuple:
    """Rotor positions (x, y, z) [m, body FLU] of F1..F4 of the ``plus`` or ``x`` frame with arm length d [m]."""
    if frame == 'plus':
        return ((d, 0.0, 0.0), (0.0, -d, 0.0), (-d, 0.0, 0.0), (0.0, d, 0.0))
    if frame == 'x':
        a = d * math.sqrt(0.5)
        return ((a, -a, 0.0), (-a, -a, 0.0), (-a, a, 0.0), (a, a, 0.0))
    raise ValueError(f'frame {frame!r} has no standard positions (one of plus, x)')


def layout_problem(positions: Sequence[Sequence[float]], directions: Sequence[int]) -> str | None:
    """Why the mixer cannot allocate for this layout, or None (see the module docstring)."""
    reach = max(math.hypot(x, y) for x, y, _ in positions)
    if reach <= 0.0:
        return 'every rotor sits on the centre'
    tolerance = SYMMETRY_TOLERANCE * reach
    for i, j in ((0, 2), (1, 3)):
        if any(abs(positions[i][k] + positions[j][k]) > tolerance for k in (0, 1)):
            return (f'rotor {j + 1} is not opposite rotor {i + 1} (x, y of rotor {j + 1} must be minus those of '
                    f'rotor {i + 1}; list the rotors in order around the frame)')
    s1, s2, s3, s4 = directions
    if not (s1 == s3 == -s2 == -s4):
        return 'rotors 1 and 3 must turn one way and rotors 2 and 4 the other'
    (x1, y1, _), (x2, y2, _) = positions[0], positions[1]
    if abs(x1 * y2 - x2 * y1) <= tolerance * reach:
        return 'the rotors lie on one line: they cannot give both a roll and a pitch torque'
    return None


def rotor_mixer(positions: Sequence[Sequence[float]], directions: Sequence[int], d, yaw_coefficient) -> np.ndarray:
    """The kernels' mixer array (MIXER_SIZE values, see ROLL ... SPIN) of a (checked) layout, arm length
    d [m] and Kd/Kp [m]; shape (B, MIXER_SIZE) when d or Kd/Kp are arrays of B vehicles (a batch).

    With X_i = x_i / d, Y_i = y_i / d and the pairs of the module docstring, U2 = -(Y1 t13 + Y2 t24) and
    U3 = X1 t13 + X2 t24 (from T1 - T3 = -t13, T2 - T4 = -t24); ``pairs`` is the inverse of that 2x2 map.
    """
    d = np.asarray(d, dtype=float)
    roll = [y / d for _, y, _ in positions]
    pitch = [-x / d for x, _, _ in positions]
    (x1, y1), (x2, y2) = (positions[0][0] / d, positions[0][1] / d), (positions[1][0] / d, positions[1][1] / d)
    det = x1 * y2 - x2 * y1          # of [[-Y1, -Y2], [X1, X2]]
    pairs = [x2 / det + 0.0, y2 / det + 0.0, -x1 / det + 0.0, -y1 / det + 0.0]   # + 0.0: no -0.0
    values = [*roll, *pitch, *[-float(s) for s in directions], yaw_coefficient, *pairs, float(directions[0])]
    mixer = np.stack(np.broadcast_arrays(*[np.asarray(v, dtype=float) for v in values]), axis=-1)
    return mixer
