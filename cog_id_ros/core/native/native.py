"""Compiled kernels: the traced kernels as C, built by the system's C compiler, cached on disk.

``backend='native'`` (and ``'auto'`` where it can) writes the mechanism's kernels as a
CPython extension module (emitter.c_module_source), compiles it once and keeps the library
in a cache directory keyed by a hash of what it is made of (the mechanism's model as read and
the core's source, kernels.kernel_key), the Python version, the flags and ``$CC`` if set.
:func:`load_module` is the whole of it; its rooms:

* native_cache.py, the cache directory: ``$COG_ID_ROS_CACHE`` if set, else
  ``$XDG_CACHE_HOME/cog_id_ros`` (an absolute ``$XDG_CACHE_HOME`` only) or
  ``$HOME/.cache/cog_id_ros``. Where there is none (no ``$HOME`` either) the library is
  built for this process only, in a private temporary directory removed at its exit. A
  library in the cache is loaded code: whoever can write there can run code as the user
  who loads it. So the cache is trusted only when the directory is owned by this process's
  user (its effective uid) and not writable by group or others, and the library, its
  checksum and its sizes file are that user's and not writable by group or others either;
  otherwise nothing is loaded from or written to it, one log line says why, and the
  library is built in a private temporary directory for this process only
  (docs/reliability.md, "The kernel cache: who may write there"). A cached library there
  is used even when the directory is read-only, and when it cannot be written the library
  is built in a private temporary directory for this process only. A library not used for
  ``KEEP_DAYS`` days is removed when another one is built, and so are temporary files of
  builds that died (killed, a full disk) once they are older than any live build could be;
* native_loading.py: what is loaded is what was checked: the library is opened once, its
  owner, mode and size read from the open file, its bytes hashed and compared with the
  sha256 and the size recorded when it was built, its ELF headers checked to lie within
  the file (a truncated library would crash the process with SIGBUS), and the loader is
  given that open file;
* native_build.py, the compiler: ``$CC`` if set, else ``cc``, ``gcc`` or ``clang`` on the
  PATH; it needs Python's headers (``Python.h``, the python3-dev package). A ``$CC`` that
  is not a command (an unbalanced quote, no executable) is no compiler: the Python kernels
  serve. A compiler dies with the process that started it (Linux: a parent-death signal),
  is stopped after ``BUILD_TIMEOUT`` seconds, and is stopped with everything it started on
  any exception, one raised by a signal handler to stop the process included.

Here: a build that failed or timed out is not tried again by the same process (its
:data:`PROCESS`): the next load of the same kernels raises :class:`NativeUnavailable` at
once with the first failure's reason. The flags keep the numbers those of the Python
kernels: no contraction into fused multiply-adds (``-ffp-contract=off``), no fast-math;
every operation is the IEEE double operation Python does, so the kernels agree with
``backend='python'`` to the last bit. Small kernels are compiled with ``-O2`` at once. A
large one (more than ``QUICK_ABOVE`` operations, where -O2 takes seconds) is compiled with
``-O0`` at once, which is fast to build and several times slower to run, while ``-O2`` is
built in the background into the cache for the next load (one build at a time: a lock file,
counted as stale, and broken with a log line, when it is older than ``BUILD_TIMEOUT`` or
dated in the future). The background build runs at the lowest priority (niceness 19 and,
on Linux, the idle scheduling class: native_build.lower_priority), so it only uses a core
nothing else wants, and nothing waits for it: the first answer comes from the -O0 library.

Nothing here is needed to run: without a compiler or headers :class:`NativeUnavailable`
says why and the caller falls back to the Python kernels.
"""
from collections.abc import Callable
import hashlib
import json
import logging
import os
import subprocess
import sys
import time
from types import ModuleType

from . import native_build
from .native_build import (
    BuildFailed,
    build_library,
    compiler,
    find_compiler,
    library_suffix,
    python_headers,
    remove,
    write_atomically,
)
from .native_cache import (
    CAN_CHECK_OWNERS,
    ProcessMemory,
    Untrusted,
    cache_directory,
    library_paths,
    open_cache,
    open_directory,
    open_file,
    prune,
    touch,
)
from .native_loading import Damaged, load_cached, load_verified

__all__ = ['BUILD_TIMEOUT', 'FLAGS', 'FUTURE_SLACK', 'PROCESS', 'QUICK_ABOVE', 'NativeUnavailable',
           'ProcessMemory', 'cache_directory', 'compiler', 'find_compiler', 'load_module']

#: flags of every build: IEEE doubles as Python computes them
FLAGS = ['-shared', '-fPIC', '-ffp-contract=off', '-fno-fast-math',
         '-fno-unsafe-math-optimizations']

#: operations (all the kernels') above which the first build is -O0, -O2 following in background
QUICK_ABOVE = 6000

#: seconds a build may take before it counts as failed (the compiler is then stopped); read
#: here at each build and handed on: the compiler's bound, the age of a stale lock and of
#: a dead build's debris (native_cache.prune) are this one setting
BUILD_TIMEOUT = 120

#: seconds a lock may be dated in the future and still count as live: file times come from
#: a coarse clock, and a lock further ahead (a clock set back, a file copied from elsewhere)
#: would otherwise block the -O2 build until the clock catches up
FUTURE_SLACK = 5.0

#: what this process remembers of its compiled kernels (a test may give itself a fresh one)
PROCESS = ProcessMemory()

_log = logging.getLogger('cog_id_ros')


class NativeUnavailable(Exception):
    """No compiled kernels here: no compiler, no Python headers, or the build failed."""


#: what the kernels' C and their operations per kernel are made from: the module's name
MakeSource = Callable[[str], tuple[str, dict[str, int]]]


def load_module(key: str, make_source: MakeSource) -> tuple[ModuleType, dict[str, int]]:
    """(compiled module, operations per kernel) for the kernels identified by ``key`` (a
    text naming everything they are made of), from the cache or built now from
    ``make_source(module name) -> (C source, {kernel: operations})``. How large the kernels
    are chooses the optimisation."""
    if not CAN_CHECK_OWNERS:
        raise NativeUnavailable('compiled kernels need a system where the owner of a cached '
                                'library can be checked (POSIX: os.geteuid, os.open with '
                                'dir_fd)')
    explicit = os.environ.get('CC', '')       # a compiler of one's own: libraries of its own
    digest = hashlib.sha256('\0'.join([key, sys.version, library_suffix(), ' '.join(FLAGS),
                                       explicit]).encode()).hexdigest()[:20]
    name = f'cog_id_kernels_{digest}'
    configured = cache_directory()
    found, writable = _cached(configured, name)
    if found is not None:
        return found
    failure = PROCESS.failed.get((configured, name))
    if failure is not None:
        raise NativeUnavailable(failure)
    command, why = find_compiler()
    if command is None:
        raise NativeUnavailable(why)
    include, why = python_headers()
    if include is None:
        raise NativeUnavailable(why)
    source, operations = make_source(name)
    try:
        module = _build_and_load(command, include, source, operations, name,
                                 configured if writable else None)
    except NativeUnavailable as exc:          # failed or timed out: not tried again
        PROCESS.failed[(configured, name)] = str(exc)
        raise
    return module, operations


def _cached(directory: str | None,
            name: str) -> tuple[tuple[ModuleType, dict[str, int]] | None, bool]:
    """((module, operations) of the library ``name`` loaded from the cache ``directory``,
    False), or (None, whether it may be built there) when it is not there or not to be
    used (a cache that may be another user's is neither read nor written)."""
    if directory is None:
        PROCESS.say_no_cache()
        return None, False
    cache, writable = open_cache(directory, PROCESS)
    if cache is None:
        return None, False
    try:
        found = load_cached(cache, directory, name, PROCESS.loaded)
        if found is not None and found[2] == 'O0':
            # the -O2 build below compiles the cached source: it must be as much one's own
            # as the libraries (whoever could write it would run code at the next load)
            _check_source(cache, directory, name)
    except Untrusted as exc:
        PROCESS.say_untrusted(directory, str(exc))
        return None, False                    # neither read nor written from now on
    finally:
        os.close(cache)
    if found is None:
        return None, writable
    module, operations, level = found
    touch(library_paths(directory, name)['json'])    # in use: not pruned
    if level == 'O0':                         # an -O2 build that never finished: again
        _build_in_background(compiler(), directory, name)
    return (module, operations), False


def _check_source(cache: int, directory: str, name: str) -> None:
    """Untrusted unless the cached C source of ``name`` (in the open cache directory
    ``cache``) is a file of this user that group and others may not write."""
    opened, _ = open_file(cache, os.path.basename(library_paths(directory, name)['c']),
                          directory)
    if opened is not None:
        os.close(opened)


def _flags(level: str, include: str) -> list[str]:
    """The compiler's flags for a build at ``level`` ('O0' or 'O2')."""
    return ['-' + level, *FLAGS, '-I' + include]


def _build_and_load(command: list[str], include: str, source: str, operations: dict[str, int],
                    name: str, directory: str | None) -> ModuleType:
    """Build the library ``name`` in the cache ``directory`` (None: in a private directory
    of this process) and load it; NativeUnavailable says why not."""
    shared = directory is not None
    try:
        if directory is None:                 # for this process only, removed at its exit
            directory = PROCESS.private_directory()
        paths = library_paths(directory, name)
        if shared:
            prune(directory, BUILD_TIMEOUT)   # before: what it frees helps a full disk
        write_atomically(paths['c'], source)
        write_atomically(paths['json'], json.dumps(operations))
        level = 'O0' if sum(operations.values()) > QUICK_ABOVE else 'O2'
        build_library(command, _flags(level, include), paths['c'], paths[level],
                      BUILD_TIMEOUT)
        fd = open_directory(directory)
        try:
            module = load_verified(fd, directory, name, level, PROCESS.loaded)
        finally:
            os.close(fd)
        if module is None:
            raise Damaged(f'{paths[level]} is not there after its build')
        if level == 'O0' and shared:
            _build_in_background(command, directory, name)
        return module
    except BuildFailed as exc:                # the compiler's own words
        raise NativeUnavailable(str(exc)) from None
    except (OSError, ImportError, Damaged, Untrusted) as exc:  # a full disk, a bad file ...
        raise NativeUnavailable(f'the compiled kernels could not be built or loaded in '
                                f'{directory}: {exc}') from None


# --- the background -O2 build ----------------------------------------------------------------

#: the background build: a detached process (it outlives the one that starts it) that
#: loads native_build.py by its path (standard library only) and runs its build_detached
_BACKGROUND = r"""
import importlib.util, json, os, sys
if os.fork():
    os._exit(0)                               # detached: the starter waits for nothing
os.setsid()
spec = importlib.util.spec_from_file_location('cog_id_ros_native_build', sys.argv[1])
build = importlib.util.module_from_spec(spec)
spec.loader.exec_module(build)
build.build_detached(*json.loads(sys.argv[2]))
"""


def _build_in_background(command: list[str] | None, directory: str, name: str) -> None:
    """Start the -O2 build of ``name`` unless one is under way (its lock is younger than
    BUILD_TIMEOUT, and not dated in the future); the quick library serves meanwhile, and a
    later load uses the new one."""
    if command is None:
        return
    paths = library_paths(directory, name)
    if not _take_lock(paths['lock']):
        return
    include, _ = python_headers()
    if include is None:
        remove(paths['lock'])
        return
    try:
        arguments = [command, _flags('O2', include), paths['c'], paths['O2'], BUILD_TIMEOUT,
                     paths['lock']]
        starter = subprocess.Popen(
            [sys.executable, '-c', _BACKGROUND, os.path.abspath(native_build.__file__),
             json.dumps(arguments)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        starter.wait()
    except OSError:
        remove(paths['lock'])


def _take_lock(lock: str) -> bool:
    """Whether this process now holds the lock of an -O2 build: not when another one holds
    it (younger than BUILD_TIMEOUT and not dated in the future). A build that died leaves
    its lock, and one dated in the future (a clock set back) would otherwise hold up the
    -O2 build until the clock got there: such a lock is stale, removed with a log line."""
    try:
        age = time.time() - os.path.getmtime(lock)
    except OSError:
        age = None                            # no lock: no build under way
    if age is not None:
        if -FUTURE_SLACK <= age <= BUILD_TIMEOUT:
            return False                      # another process is building it
        _log.warning('cog_id_ros: removing the stale lock %s (%s): the -O2 build of these '
                     'kernels starts again', lock,
                     f'{age:.0f} s old' if age > 0 else f'dated {-age:.0f} s in the future')
        remove(lock)
    try:
        os.close(os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
    except OSError:
        return False                          # someone else took it just now
    return True
