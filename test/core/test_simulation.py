"""cog_id_ros.Simulation: energy kept without gravity and efforts (Pinocchio's energy where
the oracle reads the file), the loops closed at every step, the torques of a motion
replayed reproduce it (second order in the time step, the error of holding an effort over
a step), the compiled step and the Python one agree to the bit, singular poses stop it with
the time and the joint, and the API's shapes and errors.

Pinocchio is needed for the independent energy (skipped without it, the energy from the
package's own H then checked instead); the rest needs nothing but cog_id_ros.
"""
import glob
import math
import os
import sys

import numpy as np
import pytest
import yaml

import cog_id_ros

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.dirname(HERE))

from trajectories import NOT_FOR_ORACLE, TRAJECTORIES, config_path, sample  # noqa: E402

CONFIGS = sorted(os.path.basename(p) for p in glob.glob(os.path.join(REPO, 'config', '*.yaml')))
STEP = 0.001


def _mechanism(name, **changes):
    mech = cog_id_ros.Mechanism.from_params_file(config_path(name))
    if not changes:
        return mech
    params = dict(mech.parameters)
    params.update(changes)
    return cog_id_ros.Mechanism.from_parameters(params, base_dir=os.path.dirname(config_path(name)))


def _without_gravity_oracle(name, tmp_path):
    """The Pinocchio oracle of config ``name`` with gravity off, or None where it cannot
    read the file (spherical joints, URDF) or Pinocchio is missing."""
    if name in NOT_FOR_ORACLE:
        return None
    try:
        from pinocchio_reference import Oracle
    except pytest.skip.Exception:
        return None
    with open(config_path(name), encoding='utf-8') as f:
        data = yaml.safe_load(f)
    data['/**']['ros__parameters']['mechanism']['gravity'] = [0.0, 0.0, 0.0]
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return Oracle(str(path))


@pytest.mark.parametrize('name', CONFIGS)
def test_energy_is_kept_and_the_loops_closed(name, tmp_path):
    """No gravity, no efforts, moving: 10 s at 1 ms steps keep the kinetic energy to 1e-6
    (Pinocchio's, of every joint's position and velocity as the simulation reports them),
    and every step's pose closed to closure_tolerance (also by the oracle's own closure)."""
    mech = _mechanism(name, **{'mechanism.gravity': [0.0, 0.0, 0.0]})
    _, q, qd, _ = sample(name, 200)
    sim = cog_id_ros.Simulation(mech, STEP)
    # a twentieth of the test motion's fastest rates: 10 s cover about half of its path,
    # away from the singular poses a free motion would otherwise run into
    sim.reset(q[0], 0.05 * qd[np.argmax(np.abs(qd).max(axis=1))])
    oracle = _without_gravity_oracle(name, tmp_path)
    solver = cog_id_ros.InverseDynamics(mech)

    def energy():
        if oracle is not None:
            return oracle.energy(sim.joint_positions(), sim.joint_velocities())
        h, _ = solver.equation_of_motion(sim.positions, sim.velocities)
        return 0.5 * sim.velocities @ h @ sim.velocities

    start, worst, zeros = energy(), 0.0, [0.0] * len(q[0])
    assert start > 0.0
    for i in range(int(round(10.0 / STEP))):
        sim.step(zeros)
        assert sim.closure_residual <= mech.closure_tolerance, (name, sim.time)
        if i % 250 == 249:
            worst = max(worst, abs(energy() - start) / start)
            if oracle is not None:
                assert np.abs(oracle.closure(sim.joint_positions())).max() < 1e-9
    assert sim.time == pytest.approx(10.0)
    assert worst <= 1e-6, (name, worst)
    assert np.abs(sim.positions - q[0]).max() > 0.05      # (it moved)


@pytest.mark.parametrize('name', CONFIGS)
def test_replayed_torques_reproduce_the_motion(name):
    """The torques of the test motion at the middle of each step, held over the step, move
    the simulation along the motion: the error is that of holding them (second order: half
    the time step, a quarter of the error), the loops closed at every step."""
    mech = _mechanism(name)
    solver = cog_id_ros.InverseDynamics(mech)
    errors = []
    for h in (0.002, 0.001):
        n = int(round(0.5 / h))
        t = np.arange(n + 1) * h
        q, qd, _ = TRAJECTORIES[name](t)
        tau = solver.torques(*TRAJECTORIES[name](t[:-1] + h / 2))
        solver.reset()
        sim = cog_id_ros.Simulation(mech, h)
        sim.reset(q[0], qd[0])
        error = 0.0
        for i in range(n):
            sim.step(tau[i])
            assert sim.closure_residual <= mech.closure_tolerance
            error = max(error, np.abs(sim.positions - q[i + 1]).max())
        errors.append(error)
    assert 3.9 < errors[0] / errors[1] < 4.1, (name, errors)
    assert errors[1] < 1e-3, (name, errors)


@pytest.mark.parametrize('name', CONFIGS)
def test_compiled_and_python_steps_agree_to_the_bit(name):
    """The step in C (compiled kernels) does the Python step's operations in order: the same
    state after every step, with efforts that change (a fresh k1) and that do not (the
    last accelerations kept)."""
    mech = _mechanism(name)
    sims = {}
    for backend in ('native', 'python', 'reference'):
        try:
            sims[backend] = cog_id_ros.Simulation(mech, STEP, backend)
        except cog_id_ros.MechanismConfigError:
            continue                    # no C compiler here
    assert [s.backend for s in sims.values()] == list(sims)
    _, q, qd, _ = sample(name, 200)
    tau = cog_id_ros.InverseDynamics(mech).torques(q[0], qd[0])
    for sim in sims.values():
        sim.reset(q[0], qd[0])
    for i in range(60):
        efforts = (tau * (1.0 + 0.2 * math.sin(i))).tolist() if i % 3 else tau.tolist()
        states = []
        for backend, sim in sims.items():
            if backend != 'reference' or i < 6:
                sim.step(efforts)
                states.append((sim.time, sim.positions.tolist(), sim.velocities.tolist(),
                               sim.joint_positions().tolist(), sim.accelerations.tolist()))
        assert all(s == states[0] for s in states), (name, i)


def test_a_singular_pose_stops_it_naming_the_time_and_the_joint():
    """The five-bar falling under gravity without efforts reaches a singular pose (its
    distal links in a line): the step that cannot go on raises, naming the time and a
    joint; the state stays at the last step, and reset() goes on."""
    mech = _mechanism('five_bar.yaml')
    sim = cog_id_ros.Simulation(mech, STEP)
    with pytest.raises((cog_id_ros.SingularConfigurationError, cog_id_ros.ClosureError)) \
            as info:
        for _ in range(2000):
            before = (sim.time, sim.positions.tolist(), sim.velocities.tolist())
            sim.step([0.0, 0.0])
    message = str(info.value)
    assert message.startswith(f'simulation stopped at t = {before[0] + STEP:.6g} s (the step '
                              f'from t = {before[0]:.6g} s, where j1 = ')
    assert info.value.joint in mech.joints and f'moving fastest there: {info.value.joint}' \
        in message
    assert info.value.time == before[0] and 0.1 < before[0] < 1.0
    assert (sim.time, sim.positions.tolist(), sim.velocities.tolist()) == before
    with pytest.raises(type(info.value)):
        sim.step([0.0, 0.0])            # it does not go on
    sim.reset()
    sim.step([0.0, 0.0])
    start = [mech.assembled_positions[j] for j in mech.active_index]
    assert sim.time == STEP and np.abs(sim.positions - start).max() < 1e-3


@pytest.mark.parametrize('time_step', [STEP, STEP / 2])
def test_no_step_that_jumps_is_accepted(time_step):
    """Adversarial check of issue 21: near the five-bar's singular pose the step before the
    stop was accepted with a crank turned 14 rad in 1 ms (-4.4e11 rad at 0.5 ms) and
    velocities of 2e6 rad/s, and cog_sim_node published it. Every accepted step now moves
    each joint by at most MAX_STEP_MOTION; the one that would not is refused, naming the
    joint, and the state stays at the last step. (Issue 11: the step's error control now
    stops it earlier, at the step no substep follows to the tolerance, naming why; the
    refusal of a jump, which was the only guard, is still there behind it.)"""
    from cog_id_ros.core.simulation.simulation import MAX_STEP_MOTION
    mech = _mechanism('five_bar.yaml')
    sim = cog_id_ros.Simulation(mech, time_step)
    last = sim.joint_positions()
    with pytest.raises((cog_id_ros.ClosureError, cog_id_ros.SingularConfigurationError)) as info:
        for _ in range(int(2.0 / time_step)):
            sim.step([0.0, 0.0])
            now = sim.joint_positions()
            assert np.abs(now - last).max() <= MAX_STEP_MOTION, (sim.time, now, last)
            assert np.isfinite(sim.velocities).all()
            last = now
    if isinstance(info.value, cog_id_ros.ClosureError):
        assert ' would move by ' in str(info.value) and info.value.reason == 'unreachable'
    else:
        assert 'cannot be followed to the tolerance' in str(info.value)
        assert info.value.reason == 'singular'
    assert np.array_equal(sim.joint_positions(), last)


def test_a_passive_joint_follows_its_actuator_or_the_step_is_refused():
    """Adversarial check of issue 21: the paper four-bar (a parallelogram: joint1 equals
    joint3) driven by 2000 N m turned its crank more than pi a step and the passive joints
    came out 2 pi apart from it (691 rad through cog_sim_node). joint1 follows joint3 to
    the end, where a step that would turn a joint more than MAX_STEP_MOTION is refused."""
    mech = _mechanism('paper_four_bar_a.yaml')
    sim = cog_id_ros.Simulation(mech, STEP)
    with pytest.raises(cog_id_ros.ClosureError) as info:
        for _ in range(2000):
            sim.step([2e3])
            q = sim.joint_positions()
            assert abs(q[0] - q[2]) < 1e-6, (sim.time, q)
    assert 'in one step of 0.001 s' in str(info.value)
    assert sim.velocities[0] > 400.0        # it went as fast as a step can follow


def test_state_and_reset():
    name = 'five_bar_redundant.yaml'
    mech = _mechanism(name)
    sim = cog_id_ros.Simulation(mech)
    assert sim.time_step == 0.001 and sim.time == 0.0
    start = np.array([mech.assembled_positions[j] for j in mech.active_index])
    assert np.array_equal(sim.positions, start) and np.array_equal(sim.velocities, [0, 0, 0])
    solver = cog_id_ros.InverseDynamics(mech)
    assert np.allclose(sim.joint_positions(), solver.solve_positions(start), atol=1e-12)
    assert sim.joint_positions().shape == (len(mech.joints),)
    _, q, qd, qdd = sample(name, 200)
    sim.reset(q[50], qd[50])
    assert np.allclose(sim.positions, q[50], atol=1e-12)
    assert np.allclose(sim.velocities, qd[50], atol=1e-12)      # consistent: as given
    solver.solve_positions(q[50])
    assert np.allclose(sim.joint_velocities(), solver.last_pose(qd[50])[1], atol=1e-12)
    tau = solver.torques(q[50], qd[50], qdd[50])
    sim.step(tau)
    assert sim.time == 0.001
    assert np.allclose(sim.accelerations, solver.forward_dynamics(sim.positions, sim.velocities,
                                                                  tau), rtol=1e-9, atol=1e-9)
    with pytest.raises(cog_id_ros.ClosureError) as info:
        sim.reset(q[50] + [0.0, 0.0, 0.3])                     # not on the closure
    assert info.value.reason == 'inconsistent'


def test_bad_efforts_and_parameters():
    mech = _mechanism('paper_four_bar_a.yaml')
    sim = cog_id_ros.Simulation(mech, 0.002, backend='python')
    sim.step([0.1])
    before = (sim.time, sim.positions.tolist(), sim.velocities.tolist())
    for efforts, reason in (([math.nan], 'non_finite'), ([0.0, 0.0], 'malformed'),
                            ('x', 'malformed'), ([[0.0], [0.0]], 'malformed')):
        with pytest.raises(cog_id_ros.SetpointError) as info:
            sim.step(efforts)
        assert info.value.reason == reason
        assert (sim.time, sim.positions.tolist(), sim.velocities.tolist()) == before
    for step in (0.0, -1.0, 2.0, math.nan, 'x', True):
        with pytest.raises(cog_id_ros.MechanismConfigError, match='time_step'):
            cog_id_ros.Simulation(mech, step)
    with pytest.raises(cog_id_ros.MechanismConfigError, match='mechanism'):
        cog_id_ros.Simulation('config/paper_four_bar_a.yaml')
    with pytest.raises(cog_id_ros.MechanismConfigError, match='backend'):
        cog_id_ros.Simulation(mech, backend='fast')
