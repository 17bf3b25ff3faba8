"""cog_id_simulate: the motion a closed-link mechanism makes under given actuator efforts.

    cog_id_simulate --params-file config/X.yaml --input efforts.csv --output motion.csv \
        [--time-step 0.001] [--initial-state trajectory.csv] [--plot motion.png \
        [--reference motion.csv]]

The run, step by step (:func:`run`): the paths checked, the mechanism loaded, the efforts
read (the torque tool's output format), each step's effort found by the hold rule and the
initial state chosen (:mod:`cog_id_ros.offline.simulate_inputs`), the motion integrated by
:class:`cog_id_ros.Simulation` and written row by row to a temporary file, the plot drawn,
both renamed together, a summary printed. No ROS import.
"""

import argparse
import contextlib
import os
import sys
import time as _time
from typing import TYPE_CHECKING, TextIO

import numpy as np

from ..core.model.mechanism import Mechanism
from ..core.native.kernels import BACKENDS
from . import atomic_files, outputs
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
    one_line,
    run_main,
)
from .progress import PROGRESS_MIN_SAMPLES, ProgressBar
from .simulate_inputs import (
    GRID_TOLERANCE,
    PROG,
    check_inputs,
    check_steps,
    initial_state,
    read_efforts,
    read_reference,
    step_efforts,
)
from .stop_signals import Interrupted, StopSignals
from .trajectory_io import TIME, Trajectory, joint_column

if TYPE_CHECKING:
    from ..core.simulation.simulation import Simulation

TRACEBACK_ENV = 'COG_ID_SIMULATE_TRACEBACK'
DEFAULT_TIME_STEP = 0.001
#: the longest step cog_id_ros.Simulation takes, s
MAX_TIME_STEP = 1.0
#: rows written to the output at a time
BLOCK = 10_000
#: steps between two redraws of the progress bar
PROGRESS_EVERY = 1_000

EPILOG = f"""\
input CSV (the output of cog_id_torques; comma-separated, header row first):
  time              seconds, strictly increasing (uneven steps allowed)
  <joint>.effort    required for every active joint (N m or N): the effort of row i
                    acts from time[i] until time[i+1] (zero-order hold), the last
                    row's for one step
  <joint>.position  optional, every active joint or none: the first row's values are
  <joint>.velocity  the initial state (the other rows' cells are not read: empty is
                    fine); without them: initial_positions, at rest
  A <name>.effort|position|velocity|acceleration column whose <name> is not a
  joint of the mechanism is an error (a joint's name mistyped); the columns of a
  joint that is not active, and any other column (label, <joint>.acceleration),
  are ignored with a note, as cog_id_torques does.

steps: one every --time-step from the first input time to the last (the last step
  that ends at or before it). A step within one input row's interval holds that
  row's effort exactly; a step that spans a change of effort (input times off the
  step grid, or rows closer than a step) holds the time average of the efforts it
  spans (the same impulse), with a note.

--between-rows linear: the rows are samples of a continuous effort (cog_id_torques
  writes the torque at each row's time), joined by straight lines; each step holds
  the mean of the line over the step. A sampled effort held from its own time on
  lags the curve by half a step: the motion it gives is off by O(step), which an
  open-loop unstable mechanism (the paper's upright four-bar) amplifies until it
  falls; the mean of the line is off by O(step^2) only.

--initial-state CSV: a trajectory file (the input of cog_id_torques) whose first
  row gives the initial positions and velocities of the active joints (velocities
  estimated as cog_id_torques estimates them when the file has none); it takes the
  place of position/velocity columns of --input.

output CSV: time, then <joint>.position and <joint>.velocity for every joint of the
  mechanism (mechanism.joints order), one row per step and the initial state first,
  every value at full precision; written to a temporary file and renamed.

--plot FILE: the positions of the active joints against time; with --reference
  MOTION.csv (a motion or trajectory file with the active joints' positions) the
  reference too, and the difference simulated - reference (linear interpolation at the
  step times, within the reference's time span).

exit status:
  {EXIT_OK}  success
  {EXIT_INPUT}  an input was rejected (a missing or duplicate column, a column of a joint
     the mechanism does not have, an empty or non-numeric cell, NaN or infinity, time
     not strictly increasing, an initial state that does not close the loops), or the
     simulation stopped (a singular pose, a loop that cannot close): the line names
     the row, column or time
  {EXIT_USAGE}  command line: bad option, an input not readable, an output directory
     missing, an output that is a FIFO/device/socket, too many steps
  {EXIT_PARAMS}  the parameter file cannot be read or honoured
  {EXIT_WRITE}  writing an output file failed (the message names --output or --plot)
  {EXIT_INTERNAL} an internal error (a bug; one line, set {TRACEBACK_ENV}=1 for the traceback)
  {EXIT_INTERRUPTED} Ctrl-C, 143 SIGTERM, 129 SIGHUP: temporary files removed, no output
     written; {EXIT_BROKEN_PIPE} stdout closed before the summary
"""


def finite_step(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not 0 < value <= MAX_TIME_STEP:      # also NaN
        raise argparse.ArgumentTypeError(f'must be > 0 and at most {MAX_TIME_STEP:g} s, got '
                                         f'{text!r}')
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog=PROG,
        description='The motion of a closed-link mechanism under given actuator efforts '
                    '(forward dynamics, classic RK4, every passive joint solved from the '
                    'closure): efforts CSV in, motion CSV and an optional plot out.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--params-file', required=True, metavar='YAML',
                        help='mechanism parameter file (ROS 2 parameter YAML, e.g. '
                             'config/paper_four_bar_a.yaml)')
    parser.add_argument('--input', required=True, metavar='CSV',
                        help='efforts CSV (what cog_id_torques writes)')
    parser.add_argument('--output', required=True, metavar='CSV',
                        help='motion CSV to write (replaced only when the run succeeds)')
    parser.add_argument('--time-step', type=finite_step, default=DEFAULT_TIME_STEP,
                        metavar='S', help=f'integration step, s (default {DEFAULT_TIME_STEP})')
    parser.add_argument('--between-rows', choices=('hold', 'linear'), default='hold',
                        help='hold (default): the effort of row i acts from time[i] until '
                             'time[i+1]; linear: the rows are samples of a continuous effort '
                             '(what cog_id_torques writes), joined by straight lines, and each '
                             'step holds their mean over the step (see below)')
    parser.add_argument('--initial-state', metavar='CSV',
                        help='a trajectory CSV whose first row is the initial state (e.g. '
                             'the trajectory cog_id_torques was given)')
    parser.add_argument('--plot', metavar='FILE',
                        help="also draw the active joints' positions against time (format "
                             'from the extension: png, pdf, svg, ...)')
    parser.add_argument('--reference', metavar='CSV',
                        help='a motion to compare with: drawn in --plot with the difference, '
                             'and the largest difference printed')
    parser.add_argument('--node-name', default=None, metavar='NAME',
                        help='node entry of the parameter file to read (default: the '
                             "core's default, which also accepts /**)")
    parser.add_argument('--backend', choices=BACKENDS, default='auto',
                        help='who computes the kernels (as cog_id_torques); default auto')
    parser.add_argument('--no-progress', action='store_true',
                        help='no progress bar (it is drawn on stderr only when stderr is a '
                             f'terminal and the run has over {PROGRESS_MIN_SAMPLES:,} steps)')
    return parser


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status. Never prints a traceback."""
    args = build_parser().parse_args(argv)
    return run_main(PROG, TRACEBACK_ENV,
                    lambda signals: run(args, sys.stdout, sys.stderr, signals),
                    stopped='no output written',
                    memory_hint='split the input, or use a larger --time-step')


def _simulation(args: argparse.Namespace, mech: Mechanism) -> 'Simulation':
    import cog_id_ros
    try:
        return cog_id_ros.Simulation(mech, time_step=args.time_step, backend=args.backend)
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'{args.params_file}: cannot be simulated: {one_line(exc)}',
                        EXIT_PARAMS) from None


def _reset(sim: 'Simulation', q0: list | None, qd0: list | None, source: str) -> None:
    import cog_id_ros
    try:
        sim.reset(q0, qd0)
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'the initial state ({source}) cannot be used: {one_line(exc)}',
                        EXIT_INPUT) from None


def _state(sim: 'Simulation') -> list[float]:
    """Positions and velocities of every joint, interleaved per joint (the output's order)."""
    out = []
    for q, qd in zip(sim.joint_positions(), sim.joint_velocities()):
        out += (float(q), float(qd))
    return out


def _write_block(f: TextIO, block: np.ndarray) -> None:
    cols = [list(map(repr, block[:, c].tolist())) for c in range(block.shape[1])]
    f.write('\n'.join(map(','.join, zip(*cols))) + '\n')


def integrate(args: argparse.Namespace, sim: 'Simulation', mech: Mechanism, traj: Trajectory,
              held: np.ndarray, f: TextIO, progress: ProgressBar, keep_active: bool
              ) -> tuple[np.ndarray, np.ndarray | None, float]:
    """Step the simulation through ``held`` efforts, writing the motion to ``f``; returns the
    step times and (with ``keep_active``) the active joints' positions ``(n_steps + 1, M)``."""
    import cog_id_ros
    n_steps = held.shape[0]
    time = traj.time[0] + args.time_step * np.arange(n_steps + 1)
    active = [list(mech.joints).index(j) for j in mech.active_joints]
    kept = np.empty((n_steps + 1, len(active))) if keep_active else None
    f.write(','.join([TIME] + [joint_column(j, field) for j in mech.joints
                               for field in ('position', 'velocity')]) + '\n')
    block = np.empty((min(BLOCK, n_steps + 1), 1 + 2 * len(mech.joints)))
    filled = 0
    residual = sim.closure_residual
    for k in range(n_steps + 1):
        if k:
            try:
                sim.step(held[k - 1])
            except cog_id_ros.CogIdError as exc:
                row = int(np.searchsorted(traj.time, time[k - 1] + GRID_TOLERANCE
                                          * args.time_step, side='right'))
                raise ToolError(f'{args.input}: step {k:,} (the efforts of row {row}, line '
                                f'{row + 1} of the file): {one_line(exc)}', EXIT_INPUT) from None
        residual = max(residual, sim.closure_residual)
        block[filled, 0] = time[k]
        block[filled, 1:] = _state(sim)
        if kept is not None:
            kept[k] = block[filled, 1 + 2 * np.array(active)]
        filled += 1
        if filled == block.shape[0] or k == n_steps:
            if not np.isfinite(block[:filled]).all():
                raise ToolError(f'{args.input}: the motion left the range of a double by t = '
                                f'{float(time[k])!r} s: the efforts are too large', EXIT_INPUT)
            _write_block(f, block[:filled])
            filled = 0
        if k % PROGRESS_EVERY == 0 or k == n_steps:
            progress.update(k)
    return time, kept, residual


def _note_holds(args: argparse.Namespace, spanning: int, n_steps: int, stderr: TextIO) -> None:
    if spanning:
        print(f'{PROG}: note: {spanning:,} of {n_steps:,} steps span a change of effort (the '
              f'input times are off the grid of --time-step {args.time_step!r} s, or closer '
              'than a step): those steps hold the time average of the efforts they span',
              file=stderr)


def run(args: argparse.Namespace, stdout: TextIO | None, stderr: TextIO,
        signals: StopSignals | None = None) -> int:
    """The tool's run, step by step: returns EXIT_OK, or raises ToolError (one line, an exit
    status) or Interrupted."""
    signals = signals if signals is not None else StopSignals()
    started = _time.perf_counter()
    plot_format = outputs.check_paths(args)
    check_inputs(args)
    mech, _ = load_mechanism(args, solver=False)
    traj, efforts = read_efforts(args, mech, stderr)
    n_steps = check_steps(args, traj.time)
    held, spanning = step_efforts(traj.time, efforts, args.time_step, n_steps,
                                  args.between_rows == 'linear')
    _note_holds(args, spanning, n_steps, stderr)
    q0, qd0, source = initial_state(args, mech, traj, stderr)
    reference = read_reference(args, mech, traj.time[0] + args.time_step
                               * np.arange(n_steps + 1))
    sim = _simulation(args, mech)
    _reset(sim, q0, qd0, source)
    progress = ProgressBar(n_steps, stderr, ProgressBar.wanted(n_steps, stderr, args.no_progress),
                           label='simulating', unit='steps')
    current = ('--output', args.output)
    try:
        with contextlib.ExitStack() as stack:
            tmp_csv = stack.enter_context(atomic_files.atomic_output(args.output))
            with open(tmp_csv, 'w', encoding='utf-8', newline='') as f:
                try:
                    began = _time.perf_counter()
                    time, active_q, residual = integrate(args, sim, mech, traj, held, f, progress,
                                               bool(args.plot or args.reference))
                finally:
                    progress.close()
                integrating = _time.perf_counter() - began
            if args.plot:
                current = ('--plot', args.plot)
                tmp_plot = stack.enter_context(atomic_files.atomic_output(args.plot))
                _plot(args, mech, tmp_plot, plot_format, time, active_q, reference, source)
            signals.deferring = True        # the renames (at the end of the with) go together
    except OSError as exc:
        signals.deferring = False
        option, path = current
        what = exc if isinstance(exc, atomic_files.OutputPathError) else \
            f'cannot write: {exc.strerror or one_line(exc)}'
        raise ToolError(f'{option} {path}: {what}', EXIT_WRITE) from None
    finally:
        signals.deferring = False
    if signals.pending:
        raise Interrupted(signals.pending, outputs_written=True)
    elapsed = _time.perf_counter() - started
    _print_summary(args, mech, stdout, time, active_q if active_q is not None else
                   np.array([sim.positions]), reference, (source, residual),
                   (elapsed, integrating))
    return EXIT_OK


def _plot(args: argparse.Namespace, mech: Mechanism, path: str, fmt: str, time: np.ndarray,
          active_q: np.ndarray, reference: np.ndarray | None, source: str) -> None:
    from . import plotting
    try:
        plotting.plot_motion(path, time, active_q, list(mech.active_joints),
                             [kind.unit for kind in mech.active_kinds], title=mech.name,
                             subtitle=f'{os.path.basename(args.input)} (--between-rows '
                                      f'{args.between_rows}) over steps of {args.time_step:g} s; '
                                      f'initial state: {source}',
                             reference=reference, fmt=fmt)
    except (OSError, MemoryError):
        raise
    except Exception as exc:     # matplotlib refusing the data
        raise ToolError(f'--plot {args.plot}: cannot draw the plot: {type(exc).__name__}: '
                        f'{one_line(exc)[:200]}', EXIT_WRITE) from None


def differences(active_q: np.ndarray, reference: np.ndarray, time: np.ndarray
                ) -> list[tuple[float, float] | None]:
    """Per active joint: (largest |simulated - reference|, its time), or None where the
    reference covers no step."""
    out = []
    diff = np.abs(active_q - reference)
    for k in range(diff.shape[1]):
        col = diff[:, k]
        ok = np.isfinite(col)
        if not ok.any():
            out.append(None)
            continue
        i = int(np.flatnonzero(ok)[np.argmax(col[ok])])
        out.append((float(col[i]), float(time[i])))
    return out


def _print_summary(args: argparse.Namespace, mech: Mechanism, stdout: TextIO | None,
                   time: np.ndarray, active_q: np.ndarray, reference: np.ndarray | None,
                   state: tuple[str, float], elapsed: tuple[float, float]) -> None:
    n_steps = time.size - 1
    source, residual = state
    elapsed, integrating = elapsed
    lines = [f'{mech.name}: {n_steps:,} steps of {args.time_step:g} s, t = {time[0]:.6g} .. '
             f'{time[-1]:.6g} s; initial state: {source}',
             f'loops closed at every step: largest closure residual {residual:.3g} '
             f'(closure_tolerance {mech.closure_tolerance:g})']
    units = [kind.unit for kind in mech.active_kinds]
    final = active_q[-1]
    header = ['joint', 'final position'] + (['max |simulated - reference|', 'at'] if
                                             reference is not None else [])
    rows = [header]
    diffs = differences(active_q, reference, time) if reference is not None else None
    for k, joint in enumerate(mech.active_joints):
        row = [joint, f'{final[k]:.6g} {units[k]}']
        if diffs is not None:
            d = diffs[k]
            row += ['n/a (outside the reference)', ''] if d is None else \
                [f'{d[0]:.3g} {units[k]}', f't = {d[1]:.6g} s']
        rows.append(row)
    widths = [max(len(r[c]) for r in rows) for c in range(len(header))]
    lines += ['  '.join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in rows]
    wrote = ', '.join([args.output] + ([args.plot] if args.plot else []))
    span = float(time[-1] - time[0])
    rate = ((f'; simulated and written at {n_steps / integrating:,.0f} steps/s'
             + (f', {span / integrating:.3g}x real time' if span > 0 else ''))
            if n_steps and integrating > 0 else '')
    lines.append(f'wrote {wrote}  ({elapsed:.2f} s{rate})')
    if stdout is None:
        raise BrokenPipeError('stdout is closed')
    try:
        stdout.write('\n'.join(lines) + '\n')
        stdout.flush()
    except BrokenPipeError:
        raise
    except OSError as exc:
        raise ToolError(f'the outputs are written, but the summary cannot be printed on '
                        f'stdout: {exc.strerror or exc}', EXIT_WRITE) from None


if __name__ == '__main__':
    sys.exit(main())
