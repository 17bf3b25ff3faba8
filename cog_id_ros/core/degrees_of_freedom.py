"""Degrees of freedom at load, and the actuators that drive them.

At the assembled pose (assembly.py) the degrees of freedom are read off the rank of the
closure Jacobian A there: dof = coordinates - rank(A). The actuators must determine the
motion: of the active joints, ``dof`` are *primary* (those whose coordinates determine all
others best, the smallest condition number of A's other columns), the rest of a redundant
set secondary. Every way this can fail raises MechanismConfigError with what to change.
"""
import itertools
import math

import numpy as np

from . import closure, spherical_chains
from .assembly import check_loops_hint
from .errors import MechanismConfigError
from .value_types import FloatArray, MechanismLike

#: relative singular value below which A loses rank
RANK_TOLERANCE = 1e-9


def count(mech: MechanismLike, moved: str | None,
          problem: MechanismConfigError | None) -> tuple[FloatArray, int, int]:
    """(A, rank of A, dof) at mech.assembled_coordinates; ``moved``, ``problem``: what
    assembly.assemble said about actuators it had to move (``problem`` is raised here,
    after a rigid mechanism, whose message is the clearer one)."""
    n = mech.n_coordinates
    matrix, _ = closure.closure_jacobian_matrix(mech.model, mech.assembled_coordinates)
    singular_values = np.linalg.svd(matrix, compute_uv=False) if matrix.size else np.zeros(0)
    rank = _rank(singular_values)
    dof = n - rank
    m = len(mech.active_joints)
    if dof == 0:
        raise MechanismConfigError(
            'mechanism.joints',
            f'the mechanism is rigid (locked) at the assembled initial positions: 0 degrees '
            f'of freedom (closure rank {rank} of {n} joint coordinates), so '
            f'no joint can move and there is nothing to drive. Typical causes: a joint of '
            f'the wrong type (prismatic where revolute was meant) or axis (in a planar '
            f'loop every revolute axis is normal to the plane, every prismatic one in it), '
            f'or a loop with too few joints; {check_loops_hint(mech, None)}'
            + (f' (the loops closed only after moving {moved} away from '
               f'initial_positions)' if moved else ''))
    if problem is not None:
        raise problem
    if m < dof:
        hidden = n - len(mech.joints)
        moving = _free_with_actuators_held(mech, matrix)
        raise MechanismConfigError(
            'mechanism.active_joints',
            f'{m} active joint(s) for {dof} degrees of freedom (closure rank '
            f'{rank} of {n} coordinates'
            + (f', {hidden} of them hidden: the spherical and universal joints in the '
               f'spanning tree' if hidden else '')
            + ', at the assembled initial positions): the motion is not determined'
            + (f": with every actuator held, {', '.join(moving)} can still move" if moving
               else '')
            + '; add active (revolute or prismatic) joints, or remove the idle freedom: a '
              'link between two spherical joints (a rod with a ball at each end) spins '
              'about the line through their centres, so write one of them as `type: '
              'universal`; or, if the mechanism has fewer freedoms than that, it is at a '
              'singular pose there (e.g. three revolute joints written for a spherical '
              'one, with the middle one at +-pi/2: gimbal lock; write it as `type: '
              'spherical`, or change initial_positions)')
    return matrix, rank, dof


def _free_with_actuators_held(mech: MechanismLike, matrix: FloatArray) -> list[str]:
    """Names of the joints that can still move with every actuator held: those whose
    coordinates the null space of the closure Jacobian's other columns moves."""
    held = set(mech.active_index)
    free = [j for j in range(mech.n_coordinates) if j not in held]
    if not free or not matrix.size:
        return []
    _, values, vt = np.linalg.svd(matrix[:, free])
    null = vt[_rank(values):]
    if not null.size:
        return []
    names = mech.model.coordinate_joints
    return list(dict.fromkeys(names[free[k]] for k in
                              np.flatnonzero(np.abs(null).max(axis=0) > 1e-6)))


def primary_actuators(mech: MechanismLike, matrix: FloatArray, dof: int) -> list[int]:
    """Indices (into active_joints) of ``dof`` actuators whose coordinates determine all
    others best (smallest condition number); the rest of a redundant set are secondary.

    ``matrix`` is the closure Jacobian at the assembled positions; the condition number
    of its free columns is the Frobenius one the solver uses (lane_linalg), from their
    singular values: ||A_f||_F ||A_f^+||_F."""
    best: tuple[int, ...] | None = None
    best_cond = math.inf
    n = mech.n_coordinates
    combos = itertools.combinations(range(len(mech.active_index)), dof)
    for combo in itertools.islice(combos, 5000):
        fixed = {mech.active_index[i] for i in combo}
        free = [j for j in range(n) if j not in fixed]
        cond = _condition_number(matrix[:, free])
        if cond < best_cond * (1.0 - 1e-9):    # ties: the first combination
            best, best_cond = combo, cond
    if best is None or not best_cond <= mech.max_condition_number:
        hint = _gimbal_lock_hint(mech)
        if mech.assembly_warnings and not hint:
            hint = ('; the assembly also had to move joints far from initial_positions ('
                    'see assembly_warnings): most likely the geometry (xyz, rpy, axis) or '
                    'initial_positions are wrong rather than the choice of actuators')
        raise MechanismConfigError(
            'mechanism.active_joints',
            f'{mech.active_joints} do not determine the motion at the assembled initial '
            f'positions (closure Jacobian condition number {best_cond:.3g}): some passive '
            f'joints could move with every actuator held{hint}')
    return list(best)


def _gimbal_lock_hint(mech: MechanismLike) -> str:
    """What to do where three revolute joints through massless links (a ball joint as
    written, spherical_chains.py) are near their gimbal lock at the assembled pose."""
    chains = [chain for chain in spherical_chains.chains_of(mech, near_lock=True)
              if chain.lock_distance < 0.1]
    if not chains:
        return ''
    return ('; ' + '; '.join(', '.join(c.joints) for c in chains) +
            f" {'are' if len(chains) == 1 else 'are each'} three revolute joints through "
            f'massless links at or near their gimbal lock (first and last axes '
            f'{math.degrees(math.asin(min(1.0, min(c.lock_distance for c in chains)))):.2g} '
            f'degrees from parallel): write such a ball joint as one `type: spherical` '
            f'joint, which has no lock, or give initial_positions away from it')


def _rank(singular_values: np.ndarray) -> int:
    """The rank that singular values (descending) give: those above RANK_TOLERANCE times
    the largest (or times 1, if that is smaller)."""
    scale = max(1.0, singular_values[0]) if singular_values.size else 1.0
    return int(np.sum(singular_values > RANK_TOLERANCE * scale))


def _condition_number(a: FloatArray) -> float:
    """||A||_F ||A^+||_F of a matrix with at least as many rows as columns (inf if the
    columns are dependent); 1.0 for no columns, like QRLeastSquares.condition_number."""
    rows, cols = a.shape
    if cols == 0:
        return 1.0
    if rows < cols:
        return math.inf
    s = np.linalg.svd(a, compute_uv=False)
    if not s[-1] > 0.0:
        return math.inf
    return float(math.sqrt(float(np.sum(s * s))) * math.sqrt(float(np.sum(1.0 / (s * s)))))
