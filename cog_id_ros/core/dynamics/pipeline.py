"""The paper's method at one closed pose, eq. (1) to eq. (7), in the order it is applied.

    closed pose q, velocity basis V        closure.py, joint_motion.py (given)
    qdot = S thetadot_m                    joint-rate map S              joint_motion.py
    q_i = g_i(theta_m)                     (1) COG poses                 cog_jacobian.py
    G_i = dg_i / dtheta_m                  (3) COG Jacobians             cog_jacobian.py
    qdot_i = G_i thetadot_m                (2) COG velocities            cog_jacobian.py
    qddot_i = G_i thetaddot_m + Gdot_i thetadot_m   (4) COG accelerations  cog_jacobian.py
    F_i = M_i qddot_i + b_i                (5) Newton-Euler              newton_euler.py
    tau_m = sum_i G_i^T F_i                (6)-(7)                        here
          = H(theta_m) thetaddot_m + B(theta_m, thetadot_m)

:func:`inverse_dynamics` is that table as code, its lines (1)-(4) in :func:`cog_motion`
(which eq. (7)'s H and B and the solver's cog_drifts use too). Every path of the solver
runs it: on Python floats for one sample (``backend='reference'``), traced once into
straight-line kernels (``backend='python'``, ``'native'``: kernels.py), and on numpy arrays
for a batch with the reference kernels. ``ops`` says which: spatial.ScalarOps,
spatial.ArrayOps or straight_line.SymOps.
"""
from typing import Sequence

from ..closure import closure
from ..closure.joint_motion import active_velocity_map, closure_drift, combine
from ..kinematics.kinematics import link_bias_accelerations, link_twists
from ..kinematics.parameters import massless
from ..linalg import spatial as sp
from ..value_types import Lane, LaneMatrix, MechanismLike, Ops, Twist, Vec3
from .cog_jacobian import (
    Cog,
    Motion,
    cog_accelerations,
    cog_drifts,
    cog_jacobians,
    cog_poses,
    cog_velocities,
)
from .newton_euler import newton_euler_force, rotated_inertia_times

Pose = closure.ClosureSolution
Matrix = Sequence[Sequence[Lane]]
Force = tuple[Vec3, Vec3]    # (force, moment about the COG)


def inverse_dynamics(mechanism: MechanismLike, pose: Pose, basis: Matrix, thetadot: Sequence[Lane],
                     thetaddot: Sequence[Lane], ops: Ops) -> list[Lane]:
    """tau_m (eq. 7) at a closed pose (closure.ClosureSolution) with velocity basis V."""
    cogs, jac, velocities, drifts = cog_motion(mechanism, pose, basis, thetadot, ops)  # (1)-(4)
    accelerations = cog_accelerations(jac, drifts, thetaddot)       # (4) qddot_i
    forces = link_forces(mechanism, cogs, velocities, accelerations)  # (5) F_i
    return active_torques(jac, forces)                              # (6)-(7) sum G_i^T F_i


def cog_motion(mechanism: MechanismLike, pose: Pose, basis: Matrix, thetadot: Sequence[Lane],
               ops: Ops) -> tuple[list[Cog], list[list[Motion]], list[Motion], list[Motion]]:
    """Eqs. (1)-(4) at a closed pose: COG poses g_i, COG Jacobians G_i, velocities
    G_i thetadot and drifts Gdot_i thetadot (the COG accelerations when thetaddot = 0)."""
    s, cogs, jac = cog_jacobians_at(mechanism, pose, basis, ops)    # (1), (3)
    velocities = cog_velocities(jac, thetadot)                      # (2) G_i thetadot
    drifts = cog_drifts(cogs, velocities,                           # (4) Gdot_i thetadot
                        drift_accelerations(mechanism, pose, s, thetadot))
    return cogs, jac, velocities, drifts


def cog_jacobians_at(mechanism: MechanismLike, pose: Pose, basis: Matrix,
                     ops: Ops) -> tuple[LaneMatrix, list[Cog], list[list[Motion]]]:
    """The joint-rate map S, g_i (eq. 1) and G_i (eq. 3) at a closed pose."""
    s = active_velocity_map(mechanism, basis, ops)                  # qdot = S thetadot
    cogs = cog_poses(mechanism, pose.frames)                        # (1) g_i
    jac, _ = cog_jacobians(mechanism, pose.frames, cogs, s)         # (3) G_i
    return s, cogs, jac


def equation_of_motion(mechanism: MechanismLike, pose: Pose, basis: Matrix,
                       thetadot: Sequence[Lane], ops: Ops) -> tuple[LaneMatrix, list[Lane]]:
    """H and B of eq. (7): tau = H thetaddot + B. B is eq. (7) with thetaddot = 0; H is
    sum_i G_i^T M_i G_i."""
    cogs, jac, velocities, drifts = cog_motion(mechanism, pose, basis, thetadot, ops)
    b = active_torques(jac, link_forces(mechanism, cogs, velocities, drifts))
    return inertia_matrix(mechanism, cogs, jac), b


def drift_accelerations(mechanism: MechanismLike, pose: Pose, s: Matrix,
                        thetadot: Sequence[Lane]) -> list[Twist]:
    """Spatial acceleration of every link when thetaddot_m = 0: the link-level Gdot thetadot
    of eq. (4). The joints' own bias (joint twists turning with their inner body) plus the
    joint accelerations d that keep the loops closed (joint_motion.closure_drift)."""
    bias, drift = joint_drift(mechanism, pose, s, thetadot)
    return link_drift(mechanism, pose, bias, drift)


def joint_drift(mechanism: MechanismLike, pose: Pose, s: Matrix,
                thetadot: Sequence[Lane]) -> tuple[list[Twist], list[Lane]]:
    """(bias, d): the links' bias accelerations (joint twists turning with their inner body)
    and the joint accelerations d that keep the loops closed when thetaddot_m = 0."""
    model = mechanism.model
    qdot = combine(s, thetadot)
    twists = link_twists(model, pose.frames, qdot)
    bias = link_bias_accelerations(model, pose.frames, twists, qdot)
    beta = closure.closure_bias(model, pose.frames, pose.loops, twists, bias, qdot)
    return bias, closure_drift(mechanism, pose, s, beta)


def link_drift(mechanism: MechanismLike, pose: Pose, bias: Sequence[Twist],
               drift: Sequence[Lane]) -> list[Twist]:
    """The links' spatial accelerations from their bias and the joint accelerations d."""
    drift_twists = link_twists(mechanism.model, pose.frames, drift)
    return [sp.twist_add_scaled(b, d, 1.0) for b, d in zip(bias, drift_twists)]


def link_forces(mechanism: MechanismLike, cogs: Sequence[Cog], velocities: Sequence[Motion],
                accelerations: Sequence[Motion]) -> list[Force | None]:
    """F_i (eq. 5) for every link; None for a massless link (it contributes nothing)."""
    forces: list[Force | None] = []
    for i, ((a, alpha), (_, w)) in enumerate(zip(accelerations, velocities)):
        mass, inertia = mechanism.link_mass[i], mechanism.link_inertia[i]
        forces.append(None if massless(mass, inertia) else
                      newton_euler_force(mass, inertia, cogs[i][1], mechanism.gravity,
                                         a, w, alpha))
    return forces


def active_torques(jacobians: Sequence[Sequence[Motion]],
                   forces: Sequence[Force | None]) -> list[Lane]:
    """tau = sum_i G_i^T F_i (eqs. 6-7); links with force None (massless) contribute nothing."""
    m = len(jacobians[0]) if jacobians else 0
    tau: list[Lane] = [0.0] * m
    for cols, force in zip(jacobians, forces):
        if force is None:
            continue
        f, n = force
        for a, (gv, gw) in enumerate(cols):
            tau[a] = tau[a] + sp.dot(gv, f) + sp.dot(gw, n)
    return tau


def inertia_matrix(mechanism: MechanismLike, cogs: Sequence[Cog],
                   jacobians: Sequence[Sequence[Motion]]) -> LaneMatrix:
    """H = sum_i G_i^T M_i G_i (eq. 7), as a list of rows of lanes."""
    m = len(mechanism.active_joints)
    h: LaneMatrix = [[0.0] * m for _ in range(m)]
    for i, cols in enumerate(jacobians):
        mass, inertia = mechanism.link_mass[i], mechanism.link_inertia[i]
        if massless(mass, inertia):
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
