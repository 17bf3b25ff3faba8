"""Speed of the read-out of the joints as written (core/kinematics/joint_readout.py), beside a torque sample.

    .venv/bin/python bench/bench_readout.py             (every config in config/ with chains)
    .venv/bin/python bench/bench_readout.py --robots    (and the published robots of test/models)
    .venv/bin/python bench/bench_readout.py stewart_6ups delta_3rus

A mechanism whose chains of three revolute joints are solved as spherical joints
(core/kinematics/spherical_chains.py) shows the joints as written through ``Mechanism.joints_at``, which
``InverseDynamics.last_pose`` (the node's joint_states) and ``Simulation.joint_positions``
and ``joint_velocities`` call. Along 400 samples of bench_core.motion at 1 kHz (the solver
form's coordinates and rates closed by the native kernels), medians in us per call,
interleaved sample by sample, three passes:

* ``before``: the read-out as it was written first (every frame and twist of the solver
  form on floats, then each chain), with rates;
* ``lane``, ``python``, ``native``: ``joints_at(q, qdot)`` where no solver was made (the lane
  code on floats), where a 'python' solver was (its traced read-out), where a 'native' one
  was (compiled); ``native q``: the same without rates;
* ``torque``: one ``InverseDynamics.sample_torques`` (native) along the motion, and
  ``last_pose``: ``InverseDynamics.last_pose(qd)`` after it (the rate map and the read-out);
* ``ratio``: native read-out with rates over the torque sample.

The machine's load moves every number: compare columns of one run.
"""
import os
import statistics
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, '..')
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)
from bench_core import motion  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.core.closure.joint_motion import active_velocity_map, combine  # noqa: E402
from cog_id_ros.core.kinematics import kinematics as kin  # noqa: E402
from cog_id_ros.core.kinematics.joint_readout import chain_angles, chain_rates, chain_turn  # noqa: E402
from cog_id_ros.core.linalg import spatial as sp  # noqa: E402
from cog_id_ros.core.model.assembly import AssemblyWarning  # noqa: E402
from cog_id_ros.core.native import kernels  # noqa: E402
from cog_id_ros.core.solve.inputs import rates as rates_of  # noqa: E402
from cog_id_ros.core.solve.sample_solve import SampleSolver  # noqa: E402

CONFIGS = ('stewart_6ups', 'delta_3rus', 'spatial_rsur', 'talos_like_leg')
ROBOTS = ('wl16_like', 'cassie_like', 'digit_like', 'talos_like')
SAMPLES, PASSES = 400, 3


def load(name):
    """A fresh Mechanism (kernels are made per Mechanism object) of a config or robot."""
    if name in ROBOTS:
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', AssemblyWarning)
            return cog_id_ros.Mechanism.from_parameters(
                {'mechanism.urdf_file': 'robot.urdf', 'mechanism.loop_closure_file': 'robot.yaml',
                 'mechanism.idle_spins': 'lock'},
                base_dir=os.path.join(ROOT, 'test', 'models', 'example_parallel_robots', name))
    return cog_id_ros.Mechanism.from_params_file(os.path.join(ROOT, 'config', name + '.yaml'))


def before(mech, coordinates, rates):
    """Mechanism.joints_at(coordinates, rates) of one sample as it was first written."""
    solver = mech.solver_mechanism
    q = np.atleast_2d(np.asarray(coordinates, dtype=float))
    qdot = np.atleast_2d(np.asarray(rates, dtype=float))
    frames = kin.forward_kinematics(solver.model, q[0].tolist(), sp.ScalarOps)
    twists = kin.link_twists(solver.model, frames, qdot[0].tolist())
    positions, joint_rates = np.empty((1, len(mech.joints))), np.empty((1, len(mech.joints)))
    kept = [(k, solver.joint_index[n]) for k, n in enumerate(mech.joints)
            if n in solver.joint_index]
    positions[:, [k for k, _ in kept]] = q[:, [c for _, c in kept]]
    joint_rates[:, [k for k, _ in kept]] = qdot[:, [c for _, c in kept]]
    link = {solver.base_link: kin.BASE, **solver.link_index}
    for chain in mech.spherical_chains:
        columns = [mech.joint_index[j] for j in chain.joints]
        parent, child = link[chain.parent], link[chain.child]
        rot_p = frames.rot[parent] if parent >= 0 else None
        rot_c = frames.rot[child] if child >= 0 else None
        angles = chain_angles(chain, chain_turn(chain, rot_p, rot_c), sp.ScalarOps)
        positions[:, columns] = np.array(angles, dtype=float).T
        relative = sp.sub(kin.twist_of(twists, child)[0], kin.twist_of(twists, parent)[0])
        if rot_p is not None:
            relative = sp.mat_t_vec(rot_p, relative)
        omega = sp.mat_t_vec(chain.frame_p, relative)
        joint_rates[:, columns] = np.array(chain_rates(chain, angles, omega, sp.ScalarOps),
                                           dtype=float).T
    return positions[0], joint_rates[0]


def closed(mech, q, qd):
    """The solver form's (coordinates, rates) at each setpoint, closed sample after sample."""
    solved = mech.solver_mechanism
    serial = SampleSolver(solved, kernels.kernels_for(solved, 'native'),
                          cog_id_ros.InverseDynamics.continuation_step)
    start = list(solved.assembled_coordinates)
    pose, record, _, _ = serial.close(start, [start[j] for j in solved.active_index],
                                      serial.zeros, serial.zeros)
    state, out = (list(pose), serial.basis(record)), []
    for target, rate in zip(q, qd):
        _, state = serial.solve_torques(state, target.tolist(), rate.tolist(), serial.zeros)
        out.append((list(state[0]), combine(active_velocity_map(solved, state[1], sp.ScalarOps),
                                            rates_of(mech, rate.tolist()))))
    return out


def timed(call, *args):
    t0 = time.perf_counter()
    call(*args)
    return time.perf_counter() - t0


def bench(name):
    """{column: median us} of one mechanism."""
    mech = load(name)
    q, qd, qdd = (x[:SAMPLES] for x in motion(mech, 2 * SAMPLES, 2 * SAMPLES / 1000.0))
    poses = closed(mech, q, qd)
    assert np.array_equal(before(mech, *poses[0])[1], mech.joints_at(*poses[0])[1])
    lane, python, native = load(name), load(name), load(name)
    kernels.kernels_for(python.solver_mechanism, 'python')
    solver = cog_id_ros.InverseDynamics(native, backend='native')
    times = {key: [] for key in ('before', 'lane', 'python', 'native', 'native q', 'torque',
                                 'last_pose')}
    for _ in range(PASSES):
        solver.reset()
        for k, (coordinates, rates) in enumerate(poses):
            times['torque'].append(timed(solver.sample_torques, q[k].tolist(), qd[k].tolist(),
                                         qdd[k].tolist()))
            times['last_pose'].append(timed(solver.last_pose, qd[k].tolist()))
            times['before'].append(timed(before, mech, coordinates, rates))
            for key, m in (('lane', lane), ('python', python), ('native', native)):
                times[key].append(timed(m.joints_at, coordinates, rates))
            times['native q'].append(timed(native.joints_at, coordinates))
    out = {key: statistics.median(values) * 1e6 for key, values in times.items()}
    out['chains'] = len(mech.spherical_chains)
    out['ratio'] = out['native'] / out['torque']
    return out


def main(argv):
    names = [a for a in argv if not a.startswith('--')] or \
        list(CONFIGS) + (list(ROBOTS) if '--robots' in argv else [])
    columns = ('before', 'lane', 'python', 'native', 'native q', 'torque', 'last_pose')
    print(f'{"mechanism":16s} chains ' + ' '.join(f'{c:>9s}' for c in columns) + '   ratio')
    for name in names:
        row = bench(name)
        print(f'{name:16s} {row["chains"]:6d} ' + ' '.join(f'{row[c]:9.1f}' for c in columns) +
              f'   {row["ratio"]:5.2f}', flush=True)
    print('(us per call, medians; before/lane/python/native: joints_at with rates, '
          'native q: without)')


if __name__ == '__main__':
    main(sys.argv[1:])
