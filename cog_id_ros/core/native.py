"""Compiled kernels: the traced kernels as C, built by the system's C compiler, cached on disk.

``backend='native'`` (and ``'auto'`` where it can) writes the mechanism's two kernels as a
CPython extension module (emitter.c_module_source), compiles it once and keeps the library
in a cache directory keyed by a hash of what it is made of (the mechanism's model as read and
the core's source, kernels.kernel_key), the Python version, the flags and ``$CC`` if set:

* the cache directory is ``$COG_ID_ROS_CACHE`` if set, else ``$XDG_CACHE_HOME/cog_id_ros``
  or ``~/.cache/cog_id_ros``; a cached library there is used even when the directory is
  read-only, and when it cannot be written the library is built in a temporary directory
  for this process only;
* the compiler is ``$CC`` if set, else ``cc``, ``gcc`` or ``clang`` on the PATH; it needs
  Python's headers (``Python.h``, the python3-dev package). A ``$CC`` that is not a command
  (an unbalanced quote, no executable) is no compiler: the Python kernels serve;
* a compiler dies with the process that started it (Linux: a parent-death signal), is
  stopped after ``BUILD_TIMEOUT`` seconds, and is stopped with everything it started on any
  exception, one raised by a signal handler to stop the process included. A build that
  failed or timed out is not tried again by the same process: the next load of the same
  kernels raises :class:`NativeUnavailable` at once with the first failure's reason;
* the flags keep the numbers those of the Python kernels: no contraction into fused
  multiply-adds (``-ffp-contract=off``), no fast-math; every operation is the IEEE double
  operation Python does, so the kernels agree with ``backend='python'`` to the last bit;
* a library not used for ``KEEP_DAYS`` days is removed when another one is built, and so
  are temporary files of builds that died (killed, a full disk) once they are older than
  any live build could be;
* small kernels are compiled with ``-O2`` at once. A large one (more than
  ``QUICK_ABOVE`` operations, where -O2 takes seconds) is compiled with ``-O0`` at once,
  which is fast to build and several times slower to run, while ``-O2`` is built in the
  background into the cache for the next load (one build at a time: a lock file, counted
  as stale, and broken with a log line, when it is older than ``BUILD_TIMEOUT`` or dated in
  the future).

Nothing here is needed to run: without a compiler or headers :class:`NativeUnavailable`
says why and the caller falls back to the Python kernels.
"""
import atexit
import ctypes
import glob
import hashlib
import importlib.machinery
import importlib.util
import json
import logging
import os
import shlex
import shutil
import signal
import subprocess
import sys
import sysconfig
import tempfile
import time

#: flags of every build: IEEE doubles as Python computes them
FLAGS = ['-shared', '-fPIC', '-ffp-contract=off', '-fno-fast-math',
         '-fno-unsafe-math-optimizations']

#: operations (both kernels) above which the first build is -O0 and -O2 follows in background
QUICK_ABOVE = 6000

#: seconds a build may take before it counts as failed (the compiler is then stopped)
BUILD_TIMEOUT = 120

#: seconds a lock may be dated in the future and still count as live: file times come from
#: a coarse clock, and a lock further ahead (a clock set back, a file copied from elsewhere)
#: would otherwise block the -O2 build until the clock catches up
FUTURE_SLACK = 5.0

#: seconds, beyond BUILD_TIMEOUT, after which a temporary file of this cache is debris: a
#: live build's files are younger (its compiler is stopped at BUILD_TIMEOUT)
DEBRIS_MARGIN = 60.0

#: the names of this cache's temporary files (a build's output, a file being written);
#: earlier versions named theirs tmp*.so and tmp*.tmp, pruned as well
_TEMPORARY = 'cog_id_tmp_'

_log = logging.getLogger('cog_id_ros')


class NativeUnavailable(Exception):
    """No compiled kernels here: no compiler, no Python headers, or the build failed."""


def cache_directory():
    """Where libraries are kept (see the module docstring)."""
    configured = os.environ.get('COG_ID_ROS_CACHE')
    if configured:
        return os.path.abspath(os.path.expanduser(configured))
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'cog_id_ros')


def find_compiler():
    """(the C compiler command as a list, None), or (None, why there is none: a sentence
    that says what to fix)."""
    configured = os.environ.get('CC')
    if configured:
        try:
            command = shlex.split(configured)
        except ValueError as exc:             # an unbalanced quote
            return None, (f'no C compiler: $CC={configured!r} cannot be read as a command '
                          f'({exc}); set CC to a compiler command such as gcc, or unset it')
        if not command:
            return None, (f'no C compiler: $CC={configured!r} names no command; set CC to a '
                          f'compiler command such as gcc, or unset it')
        if shutil.which(command[0]) is None:
            return None, (f'no C compiler: $CC={configured!r} names {command[0]!r}, which is '
                          f'neither an executable file nor a program on the PATH')
        return command, None
    for name in ('cc', 'gcc', 'clang'):
        path = shutil.which(name)
        if path:
            return [path], None
    return None, 'no C compiler (cc, gcc or clang on the PATH, or $CC)'


def compiler():
    """The C compiler command (a list), or None (:func:`find_compiler` says why)."""
    return find_compiler()[0]


def _suffix():
    return sysconfig.get_config_var('EXT_SUFFIX') or '.so'


def _include():
    include = sysconfig.get_paths().get('include')
    if not include or not os.path.exists(os.path.join(include, 'Python.h')):
        raise NativeUnavailable(f'no Python headers (Python.h) in {include}: install the '
                                f'python3-dev package')
    return include


#: (cache directory, library name) -> why its build failed in this process: not tried again
#: (a hung compiler would otherwise hold up every solver of the mechanism for BUILD_TIMEOUT)
_failed = {}


def load_module(key, make_source):
    """(compiled module, operations per kernel) for the kernels identified by ``key`` (a
    text naming everything they are made of), from the cache or built now from
    ``make_source(module name) -> (C source, {kernel: operations})``. How large the kernels
    are chooses the optimisation."""
    explicit = os.environ.get('CC', '')       # a compiler of one's own: libraries of its own
    digest = hashlib.sha256('\0'.join([key, sys.version, _suffix(), ' '.join(FLAGS),
                                       explicit]).encode()).hexdigest()[:20]
    name = f'cog_id_kernels_{digest}'
    directory = cache_directory()
    paths = _paths(directory, name)
    operations = _read_json(paths['json'])
    if operations is not None:
        for level in ('O2', 'O0'):
            if _intact(paths[level]):
                try:
                    module = _import(name, paths[level])
                except ImportError:
                    continue                  # damaged all the same: built again below
                _touch(paths['json'])         # in use: not pruned
                if level == 'O0':             # an -O2 build that never finished: again
                    _build_in_background(compiler(), directory, name)
                return module, operations
    failure = _failed.get((directory, name))
    if failure is not None:
        raise NativeUnavailable(failure)
    command, why = find_compiler()
    if command is None:
        raise NativeUnavailable(why)
    include = _include()
    source, operations = make_source(name)
    try:
        os.makedirs(directory, exist_ok=True)
        writable = os.access(directory, os.W_OK)
    except OSError:
        writable = False
    remembered = (directory, name)
    try:
        if not writable:                      # for this process only, removed at its exit
            directory = tempfile.mkdtemp(prefix='cog_id_ros-')
            atexit.register(shutil.rmtree, directory, ignore_errors=True)
            paths = _paths(directory, name)
        else:
            _prune(directory)                 # before: what it frees helps a full disk
        _write_atomically(paths['c'], source)
        _write_atomically(paths['json'], json.dumps(operations))
        if sum(operations.values()) > QUICK_ABOVE:
            _build(command, include, paths['c'], paths['O0'], '-O0')
            if writable:
                _build_in_background(command, directory, name)
            return _import(name, paths['O0']), operations
        _build(command, include, paths['c'], paths['O2'], '-O2')
        return _import(name, paths['O2']), operations
    except NativeUnavailable as exc:          # failed or timed out: not tried again
        _failed[remembered] = str(exc)
        raise
    except (OSError, ImportError) as exc:     # a full disk, a file that will not load ...
        _failed[remembered] = (f'the compiled kernels could not be built or loaded in '
                               f'{directory}: {exc}')
        raise NativeUnavailable(_failed[remembered]) from None


def _paths(directory, name):
    base = os.path.join(directory, name)
    return {'c': base + '.c', 'json': base + '.json', 'O2': base + '.O2' + _suffix(),
            'O0': base + '.O0' + _suffix(), 'lock': base + '.O2.lock'}


def _read_json(path):
    try:
        with open(path, encoding='utf-8') as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def _digest(path):
    with open(path, 'rb') as f:
        return hashlib.sha256(f.read()).hexdigest()


def _intact(path):
    """True when the library is there and is what was built: its sha256 is the one written
    beside it when the build finished (a truncated library would crash the process)."""
    try:
        with open(path + '.sha256', encoding='ascii') as f:
            return f.read().strip() == _digest(path)
    except OSError:
        return False


#: days after its last use at which a cached library is removed (when another is built)
KEEP_DAYS = 30


def _touch(path):
    try:
        os.utime(path)
    except OSError:
        pass                                  # a read-only cache: nothing is pruned there


def _prune(directory):
    """Remove the libraries of this cache not used for KEEP_DAYS (every change of a
    mechanism or of the package makes a new one; nothing else removes the old), and the
    temporary files of builds that died (killed, a full disk): those dated further than
    BUILD_TIMEOUT + DEBRIS_MARGIN from now, either way (a clock set back)."""
    now = time.time()
    limit = now - KEEP_DAYS * 86400.0
    here = glob.escape(directory)
    for sizes in glob.glob(os.path.join(here, 'cog_id_kernels_*.json')):
        try:
            if os.path.getmtime(sizes) >= limit:
                continue
            for path in glob.glob(glob.escape(sizes[:-len('.json')]) + '.*'):
                os.unlink(path)
        except OSError:
            pass
    for pattern in (_TEMPORARY + '*', 'tmp*.tmp', 'tmp*.so'):
        for path in glob.glob(os.path.join(here, pattern)):
            try:
                if abs(now - os.lstat(path).st_mtime) > BUILD_TIMEOUT + DEBRIS_MARGIN:
                    os.unlink(path)
            except OSError:
                pass


def _import(name, path):
    loader = importlib.machinery.ExtensionFileLoader(name, path)
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def _remove(path):
    """Remove a temporary file, if it is there: a cleanup never hides the error it follows
    (a compiler removes its own output when it fails, e.g. on a full disk)."""
    try:
        os.unlink(path)
    except OSError:
        pass


def _write_atomically(path, text, mode=0o644):
    """``path`` appears with ``text`` whole, or not at all; nothing is left on failure."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), prefix=_TEMPORARY, suffix='.tmp')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write(text)
        os.chmod(tmp, mode)                   # the modes of installed files, whatever the umask
        os.replace(tmp, path)
    except BaseException:
        _remove(tmp)
        raise


# --- the compiler ----------------------------------------------------------------------------

def _build(command, include, c_file, target, level):
    """Compile, then the library and its sha256 appear (the checksum last). On any
    exception (a failure, a timeout, or one a signal handler raises to stop the process)
    the compiler is stopped and its output removed."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(target), prefix=_TEMPORARY,
                               suffix=_suffix())
    os.close(fd)
    try:
        _compile(command, [level, *FLAGS, '-I' + include, c_file, '-o', tmp])
        os.chmod(tmp, 0o755)
        digest = _digest(tmp)
        os.replace(tmp, target)
    except BaseException:
        _remove(tmp)
        raise
    _write_atomically(target + '.sha256', digest + '\n')


def _compile(command, arguments):
    """Run the compiler; NativeUnavailable when it does not run, fails or takes more than
    BUILD_TIMEOUT. However this returns or raises, the compiler and what it started are
    gone: stopped as a process group on a timeout and on any exception while it runs."""
    argv = [*command, *arguments]
    try:
        compiling = subprocess.Popen(
            _guarded(argv), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True, errors='replace', start_new_session=True,
            preexec_fn=_parent_death_signal())
    except OSError as exc:
        raise NativeUnavailable(f'the C compiler {command[0]} did not run: {exc}') from None
    try:
        _, errors = compiling.communicate(timeout=BUILD_TIMEOUT)
    except subprocess.TimeoutExpired:
        _stop(compiling)
        raise NativeUnavailable(f'the C compiler {command[0]} took more than '
                                f'{BUILD_TIMEOUT} s') from None
    except BaseException:                     # e.g. raised by a signal handler: stop it too
        _stop(compiling)
        raise
    if compiling.returncode != 0:
        first = (errors.strip().splitlines() or ['no message'])[0]
        raise NativeUnavailable(f'the C compiler {command[0]} failed: {first}')


def _stop(process):
    """Kill the compiler's process group (the compiler and what it started) and reap it."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except OSError:
        pass                                  # gone already
    if process.stderr is not None:
        process.stderr.close()
    try:
        process.wait(timeout=10.0)
    except subprocess.TimeoutExpired:
        pass                                  # killed all the same; reaped when collected


#: The compiler runs under this shell, the leader of its process group. The shell gets a
#: parent-death signal (SIGTERM) and on it kills its whole group: the compiler driver and
#: the programs it started (cc1, as, ld), which a parent-death signal of their own could
#: not reach (it is not inherited by a child). So no compiler outlives the process that
#: waits for it (the node's trajectory process, a killed node), nor the detached -O2
#: builder, which waits for its compiler and is its parent there.
_GUARD = 'trap "kill -KILL 0" TERM; "$@" & wait $!'

_PR_SET_PDEATHSIG = 1


def _guarded(argv):
    return ['/bin/sh', '-c', _GUARD, argv[0], *argv] if _prctl() is not None else argv


def _parent_death_signal():
    """The preexec_fn that gives the compiler's shell SIGTERM when the thread that started
    it ends (prctl PR_SET_PDEATHSIG; the thread is the one that waits for it), or None where
    there is no prctl (not Linux: the compiler is then run as before, without the shell)."""
    prctl = _prctl()
    if prctl is None:
        return None
    parent = os.getpid()

    def die_with_parent():
        prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        if os.getppid() != parent:            # it died before the signal was set: now
            os._exit(1)
    return die_with_parent


def _prctl():
    """libc's prctl, looked up once (before any fork: the child only calls it), or None."""
    if not _PRCTL:
        function = None
        if sys.platform.startswith('linux') and os.path.exists('/bin/sh'):
            try:
                function = ctypes.CDLL(None, use_errno=True).prctl
                function.argtypes = [ctypes.c_int] + [ctypes.c_ulong] * 4
                function.restype = ctypes.c_int
            except (OSError, AttributeError):
                function = None
        _PRCTL.append(function)
    return _PRCTL[0]


_PRCTL = []


# --- the background -O2 build ----------------------------------------------------------------

#: the background build: a detached process (it outlives the one that starts it) that
#: loads this module (standard library only) and runs _build_detached
_BACKGROUND = r"""
import importlib.util, json, os, sys
if os.fork():
    os._exit(0)                               # detached: the starter waits for nothing
os.setsid()
spec = importlib.util.spec_from_file_location('cog_id_ros_native_build', sys.argv[1])
native = importlib.util.module_from_spec(spec)
spec.loader.exec_module(native)
native._build_detached(*json.loads(sys.argv[2]))
"""


def _build_detached(command, include, c_file, target, lock, level):
    """The background build (in its own process): :func:`_build`, then the lock goes."""
    try:
        _build(command, include, c_file, target, level)
    except (NativeUnavailable, OSError):
        pass                                  # the quick library serves; a later load retries
    finally:
        _remove(lock)


def _build_in_background(command, directory, name):
    """Start the -O2 build of ``name`` unless one is under way (its lock is younger than
    BUILD_TIMEOUT, and not dated in the future); the quick library serves meanwhile, and a
    later load uses the new one."""
    if command is None:
        return
    paths = _paths(directory, name)
    try:
        age = time.time() - os.path.getmtime(paths['lock'])
    except OSError:
        age = None                            # no lock: no build under way
    if age is not None:
        if -FUTURE_SLACK <= age <= BUILD_TIMEOUT:
            return                            # another process is building it
        # a build that died leaves its lock; one dated in the future (a clock set back)
        # would otherwise hold up the -O2 build until the clock got there
        _log.warning('cog_id_ros: removing the stale lock %s (%s): the -O2 build of these '
                     'kernels starts again', paths['lock'],
                     f'{age:.0f} s old' if age > 0 else f'dated {-age:.0f} s in the future')
        _remove(paths['lock'])
    try:
        os.close(os.open(paths['lock'], os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
    except OSError:
        return                                # someone else took it just now
    try:
        arguments = [command, _include(), paths['c'], paths['O2'], paths['lock'], '-O2']
        starter = subprocess.Popen(
            [sys.executable, '-c', _BACKGROUND, os.path.abspath(__file__),
             json.dumps(arguments)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        starter.wait()
    except (OSError, NativeUnavailable):
        _remove(paths['lock'])
