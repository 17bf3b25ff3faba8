"""Trajectories solved in a process of their own, fed by a thread of the node.

Deserialising, checking, solving and serialising a long trajectory takes seconds of Python
and C that hold the GIL (a 100,000-point one: ~7 s on the reference VM); done in the node's
process it stalled the setpoint thread and the timers. :class:`TrajectoryWorker` passes
the serialized message (bytes) through a pipe to a process started with ``spawn`` from the
node's :class:`~.config.NodeConfig` (:func:`trajectory_process`), and hands the answer it
gets back to the node: the node's threads are never held up by more than copying bytes.
"""
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from typing import Any, Callable

import rclpy.logging

from ..core import InverseDynamics
from ..description import Mechanism
from .config import NodeConfig
from .conversions import JointSelector, Rejected, solve_trajectory_message, trajectory_point_count
from .diagnostics import PythonLogsToRos


class TrajectoryWorker:
    """One trajectory solved at a time in the trajectory process; at most one waits
    (:meth:`submit` returns the one a newer one replaced). ``on_done(answer)`` is called
    by the worker's thread with each answer (see :func:`trajectory_process`).

    Nothing here waits without a bound: the process has ``STARTUP_BOUND`` s to say it is
    ready (its kernels loaded or compiled) and :meth:`answer_bound` s (the
    ``trajectory_timeout`` parameter plus ``SECONDS_PER_POINT`` a point) to take a
    trajectory *and* answer it. The trajectory is written to the pipe by a short-lived
    thread of its own (:class:`_Sender`) that the worker waits for with that bound: a
    process that does not read (stopped, stuck) fills the pipe, and a write on a full pipe
    cannot be given a timeout. A process that dies (killed, out of memory) or does not
    answer in time is killed (SIGKILL, which ends a stopped process too, and breaks the
    pipe: a write blocked on it then fails at once and its thread ends), the trajectory in
    progress is answered with ('internal', text) and a new process is started for the
    next one. :meth:`stop` kills a process that is solving at once (nobody waits for its
    answer) and gives an idle one ``EOF_GRACE`` s to end by itself (multiprocessing's exit
    handler would wait for it without a bound).

    The process computes with ``backend`` when given: the node gives the one its solver
    ended up with ('python' after a fallback from 'auto'), so the process never builds
    again what the node gave up on. It dies with the node (:func:`die_with_parent`).
    """

    #: s a new trajectory process may take to load the mechanism and its kernels (a cold
    #: compile of a large mechanism, on a loaded machine)
    STARTUP_BOUND = 300.0
    #: s per point added to ``timeout`` for a trajectory's answer: 10-15x the measured cost
    #: (a 100,000-point trajectory takes 4-8 s on the reference VM)
    SECONDS_PER_POINT = 1e-3
    #: s an idle process has to end once it read EOF (it ends within milliseconds) before
    #: it is killed: with a stopped one, how long stopping the node waits for it
    EOF_GRACE = 0.5
    #: s for a killed process to be reaped, and for the thread that wrote to its pipe to
    #: end (both take milliseconds)
    KILLED_BOUND = 5.0

    def __init__(self, config: NodeConfig, on_done: Callable[[tuple], None],
                 backend: str | None = None, logger_name: str | None = None) -> None:
        """``backend``: what the node's solver uses (None: the parameter's); ``logger_name``:
        the rclpy logger the process hands the package's Python log records to (None: they
        stay Python's)."""
        self.config = config if backend is None else config.with_backend(backend)
        self.on_done = on_done
        self.logger_name = logger_name
        self.timeout = config.trajectory_timeout
        self._cond = threading.Condition()
        # _next is solved next, never replaced (it came while nothing was solved or
        # waited); _pending waits, and a newer one replaces it
        self._next: bytes | None = None
        self._pending: bytes | None = None
        self.busy = False
        self._stopping = False
        # the process and its pipe: replaced by the worker's thread, killed by stop()
        self._process_lock = threading.Lock()
        self._process: Any = None
        self._conn: Any = None
        self._ready = False
        #: the exception that ended the worker thread, if one did (reported by the node)
        self.failure: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name='trajectory worker', daemon=True)

    def start(self) -> None:
        self._start_process()
        self._thread.start()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    @property
    def ended_by_itself(self) -> bool:
        """Whether the thread ended although :meth:`stop` was not called (an exception: a
        bug)."""
        return self._thread.ident is not None and not self._thread.is_alive() \
            and (self.failure is not None or not self._stopping)

    def answer_bound(self, points: int | None) -> float:
        """s the process has to take and answer a trajectory of ``points`` points (None:
        unknown)."""
        return self.timeout + self.SECONDS_PER_POINT * (points or 0)

    def submit(self, raw: bytes) -> bytes | None:
        """Queue ``raw`` (a serialized JointTrajectory); returns the one it replaced, or None.

        A trajectory that arrives while none is solved or waiting is solved next, whatever
        comes after it; otherwise it waits, replacing the one that waited.
        """
        with self._cond:
            if not self.busy and self._next is None and self._pending is None:
                self._next, replaced = raw, None
            else:
                replaced, self._pending = self._pending, raw
            self._cond.notify()
        return replaced

    def stop(self, timeout: float = 5.0) -> None:
        """End the process (at once if it is solving: nobody waits for its answer; an idle
        one gets ``EOF_GRACE`` s) and the thread (``timeout`` s at most)."""
        with self._cond:
            self._stopping = True
            self._next = self._pending = None
            busy = self.busy
            self._cond.notify()
        if busy:
            self._kill()    # frees the worker's thread, waiting on the process or its pipe
        if self._thread.is_alive():
            self._thread.join(timeout)
        self._end_process(0.0 if busy else self.EOF_GRACE)

    def _start_process(self) -> None:
        context = multiprocessing.get_context('spawn')
        with self._process_lock:
            if self._stopping:
                raise EOFError('the node is stopping: no new trajectory process')
            parent, child = context.Pipe()
            process = context.Process(target=trajectory_process,
                                      args=(child, self.config, os.getpid(), self.logger_name),
                                      name='cog_id_node trajectories', daemon=True)
            # Started with SIGINT blocked, which the new process inherits, so that Ctrl-C in
            # a terminal (it reaches the whole process group) never interrupts it, not even
            # while it imports; the node ends it itself. Blocked in this thread only, never
            # ignored process-wide: a SIGINT that arrives meanwhile is delivered to another
            # thread of the node (or on unblocking), not lost (ignoring it here lost a
            # Ctrl-C at start-up).
            blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            try:
                process.start()
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            child.close()
            self._process, self._conn, self._ready = process, parent, False

    def _kill(self) -> None:
        """SIGKILL the process (ends a stopped one too; its pipe breaks)."""
        with self._process_lock:
            if self._process is not None:
                self._process.kill()

    def _end_process(self, grace: float) -> None:
        """Close the pipe (the process reads EOF and ends), give the process ``grace`` s,
        then SIGKILL it. A thread still writing to the pipe must have ended first (kill
        the process, then join it): the pipe is closed here."""
        with self._process_lock:
            process, conn = self._process, self._conn
            self._process = self._conn = None
            if conn is not None:
                conn.close()
            if process is None:
                return
            if grace > 0.0:
                process.join(grace)
            if process.is_alive():
                process.kill()      # SIGKILL: ends a stopped process too
            process.join(self.KILLED_BOUND)
            if process.exitcode is not None:
                process.close()

    def _run(self) -> None:
        try:
            self._serve()
        except BaseException as exc:   # noqa: BLE001 (recorded: the node reports it)
            self.failure = exc
            raise

    def _serve(self) -> None:
        while True:
            with self._cond:
                while self._next is None and self._pending is None and not self._stopping:
                    self._cond.wait()
                if self._stopping:
                    return
                if self._next is not None:
                    raw, self._next = self._next, None
                else:
                    # (not None: the wait above ended on it)
                    raw, self._pending = self._pending, None  # type: ignore[assignment]
                self.busy = True
            try:
                result = self._solve(raw)
            except Exception as exc:   # noqa: BLE001 (the worker thread must go on)
                result = ('internal', f'{type(exc).__name__}: {exc}')
            finally:
                with self._cond:
                    self.busy = False
            if not self._stopping:
                self.on_done(result)

    def _receive(self, wait: float, what: str, bound: float) -> Any:
        """The process's next message within ``wait`` s; TimeoutError naming ``what`` and
        its ``bound``."""
        if not self._conn.poll(max(0.0, wait)):
            raise TimeoutError(f'the trajectory process did not {what} within {bound:.3g} s '
                               '(stopped or stuck)')
        return self._conn.recv()

    def _solve(self, raw: bytes) -> tuple:
        sender = None
        try:
            if self._process is None or not self._process.is_alive():
                self._end_process(0.0)
                self._start_process()
            if not self._ready:
                self._receive(self.STARTUP_BOUND, 'load the mechanism', self.STARTUP_BOUND)
                self._ready = True
            # the whole exchange within the bound: the write too (a process that does not
            # read fills the pipe, and then the write blocks)
            bound = self.answer_bound(trajectory_point_count(raw))
            deadline = time.monotonic() + bound
            sender = _Sender(self._conn, raw)
            sender.join(bound)
            if sender.is_alive():
                raise TimeoutError(f'the trajectory process did not answer the trajectory '
                                   f'within {bound:.3g} s (stopped or stuck: it did not even '
                                   'take it)')
            if sender.error is not None:
                raise sender.error
            return self._receive(deadline - time.monotonic(), 'answer the trajectory', bound)
        except (EOFError, OSError, TimeoutError) as exc:
            if self._stopping:
                return ('internal', 'stopping')
            process = self._process
            code = process.exitcode if process is not None else None
            why = str(exc) if isinstance(exc, TimeoutError) else \
                f'the trajectory process ended ({type(exc).__name__}, exit code {code})'
            self._kill()                    # stopped, stuck or dead: its pipe breaks
            if sender is not None:
                sender.join(self.KILLED_BOUND)     # its write fails at once now
            self._end_process(0.0)
            self._start_process()
            return ('internal', f'{why}; a new one is started for the next trajectory')


class _Sender(threading.Thread):
    """Writes one trajectory to the process's pipe (started at once); ``error``: what the
    write raised (EOFError, OSError: the process ended or was killed), or None."""

    def __init__(self, conn: Any, raw: bytes) -> None:
        super().__init__(name='trajectory sender', daemon=True)
        self._conn = conn
        self._raw: bytes | None = raw
        self.error: BaseException | None = None
        self.start()

    def run(self) -> None:
        try:
            self._conn.send_bytes(self._raw)
        except BaseException as exc:   # noqa: BLE001 (handed to the worker's thread)
            self.error = exc
        finally:
            self._raw = None


def trajectory_process(conn: Any, config: NodeConfig, parent: int | None = None,
                       logger_name: str | None = None) -> None:
    """Main function of the node's trajectory process (``multiprocessing``, spawn).

    ``config``: the node's (its backend: the one the node's solver uses). Reads serialized
    JointTrajectory messages from ``conn`` until EOF (the node closed its end, or ended),
    once it has said ('ready',) (its solver is built: the kernels loaded or compiled), and
    answers each with ('ok', serialized effort_trajectory, clipped, points), ('rejected',
    reason, text, points) or ('internal', text). Dies with the node ``parent`` (its pid:
    :func:`die_with_parent`). Ignores SIGINT: Ctrl-C in a terminal reaches the whole process
    group, and the node ends this process itself. The package's Python log records go to
    the rclpy logger ``logger_name`` (ROS's log format; rcutils logs without rclpy.init),
    if given.
    """
    if parent is not None:
        die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if logger_name is not None:
        PythonLogsToRos.attach(rclpy.logging.get_logger(logger_name))
    solver = InverseDynamics(Mechanism.from_parameters(config.mechanism),
                             backend=config.backend)
    selector = JointSelector(config.active_joints)
    options = {'unwrap': config.unwrap, 'max_step': config.max_setpoint_step,
               'effort_limits': config.effort_limits if config.limited else None,
               'max_points': config.max_trajectory_points}
    try:
        conn.send(('ready',))     # loaded: from here on each answer is bounded (the node)
    except (EOFError, OSError):
        return
    while True:
        try:
            raw = conn.recv_bytes()
        except (EOFError, OSError):
            return
        try:
            out, clipped, points = solve_trajectory_message(raw, solver, selector, **options)
            answer: tuple = ('ok', out, clipped, points)
        except Rejected as exc:
            answer = ('rejected', exc.reason, str(exc), getattr(exc, 'points', None))
        except Exception as exc:   # noqa: BLE001 (answer every trajectory)
            answer = ('internal', f'{type(exc).__name__}: {exc}')
        try:
            conn.send(answer)
        except (EOFError, OSError):
            return


#: prctl's option: the signal this process gets when the thread that started it ends
PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """Have this process get SIGKILL when the node ``parent`` (its pid) dies, killed with
    kill -9 included, and end at once if it already has (Linux: prctl PR_SET_PDEATHSIG;
    elsewhere nothing). SIGKILL ends a stopped process too. (The signal comes when the
    *thread* that started this process ends: the node's main thread or its trajectory
    worker's, both of which live as long as the node serves trajectories.)"""
    if not sys.platform.startswith('linux'):
        return
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return
    prctl.argtypes = [ctypes.c_int] + [ctypes.c_ulong] * 4
    prctl.restype = ctypes.c_int
    if prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
        return
    if os.getppid() != parent:      # the node died before the signal was set
        os._exit(1)
