#!/usr/bin/env python3
"""Throughput of the offline tool cog_id_torques on a 1,000,000-sample trajectory.

    python bench/bench_cli_throughput.py [--samples 1000000] [--params config/paper_four_bar_a.yaml]
                                         [--plot] [--keep DIR]

Writes the paper's target motion theta(t) = pi/2 + 0.5 sin(pi t) (both cranks) at 1 kHz
into a temporary directory, once with position, velocity and acceleration columns and
once with positions only (the tool then estimates the derivatives), runs the console
script on each as a user would, and prints wall time, samples per second and the peak
memory of the tool, with the exact command. Not a test: nothing is asserted beyond a
successful run and a complete output.
"""
import argparse
import os
from pathlib import Path
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from cog_id_ros.demos.paper_four_bar import write_csv

ROOT = Path(__file__).resolve().parents[1]


def tool_command():
    script = Path(sys.executable).parent / 'cog_id_torques'
    if script.exists():
        return [str(script)]
    found = shutil.which('cog_id_torques')
    return [found] if found else [sys.executable, '-m', 'cog_id_ros.offline.cli']


def run_measured(cmd):
    """Run ``cmd``; return (status, wall seconds, peak RSS MiB of that process, stderr)."""
    with tempfile.TemporaryFile('w+') as err:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        return proc.returncode, wall, usage.ru_maxrss / 1024.0, err.read()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--samples', type=int, default=1_000_000)
    parser.add_argument('--params', default=str(ROOT / 'config' / 'paper_four_bar_a.yaml'))
    parser.add_argument('--plot', action='store_true', help='also draw the plot (PNG)')
    parser.add_argument('--keep', metavar='DIR', help='write the files here and keep them')
    args, _ = parser.parse_known_args(argv)   # ./dev bench passes its arguments to every bench

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix='cog_id_bench_'))
    work.mkdir(parents=True, exist_ok=True)
    try:
        t = np.arange(args.samples) / 1000.0
        inputs = {}
        for variant, fields in (('full', ('position', 'velocity', 'acceleration')),
                                ('positions only', ('position',))):
            path = work / ('traj_full.csv' if variant == 'full' else 'traj_positions.csv')
            start = time.perf_counter()
            write_csv(path, t, fields=fields)
            inputs[variant] = path
            print(f'generated {path.name}: {args.samples:,} samples, '
                  f'{path.stat().st_size / 2**20:.0f} MiB in {time.perf_counter() - start:.1f} s',
                  file=sys.stderr)
        print(f'# cog_id_torques throughput, {args.samples:,} samples, '
              f'{os.path.basename(args.params)}, {os.cpu_count()} CPUs')
        print(f"{'input':<16}{'wall s':>9}{'samples/s':>13}{'peak RSS MiB':>14}")
        for variant, path in inputs.items():
            out = work / f'torques_{path.stem}.csv'
            cmd = tool_command() + ['--params-file', args.params, '--input', str(path),
                                    '--output', str(out), '--no-progress']
            if args.plot:
                cmd += ['--plot', str(out.with_suffix('.png'))]
            status, wall, rss, stderr = run_measured(cmd)
            if status != 0:
                print(stderr, file=sys.stderr)
                return status
            with open(out) as f:
                rows = sum(1 for _ in f) - 1
            if rows != args.samples:
                print(f'output has {rows} rows, expected {args.samples}', file=sys.stderr)
                return 1
            print(f'{variant:<16}{wall:>9.1f}{args.samples / wall:>13,.0f}{rss:>14,.0f}')
            print(f"  command: {' '.join(cmd)}")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
