"""The Pinocchio oracle (test/pinocchio_reference.py), the example configs, and cog_id_ros
checked against the oracle.

Part A needs no cog_id_ros: closed forms of the paper's parallelogram four-bar, the joint
convention of the parameter file written out with numpy, power balance, and finite
differences of the oracle's own motion.
Part B compares cog_id_ros with the oracle on every example config along its test motion.
It is skipped only while cog_id_ros/core/api/inverse_dynamics.py does not exist; once that file
exists, an import failure is a test failure.
"""
import glob
import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
if HERE not in sys.path:
    sys.path.insert(0, HERE)

from pinocchio_reference import Oracle, load_params, rpy_matrix, transform  # noqa: E402
from trajectories import (  # noqa: E402
    NOT_FOR_ORACLE,
    T_END,
    TRAJECTORIES,
    config_path,
    oracle,
    oracle_along,
    sample,
)

CONFIGS = sorted(os.path.basename(p) for p in glob.glob(os.path.join(REPO, 'config', '*.yaml')))
WITH_TRAJ = [c for c in CONFIGS if c in TRAJECTORIES and c not in NOT_FOR_ORACLE]
EXPECTED_DOF = {'paper_four_bar_a.yaml': 1, 'paper_four_bar_b.yaml': 1, 'slider_crank.yaml': 1,
                'five_bar.yaml': 2, 'five_bar_redundant.yaml': 2, 'spatial_rsur.yaml': 1}
N_SAMPLES = 200
M_ROD, L_ROD, G = 1.0, 0.5, 9.81


def _rodrigues(axis, angle):
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _motion(jtype, axis, q):
    """Motion(axis, q) of the spec: rotation by q about, or translation by q along, the unit axis."""
    t = np.eye(4)
    if jtype == 'revolute':
        t[:3, :3] = _rodrigues(axis, q)
    else:
        a = np.asarray(axis, dtype=float)
        t[:3, 3] = q * a / np.linalg.norm(a)
    return t


@pytest.fixture(scope='module')
def followed():
    """Oracle positions/velocities/accelerations/torques along every config's motion."""
    return lambda name: oracle_along(name, N_SAMPLES)


# =========================================================================== part A: oracle

def test_every_config_has_a_trajectory():
    missing = [c for c in CONFIGS if c not in TRAJECTORIES]
    assert not missing, f'add a test motion for {missing} in test/trajectories.py'
    assert set(EXPECTED_DOF) <= set(CONFIGS)


def test_rpy_is_urdf_convention():
    import pinocchio as pin
    rpy = np.array([0.3, -0.7, 1.2])
    assert np.allclose(rpy_matrix(rpy), pin.rpy.rpyToMatrix(rpy), atol=1e-15)
    # Rz(yaw) Ry(pitch) Rx(roll), written out independently
    assert np.allclose(rpy_matrix(rpy), _rodrigues([0, 0, 1], 1.2) @ _rodrigues([0, 1, 0], -0.7)
                       @ _rodrigues([1, 0, 0], 0.3), atol=1e-15)


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_initial_positions_assembled(name):
    o = oracle(name)
    assert len(o.initial_positions) == len(o.joints)
    assert np.abs(o.closure(o.initial_positions)).max() < 1e-12
    dof = o.dof()
    if name in EXPECTED_DOF:
        assert dof == EXPECTED_DOF[name]
    assert len(o.active) >= dof
    # the active joints determine the motion: V_a has full column rank, well conditioned
    va = o.velocity_basis(o.initial_positions)[o.ia]
    # (the oracle's basis is orthonormal: spread over the 33-36 joints of the parallel
    # robots, its active rows are smaller than over the 4-10 joints of the linkages)
    assert np.linalg.svd(va, compute_uv=False).min() > (0.1 if len(o.joints) <= 10 else 0.05)


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_closure_jacobian_by_finite_differences(name):
    """closure_jacobian is the derivative of closure w.r.t. every joint coordinate, also away
    from the closed configuration; at closure its null space is the velocity basis."""
    o = oracle(name)
    rng = np.random.default_rng(7)
    q = o.initial_positions + 0.05 * rng.standard_normal(o.n)
    h = 1e-6
    fd = np.column_stack([(o.closure(q + h * e) - o.closure(q - h * e)) / (2 * h) for e in np.eye(o.n)])
    assert np.abs(fd - o.closure_jacobian(q)).max() < 1e-7
    q0 = o.initial_positions
    v = o.velocity_basis(q0)
    assert np.abs(o.closure_jacobian(q0) @ v).max() < 1e-12
    assert np.linalg.matrix_rank(o.closure_jacobian(q0), tol=1e-9) == o.n - v.shape[1]


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_spec_joint_equation_holds_for_every_joint(name, followed):
    """T_world_child T(child) == T_world_parent T(parent) Motion(axis, q) for every joint,
    tree or loop-closing, forwards or backwards, along the motion: the oracle's model obeys
    the written convention (the link poses come from Pinocchio, the rest from numpy)."""
    o = oracle(name)
    p = load_params(config_path(name))
    q_all = followed(name)[4]
    for k in range(0, N_SAMPLES, 40):
        poses = o.link_poses(q_all[k])
        for i, jn in enumerate(o.joints):
            g = lambda key, d: p.get(f'joints.{jn}.{key}', d)  # noqa: E731
            tp = transform(g('parent_xyz', [0, 0, 0]), g('parent_rpy', [0, 0, 0]))
            tc = transform(g('child_xyz', [0, 0, 0]), g('child_rpy', [0, 0, 0]))
            lhs = poses[g('child', None)] @ tc
            motion = _motion(g('type', None), g('axis', [0, 0, 1]), q_all[k, i])
            rhs = poses[g('parent', None)] @ tp @ motion
            assert np.abs(lhs - rhs).max() < 1e-11, (name, jn, k)


def test_slider_crank_by_hand(followed):
    """Backwards prismatic joint with yawed attachments and a non-unit axis, by hand:
    the slider frame is at world (q_slide, 0.02), its wrist pin at (q_slide - 0.01, 0.03)."""
    o = oracle('slider_crank.yaml')
    q_all = followed('slider_crank.yaml')[4]
    r, l, e = 0.08, 0.25, 0.03  # noqa: E741 (the paper's names)
    th = q_all[:, 0]
    x_pin = r * np.cos(th) + np.sqrt(l ** 2 - (e - r * np.sin(th)) ** 2)
    assert np.allclose(q_all[:, 3], x_pin + 0.01, atol=1e-12, rtol=0)
    poses = o.link_poses(q_all[17])
    assert np.allclose(poses['slider'][:3, 3], [q_all[17, 3], 0.02, 0.0], atol=1e-12)
    assert np.allclose(poses['slider'][:3, :3], np.eye(3), atol=1e-12)


def test_paper_four_bar_a_closed_form(followed):
    """Parallelogram, three identical uniform rods (m, L), cranks at theta, coupler translating:
    T = 2 * (1/2)(m L^2/3) thd^2 + (1/2) m L^2 thd^2 = (5/6) m L^2 thd^2 (no theta dependence),
    V = 2 * m g (L/2) sin(theta) + m g L sin(theta) = 2 m g L sin(theta), so
    tau = (5/3) m L^2 thdd + 2 m g L cos(theta)."""
    t, q, qd, qdd, _, _, _, tau = followed('paper_four_bar_a.yaml')
    th, thdd = q[:, 0], qdd[:, 0]
    expect = 5.0 / 3.0 * M_ROD * L_ROD ** 2 * thdd + 2 * M_ROD * G * L_ROD * np.cos(th)
    assert np.abs(tau[:, 0] - expect).max() < 1e-10 * np.abs(expect).max()
    # and the motion really is theta = pi/2 + 0.5 sin(pi t)
    assert np.allclose(th, np.pi / 2 + 0.5 * np.sin(np.pi * t), atol=1e-15)
    assert np.allclose(thdd, -0.5 * np.pi ** 2 * np.sin(np.pi * t), atol=1e-13)


def test_paper_four_bar_b_halves(followed):
    _, q, _, qdd, _, _, _, tau = followed('paper_four_bar_b.yaml')
    th, thdd = q[:, 1], qdd[:, 1]
    expect = 5.0 / 3.0 * M_ROD * L_ROD ** 2 * thdd + 2 * M_ROD * G * L_ROD * np.cos(th)
    assert np.abs(tau - 0.5 * expect[:, None]).max() < 1e-10 * np.abs(expect).max()


def _stencil(f, t, h):
    """Fourth-order central difference of f (array-valued in t) at t."""
    return (-f(t + 2 * h) + 8 * f(t + h) - 8 * f(t - h) + f(t - 2 * h)) / (12 * h)


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_oracle_power_balance(name):
    """sum_k tau_k qd_k == dE/dt, E = kinetic + potential, dE/dt by differencing E along
    the motion (each shifted time solved afresh). Checks positions, velocities, the drift
    in the accelerations, gravity and RNEA together."""
    o = oracle(name)
    traj = TRAJECTORIES[name]
    t = np.linspace(0.05, T_END - 0.05, 20)
    q, qd, qdd = traj(t)
    q_all, qd_all, _, tau = o.follow(q, qd, qdd)

    def energy(ts):
        qa, qda, qdda = traj(ts)
        out = np.empty(ts.size)
        for k in range(ts.size):
            qq = o.solve_positions(qa[k], q_all[k])
            out[k] = o.energy(qq, o.joint_velocities(qq, qda[k]))
        return out

    power = np.sum(tau * qd, axis=1)
    de_dt = _stencil(energy, t, 1e-3)
    scale = np.abs(power).max()
    assert scale > 1e-3
    assert np.abs(power - de_dt).max() < 1e-7 * scale, np.abs(power - de_dt).max() / scale


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_oracle_velocities_accelerations_by_finite_differences(name):
    o = oracle(name)
    traj = TRAJECTORIES[name]
    t = np.linspace(0.05, T_END - 0.05, 12)
    q, qd, qdd = traj(t)
    q_all, qd_all, qdd_all, _ = o.follow(q, qd, qdd)
    h = 1e-3

    def pos(ts):
        qa, _, _ = traj(ts)
        return np.array([o.solve_positions(qa[k], q_all[k]) for k in range(ts.size)])

    def vel(ts):
        qa, qda, _ = traj(ts)
        out = []
        for k in range(ts.size):
            qq = o.solve_positions(qa[k], q_all[k])
            out.append(o.joint_velocities(qq, qda[k]))
        return np.array(out)

    assert np.abs(_stencil(pos, t, h) - qd_all).max() < 1e-8 * max(1.0, np.abs(qd_all).max())
    assert np.abs(_stencil(vel, t, h) - qdd_all).max() < 1e-7 * max(1.0, np.abs(qdd_all).max())


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_trajectory_derivatives_and_consistency(name):
    """Analytic (or oracle-derived) qd, qdd of the active joints match differences of q;
    redundant setpoints are on the closure; the motion starts at initial_positions."""
    o = oracle(name)
    traj = TRAJECTORIES[name]
    t = np.linspace(0.1, T_END - 0.1, 9)
    q, qd, qdd = traj(t)
    assert q.shape == qd.shape == qdd.shape == (t.size, len(o.active))
    h = 1e-3
    assert np.abs(_stencil(lambda s: traj(s)[0], t, h) - qd).max() < 1e-8 * max(1, np.abs(qd).max())
    assert np.abs(_stencil(lambda s: traj(s)[1], t, h) - qdd).max() < 1e-7 * max(1, np.abs(qdd).max())
    q0 = traj(np.array([0.0]))[0][0]
    assert np.allclose(q0, o.initial_positions[o.ia], atol=1e-12)
    qq = o.initial_positions
    for k in range(t.size):
        qq = o.solve_positions(q[k], qq)
        assert np.abs(o.closure(qq)).max() < 1e-12
        assert np.allclose(qq[o.ia], q[k], atol=1e-12)
    ts, qs, _, _ = sample(name, 50)
    assert ts[0] == 0.0 and ts[-1] == T_END and qs.shape == (50, len(o.active))


def test_weighted_minimum_norm_five_bar_redundant(followed):
    """The oracle's redundant torques solve min sum w_k tau_k^2 s.t. the motion: compared with
    an independent parametrisation tau = tau0 + N y over the internal-force space N."""
    name = 'five_bar_redundant.yaml'
    o = oracle(name)
    assert list(o.weights) == [1.0, 2.0, 0.5]
    _, q, qd, qdd, q_all, _, _, tau = followed(name)
    w = o.weights
    for k in range(0, N_SAMPLES, 30):
        v = o.velocity_basis(q_all[k])
        va = v[o.ia]
        _, qd_all, qdd_all = o.active_torques(q_all[k], qd[k], qdd[k], return_all=True)
        b = v.T @ o.tree_torques(q_all[k], qd_all, qdd_all)
        tau0 = np.linalg.lstsq(va.T, b, rcond=None)[0]
        n = np.linalg.svd(va.T)[2][va.shape[1]:].T        # internal forces: va.T @ n == 0
        y = -np.linalg.solve(n.T @ (w[:, None] * n), n.T @ (w * tau0))
        expect = tau0 + n @ y
        assert np.abs(tau[k] - expect).max() < 1e-10 * np.abs(expect).max()
        assert np.abs(va.T @ tau[k] - b).max() < 1e-10 * np.abs(b).max()
        # the weights matter: the unweighted minimum differs
        plain = tau0 - n @ np.linalg.solve(n.T @ n, n.T @ tau0)
        assert np.abs(plain - expect).max() > 1e-3 * np.abs(expect).max()


def test_oracle_handles_loop_closing_active_joint():
    """Driving the five-bar through j3 (which closes the loop in the oracle's tree) instead of
    j5 gives the same motion and the same tree torques."""
    name = 'five_bar.yaml'
    o = oracle(name)
    assert 'j3' in o.loop_joints
    alt = Oracle(config_path(name), active=['j1', 'j3'])
    t, q, qd, qdd = sample(name, 20)
    q_all, qd_all, qdd_all, _ = o.follow(q, qd, qdd)
    i3 = o.joints.index('j3')
    for k in range(20):
        qa = q_all[k, [0, i3]]
        qq = alt.solve_positions(qa, q_all[k] + 1e-3)
        assert np.allclose(qq, q_all[k], atol=1e-10)
        _, qd2, qdd2 = alt.active_torques(qq, qd_all[k, [0, i3]], qdd_all[k, [0, i3]], return_all=True)
        assert np.allclose(qd2, qd_all[k], atol=1e-10) and np.allclose(qdd2, qdd_all[k], atol=1e-8)


# =========================================================================== part B: cog_id_ros

CORE_FILE = os.path.join(REPO, 'cog_id_ros', 'core', 'api', 'inverse_dynamics.py')


@pytest.fixture(scope='module')
def cog():
    if not os.path.exists(CORE_FILE):
        pytest.skip('cog_id_ros core not written yet (no cog_id_ros/core/api/inverse_dynamics.py)')
    import cog_id_ros  # once the core exists, failing to import it is a failure, not a skip
    assert hasattr(cog_id_ros, 'InverseDynamics') and hasattr(cog_id_ros, 'Mechanism')
    return cog_id_ros


def _solver(cog, name):
    return cog.InverseDynamics(cog.Mechanism.from_params_file(config_path(name)))


def _wrap_diff(o, a, b):
    """a - b with revolute differences taken modulo 2 pi (torques do not see 2 pi)."""
    d = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    rev = np.array([o.joint[j].type == 'revolute' for j in o.joints])
    d[..., rev] = (d[..., rev] + np.pi) % (2 * np.pi) - np.pi
    return d


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_core_positions_close_the_loops(cog, name, followed):
    o = oracle(name)
    _, q, _, _, q_ref, _, _, _ = followed(name)
    solver = _solver(cog, name)
    for k in range(N_SAMPLES):
        q_all = np.asarray(solver.solve_positions(q[k]), dtype=float)
        assert q_all.shape == (len(o.joints),)
        res = np.abs(o.closure(q_all)).max()
        assert res < 1e-9, f'{name} sample {k}: oracle closure residual {res:.3e} of cog_id_ros q_all'
        assert np.abs(q_all[o.ia] - q[k]).max() < 1e-9
        # same assembly mode as the oracle's warm-started solve
        assert np.abs(_wrap_diff(o, q_all, q_ref[k])).max() < 1e-8, (name, k, q_all, q_ref[k])


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_core_torques_match_oracle(cog, name, followed):
    o = oracle(name)
    _, q, qd, qdd, q_ref, _, _, tau_ref = followed(name)
    peak = np.abs(tau_ref).max()
    tol = 1e-8 * peak
    # batch call, fresh solver
    tau = np.asarray(_solver(cog, name).torques(q, qd, qdd), dtype=float)
    assert tau.shape == q.shape
    err = np.abs(tau - tau_ref).max(axis=1)
    assert err.max() < tol, (f'{name}: batch torques differ from the oracle by {err.max():.3e} '
                             f'(peak {peak:.3e}), worst sample {err.argmax()}')
    # single-sample calls on every 8th sample, in order, fresh solver; and the oracle's
    # torques at cog_id_ros's own configuration
    solver = _solver(cog, name)
    positions = _solver(cog, name)
    for k in range(0, N_SAMPLES, 8):
        one = np.asarray(solver.torques(q[k], qd[k], qdd[k]), dtype=float)
        assert one.shape == (len(o.active),)
        assert np.abs(one - tau_ref[k]).max() < tol, (name, k, one, tau_ref[k])
        q_all = np.asarray(positions.solve_positions(q[k]), dtype=float)
        at_theirs = o.active_torques(q_all, qd[k], qdd[k])
        assert np.abs(one - at_theirs).max() < tol, (name, k, one, at_theirs)


@pytest.mark.parametrize('name', WITH_TRAJ)
def test_core_equation_of_motion_and_cog_jacobians(cog, name, followed):
    """tau = H qdd + B and G @ qd_a (COG twists) against the oracle. For redundant actuation
    H, B and G are only defined up to motions the closure forbids, so there only their action
    on consistent qd, qdd is compared."""
    import pinocchio as pin
    o = oracle(name)
    _, q, qd, qdd, q_ref, qd_ref, _, tau_ref = followed(name)
    redundant = len(o.active) > o.dof()
    tol = 1e-8 * np.abs(tau_ref).max()
    solver = _solver(cog, name)
    for k in range(0, N_SAMPLES, 24):
        h, b = (np.asarray(x, dtype=float) for x in solver.equation_of_motion(q[k], qd[k]))
        assert np.abs(h @ qdd[k] + b - tau_ref[k]).max() < tol
        if not redundant:
            h_ref = np.column_stack([o.active_torques(q_ref[k], qd[k], e) for e in np.eye(len(o.active))])
            b_ref = o.active_torques(q_ref[k], qd[k], np.zeros(len(o.active)))
            h_ref -= b_ref[:, None]
            assert np.abs(h - h_ref).max() < tol and np.abs(b - b_ref).max() < tol
        g = np.asarray(solver.cog_jacobians(q[k]), dtype=float)
        assert g.shape == (len(o.links), 6, len(o.active))
        # oracle COG twists: linear velocity of the COG point and angular velocity, world axes
        qq = q_ref[k]
        pin.computeJointJacobians(o.model, o.data, o._to_pin(qq))
        pin.updateFramePlacements(o.model, o.data)
        for i, ln in enumerate(o.links):
            fid = o.link_frame[ln]
            jac = pin.getFrameJacobian(o.model, o.data, fid, pin.LOCAL_WORLD_ALIGNED)[:, o.perm]
            com_w = o.data.oMf[fid].rotation @ o.inertia[ln].lever
            jac[:3] -= np.cross(com_w, jac[3:].T).T     # v_com = v_origin + w x (R c)
            twist = jac @ qd_ref[k]
            scale = max(1.0, np.abs(qd_ref[k]).max())
            assert np.abs(g[i] @ qd[k] - twist).max() < 1e-8 * scale, (name, ln, k)
