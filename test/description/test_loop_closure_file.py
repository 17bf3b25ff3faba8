"""A URDF with the loop list of the Pinocchio ecosystem (``mechanism.loop_closure_file``,
cog_id_ros.description.loop_closure_file, docs/loading_a_closed_loop_urdf.md).

The models in test/models/ are written as such models are published (robot.urdf with
robot.yaml beside it; test/models/make_models.py draws them) and loaded without editing. The reference is independent:
test/pinocchio_loops.py, Pinocchio's URDF parser with the loader's joint edits and its frame
constraints (for the UJOINT edit, the same URDF with the two revolute joints written out).
"""
import os
import warnings

from conftest import REPO
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros import Mechanism, MechanismConfigError
from cog_id_ros.description.urdf import native_parameters

MODELS = os.path.join(REPO, 'test', 'models')
#: the models, the model the oracle reads for each (the UJOINT edit written out), and a
#: joint to check the positions by
ORACLE_MODEL = {'five_bar': 'five_bar', 'knee': 'knee', 'rsur': 'rsur_explicit'}


def model_text(name, filename):
    with open(os.path.join(MODELS, name, filename), encoding='utf-8') as stream:
        return stream.read()


def write_params(tmp_path, model, extra=''):
    """A params file in ``tmp_path`` naming the model's files by relative paths."""
    (tmp_path / 'params.yaml').write_text(
        '/**:\n  ros__parameters:\n    mechanism:\n'
        f'      urdf_file: ../models/{model}/robot.urdf\n'
        f'      loop_closure_file: ../models/{model}/robot.yaml\n' + extra, encoding='utf-8')
    return str(tmp_path / 'params.yaml')


def load(model, **mechanism):
    params = {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
              **{f'mechanism.{k}': v for k, v in mechanism.items()}}
    return Mechanism.from_parameters(params, base_dir=os.path.join(MODELS, model))


def motion(mech, n=8):
    """n samples of a smooth motion of the actuators around the assembled pose."""
    q0 = np.array([mech.assembled_positions[j] for j in mech.active_index])
    t = np.linspace(0.0, 1.0, n)[:, None]
    k = np.arange(1, len(q0) + 1)[None, :]
    return q0 + 0.3 * np.sin(k * t), 0.7 * np.cos(t + k), 1.3 * np.sin(2 * t + k)


@pytest.mark.parametrize('model', sorted(ORACLE_MODEL))
def test_models_as_published_match_pinocchio(model, tmp_path):
    """Loaded from a params file (relative paths), without editing: torques within 1e-6
    relative of the Pinocchio model with the same loops, at poses where Pinocchio's own
    constraints hold."""
    from pinocchio_loops import LoopOracle
    models = tmp_path / 'models'
    models.mkdir()
    os.symlink(os.path.join(MODELS, model), models / model)
    params_dir = tmp_path / 'params'
    params_dir.mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        mech = Mechanism.from_params_file(write_params(params_dir, model))
    reference = ORACLE_MODEL[model]
    oracle = LoopOracle(model_text(reference, 'robot.urdf'), model_text(reference, 'robot.yaml'))
    assert mech.active_joints == oracle.active and mech.dof == len(mech.active_joints)
    solver = cog_id_ros.InverseDynamics(mech)
    q, qd, qdd = motion(mech)
    for k in range(len(q)):
        tau = np.array(solver.sample_torques(list(q[k]), list(qd[k]), list(qdd[k])))
        positions = solver.solve_positions_by_name(list(q[k]))
        closed = oracle.close(oracle.configuration(positions))
        assert np.linalg.norm(oracle.residual(closed)) < 1e-9
        for name, value in positions.items():     # ours: closed to closure_tolerance
            if oracle.model.existJointName(name):
                assert oracle.position(closed, name) == pytest.approx(value, abs=1e-7)
        expected, _, _ = oracle.torques(closed, qd[k], qdd[k])
        assert np.abs(expected).max() > 1e-3
        np.testing.assert_allclose(tau, expected, rtol=0.0, atol=1e-6 * np.abs(expected).max())


STEWART_LOCKED = ("closed_loop: [['rod_end', 'slider']]\ntype: ['3d']\nname_mot: ['motor']\n"
                  "joint_name: ['ball_1/z']\njoint_type: ['FIXED']\n")


@pytest.mark.parametrize('how', [{'locked_joints': ['ball_1/z']}, {'idle_spins': 'lock'}])
def test_a_rod_between_balls_with_its_spin_locked_matches_pinocchio(how):
    """The Stewart-like leg: its rod spins freely between the ball of three revolutes and
    the loop list's 3d pair. Locked (mechanism.locked_joints, or idle_spins: lock, which
    picks the same joint here: the rod's own axis), its torques are those of the Pinocchio
    model that locks that joint (a FIXED edit, at 0) to 1e-6, and the locked joint stays in
    every output at its initial position."""
    from pinocchio_loops import LoopOracle
    with pytest.raises(MechanismConfigError) as info:
        load('stewart_leg')
    assert 'ball_1/z' in str(info.value) and 'locked_joints' in str(info.value)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')       # idle_spins: lock says what it locked
        mech = load('stewart_leg', **how)
    assert 'ball_1/z' in mech.joints and mech.dof == 1
    oracle = LoopOracle(model_text('stewart_leg', 'robot.urdf'), STEWART_LOCKED)
    solver = cog_id_ros.InverseDynamics(mech)
    q, qd, qdd = motion(mech)
    for k in range(len(q)):
        tau = np.array(solver.sample_torques(list(q[k]), list(qd[k]), list(qdd[k])))
        positions = solver.solve_positions_by_name(list(q[k]))
        assert positions['ball_1/z'] == 0.0
        closed = oracle.close(oracle.configuration(positions))
        expected, _, _ = oracle.torques(closed, qd[k], qdd[k])
        np.testing.assert_allclose(tau, expected, rtol=0.0, atol=1e-6 * np.abs(expected).max())


def test_names_with_slashes_digits_and_other_letters_reach_every_output(tmp_path):
    """Names as written in the URDF: Mechanism.joints, the by-name positions, the keys of
    initial_positions in a params file (quoted where YAML needs it)."""
    five = load('five_bar')
    assert five.joints == ['motor/1', 'elbow/1', 'motor/2', 'elbow/2']
    assert five.links == ['1/proximal', '1/distal', '2/proximal', '2/distal']
    knee = load('knee')
    assert knee.joints == ['moteur_genou', 'genou/2', 'pivot_\u00e4', '3rd']
    assert '2nd_bar/lower' in knee.links and 'balancier_\u00e9' in knee.links
    solver = cog_id_ros.InverseDynamics(knee)
    assert set(solver.solve_positions_by_name([0.05])) == set(knee.joints)
    (tmp_path / 'models').mkdir()
    os.symlink(os.path.join(MODELS, 'five_bar'), tmp_path / 'models' / 'five_bar')
    (tmp_path / 'p').mkdir()
    path = write_params(tmp_path / 'p', 'five_bar', '      initial_positions:\n'
                        '        "motor/1": 0.05\n        elbow/1: 0.02\n')
    moved = Mechanism.from_params_file(path)
    assert moved.initial_positions[:2] == (0.05, 0.02)


def test_joint_edits_spherical_ujoint_fixed():
    """SPHERICAL: the joint is spherical (no coordinate, no JointState); UJOINT_XY: two
    revolute joints <joint>_X, <joint>_Y through a massless link; FIXED: welded at 0."""
    mech = load('rsur')
    assert mech.joints == ['crank_motor', 'rocker_pivot', 'cardan_X', 'cardan_Y']
    native = native_parameters({'mechanism.urdf_file': 'robot.urdf',
                                'mechanism.loop_closure_file': 'robot.yaml'},
                               os.path.join(MODELS, 'rsur'))
    assert native['joints.ball.type'] == 'spherical' and 'joints.ball.axis' not in native
    assert native['joints.cardan_X.axis'] == [1.0, 0.0, 0.0]
    assert native['joints.cardan_Y.axis'] == [0.0, 1.0, 0.0]
    assert native['joints.cardan_Y.parent'] == 'cardan_cross'
    assert native['links.cardan_cross.mass'] == 0.0
    assert 'counterweight' not in native['mechanism.links']      # welded to the crank
    assert native['links.crank.mass'] == pytest.approx(0.5 + 0.6)
    assert native['joints.closed_loop_1.type'] == 'fixed'
    assert load('rsur', initial_positions={'cardan_X': 0.0}).joints == mech.joints


def test_loop_file_mixes_with_loop_closures():
    """The knee's 6d loop from the file and the five-bar's tip closure from
    mechanism.loop_closures, in one URDF (two mechanisms on one base): each mechanism's
    torques as when loaded alone."""
    five = model_text('five_bar', 'robot.urdf').replace('</robot>', '')
    knee = model_text('knee', 'robot.urdf').split('\n', 3)[3].replace('"cuisse"', '"base_link"')
    params = {'robot_description': five + knee, 'mechanism.loop_closure_file': os.path.join(
                  MODELS, 'knee', 'robot.yaml'),
              'mechanism.loop_closures': ['tip'],
              'mechanism.active_joints': ['motor/1', 'motor/2', 'moteur_genou'],
              'loop_closures.tip.type': 'spherical', 'loop_closures.tip.parent': '1/tip',
              'loop_closures.tip.child': '2/tip'}
    both = Mechanism.from_parameters(params)
    assert both.dof == 3
    alone = [load('five_bar'), load('knee')]
    q = [list(motion(m, 3)[0][2]) for m in alone]
    tau = cog_id_ros.InverseDynamics(both).sample_torques(q[0] + q[1], [0.2] * 3, [0.1] * 3)
    expected = [x for m, qa in zip(alone, q) for x in cog_id_ros.InverseDynamics(m)
                .sample_torques(qa, [0.2] * len(qa), [0.1] * len(qa))]
    np.testing.assert_allclose(tau, expected, rtol=1e-9, atol=1e-12)


def test_active_joints_given_win_over_name_mot():
    mech = load('five_bar', active_joints=['elbow/1', 'motor/2'])
    assert mech.active_joints == ['elbow/1', 'motor/2']


# --- errors ---------------------------------------------------------------------------------

def error_with(tmp_path, loops, model='five_bar', **mechanism):
    (tmp_path / 'robot.yaml').write_text(loops, encoding='utf-8')
    params = {'mechanism.urdf_file': os.path.join(MODELS, model, 'robot.urdf'),
              'mechanism.loop_closure_file': 'robot.yaml',
              **{f'mechanism.{k}': v for k, v in mechanism.items()}}
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_parameters(params, base_dir=str(tmp_path))
    return info.value


FIVE = "name_mot: ['motor/1', 'motor/2']\n"


@pytest.mark.parametrize('loops, words', [
    ("closed_loop: [['1/tip', '2/tipp']]\ntype: ['3d']\n" + FIVE,
     ['closed_loop entry 1', "'2/tipp' is neither a link nor a joint of the URDF"]),
    ("closed_loop: [['1/tip', '1/distal']]\ntype: ['3d']\n" + FIVE,
     ['closed_loop entry 1', "['1/tip', '1/distal']", 'already rigidly connected']),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['4d']\n" + FIVE,
     ['type entry 1', "'6d'", "'4d'"]),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d', '3d']\n" + FIVE,
     ['type: has 2 entries, closed_loop has 1']),
    ("closed_loop: [['1/tip']]\ntype: ['3d']\n" + FIVE,
     ['closed_loop entry 1', 'a pair of frame names']),
    # one pair without its list (adversarial check: the message was about type)
    ("closed_loop: ['1/tip', '2/tip']\ntype: ['3d']\n" + FIVE,
     ['closed_loop: must be a list of pairs', "write [['1/tip', '2/tip']]"]),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\nname_mot: ['motor/1', 'motor/3']\n",
     ['name_mot entry 2', "'motor/3' is neither a joint of the URDF"]),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n" + FIVE
     + "joint_name: ['elbow/3']\njoint_type: ['SPHERICAL']\n",
     ['joint_name entry 1', "'elbow/3' is not a joint of the URDF"]),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n" + FIVE
     + "joint_name: ['elbow/1']\njoint_type: ['UJOINT_XX']\n",
     ['joint_type entry 1', 'UJOINT_<A><B>', "'UJOINT_XX'"]),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n" + FIVE
     + "joint_name: ['elbow/1', 'elbow/2']\njoint_type: ['FIXED']\n",
     ['joint_type: has 1 entries, joint_name has 2']),
    ("closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n" + FIVE
     + "joint_name: ['motor/1']\njoint_type: ['spherical']\n",
     ['name_mot entry 1', "'motor/1' is a spherical joint", 'passive']),
    ("closed_loop: [['1/tip', '2/tip']]\ntyp: ['3d']\n" + FIVE,
     ['typ: unknown key', 'closed_loop, type, name_mot, joint_name, joint_type']),
    ('closed_loop: [1/tip, 2/tip\n', ['is not valid YAML']),
    ('- closed_loop\n', ['must hold a mapping']),
])
def test_errors_name_the_file_the_key_and_the_entry(tmp_path, loops, words):
    err = error_with(tmp_path, loops)
    assert err.parameter == 'mechanism.loop_closure_file'
    assert str(tmp_path / 'robot.yaml') in str(err)
    for word in words:
        assert word in str(err)


def test_a_ujoint_edit_names_the_joints_it_made(tmp_path):
    loops = ("closed_loop: [['weld_a', 'coupler_end']]\ntype: ['6d']\nname_mot: ['cardan']\n"
             "joint_name: ['ball', 'cardan']\njoint_type: ['SPHERICAL', 'UJOINT_XY']\n")
    err = error_with(tmp_path, loops, 'rsur')
    assert 'name_mot entry 1' in str(err) and 'cardan_X and cardan_Y' in str(err)
    with pytest.raises(MechanismConfigError) as info:
        load('rsur', initial_positions={'cardan': 0.1})
    assert info.value.parameter == 'mechanism.initial_positions.cardan'
    assert 'cardan_X and cardan_Y' in str(info.value)
    with pytest.raises(MechanismConfigError) as info:
        load('rsur', initial_positions={'ball': 0.1})
    assert 'spherical joint' in str(info.value) and 'no position' in str(info.value)


def test_closure_names_from_the_file_must_be_free(tmp_path):
    loops = "closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n" + FIVE
    (tmp_path / 'robot.yaml').write_text(loops, encoding='utf-8')
    params = {'mechanism.urdf_file': os.path.join(MODELS, 'five_bar', 'robot.urdf'),
              'mechanism.loop_closure_file': str(tmp_path / 'robot.yaml'),
              'mechanism.loop_closures': ['closed_loop_1'],
              'loop_closures.closed_loop_1.type': 'spherical',
              'loop_closures.closed_loop_1.parent': '1/tip',
              'loop_closures.closed_loop_1.child': '2/tip'}
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_parameters(params)
    assert info.value.parameter == 'mechanism.loop_closure_file'
    assert "'closed_loop_1'" in str(info.value) and 'closed_loop entry 1' in str(info.value)


def test_the_file_must_exist_and_needs_a_urdf(tmp_path):
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_parameters({'mechanism.urdf_file': 'robot.urdf',
                                   'mechanism.loop_closure_file': 'missing.yaml'},
                                  base_dir=os.path.join(MODELS, 'five_bar'))
    assert info.value.parameter == 'mechanism.loop_closure_file'
    assert 'missing.yaml' in str(info.value) and 'cannot read' in str(info.value)
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_parameters({'mechanism.loop_closure_file': 'robot.yaml'})
    assert info.value.parameter == 'mechanism.loop_closure_file'
    assert 'robot_description or mechanism.urdf_file' in str(info.value)


def test_without_name_mot_or_active_joints_the_message_says_where_to_give_them(tmp_path):
    err = error_with(tmp_path, "closed_loop: [['1/tip', '2/tip']]\ntype: ['3d']\n")
    assert err.parameter == 'mechanism.active_joints' and 'name_mot' in str(err)


# --- refusals of the core, in the terms of the URDF form --------------------------------------

KNEE_BALL = ("closed_loop: [['fermeture1_A', 'fermeture1_B']]\ntype: ['3d']\n"
             "name_mot: ['moteur_genou']\n")


def test_refusals_tell_a_urdf_user_what_to_write_and_a_native_user_theirs(tmp_path):
    """The Stewart-like leg with its ball of three revolutes made one spherical joint (the
    file's edits): the rod spins between two spherical joints, which have no coordinate to
    lock. A URDF user is told of universal loop closures and UJOINT edits (a URDF joint
    cannot be universal), a user of the native schema of `type: universal`."""
    loops = ("closed_loop: [['rod_end', 'slider']]\ntype: ['3d']\nname_mot: ['motor']\n"
             "joint_name: ['ball_1/x', 'ball_1/y', 'ball_1/z']\n"
             "joint_type: ['SPHERICAL', 'FIXED', 'FIXED']\n")
    err = error_with(tmp_path, loops, 'stewart_leg')
    assert 'loop_closures.<name>.type: universal' in str(err) and 'UJOINT_<A><B>' in str(err)
    assert '`type: universal`' not in str(err)
    assert err.parameter == 'mechanism.urdf_file' and "joint 'ball_1/x' (line" in str(err)
    native = native_parameters({'mechanism.urdf_file': 'robot.urdf',
                                'mechanism.loop_closure_file': str(tmp_path / 'robot.yaml')},
                               os.path.join(MODELS, 'stewart_leg'))
    with pytest.raises(MechanismConfigError) as info:
        Mechanism.from_parameters(native)
    assert info.value.parameter == 'joints.ball_1/x.type'
    assert '`type: universal`' in str(info.value) and 'UJOINT' not in str(info.value)


def test_an_undriven_freedom_is_said_without_advice_of_the_other_form(tmp_path):
    """The knee closed by a ball ('3d') instead of a weld: a freedom its one motor does not
    drive, said in words that fit both forms."""
    err = error_with(tmp_path, KNEE_BALL, 'knee')
    assert err.parameter == 'mechanism.active_joints' and 'genou/2, 3rd' in str(err)
    assert '`type:' not in str(err) and 'parent_xyz' not in str(err)


def test_a_rigid_urdf_names_the_urdf_and_its_origins_and_axes(tmp_path):
    loops = ("closed_loop: [['weld_a', 'coupler_end']]\ntype: ['6d']\nname_mot: ['crank_motor']\n"
             "joint_name: ['ball', 'cardan', 'cw_hinge']\n"
             "joint_type: ['SPHERICAL', 'FIXED', 'FIXED']\n")
    err = error_with(tmp_path, loops, 'rsur')
    assert err.parameter == 'mechanism.urdf_file' and 'rigid' in str(err)
    assert "URDF joint's <origin> and <axis>" in str(err)
    assert 'check the geometry (parent_xyz' not in str(err)


def test_loops_that_cannot_close_and_positions_out_of_bounds_name_the_urdf_terms(tmp_path):
    loops = ("closed_loop: [['fermeture1_A', 'manivelle']]\ntype: ['6d']\n"
             "name_mot: ['moteur_genou']\n")
    err = error_with(tmp_path, loops, 'knee')
    assert err.parameter == 'mechanism.initial_positions' and '<origin>' in str(err)
    with pytest.raises(MechanismConfigError) as info:
        load('five_bar', initial_positions={'elbow/2': 1e9})
    assert info.value.parameter == 'mechanism.initial_positions.elbow/2'
    assert 'index' not in str(info.value)
