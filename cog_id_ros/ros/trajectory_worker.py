"""Trajectories solved in a process of their own, fed by a thread of the node.

Deserialising, checking, solving and serialising a long trajectory takes seconds of Python
and C that hold the GIL (a 100,000-point one: ~7 s on the reference VM); done in the node's
process it stalled the setpoint thread and the timers. :class:`TrajectoryWorker` passes
the serialized message (bytes) through a pipe to a process started with ``spawn`` from the
node's :class:`~.config.NodeConfig` (:func:`trajectory_process`), and hands the answer it
gets back to the node: the node's threads are never held up by more than copying bytes.
"""
import multiprocessing
import signal
import threading
from typing import Any, Callable

from ..core import InverseDynamics
from ..description import Mechanism
from .config import NodeConfig
from .conversions import JointSelector, Rejected, solve_trajectory_message, trajectory_point_count


class TrajectoryWorker:
    """One trajectory solved at a time in the trajectory process; at most one waits
    (:meth:`submit` returns the one a newer one replaced). ``on_done(answer)`` is called
    by the worker's thread with each answer (see :func:`trajectory_process`).

    Nothing here waits without a bound: the process has ``STARTUP_BOUND`` s to say it is
    ready (its kernels loaded or compiled) and :meth:`answer_bound` s to answer a
    trajectory (the ``trajectory_timeout`` parameter plus ``SECONDS_PER_POINT`` a point); a process
    that dies (killed, out of memory) or does not answer in time (stopped, stuck) is
    killed, the trajectory in progress is answered with ('internal', text) and a new process
    is started for the next one. :meth:`stop` kills a process that does not end within its
    timeout (SIGKILL: a stopped process ignores SIGTERM until it is continued, and
    multiprocessing's exit handler would wait for it).
    """

    #: s a new trajectory process may take to load the mechanism and its kernels (a cold
    #: compile of a large mechanism, on a loaded machine)
    STARTUP_BOUND = 300.0
    #: s per point added to ``timeout`` for a trajectory's answer: 10-15x the measured cost
    #: (a 100,000-point trajectory takes 4-8 s on the reference VM)
    SECONDS_PER_POINT = 1e-3

    def __init__(self, config: NodeConfig, on_done: Callable[[tuple], None]) -> None:
        self.config = config
        self.on_done = on_done
        self.timeout = config.trajectory_timeout
        self._cond = threading.Condition()
        # _next is solved next, never replaced (it came while nothing was solved or
        # waited); _pending waits, and a newer one replaces it
        self._next: bytes | None = None
        self._pending: bytes | None = None
        self.busy = False
        self._stopping = False
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
        """s the process has to answer a trajectory of ``points`` points (None: unknown)."""
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
        """End the process (at once if it is solving: nobody waits for its answer) and
        the thread; never waits longer than about ``timeout`` for each."""
        with self._cond:
            self._stopping = True
            self._next = self._pending = None
            self._cond.notify()
        self._end_process(0.2 if self.busy else timeout)
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _start_process(self) -> None:
        context = multiprocessing.get_context('spawn')
        parent, child = context.Pipe()
        process = context.Process(target=trajectory_process, args=(child, self.config),
                                  name='cog_id_node trajectories', daemon=True)
        # Started with SIGINT blocked, which the new process inherits, so that Ctrl-C in a
        # terminal (it reaches the whole process group) never interrupts it, not even while
        # it imports; the node ends it itself. Blocked in this thread only, never ignored
        # process-wide: a SIGINT that arrives meanwhile is delivered to another thread of the
        # node (or on unblocking), not lost (ignoring it here lost a Ctrl-C at start-up).
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        child.close()
        self._process, self._conn, self._ready = process, parent, False

    def _end_process(self, timeout: float = 5.0) -> None:
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            conn.close()            # the process reads EOF and ends
        if process is not None:
            process.join(timeout)
            if process.is_alive():
                process.kill()      # SIGKILL: ends a stopped process too
                process.join(timeout)

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
                    raw, self._pending = self._pending, None
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

    def _receive(self, bound: float, what: str) -> Any:
        """The process's next message within ``bound`` s; TimeoutError naming ``what``."""
        if not self._conn.poll(bound):
            raise TimeoutError(f'the trajectory process did not {what} within {bound:.3g} s '
                               '(stopped or stuck)')
        return self._conn.recv()

    def _solve(self, raw: bytes) -> tuple:
        if self._process is None or not self._process.is_alive():
            self._end_process(1.0)
            self._start_process()
        try:
            if not self._ready:
                self._receive(self.STARTUP_BOUND, 'load the mechanism')
                self._ready = True
            self._conn.send_bytes(raw)
            return self._receive(self.answer_bound(trajectory_point_count(raw)),
                                 'answer the trajectory')
        except (EOFError, OSError, TimeoutError) as exc:
            if self._stopping:
                return ('internal', 'stopping')
            code = self._process.exitcode if self._process is not None else None
            why = str(exc) if isinstance(exc, TimeoutError) else \
                f'the trajectory process ended ({type(exc).__name__}, exit code {code})'
            self._end_process(1.0)
            self._start_process()
            return ('internal', f'{why}; a new one is started for the next trajectory')


def trajectory_process(conn: Any, config: NodeConfig) -> None:
    """Main function of the node's trajectory process (``multiprocessing``, spawn).

    ``config``: the node's. Reads serialized JointTrajectory messages from ``conn`` until
    EOF (the node closed its end, or ended), once it has said ('ready',) (its solver is
    built: the kernels loaded or compiled), and answers each with ('ok', serialized
    effort_trajectory, clipped, points), ('rejected', reason, text, points) or ('internal',
    text). Ignores SIGINT: Ctrl-C in a terminal reaches the whole process group, and the
    node ends this process itself.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
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
            answer = ('ok', out, clipped, points)
        except Rejected as exc:
            answer = ('rejected', exc.reason, str(exc), getattr(exc, 'points', None))
        except Exception as exc:   # noqa: BLE001 (answer every trajectory)
            answer = ('internal', f'{type(exc).__name__}: {exc}')
        try:
            conn.send(answer)
        except (EOFError, OSError):
            return
