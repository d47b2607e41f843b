"""Actuation between the controller's forces and the rotors: a transport delay and a motor lag.

Closed-loop order, per control step: the controller computes rotor forces F1..F4 [N] ->
:class:`TransportDelay` (k whole control steps later) -> for each physics step: :class:`MotorLag`
-> :meth:`quad_sim.model.QuadrotorModel.step` (clips to the rotor range, then the true rotors).
Both work on one vehicle (four floats) and on a batch (four arrays of shape (B,)).
"""
from __future__ import annotations

from collections import deque
from typing import Sequence

import numpy as np

from quad_msgs_bridge.numeric import namespace_for
from quad_msgs_bridge.validation import ParameterError, check_number, check_values

#: |delay / control step - k| above which a delay is not a whole number k of control steps.
WHOLE_STEPS_TOLERANCE = 1e-6


class TransportDelay:
    """A FIFO of ``steps`` control steps: the forces applied at step n are those computed at step n - k.

    The first k calls return zero thrust (k control steps with the motors off: a vehicle that
    starts on the ground stays there). k = 0 returns the forces themselves. ``steps`` is one whole
    number for every vehicle, or (a batch) an integer array of one k per vehicle.
    """

    def __init__(self, steps):
        if isinstance(steps, np.ndarray):
            if steps.ndim != 1 or steps.dtype.kind not in 'iu' or (steps < 0).any():
                raise ParameterError(f'delay_steps: expected whole numbers of control steps >= 0, one per vehicle, '
                                     f'got {steps!r}')
        elif isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
            raise ParameterError(f'delay_steps: expected a whole number of control steps >= 0, got {steps!r}')
        self.steps = steps
        self._queue: deque = deque()

    @classmethod
    def from_seconds(cls, delay: float, control_dt: float) -> 'TransportDelay':
        """The delay of ``delay`` [s] at a control step of ``control_dt`` [s]; refused unless it is a
        whole number of control steps (a transport delay here is a queue of control steps)."""
        delay = check_number('delay_s', delay, 0.0)
        control_dt = check_number('control_dt', control_dt, 0.0, low_inclusive=False)
        steps = round(delay / control_dt)
        if abs(delay / control_dt - steps) > WHOLE_STEPS_TOLERANCE:
            below = int(delay / control_dt)
            raise ParameterError(
                f'delay_s: {delay} s is not a whole number of control steps of {control_dt} s '
                f'(nearest: {below} steps = {below * control_dt:g} s or '
                f'{below + 1} steps = {(below + 1) * control_dt:g} s)')
        return cls(steps)

    def __call__(self, forces: Sequence) -> tuple:
        """Push the forces [N] computed at this control step; return those to apply now."""
        if isinstance(self.steps, np.ndarray):
            return self._per_vehicle(forces)
        xp = namespace_for(forces[0])
        if not self._queue:
            self._queue.extend([tuple(xp.zeros_like(f) for f in forces)] * self.steps)
        self._queue.append(tuple(xp.copy(f) for f in forces))
        return self._queue.popleft()

    def _per_vehicle(self, forces: Sequence) -> tuple:
        """Vehicle v's forces of ``steps[v]`` control steps ago (zero thrust before its first)."""
        deepest = int(self.steps.max())
        if not self._queue:
            self._queue.extend([tuple(np.zeros_like(f) for f in forces)] * deepest)
        self._queue.append(tuple(np.array(f, dtype=float) for f in forces))
        vehicles = np.arange(len(self.steps))
        rows = len(self._queue) - 1 - self.steps         # the queue's row each vehicle reads
        applied = tuple(np.stack([entry[i] for entry in self._queue])[rows, vehicles] for i in range(len(forces)))
        self._queue.popleft()
        return applied


class MotorLag:
    """First-order lag of each rotor thrust, dT/dt = (F - T) / tau, F the command [N] held over a step.

    Exact under the held command (zero-order hold): T(t_k + dt) = F + (T(t_k) - F) e^(-dt/tau).
    :meth:`step` returns the thrust to hold over the physics step, the exact mean of T over it,
    F + (T(t_k) - F) (tau/dt) (1 - e^(-dt/tau)), so each rotor's impulse over the step is exact;
    :attr:`thrusts` is T at the physics instants. ``time_constant`` tau [s] >= 0 (a float or one
    per vehicle); tau = 0 is no lag. The rotors start at zero thrust (motors off).
    Commands are expected inside the rotor range (a controller saturates its output), so the lagged
    thrust stays inside it too.
    """

    def __init__(self, time_constant, dt: float):
        tau = check_values('motor_time_constant_s', time_constant, 0.0)
        dt = check_number('dt', dt, 0.0, low_inclusive=False)
        xp = namespace_for(tau)
        lagging = tau > 0.0
        ratio = dt / xp.where(lagging, tau, 1.0)
        self.decay = xp.where(lagging, xp.exp(-ratio), 0.0)
        self.mean_weight = xp.where(lagging, -xp.expm1(-ratio) / ratio, 0.0)
        self.thrusts = None

    def step(self, commanded: Sequence) -> tuple:
        """Advance the rotors by one physics step under ``commanded`` F1..F4 [N]; the thrusts to hold."""
        if self.thrusts is None:
            xp = namespace_for(commanded[0])
            self.thrusts = tuple(xp.zeros_like(f) for f in commanded)
        held = tuple(f + (t - f) * self.mean_weight for f, t in zip(commanded, self.thrusts))
        self.thrusts = tuple(f + (t - f) * self.decay for f, t in zip(commanded, self.thrusts))
        return held
