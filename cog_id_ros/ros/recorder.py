"""Record a node's answers in a process of its own, and account for every setpoint sent.

Why a process: the Fig. 4 demo once recorded ``joint_effort`` in the thread that also
published the setpoints (spun only between two publications). On a loaded machine it
missed up to 343 of 2001 efforts that the node had sent, and said nothing. Here the
recorder is a child process (multiprocessing ``spawn``: a fresh interpreter, its own
rclpy context, DDS participant and executor thread), so it is scheduled on its own and no
publishing loop or GIL of the player delays it; its subscriptions are deep enough for the
whole run (``depth``: at most one effort per setpoint, so the number of setpoints).

Why an account: a loss is only a loss if someone counts it. :func:`account` compares three
numbers per node: the setpoints sent, what the node says it did with them (its
``/diagnostics``: ``setpoints_accepted``, ``setpoints_rejected``, ``setpoints_lost``,
counted since the node started, so taken relative to a report from before the run) and
the efforts recorded. What is missing is then attributed: to the node (lost before it
took them, rejected, or never counted) or to the recorder (answered by the node, not
recorded).

Importing this needs no ROS; the child process imports rclpy.
"""
import dataclasses
import multiprocessing
import os
import signal
import threading
import time
from typing import Any, Callable, Iterable, Mapping, Sequence

#: the node's counters of what happened to the setpoints it was sent (its /diagnostics keys)
COUNTERS = ('setpoints_accepted', 'setpoints_rejected', 'setpoints_lost')
#: the efforts recorded on a topic: stamp (ns) -> (names, efforts)
Received = dict[int, tuple[list[str], list[float]]]
#: s after which the first setpoint is sent again when the node's counters are unknown
BLIND_RESEND = 1.0


def diagnostics_name(namespace: str, node: str = 'cog_id_node') -> str:
    """The name of the node's DiagnosticStatus (see docs/node.md, "Diagnostics")."""
    namespace = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return f'{namespace}/{node}: inverse dynamics'


def counters(values: Mapping[str, str] | None) -> dict[str, int] | None:
    """The three counters of a diagnostics report ``values`` (key -> str), or None."""
    if values is None:
        return None
    try:
        return {key: int(values[key]) for key in COUNTERS}
    except (KeyError, ValueError):
        return None


@dataclasses.dataclass
class Account:
    """What became of the setpoints sent to one node.

    ``sent``: setpoints published; ``recorded``: how many of them have a recorded effort
    (matched by stamp); ``accepted``, ``rejected``, ``lost``: the node's counters over the
    run (None when no report of the node came, before or after). The properties below
    count with them only for a ``reported`` account (which mypy cannot tell: the
    ``type: ignore[operator]`` comments). ``setpoint_topic``: the node's setpoint topic
    (fully qualified), which the advice on lost setpoints names.
    """

    where: str
    sent: int
    recorded: int
    accepted: int | None = None
    rejected: int | None = None
    lost: int | None = None
    setpoint_topic: str = '/<namespace>/joint_setpoint'

    @property
    def reported(self) -> bool:
        return self.accepted is not None

    @property
    def uncounted(self) -> int:
        """Setpoints the node neither answered, rejected nor counted as lost: it never saw
        them and could not tell (published before its subscription matched, or the last of
        the stream lost with nothing after them to show the gap)."""
        return self.sent - self.accepted - self.rejected - self.lost  # type: ignore[operator]

    @property
    def unrecorded(self) -> int:
        """Efforts the node says it sent (one per accepted setpoint) that were not recorded."""
        return self.accepted - self.recorded  # type: ignore[operator]

    @property
    def complete(self) -> bool:
        """Every setpoint answered and recorded, and the node's report says the same (or
        there is no report, which cannot contradict a full recording)."""
        if self.recorded < self.sent:
            return False
        return not self.reported or (self.accepted >= self.sent  # type: ignore[operator]
                                     and self.rejected == 0
                                     and self.lost == 0)

    def losses(self) -> str:
        """Where setpoints went unanswered or unrecorded: one clause each, '' when none."""
        if self.complete:
            return ''
        missing = self.sent - self.recorded
        if not self.reported:
            return (f'{missing} of {self.sent} setpoints have no recorded effort, and no '
                    '/diagnostics report of the node came to say whether the node or the '
                    'recorder lost them')
        parts: list[str] = []
        if self.lost > 0:  # type: ignore[operator]
            parts.append(f'node: {self.lost} setpoints lost before the node took them (its '
                         'joint_setpoint queue ran over; to keep them all, start the node '
                         f'with -p qos_overrides.{self.setpoint_topic}.subscription.depth:='
                         f'{self.sent})')
        if self.rejected > 0:  # type: ignore[operator]
            parts.append(f'node: {self.rejected} setpoints rejected (its log says why; '
                         "'stale': the node fell behind by more than max_setpoint_age, "
                         'which a recording may raise)')
        if self.uncounted > 0:
            parts.append(f'node: {self.uncounted} setpoints never reached the node (not in its '
                         'counts: sent before its subscription matched, or lost at the end '
                         'of the stream)')
        if self.unrecorded > 0:
            parts.append(f'recorder: {self.unrecorded} efforts the node sent were not recorded')
        if self.uncounted < 0 or self.unrecorded < 0 or not parts:
            # counters that do not add up (another publisher on the topic, a node restarted,
            # a report older than the last answers): say so rather than guess a place
            parts.append(f'{missing} of {self.sent} setpoints have no recorded effort; the '
                         f"node's counts over the run (accepted {self.accepted}, rejected "
                         f'{self.rejected}, lost {self.lost}) do not tell where')
        return '; '.join(parts)


def account(where: str, sent: int, recorded: int, before: Mapping[str, int] | None,
            after: Mapping[str, int] | None) -> Account:
    """The :class:`Account` of one node; ``before``/``after``: its counters (see
    :func:`counters`) from a report before the run and the last one after it. ``before``
    None: the node reported nothing before the run, which for a node started for the run
    means zero (it counts since its start)."""
    if after is None:
        return Account(where, sent, recorded)
    before = before or dict.fromkeys(COUNTERS, 0)
    delta = {key: after[key] - before[key] for key in COUNTERS}
    return Account(where, sent, recorded, delta['setpoints_accepted'],
                   delta['setpoints_rejected'], delta['setpoints_lost'])


class Recorder:
    """``joint_effort`` topics and ``/diagnostics`` recorded by a child process.

    ``topics``: fully qualified JointState topics to record; ``depth``: keep-last depth of
    each subscription (the number of messages the run can bring, so none is ever pushed
    out of the queue while the child is slow to take it). Use as a context manager, or
    call :meth:`close`.
    """

    def __init__(self, topics: Iterable[str], depth: int, start_timeout: float = 60.0) -> None:
        self.topics = list(topics)
        self.depth = int(depth)
        ctx = multiprocessing.get_context('spawn')
        self._conn, child = ctx.Pipe()
        self._process = ctx.Process(target=_serve, args=(child, self.topics, self.depth),
                                    name='cog_id_recorder', daemon=True)
        self._process.start()
        child.close()
        self._ask_timeout = start_timeout
        self._reply()                    # 'ready': subscriptions exist
        self._ask_timeout = 10.0

    @property
    def pid(self) -> int | None:
        return self._process.pid

    def _reply(self) -> Any:
        if not self._conn.poll(self._ask_timeout):
            raise RuntimeError(f'the recorder process did not answer in {self._ask_timeout:g} s')
        try:
            reply = self._conn.recv()
        except EOFError:
            raise RuntimeError(f'the recorder process ended (exit status '
                               f'{self._process.exitcode})') from None
        if isinstance(reply, BaseException):
            raise RuntimeError(f'the recorder process failed: {reply}')
        return reply

    def _ask(self, *request: object) -> Any:
        self._conn.send(request)
        return self._reply()

    def matched(self) -> dict[str, int]:
        """Per topic: the number of publishers its subscription is matched with."""
        return self._ask('matched')

    def wait_matched(self, topics: Iterable[str] | None = None, timeout: float = 30.0) -> bool:
        """True once every one of ``topics`` (default: all) has a matched publisher."""
        topics = self.topics if topics is None else list(topics)
        end = time.monotonic() + timeout
        while True:
            counts = self.matched()
            if all(counts[t] > 0 for t in topics):
                return True
            if time.monotonic() > end:
                return False
            time.sleep(0.02)

    def efforts(self, topic: str) -> tuple[Received, int]:
        """``(received, messages)``: stamp (ns) -> (names, efforts) of the messages recorded
        on ``topic``, and how many messages came (a repeated stamp counts twice)."""
        return self._ask('efforts', topic)

    def report(self, name: str) -> tuple[int, dict[str, str] | None, int | None]:
        """``(count, values, stamp)`` of the diagnostics status ``name``: how many reports
        came, the last one's key -> value and its header stamp (ns, the node's clock);
        ``(0, None, None)`` before the first."""
        return self._ask('report', name)

    def close(self) -> None:
        if self._process.is_alive():
            try:
                self._conn.send(('stop',))
            except (BrokenPipeError, OSError):
                pass
            self._process.join(timeout=10)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()
        self._conn.close()

    def __enter__(self) -> 'Recorder':
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def first_report(self, name: str, timeout: float = 30.0) -> dict[str, int] | None:
        """The node's counters (:func:`counters`) from its next report (None after
        ``timeout``): a report from before a run is where the run's counts start."""
        end = time.monotonic() + timeout
        count = self.report(name)[0]
        while time.monotonic() < end:
            newer, values, _ = self.report(name)
            if newer > count and counters(values) is not None:
                return counters(values)
            time.sleep(0.02)
        return None

    def answer_first(self, topic: str, name: str, stamp: int, send: Callable[[], object],
                     before: Mapping[str, int] | None, delivered: Callable[[], bool],
                     timeout: float = 30.0) -> bool:
        """Send the first setpoint (``send()``, stamped ``stamp``) until the node answers it;
        True once its effort is recorded, False when the node refused it or ``timeout``
        passed.

        Why: a publisher reports its subscription matched as soon as it has discovered the
        node's reader, and the node's reader may discover the publisher later; being
        volatile, it then skips everything sent before (under load: the first 187
        setpoints of a run, ~0.2 s after the publisher's match). An answer proves both
        links: the node took a setpoint and the recorder got its effort.

        ``before``: the node's counters before the send (:meth:`first_report`);
        ``delivered()``: True once the node's reader acknowledged what was sent (received,
        or skipped). The setpoint is sent again only when, after that acknowledgement, two
        reports of the node stamped later still show its counters unchanged: the node
        skipped it, so the copy cannot arrive twice. (Counting reports as they arrive is
        not enough: a recorder that was slow to take them receives reports from before the
        node took the setpoint after the send, and a copy was then rejected as a repeated
        stamp.)
        """
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            send()
            sent, acked_at, later = time.monotonic(), None, set()
            while time.monotonic() < end:
                if stamp in self.efforts(topic)[0]:
                    return True
                if acked_at is None and delivered():
                    acked_at = time.time_ns()
                _, values, report_stamp = self.report(name)
                now = counters(values)
                if before is not None and now is not None and now != before:
                    if now['setpoints_accepted'] == before['setpoints_accepted']:
                        return False        # rejected, or counted lost: no answer comes
                elif acked_at is None:
                    pass                    # still on its way
                elif before is None:
                    # no counters to tell: send again after a while (a copy the node does
                    # get twice is rejected as a repeated stamp, and counted so)
                    if time.monotonic() - sent > BLIND_RESEND:
                        break
                elif report_stamp is not None and report_stamp > acked_at:
                    later.add(report_stamp)
                    if len(later) >= 2:
                        break               # skipped by the node: send again
                time.sleep(0.01)
        return False

    def settle(self, where: str, topic: str, diagnostics: str, stamps: Sequence[int],
               before: Mapping[str, int] | None, quiet: float = 3.0,
               timeout: float = 30.0) -> tuple[Account, Received]:
        """Wait until the run is accounted for, then return ``(Account, received)``.

        Done when the node's counters cover every setpoint sent and every effort it says
        it sent is recorded; or, when something went missing, once nothing has changed for
        ``quiet`` seconds (the node reports once a ``diagnostics_period``: ``quiet`` must
        be longer), at the latest after ``timeout``. ``before``: the node's counters
        before the run (:func:`counters`).
        """
        wanted = set(stamps)
        end = time.monotonic() + timeout
        last_state, last_change = None, time.monotonic()
        while True:
            received, _ = self.efforts(topic)
            recorded = len(wanted.intersection(received))
            after = counters(self.report(diagnostics)[1])
            result = account(where, len(stamps), recorded, before, after)
            if result.reported and result.uncounted <= 0 and result.unrecorded <= 0:
                return result, received
            # progress is a new effort or a changed counter, not a new report: the node
            # reports every period whether or not anything happened
            now = time.monotonic()
            state = (recorded, after and tuple(after.values()))
            if state != last_state:
                last_state, last_change = state, now
            if now - last_change > quiet or now > end:
                return result, received
            time.sleep(0.05)


def _serve(conn: Any, topics: list[str], depth: int) -> None:
    """The recorder process: subscriptions spun by an executor thread, requests on ``conn``."""
    # the parent decides when the recorder stops: a Ctrl-C in the terminal reaches the whole
    # process group, and the parent still wants the recording to account for the run
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from sensor_msgs.msg import JointState

        from .conversions import stamp_to_ns

        context = rclpy.Context()
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node(f'cog_id_recorder_{os.getpid()}', context=context)
    except Exception as exc:  # noqa: BLE001 -- reported to the parent, which raises it
        conn.send(RuntimeError(f'{type(exc).__name__}: {exc}'))
        return
    lock = threading.Lock()
    efforts: dict[str, Received] = {topic: {} for topic in topics}
    messages = dict.fromkeys(topics, 0)
    reports: dict[str, tuple[int, dict[str, str], int]] = {}

    def on_effort(topic: str, msg: Any) -> None:
        with lock:
            messages[topic] += 1
            efforts[topic][stamp_to_ns(msg.header.stamp)] = (list(msg.name), list(msg.effort))

    def on_diagnostics(msg: Any) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        with lock:
            for status in msg.status:
                count = reports.get(status.name, (0,))[0]
                reports[status.name] = (count + 1, {kv.key: kv.value for kv in status.values},
                                        stamp)

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                     reliability=ReliabilityPolicy.RELIABLE)
    subscriptions = {topic: node.create_subscription(
        JointState, topic, lambda msg, topic=topic: on_effort(topic, msg),  # type: ignore[misc]
        qos)
        for topic in topics}
    # reliable like the node's publisher of /diagnostics (keep-last 10 there)
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics,
                             QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                        reliability=ReliabilityPolicy.RELIABLE))
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    stop = threading.Event()
    spinner = threading.Thread(target=_spin_until, args=(executor, stop, context), daemon=True)
    spinner.start()
    conn.send('ready')
    try:
        while True:
            request = conn.recv()
            if request[0] == 'stop':
                break
            with lock:
                if request[0] == 'matched':
                    reply: Any = {t: s.get_publisher_count() for t, s in subscriptions.items()}
                elif request[0] == 'efforts':
                    reply = (dict(efforts[request[1]]), messages[request[1]])
                elif request[0] == 'report':
                    reply = reports.get(request[1], (0, None, None))
                else:
                    reply = ValueError(f'unknown request {request[0]!r}')
            conn.send(reply)
    except (EOFError, OSError):
        pass                           # the parent is gone
    finally:
        # the spinning thread ends before the executor, the node and the context go: a C++
        # thread still waiting in it at interpreter exit aborts ("terminate called ...")
        stop.set()
        spinner.join(timeout=10.0)
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        context.try_shutdown()


def _spin_until(executor: Any, stop: threading.Event, context: Any) -> None:
    """Spin ``executor`` until ``stop`` is set (or the context is shut down). Not
    executor.spin(): shutdown() from another thread destroys the executor's guard condition
    while spin may still trigger it (a traceback, beside a CPU hog)."""
    while not stop.is_set() and context.ok():
        executor.spin_once(timeout_sec=0.1)
