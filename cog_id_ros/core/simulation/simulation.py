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
step whatever the number of steps. The accelerations there, k5 = a(z', zd'), are the next
step's k1 (with the same efforts), and with k4 they make the step's error estimate
(simulation_error.py). A published step (one :meth:`Simulation.step`) whose estimate exceeds
the tolerance, or whose stages fail, is taken in parts (a third and two thirds), each
divided again where it needs it, down to SHORTEST_SUBSTEP of a step; every substep holds
the same efforts. With
compiled kernels each substep is first tried in C (native_simulation.py: the same
operations, so the same numbers), which leaves to this one what it does not do
(continuation, errors).
"""
import math
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..closure.continuation import joint_step_limits
from ..closure.joint_motion import active_velocity_map, combine
from ..dynamics.forward_dynamics import INERTIA_CONDITION_LIMIT
from ..errors import (
    ClosureError,
    CogIdError,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
)
from ..linalg import spatial as sp
from ..model.mechanism import Mechanism
from ..native.kernels import ForwardRecord, kernels_for
from ..native.native_simulation import step_config
from ..solve.forward_solve import LABELS, ForwardSolver, State
from ..solve.inputs import setpoints
from .simulation_error import (
    DEFAULT_TOLERANCE,
    PASS_CONDITION_LIMIT,
    SHORTEST_SUBSTEP,
    SPEED_FLOOR,
    STOP_ESTIMATE,
    TOLERANCE_RANGE,
    Diagnostics,
    Point,
    Substep,
    Totals,
    acceleration_scale,
    at_shortest,
    careful_tolerance,
    energy,
    judge,
    judged,
    not_evaluated,
    not_followed,
    relaxed_stage,
    rounding,
    step_error,
    unit_scales,
)

#: InverseDynamics.continuation_step: the solver follows the branch in steps of this
CONTINUATION_STEP = 0.1
#: rad (a length as its joint's kind shares it, continuation.joint_step_limits): the most
#: any joint may move in one time step. A step that moves one further is refused: RK4 does
#: not follow such a motion (near a singular pose the accelerations in actuator coordinates
#: have no bound), and a revolute joint that turns more than pi in a step is ambiguous to
#: the closure's 2 pi continuity
MAX_STEP_MOTION = 0.5
#: rk4_step configurations kept, one per substep length met
CONFIGS_KEPT = 256


class Simulation:
    """A closed-link mechanism moved by the efforts of its active joints (docs/simulation.md).

    ``time_step`` (s): the length of one :meth:`step`. ``backend``: the kernels, as for
    InverseDynamics ('auto', 'native', 'python', 'reference'). ``tolerance``: the local
    error a step may make (simulation_error.py): a step whose estimate exceeds it is divided.
    All arrays are in ``mechanism.active_joints`` order, except :meth:`joint_positions` and
    :meth:`joint_velocities` (``mechanism.joints`` order).
    """

    # the state (set by _set): the pose, the primary rates, the time in steps, the primary
    # positions, the active rates, the closure residual, the last efforts and accelerations,
    # the condition numbers at the pose, the counts since the reset and the efforts' work
    _state: State
    _zd: List[float]
    _steps: int
    _z: List[float]
    _rates: List[float]
    _residual: float
    _last: Tuple[List[float], List[float]]
    _conditions: Tuple[float, float]
    _rounding: float
    _totals: Totals
    _work: float

    def __init__(self, mechanism: Mechanism, time_step: float = 0.001,
                 backend: str = 'auto', tolerance: float = DEFAULT_TOLERANCE) -> None:
        if not isinstance(mechanism, Mechanism):
            raise MechanismConfigError(
                'mechanism', f'must be a cog_id_ros.Mechanism (from Mechanism.from_params_file '
                             f'or from_parameters), got {type(mechanism).__name__}')
        if isinstance(time_step, bool) or not isinstance(time_step, (int, float)) or \
                not 0.0 < time_step <= 1.0:
            raise MechanismConfigError('time_step', f'must be a number of seconds in (0, 1], '
                                                    f'got {time_step!r}')
        low, high = TOLERANCE_RANGE
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or \
                not low <= tolerance <= high:
            raise MechanismConfigError('tolerance', f'must be a number from {low:g} to '
                                                    f'{high:g}, got {tolerance!r}')
        self.mechanism = mechanism
        self.time_step = float(time_step)
        self.tolerance = float(tolerance)
        self._solved = solved = mechanism.solver_mechanism
        kernels = kernels_for(solved, backend)
        self._backend = kernels.name
        self._forward = ForwardSolver(solved, kernels, CONTINUATION_STEP, mechanism.joints_at)
        #: a divided step's stages closed to careful_tolerance (made when first needed)
        self._careful: Optional[ForwardSolver] = None
        self._step_limits = joint_step_limits(solved, MAX_STEP_MOTION)
        self._scales = unit_scales(solved)
        self._pairs = solved.primary_pairs          # (active index, joint index) per primary
        #: the step in C (compiled kernels only) and its constants per (substep, careful)
        self._native: Optional[Callable[..., Any]] = self._forward.kernels.rk4_step
        self._configs: Dict[Tuple[float, bool], List[float]] = {}
        self._whole_config = self._config(self.time_step, False)
        self._origin: Tuple[List[float], List[float]] = ([], [])
        self._origin_energy: Optional[float] = None
        self._energies: Tuple[int, float, float] = (-1, 0.0, 0.0)
        #: the first error a stage met in the step being taken (said when it stops)
        self._met: Optional[CogIdError] = None
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

    @property
    def diagnostics(self) -> Diagnostics:
        """What the last step did and where the simulation is: its error estimate and
        substeps, the counts since the reset, the closure residual and condition numbers,
        the energy and its drift (simulation_error.Diagnostics; the energies are computed
        when asked for, once per step: tens of microseconds on a small mechanism, about a
        millisecond on a parallel robot, the step itself not slowed)."""
        kinetic, potential = self._energy()
        if self._origin_energy is None:
            self._origin_energy = sum(energy(self._solved, *self._origin))
        tally, total = self._totals, kinetic + potential
        return Diagnostics(
            self.time, self._steps, tally.substeps, tally.error_estimate, self.tolerance,
            tally.divided_steps, tally.total_substeps, tally.largest_error_estimate,
            tally.total_error_estimate, tally.shortest_substep, tally.near_singular_substeps,
            tally.inaccurate_substeps, float(self._residual), self._conditions[0],
            self._conditions[1], kinetic, potential, total, self._work,
            total - self._origin_energy - self._work)

    def joint_positions(self) -> np.ndarray:
        """Every joint's position, ``mechanism.joints`` order, at :attr:`time`."""
        return self.mechanism.joints_at(self._state[0])[0]

    def joint_velocities(self) -> np.ndarray:
        """Every joint's velocity, ``mechanism.joints`` order, at :attr:`time`."""
        return self.joint_state()[1]

    def joint_state(self) -> Tuple[np.ndarray, np.ndarray]:
        """Every joint's position and velocity at :attr:`time`, from one read-out (what
        :meth:`joint_positions` and :meth:`joint_velocities` give, at the cost of one)."""
        positions, rates = self.mechanism.joints_at(
            self._state[0], self._joint_rates(self._state, self._zd))
        assert rates is not None
        return positions, rates

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
        self._conditions = (float(record.condition), float(record.inertia_condition))
        self._rounding = rounding([record])
        self._totals, self._work = Totals(), 0.0
        self._origin = (list(state[0]), self._joint_rates(state, zd))
        self._origin_energy, self._energies = None, (-1, 0.0, 0.0)

    def step(self, tau: Union[Sequence[float], np.ndarray]) -> None:
        """Advance :attr:`time` by one time step with the efforts ``tau`` (active joints,
        N m or N) held over it, in substeps where the error estimate asks for them. A
        singular or unreachable pose on the way, or a motion no substep follows to the
        tolerance, raises (the state stays at the last step: :meth:`reset` to go on), the
        error naming the time and the joints; so do efforts that are not one finite number
        per active joint."""
        m = self._solved
        zeros = [0.0] * len(m.active_joints)
        _, _, checked, single = setpoints(m, (), zeros, zeros, tau, limits=False,
                                          labels=LABELS)
        if not single:
            raise SetpointError(f'step takes one sample of efforts (one number per active '
                                f'joint), got shape {np.shape(checked)}')
        efforts = list(checked)
        k1 = self._primary(self._last[1]) if self._last[0] == efforts else None
        try:
            first = self._whole(k1, efforts)
            if first is not None and not isinstance(first, Substep):
                state, zd, accelerations, worst, conditions, counts = first   # the usual case
            else:
                start = Point(self._state, self._zd, k1, self._rounding)
                end, counts = self._advance(start, efforts, first)
                state, zd, accelerations, worst = end.state, end.zd, end.accelerations, end.worst
                conditions = (end.condition, end.inertia_condition, end.end_rounding)
            self._check_motion(state[0])
        except CogIdError as exc:
            raise self._stopped(exc) from None
        q0, q1 = self._state[0], state[0]
        work = self._work
        for t, j in zip(efforts, m.active_index):
            work += t * (q1[j] - q0[j])
        self._set(state, accelerations, worst, zd, efforts, self._steps + 1)
        self._conditions, self._rounding, self._work = conditions[:2], conditions[2], work
        self._totals.add(counts)

    def _check_motion(self, q: Sequence[float]) -> None:
        """ClosureError ('unreachable') where a step from the current pose to the coordinates
        ``q`` moves a joint further than MAX_STEP_MOTION, or to a number that is not finite."""
        m = self._solved
        for j, (a, b, limit) in enumerate(zip(self._state[0], q, self._step_limits)):
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

    # --- the adaptive step --------------------------------------------------------------

    def _whole(self, k1: Optional[List[float]], tau: List[float]
               ) -> Union[Tuple[Any, ...], Substep, None]:
        """The step from the state as one substep in C where its estimate is met (the usual
        case): (state, zd, accelerations, worst, (condition number, inertia condition,
        rounding measure), counts), no Substep made; else that substep (a Substep, for
        :meth:`_advance`), or None where C leaves it to Python. ``k1``: the primary
        accelerations at the start with the efforts ``tau``, or None."""
        if self._native is None:
            return None
        h, (q, basis) = self.time_step, self._state
        out = self._native(q, basis, self._zd, tau, k1, self._whole_config)
        if out is None:
            return None
        ok, _, estimate, lost = judge(h, h, self.tolerance, self._rounding, *out[7:])
        if not ok:
            return Substep((out[0], out[1]), *out[2:])
        counts = [1, estimate, h, out[5] > self._solved.max_condition_number,
                  not lost <= self.tolerance]
        return (out[0], out[1]), out[2], out[3], out[4], (out[5], out[6], out[11]), counts

    def _advance(self, start: Point, tau: List[float], first: Optional[Substep]
                 ) -> Tuple[Substep, List[Any]]:
        """The end of one published step from ``start``, and its counts (substeps, summed
        estimate, shortest substep, near singular, passed inaccurate): one substep where
        its error estimate is met, else parts (:meth:`_divided`); refused where their
        estimate stays above STOP_ESTIMATE. ``first``: the whole step, taken in C and not
        met."""
        counts: List[Any] = [0, 0.0, math.inf, 0, 0]
        self._met = None
        end = self._divided(start, tau, self.time_step, 0, 0.0, counts, first)
        if not counts[1] <= STOP_ESTIMATE:
            raise not_evaluated(counts[1], self.time, (end.condition, end.inertia_condition),
                                self._conditions)
        return end, counts

    def _divided(self, start: Point, tau: List[float], h: float, depth: int, at: float,
                 counts: List[Any], first: Optional[Substep] = None) -> Substep:
        """The substep of length h from ``start`` (``at`` s into the step): whole where it
        meets the tolerance, else in two parts, a third and two thirds (unequal, so that
        the new boundary does not fall where the old stages between the ends were: a pose
        near a singular one there would become an end), each divided again as it needs;
        where the whole was passable (only its evaluations' rounding exceeds the tolerance:
        simulation_error.judge) and the parts fail or add up to a larger estimate, the
        whole. Raises where a substep of the shortest length (SHORTEST_SUBSTEP time steps)
        fails, with why. ``first``: the whole, already taken."""
        failure: Union[Substep, CogIdError]
        passable: Optional[Tuple[Substep, float, float]] = None
        shortest = h <= self.time_step * SHORTEST_SUBSTEP
        try:
            failure = sub = first or self._substep(start, tau, h, depth > 0)
        except CogIdError as exc:
            failure, self._met = exc, self._met or exc
        else:
            ok, fair, estimate, lost = judged(sub, h, self.time_step, self.tolerance,
                                              start.rounding)
            if ok or fair and shortest:
                return self._taken(sub, h, estimate, lost, counts)
            passable = (sub, estimate, lost) if fair else None
        if shortest:
            if isinstance(failure, CogIdError):
                raise at_shortest(failure, h, self.time + at)
            raise not_followed(failure, h, self.time + at, self.tolerance, self._conditions,
                               self._met)
        third, before = h / 3.0, list(counts)
        try:
            mid = self._divided(start, tau, third, depth + 1, at, counts)
            end = self._divided(Point(mid.state, mid.zd, self._primary(mid.accelerations),
                                      mid.end_rounding),
                                tau, h - third, depth + 1, at + third, counts)
            if passable is None or counts[1] - before[1] <= passable[1]:
                return end
        except CogIdError:
            if passable is None:
                raise
        counts[:] = before          # the whole, passable, where its parts are worse or fail
        return self._taken(passable[0], h, passable[1], passable[2], counts)

    def _taken(self, sub: Substep, h: float, estimate: float, lost: float,
               counts: List[Any]) -> Substep:
        """``sub`` (of length h) taken: counted into the step's ``counts``."""
        counts[0] += 1
        counts[1] += estimate
        counts[2] = min(counts[2], h)
        counts[3] += sub.condition > self._solved.max_condition_number
        counts[4] += not lost <= self.tolerance
        return sub

    def _substep(self, start: Point, tau: List[float], h: float, careful: bool) -> Substep:
        """One RK4 substep: in C where it can (the same numbers), else in Python."""
        if self._native is not None:
            q, basis = start.state
            out = self._native(q, basis, start.zd, tau, start.k1, self._config(h, careful))
            if out is not None:
                return Substep((out[0], out[1]), *out[2:])
        return self._rk4(start, tau, h, careful)

    def _config(self, h: float, careful: bool) -> List[float]:
        """rk4_step's constants for substeps of length h (``careful``, a divided step's:
        the loops closed to careful_tolerance, closure condition numbers up to
        PASS_CONDITION_LIMIT)."""
        key = (h, careful)
        config = self._configs.get(key)
        if config is None:
            if len(self._configs) > CONFIGS_KEPT:       # (substeps of many lengths)
                self._configs = {(self.time_step, False): self._whole_config}
            serial, m = self._forward.serial, self._solved
            config = self._configs[key] = step_config(
                h, m, INERTIA_CONDITION_LIMIT, serial.limits, serial.bounds, self._scales,
                SPEED_FLOOR, careful_tolerance(m) if careful else m.closure_tolerance,
                PASS_CONDITION_LIMIT if careful else None)
        return config

    def _rk4(self, start: Point, tau: List[float], h: float, careful: bool) -> Substep:
        state, zd = start.state, start.zd
        z = [state[0][j] for _, j in self._pairs]
        ends: List[Any] = []            # the records at the substep's ends, and between them
        if start.k1 is not None:
            k1 = start.k1
        else:
            ends.append(self._forward.again(state, self._primary_to_active(state, zd), tau))
            k1 = self._primary(ends[0].accelerations)
        zd2 = [v + 0.5 * h * a for v, a in zip(zd, k1)]
        inner = [self._evaluate(state, _moved(z, zd, 0.5 * h), zd2, tau, careful)[0]]
        k2 = self._primary(inner[0].accelerations)
        zd3 = [v + 0.5 * h * a for v, a in zip(zd, k2)]
        inner.append(self._evaluate(state, _moved(z, zd2, 0.5 * h), zd3, tau, careful)[0])
        k3 = self._primary(inner[1].accelerations)
        zd4 = [v + h * a for v, a in zip(zd, k3)]
        ends.append(self._evaluate(state, _moved(z, zd3, h), zd4, tau, careful)[0])
        k4 = self._primary(ends[-1].accelerations)
        sixth = h / 6.0
        z_new = [x + sixth * (a + 2.0 * b + 2.0 * c + d)
                 for x, a, b, c, d in zip(z, zd, zd2, zd3, zd4)]
        zd_new = [v + sixth * (a + 2.0 * b + 2.0 * c + d)
                  for v, a, b, c, d in zip(zd, k1, k2, k3, k4)]
        record, new_state = self._evaluate(state, z_new, zd_new, tau, careful)
        ends.append(record)
        k5 = self._primary(record.accelerations)
        error = step_error(h, state, zd, new_state, zd_new, zd4, k4, k5, self._scales)
        scale = acceleration_scale((k1, k2, k3, k4, k5), self._scales,
                                   [j for _, j in self._pairs])
        return Substep(new_state, zd_new, list(record.accelerations), record.worst,
                       float(record.condition), float(record.inertia_condition), *error,
                       rounding(ends), rounding(inner), scale)

    def _evaluate(self, state: State, z: List[float], zd: List[float], tau: List[float],
                  careful: bool = False) -> Tuple[ForwardRecord, State]:
        """(ForwardRecord, state) at the primary positions z and rates zd: the loops closed
        from ``state``, then forward dynamics with the rates of the active joints there.
        ``careful``, a divided step's stage: closed to careful_tolerance, closure condition
        numbers up to PASS_CONDITION_LIMIT accepted, where one continuation step closes it
        (simulation_error.relaxed_stage); else as the solver closes it (:meth:`_solve`)."""
        q = state[0]
        target = [q[j] for j in self._solved.active_index]
        for (a, _), x in zip(self._pairs, z):
            target[a] = x
        redundant = self._solved.is_redundant
        if redundant:       # the active rates V_a zd need the basis at the closed pose
            qd = self._primary_to_active(state, zd)
        else:
            qd = [0.0] * len(target)
            for (a, _), v in zip(self._pairs, zd):
                qd[a] = v
        done = None
        if careful:
            done = relaxed_stage(self._careful_solver().serial, state, target, qd, tau,
                                 PASS_CONDITION_LIMIT)
        record, new_state = done or self._solve(state, target, qd, tau, careful)
        if not redundant:
            return record, new_state
        return self._forward.again(new_state, self._primary_to_active(new_state, zd),
                                   tau), new_state

    def _solve(self, state: State, target: Sequence[float], qd: Sequence[float],
               tau: Sequence[float], careful: bool) -> Tuple[ForwardRecord, State]:
        """ForwardSolver.one (a redundant mechanism's primary actuators put at ``target``),
        the loops closed to careful_tolerance where ``careful``, and to closure_tolerance
        where that fails (Newton's method cannot get further: rounding)."""
        if careful:
            try:
                return self._careful_solver().one(state, target, qd, tau, project=False)
            except ClosureError:
                pass
        return self._forward.one(state, target, qd, tau, project=False)

    def _careful_solver(self) -> ForwardSolver:
        """The solver of a divided step's stages: the loops closed to careful_tolerance."""
        if self._careful is None:
            self._careful = ForwardSolver(self._solved, self._forward.kernels,
                                          CONTINUATION_STEP, self.mechanism.joints_at)
            self._careful.serial.tolerance = careful_tolerance(self._solved)
        return self._careful

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

    def _energy(self) -> Tuple[float, float]:
        """(kinetic, potential) energy at :attr:`time`, computed once per step."""
        if self._energies[0] != self._steps:
            kinetic, potential = energy(self._solved, self._state[0],
                                        self._joint_rates(self._state, self._zd))
            self._energies = (self._steps, kinetic, potential)
        return self._energies[1], self._energies[2]

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
