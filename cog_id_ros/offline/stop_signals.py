"""Ctrl-C, SIGTERM and SIGHUP in the offline tools: they stop a run like Ctrl-C, and no
temporary file is left behind.

:class:`StopSignals` turns them into :class:`Interrupted` (a BaseException, so the ``with``
blocks of :func:`cog_id_ros.offline.atomic_files.atomic_output` remove their temporary files
on the way out), and holds them back while the outputs are renamed; :func:`blocked` holds
them back in the kernel for the few instructions between creating a temporary file and
knowing its name. Plain Python (the node's start-up has its own, rclpy's:
``cog_id_ros.ros.stop_signals``).
"""

import contextlib
import signal

#: signals that stop the run like Ctrl-C: temporary files removed, exit 128 + signal number
STOP_SIGNALS = tuple(getattr(signal, name) for name in ('SIGINT', 'SIGTERM', 'SIGHUP')
                     if hasattr(signal, name))


class Interrupted(BaseException):
    """A stop signal (SIGINT, SIGTERM, SIGHUP) arrived; unwinds like KeyboardInterrupt,
    so every temporary file is removed on the way out."""

    def __init__(self, signum, outputs_written=False):
        self.signum = signum
        self.outputs_written = outputs_written
        super().__init__(signum)


class StopSignals:
    """Turn the stop signals into :class:`Interrupted`; defer them while outputs are renamed
    (``deferring`` set: the first one is kept in ``pending``).

    Signals a parent set to be ignored (``nohup``, a background job) stay ignored.
    Installed only in the main thread; ``restore`` puts the previous handlers back.
    """

    def __init__(self):
        self.previous = {}
        self.deferring = False
        self.pending = None

    def install(self):
        for signum in STOP_SIGNALS:
            try:
                if signal.getsignal(signum) == signal.SIG_IGN:
                    continue
                self.previous[signum] = signal.signal(signum, self._handler)
            except (ValueError, OSError):   # not the main thread
                pass
        return self

    def restore(self):
        for signum, handler in self.previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(signum, handler)
        self.previous.clear()

    def _handler(self, signum, frame):
        if self.deferring:
            self.pending = self.pending or signum
            return
        raise Interrupted(signum)


def signal_name(signum):
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f'signal {signum}'


@contextlib.contextmanager
def blocked():
    """Hold SIGINT, SIGTERM and SIGHUP back (they are delivered on leaving): a handler that
    raises must not run between the creation of a temporary file and the moment its name
    is known, or the file would be left behind."""
    if not hasattr(signal, 'pthread_sigmask'):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
