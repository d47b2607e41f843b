"""Paper eq. (2): rotor thrusts F1..F4 <-> virtual controls U1..U4, and rotor saturation.

Rotor layout (body FLU, the order of the ``rotor_forces`` array): F1 front (+x), F2 right (-y),
F3 back (-x), F4 left (+y). With this layout d U2 is the roll torque and d U3 the pitch torque
of eq. (1); rotors 2 and 4 turn clockwise seen from above, so their reaction torque is +z.
All functions work on plain floats and elementwise on numpy arrays (one element per vehicle): each is a
compiled kernel (numba) that also runs inside the other kernels (the model's rotors, a controller's
output), written once for both.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from quad_msgs_bridge.numeric import every, select

ROTOR_NAMES = ('F1_front', 'F2_right', 'F3_back', 'F4_left')
ALLOCATIONS = ('priority', 'clip')   #: how U1..U4 beyond the rotor limits become thrusts (:func:`allocate`)
CONTROL_NAMES = ('U1', 'U2', 'U3', 'U4')
CONTROL_UNITS = ('N', 'N', 'N', 'N m')   #: of U1..U4


@njit(cache=True, inline='always')
def controls_from_forces(f1, f2, f3, f4, yaw_coefficient):
    """Eq. (2): (U1 [N], U2 [N], U3 [N], U4 [N m]) from rotor thrusts [N]; yaw_coefficient = Kd/Kp [m]."""
    return (f1 + f2 + f3 + f4,
            f4 - f2,
            f3 - f1,
            yaw_coefficient * (-f1 + f2 - f3 + f4))


@njit(cache=True, inline='always', error_model='numpy')
def forces_from_controls(u1, u2, u3, u4, yaw_coefficient):
    """Inverse of eq. (2): rotor thrusts (F1..F4) [N] that produce U1..U4 exactly (no limits)."""
    front_back = 0.5 * (u1 - u4 / yaw_coefficient)   # F1 + F3
    left_right = 0.5 * (u1 + u4 / yaw_coefficient)   # F2 + F4
    return (0.5 * (front_back - u3),
            0.5 * (left_right - u2),
            0.5 * (front_back + u3),
            0.5 * (left_right + u2))


@njit(cache=True, inline='always')
def clipped(value, low, high):
    """``value`` clipped to [low, high] (a float, or elementwise an array); NaN stays NaN."""
    return np.minimum(np.maximum(value, low), high)


@njit(cache=True, inline='always')
def saturated(forces, f_min, f_max):
    """Each rotor thrust of the 4-tuple ``forces`` clipped to its physical range [f_min, f_max] [N] (kernels)."""
    return (clipped(forces[0], f_min, f_max), clipped(forces[1], f_min, f_max), clipped(forces[2], f_min, f_max),
            clipped(forces[3], f_min, f_max))


def saturate_forces(forces, f_min, f_max):
    """Each rotor thrust of ``forces`` (F1..F4, any sequence) clipped to its physical range [f_min, f_max] [N]."""
    return saturated(tuple(forces), f_min, f_max)


@njit(cache=True, error_model='numpy')
def clip_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1..U4 by the exact inverse of eq. (2), each then clipped to [f_min, f_max].

    Paper-faithful (the paper has no rotor limits), but a large yaw or roll demand can take lift away:
    two rotors clipped at f_min leave U1 below what was commanded.
    """
    return saturated(forces_from_controls(u1, u2, u3, u4, yaw_coefficient), f_min, f_max)


@njit(cache=True, inline='always', error_model='numpy')
def _most(room, size):
    """Largest s with s size <= room (room >= 0), at most 1."""
    return np.minimum(1.0, room / np.maximum(np.maximum(size, room), 1e-300))


@njit(cache=True, error_model='numpy')
def priority_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1 [N], U2 [N], U3 [N], U4 [N m]: thrust first, then roll and pitch, yaw last.

    With the mean thrust m = U1/4, the half torques h_r = U2/2, h_p = U3/2 and the yaw shift
    y = U4/(4 c) (c = yaw_coefficient [m]; y moves thrust from rotors 1, 3 to rotors 2, 4), eq. (2)
    inverted reads F1 = m - h_p - y, F2 = m - h_r + y, F3 = m + h_p - y, F4 = m + h_r + y.

    1. U1 is clipped to [4 f_min, 4 f_max] (what four rotors can give); it is then realised exactly.
    2. U2 and U3 are scaled by the largest common factor s in [0, 1] (the direction of the roll/pitch
       torque is kept) for which some yaw shift between 0 and the demanded one keeps every rotor in
       [f_min, f_max]: yaw may be cut, even to nothing, for roll and pitch, but never reversed.
    3. The yaw shift is the demanded one clipped to what then fits.

    So U1 is never given away for a torque, U4 is never larger than asked nor of the other sign,
    and a demand that fits is realised exactly (the inverse of eq. 2). Floats or arrays
    (elementwise, one element per vehicle).
    """
    mean = 0.25 * clipped(u1, 4.0 * f_min, 4.0 * f_max)
    yaw = 0.25 * u4 / yaw_coefficient
    # the common case first: the demand fits (s = 1, the demanded yaw shift), computed as below
    demanded = (mean - 0.5 * u3 - yaw, mean - 0.5 * u2 + yaw, mean + 0.5 * u3 - yaw, mean + 0.5 * u2 + yaw)
    fits = ((np.minimum(np.minimum(demanded[0], demanded[1]), np.minimum(demanded[2], demanded[3])) >= f_min)
            & (np.maximum(np.maximum(demanded[0], demanded[1]), np.maximum(demanded[2], demanded[3])) <= f_max))
    if every(fits):
        return demanded
    below, above = mean - f_min, f_max - mean                 # room of the mean thrust, >= 0
    low, high = np.minimum(yaw, 0.0), np.maximum(yaw, 0.0)   # the yaw shifts allowed: between 0 and the demand
    pitch, roll = 0.5 * np.abs(u3), 0.5 * np.abs(u2)
    # every rotor in range for some shift in [low, high]: the lower bounds of the shift (rotors 1, 3 below
    # f_max; 2, 4 above f_min) below its upper bounds (1, 3 above f_min; 2, 4 below f_max) and the demand range
    scale = _most(f_max - f_min, 2.0 * pitch)
    scale = np.minimum(scale, _most(f_max - f_min, 2.0 * roll))
    scale = np.minimum(scale, _most(2.0 * above, pitch + roll))
    scale = np.minimum(scale, _most(2.0 * below, pitch + roll))
    scale = np.minimum(scale, _most(above + high, pitch))
    scale = np.minimum(scale, _most(below + high, roll))
    scale = np.minimum(scale, _most(below - low, pitch))
    scale = np.minimum(scale, _most(above - low, roll))
    half_roll, half_pitch = 0.5 * scale * u2, 0.5 * scale * u3
    shift = clipped(yaw, np.maximum(scale * pitch - above, scale * roll - below),
                    np.minimum(below - scale * pitch, above - scale * roll))
    forces = (mean - half_pitch - shift, mean - half_roll + shift, mean + half_pitch - shift, mean + half_roll + shift)
    forces = saturated(forces, f_min, f_max)   # removes rounding only (1e-16 N)
    return (select(fits, demanded[0], forces[0]), select(fits, demanded[1], forces[1]),   # a batch: per vehicle
            select(fits, demanded[2], forces[2]), select(fits, demanded[3], forces[3]))


def allocate(allocation, u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1..U4 by ``allocation``: 'priority' (:func:`priority_allocation`) or
    'clip' (:func:`clip_allocation`)."""
    if allocation == 'priority':
        return priority_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max)
    if allocation == 'clip':
        return clip_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max)
    raise ValueError(f'allocation {allocation!r} is not one of {", ".join(ALLOCATIONS)}')
