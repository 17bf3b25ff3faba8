"""The base columns of a floating-base robot's trajectory (``cog_id_torques``): read,
checked, and the absent velocities and accelerations estimated (:func:`setpoints`).

Columns (SI units; the conventions of ``InverseDynamics.whole_body_torques``, Pinocchio's
free flyer):

* ``base.x base.y base.z`` (m): the base's origin in the world frame, and ``base.qx
  base.qy base.qz base.qw``: the unit quaternion of its orientation, world from base.
  Required in every row.
* ``base.vx base.vy base.vz`` (m/s) and ``base.wx base.wy base.wz`` (rad/s): the base's
  linear and angular velocity expressed in the base frame. Optional, six together.
* ``base.dvx .. base.dvz`` (m/s^2) and ``base.dwx .. base.dwz`` (rad/s^2): the time
  derivatives of those six components (the base acceleration in the same frame).
  Optional, six together.

Absent ones are estimated by the package's one rule (:func:`derivatives.estimates`: a
velocity from the pose; an acceleration from the given velocities, else from the pose)
with the same stencils, over the same pieces of kept rows as the joints'
(:mod:`cog_id_ros.offline.samples`). From the pose, with p the position, q the quaternion
(its sign made continuous from row to row first: q and -q are the same orientation) and R
its rotation, dots the stencils' derivatives::

    v = R^T p'          w = 2 Im(conj(q) q')
    v' = R^T p'' - w x v      w' = 2 Im(conj(q) q'')

(the second because conj(q') q' is real). A fixed-base mechanism refuses these columns:
its base does not move, and ignoring them would hide that.
"""

from typing import Callable, NamedTuple

import numpy as np

from ..core.solve.whole_body import quaternion_rotations
from . import derivatives, samples
from .trajectory_io import FIELDS, Trajectory, TrajectoryError

PREFIX = 'base.'
POSE = tuple(PREFIX + c for c in ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw'))
VELOCITY = tuple(PREFIX + c for c in ('vx', 'vy', 'vz', 'wx', 'wy', 'wz'))
ACCELERATION = tuple(PREFIX + c for c in ('dvx', 'dvy', 'dvz', 'dwx', 'dwy', 'dwz'))
COLUMNS = POSE + VELOCITY + ACCELERATION

#: largest | |q| - 1 | of a base quaternion (the core's own bound)
QUATERNION_TOLERANCE = 1e-6

_WHAT = {
    POSE: ('a floating base needs its pose in every row: base.x base.y base.z (m, the '
           "base's origin in the world frame) and base.qx base.qy base.qz base.qw (the unit "
           'quaternion, world from base)'),
    VELOCITY: ('the base velocity columns come six together (base.vx base.vy base.vz in m/s, '
               'base.wx base.wy base.wz in rad/s, in the base frame); give all six, or none '
               'to have them estimated from the base pose'),
    ACCELERATION: ('the base acceleration columns come six together (base.dvx base.dvy '
                   'base.dvz in m/s^2, base.dwx base.dwy base.dwz in rad/s^2: the time '
                   "derivatives of the base velocity's components); give all six, or none to "
                   'have them estimated'),
}


class BaseSamples(NamedTuple):
    """Per row the base's pose (N, 7), velocity (N, 6) and acceleration (N, 6), and the
    names of the columns that were estimated."""

    pose: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    estimated: list[str]


def reading(path: str, mech) -> dict:
    """The keywords of :func:`trajectory_io.read_trajectory` for ``mech``'s base: its
    columns read when it floats, and the header checked (:func:`header_check`)."""
    return {'extra': COLUMNS if mech.floating_base else (),
            'check_header': header_check(path, mech)}


def header_check(path: str, mech) -> Callable[[list[str]], None]:
    """The check of a header's base columns: a fixed base refuses them; a floating base
    needs the pose's seven, the velocity's and acceleration's six together or not at all,
    and no other ``base.<name>`` column (a typo would go unnoticed)."""
    def check(names: list[str]) -> None:
        base = [n for n in names if n.startswith(PREFIX) and n.rpartition('.')[2] not in FIELDS]
        if not mech.floating_base:
            for name in base:
                if name in COLUMNS:
                    raise TrajectoryError(
                        path, f'a base column, but {mech.name} has a fixed base '
                        '(mechanism.floating_base is false): remove the base columns, or set '
                        'mechanism.floating_base: true for a robot whose base floats',
                        header=True, column=name)
            return
        for name in base:
            if name not in COLUMNS:
                raise TrajectoryError(
                    path, f"unknown base column '{name}'; the base columns are "
                    f"{' '.join(POSE)} (required), {' '.join(VELOCITY)} and "
                    f"{' '.join(ACCELERATION)} (optional)", header=True, column=name)
        present = set(names)
        for group in (POSE, VELOCITY, ACCELERATION):
            missing = [c for c in group if c not in present]
            if missing and (group is POSE or len(missing) < len(group)):
                raise TrajectoryError(path, f"missing column '{missing[0]}': {_WHAT[group]}",
                                      header=True, column=missing[0])
    return check


def setpoints(traj: Trajectory, keep: np.ndarray | None = None) -> BaseSamples:
    """The base's pose, velocity and acceleration of every row, the absent ones estimated
    (see the module docstring). ``keep`` as for :func:`samples.setpoints`: only these rows
    are estimated from (pieces of consecutive kept rows); the others get zeros.

    TrajectoryError for a quaternion that is not a unit one (the row), too few rows or
    unusable time steps for an estimate, an estimate beyond the range of a double."""
    n = len(traj)
    pose = np.column_stack([traj.columns[c] for c in POSE])
    _check_quaternions(traj, pose)
    given = [np.column_stack([traj.columns[c] for c in group]) if group[0] in traj.columns
             else None for group in (VELOCITY, ACCELERATION)]
    estimated = [c for group, values in zip((VELOCITY, ACCELERATION), given)
                 if values is None for c in group]
    velocity = np.zeros((n, 6)) if given[0] is None else given[0]
    acceleration = np.zeros((n, 6)) if given[1] is None else given[1]
    if estimated:
        pieces = [np.arange(n)] if keep is None else samples.kept_pieces(keep)
        samples.check_pieces(traj, pieces, keep is None, estimated[0])
        for rows in pieces:
            v, a = estimate(traj.time[rows], pose[rows],
                            None if given[0] is None else given[0][rows],
                            None if given[1] is None else given[1][rows])
            for values, group in ((v, VELOCITY), (a, ACCELERATION)):
                if group[0] in estimated:
                    _check_finite(traj, rows, values, group)
            velocity[rows], acceleration[rows] = v, a
    return BaseSamples(pose, velocity, acceleration, estimated)


def estimate(t: np.ndarray, pose: np.ndarray, velocity: np.ndarray | None,
             acceleration: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(velocity, acceleration) (n, 6) of the base poses ``pose`` (n, 7) at times ``t``:
    given ones as they are, absent ones (None) by the rule of :func:`derivatives.estimates`
    (an acceleration from the given velocity, else from the pose) and the formulas of the
    module docstring (needs derivatives.STENCIL rows and increasing times)."""
    p, q = pose[:, :3], continuous(pose[:, 3:])
    rot = quaternion_rotations(q).reshape(-1, 3, 3)
    with np.errstate(all='ignore'):
        twist = None
        if velocity is None:
            twist = np.hstack([
                np.einsum('nji,nj->ni', rot, derivatives.first_derivative(t, p)),
                2.0 * _im_conj_product(q, derivatives.first_derivative(t, q))])
        if acceleration is None and twist is None:         # from the given velocities
            acceleration = derivatives.first_derivative(t, velocity)
        elif acceleration is None and twist is not None:   # from the pose
            v, w = twist[:, :3], twist[:, 3:]
            linear = np.einsum('nji,nj->ni', rot, derivatives.second_derivative(t, p))
            angular = 2.0 * _im_conj_product(q, derivatives.second_derivative(t, q))
            acceleration = np.hstack([linear - np.cross(w, v), angular])
    return (velocity if twist is None else twist), acceleration


def continuous(q: np.ndarray) -> np.ndarray:
    """Quaternions (n, 4) with signs flipped so that each is on the side of the previous
    one (q and -q are the same orientation; a derivative across a flip is not)."""
    if len(q) < 2:
        return q.copy()
    flips = np.concatenate([[False], np.einsum('ij,ij->i', q[1:], q[:-1]) < 0.0])
    return q * np.where(np.logical_xor.accumulate(flips), -1.0, 1.0)[:, None]


def _im_conj_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Im(conj(a) b) (n, 3) of quaternions (x, y, z, w) (n, 4)."""
    av, aw, bv, bw = a[:, :3], a[:, 3:], b[:, :3], b[:, 3:]
    return aw * bv - bw * av - np.cross(av, bv)


def _check_quaternions(traj: Trajectory, pose: np.ndarray) -> None:
    with np.errstate(all='ignore'):
        norms = np.sqrt(np.sum(pose[:, 3:] ** 2, axis=1))
    bad = np.flatnonzero(~(np.abs(norms - 1.0) <= QUATERNION_TOLERANCE))
    if bad.size:
        k = int(bad[0])
        raise TrajectoryError(
            traj.path, f"columns '{POSE[3]}', '{POSE[4]}', '{POSE[5]}', '{POSE[6]}': the base "
            f'quaternion has norm {norms[k]:.9g}; it must be a unit quaternion (norm 1 within '
            f'{QUATERNION_TOLERANCE:g}): write it normalized', row=k + 1)


def _check_finite(traj: Trajectory, rows: np.ndarray, values: np.ndarray, group) -> None:
    finite = np.isfinite(values)
    if not finite.all():
        k, j = (int(i) for i in np.argwhere(~finite)[0])
        raise TrajectoryError(
            traj.path, f'the estimated {group[j]} here is beyond the range of a double: the '
            'base pose changes too much for the time steps; give the columns '
            f'{group[0]} .. {group[-1]}', row=int(rows[k]) + 1)
