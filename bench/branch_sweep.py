"""Branch and accuracy sweep near singular poses: the batch against sample-by-sample calls.

    .venv/bin/python bench/branch_sweep.py             # every example and published robot
    .venv/bin/python bench/branch_sweep.py --quick     # the examples, fewer motions
    .venv/bin/python bench/branch_sweep.py five_bar delta_3rus

Outside the suite (minutes; test/core/test_branch_consistency.py is its short form). For
every parameter file in config/ and every published robot that loads
(test/models/example_parallel_robots, with ``idle_spins: lock``), along motions that run
into singular poses: a fall under gravity without efforts (cog_id_ros.Simulation, until
it stops), straight lines of the primary actuators out to a singular pose or beyond, and
large sinusoids. Each motion is solved

* in one batch (``evaluate(..., on_invalid='skip')`` and ``solve_positions``), from a
  fresh solver, also starting one and two samples later (the branch must not depend on
  where a batch starts);
* sample by sample, in order, by a fresh solver (``evaluate`` of one sample: the per-sample
  path, which keeps its warm start over a sample it refuses);
* sample by sample with ``closure_tolerance`` 1e-14 (1e-11 where the assembly at load
  cannot close so far): the reference of the accuracy check.

It counts, per mechanism: samples valid in one and not the other, samples valid in both
whose poses differ (another assembly branch: the API promises the same one), and samples
whose torques differ from the tight solve by more than the published estimate,
``(relative_error + the tight one's) x scale`` (docs/api.md, "Accuracy"; the scale is
max |H qdd| + max |B| plus the weight of the mechanism times its length scale). Exit
status 1 if any is found. A redundant mechanism's motions are made consistent by solving
the primary actuators' motion with a twin of it driven by them alone.
"""
import argparse
import glob
import os
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)

import cog_id_ros  # noqa: E402
from cog_id_ros.core.closure.continuation import length_scale  # noqa: E402

COLLECTION = os.path.join(REPO, 'test', 'models', 'example_parallel_robots')
#: the published robots that load (untouched, or with idle_spins: lock)
ROBOTS = ['5bar_linkage', '5bar_linkage_iso3d', '5bar_linkage_iso6d', 'battobot_6d',
          'cassie_like', 'digit_like', 'digit_like_2legs', 'robot_delta', 'talos_like',
          'wl16_like']
SAME = 1e-6          # rad or m: poses farther apart are on different branches
TIME_STEP = 0.001


def load_config(name):
    path = os.path.join(REPO, 'config', name + '.yaml')
    mech = cog_id_ros.Mechanism.from_params_file(path)
    return mech, os.path.dirname(path)


def load_robot(robot):
    folder = os.path.join(COLLECTION, robot)
    urdf = next(n for n in sorted(os.listdir(folder)) if n.endswith('.urdf'))
    params = {'mechanism.urdf_file': urdf, 'mechanism.idle_spins': 'lock'}
    if os.path.exists(os.path.join(folder, 'robot.yaml')):
        params['mechanism.loop_closure_file'] = 'robot.yaml'
    return cog_id_ros.Mechanism.from_parameters(params, base_dir=folder), folder


def variant(mech, base_dir, **changes):
    """``mech`` loaded again with some parameters changed (None: left out)."""
    params = dict(mech.parameters)
    for key, value in changes.items():
        params.pop(key, None)
        if value is not None:
            params[key] = value
    return cog_id_ros.Mechanism.from_parameters(params, base_dir=base_dir)


def tightened(mech, base_dir):
    """``mech`` with closure_tolerance 1e-14, or the smallest of 1e-13 and 1e-11 its
    assembly reaches (a URDF's rounded geometry may close to 1e-12 only)."""
    for tolerance in (1e-14, 1e-13, 1e-11):
        try:
            return variant(mech, base_dir, **{'mechanism.closure_tolerance': tolerance})
        except cog_id_ros.MechanismConfigError:
            continue
    return mech


def consistent(mech, base_dir, primary_q):
    """Active coordinates (N, M) of a redundant mechanism whose primary actuators follow
    ``primary_q`` (N, dof), from a twin driven by them alone; the samples it cannot solve
    are cut off. ``mech`` not redundant: ``primary_q`` itself."""
    if not mech.is_redundant:
        return primary_q
    twin = variant(mech, base_dir, **{
        'mechanism.torque_weights': None,
        'mechanism.active_joints': [mech.active_joints[a] for a in mech.primary]})
    ev = cog_id_ros.InverseDynamics(twin).evaluate(primary_q, on_invalid='skip')
    good = len(ev.valid) if ev.valid.all() else int(np.argmin(ev.valid))
    return ev.positions[:good][:, [mech.joints.index(j) for j in mech.active_joints]]


def start(mech):
    return np.array([mech.assembled_positions[j] for j in mech.active_index])


def fall(mech, seconds):
    """(q, qd, qdd) of the mechanism let go at its assembled pose, until the Simulation stops."""
    sim = cog_id_ros.Simulation(mech, TIME_STEP)
    zeros = [0.0] * len(mech.active_joints)
    q, qd, qdd = [], [], []
    try:
        for _ in range(int(seconds / TIME_STEP)):
            sim.step(zeros)
            q.append(sim.positions)
            qd.append(sim.velocities)
            qdd.append(sim.accelerations)
    except cog_id_ros.CogIdError:
        pass
    return np.array(q), np.array(qd), np.array(qdd)


def motions(mech, base_dir, rng, quick):
    """{label: (q, qd, qdd)} of the motions swept on ``mech``."""
    out = {'fall': fall(mech, 2.0 if quick else 5.0)}
    q0, dof = start(mech), mech.dof
    scale = np.array([1.0 if mech.active_kinds[a].wraps else length_scale(mech)
                      for a in mech.primary])
    for k in range(2 if quick else 6):
        d = rng.normal(size=dof)
        d *= scale / np.linalg.norm(d)
        n = 300
        s = np.linspace(0.0, 3.0, n)[:, None]                  # a line out to 3 rad (3 L)
        line = q0[mech.primary][None, :] + s * d[None, :]
        t = np.linspace(0.0, 2.0, n)[:, None]
        amplitude = rng.uniform(0.5, 2.0)
        sine = q0[mech.primary][None, :] + amplitude * np.sin(np.pi * t) * d[None, :]
        for label, primary in ((f'line{k}', line), (f'sine{k}', sine)):
            q = consistent(mech, base_dir, primary)
            if len(q) < 3:
                continue
            h = 1.0 / (len(q) - 1)
            qd = np.gradient(q, h, axis=0)
            out[label] = (q, qd, np.gradient(qd, h, axis=0))
    return out


def per_sample(mech, q, qd, qdd):
    """(valid, positions, torques, relative_error) sample by sample, in order."""
    solver = cog_id_ros.InverseDynamics(mech)
    valid, positions, torques, error = [], [], [], []
    for k in range(len(q)):
        ev = solver.evaluate(q[k], qd[k], qdd[k], on_invalid='skip')
        valid.append(bool(ev.valid[0]))
        positions.append(ev.positions[0])
        torques.append(ev.torques[0])
        error.append(ev.relative_error[0])
    return np.array(valid), np.array(positions), np.array(torques), np.array(error)


def torque_scale(mech, q, qd, qdd):
    """Per sample: max |H qdd| + max |B| + |g| (sum of the link masses) (length scale)."""
    weight = np.linalg.norm(mech.gravity) * sum(mech.link_mass) * length_scale(
        mech.solver_mechanism)
    solver = cog_id_ros.InverseDynamics(mech)
    out = np.full(len(q), np.inf)
    for k in range(len(q)):
        try:
            h, b = solver.equation_of_motion(q[k], qd[k])
        except cog_id_ros.CogIdError:
            continue
        out[k] = np.abs(h @ qdd[k]).max() + np.abs(b).max() + weight
    return out


def sweep_one(mech, tight, q, qd, qdd):
    """{'samples', 'valid', 'flags', 'branch', 'accuracy', 'worst'} of one motion."""
    valid, positions, torques, error = per_sample(mech, q, qd, qdd)
    counts = {'samples': 0, 'valid': int(valid.sum()), 'flags': 0, 'branch': 0,
              'accuracy': 0, 'worst': 0.0}
    for offset in (0, 1, 2):
        part = slice(offset, None)
        solver = cog_id_ros.InverseDynamics(mech)
        ev = solver.evaluate(q[part], qd[part], qdd[part], on_invalid='skip')
        ref_valid, ref_pos = valid[part], positions[part]
        if offset:          # the per-sample path from a fresh solver at this start
            ref_valid, ref_pos = per_sample(mech, q[part], qd[part], qdd[part])[:2]
        both = ev.valid & ref_valid
        counts['samples'] += len(ev.valid)
        counts['flags'] += int((ev.valid != ref_valid).sum())
        apart = np.abs(ev.positions - ref_pos).max(axis=1)
        counts['branch'] += int((apart[both] > SAME).sum())
        try:
            at = cog_id_ros.InverseDynamics(mech).solve_positions(q[part])
            counts['branch'] += int((np.abs(at - ref_pos).max(axis=1)[both] > SAME).sum())
        except cog_id_ros.CogIdError:
            pass
    t_valid, t_pos, t_tau, t_err = per_sample(tight, q, qd, qdd)
    same = valid & t_valid & (np.abs(positions - t_pos).max(axis=1) <= SAME)
    scale = torque_scale(tight, q, qd, qdd)
    gap = np.abs(torques - t_tau).max(axis=1)
    with np.errstate(invalid='ignore'):
        ratio = np.where(same, gap / ((error + t_err) * scale), 0.0)
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    counts['accuracy'] = int((ratio > 1.0).sum())
    counts['worst'] = float(ratio.max(initial=0.0))
    return counts


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('names', nargs='*', help='config names or robots (default: all)')
    parser.add_argument('--quick', action='store_true', help='the examples, fewer motions')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    configs = sorted(os.path.basename(p)[:-5] for p in glob.glob(os.path.join(REPO, 'config',
                                                                               '*.yaml')))
    names = args.names or configs + ([] if args.quick else ROBOTS)
    warnings.simplefilter('ignore')
    rng = np.random.default_rng(args.seed)
    total = {'samples': 0, 'flags': 0, 'branch': 0, 'accuracy': 0}
    print(f'{"mechanism":22s} {"motion":7s} {"samples":>8s} {"valid":>6s} {"flags":>6s} '
          f'{"branch":>7s} {"accuracy":>9s} {"worst":>8s}  (error / estimate)')
    for name in names:
        began = time.time()
        mech, base_dir = load_config(name) if name in configs else load_robot(name)
        tight = tightened(mech, base_dir)
        for label, (q, qd, qdd) in motions(mech, base_dir, rng, args.quick).items():
            if len(q) < 3:
                continue
            c = sweep_one(mech, tight, q, qd, qdd)
            for key in total:
                total[key] += c[key]
            print(f'{name:22s} {label:7s} {c["samples"]:8d} {c["valid"]:6d} {c["flags"]:6d} '
                  f'{c["branch"]:7d} {c["accuracy"]:9d} {c["worst"]:8.2g}', flush=True)
        print(f'{"":22s} ({time.time() - began:.1f} s)')
    print(f'total: {total["samples"]} batch samples; valid in one path only: {total["flags"]}; '
          f'on another branch: {total["branch"]}; torques beyond the estimate: '
          f'{total["accuracy"]}')
    return 1 if total['flags'] or total['branch'] or total['accuracy'] else 0


if __name__ == '__main__':
    sys.exit(main())
