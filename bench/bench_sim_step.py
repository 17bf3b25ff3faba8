"""Speed of one Simulation step, and how often the step's error control divides it.

    .venv/bin/python bench/bench_sim_step.py                       (paper_four_bar_a, stewart_6ups)
    .venv/bin/python bench/bench_sim_step.py five_bar slider_crank  (these configs)

For each mechanism and backend ('native' where a C compiler is there; add ``--python`` for
the Python step too), two motions at 1 ms steps, each run three times:

* ``replay``: the torques of bench_core.motion (a smooth swing of every actuator) replayed
  from its first sample for one simulated second, as bench_forward.py does;
* ``free``: zero efforts from the assembled pose, at rest, for one simulated second (or
  until the simulation stops at a singular pose: the time it stopped at is printed).

Printed: the median step (us), the real-time factor that makes, and, where the Simulation
reports them (``Simulation.diagnostics``), the steps it divided and the substeps it took.
"""
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, HERE)
from bench_core import motion  # noqa: E402

import cog_id_ros  # noqa: E402

STEP = 0.001
DEFAULT = ('paper_four_bar_a', 'stewart_6ups')


def run(sim, efforts, start, runs=3):
    """(median step s, steps divided, substeps, time stopped or None) over ``runs`` runs."""
    times, stopped = [], None
    divided = substeps = 0
    for _ in range(runs):
        sim.reset(*start)
        for tau in efforts:
            t0 = time.perf_counter()
            try:
                sim.step(tau)
            except cog_id_ros.CogIdError:
                stopped = sim.time
                break
            times.append(time.perf_counter() - t0)
        diagnostics = getattr(sim, 'diagnostics', None)
        if diagnostics is not None:
            divided, substeps = diagnostics.divided_steps, diagnostics.total_substeps
    return statistics.median(times), divided, substeps, stopped


def main(argv):
    names = [a for a in argv if not a.startswith('--')] or list(DEFAULT)
    backends = ['native', 'python'] if '--python' in argv else ['native']
    print(f"{'mechanism':20s} {'backend':8s} {'motion':7s} {'step us':>8s} {'x rt':>7s} "
          f"{'divided':>8s} {'substeps':>9s}  stopped")
    for name in names:
        mech = cog_id_ros.Mechanism.from_params_file(
            os.path.join(HERE, '..', 'config', name + '.yaml'))
        q, qd, qdd = motion(mech, 10_000, 10.0)
        for backend in backends:
            sim = cog_id_ros.Simulation(mech, STEP, backend)
            steps = 1000 if sim.backend == 'native' else 200
            tau = cog_id_ros.InverseDynamics(mech, backend).torques(q[:steps], qd[:steps],
                                                                    qdd[:steps]).tolist()
            zeros = [[0.0] * len(mech.active_joints)] * steps
            for label, efforts, start in (('replay', tau, (q[0], qd[0])),
                                          ('free', zeros, (None, None))):
                step, divided, substeps, stopped = run(sim, efforts, start)
                print(f'{name:20s} {sim.backend:8s} {label:7s} {step * 1e6:8.1f} '
                      f'{STEP / step:7.1f} {divided:8d} {substeps:9d}  '
                      f"{'' if stopped is None else f'{stopped:.3f} s'}", flush=True)


if __name__ == '__main__':
    main(sys.argv[1:])
