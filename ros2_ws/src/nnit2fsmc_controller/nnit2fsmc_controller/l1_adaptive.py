"""L1 adaptive augmentation of the geometric controller (``l1-se3``): Wu, Cheng, Zhao, Gahlawat,
Ackerman, Lakshmanan, Yang, Yu, Hovakimyan, "L1Quad: L1 adaptive augmentation of geometric control
for agile quadrotors with performance guarantees", arXiv 2302.07208 (2023), section III, with the
piecewise-constant adaptation law of Hovakimyan & Cao, *L1 Adaptive Control Theory* (SIAM 2010),
section 3.3.

The baseline law u_b is the ``se3`` law (:class:`.se3.SE3Controller`) with gains of its own,
``l1_se3.axes`` (the keys of ``se3.axes``: se3 and l1-se3 are tuned apart, docs/TUNING.md). The
uncertainty is lumped, as in L1Quad, into an unknown acceleration sigma_v [m/s^2, world] of the
translational dynamics and an unknown angular acceleration sigma_w [rad/s^2, body] of the
rotational ones (stated per unit of nominal mass and inertia, so the gains carry over between
vehicles). With z = (v, Omega) the measured velocity [m/s, world] and body rates [rad/s, body FLU]:

State predictor (L1Quad sec. III, its state predictor; A_s = -a_v I and -a_w I, Hurwitz):

    v-hat'     = -g e3 + (U1 / m) R e3 + sigma_v-hat - a_v (v-hat - v)
    Omega-hat' = J^-1 (M - Omega x J Omega) + sigma_w-hat - a_w (Omega-hat - Omega)

with the thrust U1 [N] and moment M [N m, body] the rotors were commanded (after the rotor limits:
u_b + u_ad). Over one control period T_s it is integrated exactly with the measurement and the input
held, so with mu = exp(-a T_s) and Phi = (1 - mu) / a (the Phi(T_s) = A_s^-1 (e^{A_s T_s} - I) and
mu(T_s) = e^{A_s T_s} of the book, diagonal here):

    z-hat(k+1) = z(k) + mu (z-hat(k) - z(k)) + Phi (f(z(k), u(k)) + sigma-hat(k))

Piecewise-constant adaptation law (Hovakimyan & Cao sec. 3.3; L1Quad sec. III, its adaptation law):

    sigma-hat(k) = -Phi^-1 mu (z-hat(k) - z(k))

(each component clamped to +-``estimate_limit``, the projection's bound). Matched part: along the
thrust axis sigma_m = (sigma_v-hat . R e3, sigma_w-hat); the horizontal components (R e1, R e2) are
unmatched, estimated but not compensated (as in L1Quad). Low-pass filtered compensation, C(s) =
omega_c / (s + omega_c) discretised exactly (b = 1 - exp(-omega_c T_s)):

    c(k) = c(k-1) + b (sigma_m(k) - c(k-1)),     U1 = U1_b - m c_1,   M = M_b - J (c_2, c_3, c_4)

The rotational channel may cascade a second low-pass, as L1Quad-style implementations do for the moment
(``cutoff_rotation_second_hz`` > 0; 0: one stage): C_w(s) = omega_1 / (s + omega_1) * omega_2 / (s + omega_2),
each stage discretised as above (b_1, b_2):

    r(k) = r(k-1) + b_1 (sigma_w(k) - r(k-1)),   (c_2, c_3, c_4)(k) = c(k-1) + b_2 (r(k) - c(k-1))

Convergence (what tests/test_adaptive_baselines.py checks): on a plant that integrates exactly
v(k+1) = v(k) + T_s (f(k) + d) with a constant unknown d, the error after one step is
z-hat - z = (Phi - T_s) f - T_s d, so from the second step on sigma-hat = (mu T_s / Phi) d +
mu (T_s - Phi) / Phi f(k): the estimate reaches d within the factor a T_s / (exp(a T_s) - 1)
(0.9975 at a = 5 1/s, T_s = 1 ms) in two control steps, and the compensation then follows it with
the filter's time constant 1 / omega_c.

Take-off: below ``takeoff_height`` the ground's reaction is what the predictor would learn (the
vehicle does not fall although the thrust is below its weight); the estimates and the compensation
are held at zero and the predictor at the measurement until the vehicle is above it.

What it measures: the velocity and body rates (no acceleration), and it assumes the commanded
thrust and moment are the ones the rotors produce (a motor lag or a lost rotor is part of sigma).

Memory of one vehicle (a row of :attr:`L1SE3Controller.memory`): MEMORY names its slots.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from quad_msgs_bridge.frames import body_rates_from_euler_rates
from quad_msgs_bridge.validation import check_number

from .se3 import SE3Controller


def memory_slots(layout) -> tuple[dict[str, int], int]:
    """({slot name: its first index}, the memory's length) of a kernel memory laid out as ``layout``:
    (name, size) pairs in order, each slot following the one before it."""
    slots, offset = {}, 0
    for name, size in layout:
        slots[name] = offset
        offset += size
    return slots, offset


#: the slots of one vehicle's L1 memory, in order, and their sizes
MEMORY = (('v_hat', 3), ('omega_hat', 3), ('sigma', 6), ('compensation', 4), ('velocity', 3), ('omega', 3),
          ('thrust_axis', 3), ('thrust_per_mass', 1), ('moment', 3), ('moment_stage', 3), ('started', 1))
SLOT, MEMORY_SIZE = memory_slots(MEMORY)
V_HAT, OMEGA_HAT, SIGMA, COMPENSATION = SLOT['v_hat'], SLOT['omega_hat'], SLOT['sigma'], SLOT['compensation']
VELOCITY, OMEGA, AXIS, THRUST, MOMENT, STARTED = (SLOT['velocity'], SLOT['omega'], SLOT['thrust_axis'],
                                                  SLOT['thrust_per_mass'], SLOT['moment'], SLOT['started'])
STAGE = SLOT['moment_stage']   #: r, the first stage of a cascaded rotational filter [rad/s^2, body]


@njit(cache=True)
def l1_vehicle(memory, measured, held, constants):
    """One vehicle's L1 step at a control instant (module docstring): predict z-hat(k) from the last
    measurement and input, adapt sigma-hat(k) from z-hat(k) - z(k), filter the matched part into the
    compensation ``memory[COMPENSATION:COMPENSATION + 4]`` (c_1 [m/s^2] along R e3, c_2..c_4 [rad/s^2, body]).

    ``measured``: v (3) [m/s, world], Omega (3) [rad/s, body], R e3 (3) now; ``held``: the take-off hold
    (everything back to zero, the predictor to the measurement). ``constants``: (mu_v, Phi_v, mu_w, Phi_w,
    b_v, b_w, g, limit_v, limit_w, Ix, Iy, Iz, b_w2) with b_w2 = 0 for one rotational stage."""
    mu_v, phi_v, mu_w, phi_w, b_v, b_w, g, limit_v, limit_w, ix, iy, iz, b_w2 = constants
    if memory[STARTED] > 0.0 and not held:
        v, w, e3 = memory[VELOCITY:VELOCITY + 3], memory[OMEGA:OMEGA + 3], memory[AXIS:AXIS + 3]
        f = memory[THRUST]
        mx, my, mz = memory[MOMENT], memory[MOMENT + 1], memory[MOMENT + 2]
        # f(z, u): translational and rotational accelerations of the nominal model at the last step
        model_v = (f * e3[0], f * e3[1], f * e3[2] - g)
        model_w = ((mx - (w[1] * iz * w[2] - w[2] * iy * w[1])) / ix,
                   (my - (w[2] * ix * w[0] - w[0] * iz * w[2])) / iy,
                   (mz - (w[0] * iy * w[1] - w[1] * ix * w[0])) / iz)
        for i in range(3):
            memory[V_HAT + i] = v[i] + mu_v * (memory[V_HAT + i] - v[i]) + phi_v * (model_v[i] + memory[SIGMA + i])
            memory[OMEGA_HAT + i] = (w[i] + mu_w * (memory[OMEGA_HAT + i] - w[i])
                                     + phi_w * (model_w[i] + memory[SIGMA + 3 + i]))
        for i in range(3):
            sigma_v = -mu_v / phi_v * (memory[V_HAT + i] - measured[i])
            sigma_w = -mu_w / phi_w * (memory[OMEGA_HAT + i] - measured[3 + i])
            memory[SIGMA + i] = min(max(sigma_v, -limit_v), limit_v)
            memory[SIGMA + 3 + i] = min(max(sigma_w, -limit_w), limit_w)
        matched = (memory[SIGMA] * measured[6] + memory[SIGMA + 1] * measured[7] + memory[SIGMA + 2] * measured[8])
        memory[COMPENSATION] += b_v * (matched - memory[COMPENSATION])
        for i in range(3):
            if b_w2 > 0.0:
                memory[STAGE + i] += b_w * (memory[SIGMA + 3 + i] - memory[STAGE + i])
                memory[COMPENSATION + 1 + i] += b_w2 * (memory[STAGE + i] - memory[COMPENSATION + 1 + i])
            else:
                memory[COMPENSATION + 1 + i] += b_w * (memory[SIGMA + 3 + i] - memory[COMPENSATION + 1 + i])
    else:
        for i in range(3):
            memory[V_HAT + i] = measured[i]
            memory[OMEGA_HAT + i] = measured[3 + i]
        memory[SIGMA:SIGMA + 6] = 0.0
        memory[COMPENSATION:COMPENSATION + 4] = 0.0
        memory[STAGE:STAGE + 3] = 0.0
    memory[VELOCITY:VELOCITY + 3] = measured[0:3]
    memory[OMEGA:OMEGA + 3] = measured[3:6]
    memory[AXIS:AXIS + 3] = measured[6:9]
    memory[STARTED] = 1.0


@njit(cache=True)
def l1_batch(memory, measured, held, constants):
    """:func:`l1_vehicle` for every vehicle of a batch: row b of ``memory`` (B, MEMORY_SIZE) and of
    ``measured`` (B, 9), ``held`` (B,)."""
    for b in range(memory.shape[0]):
        l1_vehicle(memory[b], measured[b], held[b], constants)


def discrete_pole(pole: float, dt: float) -> tuple[float, float]:
    """(mu, Phi) = (exp(-a dt), (1 - exp(-a dt)) / a) of the predictor pole a [1/s] over dt [s]."""
    mu = math.exp(-pole * dt)
    return mu, -math.expm1(-pole * dt) / pole


def filter_blend(cutoff_hz: float, dt: float) -> float:
    """b = 1 - exp(-2 pi cutoff_hz dt): C(s) = w / (s + w) held over dt [s] (exact)."""
    return -math.expm1(-2.0 * math.pi * cutoff_hz * dt)


def per_vehicle_rows(values, count: int) -> np.ndarray:
    """(count, len(values)) array: each value a float (shared) or an array of ``count`` (one per vehicle)."""
    return np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(v, dtype=float), (count,)) for v in values],
                                         axis=1))


class L1SE3Controller(SE3Controller):
    """The ``se3`` law plus the L1 adaptive augmentation of the module docstring.

    ``l1``: predictor poles a_v, a_w [1/s] (``predictor_pole_translation``, ``predictor_pole_rotation``),
    filter cutoffs [Hz] (``cutoff_translation_hz``, ``cutoff_rotation_hz`` and the cascaded rotational
    stage's ``cutoff_rotation_second_hz``, 0: none), estimate bounds
    [m/s^2], [rad/s^2] (``estimate_limit_translation``, ``estimate_limit_rotation``).
    """

    STATE = SE3Controller.STATE + ('memory',)
    GAINS_SECTION = 'l1_se3'   #: ``gains`` are ``l1_se3.axes``: its own se3 law

    def __init__(self, name, params, gains, lam, dt, l1: dict, **structure):
        super().__init__(name, params, gains, lam, dt, **structure)
        pole_v = check_number('l1_se3.predictor_pole_translation', l1['predictor_pole_translation'], 0.0,
                              low_inclusive=False)
        pole_w = check_number('l1_se3.predictor_pole_rotation', l1['predictor_pole_rotation'], 0.0,
                              low_inclusive=False)
        cutoff_v = check_number('l1_se3.cutoff_translation_hz', l1['cutoff_translation_hz'], 0.0)
        cutoff_w = check_number('l1_se3.cutoff_rotation_hz', l1['cutoff_rotation_hz'], 0.0)
        cutoff_w2 = check_number('l1_se3.cutoff_rotation_second_hz', l1['cutoff_rotation_second_hz'], 0.0)
        limit_v = check_number('l1_se3.estimate_limit_translation', l1['estimate_limit_translation'], 0.0)
        limit_w = check_number('l1_se3.estimate_limit_rotation', l1['estimate_limit_rotation'], 0.0)
        p = params
        self.constants = (*discrete_pole(pole_v, self.dt), *discrete_pole(pole_w, self.dt),
                          filter_blend(cutoff_v, self.dt), filter_blend(cutoff_w, self.dt), float(p.g),
                          limit_v, limit_w, float(p.Ix), float(p.Iy), float(p.Iz), filter_blend(cutoff_w2, self.dt))
        #: one row per vehicle (MEMORY); a single vehicle is a batch of one
        self.memory = np.zeros((1 if self.batch is None else self.batch, MEMORY_SIZE))

    @property
    def estimate(self) -> np.ndarray:
        """sigma-hat: (sigma_v [m/s^2, world], sigma_w [rad/s^2, body]), shape (6,) or (B, 6) for a batch."""
        values = self.memory[:, SIGMA:SIGMA + 6]
        return values[0].copy() if self.batch is None else values.copy()

    @property
    def compensation(self) -> np.ndarray:
        """The filtered matched estimate c: (c_1 [m/s^2] along R e3, c_2..c_4 [rad/s^2, body]), (4,) or (B, 4)."""
        values = self.memory[:, COMPENSATION:COMPENSATION + 4]
        return values[0].copy() if self.batch is None else values.copy()

    def compensated(self, state, rotation, thrust, controls, held):
        """U1 - m c_1 and (U2, U3, U4) - J (c_2, c_3, c_4) / (d, d, 1) after this step's L1 update."""
        count = self.memory.shape[0]
        omega = body_rates_from_euler_rates(state[6:9], state[9:12])
        measured = per_vehicle_rows((*state[3:6], *omega, *(row[2] for row in rotation)), count)
        l1_batch(self.memory, measured, np.ascontiguousarray(np.broadcast_to(held, (count,))), self.constants)
        c = self.memory[:, COMPENSATION:COMPENSATION + 4]
        c = c[0] if self.batch is None else c.T
        p = self.params
        u1 = thrust - p.m * c[0]                 # c is 0 while held (l1_vehicle)
        u = tuple(uk - j * ck / s for uk, j, ck, s in zip(controls, (p.Ix, p.Iy, p.Iz), c[1:], (p.d, p.d, 1.0)))
        return (float(u1), tuple(float(v) for v in u)) if self.batch is None else (u1, u)

    def applied(self, state, controls, held) -> None:
        """Keep U1 / m [m/s^2] and M = (d U2, d U3, U4) [N m, body] for the next prediction."""
        p = self.params
        u1, u2, u3, u4 = controls
        rows = self.memory
        rows[:, THRUST] = np.asarray(u1, dtype=float) / p.m
        rows[:, MOMENT] = np.asarray(u2, dtype=float) * p.d
        rows[:, MOMENT + 1] = np.asarray(u3, dtype=float) * p.d
        rows[:, MOMENT + 2] = np.asarray(u4, dtype=float)
