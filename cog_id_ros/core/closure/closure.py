"""Loop closure: the constraint equations and their Jacobian (Newton's method on them is in
sample_solve.py and batch.py).

For every loop-closing joint c between links P and C, the child attachment frame of C must
coincide with the parent attachment frame of P moved by the joint motion M(q_c). Six
equations per loop, written at the closure point x (the child attachment origin):

    Phi_c = [ x - (o + q_c a) (prismatic only);  1/2 sum_k rP_k x rC_k ]       (position)
    A_c qdot = [ v_C(x) - v_P(x) - q_c' a (prismatic);  w_C - w_P - q_c' a (revolute) ] = 0

Joints without a coordinate close loops with fewer equations, written in the same six rows
(the others are zero), and a joint in the tree may add a constraint of its own (a spherical
joint's quaternion, |q|^2 = 1). Which rows, their Jacobian columns and their bias each
kind of joint writes (joints.py: ``closure_state``, ``closure_columns``, ``closure_bias``);
here they are put together for every constraint of the model.

A planar loop gives six equations of rank three; the least-squares solves (lane_linalg)
take that in their stride. The velocity form is linear in the rates of the joints of the
loop (its cycle through the tree plus the loop joint itself), so A is assembled from the
joint twists of forward_kinematics; its time derivative along the motion, the bias beta
with A qddot + beta = 0, comes from the acceleration recursion.
"""
from typing import Iterable, Sequence

import numpy as np

from ..kinematics import kinematics as kin
from ..kinematics.loop_state import LoopState
from ..linalg import spatial as sp
from ..linalg.lane_linalg import QRLeastSquares
from ..value_types import FloatArray, Lane, Ops, Twist


def loop_closure(model: kin.KinematicModel, frames: kin.Frames, q: Sequence[Lane],
                 ops: Ops) -> list[LoopState]:
    """Residuals of every constraint at configuration q (frames from forward_kinematics)."""
    return [lp.kind.closure_state(lp, frames, q, ops) for lp in model.constraints]


def closure_jacobian_columns(model: kin.KinematicModel, frames: kin.Frames,
                             loops: Sequence[LoopState]) -> list[list[Lane]]:
    """A as a list of columns (one per coordinate, each a list of 6 L lanes; rows [v(x); w]
    of every constraint)."""
    n_rows = 6 * len(model.constraints)
    columns: list[list[Lane]] = [[0.0] * n_rows for _ in range(model.n_coordinates)]
    for li, (lp, st) in enumerate(zip(model.constraints, loops)):
        lp.kind.closure_columns(lp, st, frames, columns, 6 * li)
    return columns


def closure_bias(model: kin.KinematicModel, frames: kin.Frames, loops: Sequence[LoopState],
                 twists: Sequence[Twist], bias_acc: Sequence[Twist],
                 qdot: Sequence[Lane]) -> list[Lane]:
    """beta with A qddot + beta = 0: the closure equations differentiated twice at qddot = 0."""
    beta: list[Lane] = []
    for lp, st in zip(model.constraints, loops):
        beta.extend(lp.kind.closure_bias(lp, st, frames, twists, bias_acc, qdot))
    return beta


class ClosureSolution:
    """A configuration after Newton's method, with everything evaluated there.

    q: all joint coordinates (lanes); frames, loops, columns (A), lsq (QR of the columns of
    the joints that were solved for); residual: max |Phi| (lane); converged (bool lane);
    iterations.
    """
    __slots__ = ('q', 'frames', 'loops', 'columns', 'lsq', 'residual', 'converged', 'iterations')
    q: Sequence[Lane]
    frames: kin.Frames
    loops: list[LoopState]
    columns: list[list[Lane]]
    lsq: QRLeastSquares
    residual: Lane
    converged: Lane
    iterations: int


def evaluate(model: kin.KinematicModel, q: Sequence[Lane], free: Sequence[int],
             ops: Ops) -> ClosureSolution:
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


def loops_closed(residual: Lane, least_cosine: Lane, tolerance: float) -> Lane:
    """The loops are closed: the largest closure residual below ``tolerance`` and every
    cosine positive (``least_cosine`` the least of them: a loop closed a half-turn off has
    a zero residual too). Floats, or (N,) arrays for an (N,) bool array; False for NaN."""
    return (residual < tolerance) & (least_cosine > 0.0)


def closure_jacobian_matrix(model: kin.KinematicModel,
                            q: Iterable[float]) -> tuple[FloatArray, ClosureSolution]:
    """A at one configuration as a numpy matrix (6 constraints x coordinates), for load-time
    analysis."""
    sol = evaluate(model, list(q), [], sp.ScalarOps)
    matrix = np.zeros((6 * len(model.constraints), model.n_coordinates))
    for j, col in enumerate(sol.columns):
        matrix[:, j] = col
    return matrix, sol


def assemble(model: kin.KinematicModel, q: Iterable[float], tol: float, fixed: Iterable[int] = (),
             max_iter: int = 100, max_step: float = 0.2) -> tuple[list[float], float, bool]:
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
