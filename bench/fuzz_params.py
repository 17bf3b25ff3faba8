"""A longer fuzz campaign of mechanism loading than the suite's (test/test_fuzz.py), by hand.

    .venv/bin/python bench/fuzz_params.py [--examples 5000] [--seed 1] [--files 0.3]
        [--node 20] [--json out.json]

Same strategies and contract as test/test_fuzz.py: a mutated example config (as a flat
dict of dotted names, as a nested dict, or written as a params file) or a garbage file
either loads or raises MechanismConfigError within 2 s of CPU, without numpy warnings, and
a mechanism that loads builds a solver that serves its assembled pose (finite torques or a
CogIdError). Every example runs; violations are grouped by kind and the shortest example
of each is printed as its reproducer. Also reported: how many loaded, which parameters the
refusals named, and the load time (median, p99, max, the slowest inputs).

``--node N`` also starts cog_id_node on N mutated params files (about 1-2 s each): it must
either start (and stop with status 0 on SIGINT) or exit with status 2 and one line
``cog_id_node: cannot start: ...``, never a traceback, within 20 s.

Exit status 1 when any violation was found.
"""
import argparse
import collections
import json
import os
import re
import sys
import tempfile
import time
import warnings

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
for _folder in ('test', os.path.join('test', 'core')):   # test_fuzz and its helpers
    sys.path.insert(0, os.path.join(REPO, _folder))

from fuzz_api import kind_of  # noqa: E402  (bench/ is on the path: this file's folder)
from hypothesis import given, settings  # noqa: E402
from hypothesis import seed as hseed  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
import numpy as np  # noqa: E402
import test_fuzz as fz  # noqa: E402

import cog_id_ros  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--examples', type=int, default=5000)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--node', type=int, default=0, help='also start the node on N files')
    parser.add_argument('--slowest', type=int, default=5)
    parser.add_argument('--json', help='also write the summary here')
    args = parser.parse_args(argv)

    outcomes = collections.Counter()
    refused_by = collections.Counter()
    violations = {}
    times = collections.defaultdict(list)
    slowest = []
    directory = tempfile.mkdtemp(prefix='fuzz_params_')

    def record(route, text, run):
        try:
            start = time.thread_time()
            outcome = run()
            cpu = time.thread_time() - start
        except Exception as exc:   # noqa: BLE001 (recorded; the campaign goes on)
            entry = violations.setdefault(kind_of(exc), [0, text])
            entry[0] += 1
            if len(text) < len(entry[1]):
                entry[1] = text
            outcomes[f'{route}: VIOLATION'] += 1
            return
        outcomes[f'{route}: {outcome}'] += 1
        times[route].append(cpu)
        slowest.append((cpu, route, text[:300]))
        slowest.sort(reverse=True)
        del slowest[args.slowest:]

    def refused_name(load):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore')
                load()
        except cog_id_ros.MechanismConfigError as exc:
            refused_by[re.sub(r'\.[^.]*\.', '.<name>.', exc.parameter or '?', count=1)] += 1

    start = time.monotonic()

    @hseed(args.seed)
    @settings(fz.fuzz_settings(args.examples, derandomize=False, phases=[fz.Phase.generate]))
    @given(st.one_of(st.tuples(st.just('dict'), fz.mutated_params(), st.booleans()),
                     st.tuples(st.just('file'), fz.param_files(), st.just(False))))
    def campaign(case):
        route, data, nested = case
        if route == 'dict':
            name, params, mutations = data
            text = f'{name} mutated by {mutations}' + (' (nested)' if nested else '')
            record('nested dict' if nested else 'flat dict', text,
                   lambda: fz.check_params(name, params, mutations, nested=nested))
            given_params = (fz.nest(params) if nested else None) or params
            refused_name(lambda: cog_id_ros.Mechanism.from_parameters(given_params))
        else:
            record('file', repr(data), lambda: fz.check_params_file(data, directory))

    campaign()
    node_results = collections.Counter()
    if args.node:
        env = dict(os.environ)
        env.setdefault('ROS_DOMAIN_ID', str(120 + os.getpid() % 100))
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'

        @hseed(args.seed)
        @settings(fz.fuzz_settings(args.node, derandomize=False, phases=[fz.Phase.generate]))
        @given(fz.param_files())
        def node_campaign(text):
            try:
                node_results[fz.check_node_start(text, directory, env)] += 1
            except Exception as exc:   # noqa: BLE001
                entry = violations.setdefault('node: ' + kind_of(exc), [0, repr(text)])
                entry[0] += 1
                if len(repr(text)) < len(entry[1]):
                    entry[1] = repr(text)
                node_results['VIOLATION'] += 1

        node_campaign()
    elapsed = time.monotonic() - start

    print(f'{sum(outcomes.values())} loads in {elapsed:.0f} s (seed {args.seed})')
    print('\noutcomes:')
    for outcome, count in sorted(outcomes.items()):
        print(f'  {outcome:28s} {count:7d}')
    if node_results:
        print('  cog_id_node start-up: ' + ', '.join(f'{k} {v}' for k, v in node_results.items()))
    print('\nrefusals by parameter (dict routes):')
    for name, count in refused_by.most_common(25):
        print(f'  {count:6d}  {name}')
    print('\nCPU per load (ms):      median      p99      max    loads')
    for route in sorted(times):
        t = np.array(times[route]) * 1e3
        print(f'  {route:16s} {np.median(t):9.2f} {np.percentile(t, 99):8.1f} {t.max():8.1f} {t.size:8d}')
    print(f'\nslowest {args.slowest}:')
    for cpu, route, text in slowest:
        print(f'  {cpu * 1e3:8.1f} ms {route}: {text}')
    print(f'\nviolations: {len(violations)} kinds')
    for key, (count, text) in sorted(violations.items(), key=lambda kv: -kv[1][0]):
        print(f'  [{count}x] {key}\n      shortest: {text[:800]}')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'outcomes': dict(outcomes), 'node': dict(node_results),
                       'refused_by': dict(refused_by), 'seconds': elapsed, 'seed': args.seed,
                       'violations': {k: {'count': c, 'example': e}
                                      for k, (c, e) in violations.items()}}, f, indent=1)
    return 1 if violations else 0


if __name__ == '__main__':
    sys.exit(main())
