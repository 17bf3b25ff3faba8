"""N samples as one trajectory: the lane code on numpy arrays, checked by the serial rules.

The samples are solved on the branch that sample-by-sample continuation (sample_solve.py)
reaches, at a fraction of its cost:

1. serial anchors every continuation step of actuator travel;
2. between them, a start for every sample interpolated from its two anchors (their poses
   and velocity bases), then Newton's method on all samples at once (and the redundant
   projection), by the kernels' *_many forms (C loops with the native backend, the lane
   code on (N,) arrays otherwise);
3. a check of every sample against its predecessor by the serial path's own rules: one
   continuation step away, and the serial step itself, Newton's method from the first-order
   prediction (on all samples at once), closes the loops at the pose found in 2, within the
   correction bound of the prediction (near a singular pose two assembly branches can both
   lie that close to it: the step decides which one the serial path takes); then a serial
   re-solve, in order, of every sample that fails it;
4. eqs. (1)-(7) (pipeline.py) by the dynamics kernel, and the per-sample status (an
   Evaluation).
"""
import heapq
import math
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from ..closure import closure
from ..closure.joint_motion import projected_pose
from ..closure.newton import REFINE_ITERATIONS
from ..errors import CogIdError
from ..linalg.lanes import columns
from ..native.kernels import RECORDS, ClosureRecord, unpack
from ..value_types import BoolArray, FloatArray, IntArray
from .inputs import check_values, checked_sample, out_of_range
from .sample_solve import (
    NEWTON_ITERATIONS,
    NEWTON_MAX_INCREMENT,
    PROJECTION_ITERATIONS,
    PROJECTION_REACH,
    PROJECTION_TOLERANCE,
    SampleSolver,
    increment_left,
    relative_error,
)

if TYPE_CHECKING:
    from ..closure.continuation import State
    from ..closure.joint_motion import BasisLayout
    from ..model.mechanism import Mechanism

#: two closed poses of one setpoint closer than this fraction of the joints' step limits
#: (1e-7 rad) are one pose: on one branch they differ by the Newton increments left (1e-9 or
#: less), while two assembly branches that close to each other meet at a singular pose
SAME_POSE = 1e-6


class Evaluation:
    """Result of InverseDynamics.evaluate, always batch-shaped (N = 1 for one sample).

    torques (N, M): active-joint torques/forces, 0.0 in rows that are not valid (never NaN)
    valid (N,): bool
    errors: list of N entries, None or the exception that made the sample invalid
    positions (N, n_joints): every joint coordinate, mechanism.joints order (worked out when
        first read: for chains of revolutes solved as spherical joints it takes a pass of
        forward kinematics, spherical_chains.py)
    active_positions (N, M): the active coordinates used (projected for redundant actuation)
    closure_residual (N,): max |closure equation| at the solution
    condition_number (N,): closure Jacobian condition number (see mechanism.max_condition_number)
    relative_error (N,): the estimate of the torques' error relative to their scale, the
        Newton increment left at the pose times the squared condition number
        (sample_solve.relative_error); at most newton.ACCURACY_FACTOR * closure_tolerance
        unless rounding keeps a pose near a singular one from closing further; inf where
        not valid
    """

    def __init__(self, torques: FloatArray, valid: BoolArray, errors: list[CogIdError | None],
                 positions: FloatArray | Callable[[], FloatArray], active_positions: FloatArray,
                 residual: FloatArray, condition: FloatArray,
                 relative_error: FloatArray | None = None) -> None:
        self.torques = torques
        self.valid = valid
        self.errors = errors
        self._positions = positions         # an array, or a function that makes it
        self.active_positions = active_positions
        self.closure_residual = residual
        self.condition_number = condition
        self.relative_error = (np.where(valid, 0.0, math.inf) if relative_error is None
                               else relative_error)

    @property
    def positions(self) -> FloatArray:
        if callable(self._positions):
            self._positions = self._positions()
        return self._positions

    @positions.setter
    def positions(self, value: FloatArray) -> None:
        self._positions = value


class Batch:
    """The batch driver of one mechanism, around its per-sample solver (and its kernel for
    closed poses: ``sample_solver.whole_name``, whose records :meth:`positions` returns)."""

    def __init__(self, mechanism: 'Mechanism', sample_solver: SampleSolver,
                 joints_at: Callable[[FloatArray], tuple[FloatArray, Any]]) -> None:
        self.mechanism = mechanism
        self.joints_at = joints_at      # the joints as written from the coordinates
        self.serial = sample_solver
        self.kernels = kernels = sample_solver.kernels
        name = sample_solver.whole_name
        self.whole_many = getattr(kernels, name + '_many')
        self.layout, self.record_type = kernels.layouts[name], RECORDS[name]

    def evaluate_one(self, state: 'State', q: FloatArray, qd: FloatArray, qdd: FloatArray,
                     on_invalid: str) -> tuple[Evaluation, 'State']:
        """(Evaluation of one sample (arrays (1, M)), new state), by the per-sample path."""
        try:
            sample = checked_sample(self.mechanism, self.serial.wrapping, q, qd, qdd)
            record, new_state = self.serial.solve_torques(state, *sample)
        except CogIdError as exc:
            if on_invalid == 'raise':
                raise
            return self._one(state, np.zeros(q.shape), exc, getattr(exc, 'residual', math.inf),
                             getattr(exc, 'condition_number', math.inf), math.inf), state
        magnitude = max([abs(new_state[0][j]) for j in self.serial.free] or [0.0])
        return self._one(new_state, np.array([record.torques]), None, record.worst,
                         record.condition,
                         relative_error(increment_left(record, self.serial.redundant),
                                        record.condition, magnitude)), new_state

    def _one(self, state: 'State', torques: FloatArray, error: CogIdError | None, residual: float,
             condition: float, relative: float) -> Evaluation:
        at = np.array([state[0]])
        return Evaluation(torques, np.array([error is None]), [error],
                          lambda: self.joints_at(at)[0], at[:, self.mechanism.active_index],
                          np.array([residual]), np.array([condition]), np.array([relative]))

    def evaluate(self, state: 'State', q: FloatArray, qd: FloatArray, qdd: FloatArray,
                 on_invalid: str) -> tuple[Evaluation, 'State']:
        """(Evaluation of N > 1 samples, new state)."""
        m = self.mechanism
        n, n_act = q.shape
        finite, errors_in = check_values(m, self.serial.wrapping, q, qd, qdd, False)
        if errors_in and on_invalid == 'raise':
            raise errors_in[min(errors_in)]
        if not finite.all():   # bad rows take their neighbours so they do not disturb the rest
            q, qd, qdd = (np.where(finite[:, None], x, 0.0) for x in (q, qd, qdd))
            for i in np.flatnonzero(~finite):
                q[i] = q[i - 1] if i > 0 else [state[0][j] for j in m.active_index]
        with np.errstate(all='ignore'):
            record, positions, ok, errors, new_state = self.positions(
                state, q, on_invalid, invalid=~finite, qd=qd, qdd=qdd)
            tau = record.torques.copy()
            residual = record.worst.copy()
            condition = record.condition.copy()
            relative = relative_error(increment_left(record, m.is_redundant), condition,
                                      np.abs(positions[:, m.free_joints]).max(axis=1,
                                                                              initial=0.0))
        for k, exc in errors_in.items():
            errors[k] = exc
        ok &= finite & np.isfinite(tau).all(axis=1)
        for i in np.flatnonzero(~ok):
            exc = errors[i]
            residual[i] = getattr(exc, 'residual', math.inf)
            condition[i] = getattr(exc, 'condition_number', math.inf)
            if exc is None:
                errors[i] = out_of_range(qd[i].tolist(), qdd[i].tolist(), int(i))
                if on_invalid == 'raise':
                    raise errors[i]
        tau[~ok] = 0.0
        relative[~ok] = math.inf
        return Evaluation(tau, ok, errors, lambda: self.joints_at(positions)[0],
                          positions[:, m.active_index], residual, condition,
                          relative), new_state

    def positions(self, state: 'State', qa: FloatArray, on_invalid: str,
                  invalid: BoolArray | None = None, qd: FloatArray | None = None,
                  qdd: FloatArray | None = None
                  ) -> tuple[Any, FloatArray, BoolArray, list[Any], 'State']:
        """Solve N samples of active coordinates ``qa`` (N, M) from the warm start ``state``.

        Returns (PoseRecord of arrays at the solutions, with the rates ``qd``, ``qdd``
        (default zeros); positions (N, n_joints), ok (N,), errors list, new state)."""
        m = self.mechanism
        n = len(qa)
        qd = np.zeros_like(qa) if qd is None else qd
        qdd = np.zeros_like(qa) if qdd is None else qdd
        if n == 0:
            empty = np.zeros((0, m.n_coordinates))
            flat = self.whole_many(empty, qa, qd, qdd)
            return self.record(flat), empty, np.zeros(0, bool), [], state
        invalid = np.zeros(n, bool) if invalid is None else invalid
        knots = self.anchors(state, qa, invalid)                       # 1. serial anchors
        guess = self.interpolated_starts(state, qa, *knots)             # 2. starts, closed
        positions, flat, converged, mismatch, closed = self.close(guess, qa, qd, qdd)
        record = self.record(flat)
        basis = _Bases(self.serial.layout, record.basis)
        ok = (converged & (record.condition <= m.max_condition_number) &
              (mismatch <= m.setpoint_tolerance) & ~invalid)
        ok &= self.continues(state, qa, positions, closed, record.basis, ok)  # 3. serial rules
        errors: list[Any] = [None] * n
        redone = self.resolve_serially(state, qa, positions, basis, ok, invalid, errors,
                                       on_invalid)
        new_state = self.finish(state, (qa, qd, qdd), flat, positions, basis, ok, redone)
        return record, positions, ok, errors, new_state

    def anchors(self, state: 'State', qa: FloatArray,
                invalid: BoolArray) -> tuple[IntArray, FloatArray, FloatArray]:
        """Step 1: serial anchors every continuation step of actuator travel, each solved
        from the last (an anchor that fails is left out). Returns the knots of step 2:
        their sample indices (-1: the warm start, the first knot), poses and bases."""
        m = self.mechanism
        limits = np.array(self.serial.limits)
        start = np.array([state[0][j] for j in m.active_index])
        travel = np.max(np.abs(np.diff(np.vstack([start, qa]), axis=0)) /
                        limits[m.active_index], axis=1)
        arc = np.cumsum(travel)
        is_anchor = np.diff(np.concatenate([[0.0], np.floor(arc)])) > 0
        is_anchor[-1] = True
        is_anchor &= ~invalid
        knots_at: list[Any]             # -1, then the anchors' np.intp indices
        knots_at, knots_q, knots_v, walk = [-1], [state[0]], [state[1]], state
        for a in np.flatnonzero(is_anchor):
            try:
                walk = self.serial.solve(walk, qa[a].tolist(), sample=int(a))[1]
            except CogIdError:
                continue
            knots_at.append(a)
            knots_q.append(walk[0])
            knots_v.append(walk[1])
        return np.array(knots_at), np.array(knots_q), np.array(knots_v)

    def interpolated_starts(self, state: 'State', qa: FloatArray, knots_at: IntArray,
                            knots_q: FloatArray, knots_v: FloatArray) -> FloatArray:
        """Step 2: a start for every sample between its neighbouring anchors (the knots):
        the cubic Hermite interpolation in the sample index of the anchors' poses and rates
        dq/di = V dz/di (dz/di by central differences of the setpoints), fourth order in the
        anchors' spacing for any number of actuators. (A blend of first-order predictions,
        exact to third order along one actuator, left the Stewart platform's starts 5e-4
        off: three or four Newton passes; now 1e-5, two or three.) Returns (N, n_joints)."""
        m = self.mechanism
        n = len(qa)
        start = np.array([state[0][j] for j in m.active_index])
        index = np.arange(n)
        nxt = np.minimum(np.searchsorted(knots_at, index), len(knots_at) - 1)
        prv = np.maximum(nxt - 1, 0)
        prv = np.where(knots_at[nxt] == index, nxt, prv)
        span = (knots_at[nxt] - knots_at[prv]).astype(float)
        with np.errstate(divide='ignore', invalid='ignore'):
            s = np.where(span > 0, (index - knots_at[prv]) / span, 0.0)
        s = np.clip(s, 0.0, 1.0)[:, None]
        z = qa[:, m.primary]
        turns = np.array([m.active_kinds[a].wraps for a in m.primary])
        setpoints = np.vstack([start[m.primary][None, :], z])      # row 0: the warm start
        lo, hi = np.maximum(knots_at - 1, -1), np.minimum(knots_at + 1, n - 1)
        dz = _wrapped(setpoints[hi + 1] - setpoints[lo + 1], turns) / (hi - lo)[:, None]
        knots_rate = np.einsum('kjd,kd->kj', knots_v, dz)
        s2, s3 = s * s, s * s * s
        guess = ((2.0 * s3 - 3.0 * s2 + 1.0) * knots_q[prv] +
                 (s3 - 2.0 * s2 + s) * span[:, None] * knots_rate[prv] +
                 (3.0 * s2 - 2.0 * s3) * knots_q[nxt] +
                 (s3 - s2) * span[:, None] * knots_rate[nxt])
        # the actuators' interpolation error, taken off to first order by the nearer
        # anchor's basis (a coordinate linear in the actuators, as in a parallelogram,
        # is then exact)
        near = np.where(s[:, 0] < 0.5, prv, nxt)
        guess += _by_knot(knots_v, near, _wrapped(z - guess[:, m.primary_joints], turns))
        guess[:, m.primary_joints] = z
        return guess

    def finish(self, state: 'State', setpoints: Sequence[FloatArray], flat: FloatArray,
               positions: FloatArray, basis: '_Bases', ok: BoolArray,
               redone: BoolArray) -> 'State':
        """Step 4: the new warm start (the last good sample's pose and basis), the poses of
        the samples not ok set to it (keeps NaN out of their lanes), and the flat dynamics
        outputs evaluated again where the poses changed. Returns the new state."""
        good = np.flatnonzero(ok)
        if good.size:
            last = good[-1]
            positions[~ok] = positions[last]
            new_state = (positions[last].tolist(), basis[last].tolist())
        else:
            positions[:] = state[0]
            new_state = state
        changed = np.flatnonzero(redone | ~ok)
        if changed.size:
            flat[changed] = self.whole_many(positions[changed], *(x[changed] for x in setpoints))
        return new_state

    def close(self, guess: FloatArray, qa: FloatArray, qd: FloatArray, qdd: FloatArray
              ) -> tuple[FloatArray, FloatArray, BoolArray, FloatArray, FloatArray]:
        """Newton on every sample at once from ``guess`` (N, n_joints), then for redundant
        actuation the projection onto the setpoints ``qa``, then closed further where the
        conditioning needs it (:meth:`refine`). Returns (positions, flat dynamics outputs
        there, converged (N,), redundant mismatch (N,), the poses Newton closed before the
        projection)."""
        m = self.mechanism
        q, converged = self.newton(guess)
        flat = self.whole_many(q, qa, qd, qdd)
        converged &= self.closed(self.record(flat))     # (after the last increment too)
        if not m.is_redundant:
            self.refine(q, flat, qa, qd, qdd, converged)
            return q, flat, converged, np.zeros(len(q)), q
        closed = q.copy()
        converged &= self.within_reach(q, self.record(flat), qa)
        for _ in range(PROJECTION_ITERATIONS):      # each sample until its increment is small
            record = self.record(flat)
            todo = np.flatnonzero(converged & (np.abs(record.projection).max(axis=1) >=
                                               PROJECTION_TOLERANCE))
            if not todo.size:
                break
            part = self.record(flat[todo])
            basis = self.serial.layout.array(part.basis)
            moved = projected_pose(m, columns(q[todo]),
                                   [columns(row) for row in basis.swapaxes(0, 1)],
                                   columns(part.projection))
            q[todo], converged[todo] = self.newton(np.column_stack(moved))
            flat[todo] = self.whole_many(q[todo], qa[todo], qd[todo], qdd[todo])
            converged[todo] &= self.closed(self.record(flat[todo]))
        self.refine(q, flat, qa, qd, qdd, converged)
        return q, flat, converged, np.abs(q[:, m.active_index] - qa).max(axis=1), closed

    def within_reach(self, q: FloatArray, record: Any, qa: FloatArray) -> BoolArray:
        """(N,) bool: each redundant setpoint of ``qa`` is within the reach of the projection
        from its closed pose ``q`` (sample_solve.reach; the others are refused serially)."""
        m = self.mechanism
        error = np.abs(q[:, m.active_index] - qa).max(axis=1)
        far = np.flatnonzero(~(error <= PROJECTION_REACH * m.setpoint_tolerance))
        out = np.ones(len(q), bool)
        if far.size:
            rows = self.serial.layout.array(record.basis[far])[:, m.active_index, :]
            limit = PROJECTION_REACH * (1.0 + np.abs(rows).sum(axis=2).max(axis=1)) * \
                m.setpoint_tolerance
            out[far] = error[far] <= limit
        return out

    def refine(self, q: FloatArray, flat: FloatArray, qa: FloatArray, qd: FloatArray,
               qdd: FloatArray, converged: BoolArray) -> None:
        """The closed poses ``q`` (their flat outputs ``flat``, both updated in place) closed
        further where the conditioning needs it, as SampleSolver.refined does one: a Newton
        increment at a time while the estimated relative error exceeds newton.ACCURACY_FACTOR
        times the tolerance and the increment shrinks. (Newton's last increment has closed them to
        rounding almost everywhere: this is for the poses near a singular one.)"""
        if not self.serial.refine:
            return
        m = self.mechanism
        redundant = m.is_redundant
        target = self.serial.accuracy
        record = self.record(flat)
        with np.errstate(all='ignore'):
            todo = np.flatnonzero(converged & (relative_error(increment_left(record, redundant),
                                                              record.condition) > target))
            for _ in range(REFINE_ITERATIONS):
                if not todo.size:
                    break
                part = self.record(flat[todo])
                moved = q[todo]
                moved[:, m.free_joints] -= part.increment
                if redundant:
                    basis = self.serial.layout.array(part.basis)
                    moved = np.column_stack(projected_pose(
                        m, columns(moved), [columns(row) for row in basis.swapaxes(0, 1)],
                        columns(part.projection)))
                better = self.whole_many(moved, qa[todo], qd[todo], qdd[todo])
                new = self.record(better)
                size = increment_left(new, redundant)
                took = (size < increment_left(part, redundant)) & self.closed(new)
                q[todo[took]], flat[todo[took]] = moved[took], better[took]
                todo = todo[took][relative_error(size[took], new.condition[took]) > target]

    def newton(self, q: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Newton's method on the loop equations of all samples at once, by the closure
        kernel: each pass evaluates the samples not closed yet. A sample found closed takes
        the increment evaluated with that check too (it costs nothing and makes the pose
        exact to rounding), and no more passes; so does one whose increment was below
        :meth:`exact_step` (Newton's error after a step is of the order of the step squared:
        the pose is then closed to rounding). Either way the caller checks the closure
        again in the dynamics record at the final pose (:meth:`close`). Returns
        (positions, converged (N,))."""
        free, kernels = self.mechanism.free_joints, self.kernels
        exact = self.exact_step()
        q = np.array(q, dtype=float)
        converged = np.zeros(len(q), bool)
        todo = np.arange(len(q))
        for iteration in range(NEWTON_ITERATIONS + 1):
            record = unpack(kernels.closure_many(q[todo]), kernels.layouts['closure'],
                            ClosureRecord)
            done = self.closed(record)
            converged[todo[done]] = True
            size = record.largest_step
            if iteration == NEWTON_ITERATIONS:
                done[:] = True            # the last pass: every sample stops where it is
                record = record._replace(increment=np.where(
                    converged[todo][:, None], record.increment, 0.0))
                size = np.where(converged[todo], size, 0.0)
            else:                         # closed to rounding once this increment is taken
                small = ~done & (size < exact)
                converged[todo[small]] = True
                done |= small
            with np.errstate(divide='ignore', invalid='ignore'):
                factor = np.where(size > NEWTON_MAX_INCREMENT, NEWTON_MAX_INCREMENT / size, 1.0)
            factor = np.where(np.isfinite(factor), factor, 0.0)
            # (numpy's stubs take arrays only; ix_ takes a list of ints as well)
            q[np.ix_(todo, free)] -= record.increment * factor[:, None]  # type: ignore[arg-type]
            todo = todo[~done]
            if not todo.size:
                break
        return q, converged

    def exact_step(self) -> float:
        """A Newton increment below which the pose it leads to is closed to well within
        the closure tolerance: 0.01 sqrt(tolerance) (rad or m; 1e-7 at the default 1e-10).
        After an increment s the residual is about C s^2, C the loops' curvature (about 1
        per metre on the Stewart platform): this leaves room for C up to 1e4."""
        return 0.01 * math.sqrt(self.mechanism.closure_tolerance)

    def closed(self, record: Any) -> BoolArray:
        """(N,) bool: the loops of each sample are closed (closure.loops_closed)."""
        return closure.loops_closed(record.worst, record.least_cosine,
                                    self.mechanism.closure_tolerance)

    def record(self, flat: FloatArray) -> Any:
        return unpack(flat, self.layout, self.record_type)

    def continues(self, start_state: 'State', qa: FloatArray, positions: FloatArray,
                  closed: FloatArray, free_rows: FloatArray, candidates: BoolArray) -> BoolArray:
        """(N,) bool: each of the ``candidates`` is where the serial path takes it in one
        step from sample i-1 (``positions``; the warm start for i = 0): one continuation step
        away, and Newton's method from the first-order prediction, the serial step, closes
        the loops at ``closed`` (the batch's pose before any redundant projection), within
        the Newton correction bound of the prediction. (The bound alone does not say which
        pose the step reaches: near a singular pose two branches can both be that close.)
        ``free_rows``: the velocity basis rows of the free joints (N, n_free, dof); the
        primary actuators' rows are unit rows, so they move by dz."""
        m = self.mechanism
        free = m.free_joints
        limits, bounds = np.array(self.serial.limits), np.array(self.serial.bounds)
        prev_q = np.vstack([np.asarray(start_state[0], float)[None, :], positions[:-1]])
        dz = qa[:, m.primary] - prev_q[:, m.primary_joints]
        moved = np.empty((len(qa), len(free)))
        moved[0] = np.asarray(start_state[1], float)[free] @ dz[0]
        moved[1:] = np.matmul(free_rows[:-1], dz[1:, :, None])[:, :, 0]
        predicted = prev_q
        predicted[:, free] += moved
        predicted[:, m.primary_joints] = qa[:, m.primary]
        near = np.abs(dz) <= limits[m.primary_joints]              # as fits_one_step
        one = (candidates & near.all(axis=1) & (np.abs(moved) <= limits[free]).all(axis=1) &
               (np.abs(closed - predicted) <= bounds).all(axis=1))
        if one.all():                           # the serial step, on every sample at once
            return self.reaches(predicted, closed, limits)
        rows = np.flatnonzero(one)
        if rows.size:
            one[rows] = self.reaches(predicted[rows], closed[rows], limits)
        return one

    def reaches(self, q: FloatArray, pose: FloatArray, limits: FloatArray) -> BoolArray:
        """(N,) bool: Newton's method from ``q`` (N, n_joints; moved in place) closes the
        loops at ``pose``. Its first increment, on every sample, ends within SAME_POSE of the
        pose almost always (from a first-order prediction it is quadratically close): that
        pose is where the next ones converge; Newton goes on only from the others."""
        kernels, free = self.kernels, self.mechanism.free_joints
        record = unpack(kernels.closure_many(q), kernels.layouts['closure'], ClosureRecord)
        size = record.largest_step
        with np.errstate(divide='ignore', invalid='ignore'):
            factor = np.where(size > NEWTON_MAX_INCREMENT, NEWTON_MAX_INCREMENT / size, 1.0)
        factor = np.where(np.isfinite(factor), factor, 0.0)
        q[:, free] -= record.increment * factor[:, None]
        same: BoolArray = np.all(np.abs(q - pose) <= SAME_POSE * limits, axis=1)
        rest = np.flatnonzero(~same)
        if rest.size:
            reached, converged = self.newton(q[rest])
            same[rest] = converged & (np.abs(reached - pose[rest]) <=
                                      SAME_POSE * limits).all(axis=1)
        return same

    def resolve_serially(self, start_state: 'State', qa: FloatArray, positions: FloatArray,
                         basis: '_Bases', ok: BoolArray, invalid: BoolArray, errors: list[Any],
                         on_invalid: str) -> BoolArray:
        """Re-solve, in order, every sample not ``ok`` by serial continuation from the last
        good sample before it; a sample after one that changed is solved serially again
        too, and stands as the batch found it (closed to rounding) where the serial path
        finds the same pose. Updates the arrays in place; returns the (N,) mask of the
        samples re-solved."""
        pending = [int(i) for i in np.flatnonzero(~ok)]
        heapq.heapify(pending)
        last_good, last_done = -1, -1
        redone = np.zeros(len(ok), bool)
        while pending:
            i = heapq.heappop(pending)
            if i <= last_done:
                continue
            if last_done != i - 1:     # the samples before i were good as they were
                last_good = i - 1
            last_done = i
            previous = start_state if last_good < 0 else \
                (positions[last_good].tolist(), basis[last_good].tolist())
            if invalid[i]:
                if i + 1 < len(ok):
                    heapq.heappush(pending, i + 1)
                continue
            before = positions[i].copy()
            try:
                solved, solved_basis = self.serial.solve(previous, qa[i].tolist(), sample=i)[1]
            except CogIdError as exc:
                errors[i], ok[i] = exc, False
                if on_invalid == 'raise':
                    raise
            else:
                if ok[i] and self.same_pose(solved, before):
                    last_good = i              # still continues from its new predecessor
                    continue
                positions[i], basis[i] = solved, solved_basis
                ok[i], redone[i], last_good = True, True, i
                if np.max(np.abs(positions[i] - before)) <= 1e-9:
                    continue                    # the same pose: the samples after it stand
            if i + 1 < len(ok):
                heapq.heappush(pending, i + 1)
        return redone

    def same_pose(self, solved: Sequence[float], pose: FloatArray) -> bool:
        """True when the serial path's pose ``solved`` of a sample is the batch's ``pose``
        (within SAME_POSE of the step limits: the serial one is closed to the tolerance)."""
        return bool((np.abs(np.asarray(solved) - pose) <=
                     SAME_POSE * np.asarray(self.serial.limits)).all())


def _wrapped(dz: FloatArray, revolute: BoolArray) -> FloatArray:
    """Actuator differences (N, dof), those of revolute ones (mask) within pi (a warm start
    may be whole turns away from the setpoints)."""
    return np.where(revolute, dz - 2.0 * np.pi * np.round(dz / (2.0 * np.pi)), dz)


def _by_knot(bases: FloatArray, knot: IntArray, dz: FloatArray) -> FloatArray:
    """V_k dz of every sample, V_k = bases[knot[i]] (K, n_joints, dof), knot non-decreasing:
    one product per run of samples that share a knot, no (N, n_joints, dof) copy."""
    out = np.empty((len(dz), bases.shape[1]))
    starts = np.concatenate([[0], np.flatnonzero(np.diff(knot)) + 1, [len(dz)]])
    for a, b in zip(starts[:-1], starts[1:]):
        out[a:b] = dz[a:b] @ bases[knot[a]].T
    return out


class _Bases:
    """The velocity bases V (n_joints, dof) of N samples, made per sample when asked for
    from the records' free rows (N, n_free, dof); re-solved samples' bases as set."""

    def __init__(self, layout: 'BasisLayout', free_rows: FloatArray) -> None:
        self.solved: dict[int, FloatArray] = {}
        self.layout, self.free_rows = layout, free_rows

    def __getitem__(self, i: int) -> FloatArray:
        if i in self.solved:
            return self.solved[i]
        return self.layout.array(self.free_rows[i])

    def __setitem__(self, i: int, basis: FloatArray) -> None:
        self.solved[i] = np.asarray(basis, dtype=float)
