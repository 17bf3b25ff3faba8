"""CSV trajectories in, CSV efforts out: reading, validation and atomic writing.

Input format (the public contract of ``cog_id_torques``): a header row, then one row
per sample, comma-separated, UTF-8 (a byte-order mark is allowed; cells may be quoted).

* ``time``: seconds, strictly increasing (not necessarily even steps or from 0).
* For each active joint ``J``: ``J.position`` (required), ``J.velocity`` and
  ``J.acceleration`` (optional: estimated from the samples when absent, see
  :mod:`cog_id_ros.derivatives`). Angles in radians, never wrapped.
* ``J.position|velocity|acceleration`` columns of a joint of the mechanism that is not
  active are ignored (with a note); the same suffixes on a name that is not a joint of
  the mechanism are an error (a typo would otherwise go unnoticed). Any other column
  (``label``, ``joint3.effort``, ...) is ignored with a note and never parsed.

Row numbering, in every message of this module and of the tool: data rows count from
1 and the header does not count, so "row 17" is the 17th sample and sits on line 18
of the file; messages say both: ``row 17 (line 18 of the file)``. A blank line between
data rows is an error (blank lines at the very end are ignored), so the two numbers
always differ by exactly one.

Output (:func:`write_efforts`): ``time`` and ``J.effort`` per active joint, every value
written with ``repr`` (shortest text that reads back to the same float), the cells of
a skipped sample left empty. Every file is written to a temporary file in the target
directory and renamed into place only when complete (:func:`atomic_output`), so a
failed run leaves no partial file and never clobbers an older one.
"""

import contextlib
import csv
import math
import os
import re
import tempfile

import numpy as np

from . import derivatives

TIME = 'time'
FIELDS = ('position', 'velocity', 'acceleration')
EFFORT = 'effort'


class TrajectoryError(ValueError):
    """A trajectory file that cannot be used; the message names the row and the column.

    ``row`` is the 1-based data row (``None`` for the header or the whole file),
    ``line`` the line of the file, ``column`` the column name (or ``None``).
    """

    def __init__(self, path, message, row=None, column=None, header=False, line=None):
        self.path = str(path)
        self.row = row
        self.column = column
        self.line = line if line is not None else (row + 1 if row is not None else (1 if header else None))
        self.reason = message
        where = []
        if row is not None:
            where.append(f'row {row} (line {self.line} of the file)')
        elif header:
            where.append('header (line 1 of the file)')
        elif line is not None:
            where.append(f'line {line} of the file')
        if column is not None:
            where.append(f"column '{column}'")
        prefix = f'{self.path}: ' + (', '.join(where) + ': ' if where else '')
        super().__init__(prefix + message)


class Trajectory:
    """Parsed samples: ``time`` (N,) and ``columns`` {column name: (N,) float array}.

    Only the columns the tool uses are parsed. ``notes`` lists one human-readable line
    per ignored column group.
    """

    def __init__(self, path, time, columns, notes, header):
        self.path = str(path)
        self.time = time
        self.columns = columns
        self.notes = notes
        self.header = header

    def __len__(self):
        return self.time.size


def joint_column(joint, field):
    return f'{joint}.{field}'


def _split_lines(text):
    if '\r' in text:
        text = text.replace('\r\n', '\n').replace('\r', '\n')
    lines = text.split('\n')
    while lines and not lines[-1].strip():
        lines.pop()
    return lines


def _read_text(path):
    with open(path, 'rb') as f:
        data = f.read()
    try:
        text = data.decode('utf-8-sig')
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b'\n') + 1
        if line == 1:
            raise TrajectoryError(path, f'not UTF-8 text (byte {e.start})', header=True) from None
        raise TrajectoryError(path, f'not UTF-8 text (byte {e.start})', row=line - 1) from None
    return text


def _classify_header(path, names, joints, active_joints):
    """Map the header to used columns; returns ({name: index}, notes)."""
    joints = list(joints)
    active = list(active_joints)
    joint_set = set(joints)
    seen = {}
    for i, name in enumerate(names):
        if name in seen and name:
            raise TrajectoryError(
                path, f'duplicate column name (also column {seen[name] + 1})',
                header=True, column=name)
        seen.setdefault(name, i)
    used = {}
    ignored_inactive = []
    ignored_other = []
    for i, name in enumerate(names):
        if name == TIME:
            used[name] = i
            continue
        joint, dot, field = name.rpartition('.')
        if dot and field in FIELDS:
            if joint not in joint_set:
                raise TrajectoryError(
                    path,
                    f"unknown joint '{joint}' in column {i + 1}; the mechanism's joints are "
                    + ', '.join(joints),
                    header=True, column=name)
            if joint in active:
                used[name] = i
            else:
                ignored_inactive.append(name)
            continue
        ignored_other.append(name if name else f'<column {i + 1}: no name>')
    if TIME not in used:
        raise TrajectoryError(path, f"missing column '{TIME}' (seconds, strictly increasing)",
                              header=True, column=TIME)
    for joint in active:
        col = joint_column(joint, 'position')
        if col not in used:
            raise TrajectoryError(
                path, f"missing column '{col}' (the position of active joint {joint})",
                header=True, column=col)
    notes = []
    if ignored_inactive:
        notes.append('ignoring ' + ', '.join(ignored_inactive)
                     + ': not an active joint (active: ' + ', '.join(active) + ')')
    if ignored_other:
        notes.append('ignoring column(s) ' + ', '.join(ignored_other)
                     + ': not time or <joint>.position|velocity|acceleration')
    return used, notes


def _cells(line):
    return next(csv.reader([line], skipinitialspace=True), [])


def _check_cell_counts(path, lines, n_columns):
    """Every data line of an unquoted file must have exactly ``n_columns`` cells."""
    want = n_columns - 1
    counts = [line.count(',') for line in lines]
    if counts.count(want) == len(counts):
        return
    for k in range(1, len(lines)):
        if counts[k] != want:
            _raise_cell_count(path, k, lines[k], counts[k] + 1, n_columns)


def _raise_cell_count(path, row, line, found, expected):
    if not line.strip():
        raise TrajectoryError(path, 'blank line between data rows', row=row)
    raise TrajectoryError(path, f'expected {expected} cells like the header, found {found}', row=row)


def _parse_cell(text):
    s = text.strip()
    if not s or '_' in s:
        raise ValueError(s)
    return float(s)


def _bad_cell(path, row, name, cell):
    if not cell.strip():
        return TrajectoryError(path, 'empty cell, expected a number', row=row, column=name)
    return TrajectoryError(path, f'{cell.strip()!r} is not a number', row=row, column=name)


def _non_finite(path, row, name, value):
    what = 'NaN' if math.isnan(value) else 'an infinite value'
    return TrajectoryError(path, f'{what} is not allowed here', row=row, column=name)


def _parse_rows(path, lines, n_columns, order):
    """Exact, slow parse with the csv module (files with quotes; error location)."""
    data = np.empty((len(lines) - 1, len(order)))
    for k, line in enumerate(lines[1:], start=1):
        cells = _cells(line)
        if len(cells) != n_columns:
            _raise_cell_count(path, k, line, len(cells), n_columns)
        for j, (name, i) in enumerate(order):
            try:
                value = data[k - 1, j] = _parse_cell(cells[i])
            except ValueError:
                raise _bad_cell(path, k, name, cells[i]) from None
            if not math.isfinite(value):
                raise _non_finite(path, k, name, value)
    return data


def _locate_bad_cell(path, lines, n_columns, order, numpy_message):
    """After numpy failed: find the first bad cell exactly (always raises)."""
    _parse_rows(path, lines, n_columns, order)
    m = re.search(r'at row (\d+)', numpy_message)
    row = int(m.group(1)) + 1 if m else None
    raise TrajectoryError(path, f'cannot parse: {numpy_message}', row=row)


def read_trajectory(path, joints, active_joints):
    """Read and validate a trajectory CSV for a mechanism (``joints``, ``active_joints``).

    Raises :class:`TrajectoryError` naming the row and column of the first problem:
    a missing, duplicate or unknown column, a ragged or blank row, a cell that is not a
    number, NaN or infinity, and a time that does not strictly increase.
    ``OSError`` propagates when the file cannot be read.
    """
    text = _read_text(path)
    quoted = '"' in text
    lines = _split_lines(text)
    del text   # a million-row file: keep only the lines
    if not lines:
        raise TrajectoryError(path, 'the file is empty; expected a header row such as '
                              f"'{TIME},{joint_column(active_joints[0], 'position')}'", line=1)
    names = [name.strip() for name in _cells(lines[0])]
    used, notes = _classify_header(path, names, joints, active_joints)
    if len(lines) < 2:
        raise TrajectoryError(path, 'no data rows after the header', header=True)
    order = sorted(used.items(), key=lambda kv: kv[1])
    if quoted:
        data = _parse_rows(path, lines, len(names), order)
    else:
        _check_cell_counts(path, lines, len(names))
        try:
            data = np.loadtxt(lines[1:], delimiter=',', comments=None, usecols=[i for _, i in order],
                              dtype=float, ndmin=2)
        except ValueError as e:
            _locate_bad_cell(path, lines, len(names), order, str(e))
    finite = np.isfinite(data)
    if not finite.all():
        bad_row, bad_col = np.argwhere(~finite)[0]
        raise _non_finite(path, int(bad_row) + 1, order[bad_col][0], float(data[bad_row, bad_col]))
    columns = {name: np.ascontiguousarray(data[:, j]) for j, (name, _) in enumerate(order)}
    time = columns.pop(TIME)
    steps = np.diff(time)
    if steps.size and not (steps > 0).all():
        k = int(np.argmin(steps > 0)) + 1  # 0-based index of the offending sample
        raise TrajectoryError(
            path, f'time {float(time[k])!r} does not increase strictly (the row before has '
            f'{float(time[k - 1])!r})', row=k + 1, column=TIME)
    return Trajectory(path, time, columns, notes, names)


def setpoints(traj, active_joints):
    """Positions, velocities and accelerations (N, M) of the active joints.

    Absent velocity and acceleration columns are estimated with
    :mod:`cog_id_ros.derivatives`: a velocity from the positions; an acceleration from
    the velocity column when the file has one, else from the positions. Returns
    ``(q, qd, qdd, estimated)`` where ``estimated`` lists the estimated column names.
    """
    n = len(traj)
    m = len(active_joints)
    q = np.empty((n, m))
    qd = np.empty((n, m))
    qdd = np.empty((n, m))
    estimated = []
    for k, joint in enumerate(active_joints):
        pos = traj.columns[joint_column(joint, 'position')]
        vel = traj.columns.get(joint_column(joint, 'velocity'))
        acc = traj.columns.get(joint_column(joint, 'acceleration'))
        q[:, k] = pos
        for name, present in (('velocity', vel), ('acceleration', acc)):
            if present is None and n < derivatives.STENCIL:
                col = joint_column(joint, name)
                raise TrajectoryError(
                    traj.path,
                    f'absent, and estimating it needs at least {derivatives.STENCIL} rows '
                    f'(the file has {n}); add the column', column=col)
        if vel is None:
            qd[:, k] = derivatives.first_derivative(traj.time, pos)
            estimated.append(joint_column(joint, 'velocity'))
        else:
            qd[:, k] = vel
        if acc is None:
            if vel is None:
                qdd[:, k] = derivatives.second_derivative(traj.time, pos)
            else:
                qdd[:, k] = derivatives.first_derivative(traj.time, vel)
            estimated.append(joint_column(joint, 'acceleration'))
        else:
            qdd[:, k] = acc
    return q, qd, qdd, estimated


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(path):
    """Yield a temporary path next to ``path``; rename it to ``path`` on success only.

    On an exception the temporary file is removed and ``path`` is left as it was.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix='.' + os.path.basename(path) + '.',
                               suffix='.tmp')
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def format_efforts(time, efforts, valid, active_joints, block=100_000):
    """Yield the output CSV text in blocks (header first)."""
    time = np.asarray(time, dtype=float)
    efforts = np.asarray(efforts, dtype=float).reshape(time.size, -1)
    valid = np.ones(time.size, bool) if valid is None else np.asarray(valid, bool)
    yield ','.join([TIME] + [joint_column(j, EFFORT) for j in active_joints]) + '\n'
    for start in range(0, time.size, block):
        stop = min(start + block, time.size)
        ok = valid[start:stop]
        cols = [list(map(repr, time[start:stop].tolist()))]
        for k in range(efforts.shape[1]):
            cells = list(map(repr, efforts[start:stop, k].tolist()))
            if not ok.all():
                for i in np.flatnonzero(~ok).tolist():
                    cells[i] = ''
            cols.append(cells)
        yield '\n'.join(map(','.join, zip(*cols))) + '\n'


def write_efforts(path, time, efforts, valid, active_joints):
    """Write the output CSV atomically (see the module docstring for the format)."""
    with atomic_output(path) as tmp:
        with open(tmp, 'w', encoding='utf-8', newline='') as f:
            for chunk in format_efforts(time, efforts, valid, active_joints):
                f.write(chunk)


def read_efforts(path):
    """Read an output CSV back: ``(header, time, efforts)`` with NaN for empty cells."""
    with open(path, encoding='utf-8', newline='') as f:
        rows = list(csv.reader(f))
    header = rows[0]
    values = np.array([[float(c) if c else np.nan for c in row] for row in rows[1:]],
                      dtype=float).reshape(len(rows) - 1, len(header))
    return header, values[:, 0], values[:, 1:]
