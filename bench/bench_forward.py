"""Speed of forward dynamics and of the simulator, side by side with InverseDynamics.torques.

    .venv/bin/python bench/bench_forward.py          (also run by ./dev bench)
    .venv/bin/python bench/bench_forward.py paper_four_bar_a stewart_6ups   (only these)

For each example mechanism (config/*.yaml) and backend ('native' where a C compiler is
there, and 'python'):

* one sample: the median time of ``torques(q, qd, qdd)`` and of ``forward_dynamics(q, qd,
  tau)`` along the same smooth motion at 1 kHz (bench_core.motion; tau its torques), each
  call warm-started from the previous one as a control loop calls them, in alternating
  blocks of 250 samples; and their ratio (target: at most 2);
* a batch of 10,000 samples: samples per second of each, and their ratio;
* the simulator at 1 ms steps, as fast as possible: the motion's torques replayed for one
  simulated second from its first sample (efforts held over each step; 0.2 s with the
  Python kernels), three runs: the median step time, the real-time factor it makes (time
  step over median step), and the best run's simulated time over the processor time it
  took and over its wall time (targets: at least 50 on the paper four-bar, 5 on the
  Stewart platform). On a shared machine the wall clock counts the time other processes
  had the processor; the processor time is what one free core would take.
"""
import glob
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, HERE)
from bench_core import motion  # noqa: E402

import cog_id_ros  # noqa: E402

BLOCK = 250
STEP = 0.001


def per_sample(mech, backend, q, qd, qdd):
    """Median seconds of one torques() and one forward_dynamics() call, and the torques."""
    ids, fds = cog_id_ros.InverseDynamics(mech, backend), cog_id_ros.InverseDynamics(mech, backend)
    tau = ids.torques(q, qd, qdd)
    ids.reset()
    times = {'torques': [], 'forward': []}
    rows = [(q[i].tolist(), qd[i].tolist(), qdd[i].tolist(), tau[i].tolist())
            for i in range(len(q))]
    for block in range(0, len(rows), BLOCK):
        for i in range(block, min(block + BLOCK, len(rows))):
            qi, qdi, qddi, _ = rows[i]
            t0 = time.perf_counter()
            ids.torques(qi, qdi, qddi)
            times['torques'].append(time.perf_counter() - t0)
        for i in range(block, min(block + BLOCK, len(rows))):
            qi, qdi, _, taui = rows[i]
            t0 = time.perf_counter()
            fds.forward_dynamics(qi, qdi, taui)
            times['forward'].append(time.perf_counter() - t0)
    return {k: statistics.median(v[BLOCK // 2:]) for k, v in times.items()}, tau


def batch(mech, backend, q, qd, qdd, tau, repeats=3):
    """Samples per second of torques() and forward_dynamics() on the whole motion."""
    solver = cog_id_ros.InverseDynamics(mech, backend)
    rates = {'torques': [], 'forward': []}
    for _ in range(repeats):
        for name, call in (('torques', lambda: solver.torques(q, qd, qdd)),
                           ('forward', lambda: solver.forward_dynamics(q, qd, tau))):
            solver.reset()
            t0 = time.perf_counter()
            call()
            rates[name].append(len(q) / (time.perf_counter() - t0))
    return {k: statistics.median(v) for k, v in rates.items()}


def simulate(mech, backend, q, qd, tau, steps, runs=3):
    """(median step time, best real-time factors of ``runs`` runs by processor time and by
    wall time) replaying ``tau`` at 1 ms steps from the motion's first sample (positions
    ``q[0]``, velocities ``qd[0]``)."""
    sim = cog_id_ros.Simulation(mech, STEP, backend)
    efforts = tau.tolist()
    times, cpu, wall = [], [], []
    for _ in range(runs):
        sim.reset(q[0], qd[0])
        start, start_cpu = time.perf_counter(), time.thread_time()
        for i in range(steps):
            t0 = time.perf_counter()
            sim.step(efforts[i])
            times.append(time.perf_counter() - t0)
        cpu.append(sim.time / (time.thread_time() - start_cpu))
        wall.append(sim.time / (time.perf_counter() - start))
    return statistics.median(times), max(cpu), max(wall)


def main(names=()):
    paths = sorted(glob.glob(os.path.join(HERE, '..', 'config', '*.yaml')))
    if names:
        paths = [p for p in paths if os.path.basename(p)[:-len('.yaml')] in names]
    probe = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(paths[0]))
    backends = ['native', 'python'] if probe.backend == 'native' else ['python']
    print('command: .venv/bin/python bench/bench_forward.py   (one sample [us]: medians; '
          'batch of 10,000 [samples/s]; simulation at 1 ms steps)')
    print(f"{'mechanism':28s} {'backend':8s} {'torques':>8s} {'forward':>8s} {'ratio':>6s} "
          f"{'batch tau/s':>12s} {'batch fd/s':>11s} {'ratio':>6s} {'step us':>8s} "
          f"{'x rt (median)':>13s} {'x rt (cpu)':>10s} {'x rt (wall)':>11s}")
    for path in paths:
        name = os.path.basename(path)[:-len('.yaml')]
        mech = cog_id_ros.Mechanism.from_params_file(path)
        q, qd, qdd = motion(mech, 10_000, 10.0)      # 1 kHz
        for backend in backends:
            single, tau = per_sample(mech, backend, q[:2000], qd[:2000], qdd[:2000])
            rates = batch(mech, backend, q, qd, qdd, ids_torques(mech, backend, q, qd, qdd))
            steps = 1000 if backend == 'native' else 200
            step, cpu, wall = simulate(mech, backend, q, qd, tau, steps)
            print(f"{name:28s} {backend:8s} {single['torques'] * 1e6:8.1f} "
                  f"{single['forward'] * 1e6:8.1f} {single['forward'] / single['torques']:6.2f} "
                  f"{rates['torques']:12,.0f} {rates['forward']:11,.0f} "
                  f"{rates['torques'] / rates['forward']:6.2f} {step * 1e6:8.1f} "
                  f"{STEP / step:13.1f} {cpu:10.1f} {wall:11.1f}", flush=True)


def ids_torques(mech, backend, q, qd, qdd):
    return cog_id_ros.InverseDynamics(mech, backend).torques(q, qd, qdd)


if __name__ == '__main__':
    main(sys.argv[1:])
