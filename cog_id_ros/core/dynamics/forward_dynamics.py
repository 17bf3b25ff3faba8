"""Forward dynamics: eq. (7), tau = H thetaddot + B, solved for the accelerations.

At a closed pose with velocity basis V (the primary actuators' unit rows, joint_motion.py)
and the joint-rate map S, every feasible joint acceleration is

    qddot = V zddot + d,        A d = -beta  (d: joint_motion.closure_drift)

with zddot the accelerations of the ``dof`` primary actuators (the independent
coordinates). Its active rows are thetaddot = V_a zddot + d_a. The efforts tau of the
active joints do the virtual work tau^T V_a dz, so their generalized force on the
independent coordinates is V_a^T tau, and eq. (7) projected there reads

    (V_a^T H V_a) zddot = V_a^T (tau - B)          (H d_a = 0: G_i d_a = J_i S d_a = 0)
    thetaddot           = V_a zddot + d_a

with H = sum_i G_i^T M_i G_i and B (eq. 7 at thetaddot = 0) as pipeline.py computes them.
Without redundant actuation V_a is a permutation and d_a = 0: thetaddot = H^-1 (tau - B).
With it, only the generalized force V_a^T tau moves the mechanism: efforts that differ by
a vector with V_a^T x = 0 (an internal load of the loops) give the same motion.

V_a^T H V_a is the mechanism's inertia in the independent coordinates, symmetric positive
definite unless some motion of the mechanism moves no mass; it is solved by Cholesky. The
smallest Cholesky pivot squared over its diagonal entry (1 for a diagonal matrix, 0 for a
singular one: the scale of each coordinate, rad or m, does not matter) is reported as
``1 / ratio``, the inertia condition that forward dynamics is refused above
(:data:`INERTIA_CONDITION_LIMIT`).
"""
from typing import Any, List, Sequence, Tuple

from ..linalg.lane_linalg import cholesky, cholesky_solve
from ..model.mechanism import Mechanism
from .cog_jacobian import cog_drifts, cog_velocities
from .pipeline import (
    active_torques,
    cog_jacobians_at,
    inertia_matrix,
    joint_drift,
    link_drift,
    link_forces,
)

#: the inertia condition (see the module's text) above which the inertia of the
#: independent coordinates counts as singular: accelerations lose about log10 of it in
#: digits, so beyond 1e10 fewer than six of sixteen are left
INERTIA_CONDITION_LIMIT = 1e10

Lane = Any      # a float, an (N,) array or a symbol while tracing (spatial.py, straight_line.py)


def forward_dynamics(mechanism: Mechanism, pose: Any, basis: List[List[Lane]],
                     thetadot: Sequence[Lane], tau: Sequence[Lane], ops: Any
                     ) -> Tuple[List[Lane], Lane]:
    """(thetaddot, inertia condition) at a closed pose (closure.ClosureSolution) with
    velocity basis V: the active-joint accelerations the efforts ``tau`` produce."""
    s, cogs, jac = cog_jacobians_at(mechanism, pose, basis, ops)    # (1), (3)
    velocities = cog_velocities(jac, thetadot)                      # (2)
    bias, drift = joint_drift(mechanism, pose, s, thetadot)         # d
    drifts = cog_drifts(cogs, velocities, link_drift(mechanism, pose, bias, drift))  # (4)
    h = inertia_matrix(mechanism, cogs, jac)                        # H of eq. (7)
    b = active_torques(jac, link_forces(mechanism, cogs, velocities, drifts))  # B of eq. (7)
    active_basis = [basis[j] for j in mechanism.active_index]       # V_a
    zddot, condition = independent_accelerations(
        reduced_inertia(h, active_basis), generalized_force(active_basis, tau, b), ops)
    drift_active = [drift[j] for j in mechanism.active_index]       # d_a
    return [sum(v * z for v, z in zip(row, zddot)) + d
            for row, d in zip(active_basis, drift_active)], condition


def reduced_inertia(h: List[List[Lane]], active_basis: List[List[Lane]]) -> List[List[Lane]]:
    """V_a^T H V_a: the inertia of the mechanism in its independent coordinates."""
    dof = len(active_basis[0])
    hv = [[sum(h_ab * row[k] for h_ab, row in zip(h_a, active_basis)) for k in range(dof)]
          for h_a in h]                                             # H V_a
    return [[sum(va[k] * hv_a[c] for va, hv_a in zip(active_basis, hv)) for c in range(dof)]
            for k in range(dof)]


def generalized_force(active_basis: List[List[Lane]], tau: Sequence[Lane],
                      b: Sequence[Lane]) -> List[Lane]:
    """V_a^T (tau - B): the efforts' generalized force on the independent coordinates, less
    eq. (7)'s B (gravity, velocity and closure drift terms)."""
    net = [t - bb for t, bb in zip(tau, b)]
    return [sum(row[k] * x for row, x in zip(active_basis, net))
            for k in range(len(active_basis[0]))]


def independent_accelerations(inertia: List[List[Lane]], force: List[Lane], ops: Any
                              ) -> Tuple[List[Lane], Lane]:
    """(zddot, inertia condition): inertia zddot = force by Cholesky, and 1 / the smallest
    ratio of a pivot squared to its diagonal entry (NaN or inf when singular)."""
    lower = cholesky(inertia, ops)
    zddot = [row[0] for row in cholesky_solve(lower, [[f] for f in force], ops)]
    ratios = [lower[k][k] * lower[k][k] * ops.recip(inertia[k][k]) for k in range(len(force))]
    return zddot, ops.recip(ops.least(ratios))
