"""CSV trajectories in, CSV efforts out: reading, validation and atomic writing.

Input format (the public contract of ``cog_id_torques``): a header row, then one row
per sample, comma-separated, UTF-8 (a byte-order mark is allowed; cells may be quoted).

* ``time``: seconds, strictly increasing (not necessarily even steps or from 0).
* For each active joint ``J``: ``J.position`` (required), ``J.velocity`` and
  ``J.acceleration`` (optional: estimated from the samples when absent, see
  :mod:`cog_id_ros.offline.derivatives`). Angles in radians, not wrapped (``cog_id_torques
  --unwrap`` unwraps them with :func:`unwrap_positions`).
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
import functools
import math
import os
import re
import signal
import stat
import tempfile
from typing import Iterator, Sequence, Union

import numpy as np

from . import derivatives

PathLike = Union[str, os.PathLike]

TIME = 'time'
FIELDS = ('position', 'velocity', 'acceleration')
EFFORT = 'effort'

#: time steps (s) between which velocities and accelerations are estimated: outside this
#: range no sampled trajectory is plausible, and inside it 1/h^2 <= 1e18 keeps the
#: estimates of any position below 1e290 finite
MIN_ESTIMATE_STEP = 1e-9
MAX_ESTIMATE_STEP = 1e9

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
        notes.append('ignoring ' + _name_list(ignored_inactive)
                     + ': not an active joint (active: ' + ', '.join(active) + ')')
    if ignored_other:
        notes.append('ignoring column(s) ' + _name_list(ignored_other)
                     + ': not time or <joint>.position|velocity|acceleration')
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


def read_trajectory(path: PathLike, joints: Sequence[str],
                    active_joints: Sequence[str]) -> 'Trajectory':
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
    return Trajectory(path, time, columns, notes, names)


def unwrap_positions(traj: 'Trajectory', joints: Sequence[str]) -> dict[str, tuple[int, int]]:
    """Unwrap the position columns of ``joints`` (revolute ones) in place.

    Each position is replaced by its 2 pi equivalent nearest the previous row's (already
    unwrapped) position, as an encoder of a continuous joint that reports angles in
    (-pi, pi] needs. A step too large for that to mean anything (2^50 or more) is left as
    it is (the jump check reports it). Returns ``{column: (rows shifted, wraps)}``: how
    many rows now differ from the file and at how many rows a wrap was undone.
    """
    result = {}
    for joint in joints:
        name = joint_column(joint, 'position')
        q = traj.columns[name]
        with np.errstate(all='ignore'):
            d = np.diff(q)
            turns = np.round(d / (2.0 * math.pi))
            turns[~(np.abs(d) < 2.0 ** 50)] = 0.0
            total = np.cumsum(turns)
            shifted = np.flatnonzero(total != 0.0) + 1
            if shifted.size:
                q = q.copy()
                q[shifted] = q[shifted] - (2.0 * math.pi) * total[shifted - 1]
                traj.columns[name] = q
        result[name] = (int(shifted.size), int(np.count_nonzero(turns)))
    return result


def find_jumps(q: np.ndarray, limits: np.ndarray,
               block: int = 4096) -> list[tuple[int, int, float, int]]:
    """Rows whose position jumps from the last accepted row by more than ``limits``.

    ``q`` (N, M) positions, ``limits`` (M,) the largest step per row of each column.
    A row is compared with the last row that was not itself a jump, so one wild row is
    one jump (not two) and everything after an unwrapped 2 pi step is one. Returns
    ``[(row, k, step, ref_row)]``, rows 1-based: column ``k`` of ``row`` is
    ``step`` away from ``ref_row`` (the column with the largest step relative to its limit).
    """
    q = np.asarray(q, dtype=float)
    limits = np.asarray(limits, dtype=float)
    n = q.shape[0]
    jumps = []
    if n < 2:
        return jumps
    with np.errstate(all='ignore'):
        flagged = np.flatnonzero(~np.all(np.abs(np.diff(q, axis=0)) <= limits, axis=1))
        i = 1                     # next row to check; its predecessor is accepted
        while i < n:
            at = np.searchsorted(flagged, i - 1)
            if at == flagged.size:
                break
            ref = int(flagged[at])  # accepted; row ref + 1 jumps from it
            j = ref + 1
            accepted = None
            while j < n and accepted is None:
                part = np.abs(q[j:j + block] - q[ref])
                ok = np.all(part <= limits, axis=1)
                stop = j + int(np.argmax(ok)) if ok.any() else min(j + block, n)
                ratio = part[:stop - j] / limits
                ratio[np.isnan(ratio)] = np.inf
                for r, k in zip(range(j, stop), np.argmax(ratio, axis=1).tolist()):
                    jumps.append((r + 1, k, float(q[r, k] - q[ref, k]), ref + 1))
                if ok.any():
                    accepted = stop
                j = stop
            if accepted is None:
                break
            i = accepted + 1
    return jumps


def kept_pieces(keep: np.ndarray, max_gap: int = 1) -> list[np.ndarray]:
    """Split the kept rows (0-based indices of ``keep``) where two or more rows in a row
    were dropped: derivatives are estimated across a single dropped row (a glitch; the
    motion around it is smooth) but never across a longer gap, which may hide any motion."""
    rows = np.flatnonzero(keep)
    if rows.size == 0:
        return []
    return np.split(rows, np.flatnonzero(np.diff(rows) > max_gap + 1) + 1)


def setpoints(traj: 'Trajectory', active_joints: Sequence[str], keep: np.ndarray | None = None
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
    for rows in pieces if need else []:
        if rows.size >= derivatives.STENCIL:
            continue
        if keep is None:
            raise TrajectoryError(
                traj.path,
                f'absent, and estimating it needs at least {derivatives.STENCIL} rows '
                f'(the file has {n}); add the column', column=need[0])
        raise TrajectoryError(
            traj.path,
            f'absent, and estimating it needs at least {derivatives.STENCIL} consecutive rows; '
            f'rows {int(rows[0]) + 1}..{int(rows[-1]) + 1} are {rows.size} between skipped rows',
            row=int(rows[0]) + 1, column=need[0])
    for rows in pieces if need else []:
        _check_steps(traj.path, traj.time[rows], rows, need[0])
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


class OutputPathError(OSError):
    """An output path that must not be written (a FIFO, a device, ...): the message says why.

    An ``OSError``, so callers that handle write errors handle this refusal too."""


_SPECIAL = ((stat.S_ISFIFO, 'a FIFO (named pipe)'), (stat.S_ISCHR, 'a character device'),
            (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'))


def output_target(path: PathLike) -> str:
    """The file that writing ``path`` really replaces: ``path``, or the end of its symlinks.

    A symbolic link is written through: the file it points to is replaced (atomically)
    and the link stays; a dangling link creates its target. Raises
    :class:`OutputPathError` for a directory, a FIFO, a device or a socket (these are
    never replaced by a regular file, nor written into) and for a link that cannot be
    resolved (a loop).
    """
    path = os.fspath(path)
    target = path
    if os.path.islink(path):
        try:
            target = os.path.realpath(path, strict=True)
        except FileNotFoundError:
            target = os.path.realpath(path)
        except OSError as exc:
            raise OutputPathError(f'a symbolic link that cannot be resolved '
                                  f'({exc.strerror or exc})') from None
        if os.path.islink(target):
            raise OutputPathError('a symbolic link that cannot be resolved (a loop)')
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return target
    except OSError as exc:
        raise OutputPathError(f'cannot be examined ({exc.strerror or exc})') from None
    if stat.S_ISREG(mode):
        return target
    if stat.S_ISDIR(mode):
        raise OutputPathError('is a directory' + ('' if target == path else f' ({target})'))
    kind = next((text for test, text in _SPECIAL if test(mode)), 'a special file')
    via = '' if target == path else f' (the link points to {target})'
    raise OutputPathError(
        f'is {kind}{via}, not a regular file; outputs are written to a temporary file and '
        'renamed, which would replace it, so it is left alone: write to a regular file')


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


_STOP_SIGNALS = frozenset(getattr(signal, name) for name in ('SIGINT', 'SIGTERM', 'SIGHUP')
                          if hasattr(signal, name))


@contextlib.contextmanager
def _stop_signals_blocked():
    """Hold SIGINT, SIGTERM and SIGHUP back (they are delivered on leaving): a handler that
    raises must not run between the creation of a temporary file and the moment its name
    is known, or the file would be left behind."""
    if not hasattr(signal, 'pthread_sigmask'):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[str]:
    """Yield a temporary path next to ``path``'s target; rename it there on success only.

    The target is :func:`output_target` (``path``, or the file its symlinks lead to;
    special files raise :class:`OutputPathError` before anything is created, and are
    checked again just before the rename). On an exception (including
    ``KeyboardInterrupt`` and other ``BaseException``) the temporary file is removed and
    the target is left as it was.
    """
    target = output_target(path)
    directory = os.path.dirname(os.path.abspath(target))
    tmp = None
    try:
        with _stop_signals_blocked():
            fd, tmp = tempfile.mkstemp(dir=directory, prefix='.' + os.path.basename(target) + '.',
                                       suffix='.tmp')
            os.close(fd)
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        if output_target(path) != target:
            raise OutputPathError(f'{path} changed while it was being written')
        os.replace(tmp, target)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


def format_efforts(time: np.ndarray, efforts: np.ndarray, valid: np.ndarray,
                   active_joints: Sequence[str], block: int = 100_000) -> Iterator[str]:
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
