"""Compiled kernels: the traced kernels as C, built by the system's C compiler, cached on disk.

``backend='native'`` (and ``'auto'`` where it can) writes the mechanism's two kernels as a
CPython extension module (emitter.c_module_source), compiles it once and keeps the library
in a cache directory keyed by a hash of what it is made of (the mechanism's parameters and
the core's source, kernels.NativeKernels), the Python version and the flags:

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
import subprocess
import sys
import sysconfig
import tempfile
import time

#: flags of every build: IEEE doubles as Python computes them
FLAGS = ['-shared', '-fPIC', '-ffp-contract=off', '-fno-fast-math']

#: operations (both kernels) above which the first build is -O0 and -O2 follows in background
QUICK_ABOVE = 6000

#: seconds a build may take before it counts as failed
BUILD_TIMEOUT = 300


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
    digest = hashlib.sha256('\0'.join([key, sys.version, _suffix(),
                                       ' '.join(FLAGS)]).encode()).hexdigest()[:20]
    name = f'cog_id_kernels_{digest}'
    directory = cache_directory()
    optimised = os.path.join(directory, name + '.O2' + _suffix())
    quick = os.path.join(directory, name + '.O0' + _suffix())
    sizes = os.path.join(directory, name + '.json')
    for path in (optimised, quick):
        if os.path.exists(path):
            try:
                with open(sizes, encoding='utf-8') as f:
                    operations = json.load(f)
                module = _import(name, path)
            except (ImportError, OSError, ValueError):
                continue                      # a damaged file: build it again
            _touch(sizes)                     # in use: not pruned
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
            optimised = os.path.join(directory, name + '.O2' + _suffix())
            quick = os.path.join(directory, name + '.O0' + _suffix())
            sizes = os.path.join(directory, name + '.json')
        c_file = os.path.join(directory, name + '.c')
        _write_atomically(c_file, source)
        _write_atomically(sizes, json.dumps(operations))
        if sum(operations.values()) > QUICK_ABOVE:
            _build(command, include, c_file, quick, '-O0')
            if writable:
                _build_in_background(command, include, c_file, optimised, '-O2')
                _prune(directory)
            return _import(name, quick), operations
        _build(command, include, c_file, optimised, '-O2')
        if writable:
            _prune(directory)
        return _import(name, optimised), operations
    except (OSError, ImportError) as exc:     # a full disk, a file that will not load ...
        raise NativeUnavailable(f'the compiled kernels could not be built or loaded in '
                                f'{directory}: {exc}') from None


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


def _write_atomically(path, text):
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix='.tmp')
    with os.fdopen(fd, 'w', encoding='utf-8') as f:
        f.write(text)
    os.replace(tmp, path)


def _build(command, include, c_file, target, level):
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(target), suffix=_suffix())
    os.close(fd)
    try:
        done = subprocess.run([*command, level, *FLAGS, '-I' + include, c_file, '-o', tmp],
                              capture_output=True, text=True, timeout=BUILD_TIMEOUT)
    except (OSError, subprocess.TimeoutExpired) as exc:
        os.unlink(tmp)
        raise NativeUnavailable(f'the C compiler {command[0]} did not run: {exc}') from None
    if done.returncode != 0:
        os.unlink(tmp)
        first = (done.stderr.strip().splitlines() or ['no message'])[0]
        raise NativeUnavailable(f'the C compiler {command[0]} failed: {first}')
    os.replace(tmp, target)


def _build_in_background(command, include, c_file, target, level):
    """Build ``target`` in a detached process (it outlives this one if need be); the file
    appears, complete, once the build has succeeded."""
    tmp = target + f'.{os.getpid()}.tmp'
    script = (f'{shlex.join([*command, level, *FLAGS, "-I" + include, c_file, "-o", tmp])} '
              f'&& mv -f {shlex.quote(tmp)} {shlex.quote(target)} || rm -f {shlex.quote(tmp)}')
    try:
        subprocess.Popen(['sh', '-c', script], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    except OSError:
        pass                                  # the quick build serves; next load tries again
