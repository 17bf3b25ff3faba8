"""The kernel cache under stress: hung and broken compilers, other users, damaged files, debris.

The regression tests of the reliability issue's items 3, 5, 6, 7 and 8 (their docstrings
say "Reliability 2, item N"). Each test uses a cache directory of its own
(``COG_ID_ROS_CACHE``), a fresh Mechanism, and forgets the builds that failed in this process.
Tests that start a compiler that never returns kill whatever of it is left at their end.

"Another user" is uid 65534 (nobody) when the tests run as root: files and directories are
given to it with chown. Otherwise they are made writable by group and others, which any
user can do and which the cache must refuse just the same.
"""
import glob
import hashlib
import json
import logging
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

from mechanisms import from_yaml
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.native import kernels, native, native_build

ROOT = Path(__file__).resolve().parents[2]
OTHER_UID = 65534

needs_cc = pytest.mark.skipif(native.compiler() is None, reason='no C compiler here')
linux_only = pytest.mark.skipif(not sys.platform.startswith('linux'),
                                reason='checks processes through /proc')


def fresh(name='paper_four_bar_a', **changes):
    return cog_id_ros.Mechanism.from_parameters(dict(from_yaml(f'config/{name}.yaml'),
                                                     **changes))


@pytest.fixture
def cache(tmp_path, monkeypatch):
    directory = tmp_path / 'cache'
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(directory))
    monkeypatch.setattr(kernels, 'KERNELS', kernels.KernelCache())   # a process of its own
    monkeypatch.setattr(native, 'PROCESS', native.ProcessMemory())  # nothing failed or said
    return directory


def libraries(directory, level='*'):
    return glob.glob(os.path.join(str(directory), f'cog_id_kernels_*.{level}.*so'))


def temporary_files(directory):
    """Files of the cache that are neither a library, its checksum, its source, its sizes
    nor a lock: what a build left behind."""
    kept = re.compile(r'cog_id_kernels_\w+\.(c|json|O[02]\..*so(\.sha256)?|O2\.lock)$')
    return [name for name in os.listdir(directory) if not kept.match(name)]


def script(path, text):
    path.write_text('#!/bin/sh\n' + text)
    path.chmod(0o755)
    return path


def alive(pid):
    """True while the process runs (a zombie, dead but not yet reaped, is not alive)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            return f.read().rsplit(')', 1)[1].split()[0] != 'Z'
    except (FileNotFoundError, ProcessLookupError):
        return False


def wait_until(predicate, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


class HungCompiler:
    """A C compiler that never returns, like gcc waiting on a cc1 that hangs: a shell that
    starts a child and waits for it; both write their pids to a file."""

    def __init__(self, directory):
        self.pids_file = directory / 'hung-cc.pids'
        self.path = script(directory / 'hung-cc', f'echo $$ >> {self.pids_file}\n'
                                                  f'sleep 1000 &\necho $! >> {self.pids_file}\n'
                                                  f'wait\n')

    def pids(self):
        try:
            return [int(line) for line in self.pids_file.read_text().split()]
        except FileNotFoundError:
            return []

    def runs(self):
        """How many times the compiler was started."""
        return len(self.pids()) // 2

    def all_dead(self, timeout=5.0):
        return wait_until(lambda: not any(alive(pid) for pid in self.pids()), timeout)


@pytest.fixture
def hung(tmp_path):
    compiler = HungCompiler(tmp_path)
    yield compiler
    for pid in compiler.pids():                # whatever a failing test left running
        if alive(pid):
            os.kill(pid, signal.SIGKILL)


def hand_to_another_user(path):
    """Make ``path`` a file or directory that another user may write: theirs (as root),
    else writable by group and others. What the cache must not load from."""
    if os.geteuid() == 0:
        os.chown(path, OTHER_UID, OTHER_UID)
        return f'owned by uid {OTHER_UID}'
    os.chmod(path, 0o777 if os.path.isdir(path) else 0o666)
    return 'group or others may write it'


def run_python(code, **env):
    return subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ, **env))


# --- item 3: a hung compiler -----------------------------------------------------------------

@linux_only
def test_a_build_that_timed_out_is_not_tried_again_by_the_process(cache, monkeypatch, hung):
    """Reliability 2, item 3: a hung compiler held up node start-up for 2 x BUILD_TIMEOUT
    (two solvers of one mechanism, the failed build not remembered). The first solver
    waits BUILD_TIMEOUT, the second none, and no compiler is started again."""
    monkeypatch.setenv('CC', str(hung.path))
    monkeypatch.setattr(native, 'BUILD_TIMEOUT', 1)
    mechanism = fresh()
    started = time.monotonic()
    assert cog_id_ros.InverseDynamics(mechanism).backend == 'python'
    assert time.monotonic() - started >= 1.0 and hung.runs() == 1
    started = time.monotonic()
    assert cog_id_ros.InverseDynamics(mechanism).backend == 'python'     # the node's second
    with pytest.raises(cog_id_ros.MechanismConfigError, match='took more than 1 s'):
        cog_id_ros.InverseDynamics(fresh(), backend='native')             # the same kernels
    assert time.monotonic() - started < 0.9
    assert hung.runs() == 1
    assert hung.all_dead()
    assert temporary_files(cache) == []


class Stop(BaseException):
    """What a signal handler raises to stop start-up at once (not an Exception: nothing
    that catches errors may swallow it)."""


@linux_only
def test_an_exception_raised_while_the_compiler_runs_stops_it(cache, monkeypatch, hung):
    """Reliability 2, item 3: SIGINT was honoured only after the build: the node now raises
    out of start-up from its signal handler, and the compiler (and what it started) must
    not survive that, nor its output file. Being interrupted is not a failure: the next
    load builds again."""
    monkeypatch.setenv('CC', str(hung.path))
    monkeypatch.setattr(native, 'BUILD_TIMEOUT', 30)   # a bound, should the signal not come

    def stop(signum, frame):
        raise Stop()

    previous = signal.signal(signal.SIGUSR1, stop)
    # the signal comes once the compiler and its child run: what SIGINT interrupts
    signaller = threading.Thread(target=lambda: wait_until(lambda: len(hung.pids()) == 2, 30.0)
                                 and os.kill(os.getpid(), signal.SIGUSR1), daemon=True)
    try:
        signaller.start()
        with pytest.raises(Stop):
            cog_id_ros.InverseDynamics(fresh(), backend='native')
    finally:
        signaller.join()
        signal.signal(signal.SIGUSR1, previous)
    assert hung.runs() == 1
    assert hung.all_dead()
    assert temporary_files(cache) == []
    monkeypatch.setattr(native, 'BUILD_TIMEOUT', 1)
    with pytest.raises(cog_id_ros.MechanismConfigError, match='took more than 1 s'):
        cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert hung.runs() == 2


@linux_only
def test_the_compiler_dies_with_the_process_that_started_it(cache, hung):
    """Reliability 2, item 3: the trajectory process's compiler ran on as an orphan when the
    node stopped. A process killed while its compiler runs takes the compiler, and what the
    compiler started, with it."""
    loader = subprocess.Popen(
        [sys.executable, '-c', 'import cog_id_ros\n'
         'cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file('
         '"config/paper_four_bar_a.yaml"), backend="native")'],
        cwd=ROOT, env=dict(os.environ, CC=str(hung.path)), stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        assert wait_until(lambda: len(hung.pids()) == 2, 60.0), 'the compiler did not start'
    finally:
        loader.kill()
        loader.wait()
    assert hung.all_dead(), [pid for pid in hung.pids() if alive(pid)]


# --- item 5: who may write to the cache ------------------------------------------------------

def impostor_source(mechanism):
    """make_source for load_module: the C of ``mechanism``'s kernels."""
    return lambda module: kernels.c_module_source(
        module, [(name, params, record.__name__, fields)
                 for name, params, record, fields in kernels.trace(mechanism)])


def plant(directory, tmp_path, monkeypatch):
    """Files in ``directory`` that pass for the cached kernels of paper_four_bar_a (the
    library, its checksum and sizes, as the cache writes them) but compute those of a
    four-bar with a heavier coupler: what another user who can write there could leave."""
    planter = tmp_path / 'planter'
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(planter))
    heavier = fresh(**{'links.link2.mass': 2.0 * from_yaml('config/paper_four_bar_a.yaml')
                       ['links.link2.mass']})
    native.load_module(kernels.kernel_key(fresh()), impostor_source(heavier))
    directory.mkdir(exist_ok=True, mode=0o700)
    for path in planter.iterdir():
        if path.name.endswith(('.so', '.sha256', '.json')):
            shutil.copy(path, directory / path.name)
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(directory))
    return cog_id_ros.InverseDynamics(heavier, backend='python')


def listing(directory):
    return sorted((p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in directory.iterdir())


@needs_cc
def test_a_cache_directory_another_user_may_write_is_not_loaded_from(cache, tmp_path,
                                                                     monkeypatch, caplog):
    """Reliability 2, item 5: with the cache directory another user's, that user replaced a
    cached library and its checksum, and root's next load ran the planted code (doubled
    torques, no message). Nothing is loaded from, or written to, such a directory: the
    kernels are built for this process only, and one log line names the directory and why."""
    impostor = plant(cache, tmp_path, monkeypatch)
    why = hand_to_another_user(cache)
    before = listing(cache)
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solvers = [cog_id_ros.InverseDynamics(fresh(), backend='native') for _ in range(2)]
    reference = cog_id_ros.InverseDynamics(fresh(), backend='python')
    sample = ([1.6], [0.3], [1.0])
    assert not np.array_equal(impostor.torques(*sample), reference.torques(*sample))
    for solver in solvers:
        assert solver.backend == 'native'
        assert np.array_equal(solver.torques(*sample), reference.torques(*sample))
    said = [r.getMessage() for r in caplog.records if str(cache) in r.getMessage()]
    assert len(said) == 1 and why in said[0] and 'this process only' in said[0], said
    assert listing(cache) == before


@needs_cc
def test_a_cached_library_another_user_may_write_is_not_loaded(cache, tmp_path, monkeypatch,
                                                               caplog):
    """Reliability 2, item 5: in a directory of one's own, the files of a library (the
    library, its checksum, its sizes) must be one's own and not writable by others too."""
    impostor = plant(cache, tmp_path, monkeypatch)
    library, = libraries(cache)
    for path in (library, library + '.sha256', *glob.glob(str(cache / '*.json'))):
        why = hand_to_another_user(path)
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solver = cog_id_ros.InverseDynamics(fresh(), backend='native')
    reference = cog_id_ros.InverseDynamics(fresh(), backend='python')
    sample = ([1.6], [0.3], [1.0])
    assert not np.array_equal(impostor.torques(*sample), reference.torques(*sample))
    assert np.array_equal(solver.torques(*sample), reference.torques(*sample))
    said = [r.getMessage() for r in caplog.records if str(cache) in r.getMessage()]
    assert len(said) == 1 and why in said[0], said


@needs_cc
def test_the_cache_directory_is_made_private_whatever_the_umask(tmp_path, monkeypatch):
    """Reliability 2, item 5: under umask 000 the cache directory and the parents made for
    it were 0777: anyone could plant a library there."""
    directory = tmp_path / 'made' / 'for' / 'cache'
    monkeypatch.setenv('COG_ID_ROS_CACHE', str(directory))
    umask = os.umask(0)
    try:
        cog_id_ros.InverseDynamics(fresh(), backend='native')
    finally:
        os.umask(umask)
    for path in (tmp_path / 'made', tmp_path / 'made' / 'for', directory):
        assert oct(path.stat().st_mode & 0o777) == oct(0o700), path
    assert len(libraries(directory)) == 1                 # and used: it is one's own


def test_a_relative_xdg_cache_home_is_ignored(tmp_path, monkeypatch):
    """Reliability 2, item 5: the XDG spec says a relative $XDG_CACHE_HOME is invalid and
    ignored; it made a cache relative to whatever the working directory was."""
    monkeypatch.delenv('COG_ID_ROS_CACHE', raising=False)
    monkeypatch.setenv('HOME', str(tmp_path))
    monkeypatch.setenv('XDG_CACHE_HOME', 'relative/cache')
    assert native.cache_directory() == str(tmp_path / '.cache' / 'cog_id_ros')
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'xdg'))
    assert native.cache_directory() == str(tmp_path / 'xdg' / 'cog_id_ros')


@needs_cc
@pytest.mark.parametrize('home', ['', None])
def test_without_a_home_the_kernels_are_built_for_the_process_not_in_slash_cache(
        monkeypatch, caplog, home):
    """Reliability 2, item 5: an empty $HOME put the cache at /.cache/cog_id_ros, one
    directory for every user without a home. Without a cache directory the kernels are
    built in a private directory for the process, and one log line says how to keep them."""
    monkeypatch.delenv('COG_ID_ROS_CACHE', raising=False)
    monkeypatch.delenv('XDG_CACHE_HOME', raising=False)
    if home is None:
        monkeypatch.delenv('HOME', raising=False)
    else:
        monkeypatch.setenv('HOME', home)
    monkeypatch.setattr(native, 'PROCESS', native.ProcessMemory())   # nothing said yet
    assert native.cache_directory() is None
    existed = os.path.exists('/.cache/cog_id_ros')
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solver = cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert solver.backend == 'native'
    assert os.path.exists('/.cache/cog_id_ros') == existed
    said = [r.getMessage() for r in caplog.records if 'kernel cache' in r.getMessage()]
    assert len(said) == 1 and 'COG_ID_ROS_CACHE' in said[0], said


# --- item 6: what is loaded is what was checked ----------------------------------------------

@needs_cc
def test_a_truncated_library_whose_checksum_matches_is_not_loaded(cache):
    """Reliability 2, item 6: a library cut short, with a checksum that matches it, crashed
    the process with SIGBUS when loaded (the loader maps its segments beyond the end of
    the file). It is built again. Loaded in a subprocess, so that a crash fails this test
    instead of killing pytest."""
    expected = cog_id_ros.InverseDynamics(fresh(), backend='native').torques([1.6], [0.3],
                                                                             [1.0])
    library, = libraries(cache)
    with open(library, 'rb') as f:
        whole = f.read()
    cut = whole[:len(whole) // 3]
    with open(library + '.cut', 'wb') as f:   # a new file: the loaded one stays mapped intact
        f.write(cut)
    os.replace(library + '.cut', library)
    # its checksum made to match the cut library in every field the cache records
    with open(library + '.sha256', encoding='ascii') as f:
        record = f.read()
    record = record.replace(hashlib.sha256(whole).hexdigest(), hashlib.sha256(cut).hexdigest())
    record = re.sub(rf'\b{len(whole)}\b', str(len(cut)), record)
    with open(library + '.sha256', 'w', encoding='ascii') as f:
        f.write(record)
    loaded = run_python('import json, cog_id_ros\n'
                        's = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file('
                        '"config/paper_four_bar_a.yaml"), backend="native")\n'
                        'print(json.dumps(s.torques([1.6], [0.3], [1.0]).tolist()))',
                        COG_ID_ROS_CACHE=str(cache))
    assert loaded.returncode == 0, (f'signal {-loaded.returncode}' if loaded.returncode < 0
                                    else loaded.stderr)
    assert np.array_equal(json.loads(loaded.stdout), expected)
    with open(library, 'rb') as f:
        assert f.read() == whole                  # built again, and replaced


# --- item 7: a compiler setting that cannot be used ------------------------------------------

@pytest.mark.parametrize('cc', ['gcc "', "cc -O2 'unterminated", '   '])
def test_a_compiler_setting_that_is_not_a_command_is_no_compiler(cache, monkeypatch, caplog,
                                                                 cc):
    """Reliability 2, item 7: CC='gcc "' raised ValueError (No closing quotation) out of
    the API, and the node refused to start. It is no compiler, like a missing one: 'auto'
    uses the Python kernels with one log line naming $CC, 'native' is a configuration error
    that names it."""
    monkeypatch.setenv('CC', cc)
    assert native.compiler() is None
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solvers = [cog_id_ros.InverseDynamics(fresh(name)) for name in
                   ('paper_four_bar_a', 'slider_crank')]
    assert [s.backend for s in solvers] == ['python', 'python']
    said = [r.getMessage() for r in caplog.records if 'compiled kernels' in r.getMessage()]
    assert len(said) == 1 and f'$CC={cc!r}' in said[0], said
    with pytest.raises(cog_id_ros.MechanismConfigError, match=r'native.*\$CC') as raised:
        cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert raised.value.parameter == 'backend'


def test_the_offline_tool_runs_with_a_compiler_setting_that_is_not_a_command(cache, tmp_path):
    """Reliability 2, item 7: cog_id_torques blamed the parameter file for CC='gcc "'."""
    ran = subprocess.run([sys.executable, '-m', 'cog_id_ros.offline.cli', '--params-file',
                          'config/paper_four_bar_a.yaml', '--input',
                          'config/paper_four_bar_target.csv', '--output',
                          str(tmp_path / 'torques.csv')], cwd=ROOT, capture_output=True,
                         text=True, timeout=120, env=dict(os.environ, CC='gcc "'))
    assert ran.returncode == 0, ran.stderr
    assert (tmp_path / 'torques.csv').exists()


# --- item 8: build debris, a full disk, a stale lock -----------------------------------------

@needs_cc
@linux_only
def test_debris_of_builds_that_died_is_pruned_when_a_build_happens(cache, hung):
    """Reliability 2, item 8: temporary files of builds that died (a killed process, a full
    disk) stayed in the cache for ever. Those older than any live build could be are
    removed when a library is built; a recent one (a build under way) stays."""
    loader = subprocess.Popen(
        [sys.executable, '-c', 'import cog_id_ros\n'
         'cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file('
         '"config/paper_four_bar_a.yaml"), backend="native")'],
        cwd=ROOT, env=dict(os.environ, CC=str(hung.path)), stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL)
    try:
        assert wait_until(lambda: len(hung.pids()) == 2, 60.0), 'the compiler did not start'
    finally:
        loader.kill()                          # SIGKILL while it builds: nothing cleans up
        loader.wait()
    killed = temporary_files(cache)
    assert killed                              # what such a build leaves
    # and what earlier versions of the cache left (mkstemp's default names)
    for name in ('tmpa1b2c3d4' + native_build.library_suffix(), 'tmpe5f6g7h8.tmp'):
        (cache / name).write_bytes(b'\0' * 100)
    long_ago = time.time() - native.BUILD_TIMEOUT - 3600.0
    for name in temporary_files(cache):
        os.utime(cache / name, (long_ago, long_ago))
    (cache / 'tmpi9j0k1l2.tmp').write_bytes(b'')        # recent: a build under way
    cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert temporary_files(cache) == ['tmpi9j0k1l2.tmp']


@needs_cc
def test_a_full_disk_is_reported_as_such(cache, monkeypatch, tmp_path):
    """Reliability 2, item 8: a full disk was reported as 'No such file or directory': the
    linker removes its output when it fails, and removing it again raised ENOENT over the
    compiler's own message. This compiler fails as gcc does when ld finds the disk full."""
    full = script(tmp_path / 'cc', 'while [ $# -gt 1 ]; do [ "$1" = -o ] && out="$2"; shift; '
                                   'done\nrm -f "$out"\n'
                                   'echo "/usr/bin/ld: final link failed: No space left on '
                                   'device" >&2\n'
                                   'echo "collect2: error: ld returned 1 exit status" >&2\n'
                                   'exit 1\n')
    monkeypatch.setenv('CC', str(full))
    with pytest.raises(cog_id_ros.MechanismConfigError,
                       match='failed: /usr/bin/ld: final link failed: No space left on device'):
        cog_id_ros.InverseDynamics(fresh(), backend='native')
    assert temporary_files(cache) == []


@needs_cc
def test_a_write_that_fails_says_why_and_leaves_nothing(cache):
    """Reliability 2, item 8: a write that failed (a full disk) left its temporary file in
    the cache. Here the writes fail as they do on a full disk, with an error of the system
    (the file size limit of the process: 'File too large')."""
    failed = run_python('import resource, signal, cog_id_ros\n'
                        'signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n'
                        'resource.setrlimit(resource.RLIMIT_FSIZE, (4096, resource.getrlimit('
                        'resource.RLIMIT_FSIZE)[1]))\n'
                        'try:\n'
                        '    cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file('
                        '"config/paper_four_bar_a.yaml"), backend="native")\n'
                        'except cog_id_ros.MechanismConfigError as exc:\n'
                        '    print(exc)\n', COG_ID_ROS_CACHE=str(cache))
    assert failed.returncode == 0, failed.stderr
    assert 'File too large' in failed.stdout, failed.stdout
    assert temporary_files(cache) == []


def cached_without_its_optimised_build(cache, monkeypatch):
    """The slider-crank's kernels cached at -O0 as if their background -O2 build had never
    finished (QUICK_ABOVE 0: every build is quick first); returns where -O2 would be."""
    monkeypatch.setattr(native, 'QUICK_ABOVE', 0)
    cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert wait_until(lambda: libraries(cache, 'O2') and not glob.glob(str(cache / '*.lock')),
                      60.0)
    optimised, = libraries(cache, 'O2')
    os.unlink(optimised + '.sha256')
    os.unlink(optimised)
    return optimised


@needs_cc
def test_a_lock_dated_in_the_future_does_not_hold_up_the_optimised_build(cache, monkeypatch,
                                                                         caplog):
    """Reliability 2, item 8: a lock file dated in the future kept the -O2 build from ever
    starting, without a word (a mechanism stayed at -O0: 58 instead of 41 us a sample on
    the Stewart platform). It counts as stale: removed, said, and the build starts."""
    optimised = cached_without_its_optimised_build(cache, monkeypatch)
    lock = re.sub(r'\.O2\..*so$', '.O2.lock', optimised)
    open(lock, 'w').close()
    future = time.time() + 3600.0
    os.utime(lock, (future, future))
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    said = [r.getMessage() for r in caplog.records if lock in r.getMessage()]
    assert len(said) == 1 and 'future' in said[0], said
    assert wait_until(lambda: libraries(cache, 'O2') and not os.path.exists(lock), 30.0)


@needs_cc
def test_a_cached_source_another_user_may_write_is_not_compiled(cache, monkeypatch, caplog):
    """Reliability 2, adversarial check: with a library cached at -O0, the next load started
    the -O2 build from the cached C source without checking whose it was; another user who
    could write it had their code compiled in, and the load after that ran it as root. The
    source must be one's own like the libraries: else nothing of that cache is used (the
    kernels are built for this process only, one log line says why) and nothing compiles
    it."""
    cached_without_its_optimised_build(cache, monkeypatch)
    source, = glob.glob(str(cache / '*.c'))
    why = hand_to_another_user(source)
    monkeypatch.setattr(native, 'PROCESS', native.ProcessMemory())   # a new process
    monkeypatch.setattr(kernels, 'KERNELS', kernels.KernelCache())
    with caplog.at_level(logging.WARNING, logger='cog_id_ros'):
        solver = cog_id_ros.InverseDynamics(fresh('slider_crank'), backend='native')
    assert solver.backend == 'native'
    said = [r.getMessage() for r in caplog.records if source in r.getMessage()]
    assert len(said) == 1 and why in said[0], said
    time.sleep(1.0)                            # a background build would have begun by now
    assert not libraries(cache, 'O2') and not glob.glob(str(cache / '*.lock'))
