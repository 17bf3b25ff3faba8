"""Speed of the core: one-sample latency and batch throughput of InverseDynamics.torques.

    ./dev bench            (or: .venv/bin/python bench/bench_core.py)

For each mechanism: the median time of one single-sample call (successive setpoints along a
smooth motion at 1 kHz, as a control loop would call it) and the throughput of one call on
10,000 samples. The single-sample time is measured for each backend ('native' where a C
compiler is there, 'python', 'reference'), in alternating blocks of 500 setpoints, on one
solver each; the batch with the first. Redundantly actuated mechanisms (paper_four_bar_b,
five_bar_redundant) run through the same kernels; the last column is each mechanism's
single-sample time over paper_four_bar_a's (first backend).
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


def bench(path, backends, repeats=5):
    """Median single-sample time per backend (interleaved blocks of 500 setpoints), and the
    batch rate of the first backend."""
    mech = cog_id_ros.Mechanism.from_params_file(path)
    q, qd, qdd = motion(mech, 10_000, 10.0)      # 1 kHz
    solvers = {b: cog_id_ros.InverseDynamics(mech, backend=b) for b in backends}
    samples = {b: [] for b in backends}
    for block in range(6):          # alternate blocks of 500 setpoints between the backends
        for b, solver in solvers.items():
            for i in range(500 * block, 500 * (block + 1)):
                t0 = time.perf_counter()
                solver.torques(q[i], qd[i], qdd[i])
                samples[b].append(time.perf_counter() - t0)
    single = {b: statistics.median(times[100:]) for b, times in samples.items()}
    rates = []
    first = solvers[backends[0]]
    for _ in range(repeats):
        first.reset()
        t0 = time.perf_counter()
        first.torques(q, qd, qdd)
        rates.append(len(q) / (time.perf_counter() - t0))
    return mech, single, statistics.median(rates)


def main():
    names = [n for n in ('paper_four_bar_a', 'paper_four_bar_b', 'slider_crank', 'five_bar',
                         'five_bar_redundant', 'spatial_rsur', 'stewart_6ups', 'delta_3rus')
             if os.path.exists(os.path.join(ROOT, 'config', n + '.yaml'))]
    probe = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(
        os.path.join(ROOT, 'config', names[0] + '.yaml')))
    backends = ['native', 'python', 'reference'] if probe.backend == 'native' else \
        ['python', 'reference']
    print('command: ./dev bench   (bench/bench_core.py); one sample [us] per backend, '
          f'batch of 10,000 with {backends[0]}')
    print(f"{'mechanism':22s} {'joints':>6} {'DOF':>4} {'M':>3} " +
          ' '.join(f'{b:>10s}' for b in backends) +
          f" {'batch [samples/s]':>18} {'vs (a)':>7}")
    first = None
    for name in names:
        mech, single, rate = bench(os.path.join(ROOT, 'config', name + '.yaml'), backends)
        first = first or single[backends[0]]
        print(f'{name:22s} {len(mech.joints):6d} {mech.dof:4d} {len(mech.active_joints):3d} ' +
              ' '.join(f'{single[b] * 1e6:10.1f}' for b in backends) +
              f' {rate:18,.0f} {single[backends[0]] / first:7.2f}', flush=True)


if __name__ == '__main__':
    main()
