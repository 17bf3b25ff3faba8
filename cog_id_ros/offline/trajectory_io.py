"""CSV trajectories in, CSV efforts out: reading and validation, the efforts' format.

Input format (the public contract of ``cog_id_torques``): a header row, then one row
per sample, comma-separated, UTF-8 (a byte-order mark is allowed; cells may be quoted).

* ``time``: seconds, strictly increasing (not necessarily even steps or from 0).
* For each active joint ``J``: ``J.position`` (required), ``J.velocity`` and
  ``J.acceleration`` (optional: estimated from the samples when absent, see
  :mod:`cog_id_ros.offline.samples`). Angles in radians, not wrapped (``cog_id_torques
  --unwrap`` unwraps them with :func:`cog_id_ros.offline.jumps.unwrap_positions`).
* ``J.position|velocity|acceleration`` columns of a joint of the mechanism that is not
  active are ignored (with a note); the same suffixes on a name that is not a joint of
  the mechanism are an error (a typo would otherwise go unnoticed). Any other column
  (``label``, ``joint3.effort``, ...) is ignored with a note and never parsed.
* A floating-base mechanism's base columns (``base.x`` ... ``base.qw``, optional
  velocities and accelerations) are read too: :mod:`cog_id_ros.offline.base_samples`.

Row numbering, in every message of this module and of the tool: data rows count from
1 and the header does not count, so "row 17" is the 17th sample and sits on line 18
of the file; messages say both: ``row 17 (line 18 of the file)``. A blank line between
data rows is an error (blank lines at the very end are ignored), so the two numbers
always differ by exactly one.

Output (:func:`write_efforts`): ``time`` and ``J.effort`` per active joint, every value
written with ``repr`` (shortest text that reads back to the same float), the cells of
a skipped sample left empty (a floating base's wrench columns follow the efforts:
``extra_columns``). Every file is written to a temporary file in the target
directory and renamed into place only when complete
(:func:`cog_id_ros.offline.atomic_files.atomic_output`), so a failed run leaves no partial
file and never clobbers an older one.
"""

import csv
import math
import re
from typing import Callable, Iterator, Sequence

import numpy as np

from .atomic_files import PathLike, atomic_output

TIME = 'time'
FIELDS = ('position', 'velocity', 'acceleration')
EFFORT = 'effort'

#: at most this many characters of a cell are quoted in a message (a 50 MB cell is not)
_MAX_QUOTED = 40
#: at most this many ignored column names are listed in a note
_MAX_LISTED_COLUMNS = 10


class TrajectoryError(ValueError):
    """A trajectory file that cannot be used; the message names the row and the column.

    ``row`` is the 1-based data row (``None`` for the header or the whole file),
    ``line`` the line of the file, ``column`` the column name (or ``None``).
    """

    def __init__(self, path, message, row=None, column=None, header=False, line=None):
        self.path = str(path)
        self.row = row
        self.column = column
        if line is None:
            line = row + 1 if row is not None else (1 if header else None)
        self.line = line
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
    per ignored column group. ``first_row``: {column name: value} of the columns read on
    the first row only (see :func:`read_trajectory`).
    """

    def __init__(self, path, time, columns, notes, header):
        self.path = str(path)
        self.time = time
        self.columns = columns
        self.notes = notes
        self.header = header
        self.first_row = {}

    def __len__(self):
        return self.time.size


def joint_column(joint: str, field: str) -> str:
    return f'{joint}.{field}'


def _split_lines(text):
    if '\r' in text:
        text = text.replace('\r\n', '\n').replace('\r', '\n')
    lines = text.split('\n')
    while lines and not lines[-1].strip():
        lines.pop()
    return lines


_UTF16_BOMS = (b'\xff\xfe', b'\xfe\xff')


def _read_text(path):
    with open(path, 'rb') as f:
        data = f.read()
    if data[:2] in _UTF16_BOMS or data[:4] in (b'\xff\xfe\x00\x00', b'\x00\x00\xfe\xff'):
        raise TrajectoryError(path, 'the file is UTF-16 or UTF-32 text (it starts with that '
                              'byte-order mark); save it as UTF-8', header=True)
    if b'\x00' in data[:4096]:
        raise TrajectoryError(path, 'binary data (a NUL byte near the start), not a CSV text '
                              'file', header=True)
    try:
        text = data.decode('utf-8-sig')
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b'\n') + 1
        if line == 1:
            raise TrajectoryError(path, f'not UTF-8 text (byte {e.start})', header=True) from None
        raise TrajectoryError(path, f'not UTF-8 text (byte {e.start})', row=line - 1) from None
    return text


def _classify_header(path, names, joints, active_joints, fields=FIELDS, required='position',
                     role='active joint', extra=()):
    """Map the header to used columns (``<joint>.<field>`` for ``fields``; ``required`` the
    field every active joint must have; ``role``: what the read joints are called in the
    messages; ``extra``: other column names read when present); returns ({name: index},
    notes)."""
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
        if name == TIME or name in extra:
            used[name] = i
            continue
        joint, dot, field = name.rpartition('.')
        if dot and field in fields:
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
        col = joint_column(joint, required)
        if col not in used:
            raise TrajectoryError(
                path, f"missing column '{col}' (the {required} of {role} {joint})",
                header=True, column=col)
    notes = []
    if ignored_inactive:
        article = 'an' if role[0] in 'aeiou' else 'a'
        which = 'active' if role == 'active joint' else f'{role}s'
        notes.append('ignoring ' + _name_list(ignored_inactive)
                     + f': not {article} {role} ({which}: ' + ', '.join(active) + ')')
    if ignored_other:
        notes.append('ignoring column(s) ' + _name_list(ignored_other)
                     + ': not time or <joint>.' + '|'.join(fields))
    return used, notes


def _name_list(names):
    """At most _MAX_LISTED_COLUMNS names (a file may have a million columns)."""
    names = [_quoted(n, quote=False) for n in names[:_MAX_LISTED_COLUMNS]] + (
        [f'... ({len(names) - _MAX_LISTED_COLUMNS:,} more)']
        if len(names) > _MAX_LISTED_COLUMNS else [])
    return ', '.join(names)


def _quoted(text, quote=True):
    """A cell for a message: repr-quoted, cut to _MAX_QUOTED characters."""
    short = text if len(text) <= _MAX_QUOTED else \
        text[:_MAX_QUOTED] + f'... ({len(text):,} characters)'
    return repr(short) if quote else short


def _cells(line):
    try:
        return next(csv.reader([line], skipinitialspace=True), [])
    except csv.Error:       # a cell over the csv module's field limit (131,072 characters)
        return line.split(',')


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
    raise TrajectoryError(path, f'expected {expected} cells like the header, found {found}',
                          row=row)


def _parse_cell(text):
    s = text.strip()
    if not s or '_' in s or not s.isascii():   # as numpy reads: no '1_0', no '\uff11'
        raise ValueError(s)
    return float(s)


def _bad_cell(path, row, name, cell):
    if not cell.strip():
        return TrajectoryError(path, 'empty cell, expected a number', row=row, column=name)
    return TrajectoryError(path, f'{_quoted(cell.strip())} is not a number', row=row, column=name)


_INF_WORDS = ('inf', '+inf', '-inf', 'infinity', '+infinity', '-infinity')


def _non_finite(path, row, name, value, cell=None):
    if math.isnan(value):
        what = 'NaN is not allowed here'
    elif cell is not None and cell.strip().strip('"').strip().lower() not in _INF_WORDS:
        what = (f'{_quoted(cell.strip())} is beyond the range of a double '
                '(|x| <= 1.8e308); such a value cannot be computed with')
    else:
        what = 'an infinite value is not allowed here'
    return TrajectoryError(path, what, row=row, column=name)


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
                raise _non_finite(path, k, name, value, cells[i])
    return data


def _locate_bad_cell(path, lines, n_columns, order, numpy_message):
    """After numpy failed: find the first bad cell exactly (always raises)."""
    _parse_rows(path, lines, n_columns, order)
    m = re.search(r'at row (\d+)', numpy_message)
    row = int(m.group(1)) + 1 if m else None
    raise TrajectoryError(path, f'cannot parse: {numpy_message}', row=row)


def read_trajectory(path: PathLike, joints: Sequence[str], active_joints: Sequence[str],
                    fields: Sequence[str] = FIELDS, required: str = 'position',
                    first_row: Sequence[str] = (), role: str = 'active joint',
                    extra: Sequence[str] = (),
                    check_header: Callable[[list[str]], None] | None = None) -> 'Trajectory':
    """Read and validate a trajectory CSV for a mechanism (``joints``, ``active_joints``).

    ``fields``: the ``<joint>.<field>`` columns read (a trajectory's position, velocity and
    acceleration; ``cog_id_simulate`` reads an efforts file with effort, position and
    velocity); ``required``: the field every active joint must have a column of;
    ``first_row``: fields of ``fields`` read on the first data row only (the other rows'
    cells are not parsed), into ``Trajectory.first_row`` {column name: float}; ``role``:
    what ``active_joints`` are called in the messages ('joint-space joint' for
    ``cog_id_torques --space joint``); ``extra``: other column names read (parsed and
    checked like the joints' columns) when the header has them (a floating base's
    ``base.x`` ...); ``check_header(names)``, optional, sees the header's names before any
    row is parsed and may raise :class:`TrajectoryError`.

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
                              f"'{TIME},{joint_column(active_joints[0], required)}'", line=1)
    names = [name.strip() for name in _cells(lines[0])]
    used, notes = _classify_header(path, names, joints, active_joints, fields, required, role,
                                   frozenset(extra))
    if check_header is not None:
        check_header(names)
    if len(lines) < 2:
        raise TrajectoryError(path, 'no data rows after the header', header=True)
    once = {name: i for name, i in used.items() if name.rpartition('.')[2] in first_row}
    order = sorted(((n, i) for n, i in used.items() if n not in once), key=lambda kv: kv[1])
    if quoted:
        data = _parse_rows(path, lines, len(names), order)
    else:
        _check_cell_counts(path, lines, len(names))
        try:
            data = np.loadtxt(lines[1:], delimiter=',', comments=None,
                              usecols=[i for _, i in order], dtype=float, ndmin=2)
        except ValueError as e:
            _locate_bad_cell(path, lines, len(names), order, str(e))
    finite = np.isfinite(data)
    if not finite.all():
        bad_row, bad_col = (int(i) for i in np.argwhere(~finite)[0])
        cell = _cells(lines[bad_row + 1])[order[bad_col][1]]
        raise _non_finite(path, bad_row + 1, order[bad_col][0], float(data[bad_row, bad_col]),
                          cell)
    columns = {name: np.ascontiguousarray(data[:, j]) for j, (name, _) in enumerate(order)}
    time = columns.pop(TIME)
    steps = np.diff(time)
    if steps.size and not (steps > 0).all():
        k = int(np.argmin(steps > 0)) + 1  # 0-based index of the offending sample
        raise TrajectoryError(
            path, f'time {float(time[k])!r} does not increase strictly (the row before has '
            f'{float(time[k - 1])!r})', row=k + 1, column=TIME)
    traj = Trajectory(path, time, columns, notes, names)
    traj.first_row = dict(zip(once, map(float, _parse_rows(
        path, lines[:2], len(names), list(once.items()))[0])))
    return traj


def format_efforts(time: np.ndarray, efforts: np.ndarray, valid: np.ndarray,
                   active_joints: Sequence[str], block: int = 100_000,
                   extra_columns: Sequence[str] = ()) -> Iterator[str]:
    """Yield the output CSV text in blocks (header first). ``extra_columns``: the names of
    the columns of ``efforts`` after the active joints' (a floating base's wrenches)."""
    time = np.asarray(time, dtype=float)
    efforts = np.asarray(efforts, dtype=float).reshape(time.size, -1)
    valid = np.ones(time.size, bool) if valid is None else np.asarray(valid, bool)
    yield ','.join(_csv_cell(cell) for cell in
                   [TIME] + [joint_column(j, EFFORT) for j in active_joints]
                   + list(extra_columns)) + '\n'
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


def _csv_cell(text: str) -> str:
    """A header cell as CSV writes it: a joint name with ',', '"', a line break or spaces
    at its ends quoted (any name is a joint's: docs/mechanism.md), others as they are."""
    if any(c in text for c in ',"\r\n') or text != text.strip():
        return '"' + text.replace('"', '""') + '"'
    return text


def write_efforts(path: PathLike, time: np.ndarray, efforts: np.ndarray, valid: np.ndarray,
                  active_joints: Sequence[str]) -> None:
    """Write the output CSV atomically (see the module docstring for the format)."""
    with atomic_output(path) as tmp:
        with open(tmp, 'w', encoding='utf-8', newline='') as f:
            for chunk in format_efforts(time, efforts, valid, active_joints):
                f.write(chunk)


def read_efforts(path: PathLike) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Read an output CSV back: ``(header, time, efforts)`` with NaN for empty cells."""
    with open(path, encoding='utf-8', newline='') as f:
        rows = list(csv.reader(f))
    header = rows[0]
    values = np.array([[float(c) if c else np.nan for c in row] for row in rows[1:]],
                      dtype=float).reshape(len(rows) - 1, len(header))
    return header, values[:, 0], values[:, 1:]
