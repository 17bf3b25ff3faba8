"""Speed of the transmission maps at control rate, beside one torque sample.

    .venv/bin/python bench/bench_transmission.py [--profile]

For the parallel ankle, the four-bar knee and the TALOS-like leg: a joint-space motion at
1 kHz (each joint-space joint swings about its assembled position), its motor positions,
rates and joint-space efforts made once beforehand; then, one sample at a time, each warm
started from the previous sample of the same call (its own Transmission per map, so no map
moves another's warm start):

    to_joint_space(theta)          to_actuator_space(q)
    joint_velocities(theta, thd)   actuator_velocities(q, qd)
    actuator_efforts(theta, tau_q) joint_efforts(theta, tau_m)

beside InverseDynamics.sample_torques(theta, thd, thdd) on the same mechanism and backend
(auto: native where a C compiler is there). The calls are interleaved in blocks of 200
samples, 6 blocks each, in one run; the table is the median per call [us] and its ratio
to the torque sample's median (the target: each map within 2x). ``--profile``: cProfile
of 300 calls of each map on the ankle, the 12 most expensive functions by own time.
"""
import cProfile
import io
import math
import os
import pstats
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))
import cog_id_ros  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
CONFIGS = ('parallel_ankle', 'four_bar_knee', 'talos_like_leg')
MAPS = ('to_joint_space', 'to_actuator_space', 'joint_velocities', 'actuator_velocities',
        'actuator_efforts', 'joint_efforts')
BLOCK, BLOCKS = 200, 6
#: the joint-space motion: amplitude (rad) of each joint-space joint, at 1 Hz
AMPLITUDE = 0.2


def motion(mech, n):
    """Joint-space (q, qd, qdd) and the motors' (theta, thd, thdd, tau_m) and tau_q, n
    samples at 1 kHz."""
    t = np.arange(n) * 1e-3
    home = np.array([mech.assembled_positions[mech.joint_index[j]] for j in mech.joint_space])
    w = 2.0 * math.pi
    phase = np.arange(len(home))[None, :] * 0.7
    q = home + AMPLITUDE * np.sin(w * t[:, None] + phase)
    qd = AMPLITUDE * w * np.cos(w * t[:, None] + phase)
    tr = cog_id_ros.Transmission(mech)
    theta = tr.to_actuator_space(q)
    thd = tr.actuator_velocities(q, qd)
    thdd = np.gradient(thd, t, axis=0)
    tau_m = cog_id_ros.InverseDynamics(mech).torques(theta, thd, thdd)
    tau_q = tr.joint_efforts(theta, tau_m)
    return dict(q=q, qd=qd, theta=theta, thd=thd, thdd=thdd, tau_m=tau_m, tau_q=tau_q)


def calls(mech, m):
    """{name: (function of sample i)}: each map on its own Transmission, and the torques."""
    solver = cog_id_ros.InverseDynamics(mech)
    th, thd, thdd = (m[k].tolist() for k in ('theta', 'thd', 'thdd'))
    out = {'sample_torques': lambda i: solver.sample_torques(th[i], thd[i], thdd[i])}
    args = {'to_joint_space': ('theta',), 'to_actuator_space': ('q',),
            'joint_velocities': ('theta', 'thd'), 'actuator_velocities': ('q', 'qd'),
            'actuator_efforts': ('theta', 'tau_q'), 'joint_efforts': ('theta', 'tau_m')}
    for name in MAPS:
        method = getattr(cog_id_ros.Transmission(mech), name)
        rows = [m[k] for k in args[name]]
        out[name] = (lambda method, rows: lambda i: method(*(r[i] for r in rows)))(method, rows)
    return out


def bench(name):
    mech = cog_id_ros.Mechanism.from_params_file(os.path.join(ROOT, 'config', name + '.yaml'))
    m = motion(mech, BLOCK * BLOCKS)
    fns = calls(mech, m)
    times = {k: [] for k in fns}
    for block in range(BLOCKS):
        for key, fn in fns.items():
            for i in range(BLOCK * block, BLOCK * (block + 1)):
                t0 = time.perf_counter()
                fn(i)
                times[key].append(time.perf_counter() - t0)
    median = {k: statistics.median(v[BLOCK // 2:]) for k, v in times.items()}
    return mech, median


def profile(name='parallel_ankle', n=300):
    mech = cog_id_ros.Mechanism.from_params_file(os.path.join(ROOT, 'config', name + '.yaml'))
    m = motion(mech, n)
    fns = calls(mech, m)
    for key in ('sample_torques',) + MAPS:
        prof = cProfile.Profile()
        prof.enable()
        for i in range(n):
            fns[key](i)
        prof.disable()
        text = io.StringIO()
        pstats.Stats(prof, stream=text).sort_stats('tottime').print_stats(12)
        print(f'--- {key} ({n} calls on {name})')
        print('\n'.join(text.getvalue().splitlines()[4:24]))


def main():
    if '--profile' in sys.argv[1:]:
        profile()
        return
    probe = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(
        os.path.join(ROOT, 'config', CONFIGS[0] + '.yaml')))
    print(f'command: .venv/bin/python bench/bench_transmission.py; backend {probe.backend}; '
          f'median of one call [us] (x: over one sample_torques), {BLOCKS} blocks of {BLOCK} '
          'samples at 1 kHz, interleaved')
    print('| map | ' + ' | '.join(CONFIGS) + ' |')
    print('|---|' + '---|' * len(CONFIGS))
    results = [bench(name)[1] for name in CONFIGS]
    for key in ('sample_torques',) + MAPS:
        cells = []
        for median in results:
            ratio = median[key] / median['sample_torques']
            cells.append(f'{median[key] * 1e6:.1f} us' + ('' if key == 'sample_torques'
                                                           else f' ({ratio:.2f}x)'))
        print(f'| {key} | ' + ' | '.join(cells) + ' |', flush=True)


if __name__ == '__main__':
    main()
