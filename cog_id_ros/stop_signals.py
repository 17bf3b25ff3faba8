"""Hold Ctrl-C and SIGTERM back while a console script builds its rclpy objects.

rclpy's signal handler shuts the context down the moment SIGINT or SIGTERM arrives. If that
happens while a node or an executor is half built, its constructor fails on the dead context
and the half-built object prints "Exception ignored in __del__" tracebacks at exit. Holding
the two signals until everything exists turns a stop during start-up into an ordinary stop:
the signal stays pending and is delivered, to rclpy's handler, when released.

Python's own SIGINT handler raises KeyboardInterrupt at whatever line runs next, which may
be in the middle of the clean-up after rclpy has already stopped the executor. A node that
stops through rclpy's context shutdown alone calls :func:`no_keyboard_interrupt` first.

Threads started while the signals are held (the DDS threads) inherit the mask and never take
them, so the main thread gets them, which is where Python runs its handlers anyway.
"""
import signal

STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


def hold():
    """Block SIGINT and SIGTERM in this thread; returns the mask to give to :func:`release`."""
    return signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)


def release(previous):
    """Restore the mask from :func:`hold`; a signal that came meanwhile is delivered now."""
    signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def no_keyboard_interrupt():
    """Make Python's SIGINT handler a no-op: install before ``rclpy.init``, which chains to it.

    Ctrl-C then stops the process only through rclpy (the context shuts down, spin returns),
    never by a KeyboardInterrupt raised at an arbitrary line.
    """
    signal.signal(signal.SIGINT, _ignore)


def _ignore(signum, frame):
    """Python-level SIGINT handler that does nothing (rclpy's handler does the work)."""
