"""Compiled kernels: the traced kernels as C, built by the system's C compiler, cached on disk.

``backend='native'`` (and ``'auto'`` where it can) writes the mechanism's three kernels as a
CPython extension module (emitter.c_module_source), compiles it once and keeps the library
in a cache directory keyed by a hash of what it is made of (the mechanism's model as read and
the core's source, kernels.kernel_key), the Python version, the flags and ``$CC`` if set:

* the cache directory is ``$COG_ID_ROS_CACHE`` if set, else ``$XDG_CACHE_HOME/cog_id_ros``
  (an absolute ``$XDG_CACHE_HOME`` only: a relative one is ignored, as the XDG spec says)
  or ``$HOME/.cache/cog_id_ros``. Where there is none (no ``$HOME`` either) the library is
  built for this process only, in a private temporary directory removed at its exit;
* a library in the cache is loaded code: whoever can write there can run code as the user
  who loads it. So the cache is trusted only when the directory is owned by this process's
  user (its effective uid) and not writable by group or others, and the library, its
  checksum and its sizes file are that user's and not writable by group or others either;
  otherwise nothing is loaded from or written to it, one log line says why, and the
  library is built in a private temporary directory for this process only. The cache
  directory and the parents made for it get mode 0700 whatever the umask
  (docs/reliability.md, "The kernel cache: who may write there");
* a cached library there is used even when the directory is read-only, and when it cannot
  be written the library is built in a private temporary directory for this process only;
* what is loaded is what was checked: the library is opened once, its owner, mode and size
  read from the open file, its bytes hashed and compared with the sha256 and the size
  recorded when it was built, its ELF headers checked to lie within the file (a truncated
  library would crash the process with SIGBUS), and the loader is given that open file;
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
import stat
import struct
import subprocess
import sys
import sysconfig
import tempfile
import time

#: flags of every build: IEEE doubles as Python computes them
FLAGS = ['-shared', '-fPIC', '-ffp-contract=off', '-fno-fast-math',
         '-fno-unsafe-math-optimizations']

#: operations (the three kernels') above which the first build is -O0, -O2 following in background
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


class _Untrusted(Exception):
    """A file of the cache that another user wrote or may write: not loaded."""


class _Damaged(Exception):
    """A library that is not what was built (cut short, changed): not loaded."""


def cache_directory():
    """Where libraries are kept (see the module docstring), or None when there is no such
    place (no $COG_ID_ROS_CACHE, no absolute $XDG_CACHE_HOME, no absolute $HOME)."""
    configured = os.environ.get('COG_ID_ROS_CACHE')
    if configured:
        return os.path.abspath(os.path.expanduser(configured))
    base = os.environ.get('XDG_CACHE_HOME', '')
    if not os.path.isabs(base):               # the XDG spec: a relative path is ignored
        home = os.environ.get('HOME', '')
        if not os.path.isabs(home):           # empty or unset: not /.cache, shared by all
            return None
        base = os.path.join(home, '.cache')
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
    if not _CAN_CHECK_OWNERS:
        raise NativeUnavailable('compiled kernels need a system where the owner of a cached '
                                'library can be checked (POSIX: os.geteuid, os.open with '
                                'dir_fd)')
    explicit = os.environ.get('CC', '')       # a compiler of one's own: libraries of its own
    digest = hashlib.sha256('\0'.join([key, sys.version, _suffix(), ' '.join(FLAGS),
                                       explicit]).encode()).hexdigest()[:20]
    name = f'cog_id_kernels_{digest}'
    configured = cache_directory()
    cache, writable = _open_cache(configured)
    try:
        if cache is not None:
            try:
                found = _load_cached(cache, configured, name)
            except _Untrusted as exc:
                _say_untrusted(configured, str(exc))
                os.close(cache)
                cache, found = None, None     # neither read nor written from now on
            if found is not None:
                module, operations, level = found
                _touch(_paths(configured, name)['json'])   # in use: not pruned
                if level == 'O0':             # an -O2 build that never finished: again
                    _build_in_background(compiler(), configured, name)
                return module, operations
        failure = _failed.get((configured, name))
        if failure is not None:
            raise NativeUnavailable(failure)
        command, why = find_compiler()
        if command is None:
            raise NativeUnavailable(why)
        include = _include()
        source, operations = make_source(name)
        shared = cache is not None and writable
        try:
            module = _build_and_load(command, include, source, operations, name,
                                     configured if shared else None)
        except NativeUnavailable as exc:      # failed or timed out: not tried again
            _failed[(configured, name)] = str(exc)
            raise
        return module, operations
    finally:
        if cache is not None:
            os.close(cache)


def _build_and_load(command, include, source, operations, name, directory):
    """Build the library ``name`` in the cache ``directory`` (None: in a private directory
    of this process) and load it; NativeUnavailable says why not."""
    shared = directory is not None
    try:
        if not shared:                        # for this process only, removed at its exit
            directory = _private_directory()
        paths = _paths(directory, name)
        if shared:
            _prune(directory)                 # before: what it frees helps a full disk
        _write_atomically(paths['c'], source)
        _write_atomically(paths['json'], json.dumps(operations))
        level = 'O0' if sum(operations.values()) > QUICK_ABOVE else 'O2'
        _build(command, include, paths['c'], paths[level], '-' + level)
        fd = _open_directory(directory)
        try:
            module = _load_verified(fd, directory, name, level)
        finally:
            os.close(fd)
        if module is None:
            raise _Damaged(f'{paths[level]} is not there after its build')
        if level == 'O0' and shared:
            _build_in_background(command, directory, name)
        return module
    except (OSError, ImportError, _Damaged, _Untrusted) as exc:  # a full disk, a bad file ...
        raise NativeUnavailable(f'the compiled kernels could not be built or loaded in '
                                f'{directory}: {exc}') from None


def _paths(directory, name):
    base = os.path.join(directory, name)
    return {'c': base + '.c', 'json': base + '.json', 'O2': base + '.O2' + _suffix(),
            'O0': base + '.O0' + _suffix(), 'lock': base + '.O2.lock'}


# --- the trust model: what may be loaded -----------------------------------------------------

#: whether this system can say who owns a file opened relative to a directory (not Windows)
_CAN_CHECK_OWNERS = hasattr(os, 'geteuid') and os.open in os.supports_dir_fd

_O_DIRECTORY = getattr(os, 'O_DIRECTORY', 0)
_O_NOFOLLOW = getattr(os, 'O_NOFOLLOW', 0)
_O_NONBLOCK = getattr(os, 'O_NONBLOCK', 0)    # a FIFO named like a library: no hang


def _open_cache(directory):
    """(descriptor of the cache directory, whether this process may write there), or
    (None, False) when it is not to be used; one log line says why when it is a surprise
    (none at all, or one that others may write)."""
    if directory is None:
        _say('cog_id_ros: no directory for the kernel cache ($COG_ID_ROS_CACHE is not set, '
             '$XDG_CACHE_HOME is not an absolute path and $HOME is empty or not set): '
             'compiled kernels are built for this process only; set COG_ID_ROS_CACHE to a '
             'directory of your own to keep them')
        return None, False
    try:
        _make_private(directory)
    except OSError:
        pass                                  # read-only, or under a file: opened or not below
    try:
        return _open_directory(directory), os.access(directory, os.W_OK)
    except _Untrusted as exc:
        _say_untrusted(directory, str(exc))
    except OSError:
        pass                                  # not there: built for this process only
    return None, False


def _make_private(path):
    """Make the directory ``path`` and its missing parents with mode 0700, whatever the
    umask (os.makedirs gives the parents 0777 less the umask: 0777 under umask 000)."""
    missing = []
    while not os.path.lexists(path):
        missing.append(path)
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    for path in reversed(missing):
        try:
            os.mkdir(path, 0o700)
        except FileExistsError:
            continue                          # made by someone else meanwhile: not ours
        os.chmod(path, 0o700)                 # mkdir's mode is reduced by the umask only


def _open_directory(path):
    """A descriptor of the directory ``path`` (every file of the cache is then opened
    relative to it: what was checked is what is read); _Untrusted when it is not this
    user's or group or others may write it."""
    fd = os.open(path, os.O_RDONLY | _O_DIRECTORY | os.O_CLOEXEC)
    try:
        problem = _untrusted(os.fstat(fd), path)
    except BaseException:
        os.close(fd)
        raise
    if problem:
        os.close(fd)
        raise _Untrusted(problem)
    return fd


def _untrusted(st, path):
    """Why a file or directory of this stat may have been written by another user, or None."""
    if st.st_uid != os.geteuid():
        return f'{path} is owned by uid {st.st_uid}, not by uid {os.geteuid()} (this process)'
    if st.st_mode & 0o022:
        return (f'{path} has mode {stat.S_IMODE(st.st_mode):04o}: group or others may '
                f'write it')
    return None


def _say(message):
    """Log ``message`` once per process."""
    if message not in _said:
        _said.add(message)
        _log.warning(message)


_said = set()


def _say_untrusted(directory, problem):
    _say(f'cog_id_ros: compiled kernels are not loaded from the cache {directory}: {problem}, '
         f'and whoever can write there could run code in this process; they are built for '
         f'this process only, in a private temporary directory. To keep them: a cache '
         f'directory owned by uid {os.geteuid()}, not writable by group or others (chmod '
         f'go-w), or COG_ID_ROS_CACHE set to one (docs/reliability.md)')


def _open_file(fd, filename, directory):
    """(descriptor, stat) of the regular file ``filename`` in the cache directory of
    descriptor ``fd`` (a symbolic link is not followed: this cache makes none), or
    (None, None) when there is none; _Untrusted when it is another user's or group or
    others may write it."""
    try:
        opened = os.open(filename, os.O_RDONLY | os.O_CLOEXEC | _O_NOFOLLOW | _O_NONBLOCK,
                         dir_fd=fd)
    except OSError:
        return None, None
    try:
        st = os.fstat(opened)
        problem = _untrusted(st, os.path.join(directory, filename))
    except BaseException:
        os.close(opened)
        raise
    if not stat.S_ISREG(st.st_mode):
        os.close(opened)
        return None, None
    if problem:
        os.close(opened)
        raise _Untrusted(problem)
    return opened, st


def _read_file(fd, filename, directory):
    """The bytes of ``filename`` (see :func:`_open_file`), or None."""
    opened, _ = _open_file(fd, filename, directory)
    if opened is None:
        return None
    with os.fdopen(opened, 'rb') as f:
        return f.read()


def _load_cached(fd, directory, name):
    """(module, operations, level) of the library ``name`` in the cache directory of
    descriptor ``fd``, the -O2 build before the -O0 one, or None when neither is there
    intact (it is then built again); _Untrusted when a file of it may be another user's."""
    text = _read_file(fd, name + '.json', directory)
    try:
        operations = json.loads(text) if text is not None else None
    except ValueError:
        operations = None                     # damaged: built again
    if not isinstance(operations, dict):
        return None
    for level in ('O2', 'O0'):
        try:
            module = _load_verified(fd, directory, name, level)
        except (_Damaged, ImportError):
            continue                          # not what was built: built again
        if module is not None:
            return module, operations, level
    return None


def _load_verified(fd, directory, name, level):
    """The module of library ``name`` at ``level`` in the directory of descriptor ``fd``,
    None when it or its checksum is not there. The library is opened once: its bytes are
    hashed and compared with the sha256 and size recorded when it was built, its ELF headers
    checked to lie within them, and the loader loads that open file, not the name again
    (which another file could have taken meanwhile). _Damaged when it is not what was built,
    ImportError when it will not load, _Untrusted as :func:`_open_file`."""
    library = f'{name}.{level}{_suffix()}'
    recorded = _read_file(fd, library + '.sha256', directory)
    if recorded is None:
        return None
    opened, st = _open_file(fd, library, directory)
    if opened is None:
        return None
    path = os.path.join(directory, library)
    try:
        data = _read_all(opened)
        try:
            digest, size = recorded.decode('ascii').split()
            size = int(size)
        except ValueError:                    # UnicodeDecodeError included
            raise _Damaged(f'{path}.sha256 is not a checksum and a size') from None
        if not len(data) == st.st_size == size:
            raise _Damaged(f'{path} has {len(data)} bytes, {size} when it was built')
        if hashlib.sha256(data).hexdigest() != digest:
            raise _Damaged(f'{path} is not the library that was built (its sha256 differs)')
        problem = _elf_problem(data)
        if problem:
            raise _Damaged(f'{path}: {problem}')
    except BaseException:
        os.close(opened)
        raise
    return _import_opened(name, opened, st, path)


def _read_all(fd):
    chunks = []
    while True:
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return b''.join(chunks)
        chunks.append(chunk)


#: (st_dev, st_ino) of every library loaded through its descriptor -> that descriptor, kept
#: open for the life of the process (see _import_opened)
_kept = {}


def _import_opened(name, fd, st, path):
    """The module of the library open as ``fd`` (stat ``st``, verified); the descriptor is
    this function's to close or keep. The loader is given ``/proc/<pid>/fd/<fd>``: the very
    file that was verified, whatever has become of ``path`` since. That descriptor is never
    closed: the dynamic loader knows a library by the name it was given, and a later library
    opened under the same descriptor number (the same name) would be taken for the first
    one, loaded or not. Extension modules are never unloaded, so this costs a descriptor
    per library, which its mappings outlive anyway; the same file loaded again uses the
    descriptor kept for it. The pid in the name keeps a forked child's names apart from its
    parent's. Without /proc the library is loaded by its path if that is still the file
    that was verified."""
    through = f'/proc/{os.getpid()}/fd/{{}}'
    kept = _kept.get((st.st_dev, st.st_ino))
    if kept is not None and _same_file(through.format(kept), st):
        os.close(fd)
        return _import(name, through.format(kept))
    if _same_file(through.format(fd), st):
        _kept[(st.st_dev, st.st_ino)] = fd    # the loader's name for it from now on
        return _import(name, through.format(fd))
    try:
        if not _same_file(path, st):
            raise _Damaged(f'{path} was replaced while it was being loaded')
        return _import(name, path)
    finally:
        os.close(fd)


def _same_file(path, st):
    try:
        here = os.stat(path)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (st.st_dev, st.st_ino)


#: per ELF class (e_ident[4]): word format, offsets of e_phoff, e_shoff and e_phentsize,
#: size of the file header, and in a program header the offsets of p_offset and p_filesz
#: and its size
_ELF = {1: ('I', 28, 32, 42, 52, 4, 16, 32), 2: ('Q', 32, 40, 54, 64, 8, 32, 56)}


def _elf_problem(data):
    """Why the dynamic loader would read beyond the end of this ELF library, or None. It
    maps the segments at the offsets its headers give, and touching a mapped page beyond the
    end of the file is a SIGBUS that kills the process, not an error: so every segment must
    lie within the file. (Not ELF: another platform's format, whose loader checks its own.)"""
    if data[:4] != b'\x7fELF':
        return None
    if len(data) < 6 or data[4] not in _ELF or data[5] not in (1, 2):
        return 'not an ELF library of a known class and byte order'
    word, at_phoff, at_shoff, at_sizes, header, at_offset, at_filesz, entry = _ELF[data[4]]
    order = '<' if data[5] == 1 else '>'
    end = len(data)
    if end < header:
        return f'cut short: {end} bytes, less than an ELF header'
    phoff, = struct.unpack_from(order + word, data, at_phoff)
    shoff, = struct.unpack_from(order + word, data, at_shoff)
    phentsize, phnum, shentsize, shnum = struct.unpack_from(order + 'HHHH', data, at_sizes)
    if phnum and (phentsize < entry or phoff + phnum * phentsize > end):
        return f'cut short: its program headers are not within its {end} bytes'
    for k in range(phnum):
        at = phoff + k * phentsize
        offset, = struct.unpack_from(order + word, data, at + at_offset)
        filesz, = struct.unpack_from(order + word, data, at + at_filesz)
        if offset + filesz > end:
            return f'cut short: a segment ends at byte {offset + filesz} of its {end}'
    if shoff and shoff + max(shnum, 1) * shentsize > end:
        return f'cut short: its section headers end beyond its {end} bytes'
    return None


def _import(name, path):
    loader = importlib.machinery.ExtensionFileLoader(name, path)
    spec = importlib.util.spec_from_file_location(name, path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


# --- the cache's housekeeping ----------------------------------------------------------------

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


#: pid -> the private directory of that process (a forked child makes its own)
_private = {}


def _private_directory():
    """A directory of this process only (mkdtemp: mode 0700), removed at its exit."""
    directory = _private.get(os.getpid())
    if directory is None or not os.path.isdir(directory):
        directory = _private[os.getpid()] = tempfile.mkdtemp(prefix='cog_id_ros-')
        atexit.register(_remove_private, directory, os.getpid())
    return directory


def _remove_private(directory, pid):
    if os.getpid() == pid:                    # not a forked child's exit: the parent's own
        shutil.rmtree(directory, ignore_errors=True)


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
    """Compile, then the library and its sha256 and size appear (the checksum last). On any
    exception (a failure, a timeout, or one a signal handler raises to stop the process)
    the compiler is stopped and its output removed."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(target), prefix=_TEMPORARY,
                               suffix=_suffix())
    os.close(fd)
    try:
        _compile(command, [level, *FLAGS, '-I' + include, c_file, '-o', tmp])
        with open(tmp, 'rb') as f:
            data = f.read()
        problem = _elf_problem(data)
        if problem:
            raise NativeUnavailable(f'the C compiler {command[0]} made a damaged library '
                                    f'({problem})')
        os.chmod(tmp, 0o755)
        os.replace(tmp, target)
    except BaseException:
        _remove(tmp)
        raise
    _write_atomically(target + '.sha256', f'{hashlib.sha256(data).hexdigest()} {len(data)}\n')


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
