"""Does the background -O2 build slow down the process that answers? Foreground time beside
two -O2 builds of a large model at normal priority and at the background build's priority.

    .venv/bin/python bench/bench_background_build.py [--params-file config/stewart_6ups.yaml]
        [--builds 2] [--rounds 3]

The large model's kernels are traced and written as C once (into a temporary cache). Then,
per round and in turn: the foreground task alone; beside ``--builds`` compilers running the
-O2 build of that C as the background build runs it (``native_build.lower_priority``:
niceness 19, SCHED_IDLE on Linux); beside the same compilers at the priority of this
process (what the background build did before issue 23). The foreground task is what a
first answer costs in Python: loading the delta robot with a ball at each end of its rods
(test/spin_models.py) until it is refused for its idle spins, then the paper four-bar's
torques along 200 samples with the reference kernels. Reported: the median foreground time
of each setting, and its ratio to the time alone. The compilers are stopped after each
measurement.

Not a test: it prints a table. Exit status 0.
"""
import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(REPO, 'test'))

from mechanisms import from_yaml  # noqa: E402
from spin_models import delta_3rss  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.core.native import kernels, native, native_build  # noqa: E402
from cog_id_ros.core.native.native_cache import library_paths  # noqa: E402


def foreground():
    """Seconds of the foreground task (module docstring)."""
    started = time.perf_counter()
    try:
        cog_id_ros.Mechanism.from_parameters(delta_3rss())
    except cog_id_ros.MechanismConfigError:
        pass
    mech = cog_id_ros.Mechanism.from_parameters(
        from_yaml(os.path.join(REPO, 'config', 'paper_four_bar_a.yaml')))
    q = np.linspace(1.2, 1.9, 200)[:, None]
    cog_id_ros.InverseDynamics(mech, backend='reference').torques(q, q * 0 + 0.5, q * 0)
    return time.perf_counter() - started


def source_of(params_file, cache):
    """The C source of the model's kernels, written into ``cache`` by a first load."""
    os.environ['COG_ID_ROS_CACHE'] = cache
    native.QUICK_ABOVE = 0                    # -O0 now; its -O2 build is not waited for
    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(params_file),
                               backend='native')
    sources = [os.path.join(cache, f) for f in os.listdir(cache) if f.endswith('.c')]
    return sources[0]


def compilers(source, out_dir, count, low):
    command = native.compiler()
    include, _ = native_build.python_headers()
    flags = ['-O2', *native.FLAGS, '-I' + include]
    return [subprocess.Popen([*command, *flags, source, '-o',
                              os.path.join(out_dir, f'build{k}.so')],
                             preexec_fn=native_build.lower_priority if low else None)
            for k in range(count)]


def measure(source, out_dir, builds, setting):
    running = [] if setting == 'alone' else compilers(source, out_dir, builds, setting == 'low')
    try:
        time.sleep(0.3 if running else 0.0)   # the compilers are under way
        return foreground()
    finally:
        for process in running:
            process.kill()
            process.wait()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--params-file', default=os.path.join(REPO, 'config', 'stewart_6ups.yaml'))
    parser.add_argument('--builds', type=int, default=2)
    parser.add_argument('--rounds', type=int, default=3)
    args = parser.parse_args(argv)
    if native.compiler() is None:
        print('no C compiler here: nothing to measure')
        return 0
    with tempfile.TemporaryDirectory() as cache:
        source = source_of(args.params_file, cache)
        kernels.KERNELS = kernels.KernelCache()
        foreground()                          # warm: imports, first traces
        times = {'alone': [], 'low': [], 'normal': []}
        for _ in range(args.rounds):
            for setting in times:
                times[setting].append(measure(source, cache, args.builds, setting))
        lock = library_paths(cache, os.path.basename(source)[:-2])['lock']
        while os.path.exists(lock):           # the first load's own -O2 build
            time.sleep(0.2)
    alone = statistics.median(times['alone'])
    print(f'foreground task beside {args.builds} -O2 builds of {os.path.basename(args.params_file)}'
          f' ({args.rounds} rounds, medians; load average before: {os.getloadavg()[0]:.2f})')
    print('| compilers | foreground s | / alone |')
    print('|---|---|---|')
    for setting, label in (('alone', 'none'), ('low', 'niceness 19, SCHED_IDLE (now)'),
                           ('normal', 'same priority (before)')):
        median = statistics.median(times[setting])
        print(f'| {label} | {median:.3f} | {median / alone:.2f} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
