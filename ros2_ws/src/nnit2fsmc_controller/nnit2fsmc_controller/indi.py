"""Incremental nonlinear dynamic inversion (``indi``): the attitude loop of Smeur, Chu and de Croon,
"Adaptive incremental nonlinear dynamic inversion for attitude control of micro air vehicles",
JGCD 39(3), 2016, doi 10.2514/1.G001490, under the acceleration (INDI) outer loop with the
differential-flatness attitude of Tal and Karaman, "Accurate tracking of aggressive quadrotor
trajectories using incremental nonlinear dynamic inversion and differential flatness", IEEE TCST
29(3), 2021, doi 10.1109/TCST.2020.3001117.

Attitude (Smeur et al., sec. II-III). Instead of a model of the moments, INDI measures the angular
acceleration and changes the moment by what the difference to the desired one needs:

    M_c = M_f + G^-1 (alpha_d - alpha_f)                  (their incremental control law, sec. II)

* alpha_f [rad/s^2, body]: the derivative of the body rates Omega after a first-order low-pass
  H(z) (cutoff ``rate_filter_hz``), alpha_f(k) = (Omega_f(k) - Omega_f(k-1)) / T_s;
* M_f [N m, body]: the moment the rotors produced over the last period, from the moment they were
  commanded through their modelled response (first-order, ``motor_time_constant``; 0: they follow
  at once), through the *same* filter H (the synchronisation of Smeur et al.: both sides of the
  increment carry the same lag);
* G = diag(eta_i / J_i): the control effectiveness, the nominal J^-1 times the estimated ratio
  eta (1 on the nominal vehicle), adapted online from the filtered increments (their LMS of the
  adaptive G, sec. III; here per axis and normalised, so that its step ``effectiveness_rate`` mu is a
  fraction in (0, 2)):

      eta_i += mu (dalpha_i - eta_i du_i) du_i / (epsilon^2 + du_i^2),   du_i = dM_f,i / J_i

  with dalpha, dM_f the changes of alpha_f and M_f over one period and epsilon
  (``effectiveness_threshold`` [rad/s^2]) the increment below which it barely moves; eta is kept
  in [``effectiveness_min``, ``effectiveness_max``]. (Smeur et al. adapt the full rotor-to-rate
  matrix and a rotor-inertia term with an unnormalised LMS; the mixer here is known, so only the
  diagonal in moment space is left to learn.)
* alpha_d: the ``se3`` attitude law of the angular acceleration, -k_R e_R - k_W e_W plus the
  feed-forward of the desired body rates (:class:`.se3.SE3Controller`), without the integral (the
  increment integrates) and without the gyroscopic term (measured inside alpha_f).

With the true effectiveness and H on both sides, M_c(k) = J alpha_d(k) - H[d](k) for a moment
disturbance d: a step d is rejected as H's step response rises, the residual after n steps being
(1 - b)^n d with b = w T_s / (1 + w T_s), w = 2 pi rate_filter_hz (tests/test_adaptive_baselines.py).

Position (Tal & Karaman, sec. III-B). The acceleration a_c = xdd_d - k_x e_x - k_v e_v [m/s^2, world]
is realised incrementally too:

    T_c = T_f + m (a_c - a_f)       [N, world]

with a_f the derivative of the low-passed measured velocity and T_f the thrust vector U1 R e3 the
rotors produced: the modelled response of the collective thrust U1 (the rotors lag U1, not the axis)
along the measured thrust axis R e3, through the same filters as the velocity. The velocity reaches
the controller through the measurement stage's low-pass S (``common.velocity_filter_hz``, every kind
reads it) before the acceleration filter H (cutoff ``acceleration_filter_hz``), so T_f passes through
S and H both: a force step d is rejected as the step response s of the cascade S H rises, the part
left after n steps being d (1 - s(n - 1)) (tests/test_adaptive_baselines.py). T_c then sets
the thrust axis and the collective thrust as in ``se3`` (tilt limit, minimum lift), and the desired
attitude is its flat attitude with the reference yaw. The desired body rates and their derivative come
from ``common.attitude_rates``, the key every kind reads: with ``filter``, two filtered derivatives of the
desired attitude (:class:`.se3.SE3Controller`); with ``flatness``, those of the reference's flat attitude
alone (its acceleration, jerk, snap and yaw motion; Tal & Karaman sec. III). Unlike the other kinds'
``flatness``, no filtered derivative of the feedback's part is added: that part holds a_f, so its
derivative would put the second derivative of the velocity noise into the desired rates (measured: the
packaged indi then lost the x500 in tests/test_vehicles.py).

What it measures: body rates and velocity (it differentiates both: the odometry here carries no
accelerometer, so its alpha_f and a_f are filtered derivatives, with noise amplified by the
derivative); it assumes the rotors' response is the modelled one and that the moment and force it
does not model change slowly against the filter.

Take-off: below ``takeoff_height`` the ground holds the vehicle (alpha_f = a_f = 0 whatever the
command), which an increment would wind up; there the commands are the nominal inversions
J alpha_d + Omega x J Omega and m (a_c + g e3), the effectiveness does not adapt, and the
filters follow what the rotors were commanded.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from quad_msgs_bridge.frames import body_rates_from_euler_rates, rotation_from_euler
from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.validation import check_number

from .controller import flat_attitude_of
from .l1_adaptive import memory_slots, per_vehicle_rows
from .se3 import SE3Controller

#: the slots of one vehicle's INDI memory, in order, and their sizes
MEMORY = (('omega_f', 3), ('alpha_f', 3), ('moment_f', 3), ('moment_model', 3), ('eta', 3), ('velocity_f', 3),
          ('acceleration_f', 3), ('thrust_stage', 3), ('thrust_f', 3), ('thrust_model', 1), ('moment_command', 3),
          ('thrust_command', 1), ('started', 1))
SLOT, MEMORY_SIZE = memory_slots(MEMORY)
(OMEGA_F, ALPHA_F, MOMENT_F, MOMENT_MODEL, ETA, VELOCITY_F, ACCELERATION_F, THRUST_STAGE, THRUST_F, THRUST_MODEL,
 MOMENT_COMMAND, THRUST_COMMAND, STARTED) = (SLOT[name] for name, _ in MEMORY)


@njit(cache=True)
def indi_vehicle(memory, measured, held, constants):
    """One vehicle's INDI measurements at a control instant (module docstring): the modelled rotor response
    to the last command, the filtered body rates and their derivative alpha_f, the filtered modelled
    moment M_f, the effectiveness step (unless ``held``), the filtered velocity and its derivative a_f, the
    filtered modelled thrust vector T_f (the modelled collective thrust along the measured thrust axis, through
    the measurement stage's velocity filter and the acceleration filter, as the velocity is).
    ``measured``: v (3) [m/s, world], Omega (3) [rad/s, body], the thrust axis R e3 (3) [world].
    ``constants``: (b_rate, b_acceleration, b_stage, motor_blend, T_s, mu, epsilon, eta_min, eta_max, Ix, Iy, Iz),
    b_stage the blend of the measurement stage's velocity filter (1: none)."""
    b_r, b_a, b_v, motor, dt, mu, eps, eta_min, eta_max, ix, iy, iz = constants
    if memory[STARTED] == 0.0:
        for i in range(3):
            memory[OMEGA_F + i] = measured[3 + i]
            memory[VELOCITY_F + i] = measured[i]
        memory[STARTED] = 1.0
        return
    inertia = (ix, iy, iz)
    memory[THRUST_MODEL] += motor * (memory[THRUST_COMMAND] - memory[THRUST_MODEL])
    for i in range(3):
        memory[MOMENT_MODEL + i] += motor * (memory[MOMENT_COMMAND + i] - memory[MOMENT_MODEL + i])
        omega_f = memory[OMEGA_F + i] + b_r * (measured[3 + i] - memory[OMEGA_F + i])
        alpha_f = (omega_f - memory[OMEGA_F + i]) / dt
        moment_f = memory[MOMENT_F + i] + b_r * (memory[MOMENT_MODEL + i] - memory[MOMENT_F + i])
        if not held and mu > 0.0:
            du = (moment_f - memory[MOMENT_F + i]) / inertia[i]
            dalpha = alpha_f - memory[ALPHA_F + i]
            eta = memory[ETA + i] + mu * (dalpha - memory[ETA + i] * du) * du / (eps * eps + du * du)
            memory[ETA + i] = min(max(eta, eta_min), eta_max)
        memory[OMEGA_F + i], memory[ALPHA_F + i], memory[MOMENT_F + i] = omega_f, alpha_f, moment_f
        velocity_f = memory[VELOCITY_F + i] + b_a * (measured[i] - memory[VELOCITY_F + i])
        memory[ACCELERATION_F + i] = (velocity_f - memory[VELOCITY_F + i]) / dt
        memory[VELOCITY_F + i] = velocity_f
        memory[THRUST_STAGE + i] += b_v * (memory[THRUST_MODEL] * measured[6 + i] - memory[THRUST_STAGE + i])
        memory[THRUST_F + i] += b_a * (memory[THRUST_STAGE + i] - memory[THRUST_F + i])


@njit(cache=True)
def indi_batch(memory, measured, held, constants):
    """:func:`indi_vehicle` for every vehicle of a batch: row b of ``memory`` (B, MEMORY_SIZE) and of
    ``measured`` (B, 9), ``held`` (B,)."""
    for b in range(memory.shape[0]):
        indi_vehicle(memory[b], measured[b], held[b], constants)


def first_order_blend(cutoff_hz: float, dt: float) -> float:
    """b = w dt / (1 + w dt), w = 2 pi cutoff_hz: the discrete first-order low-pass of the measurement stage."""
    omega = 2.0 * math.pi * cutoff_hz
    return omega * dt / (1.0 + omega * dt)


class INDIController(SE3Controller):
    """INDI attitude and acceleration loops (module docstring) in the structure of :class:`.se3.SE3Controller`.

    ``gains[axis]`` = (k_error, k_rate) per axis: x, y, z k_x [1/s^2], k_v [1/s]; phi, theta, psi
    k_R [1/s^2], k_W [1/s] (accelerations: per unit of mass and inertia). ``indi``: the filter cutoffs
    ``rate_filter_hz``, ``acceleration_filter_hz`` [Hz], ``motor_time_constant`` [s], ``effectiveness_rate``
    mu [-], ``effectiveness_threshold`` epsilon [rad/s^2], ``effectiveness_min``, ``effectiveness_max`` [-].
    ``velocity_filter_hz`` [Hz]: the cutoff of the measurement stage's velocity filter the controller reads
    through (``common.velocity_filter_hz``; 0: none), applied to the modelled thrust vector as well.
    """

    STATE = SE3Controller.STATE + ('memory',)

    def __init__(self, name, params, gains, lam, dt, indi: dict, velocity_filter_hz: float, **structure):
        super().__init__(name, params, {axis: (*gains[axis], 0.0, 0.0) for axis in gains}, lam, dt, **structure)
        rate_hz = check_number('indi.rate_filter_hz', indi['rate_filter_hz'], 0.0, low_inclusive=False)
        acceleration_hz = check_number('indi.acceleration_filter_hz', indi['acceleration_filter_hz'], 0.0,
                                       low_inclusive=False)
        tau = check_number('indi.motor_time_constant', indi['motor_time_constant'], 0.0)
        mu = check_number('indi.effectiveness_rate', indi['effectiveness_rate'], 0.0, 2.0, high_inclusive=False)
        eps = check_number('indi.effectiveness_threshold', indi['effectiveness_threshold'], 0.0, low_inclusive=False)
        eta_min = check_number('indi.effectiveness_min', indi['effectiveness_min'], 0.0, 1.0, low_inclusive=False)
        eta_max = check_number('indi.effectiveness_max', indi['effectiveness_max'], 1.0)
        p = params
        self.rate_blend = first_order_blend(rate_hz, self.dt)
        stage_hz = check_number('common.velocity_filter_hz', velocity_filter_hz, 0.0)
        self.constants = (self.rate_blend, first_order_blend(acceleration_hz, self.dt),
                          first_order_blend(stage_hz, self.dt) if stage_hz > 0.0 else 1.0,
                          1.0 if tau == 0.0 else -math.expm1(-self.dt / tau), self.dt, mu, eps, eta_min, eta_max,
                          float(p.Ix), float(p.Iy), float(p.Iz))
        count = 1 if self.batch is None else self.batch
        #: one row per vehicle (MEMORY); a single vehicle is a batch of one
        self.memory = np.zeros((count, MEMORY_SIZE))
        self.memory[:, ETA:ETA + 3] = 1.0
        hover = (0.0, 0.0, float(p.m * p.g))    # before the first command: the rotors hold the nominal weight
        for slot in (THRUST_STAGE, THRUST_F):
            self.memory[:, slot:slot + 3] = hover
        self.memory[:, THRUST_MODEL] = self.memory[:, THRUST_COMMAND] = p.m * p.g

    def _values(self, slot: int) -> tuple:
        """The three values at ``slot`` of every vehicle: floats for one vehicle, arrays for a batch."""
        block = self.memory[:, slot:slot + 3]
        return tuple(float(v) for v in block[0]) if self.batch is None else tuple(block.T.copy())

    @property
    def effectiveness(self):
        """eta: the estimated effectiveness / nominal per body axis, (3,) or (B, 3) for a batch."""
        values = self.memory[:, ETA:ETA + 3]
        return values[0].copy() if self.batch is None else values.copy()

    def desired_force(self, state, reference, acceleration, held) -> list:
        """T_c = T_f + m (a_c - a_f) [N, world] after this step's measurements; m (a_c + g e3) while held."""
        count = self.memory.shape[0]
        omega = body_rates_from_euler_rates(state[6:9], state[9:12])
        axis = [row[2] for row in rotation_from_euler(*state[6:9])]
        indi_batch(self.memory, per_vehicle_rows((*state[3:6], *omega, *axis), count),
                   np.ascontiguousarray(np.broadcast_to(held, (count,))), self.constants)
        p = self.params
        xp = namespace_for(*state)
        commanded = [fb + acc for fb, acc in zip(acceleration, reference.acceleration)]
        model = [p.m * a for a in commanded]
        model[2] = model[2] + p.m * p.g
        incremental = [t + p.m * (a - af) for t, a, af in zip(self._values(THRUST_F), commanded,
                                                                self._values(ACCELERATION_F))]
        return [xp.where(held, m, i) for m, i in zip(model, incremental)]

    def desired_attitude_rates(self, phi_d, theta_d, reference, z) -> tuple:
        """(dphi_d, ddphi_d, dtheta_d, ddtheta_d) [rad/s, rad/s^2] by ``attitude_rates``: with ``flatness`` those of the
        reference's flat attitude alone (module docstring), with ``filter`` the filtered derivatives of phi_d,
        theta_d [rad] (:meth:`.se3.SE3Controller.desired_attitude_rates`)."""
        if self.attitude_rates != 'flatness':
            return super().desired_attitude_rates(phi_d, theta_d, reference, z)
        (ax, ay, _), (jx, jy, _), (sx, sy, _) = reference.acceleration, reference.jerk, reference.snap
        _, dphi, ddphi, _, dtheta, ddtheta = flat_attitude_of(ax, ay, jx, jy, sx, sy, reference.yaw, reference.yaw_rate,
                                                              reference.yaw_acceleration, z, self.params.g,
                                                              self.tilt_limit.kernel_parameters)
        return dphi, ddphi, dtheta, ddtheta

    def moment(self, state, angular_acceleration, gyroscopic, held):
        """M_c = M_f + J / eta (alpha_d - alpha_f) [N m, body]; J alpha_d + Omega x J Omega while held."""
        xp = namespace_for(*state)
        p = self.params
        inertia = (p.Ix, p.Iy, p.Iz)
        return tuple(xp.where(held, j * a + g, mf + j / eta * (a - af)) for j, a, g, mf, eta, af in zip(
            inertia, angular_acceleration, gyroscopic, self._values(MOMENT_F), self._values(ETA),
            self._values(ALPHA_F)))

    def applied(self, state, controls, held) -> None:
        """Keep the commanded moment (d U2, d U3, U4) [N m, body] and collective thrust U1 [N] for the
        modelled rotor response of the next step (the rotors lag U1; the thrust axis is measured then)."""
        p = self.params
        u1, u2, u3, u4 = (np.asarray(u, dtype=float) for u in controls)
        rows = self.memory
        for i, value in enumerate((u2 * p.d, u3 * p.d, u4)):
            rows[:, MOMENT_COMMAND + i] = value
        rows[:, THRUST_COMMAND] = u1
