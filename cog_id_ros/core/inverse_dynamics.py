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
import heapq
import math

import numpy as np

from . import closure
from . import spatial as sp
from .cog_jacobian import cog_accelerations, cog_drifts, cog_jacobians, cog_poses, cog_velocities
from .continuation import (MAX_ANGLE, MAX_STEPS, MIN_STEP, actuator_ratio, correction_bounds,
                           correction_ok, fits_one_step, intermediate_goal, joint_step_limits,
                           prediction, revolute_active, step_ratio, wrapped_state)
from .errors import (ClosureError, CogIdError, MechanismConfigError, SetpointError,
                     SingularConfigurationError)
from .joint_motion import (active_velocity_map, closure_drift, combine, projection_gram,
                           velocity_basis)
from .kinematics import link_bias_accelerations, link_twists
from .lane_linalg import solve_spd
from .mechanism import Mechanism
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
    """A solved configuration: closure solution, velocity basis, redundant mismatch, condition,
    and ``closed``: the coordinates where Newton closed the loops from the prediction (before
    the projection of a redundant setpoint, which may move them by its inconsistency)."""
    __slots__ = ('sol', 'basis', 'mismatch', 'condition', 'closed')

    def __init__(self, sol, basis, mismatch, condition, closed=None):
        self.sol, self.basis, self.mismatch, self.condition = sol, basis, mismatch, condition
        self.closed = sol.q if closed is None else closed


class InverseDynamics:
    """Active-joint torques of a closed-link mechanism by per-link COG Jacobians.

    All arrays are in ``mechanism.active_joints`` order; shapes (M,) for one sample or
    (N, M) for N samples. Angles are never wrapped.
    """

    #: largest motion of any joint in one continuation step: rad, or for prismatic joints
    #: this times the mechanism's length scale (continuation.py); longer moves are followed
    #: in steps so that the solver stays on the assembly branch it is on. Read at construction.
    continuation_step = 0.1

    def __init__(self, mechanism):
        if not isinstance(mechanism, Mechanism):
            raise MechanismConfigError(
                'mechanism', f'must be a cog_id_ros.Mechanism (from Mechanism.from_params_file '
                             f'or from_parameters), got {type(mechanism).__name__}')
        self.mechanism = mechanism
        self._limits = joint_step_limits(mechanism, self.continuation_step)
        self._bounds = correction_bounds(self._limits)
        self._wrapping = revolute_active(mechanism)
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
            return np.array(self._serve_one(*sample))
        q, qd, qdd, single = self._inputs(q, qd, qdd)
        if single:
            _, errors = self._check_values(q, qd, qdd, single)
            if errors:
                raise errors[0]
            return np.array(self._serve_one(q[0].tolist(), qd[0].tolist(), qdd[0].tolist()))
        return self._evaluate(q, qd, qdd, 'raise').torques

    def sample_torques(self, q, qd=None, qdd=None):
        """One sample at control rate: three sequences of M floats in, a list of M torques out.

        The same numbers, state and errors as :meth:`torques` on one sample, without the
        numpy round trip or the input checks that the straight-line code makes anyway (a
        NaN, an infinity or a wrong length goes to :meth:`torques`, which says what is
        wrong). This is what cog_id_node calls for every setpoint.
        """
        program = self._program
        if program is not None and program.step is not None and \
                _floats(q) and _floats(qd) and _floats(qdd):
            n = len(self.mechanism.active_joints)
            if len(q) == len(qd) == len(qdd) == n:
                done = program.step(self._state, q, qd, qdd, self._limits, self._bounds)
                if done is not None:
                    self._state = done[1]
                    return done[0]
        sample = self._one_sample(q, qd, qdd)
        if sample is not None:
            return self._serve_one(*sample)
        q, qd, qdd, single = self._inputs(q, qd, qdd)
        if not single:
            raise SetpointError(f'sample_torques takes one sample (one number per active '
                                f'joint), got shape {q.shape}: use torques() for a batch')
        return self.torques(q[0], qd[0], qdd[0]).tolist()    # reports what is wrong

    def evaluate(self, q, qd=None, qdd=None, on_invalid='raise'):
        """Torques with per-sample status (an Evaluation). on_invalid='skip' marks samples that
        cannot be served as invalid instead of raising; the others are computed as usual."""
        if on_invalid not in ('raise', 'skip'):
            raise SetpointError(f"on_invalid must be 'raise' or 'skip', got {on_invalid!r}")
        q, qd, qdd, _ = self._inputs(q, qd, qdd)
        return self._evaluate(q, qd, qdd, on_invalid)

    def solve_positions(self, q):
        """Every joint coordinate (mechanism.joints order): (n_joints,) or (N, n_joints)."""
        q, qd, _, single = self._inputs(q, None, None)
        _, errors = self._check_values(q, qd, qd, single)
        if errors:
            raise errors[min(errors)]
        if single:
            step, self._state = self._solve_serial(q[0].tolist())
            return np.array(step.sol.q)
        with np.errstate(all='ignore'):
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
        """(q, qd, qdd) as float arrays of shape (N, M), and whether it was one sample.

        ``q`` is required; ``qd`` and ``qdd`` default to zeros. One sample is (M,), or a
        plain number when M = 1. Raises SetpointError (reason 'malformed') for anything else.
        """
        names = self.mechanism.active_joints
        m = len(names)
        if q is None:
            raise SetpointError(f'q: required, one position per active joint {names}')
        arrays = [_float_array(label, value, m) if value is not None else None
                  for label, value in (('q', q), ('qd', qd), ('qdd', qdd))]
        single = arrays[0].ndim == 1
        out = []
        for label, array in zip(('q', 'qd', 'qdd'), arrays):
            if array is None:
                out.append(np.zeros((1 if single else arrays[0].shape[0], m)))
                continue
            if array.ndim != (1 if single else 2) or array.shape[-1] != m or \
                    (not single and array.shape[0] != arrays[0].shape[0]):
                expected = f'({m},)' if single else f'({arrays[0].shape[0]}, {m})'
                raise SetpointError(
                    f'{label}: expected shape {expected} (active joints {names}), got {array.shape}')
            out.append(array.reshape(1, -1) if single else array)
        return out[0], out[1], out[2], single

    def _one_sample(self, q, qd, qdd):
        """(q, qd, qdd) as lists of floats when they are one well-formed sample in range,
        else None (the general path then reports what is wrong)."""
        m = len(self.mechanism.active_joints)
        out = []
        for value in (q, qd, qdd):
            if value is None:
                if not out:
                    return None                       # q is required
                out.append([0.0] * m)
                continue
            if type(value) is np.ndarray:            # a row of a float array: one C call
                if value.ndim != 1 or value.dtype.kind != 'f':
                    return None
                floats = value.tolist()
            elif type(value) is list or type(value) is tuple:
                if not all(type(x) is float or type(x) is int for x in value):
                    return None
                try:
                    floats = [float(x) for x in value]
                except OverflowError:
                    return None
            else:
                return None
            if len(floats) != m or not all(map(math.isfinite, floats)):
                return None
            out.append(floats)
        if not all(-MAX_ANGLE <= out[0][a] <= MAX_ANGLE for a in self._wrapping):
            return None
        return out

    def _check_values(self, q, qd, qdd, single):
        """SetpointError for the first non-finite entry, or revolute position beyond
        MAX_ANGLE; returns (per-sample bool array, {sample: error})."""
        finite = np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) & np.isfinite(qdd).all(axis=1)
        wrapping = self._wrapping
        in_range = (np.abs(q[:, wrapping]) <= MAX_ANGLE).all(axis=1) if wrapping else finite
        errors = {}
        for i in np.flatnonzero(~(finite & in_range)):
            where = '' if single else f'sample {i}: '
            for label, array in (('q', q), ('qd', qd), ('qdd', qdd)):
                bad = np.flatnonzero(~np.isfinite(array[i]))
                if bad.size:
                    joint = self.mechanism.active_joints[bad[0]]
                    errors[int(i)] = SetpointError(
                        f'{where}{label} of {joint} is {array[i, bad[0]]}: setpoints must be '
                        f'finite', sample=int(i), reason='non_finite')
                    break
            else:
                a = next(a for a in wrapping if not abs(q[i, a]) <= MAX_ANGLE)
                errors[int(i)] = SetpointError(
                    f'{where}q of {self.mechanism.active_joints[a]} is {q[i, a]:.6g} rad, beyond '
                    f'+-{MAX_ANGLE:g} rad (there a float no longer holds an angle to better than '
                    f'1e-7 rad): wrap or offset the angle', sample=int(i), reason='out_of_range')
        return finite & in_range, errors

    # --- positions: one sample -------------------------------------------------------------

    def _serve_one(self, target, qd, qdd, sample=None):
        """Torques of one well-formed sample (lists of floats); the warm start moves on only
        when they are served (finite)."""
        tau, state = self._solve_one(target, qd, qdd, sample)
        if not all(map(math.isfinite, tau)):
            raise _out_of_range(qd, qdd, sample)
        self._state = state
        return tau

    def _solve_one(self, target, qd, qdd, sample=None):
        """(torques, new state) at ``target`` by continuation from the warm start; raises
        the error of the first step that cannot be served. The warm start is not changed."""
        program = self._program
        if program is not None and program.step is not None:
            # the usual sample at control rate: one step, closed in one or two Newton steps
            done = program.step(self._state, target, qd, qdd, self._limits, self._bounds)
            if done is not None:
                return done
        (kind, payload), state = self._follow(target, self._step_solver(qd, qdd, sample), sample)
        if kind == 'program':
            return list(payload), state
        return self._torques(payload, qd, qdd, sp.ScalarOps), state

    def _solve_serial(self, target, sample=None, want_step=True):
        """(closure step, new state) at ``target`` by continuation from the warm start; the
        step is None unless ``want_step``. Raises the error of the first step that cannot be
        served. The warm start is not changed."""
        zeros = [0.0] * len(target)
        (kind, payload), state = self._follow(target, self._step_solver(zeros, zeros, sample),
                                              sample)
        if kind == 'general' or not want_step:
            return (payload if kind == 'general' else None), state
        sol = closure.evaluate(self.mechanism.model, list(state[0]), self.mechanism.free_joints,
                               sp.ScalarOps)
        sol.converged, sol.iterations = True, 0
        return _Step(sol, state[1], 0.0, sol.lsq.condition_number()), state

    def _step_solver(self, qd, qdd, sample):
        """The ``solve`` of :meth:`_follow`: one continuation step by the straight-line code
        (sample_program.py) where it can decide, else by the general lane path, which raises
        the right error. Returns (('program', torques) or ('general', closure step), state,
        the coordinates Newton closed the loops at)."""
        program = self._program

        def solve(predicted, goal, final):
            if program is not None:
                done = program.solve(predicted, qd, qdd)
                if done is not None:
                    return ('program', done[0]), done[1], done[1][0]
            step = self._closure_step(predicted, goal, sp.ScalarOps, SERIAL_NEWTON_ITERATIONS,
                                      project=final)
            self._check(step, final, sample)
            return ('general', step), (step.sol.q, step.basis), step.closed
        return solve

    def _follow(self, target, solve, sample):
        """Continuation from the warm start to ``target`` (rules in continuation.py).

        ``solve(predicted, goal, final)`` closes the loops from a prediction and returns
        (result, new state, where Newton closed them); it raises ClosureError when Newton
        fails there. Returns the last (result, new state)."""
        m, limits = self.mechanism, self._limits
        start = self._state
        state = wrapped_state(m, self._wrapping, start, target)
        if actuator_ratio(m, limits, state, target) > MAX_STEPS:
            raise _unreachable(m, start, target, sample,
                               f'it is more than {MAX_STEPS} continuation steps away')
        cap = 1.0     # the largest step, in step limits (halved when a step fails)
        for _ in range(MAX_STEPS):
            predicted, moved = prediction(m, state, target)
            if cap >= 1.0 and fits_one_step(m, limits, state, target, moved):
                size, goal, final = 1.0, target, True
            else:
                ratio = step_ratio(m, limits, state, target, moved)
                if ratio <= cap * (1.0 + 1e-9):      # (not a sliver of a step left over)
                    size, goal, final = ratio, target, True
                else:
                    size, goal, final = cap, intermediate_goal(m, state, target, cap / ratio), False
                    predicted, _ = prediction(m, state, goal)
            try:
                result, new_state, corrected = solve(predicted, goal, final)
            except ClosureError as exc:
                if final or exc.reason != 'closure' or cap < MIN_STEP:
                    if final:
                        raise
                    raise _unreachable(m, start, target, sample,
                                       f'the loops stop closing on the way, at {_fmt(goal)}') from None
                cap = size / 2.0      # Newton failed on the way: try a shorter step
                continue
            except SingularConfigurationError as exc:
                if final:
                    raise
                raise _unreachable(m, start, target, sample,
                                   f'the way there passes a singular pose at {_fmt(goal)} '
                                   f'(condition number {exc.condition_number:.3g})') from None
            if not correction_ok(corrected, predicted, self._bounds):
                if size / 2.0 < MIN_STEP:
                    raise _unreachable(m, start, target, sample,
                                       'the assembly branch cannot be followed there (Newton '
                                       'corrections stay large even in short steps: a branch '
                                       'point or dead centre)')
                cap = size / 2.0      # Newton moved far from the prediction: maybe another branch
                continue
            if final:
                return result, new_state
            state, cap = new_state, min(1.0, cap * 2.0)
        raise _unreachable(m, start, target, sample, f'not reached in {MAX_STEPS} continuation steps')

    def _serial_positions(self, target, sample):
        """Every joint coordinate at one sample, by serial continuation; the warm start
        moves there."""
        self._state = self._solve_serial(target, sample, want_step=False)[1]
        return self._state[0]

    def _closure_step(self, predicted, target, ops, max_iter=30, project=True):
        """Close the loops from the prediction ``predicted`` (primary actuators at their
        targets), moving the other joints; then, for redundant actuation and ``project``,
        move to the nearest configuration (W^-1 metric) to the full ``target`` (only the
        last step of a continuation does: the steps on the way follow the primaries)."""
        m = self.mechanism
        sol = closure.solve_closure(m.model, list(predicted), m.free_joints, ops,
                                    m.closure_tolerance, max_iter=max_iter)
        basis = velocity_basis(m, sol)
        closed, mismatch = sol.q, 0.0
        if m.is_redundant and project:
            sol, basis, mismatch = self._project_redundant(sol, basis, target, ops)
        return _Step(sol, basis, mismatch, sol.lsq.condition_number(), closed)

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
            sol = closure.solve_closure(m.model, q, m.free_joints, ops, m.closure_tolerance,
                                        max_iter=SERIAL_NEWTON_ITERATIONS)
            basis = velocity_basis(m, sol)
            if scalar and not sol.converged:
                break                           # unclosable on the way: _check says so
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
                f'{step.mismatch:.6g} (rad or m), more than mechanism.setpoint_tolerance '
                f'{m.setpoint_tolerance:.6g}', step.mismatch, sample, reason='inconsistent')

    # --- positions: a batch ----------------------------------------------------------------

    def _solve_batch(self, qa, on_invalid, invalid=None):
        """Solve N samples as one trajectory, on the branch sample-by-sample continuation
        reaches: serial anchors every continuation step of actuator travel, interpolation
        between them as the start of one vectorised Newton solve of all samples, then a
        check of every sample against its predecessor by the serial path's own rules (one
        continuation step away, a small Newton correction of the first-order prediction),
        and a serial re-solve, in order, of every sample that fails it.

        Returns (step on (N,) lanes, positions (N, n_joints), ok (N,), errors list)."""
        m = self.mechanism
        n = len(qa)
        start_state = self._state
        if n == 0:
            sol = closure.evaluate(m.model, [np.full(0, x) for x in start_state[0]],
                                   m.free_joints, sp.ArrayOps)
            step = _Step(sol, velocity_basis(m, sol), 0.0, sol.lsq.condition_number())
            return step, np.zeros((0, len(m.joints))), np.zeros(0, bool), []
        invalid = np.zeros(n, bool) if invalid is None else invalid
        limits = np.array(self._limits)
        start = np.array([start_state[0][j] for j in m.active_index])
        travel = np.max(np.abs(np.diff(np.vstack([start, qa]), axis=0)) /
                        limits[m.active_index], axis=1)
        arc = np.cumsum(travel)
        bucket = np.floor(arc)
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
        guess[:, m.primary_joints] = qa[:, m.primary]
        step = self._closure_step([guess[:, j] for j in range(len(m.joints))],
                                  [qa[:, a] for a in range(len(m.active_joints))], sp.ArrayOps,
                                  SERIAL_NEWTON_ITERATIONS)   # what does not close is re-solved
        positions = np.column_stack(np.broadcast_arrays(*step.sol.q, np.zeros(n))[:-1])
        basis = np.stack([np.column_stack(np.broadcast_arrays(*row, np.zeros(n))[:-1])
                          for row in step.basis], axis=1)          # (N, n_joints, dof)
        ok = (np.broadcast_to(step.sol.converged, (n,)) &
              (step.condition <= m.max_condition_number) &
              (np.broadcast_to(step.mismatch, (n,)) <= m.setpoint_tolerance) & ~invalid)
        ok &= self._continues(start_state, qa, positions, basis)
        errors = [None] * n
        redone = self._resolve_serially(qa, positions, basis, ok, invalid, errors,
                                        start_state, on_invalid)
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

    def _continues(self, start_state, qa, positions, basis):
        """(N,) bool: sample i is one continuation step from sample i-1 (the warm start for
        i = 0) and within the Newton correction bound of its first-order prediction, i.e.
        where the serial path would have taken it in one step from there."""
        m = self.mechanism
        limits, bounds = np.array(self._limits), np.array(self._bounds)
        prev_q = np.vstack([np.asarray(start_state[0], float)[None, :], positions[:-1]])
        prev_basis = np.concatenate([np.asarray(start_state[1], float)[None], basis[:-1]])
        dz = qa[:, m.primary] - prev_q[:, m.primary_joints]
        moved = np.einsum('njk,nk->nj', prev_basis, dz)
        predicted = prev_q + moved
        predicted[:, m.primary_joints] = qa[:, m.primary]
        near = (np.abs(qa[:, m.primary] - prev_q[:, m.primary_joints]) <=   # as fits_one_step
                limits[m.primary_joints])
        return (near.all(axis=1) & (np.abs(moved) <= limits).all(axis=1) &
                (np.abs(positions - predicted) <= bounds).all(axis=1))

    def _resolve_serially(self, qa, positions, basis, ok, invalid, errors, start_state,
                          on_invalid):
        """Re-solve, in order, every sample not ``ok`` by serial continuation from the last
        good sample before it; a sample after one that changed is checked again. Updates
        the arrays in place; returns True if any sample was re-solved."""
        m = self.mechanism
        pending = [int(i) for i in np.flatnonzero(~ok)]
        heapq.heapify(pending)
        last_good, last_done, redone = -1, -1, False
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
            if ok[i] and self._one_step(previous, qa[i], positions[i]):
                last_good = i                  # still continues from its new predecessor
                continue
            self._state = previous
            before = positions[i].copy()
            try:
                _, (solved, solved_basis) = self._solve_serial(qa[i].tolist(), sample=i,
                                                               want_step=False)
            except CogIdError as exc:
                errors[i], ok[i] = exc, False
                if on_invalid == 'raise':
                    self._state = start_state
                    raise
            else:
                positions[i], basis[i] = solved, solved_basis
                ok[i], redone, last_good = True, True, i
                if np.max(np.abs(positions[i] - before)) <= 1e-9:
                    continue                    # the same pose: the samples after it stand
            if i + 1 < len(ok):
                heapq.heappush(pending, i + 1)
        return redone

    def _one_step(self, state, target, solution):
        """The serial rule of _continues for one sample (lists and arrays of floats)."""
        m = self.mechanism
        target = target.tolist()
        predicted, moved = prediction(m, state, target)
        return (fits_one_step(m, self._limits, state, target, moved) and
                correction_ok(solution.tolist(), predicted, self._bounds))

    # --- evaluation ---------------------------------------------------------------------------

    def _evaluate(self, q, qd, qdd, on_invalid):
        m = self.mechanism
        n, n_act = q.shape
        single = n == 1
        finite, errors_in = self._check_values(q, qd, qdd, single)
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
                errors[i] = _out_of_range(qd[i].tolist(), qdd[i].tolist(), int(i))
                if on_invalid == 'raise':
                    raise errors[i]
        tau[~ok] = 0.0
        return Evaluation(tau, ok, errors, positions, positions[:, m.active_index], residual, condition)

    def _evaluate_one(self, q, qd, qdd, error, on_invalid):
        m = self.mechanism
        try:
            if error is not None:
                raise error
            step, state = self._solve_serial(q[0].tolist())
            tau = self._torques(step, qd[0].tolist(), qdd[0].tolist(), sp.ScalarOps)
            if not all(map(math.isfinite, tau)):
                raise _out_of_range(qd[0].tolist(), qdd[0].tolist(), None)
            self._state = state
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
        finite, errors = self._check_values(q, qd, qd, single)
        if errors:
            raise errors[min(errors)]
        if single:
            step, state = self._solve_serial(q[0].tolist())
            extra = (qd[0].tolist(),) if with_rates else ()
            out = tuple(np.array(x) for x in compute(step, sp.ScalarOps, *extra))
        else:
            start = self._state
            with np.errstate(all='ignore'):
                step = self._solve_batch(q, 'raise')[0]
                extra = ([qd[:, a] for a in range(qd.shape[1])],) if with_rates else ()
                out = tuple(_stack(x, len(q)) for x in compute(step, sp.ArrayOps, *extra))
            state, self._state = self._state, start
        for x in out:
            if not np.isfinite(x).all():
                bad = int(np.flatnonzero(~np.isfinite(x).reshape(len(q), -1).all(axis=1))[0])
                raise _out_of_range(qd[bad].tolist(), [0.0] * qd.shape[1],
                                    None if single else bad)
        self._state = state
        return out


def _floats(value):
    """True for a list of Python floats (what a control loop passes at control rate)."""
    return type(value) is list and all(type(x) is float for x in value)


def _float_array(label, value, m):
    """``value`` as a float array; a plain number is one sample when m == 1. SetpointError
    (reason 'malformed') for strings, mappings, booleans, ragged or non-numeric input."""
    if isinstance(value, (str, bytes, dict, bool, np.bool_)) or (
            not isinstance(value, np.ndarray) and not hasattr(value, '__len__') and
            not isinstance(value, (int, float, np.number))):
        raise SetpointError(f'{label}: must be numbers (one per active joint), got '
                            f'{type(value).__name__}')
    if isinstance(value, (list, tuple)) and any(
            isinstance(x, (bool, np.bool_)) or
            (isinstance(x, (list, tuple)) and any(isinstance(y, (bool, np.bool_)) for y in x))
            for x in value):
        raise SetpointError(f'{label}: must be numbers (one per active joint), not booleans')
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in 'iufO':
            raise TypeError(f'{raw.dtype} values')
        if raw.dtype.kind == 'O' and any(x is None for x in raw.ravel().tolist()):
            raise TypeError('None values')
        with np.errstate(over='raise'):
            array = raw.astype(float)
    except FloatingPointError:
        raise SetpointError(f'{label}: a value beyond the range of a double',
                            reason='out_of_range') from None
    except Exception as exc:   # noqa: BLE001 (whatever a strange object's __float__ raises)
        raise SetpointError(f'{label}: must be numbers (one per active joint), not '
                            f'{type(exc).__name__}: {exc}') from None
    if array.ndim == 0:
        if m != 1:
            raise SetpointError(f'{label}: a single number is a setpoint for one active joint; '
                                f'this mechanism has {m}: give one number per active joint')
        array = array.reshape(1)
    return array


def _fmt(values):
    return '[' + ', '.join(f'{v:.6g}' for v in values) + ']'


def _unreachable(mechanism, start, target, sample, why):
    """ClosureError(reason='unreachable') for a setpoint continuation cannot get to."""
    where = '' if sample is None else f'sample {sample}: '
    q = start[0]
    last = [q[j] for j in mechanism.active_index]
    return ClosureError(
        f'{where}cannot reach the setpoint {_fmt(target)} from the last pose {_fmt(last)} '
        f'of {mechanism.active_joints}: {why}. Send setpoints closer together (the solver '
        f'follows the assembly branch in short steps)', math.inf, sample, reason='unreachable')


def _out_of_range(qd, qdd, sample):
    """SetpointError(reason='out_of_range') for finite input whose torques overflow."""
    where = '' if sample is None else f'sample {sample}: '
    largest = max([abs(x) for x in list(qd) + list(qdd)] or [0.0])
    return SetpointError(
        f'{where}the torques are not finite at this setpoint: the velocities or '
        f'accelerations (largest magnitude {largest:.3g}) are too large to compute with',
        sample=sample, reason='out_of_range')


#: Newton iterations of one serial continuation step (from a first-order prediction within
#: the step limits Newton converges in a few; more means the step is too long: it is halved)
SERIAL_NEWTON_ITERATIONS = 12

#: links x actuators above which the per-sample code is not traced: its size grows with
#: that product (about 8 operations each) and tracing costs ~3 kB per operation, so a
#: large mechanism would load for seconds; the general lane path serves it instead
TRACE_BUDGET = 2500


def _sample_program(solver):
    """The mechanism's straight-line per-sample code, traced once and shared by its solvers;
    None for redundant actuation (its projection is iterative: the general path serves it)
    and above TRACE_BUDGET."""
    m = solver.mechanism
    if m.is_redundant or len(m.links) * len(m.active_joints) > TRACE_BUDGET:
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
