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
  Python's headers (``Python.h``, the python3-dev package);
* the flags keep the numbers those of the Python kernels: no contraction into fused
  multiply-adds (``-ffp-contract=off``), no fast-math; every operation is the IEEE double
  operation Python does, so the kernels agree with ``backend='python'`` to the last bit;
* a library not used for ``KEEP_DAYS`` days is removed when another one is built;
* small kernels are compiled with ``-O2`` at once. A large one (more than
  ``QUICK_ABOVE`` operations, where -O2 takes seconds) is compiled with ``-O0`` at once,
  which is fast to build and several times slower to run, while ``-O2`` is built in the
  background into the cache for the next load.

Nothing here is needed to run: without a compiler or headers :class:`NativeUnavailable`
says why and the caller falls back to the Python kernels.
"""
import atexit
import glob
import hashlib
import importlib.machinery
import importlib.util
import json
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


class NativeUnavailable(Exception):
    """No compiled kernels here: no compiler, no Python headers, or the build failed."""


def cache_directory():
    """Where libraries are kept (see the module docstring)."""
    configured = os.environ.get('COG_ID_ROS_CACHE')
    if configured:
        return os.path.abspath(os.path.expanduser(configured))
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'cog_id_ros')


def compiler():
    """The C compiler command (a list), or None."""
    configured = os.environ.get('CC')
    if configured:
        command = shlex.split(configured)
        return command if command and shutil.which(command[0]) else None
    for name in ('cc', 'gcc', 'clang'):
        path = shutil.which(name)
        if path:
            return [path]
    return None


def _suffix():
    return sysconfig.get_config_var('EXT_SUFFIX') or '.so'


def _include():
    include = sysconfig.get_paths().get('include')
    if not include or not os.path.exists(os.path.join(include, 'Python.h')):
        raise NativeUnavailable(f'no Python headers (Python.h) in {include}: install the '
                                f'python3-dev package')
    return include


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
    command = compiler()
    if command is None:
        raise NativeUnavailable('no C compiler (cc, gcc or clang on the PATH, or $CC)')
    include = _include()
    source, operations = make_source(name)
    try:
        os.makedirs(directory, exist_ok=True)
        writable = os.access(directory, os.W_OK)
    except OSError:
        writable = False
    try:
        if not writable:                      # for this process only, removed at its exit
            directory = tempfile.mkdtemp(prefix='cog_id_ros-')
            atexit.register(shutil.rmtree, directory, ignore_errors=True)
            paths = _paths(directory, name)
        _write_atomically(paths['c'], source)
        _write_atomically(paths['json'], json.dumps(operations))
        if sum(operations.values()) > QUICK_ABOVE:
            _build(command, include, paths['c'], paths['O0'], '-O0')
            if writable:
                _build_in_background(command, directory, name)
                _prune(directory)
            return _import(name, paths['O0']), operations
        _build(command, include, paths['c'], paths['O2'], '-O2')
        if writable:
            _prune(directory)
        return _import(name, paths['O2']), operations
    except (OSError, ImportError) as exc:     # a full disk, a file that will not load ...
        raise NativeUnavailable(f'the compiled kernels could not be built or loaded in '
                                f'{directory}: {exc}') from None


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
    mechanism or of the package makes a new one; nothing else removes the old)."""
    limit = time.time() - KEEP_DAYS * 86400.0
    for sizes in glob.glob(os.path.join(directory, 'cog_id_kernels_*.json')):
        try:
            if os.path.getmtime(sizes) >= limit:
                continue
            for path in glob.glob(sizes[:-len('.json')] + '.*'):
                os.unlink(path)
        except OSError:
            pass


def _import(name, path):
    loader = importlib.machinery.ExtensionFileLoader(name, path)
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def _write_atomically(path, text, mode=0o644):
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix='.tmp')
    with os.fdopen(fd, 'w', encoding='utf-8') as f:
        f.write(text)
    os.chmod(tmp, mode)                       # readable by every user of a shared cache
    os.replace(tmp, path)


def _build(command, include, c_file, target, level):
    """Compile, then the library and its sha256 appear (the checksum last)."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(target), suffix=_suffix())
    os.close(fd)
    try:
        compiling = subprocess.Popen([*command, level, *FLAGS, '-I' + include, c_file, '-o',
                                      tmp], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                     text=True, start_new_session=True)
        try:
            _, errors = compiling.communicate(timeout=BUILD_TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(compiling.pid, signal.SIGKILL)   # the compiler and what it started
            compiling.communicate()
            raise NativeUnavailable(f'the C compiler {command[0]} took more than '
                                    f'{BUILD_TIMEOUT} s') from None
    except OSError as exc:
        os.unlink(tmp)
        raise NativeUnavailable(f'the C compiler {command[0]} did not run: {exc}') from None
    except NativeUnavailable:
        os.unlink(tmp)
        raise
    if compiling.returncode != 0:
        os.unlink(tmp)
        first = (errors.strip().splitlines() or ['no message'])[0]
        raise NativeUnavailable(f'the C compiler {command[0]} failed: {first}')
    os.chmod(tmp, 0o755)
    digest = _digest(tmp)
    os.replace(tmp, target)
    _write_atomically(target + '.sha256', digest + '\n')


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
        try:
            os.unlink(lock)
        except OSError:
            pass


def _build_in_background(command, directory, name):
    """Start the -O2 build of ``name`` unless one is under way (its lock is younger than
    BUILD_TIMEOUT); the quick library serves meanwhile, and a later load uses the new one."""
    if command is None:
        return
    paths = _paths(directory, name)
    try:
        if time.time() - os.path.getmtime(paths['lock']) < BUILD_TIMEOUT:
            return                            # another process is building it
        os.unlink(paths['lock'])              # a build that died: its lock is stale
    except OSError:
        pass
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
        try:
            os.unlink(paths['lock'])
        except OSError:
            pass
