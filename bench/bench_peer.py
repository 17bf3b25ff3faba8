"""cog_id_ros against the Pinocchio-style peer (bench/peer.py), side by side in one run.

    .venv/bin/python bench/bench_peer.py [--backend NAME] [--only NAME] [--batch 10000]

For every example mechanism (config/*.yaml with a test motion in test/trajectories.py; the
peers time a twin written with spherical joints, e.g. stewart_6ups_spherical, on its
helper-link original, the same mechanism):

* per sample: the test motion at 1 kHz (2,001 setpoints over its 2 s), each sample one call,
  warm-started from the previous one, ``InverseDynamics(mech)`` (or ``backend=NAME``) and the
  peer taking turns in blocks of 500 samples; medians in microseconds and ours/peer;
* batch: one ``solver.torques(q, qd, qdd)`` call on 10,000 samples of the motion at 1 kHz
  (10 s), best of 3, in samples/s, against the peer's per-sample rate (1 / its median);
* load: ``Mechanism.from_params_file`` + ``InverseDynamics`` construction and the peak RSS
  growth it causes, in a fresh process with an empty kernel cache (``COG_ID_ROS_CACHE`` a new
  temporary directory: the first-time trace and compile), then again from that cache; the
  peer's load beside it.

Before timing, the peer's torques are checked against ours at a few samples (1e-8 relative to
the largest torque). This machine is shared and noisy: read the ratios, not single figures.
"""
import argparse
import datetime
import glob
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
for path in (REPO, HERE, os.path.join(REPO, 'test')):
    if path not in sys.path:
        sys.path.insert(0, path)

from peer import OraclePeer, Peer  # noqa: E402
from trajectories import NOT_FOR_ORACLE, TRAJECTORIES, TWINS  # noqa: E402

import cog_id_ros  # noqa: E402
from cog_id_ros.core.native import native  # noqa: E402

BLOCK = 500
RTOL = 1e-8

_LOAD = r"""
import json, sys, time
sys.path.insert(0, {repo!r}); sys.path.insert(0, {bench!r})
def rss():   # VmHWM: the peak of this process (ru_maxrss would include the parent's, kept over exec)
    with open('/proc/self/status') as f:
        return next(int(x.split()[1]) for x in f if x.startswith('VmHWM')) / 1024.0
if {peer!r}:
    from peer import Peer
    r0 = rss(); t0 = time.perf_counter()
    Peer({path!r})
else:
    import cog_id_ros
    r0 = rss(); t0 = time.perf_counter()
    mech = cog_id_ros.Mechanism.from_params_file({path!r})
    cog_id_ros.InverseDynamics(mech, **{kwargs!r})
print(json.dumps([time.perf_counter() - t0, rss() - r0]))
"""


def load_cost(path, kwargs, peer=False, cache=None):
    """(seconds, peak RSS growth MB) of loading in a fresh process; ``cache``: the native
    kernel cache directory to use (COG_ID_ROS_CACHE)."""
    code = _LOAD.format(repo=REPO, bench=HERE, path=path, kwargs=kwargs, peer=peer)
    env = dict(os.environ)
    if cache is not None:
        env['COG_ID_ROS_CACHE'] = cache
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def background_builds_done(cache, limit=180.0):
    """Wait until the -O2 builds that a first load started in the background (native.py:
    large kernels load at -O0 first) have finished in ``cache``: a compiler left running
    would share the 2 cores with every timing that follows. True if there was one.
    ``cache`` None: no cache directory (native.cache_directory), nothing built in background."""
    if cache is None:
        return False
    deadline = time.time() + limit
    waited = False
    while glob.glob(os.path.join(cache, '*.lock')) and time.time() < deadline:
        waited = True
        time.sleep(0.5)
    return waited


def check(name, mech, peer, kwargs, q, qd, qdd):
    """The peer agrees with us at a few samples (both warm-started along the motion)."""
    solver = cog_id_ros.InverseDynamics(mech, **kwargs)
    ks = list(range(0, 200)) + list(range(200, len(q), 199))
    ours = np.array([solver.torques(q[k], qd[k], qdd[k]) for k in ks])
    theirs = np.array([peer.torques(q[k], qd[k], qdd[k]) for k in ks])
    err = np.abs(ours - theirs).max() / max(np.abs(ours).max(), 1e-300)
    peer.reset()
    if not err < RTOL:
        raise SystemExit(f'{name}: peer and cog_id_ros disagree: {err:.2e} relative')
    return err


def per_sample(solver, peer, q, qd, qdd):
    """Median seconds per sample, ours and the peer's, in interleaved blocks of BLOCK."""
    times = {'ours': [], 'peer': []}
    calls = {'ours': solver.torques, 'peer': peer.torques}
    clock = time.perf_counter
    for start in range(0, len(q), BLOCK):
        for who in ('ours', 'peer'):
            f, out = calls[who], times[who]
            for i in range(start, min(start + BLOCK, len(q))):
                t0 = clock()
                f(q[i], qd[i], qdd[i])
                out.append(clock() - t0)
    return {k: statistics.median(v[20:]) for k, v in times.items()}


#: rounds of the side-by-side batch measurement (--oracle)
ROUNDS = 11


def batch_over_oracle(mech, kwargs, oracle, motion, batch):
    """Our batch rate over the oracle's per-sample rate, measured side by side: each round
    times the oracle on 100 consecutive samples of the 1 kHz motion (median, warm-started
    from the sample before) and then one
    batch call of ours on ``batch`` (a fresh solver); the median over ROUNDS rounds of
    (samples / batch seconds) x (oracle seconds per sample). The machine's speed drifts from
    minute to minute; a ratio taken within one round is not fooled by it."""
    q, qd, qdd = motion
    ratios = []
    for r in range(ROUNDS):
        start = 1 + (r * 100) % (len(q) - 101)
        oracle.torques(q[start - 1], qd[start - 1], qdd[start - 1])    # warm-started there
        times = []
        for i in range(start, start + 100):
            t0 = time.perf_counter()
            oracle.torques(q[i], qd[i], qdd[i])
            times.append(time.perf_counter() - t0)
        fresh = cog_id_ros.InverseDynamics(mech, **kwargs)
        t0 = time.perf_counter()
        fresh.torques(*batch)
        ratios.append(len(batch[0]) / (time.perf_counter() - t0) * statistics.median(times))
    return statistics.median(ratios)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--backend', default=None,
                    help='passed to InverseDynamics(mech, backend=NAME) (default: its default)')
    ap.add_argument('--only', default=None, help='only configs whose file name contains NAME')
    ap.add_argument('--batch', type=int, default=10_000, help='samples in the batch call')
    ap.add_argument('--oracle', action='store_true',
                    help='also time the test oracle (test/pinocchio_reference.py) per sample, '
                         'on the first 500 samples: the peer the speed issue measured')
    args = ap.parse_args(argv)
    kwargs = {} if args.backend is None else {'backend': args.backend}
    argv_shown = sys.argv[1:] if argv is None else argv
    print('command: ' + ' '.join([os.path.relpath(sys.executable, REPO), 'bench/bench_peer.py'] + argv_shown))
    print(f'date: {datetime.datetime.now().isoformat(timespec="seconds")}   host cpus: {os.cpu_count()}')
    names = [os.path.basename(p) for p in sorted(glob.glob(os.path.join(REPO, 'config', '*.yaml')))]
    names = [n for n in names if n in TRAJECTORIES and (args.only is None or args.only in n)
             and (n in TWINS or n not in NOT_FOR_ORACLE)]     # (the peers read no URDF)
    head = ('mechanism', 'joints', 'loops', 'DOF', 'backend', 'ours us', 'peer us', 'ours/peer',
            'batch /s', 'peer /s', 'batch/peer', 'load s', 'load MB', 'cached load s',
            'peer load s', 'check') + (('oracle us', 'ours/oracle', 'batch/oracle (rounds)')
                                       if args.oracle else ())
    rows = []
    for name in names:
        path = os.path.join(REPO, 'config', name)
        # a twin (spherical joints where the original has helper links) is the same
        # mechanism: the peers, which know revolute and prismatic joints only, read the original
        peer_path = os.path.join(REPO, 'config', TWINS.get(name, name))
        mech = cog_id_ros.Mechanism.from_params_file(path)
        solver = cog_id_ros.InverseDynamics(mech, **kwargs)
        if background_builds_done(native.cache_directory()):   # a first load: time the -O2
            mech = cog_id_ros.Mechanism.from_params_file(path)
            solver = cog_id_ros.InverseDynamics(mech, **kwargs)
        peer = Peer(peer_path)
        t = np.arange(2001) / 1000.0
        q, qd, qdd = TRAJECTORIES[name](t)
        err = check(name, mech, peer, kwargs, q, qd, qdd)
        solver.reset()
        med = per_sample(solver, peer, q, qd, qdd)
        tb = np.arange(args.batch) / 1000.0
        qb, qdb, qddb = TRAJECTORIES[name](tb)
        best = float('inf')
        for _ in range(3):
            fresh = cog_id_ros.InverseDynamics(mech, **kwargs)
            t0 = time.perf_counter()
            fresh.torques(qb, qdb, qddb)
            best = min(best, time.perf_counter() - t0)
        rate, peer_rate = args.batch / best, 1.0 / med['peer']
        with tempfile.TemporaryDirectory() as cache:     # first time: trace (+ compile)
            load_s, load_mb = load_cost(path, kwargs, cache=cache)
            cached_s, _ = load_cost(path, kwargs, cache=cache)
            background_builds_done(cache)
        peer_load_s, _ = load_cost(peer_path, {}, peer=True)
        row = (name.replace('.yaml', ''), len(mech.joints), len(mech.model.loops),
               mech.dof, solver.backend, f'{med["ours"] * 1e6:.1f}', f'{med["peer"] * 1e6:.1f}',
               f'{med["ours"] / med["peer"]:.3f}', f'{rate:,.0f}', f'{peer_rate:,.0f}',
               f'{rate / peer_rate:.1f}', f'{load_s:.3f}', f'{load_mb:.0f}', f'{cached_s:.3f}',
               f'{peer_load_s:.3f}',
               f'{err:.0e}')
        if args.oracle:
            oracle = OraclePeer(peer_path)
            times = []
            for i in range(BLOCK):
                t0 = time.perf_counter()
                oracle.torques(q[i], qd[i], qdd[i])
                times.append(time.perf_counter() - t0)
            slow = statistics.median(times[20:])
            row += (f'{slow * 1e6:.1f}', f'{med["ours"] / slow:.3f}',
                    f'{batch_over_oracle(mech, kwargs, oracle, (q, qd, qdd), (qb, qdb, qddb)):.0f}')
        rows.append(row)
        print(f'  {name}: done', file=sys.stderr, flush=True)
    print('| ' + ' | '.join(head) + ' |')
    print('|' + '---|' * len(head))
    for row in rows:
        print('| ' + ' | '.join(str(x) for x in row) + ' |')
    print("ours/peer: median time per sample, ours over the peer's (lower is better); "
          "batch/peer: our batch samples/s over the peer's per-sample rate; load: "
          'Mechanism.from_params_file + InverseDynamics in a fresh process with an empty kernel '
          'cache (trace, compile), its peak RSS growth, and again from that cache; '
          'check: largest |ours - peer| / max |tau| at the checked samples; oracle: the test '
          "oracle's median per sample (--oracle); batch/oracle (rounds): our batch rate "
          "over the oracle's per-sample rate, each round timing both side by side, the median "
          f'over {ROUNDS} rounds (--oracle).')


if __name__ == '__main__':
    main()
