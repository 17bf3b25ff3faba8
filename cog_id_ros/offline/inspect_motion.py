"""cog_id_inspect's --trajectory: a motion solved row by row along the solver's branch,
the closure along it reported, and snapshots of it to draw.
"""

import textwrap

import numpy as np

from ..core.errors import CogIdError
from . import trajectory_io
from .console import one_line
from .inspect_structure import WIDTH

#: rows of --trajectory solved (evenly spaced, the snapshots among them): the solver
#: follows the motion from one to the next, so the snapshots stay on its branch
TRAJECTORY_ROWS = 200


class Motion:
    """What solving --trajectory gave: ``snapshots`` [(time, positions (n_joints,))] to
    draw and ``snapshot_links`` beside them [(COG positions (n_links, 3), link rotations
    (n_links, 3, 3))] (``InverseDynamics.cog_poses``: the joints' positions alone do not
    place a link reached through a spherical or universal joint), the rows solved, the
    largest closure residual and condition number, and the rows the solver refused
    [(row, time, message)]."""

    def __init__(self, path, n_rows, time_span, snapshots, solved, residual, condition,
                 condition_time, refused, snapshot_links=()):
        self.path = path
        self.n_rows = n_rows
        self.time_span = time_span
        self.snapshots = snapshots
        self.snapshot_links = list(snapshot_links)
        self.solved = solved
        self.residual = residual
        self.condition = condition
        self.condition_time = condition_time
        self.refused = refused


def solve_motion(mech, solver, traj, path, n_snapshots):
    """Solve up to TRAJECTORY_ROWS evenly spaced rows of ``traj`` (read from ``path``) in
    order (the solver follows the branch from one to the next), the ``n_snapshots`` snapshot
    rows among them."""
    active = list(mech.active_joints)
    n = len(traj)
    snapshot_rows = np.unique(np.round(np.linspace(0, n - 1, min(n, n_snapshots))).astype(int))
    rows = np.union1d(np.round(np.linspace(0, n - 1, min(n, TRAJECTORY_ROWS))).astype(int),
                      snapshot_rows)
    q = np.column_stack([traj.columns[trajectory_io.joint_column(j, 'position')][rows]
                         for j in active])
    solver.reset()
    # in order, in pieces that end at the snapshot rows: at the end of each the solver is at
    # the snapshot's pose, whose link poses it gives (cog_poses) without leaving the branch
    wanted = set(snapshot_rows.tolist())
    ends = [k + 1 for k, r in enumerate(rows.tolist()) if r in wanted]
    if not ends or ends[-1] != len(rows):
        ends.append(len(rows))
    valid, errors, positions, residuals, conditions = [], [], [], [], []
    snapshots, links = [], []
    start = 0
    for end in ends:
        part = solver.evaluate(q[start:end], on_invalid='skip')
        valid += np.asarray(part.valid, bool).tolist()
        errors += list(part.errors)
        positions += list(np.asarray(part.positions))
        residuals += np.asarray(part.closure_residual, float).tolist()
        conditions += np.asarray(part.condition_number, float).tolist()
        k = end - 1
        if int(rows[k]) in wanted and valid[k]:
            try:
                cogs, rotations = solver.cog_poses(q[k])
            except CogIdError:              # (at a pose just solved: not expected)
                pass
            else:
                snapshots.append((float(traj.time[rows[k]]), np.array(positions[k])))
                links.append((np.array(cogs), np.array(rotations)))
        start = end
    valid = np.array(valid, bool)
    refused = [(int(rows[k]) + 1, float(traj.time[rows[k]]), one_line(errors[k]))
               for k in np.flatnonzero(~valid)]
    residual = condition = condition_time = None
    if valid.any():
        residual = float(np.max(np.array(residuals)[valid]))
        k = int(np.argmax(np.where(valid, conditions, -np.inf)))
        condition, condition_time = float(conditions[k]), float(traj.time[rows[k]])
    return Motion(path, n, (float(traj.time[0]), float(traj.time[-1])), snapshots,
                  int(valid.sum()), residual, condition, condition_time, refused, links)


def format_motion(motion):
    t0, t1 = motion.time_span
    taken = motion.solved + len(motion.refused)
    lines = [f'trajectory {motion.path}: {motion.n_rows:,} rows, t = {t0:.6g} .. {t1:.6g} s',
             f'  solved {motion.solved} of {taken} rows taken in order along it (evenly spaced, '
             f'the snapshots among them)']
    if motion.residual is not None:
        lines.append(f'  largest closure residual {motion.residual:.3g}, largest condition '
                     f'number {motion.condition:.4g} (t = {motion.condition_time:.6g} s)')
    if motion.snapshots:
        lines.append('  snapshots: t = ' + ', '.join(f'{t:.4g}' for t, _ in motion.snapshots)
                     + ' s')
    for row, time, message in motion.refused[:10]:
        lines += textwrap.wrap(f'WARNING: row {row} (line {row + 1} of the file, t = {time:.6g} '
                               f's) cannot be solved: {message}', WIDTH, subsequent_indent='  ')
    if len(motion.refused) > 10:
        lines.append(f'  ... and {len(motion.refused) - 10} more rows that cannot be solved')
    return lines
