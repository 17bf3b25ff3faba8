"""cog_id_inspect's report of the assembled pose: every joint's given initial_positions
beside the position the assembly at load reached (a WARNING where an actuator moved, or a
passive joint moved further than the loader's "far" threshold), and the closure residual
and condition number there.
"""

import textwrap

from .console import one_line
from .inspect_structure import WIDTH, closure_joints_in_tree

#: coordinates and differences below this (rad or m) are shown as 0: closure rounding
TINY = 1e-12


def joint_rows(mech):
    """Per joint with a coordinate: (name, type, role, given, assembled, unit, warning or
    None); role is 'active', 'active, redundant', 'locked' or 'passive' (', closes loop k'
    added); given is None where the assembly found the position (none was given)."""
    closing = {lp.joint: k for k, lp in enumerate(mech.model.loops, start=1)
               if lp.joint is not None}
    primary = set(mech.primary_joints)
    rows = []
    found = set(getattr(mech, 'found_index', ()))
    for j, name in enumerate(mech.joints):
        given, assembled = mech.initial_positions[j], mech.assembled_positions[j]
        kind = mech.joint_types[j]
        unit = mech.joint_specs[j].kind.unit
        moved = abs(assembled - given)
        warning = None
        if j in found:
            role = ('active' if j in primary else 'active, redundant') \
                if j in mech.active_index else 'locked' if j in mech.locked_index else 'passive'
            given = None
        elif j in mech.active_index:
            role = 'active' if j in primary else 'active, redundant'
            if assembled != given:
                warning = (f"active joint '{name}' moved from {given:.9g} to {assembled:.9g} "
                           f'{unit} (by {moved:.3g}) to close the loops: its initial_positions '
                           f'entry disagrees with the loop closure')
        elif j in mech.locked_index:
            role = 'locked'
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
        table.append((name + (' !' if warning else ''), kind, role,
                      'found' if given is None else _value(given), _value(assembled),
                      '-' if given is None else _signed(assembled - given), unit))
    table += closure_rows(mech)
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = ['joints (given: initial_positions, or found where the loader looked for it; '
             'assembled: where the loader closed the loops):']
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
    if not warned and all(row[3] is None for row in rows):
        lines.append('every position was found by the assembly (none given)')
    elif not warned:
        lines.append(f'no joint moved far at assembly ({_far_text(mech)}): the pose is the one '
                     f'initial_positions points at')
    if any(row[3] is None for row in rows):
        lines.append('the assembled pose, to start from it at every load whatever the loader '
                     'does (one line to paste under `mechanism:`):')
        lines.append('  ' + pose_block(mech).strip('`'))
    notes = list(mech.assembly_warnings)
    if notes:
        lines.append('the loader said (mechanism.assembly_warnings):')
        for note in notes:
            lines += textwrap.wrap(note, WIDTH, initial_indent='  - ', subsequent_indent='    ')
    return lines


def pose_block(mech):
    """The assembled pose as an initial_positions entry to paste: a mapping for the URDF
    form (whose reader names the joints it left to the assembly), else a list."""
    from ..core.model import assembly
    pose = assembly.pose_block(mech, mech.assembled_positions)
    if 'mechanism.found_at_assembly' in mech.parameters:
        return assembly.mapping_block(pose)
    return assembly.native_block(pose)


def _value(value):
    """A coordinate for the table: 6 digits; below TINY (rounding in the closure), 0."""
    return f'{value:.6g}' if abs(value) >= TINY else '0'


def _signed(value):
    return f'{value:+.3g}' if abs(value) >= TINY else '0'


def _far_text(mech):
    from ..core.model import assembly
    text = f'threshold {assembly.FAR_ANGLE:g} rad'
    lengths = [j for j in range(len(mech.joints)) if mech.far_move_limit(j)[1] == 'm']
    if lengths:
        text += f', {mech.far_move_limit(lengths[0])[0]:.3g} m'
    return text


def format_closure(mech, evaluation):
    lines = ['at the assembled pose:']
    if not bool(evaluation.valid[0]):
        error = evaluation.errors[0]
        lines.append(f'  the solver cannot serve it: {one_line(error)}')
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
