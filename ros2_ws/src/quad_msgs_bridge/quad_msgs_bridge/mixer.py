"""Paper eq. (2): rotor thrusts F1..F4 <-> virtual controls U1..U4, and rotor saturation.

Rotor layout (body FLU, the order of the ``rotor_forces`` array): F1 front (+x), F2 right (-y),
F3 back (-x), F4 left (+y). With this layout d U2 is the roll torque and d U3 the pitch torque
of eq. (1); rotors 2 and 4 turn clockwise seen from above, so their reaction torque is +z.
All functions work on plain floats and elementwise on numpy arrays (one element per vehicle).
"""
from __future__ import annotations

from quad_msgs_bridge.numeric import namespace_for

ROTOR_NAMES = ('F1_front', 'F2_right', 'F3_back', 'F4_left')
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
