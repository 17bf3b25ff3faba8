"""Three revolute joints through two massless links, solved as the spherical joint they are
(cog_id_ros/core/kinematics/spherical_chains.py): which chains qualify, the same torques, positions
and rates as solving them as written, and the angles read back."""
import math

import numpy as np
import pytest
from test_closure_joints import rsur, wrist
from trajectories import config_path, sample

import cog_id_ros
from cog_id_ros.core.kinematics import spherical_chains
from cog_id_ros.core.linalg import spatial as sp
from cog_id_ros.description.params_file import load_params_file

BACKENDS = ('reference', 'python', 'native')


def as_written(params, monkeypatch):
    """The mechanism of ``params`` solved as written (no chain taken as a spherical joint)."""
    with monkeypatch.context() as patch:
        patch.setattr(spherical_chains, 'find_chains', lambda *args: [])
        mech = cog_id_ros.Mechanism.from_parameters(params)
    assert mech.solver_mechanism is mech and not mech.spherical_chains
    return mech


def params_of(name):
    return dict(load_params_file(config_path(name)))


def turned_helper(params, link, rpy):
    """``params`` with the frame of ``link`` turned by rpy: every joint's attachment on it
    turned with it (the same mechanism, other numbers in the file)."""
    p = dict(params)
    q = sp.rpy_matrix(rpy)
    for name in p['mechanism.joints']:
        for side in ('parent', 'child'):
            if p.get(f'joints.{name}.{side}') != link:
                continue
            xyz = p.get(f'joints.{name}.{side}_xyz', [0.0, 0.0, 0.0])
            r = sp.rpy_matrix(p.get(f'joints.{name}.{side}_rpy', [0.0, 0.0, 0.0]))
            p[f'joints.{name}.{side}_xyz'] = list(sp.mat_t_vec(q, xyz))
            p[f'joints.{name}.{side}_rpy'] = list(sp.matrix_rpy(sp.mat_mat(sp.transpose(q),
                                                                            r)))
    return p


def reversed_joint(params, name):
    """``params`` with joint ``name`` written from its child to its parent: the same
    mechanism, the joint's coordinate negated."""
    p = dict(params)
    pre = f'joints.{name}.'
    for a, b in (('parent', 'child'), ('parent_xyz', 'child_xyz'), ('parent_rpy', 'child_rpy')):
        p[pre + a], p[pre + b] = p.get(pre + b, [0.0] * 3), p.get(pre + a, [0.0] * 3)
    revolute = [n for n in p['mechanism.joints']
                if p[f'joints.{n}.type'] in ('revolute', 'prismatic')]
    k = revolute.index(name)
    positions = list(p['mechanism.initial_positions'])
    positions[k] = -positions[k]
    p['mechanism.initial_positions'] = positions
    return p


@pytest.mark.parametrize('name,chains,coordinates', [('stewart_6ups.yaml', 6, 22),
                                                     ('delta_3rus.yaml', 6, 19),
                                                     ('spatial_rsur.yaml', 1, 4)])
def test_the_example_robots_chains_are_found(name, chains, coordinates):
    mech = cog_id_ros.Mechanism.from_params_file(config_path(name))
    solver = mech.solver_mechanism
    assert len(mech.spherical_chains) == chains
    assert solver.n_coordinates == coordinates < mech.n_coordinates
    assert solver.active_joints == mech.active_joints and solver.dof == mech.dof
    helpers = {h for chain in mech.spherical_chains for h in chain.helpers}
    assert len(helpers) == 2 * chains and not helpers & set(solver.links)
    # the joints as written are what the mechanism shows
    positions, _ = mech.joints_at(solver.assembled_coordinates)
    assert np.abs(positions - mech.assembled_positions).max() < 1e-9


@pytest.mark.parametrize('change', ['mass', 'active', 'offset', 'skew', 'third'])
def test_a_chain_that_is_not_a_spherical_joint_is_solved_as_written(change):
    """The spatial R-S-U-R's S chain (sph_z, sph_y, sph_x through sph_a, sph_b), spoiled one
    way at a time."""
    p = rsur()
    if change == 'mass':                         # a helper with mass
        p['links.sph_a.mass'] = 0.01
    elif change == 'active':                     # a chain joint driven (then two actuators)
        p['mechanism.active_joints'] = p['mechanism.active_joints'] + ['sph_y']
        p['mechanism.torque_weights'] = [1.0, 1.0]     # the redundancy is meant: no warning
    elif change == 'offset':                     # the middle axis (y) 1 mm off the centre
        xyz = p.get('joints.sph_y.parent_xyz', [0.0, 0.0, 0.0])
        p['joints.sph_y.parent_xyz'] = [xyz[0] + 1e-3, xyz[1], xyz[2]]
        p['joints.sph_y.child_xyz'] = [xyz[0] + 1e-3, xyz[1], xyz[2]]
    elif change == 'skew':                       # consecutive axes not at right angles
        axis = np.array(p.get('joints.sph_y.axis', [0.0, 0.0, 1.0]), float)
        p['joints.sph_y.axis'] = (axis + 0.01 * np.roll(axis, 1)).tolist()
    else:                                        # a third joint on a helper link
        p['mechanism.links'] = p['mechanism.links'] + ['extra']
        p['links.extra.mass'] = 0.1
        p['mechanism.joints'] = p['mechanism.joints'] + ['extra_joint']
        p.update({'joints.extra_joint.type': 'fixed', 'joints.extra_joint.parent': 'sph_a',
                  'joints.extra_joint.child': 'extra',
                  'joints.extra_joint.parent_xyz': [0.1, 0.0, 0.0]})
    try:
        mech = cog_id_ros.Mechanism.from_parameters(p)
    except cog_id_ros.MechanismConfigError:
        assert change == 'active'     # two actuators for one freedom: refused as written
        return
    assert not mech.spherical_chains and mech.solver_mechanism is mech


def test_found_in_any_frames_and_either_direction(monkeypatch):
    """The R-S-U-R with its helper links' frames turned arbitrarily and its chain written
    partly backwards (one joint from child to parent, its coordinate negated): still one
    chain, and the same torques and angles as written."""
    p = turned_helper(turned_helper(rsur(), 'sph_a', [0.3, -1.1, 2.0]), 'sph_b',
                      [-2.5, 0.4, 0.9])
    p = reversed_joint(p, 'sph_y')
    mech = cog_id_ros.Mechanism.from_parameters(p)
    assert len(mech.spherical_chains) == 1
    check_as_written(mech, as_written(p, monkeypatch), 'spatial_rsur.yaml')


def test_a_chain_that_ends_on_the_base_link_reads_back_its_angles(monkeypatch):
    """The R-S-U-R re-rooted at its crank (the crank the base link, the ground a moving
    link) with its chain written from the coupler towards the crank: the chain's far end C
    is the base link, whose rotation is the identity (its angles were not read back: a
    TypeError in last_pose and every position). The same numbers as written."""
    p = rsur()
    p['mechanism.base_link'] = 'crank'
    p['mechanism.links'] = ['ground'] + [n for n in p['mechanism.links'] if n != 'crank']
    for key in ('mass', 'com', 'inertia'):
        p[f'links.ground.{key}'] = p.pop(f'links.crank.{key}')
    p = reversed_joint(p, 'sph_y')
    mech = cog_id_ros.Mechanism.from_parameters(p)
    assert [(c.parent, c.child) for c in mech.spherical_chains] == [('coupler', 'crank')]
    check_as_written(mech, as_written(p, monkeypatch), 'spatial_rsur.yaml')


@pytest.mark.parametrize('name', ['stewart_6ups.yaml', 'delta_3rus.yaml',
                                  'spatial_rsur.yaml'])
def test_the_same_numbers_as_solved_as_written(name, monkeypatch):
    mech = cog_id_ros.Mechanism.from_params_file(config_path(name))
    check_as_written(mech, as_written(params_of(name), monkeypatch), name)


def check_as_written(mech, written, name, n=120):
    """Torques (batch on every backend; sample by sample), every joint's position from
    every entry, and last_pose's rates: ``mech`` (chains as spherical joints) against
    ``written``. A chain's angles are read back within pi of their assembled values, where
    as written they wind on with the motion: positions agree modulo 2 pi."""
    _, q, qd, qdd = sample(name, n)
    chained = [mech.joints.index(j) for c in mech.spherical_chains for j in c.joints]

    def apart(a, b):
        d = np.array(a, dtype=float) - np.array(b, dtype=float)
        d[..., chained] = (d[..., chained] + np.pi) % (2.0 * np.pi) - np.pi
        return np.abs(d).max()

    ref = cog_id_ros.InverseDynamics(written, backend='python')
    expected = ref.evaluate(q, qd, qdd)
    scale = np.abs(expected.torques).max()
    for backend in BACKENDS:
        got = cog_id_ros.InverseDynamics(mech, backend=backend).evaluate(q, qd, qdd)
        assert got.valid.all() and got.positions.shape == expected.positions.shape
        assert np.abs(got.torques - expected.torques).max() < 1e-12 * scale, backend
        assert apart(got.positions, expected.positions) < 1e-9, backend
        assert np.abs(got.active_positions - expected.active_positions).max() < 1e-12
    one, other = cog_id_ros.InverseDynamics(mech), cog_id_ros.InverseDynamics(written)
    for k in range(0, n, 5):
        a = one.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        b = other.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        assert np.abs(np.array(a) - b).max() < 1e-8 * scale
        (pa, ra), (pb, rb) = one.last_pose(qd[k].tolist()), other.last_pose(qd[k].tolist())
        assert len(pa) == len(mech.joints) and len(ra) == len(mech.joints)
        assert apart(pa, pb) < 1e-8
        assert np.abs(np.array(ra) - rb).max() < 1e-7 * max(1.0, np.abs(rb).max())
    assert apart(one.solve_positions(q[7]), other.solve_positions(q[7])) < 1e-8
    # the per-link quantities are those of the links as written, helpers included
    a, b = one.cog_jacobians(q[:9]), other.cog_jacobians(q[:9])
    assert a.shape == b.shape and np.abs(a - b).max() < 1e-8
    a, b = one.cog_poses(q[3])[1], other.cog_poses(q[3])[1]
    assert np.abs(a - b).max() < 1e-8


def read_0(lanes):
    return np.array([x[0] for x in lanes])


def test_angles_and_rates_read_back():
    """chain_angles and chain_rates invert T = Rot(e1, q1) Rot(e2, q2) Rot(e3, q3) and its
    angular velocity, for the axes of a real chain, away from the lock."""
    mech = cog_id_ros.Mechanism.from_params_file(config_path('stewart_6ups.yaml'))
    chain = mech.spherical_chains[2]
    rng = np.random.default_rng(4)
    angles = np.array(chain.reference) + rng.uniform(-1.2, 1.2, (50, 3))
    rates = rng.normal(size=(50, 3))
    e = [np.array(x) for x in chain.axes]

    def turn(a):
        out = np.eye(3)
        for axis, angle in zip(e, a):
            out = out @ np.array(sp.rotation_about(tuple(axis), float(angle))).reshape(3, 3)
        return out

    turns = np.array([turn(a) for a in angles]).reshape(-1, 9)
    read = spherical_chains.chain_angles(chain, tuple(turns.T), sp.ArrayOps)
    assert np.abs(np.array(read).T - angles).max() < 1e-12
    one = spherical_chains.chain_angles(chain, tuple(turns[0].tolist()), sp.ScalarOps)
    assert all(type(x) is float for x in one) and np.abs(np.array(one) - read_0(read)).max() == 0
    h = 1e-6
    omega = []
    for a, r in zip(angles, rates):    # w from (T(a + h r) - T(a - h r)) / 2h = [w]x T
        d = (turn(a + h * r) - turn(a - h * r)) / (2 * h) @ turn(a).T
        omega.append([d[2, 1], d[0, 2], d[1, 0]])
    got = spherical_chains.chain_rates(chain, tuple(angles.T), tuple(np.array(omega).T),
                                       sp.ArrayOps)
    assert np.abs(np.array(got).T - rates).max() < 1e-7
    # at the lock (Rot(e2, q2) e3 along e1) the rates are huge or not finite, never an
    # exception
    lock = math.atan2(float(e[0] @ np.cross(e[1], e[2])), float(e[0] @ e[2]))
    assert abs(e[0] @ (turn([0.0, lock, 0.0]) @ e[2])) > 1.0 - 1e-12
    at_lock = spherical_chains.chain_rates(chain, (0.3, lock, -0.2), (0.1, 0.2, 0.3),
                                           sp.ScalarOps)
    assert not np.abs(np.array(at_lock)).max() < 1e12


def test_a_mechanism_with_both_kinds_reads_back_its_hidden_coordinates_too(monkeypatch):
    """The 3-UPS/S wrist with its central ball as three revolutes and its legs' U joints
    native (hidden coordinates in the tree as written): the per-link quantities, which need
    every coordinate as written, agree with solving it as written."""
    params = wrist(True)
    mech = cog_id_ros.Mechanism.from_parameters(params)
    written = as_written(params, monkeypatch)
    assert len(mech.spherical_chains) == 1 and mech.n_coordinates > len(mech.joints)
    legs = [mech.joints.index(f'p{i}') for i in range(3)]
    from cog_id_ros.core.closure import closure
    ball = [mech.joints.index(j) for j in ('ball_x', 'ball_y', 'ball_z')]
    q, lengths = list(mech.assembled_coordinates), []
    for turn in np.linspace(0.0, 0.6, 7):
        q[ball[0]], q[ball[1]], q[ball[2]] = 0.3 * turn, -turn, 0.5 * turn
        q, _, ok = closure.assemble(mech.model, q, 1e-13, fixed=ball)
        assert ok
        lengths.append([q[j] for j in legs])
    lengths = np.array(lengths)
    one, other = cog_id_ros.InverseDynamics(mech), cog_id_ros.InverseDynamics(written)
    for name in ('cog_jacobians', 'solve_positions'):
        a, b = getattr(one, name)(lengths), getattr(other, name)(lengths)
        assert a.shape == b.shape and np.abs(a - b).max() < 1e-8, name
    h, bias = one.equation_of_motion(lengths[3], [0.1, -0.2, 0.3])
    h2, bias2 = other.equation_of_motion(lengths[3], [0.1, -0.2, 0.3])
    assert np.abs(h - h2).max() < 1e-8 and np.abs(bias - bias2).max() < 1e-8


def _wrist_legs(pitch):
    """Leg lengths of the 3-UPS wrist (test_closure_joints.wrist, its geometry read from
    its parameters) with the plate pitched by ``pitch`` about y."""
    p = wrist(False)
    c, s = math.cos(pitch), math.sin(pitch)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    centre = np.array(p['joints.ball.parent_xyz'])
    out = []
    for i in range(3):
        base, top = np.array(p[f'joints.u{i}.parent_xyz']), np.array(p[f'joints.s{i}.child_xyz'])
        stroke = p[f'joints.p{i}.parent_xyz'][2] - p[f'joints.p{i}.child_xyz'][2]
        out.append(float(np.linalg.norm(centre + rot @ top - base)) - stroke)
    return out


def test_through_the_lock_the_torques_and_h_b_go_on_and_per_link_rates_are_refused():
    """The wrist's ball written x-y-x, started pitched by 0.3 rad and tilted back to home,
    where its first and last axes line up (the lock): the torques and H, B of eq. (7) are
    those of the native ball all the way; cog_drifts, which needs the rates of the joints
    as written, says singular at the lock instead of returning numbers."""
    p = wrist(True)
    p['joints.ball_z.axis'] = [1.0, 0.0, 0.0]
    p['mechanism.initial_positions'] = [0.0, 0.3, 0.0] + _wrist_legs(0.3)
    native = wrist(False)
    native['mechanism.initial_positions'] = _wrist_legs(0.3)
    t = np.linspace(0.0, 1.0, 41)
    q = np.array([_wrist_legs(0.3 * (1.0 - x)) for x in t])
    qd = np.gradient(q, t[1], axis=0)
    qdd = np.gradient(qd, t[1], axis=0)
    chained = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(p))
    ball = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(native))
    assert len(chained.mechanism.spherical_chains) == 1
    tau, expected = chained.torques(q, qd, qdd), ball.torques(q, qd, qdd)
    assert np.abs(tau - expected).max() < 1e-9 * np.abs(expected).max()
    h, b = chained.equation_of_motion(q[-1], qd[-1])
    assert np.abs(h @ qdd[-1] + b - tau[-1]).max() < 1e-9 * np.abs(tau[-1]).max()
    with pytest.raises(cog_id_ros.SingularConfigurationError, match='gimbal lock'):
        chained.cog_drifts(q[-1], qd[-1])
    drifts = chained.cog_drifts(q[5], qd[5])          # away from the lock: as the ball's
    assert np.abs(drifts[0] - ball.cog_drifts(q[5], qd[5])[0]).max() < 1e-8


def test_a_chain_near_its_lock_at_load_is_named_in_the_error():
    """Assembled 0.001 rad from the lock the joints as written are singular (the load
    refuses them) and too near it to be taken as a ball: the message names the chain and
    says to write it as one spherical joint."""
    p = wrist(True)
    p['mechanism.initial_positions'] = [0.0, 1.5706, 0.0] + _wrist_legs(1.5706)
    with pytest.raises(cog_id_ros.MechanismConfigError) as info, \
            pytest.warns(cog_id_ros.AssemblyWarning, match='moved passive joint'):
        cog_id_ros.Mechanism.from_parameters(p)
    assert 'ball_x, ball_y, ball_z' in str(info.value) and 'gimbal lock' in str(info.value)
    assert '`type: spherical`' in str(info.value)
