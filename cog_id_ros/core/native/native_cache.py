"""The directory where compiled kernels are kept: where it is, whom it trusts, its housekeeping.

* it is ``$COG_ID_ROS_CACHE`` if set, else ``$XDG_CACHE_HOME/cog_id_ros`` (an absolute
  ``$XDG_CACHE_HOME`` only: a relative one is ignored, as the XDG spec says) or
  ``$HOME/.cache/cog_id_ros``; with none of these there is no cache;
* a library there is loaded code: whoever can write there can run code as the user who
  loads it. So the directory is trusted only when it is owned by this process's user (its
  effective uid) and not writable by group or others, and every file of it is opened
  relative to the open directory, without following a symbolic link, and trusted only
  when it is a regular file of that user not writable by group or others. The directory
  and the parents made for it get mode 0700 whatever the umask;
* a library not used for ``KEEP_DAYS`` days is removed when another one is built, and so
  are temporary files of builds that died once they are older than any live build could be.

What this process remembers of its compiled kernels (builds that failed, what it has said,
the libraries it loaded, its private directory) is one :class:`ProcessMemory`.
(docs/reliability.md, "The kernel cache: who may write there".)
"""
import atexit
import glob
import logging
import os
import shutil
import stat
import tempfile
import time

from .native_build import TEMPORARY, library_suffix

#: days after its last use at which a cached library is removed (when another is built)
KEEP_DAYS = 30

#: seconds, beyond the build timeout, after which a temporary file of this cache is debris:
#: a live build's files are younger (its compiler is stopped at the timeout)
DEBRIS_MARGIN = 60.0

#: whether this system can say who owns a file opened relative to a directory (not Windows)
CAN_CHECK_OWNERS = hasattr(os, 'geteuid') and os.open in os.supports_dir_fd

_O_DIRECTORY = getattr(os, 'O_DIRECTORY', 0)
_O_NOFOLLOW = getattr(os, 'O_NOFOLLOW', 0)
_O_NONBLOCK = getattr(os, 'O_NONBLOCK', 0)    # a FIFO named like a library: no hang

_log = logging.getLogger('cog_id_ros')


class Untrusted(Exception):
    """A file of the cache that another user wrote or may write: not loaded."""


class ProcessMemory:
    """What this process remembers of its compiled kernels, and nothing else does: a forked
    child inherits it, a new process starts with a fresh one (and so may a test:
    ``native.PROCESS = ProcessMemory()``)."""

    def __init__(self) -> None:
        #: (cache directory, library name) -> why its build failed in this process: not
        #: tried again (a hung compiler would otherwise hold up every solver of the
        #: mechanism for the build timeout)
        self.failed: dict[tuple[str | None, str], str] = {}
        #: the log lines said (each once per process)
        self.said: set[str] = set()
        #: (st_dev, st_ino) of every library loaded through its descriptor -> that
        #: descriptor, kept open for the life of the process (native_loading.py)
        self.loaded: dict[tuple[int, int], int] = {}
        #: pid -> the private directory of that process (a forked child makes its own)
        self.private: dict[int, str] = {}

    def say(self, message: str) -> None:
        """Log ``message`` once per process."""
        if message not in self.said:
            self.said.add(message)
            _log.warning(message)

    def say_no_cache(self) -> None:
        """Say, once, that there is no cache directory and how to have one."""
        self.say('cog_id_ros: no directory for the kernel cache ($COG_ID_ROS_CACHE is not '
                 'set, $XDG_CACHE_HOME is not an absolute path and $HOME is empty or not '
                 'set): compiled kernels are built for this process only; set '
                 'COG_ID_ROS_CACHE to a directory of your own to keep them')

    def say_untrusted(self, directory: str, problem: str) -> None:
        """Say, once, that the cache ``directory`` is not used and why (``problem``)."""
        self.say(f'cog_id_ros: compiled kernels are not loaded from the cache {directory}: '
                 f'{problem}, and whoever can write there could run code in this process; '
                 f'they are built for this process only, in a private temporary directory. '
                 f'To keep them: a cache directory owned by uid {os.geteuid()}, not writable '
                 f'by group or others (chmod go-w), or COG_ID_ROS_CACHE set to one '
                 f'(docs/reliability.md)')

    def private_directory(self) -> str:
        """A directory of this process only (mkdtemp: mode 0700), removed at its exit."""
        directory = self.private.get(os.getpid())
        if directory is None or not os.path.isdir(directory):
            directory = self.private[os.getpid()] = tempfile.mkdtemp(prefix='cog_id_ros-')
            atexit.register(_remove_private, directory, os.getpid())
        return directory


def _remove_private(directory: str, pid: int) -> None:
    if os.getpid() == pid:                    # not a forked child's exit: the parent's own
        shutil.rmtree(directory, ignore_errors=True)


def cache_directory() -> str | None:
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


def library_paths(directory: str, name: str) -> dict[str, str]:
    """The files of library ``name`` in ``directory``: its source ('c'), its operations per
    kernel ('json'), its builds ('O2', 'O0') and the lock of its -O2 build ('lock')."""
    base = os.path.join(directory, name)
    return {'c': base + '.c', 'json': base + '.json', 'O2': base + '.O2' + library_suffix(),
            'O0': base + '.O0' + library_suffix(), 'lock': base + '.O2.lock'}


# --- the trust model: what may be loaded -----------------------------------------------------

def open_cache(directory: str, process: ProcessMemory) -> tuple[int | None, bool]:
    """(descriptor of the cache directory, whether this process may write there), or
    (None, False) when it is not to be used; one log line says why when it is a surprise
    (one that others may write)."""
    try:
        _make_private(directory)
    except OSError:
        pass                                  # read-only, or under a file: opened or not below
    try:
        return open_directory(directory), os.access(directory, os.W_OK)
    except Untrusted as exc:
        process.say_untrusted(directory, str(exc))
    except OSError:
        pass                                  # not there: built for this process only
    return None, False


def _make_private(path: str) -> None:
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


def open_directory(path: str) -> int:
    """A descriptor of the directory ``path`` (every file of the cache is then opened
    relative to it: what was checked is what is read); Untrusted when it is not this
    user's or group or others may write it."""
    fd = os.open(path, os.O_RDONLY | _O_DIRECTORY | os.O_CLOEXEC)
    try:
        problem = _untrusted(os.fstat(fd), path)
    except BaseException:
        os.close(fd)
        raise
    if problem:
        os.close(fd)
        raise Untrusted(problem)
    return fd


def _untrusted(st: os.stat_result, path: str) -> str | None:
    """Why a file or directory of this stat may have been written by another user, or None."""
    if st.st_uid != os.geteuid():
        return f'{path} is owned by uid {st.st_uid}, not by uid {os.geteuid()} (this process)'
    if st.st_mode & 0o022:
        return (f'{path} has mode {stat.S_IMODE(st.st_mode):04o}: group or others may '
                f'write it')
    return None


def open_file(fd: int, filename: str,
              directory: str) -> tuple[int, os.stat_result] | tuple[None, None]:
    """(descriptor, stat) of the regular file ``filename`` in the cache directory of
    descriptor ``fd`` (a symbolic link is not followed: this cache makes none), or
    (None, None) when there is none; Untrusted when it is another user's or group or
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
        raise Untrusted(problem)
    return opened, st


def read_file(fd: int, filename: str, directory: str) -> bytes | None:
    """The bytes of ``filename`` (see :func:`open_file`), or None."""
    opened, _ = open_file(fd, filename, directory)
    if opened is None:
        return None
    with os.fdopen(opened, 'rb') as f:
        return f.read()


# --- the cache's housekeeping ----------------------------------------------------------------

def touch(path: str) -> None:
    """Mark a library's file as used now (not pruned)."""
    try:
        os.utime(path)
    except OSError:
        pass                                  # a read-only cache: nothing is pruned there


def prune(directory: str, build_timeout: float) -> None:
    """Remove the libraries of this cache not used for KEEP_DAYS (every change of a
    mechanism or of the package makes a new one; nothing else removes the old), and the
    temporary files of builds that died (killed, a full disk): those dated further than
    ``build_timeout`` + DEBRIS_MARGIN from now, either way (a clock set back). Earlier
    versions named their temporary files tmp*.so and tmp*.tmp: pruned as well."""
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
    for pattern in (TEMPORARY + '*', 'tmp*.tmp', 'tmp*.so'):
        for path in glob.glob(os.path.join(here, pattern)):
            try:
                if abs(now - os.lstat(path).st_mtime) > build_timeout + DEBRIS_MARGIN:
                    os.unlink(path)
            except OSError:
                pass
