"""The paper's eqs. (1)-(4): pose, COG Jacobian and drift of the centre of gravity of each link.

    q_i      = g_i(theta_m)                          (1)  cog_poses
    qdot_i   = G_i(theta_m) thetadot_m                (2)  cog_velocities
    G_i      = dg_i / dtheta_m                        (3)  cog_jacobians
    qddot_i  = G_i thetaddot_m + Gdot_i thetadot_m    (4)  cog_accelerations, cog_drifts

Rows of every 6-vector: linear velocity (or acceleration) of the COG, then angular velocity
(or acceleration) of the link, both in the base frame. Column m of G_i is the COG motion
when actuator m moves at unit rate and the others stand still: the link twists obtained by
pushing column m of the active-to-joint map S (joint_motion.py) through the tree.
"""
from typing import Sequence

from ..kinematics.kinematics import Frames, link_twists
from ..linalg import spatial as sp
from ..value_types import Lane, MechanismLike, Rotation, Twist, Vec3

Cog = tuple[Vec3, Rotation]        # (COG position, link rotation)
Motion = tuple[Vec3, Vec3]        # (linear, angular): a column of G_i, a velocity, a drift


def cog_poses(mechanism: MechanismLike, frames: Frames) -> list[Cog]:
    """g_i (eq. 1): per link (COG position, link rotation as a row-major 9-tuple)."""
    return [(sp.add(frames.pos[i], sp.mat_vec(frames.rot[i], com)), frames.rot[i])
            for i, com in enumerate(mechanism.link_com)]


def cog_jacobians(mechanism: MechanismLike, frames: Frames, cogs: Sequence[Cog],
                  velocity_map: Sequence[Sequence[Lane]]
                  ) -> tuple[list[list[Motion]], list[list[Twist]]]:
    """G_i (eq. 3): per link, per actuator m, the 6-vector (v_cog, w) for thetadot_m = 1.

    Also returns the unit link twists, from which any link twist follows by linearity.
    """
    m = len(mechanism.active_joints)
    unit_twists = [link_twists(mechanism.model, frames, [row[a] for row in velocity_map])
                   for a in range(m)]
    jac: list[list[Motion]] = []
    for i, (c, _) in enumerate(cogs):
        cols = []
        for a in range(m):
            w, v0 = unit_twists[a][i]
            cols.append((sp.add(v0, sp.cross(w, c)), w))
        jac.append(cols)
    return jac, unit_twists


def cog_velocities(jacobians: Sequence[Sequence[Motion]],
                   thetadot: Sequence[Lane]) -> list[Motion]:
    """qdot_i = G_i thetadot (eq. 2): per link (v_cog, w)."""
    out = []
    for cols in jacobians:
        v, w = sp.ZERO3, sp.ZERO3
        for (gv, gw), rate in zip(cols, thetadot):
            v, w = sp.add_scaled(v, gv, rate), sp.add_scaled(w, gw, rate)
        out.append((v, w))
    return out


def cog_drifts(cogs: Sequence[Cog], velocities: Sequence[Motion],
               drift_accelerations: Sequence[Twist]) -> list[Motion]:
    """Gdot_i thetadot (eq. 4, second term): COG acceleration and link angular acceleration
    when thetaddot = 0, from the links' spatial accelerations at thetaddot = 0."""
    out = []
    for (c, _), (v, w), (alpha, a0) in zip(cogs, velocities, drift_accelerations):
        # classical acceleration of a body point from a spatial acceleration:
        # a0 + alpha x c + w x v
        out.append((sp.add(sp.add(a0, sp.cross(alpha, c)), sp.cross(w, v)), alpha))
    return out


def cog_accelerations(jacobians: Sequence[Sequence[Motion]], drifts: Sequence[Motion],
                      thetaddot: Sequence[Lane]) -> list[Motion]:
    """qddot_i = G_i thetaddot + Gdot_i thetadot (eq. 4): per link (a_cog, alpha)."""
    out = []
    for cols, (a, alpha) in zip(jacobians, drifts):
        for (gv, gw), acc in zip(cols, thetaddot):
            a, alpha = sp.add_scaled(a, gv, acc), sp.add_scaled(alpha, gw, acc)
        out.append((a, alpha))
    return out
