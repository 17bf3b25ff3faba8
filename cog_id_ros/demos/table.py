"""Torques of the paper's four-bar, (a) one actuator and (b) two, along the target motion.

    cog_id_demo [--step 0.1]
    python -m cog_id_ros.demos.table [--step 0.1]

Prints a table; the mechanism files are config/paper_four_bar_a.yaml and _b.yaml, found
by :func:`~cog_id_ros.demos.paper_four_bar.config_dir` (a source checkout's config/, else
the installed share/cog_id_ros/config).

Exit status: 0 the table printed; 2 the config files are in none of the places looked in
(one line naming them).
"""
import argparse
import os
import sys

import numpy as np

from .. import InverseDynamics, Mechanism
from .paper_four_bar import DURATION, ConfigNotFound, config_dir, target_motion


def paper_torques(t):
    """(tau_a (N,), tau_b (N, 2)) along the target motion at times t."""
    th, thd, thdd = target_motion(t)
    out = []
    for variant in ('a', 'b'):
        path = os.path.join(config_dir(), f'paper_four_bar_{variant}.yaml')
        mech = Mechanism.from_params_file(path)
        m = len(mech.active_joints)
        columns = (np.tile(x[:, None], (1, m)) for x in (th, thd, thdd))
        out.append(InverseDynamics(mech).torques(*columns))
    return out[0][:, 0], out[1]


def fixed(x, width, decimals=4):
    """``x`` in fixed point; a value that rounds to zero prints 0, never -0 (the torques at
    the turning points are a few 1e-16 either side of zero, and ``-0.0000`` reads as a
    sign that is not there)."""
    # round() gives the digits format() would print; adding 0.0 turns -0.0 into 0.0
    return f'{round(float(x), decimals) + 0.0:{width}.{decimals}f}'


def format_table(t, tau_a, tau_b):
    lines = ['paper four-bar (Sonoda, Ishii, Isobe), target motion theta = pi/2 + 0.5 sin(pi t)',
             f"{'t [s]':>6} {'theta [rad]':>12} | {'(a) tau3 [Nm]':>14} | "
             f"{'(b) tau1 [Nm]':>14} {'(b) tau3 [Nm]':>14}"]
    th = target_motion(t)[0]
    for time, theta, a, b1, b3 in zip(t, th, tau_a, tau_b[:, 0], tau_b[:, 1]):
        lines.append(f'{fixed(time, 6, 2)} {fixed(theta, 12)} | {fixed(a, 14)} | '
                     f'{fixed(b1, 14)} {fixed(b3, 14)}')
    lines.append(f'peak |tau|: (a) {np.max(np.abs(tau_a)):.4f} Nm; (b) '
                 f'{np.max(np.abs(tau_b[:, 0])):.4f} / {np.max(np.abs(tau_b[:, 1])):.4f} Nm '
                 f'(the minimum-norm pair: each crank carries half of (a))')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--step', type=float, default=0.1, help='table time step, s (default 0.1)')
    args = parser.parse_args(argv)
    t = np.arange(0.0, DURATION + 1e-9, args.step)
    try:
        torques = paper_torques(t)
    except ConfigNotFound as exc:
        print(f'{parser.prog}: {exc}', file=sys.stderr)
        return 2
    print(format_table(t, *torques))
    return 0


if __name__ == '__main__':
    sys.exit(main())
