"""mechanism.joint_space: the joints a controller commands, read and checked at load.

A joint space is a set of revolute or prismatic joints of the mechanism (passive or active),
as many as it has degrees of freedom, whose rates determine its motion: held, nothing moves.
At the assembled pose the motions the loops allow (with the locked joints held) form a basis
V (orthonormal); the joint space's rows of V must be square and see every motion
(:func:`seen_condition`, 1 / their least singular value, within
mechanism.max_condition_number). Otherwise the error names ``mechanism.joint_space`` and
what is wrong: the free motion left (the joints that still move with the joint space held)
or the joints of the joint space whose rates the loops tie to each other.
"""
import math
from typing import Any

import numpy as np

from ..errors import MechanismConfigError

PARAMETER = 'mechanism.joint_space'


def read_joint_space(mech: Any, reader: Any) -> list[str]:
    """The names of mechanism.joint_space ([] when absent), each a revolute or prismatic
    joint of mechanism.joints (the reader refuses a name given twice)."""
    names = reader.string_list(PARAMETER) or []
    for name in names:
        if name in getattr(mech, 'locked_joints', ()):
            raise MechanismConfigError(
                PARAMETER, f"'{name}' is held (mechanism.locked_joints): a joint that cannot "
                           'move cannot be commanded')
        if name not in mech.joints:
            closure = name in getattr(mech, 'closure_joints', ())
            raise MechanismConfigError(
                PARAMETER, f"'{name}' is " + ('a spherical, universal or fixed joint: a joint '
                                              'space is made of revolute and prismatic joints'
                                              if closure else 'not in mechanism.joints'))
    return list(names)


def check_joint_space(mech: Any, equations: np.ndarray) -> None:
    """Raise MechanismConfigError (mechanism.joint_space) unless the joint space determines
    the motion at the assembled pose. ``equations``: the closure Jacobian with the locked
    joints' unit rows (idle_spins.with_locks), over every coordinate."""
    names = mech.joint_space
    if not names:
        return
    if len(names) != mech.dof:
        raise MechanismConfigError(
            PARAMETER, f'must name as many joints as the mechanism has degrees of freedom '
                       f'({mech.dof}), got {len(names)}: {", ".join(names)}')
    basis = _motions(equations, mech.n_coordinates, mech.dof)   # (n, dof)
    rows = basis[[mech.joint_index[name] for name in names]]  # (dof, dof)
    condition = seen_condition(rows)
    if condition <= mech.max_condition_number:
        return
    u, _, vt = np.linalg.svd(rows)          # (the refusal says what moves and what is tied)
    moving = basis @ vt[-1]
    scale = np.abs(moving).max()
    still = [mech.joints[j] for j in range(len(mech.joints))
             if abs(moving[j]) > 1e-6 * scale and mech.joints[j] not in names]
    tied = [name for name, c in zip(names, u[:, -1]) if abs(c) > 1e-6]
    raise MechanismConfigError(
        PARAMETER, f"does not determine the motion at the assembled pose (condition number "
                   f"{condition:.3g}): with {', '.join(names)} held, "
                   + (f"{', '.join(still)} can still move" if still else 'a motion is left')
                   + f"; the rates of {', '.join(tied)} are tied to each other by the loops. "
                   'Name joints whose rates are independent (the knee, the ankle pitch and '
                   'roll, ...), or move initial_positions away from a singular pose')


def seen_condition(rows: np.ndarray) -> float:
    """How badly the joint space sees the motion: 1 / the least singular value of its rows
    (D, D) of an orthonormal basis of the motions (>= 1; inf where it misses one). Each
    row's norm is at most 1, so this bounds their condition number too, and for one joint
    it is the share of the motion that joint's rate carries, inverted."""
    least = np.linalg.svd(rows, compute_uv=False)[-1]
    return 1.0 / least if least > 0.0 else math.inf


def _motions(equations: np.ndarray, n: int, dof: int) -> np.ndarray:
    """An orthonormal basis (n, dof) of the coordinate rates the equations allow (their
    ``dof`` least singular directions: the rank was counted at load)."""
    if equations.size == 0:
        return np.eye(n)[:, :dof]
    return np.linalg.svd(equations.reshape(-1, n))[2][n - dof:].T
