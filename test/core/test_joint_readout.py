"""The joints as written read back from the solver form's coordinates (core/kinematics/joint_readout.py):
the same numbers, to the bit, as the straightforward read-out (every frame and twist of
the solver form, then each chain), whoever computes them: the lane code on floats (no
solver made), the traced Python read-out, the compiled one; N samples as the lane code on
(N,) arrays. Along each config's test motion (test/trajectories.py) and along small motions
of the published robots about their assembled pose."""
import functools
import glob
import math
import os
from typing import NamedTuple
import warnings

import numpy as np
import pytest
from trajectories import config_path, sample

import cog_id_ros
from cog_id_ros.core.closure.joint_motion import active_velocity_map, combine
from cog_id_ros.core.kinematics import joint_readout
from cog_id_ros.core.kinematics import kinematics as kin
from cog_id_ros.core.linalg import spatial as sp
from cog_id_ros.core.model.assembly import AssemblyWarning
from cog_id_ros.core.native import kernels, native
from cog_id_ros.core.native.emitter import c_module_source, python_function
from cog_id_ros.core.native.straight_line import Graph, SymOps
from cog_id_ros.core.solve.inputs import rates as rates_of
from cog_id_ros.core.solve.sample_solve import SampleSolver

ROBOTS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'models',
                      'example_parallel_robots')
#: the configs whose chains of three revolutes are solved as spherical joints
CHAINED = ['stewart_6ups.yaml', 'delta_3rus.yaml', 'spatial_rsur.yaml', 'talos_like_leg.yaml']
PUBLISHED = ['wl16_like', 'cassie_like', 'digit_like', 'talos_like']


def robot(name):
    """A published robot (its assembled pose may be near the edge of the workspace: the
    warning that says so is not this file's subject)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        return cog_id_ros.Mechanism.from_parameters(
            {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
             'mechanism.idle_spins': 'lock'}, base_dir=os.path.join(ROBOTS, name))


def mechanism(name):
    return cog_id_ros.Mechanism.from_params_file(config_path(name)) if name in CHAINED \
        else robot(name)


def actuator_motion(name, n):
    """(q, qd) of the actuators: the config's test motion, or for a published robot each
    actuator swinging by 0.01 (rad or m) about its assembled position."""
    if name in CHAINED:
        return sample(name, n)[1:3]
    mech = mechanism(name)
    t = np.linspace(0.0, 1.0, n)[:, None]
    k = np.arange(len(mech.active_joints))
    w, size = np.pi * (1 + k % 3), 0.01 * (1 + k) / len(k)
    start = np.array([mech.assembled_positions[j] for j in mech.active_index])
    return start + size * np.sin(w * t), size * w * np.cos(w * t)


@functools.lru_cache(maxsize=None)
def closed_motion(name, n=40):
    """(coordinates, rates) of the solver form along the motion, sample after sample (the
    reference kernels of a mechanism of its own: nothing offered to the read-out)."""
    mech = mechanism(name)
    solved = mech.solver_mechanism
    serial = SampleSolver(solved, kernels.ReferenceKernels(solved),
                          cog_id_ros.InverseDynamics.continuation_step)
    start = list(solved.assembled_coordinates)
    q, record, _, _ = serial.close(start, [start[j] for j in solved.active_index],
                                   serial.zeros, serial.zeros)
    state = (list(q), serial.basis(record))
    coordinates, rates = [], []
    for target, qd in zip(*actuator_motion(name, n)):
        _, state = serial.solve_torques(state, target.tolist(), qd.tolist(), serial.zeros)
        rates_in = rates_of(mech, qd.tolist())
        coordinates.append(list(state[0]))
        rates.append(combine(active_velocity_map(solved, state[1], sp.ScalarOps), rates_in))
    coordinates, rates = np.array(coordinates), np.array(rates)
    for array in (coordinates, rates):
        array.setflags(write=False)
    return coordinates, rates


def straightforward(mech, q, qdot, ops):
    """The read-out as first written: every frame and twist of the solver form, then each
    chain's angles and rates (lanes: floats, or (N,) arrays)."""
    solver = mech.solver_mechanism
    frames = kin.forward_kinematics(solver.model, q, ops)
    twists = kin.link_twists(solver.model, frames, qdot)
    link = {solver.base_link: kin.BASE, **solver.link_index}
    positions = {name: q[solver.joint_index[name]] for name in solver.joints}
    rates = {name: qdot[solver.joint_index[name]] for name in solver.joints}
    for chain in mech.spherical_chains:
        parent, child = link[chain.parent], link[chain.child]
        rot_p = frames.rot[parent] if parent >= 0 else None
        rot_c = frames.rot[child] if child >= 0 else None
        angles = joint_readout.chain_angles(chain, joint_readout.chain_turn(chain, rot_p, rot_c),
                                            ops)
        relative = sp.sub(kin.twist_of(twists, child)[0], kin.twist_of(twists, parent)[0])
        if rot_p is not None:
            relative = sp.mat_t_vec(rot_p, relative)
        omega = sp.mat_t_vec(chain.frame_p, relative)
        positions.update(zip(chain.joints, angles))
        rates.update(zip(chain.joints, joint_readout.chain_rates(chain, angles, omega, ops)))
    return (np.array([positions[name] for name in mech.joints], dtype=float).T,
            np.array([rates[name] for name in mech.joints], dtype=float).T)


def test_the_configs_with_chains_are_those_listed():
    found = [os.path.basename(path) for path in sorted(glob.glob(config_path('*.yaml')))
             if cog_id_ros.Mechanism.from_params_file(path).spherical_chains]
    assert sorted(found) == sorted(CHAINED)


def test_a_mechanism_without_chains_shows_its_coordinates():
    mech = cog_id_ros.Mechanism.from_params_file(config_path('stewart_6ups_spherical.yaml'))
    q = np.array(mech.assembled_coordinates)
    positions, rates = mech.joints_at(q, 2.0 * q)
    assert np.array_equal(positions, q[:len(mech.joints)])
    assert np.array_equal(rates, 2.0 * q[:len(mech.joints)])
    assert kernels.first_kernels(mech) == kernels.TORQUE_KERNELS


def native_or_none(solved):
    try:
        return kernels.kernels_for(solved, 'native')
    except cog_id_ros.MechanismConfigError:
        return None


@pytest.mark.parametrize('name', CHAINED + PUBLISHED)
def test_every_readout_gives_the_straightforward_numbers_to_the_bit(name):
    """One sample by the lane code (no solver made), then by the traced Python read-out,
    then by the compiled one (where a compiler is there), with and without rates; and
    what each backend's kernels read out directly."""
    mech = mechanism(name)
    solved = mech.solver_mechanism
    assert len(mech.spherical_chains) > 0 and kernels.first_kernels(solved)[-1] == 'readout'
    coordinates, rates = closed_motion(name)
    expected = [straightforward(mech, q.tolist(), qdot.tolist(), sp.ScalarOps)
                for q, qdot in zip(coordinates, rates)]
    made = {'reference': kernels.ReferenceKernels(solved)}
    for backend in ('lane code', 'python', 'native'):
        if backend == 'python':
            made['python'] = kernels.kernels_for(solved, 'python')
        elif backend == 'native':
            made['native'] = native_or_none(solved)
            if made['native'] is None:
                continue
        readout, _ = joint_readout.offered(solved)
        assert readout is (None if backend == 'lane code' else made[backend].readout)
        for k, (q, qdot) in enumerate(zip(coordinates, rates)):
            positions, joint_rates = mech.joints_at(q.tolist(), qdot.tolist())
            assert np.array_equal(positions, expected[k][0]), (backend, k)
            assert np.array_equal(joint_rates, expected[k][1]), (backend, k)
            alone, none = mech.joints_at(q)
            assert none is None and np.array_equal(alone, positions), (backend, k)
    records = {b: [tuple(map(tuple, k.readout(q.tolist(), qdot.tolist())))
                   for q, qdot in zip(coordinates, rates)] for b, k in made.items() if k}
    assert all(got == records['reference'] for got in records.values())


@pytest.mark.parametrize('name', CHAINED + PUBLISHED)
def test_samples_in_a_batch_are_read_out_by_the_lane_code_on_arrays(name):
    """N samples: the straightforward read-out on (N,) arrays, to the bit (with compiled
    kernels made too), the (N, n) shapes kept for N = 1 and 0; within rounding of the
    samples read one by one (numpy's arccos and arctan2 may round otherwise than libm's)."""
    mech = mechanism(name)
    kernels.kernels_for(mech.solver_mechanism, 'auto')
    coordinates, rates = closed_motion(name)
    positions, joint_rates = mech.joints_at(coordinates, rates)
    expected = straightforward(mech, list(coordinates.T), list(rates.T), sp.ArrayOps)
    assert np.array_equal(positions, expected[0]) and np.array_equal(joint_rates, expected[1])
    assert np.array_equal(mech.joints_at(coordinates)[0], positions)
    one = np.array([mech.joints_at(q, qdot)[0] for q, qdot in zip(coordinates, rates)])
    assert np.abs(one - positions).max() < 1e-12
    for rows in (coordinates[:1], coordinates[:0]):
        got, none = mech.joints_at(rows)
        assert got.shape == (len(rows), len(mech.joints)) and none is None
        assert np.array_equal(got, positions[:len(rows)])


def test_last_pose_reads_the_chains_back():
    """What the node publishes: last_pose's positions and rates are the read-out at the
    pose the solver is at, the traced one (the solver made it) as the straightforward."""
    mech = mechanism('delta_3rus.yaml')
    solver = cog_id_ros.InverseDynamics(mech, backend='python')
    assert joint_readout.offered(mech.solver_mechanism)[0] is not None
    _, q, qd, qdd = sample('delta_3rus.yaml', 40)
    reference = cog_id_ros.InverseDynamics(mechanism('delta_3rus.yaml'), backend='reference')
    for k in range(0, 40, 3):
        solver.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        reference.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        assert solver.last_pose(qd[k].tolist()) == reference.last_pose(qd[k].tolist())
        assert solver.last_pose()[0] == reference.last_pose()[0]


def test_only_the_links_the_chains_need_are_placed():
    """The read-out places the tree paths of the chains' end links, not the whole tree."""
    mech = robot('talos_like')
    plan = joint_readout.ReadoutPlan(mech.solver_mechanism)
    model = mech.solver_mechanism.model
    ends = {k for _, p, c in plan.chains for k in (p, c) if k != kin.BASE}
    placed = {e.child for e in plan.edges}
    assert ends <= placed and len(plan.edges) < len(model.edges)
    for e in plan.edges:         # every edge's parent is placed before it
        assert e.parent == kin.BASE or e.parent in placed


# --- the operations the read-out adds to the traced code ------------------------------------

SPECIAL = [-7.5, -math.pi, -1.0000001, -1.0, -0.3, -0.0, 0.0, 1e-300, 0.3, 1.0, 1.0000001,
           2.0 * math.pi, 9.25, 1e300, math.inf, -math.inf, math.nan]
DIVISORS = [2.0 * math.pi, -2.0 * math.pi, 0.5, -3.0]


def operations(x, y, ops):
    """Each operation the read-out's lane code uses beyond the torque kernels', of lanes
    x and y (y not zero)."""
    return (ops.acos(x), ops.atan2(x, y), x % y, (x + math.pi) % (2.0 * math.pi) - math.pi,
            abs(x), ops.select(abs(x) <= y, x, y), ops.select(x < y, x * 2.0, y),
            ops.select(x > y, x, -y), ops.select(x >= y, y, x))


def same(a, b):
    """Equal floats, the sign of a zero included, or both NaN."""
    return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1.0, a) ==
                                                 math.copysign(1.0, b))


def traced_operations():
    graph = Graph()
    x, y = graph.inputs('xy', 2)
    return [('values', list(operations(x, y, SymOps)))], [('xy', [x, y])]


class Values(NamedTuple):
    """The record the operations' kernel returns."""
    values: tuple


def test_the_traced_python_computes_what_the_lane_code_does():
    fields, params = traced_operations()
    function, source, _ = python_function('ops', params, Values, fields)
    assert 'acos(' in source and ' % ' in source
    for x in SPECIAL:
        for y in DIVISORS + [x] if x != 0.0 else DIVISORS:
            expected = operations(x, y, sp.ScalarOps)
            got = function((x, y))[0]
            assert all(same(a, b) for a, b in zip(got, expected)), (x, y, got, expected)
    with pytest.raises(TypeError):
        bool(Graph().inputs('z', 1)[0] <= 1.0)       # only branch-free code can be traced


@pytest.mark.skipif(native.compiler() is None, reason='no C compiler here')
def test_the_compiled_code_computes_what_the_lane_code_does(tmp_path, monkeypatch):
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(tmp_path / 'cache'))
    fields, params = traced_operations()
    module, _ = native.load_module(
        'test_joint_readout operations' + kernels.core_version(),
        lambda name: c_module_source(name, [('ops', params, 'Values', fields)]))
    module.set_record_types(Values)
    for x in SPECIAL:
        for y in DIVISORS + [x] if x != 0.0 else DIVISORS:
            expected = operations(x, y, sp.ScalarOps)
            got = module.ops((x, y))[0]
            assert all(same(a, b) for a, b in zip(got, expected)), (x, y, got, expected)
