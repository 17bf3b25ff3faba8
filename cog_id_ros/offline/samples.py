"""The samples of a trajectory as the solver takes them: positions, velocities and
accelerations of the active joints, the absent ones estimated (:func:`setpoints`).

Estimates follow the package's one rule (:mod:`cog_id_ros.offline.derivatives`), over
pieces of consecutive kept rows (:func:`kept_pieces`), within time steps of
``MIN_ESTIMATE_STEP`` .. ``MAX_ESTIMATE_STEP``; a row and a column are named
(:class:`~cog_id_ros.offline.trajectory_io.TrajectoryError`) where one cannot be made.
"""

import functools
from typing import Sequence

import numpy as np

from . import derivatives
from .trajectory_io import TIME, Trajectory, TrajectoryError, joint_column

#: time steps (s) between which velocities and accelerations are estimated: outside this
#: range no sampled trajectory is plausible, and inside it 1/h^2 <= 1e18 keeps the
#: estimates of any position below 1e290 finite
MIN_ESTIMATE_STEP = 1e-9
MAX_ESTIMATE_STEP = 1e9


def kept_pieces(keep: np.ndarray, max_gap: int = 1) -> list[np.ndarray]:
    """Split the kept rows (0-based indices of ``keep``) where two or more rows in a row
    were dropped: derivatives are estimated across a single dropped row (a glitch; the
    motion around it is smooth) but never across a longer gap, which may hide any motion."""
    rows = np.flatnonzero(keep)
    if rows.size == 0:
        return []
    return np.split(rows, np.flatnonzero(np.diff(rows) > max_gap + 1) + 1)


def setpoints(traj: Trajectory, active_joints: Sequence[str], keep: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Positions, velocities and accelerations (N, M) of the active joints.

    Absent velocity and acceleration columns are estimated by the package's one rule,
    :func:`cog_id_ros.offline.derivatives.fill_in`: a velocity from the positions; an
    acceleration from the velocity column when the file has one, else from the positions.
    ``keep`` (N,) bool, optional: only these rows are used for (and get) estimates; the
    others (rows skipped before solving) get velocity and acceleration 0. Estimates span a single
    dropped row but not two or more: the kept rows are differentiated in pieces
    (:func:`kept_pieces`; one-sided stencils at the ends of each piece), and every piece
    needs ``derivatives.STENCIL`` rows. Returns ``(q, qd, qdd, estimated)`` where
    ``estimated`` lists the estimated column names.

    Raises :class:`TrajectoryError` when an estimate cannot be made: too few rows (in
    the file or in a piece), a time step outside
    [``MIN_ESTIMATE_STEP``, ``MAX_ESTIMATE_STEP``] (column ``time``, the row after the
    step), or an estimate beyond the range of a double (the position column).
    """
    n = len(traj)
    m = len(active_joints)
    pieces = [np.arange(n)] if keep is None else kept_pieces(keep)
    q = np.empty((n, m))
    qd = np.zeros((n, m))
    qdd = np.zeros((n, m))
    need = [joint_column(j, f) for j in active_joints for f in ('velocity', 'acceleration')
            if joint_column(j, f) not in traj.columns]
    if need:
        check_pieces(traj, pieces, keep is None, need[0])
    estimated = []
    for k, joint in enumerate(active_joints):
        pos = traj.columns[joint_column(joint, 'position')]
        vel = traj.columns.get(joint_column(joint, 'velocity'))
        acc = traj.columns.get(joint_column(joint, 'acceleration'))
        q[:, k] = pos
        if vel is None:
            estimated.append(joint_column(joint, 'velocity'))
        else:
            qd[:, k] = vel
        if acc is None:
            estimated.append(joint_column(joint, 'acceleration'))
        else:
            qdd[:, k] = acc
        if vel is not None and acc is not None:
            continue
        for rows in pieces:
            v, a = derivatives.fill_in(
                traj.time[rows], pos[rows], None if vel is None else vel[rows],
                None if acc is None else acc[rows],
                check=functools.partial(_check_estimate, traj.path, rows, joint))
            qd[rows, k] = v
            qdd[rows, k] = a
    return q, qd, qdd, estimated


def check_pieces(traj: Trajectory, pieces: list[np.ndarray], whole: bool, column: str) -> None:
    """TrajectoryError unless every piece of kept rows (``whole``: the one piece is the
    file) can be differentiated to estimate the absent ``column``: enough rows, usable
    time steps."""
    for rows in pieces:
        if rows.size >= derivatives.STENCIL:
            continue
        if whole:
            raise TrajectoryError(
                traj.path,
                f'absent, and estimating it needs at least {derivatives.STENCIL} rows '
                f'(the file has {len(traj)}); add the column', column=column)
        raise TrajectoryError(
            traj.path,
            f'absent, and estimating it needs at least {derivatives.STENCIL} consecutive rows; '
            f'rows {int(rows[0]) + 1}..{int(rows[-1]) + 1} are {rows.size} between skipped rows',
            row=int(rows[0]) + 1, column=column)
    for rows in pieces:
        _check_steps(traj.path, traj.time[rows], rows, column)


def _check_steps(path, time, rows, column):
    steps = np.diff(time)
    bad = np.flatnonzero(~((steps >= MIN_ESTIMATE_STEP) & (steps <= MAX_ESTIMATE_STEP)))
    if bad.size:
        k = int(bad[0]) + 1
        h = float(steps[k - 1])
        what = 'small' if h < MIN_ESTIMATE_STEP else 'large'
        raise TrajectoryError(
            path, f'the time step to this row, {h!r} s (from row {int(rows[k - 1]) + 1}), is too '
            f'{what} to estimate {column} and the other absent derivatives: estimates need '
            f'steps of {MIN_ESTIMATE_STEP:g} .. {MAX_ESTIMATE_STEP:g} s (rescale the time '
            'column, or give the velocity and acceleration columns)',
            row=int(rows[k]) + 1, column=TIME)


def _check_estimate(path, rows, joint, field, source, result):
    """An estimate of derivatives.fill_in beyond the range of a double: TrajectoryError."""
    finite = np.isfinite(result)
    if not finite.all():
        k = int(np.argmin(finite))
        col = joint_column(joint, source)
        raise TrajectoryError(
            path, f'the estimated {joint_column(joint, field)} here is beyond the range of a '
            f'double: the {source}s change too much for the time steps; give the '
            f'{joint_column(joint, field)} column', row=int(rows[k]) + 1, column=col)
