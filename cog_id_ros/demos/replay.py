"""The paper's Fig. 4 torques replayed reproduce its Fig. 3 motion: ``cog_id_torques``, then
``cog_id_simulate``, on the four-bar (a) (one actuator) and (b) (both cranks).

    ./dev replay [--output-dir out] [--time-step 0.001]
    python -m cog_id_ros.demos.replay [--output-dir out] [--time-step 0.001]

For each case it runs, as a user would (the commands are printed)::

    cog_id_torques  --params-file paper_four_bar_X.yaml --input paper_four_bar_target.csv \\
                    --output replay_X_torques.csv
    cog_id_simulate --params-file paper_four_bar_X.yaml --input replay_X_torques.csv \\
                    --initial-state paper_four_bar_target.csv --between-rows linear \\
                    --output replay_X_motion.csv --reference paper_four_bar_target.csv \\
                    --plot replay_X.png

and compares the replayed crank angles with the target motion against :func:`error_bound`.
It also replays (a) with the efforts held from their own time on (``--between-rows hold``),
for the record: the upright parallelogram is open-loop unstable, and that half-step lag
makes it fall away (the line says by how much; it does not decide the status).

Exit status: 0 every replayed angle within the bound; 1 one is not, or a tool failed (its
message is printed); 2 the config files are in none of the places looked in (one line
naming them).
"""
import argparse
import math
import os
import subprocess
import sys
from typing import Sequence

import numpy as np

from ..offline import trajectory_io
from .paper_four_bar import (
    DURATION,
    ConfigNotFound,
    G,
    L,
    M,
    config_dir,
    target_motion,
    write_csv,
)

#: the target motion's file, beside the parameter files
TARGET_FILE = 'paper_four_bar_target.csv'
#: the parallelogram's inertia about a crank, kg m^2: tau = I thetaddot + 2 M G L cos(theta)
INERTIA = 5.0 / 3.0 * M * L * L
#: the largest growth rate of a deviation, 1/s: the linearised e'' = (2 M G L sin(theta) / I) e
#: with sin(theta) <= 1
GROWTH = math.sqrt(2.0 * M * G * L / INERTIA)
CASES = (('a', ('joint3',)), ('b', ('joint1', 'joint3')))
FAILED = 1
NOT_FOUND = 2


def torque_derivatives(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|tau'| and |tau''| of the exact torque tau(t) = I theta'' + 2 M G L cos(theta) along the
    target motion theta = pi/2 + 0.5 sin(pi t), analytically."""
    w = math.pi
    th, th1, th2 = target_motion(t)
    th3, th4 = -0.5 * w ** 3 * np.cos(w * t), 0.5 * w ** 4 * np.sin(w * t)
    k = 2.0 * M * G * L
    d1 = INERTIA * th3 - k * np.sin(th) * th1
    d2 = INERTIA * th4 - k * (np.cos(th) * th1 ** 2 + np.sin(th) * th2)
    return np.abs(d1), np.abs(d2)


def error_bound(h: float, duration: float = DURATION) -> float:
    """The largest crank-angle error (rad) a replay with ``--between-rows linear`` and steps of
    ``h`` s can make over ``duration``, from the step size alone.

    Each step holds the mean of the straight line between two torque samples, which differs
    from the mean of the true torque over the step by at most h^2/12 max|tau''| (the
    trapezoid rule's error): an acceleration error f <= h^2/12 max|tau''| / I. The torque
    also varies within the step while the held one does not: that moves the crank by at most
    h^3/12 max|tau'| / I per step (its velocity not at all, to this order). A deviation e of
    the upright parallelogram grows as e'' = (2 M G L sin(theta) / I) e <= GROWTH^2 e (it has
    no velocity terms), so from e(0) = e'(0) = 0 the first makes at most
    f (cosh(GROWTH T) - 1) / GROWTH^2, and the per-step offsets at most
    (h^2/12 max|tau'| / I) sinh(GROWTH T) / GROWTH. RK4's own error (h^4) and the closure
    (1e-10) are far below. The bound is second order in h: halve the step, quarter it."""
    t = np.linspace(0.0, duration, 20001)
    d1, d2 = (float(d.max()) for d in torque_derivatives(t))
    grown = GROWTH * duration
    return h * h / (12.0 * INERTIA) * (d2 * (math.cosh(grown) - 1.0) / GROWTH ** 2
                                      + d1 * math.sinh(grown) / GROWTH)


def tool(name: str) -> list[str]:
    """The command of a console tool (its module, with this interpreter)."""
    module = {'cog_id_torques': 'cli', 'cog_id_simulate': 'simulate'}[name]
    return [sys.executable, '-m', f'cog_id_ros.offline.{module}']


def run_tool(name: str, args: list[str]) -> int:
    """Run a tool; print its command (as a user types it) and its output; its exit status."""
    shown = [os.path.relpath(a) if os.path.isabs(a) else a for a in args]
    print('$ ' + ' '.join([name] + shown), flush=True)
    proc = subprocess.run(tool(name) + args, capture_output=True, text=True)
    text = (proc.stdout + proc.stderr).strip()
    if text:
        print('  ' + text.replace('\n', '\n  '), flush=True)
    return proc.returncode


def target_file(configs: str, out: str, h: float) -> str:
    """The target motion sampled every ``h`` s: config/paper_four_bar_target.csv for 1 ms,
    else written to ``out`` (the bound assumes torque rows one step apart)."""
    if h == 0.001:
        return os.path.join(configs, TARGET_FILE)
    path = os.path.join(out, f'replay_target_{h:g}.csv')
    write_csv(path, np.arange(int(round(DURATION / h)) + 1) * h)
    return path


def replay(case: str, target: str, configs: str, out: str, h: float, between: str = 'linear',
           plot: bool = True) -> str | None:
    """Run the two tools for ``case``; the replayed motion's CSV, or None when one failed."""
    params = os.path.join(configs, f'paper_four_bar_{case}.yaml')
    torques = os.path.join(out, f'replay_{case}_torques.csv')
    motion = os.path.join(out, f'replay_{case}_motion' + ('' if between == 'linear' else
                                                          '_' + between) + '.csv')
    if run_tool('cog_id_torques', ['--params-file', params, '--input', target,
                                   '--output', torques]):
        return None
    args = ['--params-file', params, '--input', torques, '--initial-state', target,
            '--between-rows', between, '--time-step', repr(h), '--output', motion,
            '--reference', target] + (['--plot', os.path.join(out, f'replay_{case}.png')]
                                      if plot else [])
    return None if run_tool('cog_id_simulate', args) else motion


def crank_angle(motion: str, joint: str = 'joint3') -> tuple[np.ndarray, np.ndarray]:
    """(time, the crank angle) of a motion CSV."""
    header, t, values = trajectory_io.read_efforts(motion)
    return t, values[:, header.index(f'{joint}.position') - 1]


def draw(path: str, linear: str, held: str | None, h: float) -> None:
    """The picture: the target, the replays (``linear``, ``held``: motion CSVs of (a), held
    may be None) and their errors against the bound, on a log scale."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(11.0, 4.0), layout='constrained')
    left, right = fig.subplots(1, 2)
    t, theta = crank_angle(linear)
    exact = target_motion(t)[0]
    left.plot(t, exact, color='k', lw=3.0, alpha=0.25, label='target (Fig. 3)')
    left.plot(t, theta, color='C0', lw=1.3, label='replayed, --between-rows linear')
    right.semilogy(t[1:], np.abs(theta - exact)[1:], color='C0', label='linear')
    if held is not None:
        th, theta_h = crank_angle(held)
        left.plot(th, theta_h, color='C3', lw=1.0, ls='--',
                  label='replayed, --between-rows hold')
        right.semilogy(th[1:], np.abs(theta_h - target_motion(th)[0])[1:], color='C3', ls='--',
                       label='hold')
    grid = np.linspace(0.0, t[-1], 101)[1:]
    right.semilogy(grid, [error_bound(h, x) for x in grid], color='k', lw=1.0, ls=':',
                   label=f'bound for {h:g} s steps (error_bound)')
    left.set_ylim(exact.min() - 0.4, exact.max() + 0.4)
    left.set(xlabel='time  [s]', ylabel='crank angle joint3  [rad]')
    right.set(xlabel='time  [s]', ylabel='|replayed - target|  [rad]')
    for ax in (left, right):
        ax.grid(True, color='0.9', lw=0.6)
        ax.legend(fontsize='small', frameon=False, loc='lower left' if ax is left else 'best')
    fig.suptitle('Paper four-bar (a): the Fig. 4 torques (cog_id_torques) replayed by '
                 f'cog_id_simulate in steps of {h:g} s')
    fig.savefig(path, dpi=100)


def angle_errors(motion: str, joints: Sequence[str]) -> list[tuple[float, float]]:
    """(max |replayed - target|, its time) per joint of a motion CSV."""
    header, t, values = trajectory_io.read_efforts(motion)
    exact = target_motion(t)[0]
    out = []
    for joint in joints:
        err = np.abs(values[:, header.index(f'{joint}.position') - 1] - exact)
        k = int(np.argmax(err))
        out.append((float(err[k]), float(t[k])))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='python -m cog_id_ros.demos.replay',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--output-dir', default='out', help='where the files go (default out)')
    parser.add_argument('--time-step', type=float, default=0.001,
                        help="the simulation step and the torque samples' spacing, s (default "
                             '0.001: config/paper_four_bar_target.csv; another step writes the '
                             'target motion at that rate to the output directory)')
    args = parser.parse_args(argv)
    try:
        configs = config_dir()
    except ConfigNotFound as exc:
        print(f'{parser.prog}: {exc}', file=sys.stderr)
        return NOT_FOUND
    if not os.path.isfile(os.path.join(configs, TARGET_FILE)):
        print(f'{parser.prog}: {os.path.join(configs, TARGET_FILE)} is missing', file=sys.stderr)
        return NOT_FOUND
    os.makedirs(args.output_dir, exist_ok=True)
    bound = error_bound(args.time_step)
    target = target_file(configs, args.output_dir, args.time_step)
    rows, ok = [], True
    for case, joints in CASES:
        motion = replay(case, target, configs, args.output_dir, args.time_step)
        if motion is None:
            return FAILED
        for joint, (err, at) in zip(joints, angle_errors(motion, joints)):
            ok &= err <= bound
            where = f'({case})   {joint}  {err:9.3g} rad at t = {at:.4g} s'
            rows.append(f'{where:<46}{bound:9.3g} rad  {"yes" if err <= bound else "NO"}')
    held = replay('a', target, configs, args.output_dir, args.time_step, between='hold',
                  plot=False)
    picture = os.path.join(args.output_dir, 'replay.png')
    draw(picture, os.path.join(args.output_dir, 'replay_a_motion.csv'), held, args.time_step)
    print(f'\nthe Fig. 4 torques replayed in steps of {args.time_step:g} s (--between-rows '
          'linear) against the Fig. 3 motion (picture: ' + picture + '):\n'
          'case  joint   max |replayed - target|       bound      within')
    print('\n'.join(rows))
    if held is not None:
        err, at = angle_errors(held, ('joint3',))[0]
        print(f'(a) with --between-rows hold (each torque from its own time on, half a step '
              f'late): {err:.3g} rad at t = {at:.4g} s: the upright parallelogram falls away')
    return 0 if ok else FAILED


if __name__ == '__main__':
    sys.exit(main())
