"""Every number the solver gives on every example, saved to compare bit for bit after a change.

    .venv/bin/python bench/fingerprint.py --save /tmp/before      # before the change
    .venv/bin/python bench/fingerprint.py --compare /tmp/before   # after: exit 1 on any bit

A redesign that must keep "behaviour and numbers exactly as they are" is checked with it:
for every parameter file in config/ and every backend ('reference', 'python', 'native'
where a compiler is there), along the file's test motion (test/trajectories.py; the
parallel robots without one: their initial pose plus a small sinusoid per actuator), it
records the batch torques, the torques sample by sample (warm-started, as the node calls
``sample_torques``), the joint states the node would publish after each sample
(``last_pose`` with the rates), H and B of eq. (7) in a batch, and every joint's position
in a batch. Comparison is exact (NaN equal to NaN), not within a tolerance.
"""
import argparse
import glob
import os
import sys
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, REPO)
sys.path.insert(0, os.path.join(REPO, 'test'))

import cog_id_ros  # noqa: E402

SAMPLES = 201


def motion(name, mech):
    """(q, qd, qdd) of config ``name``: its test motion, else a small sinusoid."""
    try:
        import trajectories
        if name in trajectories.TRAJECTORIES:
            return trajectories.sample(name, SAMPLES)[1:]
    except Exception:   # noqa: BLE001 (Pinocchio missing for a redundant motion: synthetic)
        pass
    t = np.linspace(0.0, 2.0, SAMPLES)[:, None]
    start = np.array([mech.assembled_positions[mech.joints.index(j)]
                      for j in mech.active_joints])[None, :]
    w = np.pi * (1.0 + 0.25 * np.arange(start.shape[1]))[None, :]
    amplitude = 0.02
    return (start + amplitude * np.sin(w * t), amplitude * w * np.cos(w * t),
            -amplitude * w * w * np.sin(w * t))


def record(name, backend):
    """{key: array} of config ``name`` on ``backend``."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        mech = cog_id_ros.Mechanism.from_params_file(os.path.join(REPO, 'config', name))
    q, qd, qdd = motion(name, mech)
    out = {}
    solver = cog_id_ros.InverseDynamics(mech, backend=backend)
    out['torques_batch'] = solver.torques(q, qd, qdd)
    solver = cog_id_ros.InverseDynamics(mech, backend=backend)
    per_sample, positions, rates = [], [], []
    for row in range(len(q)):
        per_sample.append(solver.sample_torques(q[row].tolist(), qd[row].tolist(),
                                                qdd[row].tolist()))
        pose, qdot = solver.last_pose(qd[row].tolist())
        positions.append(pose)
        rates.append(qdot)
    out['torques_per_sample'] = np.array(per_sample)
    out['joint_states_position'] = np.array(positions)
    out['joint_states_velocity'] = np.array(rates)
    solver = cog_id_ros.InverseDynamics(mech, backend=backend)
    h, b = solver.equation_of_motion(q, qd)
    out['H'], out['B'] = h, b
    solver = cog_id_ros.InverseDynamics(mech, backend=backend)
    out['positions_batch'] = solver.solve_positions(q)
    return out, solver.backend


def every_record():
    for path in sorted(glob.glob(os.path.join(REPO, 'config', '*.yaml'))):
        name = os.path.basename(path)
        for backend in ('reference', 'python', 'native'):
            try:
                values, used = record(name, backend)
            except cog_id_ros.MechanismConfigError as exc:
                if backend == 'native':     # no compiler here: nothing to compare
                    print(f'{name} native: skipped ({exc})')
                    continue
                raise
            yield f'{name}:{used}', values


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    action = parser.add_mutually_exclusive_group(required=True)
    action.add_argument('--save', metavar='DIR')
    action.add_argument('--compare', metavar='DIR')
    args = parser.parse_args(argv)
    differences = 0
    count = 0
    new = []
    for key, values in every_record():
        file = os.path.join(args.save or args.compare, key.replace(':', '__') + '.npz')
        if args.save:
            count += 1
            os.makedirs(args.save, exist_ok=True)
            np.savez(file, **values)
            continue
        if not os.path.exists(file):        # an example added since the save: nothing to
            new.append(key)                 # compare it with
            continue
        count += 1
        with np.load(file) as before:
            for field, now in values.items():
                then = before[field]
                same = then.shape == now.shape and np.array_equal(then, now, equal_nan=True)
                if not same:
                    differences += 1
                    worst = (np.nanmax(np.abs(then - now)) if then.shape == now.shape
                             else f'shape {then.shape} -> {now.shape}')
                    print(f'DIFFERENT {key} {field}: largest difference {worst}')
    verb = 'saved' if args.save else 'compared'
    print(f'{count} records {verb}' + ('' if args.save else f', {differences} different')
          + (f"; {len(new)} new, not saved before: {', '.join(new)}" if new else ''))
    return 1 if differences else 0


if __name__ == '__main__':
    sys.exit(main())
