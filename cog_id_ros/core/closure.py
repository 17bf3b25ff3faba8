"""Loop closure: the constraint equations and their Jacobian (Newton's method on them is in
sample_solve.py and batch.py).

For every loop-closing joint c between links P and C, the child attachment frame of C must
coincide with the parent attachment frame of P moved by the joint motion M(q_c). Six
equations per loop, written at the closure point x (the child attachment origin):

    Phi_c = [ x - (o + q_c a) (prismatic only);  1/2 sum_k rP_k x rC_k ]       (position)
    A_c qdot = [ v_C(x) - v_P(x) - q_c' a (prismatic);  w_C - w_P - q_c' a (revolute) ] = 0

A spherical joint in the tree (kinematics.py) adds one equation, |q|^2 - 1 = 0 on its
quaternion (a ``unit`` constraint, its other five rows zero), velocity row 2 q . qdot.

Joints without a coordinate close loops with fewer equations, written in the same six rows
(the others are zero): ``spherical`` only the position rows, x - o (the two attachment
origins coincide); ``universal`` also a . b = 0 in the first orientation row (a the axis in
the parent attachment frame, b the second axis in the child's, both in the base frame, kept
perpendicular); ``fixed`` all six, as a revolute joint held at q = 0. Their velocity rows
are v_C(x) - v_P(x) and (w_C - w_P) . (b x a); a point constraint's bias has the term
(w_C - w_P) x v_C(x) of the moving point x (the full six-row constraints need none: their
relative twist is zero, or along the joint's own twist).

A planar loop gives six equations of rank three; the least-squares solves (lane_linalg)
take that in their stride. The velocity form is linear in the rates of the joints of the
loop (its cycle through the tree plus the loop joint itself), so A is assembled from the
joint twists of forward_kinematics; its time derivative along the motion, the bias beta
with A qddot + beta = 0, comes from the acceleration recursion.
"""
import numpy as np

from . import kinematics as kin
from . import spatial as sp
from .lane_linalg import QRLeastSquares


class LoopState:
    """Per loop: closure point x (base frame), residual (6 lanes), and the cosine of the
    angle between the two attachment frames (a half-turn also zeroes the residual; 1.0
    where the orientation is free); universal: its two axes a, b (base frame)."""
    __slots__ = ('x', 'residual', 'cosine', 'a', 'b')


def loop_closure(model, frames, q, ops):
    """Residuals of every constraint at configuration q (frames from forward_kinematics)."""
    states = []
    for lp in model.constraints:
        if lp.kind == 'unit':                    # a tree quaternion: |q|^2 = 1
            st = LoopState()
            st.x = tuple(q[c] for c, _ in lp.cycle)
            st.residual = (sum(v * v for v in st.x) - 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            st.cosine = 1.0
            states.append(st)
            continue
        if lp.joint is None:                     # spherical, universal, fixed: held at rest
            r_moved, t_moved = lp.d0, lp.t_pj
        elif lp.revolute:
            qc = q[lp.joint]
            r_moved = sp.mat_combination(lp.d0, lp.d1, ops.sin(qc), lp.d2, 1.0 - ops.cos(qc))
            t_moved = lp.t_pj
        else:
            r_moved = lp.d0
            t_moved = sp.add_scaled(lp.t_pj, lp.axis_p, q[lp.joint])
        r_p, target = kin.to_base(frames, lp.parent, r_moved, t_moved)
        r_c, x = kin.to_base(frames, lp.child, lp.r_cj, lp.t_cj)
        st = LoopState()
        st.x = x
        if lp.kind == 'spherical':
            st.residual = sp.sub(x, target) + (0.0, 0.0, 0.0)
            st.cosine = 1.0
        elif lp.kind == 'universal':
            st.a = kin.vector_to_base(frames, lp.parent, lp.axis_p)
            st.b = kin.vector_to_base(frames, lp.child, lp.axis_c)
            st.residual = sp.sub(x, target) + (sp.dot(st.a, st.b), 0.0, 0.0)
            st.cosine = 1.0
        else:
            st.residual = sp.sub(x, target) + sp.orientation_error(r_p, r_c)
            st.cosine = sp.rotation_cosine(r_p, r_c)
        states.append(st)
    return states


def closure_jacobian_columns(model, frames, loops):
    """A as a list of columns (one per coordinate, each a list of 6 L lanes; rows [v(x); w]
    of every constraint)."""
    n_rows = 6 * len(model.constraints)
    columns = [[0.0] * n_rows for _ in range(model.n_coordinates)]
    for li, (lp, st) in enumerate(zip(model.constraints, loops)):
        row = 6 * li
        if lp.kind == 'unit':
            for (c, _), v in zip(lp.cycle, st.x):
                columns[c][row] = 2.0 * v
            continue
        entries = list(lp.cycle) + ([] if lp.joint is None else [(lp.joint, -1.0)])
        normal = sp.cross(st.b, st.a) if lp.kind == 'universal' else None
        for j, sign in entries:
            v, w = sp.twist_at(frames.xi[j], st.x)
            col = columns[j]
            col[row:row + 3] = sp.scale(v, sign)
            if normal is not None:
                col[row + 3] = sp.dot(w, normal) * sign
            elif lp.kind != 'spherical':
                col[row + 3:row + 6] = sp.scale(w, sign)
    return columns


def closure_bias(model, frames, loops, twists, bias_acc, qdot):
    """beta with A qddot + beta = 0: the closure equations differentiated twice at qddot = 0."""
    beta = []
    for lp, st in zip(model.constraints, loops):
        if lp.kind == 'unit':                    # d2/dt2 |q|^2 = 2 q . qddot + 2 |qdot|^2
            beta.extend((2.0 * sum(qdot[c] * qdot[c] for c, _ in lp.cycle),
                         0.0, 0.0, 0.0, 0.0, 0.0))
            continue
        acc = sp.twist_add_scaled(kin.twist_of(bias_acc, lp.child),
                                  kin.twist_of(bias_acc, lp.parent), -1.0)
        if lp.joint is not None:
            rate_of_xi = sp.motion_cross(kin.twist_of(twists, lp.parent), frames.xi[lp.joint])
            acc = sp.twist_add_scaled(acc, rate_of_xi, -qdot[lp.joint])
        v, w = sp.twist_at(acc, st.x)
        if lp.kind in ('spherical', 'universal'):    # a point constraint at the moving x
            w_c, w_p = kin.twist_of(twists, lp.child)[0], kin.twist_of(twists, lp.parent)[0]
            w_rel = sp.sub(w_c, w_p)
            v = sp.add(v, sp.cross(w_rel, sp.twist_at(kin.twist_of(twists, lp.child), st.x)[0]))
            w = [0.0, 0.0, 0.0]
            if lp.kind == 'universal':
                normal = sp.cross(st.b, st.a)
                normal_rate = sp.add(sp.cross(sp.cross(w_c, st.b), st.a),
                                     sp.cross(st.b, sp.cross(w_p, st.a)))
                w[0] = sp.dot(acc[0], normal) + sp.dot(w_rel, normal_rate)   # acc[0]: alpha
        beta.extend(v)
        beta.extend(w)
    return beta


class ClosureSolution:
    """A configuration after Newton's method, with everything evaluated there.

    q: all joint coordinates (lanes); frames, loops, columns (A), lsq (QR of the columns of
    the joints that were solved for); residual: max |Phi| (lane); converged (bool lane);
    iterations.
    """
    __slots__ = ('q', 'frames', 'loops', 'columns', 'lsq', 'residual', 'converged', 'iterations')


def evaluate(model, q, free, ops):
    """Forward kinematics, closure residual and Jacobian, QR of the free columns at q."""
    sol = ClosureSolution()
    sol.q = q
    sol.frames = kin.forward_kinematics(model, q, ops)
    sol.loops = loop_closure(model, sol.frames, q, ops)
    sol.residual = ops.maxabs([r for st in sol.loops for r in st.residual])
    sol.columns = closure_jacobian_columns(model, sol.frames, sol.loops)
    sol.lsq = QRLeastSquares([sol.columns[j] for j in free], ops,
                             model.elimination_order(free))
    return sol


def loops_closed(residual, least_cosine, tolerance):
    """The loops are closed: the largest closure residual below ``tolerance`` and every
    cosine positive (``least_cosine`` the least of them: a loop closed a half-turn off has
    a zero residual too). Floats, or (N,) arrays for an (N,) bool array; False for NaN."""
    return (residual < tolerance) & (least_cosine > 0.0)


def closure_jacobian_matrix(model, q):
    """A at one configuration as a numpy matrix (6 constraints x coordinates), for load-time
    analysis."""
    sol = evaluate(model, list(q), [], sp.ScalarOps)
    matrix = np.zeros((6 * len(model.constraints), model.n_coordinates))
    for j, col in enumerate(sol.columns):
        matrix[:, j] = col
    return matrix, sol


def assemble(model, q, tol, fixed=(), max_iter=100, max_step=0.2):
    """Close every loop from ``q`` moving every coordinate but ``fixed`` (minimum-norm
    Gauss-Newton steps).

    Load time only (numpy least squares on the column-rank-deficient Jacobian).
    Returns (q, residual, converged).
    """
    q = [float(x) for x in q]
    moving = np.array([j not in set(fixed) for j in range(model.n_coordinates)])
    residual = 0.0
    for _ in range(max_iter):
        matrix, sol = closure_jacobian_matrix(model, q)
        residual = sol.residual
        if loops_closed(residual, sp.ScalarOps.least([st.cosine for st in sol.loops]), tol):
            return q, residual, True
        phi = np.array([r for st in sol.loops for r in st.residual])
        step = np.zeros(model.n_coordinates)
        step[moving] = np.linalg.lstsq(matrix[:, moving], phi, rcond=1e-12)[0]
        size = np.max(np.abs(step))
        if not np.isfinite(size):
            break
        step *= min(1.0, max_step / size) if size > 0 else 1.0
        q = [float(x - d) for x, d in zip(q, step)]
    return q, residual, False
