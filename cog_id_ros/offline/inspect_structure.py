"""cog_id_inspect's report of a mechanism's structure: the header (links, joints by kind,
loops, DOF, gravity), the spanning tree the solver built and the loops with the joints that
close them, and the actuation (degrees of freedom, hidden coordinates, active joints).
"""

import textwrap

#: the report's text width
WIDTH = 99


def _link_name(mech, link):
    from ..core.kinematics.kinematics import BASE
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
            f"[{', '.join(f'{g:g}' for g in mech.gravity)}] m/s^2",
            _base_line(mech), *_contact_lines(mech)]


def _base_line(mech):
    if not mech.floating_base:
        return (f"  base link '{mech.base_link}' held fixed to the world (a fixed base: a robot "
                'that floats or stands on its feet is held by it here; '
                'mechanism.floating_base frees it)')
    com = ', '.join(f'{round(x, 9) + 0.0:.4g}' for x in mech.base_com)
    return (f"  base link '{mech.base_link}' floats ({mech.base_mass:.6g} kg, COG [{com}] m): "
            'six more freedoms, whole_body_torques (docs/floating_base.md)')


def _contact_lines(mech):
    """One line per contact of mechanism.contacts: its kind, link and frame."""
    return [f"  contact '{c.name}': {c.size}d on '{c.link_name}' at "
            f"[{', '.join(f'{round(x, 9) + 0.0:.4g}' for x in c.xyz)}] m"
            for c in mech.contacts.values()]


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
    from ..core.kinematics.kinematics import BASE
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
    from ..core.kinematics.kinematics import BASE
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
    two massless links (core/kinematics/spherical_chains.py), and the coordinates that leaves
    it."""
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
    if mech.locked_joints:
        lines[0] = lines[0][:-1] + (f', {len(mech.locked_joints)} of it the locked joints)')
        lines += textwrap.wrap(f"locked joints (held at their initial positions): "
                               f"{', '.join(mech.locked_joints)}", WIDTH,
                               initial_indent='  ', subsequent_indent='    ')
    lines += format_idle_spins(mech)
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


def format_idle_spins(mech):
    """The idle spins idle_spins: lock took out: per spin, what spins, about which joints,
    the joint locked and the others that could have been."""
    spins = getattr(mech, 'idle_spin_sets', [])
    if not spins:
        return []
    lines = [f'idle spins (mechanism.idle_spins: lock): {len(spins)}, one joint locked each']
    for spin in spins:
        what = ', '.join(spin['links']) or 'massless links ' + ', '.join(spin['moving'])
        text = (f"{what}: spins about the line through {', '.join(spin['ends'])}; locked "
                f"{spin['locked']}" + (f" (could be: {', '.join(spin['others'])})"
                                       if spin['others'] else ''))
        lines += textwrap.wrap(text, WIDTH, initial_indent='  ', subsequent_indent='    ')
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
