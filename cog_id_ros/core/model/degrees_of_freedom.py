"""Degrees of freedom at load, and the actuators that drive them.

At the assembled pose (assembly.py) the degrees of freedom are read off the rank of the
closure Jacobian A there, with a unit row per locked joint (held at its initial position):
dof = coordinates - rank. The actuators must determine the motion: free motion that is left
is either idle spins (rods between two ball joints, which idle_spins.py refuses or locks)
or refused as a missing actuator. Of the active joints, ``dof`` are *primary* (those whose
coordinates determine all others best, the smallest condition number of A's other
columns), the rest of a redundant set secondary; actuators that are dependent without
``torque_weights`` saying so are reported (:func:`report_dependent`). Every way this can
fail raises MechanismConfigError with what to change.
"""
import itertools
import math
from typing import Iterable

import numpy as np

from ..closure import closure
from ..errors import MechanismConfigError
from ..kinematics import spherical_chains
from ..value_types import FloatArray, MechanismLike
from . import assembly, idle_spins
from .assembly import check_loops_hint

#: relative singular value below which A loses rank
RANK_TOLERANCE = 1e-9
#: sets of primary actuators compared one by one up to this many (beyond: chosen greedily)
COMBINATIONS = 5000


def count(mech: MechanismLike, moved: str | None,
          problem: MechanismConfigError | None) -> tuple[FloatArray, int, int]:
    """(A, rank of A, dof) at mech.assembled_coordinates; ``moved``, ``problem``: what
    assembly.assemble said about actuators it had to move (``problem`` is raised here,
    after a rigid mechanism, whose message is the clearer one)."""
    n = mech.n_coordinates
    matrix, _ = closure.closure_jacobian_matrix(mech.model, mech.assembled_coordinates)
    equations = idle_spins.with_locks(mech, matrix)    # locked joints held
    singular_values = (np.linalg.svd(equations, compute_uv=False) if equations.size
                       else np.zeros(0))
    rank = _rank(singular_values)
    dof = n - rank
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
               f'initial_positions)' if moved else '')
            + (f"; the locked joints ({', '.join(mech.locked_joints)}, held at their initial "
               f'positions) count: mechanism.locked_joints' if mech.locked_joints else ''))
    if problem is not None:
        raise problem
    basis = idle_spins.free_motions(mech, matrix)
    if basis.shape[1]:           # motion left with every actuator held (a redundant set too)
        idle_spins.resolve(mech, basis, rank, dof)   # raises: locks to add, or what moves
    return matrix, rank, dof


def primary_actuators(mech: MechanismLike, matrix: FloatArray, dof: int) -> list[int]:
    """Indices (into active_joints) of ``dof`` actuators whose coordinates determine all
    others best (smallest condition number); the rest of a redundant set are secondary.

    ``matrix`` is the closure Jacobian at the assembled positions; the condition number
    of its free columns is the Frobenius one the solver uses (lane_linalg), from their
    singular values: ||A_f||_F ||A_f^+||_F."""
    best: tuple[int, ...] | None = None
    best_cond = math.inf
    n = mech.n_coordinates
    combos: Iterable[tuple[int, ...]] = itertools.combinations(range(len(mech.active_index)),
                                                               dof)
    if math.comb(len(mech.active_index), dof) > COMBINATIONS:
        combos = [_greedy_primary(mech, matrix, dof)]
    locked = set(mech.locked_index)
    for combo in combos:
        fixed = {mech.active_index[i] for i in combo} | locked
        free = [j for j in range(n) if j not in fixed]
        cond = _condition_number(matrix[:, free])
        if cond < best_cond * (1.0 - 1e-9):    # ties: the first combination
            best, best_cond = combo, cond
    if best is None or not best_cond <= mech.max_condition_number:
        hint = _gimbal_lock_hint(mech)
        if mech.locked_joints and not hint:
            hint = (f"; the locked joints ({', '.join(mech.locked_joints)}) may not be the "
                    f'ones to lock: a joint with a small share of an idle spin barely holds it '
                    f'(without mechanism.locked_joints the load names each spin and its '
                    f'shares)')
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


def _greedy_primary(mech: MechanismLike, matrix: FloatArray, dof: int) -> tuple[int, ...]:
    """``dof`` actuators (indices into active_joints) chosen greedily where there are too
    many sets to compare: the motions of the mechanism (null space of A, the locked joints
    held) as rows per actuator; each step takes the actuator whose row is furthest from
    those taken (pivoted Gram-Schmidt), ties by order."""
    stacked = idle_spins.with_locks(mech, matrix)
    motions = idle_spins.null_rows(stacked).T if stacked.size else np.eye(mech.n_coordinates)
    rows = motions[mech.active_index].copy()
    chosen: list[int] = []
    for _ in range(dof):
        norms = np.linalg.norm(rows, axis=1)
        norms[chosen] = -1.0
        k = int(np.argmax(norms))
        chosen.append(k)
        if norms[k] > 0.0:
            unit = rows[k] / norms[k]
            rows -= np.outer(rows @ unit, unit)
    return tuple(sorted(chosen))


def report_dependent(mech: MechanismLike, matrix: FloatArray) -> None:
    """An assembly warning naming the actuators that do not move independently, when the
    mechanism is redundant and ``mechanism.torque_weights`` does not say that is meant."""
    if not mech.is_redundant or mech.weights_given:
        return
    dependent = idle_spins.dependent_actuators(mech, matrix)
    assembly.note(
        mech,
        f"the actuators do not all move independently: {', '.join(map(repr, dependent))} "
        f'determine each other with the loops closed ({len(mech.active_joints)} active '
        f'joints for {mech.dof} degrees of freedom), so the mechanism is treated as '
        f'redundantly actuated: their setpoints must agree with the loop closure within '
        f'mechanism.setpoint_tolerance and the torques are shared among them (least squares, '
        f'mechanism.torque_weights). If that is meant, give mechanism.torque_weights (then '
        f'this is not reported); if not, check mechanism.active_joints and the joints of the '
        f'loops they are in (a joint of the wrong type or axis, a ball joint written as a '
        f'revolute one)')


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
