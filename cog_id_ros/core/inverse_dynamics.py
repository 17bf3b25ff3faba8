"""The paper's eqs. (6)-(7) and the solver users call.

    tau_mi = G_i^T F_i                                           (6)  link i's share
    tau_m  = sum_i G_i^T F_i = H(theta_m) thetaddot_m + B(theta_m, thetadot_m)   (7)

``InverseDynamics`` strings the steps together for a sample or a batch of samples:
closure (closure.py) -> joint rates (joint_motion.py) -> COG Jacobians and drifts
(cog_jacobian.py, eqs. 1-4) -> Newton-Euler forces (newton_euler.py, eq. 5) -> eq. (6)-(7).

One sample runs on Python floats (lean enough for a control loop); a batch runs the very
same code on numpy arrays of shape (N,), vectorised over samples. Successive calls keep
the assembly branch: each solve is warm-started from the previous one.
"""
import math

import numpy as np

from . import closure
from . import spatial as sp
from .cog_jacobian import cog_accelerations, cog_drifts, cog_jacobians, cog_poses, cog_velocities
from .errors import ClosureError, CogIdError, SetpointError, SingularConfigurationError
from .joint_motion import (active_velocity_map, closure_drift, combine, projection_gram,
                           velocity_basis)
from .kinematics import link_bias_accelerations, link_twists
from .lane_linalg import solve_spd
from .newton_euler import newton_euler_force, rotated_inertia_times
from .sample_program import SampleProgram


def active_torques(jacobians, forces):
    """tau = sum_i G_i^T F_i (eqs. 6-7); links with force None (massless) contribute nothing."""
    m = len(jacobians[0]) if jacobians else 0
    tau = [0.0] * m
    for cols, force in zip(jacobians, forces):
        if force is None:
            continue
        f, n = force
        for a, (gv, gw) in enumerate(cols):
            tau[a] = tau[a] + sp.dot(gv, f) + sp.dot(gw, n)
    return tau


def inertia_matrix(mechanism, cogs, jacobians):
    """H = sum_i G_i^T M_i G_i (eq. 7), as a list of rows of lanes."""
    m = len(mechanism.active_joints)
    h = [[0.0] * m for _ in range(m)]
    for i, cols in enumerate(jacobians):
        mass, inertia = mechanism.link_mass[i], mechanism.link_inertia[i]
        if _massless(mass, inertia):
            continue
        rot = cogs[i][1]
        for b, (gv_b, gw_b) in enumerate(cols):
            f = sp.scale(gv_b, mass)
            n = rotated_inertia_times(rot, inertia, gw_b)
            for a in range(b, m):
                gv_a, gw_a = cols[a]
                h[a][b] = h[a][b] + sp.dot(gv_a, f) + sp.dot(gw_a, n)
    for a in range(m):
        for b in range(a + 1, m):
            h[a][b] = h[b][a]
    return h


def _massless(mass, inertia):
    return mass == 0.0 and not any(inertia)


class Evaluation:
    """Result of InverseDynamics.evaluate, always batch-shaped (N = 1 for one sample).

    torques (N, M): active-joint torques/forces, 0.0 in rows that are not valid (never NaN)
    valid (N,): bool
    errors: list of N entries, None or the exception that made the sample invalid
    positions (N, n_joints): every joint coordinate, mechanism.joints order
    active_positions (N, M): the active coordinates used (projected for redundant actuation)
    closure_residual (N,): max |closure equation| at the solution
    condition_number (N,): closure Jacobian condition number (see mechanism.max_condition_number)
    """

    def __init__(self, torques, valid, errors, positions, active_positions, residual, condition):
        self.torques = torques
        self.valid = valid
        self.errors = errors
        self.positions = positions
        self.active_positions = active_positions
        self.closure_residual = residual
        self.condition_number = condition


class _Step:
    """A solved configuration: closure solution, velocity basis, redundant mismatch, condition."""
    __slots__ = ('sol', 'basis', 'mismatch', 'condition')

    def __init__(self, sol, basis, mismatch, condition):
        self.sol, self.basis, self.mismatch, self.condition = sol, basis, mismatch, condition


class InverseDynamics:
    """Active-joint torques of a closed-link mechanism by per-link COG Jacobians.

    All arrays are in ``mechanism.active_joints`` order; shapes (M,) for one sample or
    (N, M) for N samples. Angles are never wrapped.
    """

    #: largest step (rad or m, any actuator) taken at once; longer moves are followed in
    #: steps of this size so that the solver stays on the assembly branch it is on
    continuation_step = 0.1
    #: largest change of any joint coordinate (rad or m) between the interpolated start and
    #: the solution, in the vectorised batch solve, before a sample is re-solved serially
    batch_jump_limit = 0.5

    def __init__(self, mechanism):
        self.mechanism = mechanism
        self._program = _sample_program(self)
        self.reset()

    def reset(self):
        """Forget the previous calls: the next one starts from the assembled initial_positions."""
        m = self.mechanism
        sol = closure.solve_closure(m.model, list(m.assembled_positions), m.free_joints,
                                    sp.ScalarOps, m.closure_tolerance)
        self._state = (sol.q, velocity_basis(m, sol))

    # --- public API -------------------------------------------------------------------------

    def torques(self, q, qd=None, qdd=None):
        """tau = H(q) qdd + B(q, qd) for the active joints: (M,) or (N, M).

        Raises ClosureError, SingularConfigurationError or SetpointError for the first sample
        that cannot be served (``.sample`` is its index); the warm start is then unchanged.
        """
        sample = self._one_sample(q, qd, qdd)
        if sample is not None:                       # the control-rate path: plain floats
            done = self._program_serial(*sample)      # straight-line code (sample_program.py)
            if done is not None:
                return np.array(done)
            step = self._solve_serial(sample[0])
            return np.array(self._torques(step, sample[1], sample[2], sp.ScalarOps))
        q, qd, qdd, single = self._inputs(q, qd, qdd)
        if single:
            _, errors = self._check_finite(q, qd, qdd, single)
            if errors:
                raise errors[0]
            step = self._solve_serial(q[0].tolist())
            return np.array(self._torques(step, qd[0].tolist(), qdd[0].tolist(), sp.ScalarOps))
        return self._evaluate(q, qd, qdd, 'raise').torques

    def sample_torques(self, q, qd, qdd):
        """One sample at control rate: three sequences of M floats in, a list of M torques out.

        The same numbers, state and errors as :meth:`torques` on one sample, without the
        numpy round trip or the input checks that the straight-line code makes anyway (a
        NaN, an infinity or a wrong length goes to :meth:`torques`, which says what is
        wrong). This is what cog_id_node calls for every setpoint.
        """
        program = self._program
        if program is not None and program.step is not None:
            try:
                n = len(self.mechanism.active_joints)
                if len(q) == len(qd) == len(qdd) == n:
                    done = program.step(self._state, q, qd, qdd, self.continuation_step)
                    if done is not None:
                        self._state = done[1]
                        return done[0]
            except TypeError:      # None or a non-number somewhere: torques() reports it
                pass
        return self.torques(q, qd, qdd).tolist()

    def evaluate(self, q, qd=None, qdd=None, on_invalid='raise'):
        """Torques with per-sample status (an Evaluation). on_invalid='skip' marks samples that
        cannot be served as invalid instead of raising; the others are computed as usual."""
        if on_invalid not in ('raise', 'skip'):
            raise ValueError(f"on_invalid must be 'raise' or 'skip', got {on_invalid!r}")
        q, qd, qdd, _ = self._inputs(q, qd, qdd)
        return self._evaluate(q, qd, qdd, on_invalid)

    def solve_positions(self, q):
        """Every joint coordinate (mechanism.joints order): (n_joints,) or (N, n_joints)."""
        q, _, _, single = self._inputs(q, None, None)
        if single:
            return np.array(self._solve_serial(q[0].tolist()).sol.q)
        return self._solve_batch(q, 'raise')[1]

    def cog_poses(self, q):
        """g_i (eq. 1): (positions (..., n_links, 3), rotations (..., n_links, 3, 3))."""
        def compute(step, ops):
            poses = cog_poses(self.mechanism, step.sol.frames)
            return [list(c) for c, _ in poses], [list(r) for _, r in poses]
        positions, rotations = self._per_sample(q, compute)
        return positions, rotations.reshape(rotations.shape[:-1] + (3, 3))

    def cog_jacobians(self, q):
        """G_i (eq. 3): (n_links, 6, M) or (N, n_links, 6, M); rows vx vy vz wx wy wz of the
        COG (linear) and the link (angular), base frame."""
        def compute(step, ops):
            _, _, jac = self._cog_jacobians(step, ops)
            return ([[[gv[r] for gv, _ in cols] for r in range(3)] +
                     [[gw[r] for _, gw in cols] for r in range(3)] for cols in jac],)
        return self._per_sample(q, compute)[0]

    def cog_drifts(self, q, qd):
        """Gdot_i thetadot (eq. 4): (n_links, 6) or (N, n_links, 6): COG acceleration and link
        angular acceleration when thetaddot = 0."""
        def compute(step, ops, qd_lanes):
            s, cogs, jac = self._cog_jacobians(step, ops)
            _, drifts = self._cog_motion(step, s, cogs, jac, qd_lanes, ops)
            return ([list(a) + list(alpha) for a, alpha in drifts],)
        return self._per_sample(q, compute, qd)[0]

    def equation_of_motion(self, q, qd=None):
        """H (M, M) and B (M,) of eq. (7), tau = H qdd + B; batch: (N, M, M), (N, M)."""
        def compute(step, ops, qd_lanes):
            s, cogs, jac = self._cog_jacobians(step, ops)
            drift_forces = self._drift_forces(step, s, cogs, jac, qd_lanes, ops)
            return inertia_matrix(self.mechanism, cogs, jac), active_torques(jac, drift_forces)
        return self._per_sample(q, compute, qd)

    # --- the pipeline on lanes ----------------------------------------------------------------

    def _cog_jacobians(self, step, ops):
        m = self.mechanism
        s = active_velocity_map(m, step.basis, ops)
        cogs = cog_poses(m, step.sol.frames)
        jac, _ = cog_jacobians(m, step.sol.frames, cogs, s)
        return s, cogs, jac

    def _cog_motion(self, step, s, cogs, jac, qd, ops):
        """COG velocities (eq. 2) and drifts Gdot_i thetadot (eq. 4, thetaddot = 0)."""
        m = self.mechanism
        model, sol = m.model, step.sol
        qdot = combine(s, qd)
        twists = link_twists(model, sol.frames, qdot)
        bias = link_bias_accelerations(model, sol.frames, twists, qdot)
        beta = closure.closure_bias(model, sol.frames, sol.loops, twists, bias, qdot)
        drift = closure_drift(m, sol, s, beta)
        drift_twists = link_twists(model, sol.frames, drift)
        drift_acc = [sp.twist_add_scaled(b, d, 1.0) for b, d in zip(bias, drift_twists)]
        velocities = cog_velocities(jac, qd)
        return velocities, cog_drifts(cogs, velocities, drift_acc)

    def _drift_forces(self, step, s, cogs, jac, qd, ops, qdd=None):
        """F_i of eq. (5) with the COG accelerations of eq. (4) (thetaddot = qdd, or 0)."""
        m = self.mechanism
        velocities, accelerations = self._cog_motion(step, s, cogs, jac, qd, ops)
        if qdd is not None:
            accelerations = cog_accelerations(jac, accelerations, qdd)
        forces = []
        for i, ((a, alpha), (_, w)) in enumerate(zip(accelerations, velocities)):
            mass, inertia = m.link_mass[i], m.link_inertia[i]
            forces.append(None if _massless(mass, inertia) else
                          newton_euler_force(mass, inertia, cogs[i][1], m.gravity, a, w, alpha))
        return forces

    def _torques(self, step, qd, qdd, ops):
        s, cogs, jac = self._cog_jacobians(step, ops)
        return active_torques(jac, self._drift_forces(step, s, cogs, jac, qd, ops, qdd))

    def _pipeline(self, sol, basis, condition, qd, qdd, ops):
        """Eqs. (1)-(7) at a closure solution (what sample_program.py traces)."""
        return self._torques(_Step(sol, basis, 0.0, condition), qd, qdd, ops)

    # --- inputs ---------------------------------------------------------------------------

    def _inputs(self, q, qd, qdd):
        names = self.mechanism.active_joints
        arrays = []
        for label, value in (('q', q), ('qd', qd), ('qdd', qdd)):
            if value is None:
                arrays.append(None)
                continue
            try:
                array = np.asarray(value, dtype=float)
            except (TypeError, ValueError) as exc:
                raise SetpointError(f'{label}: not numeric ({exc})') from exc
            arrays.append(array)
        single = arrays[0].ndim == 1
        out = []
        for label, array in zip(('q', 'qd', 'qdd'), arrays):
            if array is None:
                out.append(np.zeros((1 if single else arrays[0].shape[0], len(names))))
                continue
            if array.ndim != (1 if single else 2) or array.shape[-1] != len(names) or \
                    (not single and array.shape[0] != arrays[0].shape[0]):
                expected = f'({len(names)},)' if single else f'({arrays[0].shape[0]}, {len(names)})'
                raise SetpointError(
                    f'{label}: expected shape {expected} (active joints {names}), got {array.shape}')
            out.append(array.reshape(1, -1) if single else array)
        return out[0], out[1], out[2], single

    def _one_sample(self, q, qd, qdd):
        """(q, qd, qdd) as lists of finite floats when they are one well-formed sample, else
        None (the general path then reports what is wrong)."""
        m = len(self.mechanism.active_joints)
        out = []
        for value in (q, qd, qdd):
            if value is None:
                out.append([0.0] * m)
                continue
            if type(value) is np.ndarray:            # a row of a float array: one C call
                if value.ndim != 1 or value.dtype.kind != 'f':
                    return None
                floats = value.tolist()
            else:
                if getattr(value, 'ndim', 1) != 1:
                    return None
                try:
                    floats = [float(x) for x in value]
                except (TypeError, ValueError):
                    return None
            if len(floats) != m or not all(map(math.isfinite, floats)):
                return None
            out.append(floats)
        return out

    def _check_finite(self, q, qd, qdd, single):
        """SetpointError for the first non-finite entry; else None. Per sample: a bool array."""
        finite = np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) & np.isfinite(qdd).all(axis=1)
        errors = {}
        for i in np.flatnonzero(~finite):
            for label, array in (('q', q), ('qd', qd), ('qdd', qdd)):
                bad = np.flatnonzero(~np.isfinite(array[i]))
                if bad.size:
                    joint = self.mechanism.active_joints[bad[0]]
                    where = f'{label} of {joint}' if single else f'sample {i}: {label} of {joint}'
                    errors[int(i)] = SetpointError(
                        f'{where} is {array[i, bad[0]]}: setpoints must be finite', sample=int(i),
                        reason='non_finite')
                    break
        return finite, errors

    # --- positions: one sample -------------------------------------------------------------

    def _solve_serial(self, target, sample=None):
        """Solve one sample from the warm start, in continuation steps if it is far away."""
        q, basis = self._state
        goals = self._continuation_goals(target)
        if goals is None:
            raise SetpointError('setpoints must be finite', sample=sample, reason='non_finite')
        for k, goal in enumerate(goals, 1):
            step = self._closure_step(q, basis, goal, sp.ScalarOps)
            self._check(step, k == len(goals), sample)
            q, basis = step.sol.q, step.basis
        self._state = (q, basis)
        return step

    def _continuation_goals(self, target):
        """The active setpoints to solve in turn from the warm start to ``target``: steps of
        at most ``continuation_step``, ``target`` last; None if the distance is not finite."""
        q = self._state[0]
        start = [q[j] for j in self.mechanism.active_index]
        distance = max(abs(t - s) for t, s in zip(target, start))
        if not distance < math.inf:
            return None
        n_steps = max(1, math.ceil(distance / self.continuation_step - 1e-9))
        return [[s + (t - s) * (k / n_steps) for s, t in zip(start, target)]
                for k in range(1, n_steps)] + [target]

    def _program_serial(self, target, qd, qdd):
        """_solve_serial and the torques by the straight-line code, through the same
        continuation steps; None (and the state unchanged) when it cannot serve a step."""
        if self._program is None:
            return None
        step = self._program.step
        if step is not None:        # the usual sample: one goal, at most two Newton steps
            done = step(self._state, target, qd, qdd, self.continuation_step)
            if done is not None:
                tau, self._state = done
                return tau
        goals = self._continuation_goals(target)
        if goals is None:
            return None
        state = self._state
        for goal in goals:
            done = self._program.torques(state, goal, qd, qdd)
            if done is None:
                return None
            tau, state = done
        self._state = state
        return tau

    def _serial_positions(self, target, sample):
        """Every joint coordinate at one sample (as _solve_serial.sol.q), by the straight-line
        code when it can serve the sample."""
        zeros = [0.0] * len(target)
        if self._program_serial(target, zeros, zeros) is not None:
            return self._state[0]
        return self._solve_serial(target, sample=sample).sol.q

    def _closure_step(self, q, basis, target, ops):
        """Close the loops with the primary actuators at ``target``, from ``q`` advanced by the
        velocity basis (first-order predictor; skipped when basis is None); then, for redundant
        actuation, move to the nearest configuration (W^-1 metric) to the full target."""
        m = self.mechanism
        q = list(q)
        if basis is not None:
            dz = [target[a] - q[j] for a, j in zip(m.primary, m.primary_joints)]
            q = [x + sum(b * d for b, d in zip(row, dz)) for x, row in zip(q, basis)]
        for a, j in zip(m.primary, m.primary_joints):
            q[j] = target[a]
        sol = closure.solve_closure(m.model, q, m.free_joints, ops, m.closure_tolerance)
        basis = velocity_basis(m, sol)
        mismatch = 0.0
        if m.is_redundant:
            sol, basis, mismatch = self._project_redundant(sol, basis, target, ops)
        return _Step(sol, basis, mismatch, sol.lsq.condition_number())

    def _project_redundant(self, sol, basis, target, ops, max_iter=6):
        """Gauss-Newton on min (q_a - target)^T W^-1 (q_a - target) over closed configurations."""
        m = self.mechanism
        scalar = ops is sp.ScalarOps
        for _ in range(max_iter):
            error = [sol.q[j] - t for j, t in zip(m.active_index, target)]
            gram, va_t_winv = projection_gram(m, basis, ops)
            rhs = [[sum(r * e for r, e in zip(row, error))] for row in va_t_winv]
            dz = [row[0] for row in solve_spd(gram, rhs, ops)]
            size = ops.maxabs(dz)
            if (size < 1e-14) if scalar else bool(np.all(size < 1e-14)):
                break
            q = [x - sum(b * d for b, d in zip(row, dz)) for x, row in zip(sol.q, basis)]
            for k, j in enumerate(m.primary_joints):
                q[j] = sol.q[j] - dz[k]
            sol = closure.solve_closure(m.model, q, m.free_joints, ops, m.closure_tolerance)
            basis = velocity_basis(m, sol)
        mismatch = ops.maxabs([sol.q[j] - t for j, t in zip(m.active_index, target)])
        return sol, basis, mismatch

    def _check(self, step, final, sample):
        m, sol = self.mechanism, step.sol
        where = '' if sample is None else f'sample {sample}: '
        if not sol.converged:
            raise ClosureError(
                f'{where}the loops cannot be closed at this setpoint: closure residual '
                f'{sol.residual:.3g} (tolerance {m.closure_tolerance:.3g}) after '
                f'{sol.iterations} Newton iterations', sol.residual, sample)
        if not step.condition <= m.max_condition_number:
            raise SingularConfigurationError(
                f'{where}singular configuration: closure Jacobian condition number '
                f'{step.condition:.3g} exceeds mechanism.max_condition_number '
                f'{m.max_condition_number:.3g}', step.condition, sample)
        if final and step.mismatch > m.setpoint_tolerance:
            raise ClosureError(
                f'{where}the redundant setpoint disagrees with the loop closure by '
                f'{step.mismatch:.3g} (rad or m), more than mechanism.setpoint_tolerance '
                f'{m.setpoint_tolerance:.3g}', step.mismatch, sample, reason='inconsistent')

    # --- positions: a batch ----------------------------------------------------------------

    def _solve_batch(self, qa, on_invalid, invalid=None):
        """Solve N samples as one trajectory: serial anchors every ``continuation_step`` of
        actuator travel, interpolation between them as the start of one vectorised Newton
        solve of all samples, and a serial re-solve of any sample that did not come out right.

        Returns (step on (N,) lanes, positions (N, n_joints), ok (N,), errors list)."""
        m = self.mechanism
        n = len(qa)
        start_state = self._state
        invalid = np.zeros(n, bool) if invalid is None else invalid
        start = np.array([start_state[0][j] for j in m.active_index])
        travel = np.max(np.abs(np.diff(np.vstack([start, qa]), axis=0)), axis=1)
        arc = np.cumsum(travel)
        bucket = np.floor(arc / self.continuation_step)
        is_anchor = np.diff(np.concatenate([[0.0], bucket])) > 0
        is_anchor[-1] = True
        is_anchor &= ~invalid
        anchors = np.flatnonzero(is_anchor)
        anchor_q, failed = {}, set()
        for a in anchors:
            try:
                anchor_q[a] = self._serial_positions(qa[a].tolist(), int(a))
            except CogIdError:
                failed.add(a)
        # interpolated start of every sample between its neighbouring anchors (by travel)
        known = [a for a in anchors if a not in failed]
        knots_at = np.array([-1] + known)
        knots_q = np.array([start_state[0]] + [anchor_q[a] for a in known])
        knots_arc = np.concatenate([[0.0], arc[known]]) if known else np.array([0.0])
        nxt = np.minimum(np.searchsorted(knots_at, np.arange(n)), len(knots_at) - 1)
        prv = np.maximum(nxt - 1, 0)
        prv = np.where(knots_at[nxt] == np.arange(n), nxt, prv)
        span = knots_arc[nxt] - knots_arc[prv]
        with np.errstate(divide='ignore', invalid='ignore'):
            lam = np.where(span > 0, (arc - knots_arc[prv]) / span, 1.0)
        lam = np.clip(lam, 0.0, 1.0)[:, None]
        guess = knots_q[prv] + lam * (knots_q[nxt] - knots_q[prv])
        suspect = invalid.copy()
        for a in failed:   # samples up to a failed anchor are re-solved serially
            lo = max([k for k in known if k < a], default=-1)
            suspect[lo + 1:a + 1] = True
        step = self._closure_step([guess[:, j] for j in range(len(m.joints))], None,
                                  [qa[:, a] for a in range(len(m.active_joints))], sp.ArrayOps)
        positions = np.column_stack(np.broadcast_arrays(*step.sol.q, np.zeros(n))[:-1])
        ok = (np.broadcast_to(step.sol.converged, (n,)) &
              (step.condition <= m.max_condition_number) &
              (np.broadcast_to(step.mismatch, (n,)) <= m.setpoint_tolerance) &
              (np.max(np.abs(positions - guess), axis=1) <= self.batch_jump_limit) & ~suspect)
        errors = [None] * n
        basis = np.stack([np.column_stack(np.broadcast_arrays(*row, np.zeros(n))[:-1])
                          for row in step.basis], axis=1)          # (N, n_joints, dof)
        redone = False
        for i in np.flatnonzero(~ok):
            if invalid[i]:
                continue
            good = np.flatnonzero(ok[:i])
            self._state = start_state if good.size == 0 else \
                (positions[good[-1]].tolist(), basis[good[-1]].tolist())
            try:
                serial = self._solve_serial(qa[i].tolist(), sample=int(i))
            except CogIdError as exc:
                errors[i] = exc
                if on_invalid == 'raise':
                    self._state = start_state
                    raise
                continue
            positions[i] = serial.sol.q
            basis[i] = serial.basis
            ok[i], redone = True, True
        good = np.flatnonzero(ok)
        if good.size:
            last = good[-1]
            positions[~ok] = positions[last]       # keep NaN out of the masked lanes
            self._state = (positions[last].tolist(), basis[last].tolist())
        else:
            positions[:] = start_state[0]
            self._state = start_state
        if redone or not ok.all():
            sol = closure.evaluate(m.model, [positions[:, j] for j in range(len(m.joints))],
                                   m.free_joints, sp.ArrayOps)
            step = _Step(sol, velocity_basis(m, sol), step.mismatch, sol.lsq.condition_number())
        return step, positions, ok, errors

    # --- evaluation ---------------------------------------------------------------------------

    def _evaluate(self, q, qd, qdd, on_invalid):
        m = self.mechanism
        n, n_act = q.shape
        single = n == 1
        finite, errors_in = self._check_finite(q, qd, qdd, single)
        if errors_in and on_invalid == 'raise':
            raise errors_in[min(errors_in)]
        if single:
            return self._evaluate_one(q, qd, qdd, errors_in.get(0), on_invalid)
        if n == 0:
            empty = np.zeros((0, n_act))
            return Evaluation(empty, np.zeros(0, bool), [], np.zeros((0, len(m.joints))),
                              empty, np.zeros(0), np.zeros(0))
        if not finite.all():   # fill bad rows with their neighbours so they do not disturb the rest
            q, qd, qdd = (np.where(finite[:, None], x, 0.0) for x in (q, qd, qdd))
            for i in np.flatnonzero(~finite):
                q[i] = q[i - 1] if i > 0 else [self._state[0][j] for j in m.active_index]
        with np.errstate(all='ignore'):
            step, positions, ok, errors = self._solve_batch(q, on_invalid, invalid=~finite)
            tau = self._torques(step, [qd[:, a] for a in range(n_act)],
                                [qdd[:, a] for a in range(n_act)], sp.ArrayOps)
            tau = np.column_stack(np.broadcast_arrays(*tau, np.zeros(n))[:-1])
            residual = np.broadcast_to(step.sol.residual, (n,)).copy()
            condition = np.broadcast_to(step.condition, (n,)).copy()
        for i, exc in errors_in.items():
            errors[i] = exc
        ok &= finite & np.isfinite(tau).all(axis=1)
        for i in np.flatnonzero(~ok):
            exc = errors[i]
            residual[i] = getattr(exc, 'residual', math.inf)
            condition[i] = getattr(exc, 'condition_number', math.inf)
            if exc is None:
                errors[i] = SingularConfigurationError(
                    f'sample {i}: torques are not finite here', math.inf, int(i))
                if on_invalid == 'raise':
                    raise errors[i]
        tau[~ok] = 0.0
        return Evaluation(tau, ok, errors, positions, positions[:, m.active_index], residual, condition)

    def _evaluate_one(self, q, qd, qdd, error, on_invalid):
        m = self.mechanism
        try:
            if error is not None:
                raise error
            step = self._solve_serial(q[0].tolist())
            tau = self._torques(step, qd[0].tolist(), qdd[0].tolist(), sp.ScalarOps)
            if not all(map(math.isfinite, tau)):
                raise SingularConfigurationError('torques are not finite here', math.inf)
        except CogIdError as exc:
            if on_invalid == 'raise':
                raise
            positions = np.array([self._state[0]])
            return Evaluation(np.zeros((1, len(q[0]))), np.array([False]), [exc], positions,
                              positions[:, m.active_index],
                              np.array([getattr(exc, 'residual', math.inf)]),
                              np.array([getattr(exc, 'condition_number', math.inf)]))
        positions = np.array([step.sol.q])
        return Evaluation(np.array([tau]), np.array([True]), [None], positions,
                          positions[:, m.active_index], np.array([step.sol.residual]),
                          np.array([step.condition]))

    def _per_sample(self, q, compute, qd=None, with_rates=False):
        """Run ``compute(step, ops[, qd lanes])`` on one sample or a batch; numpy results."""
        with_rates = with_rates or qd is not None or compute.__code__.co_argcount == 3
        q, qd, _, single = self._inputs(q, qd, None)
        finite, errors = self._check_finite(q, qd, qd, single)
        if errors:
            raise errors[min(errors)]
        if single:
            step = self._solve_serial(q[0].tolist())
            extra = (qd[0].tolist(),) if with_rates else ()
            return tuple(np.array(x) for x in compute(step, sp.ScalarOps, *extra))
        with np.errstate(all='ignore'):
            step = self._solve_batch(q, 'raise')[0]
            extra = ([qd[:, a] for a in range(qd.shape[1])],) if with_rates else ()
            return tuple(_stack(x, len(q)) for x in compute(step, sp.ArrayOps, *extra))


def _sample_program(solver):
    """The mechanism's straight-line per-sample code, traced once and shared by its solvers;
    None for redundant actuation (its projection is iterative: the general path serves it)."""
    m = solver.mechanism
    if m.is_redundant:
        return None
    program = getattr(m, '_sample_program', None)
    if program is None:
        program = m._sample_program = SampleProgram(m, solver._pipeline)
    return program


def _stack(nested, n):
    """Nested lists of lanes -> array of shape (n, ...)."""
    if isinstance(nested, (list, tuple)):
        return np.stack([_stack(x, n) for x in nested], axis=1)
    return np.broadcast_to(np.asarray(nested, dtype=float), (n,))
