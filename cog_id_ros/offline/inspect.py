"""cog_id_inspect: what a mechanism parameter file describes, and how it assembled.

    cog_id_inspect --params-file config/X.yaml [--plot pose.png] [--trajectory motion.csv]
                   [--transmission map.png]

Prints the spanning tree the solver built (base link first; a spherical, universal or
fixed joint in it as one hop, by its declared name), the loops and the joints that close
them, the degrees of freedom (hidden coordinates counted) and the actuators, every joint's
given ``initial_positions`` beside the position the assembly at load reached (a WARNING
where an actuator moved, or a passive joint moved further than the loader's "far"
threshold: the assembly probably took another branch than the one meant), and the closure
residual and condition number at that pose. ``--plot`` draws the mechanism there
(:mod:`cog_id_ros.offline.mechanism_plot`), ``--trajectory`` adds snapshots along a motion
in the input format of ``cog_id_torques``. A mechanism that names ``mechanism.joint_space``
is drawn with both spaces labelled (:mod:`cog_id_ros.offline.joint_space_marks`), and
``--transmission`` plots the map between them over each joint-space joint's range
(:mod:`cog_id_ros.offline.transmission_plot`). Pure reporting: nothing is changed or written
but the pictures. No ROS import. docs/inspect.md has an example.
"""

import argparse
import os
import sys
import warnings

from . import atomic_files, inspect_motion, trajectory_io
from .console import (
    EXIT_INPUT,
    EXIT_INTERNAL,
    EXIT_OK,
    EXIT_USAGE,
    EXIT_WRITE,
    Parser,
    ToolError,
    load_mechanism,
    output_target,
    plot_format,
    positive_int,
    run_main,
)
from .inspect_motion import format_motion
from .inspect_pose import format_closure, format_joint_table, joint_rows
from .inspect_structure import format_actuation, format_header, format_structure
from .trajectory_io import TrajectoryError

PROG = 'cog_id_inspect'
TRACEBACK_ENV = 'COG_ID_INSPECT_TRACEBACK'

#: the solver behind the report: it solves a handful of poses, so nothing is compiled
BACKEND = 'reference'
#: the transmission's solvers (--transmission): a few hundred poses, traced kernels (nothing
#: compiled either, three times the reference's speed)
TRANSMISSION_BACKEND = 'python'
DEFAULT_SNAPSHOTS = 6
MAX_SNAPSHOTS = 12

EPILOG = f"""\
what it prints:
  the spanning tree (each link under its tree parent, with the joint between them;
  active joints marked; a spherical, universal or fixed joint where the tree needs one),
  the loops (the joint that closes each, and its cycle through the tree), degrees of
  freedom and actuators (primary or redundant, torque weights), a table of every joint:
  initial_positions (given) beside the pose the loader assembled and the difference,
  WARNING lines where an actuator moved or a passive joint moved more than the loader's
  threshold (the assembly probably took another branch: set initial_positions near the
  pose you mean), then the closure residual and the closure Jacobian condition number at
  the assembled pose. With mechanism.joint_space: the joint space beside the actuator
  space, and with --transmission the ratio and conditioning of the map between them.

exit status:
  {EXIT_OK}  success (also with warnings)
  {EXIT_INPUT}  the --trajectory CSV was rejected (one line names the row and column)
  {EXIT_USAGE}  command line, or a parameter file that cannot be read or honoured (one line
     naming the parameter); --transmission of a mechanism without
     mechanism.joint_space. A mechanism refused for idle spins (rods that spin about their
     own axes: mechanism.locked_joints) is still reported and drawn as it loads with
     idle_spins: lock, the spinning sets and the joints that would be locked marked
  {EXIT_WRITE}  the picture cannot be written
  {EXIT_INTERNAL} an internal error (a bug; {TRACEBACK_ENV}=1 shows the traceback)
  130 Ctrl-C (143 SIGTERM, 129 SIGHUP): no picture written
"""


def build_parser():
    parser = Parser(
        prog=PROG,
        description='Show a mechanism parameter file as the solver reads it: spanning tree, '
                    'loops, degrees of freedom, the assembled pose beside initial_positions '
                    '(with a warning where the assembly took another branch), and a picture.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--params-file', required=True, metavar='YAML',
                        help='mechanism parameter file (ROS 2 parameter YAML, e.g. '
                             'config/paper_four_bar_a.yaml)')
    parser.add_argument('--plot', metavar='FILE',
                        help='draw the mechanism at the assembled pose (format from the '
                             'extension: png, pdf, svg, ...)')
    parser.add_argument('--trajectory', metavar='CSV',
                        help="a motion in cog_id_torques' input format (time, "
                             '<joint>.position per active joint): solve it and report the '
                             'closure along it; with --plot, also draw snapshots along it')
    parser.add_argument('--snapshots', type=_snapshot_count, default=DEFAULT_SNAPSHOTS,
                        metavar='N', help=f'snapshots of --trajectory drawn (default '
                                          f'{DEFAULT_SNAPSHOTS}, at most {MAX_SNAPSHOTS})')
    parser.add_argument('--transmission', metavar='FILE',
                        help='plot the transmission between actuator space and '
                             'mechanism.joint_space: over the range of each joint-space joint '
                             '(its limits, or as far as the map stays non-singular) the '
                             'singular values (1 x 1: the ratio) and the condition number of '
                             'J = dq/dtheta (format from the extension)')
    parser.add_argument('--node-name', default=None, metavar='NAME',
                        help='node entry of the parameter file to read (default: the '
                             "core's default, which also accepts /**)")
    return parser


def _snapshot_count(text):
    value = positive_int(text)
    if value > MAX_SNAPSHOTS:
        raise argparse.ArgumentTypeError(f'must be at most {MAX_SNAPSHOTS}, got {value}')
    return value


def main(argv: 'list[str] | None' = None) -> int:
    """Console entry point; returns the exit status. Never prints a traceback."""
    args = build_parser().parse_args(argv)
    return run_main(PROG, TRACEBACK_ENV, lambda signals: run(args, sys.stdout, sys.stderr),
                    stopped='no picture written')


def run(args, stdout, stderr):
    plot_format = _check_plot_path(args)
    map_format = _check_plot_path(args, '--transmission')
    mech, solver, refused = load(args)
    if args.transmission:
        _need_joint_space(mech)
    evaluation = solver.evaluate([mech.assembled_positions[j] for j in mech.active_index],
                                 on_invalid='skip')
    text = format_report(mech, evaluation, args.params_file)
    if refused is not None:
        text = (f'REFUSED as written for its idle spins (mechanism.locked_joints: what to '
                f'write is on stderr; exit status {EXIT_USAGE}). Shown as it loads with '
                f'idle_spins: lock, the spinning sets and the joints it locks marked:\n\n'
                + text)
    motion = None
    if args.trajectory:
        motion = solve_trajectory(mech, solver, args.trajectory, args.snapshots, stderr)
        text += '\n\n' + '\n'.join(format_motion(motion))
    if args.plot:
        # every solver coordinate: the hidden ones of the tree's spherical and universal
        # joints place the links they reach (evaluation.positions has the joints' only)
        _draw(args, mech, mech.assembled_coordinates,
              motion, plot_format)
        text += f'\n\nwrote {args.plot}'
    if args.transmission:
        text += '\n\n' + '\n'.join(_draw_transmission(args, mech, map_format))
    if stdout is None:
        raise BrokenPipeError('stdout is closed')
    stdout.write(text + '\n')
    stdout.flush()
    if refused is not None:
        raise ToolError(refused, EXIT_USAGE)
    return EXIT_OK


def format_report(mech, evaluation, params_file):
    """The whole text report (without the trajectory part)."""
    actuation = format_actuation(mech)
    if getattr(mech, 'joint_space', None):
        actuation.append(f"joint space (what a controller commands): {', '.join(mech.joint_space)}"
                         f"; actuator space (the motors): {', '.join(mech.active_joints)}")
    sections = [format_header(mech, params_file), format_structure(mech),
                actuation, format_joint_table(mech), format_closure(mech, evaluation)]
    return '\n\n'.join('\n'.join(lines) for lines in sections)


def solve_trajectory(mech, solver, path, n_snapshots, stderr):
    """--trajectory read (its notes on stderr) and solved along the solver's branch
    (:func:`cog_id_ros.offline.inspect_motion.solve_motion`); ToolError naming the row and
    column of a bad CSV."""
    active = list(mech.active_joints)
    try:
        traj = trajectory_io.read_trajectory(path, list(mech.joints), active)
    except TrajectoryError as exc:
        raise ToolError(str(exc), EXIT_INPUT) from None
    except OSError as exc:
        raise ToolError(f'--trajectory {path}: cannot read: {exc.strerror or exc}',
                        EXIT_USAGE) from None
    for note in traj.notes:
        print(f'{PROG}: note: {path}: {note}', file=stderr)
    return inspect_motion.solve_motion(mech, solver, traj, path, n_snapshots)


def load(args):
    """(Mechanism, InverseDynamics, refusal or None) of --params-file; ToolError (exit 2)
    naming the parameter. A mechanism refused for its idle spins is loaded again with
    ``idle_spins: lock`` to show them (the refusal is returned, and the exit status is
    still 2). The loader's AssemblyWarnings are not printed as Python warnings: the report
    shows them (``assembly_warnings``)."""
    from ..core.model.mechanism import AssemblyWarning
    if not os.path.isfile(args.params_file):
        what = 'no such file' if not os.path.exists(args.params_file) else 'not a regular file'
        raise ToolError(f'--params-file {args.params_file}: {what}', EXIT_USAGE)
    loading = argparse.Namespace(params_file=args.params_file, node_name=args.node_name,
                                 backend=BACKEND)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        try:
            return (*load_mechanism(loading), None)
        except ToolError as exc:
            if exc.parameter != 'mechanism.locked_joints':
                raise ToolError(str(exc), EXIT_USAGE) from None
            refused = str(exc)
        try:
            return (*load_mechanism(loading, overrides={'mechanism.idle_spins': 'lock'}),
                    refused)
        except ToolError:
            raise ToolError(refused, EXIT_USAGE) from None


def _check_plot_path(args, option='--plot'):
    """Fail before any solving on a --plot (or ``option``) path that cannot work; returns
    its format."""
    path = getattr(args, option.lstrip('-'), None)
    if path is None:
        return None
    if not path or path.endswith(('/', os.sep)):
        raise ToolError(f'{option} {path!r}: give a file name', EXIT_USAGE)
    target, _ = output_target(option, path)
    if option != '--plot' and args.plot and os.path.abspath(args.plot) == os.path.abspath(path):
        raise ToolError(f'{option} {path}: is the same file as --plot', EXIT_USAGE)
    for other_option, other in (('--params-file', args.params_file),
                                ('--trajectory', args.trajectory)):
        if other and os.path.exists(target) and os.path.exists(other) \
                and os.path.samefile(target, other):
            raise ToolError(f'{option} {path}: is the {other_option} file', EXIT_USAGE)
    try:
        from . import plotting
        formats = plotting.supported_formats()
    except ImportError:
        raise ToolError(f'{option} needs matplotlib (pip install matplotlib)',
                        EXIT_USAGE) from None
    try:
        return plot_format(path, formats)
    except ToolError as exc:
        raise ToolError(str(exc).replace('--plot', option, 1), EXIT_USAGE) from None


def _draw(args, mech, positions, motion, fmt):
    from . import mechanism_plot
    snapshots = [] if motion is None else [
        (t, mechanism_plot.frames_from_cog_poses(mech, *links))
        for (t, _), links in zip(motion.snapshots, motion.snapshot_links)]
    try:
        with atomic_files.atomic_output(args.plot) as tmp:
            mechanism_plot.draw_mechanism(
                tmp, mech, positions, snapshots=snapshots, fmt=fmt,
                subtitle=(f'{len(snapshots)} snapshots of {os.path.basename(args.trajectory)}'
                          if snapshots else None),
                warning=_picture_warning(mech))
    except atomic_files.OutputPathError as exc:
        raise ToolError(f'--plot {args.plot}: {exc}', EXIT_WRITE) from None
    except OSError as exc:
        raise ToolError(f'--plot {args.plot}: cannot write: {exc.strerror or exc}',
                        EXIT_WRITE) from None


def _draw_transmission(args, mech, fmt):
    """--transmission: the sweeps drawn into the file; the report's lines. ToolError naming
    mechanism.joint_space without one (EXIT_USAGE), or the file (EXIT_WRITE)."""
    import cog_id_ros

    from . import transmission_plot
    _need_joint_space(mech)
    try:
        sweeps = transmission_plot.sweep(cog_id_ros.Transmission(mech, TRANSMISSION_BACKEND))
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'--transmission: {" ".join(str(exc).split())}', EXIT_USAGE) from None
    try:
        with atomic_files.atomic_output(args.transmission) as tmp:
            transmission_plot.draw_transmission(tmp, mech, sweeps, fmt)
    except atomic_files.OutputPathError as exc:
        raise ToolError(f'--transmission {args.transmission}: {exc}', EXIT_WRITE) from None
    except OSError as exc:
        raise ToolError(f'--transmission {args.transmission}: cannot write: '
                        f'{exc.strerror or exc}', EXIT_WRITE) from None
    return transmission_plot.format_sweeps(sweeps) + [f'wrote {args.transmission}']


def _need_joint_space(mech):
    if not getattr(mech, 'joint_space', None):
        raise ToolError(f'--transmission: {mech.name} names no mechanism.joint_space (the '
                        'joints a controller commands, one per degree of freedom): add it '
                        'under mechanism: to plot the map between them and the motors '
                        '(docs/transmission.md)', EXIT_USAGE)


def _picture_warning(mech):
    moved = [row[0] for row in joint_rows(mech) if row[-1] and row[2].startswith('passive')]
    if not moved:
        return None
    more = f' and {len(moved) - 4} more' if len(moved) > 4 else ''
    return (f"WARNING: the assembly moved {', '.join(moved[:4])}{more} far from "
            f'initial_positions: another branch?')


if __name__ == '__main__':
    sys.exit(main())
