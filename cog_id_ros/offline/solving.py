"""The samples of ``cog_id_torques`` solved in chunks on the core's batch path
(``InverseDynamics.evaluate``; chunking is exact because the solver warm-starts across
calls): a refused row stops the run with one line naming it, or with --skip-invalid is a
:class:`~cog_id_ros.offline.skipped_rows.Skip` and the run goes on.
"""

import re

import numpy as np

from . import trajectory_io
from .console import EXIT_INPUT, ToolError, one_line
from .skipped_rows import Skip


def _core_reason(exc):
    """The core's message without its chunk-relative 'sample i: ' prefix, on one line."""
    return re.sub(r'^sample \d+: ', '', one_line(exc))


def _columns(solver):
    """(the columns a refused pose is named by, per field (position, velocity,
    acceleration) the column of each value of a sample): the solver's ``message_columns``
    where it has them (a floating base's packed samples), else the active joints'."""
    named = getattr(solver, 'message_columns', None)
    if named is not None:
        return named
    active = solver.mechanism.active_joints
    fields = [[trajectory_io.joint_column(j, f) for j in active] for f in trajectory_io.FIELDS]
    return fields[0], fields


def _invalid_message(path, row, columns, exc, values=None):
    """One line for a row the core refused. ``columns``: :func:`_columns`; ``values``: the
    row's (q, qd, qdd); for a value out of range the column holding the largest magnitude
    is named, for the other reasons the positions (the pose is what is wrong)."""
    pose, per_field = columns
    named = ', '.join(f"'{c}'" for c in pose)
    if values is not None and getattr(exc, 'reason', None) in ('out_of_range', 'non_finite'):
        largest = None
        for field, names in zip(values, per_field):
            with np.errstate(all='ignore'):
                mags = np.abs(np.asarray(field, dtype=float))[:len(names)]
                mags[np.isnan(mags)] = np.inf
            k = int(np.argmax(mags))
            if largest is None or mags[k] > largest[0]:
                largest = (mags[k], names[k])
        named = f"'{largest[1]}'" if largest is not None else named
    return (f'{path}: row {row} (line {row + 1} of the file), column(s) {named}: '
            f'{_core_reason(exc)}')


def _reason(exc):
    """The machine-readable reason of a core error (a key of REASONS), never its text."""
    reason = getattr(exc, 'reason', None)
    return reason if isinstance(reason, str) and reason else 'invalid'


def _row_level(exc):
    """A core error about one sample (skippable), not about the mechanism or the call."""
    from ..core.errors import REASONS
    return getattr(exc, 'reason', None) in REASONS


def _overflow_error(sample):
    import cog_id_ros
    return cog_id_ros.SetpointError(
        'the torques are beyond the range of a double (|tau| > 1.8e308): the accelerations '
        'or velocities are too large to compute with', sample=sample, reason='out_of_range')


def solve(solver, q, qd, qdd, chunk, skip_invalid, progress, path, rows=None, rates=None):
    """Efforts (N, M), valid (N,), and the [Skip] of the rows the solver could not serve.

    ``rows``: the 0-based rows to solve (default all), in order; the others stay invalid
    and are not reported here. M is the width of the solver where it has one (a joint-space
    motion: :mod:`cog_id_ros.offline.joint_space_solving`), else the samples' width;
    ``rates`` (N, M), optional: filled with the evaluations' ``rates`` (the motors' rates
    of a joint-space motion). With ``skip_invalid``, a row-level error the core raises
    instead of marking (e.g. 'out_of_range') skips that row too: the rows before it in
    its chunk are solved again and the run goes on after it.
    """
    import cog_id_ros
    n = q.shape[0]
    m = getattr(solver, 'width', q.shape[1])
    rows = np.arange(n) if rows is None else np.asarray(rows)
    efforts = np.zeros((n, m))
    valid = np.zeros(n, bool)
    skipped = []
    columns = _columns(solver)
    mode = 'skip' if skip_invalid else 'raise'
    pos, skip_at, skip_error = 0, None, None
    total = rows.size
    while pos < total:
        if skip_at == pos:
            row = int(rows[pos]) + 1
            skipped.append(Skip(row, _reason(skip_error), _core_reason(skip_error), skip_error))
            pos, skip_at, skip_error = pos + 1, None, None
            continue
        stop = min(pos + chunk, total) if skip_at is None else min(pos + chunk, skip_at)
        idx = rows[pos:stop]
        try:
            ev = solver.evaluate(q[idx], qd[idx], qdd[idx], on_invalid=mode)
            torques = np.asarray(ev.torques, dtype=float).reshape(idx.size, m)
            ok = np.asarray(ev.valid, bool).reshape(idx.size)
            errors = list(ev.errors)
            with np.errstate(all='ignore'):
                bad = ok & ~np.isfinite(torques).all(axis=1)
            if bad.any():          # the core is meant to refuse these; never write them
                first = int(np.argmax(bad))
                if not skip_invalid:
                    raise _overflow_error(first)
                for i in np.flatnonzero(bad).tolist():
                    ok[i] = False
                    errors[i] = _overflow_error(i)
        except cog_id_ros.CogIdError as exc:
            sample = getattr(exc, 'sample', None)
            if sample is None and idx.size == 1:
                sample = 0
            if skip_invalid and sample is not None and _row_level(exc) \
                    and 0 <= int(sample) < idx.size:
                skip_at, skip_error = pos + int(sample), exc
                continue
            progress.close()
            if sample is None:
                first, last = int(idx[0]) + 1, int(idx[-1]) + 1
                raise ToolError(
                    f'{path}: rows {first}..{last} (lines {first + 1}..{last + 1} of the '
                    f'file): {_core_reason(exc)}', EXIT_INPUT) from None
            r = int(idx[int(sample)])
            raise ToolError(_invalid_message(path, r + 1, columns, exc, (q[r], qd[r], qdd[r])),
                            EXIT_INPUT) from None
        efforts[idx] = torques
        valid[idx] = ok
        if rates is not None and getattr(ev, 'rates', None) is not None:
            rates[idx] = ev.rates
        for i in np.flatnonzero(~ok).tolist():
            exc = errors[i]
            skipped.append(Skip(int(idx[i]) + 1, _reason(exc),
                                _core_reason(exc) if exc is not None else 'invalid sample', exc))
        pos = stop
        progress.update(pos)
    progress.close()
    return efforts, valid, skipped
