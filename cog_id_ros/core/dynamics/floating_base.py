"""The paper's method with a floating base: the base's six coordinates join the actuators.

Everything is written in the base frame B (the root link's), as the fixed-base pipeline is;
the base moves with the twist (v_b, w_b) (B axes, Pinocchio's free flyer) and its time
derivative (dv_b, dw_b). The independent coordinates are the base's six and the actuators'
theta_m; the loops, inside the robot, tie only the other joints to theta_m, so each link's
COG Jacobian is the fixed-base G_i (pipeline.py) beside the base's columns:

    c_i, G_i, G_i thetadot, Gdot_i thetadot (1)-(4) fixed base, in B   pipeline.cog_motion
    g_B = R_b^T g                            gravity in B               base_gravity
    qdot_i  = (v_b + w_b x c_i, w_b) + G_i thetadot                 (2')  floating_velocities
    qddot_i = (dv_b + w_b x v_b + dw_b x c_i + w_b x (w_b x c_i)
               + 2 w_b x cdot_i, dw_b + w_b x omega_i)
              + G_i thetaddot + Gdot_i thetadot                     (4')  floating_accelerations
    F_i = M_i qddot_i + b_i (with g_B)                              (5)   newton_euler_force
    Q_b = sum_i (F_i, c_i x F_i + N_i)       the base's six rows    (6')  base_forces
    tau = sum_i G_i^T F_i                    the actuators' rows    (6)-(7) active_torques

A contact on link l at p_c (B) moves as the link does: its Jacobian columns are G_l's with
the point moved, (gv + gw x (p_c - c_l), gw) (:func:`contact_jacobians`); a wrench (f, m)
there adds (f, p_c x f + m) to the base's rows and J_c^T (f, m) to the actuators' (what
:func:`contact_maps` returns, for solve/whole_body.py to balance).

Every function here is lane code (spatial.py): floats for one sample, (N,) arrays for N.
"""
from typing import Any, Sequence

from ..kinematics.parameters import massless
from ..linalg import spatial as sp
from ..value_types import Lane, MechanismLike, Vec3
from .cog_jacobian import Cog, Motion, cog_accelerations
from .newton_euler import newton_euler_force
from .pipeline import Force, Matrix, Pose, active_torques, cog_motion

BaseMotion = tuple[Vec3, Vec3, Vec3, Vec3]   # (v_b, w_b, dv_b, dw_b), B axes


def whole_body_forces(mechanism: MechanismLike, pose: Pose, basis: Matrix,
                      thetadot: Sequence[Lane], thetaddot: Sequence[Lane], base: BaseMotion,
                      rotation: Sequence[Lane], ops: Any
                      ) -> tuple[list[Lane], list[Lane], list[Cog], list[list[Motion]]]:
    """(Q_b (6 lanes: force, moment at the base origin, B axes), tau (M lanes), COG poses,
    G_i): the generalized forces the motion needs, gravity included, before any contact.
    ``rotation``: R_b, world from base (row-major 9 lanes)."""
    cogs, jac, velocities, drifts = cog_motion(mechanism, pose, basis, thetadot, ops)  # (1)-(4)
    relative = cog_accelerations(jac, drifts, thetaddot)                  # (4) in B
    gravity = base_gravity(rotation, mechanism.gravity)                   # g_B
    absolute_v = floating_velocities(cogs, velocities, base)              # (2')
    absolute_a = floating_accelerations(cogs, velocities, relative, base)  # (4')
    forces: list[Force | None] = []
    for i, ((a, alpha), (_, w)) in enumerate(zip(absolute_a, absolute_v)):
        mass, inertia = mechanism.link_mass[i], mechanism.link_inertia[i]
        forces.append(newton_euler_force(mass, inertia, cogs[i][1], gravity, a, w, alpha)
                      if not massless(mass, inertia) else None)          # (5)
    tau = active_torques(jac, forces)                                     # (6)-(7)
    q_base = base_forces(cogs, forces)                                    # (6')
    own = base_link_force(mechanism, base, gravity)                        # the root's own
    return [x + y for x, y in zip(q_base, own)], tau, cogs, jac


def base_gravity(rotation: Sequence[Lane], gravity: Sequence[float]) -> Vec3:
    """g_B = R_b^T g: the world's gravity in the base frame."""
    return sp.mat_t_vec(tuple(rotation), tuple(gravity))


def floating_velocities(cogs: Sequence[Cog], relative: Sequence[Motion],
                        base: BaseMotion) -> list[Motion]:
    """(2'): each COG's velocity and link's angular velocity in the world, B axes."""
    v_b, w_b = base[0], base[1]
    return [(sp.add(sp.add(v_b, sp.cross(w_b, c)), v), sp.add(w_b, w))
            for (c, _), (v, w) in zip(cogs, relative)]


def floating_accelerations(cogs: Sequence[Cog], relative_v: Sequence[Motion],
                           relative_a: Sequence[Motion], base: BaseMotion) -> list[Motion]:
    """(4'): each COG's acceleration and link's angular acceleration in the world, B axes:
    the base's own acceleration at the COG, Coriolis 2 w_b x cdot_i, and the fixed-base
    (4)."""
    w_b, dw_b = base[1], base[3]
    out = []
    for (c, _), (v, w), (a, alpha) in zip(cogs, relative_v, relative_a):
        at_cog = base_point_acceleration(base, c)
        out.append((sp.add(sp.add(at_cog, sp.scale(sp.cross(w_b, v), 2.0)), a),
                    sp.add(sp.add(dw_b, sp.cross(w_b, w)), alpha)))
    return out


def base_point_acceleration(base: BaseMotion, c: Vec3) -> Vec3:
    """The classical acceleration of the base-fixed point c (B axes): the base origin's,
    dv_b + w_b x v_b, plus dw_b x c + w_b x (w_b x c)."""
    v_b, w_b, dv_b, dw_b = base
    origin = sp.add(dv_b, sp.cross(w_b, v_b))
    return sp.add(sp.add(origin, sp.cross(dw_b, c)), sp.cross(w_b, sp.cross(w_b, c)))


def base_forces(cogs: Sequence[Cog], forces: Sequence[Force | None]) -> list[Lane]:
    """(6'): the base's rows, sum_i (F_i, c_i x F_i + N_i): what the links need, as a force
    and a moment at the base origin (B axes)."""
    f: Vec3 = sp.ZERO3
    n: Vec3 = sp.ZERO3
    for (c, _), force in zip(cogs, forces):
        if force is None:
            continue
        f = sp.add(f, force[0])
        n = sp.add(n, sp.add(sp.cross(c, force[0]), force[1]))
    return [*f, *n]


def base_link_force(mechanism: MechanismLike, base: BaseMotion, gravity: Vec3) -> list[Lane]:
    """Eq. (5) for the base link itself (it moves with the base alone), as its rows of Q_b."""
    mass, com, inertia = mechanism.base_mass, mechanism.base_com, mechanism.base_inertia
    identity = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    a = base_point_acceleration(base, com)
    f, n = newton_euler_force(mass, inertia, identity, gravity, a, base[1], base[3])
    return [*f, *sp.add(sp.cross(com, f), n)]


def contact_jacobians(mechanism: MechanismLike, pose: Pose, cogs: Sequence[Cog],
                      jac: Sequence[Sequence[Motion]], link: int, xyz: Vec3
                      ) -> tuple[Vec3, list[Motion]]:
    """(p_c, columns of J_c): the contact point in B and its velocity and its link's
    angular velocity per unit actuator rate (zero columns on the base link itself)."""
    m = len(mechanism.active_joints)
    if link < 0:
        return tuple(xyz), [(sp.ZERO3, sp.ZERO3)] * m
    frames = pose.frames
    point = sp.add(frames.pos[link], sp.mat_vec(frames.rot[link], tuple(xyz)))
    arm = sp.sub(point, cogs[link][0])
    return point, [(sp.add(gv, sp.cross(gw, arm)), gw) for gv, gw in jac[link]]


def contact_maps(mechanism: MechanismLike, pose: Pose, cogs: Sequence[Cog],
                 jac: Sequence[Sequence[Motion]], contacts: Sequence[Any],
                 rotation: Sequence[Lane]) -> tuple[list[list[Lane]], list[list[Lane]]]:
    """(A, C): per component of every contact's wrench (world axes at the contact point:
    fx fy fz [mx my mz]), its column of the base's rows (A, 6 rows) and of the actuators'
    (C, M rows): Q_b = A w + base_wrench and tau = C w + efforts for wrenches w."""
    m = len(mechanism.active_joints)
    a_rows: list[list[Lane]] = [[] for _ in range(6)]
    c_rows: list[list[Lane]] = [[] for _ in range(m)]
    r = tuple(rotation)
    for contact in contacts:
        point, cols = contact_jacobians(mechanism, pose, cogs, jac, contact.link, contact.xyz)
        for k in range(contact.size):
            unit = tuple(r[3 * (k % 3) + j] for j in range(3))  # world axis k % 3 in B: R^T e
            f, n = (unit, sp.cross(point, unit)) if k < 3 else (sp.ZERO3, unit)
            for row, value in enumerate((*f, *n)):
                a_rows[row].append(value)
            for row, (gv, gw) in enumerate(cols):
                c_rows[row].append(sp.dot(gv, f) if k < 3 else sp.dot(gw, n))
    return a_rows, c_rows
