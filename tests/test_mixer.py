"""Paper eq. (2): rotor thrusts <-> U1..U4, its inverse and rotor saturation."""
import numpy as np
import pytest

from quad_msgs_bridge.mixer import controls_from_forces, forces_from_controls, saturate_forces
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, _ = load_vehicle_file()
C = PARAMS.yaw_coefficient
F_MIN, F_MAX = PARAMS.F_min, PARAMS.F_max
# Rotor layout (body FLU) documented in mixer.py: F1 front (+x), F2 right (-y), F3 back (-x), F4 left (+y);
# rotors 2 and 4 spin clockwise seen from above, so their reaction torque about +z is positive.
POSITIONS = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * PARAMS.d
SPIN = np.array([-1.0, 1.0, -1.0, 1.0])


def rigid_body_wrench(forces):
    """Thrust and torques [N, N m] of four vertical rotor forces from first principles: sum r x F + reaction."""
    thrust = sum(forces)
    torque = sum(np.cross(r, [0.0, 0.0, f]) for r, f in zip(POSITIONS, forces))
    torque = torque + np.array([0.0, 0.0, C * float(np.dot(SPIN, forces))])
    return thrust, torque


@pytest.mark.parametrize('seed', range(10))
def test_eq2_matches_the_rotor_layout(seed):
    """d U2 is the roll torque, d U3 the pitch torque and U4 the yaw torque of eq. (1)."""
    forces = np.random.default_rng(seed).uniform(0.0, F_MAX, 4)
    u1, u2, u3, u4 = controls_from_forces(*forces, C)
    thrust, torque = rigid_body_wrench(forces)
    assert u1 == pytest.approx(thrust, abs=1e-14)
    np.testing.assert_allclose(torque, [PARAMS.d * u2, PARAMS.d * u3, u4], atol=1e-15)


@pytest.mark.parametrize('seed', range(10))
def test_inverse_round_trip(seed):
    rng = np.random.default_rng(seed)
    forces = tuple(rng.uniform(-1.0, 4.0, 4))
    np.testing.assert_allclose(forces_from_controls(*controls_from_forces(*forces, C), C), forces, atol=1e-12)
    controls = (rng.uniform(0, 10), *rng.uniform(-2, 2, 2), rng.uniform(-0.05, 0.05))
    np.testing.assert_allclose(controls_from_forces(*forces_from_controls(*controls, C), C), controls, atol=1e-12)


def test_hover_forces_give_weight_and_no_torque():
    u1, u2, u3, u4 = controls_from_forces(*(PARAMS.hover_force,) * 4, C)
    assert u1 == pytest.approx(PARAMS.m * PARAMS.g, rel=1e-15)
    assert (u2, u3, u4) == (0.0, 0.0, 0.0)


def test_functions_work_elementwise_on_arrays():
    rng = np.random.default_rng(7)
    forces = [rng.uniform(-1.0, 4.0, 50) for _ in range(4)]
    batch_controls = controls_from_forces(*forces, C)
    batch_back = forces_from_controls(*batch_controls, C)
    batch_clipped = saturate_forces(tuple(forces), F_MIN, F_MAX)
    for i in range(50):
        single = [float(f[i]) for f in forces]
        controls = controls_from_forces(*single, C)
        np.testing.assert_allclose([c[i] for c in batch_controls], controls, rtol=0, atol=1e-15)
        np.testing.assert_allclose([f[i] for f in batch_back], forces_from_controls(*controls, C), atol=1e-15)
        np.testing.assert_allclose([f[i] for f in batch_clipped], saturate_forces(single, F_MIN, F_MAX), atol=0)


def test_saturation_clips_each_rotor():
    assert saturate_forces((-1.0, 0.5, 3.0, F_MAX), F_MIN, F_MAX) == (F_MIN, 0.5, F_MAX, F_MAX)

