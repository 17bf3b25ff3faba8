"""cog_id_inspect: what a mechanism parameter file describes, and how it assembled.

    cog_id_inspect --params-file config/X.yaml [--plot pose.png] [--trajectory motion.csv]

Prints the spanning tree the solver built (base link first), the loops and the joints
that close them, the degrees of freedom and the actuators, every joint's given
``initial_positions`` beside the position the assembly at load reached (a WARNING where an
actuator moved, or a passive joint moved further than the loader's "far" threshold: the
assembly probably took another branch than the one meant), and the closure residual and
condition number at that pose. ``--plot`` draws the mechanism there
(:mod:`cog_id_ros.offline.mechanism_plot`), ``--trajectory`` adds snapshots along a motion
in the input format of ``cog_id_torques``. Pure reporting: nothing is changed or written
but the picture. No ROS import. docs/inspect.md has an example.
"""

import argparse
import os
import sys
import textwrap
import warnings

import numpy as np

from . import cli, trajectory_io
from .cli import Interrupted, StopSignals, ToolError
from .trajectory_io import TrajectoryError

PROG = 'cog_id_inspect'

EXIT_OK = cli.EXIT_OK
EXIT_INPUT = cli.EXIT_INPUT        # the --trajectory CSV was rejected
EXIT_USAGE = 2                     # command line, or a parameter file that cannot be used
EXIT_WRITE = cli.EXIT_WRITE        # the picture cannot be written
EXIT_INTERNAL = cli.EXIT_INTERNAL
EXIT_BROKEN_PIPE = cli.EXIT_BROKEN_PIPE
TRACEBACK_ENV = 'COG_ID_INSPECT_TRACEBACK'

#: the solver behind the report: it solves a handful of poses, so nothing is compiled
BACKEND = 'reference'
DEFAULT_SNAPSHOTS = 6
MAX_SNAPSHOTS = 12
#: rows of --trajectory solved (evenly spaced, the snapshots among them): the solver
#: follows the motion from one to the next, so the snapshots stay on its branch
TRAJECTORY_ROWS = 200
WIDTH = 99
#: coordinates and differences below this (rad or m) are shown as 0: closure rounding
TINY = 1e-12

EPILOG = f"""\
what it prints:
  the spanning tree (each link under its tree parent, with the joint between them;
  active joints marked), the loops (the joint that closes each, and its cycle through
  the tree), degrees of freedom and actuators (primary or redundant, torque weights),
  a table of every joint: initial_positions (given) beside the pose the loader assembled
  and the difference, WARNING lines where an actuator moved or a passive joint moved more
  than the loader's threshold (the assembly probably took another branch: set
  initial_positions near the pose you mean), then the closure residual and the closure
  Jacobian condition number at the assembled pose.

exit status:
  {EXIT_OK}  success (also with warnings)
  {EXIT_INPUT}  the --trajectory CSV was rejected (one line names the row and column)
  {EXIT_USAGE}  command line, or a parameter file that cannot be read or honoured (one line
     naming the parameter)
  {EXIT_WRITE}  the picture cannot be written
  {EXIT_INTERNAL} an internal error (a bug; {TRACEBACK_ENV}=1 shows the traceback)
  130 Ctrl-C (143 SIGTERM, 129 SIGHUP): no picture written
"""


def build_parser():
    parser = cli._Parser(
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
    parser.add_argument('--node-name', default=None, metavar='NAME',
                        help='node entry of the parameter file to read (default: the '
                             "core's default, which also accepts /**)")
    return parser


def _snapshot_count(text):
    value = cli._positive_int(text)
    if value > MAX_SNAPSHOTS:
        raise argparse.ArgumentTypeError(f'must be at most {MAX_SNAPSHOTS}, got {value}')
    return value


def main(argv: 'list[str] | None' = None) -> int:
    """Console entry point; returns the exit status. Never prints a traceback."""
    args = build_parser().parse_args(argv)
    signals = StopSignals().install()
    try:
        return run(args, sys.stdout, sys.stderr)
    except ToolError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return exc.status
    except Interrupted as exc:
        print(f'{PROG}: interrupted by {cli._signal_name(exc.signum)}; no picture written',
              file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted by SIGINT; no picture written', file=sys.stderr)
        return cli.EXIT_INTERRUPTED
    except BrokenPipeError:
        if sys.stdout is not None:      # the reader went away (`| head`): silence the flush
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as exc:    # a bug: one line, the traceback only on request
        if os.environ.get(TRACEBACK_ENV):
            raise
        print(f'{PROG}: internal error: {type(exc).__name__}: {cli._one_line(exc)[:300]} '
              f'(a bug; please report it with the command; {TRACEBACK_ENV}=1 shows the '
              'traceback)', file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        signals.restore()


def run(args, stdout, stderr):
    plot_format = _check_plot_path(args)
    mech, solver = load(args)
    evaluation = solver.evaluate([mech.assembled_positions[j] for j in mech.active_index],
                                 on_invalid='skip')
    text = format_report(mech, evaluation, args.params_file)
    motion = None
    if args.trajectory:
        motion = solve_trajectory(mech, solver, args.trajectory, args.snapshots, stderr)
        text += '\n\n' + '\n'.join(format_motion(motion))
    if args.plot:
        _draw(args, mech, evaluation.positions[0], motion, plot_format)
        text += f'\n\nwrote {args.plot}'
    if stdout is None:
        raise BrokenPipeError('stdout is closed')
    stdout.write(text + '\n')
    stdout.flush()
    return EXIT_OK


def load(args):
    """(Mechanism, InverseDynamics) of --params-file; ToolError (exit 2) naming the
    parameter. The loader's AssemblyWarnings are not printed as Python warnings: the
    report shows them (``assembly_warnings``)."""
    from ..core.mechanism import AssemblyWarning
    if not os.path.isfile(args.params_file):
        what = 'no such file' if not os.path.exists(args.params_file) else 'not a regular file'
        raise ToolError(f'--params-file {args.params_file}: {what}', EXIT_USAGE)
    loading = argparse.Namespace(params_file=args.params_file, node_name=args.node_name,
                                 backend=BACKEND)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        try:
            return cli._load_mechanism(loading)
        except ToolError as exc:
            raise ToolError(str(exc), EXIT_USAGE) from None


def _check_plot_path(args):
    """Fail before any solving on a --plot path that cannot work; returns its format."""
    if args.plot is None:
        return None
    path = args.plot
    if not path or path.endswith(('/', os.sep)):
        raise ToolError(f'--plot {path!r}: give a file name', EXIT_USAGE)
    try:
        target = trajectory_io.output_target(path)
    except trajectory_io.OutputPathError as exc:
        raise ToolError(f'--plot {path}: {exc}', EXIT_USAGE) from None
    directory = os.path.dirname(os.path.abspath(target))
    if not os.path.isdir(directory):
        raise ToolError(f'--plot {path}: directory {directory} does not exist', EXIT_USAGE)
    for option, other in (('--params-file', args.params_file),
                          ('--trajectory', args.trajectory)):
        if other and os.path.exists(target) and os.path.exists(other) \
                and os.path.samefile(target, other):
            raise ToolError(f'--plot {path}: is the {option} file', EXIT_USAGE)
    try:
        from . import plotting
        formats = plotting.supported_formats()
    except ImportError:
        raise ToolError('--plot needs matplotlib (pip install matplotlib)', EXIT_USAGE) from None
    fmt = os.path.splitext(path)[1].lstrip('.').lower()
    if fmt not in formats:
        raise ToolError(f'--plot {path}: unknown image format {fmt!r} (use one of '
                        + ', '.join(formats) + ')', EXIT_USAGE)
    return fmt


def _draw(args, mech, positions, motion, fmt):
    from . import mechanism_plot
    snapshots = motion.snapshots if motion is not None else ()
    try:
        with trajectory_io.atomic_output(args.plot) as tmp:
            mechanism_plot.draw_mechanism(
                tmp, mech, positions, snapshots=snapshots, fmt=fmt,
                subtitle=(f'{len(snapshots)} snapshots of {os.path.basename(args.trajectory)}'
                          if snapshots else None),
                warning=_picture_warning(mech))
    except trajectory_io.OutputPathError as exc:
        raise ToolError(f'--plot {args.plot}: {exc}', EXIT_WRITE) from None
    except OSError as exc:
        raise ToolError(f'--plot {args.plot}: cannot write: {exc.strerror or exc}',
                        EXIT_WRITE) from None


def _picture_warning(mech):
    moved = [row[0] for row in joint_rows(mech) if row[-1] and row[2].startswith('passive')]
    if not moved:
        return None
    more = f' and {len(moved) - 4} more' if len(moved) > 4 else ''
    return (f"WARNING: the assembly moved {', '.join(moved[:4])}{more} far from "
            f'initial_positions: another branch?')


# --- the report ----------------------------------------------------------------------------

def _link_name(mech, link):
    from ..core.kinematics import BASE
    return mech.base_link if link == BASE else mech.links[link]


def _joint_kinds(mech):
    """{joint name: type} of every joint, those with a coordinate and the closure-only ones."""
    kinds = dict(zip(mech.joints, mech.joint_types))
    kinds.update((spec.name, spec.kind) for spec in getattr(mech, 'closure_specs', ()))
    return kinds


def format_report(mech, evaluation, params_file):
    """The whole text report (without the trajectory part)."""
    sections = [format_header(mech, params_file), format_structure(mech),
                format_actuation(mech), format_joint_table(mech), format_closure(mech, evaluation)]
    return '\n\n'.join('\n'.join(lines) for lines in sections)


def format_header(mech, params_file):
    kinds = _joint_kinds(mech)
    counts = {}
    for kind in kinds.values():
        counts[kind] = counts.get(kind, 0) + 1
    by_kind = ', '.join(f'{n} {kind}' for kind, n in counts.items())
    loops = len(mech.model.loops)
    mass = sum(mech.link_mass)
    return [f'{mech.name}  ({params_file})',
            f'  {len(mech.links)} moving links ({mass:.6g} kg), {len(kinds)} joints ({by_kind}), '
            f"{loops} loop{'' if loops == 1 else 's'}, {mech.dof} DOF; gravity "
            f"[{', '.join(f'{g:g}' for g in mech.gravity)}] m/s^2"]


def format_structure(mech):
    """The spanning tree (base first; every link under its tree parent, with the joint
    between them) and the loops (closing joint, and the cycle of tree joints), as lines.

    One function for both, so that new kinds of joints show up in one place."""
    from ..core.kinematics import BASE
    model = mech.model
    kinds = _joint_kinds(mech)
    active = set(mech.active_joints)
    children = {}
    edge_of_joint = {}
    for edge in model.edges:
        children.setdefault(edge.parent, []).append(edge)
        edge_of_joint[edge.joint] = edge

    def joint_label(name, parent, child, declared):
        marks = [kinds[name]]
        if name in active:
            marks.append('ACTIVE')
        if declared != (parent, child):
            marks.append(f'written {_link_name(mech, declared[0])} -> '
                         f'{_link_name(mech, declared[1])}')
        return f"{name} ({', '.join(marks)})"

    lines = ['spanning tree (each link under its tree parent, by the joint between them):',
             f'  {mech.base_link} (base link)']

    def walk(link, prefix):
        edges = children.get(link, [])
        for k, edge in enumerate(edges):
            last = k == len(edges) - 1
            spec = mech.joint_specs[edge.joint]
            label = joint_label(spec.name, edge.parent, edge.child, (spec.parent, spec.child))
            lines.append(f"  {prefix}{'`-- ' if last else '|-- '}"
                         f'{_link_name(mech, edge.child)}  by {label}')
            walk(edge.child, prefix + ('    ' if last else '|   '))

    walk(BASE, '')
    loops = model.loops
    lines.append('')
    lines.append(f"loops ({len(loops)}): each closed by one joint ('=j='), through tree joints "
                 f"('-j-')")
    if not loops:
        lines.append('  none: an open chain')
    for number, loop in enumerate(loops, start=1):
        name = loop.name or mech.joints[loop.joint]
        label = joint_label(name, loop.parent, loop.child, (loop.parent, loop.child))
        lines.append(f'  {number}. closed by {label}, between '
                     f'{_link_name(mech, loop.parent)} and {_link_name(mech, loop.child)}')
        cycle = _cycle_text(mech, loop, edge_of_joint)
        lines.extend(textwrap.wrap(cycle, WIDTH - 4, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 8, break_on_hyphens=False))
    return lines


def _cycle_text(mech, loop, edge_of_joint):
    """'a -j1- b -j2- c =jc= d -j3- a': from the loop's nearest common ancestor down the
    tree to the closing joint's parent link, across it, and back up from its child."""
    down_to_child = [mech.joints[j] for j, sign in loop.cycle if sign > 0]
    down_to_parent = [mech.joints[j] for j, sign in loop.cycle if sign < 0]
    child_edges = [edge_of_joint[j] for j, sign in loop.cycle if sign > 0]
    parent_edges = [edge_of_joint[j] for j, sign in loop.cycle if sign < 0]
    first = (parent_edges or child_edges)
    top = first[0].parent if first else loop.parent
    words = [_link_name(mech, top)]
    for name, edge in zip(down_to_parent, parent_edges):
        words += [f'-{name}-', _link_name(mech, edge.child)]
    words += [f'={loop.name or mech.joints[loop.joint]}=', _link_name(mech, loop.child)]
    for name, edge in reversed(list(zip(down_to_child, child_edges))):
        words += [f'-{name}-', _link_name(mech, edge.parent)]
    return ' '.join(words)


def format_actuation(mech):
    primary = set(mech.primary)
    n_active = len(mech.active_joints)
    coordinates = len(mech.joints)
    lines = [f'degrees of freedom: {mech.dof} ({coordinates} joint coordinates - closure '
             f'rank {mech.closure_rank})']
    if mech.is_redundant:
        lines.append(f'active joints: {n_active} for {mech.dof} DOF (redundant); the torques '
                     f'minimise sum(w_k tau_k^2), w = torque_weights:')
        width = max(map(len, mech.active_joints))
        for a, name in enumerate(mech.active_joints):
            role = 'primary  ' if a in primary else 'redundant'
            lines.append(f'  {name.ljust(width)}  {role}  weight {mech.torque_weights[a]:g}')
        lines.append(f'  (primary: the {mech.dof} whose coordinates determine the pose best; the '
                     f'others must agree with them)')
    else:
        lines.append(f"active joints: {', '.join(mech.active_joints)} "
                     f"({'all primary' if n_active > 1 else 'primary'}; not redundant)")
    return lines


def joint_rows(mech):
    """Per joint with a coordinate: (name, type, role, given, assembled, unit, warning or
    None); role is 'active', 'active, redundant' or 'passive' (', closes loop k' added)."""
    closing = {lp.joint: k for k, lp in enumerate(mech.model.loops, start=1)
               if lp.joint is not None}
    primary = set(mech.primary_joints)
    rows = []
    for j, name in enumerate(mech.joints):
        given, assembled = mech.initial_positions[j], mech.assembled_positions[j]
        kind = mech.joint_types[j]
        unit = 'rad' if kind == 'revolute' else 'm'
        moved = abs(assembled - given)
        warning = None
        if j in mech.active_index:
            role = 'active' if j in primary else 'active, redundant'
            if assembled != given:
                warning = (f"active joint '{name}' moved from {given:.9g} to {assembled:.9g} "
                           f'{unit} (by {moved:.3g}) to close the loops: its initial_positions '
                           f'entry disagrees with the loop closure')
        else:
            role = 'passive'
            limit, _ = mech.far_move_limit(j)
            if moved > limit:
                warning = (f"passive joint '{name}' moved from {_value(given)} to "
                           f"{_value(assembled)} "
                           f'{unit} (by {moved:.3g}, more than {limit:.3g} {unit})')
        if j in closing:
            role += f', closes loop {closing[j]}'
        rows.append((name, kind, role, given, assembled, unit, warning))
    return rows


def format_joint_table(mech):
    rows = joint_rows(mech)
    header = ('joint', 'type', 'role', 'given', 'assembled', 'difference', 'unit')
    table = [header]
    for name, kind, role, given, assembled, unit, warning in rows:
        table.append((name + (' !' if warning else ''), kind, role, _value(given),
                      _value(assembled), _signed(assembled - given), unit))
    closing = {lp.name: k for k, lp in enumerate(mech.model.loops, start=1)}
    for spec in getattr(mech, 'closure_specs', ()):
        table.append((spec.name, spec.kind, f'passive, closes loop {closing.get(spec.name)}',
                      '-', '-', '-', 'no coordinate'))
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = ['joints (given: initial_positions; assembled: where the loader closed the loops, '
             'actuators held):']
    lines += ['  ' + '  '.join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in table]
    warned = [row for row in rows if row[-1]]
    for row in warned:
        lines += textwrap.wrap('WARNING: ' + row[-1], WIDTH, subsequent_indent='  ')
    far = [name for name, _, role, *_ in warned if role.startswith('passive')]
    if far:
        lines += textwrap.wrap(
            f"The assembly probably went to another branch than meant (another way of "
            f"closing the loops). Look at the picture (--plot); if it is not the pose you "
            f"mean, set initial_positions near that pose: {', '.join(far)}, and the other "
            f"passive joints of their loops.", WIDTH,
            initial_indent='  ', subsequent_indent='  ')
    if not warned:
        lines.append(f'no joint moved far at assembly ({_far_text(mech)}): the pose is the one '
                     f'initial_positions points at')
    notes = list(mech.assembly_warnings)
    if notes:
        lines.append('the loader said (mechanism.assembly_warnings):')
        for note in notes:
            lines += textwrap.wrap(note, WIDTH, initial_indent='  - ', subsequent_indent='    ')
    return lines


def _value(value):
    """A coordinate for the table: 6 digits; below TINY (rounding in the closure), 0."""
    return f'{value:.6g}' if abs(value) >= TINY else '0'


def _signed(value):
    return f'{value:+.3g}' if abs(value) >= TINY else '0'


def _far_text(mech):
    from ..core import mechanism as mechanism_module
    text = f'threshold {mechanism_module.FAR_ANGLE:g} rad'
    prismatic = [j for j, kind in enumerate(mech.joint_types) if kind == 'prismatic']
    if prismatic:
        text += f', {mech.far_move_limit(prismatic[0])[0]:.3g} m'
    return text


def format_closure(mech, evaluation):
    lines = ['at the assembled pose:']
    if not bool(evaluation.valid[0]):
        error = evaluation.errors[0]
        lines.append(f'  the solver cannot serve it: {cli._one_line(error)}')
    residual = float(evaluation.closure_residual[0])
    condition = float(evaluation.condition_number[0])
    closed = 'closed' if residual < mech.closure_tolerance else 'NOT closed'
    lines.append(f'  closure residual {residual:.3g} (mechanism.closure_tolerance '
                 f'{mech.closure_tolerance:g}): {closed}')
    far = condition > 0.1 * mech.max_condition_number
    lines.append(f'  closure Jacobian condition number {condition:.4g} '
                 f'(mechanism.max_condition_number {mech.max_condition_number:g})'
                 + (': near the limit, a singular pose is close' if far else ''))
    return lines


# --- a trajectory --------------------------------------------------------------------------

class Motion:
    """What solving --trajectory gave: ``snapshots`` [(time, positions (n_joints,))] to
    draw, the rows solved, the largest closure residual and condition number, and the
    rows the solver refused [(row, time, message)]."""

    def __init__(self, path, n_rows, time_span, snapshots, solved, residual, condition,
                 condition_time, refused):
        self.path = path
        self.n_rows = n_rows
        self.time_span = time_span
        self.snapshots = snapshots
        self.solved = solved
        self.residual = residual
        self.condition = condition
        self.condition_time = condition_time
        self.refused = refused


def solve_trajectory(mech, solver, path, n_snapshots, stderr):
    """Solve up to TRAJECTORY_ROWS evenly spaced rows of the CSV in order (the solver
    follows the branch from one to the next), the ``n_snapshots`` snapshot rows among them."""
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
    n = len(traj)
    snapshot_rows = np.unique(np.round(np.linspace(0, n - 1, min(n, n_snapshots))).astype(int))
    rows = np.union1d(np.round(np.linspace(0, n - 1, min(n, TRAJECTORY_ROWS))).astype(int),
                      snapshot_rows)
    q = np.column_stack([traj.columns[trajectory_io.joint_column(j, 'position')][rows]
                         for j in active])
    solver.reset()
    result = solver.evaluate(q, on_invalid='skip')
    valid = np.asarray(result.valid, bool)
    refused = [(int(rows[k]) + 1, float(traj.time[rows[k]]), cli._one_line(result.errors[k]))
               for k in np.flatnonzero(~valid)]
    wanted = set(snapshot_rows.tolist())
    snapshots = [(float(traj.time[r]), np.array(result.positions[k]))
                 for k, r in enumerate(rows.tolist()) if r in wanted and valid[k]]
    residual = condition = condition_time = None
    if valid.any():
        residual = float(np.max(result.closure_residual[valid]))
        k = int(np.argmax(np.where(valid, result.condition_number, -np.inf)))
        condition, condition_time = float(result.condition_number[k]), float(traj.time[rows[k]])
    return Motion(path, n, (float(traj.time[0]), float(traj.time[-1])), snapshots,
                  int(valid.sum()), residual, condition, condition_time, refused)


def format_motion(motion):
    t0, t1 = motion.time_span
    taken = motion.solved + len(motion.refused)
    lines = [f'trajectory {motion.path}: {motion.n_rows:,} rows, t = {t0:.6g} .. {t1:.6g} s',
             f'  solved {motion.solved} of {taken} rows taken in order along it (evenly spaced, '
             f'the snapshots among them)']
    if motion.residual is not None:
        lines.append(f'  largest closure residual {motion.residual:.3g}, largest condition '
                     f'number {motion.condition:.4g} (t = {motion.condition_time:.6g} s)')
    if motion.snapshots:
        lines.append('  snapshots: t = ' + ', '.join(f'{t:.4g}' for t, _ in motion.snapshots)
                     + ' s')
    for row, time, message in motion.refused[:10]:
        lines += textwrap.wrap(f'WARNING: row {row} (line {row + 1} of the file, t = {time:.6g} '
                               f's) cannot be solved: {message}', WIDTH, subsequent_indent='  ')
    if len(motion.refused) > 10:
        lines.append(f'  ... and {len(motion.refused) - 10} more rows that cannot be solved')
    return lines


if __name__ == '__main__':
    sys.exit(main())
