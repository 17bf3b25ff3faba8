"""Whole-body inverse dynamics beside the fixed-base torques of the same robot, one run.

    .venv/bin/python bench/bench_whole_body.py [--repeat 2000] [--batch 100]

config/digit_biped.yaml (12 motors, six loops, floating, two 6d feet): median wall time of
one sample of ``torques`` and of ``whole_body_torques`` (both feet in contact, and none),
interleaved in the same loop so that both see the same machine; then a batch of N of each.
Prints medians and the ratio; exits 1 if a call fails.
"""
import argparse
import os
import sys
import time
import warnings

import numpy as np

import cog_id_ros

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--repeat', type=int, default=2000)
    parser.add_argument('--batch', type=int, default=100)
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        mech = cog_id_ros.Mechanism.from_params_file(
            os.path.join(HERE, '..', 'config', 'digit_biped.yaml'))
    solver = cog_id_ros.InverseDynamics(mech)
    theta = [mech.assembled_positions[j] for j in mech.active_index]
    rng = np.random.default_rng(0)
    rates = (0.1 * rng.normal(size=len(theta))).tolist()
    accelerations = rng.normal(size=len(theta)).tolist()
    pose = [0.0, 0.0, 0.67, 0.0, 0.0, 0.0, 1.0]
    twist = [0.1, 0.0, 0.0, 0.0, 0.2, 0.0]
    calls = {
        'torques': lambda: solver.torques(theta, rates, accelerations),
        'whole_body_torques, two feet': lambda: solver.whole_body_torques(
            pose, twist, twist, theta, rates, accelerations),
        'whole_body_torques, no contact': lambda: solver.whole_body_torques(
            pose, twist, twist, theta, rates, accelerations, contacts=[]),
    }
    times = {name: [] for name in calls}
    for name, call in calls.items():       # warm: kernels built or loaded
        call()
    for _ in range(args.repeat):
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            times[name].append(time.perf_counter() - start)
    print(f'backend {solver.backend}, {len(theta)} motors, {len(mech.links)} links; '
          f'median of {args.repeat} interleaved calls')
    base = np.median(times['torques'])
    for name, values in times.items():
        median = np.median(values)
        print(f'  {name:32s} {1e6 * median:9.1f} us   {median / base:6.1f} x torques')
    n = args.batch
    q, qd, qdd = (np.tile(v, (n, 1)) for v in (theta, rates, accelerations))
    poses, twists = np.tile(pose, (n, 1)), np.tile(twist, (n, 1))
    batch = {'torques': lambda: solver.torques(q, qd, qdd),
             'whole_body_torques, two feet': lambda: solver.whole_body_torques(
                 poses, twists, twists, q, qd, qdd)}
    print(f'batch of {n}, median of 20:')
    medians = {}
    for name, call in batch.items():
        values = []
        for _ in range(20):
            start = time.perf_counter()
            call()
            values.append(time.perf_counter() - start)
        medians[name] = np.median(values)
        print(f'  {name:32s} {1e3 * medians[name]:9.2f} ms   '
              f'{1e6 * medians[name] / n:7.1f} us a sample')
    return 0


if __name__ == '__main__':
    sys.exit(main())
