"""A cascaded PID/PD controller, the template of a controller package (docs/CONTROLLERS.md).

Position PID -> desired acceleration [m/s^2, world ENU] -> collective thrust U1 [N] and desired roll,
pitch [rad] (the thrust direction for the reference yaw) -> attitude PD -> U2, U3 [N], U4 [N m] of the
paper's eq. (2) -> rotor thrusts F1..F4 [N] by the vehicle's mixer. Gains are per unit mass and
inertia, so the same gains fly every vehicle.
"""
import math

from nnit2fsmc_controller.contract import Gain
from quad_msgs_bridge.mixer import forces_from_controls

__all__ = ['GeometricPD']


class GeometricPD:
    """cascaded PID/PD: position to tilt and thrust, attitude to moments (the controller-package template)"""

    gains = {
        'position': {'kp': Gain(25.0, '1/s^2', 0.5, 50.0, 'x, y position error gain'),
                     'ki': Gain(15.0, '1/s^3', 0.1, 40.0, 'x, y integral gain'),
                     'kd': Gain(10.0, '1/s', 0.5, 20.0, 'x, y velocity error gain')},
        'height': {'kp': Gain(30.0, '1/s^2', 1.0, 80.0, 'z position error gain'),
                   'ki': Gain(12.0, '1/s^3', 0.1, 40.0, 'z integral gain'),
                   'kd': Gain(12.0, '1/s', 1.0, 30.0, 'z velocity error gain')},
        'attitude': {'kp': Gain(400.0, '1/s^2', 20.0, 800.0, 'roll, pitch angle error gain'),
                     'kd': Gain(40.0, '1/s', 5.0, 80.0, 'roll, pitch rate error gain')},
        'yaw': {'kp': Gain(30.0, '1/s^2', 2.0, 200.0, 'yaw error gain'),
                'kd': Gain(10.0, '1/s', 1.0, 40.0, 'yaw rate error gain')},
    }
    gains_section = 'geometric_pd'
    search = ('position.kp', 'position.ki', 'position.kd', 'height.kp', 'height.ki', 'height.kd')   # what tune searches
    integral_limit = 0.5   # [m s] each integral of the position error is kept within +-this
    integrate_within = 0.2   # [m] an axis integrates only while its error is smaller (not during a climb)

    def __init__(self, vehicle, gains, dt):
        self.vehicle, self.gains, self.dt = vehicle, gains, dt
        self.integral = [0.0, 0.0, 0.0]   # [m s] of x, y, z

    def update(self, t, state, reference):
        """Rotor thrusts F1..F4 [N] for the 12 states (world ENU, Z-Y-X Euler angles and their rates)."""
        v, k = self.vehicle, self.gains
        x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = state
        (xr, yr, zr), (vxr, vyr, vzr), (axr, ayr, azr) = reference.position, reference.velocity, reference.acceleration
        if z > 0.05:   # integrate only once airborne: on the ground the vehicle cannot move
            self.integral = [min(max(i + e * self.dt, -self.integral_limit), self.integral_limit)
                             if abs(e) < self.integrate_within else i
                             for i, e in zip(self.integral, (x - xr, y - yr, z - zr))]
        ix, iy, iz = self.integral
        p, h = k['position'], k['height']
        ax = axr - p['kp'] * (x - xr) - p['ki'] * ix - p['kd'] * (vx - vxr)
        ay = ayr - p['kp'] * (y - yr) - p['ki'] * iy - p['kd'] * (vy - vyr)
        az = azr - h['kp'] * (z - zr) - h['ki'] * iz - h['kd'] * (vz - vzr) + v.g
        yaw = reference.yaw
        theta_d = math.atan2(ax * math.cos(yaw) + ay * math.sin(yaw), az)
        phi_d = math.atan2((ax * math.sin(yaw) - ay * math.cos(yaw)) * math.cos(theta_d), az)
        u1 = v.m * az / max(math.cos(phi) * math.cos(theta), 0.2)
        att, yw = k['attitude'], k['yaw']
        yaw_error = math.remainder(psi - yaw, 2.0 * math.pi)
        u2 = v.Ix / v.d * (-att['kp'] * (phi - phi_d) - att['kd'] * dphi)
        u3 = v.Iy / v.d * (-att['kp'] * (theta - theta_d) - att['kd'] * dtheta)
        u4 = v.Iz * (-yw['kp'] * yaw_error - yw['kd'] * (dpsi - reference.yaw_rate))
        return forces_from_controls(u1, u2, u3, u4, v.mixer)
