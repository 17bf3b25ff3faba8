"""Building one library of compiled kernels: the C compiler found and run safely, its output
checked and recorded.

* the compiler is ``$CC`` if set, else ``cc``, ``gcc`` or ``clang`` on the PATH; it needs
  Python's headers (``Python.h``, the python3-dev package). A ``$CC`` that is not a command
  (an unbalanced quote, no executable) is no compiler;
* a compiler dies with the process that started it (Linux: a parent-death signal given to
  a small shell that then kills its whole process group), is stopped after the timeout it
  is given, and is stopped with everything it started on any exception, one raised by a
  signal handler to stop the process included;
* what it made is checked before it is kept: its ELF headers must lie within the file (a
  truncated library would crash the process that loads it with SIGBUS); then the library
  and its sha256 and size (the checksum last) appear whole, or nothing does.

This module imports the standard library only: the detached background build
(native.py) loads it by its file path, without the package, and runs :func:`build_detached`,
which first gives itself and its compiler the lowest priority (:func:`lower_priority`).
What to build, with which flags and how long it may take, is native.py's to say.
"""
from collections.abc import Callable
import ctypes
import functools
import hashlib
import os
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import sysconfig
import tempfile

#: the names of the cache's temporary files (a build's output, a file being written)
TEMPORARY = 'cog_id_tmp_'


class BuildFailed(Exception):
    """The C compiler did not run, failed, took too long, or made a damaged library."""


def find_compiler() -> tuple[list[str] | None, str | None]:
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


def compiler() -> list[str] | None:
    """The C compiler command (a list), or None (:func:`find_compiler` says why)."""
    return find_compiler()[0]


def python_headers() -> tuple[str | None, str | None]:
    """(the directory of Python's headers, None), or (None, why they are not there)."""
    include = sysconfig.get_paths().get('include')
    if not include or not os.path.exists(os.path.join(include, 'Python.h')):
        return None, (f'no Python headers (Python.h) in {include}: install the python3-dev '
                      f'package')
    return include, None


def library_suffix() -> str:
    """The file name ending of this Python's extension modules (``.cpython-311-...so``)."""
    return sysconfig.get_config_var('EXT_SUFFIX') or '.so'


def build_library(command: list[str], flags: list[str], c_file: str, target: str,
                  timeout: float) -> None:
    """Compile ``c_file`` into the library ``target``, then the library and its sha256 and
    size appear (the checksum last). On any exception (a failure, a timeout, or one a
    signal handler raises to stop the process) the compiler is stopped and its output
    removed."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(target), prefix=TEMPORARY,
                               suffix=library_suffix())
    os.close(fd)
    try:
        _compile(command, [*flags, c_file, '-o', tmp], timeout)
        with open(tmp, 'rb') as f:
            data = f.read()
        problem = elf_problem(data)
        if problem:
            raise BuildFailed(f'the C compiler {command[0]} made a damaged library '
                              f'({problem})')
        os.chmod(tmp, 0o755)
        os.replace(tmp, target)
    except BaseException:
        remove(tmp)
        raise
    write_atomically(target + '.sha256', f'{hashlib.sha256(data).hexdigest()} {len(data)}\n')


def build_detached(command: list[str], flags: list[str], c_file: str, target: str,
                   timeout: float, lock: str) -> None:
    """The background build (in a process of its own): at the lowest priority
    (:func:`lower_priority`), :func:`build_library`, then the lock goes."""
    try:
        lower_priority()
        build_library(command, flags, c_file, target, timeout)
    except (BuildFailed, OSError):
        pass                                  # the quick library serves; a later load retries
    finally:
        remove(lock)


#: the niceness of the background build (the lowest priority there is)
BACKGROUND_NICENESS = 19


def lower_priority() -> None:
    """Give this process, and the compiler it starts (which inherits both), the lowest
    priority: niceness BACKGROUND_NICENESS and, where there is one (Linux), the idle
    scheduling class SCHED_IDLE, which runs only on a core that nothing else wants. So a
    background build takes no time from the process that answers (or from anything else on
    the machine): it only uses a core that would otherwise idle. What the system does not
    allow is left as it is."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, BACKGROUND_NICENESS)
    except (AttributeError, OSError):
        pass                                  # not POSIX, or not allowed: as it is
    idle = getattr(os, 'SCHED_IDLE', None)
    if idle is not None:
        try:
            os.sched_setscheduler(0, idle, os.sched_param(0))
        except OSError:
            pass


def remove(path: str) -> None:
    """Remove a temporary file, if it is there: a cleanup never hides the error it follows
    (a compiler removes its own output when it fails, e.g. on a full disk)."""
    try:
        os.unlink(path)
    except OSError:
        pass


def write_atomically(path: str, text: str, mode: int = 0o644) -> None:
    """``path`` appears with ``text`` whole, or not at all; nothing is left on failure."""
    fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), prefix=TEMPORARY, suffix='.tmp')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as f:
            f.write(text)
        os.chmod(tmp, mode)                   # the modes of installed files, whatever the umask
        os.replace(tmp, path)
    except BaseException:
        remove(tmp)
        raise


# --- a library that lies within its file -----------------------------------------------------

#: per ELF class (e_ident[4]): word format, offsets of e_phoff, e_shoff and e_phentsize,
#: size of the file header, and in a program header the offsets of p_offset and p_filesz
#: and its size
_ELF = {1: ('I', 28, 32, 42, 52, 4, 16, 32), 2: ('Q', 32, 40, 54, 64, 8, 32, 56)}


def elf_problem(data: bytes) -> str | None:
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


# --- running the compiler --------------------------------------------------------------------

def _compile(command: list[str], arguments: list[str], timeout: float) -> None:
    """Run the compiler; BuildFailed when it does not run, fails or takes more than
    ``timeout`` seconds. However this returns or raises, the compiler and what it started
    are gone: stopped as a process group on a timeout and on any exception while it runs."""
    argv = [*command, *arguments]
    try:
        compiling = subprocess.Popen(
            _guarded(argv), stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, text=True, errors='replace', start_new_session=True,
            preexec_fn=_parent_death_signal())
    except OSError as exc:
        raise BuildFailed(f'the C compiler {command[0]} did not run: {exc}') from None
    try:
        _, errors = compiling.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        _stop(compiling)
        raise BuildFailed(f'the C compiler {command[0]} took more than {timeout} s') from None
    except BaseException:                     # e.g. raised by a signal handler: stop it too
        _stop(compiling)
        raise
    if compiling.returncode != 0:
        first = (errors.strip().splitlines() or ['no message'])[0]
        raise BuildFailed(f'the C compiler {command[0]} failed: {first}')


def _stop(process: 'subprocess.Popen[str]') -> None:
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


def _guarded(argv: list[str]) -> list[str]:
    return ['/bin/sh', '-c', _GUARD, argv[0], *argv] if _prctl() is not None else argv


def _parent_death_signal() -> Callable[[], None] | None:
    """The preexec_fn that gives the compiler's shell SIGTERM when the thread that started
    it ends (prctl PR_SET_PDEATHSIG; the thread is the one that waits for it), or None where
    there is no prctl (not Linux: the compiler is then run as before, without the shell)."""
    prctl = _prctl()
    if prctl is None:
        return None
    parent = os.getpid()

    def die_with_parent() -> None:
        prctl(_PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        if os.getppid() != parent:            # it died before the signal was set: now
            os._exit(1)
    return die_with_parent


@functools.cache
def _prctl() -> Callable[..., int] | None:
    """libc's prctl, or None. Memoized, not state: the C library of a process does not
    change, and it is looked up before any fork (the child only calls it)."""
    if sys.platform.startswith('linux') and os.path.exists('/bin/sh'):
        try:
            function = ctypes.CDLL(None, use_errno=True).prctl
            function.argtypes = [ctypes.c_int] + [ctypes.c_ulong] * 4
            function.restype = ctypes.c_int
            return function
        except (OSError, AttributeError):
            pass
    return None
