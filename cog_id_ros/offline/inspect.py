"""cog_id_inspect: what a mechanism parameter file describes, and how it assembled.

    cog_id_inspect --params-file config/X.yaml [--plot pose.png] [--trajectory motion.csv]

Prints the spanning tree the solver built (base link first; a spherical, universal or
fixed joint in it as one hop, by its declared name), the loops and the joints that close
them, the degrees of freedom (hidden coordinates counted) and the actuators, every joint's
given ``initial_positions`` beside the position the assembly at load reached (a WARNING
where an actuator moved, or a passive joint moved further than the loader's "far"
threshold: the assembly probably took another branch than the one meant), and the closure
residual and condition number at that pose. ``--plot`` draws the mechanism there
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

from ..core.errors import CogIdError
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
  active joints marked; a spherical, universal or fixed joint where the tree needs one),
  the loops (the joint that closes each, and its cycle through the tree), degrees of
  freedom and actuators (primary or redundant, torque weights), a table of every joint:
  initial_positions (given) beside the pose the loader assembled and the difference,
  WARNING lines where an actuator moved or a passive joint moved more than the loader's
  threshold (the assembly probably took another branch: set initial_positions near the
  pose you mean), then the closure residual and the closure Jacobian condition number at
  the assembled pose.

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
        # every solver coordinate: the hidden ones of the tree's spherical and universal
        # joints place the links they reach (evaluation.positions has the joints' only)
        _draw(args, mech, mech.assembled_coordinates,
              motion, plot_format)
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
    snapshots = [] if motion is None else [
        (t, mechanism_plot.frames_from_cog_poses(mech, *links))
        for (t, _), links in zip(motion.snapshots, motion.snapshot_links)]
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
    """{joint name: type} of every joint: those with a coordinate, then the spherical,
    universal and fixed ones."""
    kinds = dict(zip(mech.joints, mech.joint_types))
    kinds.update((spec.name, spec.kind.name) for spec in getattr(mech, 'closure_specs', ()))
    return kinds


def _declared(mech):
    """{joint name: (parent link, child link)} as written in the parameter file."""
    specs = list(mech.joint_specs) + list(getattr(mech, 'closure_specs', ()))
    return {spec.name: (spec.parent, spec.child) for spec in specs}


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


def tree_hops(mech):
    """The spanning tree by declared joints: {link: (tree parent link, joint name)} for
    every moving link (BASE for the base link as parent).

    The solver's tree may hold links of its own (the massless cross of a universal joint in
    the tree, ``<joint>.cross``, two revolute edges of that joint's name): a hop passes
    through them, from the real link above to the real link below, as one joint."""
    model = mech.model
    n_real = len(mech.links)
    hops = {}
    for edge in model.edges:
        if edge.child >= n_real:                 # into a virtual link: its hop ends below
            continue
        parent = edge.parent
        while parent >= n_real:                  # up through virtual links
            parent = model.edges[model.edge_of_link[parent]].parent
        hops[edge.child] = (parent, edge.name or mech.joints[edge.joint])
    return hops


def tree_children(mech, hops=None):
    """{link: [(child link, joint name)]} in the solver's (breadth-first) order."""
    hops = tree_hops(mech) if hops is None else hops
    children = {}
    for edge in mech.model.edges:
        if edge.child in hops:
            parent, name = hops[edge.child]
            children.setdefault(parent, []).append((edge.child, name))
    return children


def closure_joints_in_tree(mech):
    """The spherical, universal and fixed joints the solver put in the spanning tree."""
    closure = set(mech.closure_joints)
    return {name for _, name in tree_hops(mech).values() if name in closure}


def format_structure(mech):
    """The spanning tree (base first; every link under its tree parent, with the joint
    between them) and the loops (closing joint, and the cycle of tree joints), as lines.

    One function for both, so that new kinds of joints show up in one place."""
    from ..core.kinematics import BASE
    model = mech.model
    kinds = _joint_kinds(mech)
    declared = _declared(mech)
    active = set(mech.active_joints)
    hops = tree_hops(mech)
    children = tree_children(mech, hops)

    def joint_label(name, parent, child):
        marks = [kinds[name]]
        if name in active:
            marks.append('ACTIVE')
        written = declared[name]
        if written != (parent, child):
            marks.append(f'written {_link_name(mech, written[0])} -> '
                         f'{_link_name(mech, written[1])}')
        return f"{name} ({', '.join(marks)})"

    lines = ['spanning tree (each link under its tree parent, by the joint between them):',
             f'  {mech.base_link} (base link)']

    def walk(link, prefix):
        below = children.get(link, [])
        for k, (child, name) in enumerate(below):
            last = k == len(below) - 1
            lines.append(f"  {prefix}{'`-- ' if last else '|-- '}"
                         f'{_link_name(mech, child)}  by {joint_label(name, link, child)}')
            walk(child, prefix + ('    ' if last else '|   '))

    walk(BASE, '')
    loops = model.loops
    lines.append('')
    lines.append(f"loops ({len(loops)}): each closed by one joint ('=j='), through tree joints "
                 f"('-j-')")
    if not loops:
        lines.append('  none: an open chain')
    for number, loop in enumerate(loops, start=1):
        name = loop.name or mech.joints[loop.joint]
        label = joint_label(name, loop.parent, loop.child)
        lines.append(f'  {number}. closed by {label}, between '
                     f'{_link_name(mech, loop.parent)} and {_link_name(mech, loop.child)}')
        cycle = _cycle_text(mech, loop, hops)
        lines.extend(textwrap.wrap(cycle, WIDTH - 4, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 8, break_on_hyphens=False))
    return lines


def _up_path(hops, link):
    """[(joint, link above)] from ``link`` up to the base link."""
    from ..core.kinematics import BASE
    path = []
    while link != BASE:
        parent, name = hops[link]
        path.append((name, parent))
        link = parent
    return path


def _cycle_text(mech, loop, hops):
    """'a -j1- b -j2- c =jc= d -j3- a': from the loop's nearest common ancestor down the
    tree to the closing joint's parent link, across it, and back up from its child. Tree
    joints by their declared names (a universal joint in the tree is one hop)."""
    up_parent, up_child = _up_path(hops, loop.parent), _up_path(hops, loop.child)
    above_parent = [loop.parent] + [link for _, link in up_parent]
    above_child = [loop.child] + [link for _, link in up_child]
    top = next(link for link in above_parent if link in above_child)
    words = [_link_name(mech, top)]
    for i in reversed(range(above_parent.index(top))):
        words += [f'-{up_parent[i][0]}-', _link_name(mech, above_parent[i])]
    words += [f'={loop.name or mech.joints[loop.joint]}=', _link_name(mech, loop.child)]
    for i in range(above_child.index(top)):
        words += [f'-{up_child[i][0]}-', _link_name(mech, above_child[i + 1])]
    return ' '.join(words)


def format_spherical_chains(mech):
    """What the solver takes as spherical joints: chains of three revolute joints through
    two massless links (core/spherical_chains.py), and the coordinates that leaves it."""
    chains = mech.spherical_chains
    if not chains:
        return []
    solver = mech.solver_mechanism
    equations = sum(lp.kind.closure_equations for lp in solver.model.constraints)
    text = (f'solved as spherical joints: {len(chains)} chain(s) of three revolute joints '
            f'through massless links (' +
            '; '.join(f"{', '.join(c.joints)}" for c in chains) +
            f'): the solver has {solver.n_coordinates} coordinates and {equations} closure '
            f'equations (closure rank {solver.closure_rank}); the angles are read back for '
            f'the outputs')
    return textwrap.wrap(text, WIDTH, initial_indent='  ', subsequent_indent='    ')


def format_actuation(mech):
    primary = set(mech.primary)
    n_active = len(mech.active_joints)
    coordinates = mech.n_coordinates
    hidden = coordinates - len(mech.joints)
    if hidden:
        lines = [f'degrees of freedom: {mech.dof} ({coordinates} coordinates - closure rank '
                 f'{mech.closure_rank})']
        lines += textwrap.wrap(f'coordinates: {len(mech.joints)} of the joints, {hidden} '
                               f'hidden ({_hidden_text(mech)})', WIDTH,
                               initial_indent='  ', subsequent_indent='    ')
    else:
        lines = [f'degrees of freedom: {mech.dof} ({coordinates} joint coordinates - closure '
                 f'rank {mech.closure_rank})']
    lines += format_spherical_chains(mech)
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


def _hidden_text(mech):
    """What the hidden coordinates are: those of the tree's joints without a coordinate
    of their own (their kinds' ``hidden_detail``), kinds of fewer hidden ones first."""
    in_tree = closure_joints_in_tree(mech)
    counts = {}
    for spec in getattr(mech, 'closure_specs', ()):
        if spec.name in in_tree and spec.kind.hidden:
            counts.setdefault(spec.kind.name, [spec.kind, 0])[1] += 1
    parts = []
    for kind, n in sorted(counts.values(), key=lambda kind_n: len(kind_n[0].hidden)):
        parts.append(f'{kind.hidden_detail} of the {kind.name} joint in the tree' if n == 1
                     else f'{kind.hidden_detail} each of the {n} {kind.name} joints in the tree')
    return '; '.join(parts)


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
        unit = mech.joint_specs[j].kind.unit
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


def closure_rows(mech):
    """Table rows of the spherical, universal and fixed joints (no coordinate of their own):
    role 'passive, closes loop k', or 'in the tree (hidden coordinates: ...)' for one the
    solver put in the spanning tree."""
    closing = {lp.name: k for k, lp in enumerate(mech.model.loops, start=1)
               if lp.joint is None}
    in_tree = closure_joints_in_tree(mech)
    rows = []
    for spec in getattr(mech, 'closure_specs', ()):
        if spec.name in closing:
            role = f'passive, closes loop {closing[spec.name]}'
        elif spec.name in in_tree:
            role = f'in the tree ({spec.kind.hidden_summary})'
        else:                # (the core puts every one in the tree or a loop)
            role = 'passive'
        rows.append((spec.name, spec.kind.name, role, '-', '-', '-',
                     'hidden' if spec.name in in_tree and spec.kind.hidden
                     else 'no coordinate'))
    return rows


def format_joint_table(mech):
    rows = joint_rows(mech)
    header = ('joint', 'type', 'role', 'given', 'assembled', 'difference', 'unit')
    table = [header]
    for name, kind, role, given, assembled, unit, warning in rows:
        table.append((name + (' !' if warning else ''), kind, role, _value(given),
                      _value(assembled), _signed(assembled - given), unit))
    table += closure_rows(mech)
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
    from ..core import assembly
    text = f'threshold {assembly.FAR_ANGLE:g} rad'
    lengths = [j for j in range(len(mech.joints)) if mech.far_move_limit(j)[1] == 'm']
    if lengths:
        text += f', {mech.far_move_limit(lengths[0])[0]:.3g} m'
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
                 + (': near the limit, a singular pose is close' if far else '')
                 + (' (of the closure as solved: the chains of revolutes as spherical joints)'
                    if mech.spherical_chains else ''))
    return lines


# --- a trajectory --------------------------------------------------------------------------

class Motion:
    """What solving --trajectory gave: ``snapshots`` [(time, positions (n_joints,))] to
    draw and ``snapshot_links`` beside them [(COG positions (n_links, 3), link rotations
    (n_links, 3, 3))] (``InverseDynamics.cog_poses``: the joints' positions alone do not
    place a link reached through a spherical or universal joint), the rows solved, the
    largest closure residual and condition number, and the rows the solver refused
    [(row, time, message)]."""

    def __init__(self, path, n_rows, time_span, snapshots, solved, residual, condition,
                 condition_time, refused, snapshot_links=()):
        self.path = path
        self.n_rows = n_rows
        self.time_span = time_span
        self.snapshots = snapshots
        self.snapshot_links = list(snapshot_links)
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
    # in order, in pieces that end at the snapshot rows: at the end of each the solver is at
    # the snapshot's pose, whose link poses it gives (cog_poses) without leaving the branch
    wanted = set(snapshot_rows.tolist())
    ends = [k + 1 for k, r in enumerate(rows.tolist()) if r in wanted]
    if not ends or ends[-1] != len(rows):
        ends.append(len(rows))
    valid, errors, positions, residuals, conditions = [], [], [], [], []
    snapshots, links = [], []
    start = 0
    for end in ends:
        part = solver.evaluate(q[start:end], on_invalid='skip')
        valid += np.asarray(part.valid, bool).tolist()
        errors += list(part.errors)
        positions += list(np.asarray(part.positions))
        residuals += np.asarray(part.closure_residual, float).tolist()
        conditions += np.asarray(part.condition_number, float).tolist()
        k = end - 1
        if int(rows[k]) in wanted and valid[k]:
            try:
                cogs, rotations = solver.cog_poses(q[k])
            except CogIdError:              # (at a pose just solved: not expected)
                pass
            else:
                snapshots.append((float(traj.time[rows[k]]), np.array(positions[k])))
                links.append((np.array(cogs), np.array(rotations)))
        start = end
    valid = np.array(valid, bool)
    refused = [(int(rows[k]) + 1, float(traj.time[rows[k]]), cli._one_line(errors[k]))
               for k in np.flatnonzero(~valid)]
    residual = condition = condition_time = None
    if valid.any():
        residual = float(np.max(np.array(residuals)[valid]))
        k = int(np.argmax(np.where(valid, conditions, -np.inf)))
        condition, condition_time = float(conditions[k]), float(traj.time[rows[k]])
    return Motion(path, n, (float(traj.time[0]), float(traj.time[-1])), snapshots,
                  int(valid.sum()), residual, condition, condition_time, refused, links)


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
