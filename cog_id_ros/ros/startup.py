"""Start a node of the package, spin it until Ctrl-C or SIGTERM, and stop it cleanly.

:func:`run` is the body of every node's ``main``: rclpy initialised without its signal
handlers until the node is built (:mod:`.stop_signals`), a params file rcl would refuse
named by its parameter (:mod:`.command_line`), the node built, started and spun, and the
exit status: 0 after a stop signal, 2 with one line when a parameter cannot be
honoured, 1 when a thread of the node ended by itself.

The node that ``build`` returns offers ``start()`` (its threads, once built),
``stop()`` (ends them; returns '<thread>: <why>' of those that had ended by themselves)
and ``internal_error(where, exc)`` (counts and logs an exception out of a callback).
"""
import gc
import sys
import time
from typing import Any, Callable

import rclpy
import rclpy.exceptions
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from ..core import MechanismConfigError
from . import stop_signals
from .command_line import (
    StderrHeld,
    node_arguments,
    node_name,
    one_line,
    other_nodes_hint,
    params_file_problem,
    rcl_message,
)

#: Python's thread switch interval in the node: the longest a thread holding the GIL keeps
#: the setpoint thread waiting (Python's default is 5 ms)
SWITCH_INTERVAL = 0.001

#: s: the longest the executor waits before it looks whether a stop signal was noted
STOP_POLL = 0.25

#: what a node's constructor raises for a parameter it cannot honour (exit status 2)
PARAMETER_ERRORS = (MechanismConfigError, rclpy.exceptions.InvalidParameterTypeException,
                    rclpy.exceptions.InvalidParameterValueException)


def run(name: str, build: Callable[..., Any], args: list[str] | None = None) -> int:
    """Build the node ``name`` with ``build(interruptible=...)`` and spin it; the exit status.

    ``args``: the process's arguments (None: sys.argv). ``interruptible`` is the context
    manager around the parts of start-up that may take long and build no rclpy object
    (loading the mechanism, compiling its kernels): a stop signal raises there at once.
    """
    problem = params_file_problem(node_arguments(args))
    if problem:
        return cannot_start(name, problem)
    stop = stop_signals.DeferredStop()
    try:
        with StderrHeld() as held:
            rclpy.init(args=args, signal_handler_options=stop.RCLPY_OPTIONS)
    except Exception as exc:   # noqa: BLE001 (e.g. a params file rcl cannot parse)
        return cannot_start(name, rcl_message(exc))
    held.replay()
    sys.setswitchinterval(SWITCH_INTERVAL)
    node = None
    stopped = []
    try:
        node = build(interruptible=stop.interruptible)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # Start-up left tens of thousands of long-lived objects (rclpy, numpy, the traced
        # program). Frozen, a full collection during the stream no longer walks them: its
        # pause (~10 ms on the reference VM) becomes microseconds.
        gc.collect()
        gc.freeze()
        node.start()
        if stop.hand_over() is None:   # no stop asked for during start-up
            _spin(executor, node, stop)
    except PARAMETER_ERRORS as exc:
        argv = node_arguments(args)
        return cannot_start(name, one_line(exc) + other_nodes_hint(argv, node_name(argv, name)))
    except (ExternalShutdownException, stop_signals.StopRequested):
        pass   # Ctrl-C or SIGTERM: rclpy's signal handler has shut the context down, or
        # start-up was interrupted while it loaded the mechanism or compiled its kernels
    except Exception as exc:   # noqa: BLE001
        if rclpy.ok():
            if node is None:   # start-up: an error rclpy raised for something we did not check
                return cannot_start(name, f'{type(exc).__name__}: {one_line(exc)}')
            raise
        # the signal shut the context down between two turns of spin(), whose next wait set
        # then fails on the dead context (an RCLError): a clean stop too
    finally:
        if node is not None:
            stopped = node.stop()
            node.destroy_node()
        rclpy.try_shutdown()
    if stopped:
        print(f"{name}: stopped serving before the end: {'; '.join(stopped)}", file=sys.stderr)
        return 1
    return 0


def cannot_start(name: str, why: str) -> int:
    """Print ``<name>: cannot start: <why>``; the exit status, 2."""
    print(f'{name}: cannot start: {why}', file=sys.stderr)
    return 2


def _spin(executor: SingleThreadedExecutor, node: Any, stop: stop_signals.DeferredStop
          ) -> None:
    """executor.spin(), except that an exception out of a callback does not end it, and a
    stop signal ends it within STOP_POLL s even when rclpy's handler did not wake it; so
    does a node that is ``finished`` (a managed node shut down: finalized).

    Every callback of the node is guarded (:func:`.diagnostics.guarded`); this catches
    what is left, e.g. an exception rclpy raises around a callback, counts and logs it,
    and spins on. rclpy's signal handler shuts the context down and wakes the executor;
    the managed node once (in ~1 of 10 lifecycle runs beside other work) took the signal
    and still waited on in rcl_wait with no timeout, the context apparently never woken.
    So the wait has a timeout, and the stop noted by :class:`.stop_signals.DeferredStop`
    (its Python handler stays installed under rclpy's) is looked at between two waits.
    """
    while rclpy.ok() and stop.received is None and not getattr(node, 'finished', False):
        try:
            executor.spin_once(timeout_sec=STOP_POLL)
        except ExternalShutdownException:
            raise
        except Exception as exc:   # noqa: BLE001
            if not rclpy.ok():
                raise
            node.internal_error('executor', exc)
            time.sleep(0.01)   # an error that repeats must not turn into a busy loop
