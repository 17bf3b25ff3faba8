"""The paper's eq. (5): the force and moment each link needs at its centre of gravity.

    F_i = M_i qddot_i + b(q_i, qdot_i)
        = [ m_i (a_i - g) ;  I_i alpha_i + w_i x I_i w_i ]

with I_i = R_i I_link R_i^T the inertia about the COG in base-frame axes. Gravity enters
b as -m g; the gyroscopic term w x I w is the 3-D part of b.
"""
from ..linalg import spatial as sp
from ..value_types import Lane, Rotation, Vec3


def rotated_inertia_times(rot: Rotation, inertia_link: Rotation, vector: Vec3) -> Vec3:
    """(R I R^T) v without forming R I R^T."""
    return sp.mat_vec(rot, sp.mat_vec(inertia_link, sp.mat_t_vec(rot, vector)))


def newton_euler_force(mass: Lane, inertia_link: Rotation, rot: Rotation, gravity: Vec3,
                       acceleration: Vec3, omega: Vec3, alpha: Vec3) -> tuple[Vec3, Vec3]:
    """F_i (eq. 5) as (force, moment about the COG), both in the base frame."""
    force = sp.scale(sp.sub(acceleration, gravity), mass)
    moment = sp.add(rotated_inertia_times(rot, inertia_link, alpha),
                    sp.cross(omega, rotated_inertia_times(rot, inertia_link, omega)))
    return force, moment
