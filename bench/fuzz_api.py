"""A longer fuzz campaign of the Python API than the suite's (test/test_fuzz.py), run by hand.

    .venv/bin/python bench/fuzz_api.py [--examples 20000] [--seed 1] [--mechanisms ...]
        [--json out.json]

Same strategies and the same contract as test/test_fuzz.py
(``test_api_any_input_only_cog_id_errors_and_finite_results``): any arguments to torques,
sample_torques, evaluate, solve_positions, cog_jacobians, cog_poses, cog_drifts and
equation_of_motion give finite results or a CogIdError with a known reason, no numpy
warning, a bounded CPU time, an unchanged warm start after an error. Unlike the suite, a
violation does not stop the campaign: every example runs, violations are grouped by kind
(exception type and message head, or which check failed) and the shortest example of each
kind is printed as its reproducer. Also reported: outcomes by reason, and CPU time per call
(median, p99, max, and the slowest calls with their arguments), the figure behind the
contract's "a few milliseconds per sample".

Not derandomized: ``--seed`` picks the run (hypothesis' own generation, seeded).
Exit status 1 when any violation was found.
"""
import argparse
import collections
import json
import os
import re
import sys
import time
import traceback

HERE = os.path.dirname(os.path.abspath(__file__))
for _folder in ('test', os.path.join('test', 'core')):   # test_fuzz and its helpers
    sys.path.insert(0, os.path.join(os.path.dirname(HERE), _folder))

from hypothesis import given, settings  # noqa: E402
from hypothesis import seed as hseed  # noqa: E402
import numpy as np  # noqa: E402
import test_fuzz as fz  # noqa: E402


def kind_of(exc):
    """A short key that groups violations of the same cause."""
    if isinstance(exc, AssertionError):
        text = str(exc).split('\n')[0]
        text = re.sub(r'[-+]?\d[\d.e+-]*', 'N', text)
        return 'contract: ' + (text if len(text) <= 160 else text[:50] + ' ... ' + text[-110:])
    tb = traceback.extract_tb(exc.__traceback__)
    where = next((f'{os.path.basename(f.filename)}:{f.lineno}' for f in reversed(tb)
                  if 'cog_id_ros' in f.filename), '?')
    return f'{type(exc).__name__} at {where}: {str(exc)[:80]}'


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--examples', type=int, default=20000)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--mechanisms', nargs='+', default=list(fz.API_CONFIGS))
    parser.add_argument('--slowest', type=int, default=8, help='slowest calls to list')
    parser.add_argument('--json', help='also write the summary here')
    args = parser.parse_args(argv)

    outcomes = collections.Counter()
    violations = {}                 # kind -> [count, shortest repr]
    times = collections.defaultdict(list)   # method -> CPU seconds per sample
    slowest = []                    # (cpu per sample, repr)
    start = time.monotonic()

    @hseed(args.seed)
    @settings(fz.fuzz_settings(args.examples, derandomize=False, phases=[fz.Phase.generate]))
    @given(fz.api_calls(tuple(args.mechanisms)))
    def campaign(call):
        name, method, call_args, kwargs = call
        text = repr(call)
        try:
            outcome, cpu = fz.check_api_call(name, method, call_args, kwargs)
        except Exception as exc:   # noqa: BLE001 (everything is recorded, nothing stops us)
            key = kind_of(exc)
            entry = violations.setdefault(key, [0, text])
            entry[0] += 1
            if len(text) < len(entry[1]):
                entry[1] = text
            outcomes['VIOLATION'] += 1
            return
        outcomes[outcome] += 1
        n = max(fz._samples(a) for a in call_args)
        times[method].append(cpu / n)
        slowest.append((cpu / n, cpu, text[:300]))
        if len(slowest) > 4 * args.slowest:
            slowest.sort(reverse=True)
            del slowest[args.slowest:]

    campaign()
    elapsed = time.monotonic() - start
    slowest.sort(reverse=True)
    n_total = sum(outcomes.values())
    print(f'{n_total} calls in {elapsed:.0f} s on {", ".join(args.mechanisms)} (seed {args.seed})')
    print('\noutcomes:')
    for outcome, count in outcomes.most_common():
        print(f'  {outcome:24s} {count:7d}')
    print('\nCPU per sample (ms):        median      p99      max    calls')
    for method in sorted(times):
        t = np.array(times[method]) * 1e3
        print(f'  {method:22s} {np.median(t):9.3f} {np.percentile(t, 99):8.2f} {t.max():8.2f} '
              f'{t.size:8d}')
    print(f'\nslowest {args.slowest} calls (CPU per sample, whole call):')
    for per, cpu, text in slowest[:args.slowest]:
        print(f'  {per * 1e3:8.2f} ms {cpu * 1e3:8.2f} ms  {text}')
    print(f'\nviolations: {len(violations)} kinds')
    for key, (count, text) in sorted(violations.items(), key=lambda kv: -kv[1][0]):
        print(f'  [{count}x] {key}\n      shortest: {text[:600]}')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'calls': n_total, 'seconds': elapsed, 'seed': args.seed,
                       'outcomes': dict(outcomes),
                       'cpu_ms_per_sample': {m: {'median': float(np.median(t) * 1e3),
                                                 'p99': float(np.percentile(t, 99) * 1e3),
                                                 'max': float(np.max(t) * 1e3), 'calls': len(t)}
                                             for m, t in times.items()},
                       'violations': {k: {'count': c, 'example': e}
                                      for k, (c, e) in violations.items()}}, f, indent=1)
    return 1 if violations else 0


if __name__ == '__main__':
    sys.exit(main())
