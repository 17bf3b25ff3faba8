"""The paper's example, defined once: its target motion, the exact torque, the config files.

Our reading of the paper's Fig. 2 and 3 (its figures are not in the text we have): three
identical uniform rods of ``L`` = 0.5 m and ``M`` = 1 kg with ground pivots 0.5 m apart, a
parallelogram, driven along the target motion

    theta(t) = pi/2 + 0.5 sin(pi t) rad,  t in [0, 2] s

by its crank (a, config/paper_four_bar_a.yaml) or by both cranks (b, redundant actuation,
config/paper_four_bar_b.yaml). ``config/paper_four_bar_target.csv`` is that motion at
1 kHz (2001 samples) for joint1 and joint3, with exact velocity and acceleration columns,
so the one file serves both (a ignores the joint1 columns with a note). It is written by

    python -m cog_id_ros.demos.paper_four_bar [--rate 1000] [--duration 2] [--output FILE]

Used by the demos (``fig4.py``, ``table.py``) and the benchmarks.
"""
import argparse
import math
import os
import sys

import numpy as np

from ..offline.trajectory_io import FIELDS, TIME, joint_column

#: the paper's links, our reading (see config/paper_four_bar_*.yaml): mass kg, length m, g
M, L, G = 1.0, 0.5, 9.81
#: the target motion's duration, s
DURATION = 2.0
#: the joints driven in config/paper_four_bar_target.csv (the two cranks)
JOINTS = ('joint1', 'joint3')
#: the source tree's config/ (an installed package: share/cog_id_ros/config, see config_dir)
SOURCE_CONFIG = os.path.join(
    os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), 'config')
DEFAULT_OUTPUT = os.path.join(SOURCE_CONFIG, 'paper_four_bar_target.csv')


def target_motion(t):
    """theta, theta_dot, theta_ddot (rad, rad/s, rad/s^2) of the target motion at times t (s)."""
    t = np.asarray(t, dtype=float)
    w = math.pi
    theta = math.pi / 2 + 0.5 * np.sin(w * t)
    # + 0.0 turns -0.0 into 0.0 (cosmetic: the file shows 0.0 at t = 0)
    return theta + 0.0, 0.5 * w * np.cos(w * t) + 0.0, -0.5 * w * w * np.sin(w * t) + 0.0


def exact_torque(theta, thetaddot):
    """The single actuator's torque of the parallelogram (a), N m:
    tau3 = (5/3) M L^2 thetaddot + 2 M G L cos(theta); (b) puts half of it on each crank."""
    return (5.0 / 3.0) * M * L * L * thetaddot + 2.0 * M * G * L * np.cos(theta)


def config_dir():
    """config/ of a source checkout, else the installed share/cog_id_ros/config."""
    if os.path.isdir(SOURCE_CONFIG):
        return SOURCE_CONFIG
    try:
        from ament_index_python.packages import get_package_share_directory
        return os.path.join(get_package_share_directory('cog_id_ros'), 'config')
    except Exception:  # noqa: BLE001 - no ament index either: report the source path
        return SOURCE_CONFIG


def write_csv(path, t, joints=JOINTS, fields=FIELDS, block=100_000):
    """Write the target motion at times ``t`` for ``joints`` with the given columns.

    Values are written with ``repr`` (full precision), ``block`` rows at a time so that a
    million-row file needs little memory."""
    t = np.asarray(t, dtype=float)
    header = [TIME] + [joint_column(j, f) for j in joints for f in fields]
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
    parser = argparse.ArgumentParser(
        prog='python -m cog_id_ros.demos.paper_four_bar',
        description="Write the paper's target motion as a trajectory CSV (default: "
                    'config/paper_four_bar_target.csv).')
    parser.add_argument('--rate', type=float, default=1000.0, help='samples per second')
    parser.add_argument('--duration', type=float, default=DURATION, help='seconds')
    parser.add_argument('--output', default=DEFAULT_OUTPUT)
    args = parser.parse_args(argv)
    n = int(round(args.duration * args.rate)) + 1
    t = np.arange(n) / args.rate       # exact multiples: 0.001 is written as 0.001
    write_csv(args.output, t)
    print(f'wrote {os.path.normpath(args.output)}: {n} samples', file=sys.stderr)


if __name__ == '__main__':
    main()
