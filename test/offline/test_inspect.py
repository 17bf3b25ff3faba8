"""cog_id_inspect: the printed tree, loops, DOF and joint table against the Mechanism, the
warning for an assembly on another branch, the picture, and the error paths.

Most runs call main() in this process (fast); the error path and --help also run the
installed console script, as a user runs it.
"""
import math
from pathlib import Path
import re
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.kinematics.kinematics import BASE
from cog_id_ros.offline import inspect as tool
from cog_id_ros.offline import mechanism_plot

pytest.importorskip('matplotlib')

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / 'config'
# and two with every U and S joint native: one universal and one spherical joint enter the
# spanning tree per leg (hidden coordinates), the other spherical joints close the loops
SPHERICAL = ['stewart_6ups_spherical', 'delta_3rus_spherical']
CONFIGS = ['paper_four_bar_a', 'five_bar_redundant', 'stewart_6ups', 'spatial_rsur'] + SPHERICAL
#: what the joint table says of a spherical, universal or fixed joint in the spanning tree
IN_TREE = {'universal': 'in the tree (hidden coordinates: 2 angles)',
           'spherical': 'in the tree (hidden coordinates: a quaternion)',
           'fixed': 'in the tree (no coordinate)'}
TARGET = CONFIG / 'paper_four_bar_target.csv'
UPRIGHT = ('initial_positions: [1.5707963267948966, -1.5707963267948966, 1.5707963267948966, '
           '1.5707963267948966]')
# joint1 and joint2 at 0 with the crank joint3 upright: the loop closes with link1 along the
# ground and link2 folded onto link3, not the upright parallelogram of the file
FOLDED = 'initial_positions: [0.0, 0.0, 1.5707963267948966, 1.5707963267948966]'


def load(path):
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', cog_id_ros.AssemblyWarning)
        return cog_id_ros.Mechanism.from_params_file(str(path))


def run_main(capsys, *args):
    status = tool.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def tool_command():
    """The installed console script (as a user has it), else the module."""
    script = Path(sys.executable).parent / 'cog_id_inspect'
    if script.exists():
        return [str(script)]
    found = shutil.which('cog_id_inspect')
    return [found] if found else [sys.executable, '-m', 'cog_id_ros.offline.inspect']


def section(out, first_line_start):
    """The lines of the report from the one starting with ``first_line_start`` to the next
    blank line."""
    lines = out.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith(first_line_start))
    end = next((k for k in range(start, len(lines)) if not lines[k].strip()), len(lines))
    return lines[start:end]


def parse_tree(out):
    """{link: (tree parent, joint, type, active, written)} from the printed spanning tree
    (written: the 'written A -> B' mark, or None)."""
    lines = section(out, 'spanning tree')[2:]
    tree, stack = {}, []
    for line in lines:
        m = re.match(r'^  ([| `-]*?)(?:\|-- |`-- )(\w+)  by (\w+) \((\w+)(, ACTIVE)?'
                     r'(?:, written (\w+) -> (\w+))?\)$', line)
        assert m, line
        depth = len(m.group(1)) // 4
        del stack[depth:]
        parent = stack[-1] if stack else None
        written = (m.group(6), m.group(7)) if m.group(6) else None
        tree[m.group(2)] = (parent, m.group(3), m.group(4), bool(m.group(5)), written)
        stack.append(m.group(2))
    return tree


def parse_loops(out):
    """[(closing joint, [tree joints of the cycle], [links of the cycle])]."""
    lines = section(out, 'loops (')[1:]
    loops = []
    for line in lines:
        m = re.match(r'^  \d+\. closed by (\w+) \(', line)
        if m:
            loops.append([m.group(1), ''])
        else:
            loops[-1][1] += ' ' + line.strip()
    parsed = []
    for closing, cycle in loops:
        words = cycle.split()
        assert words[1::2].count(f'={closing}=') == 1, cycle
        tree_joints = [w.strip('-') for w in words[1::2] if w.startswith('-')]
        parsed.append((closing, tree_joints, words))
    return parsed


def link_name(mech, link):
    return mech.base_link if link == BASE else mech.model.link_names[link]


def declared_joints(mech):
    """{joint: (type, parent link name, child link name)} as the parameter file has them."""
    return {spec.name: (spec.kind.name, link_name(mech, spec.parent),
                        link_name(mech, spec.child))
            for spec in list(mech.joint_specs) + list(mech.closure_specs)}


def expected_tree(mech):
    """{link: (tree parent, declared joint)} from the solver's tree edges: a universal
    joint in the tree is two edges through the virtual link '<joint>.cross' (not a link of
    the mechanism), which the report shows as one hop."""
    model, n_real = mech.model, len(mech.links)
    assert model.n_links == len(model.link_names) >= n_real
    tree = {}
    for edge in model.edges:
        if edge.child >= n_real:
            assert model.link_names[edge.child] == f'{edge.name}.cross'
            assert edge.kind.name == 'revolute' and edge.joint >= len(mech.joints)
            continue
        parent = edge.parent
        if parent >= n_real:             # the second hop of a universal joint in the tree
            assert model.link_names[parent] == f'{edge.name}.cross'
            (up,) = [e for e in model.edges if e.child == parent]
            assert up.name == edge.name
            parent = up.parent
        tree[mech.links[edge.child]] = (link_name(mech, parent), edge.name)
    return tree


def check_structure(out, mech):
    """The printed tree, loops and DOF are the mechanism's."""
    tree = parse_tree(out)
    assert set(tree) == set(mech.links)          # the cross of a U joint is no link
    declared = declared_joints(mech)
    expected = expected_tree(mech)
    for link, (parent, joint, kind, active, written) in tree.items():
        assert (parent or mech.base_link, joint) == expected[link], link
        assert kind == declared[joint][0]
        assert active == (joint in mech.active_joints)
        if written is None:
            assert declared[joint][1:] == (parent or mech.base_link, link)
        else:
            assert written == declared[joint][1:] != (parent or mech.base_link, link)
    hops = {(parent or mech.base_link, joint, link)
            for link, (parent, joint, *_) in tree.items()}
    loops = parse_loops(out)
    assert len(loops) == len(mech.model.loops)
    fixed = {name for name, (kind, *_) in declared.items() if kind == 'fixed'}
    for (closing, tree_joints, words), loop in zip(loops, mech.model.loops):
        assert closing == loop.name
        # every coordinate of the cycle (hidden ones too) is a declared joint's, once each;
        # a fixed joint in the tree has none
        names = list(dict.fromkeys(mech.model.coordinate_joints[c] for c, _ in loop.cycle))
        assert len(tree_joints) == len(set(tree_joints))
        assert set(tree_joints) - fixed == set(names)
        links = words[0::2]
        assert links[0] == links[-1]          # the cycle comes back where it started
        for a, joint, b in zip(words[0::2], words[1::2], words[2::2]):
            if joint == f'={closing}=':
                assert (a, b) == declared[closing][1:]
            else:                             # a hop of the printed tree, either way
                joint = joint.strip('-')
                assert (a, joint, b) in hops or (b, joint, a) in hops, (a, joint, b)
    assert f'degrees of freedom: {mech.dof} ' in out
    assert f' {mech.dof} DOF' in out
    assert mech.dof == mech.n_coordinates - mech.closure_rank
    if mech.n_coordinates > len(mech.joints):
        assert (f'degrees of freedom: {mech.dof} ({mech.n_coordinates} coordinates - closure '
                f'rank {mech.closure_rank})') in out
        hidden = mech.n_coordinates - len(mech.joints)
        assert f'coordinates: {len(mech.joints)} of the joints, {hidden} hidden' in out
    else:
        assert (f'degrees of freedom: {mech.dof} ({len(mech.joints)} joint coordinates - '
                f'closure rank {mech.closure_rank})') in out


def check_closure_rows(out, mech):
    """The spherical, universal and fixed joints' rows: the loop each closes, or in the
    tree with its hidden coordinates."""
    closes = {lp.name: k for k, lp in enumerate(mech.model.loops, start=1)}
    in_tree = {edge.name for edge in mech.model.edges}
    for spec in mech.closure_specs:
        assert (spec.name in closes) != (spec.name in in_tree), spec.name
        role = (f'passive, closes loop {closes[spec.name]}' if spec.name in closes
                else IN_TREE[spec.kind.name])
        assert re.search(rf'^  {spec.name}\s+{spec.kind.name}\s+{re.escape(role)}\s+-', out,
                         re.MULTILINE), (spec.name, role)
    for unit in mech.model.units:             # a quaternion of a spherical joint in the tree
        assert unit.name in in_tree and unit.name not in closes


def joint_table(out):
    """{joint: (type, role, given, assembled)} from the printed table (coordinates only)."""
    rows = {}
    for line in section(out, 'joints (given')[2:]:
        if not line.startswith('  '):       # the WARNING lines after the table
            break
        cells = re.split(r'\s{2,}', line.strip())
        if cells[3] == '-':
            continue
        rows[cells[0].rstrip(' !')] = (cells[1], cells[2], float(cells[3]), float(cells[4]))
    return rows


def check_picture(path):
    from matplotlib import image
    data = Path(path).read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    assert 15_000 < len(data) < 300_000
    pixels = image.imread(str(path))
    assert pixels.shape[0] > 300 and pixels.shape[1] > 500
    # not blank: many pixels away from white, and some colours (the links) besides grey
    rgb = pixels[..., :3]
    assert np.mean(rgb.min(axis=2) < 0.9) > 0.02
    assert np.mean(rgb.max(axis=2) - rgb.min(axis=2) > 0.3) > 0.002


@pytest.mark.parametrize('name', CONFIGS)
def test_report_and_picture_match_the_mechanism(name, tmp_path, capsys):
    params = CONFIG / f'{name}.yaml'
    picture = tmp_path / f'{name}.png'
    status, out, err = run_main(capsys, '--params-file', params, '--plot', picture)
    assert status == 0, err
    assert err == ''
    mech = load(params)
    assert out.startswith(f'{mech.name}  ({params})')
    check_structure(out, mech)
    table = joint_table(out)
    assert list(table) == list(mech.joints)
    for j, name_j in enumerate(mech.joints):
        kind, role, given, assembled = table[name_j]
        assert kind == mech.joint_types[j]
        assert role.startswith('active' if name_j in mech.active_joints else 'passive')
        assert given == pytest.approx(mech.initial_positions[j], rel=1e-5, abs=1e-12)
        assert assembled == pytest.approx(mech.assembled_positions[j], rel=1e-5, abs=1e-12)
    check_closure_rows(out, mech)
    assert 'WARNING' not in out
    assert 'no joint moved far at assembly' in out
    evaluation = cog_id_ros.InverseDynamics(mech, backend='reference').evaluate(
        [mech.assembled_positions[j] for j in mech.active_index])
    residual = float(re.search(r'closure residual (\S+)', out).group(1))
    condition = float(re.search(r'condition number (\S+)', out).group(1))
    assert residual == pytest.approx(float(evaluation.closure_residual[0]), rel=0.01, abs=1e-300)
    assert residual < mech.closure_tolerance
    assert condition == pytest.approx(float(evaluation.condition_number[0]), rel=1e-3)
    assert out.rstrip().endswith(f'wrote {picture}')
    check_picture(picture)


def closure_joint_builders():
    """test/core/test_closure_joints.py (its parameter builders)."""
    import importlib.util
    path = ROOT / 'test' / 'core' / 'test_closure_joints.py'
    spec = importlib.util.spec_from_file_location('closure_joint_builders', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def welded_rsur(build):
    """spatial_rsur with a second link welded to the rocker by a fixed joint, written from
    the new link to the rocker: reached only through it, it enters the tree (reversed)."""
    p = build.rsur()
    p['mechanism.links'] = p['mechanism.links'] + ['weight']
    p['links.weight.mass'] = 2.0
    p['links.weight.com'] = [0.05, 0.01, 0.0]
    p['links.weight.inertia'] = [1e-3, 2e-3, 2.5e-3, 1e-4, 0.0, 0.0]
    build.joint(p, 'weld', 'fixed', 'weight', 'rocker', parent_xyz=[0.02, 0.0, 0.0])
    return p


@pytest.mark.parametrize('case', ['rsur_both', 'wrist', 'welded'])
def test_joints_without_coordinate_in_the_tree(case, tmp_path):
    """A link reached only through a universal joint (two hidden angles through a virtual
    cross, here from the joint's child end: 'written' against the tree), a spherical one (a
    quaternion) or a fixed one: the tree names the joint, the loops name declared joints,
    the table says 'in the tree', the picture draws every link and joint."""
    build = closure_joint_builders()
    params = {'rsur_both': build.rsur_both, 'wrist': lambda: build.wrist(False),
              'welded': lambda: welded_rsur(build)}[case]()
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', cog_id_ros.AssemblyWarning)
        mech = cog_id_ros.Mechanism.from_parameters(params)
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    evaluation = solver.evaluate([mech.assembled_positions[j] for j in mech.active_index])
    out = tool.format_report(mech, evaluation, 'in memory')
    check_structure(out, mech)
    check_closure_rows(out, mech)
    tree = parse_tree(out)
    link, parent, joint, kind, written = {
        'rsur_both': ('coupler', 'rocker', 'uni', 'universal', ('coupler', 'rocker')),
        'wrist': ('plate', None, 'ball', 'spherical', None),
        'welded': ('weight', 'rocker', 'weld', 'fixed', ('weight', 'rocker'))}[case]
    assert tree[link] == (parent, joint, kind, False, written)
    assert '.cross' not in out
    assert IN_TREE[kind] in out
    picture = tmp_path / f'{case}.png'
    mechanism_plot.draw_mechanism(str(picture), mech, mech.assembled_coordinates)
    check_picture(picture)
    pose = mechanism_plot.Pose(mech, mech.assembled_coordinates)
    assert [name for name, *_ in pose.links] == list(mech.links)
    assert {j['name'] for j in pose.joints} == set(mech.joints) | set(mech.closure_joints)
    for j in pose.joints:                # every joint closed at the assembled pose
        if j['kind'].name != 'prismatic':
            assert np.linalg.norm(j['parent_point'] - j['child_point']) < 1e-9, j['name']


def test_the_solver_coordinates_place_the_links():
    """The picture of a mechanism with hidden coordinates needs them all (the joints'
    positions do not place the links a spherical or universal joint reaches); the solver's
    link poses (cog_poses) give the same picture; and it is the picture of the same
    mechanism written with revolute joints through massless helper links."""
    mech = load(CONFIG / 'stewart_6ups_spherical.yaml')
    assert mech.n_coordinates > len(mech.joints)
    with pytest.raises(ValueError, match='assembled_coordinates'):
        mechanism_plot.Pose(mech, mech.assembled_positions)
    pose = mechanism_plot.Pose(mech, mech.assembled_coordinates)
    assert mechanism_plot.figure_kind(mech, mech.assembled_coordinates) == 'spatial'
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    cogs, rotations = solver.cog_poses([mech.assembled_positions[j]
                                        for j in mech.active_index])
    again = mechanism_plot.Pose(mech,
                                mechanism_plot.frames_from_cog_poses(mech, cogs, rotations))
    helper = load(CONFIG / 'stewart_6ups.yaml')
    twin = {name: (points, cog) for name, points, cog, _ in
            mechanism_plot.Pose(helper, helper.assembled_positions).links}

    def same_points(a, b):
        return a.shape == b.shape and all(np.linalg.norm(b - p, axis=1).min() < 1e-9
                                          for p in a)
    for (name, points, cog, _), (_, points2, cog2, _) in zip(pose.links, again.links):
        assert np.abs(points - points2).max() < 1e-12 and np.abs(cog - cog2).max() < 1e-12
        assert same_points(points, twin[name][0]), name
        assert np.abs(cog - twin[name][1]).max() < 1e-9, name
    assert len(pose.base_points) == 6                # the six U joints on the ground


@pytest.mark.parametrize('name', SPHERICAL)
def test_trajectory_snapshots_with_hidden_coordinates(name, tmp_path, capsys):
    """--trajectory on a mechanism whose links hang from spherical and universal joints in
    the tree: the snapshots are drawn at the poses the solver reached (its link poses)."""
    mech = load(CONFIG / f'{name}.yaml')
    times = np.linspace(0.0, 2.0, 301)
    start = np.array([mech.assembled_positions[j] for j in mech.active_index])
    amplitude = 0.03 if name.startswith('stewart') else 0.3
    csv = tmp_path / 'motion.csv'
    with open(csv, 'w') as out:
        out.write('time,' + ','.join(f'{j}.position' for j in mech.active_joints) + '\n')
        for t in times:
            q = start + amplitude * np.sin(np.pi * t + np.arange(len(start)))
            out.write(f'{t:.6f},' + ','.join(f'{x:.12g}' for x in q) + '\n')
    picture = tmp_path / 'motion.png'
    status, out, err = run_main(capsys, '--params-file', CONFIG / f'{name}.yaml', '--plot',
                                picture, '--trajectory', csv, '--snapshots', '3')
    assert status == 0, err
    assert re.search(r'solved (\d+) of \1 rows', out)
    assert 'snapshots: t = 0, 1, 2 s' in out
    check_picture(picture)
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    motion = tool.solve_trajectory(mech, solver, str(csv), 3, sys.stderr)
    assert len(motion.snapshots) == len(motion.snapshot_links) == 3
    for (t, q), (cogs, rotations) in zip(motion.snapshots, motion.snapshot_links):
        assert len(q) == len(mech.joints)
        expected = start + amplitude * np.sin(np.pi * t + np.arange(len(start)))
        assert q[mech.active_index] == pytest.approx(expected, abs=1e-8)
        pose = mechanism_plot.Pose(mech, mechanism_plot.frames_from_cog_poses(mech, cogs,
                                                                              rotations))
        for j in pose.joints:            # the links' poses close every joint there
            gap = np.linalg.norm(j['parent_point'] - j['child_point'])
            if j['kind'].name == 'prismatic':
                assert gap == pytest.approx(abs(q[mech.joints.index(j['name'])]), abs=1e-9)
            else:
                assert gap < 1e-9, (t, j['name'])


def test_redundant_actuation_lists_roles_and_weights(capsys):
    params = CONFIG / 'five_bar_redundant.yaml'
    status, out, _ = run_main(capsys, '--params-file', params)
    assert status == 0
    mech = load(params)
    assert mech.is_redundant
    for a, name in enumerate(mech.active_joints):
        role = 'primary' if a in mech.primary else 'redundant'
        assert re.search(rf'^  {name}\s+{role}\s+weight {mech.torque_weights[a]:g}$', out,
                         re.MULTILINE), name
    assert 'redundant' in joint_table(out)['j3'][1]


def test_planar_and_spatial_pictures():
    for name, kind in (('paper_four_bar_a', 'planar'), ('five_bar_redundant', 'planar'),
                       ('slider_crank', 'planar'), ('stewart_6ups', 'spatial'),
                       ('spatial_rsur', 'spatial')):
        mech = load(CONFIG / f'{name}.yaml')
        assert mechanism_plot.figure_kind(mech, mech.assembled_positions) == kind, name


def test_joint_points_close_the_loops():
    """The picture's joints: both attachment frames of a revolute joint at one point."""
    mech = load(CONFIG / 'stewart_6ups.yaml')
    pose = mechanism_plot.Pose(mech, mech.assembled_positions)
    for joint in pose.joints:
        gap = np.linalg.norm(joint['parent_point'] - joint['child_point'])
        if joint['kind'].name == 'revolute':
            assert gap < 1e-9, joint['name']
        else:          # prismatic: apart by the joint coordinate
            q = mech.assembled_positions[mech.joints.index(joint['name'])]
            assert gap == pytest.approx(abs(q), abs=1e-9)
    assert len(pose.base_points) == 6                # the six U joints on the ground


def test_another_branch_is_warned(tmp_path, capsys):
    text = (CONFIG / 'paper_four_bar_a.yaml').read_text()
    assert UPRIGHT in text
    params = tmp_path / 'folded.yaml'
    params.write_text(text.replace(UPRIGHT, FOLDED))
    picture = tmp_path / 'folded.png'
    status, out, err = run_main(capsys, '--params-file', params, '--plot', picture)
    assert status == 0, err
    mech = load(params)
    # the loader's own judgement: it moved joint2 and joint4 far (another branch)
    assert mech.assembly_warnings
    far = set(re.findall(r"'(\w+)' from", mech.assembly_warnings[0]))
    assert far == {'joint2', 'joint4'}
    warned = re.findall(r"^WARNING: passive joint '(\w+)' moved from (\S+) to (\S+) rad",
                        out, re.MULTILINE)
    assert {name for name, _, _ in warned} == far
    for name, given, assembled in warned:
        j = mech.joints.index(name)
        assert float(given) == pytest.approx(mech.initial_positions[j], abs=1e-4)
        assert float(assembled) == pytest.approx(mech.assembled_positions[j], abs=1e-4)
        assert abs(float(assembled) - float(given)) > 1.0
    assert 'another branch' in out
    assert 'set initial_positions near that pose: joint2, joint4,' in ' '.join(out.split())
    table = joint_table(out)
    assert table['joint2'][3] == pytest.approx(math.pi / 2, abs=1e-4)
    assert table['joint1'][3] == pytest.approx(0.0, abs=1e-4)
    assert 'the loader said' in out
    check_structure(out, mech)          # the structure does not depend on the branch
    check_picture(picture)
    # the fix docs/inspect.md gives: initial_positions near the upright pose, every passive
    # joint of the loop (joint1 stayed at 0 on the folded branch, so it is not named)
    params.write_text(text.replace(UPRIGHT, UPRIGHT.replace('1.5707963267948966', '1.55')))
    status, out, _ = run_main(capsys, '--params-file', params)
    assert status == 0 and 'WARNING' not in out


def test_moved_actuators_are_warned(tmp_path, capsys):
    """Redundant initial positions that disagree with the closure (within
    setpoint_tolerance): the loader moves the actuators, the report says which."""
    text = (CONFIG / 'five_bar_redundant.yaml').read_text()
    given = '1.4154911147693727'
    assert text.count(given) == 1
    params = tmp_path / 'inconsistent.yaml'
    params.write_text(text.replace(given, '1.4159911147693727'))      # j3 off by 5e-4 rad
    status, out, err = run_main(capsys, '--params-file', params)
    assert status == 0, err
    mech = load(params)
    moved = set(re.findall(r"active joint '(\w+)' from", ' '.join(mech.assembly_warnings)))
    assert 'j3' in moved
    warned = set(re.findall(r"^WARNING: active joint '(\w+)' moved", out, re.MULTILINE))
    assert warned == moved
    assert 'another branch' not in out          # a small move of the actuators is not that


def test_trajectory_snapshots(tmp_path, capsys):
    params = CONFIG / 'paper_four_bar_a.yaml'
    picture = tmp_path / 'motion.png'
    status, out, err = run_main(capsys, '--params-file', params, '--plot', picture,
                                '--trajectory', TARGET, '--snapshots', '4')
    assert status == 0, err
    assert 'ignoring joint1.position' in err          # the note of the CSV reader
    assert f'trajectory {TARGET}: 2,001 rows, t = 0 .. 2 s' in out
    assert re.search(r'solved (\d+) of \1 rows', out)
    assert 'snapshots: t = 0, 0.667, 1.333, 2 s' in out      # rows 1, 668, 1334, 2001
    check_picture(picture)
    # the snapshots are solved poses of the parallelogram: joint1 = joint3 = theta(t)
    mech = load(params)
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    motion = tool.solve_trajectory(mech, solver, TARGET, 4, sys.stderr)
    assert [t for t, _ in motion.snapshots] == pytest.approx([0.0, 2 / 3, 4 / 3, 2.0],
                                                             abs=1e-3)
    for t, q in motion.snapshots:
        theta = math.pi / 2 + 0.5 * math.sin(math.pi * t)
        assert q[mech.joints.index('joint3')] == pytest.approx(theta, abs=1e-9)
        assert q[mech.joints.index('joint1')] == pytest.approx(theta, abs=1e-9)
    assert motion.residual < mech.closure_tolerance and not motion.refused


def test_trajectory_without_plot_and_a_bad_csv(tmp_path, capsys):
    params = CONFIG / 'paper_four_bar_a.yaml'
    status, out, _ = run_main(capsys, '--params-file', params, '--trajectory', TARGET)
    assert status == 0
    assert 'largest closure residual' in out and 'wrote' not in out
    bad = tmp_path / 'bad.csv'
    bad.write_text('time,joint3.position\n0.0,1.5\n0.1,oops\n')
    status, out, err = run_main(capsys, '--params-file', params, '--trajectory', bad)
    assert status == 1 and out == ''
    assert err.count('\n') == 1
    assert "row 2 (line 3 of the file), column 'joint3.position'" in err


def test_configuration_error_exits_2_naming_the_parameter(tmp_path):
    text = (CONFIG / 'paper_four_bar_a.yaml').read_text()
    params = tmp_path / 'bad.yaml'
    params.write_text(text.replace('mass: 1.0', 'mass: -1.0', 1))
    picture = tmp_path / 'never.png'
    proc = subprocess.run(tool_command() + ['--params-file', str(params), '--plot',
                                            str(picture)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ''
    assert proc.stderr.count('\n') == 1
    assert proc.stderr.startswith('cog_id_inspect: error: ')
    assert 'links.link1.mass: must be >= 0' in proc.stderr
    assert 'Traceback' not in proc.stderr
    assert not picture.exists() and list(tmp_path.iterdir()) == [params]


def test_usage_errors_and_help(tmp_path, capsys):
    params = CONFIG / 'paper_four_bar_a.yaml'
    status, out, err = run_main(capsys, '--params-file', tmp_path / 'missing.yaml')
    assert status == 2 and 'missing.yaml: no such file' in err and out == ''
    status, _, err = run_main(capsys, '--params-file', params, '--plot', tmp_path / 'x.nope')
    assert status == 2 and "unknown image format 'nope'" in err
    status, _, err = run_main(capsys, '--params-file', params, '--plot',
                              tmp_path / 'no_dir' / 'x.png')
    assert status == 2 and 'does not exist' in err
    with pytest.raises(SystemExit) as exc:
        tool.main([])
    assert exc.value.code == 2
    assert '--params-file' in capsys.readouterr().err
    proc = subprocess.run(tool_command() + ['--help'], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0
    assert 'exit status' in proc.stdout and '--trajectory' in proc.stdout
