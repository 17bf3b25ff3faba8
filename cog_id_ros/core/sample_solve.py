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

A pose that cannot be served raises the error that says why (``.reason``: closure,
singular, inconsistent, unreachable); the warm start is the caller's and is never changed
here.
"""
import math
from typing import TYPE_CHECKING, Any, Sequence

from .closure import loops_closed
from .continuation import (
    MAX_STEPS,
    MIN_STEP,
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
from .errors import ClosureError, SingularConfigurationError
from .inputs import out_of_range
from .joint_motion import BasisLayout, projected_pose
from .newton import LIKELY_CLOSED, NEWTON_ITERATIONS, NEWTON_MAX_INCREMENT, STAGNATION
from .value_types import LaneMatrix

if TYPE_CHECKING:
    from .kernels import PoseRecord, ReferenceKernels
    from .mechanism import Mechanism

#: Gauss-Newton iterations of the redundant projection, and the increment that ends it
PROJECTION_ITERATIONS = 6
PROJECTION_TOLERANCE = 1e-14


class SampleSolver:
    """The per-sample solve of one mechanism with one set of kernels.

    A state is (q, V): every joint coordinate and the velocity basis there (a list over
    joints of rows over the primary actuators), as solve() returns it. ``whole``: the kernel
    that evaluates a closed pose, 'dynamics' (torques from qd, qdd) or 'forward'
    (accelerations from qd and the efforts, in place of qdd: forward_dynamics.py).
    """

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
                                                      qdd, sample)
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
             qd: Sequence[float], qdd: Sequence[float],
             sample: int | None) -> tuple['PoseRecord', State, Sequence[float]]:
        """One continuation step: close the loops from ``predicted``, check, and when
        ``final`` (the final step, projected) for a redundant mechanism project onto
        ``goal``. Returns (PoseRecord, new state,
        the pose Newton closed before any projection)."""
        m = self.mechanism
        q, record, iterations, ok = self.close(predicted, goal, qd, qdd)
        if not ok:
            raise not_closed(record, self.tolerance, iterations, sample)
        closed = q
        if final and self.redundant:
            q, record = self.project(q, record, goal, qd, qdd, sample)
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
        whole = likely_closed
        # a ClosureRecord while the loops are probably not closed, a whole record once they are
        record: Any = evaluate(q, goal, qd, qdd) if whole else kernels.closure(q)
        for iteration in range(NEWTON_ITERATIONS + 1):
            if loops_closed(record.worst, record.least_cosine, tol):
                if not whole:
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
            whole = size * factor < LIKELY_CLOSED
            record = evaluate(q, goal, qd, qdd) if whole else kernels.closure(q)
        if not whole:
            record = evaluate(q, goal, qd, qdd)
        return q, record, iteration, False

    def project(self, q: Sequence[float], record: 'PoseRecord', target: Sequence[float],
                qd: Sequence[float], qdd: Sequence[float],
                sample: int | None) -> tuple[Sequence[float], 'PoseRecord']:
        """Redundant actuation: Gauss-Newton over closed poses towards ``target``; the
        setpoint must then be within mechanism.setpoint_tolerance of the pose."""
        m = self.mechanism
        for _ in range(PROJECTION_ITERATIONS):
            dz = record.projection
            if max(map(abs, dz)) < PROJECTION_TOLERANCE:
                break
            q, record, iterations, ok = self.close(
                projected_pose(m, q, self.basis(record), dz), target, qd, qdd,
                likely_closed=True)
            if not ok:
                raise not_closed(record, self.tolerance, iterations, sample)
        mismatch = max(abs(q[j] - t) for j, t in zip(m.active_index, target))
        if mismatch > m.setpoint_tolerance:
            raise ClosureError(
                f'{_where(sample)}the redundant setpoint disagrees with the loop closure by '
                f'{mismatch:.6g} (rad or m), more than mechanism.setpoint_tolerance '
                f'{m.setpoint_tolerance:.6g}', mismatch, sample, reason='inconsistent')
        return q, record

    def basis(self, record: 'PoseRecord') -> LaneMatrix:
        """The velocity basis V (list over joints) from a record's rows of the free joints."""
        return self.layout.rows(record.basis)


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
