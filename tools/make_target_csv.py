#!/usr/bin/env python3
"""Write config/paper_four_bar_target.csv: the paper's target motion, sampled at 1 kHz.

    theta(t) = pi/2 + 0.5 sin(pi t) rad,  t in [0, 2] s  (2001 samples)

Both cranks follow it (joint1 and joint3), with exact velocity and acceleration columns,
so the one file serves paper_four_bar_a (active joint3; the joint1 columns are ignored
with a note) and paper_four_bar_b (active joint1 and joint3). In the parallelogram the
two cranks stay parallel, so the redundant setpoint of (b) is consistent.

    python tools/make_target_csv.py [--rate 1000] [--duration 2] [--output FILE]

Also importable: ``target_motion(t)`` and ``write_csv(path, t)`` are used by the tests
and the benchmark.
"""
import argparse
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_OUTPUT = os.path.join(HERE, '..', 'config', 'paper_four_bar_target.csv')
JOINTS = ('joint1', 'joint3')


def target_motion(t):
    """theta, theta_dot, theta_ddot of the paper's target motion at times t (s)."""
    t = np.asarray(t, dtype=float)
    w = math.pi
    theta = math.pi / 2 + 0.5 * np.sin(w * t)
    # + 0.0 turns -0.0 into 0.0 (cosmetic: the file shows 0.0 at t = 0)
    return theta + 0.0, 0.5 * w * np.cos(w * t) + 0.0, -0.5 * w * w * np.sin(w * t) + 0.0


def write_csv(path, t, joints=JOINTS, fields=('position', 'velocity', 'acceleration'),
              block=100_000):
    """Write the target motion at times ``t`` for ``joints`` with the given columns.

    Values are written with ``repr`` (full precision), ``block`` rows at a time so that a
    million-row file needs little memory."""
    t = np.asarray(t, dtype=float)
    header = ['time'] + [f'{j}.{f}' for j in joints for f in fields]
    with open(path, 'w', encoding='utf-8', newline='') as out:
        out.write(','.join(header) + '\n')
        for start in range(0, t.size, block):
            tb = t[start:start + block]
            theta, dtheta, ddtheta = target_motion(tb)
            values = {'position': theta, 'velocity': dtheta, 'acceleration': ddtheta}
            cols = [list(map(repr, tb.tolist()))]
            for _ in joints:
                for f in fields:
                    cols.append(list(map(repr, values[f].tolist())))
            out.write('\n'.join(map(','.join, zip(*cols))) + '\n')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='samples per second')
    parser.add_argument('--duration', type=float, default=2.0, help='seconds')
    parser.add_argument('--output', default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    n = int(round(args.duration * args.rate)) + 1
    t = np.arange(n) / args.rate       # exact multiples: 0.001 is written as 0.001
    write_csv(args.output, t)
    print(f'wrote {os.path.normpath(args.output)}: {n} samples', file=sys.stderr)


if __name__ == '__main__':
    main()
