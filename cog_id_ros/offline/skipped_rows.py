"""Rows ``cog_id_torques`` leaves unsolved before solving: active positions that jump
beyond --max-step / --max-step-linear (refused, or skipped with --skip-invalid), and the
rows such skips cut off into pieces too short to estimate derivatives from. Each skipped
row is a :class:`Skip`, like those the solver refuses (:mod:`cog_id_ros.offline.solving`).
"""

import math

import numpy as np

from . import derivatives, samples, trajectory_io
from .console import EXIT_INPUT, ToolError
from .jumps import find_jumps


class Skip:
    """A row left unsolved: 1-based ``row``, ``reason`` (a key of REASONS, or 'jump'),
    ``message`` (one line), ``error`` (the core exception, or None)."""

    __slots__ = ('row', 'reason', 'message', 'error')

    def __init__(self, row, reason, message, error=None):
        self.row, self.reason, self.message, self.error = row, reason, message, error


def _step_limit(args, kind):
    """(--max-step or --max-step-linear, its name, unit) for a joint of ``kind``: by the unit
    of its coordinate, an angle or a length."""
    if kind.unit == 'rad':
        return args.max_step, '--max-step', kind.unit
    return args.max_step_linear, '--max-step-linear', kind.unit


def _jump_message(args, kinds, active, row, k, step, ref):
    limit, option, unit = _step_limit(args, kinds[k])
    hint = ''
    if kinds[k].wraps and not args.unwrap:
        hint = '; if the angle wraps at +-pi (a continuous joint), use --unwrap'
    return (f'jumps by {step:.6g} {unit} from row {ref} (limit {limit:g} {unit} per row, '
            f'{option}){hint}')


def check_jumps(args, mech, traj, active):
    """Rows to solve (bool mask) and the [Skip] of the jumps; raises without --skip-invalid."""
    kinds = mech.active_kinds
    limits = [_step_limit(args, kind)[0] for kind in kinds]
    n = len(traj)
    keep = np.ones(n, bool)
    if all(math.isinf(x) for x in limits):
        return keep, []
    q = np.column_stack([traj.columns[trajectory_io.joint_column(j, 'position')] for j in active])
    jumps = find_jumps(q, limits)
    if jumps and not args.skip_invalid:
        row, k, step, ref = jumps[0]
        column = trajectory_io.joint_column(active[k], 'position')
        raise ToolError(f"{args.input}: row {row} (line {row + 1} of the file), column "
                        f"'{column}': {_jump_message(args, kinds, active, row, k, step, ref)}",
                        EXIT_INPUT)
    skipped = []
    for row, k, step, ref in jumps:
        keep[row - 1] = False
        column = trajectory_io.joint_column(active[k], 'position')
        skipped.append(Skip(row, 'jump', f"column '{column}': "
                            + _jump_message(args, kinds, active, row, k, step, ref)))
    return keep, skipped


def short_pieces(traj, active, keep, more=()):
    """With derivatives to estimate, rows left in pieces of fewer than STENCIL rows between
    skipped stretches (see samples.kept_pieces) cannot be estimated: skip them too
    (reason 'jump'), updating ``keep``. ``more``: other columns estimated when absent (a
    floating base's velocities and accelerations)."""
    fields = ('velocity', 'acceleration')
    if all(trajectory_io.joint_column(j, f) in traj.columns for j in active for f in fields) \
            and all(column in traj.columns for column in more):
        return []
    skipped = []
    for rows in samples.kept_pieces(keep):
        if rows.size >= derivatives.STENCIL:
            continue
        first, last = int(rows[0]) + 1, int(rows[-1]) + 1
        for r in rows.tolist():
            keep[r] = False
            skipped.append(Skip(r + 1, 'jump', f'rows {first}..{last} are cut off by rows skipped '
                                f'as jumps: too few ({rows.size}) to estimate derivatives from '
                                f'(at least {derivatives.STENCIL} needed)'))
    return skipped
