"""The inputs of ``cog_id_simulate``: the efforts file read (the torque tool's output
format, :func:`read_efforts`), the effort each step holds (:func:`step_efforts`), the initial
state (:func:`initial_state`), the reference motion (:func:`read_reference`), and the checks
of the steps and paths; every problem a ToolError naming what to fix, numbers in it as
Python writes a float (``0.5``, not numpy's ``np.float64(0.5)``).

Columns, as ``cog_id_torques`` reads its input: ``<name>.<field>`` with a field of the
package's CSV formats (JOINT_FIELDS) names a joint, and an unknown ``<name>`` is an error
(most likely a joint's name mistyped); the columns of a joint that is not active, and any
other column (``label``, ``joint3.acceleration`` in an efforts file), are ignored with a
note.
"""
import argparse
import math
import os
from typing import Sequence, TextIO

import numpy as np

from ..core.model.mechanism import Mechanism
from . import samples, trajectory_io
from .console import EXIT_INPUT, EXIT_USAGE, ToolError, output_target
from .trajectory_io import EFFORT, Trajectory, TrajectoryError, joint_column

PROG = 'cog_id_simulate'
#: more steps than this is refused (a 1e9 s file at 1 ms): a larger --time-step, or less time
MAX_STEPS = 100_000_000
#: an input time within this fraction of a step of a step boundary is on it
GRID_TOLERANCE = 1e-9
#: the fields of the package's CSV formats (trajectories, efforts, motions): a column
#: ``<name>.<field>`` names a joint in every file the tool reads, whatever fields it uses
JOINT_FIELDS = ('position', 'velocity', 'acceleration', EFFORT)


def _num(x: float) -> str:
    """A number for a message, as Python writes a float: '0.5', never 'np.float64(0.5)'."""
    return repr(float(x))


def read_csv(path: str, mech: Mechanism, **how: object) -> Trajectory:
    """:func:`trajectory_io.read_trajectory` of ``path`` for ``mech`` (``how``: its
    ``fields``, ``required``, ``first_row``), with a column ``<name>.<field>`` of any of
    JOINT_FIELDS an error when ``<name>`` is not a joint of ``mech``, as cog_id_torques
    refuses one (a field the tool does not read included: a typo of a joint's name);
    TrajectoryError naming the column."""
    joints = list(mech.joints) + list(mech.closure_joints)
    traj = trajectory_io.read_trajectory(path, joints, list(mech.active_joints), **how)
    for i, name in enumerate(traj.header):
        joint, dot, field = name.rpartition('.')
        if dot and field in JOINT_FIELDS and joint not in joints:
            raise TrajectoryError(path, f"unknown joint '{joint}' in column {i + 1}; the "
                                        "mechanism's joints are " + ', '.join(joints),
                                  header=True, column=name)
    return traj


def step_count(time: np.ndarray, h: float) -> int:
    """Steps of ``h`` from the first time to the last (the last that ends at or before it)."""
    span = float(time[-1] - time[0])
    return int(math.floor(span / h + GRID_TOLERANCE)) if span > 0 else 0


def step_efforts(time: np.ndarray, efforts: np.ndarray, h: float, n_steps: int,
                 linear: bool = False) -> tuple[np.ndarray, int]:
    """The effort each of ``n_steps`` steps of ``h`` from ``time[0]`` holds, ``(n_steps, M)``,
    and how many steps span a row's time.

    ``linear`` False (the contract): row i's effort acts from ``time[i]`` until
    ``time[i + 1]`` (the last row's for one step). A step inside one row's interval (to
    GRID_TOLERANCE of a step) holds that row's effort bit for bit; a step that spans a change
    holds the time average over the step. ``linear`` True (``--between-rows linear``): the
    rows are samples of a continuous effort, joined by straight lines, and each step holds
    the mean of that line over the step."""
    n = time.size
    starts = time[0] + h * np.arange(n_steps)
    ends = time[0] + h * np.arange(1, n_steps + 1)
    tol = GRID_TOLERANCE * h
    first = np.searchsorted(time, starts + tol, side='right') - 1
    last = np.searchsorted(time, ends - tol, side='left') - 1
    if linear:
        nxt = np.minimum(first + 1, n - 1)
        gap = time[nxt] - time[first]
        frac = np.divide(0.5 * (starts + ends) - time[first], gap, out=np.zeros(n_steps),
                         where=gap > 0)
        held = efforts[first] + frac[:, None] * (efforts[nxt] - efforts[first])
    else:
        held = efforts[first].copy()
    spans = np.flatnonzero(last > first)
    bounds = np.append(time, time[-1] + h)
    for k in spans.tolist():
        rows = np.arange(first[k], last[k] + 1)
        lo = np.maximum(bounds[rows], starts[k])
        hi = np.minimum(bounds[rows + 1], ends[k])
        values = efforts[rows]
        if linear:
            nxt = np.minimum(rows + 1, n - 1)
            gap = np.where(nxt > rows, time[nxt] - time[rows], 1.0)
            values = values + (((lo + hi) / 2 - time[rows]) / gap)[:, None] * (
                efforts[nxt] - values)
        held[k] = (hi - lo) @ values / (ends[k] - starts[k])
    return held, int(spans.size)


def _columns(traj: Trajectory, active: Sequence[str], field: str) -> np.ndarray | None:
    """``(N, M)`` of the ``field`` columns of every active joint, or None when there are none;
    ToolError naming the missing ones when only some joints have one."""
    names = [joint_column(j, field) for j in active]
    have = [name for name in names if name in traj.first_row]
    if not have:
        return None
    if len(have) < len(names):
        missing = [name for name in names if name not in traj.first_row]
        raise ToolError(f"{traj.path}: has {', '.join(have)} but not {', '.join(missing)}: "
                        f'the initial state needs the {field} of every active joint (or of '
                        'none)', EXIT_INPUT)
    return np.array([[traj.first_row[name] for name in names]])


def initial_state(args: argparse.Namespace, mech: Mechanism, traj: Trajectory, stderr: TextIO
                  ) -> tuple[list | None, list | None, str]:
    """(active positions or None, active velocities or None, where they come from)."""
    active = list(mech.active_joints)
    if args.initial_state:
        try:
            state = read_csv(args.initial_state, mech)
            q, qd, _, estimated = samples.setpoints(state, active)
        except TrajectoryError as exc:
            raise ToolError(f'--initial-state {exc}', EXIT_INPUT) from None
        except OSError as exc:
            raise ToolError(f'--initial-state {args.initial_state}: cannot read: '
                            f'{exc.strerror or exc}', EXIT_USAGE) from None
        if abs(state.time[0] - traj.time[0]) > GRID_TOLERANCE * args.time_step:
            print(f'{PROG}: note: --initial-state starts at t = {_num(state.time[0])} s, '
                  f'--input at t = {_num(traj.time[0])} s: the state of its first row is '
                  'taken as the state at the first input time', file=stderr)
        how = 'estimated' if estimated else 'given'
        return (q[0].tolist(), qd[0].tolist(),
                f'row 1 of {os.path.basename(args.initial_state)} (velocities {how})')
    q = _columns(traj, active, 'position')
    qd = _columns(traj, active, 'velocity')
    if q is None and qd is None:
        return None, None, 'initial_positions, at rest'
    where = (('positions' if q is not None else '') + (' and ' if q is not None and qd is not None
             else '') + ('velocities' if qd is not None else ''))
    rest = ('' if q is not None else ', positions initial_positions') + (
        '' if qd is not None else ', at rest')
    return (None if q is None else q[0].tolist(), None if qd is None else qd[0].tolist(),
            f'{where} of row 1 of {os.path.basename(args.input)}{rest}')


def read_efforts(args: argparse.Namespace, mech: Mechanism, stderr: TextIO
                 ) -> tuple[Trajectory, np.ndarray]:
    """The efforts file: (Trajectory, efforts (N, M)); ToolError naming a bad row/column."""
    active = list(mech.active_joints)
    try:
        traj = read_csv(args.input, mech, fields=(EFFORT, 'position', 'velocity'),
                        required=EFFORT, first_row=('position', 'velocity'))
    except TrajectoryError as exc:
        hint = ''
        if exc.column and exc.column.endswith('.' + EFFORT) and exc.reason.startswith('empty'):
            hint = ('; cog_id_torques --skip-invalid leaves the efforts of a row it could not '
                    'solve empty: fix that row of its input, or remove the row')
        raise ToolError(f'{exc}{hint}', EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--input {args.input}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    for note in traj.notes:
        print(f'{PROG}: note: {args.input}: {note}', file=stderr)
    return traj, np.column_stack([traj.columns[joint_column(j, EFFORT)] for j in active])


def read_reference(args: argparse.Namespace, mech: Mechanism, time: np.ndarray
                   ) -> np.ndarray | None:
    """The --reference positions of the active joints at the step times ``time``
    (linear interpolation; NaN outside the reference's time span), or None."""
    if not args.reference:
        return None
    active = list(mech.active_joints)
    try:
        ref = read_csv(args.reference, mech)
    except TrajectoryError as exc:
        raise ToolError(f'--reference {exc}', EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--reference {args.reference}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    tol = GRID_TOLERANCE * args.time_step
    inside = (time >= ref.time[0] - tol) & (time <= ref.time[-1] + tol)
    if not inside.any():
        raise ToolError(f'--reference {args.reference}: its times ({_num(ref.time[0])} .. '
                        f"{_num(ref.time[-1])} s) do not overlap the simulation's "
                        f'({_num(time[0])} .. {_num(time[-1])} s)', EXIT_INPUT)
    values = np.full((time.size, len(active)), np.nan)
    for k, joint in enumerate(active):
        values[inside, k] = np.interp(time[inside], ref.time,
                                      ref.columns[joint_column(joint, 'position')])
    return values


def check_steps(args: argparse.Namespace, time: np.ndarray) -> int:
    """The number of steps; ToolError when the run cannot be made with this --time-step."""
    h = args.time_step
    n_steps = step_count(time, h)
    if n_steps > MAX_STEPS:
        raise ToolError(f'--time-step {_num(h)}: {n_steps:,} steps from t = {_num(time[0])} '
                        f'to {_num(time[-1])} s, more than {MAX_STEPS:,}: use a larger '
                        '--time-step or split the input', EXIT_USAGE)
    largest = float(max(abs(time[0]), abs(time[-1])))
    if np.spacing(largest) * 1e3 > h:
        raise ToolError(f'--time-step {_num(h)}: too small for times of {_num(largest)} s (a '
                        'double there is not fine enough to count steps): subtract the start '
                        'time from the time column', EXIT_USAGE)
    return n_steps


def check_inputs(args: argparse.Namespace) -> None:
    for option in ('initial_state', 'reference'):
        path = getattr(args, option)
        name = '--' + option.replace('_', '-')
        if path is not None and not os.path.isfile(path):
            what = 'no such file' if not os.path.exists(path) else 'not a regular file'
            raise ToolError(f'{name} {path}: {what}', EXIT_USAGE)
        if path is not None and os.path.exists(args.output) and os.path.samefile(
                path, output_target('--output', args.output)[0]):
            raise ToolError(f'--output {args.output}: is the {name} file', EXIT_USAGE)
