"""Paper eq. (2): rotor thrusts F1..F4 <-> virtual controls U1..U4, and rotor saturation.

Rotor layout (body FLU, the order of the ``rotor_forces`` array): F1 front (+x), F2 right (-y),
F3 back (-x), F4 left (+y). With this layout d U2 is the roll torque and d U3 the pitch torque
of eq. (1); rotors 2 and 4 turn clockwise seen from above, so their reaction torque is +z.
All functions work on plain floats and elementwise on numpy arrays (one element per vehicle).
"""
from __future__ import annotations

from quad_msgs_bridge.numeric import namespace_for

ROTOR_NAMES = ('F1_front', 'F2_right', 'F3_back', 'F4_left')
ALLOCATIONS = ('priority', 'clip')   #: how U1..U4 beyond the rotor limits become thrusts (:func:`allocate`)
CONTROL_NAMES = ('U1', 'U2', 'U3', 'U4')
CONTROL_UNITS = ('N', 'N', 'N', 'N m')   #: of U1..U4


def controls_from_forces(f1, f2, f3, f4, yaw_coefficient):
    """Eq. (2): (U1 [N], U2 [N], U3 [N], U4 [N m]) from rotor thrusts [N]; yaw_coefficient = Kd/Kp [m]."""
    return (f1 + f2 + f3 + f4,
            f4 - f2,
            f3 - f1,
            yaw_coefficient * (-f1 + f2 - f3 + f4))


def forces_from_controls(u1, u2, u3, u4, yaw_coefficient):
    """Inverse of eq. (2): rotor thrusts (F1..F4) [N] that produce U1..U4 exactly (no limits)."""
    front_back = 0.5 * (u1 - u4 / yaw_coefficient)   # F1 + F3
    left_right = 0.5 * (u1 + u4 / yaw_coefficient)   # F2 + F4
    return (0.5 * (front_back - u3),
            0.5 * (left_right - u2),
            0.5 * (front_back + u3),
            0.5 * (left_right + u2))


def saturate_forces(forces, f_min, f_max):
    """Each rotor thrust clipped to its physical range [f_min, f_max] [N]."""
    clip = namespace_for(forces[0]).clip
    return tuple(clip(f, f_min, f_max) for f in forces)


def clip_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1..U4 by the exact inverse of eq. (2), each then clipped to [f_min, f_max].

    Paper-faithful (the paper has no rotor limits), but a large yaw or roll demand can take lift away:
    two rotors clipped at f_min leave U1 below what was commanded.
    """
    return saturate_forces(forces_from_controls(u1, u2, u3, u4, yaw_coefficient), f_min, f_max)


def priority_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1 [N], U2 [N], U3 [N], U4 [N m], thrust first, yaw last.

    1. U1 is clipped to [4 f_min, 4 f_max] (what four rotors can give); it is then realised exactly.
    2. U2 and U3 are scaled down by one common factor (the direction of the roll/pitch torque is
       kept) until every rotor fits: |U2| / 2 and |U3| / 2 within the room h = min(U1/4 - f_min,
       f_max - U1/4) left around the mean thrust U1/4.
    3. U4, which moves U4/(4 c) from rotors 1, 3 to rotors 2, 4 (c = yaw_coefficient [m]), is
       clipped to the room the first two steps leave.

    So the realised U1 is the commanded one within the rotor limits, roll and pitch are served
    before yaw, and inside the limits the result is the exact inverse of eq. (2). Floats or arrays
    (elementwise, one element per vehicle).
    """
    xp = namespace_for(u1, u2, u3, u4)
    u1 = xp.clip(u1, 4.0 * f_min, 4.0 * f_max)
    mean = 0.25 * u1
    room = xp.minimum(mean - f_min, f_max - mean)
    largest = 0.5 * xp.maximum(xp.abs(u2), xp.abs(u3))
    scale = xp.minimum(1.0, room / xp.maximum(largest, 1e-12))    # exactly 1 wherever everything fits
    half_roll, half_pitch = 0.5 * scale * u2, 0.5 * scale * u3
    yaw_up = xp.minimum(mean - xp.abs(half_pitch) - f_min, f_max - mean - xp.abs(half_roll))
    yaw_down = xp.minimum(f_max - mean - xp.abs(half_pitch), mean - xp.abs(half_roll) - f_min)
    yaw = xp.clip(0.25 * u4 / yaw_coefficient, -yaw_down, yaw_up)   # thrust moved from rotors 1, 3 to 2, 4
    forces = (mean - half_pitch - yaw, mean - half_roll + yaw, mean + half_pitch - yaw, mean + half_roll + yaw)
    return saturate_forces(forces, f_min, f_max)   # removes rounding only (1e-16 N)


def allocate(allocation, u1, u2, u3, u4, yaw_coefficient, f_min, f_max):
    """Rotor thrusts [N] for U1..U4 by ``allocation``: 'priority' (:func:`priority_allocation`) or
    'clip' (:func:`clip_allocation`)."""
    if allocation == 'priority':
        return priority_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max)
    if allocation == 'clip':
        return clip_allocation(u1, u2, u3, u4, yaw_coefficient, f_min, f_max)
    raise ValueError(f'allocation {allocation!r} is not one of {", ".join(ALLOCATIONS)}')
