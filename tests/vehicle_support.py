"""Test vehicles shared by the model and controller tests."""
import dataclasses
import math

from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, DISTURBANCES = load_vehicle_file()
# Every inertia and every drag coefficient different: a roll equation divided by Iy, Kfy used for x,
# or a gyroscopic term of the wrong sign gives a different number here (the paper's set has Ix = Iy
# and equal drag on x and y, so each of those slips is invisible on it).
ASYMMETRIC = dataclasses.replace(PARAMS, Ix=3.1e-3, Iy=4.7e-3, Iz=8.3e-3, Kfx=2.1e-3, Kfy=3.7e-3, Kfz=5.3e-3,
                                 Kfphi=1.3e-3, Kftheta=2.9e-3, Kfpsi=4.1e-3)


def paper_eq1(p, s, u, a):
    """Eq. (1) written out independently, friction as -Kf rate |rate| (see docs/PAPER.md)."""
    x, y, z, vx, vy, vz, phi, theta, psi, dphi, dtheta, dpsi = s
    u1, u2, u3, u4 = u
    ax, ay, az, aphi, atheta, apsi = a
    cf, sf, ct, st, cs, ss = (math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta),
                              math.cos(psi), math.sin(psi))
    return [vx, vy, vz,
            ((cf * cs * st + ss * sf) * u1 - p.Kfx * vx) / p.m + ax / p.m,
            ((cf * ss * st - cs * sf) * u1 - p.Kfy * vy) / p.m + ay / p.m,
            ((cf * ct) * u1 - p.Kfz * vz) / p.m - p.g + az / p.m,
            dphi, dtheta, dpsi,
            (dtheta * dpsi * (p.Iy - p.Iz) + p.d * u2 - p.Kfphi * dphi * abs(dphi)) / p.Ix + aphi / p.Ix,
            (dphi * dpsi * (p.Iz - p.Ix) + p.d * u3 - p.Kftheta * dtheta * abs(dtheta)) / p.Iy + atheta / p.Iy,
            (dphi * dtheta * (p.Ix - p.Iy) + u4 - p.Kfpsi * dpsi * abs(dpsi)) / p.Iz + apsi / p.Iz]
