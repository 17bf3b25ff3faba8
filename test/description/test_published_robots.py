"""Every robot of the published example-parallel-robots collection, as its authors wrote it
(test/models/example_parallel_robots: URDF and loop file byte for byte, BSD-3-Clause), with
a fixed base: each loads, or is refused for the reason its structure gives; the torques of
each that loads (untouched, with ``idle_spins: lock``, or with the joints the refusal
names in ``locked_joints``) are Pinocchio's, from Pinocchio's own URDF parser with the same
loops, couplings and locked joints (test/pinocchio_loops.py), to 1e-6 relative.
"""
import os
import re
import subprocess
import sys
import warnings

from conftest import BIN, REPO
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros import MechanismConfigError
from cog_id_ros.core.model.assembly import AssemblyWarning

COLLECTION = os.path.join(REPO, 'test', 'models', 'example_parallel_robots')
#: robots that load untouched
LOAD = ['5bar_linkage_iso3d', '5bar_linkage_iso6d', 'battobot_6d', 'digit_like_2legs',
        'digit_like_2legs_6D', 'digit_like_2legs_old']
#: robots with rods (or a body between coaxial joints) that spin idly: (robot, spins)
SPIN = [('5bar_linkage', 1), ('cassie_like', 2), ('digit_like', 3), ('old/digit_like_2legs', 6),
        ('robot_delta', 3), ('talos_like', 1), ('true_talos_2_legs', 2), ('wl16_like', 6)]
#: robots refused for what their files say: (robot, parameter, what the message says)
REFUSED = [
    ('disney_like', 'mechanism.active_joints', 'free_hip_x, ankle_universal_2_rev0'),
    ('disney_robot', 'mechanism.loop_closure_file',
     "'left_spherical_free_foot' is not a joint of the URDF"),
    ('kangaroo_like', 'mechanism.initial_positions', 'not even with every joint free'),
    ('kangaroo_like_2legs', 'mechanism.initial_positions', 'not even with every joint free'),
    ('kangaroo_like_2leg', 'mechanism.active_joints', 'missing'),
]
RTOL = 1e-6
#: the robots whose loading takes tens of seconds (the TALOS humanoid's 44 motors, the
#: kangaroo's refusal after a search with every joint free): their cases are in
#: test_published_robots_large.py, so that the suite's two workers share the load
LARGE = ('true_talos_2_legs', 'old/digit_like_2legs', 'kangaroo_like', 'kangaroo_like_2legs')
SMALL_SPIN = [case for case in SPIN if case[0] not in LARGE]
SMALL_REFUSED = [case for case in REFUSED if case[0] not in LARGE]
_loaded = {}


def files(robot):
    folder = os.path.join(COLLECTION, robot)
    urdf = next(name for name in sorted(os.listdir(folder)) if name.endswith('.urdf'))
    loops = 'robot.yaml' if os.path.exists(os.path.join(folder, 'robot.yaml')) else None
    return folder, urdf, loops


def load(robot, **mechanism):
    """The robot from its published files (and ``mechanism.*`` given), once per test run."""
    key = (robot, tuple(sorted((k, str(v)) for k, v in mechanism.items())))
    if key not in _loaded:
        folder, urdf, loops = files(robot)
        params = {'mechanism.urdf_file': urdf,
                  **{f'mechanism.{k}': v for k, v in mechanism.items()}}
        if loops:
            params['mechanism.loop_closure_file'] = loops
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', AssemblyWarning)
            try:
                _loaded[key] = cog_id_ros.Mechanism.from_parameters(params, base_dir=folder)
            except MechanismConfigError as exc:
                _loaded[key] = exc
    if isinstance(_loaded[key], Exception):
        raise _loaded[key]
    return _loaded[key]


def read(folder, name):
    with open(os.path.join(folder, name), encoding='utf-8') as stream:
        return stream.read()


def oracle(robot, mech):
    from pinocchio_loops import LoopOracle
    folder, urdf, loops = files(robot)
    return LoopOracle(read(folder, urdf), read(folder, loops), held=mech.locked_joints)


def motion(mech, k, n=4):
    """Sample k of n of a small smooth motion of the primary actuators about the assembled
    pose (the others, dependent on them here, still), inside the position limits."""
    q0 = np.array([mech.assembled_positions[j] for j in mech.active_index])
    t = k / n
    amplitude, velocity, acceleration = (np.zeros(len(q0)) for _ in range(3))
    coupled = {name for pair in mech.couplings for name in pair[:2]}
    for a in mech.primary:
        if mech.active_joints[a] in coupled:
            continue
        lo, hi = mech.active_position_limits[a]
        side = -1.0 if q0[a] + 0.01 > hi else 1.0 if q0[a] - 0.01 < lo else np.sin(2.0 + a)
        amplitude[a] = 0.01 * side * (1.0 - np.cos(3.0 * t + a))
        velocity[a] = 0.2 * np.cos(1.0 + a + t)
        acceleration[a] = 0.5 * np.sin(a - t)
    return q0 + amplitude, velocity, acceleration


def spin_locks(robot):
    """The joints the refusal says to put in locked_joints."""
    with pytest.raises(MechanismConfigError) as info:
        load(robot)
    found = re.search(r'`locked_joints: \[([^\]]*)\]`', str(info.value))
    assert found, str(info.value)
    return found.group(1).split(', ')


# --- loads, or is refused for its reason -------------------------------------------------------

@pytest.mark.parametrize('robot', LOAD)
def test_robots_that_load_as_published(robot):
    mech = load(robot)
    assert not mech.locked_joints and mech.dof == len(mech.active_joints)


def check_refused_naming_locked_joints(robot, spins):
    """Refused for its idle spins, the message naming locked_joints and idle_spins: lock."""
    with pytest.raises(MechanismConfigError) as info:
        load(robot)
    text = str(info.value)
    assert info.value.parameter == 'mechanism.locked_joints', text
    assert f'({spins} spin(s):' in text and 'add active' not in text, text
    assert '`idle_spins: lock`' in text, text
    assert len(spin_locks(robot)) == spins


def check_loads_with_locks(robot, spins):
    """Loads with idle_spins: lock, and with the joints the refusal names locked."""
    locked = load(robot, idle_spins='lock')
    assert len(locked.locked_joints) == spins and len(locked.idle_spin_sets) == spins
    named = load(robot, locked_joints=spin_locks(robot))
    assert named.locked_joints == spin_locks(robot) and named.dof == locked.dof


def check_refused(robot, parameter, fragment):
    """Refused (with idle_spins: lock) naming ``parameter``, the message holding ``fragment``."""
    with pytest.raises(MechanismConfigError) as info:
        load(robot, idle_spins='lock')
    assert info.value.parameter == parameter, str(info.value)
    assert fragment in str(info.value), str(info.value)


@pytest.mark.parametrize('robot,spins', SMALL_SPIN)
def test_spinning_rods_are_refused_naming_locked_joints(robot, spins):
    check_refused_naming_locked_joints(robot, spins)


@pytest.mark.parametrize('robot,spins', SMALL_SPIN)
def test_spinning_robots_load_with_idle_spins_lock_or_the_named_joints(robot, spins):
    check_loads_with_locks(robot, spins)


@pytest.mark.parametrize('robot,parameter,fragment', SMALL_REFUSED)
def test_robots_refused_for_what_their_files_say(robot, parameter, fragment):
    check_refused(robot, parameter, fragment)


def test_the_disney_legs_free_motion_is_pinocchios_too():
    """disney_like is refused for a motion its six motors leave free (besides its two rods):
    Pinocchio's constraints, at the pose the assembly found, leave it free too."""
    with pytest.raises(MechanismConfigError) as info:
        load('disney_like')
    assert 'can still move' in str(info.value)
    from pinocchio_loops import LoopOracle

    from cog_id_ros.core.model import assembly
    folder, urdf, loops = files('disney_like')
    probe = {}
    original = assembly.assemble

    def keep(mech, start=None, settled=False):
        out = original(mech, start, settled)
        probe.update(mech=mech, q=out[0])
        return out
    assembly.assemble = keep
    try:
        with pytest.raises(MechanismConfigError), warnings.catch_warnings():
            warnings.simplefilter('ignore', AssemblyWarning)
            cog_id_ros.Mechanism.from_parameters(
                {'mechanism.urdf_file': urdf, 'mechanism.loop_closure_file': loops,
                 'mechanism.idle_spins': 'lock'}, base_dir=folder)
    finally:
        assembly.assemble = original
    mech = probe['mech']
    orc = LoopOracle(read(folder, urdf), read(folder, loops))
    positions = dict(zip(mech.joints, probe['q']))
    closed = orc.close(orc.configuration(positions))
    jac = orc.velocity_jacobian(closed)
    held = np.eye(orc.model.nv)[orc.ia]
    rank = np.linalg.matrix_rank(np.vstack([jac, held]), tol=1e-9 * np.abs(jac).max())
    free = orc.model.nv - rank
    assert free == 3, free           # the two rods' spins and the motion named


# --- the torques, against Pinocchio ------------------------------------------------------------

def check_torques(mech, orc, samples=3):
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    for k in range(samples):
        q, qd, qdd = motion(mech, k)
        tau = np.array(solver.torques(q, qd, qdd))
        closed = orc.close(orc.configuration(solver.solve_positions_by_name(list(q))))
        expected, _, _ = orc.torques(closed, qd, qdd)
        assert np.abs(expected).max() > 0.0
        np.testing.assert_allclose(tau, expected, rtol=0.0,
                                   atol=RTOL * np.abs(expected).max())


@pytest.mark.parametrize('robot', LOAD + [robot for robot, _ in SMALL_SPIN])
def test_torques_match_pinocchio(robot):
    pytest.importorskip('pinocchio')
    mech = load(robot) if robot in LOAD else load(robot, idle_spins='lock')
    check_torques(mech, oracle(robot, mech))


def widened_talos(tmp_path):
    """(Mechanism, URDF text) of TALOS with its two shin motors' limits widened (a copy)."""
    folder, urdf, loops = files('true_talos_2_legs')
    text = read(folder, urdf)
    for side in ('left', 'right'):
        start = text.index(f'<joint name="leg_{side}_shin_joint"')
        end = text.index('</joint>', start)
        text = text[:start] + text[start:end].replace('lower="0"', 'lower="-2.618"') \
            + text[end:]
    (tmp_path / urdf).write_text(text, encoding='utf-8')
    (tmp_path / loops).write_text(read(folder, loops), encoding='utf-8')
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        mech = cog_id_ros.Mechanism.from_parameters(
            {'mechanism.urdf_file': urdf, 'mechanism.loop_closure_file': loops,
             'mechanism.idle_spins': 'lock'}, base_dir=str(tmp_path))
    return mech, text


def test_the_named_locks_give_pinocchios_torques_with_those_locks():
    pytest.importorskip('pinocchio')
    mech = load('digit_like', locked_joints=spin_locks('digit_like'))
    orc = oracle('digit_like', mech)
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    q, qd, qdd = motion(mech, 1)
    closed = orc.close(orc.configuration(solver.solve_positions_by_name(list(q))))
    expected, _, _ = orc.torques(closed, qd, qdd)
    np.testing.assert_allclose(solver.torques(q, qd, qdd), expected, rtol=0.0,
                               atol=RTOL * np.abs(expected).max())


# --- what the assembly and the loader give ---------------------------------------------------

@pytest.mark.parametrize('robot', ['wl16_like', 'talos_like', 'cassie_like', 'battobot_6d'])
def test_every_actuator_moves_from_the_assembled_pose(robot):
    """0.05 rad (a prismatic motor: 5 % of the mechanism's length scale, the solver's) either
    way, the others held, by the per-sample solver: a pose at the edge of the workspace is
    the assembler's fault."""
    from cog_id_ros.core.closure.continuation import length_scale
    mech = load(robot) if robot in LOAD else load(robot, idle_spins='lock')
    q0 = np.array([mech.assembled_positions[j] for j in mech.active_index])
    for a, j in enumerate(mech.active_index):
        reach = 0.05 if mech.joint_specs[j].kind.unit == 'rad' else 0.05 * length_scale(mech)
        for direction in (1.0, -1.0):
            solver = cog_id_ros.InverseDynamics(mech, backend='reference')
            for part in range(1, 6):
                q = q0.copy()
                q[a] += direction * reach * part / 5
                solver.solve_positions(q)


def test_a_five_bar_with_its_end_effector_written_twice_loads_with_one_lock():
    """5bar_linkage: the end effector written once on each arm, welded by the loop file,
    turns about the common axis of its two revolute joints."""
    mech = load('5bar_linkage', idle_spins='lock')
    assert mech.locked_joints == ['closedloop1_A'] and mech.dof == 2     # a tie: joint order
    spin, = mech.idle_spin_sets
    assert spin['links'] == ['sphere', 'sphere_2'] and spin['others'] == ['closedloop1_B']


def test_a_link_of_absurd_mass_is_named():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always', AssemblyWarning)
        mech = cog_id_ros.Mechanism.from_parameters(
            {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
             'mechanism.idle_spins': 'lock'}, base_dir=os.path.join(COLLECTION, '5bar_linkage'))
    heavy = [text for text in mech.assembly_warnings if 'weighs' in text]
    assert len(heavy) == 2 and heavy[0].startswith("link 'sphere' weighs 6.545e+05 kg, 2.19e+04 "
                                                   'times the median link'), heavy
    assert sum('weighs' in str(w.message) for w in caught) == 2


def test_mimic_joints_follow_their_leader_in_every_output(tmp_path):
    """TALOS's grippers: <mimic> couples six joints to gripper_<side>_joint (multiplier
    +-1); name_mot drives them all, so the actuators are dependent (redundant)."""
    mech, _ = widened_talos(tmp_path)
    assert mech.is_redundant
    couplings = {f: (leader, m) for f, leader, m, _ in mech.couplings}
    assert couplings['gripper_left_fingertip_1_joint'] == ('gripper_left_joint', -1.0)
    solver = cog_id_ros.InverseDynamics(mech, backend='reference')
    q = np.array([mech.assembled_positions[j] for j in mech.active_index])
    for a, name in enumerate(mech.active_joints):
        if name in ('gripper_left_joint', 'gripper_right_joint'):
            q[a] -= 0.2
        elif name in couplings:
            q[a] -= 0.2 * couplings[name][1]
    positions = solver.solve_positions_by_name(list(q))
    for follower, (leader, m) in couplings.items():
        assert positions[follower] == pytest.approx(m * positions[leader], abs=1e-9)


def test_what_a_refusal_says_to_write_loads(tmp_path):
    """wl16_like with its six motors held at 0: the loops cannot close there. The refusal
    prints the nearest closed pose as an initial_positions block; pasted, it loads with the
    motors held where the block puts them."""
    folder, urdf, loops = files('wl16_like')
    zeros = ', '.join(f'motor_{k}: 0.0' for k in range(1, 7))
    header = ('/**:\n  ros__parameters:\n    mechanism:\n'
              f'      urdf_file: {os.path.join(folder, urdf)}\n'
              f'      loop_closure_file: {os.path.join(folder, loops)}\n'
              '      idle_spins: lock\n')
    path = tmp_path / 'wl16.yaml'
    path.write_text(header + f'      initial_positions: {{{zeros}}}\n')
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        with pytest.raises(MechanismConfigError) as info:
            cog_id_ros.Mechanism.from_params_file(str(path))
        block = re.search(r'`(initial_positions: \{[^`]*\})`', str(info.value)).group(1)
        path.write_text(header + '      ' + block + '\n')
        mech = cog_id_ros.Mechanism.from_params_file(str(path))
    assert mech.found_at_assembly == []
    import yaml
    pose = yaml.safe_load(block)['initial_positions']
    for name in mech.active_joints:
        assert mech.assembled_positions[mech.joints.index(name)] == pose[name]


def test_inspect_shows_the_spins_of_a_refused_robot_and_draws_them(tmp_path):
    folder, urdf, loops = files('cassie_like')
    params = tmp_path / 'cassie.yaml'
    params.write_text('/**:\n  ros__parameters:\n    mechanism:\n'
                      f'      urdf_file: {os.path.join(folder, urdf)}\n'
                      f'      loop_closure_file: {os.path.join(folder, loops)}\n')
    picture = tmp_path / 'cassie.png'
    done = subprocess.run([os.path.join(BIN, 'cog_id_inspect'), '--params-file', str(params),
                           '--plot', str(picture)], capture_output=True, text=True,
                          timeout=300, env=dict(os.environ, PYTHONPATH=REPO))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count('\n') == 1 and 'mechanism.locked_joints' in done.stderr
    assert done.stdout.startswith('REFUSED as written for its idle spins'), done.stdout[:300]
    assert 'idle spins (mechanism.idle_spins: lock): 2, one joint locked each' in done.stdout
    assert "base link 'pelvis' held fixed to the world" in done.stdout
    assert '\n  initial_positions: {"motor_ankle": ' in done.stdout
    assert picture.stat().st_size > 10000
    assert sys.executable
