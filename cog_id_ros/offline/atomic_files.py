"""Output files written whole or not at all: a temporary file beside the target, renamed
into place only when complete (:func:`atomic_output`), so a failed or interrupted run leaves
no partial file and never clobbers an older one. A symbolic link is written through; a
FIFO, device or socket is never replaced (:func:`output_target`).
"""

import contextlib
import os
import stat
import tempfile
from typing import Iterator, Union

from . import stop_signals

PathLike = Union[str, os.PathLike]


class OutputPathError(OSError):
    """An output path that must not be written (a FIFO, a device, ...): the message says why.

    An ``OSError``, so callers that handle write errors handle this refusal too."""


_SPECIAL = ((stat.S_ISFIFO, 'a FIFO (named pipe)'), (stat.S_ISCHR, 'a character device'),
            (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'))


def output_target(path: PathLike) -> str:
    """The file that writing ``path`` really replaces: ``path``, or the end of its symlinks.

    A symbolic link is written through: the file it points to is replaced (atomically)
    and the link stays; a dangling link creates its target. Raises
    :class:`OutputPathError` for a directory, a FIFO, a device or a socket (these are
    never replaced by a regular file, nor written into) and for a link that cannot be
    resolved (a loop).
    """
    path = os.fspath(path)
    target = path
    if os.path.islink(path):
        try:
            target = os.path.realpath(path, strict=True)
        except FileNotFoundError:
            target = os.path.realpath(path)
        except OSError as exc:
            raise OutputPathError(f'a symbolic link that cannot be resolved '
                                  f'({exc.strerror or exc})') from None
        if os.path.islink(target):
            raise OutputPathError('a symbolic link that cannot be resolved (a loop)')
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return target
    except OSError as exc:
        raise OutputPathError(f'cannot be examined ({exc.strerror or exc})') from None
    if stat.S_ISREG(mode):
        return target
    if stat.S_ISDIR(mode):
        raise OutputPathError('is a directory' + ('' if target == path else f' ({target})'))
    kind = next((text for test, text in _SPECIAL if test(mode)), 'a special file')
    via = '' if target == path else f' (the link points to {target})'
    raise OutputPathError(
        f'is {kind}{via}, not a regular file; outputs are written to a temporary file and '
        'renamed, which would replace it, so it is left alone: write to a regular file')


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_output(path: PathLike) -> Iterator[str]:
    """Yield a temporary path next to ``path``'s target; rename it there on success only.

    The target is :func:`output_target` (``path``, or the file its symlinks lead to;
    special files raise :class:`OutputPathError` before anything is created, and are
    checked again just before the rename). On an exception (including
    ``KeyboardInterrupt`` and other ``BaseException``) the temporary file is removed and
    the target is left as it was.
    """
    target = output_target(path)
    directory = os.path.dirname(os.path.abspath(target))
    tmp = None
    try:
        with stop_signals.blocked():
            fd, tmp = tempfile.mkstemp(dir=directory, prefix='.' + os.path.basename(target) + '.',
                                       suffix='.tmp')
            os.close(fd)
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        if output_target(path) != target:
            raise OutputPathError(f'{path} changed while it was being written')
        os.replace(tmp, target)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise
