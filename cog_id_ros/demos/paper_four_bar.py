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
#: the package's own directory (cog_id_ros/)
PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: the source tree's config/ (an installed package: share/cog_id_ros/config, see config_dir)
SOURCE_CONFIG = os.path.join(os.path.dirname(PACKAGE_DIR), 'config')
#: the files a directory must hold to be the demos' config directory
DEMO_FILES = ('paper_four_bar_a.yaml', 'paper_four_bar_b.yaml')
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


class ConfigNotFound(FileNotFoundError):
    """None of the places :func:`config_dir` looks in holds the demos' config files; the
    message is one line naming every place."""


def config_places():
    """Where :func:`config_dir` looks, in this order (docs/node.md, "Installing with pip"):
    ``(directory, None)`` per place, or ``(None, why)`` for the ament index when it has no
    answer.

    1. ``config/`` of a source checkout (the package's parent directory): ``./dev``, an
       editable install;
    2. ``share/cog_id_ros/config`` beside the package: ``pip install --target T`` puts the
       package in ``T/cog_id_ros`` and the data files in ``T/share/cog_id_ros``;
    3. ``<sys.prefix>/share/cog_id_ros/config``: ``pip install`` into the running
       interpreter's environment (a venv, or the system's);
    4. the ament index: ``share/cog_id_ros/config`` of the prefix in ``AMENT_PREFIX_PATH``
       that has the package (a colcon workspace, sourced).
    """
    places = []
    for directory in (SOURCE_CONFIG,
                      os.path.join(os.path.dirname(PACKAGE_DIR), 'share', 'cog_id_ros',
                                   'config'),
                      os.path.join(sys.prefix, 'share', 'cog_id_ros', 'config')):
        if (directory, None) not in places:
            places.append((directory, None))
    try:
        from ament_index_python.packages import get_package_share_directory
        places.append((os.path.join(get_package_share_directory('cog_id_ros'), 'config'),
                       None))
    except ImportError:
        places.append((None, 'the ament index (ament_index_python is not installed)'))
    except Exception as exc:  # noqa: BLE001 - no AMENT_PREFIX_PATH, or no package in it
        why = exc.args[0] if exc.args else exc          # a KeyError's text, unquoted
        places.append((None, f'the ament index ({why})'))
    return places


def config_dir():
    """The directory holding the demos' config files (DEMO_FILES): the first of
    :func:`config_places` that has them all. Raises :class:`ConfigNotFound` otherwise."""
    places = config_places()
    for directory, _ in places:
        if directory is not None and all(os.path.isfile(os.path.join(directory, name))
                                         for name in DEMO_FILES):
            return directory
    looked = '; '.join(directory or why for directory, why in places)
    raise ConfigNotFound(f"cannot find the demo's config files ({', '.join(DEMO_FILES)}): "
                         f'looked in {looked}')


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
