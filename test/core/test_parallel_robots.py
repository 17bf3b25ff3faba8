"""The two parallel robots of config/: the Stewart-Gough 6-UPS platform and the delta robot.

They load with the expected size and DOF, their initial positions are a closed assembly at
the start of their test motion, the test motions are what they claim (the platform follows
the driven pose; exact derivatives; no joint near a lock, no pose near a singularity), and
cog_id_ros's torques agree with the Pinocchio oracle (test/pinocchio_reference.py) to 1e-9
relative along each motion, per sample (warm-started) and in one batch call. One test
checks that the comparison would notice a 1 % mass error.
"""
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
TEST = os.path.dirname(HERE)
if TEST not in sys.path:
    sys.path.insert(0, TEST)

from trajectories import (  # noqa: E402
    DELTA,
    STEWART,
    TRAJECTORIES,
    config_path,
    delta_platform_motion,
    oracle_along,
    stewart_platform_motion,
)

pytest.importorskip('pinocchio')
from pinocchio_reference import Oracle  # noqa: E402

import cog_id_ros  # noqa: E402

# name: (joints, loops, DOF, active joints)
EXPECTED = {STEWART: (36, 5, 6, 6), DELTA: (33, 5, 3, 3)}
NAMES = list(EXPECTED)
N_SAMPLES = 120          # reference backend: a few ms a Stewart sample
RTOL = 1e-9


@pytest.fixture(scope='module')
def followed():
    """(t, q, qd, qdd, q_all, tau) of the oracle along each motion, computed once."""
    def get(name):
        t, q, qd, qdd, q_all, _, _, tau = oracle_along(name, N_SAMPLES)
        return t, q, qd, qdd, q_all, tau
    return get


@pytest.fixture(scope='module')
def mechanisms():
    return {name: cog_id_ros.Mechanism.from_params_file(config_path(name)) for name in NAMES}


@pytest.mark.parametrize('name', NAMES)
def test_loads_with_expected_size_and_dof(name, mechanisms):
    mech = mechanisms[name]
    joints, loops, dof, active = EXPECTED[name]
    assert len(mech.joints) == joints
    assert len(mech.joints) - len(mech.links) == loops
    assert mech.dof == dof
    assert len(mech.active_joints) == active and not mech.is_redundant
    assert mech.assembly_warnings == []
    assert Oracle(config_path(name)).dof() == dof


@pytest.mark.parametrize('name', NAMES)
def test_initial_positions_are_closed_and_start_the_motion(name, mechanisms):
    orc = Oracle(config_path(name))
    assert np.abs(orc.closure(orc.initial_positions)).max() < 1e-14
    # the package's assembly kept them as written
    assert np.abs(np.asarray(mechanisms[name].assembled_positions) - orc.initial_positions).max() < 1e-12
    q0, _, _ = TRAJECTORIES[name](np.array([0.0]))
    assert np.abs(q0[0] - orc.initial_positions[orc.ia]).max() < 1e-13


@pytest.mark.parametrize('name', NAMES)
def test_motion_drives_the_platform_as_claimed(name, followed):
    """The inverse kinematics of the test motion is right: closing the loops at the actuator
    coordinates puts the platform where the motion says."""
    t, _, _, _, q_all, _ = followed(name)
    orc = Oracle(config_path(name))
    ks = range(0, N_SAMPLES, 10)
    poses = [orc.link_poses(q_all[k])['platform'] for k in ks]
    if name == STEWART:
        p, _, _, r, _, _ = stewart_platform_motion(t[list(ks)])
    else:
        p, _, _ = delta_platform_motion(t[list(ks)])
        r = np.broadcast_to(np.eye(3), (len(p), 3, 3))      # translation only
    for pose, pk, rk in zip(poses, p, r):
        assert np.abs(pose[:3, 3] - pk).max() < 1e-12
        assert np.abs(pose[:3, :3] - rk).max() < 1e-12
    for k in range(N_SAMPLES):
        assert np.abs(orc.closure(q_all[k])).max() < 1e-12


@pytest.mark.parametrize('name', NAMES)
def test_motion_derivatives_are_exact(name):
    traj = TRAJECTORIES[name]
    h = 1e-4
    for t0 in (0.0, 0.37, 1.0, 1.71):
        t = np.array([t0 - h, t0, t0 + h])
        q, qd, qdd = traj(t)
        assert np.abs((q[2] - q[0]) / (2 * h) - qd[1]).max() < 1e-6 * max(1.0, np.abs(qd).max())
        assert np.abs((qd[2] - qd[0]) / (2 * h) - qdd[1]).max() < 1e-6 * max(1.0, np.abs(qdd).max())
        assert np.abs((q[2] - 2 * q[1] + q[0]) / h ** 2 - qdd[1]).max() < 1e-4 * max(1.0, np.abs(qdd).max())


@pytest.mark.parametrize('name', NAMES)
def test_motion_stays_far_from_locks_and_singularities(name, followed, mechanisms):
    _, q, qd, qdd, q_all, _ = followed(name)
    joints = mechanisms[name].joints
    middle = [i for i, j in enumerate(joints) if j.endswith('_s2')]
    universal = [i for i, j in enumerate(joints) if j.endswith('_u1') or j.endswith('_u2')]
    assert len(middle) == 6 and len(universal) == 12
    assert np.abs(q_all[:, middle]).max() < 0.3          # gimbal lock at pi/2
    assert np.abs(q_all[:, universal]).max() < 0.5       # U lock at pi/2
    ev = cog_id_ros.InverseDynamics(mechanisms[name], backend='reference').evaluate(q, qd, qdd)
    assert ev.valid.all()
    assert ev.condition_number.max() < 1e3


@pytest.mark.parametrize('name', NAMES)
def test_torques_match_oracle_sample_by_sample(name, followed, mechanisms):
    _, q, qd, qdd, _, tau = followed(name)
    solver = cog_id_ros.InverseDynamics(mechanisms[name], backend='reference')
    ours = np.array([solver.torques(q[k], qd[k], qdd[k]) for k in range(N_SAMPLES)])
    scale = np.abs(tau).max()
    assert scale > 0.5
    err = np.abs(ours - tau).max() / scale
    assert err < RTOL, f'{name}: max relative error {err:.2e}'


@pytest.mark.parametrize('name', NAMES)
def test_torques_match_oracle_in_one_batch(name, followed, mechanisms):
    _, q, qd, qdd, _, tau = followed(name)
    solver = cog_id_ros.InverseDynamics(mechanisms[name], backend='reference')
    ours = solver.torques(q, qd, qdd)
    assert ours.shape == tau.shape
    err = np.abs(ours - tau).max() / np.abs(tau).max()
    assert err < RTOL, f'{name}: max relative error {err:.2e}'


@pytest.mark.parametrize('name', NAMES)
def test_comparison_notices_a_one_percent_mass_error(name, followed):
    """The oracle comparison has teeth: the package on the same file with the heaviest link
    1 % heavier misses the oracle's torques by far more than the tolerance."""
    from pinocchio_reference import load_params
    _, q, qd, qdd, _, tau = followed(name)
    params = load_params(config_path(name))
    heaviest = max(params['mechanism.links'], key=lambda ln: params[f'links.{ln}.mass'])
    params[f'links.{heaviest}.mass'] *= 1.01
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params),
                                        backend='reference')
    k = slice(0, N_SAMPLES, 20)
    err = np.abs(solver.torques(q[k], qd[k], qdd[k]) - tau[k]).max() / np.abs(tau).max()
    assert err > 1e3 * RTOL
