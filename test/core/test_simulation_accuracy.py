"""Issue 11: the Simulation's error control (cog_id_ros/core/simulation/simulation_error.py).

Each published step carries an error estimate (RK4's stages and the accelerations at its
end as an embedded pair, plus what the evaluations' rounding near a singular pose may add)
and is divided where the estimate exceeds the tolerance; ``Simulation.diagnostics`` reports
it with the energy and its drift. The three motions of the issue:

* the five-bar falling without efforts passes near its singular pose (t = 0.233 s) and kept
  0.24 % less energy after it than before (0.76 % of its kinetic energy), silently; then
  it stopped at the next one (0.345 s);
* the paper four-bar swinging from 1 rad stopped at 26.227 s, where a step's stage came
  within rounding of its flat pose (a change point: the parallelogram passes it);
* battobot falling at 1 ms steps lost 0.8 % of its kinetic energy in the last steps before
  its singular pose, unflagged.
"""
import math
import os
import sys
import warnings

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.simulation.simulation_error import (
    DEFAULT_TOLERANCE,
    Diagnostics,
    Substep,
    judged,
    not_followed,
    step_error,
)

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.dirname(HERE))

from trajectories import config_path  # noqa: E402

STEP = 0.001
BATTOBOT = os.path.join(REPO, 'test', 'models', 'example_parallel_robots', 'battobot_6d')
#: the paper four-bar (a) as a parallelogram: theta'' = -K cos(theta) for the crank
#: (three uniform rods of 1 kg and 0.5 m, the coupler translating; config file's comment)
PARALLELOGRAM_K = 9.81 / (2 * 0.25 / 3 + 0.25)


def _mechanism(name):
    return cog_id_ros.Mechanism.from_params_file(config_path(name))


def _oracle(name):
    try:
        from pinocchio_reference import Oracle
    except pytest.skip.Exception:
        return None
    return Oracle(config_path(name))


def _fall(sim, seconds, every=None):
    """Step ``sim`` with zero efforts until ``seconds`` or an error: (the error or None,
    [diagnostics after each step (or every ``every`` steps)])."""
    zeros = [0.0] * len(sim.mechanism.active_joints)
    seen = []
    for k in range(int(round(seconds / sim.time_step))):
        try:
            sim.step(zeros)
        except cog_id_ros.CogIdError as exc:
            return exc, seen
        if every is None or k % every == every - 1:
            seen.append(sim.diagnostics)
    return None, seen


def test_the_five_bar_keeps_its_energy_past_its_singular_pose_then_stops_at_the_next():
    """The five-bar falls past its singular pose (closure condition number 1250 at 0.233 s)
    with its energy kept to 2e-6 of its kinetic energy (it was 0.76 %), within what the
    estimates add up to; the steps near it are divided; then, where its motion leaves the
    actuators' coordinates (the distal links folding over), it stops, saying why."""
    mech = _mechanism('five_bar.yaml')
    sim = cog_id_ros.Simulation(mech, STEP)
    oracle = _oracle('five_bar.yaml')
    error, seen = _fall(sim, 1.0)
    assert isinstance(error, cog_id_ros.SingularConfigurationError) and error.reason == 'singular'
    message = str(error)
    assert message.startswith(f'simulation stopped at t = {sim.time + STEP:.6g} s (the step '
                              f'from t = {sim.time:.6g} s, where j1 = ')
    assert 'the motion cannot be followed to the tolerance' in message
    assert 'a singular pose ahead' in message and error.time == sim.time
    assert 0.3 < sim.time < 0.4
    passing = [d for d in seen if d.time < 0.25]
    assert max(d.condition_number for d in passing) > 1000.0         # it came near ...
    assert any(d.time > 0.3 for d in seen)                            # ... and went on
    assert sum(d.substeps > 1 for d in passing) >= 5                  # in divided steps
    largest = max(d.kinetic_energy for d in seen)
    drift = max(abs(d.energy_drift) for d in seen)
    assert drift < 1e-5 * largest, (drift, largest)                  # was 7.6e-3 of it
    assert drift <= 2.0 * seen[-1].total_error_estimate * largest
    if oracle is not None:        # the diagnostics' energy is Pinocchio's
        assert seen[-1].energy == pytest.approx(
            oracle.energy(sim.joint_positions(), sim.joint_velocities()), abs=1e-10)


def _parallelogram(theta, rate, seconds, n=20000):
    """The paper four-bar's crank angle and rate after ``seconds`` by the exact equation of
    the parallelogram, fine RK4 steps."""
    h = seconds / n

    def f(x, v):
        return v, -PARALLELOGRAM_K * math.cos(x)
    for _ in range(n):
        k1 = f(theta, rate)
        k2 = f(theta + h / 2 * k1[0], rate + h / 2 * k1[1])
        k3 = f(theta + h / 2 * k2[0], rate + h / 2 * k2[1])
        k4 = f(theta + h * k3[0], rate + h * k3[1])
        theta += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        rate += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return theta, rate


def test_the_paper_four_bar_swings_through_its_flat_pose():
    """The parallelogram passes its flat pose (a change point: the closure Jacobian is
    singular there, the motion is not) on its branch, joint1 = joint3, swing after swing:
    300 s with compiled kernels (it stopped at 26.227 s), its energy within the estimates,
    and across a crossing whose step ends 1.2e-5 rad from the flat pose (condition number
    8.6e5) it follows the parallelogram's own equation of motion."""
    mech = _mechanism('paper_four_bar_a.yaml')
    sim = cog_id_ros.Simulation(mech, STEP)
    sim.reset([0.007], [-7.0])
    for _ in range(3):
        sim.step([0.0])
    theta, rate = _parallelogram(0.007, -7.0, 3 * STEP)
    assert sim.diagnostics.divided_steps >= 1
    assert abs(sim.positions[0] - theta) < 1e-9 and abs(sim.velocities[0] - rate) < 1e-6
    seconds = 300.0 if sim.backend == 'native' else 30.0
    sim.reset([1.0], [0.0])
    zeros, crossings, sign, largest = [0.0], 0, 1.0, 0.0
    for k in range(int(round(seconds / STEP))):
        sim.step(zeros)                     # never stops
        if k % 10 == 0:
            q = sim.joint_positions()
            assert abs(q[0] - q[2]) < 1e-9, (sim.time, q)        # on its branch
            now = math.copysign(1.0, math.sin(q[2]))
            crossings += now != sign
            sign = now
        if k % 1000 == 0:
            largest = max(largest, sim.diagnostics.kinetic_energy)
    assert crossings >= (200 if seconds > 100 else 20)
    d = sim.diagnostics
    assert d.divided_steps >= 1 and d.total_substeps > d.steps
    assert abs(d.energy_drift) < 1e-4 * largest, (d.energy_drift, largest)
    assert abs(d.energy_drift) <= 2.0 * d.total_error_estimate * largest
    assert all(map(math.isfinite, d))


def _battobot():
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')             # it is assembled from the motors alone
        return cog_id_ros.Mechanism.from_parameters(
            {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml'},
            base_dir=BATTOBOT)


def test_battobot_stops_at_its_singular_pose_with_its_energy_kept():
    """Battobot falling without efforts at 1 ms steps: the steps nearing its singular pose
    are divided and keep the energy (it lost 0.8 % of the kinetic energy there), and where
    no substep follows the motion the simulation stops, naming the pose, instead of going
    on with the energy it no longer keeps."""
    mech = _battobot()
    assert len(mech.active_joints) == 12
    sim = cog_id_ros.Simulation(mech, STEP)
    error, seen = _fall(sim, 1.0)
    assert isinstance(error, (cog_id_ros.SingularConfigurationError, cog_id_ros.ClosureError))
    assert error.reason in ('singular', 'closure') and 'in a substep of' in str(error), error
    assert str(error).startswith('simulation stopped at t = ') and 0.1 < sim.time < 0.3
    largest = max(d.kinetic_energy for d in seen)
    drift = max(abs(d.energy_drift) for d in seen)
    assert drift < 1e-6 * largest, (drift, largest)                  # was 8e-3 of it
    assert seen[-1].substeps > 10                                     # divided, near it
    assert np.abs(sim.positions).max() < 3.0


def test_diagnostics_report_the_step_the_energy_and_the_work():
    """Diagnostics after a reset and after each step: the error estimate and substeps, the
    closure residual and condition numbers at the pose, the energy (Pinocchio's), the
    efforts' work (tau . delta theta each step) and the drift; unchanged by a refused step,
    back to zero by a reset."""
    name = 'paper_four_bar_a.yaml'
    mech = _mechanism(name)
    oracle = _oracle(name)
    sim = cog_id_ros.Simulation(mech, STEP)
    sim.reset([1.2], [0.5])
    d = sim.diagnostics
    assert isinstance(d, Diagnostics) and d._fields[:3] == ('time', 'steps', 'substeps')
    assert (d.time, d.steps, d.substeps, d.total_substeps, d.divided_steps) == (0.0, 0, 0, 0, 0)
    assert (d.work, d.energy_drift, d.error_estimate) == (0.0, 0.0, 0.0)
    assert d.tolerance == sim.tolerance == DEFAULT_TOLERANCE
    assert d.kinetic_energy > 0.0 and d.energy == d.kinetic_energy + d.potential_energy
    solver = cog_id_ros.InverseDynamics(mech)
    work, before = 0.0, sim.positions
    for k in range(200):
        tau = [3.0 * math.sin(0.05 * k)]
        sim.step(tau)
        work += tau[0] * (sim.positions[0] - before[0])
        before = sim.positions
        d = sim.diagnostics
        assert d.steps == k + 1 and d.time == sim.time and d.substeps == 1
        assert d.error_estimate <= sim.tolerance and d.closure_residual == sim.closure_residual
        assert d.closure_residual <= mech.closure_tolerance
        assert all(map(math.isfinite, d))
        if k % 50 == 49:
            assert d.work == pytest.approx(work, rel=1e-12, abs=1e-15)
            assert abs(d.energy_drift) < 1e-9 * (abs(d.energy) + abs(d.work))
            assert d.condition_number == pytest.approx(
                float(solver.evaluate(sim.positions).condition_number[0]), rel=1e-6)
            if oracle is not None:
                assert d.energy == pytest.approx(
                    oracle.energy(sim.joint_positions(), sim.joint_velocities()), abs=1e-10)
    assert d.work != 0.0 and d.total_substeps == 200 and d.largest_error_estimate > 0.0
    with pytest.raises(cog_id_ros.SetpointError):
        sim.step([math.nan])
    assert sim.diagnostics == d
    sim.reset()
    d = sim.diagnostics
    assert (d.steps, d.total_substeps, d.work, d.energy_drift) == (0, 0, 0.0, 0.0)


def test_the_tolerance_sets_how_far_steps_are_divided():
    """A tighter tolerance divides more and keeps the energy closer; tolerances that are not
    a number within TOLERANCE_RANGE are refused, naming the parameter."""
    mech = _mechanism('five_bar.yaml')
    for bad in (0.0, -1e-6, 1.0, math.nan, 'x', True, 1e-15):
        with pytest.raises(cog_id_ros.MechanismConfigError, match='tolerance'):
            cog_id_ros.Simulation(mech, STEP, tolerance=bad)
    results = []
    for tolerance in (1e-5, 1e-7, 1e-9):
        sim = cog_id_ros.Simulation(mech, STEP, tolerance=tolerance)
        error, seen = _fall(sim, 0.3)
        assert error is None
        results.append((seen[-1].total_substeps, abs(seen[-1].energy_drift)))
    assert results[0][0] < results[1][0] < results[2][0]
    assert results[0][1] > results[1][1] > results[2][1]


@pytest.mark.parametrize('name, start', [('five_bar.yaml', None),
                                         ('paper_four_bar_a.yaml', ([0.007], [-7.0]))])
def test_compiled_and_python_divided_steps_agree_to_the_bit(name, start):
    """Divided steps (the five-bar near its singular pose, the four-bar's step ending next
    to its flat pose) take the same substeps in C and in Python: the same state and the
    same diagnostics after every step."""
    mech = _mechanism(name)
    sims = {}
    for backend in ('native', 'python'):
        try:
            sims[backend] = cog_id_ros.Simulation(mech, STEP, backend)
        except cog_id_ros.MechanismConfigError:
            pytest.skip('no C compiler here')
    if start is None:       # just before the five-bar's singular pose
        probe = sims['native']
        _fall(probe, 0.225)
        start = (probe.positions, probe.velocities)
    for sim in sims.values():
        sim.reset(*start)
    divided = 0
    for _ in range(15):
        states = []
        for sim in sims.values():
            sim.step([0.0] * len(mech.active_joints))
            states.append((sim.positions.tolist(), sim.velocities.tolist(),
                           sim.joint_positions().tolist(), sim.accelerations.tolist(),
                           sim.diagnostics))
        assert states[0] == states[1]
        divided = states[0][-1].divided_steps
    assert divided >= 2


def test_the_branch_check_refuses_a_step_whose_joints_move_against_their_rates():
    """step_error's branch check: joints that move as their rates say pass; a passive joint
    that came out on the other side of its rates (another assembly branch) does not, and
    the error a shortest substep would raise says so."""
    h, zd, basis = 0.001, [2.0], [[1.0], [-1.0]]
    start = ([0.0, 0.0], basis)
    end = ([0.002, -0.002], basis)                   # both as their rates: 2 and -2 rad/s
    swapped = ([0.002, -0.002], [[1.0], [1.0]])       # the passive rate flipped at the end
    scales = [1.0, 1.0]
    good = step_error(h, start, zd, end, zd, zd, [0.0], [0.0], scales)
    bad = step_error(h, start, zd, swapped, zd, zd, [0.0], [0.0], scales)
    assert good[1] < 1e-15 and bad[1] == pytest.approx(0.002)
    assert good[2] == bad[2] == pytest.approx(0.002)

    def substep(error):
        return Substep(end, zd, [0.0], 0.0, 1.0, 1.0, *error, 0.0, 0.0, 1.0)
    assert judged(substep(good), h, h, 1e-7, 0.0)[:2] == (True, True)
    assert judged(substep(bad), h, h, 1e-7, 0.0)[:2] == (False, False)
    refusal = not_followed(substep(bad), h, 0.5, 1e-7, (1.0, 1.0))
    assert isinstance(refusal, cog_id_ros.SingularConfigurationError)
    assert 'another assembly branch' in str(refusal) and 'from t = 0.5 s' in str(refusal)
