"""Compiled kernels: built once, cached on disk, and never required.

Each test uses a cache directory of its own (``COG_ID_ROS_CACHE``), a kernel cache of its own
(kernels.KERNELS, as a new process has) and a fresh Mechanism (kernels are shared per
Mechanism object within a process).
"""
import ast
import gc
import glob
import logging
import os
from pathlib import Path
import shutil
import subprocess
import sys
import time
import weakref

from mechanisms import from_yaml
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.native import kernels, native, native_build, native_cache

pytestmark = pytest.mark.skipif(native.compiler() is None, reason='no C compiler here')


def fresh(name='paper_four_bar_a'):
    return cog_id_ros.Mechanism.from_parameters(from_yaml(f'config/{name}.yaml'))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    directory = tmp_path / 'cache'
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(directory))
    monkeypatch.setattr(kernels, 'KERNELS', kernels.KernelCache())   # a process of its own
    return directory


def no_compiler(monkeypatch):
    """No cc, gcc or clang on the PATH and no $CC."""
    monkeypatch.delenv('CC', raising=False)
    monkeypatch.setenv('PATH', '/nonexistent')
    assert native.compiler() is None


def libraries(directory, level='*'):
    return glob.glob(os.path.join(str(directory), f'cog_id_kernels_*.{level}.*so'))


def test_the_first_load_builds_and_caches_and_the_next_needs_no_compiler(cache, monkeypatch):
    solver = cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert solver.backend == 'native' and len(libraries(cache, 'O2')) == 1
    assert len(glob.glob(str(cache / '*.c'))) == 1       # the source kept beside it
    expected = solver.torques([1.6], [0.3], [1.0])
    no_compiler(monkeypatch)
    again = cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert again.backend == 'native'
    assert np.array_equal(again.torques([1.6], [0.3], [1.0]), expected)
    assert kernels.kernels_for(again.mechanism, 'native').operations == \
        kernels.kernels_for(fresh(), 'python').operations


def test_a_mechanism_is_compiled_once_however_many_solvers_and_its_kernels_go_with_it(
        cache, monkeypatch):
    builds, loads = [], []
    build, load = native._build_and_load, native.load_module
    monkeypatch.setattr(native, '_build_and_load', lambda *a: builds.append(a[4]) or build(*a))
    monkeypatch.setattr(native, 'load_module', lambda *a: loads.append(a[0]) or load(*a))
    mechanism = fresh()
    solvers = [cog_id_ros.InverseDynamics(mechanism, backend=backend)     # as the node does
               for backend in ('auto', 'native', 'native', 'auto')]
    assert [s.backend for s in solvers] == ['native'] * 4
    assert len(builds) == 1 and len(loads) == 1 and len(libraries(cache, 'O2')) == 1
    compiled = kernels.kernels_for(mechanism, 'native')
    assert compiled is kernels.kernels_for(mechanism, 'auto')
    assert not hasattr(mechanism, 'kernels_made')       # the cache is beside the kernels
    assert all(np.array_equal(s.torques([1.6], [0.3], [1.0]), solvers[0].torques([1.6], [0.3],
                                                                              [1.0]))
               for s in solvers)
    gone = weakref.ref(compiled), weakref.ref(mechanism)
    del solvers, compiled, mechanism
    gc.collect()
    assert gone[0]() is None and gone[1]() is None     # a mechanism and its kernels go together
    assert len(loads) == 1


def test_a_changed_mechanism_is_a_new_library(cache):
    params = from_yaml('config/paper_four_bar_a.yaml')
    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params), backend='native')
    params['links.link2.mass'] = params['links.link2.mass'] * 2.0
    heavier = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params),
                                         backend='native')
    assert len(libraries(cache)) == 2
    reference = cog_id_ros.InverseDynamics(heavier.mechanism, backend='reference')
    assert np.array_equal(heavier.torques([1.6], [0.3], [1.0]),
                          reference.torques([1.6], [0.3], [1.0]))


def test_without_a_compiler_auto_says_so_once_and_uses_the_python_kernels(cache, monkeypatch,
                                                                          caplog):
    monkeypatch.setenv('CC', '/nonexistent/cc')
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solvers = [cog_id_ros.InverseDynamics(fresh(name)) for name in
                   ('paper_four_bar_a', 'slider_crank')]
    assert [s.backend for s in solvers] == ['python', 'python']
    said = [r.getMessage() for r in caplog.records if 'compiled kernels' in r.getMessage()]
    assert len(said) == 1 and 'no C compiler' in said[0] and "backend='python'" in said[0]
    with pytest.raises(cog_id_ros.MechanismConfigError, match="backend.*'native'.*compiler"):
        cog_id_ros.InverseDynamics(fresh(), backend='native')


def test_a_compiler_that_fails_is_no_compiled_kernels(cache, monkeypatch, tmp_path):
    broken = tmp_path / 'cc'
    broken.write_text('#!/bin/sh\necho "cc: internal error" >&2\nexit 1\n')
    broken.chmod(0o755)
    monkeypatch.setenv('CC', str(broken))
    assert cog_id_ros.InverseDynamics(fresh()).backend == 'python'
    with pytest.raises(cog_id_ros.MechanismConfigError, match='failed: cc: internal error'):
        cog_id_ros.InverseDynamics(fresh(), backend='native')


def test_a_cache_that_cannot_be_written_builds_for_this_process_only(tmp_path, monkeypatch):
    not_a_directory = tmp_path / 'file'
    not_a_directory.write_text('')
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(not_a_directory / 'cache'))
    solver = cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert solver.backend == 'native'
    assert np.isfinite(solver.torques([1.6])).all()


def test_a_cached_library_is_used_from_a_copy_elsewhere(cache, monkeypatch, tmp_path):
    """What an install does: libraries built once, copied to a location users only read."""
    cog_id_ros.InverseDynamics(fresh(), backend='native')
    shipped = tmp_path / 'shipped'
    shutil.copytree(cache, shipped)
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(shipped))
    no_compiler(monkeypatch)
    started = time.perf_counter()
    assert cog_id_ros.InverseDynamics(fresh(), backend='native').backend == 'native'
    assert time.perf_counter() - started < 5.0        # loaded, not built (no compiler)


def test_large_kernels_load_quickly_and_are_optimised_in_the_background(cache, monkeypatch):
    monkeypatch.setattr(native, 'QUICK_ABOVE', 0)
    solver = cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert len(libraries(cache, 'O0')) == 1
    deadline = time.monotonic() + 60.0
    while not libraries(cache, 'O2') and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(libraries(cache, 'O2')) == 1
    assert not glob.glob(str(cache / '*.tmp'))
    again = cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert np.array_equal(again.torques([0.4], [1.0], [0.0]), solver.torques([0.4], [1.0], [0.0]))


def test_the_background_build_needs_nothing_but_the_standard_library():
    """The detached -O2 build loads native_build.py by its path, without the package (its
    relative imports would fail there): that module imports the standard library only."""
    tree = ast.parse(Path(native_build.__file__).read_text(encoding='utf-8'))
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            imported.add('.' * node.level + (node.module or ''))
    assert imported and {name for name in imported
                         if name.split('.')[0] not in sys.stdlib_module_names} == set()


def test_bad_input_to_a_compiled_kernel_is_a_python_error_not_a_crash(cache):
    compiled = kernels.kernels_for(fresh(), 'native')
    with pytest.raises(ValueError, match='q: expected 4 values'):
        compiled.closure([1.0, 2.0])
    with pytest.raises(TypeError):
        compiled.closure([1.0, 2.0, 'x', 4.0])
    with pytest.raises(TypeError):
        compiled.dynamics([0.0] * 4)
    record = compiled.closure((1.6, 0.0, 0.0, 0.0))
    assert isinstance(record, kernels.ClosureRecord)


def test_libraries_unused_for_a_month_are_pruned_when_another_is_built(cache):
    cog_id_ros.InverseDynamics(fresh(), backend='native')
    old = glob.glob(str(cache / '*.json'))[0]
    month_ago = time.time() - (native_cache.KEEP_DAYS + 1) * 86400.0
    os.utime(old, (month_ago, month_ago))
    cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert not os.path.exists(old) and not glob.glob(old[:-len('.json')] + '.*')
    assert len(libraries(cache)) == 1
    used = glob.glob(str(cache / '*.json'))[0]       # a load marks its library as used
    os.utime(used, (month_ago, month_ago))
    cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert os.path.getmtime(used) > month_ago + 86400.0


def test_a_damaged_library_is_built_again_not_loaded(cache):
    """Review of issue 11: a truncated cached library crashed the process (SIGBUS) at every
    later start; its checksum no longer matches, so it is built again."""
    solver = cog_id_ros.InverseDynamics(fresh(), backend='native')
    expected = solver.torques([1.6], [0.3], [1.0])
    library, = libraries(cache)
    with open(library, 'rb') as f:
        whole = f.read()
    damaged = library + '.damaged'
    with open(damaged, 'wb') as f:          # a new file: the loaded one stays mapped intact
        f.write(whole[:len(whole) // 3])
    os.replace(damaged, library)
    again = cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert np.array_equal(again.torques([1.6], [0.3], [1.0]), expected)
    with open(library, 'rb') as f:
        assert f.read() == whole or os.path.getsize(library) > len(whole) // 3


def test_a_compiler_of_ones_own_gets_libraries_of_its_own(cache, monkeypatch):
    cog_id_ros.InverseDynamics(fresh(), backend='native')
    monkeypatch.setenv('CC', native.compiler()[0] + ' -O3')
    cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert len(libraries(cache)) == 2


def test_cached_files_are_readable_by_every_user(cache):
    cog_id_ros.InverseDynamics(fresh(), backend='native')
    for path in glob.glob(str(cache / 'cog_id_kernels_*')):
        assert os.stat(path).st_mode & 0o444 == 0o444, path


def test_no_second_background_build_while_one_is_under_way(cache, monkeypatch):
    monkeypatch.setattr(native, 'QUICK_ABOVE', 0)
    cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    locks = glob.glob(str(cache / '*.lock'))
    optimised = libraries(cache, 'O2')
    assert locks or optimised                 # under way, or already done
    deadline = time.monotonic() + 60.0
    while glob.glob(str(cache / '*.lock')) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not glob.glob(str(cache / '*.lock')) and len(libraries(cache, 'O2')) == 1


def test_the_same_model_from_other_parameter_types_shares_its_library(cache):
    """The node declares the parameters through rclpy (double arrays come back as
    array.array): the same mechanism must not be compiled again in every node process, nor
    for other initial positions (the kernels do not depend on them)."""
    import array
    params = from_yaml('config/paper_four_bar_a.yaml')
    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(params), backend='native')
    as_rclpy = {k: array.array('d', v) if isinstance(v, list) and v and
                isinstance(v[0], float) else v for k, v in params.items()}
    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(as_rclpy),
                               backend='native')
    moved = dict(params, **{'mechanism.initial_positions':
                            [1.6] + list(params['mechanism.initial_positions'][1:])})
    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(moved), backend='native')
    assert len(libraries(cache)) == 1


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='reads /proc')
def test_the_optimised_build_runs_at_the_lowest_priority_and_the_first_answer_does_not_wait(
        cache, monkeypatch, tmp_path):
    """Issue 23: a cold first load of a large model must not starve the machine. A compiler
    wrapper records the niceness and scheduling policy it runs with, and holds the -O2 build
    until the test releases it: the first torques come while it is held, from the -O0
    library, and the -O2 compiler runs at niceness 19 in SCHED_IDLE (policy 5)."""
    monkeypatch.setattr(native, 'QUICK_ABOVE', 0)
    runs, release = tmp_path / 'runs', tmp_path / 'release'
    wrapper = tmp_path / 'cc'
    wrapper.write_text(
        '#!/bin/sh\n'
        'level=none\n'
        'for a in "$@"; do case "$a" in -O0|-O2) level=$a;; esac; done\n'
        f'echo "$level $(cut -d")" -f2 /proc/$$/stat | awk \'{{print $17, $39}}\')" >> {runs}\n'
        'if [ "$level" = -O2 ]; then\n'
        f'  i=0; while [ ! -e {release} ] && [ $i -lt 1200 ]; do sleep 0.05; i=$((i+1)); done\n'
        'fi\n'
        f'exec {native.compiler()[0]} "$@"\n')
    wrapper.chmod(0o755)
    monkeypatch.setenv('CC', str(wrapper))
    try:
        solver = cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
        first = solver.torques([0.4], [1.0], [0.0])
        assert np.isfinite(first).all() and libraries(cache, 'O0') and not libraries(cache, 'O2')
        deadline = time.monotonic() + 60.0       # the background build starts its compiler
        while '-O2' not in (runs.read_text() if runs.exists() else '') and \
                time.monotonic() < deadline:
            time.sleep(0.05)
        assert not libraries(cache, 'O2')        # held: the answer did not wait for it
    finally:
        release.touch()
    levels = {line.split()[0]: line.split()[1:] for line in runs.read_text().splitlines()}
    assert levels['-O0'] == [str(os.getpriority(os.PRIO_PROCESS, 0)), '0'], levels
    assert levels['-O2'] == ['19', str(os.SCHED_IDLE)], levels
    deadline = time.monotonic() + 60.0
    while not libraries(cache, 'O2') and time.monotonic() < deadline:
        time.sleep(0.1)
    assert len(libraries(cache, 'O2')) == 1


def test_lower_priority_gives_the_lowest_niceness_and_the_idle_class():
    code = ('import os, sys; sys.path.insert(0, sys.argv[1]); import native_build; '
            'native_build.lower_priority(); print(os.getpriority(os.PRIO_PROCESS, 0), '
            'os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else -1)')
    out = subprocess.run([sys.executable, '-c', code, os.path.dirname(native_build.__file__)],
                         capture_output=True, text=True, timeout=60, check=True).stdout.split()
    assert out[0] == str(native_build.BACKGROUND_NICENESS)
    if hasattr(os, 'SCHED_IDLE'):
        assert out[1] == str(os.SCHED_IDLE)
