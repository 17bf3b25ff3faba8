"""mechanism.joint_space: the joints a controller commands, read and checked at load.

A joint space is a set of revolute or prismatic joints of the mechanism (passive or active),
as many as it has degrees of freedom, whose rates determine its motion: held, nothing moves.
At the assembled pose the motions the loops allow (with the locked joints held) form a basis
V; the joint space's rows of V must be square and invertible (condition number within
mechanism.max_condition_number). Otherwise the error names ``mechanism.joint_space`` and
what is wrong: the free motion left (the joints that still move with the joint space held)
or the joints of the joint space whose rates the loops tie to each other.
"""
from typing import Any

import numpy as np

from ..errors import MechanismConfigError

PARAMETER = 'mechanism.joint_space'
#: a singular value of the joint space's rows of the (orthonormal) motion basis below this:
#: a motion the joint space does not see
UNSEEN = 1e-9


def read_joint_space(mech: Any, reader: Any) -> list[str]:
    """The names of mechanism.joint_space ([] when absent), each a revolute or prismatic
    joint of mechanism.joints (the reader refuses a name given twice)."""
    names = reader.string_list(PARAMETER) or []
    for name in names:
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
    u, s, vt = np.linalg.svd(rows)
    # (the basis is orthonormal: a joint space that sees the motion has s of order 1)
    if s[-1] > max(s[0] / mech.max_condition_number, UNSEEN):
        return
    moving = basis @ vt[-1]
    scale = np.abs(moving).max()
    still = [mech.joints[j] for j in range(len(mech.joints))
             if abs(moving[j]) > 1e-6 * scale and mech.joints[j] not in names]
    tied = [name for name, c in zip(names, u[:, -1]) if abs(c) > 1e-6]
    raise MechanismConfigError(
        PARAMETER, f"does not determine the motion at the assembled pose (condition number "
                   f"{s[0] / max(s[-1], 1e-300):.3g}): with {', '.join(names)} held, "
                   + (f"{', '.join(still)} can still move" if still else 'a motion is left')
                   + f"; the rates of {', '.join(tied)} are tied to each other by the loops. "
                   'Name joints whose rates are independent (the knee, the ankle pitch and '
                   'roll, ...), or move initial_positions away from a singular pose')


def _motions(equations: np.ndarray, n: int, dof: int) -> np.ndarray:
    """An orthonormal basis (n, dof) of the coordinate rates the equations allow (their
    ``dof`` least singular directions: the rank was counted at load)."""
    if equations.size == 0:
        return np.eye(n)[:, :dof]
    return np.linalg.svd(equations.reshape(-1, n))[2][n - dof:].T
