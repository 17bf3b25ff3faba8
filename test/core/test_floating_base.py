"""Floating base and contacts (docs/floating_base.md): whole_body_torques against Pinocchio with
a free-flyer root, the same loops and contact frames (test/pinocchio_loops.py), on a
two-legged robot of the published collection as its authors wrote it."""
import os
import warnings

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.errors import MechanismConfigError, SetpointError
from cog_id_ros.core.model.assembly import AssemblyWarning

HERE = os.path.dirname(os.path.abspath(__file__))
BIPED = os.path.join(HERE, '..', 'models', 'example_parallel_robots', 'digit_like_2legs')
CONTACTS = {'right_foot': ('foot', '6d', (0.02, 0.01, -0.03), (0.1, -0.2, 0.3)),
            'left_foot': ('foot_left', '6d', (0.0, 0.0, -0.02), (0.0, 0.0, 0.0)),
            'left_toe': ('foot_left', '3d', (0.08, 0.0, -0.02), (0.0, 0.0, 0.0))}
RTOL = 1e-6


def biped_params(**extra):
    params = {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
              'mechanism.floating_base': True}
    for name, (link, kind, xyz, rpy) in CONTACTS.items():
        params.update({f'mechanism.contacts.{name}.link': link,
                       f'mechanism.contacts.{name}.type': kind,
                       f'mechanism.contacts.{name}.xyz': list(xyz),
                       f'mechanism.contacts.{name}.rpy': list(rpy)})
    params.update(extra)
    return params


@pytest.fixture(scope='module')
def biped():
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        return cog_id_ros.Mechanism.from_parameters(biped_params(), base_dir=BIPED)


@pytest.fixture(scope='module')
def oracle(biped):
    from pinocchio_loops import LoopOracle
    o = LoopOracle(read('robot.urdf'), read('robot.yaml'), free_flyer=True)
    for name, (link, _, xyz, rpy) in CONTACTS.items():
        o.add_contact(name, link, xyz, rpy)
    return o


def read(name):
    with open(os.path.join(BIPED, name), encoding='utf-8') as stream:
        return stream.read()


def quaternion(r):
    """(qx, qy, qz, qw) of a rotation matrix (its w well away from 0 here)."""
    w = 0.5 * np.sqrt(1.0 + np.trace(r))
    return np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1], 4 * w * w]) / (4 * w)


def state(mech, k):
    """A base pose, twist and acceleration and an actuator motion about the assembled pose."""
    rng = np.random.default_rng(k)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    half = 0.3 * rng.uniform(-1, 1)
    pose = np.concatenate([rng.normal(size=3), axis * np.sin(half), [np.cos(half)]])
    q0 = np.array([mech.assembled_positions[j] for j in mech.active_index])
    theta = q0 + 0.01 * rng.uniform(-1, 1, size=len(q0))
    return (pose, rng.normal(size=6), rng.normal(size=6), theta,
            0.3 * rng.normal(size=len(q0)), rng.normal(size=len(q0)))


def oracle_at(oracle, mech, pose, theta):
    """Pinocchio's configuration at our closed pose (its loops closed again by Pinocchio)."""
    solver = cog_id_ros.InverseDynamics(mech)
    positions = solver.solve_positions_by_name(theta)
    q = oracle.configuration(positions)
    q[:7] = pose
    return oracle.close(q)


@pytest.mark.parametrize('contacts', [[], ['right_foot'], ['right_foot', 'left_foot'],
                                      ['left_toe'], ['right_foot', 'left_foot', 'left_toe']])
def test_whole_body_torques_match_pinocchio(biped, oracle, contacts):
    """Efforts, wrenches and base wrench to 1e-6 relative: none (all in base_wrench), one
    6d (unique), two (least norm), a 3d alone (what it cannot balance left over)."""
    pytest.importorskip('pinocchio')
    solver = cog_id_ros.InverseDynamics(biped)
    for k in range(3):
        pose, v, a, theta, thd, thdd = state(biped, k)
        got = solver.whole_body_torques(pose, v, a, theta, thd, thdd, contacts=contacts)
        q = oracle_at(oracle, biped, pose, theta)
        sizes = [(name, 6 if CONTACTS[name][1] == '6d' else 3) for name in contacts]
        efforts, w, rest = oracle.whole_body(q, v, a, thd, thdd, sizes)
        scale = max(np.abs(efforts).max(), np.abs(rest).max(), 1.0)
        np.testing.assert_allclose(got.efforts, efforts, atol=RTOL * scale)
        np.testing.assert_allclose(got.base_wrench, rest, atol=RTOL * scale)
        ours = np.concatenate([got.wrenches[name] for name in contacts]) if contacts else w
        np.testing.assert_allclose(ours, w, atol=RTOL * max(np.abs(w).max(initial=0), 1.0))
        if contacts and CONTACTS[contacts[0]][1] == '6d':
            assert np.abs(got.base_wrench).max() < 1e-9 * scale    # a 6d contact balances


def test_wrench_weights_shift_the_load(biped, oracle):
    """Weights on the two feet's wrenches: the least weighted norm, as Pinocchio's motion
    with the same weights; a heavier weight on a foot gives it less."""
    pytest.importorskip('pinocchio')
    solver = cog_id_ros.InverseDynamics(biped)
    pose, v, a, theta, thd, thdd = state(biped, 7)
    weights = {'right_foot': [4.0, 4.0, 4.0, 1.0, 2.0, 3.0], 'left_foot': 1.0}
    got = solver.whole_body_torques(pose, v, a, theta, thd, thdd,
                                    contacts=['right_foot', 'left_foot'],
                                    wrench_weights=weights)
    q = oracle_at(oracle, biped, pose, theta)
    efforts, w, _ = oracle.whole_body(q, v, a, thd, thdd, [('right_foot', 6), ('left_foot', 6)],
                                      np.array([4.0, 4.0, 4.0, 1.0, 2.0, 3.0] + [1.0] * 6))
    np.testing.assert_allclose(got.efforts, efforts, atol=RTOL * np.abs(efforts).max())
    np.testing.assert_allclose(np.concatenate([got.wrenches['right_foot'],
                                               got.wrenches['left_foot']]), w,
                               atol=RTOL * np.abs(w).max())
    even = solver.whole_body_torques(pose, v, a, theta, thd, thdd,
                                     contacts=['right_foot', 'left_foot'])
    assert np.linalg.norm(got.wrenches['right_foot'][:3]) < \
        np.linalg.norm(even.wrenches['right_foot'][:3])


def test_at_rest_without_contacts_the_base_wrench_is_the_weight(biped):
    """contacts=[] and no motion: base_wrench is the robot's weight (in the base frame) and
    its moment about the root."""
    solver = cog_id_ros.InverseDynamics(biped)
    theta = np.array([biped.assembled_positions[j] for j in biped.active_index])
    half = 0.4
    pose = [0.1, -0.2, 0.9, np.sin(half), 0.0, 0.0, np.cos(half)]   # rolled about x
    out = solver.whole_body_torques(pose, None, None, theta, contacts=[])
    masses = [biped.base_mass] + list(biped.link_mass)
    centres = np.vstack([biped.base_com, solver.cog_poses(theta)[0]])
    rot = np.array([[1, 0, 0], [0, np.cos(2 * half), -np.sin(2 * half)],
                    [0, np.sin(2 * half), np.cos(2 * half)]])
    weight = -sum(masses) * rot.T @ np.array([0.0, 0.0, -9.81])      # what holds it up
    com = np.average(centres, axis=0, weights=masses)
    np.testing.assert_allclose(out.base_wrench[:3], weight, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(out.base_wrench[3:], np.cross(com, weight), atol=1e-9)
    assert out.wrenches == {}


def test_batch_equals_samples(biped):
    solver = cog_id_ros.InverseDynamics(biped)
    samples = [state(biped, k) for k in range(4)]
    batch = solver.whole_body_torques(*[np.array(column) for column in zip(*samples)],
                                      contacts=['right_foot', 'left_toe'])
    for k, sample in enumerate(samples):
        one = cog_id_ros.InverseDynamics(biped).whole_body_torques(
            *sample, contacts=['right_foot', 'left_toe'])
        np.testing.assert_allclose(batch.efforts[k], one.efforts, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(batch.base_wrench[k], one.base_wrench, atol=1e-9)
        for name in one.wrenches:
            np.testing.assert_allclose(batch.wrenches[name][k], one.wrenches[name], atol=1e-9)


def test_power_balance_with_moving_contacts(biped):
    """The efforts' power plus the contacts' and the base wrench's equals the rate of the
    robot's kinetic and potential energy (a finite difference along the motion), contacts
    moving (the caller decides what touches)."""
    solver = cog_id_ros.InverseDynamics(biped)
    pose, v, a, theta, thd, thdd = state(biped, 3)
    out = solver.whole_body_torques(pose, v, a, theta, thd, thdd,
                                    contacts=['right_foot', 'left_foot'])
    # power of everything applied = the generalized forces times the independent rates
    q_base = out.base_wrench + _base_part(solver, pose, theta, ['right_foot', 'left_foot'],
                                          out.wrenches)
    no_contact = solver.whole_body_torques(pose, v, a, theta, thd, thdd, contacts=[])
    np.testing.assert_allclose(q_base, no_contact.base_wrench, rtol=1e-9, atol=1e-9)
    contact_power = sum(np.dot(out.wrenches[name], _contact_twist(solver, pose, v, theta, thd,
                                                                  name))
                        for name in out.wrenches)
    power_with = np.dot(out.efforts, thd) + np.dot(out.base_wrench, v) + contact_power
    power_without = np.dot(no_contact.efforts, thd) + np.dot(no_contact.base_wrench, v)
    assert power_with == pytest.approx(power_without, rel=1e-9, abs=1e-9)


def _base_part(solver, pose, theta, names, wrenches):
    """What the wrenches contribute to the base's rows: Q_b - base_wrench."""
    from cog_id_ros.core.solve.whole_body import quaternion_rotations
    r = quaternion_rotations(np.array([pose[3:]]))[0].reshape(3, 3)
    mech = solver.mechanism
    positions, rotations = solver.cog_poses(theta)
    total = np.zeros(6)
    for name in names:
        c = mech.contacts[name]
        point = c.xyz if c.link < 0 else _point(solver, theta, name)
        f = r.T @ wrenches[name][:3]
        m = r.T @ wrenches[name][3:] if c.size == 6 else np.zeros(3)
        total += np.concatenate([f, np.cross(point, f) + m])
    return total


def _point(solver, theta, name):
    """The contact point in the base frame, from the link's COG pose."""
    mech = solver.mechanism
    c = mech.contacts[name]
    positions, rotations = solver.cog_poses(theta)
    com = np.array(mech.link_com[c.link])
    return positions[c.link] + rotations[c.link] @ (np.array(c.xyz) - com)


def _contact_twist(solver, pose, v, theta, thd, name, h=1e-6):
    """The contact frame's linear (and angular) velocity in world axes: finite differences
    of its world pose along the motion."""
    from cog_id_ros.core.solve.whole_body import quaternion_rotations
    mech = solver.mechanism
    c = mech.contacts[name]

    def world(t):
        # base moves with body twist v: first order is enough for a derivative at t=0
        rot = quaternion_rotations(np.array([pose[3:]]))[0].reshape(3, 3)
        w = v[3:]
        skew = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
        rot_t = rot @ (np.eye(3) + t * skew)
        p_t = pose[:3] + t * rot @ v[:3]
        probe = cog_id_ros.InverseDynamics(mech)
        positions, rotations = probe.cog_poses(theta + t * thd)
        com = np.array(mech.link_com[c.link])
        point = positions[c.link] + rotations[c.link] @ (np.array(c.xyz) - com)
        frame = rotations[c.link] @ np.array(c.rotation).reshape(3, 3)
        return p_t + rot_t @ point, rot_t @ frame
    (p1, r1), (p0, r0) = world(h), world(-h)
    linear = (p1 - p0) / (2 * h)
    spin = (r1 - r0) / (2 * h) @ ((r1 + r0) / 2).T
    angular = np.array([spin[2, 1], spin[0, 2], spin[1, 0]])
    return np.concatenate([linear, angular])[:c.size]


def test_refusals_name_what_to_fix(biped):
    solver = cog_id_ros.InverseDynamics(biped)
    theta = np.array([biped.assembled_positions[j] for j in biped.active_index])
    with pytest.raises(SetpointError, match="'nose' is not in mechanism.contacts"):
        solver.whole_body_torques([0, 0, 1, 0, 0, 0, 1], None, None, theta, contacts=['nose'])
    with pytest.raises(SetpointError, match='unit one'):
        solver.whole_body_torques([0, 0, 1, 0, 0, 0, 2], None, None, theta)
    with pytest.raises(SetpointError, match='wrench_weights'):
        solver.whole_body_torques([0, 0, 1, 0, 0, 0, 1], None, None, theta,
                                  contacts=['left_toe'], wrench_weights={'left_toe': [-1.0]})
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        with pytest.raises(MechanismConfigError, match='mechanism.floating_base'):
            cog_id_ros.Mechanism.from_parameters(
                biped_params(**{'mechanism.floating_base': False}), base_dir=BIPED)
        with pytest.raises(MechanismConfigError, match=r'mechanism.contacts.left_toe.type'):
            cog_id_ros.Mechanism.from_parameters(
                biped_params(**{'mechanism.contacts.left_toe.type': '4d'}), base_dir=BIPED)


def test_standing_on_one_foot_equals_the_robot_fixed_at_that_foot(biped):
    """The contract's check: one 6d contact and a motion that keeps it still (the base moves as
    the foot held at the world origin makes it: finite differences of that base pose along
    the motion) give the efforts of the same robot with that foot as its fixed base_link."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        fixed = cog_id_ros.Mechanism.from_parameters(
            {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
             'mechanism.base_link': 'foot'}, base_dir=BIPED)
        sole = cog_id_ros.Mechanism.from_parameters(
            biped_params(**{'mechanism.contacts.sole.link': 'foot'}), base_dir=BIPED)
    assert fixed.active_joints == sole.active_joints
    _, _, _, theta0, thd, thdd = state(sole, 5)
    probe = cog_id_ros.InverseDynamics(sole)

    def base_at(t):      # (p, R) of the base in the world with the sole at the origin
        positions, rotations = probe.cog_poses(theta0 + t * thd + 0.5 * t * t * thdd)
        c = sole.contacts['sole']
        com = np.array(sole.link_com[c.link])
        rot = rotations[c.link] @ np.array(c.rotation).reshape(3, 3)
        point = positions[c.link] + rotations[c.link] @ (np.array(c.xyz) - com)
        return -rot.T @ point, rot.T

    def twist(t, h):
        (p1, r1), (p0, r0), (_, r) = base_at(t + h), base_at(t - h), base_at(t)
        spin = r.T @ (r1 - r0) / (2 * h)
        return np.concatenate([r.T @ (p1 - p0) / (2 * h), [spin[2, 1], spin[0, 2], spin[1, 0]]])
    h = 1e-3
    p, r = base_at(0.0)
    v = twist(0.0, h)
    a = (twist(h, h) - twist(-h, h)) / (2 * h)
    pose = np.concatenate([p, quaternion(r)])
    got = cog_id_ros.InverseDynamics(sole).whole_body_torques(pose, v, a, theta0, thd, thdd,
                                                              contacts=['sole'])
    expected = cog_id_ros.InverseDynamics(fixed).torques(theta0, thd, thdd)
    np.testing.assert_allclose(got.efforts, expected, atol=1e-5 * np.abs(expected).max())
    assert np.abs(got.base_wrench).max() < 1e-9 * np.abs(expected).max()


@pytest.mark.parametrize('batch', [False, True])
def test_backends_agree_to_the_bit(biped, batch):
    """The whole-body kernel traced into Python and compiled into C gives the lane code's
    numbers (native/whole_body_kernel.py), one sample and a batch."""
    samples = [state(biped, k) for k in range(3)]
    results = {}
    for backend in ('reference', 'python', 'native'):
        try:
            solver = cog_id_ros.InverseDynamics(biped, backend=backend)
        except MechanismConfigError:       # no C compiler here
            continue
        if batch:
            out = solver.whole_body_torques(*[np.array(c) for c in zip(*samples)],
                                            contacts=['left_toe', 'right_foot'])
        else:
            out = [solver.whole_body_torques(*s, contacts=['left_toe', 'right_foot'])
                   for s in samples]
            out = [np.concatenate([o.efforts, o.base_wrench, *o.wrenches.values()]) for o in out]
        results[backend] = out if not batch else np.concatenate(
            [out.efforts, out.base_wrench, *out.wrenches.values()], axis=1)
    assert len(results) >= 2
    for backend, values in results.items():
        np.testing.assert_array_equal(values, results['reference'], err_msg=backend)


def test_inspect_says_the_base_floats_and_names_the_contacts(biped):
    from cog_id_ros.offline.inspect_structure import format_header
    lines = format_header(biped, 'biped.yaml')
    assert "base link 'torso' floats (3.24523 kg" in lines[2], lines
    assert lines[3] == "  contact 'right_foot': 6d on 'foot_part' at [-0.09189, 0.01, 0.01224] m"
    assert "contact 'left_toe': 3d on 'foot_part_2'" in lines[5]


def test_what_a_user_gets_wrong_is_named(biped):
    """Found by a new user trying to break it: each mistake is an error naming it."""
    solver = cog_id_ros.InverseDynamics(biped)
    theta = np.array([biped.assembled_positions[j] for j in biped.active_index])
    pose = [0.0, 0.0, 0.67, 0.0, 0.0, 0.0, 1.0]
    at_rest = solver.whole_body_torques(np.tile(pose, (2, 1)), None, None, np.tile(theta, (2, 1)))
    assert at_rest.efforts.shape == (2, 12)            # None: at rest, in a batch too
    for weights, what in (({'rigth_foot': [1.0] * 6}, 'not among the contacts'),
                          ([1.0], 'a list of 3'), ({'right_foot': 'a'}, "of 'right_foot'")):
        with pytest.raises(SetpointError, match=what):
            solver.whole_body_torques(pose, None, None, theta, wrench_weights=weights)
    everywhere = solver.whole_body_torques(pose, None, None, theta, wrench_weights=2.0)
    np.testing.assert_allclose(everywhere.efforts, solver.whole_body_torques(
        pose, None, None, theta).efforts, rtol=1e-12)     # scaling every weight changes nothing
    with pytest.raises(SetpointError, match=r"\['right_foot'\]"):
        solver.whole_body_torques(pose, None, None, theta, contacts='right_foot')
    with pytest.raises(SetpointError, match='base velocity and acceleration'):
        solver.whole_body_torques(pose, [0, 0, 0, 1e200, 0, 0], None, theta)
    with pytest.raises(SetpointError, match='0 rows'):
        solver.whole_body_torques(np.zeros((0, 7)), None, None, np.zeros((0, 12)))
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        for extra, name in (({'mechanism.contacts.left_toe.xyz': [0.1, 0.2]},
                             'mechanism.contacts.left_toe.xyz'),
                            ({'mechanism.contacts.left_toe.rpy': 'abc'},
                             'mechanism.contacts.left_toe.rpy')):
            with pytest.raises(MechanismConfigError, match=name):
                cog_id_ros.Mechanism.from_parameters(biped_params(**extra), base_dir=BIPED)
        params = {k: v for k, v in biped_params().items() if '.contacts.' not in k}
        with pytest.raises(MechanismConfigError, match='must be a mapping'):
            cog_id_ros.Mechanism.from_parameters({**params, 'mechanism.contacts': ['foot']},
                                                 base_dir=BIPED)
        assert cog_id_ros.Mechanism.from_parameters({**params, 'mechanism.contacts': {}},
                                                    base_dir=BIPED).contacts == {}
