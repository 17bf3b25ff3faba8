"""InverseDynamics.forward_dynamics: against Pinocchio (the spanning tree's dynamics with the
loops closed by their constraint, solved in the constraint's null space: an independent
engine), the round trips with torques() the contract promises, every backend to the bit,
and the errors.

Needs Pinocchio for the comparison with the oracle (skipped without it); the round trips,
backends and errors need nothing but cog_id_ros.
"""
import glob
import math
import os
import sys

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.dynamics.forward_dynamics import INERTIA_CONDITION_LIMIT

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.dirname(HERE))

from trajectories import NOT_FOR_ORACLE, TRAJECTORIES, config_path, sample  # noqa: E402

CONFIGS = sorted(os.path.basename(p) for p in glob.glob(os.path.join(REPO, 'config', '*.yaml')))
FOR_ORACLE = [c for c in CONFIGS if c in TRAJECTORIES and c not in NOT_FOR_ORACLE]
N_SAMPLES = 60


def _mechanism(name, **changes):
    mech = cog_id_ros.Mechanism.from_params_file(config_path(name))
    if not changes:
        return mech
    params = dict(mech.parameters)
    params.update(changes)
    return cog_id_ros.Mechanism.from_parameters(params, base_dir=os.path.dirname(config_path(name)))


def _efforts(name, q, qd, qdd, seed=0):
    """The motion's torques (cog_id_ros) plus a random effort of their size: efforts that do
    not produce the motion, so forward dynamics has something to find."""
    tau = cog_id_ros.InverseDynamics(_mechanism(name)).torques(q, qd, qdd)
    rng = np.random.default_rng(seed)
    return tau + rng.standard_normal(tau.shape) * (0.3 * np.abs(tau).max() + 1e-3)


def oracle_accelerations(o, q_all, qd_all, tau):
    """The active-joint accelerations the efforts ``tau`` produce, by Pinocchio: the tree's
    mass matrix M and bias h (RNEA: h at zero acceleration, gravity and velocity terms; M
    column by column from unit accelerations), the loops closed by J qdd = -Jdot qd, solved
    in the null space V of J: qdd = qdd_p + V zdd with V^T M V zdd = V^T (Q - h - M qdd_p),
    Q the efforts on the active joints."""
    h = o.tree_torques(q_all, qd_all, np.zeros(o.n))
    mass = np.column_stack([o.tree_torques(q_all, qd_all, e) - h for e in np.eye(o.n)])
    jac = o.velocity_jacobian(q_all)
    qdd_p = -np.linalg.lstsq(jac, o.drift(q_all, qd_all), rcond=1e-10)[0]
    basis = o.velocity_basis(q_all)
    force = np.zeros(o.n)
    force[o.ia] = tau
    zdd = np.linalg.solve(basis.T @ mass @ basis, basis.T @ (force - h - mass @ qdd_p))
    return (qdd_p + basis @ zdd)[o.ia]


@pytest.mark.parametrize('name', FOR_ORACLE)
def test_forward_dynamics_matches_pinocchio(name):
    """Every example the oracle reads, along its test motion, with efforts that do not
    produce it: to 1e-8 of the largest acceleration, per sample and in batch."""
    from trajectories import oracle
    o = oracle(name)
    _, q, qd, qdd = sample(name, N_SAMPLES)
    tau = _efforts(name, q, qd, qdd)
    mech = _mechanism(name)
    solver = cog_id_ros.InverseDynamics(mech)
    positions = cog_id_ros.InverseDynamics(mech).solve_positions(q)
    reference = np.array([oracle_accelerations(o, positions[k],
                                               o.joint_velocities(positions[k], qd[k], o.weights),
                                               tau[k]) for k in range(N_SAMPLES)])
    scale = np.abs(reference).max()
    batch = solver.forward_dynamics(q, qd, tau)
    assert batch.shape == q.shape
    err = np.abs(batch - reference).max(axis=1)
    assert err.max() <= 1e-8 * scale, (name, err.max(), scale, int(err.argmax()))
    solver.reset()
    for k in range(0, N_SAMPLES, 5):
        one = solver.forward_dynamics(q[k], qd[k], tau[k])
        assert one.shape == (len(mech.active_joints),)
        assert np.abs(one - reference[k]).max() <= 1e-8 * scale, (name, k)


@pytest.mark.parametrize('name', CONFIGS)
def test_round_trips(name):
    """forward_dynamics(torques(qdd)) = qdd on every mechanism; torques(forward_dynamics(tau))
    = tau without redundant actuation (with it: the same generalized force, V_a^T tau).
    To 1e-8 of the terms summed (the accelerations of the efforts alone and of B alone:
    gravity and velocity terms, which a motion at constant speed cancels to zero): each
    call closes its poses to closure_tolerance (1e-10) on its own, and a batch's numbers
    differ from a sample's by about that times the condition number (api.md)."""
    _, q, qd, qdd = sample(name, N_SAMPLES)
    mech = _mechanism(name)
    solver = cog_id_ros.InverseDynamics(mech)
    tau = solver.torques(q, qd, qdd)
    terms = max(np.abs(qdd).max(), np.abs(solver.forward_dynamics(q, qd, None)).max(),
                np.abs(solver.forward_dynamics(q, None, tau)).max())
    back = solver.forward_dynamics(q, qd, tau)
    assert np.abs(back - qdd).max() <= 1e-8 * terms, name
    efforts = _efforts(name, q, qd, qdd, seed=1)
    accelerations = solver.forward_dynamics(q, qd, efforts)
    again = solver.torques(q, qd, accelerations)
    if not mech.is_redundant:
        assert np.abs(again - efforts).max() <= 1e-8 * np.abs(efforts).max(), name
    else:   # the efforts and the torques that make their motion differ by internal loads
        with_efforts = solver.forward_dynamics(q, qd, again)
        assert np.abs(with_efforts - accelerations).max() <= \
            1e-8 * np.abs(accelerations).max(), name
        assert np.abs(again - efforts).max() > 1e-6 * np.abs(efforts).max()   # (not trivial)
    for k in range(0, N_SAMPLES, 7):      # one sample at a time, warm-started
        one = solver.forward_dynamics(q[k].tolist(), qd[k].tolist(), tau[k].tolist())
        assert np.abs(one - qdd[k]).max() <= 1e-8 * terms, (name, k)


@pytest.mark.parametrize('name', CONFIGS)
def test_backends_agree_to_the_bit(name):
    """'reference' (the lane code), 'python' and 'native' (traced kernels) compute the same
    operations: the same accelerations to the last bit."""
    _, q, qd, qdd = sample(name, N_SAMPLES)
    q, qd = q[::12], qd[::12]
    tau = _efforts(name, q, qd, qdd[::12])
    mech = _mechanism(name)
    results = {}
    for backend in ('reference', 'python', 'native'):
        try:
            solver = cog_id_ros.InverseDynamics(mech, backend=backend)
        except cog_id_ros.MechanismConfigError:
            continue                    # no C compiler here
        one = [solver.forward_dynamics(q[k], qd[k], tau[k]) for k in range(len(q))]
        solver.reset()
        results[solver.backend] = (np.array(one), solver.forward_dynamics(q, qd, tau))
    first = results.pop('reference')
    for backend, (one, batch) in results.items():
        assert np.array_equal(one, first[0]) and np.array_equal(batch, first[1]), (name, backend)


def test_shapes_and_inputs():
    mech = _mechanism('five_bar.yaml')
    solver = cog_id_ros.InverseDynamics(mech)
    q = np.array([mech.assembled_positions[j] for j in mech.active_index])
    at_rest = solver.forward_dynamics(q, None, None)      # qd, tau: zeros: a free fall
    assert at_rest.shape == (2,) and np.all(np.isfinite(at_rest)) and np.abs(at_rest).max() > 0
    assert np.array_equal(solver.forward_dynamics(q, [0.0, 0.0], [0.0, 0.0]), at_rest)
    assert solver.forward_dynamics(q[None, :], None, None).shape == (1, 2)
    assert solver.forward_dynamics(np.zeros((0, 2)), None, None).shape == (0, 2)
    with pytest.raises(cog_id_ros.SetpointError, match='tau') as info:
        solver.forward_dynamics(q, [0.0, 0.0], [0.0])
    assert info.value.reason == 'malformed'
    with pytest.raises(cog_id_ros.SetpointError, match='tau of j5') as info:
        solver.forward_dynamics(q, [0.0, 0.0], [0.0, math.nan])
    assert info.value.reason == 'non_finite'
    with pytest.raises(cog_id_ros.SetpointError, match='sample 1: tau') as info:
        solver.forward_dynamics(np.array([q, q]), np.zeros((2, 2)), [[0.0, 0.0], [math.inf, 0]])
    assert info.value.sample == 1


def test_singular_inertia_is_refused():
    """Links without mass: no finite acceleration answers an effort. The warm start is kept."""
    name = 'paper_four_bar_a.yaml'
    mech0 = _mechanism(name)
    massless = {f'links.{link}.{key}': value for link in mech0.links
                for key, value in (('mass', 0.0), ('inertia', [0.0] * 6))}
    mech = _mechanism(name, **massless)
    solver = cog_id_ros.InverseDynamics(mech)
    q = [mech.assembled_positions[j] for j in mech.active_index]
    before = solver.last_pose()
    for call in (lambda: solver.forward_dynamics(q, [0.0], [1.0]),
                 lambda: solver.forward_dynamics([q, q], [[0.0], [0.0]], [[1.0], [1.0]])):
        with pytest.raises(cog_id_ros.SingularConfigurationError, match='singular inertia') \
                as info:
            call()
        assert info.value.reason == 'singular'
        # infinite, as documented, never NaN (adversarial check of issue 21: it was NaN)
        assert info.value.condition_number == math.inf > INERTIA_CONDITION_LIMIT
        assert 'condition inf' in str(info.value)
    assert solver.last_pose() == before
    assert np.array_equal(solver.torques(q, [1.0], [1.0]), [0.0])   # (torques are zero)


def test_singular_closure_is_refused():
    """At the parallelogram's change point (crank and coupler aligned) the closure is
    singular: forward_dynamics refuses it as torques does."""
    name = 'paper_four_bar_a.yaml'
    solver = cog_id_ros.InverseDynamics(_mechanism(name))
    torques = cog_id_ros.InverseDynamics(_mechanism(name))
    path = np.linspace(math.pi / 2, math.pi, 200)[:, None]
    for errors in (lambda s: s.torques(path), lambda s: s.forward_dynamics(path, None, None)):
        with pytest.raises(cog_id_ros.SingularConfigurationError) as info:
            errors(solver if errors.__code__.co_names[-1] == 'forward_dynamics' else torques)
        assert info.value.reason == 'singular' and info.value.sample == 199
