"""Speed of the core: one-sample latency and batch throughput of InverseDynamics.torques.

    ./dev bench            (or: .venv/bin/python bench/bench_core.py)

For each mechanism: the median time of one single-sample call (successive setpoints along a
smooth motion at 1 kHz, as a control loop would call it) and the throughput of one call on
10,000 samples. The single-sample time is measured for ``backend='python'`` (traced
straight-line kernels, what 'auto' picks) and, in alternating blocks of 500 setpoints on a
second solver, for ``backend='reference'`` (the lane code on floats). Redundantly actuated
mechanisms (paper_four_bar_b, five_bar_redundant) run through the same kernels; the last
column is each mechanism's single-sample time over paper_four_bar_a's.
Targets (2-core machine): four-bar single sample < 50 us, batch > 200,000 samples/s,
redundant mechanisms within 2x of paper_four_bar_a.
"""
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))
import cog_id_ros  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')


def motion(mech, n, duration):
    """A smooth motion around the assembled pose: each actuator swings by 0.2 rad (or m/10)."""
    t = np.linspace(0.0, duration, n)
    start = np.array([mech.assembled_positions[j] for j in mech.active_index])
    if mech.is_redundant:  # keep redundant setpoints consistent: take them from the closure
        params = {k: v for k, v in mech.parameters.items() if k != 'mechanism.torque_weights'}
        params['mechanism.active_joints'] = [mech.active_joints[i] for i in mech.primary]
        solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params))
        primary = start[mech.primary][None, :] + 0.2 * np.sin(np.pi * t)[:, None]
        q = solver.solve_positions(primary)[:, mech.active_index]
    else:
        q = start[None, :] + 0.2 * np.sin(np.pi * t)[:, None] * (1 + np.arange(len(start)))[None, :] / len(start)
    qd = np.gradient(q, t, axis=0)
    return q, qd, np.gradient(qd, t, axis=0)


def bench(path, repeats=5):
    mech = cog_id_ros.Mechanism.from_params_file(path)
    q, qd, qdd = motion(mech, 10_000, 10.0)      # 1 kHz
    solver = cog_id_ros.InverseDynamics(mech, backend='python')
    general = cog_id_ros.InverseDynamics(mech, backend='reference')
    samples, general_samples = [], []
    for block in range(6):          # alternate blocks of 500 setpoints between the two paths
        for i in range(500 * block, 500 * (block + 1)):
            t0 = time.perf_counter()
            solver.torques(q[i], qd[i], qdd[i])
            samples.append(time.perf_counter() - t0)
        for i in range(500 * block, 500 * (block + 1)):
            t0 = time.perf_counter()
            general.torques(q[i], qd[i], qdd[i])
            general_samples.append(time.perf_counter() - t0)
    single = statistics.median(samples[100:]), statistics.median(general_samples[100:])
    rates = []
    for _ in range(repeats):
        solver.reset()
        t0 = time.perf_counter()
        solver.torques(q, qd, qdd)
        rates.append(len(q) / (time.perf_counter() - t0))
    return mech, single, statistics.median(rates)


def main():
    names = [n for n in ('paper_four_bar_a', 'paper_four_bar_b', 'slider_crank', 'five_bar',
                         'five_bar_redundant', 'spatial_rsur') if os.path.exists(os.path.join(ROOT, 'config', n + '.yaml'))]
    print('command: ./dev bench   (bench/bench_core.py)')
    print(f"{'mechanism':22s} {'joints':>6} {'DOF':>4} {'M':>3} {'python [us]':>12} "
          f"{'reference [us]':>15} {'ratio':>6} {'batch [samples/s]':>18} {'vs (a)':>7}")
    first = None
    for name in names:
        mech, (single, general), rate = bench(os.path.join(ROOT, 'config', name + '.yaml'))
        first = first or single
        print(f'{name:22s} {len(mech.joints):6d} {mech.dof:4d} {len(mech.active_joints):3d} '
              f'{single * 1e6:12.1f} {general * 1e6:15.1f} {general / single:6.1f} {rate:18,.0f} '
              f'{single / first:7.2f}', flush=True)


if __name__ == '__main__':
    main()
