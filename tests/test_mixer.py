"""Paper eq. (2): rotor thrusts <-> U1..U4, its inverse and rotor saturation."""
from dataclasses import replace

import numpy as np
import pytest

from quad_msgs_bridge.mixer import (ALLOCATIONS, allocate, clip_allocation, controls_from_forces, forces_from_controls,
                                     pair_torques, priority_allocation, saturate_forces)
from quad_msgs_bridge.vehicle_params import load_vehicle_file

PARAMS, _ = load_vehicle_file()
C = PARAMS.yaw_coefficient
MIXER = PARAMS.mixer
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
    u1, u2, u3, u4 = controls_from_forces(*forces, MIXER)
    thrust, torque = rigid_body_wrench(forces)
    assert u1 == pytest.approx(thrust, abs=1e-14)
    np.testing.assert_allclose(torque, [PARAMS.d * u2, PARAMS.d * u3, u4], atol=1e-15)


@pytest.mark.parametrize('seed', range(10))
def test_inverse_round_trip(seed):
    rng = np.random.default_rng(seed)
    forces = tuple(rng.uniform(-1.0, 4.0, 4))
    np.testing.assert_allclose(forces_from_controls(*controls_from_forces(*forces, MIXER), MIXER), forces, atol=1e-12)
    controls = (rng.uniform(0, 10), *rng.uniform(-2, 2, 2), rng.uniform(-0.05, 0.05))
    np.testing.assert_allclose(controls_from_forces(*forces_from_controls(*controls, MIXER), MIXER), controls,
                               atol=1e-12)


def test_hover_forces_give_weight_and_no_torque():
    u1, u2, u3, u4 = controls_from_forces(*(PARAMS.hover_force,) * 4, MIXER)
    assert u1 == pytest.approx(PARAMS.m * PARAMS.g, rel=1e-15)
    assert (u2, u3, u4) == (0.0, 0.0, 0.0)


def test_functions_work_elementwise_on_arrays():
    rng = np.random.default_rng(7)
    forces = [rng.uniform(-1.0, 4.0, 50) for _ in range(4)]
    batch_controls = controls_from_forces(*forces, MIXER)
    batch_back = forces_from_controls(*batch_controls, MIXER)
    batch_clipped = saturate_forces(tuple(forces), F_MIN, F_MAX)
    for i in range(50):
        single = [float(f[i]) for f in forces]
        controls = controls_from_forces(*single, MIXER)
        np.testing.assert_allclose([c[i] for c in batch_controls], controls, rtol=0, atol=1e-15)
        np.testing.assert_allclose([f[i] for f in batch_back], forces_from_controls(*controls, MIXER), atol=1e-15)
        np.testing.assert_allclose([f[i] for f in batch_clipped], saturate_forces(single, F_MIN, F_MAX), atol=0)


def test_saturation_clips_each_rotor():
    assert saturate_forces((-1.0, 0.5, 3.0, F_MAX), F_MIN, F_MAX) == (F_MIN, 0.5, F_MAX, F_MAX)



# ---------------------------------------------------------------- allocation within the rotor limits
def realised(forces):
    return np.array(controls_from_forces(*forces, MIXER))


def test_a_saturating_yaw_demand_does_not_starve_lift():
    """Issue finding 7: at mass +30 % a yaw demand clipped two rotors to F_min and U1 fell below the weight.
    Priority allocation keeps U1 and the roll/pitch torques, and gives yaw what is left."""
    weight = 1.3 * PARAMS.m * PARAMS.g                      # 6.2 N of the 10.7 N the rotors can give
    demand = (weight, 0.3, -0.2, -0.2)                      # -0.2 N m: far beyond the yaw authority
    clipped = realised(clip_allocation(*demand, MIXER, F_MIN, F_MAX))
    assert clipped[0] < weight - 0.5                        # the hazard: per-rotor clipping loses lift
    forces = priority_allocation(*demand, MIXER, F_MIN, F_MAX)
    u1, u2, u3, u4 = realised(forces)
    assert all(F_MIN <= f <= F_MAX for f in forces)
    assert u1 == pytest.approx(weight, abs=1e-12)
    assert (u2, u3) == pytest.approx((0.3, -0.2), abs=1e-12)
    assert -0.2 < u4 < 0.0                                  # yaw reduced, same direction
    assert min(forces) == pytest.approx(F_MIN, abs=1e-12) or max(forces) == pytest.approx(F_MAX, abs=1e-12)


def test_a_saturating_roll_demand_is_scaled_with_pitch_and_yaw_goes_first():
    weight = PARAMS.m * PARAMS.g
    room = 2.0 * min(weight / 4 - F_MIN, F_MAX - weight / 4)    # largest |U2| that fits at this U1 without yaw
    forces = priority_allocation(weight, 3.0 * room, 0.5 * room, 0.0, MIXER, F_MIN, F_MAX)
    u1, u2, u3, u4 = realised(forces)
    assert u1 == pytest.approx(weight, abs=1e-12)
    assert (u2, u3) == pytest.approx((room, room / 6.0), abs=1e-12)   # one factor: the torque direction kept
    assert u4 == pytest.approx(0.0, abs=1e-15)                       # no yaw asked, none made
    # with a yaw demand, roll and pitch take what yaw can leave them: more roll, less yaw than asked
    forces = priority_allocation(weight, 3.0 * room, 0.5 * room, 0.01, MIXER, F_MIN, F_MAX)
    u1, u2, u3, u4 = realised(forces)
    assert u1 == pytest.approx(weight, abs=1e-12)
    assert room < u2 < 3.0 * room and u3 == pytest.approx(u2 / 6.0, abs=1e-12)
    assert 0.0 <= u4 < 0.01
    # roll fits alone but not with the whole yaw: roll is served in full, yaw cut
    forces = priority_allocation(weight, 0.8 * room, 0.0, 0.05, MIXER, F_MIN, F_MAX)
    u1, u2, u3, u4 = realised(forces)
    assert (u1, u2, u3) == pytest.approx((weight, 0.8 * room, 0.0), abs=1e-12)
    assert 0.0 < u4 < 0.05


def test_collective_beyond_the_rotors_is_clipped():
    assert priority_allocation(20.0, 0.1, 0.1, 0.001, MIXER, F_MIN, F_MAX) == (F_MAX,) * 4
    assert priority_allocation(-1.0, 0.1, -0.1, 0.001, MIXER, F_MIN, F_MAX) == (F_MIN,) * 4


@pytest.mark.parametrize('seed', range(5))
def test_priority_allocation_properties(seed):
    """For any demand: rotor limits hold; U1 is the demand clipped to [4 F_min, 4 F_max]; (U2, U3) is the
    demand times one factor in [0, 1]; U4 has the demand's sign and at most its size; a demand that
    fits is realised exactly (the inverse of eq. 2)."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        demand = (rng.uniform(-2.0, 13.0), *rng.normal(0.0, 1.5, 2), rng.normal(0.0, 0.03))
        forces = priority_allocation(*demand, MIXER, F_MIN, F_MAX)
        u1, u2, u3, u4 = realised(forces)
        assert all(F_MIN <= f <= F_MAX for f in forces)
        assert u1 == pytest.approx(min(max(demand[0], 4 * F_MIN), 4 * F_MAX), abs=1e-12)
        factor = u2 / demand[1]
        assert -1e-12 <= factor <= 1 + 1e-12 and u3 == pytest.approx(factor * demand[2], abs=1e-12)
        assert u4 * demand[3] >= -1e-15 and abs(u4) <= abs(demand[3]) + 1e-15
        if 0.0 < factor < 1.0 - 1e-9:      # roll/pitch cut: some rotor is at a limit
            assert min(forces) == pytest.approx(F_MIN, abs=1e-12) or max(forces) == pytest.approx(F_MAX, abs=1e-12)
        exact = forces_from_controls(*demand, MIXER)
        if all(F_MIN <= f <= F_MAX for f in exact):
            np.testing.assert_allclose(forces, exact, atol=1e-15)


def test_allocations_work_elementwise_on_arrays():
    rng = np.random.default_rng(3)
    demand = (rng.uniform(-2.0, 13.0, 40), *rng.normal(0.0, 1.5, (2, 40)), rng.normal(0.0, 0.03, 40))
    for allocation in ALLOCATIONS:
        batch = allocate(allocation, *demand, MIXER, F_MIN, F_MAX)
        for i in range(40):
            single = allocate(allocation, *(float(d[i]) for d in demand), MIXER, F_MIN, F_MAX)
            np.testing.assert_allclose([f[i] for f in batch], single, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match='allocation'):
        allocate('scale', 5.0, 0.0, 0.0, 0.0, MIXER, F_MIN, F_MAX)


# ---------------------------------------------------------------- every rotor layout (rotor_layout.py)
ARM = PARAMS.d
LAYOUTS = {
    'plus': PARAMS,
    'x': replace(PARAMS, frame='x'),
    'x, spins mirrored (Crazyflie)': replace(PARAMS, frame='x', rotor_directions=(-1, 1, -1, 1)),
    'custom: wide H frame': replace(PARAMS, frame='custom', rotor_directions=(1, -1, 1, -1), rotor_positions=(
        (0.12, -0.2, 0.02), (-0.12, -0.2, 0.02), (-0.12, 0.2, -0.02), (0.12, 0.2, -0.02))),
    'custom: skewed': replace(PARAMS, frame='custom', rotor_directions=(-1, 1, -1, 1), rotor_positions=(
        (0.2, 0.05, 0.0), (-0.1, -0.22, 0.0), (-0.2, -0.05, 0.0), (0.1, 0.22, 0.0))),
}


def layout_wrench(params, forces):
    """Thrust [N] and torque [N m, body FLU] from first principles: sum r_i x (0, 0, F_i) + the rotors'
    reaction torques -s_i (Kd/Kp) F_i about +z (a counter-clockwise rotor pushes the body clockwise)."""
    torque = sum(np.cross(r, [0.0, 0.0, f]) for r, f in zip(params.rotor_positions, forces))
    reaction = -params.yaw_coefficient * float(np.dot(params.rotor_directions, forces))
    return sum(forces), torque + np.array([0.0, 0.0, reaction])


@pytest.mark.parametrize('layout', LAYOUTS)
def test_eq2_matches_r_cross_f_in_every_layout(layout):
    """d U2 is the roll torque, d U3 the pitch torque and U4 the yaw torque of eq. (1), whatever the layout."""
    params = LAYOUTS[layout]
    for forces in np.random.default_rng(5).uniform(0.0, F_MAX, (20, 4)):
        u1, u2, u3, u4 = controls_from_forces(*forces, params.mixer)
        thrust, torque = layout_wrench(params, forces)
        assert u1 == pytest.approx(thrust, abs=1e-14)
        np.testing.assert_allclose(torque, [ARM * u2, ARM * u3, u4], atol=1e-14)


@pytest.mark.parametrize('layout', LAYOUTS)
def test_mixer_and_inverse_round_trip_in_every_layout(layout):
    mixer = LAYOUTS[layout].mixer
    rng = np.random.default_rng(11)
    for _ in range(50):
        forces = tuple(rng.uniform(-1.0, 4.0, 4))
        np.testing.assert_allclose(forces_from_controls(*controls_from_forces(*forces, mixer), mixer), forces,
                                   atol=1e-12)
        controls = (rng.uniform(0, 10), *rng.uniform(-2, 2, 2), rng.uniform(-0.05, 0.05))
        np.testing.assert_allclose(controls_from_forces(*forces_from_controls(*controls, mixer), mixer), controls,
                                   atol=1e-12)


def test_the_x_frame_puts_its_rotors_on_the_diagonals_at_the_arm_length():
    x = LAYOUTS['x']
    expected = np.array([[1, -1, 0], [-1, -1, 0], [-1, 1, 0], [1, 1, 0]]) * ARM / np.sqrt(2.0)
    np.testing.assert_allclose(x.rotor_positions, expected, atol=1e-15)
    assert x.rotor_names == ('F1_front_right', 'F2_back_right', 'F3_back_left', 'F4_front_left')
    # a pure roll demand d U2 [N m] raises the left rotors (3, 4) and lowers the right ones (1, 2) alike:
    # d U2 = (d / sqrt 2) (F3 + F4 - F1 - F2)
    f1, f2, f3, f4 = forces_from_controls(PARAMS.m * PARAMS.g, 0.2, 0.0, 0.0, x.mixer)
    assert f1 == pytest.approx(f2) and f3 == pytest.approx(f4) and f3 - f1 == pytest.approx(0.2 / np.sqrt(2.0))


@pytest.mark.parametrize('layout', LAYOUTS)
def test_priority_allocation_properties_in_every_layout(layout):
    """As test_priority_allocation_properties, for each layout (the allocation pairs opposite rotors)."""
    params = LAYOUTS[layout]
    mixer = params.mixer
    rng = np.random.default_rng(21)
    for _ in range(300):
        demand = (rng.uniform(-2.0, 13.0), *rng.normal(0.0, 1.5, 2), rng.normal(0.0, 0.03))
        forces = priority_allocation(*demand, mixer, F_MIN, F_MAX)
        u1, u2, u3, u4 = controls_from_forces(*forces, mixer)
        assert all(F_MIN <= f <= F_MAX for f in forces)
        assert u1 == pytest.approx(min(max(demand[0], 4 * F_MIN), 4 * F_MAX), abs=1e-12)
        factor = u2 / demand[1]
        assert -1e-12 <= factor <= 1 + 1e-12 and u3 == pytest.approx(factor * demand[2], abs=1e-12)
        assert u4 * demand[3] >= -1e-15 and abs(u4) <= abs(demand[3]) + 1e-15
        exact = forces_from_controls(*demand, mixer)
        if all(F_MIN <= f <= F_MAX for f in exact):
            np.testing.assert_allclose(forces, exact, atol=1e-15)


def test_airmode_keeps_the_moments_when_the_thrust_asks_for_less_than_they_need():
    """Issue 37: a z loop that asks for no thrust (U1 <= 0) leaves thrust-first allocation no moment at all: every
    rotor at F_min. Airmode keeps the roll, pitch and yaw torques and raises the collective just enough."""
    demand = (-1.0, 0.3, -0.2, 0.002)
    assert priority_allocation(*demand, MIXER, F_MIN, F_MAX) == (F_MIN,) * 4
    forces = allocate('airmode', *demand, MIXER, F_MIN, F_MAX)
    u1, u2, u3, u4 = controls_from_forces(*forces, MIXER)
    assert (u2, u3, u4) == pytest.approx(demand[1:], abs=1e-12)
    assert min(forces) == pytest.approx(F_MIN, abs=1e-12) and all(f <= F_MAX for f in forces)   # the least lift


@pytest.mark.parametrize('layout', LAYOUTS)
def test_airmode_allocation_properties_in_every_layout(layout):
    """For any demand, in every layout: rotor limits hold. When U1 asks for less than the moments need (its mean
    below F_MIN less the lowest differential part of the moments as asked): (U2, U3) is the demand times one factor
    in [0, 1], 1 when the pair torques fit in one rotor's range; U4 has the demand's sign and at most its size; U1
    is the demand raised to the least the realised moments need, below it only where they take a rotor's whole
    range. Otherwise it is the thrust-first allocation, so a demand that fits is realised exactly."""
    params = LAYOUTS[layout]
    mixer = params.mixer
    rng = np.random.default_rng(37)
    raised = 0
    for _ in range(300):
        demand = (rng.uniform(-2.0, 13.0), *rng.normal(0.0, 1.5, 2), rng.normal(0.0, 0.03))
        forces = allocate('airmode', *demand, mixer, F_MIN, F_MAX)
        assert all(F_MIN - 1e-12 <= f <= F_MAX + 1e-12 for f in forces)
        asked = [f - demand[0] / 4 for f in forces_from_controls(*demand, mixer)]   # the differential parts asked
        if demand[0] / 4 >= F_MIN - min(asked):
            assert forces == priority_allocation(*demand, mixer, F_MIN, F_MAX)
            continue
        raised += 1
        u1, u2, u3, u4 = controls_from_forces(*forces, mixer)
        factor = u2 / demand[1]
        assert -1e-12 <= factor <= 1 + 1e-12 and u3 == pytest.approx(factor * demand[2], abs=1e-12)
        t13, t24 = (abs(t) for t in pair_torques(demand[1], demand[2], mixer))
        if max(t13, t24) <= F_MAX - F_MIN:
            assert factor == pytest.approx(1.0, abs=1e-12)
        assert u4 * demand[3] >= -1e-15 and abs(u4) <= abs(demand[3]) + 1e-15
        differential = [f - u1 / 4 for f in forces]
        if u1 < demand[0] - 1e-12:    # lowered only where the moments take a rotor's whole range
            assert max(differential) - min(differential) == pytest.approx(F_MAX - F_MIN, abs=1e-12)
        assert u1 == pytest.approx(min(max(demand[0], 4 * (F_MIN - min(differential))),
                                       4 * (F_MAX - max(differential))), abs=1e-12)
    assert 30 <= raised <= 270      # both branches drawn


def test_airmode_gives_a_heavy_climb_its_thrust_as_thrust_first_does():
    """At the top (the collective asked near the rotors' maximum, moments that do not fit above it) airmode is the
    thrust-first allocation: U1 kept, the moments scaled; it never lowers the thrust for a moment."""
    demand = (4 * F_MAX - 0.05, 0.4, -0.3, 0.001)
    forces = allocate('airmode', *demand, MIXER, F_MIN, F_MAX)
    assert forces == priority_allocation(*demand, MIXER, F_MIN, F_MAX)
    assert controls_from_forces(*forces, MIXER)[0] == pytest.approx(demand[0], abs=1e-12)
