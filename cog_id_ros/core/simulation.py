"""Simulation: eq. (7) integrated in time, the loops closed at every stage.

The state is the positions z and rates zdot of the ``dof`` primary actuators (the
independent coordinates, mechanism.primary); every other joint is solved from the closure
whenever the mechanism is evaluated, never integrated. One step of length h with the efforts
tau held over it (zero-order hold, as a motor driver applies a command) is the classic
fourth-order Runge-Kutta rule on (z, zdot):

    a(z, zdot)  = zddot: close the loops at z (sample_solve.py), then forward dynamics
                  (forward_dynamics.py) with the rates V_a zdot and the efforts tau
    k1 = a(z, zd)
    k2 = a(z + h/2 zd,    zd + h/2 k1)
    k3 = a(z + h/2 zd2,   zd + h/2 k2)             zd2 = zd + h/2 k1
    k4 = a(z + h zd3,     zd + h k3)               zd3 = zd + h/2 k2
    z'  = z  + h/6 (zd + 2 zd2 + 2 zd3 + zd4)      zd4 = zd + h k3
    zd' = zd + h/6 (k1 + 2 k2 + 2 k3 + k4)

and the pose at z' is closed again, so the loops stay closed to closure_tolerance at every
step whatever the number of steps. The accelerations of the last evaluation are kept with
their efforts: a step with the same efforts as the last one starts from them. With compiled
kernels the step is first tried in C (native_simulation.py: the same operations, so the
same numbers), which leaves to this one what it does not do (continuation, errors).
"""
from typing import Any, Callable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import spatial as sp
from .continuation import joint_step_limits
from .errors import (
    ClosureError,
    CogIdError,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
)
from .forward_dynamics import INERTIA_CONDITION_LIMIT
from .forward_solve import LABELS, ForwardSolver, State
from .inputs import setpoints
from .joint_motion import active_velocity_map, combine
from .kernels import ForwardRecord, kernels_for
from .mechanism import Mechanism
from .native_simulation import step_config

#: InverseDynamics.continuation_step: the solver follows the branch in steps of this
CONTINUATION_STEP = 0.1
#: rad (a length as its joint's kind shares it, continuation.joint_step_limits): the most
#: any joint may move in one time step. A step that moves one further is refused: RK4 does
#: not follow such a motion (near a singular pose the accelerations in actuator coordinates
#: have no bound), and a revolute joint that turns more than pi in a step is ambiguous to
#: the closure's 2 pi continuity
MAX_STEP_MOTION = 0.5


class Simulation:
    """A closed-link mechanism moved by the efforts of its active joints (docs/simulation.md).

    ``time_step`` (s): the length of one :meth:`step`. ``backend``: the kernels, as for
    InverseDynamics ('auto', 'native', 'python', 'reference'). All arrays are in
    ``mechanism.active_joints`` order, except :meth:`joint_positions` and
    :meth:`joint_velocities` (``mechanism.joints`` order).
    """

    # the state (set by _set): the pose, the primary rates, the time in steps, the primary
    # positions, the active rates, the closure residual, the last efforts and accelerations
    _state: State
    _zd: List[float]
    _steps: int
    _z: List[float]
    _rates: List[float]
    _residual: float
    _last: Tuple[List[float], List[float]]

    def __init__(self, mechanism: Mechanism, time_step: float = 0.001,
                 backend: str = 'auto') -> None:
        if not isinstance(mechanism, Mechanism):
            raise MechanismConfigError(
                'mechanism', f'must be a cog_id_ros.Mechanism (from Mechanism.from_params_file '
                             f'or from_parameters), got {type(mechanism).__name__}')
        if isinstance(time_step, bool) or not isinstance(time_step, (int, float)) or \
                not 0.0 < time_step <= 1.0:
            raise MechanismConfigError('time_step', f'must be a number of seconds in (0, 1], '
                                                    f'got {time_step!r}')
        self.mechanism = mechanism
        self.time_step = float(time_step)
        self._solved = solved = mechanism.solver_mechanism
        kernels = kernels_for(solved, backend)
        self._backend = kernels.name
        self._forward = ForwardSolver(solved, kernels, CONTINUATION_STEP, mechanism.joints_at)
        self._step_limits = joint_step_limits(solved, MAX_STEP_MOTION)
        self._pairs = solved.primary_pairs          # (active index, joint index) per primary
        serial = self._forward.serial
        #: the step in C (compiled kernels only) and its constants
        self._native: Optional[Callable[..., Any]] = self._forward.kernels.rk4_step
        self._config = step_config(self.time_step, solved, INERTIA_CONDITION_LIMIT,
                                   serial.limits, serial.bounds)
        self.reset()

    # --- state --------------------------------------------------------------------------

    @property
    def backend(self) -> str:
        """The kernels this simulation uses: 'native', 'python' or 'reference'."""
        return self._backend

    @property
    def time(self) -> float:
        """Simulated time (s) since the last :meth:`reset`."""
        return self._steps * self.time_step

    @property
    def positions(self) -> np.ndarray:
        """Active-joint positions (M,) at :attr:`time`."""
        q = self._state[0]
        return np.array([q[j] for j in self._solved.active_index])

    @property
    def velocities(self) -> np.ndarray:
        """Active-joint velocities (M,) at :attr:`time`."""
        return np.array(self._rates)

    @property
    def accelerations(self) -> np.ndarray:
        """Active-joint accelerations (M,) the last efforts produce at :attr:`time` (zeros
        before the first step)."""
        return np.array(self._last[1])

    @property
    def closure_residual(self) -> float:
        """The largest closure equation residual (m or rad) of the pose at :attr:`time`."""
        return float(self._residual)

    def joint_positions(self) -> np.ndarray:
        """Every joint's position, ``mechanism.joints`` order, at :attr:`time`."""
        return self.mechanism.joints_at(self._state[0])[0]

    def joint_velocities(self) -> np.ndarray:
        """Every joint's velocity, ``mechanism.joints`` order, at :attr:`time`."""
        rates = self.mechanism.joints_at(self._state[0], self._joint_rates(self._state,
                                                                           self._zd))[1]
        assert rates is not None
        return rates

    # --- moving -------------------------------------------------------------------------

    def reset(self, positions: Optional[Sequence[float]] = None,
              velocities: Optional[Sequence[float]] = None) -> None:
        """Start again at time 0 from ``positions`` (default: initial_positions) and
        ``velocities`` (default: at rest), active joints. The pose is solved as torques
        solves it from the assembled initial_positions (a redundant mechanism's positions
        must be consistent, its velocities are projected as torques projects them)."""
        m, serial = self._solved, self._forward.serial
        start = list(m.assembled_coordinates)
        zeros = [0.0] * len(m.active_joints)
        record: Any
        q, record, _, _ = serial.close(start, [start[j] for j in m.active_index], zeros, zeros)
        state: State = (list(q), serial.basis(record))
        zd = [0.0] * len(self._pairs)
        if positions is not None or velocities is not None:
            q = [q[j] for j in m.active_index] if positions is None else positions
            q, qd, _, single = setpoints(m, serial.wrapping, q, velocities, None,
                                         labels=('positions', 'velocities', 'tau'))
            if not single:
                raise SetpointError(f'reset takes one sample (one number per active joint), '
                                    f'got shape {np.shape(q)}')
            record, state = self._forward.one(state, q, qd, zeros)
            zd = self._active_to_primary(state, qd)
            if m.is_redundant:
                record = self._forward.again(state, self._primary_to_active(state, zd), zeros)
        else:
            record = self._forward.again(state, zeros, zeros)
        self._set(state, record.accelerations, record.worst, zd, zeros, 0)

    def step(self, tau: Union[Sequence[float], np.ndarray]) -> None:
        """Advance :attr:`time` by one time step with the efforts ``tau`` (active joints,
        N m or N) held over it. A singular or unreachable pose on the way raises (the
        state stays at the last step: :meth:`reset` to go on), the error naming the time
        and the joints; so do efforts that are not one finite number per active joint."""
        m = self._solved
        zeros = [0.0] * len(m.active_joints)
        _, _, checked, single = setpoints(m, (), zeros, zeros, tau, limits=False,
                                          labels=LABELS)
        if not single:
            raise SetpointError(f'step takes one sample of efforts (one number per active '
                                f'joint), got shape {np.shape(checked)}')
        efforts = list(checked)
        before = (self._state, self._zd, self._steps, self._z, self._rates, self._residual,
                  self._last)
        try:
            if not self._native_step(efforts):
                self._rk4(efforts)
            self._check_motion(before[0][0])
        except CogIdError as exc:
            (self._state, self._zd, self._steps, self._z, self._rates, self._residual,
             self._last) = before
            raise self._stopped(exc) from None

    def _check_motion(self, q: Sequence[float]) -> None:
        """ClosureError ('unreachable') where the step just taken from the coordinates ``q``
        moved a joint further than MAX_STEP_MOTION, or to a number that is not finite."""
        m = self._solved
        for j, (a, b, limit) in enumerate(zip(q, self._state[0], self._step_limits)):
            moved = abs(float(b) - float(a))
            if not moved <= limit:
                name = m.model.coordinate_joints[j]
                raise ClosureError(
                    f'{name} would move by {moved:.3g} in one step of {self.time_step:g} s, '
                    f'more than the {limit:.3g} a step can follow: the motion is too fast for '
                    f'the time step: near a singular pose (the accelerations have no bound '
                    f'there, and a shorter time_step only stops it later) or under efforts '
                    f'too large (a shorter time_step follows those); the state stays at the '
                    f'last step', moved, reason='unreachable')

    def _native_step(self, tau: List[float]) -> bool:
        """The step in C (native_simulation.py); False where it leaves it to :meth:`_rk4`
        (or there are no compiled kernels)."""
        if self._native is None:
            return False
        k1 = self._primary(self._last[1]) if self._last[0] == tau else None
        q, basis = self._state
        out = self._native(q, basis, self._zd, tau, k1, self._config)
        if out is None:
            return False
        q, basis, zd, accelerations, worst = out
        self._set((q, basis), accelerations, worst, zd, tau, self._steps + 1)
        return True

    def _rk4(self, tau: List[float]) -> None:
        h, state, z, zd = self.time_step, self._state, self._z, self._zd
        if self._last[0] == tau:
            k1 = self._primary(self._last[1])
        else:
            k1 = self._primary(self._forward.again(state, self._rates, tau).accelerations)
        zd2 = [v + 0.5 * h * a for v, a in zip(zd, k1)]
        k2 = self._primary(self._evaluate(state, _moved(z, zd, 0.5 * h), zd2, tau)[0]
                           .accelerations)
        zd3 = [v + 0.5 * h * a for v, a in zip(zd, k2)]
        k3 = self._primary(self._evaluate(state, _moved(z, zd2, 0.5 * h), zd3, tau)[0]
                           .accelerations)
        zd4 = [v + h * a for v, a in zip(zd, k3)]
        k4 = self._primary(self._evaluate(state, _moved(z, zd3, h), zd4, tau)[0]
                           .accelerations)
        sixth = h / 6.0
        z_new = [x + sixth * (a + 2.0 * b + 2.0 * c + d)
                 for x, a, b, c, d in zip(z, zd, zd2, zd3, zd4)]
        zd_new = [v + sixth * (a + 2.0 * b + 2.0 * c + d)
                  for v, a, b, c, d in zip(zd, k1, k2, k3, k4)]
        record, new_state = self._evaluate(state, z_new, zd_new, tau)
        self._set(new_state, record.accelerations, record.worst, zd_new, tau, self._steps + 1)

    def _evaluate(self, state: State, z: List[float], zd: List[float], tau: List[float]
                  ) -> Tuple[ForwardRecord, State]:
        """(ForwardRecord, state) at the primary positions z and rates zd: the loops closed
        from ``state``, then forward dynamics with the rates of the active joints there."""
        q = state[0]
        target = [q[j] for j in self._solved.active_index]
        for (a, _), x in zip(self._pairs, z):
            target[a] = x
        if not self._solved.is_redundant:
            qd = [0.0] * len(target)
            for (a, _), v in zip(self._pairs, zd):
                qd[a] = v
            return self._forward.one(state, target, qd, tau, project=False)
        # redundant: the active rates V_a zd need the basis at the closed pose
        _, new_state = self._forward.one(state, target, self._primary_to_active(state, zd),
                                         tau, project=False)
        return self._forward.again(new_state, self._primary_to_active(new_state, zd),
                                   tau), new_state

    # --- helpers ------------------------------------------------------------------------

    def _set(self, state: State, accelerations: Sequence[float], residual: float,
             zd: Sequence[float], tau: List[float], steps: int) -> None:
        """The state after a step (or a reset): the pose, the primary rates, the time in
        steps; the accelerations there with the efforts ``tau`` and the closure residual."""
        self._state, self._zd, self._steps = state, list(zd), steps
        self._z = [state[0][j] for _, j in self._pairs]
        self._rates = self._primary_to_active(state, self._zd)
        self._residual = residual
        self._last = (list(tau), list(accelerations))

    def _primary(self, accelerations: Sequence[float]) -> List[float]:
        """The primary actuators' entries of an active-joint vector."""
        return [accelerations[a] for a, _ in self._pairs]

    def _primary_to_active(self, state: State, zd: Sequence[float]) -> List[float]:
        """V_a zd: the active joints' rates of the primary rates zd at the pose ``state``."""
        basis = state[1]
        return [sum(b * v for b, v in zip(basis[j], zd)) for j in self._solved.active_index]

    def _active_to_primary(self, state: State, qd: Sequence[float]) -> List[float]:
        """The primary rates of active rates qd (projected as torques projects them)."""
        rates = combine(active_velocity_map(self._solved, state[1], sp.ScalarOps), qd)
        return [rates[j] for _, j in self._pairs]

    def _joint_rates(self, state: State, zd: Sequence[float]) -> List[float]:
        """V zd: every coordinate's rate."""
        return [sum(b * v for b, v in zip(row, zd)) for row in state[1]]

    def _stopped(self, exc: CogIdError) -> CogIdError:
        """``exc`` said again with the time it happened at and the joints involved."""
        m = self._solved
        where = ', '.join(f'{name} = {x:.6g}' for name, x in
                          zip(m.active_joints, self.positions))
        rows = [(max(map(abs, self._state[1][j])), j) for j in range(len(m.joints))
                if j not in set(m.primary_joints)]
        fastest = m.joints[max(rows)[1]] if rows else None
        joint = f'; the passive joint moving fastest there: {fastest}' if fastest else ''
        why = str(exc)
        if getattr(exc, 'reason', None) == 'unreachable' and ' would move by ' not in why:
            why = ('the pose of the next step cannot be reached on the assembly branch: a '
                   'singular pose or dead centre on the way, or a motion too fast for the time '
                   'step (a shorter time_step follows it closer)')
        message = (f'simulation stopped at t = {self.time + self.time_step:.6g} s (the step '
                   f'from t = {self.time:.6g} s, where {where}{joint}): {why}')
        if isinstance(exc, SingularConfigurationError):
            new: CogIdError = SingularConfigurationError(message, exc.condition_number)
        elif isinstance(exc, ClosureError):
            new = ClosureError(message, exc.residual, reason=exc.reason or 'closure')
        elif isinstance(exc, SetpointError):
            new = SetpointError(message, reason=exc.reason or 'malformed')
        else:
            return exc
        new.time, new.joint = self.time, fastest        # type: ignore[attr-defined]
        return new


def _moved(z: List[float], rates: List[float], dt: float) -> List[float]:
    return [x + dt * v for x, v in zip(z, rates)]
