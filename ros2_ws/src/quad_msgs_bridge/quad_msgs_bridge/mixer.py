"""Paper eq. (2): rotor thrusts F1..F4 <-> virtual controls U1..U4, and rotor saturation, for a rotor layout.

The layout (:mod:`quad_msgs_bridge.rotor_layout`; a vehicle's ``VehicleParams.mixer``, an array) says where rotors
F1..F4 (the order of the ``rotor_forces`` array) sit and which way they spin. In the paper's "+"
frame F1 is front (+x, body FLU), F2 right (-y), F3 back (-x), F4 left (+y), F2 and F4 turn
clockwise seen from above (their reaction torque is +z): then U2 = F4 - F2, U3 = F3 - F1 and
U4 = Kd/Kp (-F1 + F2 - F3 + F4), with the same floating-point operations as eq. (2) printed. In every
layout d U2 is the roll torque and d U3 the pitch torque of eq. (1), U4 the yaw torque.
All functions work on plain floats and elementwise on numpy arrays (one element per vehicle, one
layout): each is a compiled kernel (numba) that also runs inside the other kernels (the model's
rotors, a controller's output), written once for both.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from quad_msgs_bridge.numeric import every, select
from quad_msgs_bridge.rotor_layout import PAIRS, PITCH, ROLL, SPIN, YAW, YAW_COEFFICIENT, rotor_names

ROTOR_NAMES = rotor_names('plus')   #: F1..F4 of the paper's "+" frame (a vehicle's own: VehicleParams.rotor_names)
#: how U1..U4 beyond the rotor limits become thrusts (:func:`allocate`); a kernel names one by its index
ALLOCATIONS = ('priority', 'clip', 'airmode')
CONTROL_NAMES = ('U1', 'U2', 'U3', 'U4')
CONTROL_UNITS = ('N', 'N', 'N', 'N m')   #: of U1..U4


@njit(cache=True, inline='always')
def controls_from_forces(f1, f2, f3, f4, mixer):
    """Eq. (2): (U1 [N], U2 [N], U3 [N], U4 [N m]) from rotor thrusts [N] in the layout ``mixer`` (its
    per-rotor coefficients y_i/d, -x_i/d, -s_i and Kd/Kp: :mod:`quad_msgs_bridge.rotor_layout`)."""
    return (f1 + f2 + f3 + f4,
            mixer[ROLL] * f1 + mixer[ROLL + 1] * f2 + mixer[ROLL + 2] * f3 + mixer[ROLL + 3] * f4,
            mixer[PITCH] * f1 + mixer[PITCH + 1] * f2 + mixer[PITCH + 2] * f3 + mixer[PITCH + 3] * f4,
            mixer[YAW_COEFFICIENT] * (mixer[YAW] * f1 + mixer[YAW + 1] * f2 + mixer[YAW + 2] * f3
                                      + mixer[YAW + 3] * f4))


@njit(cache=True, inline='always')
def pair_torques(u2, u3, mixer):
    """(t13, t24) [N]: the thrust differences F3 - F1 and F4 - F2 that give U2, U3 [N] in the layout."""
    return mixer[PAIRS] * u2 + mixer[PAIRS + 1] * u3, mixer[PAIRS + 2] * u2 + mixer[PAIRS + 3] * u3


@njit(cache=True, inline='always', error_model='numpy')
def forces_from_controls(u1, u2, u3, u4, mixer):
    """Inverse of eq. (2): rotor thrusts (F1..F4) [N] that produce U1..U4 exactly (no limits)."""
    t13, t24 = pair_torques(u2, u3, mixer)
    spin_yaw = mixer[SPIN] * (u4 / mixer[YAW_COEFFICIENT])
    first_third = 0.5 * (u1 - spin_yaw)    # F1 + F3
    second_fourth = 0.5 * (u1 + spin_yaw)  # F2 + F4
    return (0.5 * (first_third - t13),
            0.5 * (second_fourth - t24),
            0.5 * (first_third + t13),
            0.5 * (second_fourth + t24))


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
def clip_allocation(u1, u2, u3, u4, mixer, f_min, f_max):
    """Rotor thrusts [N] for U1..U4 by the exact inverse of eq. (2), each then clipped to [f_min, f_max].

    Paper-faithful (the paper has no rotor limits), but a large yaw or roll demand can take lift away:
    two rotors clipped at f_min leave U1 below what was commanded.
    """
    return saturated(forces_from_controls(u1, u2, u3, u4, mixer), f_min, f_max)


@njit(cache=True, inline='always', error_model='numpy')
def _most(room, size):
    """Largest s with s size <= room (room >= 0), at most 1."""
    return np.minimum(1.0, room / np.maximum(np.maximum(size, room), 1e-300))


@njit(cache=True, error_model='numpy')
def priority_allocation(u1, u2, u3, u4, mixer, f_min, f_max):
    """Rotor thrusts [N] for U1 [N], U2 [N], U3 [N], U4 [N m]: thrust first, then roll and pitch, yaw last.

    With the mean thrust m = U1/4, the pair torques (t13, t24) of U2, U3 (:func:`pair_torques`; in
    the "+" frame t13 = U3, t24 = U2) and the yaw shift y = s_1 U4/(4 c) (c = Kd/Kp [m]; y moves
    thrust from rotors 1, 3 to rotors 2, 4), eq. (2) inverted reads F1 = m - t13/2 - y,
    F2 = m - t24/2 + y, F3 = m + t13/2 - y, F4 = m + t24/2 + y.

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
    t13, t24 = pair_torques(u2, u3, mixer)
    yaw = mixer[SPIN] * (0.25 * u4 / mixer[YAW_COEFFICIENT])
    # the common case first: the demand fits (s = 1, the demanded yaw shift), computed as below
    demanded = (mean - 0.5 * t13 - yaw, mean - 0.5 * t24 + yaw, mean + 0.5 * t13 - yaw, mean + 0.5 * t24 + yaw)
    fits = ((np.minimum(np.minimum(demanded[0], demanded[1]), np.minimum(demanded[2], demanded[3])) >= f_min)
            & (np.maximum(np.maximum(demanded[0], demanded[1]), np.maximum(demanded[2], demanded[3])) <= f_max))
    if every(fits):
        return demanded
    below, above = mean - f_min, f_max - mean                 # room of the mean thrust, >= 0
    low, high = np.minimum(yaw, 0.0), np.maximum(yaw, 0.0)   # the yaw shifts allowed: between 0 and the demand
    pitch, roll = 0.5 * np.abs(t13), 0.5 * np.abs(t24)     # half pair torques ("+": pitch and roll)
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
    half_roll, half_pitch = 0.5 * scale * t24, 0.5 * scale * t13
    shift = clipped(yaw, np.maximum(scale * pitch - above, scale * roll - below),
                    np.minimum(below - scale * pitch, above - scale * roll))
    forces = (mean - half_pitch - shift, mean - half_roll + shift, mean + half_pitch - shift, mean + half_roll + shift)
    forces = saturated(forces, f_min, f_max)   # removes rounding only (1e-16 N)
    return (select(fits, demanded[0], forces[0]), select(fits, demanded[1], forces[1]),   # a batch: per vehicle
            select(fits, demanded[2], forces[2]), select(fits, demanded[3], forces[3]))


@njit(cache=True, error_model='numpy')
def airmode_allocation(u1, u2, u3, u4, mixer, f_min, f_max, airborne=True):
    """Rotor thrusts [N] for U1 [N], U2 [N], U3 [N], U4 [N m]: where ``airborne`` (a bool, or one per vehicle),
    the moments are kept when the collective thrust asked for is below what they need (airmode at low thrust:
    attitude authority whatever U1 asks, even U1 <= 0); otherwise :func:`priority_allocation` (U1 kept, the
    moments scaled to fit). On the ground it is 'priority', since moments realised against the ground tip a
    vehicle as it lifts off (PX4 warns the same of its airmode); the controllers pass airborne above
    ``common.takeoff_height``. With that, airmode still finishes fewer flights than 'priority' on the
    drawn-actuator campaign (docs/BASELINES.md, section 5).

    With the notation of :func:`priority_allocation`, F_i = m + d_i where the differential parts are
    d = (-t13/2 - y, -t24/2 + y, t13/2 - y, t24/2 + y) and W = f_max - f_min is the range of one rotor.
    The spread of the d_i is max(|t13|, |t24|, (|t13| + |t24|)/2 + 2|y|), so, when U1/4 < f_min - min_i d_i
    for the moments as asked (they do not fit below):

    1. U2 and U3 are scaled by s = min(1, W / max(|t13|, |t24|)) (the torque's direction is kept);
    2. the yaw shift is the demanded y clipped to |y| <= (W - s (|t13| + |t24|)/2) / 2 (cut, never reversed);
    3. the mean thrust is U1/4 raised to f_min - min_i d_i (of the moments of steps 1-2), the least collective that
       realises them, and bounded by f_max - max_i d_i (below U1/4 only when they take a rotor's whole range W),
       an interval that steps 1-2 make non-empty.

    At the top the thrust comes first, as with ``priority``: an airmode that also lowered the collective to fit
    the moments kept heavy vehicles from climbing (the NNIT2FSMC finished 44 of 50 example-campaign flights with
    it, 50 with ``priority``; docs/BASELINES.md). A demand that fits is realised exactly (the inverse of eq. 2).
    Floats or arrays (elementwise, one element per vehicle)."""
    t13, t24 = pair_torques(u2, u3, mixer)
    yaw = mixer[SPIN] * (0.25 * u4 / mixer[YAW_COEFFICIENT])
    lowest_asked = np.minimum(np.minimum(-0.5 * t13 - yaw, -0.5 * t24 + yaw),
                              np.minimum(0.5 * t13 - yaw, 0.5 * t24 + yaw))
    thrust_first = priority_allocation(u1, u2, u3, u4, mixer, f_min, f_max)
    below = (0.25 * u1 < f_min - lowest_asked) & airborne
    if not np.any(below):
        return thrust_first
    span = f_max - f_min
    pitch, roll = np.abs(t13), np.abs(t24)
    scale = _most(span, np.maximum(pitch, roll))
    half13, half24 = 0.5 * scale * t13, 0.5 * scale * t24
    room = np.maximum(0.5 * (span - 0.5 * scale * (pitch + roll)), 0.0)
    shift = clipped(yaw, -room, room)
    d = (-half13 - shift, -half24 + shift, half13 - shift, half24 + shift)
    lowest = np.minimum(np.minimum(d[0], d[1]), np.minimum(d[2], d[3]))
    highest = np.maximum(np.maximum(d[0], d[1]), np.maximum(d[2], d[3]))
    mean = clipped(np.maximum(0.25 * u1, f_min - lowest), f_min - lowest, f_max - highest)
    kept = saturated((mean + d[0], mean + d[1], mean + d[2], mean + d[3]), f_min, f_max)   # rounding only
    return (select(below, kept[0], thrust_first[0]), select(below, kept[1], thrust_first[1]),
            select(below, kept[2], thrust_first[2]), select(below, kept[3], thrust_first[3]))


@njit(cache=True, error_model='numpy')
def allocate_by_index(index, u1, u2, u3, u4, mixer, f_min, f_max, airborne=True):
    """:func:`allocate` for the allocation ALLOCATIONS[index] (what a compiled kernel holds)."""
    if index == 0:
        return priority_allocation(u1, u2, u3, u4, mixer, f_min, f_max)
    if index == 1:
        return clip_allocation(u1, u2, u3, u4, mixer, f_min, f_max)
    return airmode_allocation(u1, u2, u3, u4, mixer, f_min, f_max, airborne)


def allocate(allocation, u1, u2, u3, u4, mixer, f_min, f_max, airborne=True):
    """Rotor thrusts [N] for U1..U4 by ``allocation``: 'priority' (:func:`priority_allocation`), 'clip'
    (:func:`clip_allocation`) or 'airmode' (:func:`airmode_allocation`), in the layout ``mixer``
    (``VehicleParams.mixer``); ``airborne`` is airmode's (:func:`airmode_allocation`)."""
    if allocation not in ALLOCATIONS:
        raise ValueError(f'allocation {allocation!r} is not one of {", ".join(ALLOCATIONS)}')
    if allocation == 'airmode':
        return airmode_allocation(u1, u2, u3, u4, mixer, f_min, f_max, airborne)
    return (priority_allocation, clip_allocation)[ALLOCATIONS.index(allocation)](u1, u2, u3, u4, mixer, f_min, f_max)
