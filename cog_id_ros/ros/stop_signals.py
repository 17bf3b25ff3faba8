"""Ctrl-C and SIGTERM while a console script builds its rclpy objects: noted, acted on after.

(Before that, while Python imports numpy and rclpy, ``cog_id_node``'s main() exits 0 at
once on a stop signal: nothing exists yet to clean up. :class:`DeferredStop` replaces that
handler before ``rclpy.init``.)

rclpy's signal handler shuts the context down the moment SIGINT or SIGTERM arrives. If that
happens while a node or an executor is half built, its constructor fails on the dead context
and the half-built object prints "Exception ignored in __del__" tracebacks at exit.

Blocking the two signals in the main thread (pthread_sigmask) does not prevent it: threads
that exist before ``main()`` runs -- OpenBLAS starts one when numpy is imported, SciPy
another -- do not block them, so the kernel delivers the signal there and rclpy's C
handler runs at once (measured: the start-up signal test, 8 starts a run, failed in 2 of
3 runs). So the scripts start rclpy *without* its signal handlers and install Python-level
handlers that only note the signal (Python runs them in the main thread, whichever thread
the kernel picked). Once everything exists, :meth:`DeferredStop.hand_over` installs
rclpy's handlers and says whether a stop was asked for meanwhile::

    stop = DeferredStop()
    rclpy.init(args=args, signal_handler_options=stop.RCLPY_OPTIONS)
    ... build node and executor ...
    if stop.hand_over():
        return 0                 # stopped during start-up: clean up, no spin
    executor.spin()              # from here on a signal shuts the context down (rclpy)

The node keeps the noting handlers after the hand-over (rclpy's handler calls them too):
Ctrl-C then stops it only through rclpy's context shutdown, never by a KeyboardInterrupt
raised at an arbitrary line of the clean-up.

Parts of start-up that build no rclpy object but may take long (loading the mechanism,
compiling its kernels: a hung compiler may take minutes) run inside
:meth:`DeferredStop.interruptible`: there a stop signal, or one noted before, raises
:class:`StopRequested` at once, and the code unwinds (a compiler it started is killed on
the way, core/native/native_build.py)::

    with stop.interruptible():
        mechanism = Mechanism.from_parameters(...)    # StopRequested on Ctrl-C
"""
import contextlib
import signal
from types import FrameType
from typing import Iterator

from rclpy.signals import SignalHandlerOptions, install_signal_handlers

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequested(BaseException):
    """A stop signal during an interruptible part of start-up (a BaseException, like
    KeyboardInterrupt, so that no ``except Exception`` on the way swallows it)."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f'stopped by {signal.Signals(signum).name} during start-up')


class DeferredStop:
    """Note SIGINT and SIGTERM until :meth:`hand_over` gives them to rclpy."""

    #: the ``signal_handler_options`` for ``rclpy.init``: none until the hand-over
    RCLPY_OPTIONS = SignalHandlerOptions.NO

    def __init__(self) -> None:
        self.received: int | None = None        # the first stop signal noted, or None
        self._interruptible = False
        self._previous = {signum: signal.signal(signum, self._note) for signum in STOP_SIGNALS}

    def _note(self, signum: int, frame: FrameType | None) -> None:
        if self.received is None:
            self.received = signum
        if self._interruptible:
            self._interruptible = False     # raised once
            raise StopRequested(signum)

    @contextlib.contextmanager
    def interruptible(self) -> Iterator[None]:
        """Within the block a stop signal raises StopRequested (in the main thread, where
        Python runs signal handlers); one noted before it raises on entry."""
        if self.received is not None:
            raise StopRequested(self.received)
        self._interruptible = True
        try:
            yield
        finally:
            self._interruptible = False

    def hand_over(self, restore_python_handlers: bool = False) -> int | None:
        """Install rclpy's signal handlers; return the signal noted before, or None.

        ``restore_python_handlers``: put back the Python handlers that were there before
        (e.g. Python's KeyboardInterrupt for Ctrl-C, for a script that catches it);
        otherwise the noting handlers stay.
        """
        if restore_python_handlers:
            for signum, handler in self._previous.items():
                signal.signal(signum, handler)
        install_signal_handlers(SignalHandlerOptions.ALL)
        # A signal that arrived during the C call above is only *pending* for Python: its
        # handler (_note) runs at the interpreter's next check, on entry to a Python
        # function. Without this call that check came after `return self.received`, in the
        # caller's spin(), and the stop was lost (about 1 start in 4 in the fuzz test).
        _run_pending_handlers()
        return self.received


def _run_pending_handlers() -> None:
    """Nothing: entering a Python function makes the interpreter run pending signal handlers."""
