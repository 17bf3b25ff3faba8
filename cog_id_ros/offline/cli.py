"""cog_id_torques: actuator torques of a closed-link mechanism along a CSV trajectory.

    cog_id_torques --params-file config/X.yaml --input traj.csv --output torques.csv \
        [--plot torques.png] [--space joint] [--contacts NAME,NAME]

The run, step by step (:func:`run`): the paths checked (:mod:`cog_id_ros.offline.outputs`),
the mechanism loaded, the trajectory read (:mod:`cog_id_ros.offline.trajectory_io`), angles
unwrapped and jumps found (:mod:`cog_id_ros.offline.jumps`,
:mod:`cog_id_ros.offline.skipped_rows`), absent velocities and accelerations estimated
(:mod:`cog_id_ros.offline.samples`), the samples solved in chunks
(:mod:`cog_id_ros.offline.solving`), the efforts and the plot written atomically, and a
summary printed (:mod:`cog_id_ros.offline.summary`). With ``--space joint`` the input
is a motion of ``mechanism.joint_space`` and the output still the motors' torques
(:mod:`cog_id_ros.offline.joint_space_solving`). A floating-base mechanism also reads the
base's columns and writes the contact wrenches and the base wrench
(:mod:`cog_id_ros.offline.floating_base`). No ROS import: the tool runs wherever numpy
does.
"""

import argparse
import json
import sys
import textwrap
import time as _time

import numpy as np

from ..core.native.kernels import BACKENDS
from . import (
    base_samples,
    derivatives,
    floating_base,
    joint_space_solving,
    jumps,
    outputs,
    samples,
    skipped_rows,
    trajectory_io,
)
from .console import (
    EXIT_BROKEN_PIPE,
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_PARAMS,
    EXIT_USAGE,
    EXIT_WRITE,
    Parser,
    ToolError,
    load_mechanism,
    positive_float,
    positive_int,
    run_main,
)
from .jumps import DEFAULT_MAX_STEP
from .progress import PROGRESS_MIN_SAMPLES, ProgressBar
from .solving import solve
from .stop_signals import StopSignals
from .summary import build_summary, finite_for_json, format_summary
from .trajectory_io import TrajectoryError

PROG = 'cog_id_torques'
TRACEBACK_ENV = 'COG_ID_TORQUES_TRACEBACK'

DEFAULT_CHUNK = 20_000          # samples per core call
MAX_LISTED_SKIPS = 20           # skipped rows listed one per line on stderr

EPILOG = f"""\
input CSV (comma-separated, header row first):
  time                 seconds, strictly increasing (uneven steps allowed)
  <joint>.position     required for every active joint (rad or m; angles are not
                       wrapped, and unwrapped with --unwrap)
  <joint>.velocity     optional; estimated from the positions when absent
  <joint>.acceleration optional; estimated from the velocity column when present,
                       else from the positions
  With --space joint: <joint> is each joint of mechanism.joint_space instead (the
  joints a controller commands), and the output is still the active joints' efforts.
  Columns of non-active joints of the mechanism are ignored with a note; a
  <name>.position|velocity|acceleration column whose <name> is not a joint of the
  mechanism is an error; any other column is ignored with a note.

floating base (mechanism.floating_base true), also the base's columns:
  base.x base.y base.z     required: the base's origin in the world frame (m)
  base.qx base.qy base.qz base.qw
                           required: its orientation, a unit quaternion, world from base
  base.vx base.vy base.vz base.wx base.wy base.wz
                           optional, all six or none: the base's velocity in the base
                           frame (m/s, rad/s); estimated from the pose when absent
  base.dvx base.dvy base.dvz base.dwx base.dwy base.dwz
                           optional, all six or none: the time derivatives of those
                           (m/s^2, rad/s^2); estimated as the joints' accelerations are
  --contacts names the contacts touching the ground (default: all of mechanism.contacts).
  A fixed-base mechanism refuses base columns (exit 1) and --contacts (exit 2).

derivative estimate (absent columns; needs at least {derivatives.STENCIL} rows):
{textwrap.fill(derivatives.SCHEME + '.', 80, initial_indent='  ', subsequent_indent='  ')}

  Estimates need time steps of {samples.MIN_ESTIMATE_STEP:g} .. {samples.MAX_ESTIMATE_STEP:g} s and values within the
  range of a double; otherwise the row and the column are named (exit 1).

jumps and wrapped angles: an active position that moves by more than --max-step
  (default {DEFAULT_MAX_STEP['rad']} rad, revolute joints) or --max-step-linear (default {DEFAULT_MAX_STEP['m']} m,
  prismatic joints) from one row to the next is a bad row: exit 1, or with
  --skip-invalid the row is skipped with reason 'jump' (and the next row is compared
  with the last row that was not a jump). The limit is per row, not per second: a
  wrapped angle jumps by ~2 pi in one row at any sample rate, and the solver follows
  the mechanism from row to row. An encoder of a continuous joint reports +pi then
  -pi: --unwrap takes each revolute position as the 2 pi equivalent nearest the
  previous row's (prismatic columns untouched) and says how many rows it shifted.

output CSV: time and <joint>.effort per active joint (N m or N), every value at
  full precision; the cells of a row skipped by --skip-invalid are empty. A floating
  base adds per contact <contact>.fx .fy .fz .mx .my .mz (a 3d contact: .fx .fy .fz; N,
  N m; world axes, at the contact point, applied by the ground to the robot), then
  base_wrench.fx .fy .fz .mx .my .mz (what the world must still apply at the base: base
  frame, at its origin).
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
  {EXIT_INPUT}  the trajectory was rejected: missing/duplicate/unknown column (base columns
     for a fixed base), a base quaternion that is not a unit one, ragged row,
     non-numeric cell, NaN, infinity or a number beyond a double, time not strictly
     increasing, time steps unusable for an estimate, or (without --skip-invalid) a
     jump beyond --max-step or a sample that cannot be solved (the loop cannot close,
     the mechanism is singular, the torques would overflow)
  {EXIT_USAGE}  command line: bad option, input not readable, output directory missing,
     output is a FIFO/device/socket, --contacts naming no contact of the mechanism or
     given for a fixed base, --space joint with a floating base
  {EXIT_PARAMS}  the parameter file cannot be read or honoured
  {EXIT_WRITE}  writing an output file failed (the message names --output or --plot)
  {EXIT_INTERNAL} an internal error (a bug; one line, set {TRACEBACK_ENV}=1 for the traceback)
  {EXIT_INTERRUPTED} Ctrl-C, 143 SIGTERM, 129 SIGHUP (128 + the signal number): temporary
     files removed, no output written; {EXIT_BROKEN_PIPE} stdout closed before the summary
  On any error, one line on stderr names the row and column, and no output file is
  written (outputs are written to temporary files and renamed when complete).
"""  # noqa: E501 (help text as printed)


def build_parser():
    parser = Parser(
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
    parser.add_argument('--space', choices=('actuator', 'joint'), default='actuator',
                        help='what the input columns are: actuator (default: the active '
                             'joints, the motors) or joint (mechanism.joint_space, the joints '
                             "a controller commands); the output is the motors' torques "
                             "either way, the exact ones (the linkage's inertia and gravity "
                             'included; docs/transmission.md)')
    parser.add_argument('--contacts', metavar='NAMES',
                        help='a floating-base mechanism (mechanism.floating_base): the '
                             'contacts touching the ground, comma-separated names of '
                             'mechanism.contacts (default: all of them; none: no contact, the '
                             'whole residual is the base wrench); their wrenches are written '
                             'after the efforts')
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
    parser.add_argument('--max-step', type=positive_float, default=DEFAULT_MAX_STEP['rad'],
                        metavar='RAD',
                        help='largest change of a revolute active position from one row to the '
                             f"next (default {DEFAULT_MAX_STEP['rad']} rad per row; inf: no "
                             'limit); a larger jump is a bad row (exit 1, or skipped with '
                             '--skip-invalid)')
    parser.add_argument('--max-step-linear', type=positive_float,
                        default=DEFAULT_MAX_STEP['m'], metavar='M',
                        help='the same for prismatic active joints (default '
                             f"{DEFAULT_MAX_STEP['m']} m per row; inf: no limit)")
    parser.add_argument('--chunk-size', type=positive_int, default=DEFAULT_CHUNK, metavar='N',
                        help=f'samples per solver call (default {DEFAULT_CHUNK}); sets memory use '
                             'and progress-bar steps; results agree to within the closure '
                             'tolerance whatever the chunk size')
    parser.add_argument('--no-progress', action='store_true',
                        help='no progress bar (it is drawn on stderr only when stderr is a '
                             f'terminal and the input has over {PROGRESS_MIN_SAMPLES:,} samples)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status. Never prints a traceback."""
    args = build_parser().parse_args(argv)
    return run_main(PROG, TRACEBACK_ENV,
                    lambda signals: run(args, sys.stdout, sys.stderr, signals),
                    stopped='no output written',
                    memory_hint='split the input, or lower --chunk-size')


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


def run(args, stdout, stderr, signals=None):
    """The tool's run, step by step: returns EXIT_OK, or raises ToolError (one line, an exit
    status) or Interrupted. ``signals``: the installed StopSignals (held back while the
    outputs are renamed)."""
    signals = signals if signals is not None else StopSignals()
    started = _time.perf_counter()
    plot_format = outputs.check_paths(args)
    mech, solver = load_mechanism(args)
    active = list(mech.active_joints)
    motor_rates = None
    contacts = floating_base.contact_names(args, mech)     # None: a fixed base
    if getattr(args, 'space', 'actuator') == 'joint':
        solver = joint_space_solving.JointSpaceSolver(
            joint_space_solving.transmission_of(mech, solver, args.params_file))
    traj, (q, qd, qdd, estimated), keep, jump_skips, unwrapped, base = _read(
        args, solver.mechanism, stderr)
    if solver.mechanism is not mech:
        motor_rates = np.zeros((len(traj), len(active)))
    if contacts is not None:        # a floating base: the base's samples beside the motors'
        solver = floating_base.WholeBodySolver(solver, contacts)
        q, qd, qdd = solver.pack(q, qd, qdd, base)
    n = len(traj)
    to_solve = int(np.count_nonzero(keep))
    wanted = ProgressBar.wanted(to_solve, stderr, args.no_progress)
    progress = ProgressBar(to_solve, stderr, wanted)
    progress.update(0)
    try:
        efforts, valid, skipped = solve(solver, q, qd, qdd, args.chunk_size, args.skip_invalid,
                                        progress, args.input, np.flatnonzero(keep), motor_rates)
    finally:
        progress.close()
    qd = qd if motor_rates is None else motor_rates     # the summary's power is the motors'
    skipped = sorted(jump_skips + skipped, key=lambda skip: skip.row)
    _report_skipped(skipped, args.input, stderr)
    elapsed = _time.perf_counter() - started
    summary = build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed,
                            unwrapped)
    floating = contacts is not None
    if floating:
        summary['contacts'] = contacts
    outputs.write_outputs(args, signals, traj, efforts, valid, active, summary, mech, skipped,
                          plot_format, solver.extra_columns if floating else (),
                          solver.vertical_forces(efforts) if floating else None)
    summary['elapsed_seconds'] = _time.perf_counter() - started
    summary['samples_per_second'] = n / summary['elapsed_seconds']
    _print_summary(args, summary, stdout, stderr)
    return EXIT_OK


def _read(args, mech, stderr):
    """The trajectory of --input, its samples ``(q, qd, qdd, estimated columns)``, the rows
    to solve (bool mask), the [Skip] of the jumps, the unwrapped columns (or None) and a
    floating base's samples (base_samples.BaseSamples, or None); the notes on stderr.
    ToolError naming the row and column of a bad trajectory. ``mech``'s active joints name
    the columns (--space joint: the mechanism driven at its joint space)."""
    active = list(mech.active_joints)
    kinds = mech.active_kinds
    unwrapped = base = None
    try:
        # every joint of the mechanism, those without a coordinate too (their columns are
        # ignored like any passive joint's, not called unknown)
        traj = trajectory_io.read_trajectory(
            args.input, list(mech.joints) + list(mech.closure_joints), active,
            role=(joint_space_solving.ROLE if getattr(args, 'space', 'actuator') == 'joint'
                  else 'active joint'), **base_samples.reading(args.input, mech))
        for note in traj.notes:
            print(f'{PROG}: note: {args.input}: {note}', file=stderr)
        if getattr(args, 'unwrap', False):
            wrapping = [j for j, kind in zip(active, kinds) if kind.wraps]
            unwrapped = jumps.unwrap_positions(traj, wrapping)
            print(f'{PROG}: note: --unwrap: ' + (', '.join(
                f'{col}: {r:,} row(s) shifted by a multiple of 2 pi ({w:,} wrap(s))'
                for col, (r, w) in unwrapped.items()) or 'no revolute active joint to unwrap'),
                file=stderr)
        keep, jump_skips = skipped_rows.check_jumps(args, mech, traj, active)
        if jump_skips:
            jump_skips += skipped_rows.short_pieces(
                traj, active, keep, base_samples.VELOCITY + base_samples.ACCELERATION
                if mech.floating_base else ())
        q, qd, qdd, estimated = samples.setpoints(
            traj, active, keep if jump_skips else None)
        if mech.floating_base:
            base = base_samples.setpoints(traj, keep if jump_skips else None)
            estimated += base.estimated
    except TrajectoryError as exc:
        raise ToolError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--input {args.input}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    if estimated:
        print(f'{PROG}: note: estimating ' + ', '.join(estimated)
              + ' by finite differences (see --help)', file=stderr)
    return traj, (q, qd, qdd, estimated), keep, jump_skips, unwrapped, base


def _print_summary(args, summary, stdout, stderr):
    """The summary on stdout (a table, or JSON with --json), its notes on stderr."""
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


if __name__ == '__main__':
    sys.exit(main())
