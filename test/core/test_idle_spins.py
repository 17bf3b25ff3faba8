"""Locked joints, idle spins and dependent actuators (issue 23, items 2 and 4).

The Stewart-like model is the delta robot with a ball at both ends of its six rods
(test/spin_models.py), in the native schema (revolute joints only, and with native
spherical joints) and as a URDF with loop closures. Torques are checked against the
Pinocchio oracle (test/pinocchio_reference.py) of the same loops, where a locked joint is
held by driving it at its initial position (an actuator that does not move is a lock):
to 1e-6 relative with ``locked_joints`` naming the joint the oracle holds, and with
``idle_spins: lock`` within the spread that the two valid lock choices (elbow or platform
end of each rod) give.
"""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
TEST = os.path.dirname(HERE)
if TEST not in sys.path:
    sys.path.insert(0, TEST)

from mechanisms import double_pendulum, four_bar, from_yaml, with_changes  # noqa: E402
from spin_models import (  # noqa: E402
    ELBOW_LOCKS,
    PLATFORM_LOCKS,
    RODS,
    delta_3rss,
    delta_3rss_spherical,
    delta_3rss_urdf,
    write_params,
)
from trajectories import sample  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.core.model.assembly import AssemblyWarning  # noqa: E402

pin = pytest.importorskip('pinocchio')
from pinocchio_reference import Oracle  # noqa: E402

ARMS = ['l0_arm_joint', 'l1_arm_joint', 'l2_arm_joint']
N = 24
RTOL = 1e-6


def load(params, **changes):
    return cog_id_ros.Mechanism.from_parameters(
        with_changes(params, **{k.replace('.', '__'): v for k, v in changes.items()}))


def locked_lock(params):
    """Load with idle_spins: lock, which reports each lock as an AssemblyWarning."""
    with pytest.warns(AssemblyWarning, match='idle_spins: lock locked joint'):
        return load(params, **{'mechanism.idle_spins': 'lock'})


@pytest.fixture(scope='module')
def motion():
    _, q, qd, qdd = sample('delta_3rus.yaml', N)
    return q, qd, qdd


@pytest.fixture(scope='module')
def oracle_torques(motion, tmp_path_factory):
    """Per lock set (a tuple of joint names): the oracle's torques of the three arms."""
    path = write_params(delta_3rss(), tmp_path_factory.mktemp('spins') / 'delta_3rss.yaml')
    q, qd, qdd = motion
    cache = {}

    def get(locks):
        if locks not in cache:
            orc = Oracle(path, active=ARMS + list(locks))
            held = orc.initial_positions[[orc.joints.index(j) for j in locks]]
            still = np.zeros((len(q), len(locks)))
            *_, tau = orc.follow(np.hstack([q, np.tile(held, (len(q), 1))]),
                                 np.hstack([qd, still]), np.hstack([qdd, still]))
            cache[locks] = tau[:, :len(ARMS)]
        return cache[locks]
    return get


def torques(mech, motion, backend='reference'):
    return cog_id_ros.InverseDynamics(mech, backend=backend).torques(*motion)


def relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


# --- idle spins: refused by default ---------------------------------------------------------

def test_rods_between_two_balls_are_refused_naming_links_joints_and_the_parameter():
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        load(delta_3rss())
    text = str(info.value)
    assert info.value.parameter == 'mechanism.locked_joints', text
    assert text.startswith('mechanism.locked_joints: 6 link(s) spin freely'), text
    for rod in RODS:
        assert f"link '{rod}'" in text and f"'{rod}_u3' (1)" in text, text
        assert f"'{rod}_s3' (1)" in text, text
    assert f"`locked_joints: [{', '.join(ELBOW_LOCKS)}]`" in text, text
    assert '`idle_spins: lock`' in text and 'under `mechanism:`' in text, text
    assert 'universal' not in text, text       # nothing a URDF user could not write


def test_the_urdf_form_is_refused_with_what_to_write_in_the_parameters():
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        cog_id_ros.Mechanism.from_parameters(delta_3rss_urdf())
    text = str(info.value)
    assert info.value.parameter == 'mechanism.locked_joints', text
    assert f"`locked_joints: [{', '.join(ELBOW_LOCKS)}]`" in text, text
    assert 'universal' not in text, text


# --- idle spins: locked ------------------------------------------------------------------------

def test_lock_takes_the_largest_share_first_in_joint_order_and_says_so():
    mech = locked_lock(delta_3rss())
    assert mech.locked_joints == ELBOW_LOCKS          # u3 and s3 tie at 1: u3 comes first
    assert mech.dof == 3 and not mech.is_redundant
    assert len(mech.assembly_warnings) == len(RODS)
    for rod, text in zip(RODS, mech.assembly_warnings):
        assert f"link '{rod}' spins freely" in text and f"locked joint '{rod}_u3' at 0" in text
        assert f"'{rod}_s3' (1)" in text and 'off that axis' not in text, text
    # the platform balls are still solved as spherical joints; the elbows are not
    assert len(mech.spherical_chains) == len(RODS)


@pytest.mark.parametrize('locks', [ELBOW_LOCKS, PLATFORM_LOCKS], ids=['elbow', 'platform'])
def test_locked_joints_give_the_oracles_torques(locks, motion, oracle_torques):
    mech = load(delta_3rss(), **{'mechanism.locked_joints': locks})
    assert mech.assembly_warnings == [] and mech.locked_joints == locks
    expected = oracle_torques(tuple(locks))
    assert relative(torques(mech, motion), expected) < RTOL
    serial = cog_id_ros.InverseDynamics(mech, backend='python')
    one_by_one = np.array([serial.torques(*(x[k] for x in motion)) for k in range(N)])
    assert relative(one_by_one, expected) < RTOL


def test_idle_spins_lock_is_within_the_spread_of_valid_lock_choices(motion, oracle_torques):
    chosen = torques(locked_lock(delta_3rss()), motion)
    elbow, platform = oracle_torques(tuple(ELBOW_LOCKS)), oracle_torques(tuple(PLATFORM_LOCKS))
    spread = np.abs(elbow - platform).max()
    assert 0.0 < spread < 1e-6 * np.abs(elbow).max()   # the rods' axial inertia: tiny
    for reference in (elbow, platform):
        assert np.abs(chosen - reference).max() <= spread + RTOL * np.abs(reference).max()


def test_a_locked_joint_stays_at_its_initial_position_in_every_output(motion):
    p = delta_3rss()
    k = p['mechanism.joints'].index('r1b_s3')
    p['mechanism.initial_positions'][k] = 0.0    # s3 held a little off its closed value
    locks = ELBOW_LOCKS[:3] + ['r1b_s3'] + ELBOW_LOCKS[4:]
    mech = load(p, **{'mechanism.locked_joints': locks})
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    q, qd, qdd = motion
    positions = solver.solve_positions(q)
    for name in locks:
        j = mech.joints.index(name)
        assert np.all(positions[:, j] == mech.initial_positions[j]), name
    assert mech.initial_positions[k] == 0.0
    solver.torques(q[5], qd[5], qdd[5])
    at, rates = solver.last_pose(qd[5])
    for name in locks:
        j = mech.joints.index(name)
        assert at[j] == mech.initial_positions[j] and rates[j] == 0.0, name
    evaluation = solver.evaluate(q, qd, qdd)
    assert np.all(evaluation.positions[:, k] == 0.0)


@pytest.mark.parametrize('make', [delta_3rss_spherical, delta_3rss_urdf], ids=['native', 'urdf'])
def test_native_balls_and_the_urdf_form_lock_and_match_the_oracle(make, motion, oracle_torques):
    mech = locked_lock(make())
    assert mech.locked_joints == ELBOW_LOCKS     # the native balls have nothing to lock
    expected = oracle_torques(tuple(ELBOW_LOCKS))
    assert relative(torques(mech, motion), expected) < RTOL
    named = cog_id_ros.Mechanism.from_parameters(
        dict(make(), **{'mechanism.locked_joints': ELBOW_LOCKS}))
    assert relative(torques(named, motion), expected) < RTOL


def test_a_centre_of_mass_off_the_spin_axis_is_warned_about():
    p = with_changes(delta_3rss(), links__r1a__com=[0.01, 0.0, 0.35])
    with pytest.warns(AssemblyWarning) as caught:
        mech = load(p, **{'mechanism.idle_spins': 'lock'})
    off = [text for text in mech.assembly_warnings if 'off that axis' in text]
    assert len(off) == 1 and "link 'r1a'" in off[0] and '0.01 m off' in off[0], off
    assert 'changes the torques' in off[0] and 'mechanism.locked_joints' in off[0]
    assert any('off that axis' in str(w.message) for w in caught)


def test_a_forgotten_actuator_is_refused_even_with_idle_spins_lock():
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        load(delta_3rss(), **{'mechanism.idle_spins': 'lock',
                              'mechanism.active_joints': ARMS[:2]})
    text = str(info.value)
    assert info.value.parameter == 'mechanism.active_joints', text
    assert '2 active joint(s) for 9 degrees of freedom' in text, text
    assert 'l2_arm_joint' in text and 'can still move' in text, text
    assert 'spin idly' in text, text


# --- locked joints outside spins, and the errors -----------------------------------------------

def test_a_locked_joint_turns_a_five_bar_into_a_four_bar(tmp_path):
    p = from_yaml(os.path.join(os.path.dirname(TEST), 'config', 'five_bar.yaml'))
    p = with_changes(p, mechanism__active_joints=['j1'], mechanism__locked_joints=['j5'])
    mech = load(p)
    assert mech.dof == 1 and mech.joints == p['mechanism.joints']
    orc = Oracle(write_params(p, tmp_path / 'five.yaml'), active=['j1', 'j5'])
    q = np.linspace(1.8, 2.2, 9)[:, None]
    held = np.full_like(q, orc.initial_positions[orc.joints.index('j5')])
    *_, expected = orc.follow(np.hstack([q, held]), np.hstack([q * 0 + 0.7, q * 0]),
                              np.hstack([q * 0 - 1.3, q * 0]))
    got = torques(mech, (q, q * 0 + 0.7, q * 0 - 1.3))
    assert relative(got, expected[:, :1]) < 1e-9


@pytest.mark.parametrize('changes,parameter,fragment', [
    ({'mechanism.locked_joints': ['nope']}, 'mechanism.locked_joints',
     "'nope' is not a revolute or prismatic joint"),
    ({'mechanism.locked_joints': ['joint3']}, 'mechanism.locked_joints',
     "'joint3' is in mechanism.active_joints"),
    ({'mechanism.locked_joints': ['joint2', 'joint2']}, 'mechanism.locked_joints',
     "duplicate name 'joint2'"),
    ({'mechanism.locked_joints': 'joint2'}, 'mechanism.locked_joints', 'must be a list'),
    ({'mechanism.idle_spins': 'ignore'}, 'mechanism.idle_spins',
     "must be 'refuse' or 'lock', got 'ignore'"),
    ({'mechanism.locked_joints': ['joint2']}, 'mechanism.joints', 'locked joints (joint2'),
])
def test_locked_joint_errors_name_the_parameter(changes, parameter, fragment):
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        load(four_bar(init=[1.2, -1.2, 1.2, 1.2]), **changes)
    assert info.value.parameter == parameter, str(info.value)
    assert fragment in str(info.value)


def test_a_spherical_joint_cannot_be_locked():
    p = delta_3rss_spherical()
    with pytest.raises(cog_id_ros.MechanismConfigError) as info:
        load(p, **{'mechanism.locked_joints': ['r0b_s']})
    assert info.value.parameter == 'mechanism.locked_joints'
    assert "'r0b_s' is a spherical joint: only revolute and prismatic" in str(info.value)


# --- dependent actuators --------------------------------------------------------------------

def test_dependent_actuators_are_named_and_treated_as_redundant():
    p = four_bar(active=('joint1', 'joint3'), init=[1.2, -1.2, 1.2, 1.2])
    with pytest.warns(AssemblyWarning, match="'joint1', 'joint3' determine each other"):
        mech = load(p)
    assert mech.is_redundant
    text, = mech.assembly_warnings
    assert 'treated as redundantly actuated' in text and 'mechanism.torque_weights' in text


def test_only_the_dependent_actuators_are_named():
    """A double pendulum driven at both joints, plus a four-bar driven twice: only the
    four-bar's two actuators depend on each other."""
    p = four_bar(active=('joint1', 'joint3'), init=[1.2, -1.2, 1.2, 1.2])
    pendulum = double_pendulum()
    for key, value in pendulum.items():
        if key.startswith(('links.', 'joints.')):
            p[key] = value
    p['mechanism.links'] += pendulum['mechanism.links']
    p['mechanism.joints'] += pendulum['mechanism.joints']
    p['mechanism.active_joints'] = ['joint1', 'shoulder', 'joint3', 'elbow']
    p['mechanism.initial_positions'] = [1.2, -1.2, 1.2, 1.2] + [0.3, 0.4]
    with pytest.warns(AssemblyWarning) as caught:
        mech = load(p)
    text, = mech.assembly_warnings
    assert "the actuators do not all move independently: 'joint1', 'joint3' determine" in text
    assert 'shoulder' not in text and 'elbow' not in text
    assert len(caught) == 1


def test_torque_weights_say_the_redundancy_is_meant():
    p = four_bar(active=('joint1', 'joint3'), init=[1.2, -1.2, 1.2, 1.2])
    mech = load(p, **{'mechanism.torque_weights': [1.0, 1.0]})
    assert mech.is_redundant and mech.assembly_warnings == []


def test_inspect_shows_the_locked_joints():
    from cog_id_ros.offline.inspect_pose import joint_rows
    from cog_id_ros.offline.inspect_structure import format_actuation
    mech = load(delta_3rss(), **{'mechanism.locked_joints': ELBOW_LOCKS})
    text = '\n'.join(format_actuation(mech))
    assert 'closure rank 36, 6 of it the locked joints' in text, text
    assert f"locked joints (held at their initial positions): {', '.join(ELBOW_LOCKS)}" in text
    roles = {row[0]: row[2] for row in joint_rows(mech)}
    assert [name for name, role in roles.items() if role == 'locked'] == ELBOW_LOCKS
