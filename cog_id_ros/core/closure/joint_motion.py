"""From actuator rates to the rates of every joint: qdot = S thetadot, qddot = S thetaddot + d.

The feasible joint velocities are the null space of the closure Jacobian A. With ``dof``
primary actuators p (mechanism.primary) and the other joints f, a basis is
    V = [I; T] (rows p; f),   T = -A_f^+ A_p.
With V_a the active rows of V and W the torque weights, the active-to-joint map is
    S = V (V_a^T W^-1 V_a)^-1 V_a^T W^-1
which is [I; T] when every actuator is primary (no redundancy), and otherwise projects a
slightly inconsistent redundant rate vector in the W^-1 metric. Its transpose gives the
weighted minimum-norm torques: tau = S^T Q minimises sum w_k tau_k^2 subject to
V_a^T tau = V^T Q (virtual work). S does not depend on the choice of basis V.

The accelerations satisfy A qddot + beta = 0 (closure.closure_bias). With c any solution
(c_p = 0, c_f = -A_f^+ beta), qddot = S thetaddot + (c - S c_a): the last term is the
drift, Gdot thetadot in the paper's eq. (4) once mapped onto the links.
"""
from typing import Any, Sequence

import numpy as np

from ..linalg.lane_linalg import solve_spd
from ..value_types import FloatArray, Lane, LaneMatrix, MechanismLike, Ops
from .closure import ClosureSolution

Matrix = Sequence[Sequence[Lane]]


class BasisLayout:
    """How V is made of its rows: the free joints' rows (-T, as the lane code solves them or
    a dynamics record returns them: kernels.PoseRecord.basis), the primary actuators'
    unit rows (I) and the locked joints' zero rows (idle_spins.py: they do not move). The
    one place that puts them together, for one sample as a list over
    joints (what the lane code and the kernels take) or as arrays."""

    def __init__(self, mechanism: MechanismLike) -> None:
        m = mechanism
        self.free = m.free_joints
        self.shape = (m.n_coordinates, m.dof)
        self.zero_row = [0.0] * m.dof
        #: (joint, its row) of every primary actuator: constant, shared by every V made here
        self.unit_rows = [(j, [1.0 if i == k else 0.0 for i in range(m.dof)])
                          for k, j in enumerate(m.primary_joints)]

    def rows(self, free_rows: Sequence[list[Lane]]) -> LaneMatrix:
        """V (a list over joints of rows over the primary actuators) from the rows of the
        free joints, in mechanism.free_joints order."""
        rows = [self.zero_row] * self.shape[0]     # the locked joints' rows stay zero
        for j, row in self.unit_rows:
            rows[j] = row
        for j, row in zip(self.free, free_rows):
            rows[j] = row
        return rows

    def array(self, free_rows: Any) -> FloatArray:
        """V as an array (n_joints, dof) from the free rows (n_free, dof); of N samples
        (N, n_joints, dof) from (N, n_free, dof)."""
        free_rows = np.asarray(free_rows, dtype=float)
        basis = np.zeros(free_rows.shape[:-2] + self.shape)
        basis[..., self.free, :] = free_rows
        for j, row in self.unit_rows:
            basis[..., j, :] = row
        return basis


def velocity_basis(mechanism: MechanismLike, sol: ClosureSolution) -> LaneMatrix:
    """V as a list over joints of lists over the ``dof`` primary actuators (lanes)."""
    columns = [sol.columns[j] for j in mechanism.primary_joints]
    t = [sol.lsq.solve(col) for col in columns]           # A_f^+ A_p, column by column
    return BasisLayout(mechanism).rows([[-t[k][i] for k in range(len(columns))]
                                        for i in range(len(mechanism.free_joints))])


def projection_gram(mechanism: MechanismLike, basis: Matrix) -> tuple[LaneMatrix, LaneMatrix]:
    """(V_a^T W^-1 V_a, V_a^T W^-1): the normal equations of the weighted projection."""
    w_inv = mechanism.inverse_torque_weights
    rows = [basis[j] for j in mechanism.active_index]
    dof = mechanism.dof
    va_t_winv = [[rows[a][k] * w_inv[a] for a in range(len(rows))] for k in range(dof)]
    gram = [[sum(va_t_winv[k][a] * rows[a][c] for a in range(len(rows))) for c in range(dof)]
            for k in range(dof)]
    return gram, va_t_winv


def active_velocity_map(mechanism: MechanismLike, basis: Matrix, ops: Ops) -> LaneMatrix:
    """S (list over joints of lists over active joints): qdot = S thetadot."""
    if not mechanism.is_redundant:
        order = mechanism.primary             # primary k is active joint order[k]
        m = len(order)
        s: LaneMatrix = [[0.0] * m for _ in basis]
        for j, row in enumerate(basis):
            for k, a in enumerate(order):
                s[j][a] = row[k]
        return s
    gram, va_t_winv = projection_gram(mechanism, basis)
    x = solve_spd(gram, va_t_winv, ops)                  # dof x M
    dof = mechanism.dof
    m = len(mechanism.active_index)
    return [[sum(row[k] * x[k][a] for k in range(dof)) for a in range(m)] for row in basis]


def projection_increment(mechanism: MechanismLike, basis: Matrix, q: Sequence[Lane],
                         target: Sequence[Lane], ops: Ops) -> list[Lane]:
    """Redundant actuation: the Gauss-Newton increment dz (one per primary actuator) towards
    the closed pose nearest ``target`` in the W^-1 metric, min (q_a - target)^T W^-1
    (q_a - target); the pose moves by -V dz (:func:`projected_pose`), then closes again."""
    error = [q[j] - t for j, t in zip(mechanism.active_index, target)]
    gram, va_t_winv = projection_gram(mechanism, basis)
    rhs = [[sum(r * e for r, e in zip(row, error))] for row in va_t_winv]
    return [row[0] for row in solve_spd(gram, rhs, ops)]


def projected_pose(mechanism: MechanismLike, q: Sequence[Lane], basis: Matrix,
                   dz: Sequence[Lane]) -> list[Lane]:
    """q - V dz, the primary actuators moved by exactly -dz (before the loops close again)."""
    moved = [x - sum(b * d for b, d in zip(row, dz)) for x, row in zip(q, basis)]
    for k, j in enumerate(mechanism.primary_joints):
        moved[j] = q[j] - dz[k]
    return moved


def closure_drift(mechanism: MechanismLike, sol: ClosureSolution, velocity_map: Matrix,
                  beta: Sequence[Lane]) -> list[Lane]:
    """d = c - S c_a with A c = -beta, c = 0 on the primary joints (list over joints)."""
    n = mechanism.n_coordinates
    c: list[Lane] = [0.0] * n
    if beta:
        for j, value in zip(mechanism.free_joints, sol.lsq.solve(beta)):
            c[j] = -value
    if not mechanism.is_redundant:
        return c
    c_active = [c[j] for j in mechanism.active_index]
    return [c[j] - sum(s * ca for s, ca in zip(velocity_map[j], c_active)) for j in range(n)]


def combine(matrix: Matrix, vector: Sequence[Lane]) -> list[Lane]:
    """matrix @ vector for a list-of-rows matrix of lanes."""
    return [sum(m * v for m, v in zip(row, vector)) for row in matrix]
