"""cog_id_torques: actuator torques of a closed-link mechanism along a CSV trajectory.

    cog_id_torques --params-file config/X.yaml --input traj.csv --output torques.csv \
        [--plot torques.png]

Reads the trajectory (:mod:`cog_id_ros.offline.trajectory_io`), estimates absent velocities
and accelerations (:mod:`cog_id_ros.offline.derivatives`), solves the samples in chunks on the
core's batch path (``InverseDynamics.evaluate``; chunking is exact because the solver
warm-starts across calls), writes the efforts and the plot atomically, and prints a
summary. No ROS import: the tool runs wherever numpy does.
"""

import argparse
import contextlib
import json
import math
import os
import re
import signal
import sys
import textwrap
import time as _time

import numpy as np

from ..core.kernels import BACKENDS
from . import derivatives, trajectory_io
from .trajectory_io import TrajectoryError

PROG = 'cog_id_torques'

EXIT_OK = 0
EXIT_INPUT = 1        # the trajectory was rejected: bad CSV, or a sample cannot be solved
EXIT_USAGE = 2        # command line: bad option, unreadable input, unwritable output path
EXIT_PARAMS = 3       # the parameter file cannot be read or honoured
EXIT_WRITE = 4        # writing an output file failed
EXIT_INTERNAL = 70    # a bug: reported in one line, never as a traceback
EXIT_INTERRUPTED = 130  # 128 + SIGINT; SIGTERM gives 143, SIGHUP 129
EXIT_BROKEN_PIPE = 141  # stdout closed before the summary was printed (outputs are complete)

#: signals that stop the run like Ctrl-C: temporary files removed, exit 128 + signal number
STOP_SIGNALS = ('SIGINT', 'SIGTERM', 'SIGHUP')

#: largest change of an active position between consecutive rows, per row (not per
#: second): a crank wrapping from +pi to -pi jumps by ~2 pi in one row at any sample rate,
#: and the solver follows the mechanism from row to row, which is a per-row matter too
DEFAULT_MAX_STEP = 1.0            # rad, revolute joints (the node's max_setpoint_step too)
DEFAULT_MAX_STEP_LINEAR = 0.1     # m, prismatic joints
TRACEBACK_ENV = 'COG_ID_TORQUES_TRACEBACK'

PROGRESS_MIN_SAMPLES = 10_000   # the bar appears for inputs over this many samples
DEFAULT_CHUNK = 20_000          # samples per core call
MAX_LISTED_SKIPS = 20           # skipped rows listed one per line on stderr

ROW_NUMBERING = ('data rows count from 1, the header does not count: '
                 'row r is line r+1 of the file')

EPILOG = f"""\
input CSV (comma-separated, header row first):
  time                 seconds, strictly increasing (uneven steps allowed)
  <joint>.position     required for every active joint (rad or m; angles are not
                       wrapped, and unwrapped with --unwrap)
  <joint>.velocity     optional; estimated from the positions when absent
  <joint>.acceleration optional; estimated from the velocity column when present,
                       else from the positions
  Columns of non-active joints of the mechanism are ignored with a note; a
  <name>.position|velocity|acceleration column whose <name> is not a joint of the
  mechanism is an error; any other column is ignored with a note.

derivative estimate (absent columns; needs at least {derivatives.STENCIL} rows):
{textwrap.fill(derivatives.SCHEME + '.', 80, initial_indent='  ', subsequent_indent='  ')}

  Estimates need time steps of {trajectory_io.MIN_ESTIMATE_STEP:g} .. {trajectory_io.MAX_ESTIMATE_STEP:g} s and values within the
  range of a double; otherwise the row and the column are named (exit 1).

jumps and wrapped angles: an active position that moves by more than --max-step
  (default {DEFAULT_MAX_STEP} rad, revolute joints) or --max-step-linear (default {DEFAULT_MAX_STEP_LINEAR} m,
  prismatic joints) from one row to the next is a bad row: exit 1, or with
  --skip-invalid the row is skipped with reason 'jump' (and the next row is compared
  with the last row that was not a jump). The limit is per row, not per second: a
  wrapped angle jumps by ~2 pi in one row at any sample rate, and the solver follows
  the mechanism from row to row. An encoder of a continuous joint reports +pi then
  -pi: --unwrap takes each revolute position as the 2 pi equivalent nearest the
  previous row's (prismatic columns untouched) and says how many rows it shifted.

output CSV: time and <joint>.effort per active joint (N m or N), every value at
  full precision; the cells of a row skipped by --skip-invalid are empty.
  --output and --plot: a symbolic link is written through (its target is replaced
  atomically, the link stays); a FIFO, device or socket is refused (exit 2).

row numbering: data rows count from 1, the header does not count: row r is
  line r+1 of the file. Messages say both: "row 17 (line 18 of the file)".

summary (stdout; --json for the same as JSON): per active joint the peak |effort|
  and the row and time where it occurs, the RMS effort (over the solved rows,
  not time-weighted), the peak |power| = max |effort * velocity| and its row.
  A value beyond the range of a double is n/a in the table and null in the JSON,
  with a note saying so (the JSON never holds NaN or Infinity).

exit status:
  {EXIT_OK}  success (also when --skip-invalid skipped rows; they are listed on stderr)
  {EXIT_INPUT}  the trajectory was rejected: missing/duplicate/unknown column, ragged row,
     non-numeric cell, NaN, infinity or a number beyond a double, time not strictly
     increasing, time steps unusable for an estimate, or (without --skip-invalid) a
     jump beyond --max-step or a sample that cannot be solved (the loop cannot close,
     the mechanism is singular, the torques would overflow)
  {EXIT_USAGE}  command line: bad option, input not readable, output directory missing,
     output is a FIFO/device/socket
  {EXIT_PARAMS}  the parameter file cannot be read or honoured
  {EXIT_WRITE}  writing an output file failed (the message names --output or --plot)
  {EXIT_INTERNAL} an internal error (a bug; one line, set {TRACEBACK_ENV}=1 for the traceback)
  {EXIT_INTERRUPTED} Ctrl-C, 143 SIGTERM, 129 SIGHUP (128 + the signal number): temporary
     files removed, no output written; {EXIT_BROKEN_PIPE} stdout closed before the summary
  On any error, one line on stderr names the row and column, and no output file is
  written (outputs are written to temporary files and renamed when complete).
"""  # noqa: E501 (help text as printed)


class ToolError(Exception):
    """An error the tool reports as one line, with its exit status."""

    def __init__(self, message, status):
        self.status = status
        super().__init__(message)


class Interrupted(BaseException):
    """A stop signal (SIGINT, SIGTERM, SIGHUP) arrived; unwinds like KeyboardInterrupt,
    so every temporary file is removed on the way out."""

    def __init__(self, signum, outputs_written=False):
        self.signum = signum
        self.outputs_written = outputs_written
        super().__init__(signum)


class StopSignals:
    """Turn the stop signals into :class:`Interrupted`; defer them while outputs are renamed.

    Signals a parent set to be ignored (``nohup``, a background job) stay ignored.
    Installed only in the main thread; ``restore`` puts the previous handlers back.
    """

    def __init__(self):
        self.previous = {}
        self.deferring = False
        self.pending = None

    def install(self):
        for name in STOP_SIGNALS:
            signum = getattr(signal, name, None)
            if signum is None:
                continue
            try:
                if signal.getsignal(signum) == signal.SIG_IGN:
                    continue
                self.previous[signum] = signal.signal(signum, self._handler)
            except (ValueError, OSError):   # not the main thread
                pass
        return self

    def restore(self):
        for signum, handler in self.previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(signum, handler)
        self.previous.clear()

    def _handler(self, signum, frame):
        if self.deferring:
            self.pending = self.pending or signum
            return
        raise Interrupted(signum)

    @contextlib.contextmanager
    def deferred(self):
        """Hold signals back (the renames of the outputs happen together or not at all)."""
        self.deferring = True
        try:
            yield
        finally:
            self.deferring = False
        if self.pending:
            raise Interrupted(self.pending, outputs_written=True)


def _signal_name(signum):
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f'signal {signum}'


class _Parser(argparse.ArgumentParser):
    """argparse, with a usage mistake reported as one line (not the whole usage block)."""

    def error(self, message):
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def build_parser():
    parser = _Parser(
        prog=PROG,
        description='Actuator torques/forces of a closed-link mechanism along a trajectory '
                    '(COG-Jacobian inverse dynamics): CSV in, CSV and an optional plot out.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--params-file', required=True, metavar='YAML',
                        help='mechanism parameter file (ROS 2 parameter YAML, e.g. '
                             'config/paper_four_bar_a.yaml)')
    parser.add_argument('--input', required=True, metavar='CSV', help='trajectory CSV')
    parser.add_argument('--output', required=True, metavar='CSV',
                        help='efforts CSV to write (replaced only when the run succeeds)')
    parser.add_argument('--plot', metavar='FILE',
                        help='also draw efforts against time (format from the extension: '
                             'png, pdf, svg, ...)')
    parser.add_argument('--json', action='store_true',
                        help='print the summary as one JSON object instead of a table')
    parser.add_argument('--skip-invalid', action='store_true',
                        help='skip rows that cannot be solved (the loop cannot close, the '
                             'mechanism is singular, the torques would overflow) or that jump '
                             'beyond --max-step: list them on stderr with their reason, leave '
                             'their efforts empty, instead of stopping')
    parser.add_argument('--node-name', default=None, metavar='NAME',
                        help='node entry of the parameter file to read (default: the '
                             "core's default, which also accepts /**)")
    parser.add_argument('--unwrap', action='store_true',
                        help='unwrap revolute active positions: each is taken as the 2 pi '
                             "equivalent nearest the previous row's (for encoders of continuous "
                             'joints that report angles in (-pi, pi]); prismatic columns are '
                             'untouched; the summary says how many rows were shifted')
    parser.add_argument('--backend', choices=BACKENDS,
                        default='auto',
                        help='who computes the kernels: auto (compiled C where a C compiler '
                             'is there, else Python), native, python (never compile), '
                             'reference (the plain lane code, slow); default auto')
    parser.add_argument('--max-step', type=_positive_float, default=DEFAULT_MAX_STEP,
                        metavar='RAD',
                        help='largest change of a revolute active position from one row to the '
                             f'next (default {DEFAULT_MAX_STEP} rad per row; inf: no limit); a '
                             'larger jump is a bad row (exit 1, or skipped with --skip-invalid)')
    parser.add_argument('--max-step-linear', type=_positive_float,
                        default=DEFAULT_MAX_STEP_LINEAR, metavar='M',
                        help='the same for prismatic active joints (default '
                             f'{DEFAULT_MAX_STEP_LINEAR} m per row; inf: no limit)')
    parser.add_argument('--chunk-size', type=_positive_int, default=DEFAULT_CHUNK, metavar='N',
                        help=f'samples per solver call (default {DEFAULT_CHUNK}); sets memory use '
                             'and progress-bar steps; results agree to within the closure '
                             'tolerance whatever the chunk size')
    parser.add_argument('--no-progress', action='store_true',
                        help='no progress bar (it is drawn on stderr only when stderr is a '
                             f'terminal and the input has over {PROGRESS_MIN_SAMPLES:,} samples)')
    return parser


def _positive_int(text):
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def _positive_float(text):
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not value > 0:       # also NaN
        raise argparse.ArgumentTypeError(f'must be > 0 (inf for no limit), got {text!r}')
    return value


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status. Never prints a traceback."""
    args = build_parser().parse_args(argv)
    signals = StopSignals().install()
    try:
        return run(args, sys.stdout, sys.stderr, signals)
    except ToolError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return exc.status
    except Interrupted as exc:
        what = ('the outputs are complete, the summary was not printed' if exc.outputs_written
                else 'no output written')
        print(f'{PROG}: interrupted by {_signal_name(exc.signum)}; {what}', file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted by SIGINT; no output written', file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of stdout went away (e.g. `| head`): silence the flush at exit
        if sys.stdout is not None:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except MemoryError:
        print(f'{PROG}: error: out of memory (split the input, or lower --chunk-size)',
              file=sys.stderr)
        return EXIT_INTERNAL
    except Exception as exc:    # a bug: one line, the traceback only on request
        if os.environ.get(TRACEBACK_ENV):
            raise
        print(f'{PROG}: internal error: {type(exc).__name__}: {_one_line(exc)[:300]} '
              f'(a bug; please report it with the command; {TRACEBACK_ENV}=1 shows the '
              'traceback)', file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        signals.restore()


# --- progress ------------------------------------------------------------------------------

class ProgressBar:
    """A one-line progress bar redrawn in place with carriage returns."""

    def __init__(self, total, stream, enabled, label='solving'):
        self.total = total
        self.stream = stream
        self.enabled = enabled
        self.label = label
        self.start = _time.perf_counter()
        self.drawn = False
        self.last_length = 0

    @staticmethod
    def wanted(total, stream, disabled=False):
        if disabled or total <= PROGRESS_MIN_SAMPLES:
            return False
        try:
            return bool(stream.isatty())
        except (AttributeError, ValueError, OSError):
            return False

    def _width(self):
        try:
            columns = os.get_terminal_size(self.stream.fileno()).columns
        except (AttributeError, ValueError, OSError):
            columns = 0
        return columns if columns > 0 else 80

    def update(self, done):
        if not self.enabled:
            return
        elapsed = _time.perf_counter() - self.start
        frac = done / self.total if self.total else 1.0
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else float('nan')
        tail = (f' {frac:4.0%} {done:,}/{self.total:,} samples  {rate:,.0f}/s'
                + (f'  {eta:.0f} s left' if done < self.total and math.isfinite(eta)
                   else f'  {elapsed:.1f} s'))
        room = max(10, min(40, self._width() - len(self.label) - len(tail) - 5))
        fill = int(round(frac * room))
        line = f'{self.label} [{"#" * fill}{"." * (room - fill)}]{tail}'
        self.stream.write('\r' + line.ljust(self.last_length))
        self.last_length = len(line)
        self.stream.flush()
        self.drawn = True

    def close(self):
        if self.enabled and self.drawn:
            self.stream.write('\n')
            self.stream.flush()


# --- the run -------------------------------------------------------------------------------

def _check_paths(args):
    """Fail fast (before any solving) on paths that cannot work; returns the plot format."""
    if not os.path.isfile(args.input):
        what = 'no such file' if not os.path.exists(args.input) else 'not a regular file'
        raise ToolError(f'--input {args.input}: {what}', EXIT_USAGE)
    if not os.access(args.input, os.R_OK):
        raise ToolError(f'--input {args.input}: not readable', EXIT_USAGE)
    if not os.path.isfile(args.params_file):
        what = 'no such file' if not os.path.exists(args.params_file) else 'not a regular file'
        raise ToolError(f'--params-file {args.params_file}: {what}', EXIT_PARAMS)
    outputs = [('--output', args.output)]
    if args.plot is not None:
        outputs.append(('--plot', args.plot))
    targets = {}
    for option, path in outputs:
        if not path:
            raise ToolError(f'{option}: the path is empty', EXIT_USAGE)
        if path.endswith(('/', os.sep)):
            raise ToolError(f'{option} {path}: ends with {path[-1]}, so it names a directory; '
                            'give a file name', EXIT_USAGE)
        try:
            target = trajectory_io.output_target(path)
        except trajectory_io.OutputPathError as exc:
            raise ToolError(f'{option} {path}: {exc}', EXIT_USAGE) from None
        directory = os.path.dirname(os.path.abspath(target))
        if not os.path.isdir(directory):
            raise ToolError(f'{option} {path}: directory {directory} does not exist', EXIT_USAGE)
        if not os.access(directory, os.W_OK):
            raise ToolError(f'{option} {path}: directory {directory} is not writable', EXIT_USAGE)
        if os.path.exists(target) and os.path.samefile(target, args.input):
            raise ToolError(f'{option} {path}: is the input file', EXIT_USAGE)
        if os.path.exists(target) and os.path.samefile(target, args.params_file):
            raise ToolError(f'{option} {path}: is the parameter file', EXIT_USAGE)
        targets[option] = os.path.abspath(target)
    if args.plot and targets['--plot'] == targets['--output']:
        raise ToolError(f'--plot {args.plot}: is the same file as --output', EXIT_USAGE)
    if not args.plot:
        return None
    from . import plotting
    fmt = os.path.splitext(args.plot)[1].lstrip('.').lower()
    formats = plotting.supported_formats()
    if fmt not in formats:
        raise ToolError(f'--plot {args.plot}: unknown image format {fmt!r} (use one of '
                        + ', '.join(formats) + ')', EXIT_USAGE)
    return fmt


def _load_mechanism(args):
    import cog_id_ros
    try:
        if args.node_name is None:
            mech = cog_id_ros.Mechanism.from_params_file(args.params_file)
        else:
            mech = cog_id_ros.Mechanism.from_params_file(args.params_file, args.node_name)
        return mech, cog_id_ros.InverseDynamics(mech, backend=args.backend)
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'{args.params_file}: {_one_line(exc)}', EXIT_PARAMS) from None
    except OSError as exc:
        raise ToolError(f'{args.params_file}: cannot read: {exc.strerror or exc}',
                        EXIT_PARAMS) from None
    except UnicodeDecodeError as exc:
        raise ToolError(f'{args.params_file}: not UTF-8 text (byte {exc.start}); a parameter '
                        'file is YAML text', EXIT_PARAMS) from None
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as exc:
        raise ToolError(f'{args.params_file}: cannot be used as a parameter file: '
                        f'{type(exc).__name__}: {_one_line(exc)[:200]}', EXIT_PARAMS) from None


def _one_line(exc):
    return ' '.join(str(exc).split())


def _core_reason(exc):
    """The core's message without its chunk-relative 'sample i: ' prefix, on one line."""
    return re.sub(r'^sample \d+: ', '', _one_line(exc))


def _position_columns(active):
    return ', '.join(f"'{trajectory_io.joint_column(j, 'position')}'" for j in active)


def _invalid_message(path, row, active, exc, values=None):
    """One line for a row the core refused. ``values``: the row's (q, qd, qdd) of the
    active joints; for a value out of range the column holding the largest magnitude is
    named, for the other reasons the positions (the pose is what is wrong)."""
    columns = _position_columns(active)
    if values is not None and getattr(exc, 'reason', None) in ('out_of_range', 'non_finite'):
        with np.errstate(all='ignore'):
            mags = np.abs(np.asarray(values, dtype=float))     # (3, M)
            mags[np.isnan(mags)] = np.inf
        field, k = np.unravel_index(int(np.argmax(mags)), mags.shape)
        columns = f"'{trajectory_io.joint_column(active[k], trajectory_io.FIELDS[field])}'"
    return (f'{path}: row {row} (line {row + 1} of the file), column(s) {columns}: '
            f'{_core_reason(exc)}')


def _reason(exc):
    """The machine-readable reason of a core error (a key of REASONS), never its text."""
    reason = getattr(exc, 'reason', None)
    return reason if isinstance(reason, str) and reason else 'invalid'


def _row_level(exc):
    """A core error about one sample (skippable), not about the mechanism or the call."""
    from ..core.errors import REASONS
    return getattr(exc, 'reason', None) in REASONS


class Skip:
    """A row left unsolved: 1-based ``row``, ``reason`` (a key of REASONS, or 'jump'),
    ``message`` (one line), ``error`` (the core exception, or None)."""

    __slots__ = ('row', 'reason', 'message', 'error')

    def __init__(self, row, reason, message, error=None):
        self.row, self.reason, self.message, self.error = row, reason, message, error


def _overflow_error(sample):
    import cog_id_ros
    return cog_id_ros.SetpointError(
        'the torques are beyond the range of a double (|tau| > 1.8e308): the accelerations '
        'or velocities are too large to compute with', sample=sample, reason='out_of_range')


def solve(solver, q, qd, qdd, chunk, skip_invalid, progress, path, rows=None):
    """Efforts (N, M), valid (N,), and the [Skip] of the rows the solver could not serve.

    ``rows``: the 0-based rows to solve (default all), in order; the others stay invalid
    and are not reported here. With ``skip_invalid``, a row-level error the core raises
    instead of marking (e.g. 'out_of_range') skips that row too: the rows before it in
    its chunk are solved again and the run goes on after it.
    """
    import cog_id_ros
    n, m = q.shape
    rows = np.arange(n) if rows is None else np.asarray(rows)
    efforts = np.zeros((n, m))
    valid = np.zeros(n, bool)
    skipped = []
    active = solver.mechanism.active_joints
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
            raise ToolError(_invalid_message(path, r + 1, active, exc, (q[r], qd[r], qdd[r])),
                            EXIT_INPUT) from None
        efforts[idx] = torques
        valid[idx] = ok
        for i in np.flatnonzero(~ok).tolist():
            exc = errors[i]
            skipped.append(Skip(int(idx[i]) + 1, _reason(exc),
                                _core_reason(exc) if exc is not None else 'invalid sample', exc))
        pos = stop
        progress.update(pos)
    progress.close()
    return efforts, valid, skipped


def _units(mech):
    return [kind.effort_unit for kind in mech.active_kinds]


def _step_limit(args, kind):
    """(--max-step or --max-step-linear, its name, unit) for a joint of ``kind``: by the unit
    of its coordinate, an angle or a length."""
    if kind.unit == 'rad':
        return args.max_step, '--max-step', kind.unit
    return args.max_step_linear, '--max-step-linear', kind.unit


def _rms(values):
    """Root mean square without overflow or underflow: scaled by the largest |value|."""
    peak = float(np.max(np.abs(values)))
    if peak == 0.0 or not math.isfinite(peak):
        return peak
    scaled = values / peak
    return peak * math.sqrt(float(np.mean(scaled * scaled)))


def joint_statistics(time, effort, velocity, valid):
    """Peak |effort|, RMS effort and peak |power| of one joint over the valid samples.

    Rows in the result are 1-based data rows. Values are None when no sample is valid.
    The RMS is scaled by the peak, so it is finite whenever the efforts are; a power
    beyond the range of a double comes out as inf (its row is still the right one).
    """
    keys = ('peak_effort', 'peak_effort_signed', 'peak_effort_row', 'peak_effort_time',
            'rms_effort', 'peak_power', 'peak_power_signed', 'peak_power_row',
            'peak_power_time')
    index = np.flatnonzero(valid)
    if index.size == 0:
        return dict.fromkeys(keys)
    e = effort[index]
    with np.errstate(all='ignore'):
        p = e * velocity[index]
        k = int(np.argmax(np.abs(e)))
        kp = int(np.argmax(np.abs(p)))
        rms = _rms(e)
    return {
        'peak_effort': float(abs(e[k])),
        'peak_effort_signed': float(e[k]),
        'peak_effort_row': int(index[k]) + 1,
        'peak_effort_time': float(time[index[k]]),
        'rms_effort': rms,
        'peak_power': float(abs(p[kp])),
        'peak_power_signed': float(p[kp]),
        'peak_power_row': int(index[kp]) + 1,
        'peak_power_time': float(time[index[kp]]),
    }


def build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed,
                  unwrapped=None):
    units = _units(mech)
    joints = []
    for k, joint in enumerate(mech.active_joints):
        st = joint_statistics(traj.time, efforts[:, k], qd[:, k], valid)
        joints.append({'joint': joint, 'unit': units[k], 'power_unit': 'W', **st})
    reasons = {}
    types = {}
    for skip in skipped:
        reasons[skip.reason] = reasons.get(skip.reason, 0) + 1
        kind = type(skip.error).__name__ if skip.error is not None else 'TrajectoryJump'
        types[kind] = types.get(kind, 0) + 1
    n = len(traj)
    return {
        'mechanism': mech.name,
        'params_file': args.params_file,
        'input': args.input,
        'output': args.output,
        'plot': args.plot,
        'samples': n,
        'solved': int(np.count_nonzero(valid)),
        'skipped': len(skipped),
        'skipped_rows': [skip.row for skip in skipped],
        'skipped_row_reasons': [skip.reason for skip in skipped],
        'skipped_reasons': reasons,
        'skipped_error_types': types,
        'time_start': float(traj.time[0]),
        'time_end': float(traj.time[-1]),
        'estimated_columns': estimated,
        'derivative_scheme': derivatives.SCHEME if estimated else None,
        'unwrap': bool(getattr(args, 'unwrap', False)),
        'unwrapped': {col: {'rows': r, 'wraps': w} for col, (r, w) in (unwrapped or {}).items()},
        'max_step': {'revolute_rad_per_row': _json_limit(getattr(args, 'max_step', None)),
                     'prismatic_m_per_row': _json_limit(getattr(args, 'max_step_linear', None))},
        'row_numbering': ROW_NUMBERING,
        'active_joints': list(mech.active_joints),
        'joints': joints,
        'elapsed_seconds': elapsed,
        'samples_per_second': n / elapsed if elapsed > 0 else None,
        'notes': [],
    }


def _json_limit(value):
    return None if value is None or not math.isfinite(value) else value


def finite_for_json(summary):
    """Replace every non-finite number by None, adding a note per value to ``notes``.

    JSON has no NaN or Infinity (``json.dumps(allow_nan=False)`` is used on the result),
    so a value beyond the range of a double is written as null and the note says so.
    """
    notes = summary.setdefault('notes', [])

    def walk(value, where):
        if isinstance(value, float) and not math.isfinite(value):
            notes.append(f'{where}: beyond the range of a double ({value!r}): null in --json, '
                         'n/a in the table')
            return None
        if isinstance(value, dict):
            return {k: walk(v, f'{where}.{k}' if where else k) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(v, f"{where}[{v['joint']}]" if isinstance(v, dict) and 'joint' in v
                         else f'{where}[{i}]') for i, v in enumerate(value)]
        return value

    clean = walk({k: v for k, v in summary.items() if k != 'notes'}, '')
    clean['notes'] = notes
    return clean


def _g(value, unit=''):
    if value is None:
        return 'n/a'
    if not math.isfinite(value):
        return 'n/a (beyond a double)'
    return f'{value:.6g}' + (f' {unit}' if unit else '')


def format_summary(summary):
    s = summary
    plural = '' if s['samples'] == 1 else 's'
    lines = [f"{s['mechanism']}: {s['samples']:,} sample{plural}, t = {s['time_start']:.6g} .. "
             f"{s['time_end']:.6g} s; {s['solved']:,} solved, {s['skipped']:,} skipped"]
    if s['estimated_columns']:
        lines.append('estimated from the samples: ' + ', '.join(s['estimated_columns']))
    if s.get('unwrap'):
        lines.append('unwrapped (--unwrap): ' + (', '.join(
            f"{col}: {u['rows']:,} row(s) shifted by a multiple of 2 pi ({u['wraps']:,} wrap(s))"
            for col, u in s['unwrapped'].items()) or 'no revolute active joint'))
    header = ('joint', 'peak |effort|', 'at', 'RMS effort', 'peak |power|', 'at')
    rows = [header]
    for j in s['joints']:
        at = (f"row {j['peak_effort_row']} (t = {j['peak_effort_time']:.6g} s)"
              if j['peak_effort'] is not None else 'n/a')
        at_p = (f"row {j['peak_power_row']} (t = {j['peak_power_time']:.6g} s)"
                if j['peak_power'] is not None else 'n/a')
        rows.append((j['joint'], _g(j['peak_effort'], j['unit']), at,
                     _g(j['rms_effort'], j['unit']), _g(j['peak_power'], 'W'), at_p))
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    for r in rows:
        lines.append('  '.join(c.ljust(w) for c, w in zip(r, widths)).rstrip())
    written = [s['output']] + ([s['plot']] if s['plot'] else [])
    lines.append('wrote ' + ', '.join(written)
                 + f"  ({s['elapsed_seconds']:.2f} s, "
                 + f"{s['samples_per_second'] or 0:,.0f} samples/s)")
    return '\n'.join(lines)


def _report_skipped(skipped, path, stderr):
    if not skipped:
        return
    print(f'{PROG}: skipped {len(skipped):,} row(s) (--skip-invalid); their efforts are left '
          'empty:', file=stderr)
    for skip in skipped[:MAX_LISTED_SKIPS]:
        print(f'  {path}: row {skip.row} (line {skip.row + 1} of the file): {skip.message} '
              f'[{skip.reason}]', file=stderr)
    if len(skipped) > MAX_LISTED_SKIPS:
        print(f'  ... and {len(skipped) - MAX_LISTED_SKIPS:,} more (all rows are listed in '
              'skipped_rows of --json)', file=stderr)


def _jump_message(args, kinds, active, row, k, step, ref):
    limit, option, unit = _step_limit(args, kinds[k])
    hint = ''
    if kinds[k].wraps and not args.unwrap:
        hint = '; if the angle wraps at +-pi (a continuous joint), use --unwrap'
    return (f'jumps by {step:.6g} {unit} from row {ref} (limit {limit:g} {unit} per row, '
            f'{option}){hint}')


def _check_jumps(args, mech, traj, active):
    """Rows to solve (bool mask) and the [Skip] of the jumps; raises without --skip-invalid."""
    kinds = mech.active_kinds
    limits = [_step_limit(args, kind)[0] for kind in kinds]
    n = len(traj)
    keep = np.ones(n, bool)
    if all(math.isinf(x) for x in limits):
        return keep, []
    q = np.column_stack([traj.columns[trajectory_io.joint_column(j, 'position')] for j in active])
    jumps = trajectory_io.find_jumps(q, limits)
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


def _short_pieces(traj, active, keep):
    """With derivatives to estimate, rows left in pieces of fewer than STENCIL rows between
    skipped stretches (see trajectory_io.kept_pieces) cannot be estimated: skip them too
    (reason 'jump'), updating ``keep``."""
    fields = ('velocity', 'acceleration')
    if all(trajectory_io.joint_column(j, f) in traj.columns for j in active for f in fields):
        return []
    skipped = []
    for rows in trajectory_io.kept_pieces(keep):
        if rows.size >= derivatives.STENCIL:
            continue
        first, last = int(rows[0]) + 1, int(rows[-1]) + 1
        for r in rows.tolist():
            keep[r] = False
            skipped.append(Skip(r + 1, 'jump', f'rows {first}..{last} are cut off by rows skipped '
                                f'as jumps: too few ({rows.size}) to estimate derivatives from '
                                f'(at least {derivatives.STENCIL} needed)'))
    return skipped


class _Outputs:
    """Which user path (--output or --plot) a write error is about, from its file names."""

    def __init__(self):
        self.paths = {}     # file name (temporary or target) -> (option, user path)

    def add(self, option, user_path, *names):
        for name in names:
            self.paths[os.path.abspath(name)] = (option, user_path)

    def which(self, exc, default):
        for name in (getattr(exc, 'filename', None), getattr(exc, 'filename2', None)):
            if isinstance(name, (str, bytes, os.PathLike)):
                found = self.paths.get(os.path.abspath(os.fsdecode(name)))
                if found:
                    return found
        return default


def _write_outputs(args, signals, traj, efforts, valid, active, summary, mech, skipped,
                   plot_format):
    """Write the CSV and the plot to temporary files, then rename both (signals held back)."""
    n = len(traj)
    outputs = _Outputs()
    current = ('--output', args.output)
    try:
        with contextlib.ExitStack() as stack:
            tmp_csv = stack.enter_context(trajectory_io.atomic_output(args.output))
            outputs.add('--output', args.output, tmp_csv,
                        trajectory_io.output_target(args.output))
            with open(tmp_csv, 'w', encoding='utf-8', newline='') as f:
                for block in trajectory_io.format_efforts(traj.time, efforts, valid, active):
                    f.write(block)
            if args.plot:
                from . import plotting
                current = ('--plot', args.plot)
                tmp_plot = stack.enter_context(trajectory_io.atomic_output(args.plot))
                outputs.add('--plot', args.plot, tmp_plot, trajectory_io.output_target(args.plot))
                try:
                    plotting.plot_efforts(
                        tmp_plot, traj.time, efforts, valid, active, summary['joints'],
                        title=mech.name, units=[j['unit'] for j in summary['joints']],
                        subtitle=f'{os.path.basename(args.input)}: {n:,} samples'
                                 + (f', {len(skipped):,} skipped' if skipped else ''),
                        fmt=plot_format)
                except (OSError, MemoryError):
                    raise
                except Exception as exc:     # matplotlib refusing the data
                    raise ToolError(f'--plot {args.plot}: cannot draw the plot: '
                                    f'{type(exc).__name__}: {_one_line(exc)[:200]}',
                                    EXIT_WRITE) from None
            current = ('--output', args.output)
            signals.deferring = True        # the renames (at the end of the with) go together
    except trajectory_io.OutputPathError as exc:
        signals.deferring = False
        option, path = current
        raise ToolError(f'{option} {path}: {exc}', EXIT_WRITE) from None
    except OSError as exc:
        signals.deferring = False
        option, path = outputs.which(exc, current)
        raise ToolError(f'{option} {path}: cannot write: {exc.strerror or _one_line(exc)}',
                        EXIT_WRITE) from None
    finally:
        signals.deferring = False
    if signals.pending:
        raise Interrupted(signals.pending, outputs_written=True)


def run(args, stdout, stderr, signals=None):
    signals = signals if signals is not None else StopSignals()
    started = _time.perf_counter()
    plot_format = _check_paths(args)
    mech, solver = _load_mechanism(args)
    active = list(mech.active_joints)
    kinds = mech.active_kinds
    unwrapped = None
    try:
        # every joint of the mechanism, those without a coordinate too (their columns are
        # ignored like any passive joint's, not called unknown)
        traj = trajectory_io.read_trajectory(
            args.input, list(mech.joints) + list(mech.closure_joints), active)
        for note in traj.notes:
            print(f'{PROG}: note: {args.input}: {note}', file=stderr)
        if getattr(args, 'unwrap', False):
            wrapping = [j for j, kind in zip(active, kinds) if kind.wraps]
            unwrapped = trajectory_io.unwrap_positions(traj, wrapping)
            print(f'{PROG}: note: --unwrap: ' + (', '.join(
                f'{col}: {r:,} row(s) shifted by a multiple of 2 pi ({w:,} wrap(s))'
                for col, (r, w) in unwrapped.items()) or 'no revolute active joint to unwrap'),
                file=stderr)
        keep, jump_skips = _check_jumps(args, mech, traj, active)
        if jump_skips:
            jump_skips += _short_pieces(traj, active, keep)
        q, qd, qdd, estimated = trajectory_io.setpoints(
            traj, active, keep if jump_skips else None)
    except TrajectoryError as exc:
        raise ToolError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--input {args.input}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    if estimated:
        print(f'{PROG}: note: estimating ' + ', '.join(estimated)
              + ' by finite differences (see --help)', file=stderr)
    n = len(traj)
    to_solve = int(np.count_nonzero(keep))
    wanted = ProgressBar.wanted(to_solve, stderr, args.no_progress)
    progress = ProgressBar(to_solve, stderr, wanted)
    progress.update(0)
    try:
        efforts, valid, skipped = solve(solver, q, qd, qdd, args.chunk_size, args.skip_invalid,
                                        progress, args.input, np.flatnonzero(keep))
    finally:
        progress.close()
    skipped = sorted(jump_skips + skipped, key=lambda skip: skip.row)
    _report_skipped(skipped, args.input, stderr)
    elapsed = _time.perf_counter() - started
    summary = build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed,
                            unwrapped)
    _write_outputs(args, signals, traj, efforts, valid, active, summary, mech, skipped,
                   plot_format)
    summary['elapsed_seconds'] = _time.perf_counter() - started
    summary['samples_per_second'] = n / summary['elapsed_seconds']
    clean = finite_for_json(summary)
    for note in clean['notes']:
        print(f'{PROG}: note: {note}', file=stderr)
    text = json.dumps(clean, indent=2, allow_nan=False) if args.json else format_summary(summary)
    if stdout is None:                  # started with stdout closed (>&-): like a closed pipe
        raise BrokenPipeError('stdout is closed')
    try:
        stdout.write(text + '\n')
        stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:              # e.g. stdout is /dev/full: the outputs are complete
        raise ToolError(f'the outputs are written, but the summary cannot be printed on '
                        f'stdout: {exc.strerror or exc}', EXIT_WRITE) from None
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
