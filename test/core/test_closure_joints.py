"""Spherical, universal and fixed joints: loop closures, and joints of the spanning tree
with hidden coordinates where nothing else reaches a link.

Each is checked against the same mechanism written with revolute joints through massless
helper links (the only way before), which must give the same torques: the helper links
carry no mass, so the two descriptions are one mechanism.
"""
import os
import sys

import numpy as np
import pytest
from trajectories import TWINS, config_path, sample

import cog_id_ros
from cog_id_ros.description.params_file import load_params_file

BACKENDS = ('reference', 'python')


def rsur(params=None):
    return dict(params or load_params_file(config_path('spatial_rsur.yaml')))


def without(params, links=(), joints=()):
    """The params without the named links and joints (and their entries)."""
    out = {k: v for k, v in params.items()
           if not any(k.startswith(f'links.{n}.') for n in links)
           and not any(k.startswith(f'joints.{n}.') for n in joints)}
    out['mechanism.links'] = [n for n in params['mechanism.links'] if n not in links]
    out['mechanism.joints'] = [n for n in params['mechanism.joints'] if n not in joints]
    with_coordinate = [n for n in params['mechanism.joints']
                       if params[f'joints.{n}.type'] in ('revolute', 'prismatic')]
    out['mechanism.initial_positions'] = [
        x for n, x in zip(with_coordinate, params['mechanism.initial_positions'])
        if n not in joints]
    return out


def joint(params, name, kind, parent, child, **entries):
    params[f'joints.{name}.type'] = kind
    params[f'joints.{name}.parent'] = parent
    params[f'joints.{name}.child'] = child
    for key, value in entries.items():
        params[f'joints.{name}.{key}'] = value
    params['mechanism.joints'] = params['mechanism.joints'] + [name]


def rsur_universal():
    """spatial_rsur with its U joint (uni_a, uni_b through the massless uni_cross) as one
    universal joint between the coupler and the rocker."""
    p = without(rsur(), links=['uni_cross'], joints=['uni_a', 'uni_b'])
    joint(p, 'uni', 'universal', 'coupler', 'rocker', parent_xyz=[0.33, 0.0, 0.0],
          child_xyz=[0.12, 0.0, 0.0], axis=[0.0, 0.0, 1.0], axis2=[0.0, -1.0, 0.0])
    return p


def rsur_spherical():
    """spatial_rsur with its S joint (sph_z, sph_y, sph_x through sph_a, sph_b) as one
    spherical joint between the crank pin and the coupler."""
    p = without(rsur(), links=['sph_a', 'sph_b'], joints=['sph_z', 'sph_y', 'sph_x'])
    joint(p, 'sph', 'spherical', 'crank', 'coupler', parent_xyz=[0.05, 0.0, 0.0])
    return p


def torques(params, backend, q, qd, qdd, serial=False):
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params),
                                        backend=backend)
    if serial:
        return np.array([solver.torques(q[i], qd[i], qdd[i]) for i in range(len(q))])
    return solver.torques(q, qd, qdd)


@pytest.mark.parametrize('backend', BACKENDS)
@pytest.mark.parametrize('make', [rsur_universal, rsur_spherical])
def test_a_joint_without_coordinate_gives_the_torques_of_its_helper_links(make, backend):
    _, q, qd, qdd = sample('spatial_rsur.yaml', 120)
    expected = torques(rsur(), backend, q, qd, qdd)
    scale = np.abs(expected).max()
    assert np.abs(torques(make(), backend, q, qd, qdd) - expected).max() < 1e-12 * scale
    # sample by sample (warm-started Newton stops at the closure tolerance)
    assert np.abs(torques(make(), backend, q, qd, qdd, serial=True)
                  - expected).max() < 1e-8 * scale


@pytest.mark.parametrize('twin', sorted(TWINS))
def test_parallel_robots_with_spherical_joints_match_the_helper_link_ones(twin):
    original = TWINS[twin]
    _, q, qd, qdd = sample(original, 100)
    helper = cog_id_ros.Mechanism.from_params_file(config_path(original))
    native = cog_id_ros.Mechanism.from_params_file(config_path(twin))
    # no helper link left: every U and S is one joint, the actuators the only coordinates
    assert native.joints == native.active_joints and native.dof == helper.dof
    assert len(native.closure_joints) == 12 and len(native.links) == len(helper.links) - 18
    kinds = native.coordinate_types[len(native.joints):]
    assert kinds.count('quaternion') == 4 and kinds.count('revolute') == 12
    expected = cog_id_ros.InverseDynamics(helper, backend='python').torques(q, qd, qdd)
    for backend in BACKENDS:
        got = cog_id_ros.InverseDynamics(native, backend=backend).torques(q, qd, qdd)
        assert np.abs(got - expected).max() < 1e-12 * np.abs(expected).max(), backend
    # sample by sample too (warm-started Newton stops at the closure tolerance)
    solver = cog_id_ros.InverseDynamics(native)
    got = np.array([solver.torques(q[i], qd[i], qdd[i]) for i in range(len(q))])
    assert np.abs(got - expected).max() < 1e-8 * np.abs(expected).max()
    # and so do the positions of the joints both have (the actuators), from every entry
    a = cog_id_ros.InverseDynamics(helper).solve_positions(q)[:, [helper.joints.index(j)
                                                                  for j in native.joints]]
    b = cog_id_ros.InverseDynamics(native).solve_positions(q)
    assert b.shape == (len(q), len(native.joints)) and np.abs(a - b).max() < 1e-9
    assert np.abs(solver.evaluate(q).positions - a).max() < 1e-9
    assert solver.last_pose(qd[-1].tolist())[0] == solver.solve_positions(q[-1]).tolist()


def test_a_fixed_joint_welds_two_links():
    """The rocker welded to a second, heavy link by a fixed joint: the torques are those of
    the rocker carrying that link's mass (the second link is also held by a revolute joint
    to the ground on the rocker's axis, so the fixed joint closes a loop)."""
    _, q, qd, qdd = sample('spatial_rsur.yaml', 60)
    base = rsur()
    # the rocker's axis in the ground frame: rocker_joint's attachment frame, axis -y
    rocker = {k.split('.')[-1]: v for k, v in base.items()
              if k.startswith('joints.rocker_joint.')}
    welded = dict(base)
    welded['mechanism.links'] = base['mechanism.links'] + ['weight']
    welded['links.weight.mass'] = 2.0
    welded['links.weight.com'] = [0.05, 0.01, 0.0]
    welded['links.weight.inertia'] = [1e-3, 2e-3, 2.5e-3, 1e-4, 0.0, 0.0]
    joint(welded, 'weight_hinge', 'revolute', 'ground', 'weight',
          parent_xyz=rocker['parent_xyz'], parent_rpy=rocker['parent_rpy'],
          axis=rocker['axis'])
    joint(welded, 'weld', 'fixed', 'rocker', 'weight')
    welded['mechanism.initial_positions'] = base['mechanism.initial_positions'] + [
        base['mechanism.initial_positions'][-1]]
    # the same weight as part of the rocker: mass and inertia combined (same frame)
    merged = dict(base)
    m1, c1 = base['links.rocker.mass'], np.array(base['links.rocker.com'])
    m2, c2 = 2.0, np.array([0.05, 0.01, 0.0])
    com = (m1 * c1 + m2 * c2) / (m1 + m2)

    def about(c, inertia, mass):
        ixx, iyy, izz, ixy, ixz, iyz = inertia
        i = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        d = c - com
        return i + mass * (d @ d * np.eye(3) - np.outer(d, d))
    total = about(c1, base['links.rocker.inertia'], m1) + about(
        c2, welded['links.weight.inertia'], m2)
    merged['links.rocker.mass'] = m1 + m2
    merged['links.rocker.com'] = com.tolist()
    merged['links.rocker.inertia'] = [total[0, 0], total[1, 1], total[2, 2], total[0, 1],
                                      total[0, 2], total[1, 2]]
    expected = torques(merged, 'python', q, qd, qdd)
    got = torques(welded, 'python', q, qd, qdd)
    assert np.abs(got - expected).max() < 1e-10 * np.abs(expected).max()
    assert np.abs(expected - torques(base, 'python', q, qd, qdd)).max() > 0.01 * np.abs(
        expected).max()        # the weight matters: the check above can fail


@pytest.mark.parametrize('change, parameter, words', [
    (lambda p: p.update({'mechanism.active_joints': ['uni']}), 'mechanism.active_joints',
     'universal joint'),
    (lambda p: p.pop('joints.uni.axis2'), 'joints.uni.axis2', 'missing'),
    (lambda p: p.update({'joints.uni.axis2': [0.0, 0.3, 1.0]}), 'joints.uni.axis2',
     'perpendicular'),
    (lambda p: p.update({'joints.uni.upper': 1.0}), 'joints.uni.upper', 'no coordinate'),
    (lambda p: p.update({'joints.rocker_joint.axis2': [1.0, 0.0, 0.0]}),
     'joints.rocker_joint.axis2', 'second axis of a universal joint'),
    (lambda p: p.update({'mechanism.initial_positions': [0.0] * 6}),
     'mechanism.initial_positions', 'spherical, universal or fixed'),
])
def test_errors_of_joints_without_coordinate_name_the_parameter(change, parameter, words):
    p = rsur_universal()
    change(p)
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    assert info.value.parameter == parameter and words in str(info.value), str(info.value)


def rsur_both():
    """spatial_rsur with both its S and its U as one joint each: the coupler is reached
    through neither a revolute nor a prismatic joint, so one of them (the universal joint,
    fewer hidden coordinates) enters the spanning tree and the other closes the loop."""
    p = without(rsur_spherical(), links=['uni_cross'], joints=['uni_a', 'uni_b'])
    joint(p, 'uni', 'universal', 'coupler', 'rocker', parent_xyz=[0.33, 0.0, 0.0],
          child_xyz=[0.12, 0.0, 0.0], axis=[0.0, 0.0, 1.0], axis2=[0.0, -1.0, 0.0])
    return p


def wrist(helper_links):
    """A 3-UPS/S spherical wrist: a plate on a central ball joint above the base, turned by
    three UPS legs. The plate is reached only through spherical joints, so one (the
    central ball, listed first) enters the spanning tree as a quaternion. ``helper_links``:
    the same mechanism with the central ball as three revolute joints through two massless
    links (about x, y, z; 0 at home)."""
    p = {'mechanism.name': 'wrist', 'mechanism.gravity': [0.0, 0.0, -9.81],
         'mechanism.joints': [],
         'links.plate.mass': 2.0, 'links.plate.com': [0.01, 0.0, 0.05],
         'links.plate.inertia': [0.02, 0.025, 0.04, 0.001, 0.0, 0.002]}
    links = ['plate']
    if helper_links:
        links += ['ball_a', 'ball_b']
        for name in ('ball_a', 'ball_b'):
            p[f'links.{name}.mass'] = 0.0
        for name, parent, child, axis in (('ball_x', 'ground', 'ball_a', [1.0, 0.0, 0.0]),
                                          ('ball_y', 'ball_a', 'ball_b', [0.0, 1.0, 0.0]),
                                          ('ball_z', 'ball_b', 'plate', [0.0, 0.0, 1.0])):
            joint(p, name, 'revolute', parent, child, axis=axis,
                  **({'parent_xyz': [0.0, 0.0, 0.3]} if parent == 'ground' else {}))
    else:
        joint(p, 'ball', 'spherical', 'ground', 'plate', parent_xyz=[0.0, 0.0, 0.3])
    for i in range(3):
        a = 2.0 * np.pi * i / 3.0
        base = [0.25 * np.cos(a), 0.25 * np.sin(a), 0.0]
        top = [0.15 * np.cos(a + 0.6), 0.15 * np.sin(a + 0.6), 0.0]
        d = np.array([top[0], top[1], 0.3]) - base
        pitch, yaw = np.arccos(d[2] / np.linalg.norm(d)), np.arctan2(d[1], d[0])
        links += [f'lower{i}', f'upper{i}']
        p[f'links.lower{i}.mass'] = 1.0
        p[f'links.lower{i}.com'] = [0.0, 0.0, 0.1]
        p[f'links.lower{i}.inertia'] = [0.004, 0.004, 0.0005, 0.0, 0.0, 0.0]
        p[f'links.upper{i}.mass'] = 0.5
        p[f'links.upper{i}.com'] = [0.0, 0.0, -0.1]
        p[f'links.upper{i}.inertia'] = [0.002, 0.002, 0.0002, 0.0, 0.0, 0.0]
        joint(p, f'u{i}', 'universal', 'ground', f'lower{i}', parent_xyz=base,
              parent_rpy=[0.0, float(pitch), float(yaw)], axis=[1.0, 0.0, 0.0],
              axis2=[0.0, 1.0, 0.0])
        joint(p, f'p{i}', 'prismatic', f'lower{i}', f'upper{i}', parent_xyz=[0.0, 0.0, 0.2],
              child_xyz=[0.0, 0.0, -0.2])
        joint(p, f's{i}', 'spherical', f'upper{i}', 'plate', child_xyz=top)
    p['mechanism.links'] = links
    p['mechanism.active_joints'] = ['p0', 'p1', 'p2']
    length = float(np.linalg.norm(d))
    p['mechanism.initial_positions'] = ([0.0] * 3 if helper_links else []) + [length - 0.4] * 3
    return p


def test_a_link_reached_only_through_joints_without_coordinate_enters_the_tree_by_one():
    """Universal and spherical joints may stand anywhere: where no revolute or prismatic
    joint reaches a link, one of them joins the spanning tree with hidden coordinates (two
    angles, or a quaternion) that no output shows, and gives the torques of its helper-link
    twin."""
    _, q, qd, qdd = sample('spatial_rsur.yaml', 120)
    expected = torques(rsur(), 'python', q, qd, qdd)
    mech = cog_id_ros.Mechanism.from_parameters(rsur_both())
    assert mech.closure_joints == ['sph', 'uni'] and len(mech.model.loops) == 1
    assert mech.coordinate_types[len(mech.joints):] == ['revolute', 'revolute']
    for backend in BACKENDS:
        got = torques(rsur_both(), backend, q, qd, qdd)
        assert np.abs(got - expected).max() < 1e-12 * np.abs(expected).max(), backend


def wrist_motion(n=150):
    """The legs' lengths for the plate turning about all three axes (by inverse kinematics
    of the helper-link twin's own solver, finite differences for the rates)."""
    t = np.linspace(0.0, 1.5, n)
    twin = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(wrist(True)))
    # drive the twin's ball angles through a closed-form motion and read the leg lengths off
    angles = np.stack([0.3 * np.sin(2.0 * t), 0.25 * np.sin(3.0 * t + 0.4),
                       0.4 * np.sin(1.5 * t)], axis=1)
    mech = twin.mechanism
    ball = [mech.joints.index(j) for j in ('ball_x', 'ball_y', 'ball_z')]
    legs = [mech.joints.index(f'p{i}') for i in range(3)]
    from cog_id_ros.core.closure import closure
    lengths = []
    q = list(mech.assembled_coordinates)
    for a in angles:
        for j, v in zip(ball, a):
            q[j] = v
        q, _, ok = closure.assemble(mech.model, q, 1e-13, fixed=ball)
        assert ok
        lengths.append([q[j] for j in legs])
    lengths = np.array(lengths)
    dt = t[1] - t[0]
    return lengths, np.gradient(lengths, dt, axis=0), \
        np.gradient(np.gradient(lengths, dt, axis=0), dt, axis=0)


def test_a_spherical_joint_in_the_tree_matches_three_revolutes_and_never_locks():
    """The central ball of the wrist is a quaternion of the tree: the same torques as three
    revolutes through massless links, by every backend, per sample and in a batch; and where
    the helper links lock (middle angle at pi/2: a singular configuration) the ball does
    not."""
    q, qd, qdd = wrist_motion()
    native = cog_id_ros.Mechanism.from_parameters(wrist(False))
    assert native.joints == ['p0', 'p1', 'p2'] and native.closure_joints[0] == 'ball'
    assert native.coordinate_types[3:].count('quaternion') == 4
    helper = cog_id_ros.Mechanism.from_parameters(wrist(True))
    expected = cog_id_ros.InverseDynamics(helper, backend='python').torques(q, qd, qdd)
    scale = np.abs(expected).max()
    for backend in BACKENDS:
        solver = cog_id_ros.InverseDynamics(native, backend=backend)
        assert np.abs(solver.torques(q, qd, qdd) - expected).max() < 1e-12 * scale, backend
        solver.reset()
        serial = np.array([solver.torques(q[i], qd[i], qdd[i]) for i in range(len(q))])
        assert np.abs(serial - expected).max() < 1e-8 * scale, backend
    # the closure residual counts the quaternion's |q|^2 - 1 too: it stays a unit one
    evaluation = cog_id_ros.InverseDynamics(native).evaluate(q, qd, qdd)
    assert evaluation.valid.all() and evaluation.closure_residual.max() < 1e-10
    assert evaluation.positions.shape == (len(q), 3)


def test_a_tree_spherical_joint_turns_through_the_helper_links_gimbal_lock(monkeypatch):
    """Plate pitched from 0 to 1.7 rad about y, held there by the legs. Solved as written,
    the helper-link twin's middle angle passes pi/2 and it refuses the motion (singular);
    the native ball follows the whole way. The twin as loaded is solved as the ball its
    chain stands for (spherical_chains.py): it follows too, with the native torques, and
    reads its angles back on the other branch past the lock (the same rotation)."""
    native = cog_id_ros.Mechanism.from_parameters(wrist(False))
    helper = cog_id_ros.Mechanism.from_parameters(wrist(True))
    assert [c.joints for c in helper.spherical_chains] == [('ball_x', 'ball_y', 'ball_z')]
    ball = [helper.joints.index(j) for j in ('ball_x', 'ball_y', 'ball_z')]
    legs = [helper.joints.index(f'p{i}') for i in range(3)]
    from cog_id_ros.core.closure import closure
    from cog_id_ros.core.kinematics import spherical_chains
    q = list(helper.assembled_coordinates)
    pitches = np.linspace(0.0, 1.7, 171)
    lengths = []
    for pitch in pitches:
        q[ball[1]] = pitch
        q, _, ok = closure.assemble(helper.model, q, 1e-13, fixed=ball)
        assert ok
        lengths.append([q[j] for j in legs])
    lengths = np.array(lengths)
    solver = cog_id_ros.InverseDynamics(native)
    assert np.abs(solver.solve_positions(lengths) - lengths).max() < 1e-12
    solver.reset()
    got = np.array([solver.sample_torques(x.tolist()) for x in lengths])
    assert np.isfinite(got).all()
    twin = cog_id_ros.InverseDynamics(helper).evaluate(lengths)
    assert np.abs(twin.torques - got).max() < 1e-8 * np.abs(got).max()
    angles = twin.positions[:, ball]
    before = pitches < 1.5
    assert np.abs(angles[before] - [[0.0, p, 0.0] for p in pitches[before]]).max() < 1e-8
    after = pitches > 1.6          # x and z half a turn away, y mirrored: the same rotation
    # (x and z near the lock: the closure tolerance over the sine of the distance to it)
    assert np.abs(np.abs(angles[after][:, [0, 2]]) - np.pi).max() < 1e-6
    assert np.abs(angles[after, 1] - (np.pi - pitches[after])).max() < 1e-8
    monkeypatch.setattr(spherical_chains, 'find_chains', lambda *args: [])
    as_written = cog_id_ros.Mechanism.from_parameters(wrist(True))
    assert as_written.solver_mechanism is as_written
    with pytest.raises(cog_id_ros.CogIdError) as info:       # the helper links lock
        cog_id_ros.InverseDynamics(as_written).torques(lengths)
    assert info.value.reason in ('singular', 'unreachable'), info.value
    before = pitches < 1.3
    expected = cog_id_ros.InverseDynamics(as_written).torques(lengths[before])
    assert np.abs(got[before] - expected).max() < 1e-8 * np.abs(expected).max()


def test_position_and_effort_limits_of_the_native_schema():
    p = rsur()
    p['joints.crank_joint.lower'] = -1.0
    p['joints.crank_joint.upper'] = 2.0
    p['joints.crank_joint.effort'] = 5.0
    mech = cog_id_ros.Mechanism.from_parameters(p)
    assert mech.effort_limits == [5.0] and mech.active_position_limits == [(-1.0, 2.0)]
    solver = cog_id_ros.InverseDynamics(mech)
    solver.torques([1.9])
    for q in ([2.5], [-1.5]):
        with pytest.raises(cog_id_ros.SetpointError) as info:
            solver.sample_torques(q, [0.0], [0.0])
        assert info.value.reason == 'limit' and 'crank_joint' in str(info.value)
    batch = solver.evaluate(np.array([[0.5], [2.5], [0.6]]), on_invalid='skip')
    assert batch.valid.tolist() == [True, False, True]
    assert batch.errors[1].reason == 'limit'
    # the rates alone are checked without the positions (solver.cog_drifts, equation_of_motion)
    solver.equation_of_motion([0.5], [1.0])
    p['joints.crank_joint.upper'] = -2.0
    with pytest.raises(cog_id_ros.MechanismConfigError, match='joints.crank_joint.upper'):
        cog_id_ros.Mechanism.from_parameters(p)
    p['joints.crank_joint.upper'] = 2.0
    p['joints.crank_joint.effort'] = 0.0
    with pytest.raises(cog_id_ros.MechanismConfigError, match='joints.crank_joint.effort'):
        cog_id_ros.Mechanism.from_parameters(p)


def test_a_platform_described_turned_round_is_assembled_on_the_same_branch():
    """The platform of the native Stewart platform described with its frame turned by pi
    about z (attachment points, COG and inertia written in that frame): the same body, so
    the same torques. The ball joint that carries it in the tree starts where the platform's
    other joint centres meet their partners (not with its frame parallel to the base, which
    assembled it on another branch)."""
    _, q, qd, qdd = sample('stewart_6ups_spherical.yaml', 60)
    params = load_params_file(config_path('stewart_6ups_spherical.yaml'))
    expected = cog_id_ros.InverseDynamics(
        cog_id_ros.Mechanism.from_parameters(dict(params))).torques(q, qd, qdd)
    turned = dict(params)
    flip = np.array([-1.0, -1.0, 1.0])
    for key, value in params.items():
        if key.startswith('joints.') and key.endswith('.child_xyz') and \
                params[key.replace('child_xyz', 'child')] == 'platform':
            turned[key] = (np.array(value) * flip).tolist()
    turned['links.platform.com'] = (np.array(params['links.platform.com']) * flip).tolist()
    ixx, iyy, izz, ixy, ixz, iyz = params['links.platform.inertia']
    turned['links.platform.inertia'] = [ixx, iyy, izz, ixy, -ixz, -iyz]
    mech = cog_id_ros.Mechanism.from_parameters(turned)
    for backend in BACKENDS:
        got = cog_id_ros.InverseDynamics(mech, backend=backend).torques(q, qd, qdd)
        assert np.abs(got - expected).max() < 1e-10 * np.abs(expected).max(), backend


@pytest.mark.parametrize('idle_spins', ['refuse', 'lock'])
def test_a_link_between_two_ball_joints_is_refused_naming_the_fix(idle_spins):
    """The R-S-U-R coupler with a ball joint at each end spins idly about the line through
    their centres (core/model/idle_spins.py): refused at load, naming the link, its two spherical
    joints and the fix (one of them universal), not 'add active joints' (spherical joints
    cannot be); with idle_spins: lock too, as nothing there can be locked."""
    p = rsur_both()
    p['joints.uni.type'] = 'spherical'
    p['mechanism.idle_spins'] = idle_spins
    del p['joints.uni.axis'], p['joints.uni.axis2']
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(p)
    text = str(info.value)
    assert info.value.parameter == 'joints.sph.type', text
    assert "link 'coupler' spins between the spherical joints 'sph' and 'uni'" in text, text
    assert 'no coordinate to lock' in text and '`type: universal`' in text, text


def stacked_platforms(native):
    """Two Stewart platforms stacked (bench/mechanism_family.ups_platform twice): the upper
    one's legs stand on the lower platform, so two links (the platforms) are reached only
    through spherical joints, one above the other: two quaternions in the tree, the second
    started from the first. ``native`` False: every S and U as revolute joints through
    massless links (the twin)."""
    bench = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', 'bench')
    if bench not in sys.path:
        sys.path.insert(0, bench)
    import mechanism_family as family
    lower, _ = family.ups_platform(6, native=native)
    upper, _ = family.ups_platform(6, native=native)
    p = dict(lower)

    def renamed(name):
        return 'platform' if name == 'ground' else f'up_{name}'

    for key, value in upper.items():
        if key.startswith('links.') or key.startswith('joints.'):
            group, name, field = key.split('.', 2)
            if field in ('parent', 'child'):
                value = renamed(value)
            p[f'{group}.{renamed(name)}.{field}'] = value
    for key in ('links', 'joints', 'active_joints'):
        p[f'mechanism.{key}'] = lower[f'mechanism.{key}'] + [
            renamed(n) for n in upper[f'mechanism.{key}']]
    p['mechanism.initial_positions'] = (lower['mechanism.initial_positions'] +
                                        upper['mechanism.initial_positions'])
    return p


def test_two_platforms_each_reached_only_through_spherical_joints():
    """Two tree quaternions in a row (a platform on legs that stand on a platform): the
    torques of the helper-link twin, in a batch and sample by sample."""
    native = cog_id_ros.Mechanism.from_parameters(stacked_platforms(True))
    helper = cog_id_ros.Mechanism.from_parameters(stacked_platforms(False))
    assert native.coordinate_types.count('quaternion') == 8 and native.dof == 12
    t = np.linspace(0.0, 1.0, 80)[:, None]
    phase = np.arange(12)[None, :]
    home = np.array([helper.assembled_positions[helper.joints.index(j)]
                     for j in native.active_joints])
    w = 2.0 * np.pi
    q = home + 0.02 * np.sin(w * t + phase)
    qd = 0.02 * w * np.cos(w * t + phase)
    qdd = -0.02 * w * w * np.sin(w * t + phase)
    expected = cog_id_ros.InverseDynamics(helper, backend='python').torques(q, qd, qdd)
    scale = np.abs(expected).max()
    solver = cog_id_ros.InverseDynamics(native)
    assert np.abs(solver.torques(q, qd, qdd) - expected).max() < 1e-12 * scale
    solver.reset()
    serial = np.array([solver.torques(q[i], qd[i], qdd[i]) for i in range(len(q))])
    assert np.abs(serial - expected).max() < 1e-8 * scale
