"""cog_id_torques: actuator torques of a closed-link mechanism along a CSV trajectory.

    cog_id_torques --params-file config/X.yaml --input traj.csv --output torques.csv [--plot torques.png]

Reads the trajectory (:mod:`cog_id_ros.trajectory_io`), estimates absent velocities and
accelerations (:mod:`cog_id_ros.derivatives`), solves the samples in chunks on the core's
batch path (``InverseDynamics.evaluate``; chunking is exact because the solver
warm-starts across calls), writes the efforts and the plot atomically, and prints a
summary. No ROS import: the tool runs wherever numpy does.
"""

import argparse
import json
import math
import os
import re
import sys
import textwrap
import time as _time

import numpy as np

from . import derivatives, trajectory_io
from .trajectory_io import TrajectoryError

PROG = 'cog_id_torques'

EXIT_OK = 0
EXIT_INPUT = 1        # the trajectory was rejected: bad CSV, or a sample cannot be solved
EXIT_USAGE = 2        # command line: bad option, unreadable input, unwritable output path
EXIT_PARAMS = 3       # the parameter file cannot be read or honoured
EXIT_WRITE = 4        # writing an output file failed
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # stdout closed before the summary was printed (outputs are complete)

PROGRESS_MIN_SAMPLES = 10_000   # the bar appears for inputs over this many samples
DEFAULT_CHUNK = 20_000          # samples per core call
MAX_LISTED_SKIPS = 20           # skipped rows listed one per line on stderr

ROW_NUMBERING = ('data rows count from 1, the header does not count: '
                 'row r is line r+1 of the file')

EPILOG = f"""\
input CSV (comma-separated, header row first):
  time                 seconds, strictly increasing (uneven steps allowed)
  <joint>.position     required for every active joint (rad or m; angles never wrapped)
  <joint>.velocity     optional; estimated from the positions when absent
  <joint>.acceleration optional; estimated from the velocity column when present,
                       else from the positions
  Columns of non-active joints of the mechanism are ignored with a note; a
  <name>.position|velocity|acceleration column whose <name> is not a joint of the
  mechanism is an error; any other column is ignored with a note.

derivative estimate (absent columns; needs at least {derivatives.STENCIL} rows):
{textwrap.fill(derivatives.SCHEME + '.', 80, initial_indent='  ', subsequent_indent='  ')}

output CSV: time and <joint>.effort per active joint (N m or N), every value at
  full precision; the cells of a row skipped by --skip-invalid are empty.

row numbering: data rows count from 1, the header does not count: row r is
  line r+1 of the file. Messages say both: "row 17 (line 18 of the file)".

summary (stdout; --json for the same as JSON): per active joint the peak |effort|
  and the row and time where it occurs, the RMS effort (over the solved rows,
  not time-weighted), the peak |power| = max |effort * velocity| and its row.

exit status:
  {EXIT_OK}  success (also when --skip-invalid skipped rows; they are listed on stderr)
  {EXIT_INPUT}  the trajectory was rejected: missing/duplicate/unknown column, ragged row,
     non-numeric cell, NaN or infinity, time not strictly increasing, or (without
     --skip-invalid) a sample where the loop cannot close or the mechanism is singular
  {EXIT_USAGE}  command line: bad option, input not readable, output directory missing
  {EXIT_PARAMS}  the parameter file cannot be read or honoured
  {EXIT_WRITE}  writing an output file failed
  {EXIT_INTERRUPTED}  interrupted (Ctrl-C); {EXIT_BROKEN_PIPE}  stdout closed before the summary
  On any error, one line on stderr names the row and column, and no output file is
  written (outputs are written to temporary files and renamed when complete).
"""


class ToolError(Exception):
    """An error the tool reports as one line, with its exit status."""

    def __init__(self, message, status):
        self.status = status
        super().__init__(message)


def build_parser():
    parser = argparse.ArgumentParser(
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
                        help='skip samples where the loop cannot close or the mechanism is '
                             'singular (list their rows on stderr, leave their efforts empty) '
                             'instead of stopping')
    parser.add_argument('--node-name', default=None, metavar='NAME',
                        help='node entry of the parameter file to read (default: the '
                             "core's default, which also accepts /**)")
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


def main(argv=None):
    """Console entry point; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return run(args, sys.stdout, sys.stderr)
    except ToolError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return exc.status
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted; no output written', file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of stdout went away (e.g. `| head`): silence the flush at exit
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE


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
        raise ToolError(f'--params-file {args.params_file}: no such file', EXIT_PARAMS)
    outputs = [('--output', args.output)] + ([('--plot', args.plot)] if args.plot else [])
    for option, path in outputs:
        if os.path.isdir(path):
            raise ToolError(f'{option} {path}: is a directory', EXIT_USAGE)
        directory = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(directory):
            raise ToolError(f'{option} {path}: directory {directory} does not exist', EXIT_USAGE)
        if not os.access(directory, os.W_OK):
            raise ToolError(f'{option} {path}: directory {directory} is not writable', EXIT_USAGE)
        if os.path.exists(path) and os.path.samefile(path, args.input):
            raise ToolError(f'{option} {path}: is the input file', EXIT_USAGE)
    if args.plot and os.path.abspath(args.plot) == os.path.abspath(args.output):
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
        return mech, cog_id_ros.InverseDynamics(mech)
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'{args.params_file}: {_one_line(exc)}', EXIT_PARAMS) from None
    except OSError as exc:
        raise ToolError(f'{args.params_file}: cannot read: {exc.strerror or exc}',
                        EXIT_PARAMS) from None


def _one_line(exc):
    return ' '.join(str(exc).split())


def _core_reason(exc):
    """The core's message without its chunk-relative 'sample i: ' prefix, on one line."""
    return re.sub(r'^sample \d+: ', '', _one_line(exc))


def _position_columns(active):
    return ', '.join(f"'{trajectory_io.joint_column(j, 'position')}'" for j in active)


def _invalid_message(path, row, active, exc):
    return (f'{path}: row {row} (line {row + 1} of the file), column(s) {_position_columns(active)}: '
            f'{_core_reason(exc)}')


def solve(solver, q, qd, qdd, chunk, skip_invalid, progress, path):
    """Efforts (N, M), valid (N,), and [(row, exception)] of the skipped rows."""
    import cog_id_ros
    n, m = q.shape
    efforts = np.zeros((n, m))
    valid = np.ones(n, bool)
    skipped = []
    active = solver.mechanism.active_joints
    mode = 'skip' if skip_invalid else 'raise'
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        try:
            ev = solver.evaluate(q[start:stop], qd[start:stop], qdd[start:stop], on_invalid=mode)
        except cog_id_ros.CogIdError as exc:
            progress.close()
            sample = getattr(exc, 'sample', None)
            if sample is None and stop - start == 1:
                sample = 0
            if sample is None:
                raise ToolError(
                    f'{path}: rows {start + 1}..{stop} (lines {start + 2}..{stop + 1} of the '
                    f'file): {_core_reason(exc)}', EXIT_INPUT) from None
            raise ToolError(_invalid_message(path, start + int(sample) + 1, active, exc),
                            EXIT_INPUT) from None
        efforts[start:stop] = ev.torques
        valid[start:stop] = ev.valid
        for i in np.flatnonzero(~np.asarray(ev.valid)).tolist():
            skipped.append((start + i + 1, ev.errors[i]))
        progress.update(stop)
    progress.close()
    return efforts, valid, skipped


def _units(mech):
    types = getattr(mech, 'joint_types', None)
    units = []
    for joint in mech.active_joints:
        kind = 'revolute'
        if types is not None:
            kind = types[list(mech.joints).index(joint)]
        units.append('N' if kind == 'prismatic' else 'N m')
    return units


def joint_statistics(time, effort, velocity, valid):
    """Peak |effort|, RMS effort and peak |power| of one joint over the valid samples.

    Rows in the result are 1-based data rows. Values are None when no sample is valid.
    """
    keys = ('peak_effort', 'peak_effort_signed', 'peak_effort_row', 'peak_effort_time',
            'rms_effort', 'peak_power', 'peak_power_signed', 'peak_power_row',
            'peak_power_time')
    index = np.flatnonzero(valid)
    if index.size == 0:
        return dict.fromkeys(keys)
    e = effort[index]
    p = e * velocity[index]
    k = int(np.argmax(np.abs(e)))
    kp = int(np.argmax(np.abs(p)))
    return {
        'peak_effort': float(abs(e[k])),
        'peak_effort_signed': float(e[k]),
        'peak_effort_row': int(index[k]) + 1,
        'peak_effort_time': float(time[index[k]]),
        'rms_effort': float(np.sqrt(np.mean(e * e))),
        'peak_power': float(abs(p[kp])),
        'peak_power_signed': float(p[kp]),
        'peak_power_row': int(index[kp]) + 1,
        'peak_power_time': float(time[index[kp]]),
    }


def _reason_name(exc):
    return type(exc).__name__ if exc is not None else 'invalid'


def build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed):
    units = _units(mech)
    joints = []
    for k, joint in enumerate(mech.active_joints):
        st = joint_statistics(traj.time, efforts[:, k], qd[:, k], valid)
        joints.append({'joint': joint, 'unit': units[k], 'power_unit': 'W', **st})
    reasons = {}
    for _, exc in skipped:
        reasons[_reason_name(exc)] = reasons.get(_reason_name(exc), 0) + 1
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
        'skipped_rows': [row for row, _ in skipped],
        'skipped_reasons': reasons,
        'time_start': float(traj.time[0]),
        'time_end': float(traj.time[-1]),
        'estimated_columns': estimated,
        'derivative_scheme': derivatives.SCHEME if estimated else None,
        'row_numbering': ROW_NUMBERING,
        'active_joints': list(mech.active_joints),
        'joints': joints,
        'elapsed_seconds': elapsed,
        'samples_per_second': n / elapsed if elapsed > 0 else None,
    }


def _g(value, unit=''):
    if value is None:
        return 'n/a'
    return f'{value:.6g}' + (f' {unit}' if unit else '')


def format_summary(summary):
    s = summary
    plural = '' if s['samples'] == 1 else 's'
    lines = [f"{s['mechanism']}: {s['samples']:,} sample{plural}, t = {s['time_start']:.6g} .. "
             f"{s['time_end']:.6g} s; {s['solved']:,} solved, {s['skipped']:,} skipped"]
    if s['estimated_columns']:
        lines.append('estimated from the samples: ' + ', '.join(s['estimated_columns']))
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
                 + f"  ({s['elapsed_seconds']:.2f} s, {s['samples_per_second'] or 0:,.0f} samples/s)")
    return '\n'.join(lines)


def _report_skipped(skipped, path, active, stderr):
    if not skipped:
        return
    print(f'{PROG}: skipped {len(skipped):,} row(s) (--skip-invalid); their efforts are left '
          'empty:', file=stderr)
    for row, exc in skipped[:MAX_LISTED_SKIPS]:
        reason = _core_reason(exc) if exc is not None else 'invalid sample'
        print(f'  {path}: row {row} (line {row + 1} of the file): {reason}', file=stderr)
    if len(skipped) > MAX_LISTED_SKIPS:
        print(f'  ... and {len(skipped) - MAX_LISTED_SKIPS:,} more (all rows are listed in '
              'skipped_rows of --json)', file=stderr)


def run(args, stdout, stderr):
    started = _time.perf_counter()
    plot_format = _check_paths(args)
    mech, solver = _load_mechanism(args)
    active = list(mech.active_joints)
    try:
        traj = trajectory_io.read_trajectory(args.input, list(mech.joints), active)
        for note in traj.notes:
            print(f'{PROG}: note: {args.input}: {note}', file=stderr)
        q, qd, qdd, estimated = trajectory_io.setpoints(traj, active)
    except TrajectoryError as exc:
        raise ToolError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--input {args.input}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    if estimated:
        print(f'{PROG}: note: estimating ' + ', '.join(estimated)
              + f' by finite differences (see --help)', file=stderr)
    n = len(traj)
    progress = ProgressBar(n, stderr, ProgressBar.wanted(n, stderr, args.no_progress))
    progress.update(0)
    efforts, valid, skipped = solve(solver, q, qd, qdd, args.chunk_size, args.skip_invalid,
                                    progress, args.input)
    _report_skipped(skipped, args.input, active, stderr)
    elapsed = _time.perf_counter() - started
    summary = build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed)
    try:
        with trajectory_io.atomic_output(args.output) as tmp_csv:
            with open(tmp_csv, 'w', encoding='utf-8', newline='') as f:
                for block in trajectory_io.format_efforts(traj.time, efforts, valid, active):
                    f.write(block)
            if args.plot:
                from . import plotting
                with trajectory_io.atomic_output(args.plot) as tmp_plot:
                    plotting.plot_efforts(
                        tmp_plot, traj.time, efforts, valid, active, summary['joints'],
                        title=mech.name, units=[j['unit'] for j in summary['joints']],
                        subtitle=f'{os.path.basename(args.input)}: {n:,} samples'
                                 + (f', {len(skipped):,} skipped' if skipped else ''),
                        fmt=plot_format)
    except OSError as exc:
        raise ToolError(f'cannot write the output: {exc}', EXIT_WRITE) from None
    summary['elapsed_seconds'] = _time.perf_counter() - started
    summary['samples_per_second'] = n / summary['elapsed_seconds']
    if args.json:
        json.dump(summary, stdout, indent=2)
        stdout.write('\n')
    else:
        print(format_summary(summary), file=stdout)
    return EXIT_OK


if __name__ == '__main__':
    sys.exit(main())
