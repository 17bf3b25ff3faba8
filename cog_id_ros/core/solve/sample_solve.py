"""One sample: from the warm start to the closed pose at a setpoint, and the torques there.

The per-sample solve, written once for every backend (kernels.py does the arithmetic):

1. **Continuation** (rules in continuation.py): the primary actuators move from the warm
   start towards the setpoint in steps short enough to stay on the assembly branch; at
   control rate the setpoint is one step away and the loop below runs once.
2. **Each step**: a first-order prediction q + V dz, then Newton's method on the loop
   equations over the free joints (:meth:`SampleSolver.close`), then the checks: closed,
   not singular, a Newton correction small enough to be on the same branch.
3. **Redundant actuation**, at the last step only: Gauss-Newton towards the closed pose
   nearest the whole setpoint (W^-1 metric), and the check that it is near enough.
4. **Closed further where the conditioning needs it** (InverseDynamics' solvers, ``refine``),
   at the last step only: one more Newton increment while the increment left times the
   squared condition number exceeds newton.ACCURACY_FACTOR times the tolerance (near a
   singular pose; a well-conditioned one closed to the tolerance is left as it is).

A pose that cannot be served raises the error that says why (``.reason``: closure,
singular, inconsistent, unreachable); the warm start is the caller's and is never changed
here.
"""
import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..closure.closure import assemble, loops_closed
from ..closure.continuation import (
    MAX_STEPS,
    MIN_STEP,
    TWO_PI,
    State,
    actuator_ratio,
    correction_bounds,
    correction_ok,
    fits_one_step,
    intermediate_goal,
    joint_step_limits,
    step_ratio,
    wrapped_state,
    wrapping_actuators,
)
from ..closure.joint_motion import BasisLayout, projected_pose
from ..closure.newton import (
    ACCURACY_FACTOR,
    LIKELY_CLOSED,
    NEWTON_ITERATIONS,
    NEWTON_MAX_INCREMENT,
    REFINE_ITERATIONS,
    STAGNATION,
)
from ..errors import ClosureError, SingularConfigurationError
from ..value_types import LaneMatrix
from .inputs import out_of_range

if TYPE_CHECKING:
    from ..model.mechanism import Mechanism
    from ..native.kernels import ClosureRecord, PoseRecord, ReferenceKernels

#: Gauss-Newton iterations of the redundant projection, and the increment that ends it
PROJECTION_ITERATIONS = 6
PROJECTION_TOLERANCE = 1e-14

#: the relative rounding of a coordinate (a double's machine epsilon)
ROUNDING = 2.220446049250313e-16

#: a redundant setpoint within mechanism.setpoint_tolerance of a closed pose of a branch
#: (every actuator) is within (1 + |V_a|) times that of the branch's pose at its primary
#: actuators (V_a the active rows of the velocity basis, to first order); this many times
#: that, it is refused at once (:func:`reach`)
PROJECTION_REACH = 2.0


class SampleSolver:
    """The per-sample solve of one mechanism with one set of kernels.

    A state is (q, V): every joint coordinate and the velocity basis there (a list over
    joints of rows over the primary actuators), as solve() returns it. ``whole``: the kernel
    that evaluates a closed pose, 'dynamics' (torques from qd, qdd) or 'forward'
    (accelerations from qd and the efforts, in place of qdd: forward_dynamics.py).
    ``refine``: the pose of a setpoint is closed past the tolerance where its conditioning
    needs it (:meth:`refined`); InverseDynamics sets it, a Simulation's stages do not.
    """

    #: close the final pose past the tolerance where its conditioning needs it
    refine = False
    #: the largest relative_error a refined pose is left at, over the closure tolerance
    accuracy_factor = ACCURACY_FACTOR

    @property
    def closes_to_rounding(self) -> bool:
        """Whether poses are closed to rounding (ActuatorSpaceSolver.close_to_rounding: an
        accuracy_factor below 1), not to the tolerance: :meth:`_polished`."""
        return self.refine and self.accuracy_factor < 1.0

    @property
    def accuracy(self) -> float:
        """The largest relative_error a pose is left at (where rounding allows):
        accuracy_factor (newton.ACCURACY_FACTOR) times the closure tolerance."""
        return self.accuracy_factor * self.tolerance

    def __init__(self, mechanism: 'Mechanism', kernels: 'ReferenceKernels',
                 continuation_step: float, whole: str = 'dynamics') -> None:
        m = self.mechanism = mechanism
        self.kernels = kernels
        self.whole_name = whole
        self.whole = getattr(kernels, whole)
        self.limits = joint_step_limits(m, continuation_step)
        self.bounds = correction_bounds(self.limits)
        self.wrapping = wrapping_actuators(m)
        self.free = m.free_joints
        self.tolerance = m.closure_tolerance
        self.redundant = m.is_redundant
        self.zeros = [0.0] * len(m.active_joints)
        self.layout = BasisLayout(m)

    def solve(self, state: State, target: Sequence[float], qd: Sequence[float] | None = None,
              qdd: Sequence[float] | None = None, sample: int | None = None,
              project: bool = True) -> tuple['PoseRecord', State]:
        """(PoseRecord at ``target``, new state) by continuation from ``state``. Without
        ``project``, a redundant mechanism's primary actuators are put at their targets and
        the others follow from the closure (their targets are not used)."""
        m, limits = self.mechanism, self.limits
        qd = self.zeros if qd is None else qd
        qdd = self.zeros if qdd is None else qdd
        start = state
        state = wrapped_state(m, self.wrapping, state, target)
        predict = self.kernels.prediction
        ahead, moved = predict(state[0], state[1], target)
        one_step = fits_one_step(m, limits, state, target, moved)
        if not one_step and actuator_ratio(m, limits, state, target) > MAX_STEPS:
            raise unreachable(m, start, target, sample,
                              f'it is more than {MAX_STEPS} continuation steps away')
        cap = 1.0     # the largest step, in step limits (halved when a step fails)
        for _ in range(MAX_STEPS):
            predicted = ahead
            if cap >= 1.0 and one_step:         # at control rate: the only step
                size, goal, final = 1.0, target, True
            else:
                ratio = step_ratio(m, limits, state, target, moved)
                if ratio <= cap * (1.0 + 1e-9):      # (not a sliver of a step left over)
                    size, goal, final = ratio, target, True
                else:
                    size, final = cap, False
                    goal = intermediate_goal(m, state, target, cap / ratio)
                    predicted = predict(state[0], state[1], goal).predicted
            try:
                record, new_state, closed = self.step(predicted, goal, final and project, qd,
                                                      qdd, sample, last=final)
            except ClosureError as exc:
                if final:
                    raise
                if exc.reason != 'closure' or cap < MIN_STEP:
                    raise unreachable(m, start, target, sample, f'the loops stop closing on '
                                      f'the way, at {_fmt(goal)}') from None
                cap = size / 2.0      # Newton failed on the way: try a shorter step
                continue
            except SingularConfigurationError as exc:
                if final:
                    raise
                raise unreachable(m, start, target, sample,
                                  f'the way there passes a singular pose at {_fmt(goal)} '
                                  f'(condition number {exc.condition_number:.3g})') from None
            if not correction_ok(closed, predicted, self.bounds):
                if size / 2.0 < MIN_STEP:
                    raise unreachable(m, start, target, sample,
                                      'the assembly branch cannot be followed there (Newton '
                                      'corrections stay large even in short steps: a branch '
                                      'point or dead centre)')
                cap = size / 2.0      # Newton moved far from the prediction: maybe another branch
                continue
            if final:
                return record, new_state
            state, cap = new_state, min(1.0, cap * 2.0)
            ahead, moved = predict(state[0], state[1], target)
            one_step = fits_one_step(m, limits, state, target, moved)
        raise unreachable(m, start, target, sample,
                          f'not reached in {MAX_STEPS} continuation steps')

    def solve_torques(self, state: State, target: Sequence[float], qd: Sequence[float],
                      qdd: Sequence[float],
                      sample: int | None = None) -> tuple['PoseRecord', State]:
        """:meth:`solve`, and SetpointError (reason 'out_of_range') where the torques there
        are not finite; the warm start is the caller's."""
        record, state = self.solve(state, target, qd, qdd, sample)
        if not all(map(math.isfinite, record.torques)):
            raise out_of_range(qd, qdd, sample)
        return record, state

    def step(self, predicted: Sequence[float], goal: Sequence[float], final: bool,
             qd: Sequence[float], qdd: Sequence[float], sample: int | None,
             last: bool = False) -> tuple['PoseRecord', State, Sequence[float]]:
        """One continuation step: close the loops from ``predicted``, check, and when
        ``final`` (the final step, projected) for a redundant mechanism project onto
        ``goal``; when ``last`` (the final step) and :attr:`refine`, close further where the
        conditioning needs it. Returns (PoseRecord, new state,
        the pose Newton closed before any projection)."""
        m = self.mechanism
        q, record, iterations, ok = self.close(predicted, goal, qd, qdd)
        if not ok:
            raise not_closed(record, self.tolerance, iterations, sample)
        closed = q
        if final and self.redundant:
            q, record = self.project(q, record, goal, qd, qdd, sample)
        if last and self.refine and (self.redundant or record.largest_step *
                                     record.condition * record.condition > self.accuracy) \
                and not self._at_rounding(q, record):
            q, record = self.refined(q, record, goal, qd, qdd)
        if not record.condition <= m.max_condition_number:
            raise singular(m, record.condition, sample)
        return record, (q, self.layout.rows(record.basis)), closed

    def close(self, q: Sequence[float], goal: Sequence[float], qd: Sequence[float],
              qdd: Sequence[float],
              likely_closed: bool = False) -> tuple[Sequence[float], 'PoseRecord', int, bool]:
        """Newton's method on the loop equations from ``q``, moving the free joints.

        Returns (q, PoseRecord at q, iterations, closed); when not closed the record is
        where Newton stopped. The cheap closure kernel is used where the pose is probably
        not closed (a prediction, or after an increment of LIKELY_CLOSED or more); after a
        small increment, or when ``likely_closed``, the whole record is evaluated at once."""
        kernels, tol, free, evaluate = self.kernels, self.tolerance, self.free, self.whole
        polish = self.closes_to_rounding
        whole = likely_closed and not polish
        # a ClosureRecord while the loops are probably not closed, a whole record once they are
        record: Any = evaluate(q, goal, qd, qdd) if whole else kernels.closure(q)
        for iteration in range(NEWTON_ITERATIONS + 1):
            if loops_closed(record.worst, record.least_cosine, tol):
                if polish:
                    record, q = self._polished(q, record, goal, qd, qdd)
                elif not whole:
                    record = evaluate(q, goal, qd, qdd)
                return q, record, iteration, True
            if iteration == NEWTON_ITERATIONS:
                break
            increment = record.increment
            size = record.largest_step
            if not size < math.inf or size < STAGNATION and \
                    size < 1e-15 * (1.0 + max(map(abs, map(q.__getitem__, free)))):
                break                               # NaN or infinite, or stagnated
            factor = min(1.0, NEWTON_MAX_INCREMENT / size)
            q = list(q)
            for k, j in enumerate(free):
                q[j] = q[j] - increment[k] * factor
            whole = size * factor < LIKELY_CLOSED and not polish
            record = evaluate(q, goal, qd, qdd) if whole else kernels.closure(q)
        if not whole:
            record = evaluate(q, goal, qd, qdd)
        return q, record, iteration, False

    def _at_rounding(self, q: Sequence[float], record: 'PoseRecord') -> bool:
        """Closing to rounding, not redundant: whether the increment left at the polished
        pose ``q`` is what the rounding of the loop equations makes (machine epsilon times
        the condition number and the coordinates' size, with a margin of 4): another Newton
        increment cannot make it smaller, and :meth:`refined` would only evaluate it again."""
        if self.redundant or not self.closes_to_rounding:
            return False
        size = 1.0 + max(map(abs, map(q.__getitem__, self.free)), default=0.0)
        return bool(record.largest_step <= 4.0 * ROUNDING * record.condition * size)

    def _polished(self, q: Sequence[float], record: 'ClosureRecord', goal: Sequence[float],
                  qd: Sequence[float], qdd: Sequence[float]) -> tuple['PoseRecord', Any]:
        """Closing to rounding (close_to_rounding): the pose ``q``, closed to the tolerance
        by the closure kernel's ``record``, moved by that record's increment (Newton's
        quadratic convergence: from a pose closed to the tolerance one increment reaches
        rounding, as :meth:`refined` would, without a second whole record), then its whole
        record: (whole record, pose). Where that pose would not be closed (cannot be for an
        increment this small; be safe), ``q`` as it was."""
        moved = list(q)
        for k, j in enumerate(self.free):
            moved[j] = q[j] - record.increment[k]
        better = self.whole(moved, goal, qd, qdd)
        if loops_closed(better.worst, better.least_cosine, self.tolerance):
            return better, moved
        return self.whole(q, goal, qd, qdd), q

    def refined(self, q: Sequence[float], record: 'PoseRecord', goal: Sequence[float],
                qd: Sequence[float], qdd: Sequence[float]
                ) -> tuple[Sequence[float], 'PoseRecord']:
        """The closed pose ``q`` (its whole record ``record``) closed further while its
        :func:`relative_error` exceeds newton.ACCURACY_FACTOR times the tolerance: one Newton
        increment at a time (the record holds it; with redundant actuation the projection's
        increment is taken with it), each evaluated as a whole record, at most
        REFINE_ITERATIONS, and only while the increment shrinks (else rounding: the pose
        cannot be closed further, and stays where it is)."""
        tol, free = self.tolerance, self.free
        size = increment_left(record, self.redundant)
        for _ in range(REFINE_ITERATIONS):
            if not relative_error(size, record.condition) > self.accuracy or \
                    not size < math.inf:
                break
            moved = list(q)
            increment = record.increment
            for k, j in enumerate(free):
                moved[j] = q[j] - increment[k]
            if self.redundant:
                moved = projected_pose(self.mechanism, moved, self.basis(record),
                                       record.projection)
            better = self.whole(moved, goal, qd, qdd)
            smaller = increment_left(better, self.redundant)
            if not (smaller < size and loops_closed(better.worst, better.least_cosine, tol)):
                break
            q, record, size = moved, better, smaller
        return q, record

    def project(self, q: Sequence[float], record: 'PoseRecord', target: Sequence[float],
                qd: Sequence[float], qdd: Sequence[float],
                sample: int | None) -> tuple[Sequence[float], 'PoseRecord']:
        """Redundant actuation: Gauss-Newton over closed poses towards ``target``; the
        setpoint must then be within mechanism.setpoint_tolerance of the pose. A setpoint
        farther from the closed pose ``q`` than any on its branch can be (:func:`reach`) is
        refused at once: the projection would leave the branch (to another assembly mode)."""
        m = self.mechanism
        for iteration in range(PROJECTION_ITERATIONS):
            dz = record.projection
            if max(map(abs, dz)) < PROJECTION_TOLERANCE:
                break
            if not iteration:
                self.within_reach(q, record, target, sample)
            q, record, iterations, ok = self.close(
                projected_pose(m, q, self.basis(record), dz), target, qd, qdd,
                likely_closed=True)
            if not ok:
                raise not_closed(record, self.tolerance, iterations, sample)
        mismatch = max(abs(q[j] - t) for j, t in zip(m.active_index, target))
        if mismatch > m.setpoint_tolerance:
            raise inconsistent(m, q, target, mismatch, sample)
        return q, record

    def within_reach(self, q: Sequence[float], record: 'PoseRecord', target: Sequence[float],
                     sample: int | None) -> None:
        """Raises 'inconsistent' where the redundant setpoint ``target`` is farther from the
        closed pose ``q`` of its primary actuators than any setpoint the projection can
        honour on this branch (:func:`reach`): the projection would leave the branch, to
        another assembly mode."""
        m = self.mechanism
        error = max(abs(q[j] - t) for j, t in zip(m.active_index, target))
        if error > PROJECTION_REACH * m.setpoint_tolerance:
            basis = self.basis(record)
            if error > reach(m, basis):
                dz = record.projection          # (the disagreement left, to first order)
                left = max(abs(q[j] - t - sum(b * d for b, d in zip(basis[j], dz)))
                           for j, t in zip(m.active_index, target))
                raise inconsistent(m, q, target, left, sample)

    def basis(self, record: 'PoseRecord') -> LaneMatrix:
        """The velocity basis V (list over joints) from a record's rows of the free joints."""
        return self.layout.rows(record.basis)


def reach(mechanism: 'Mechanism', basis: LaneMatrix) -> float:
    """How far (rad or m) a redundant setpoint that the projection can honour may be from the
    closed pose of its primary actuators, with the velocity basis ``basis`` there:
    PROJECTION_REACH (1 + max row sum of |V_a|) mechanism.setpoint_tolerance. Farther, no
    pose of the branch is within the tolerance of it."""
    rows = max(sum(map(abs, basis[j])) for j in mechanism.active_index)
    return PROJECTION_REACH * (1.0 + rows) * mechanism.setpoint_tolerance


def increment_left(record: Any, redundant: bool) -> Any:
    """The Newton increment left at a closed pose (rad or m): the closure's largest, and
    with ``redundant`` actuation the projection's if larger. A record of floats, or of (N,)
    arrays for an (N,) array."""
    if not redundant:
        return record.largest_step
    if isinstance(record.largest_step, float):
        return max(record.largest_step, max(map(abs, record.projection)))
    return np.maximum(record.largest_step, np.abs(record.projection).max(axis=-1))


def relative_error(increment: Any, condition: Any, magnitude: Any = None) -> Any:
    """The estimate of the torques' error at a closed pose relative to their scale: the
    Newton increment left there (:func:`increment_left`, rad or m) times the squared
    condition number (newton.ACCURACY_FACTOR). With ``magnitude``, the largest |coordinate|
    of the free joints, the coordinates' rounding, ROUNDING (1 + magnitude), is added to
    the increment (a pose closed to rounding is not exact). Floats, or (N,) arrays."""
    if magnitude is not None:
        increment = increment + ROUNDING * (1.0 + magnitude)
    return increment * condition * condition


def _where(sample: int | None) -> str:
    return '' if sample is None else f'sample {sample}: '


def _fmt(values: Sequence[float]) -> str:
    return '[' + ', '.join(f'{v:.6g}' for v in values) + ']'


def not_closed(record: Any, tolerance: float, iterations: int, sample: int | None) -> ClosureError:
    residual = record.worst
    return ClosureError(
        f'{_where(sample)}the loops cannot be closed at this setpoint: closure residual '
        f'{residual:.3g} (tolerance {tolerance:.3g}) after {iterations} Newton iterations',
        residual, sample)


def singular(mechanism: 'Mechanism', condition: float,
             sample: int | None) -> SingularConfigurationError:
    return SingularConfigurationError(
        f'{_where(sample)}singular configuration: closure Jacobian condition number '
        f'{condition:.3g} exceeds mechanism.max_condition_number '
        f'{mechanism.max_condition_number:.3g}', condition, sample)


def inconsistent(mechanism: 'Mechanism', q: Sequence[float], target: Sequence[float],
                 mismatch: float, sample: int | None) -> ClosureError:
    """ClosureError(reason='inconsistent') for a redundant setpoint ``target`` that the pose
    ``q`` of the solver's assembly branch misses by ``mismatch``
    (:class:`InconsistentSetpointError`)."""
    return InconsistentSetpointError(mechanism, q, target, mismatch, sample)


class InconsistentSetpointError(ClosureError):
    """ClosureError(reason='inconsistent') for a redundant setpoint that the pose ``q`` of
    the solver's assembly branch misses by ``mismatch``. Where the loops close with every
    active joint at the setpoint in another assembly mode (:func:`other_mode`), its message
    says so and what to do: worked out when the message is first read (a few least-squares
    solves: a batch of refused samples does not pay for messages no one reads)."""

    def __init__(self, mechanism: 'Mechanism', q: Sequence[float], target: Sequence[float],
                 mismatch: float, sample: int | None) -> None:
        super().__init__(
            f'{_where(sample)}the redundant setpoint disagrees with the loop closure by '
            f'{mismatch:.6g} (rad or m), more than mechanism.setpoint_tolerance '
            f'{mechanism.setpoint_tolerance:.6g}', mismatch, sample, reason='inconsistent')
        self._pose: Any = (mechanism, list(q), list(target))
        self._text: str | None = None

    def __str__(self) -> str:
        if self._text is None:
            text = super().__str__()
            other = other_mode(*self._pose)
            if other is not None:
                joint, here, there = other
                text += (f', on the assembly branch the solver follows; the loops do close at '
                         f'this setpoint, in another assembly mode ({joint} at {there:.6g} '
                         f'there, {here:.6g} on this branch). The solver keeps the assembly '
                         f'mode it is on (continuation from the last pose): to serve setpoints '
                         f'of the other mode, reset() if initial_positions are in it, or start '
                         f'nearer, from setpoints of a motion that stays in that mode')
            self._text = text
        return self._text

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as the ClosureError it says (its message worked out)."""
        return ClosureError, (str(self), self.residual, self.sample, self.reason)


def other_mode(mechanism: 'Mechanism', q: Sequence[float], target: Sequence[float]
               ) -> tuple[str, float, float] | None:
    """Where a redundant setpoint ``target`` is consistent with another assembly mode than
    that of the closed pose ``q``: the loops closed from ``q`` with every active joint moved
    to ``target`` and held (closure.assemble, Gauss-Newton), and if they close, (the joint
    that differs most from ``q``, its coordinate in ``q``, there); None otherwise. (The
    error path only: a few least-squares solves.)"""
    m = mechanism
    start = list(q)
    for j, t in zip(m.active_index, target):
        start[j] = t
    held = set(m.active_index) | set(getattr(m, 'locked_index', ()))
    try:
        closed, _, ok = assemble(m.model, start, m.closure_tolerance, held, max_iter=50)
    except (ArithmeticError, ValueError, np.linalg.LinAlgError):
        return None
    kinds = m.model.coordinate_kinds
    moved = []              # (how far, joint, where): a revolute joint's nearest turn
    for j in range(len(m.joints)):
        if j not in held:
            d = closed[j] - q[j]
            if kinds[j].wraps:
                d -= TWO_PI * round(d / TWO_PI)
            moved.append((abs(d), j, q[j] + d))
    if not ok or not moved:
        return None
    _, j, there = max(moved)
    return m.joints[j], q[j], there


def unreachable(mechanism: 'Mechanism', start: State, target: Sequence[float], sample: int | None,
                why: str) -> ClosureError:
    """ClosureError(reason='unreachable') for a setpoint continuation cannot get to."""
    q = start[0]
    last = [q[j] for j in mechanism.active_index]
    return ClosureError(
        f'{_where(sample)}cannot reach the setpoint {_fmt(target)} from the last pose '
        f'{_fmt(last)} of {mechanism.active_joints}: {why}. Send setpoints closer together '
        f'(the solver follows the assembly branch in short steps)', math.inf, sample,
        reason='unreachable')
