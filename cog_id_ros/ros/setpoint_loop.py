"""A subscription served by a thread of its own, outside the executor (the control-rate path).

rclpy's executor rebuilds its whole wait set (every subscription, timer, service and QoS
event of the node) and wraps each message in a task before a callback runs, then wakes
once more after it: on the 2-core reference VM a plain echo node answers 25-200 us later
through the executor than through this loop (bench/bench_node_latency.py --lean-echo),
more than the inverse dynamics itself. A control stream at 1-2 kHz should not pay it.
:class:`SetpointLoop` creates an ordinary subscription (topic remapping, namespaces, QoS
overrides and graph introspection all behave as usual) but keeps it out of every executor,
and serves it from a thread that waits on that subscription alone: wait, take every queued
message, call back, wait again. This is the usual shape of a control node: ros2_control
runs its update loop in a thread of its own beside the executor that handles parameters
and services.

The subscription's QoS event handlers (the "incompatible QoS" warning) are served by the
same thread, in the same wait set; everything else of the node (timers, other
subscriptions, parameter services) stays with the executor. Callbacks of the two threads
that share state take the same ``lock``.

One private name of rclpy is used, here only:
``rclpy.impl.implementation_singleton.rclpy_implementation.WaitSet`` (built once in
:meth:`SetpointLoop.start`; then ``clear_entities``, ``add_subscription``,
``add_guard_condition``, ``wait`` and ``destroy_when_not_in_use``), the wait set rclpy's
own executors and ``wait_for_message`` use. rclpy Jazzy has no public one, and nothing
public serves one subscription of a node from a thread of its own: an executor serves
whole nodes, and a node belongs to one executor (``Executor.add_node`` takes it from the
one it was in); a subscription on a second node served by an executor of its own would
add a node to the ROS graph and move the ``qos_overrides./joint_setpoint.subscription.*``
parameters to it; ``rclpy.experimental.EventsExecutor`` is experimental (spun in a
thread of its own beside the node's executor, it answered none of 10,000 setpoints and
did not stop on SIGINT); ``wait_for_message`` creates a subscription per message.
Measured anyway, the second
node with a SingleThreadedExecutor in a thread of its own, as an echo beside the
bench's (bench/bench_node_latency.py with that echo added, 2-core VM shared with other
work, two runs): at 1 kHz its median latency was +17 and -32 us from the plain
executor's echo, this loop's -44 and -108 us; p99 34 and 46 ms against 9 and 5 ms;
at 2 kHz it lost 36 and 472 of 20,000 setpoints, this loop none.
"""
import contextlib
import threading
from typing import Any, Callable, ContextManager

from rclpy.callback_groups import CallbackGroup
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile


class OwnThreadCallbackGroup(CallbackGroup):
    """A callback group no executor ever runs: its entities are served elsewhere."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class SetpointLoop:
    """Serve subscription ``topic`` from a thread of its own; ``callback(msg)`` per message.

    Construct it like ``node.create_subscription`` (keywords are passed on, e.g.
    ``qos_overriding_options``); :meth:`start` the thread once the node is built and
    :meth:`stop` it before the node is destroyed. Messages are taken in order; every
    message queued when the thread wakes is served before it waits again. ``lock``, when
    given, is held around each callback. An exception from a callback is passed to
    ``on_error(exc)`` (default: logged by the node), with the lock still held, and the
    loop goes on; so does an exception from taking a message. ``with_info``: the callback
    is ``callback(msg, info)``, ``info`` rclpy's message info dict (source and received
    timestamps, the publisher's ``publication_sequence_number``).
    """

    def __init__(self, node: Node, msg_type: type, topic: str, callback: Callable[..., None],
                 qos_profile: QoSProfile | int, *, lock: ContextManager[Any] | None = None,
                 on_error: Callable[[Exception], None] | None = None, with_info: bool = False,
                 **subscription_kwargs: Any) -> None:
        self.node = node
        self.callback = callback
        self.with_info = with_info
        self._held: ContextManager[Any] = contextlib.nullcontext() if lock is None else lock
        self.on_error = on_error or self._log_error
        self.subscription = node.create_subscription(
            msg_type, topic, _never_called, qos_profile, callback_group=OwnThreadCallbackGroup(),
            **subscription_kwargs)
        # The subscription's QoS event handlers ("publisher offering incompatible QoS", ...)
        # are served here too, in the same wait set: with rmw_fastrtps a subscription's data
        # and its events share one listener, and a second wait set waiting on the events
        # (the executor's) takes the data wake-ups away from this one (measured: p99 latency
        # from 0.3 ms to 15-150 ms).
        # (a list: rclpy annotates Subscription.event_handlers as one EventHandler)
        self.event_handlers = list(self.subscription.event_handlers)  # type: ignore[call-overload]
        self._wake = GuardCondition(None, None, context=node.context)
        self._stopping = False
        self._thread: threading.Thread | None = None
        #: the exception that ended the thread, if one did (the node reports it: a loop that
        #: dies must never do so silently)
        self.failure: BaseException | None = None
        #: whether the thread ended because the context was shut down (Ctrl-C, SIGTERM)
        self._ended_at_shutdown = False

    def start(self) -> None:
        """Start serving. The wait set is built here, in the caller's thread (an error
        shows there); the thread inherits the caller's signal mask."""
        sub = self.subscription
        in_use = contextlib.ExitStack()   # none of these is destroyed while waited on
        context = self.node.context
        try:
            for entity in (context.handle, sub.handle, self._wake.handle, *self.event_handlers):
                in_use.enter_context(entity)
            wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, len(self.event_handlers), context.handle)
        except BaseException:
            in_use.close()
            raise
        self._thread = threading.Thread(target=self._run, args=(wait_set, in_use),
                                        name=f'{sub.topic} loop', daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the thread and wait for it (the callback in progress, if any, finishes)."""
        if self._stopping:
            return
        self._stopping = True
        if self._thread is not None and self._thread.is_alive():
            try:
                self._wake.trigger()
            except Exception:   # noqa: BLE001 (guard already gone: the thread is ending anyway)
                pass
            self._thread.join(timeout)
        self._wake.destroy()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def ended_by_itself(self) -> bool:
        """Whether the thread ended with an exception, or while nobody stopped it and the
        context was still ok (a bug); not when it ended because the context was shut down
        (rclpy's signal handler does that on Ctrl-C, before the node stops its threads)."""
        if self._thread is None or self._thread.is_alive():
            return False
        return self.failure is not None or not (self._stopping or self._ended_at_shutdown)

    def _run(self, wait_set: Any, in_use: contextlib.ExitStack) -> None:
        sub = self.subscription
        try:
            self._loop(wait_set, sub.handle, sub.msg_type, sub.raw, self.node.context)
            self._ended_at_shutdown = not self.node.context.ok()
        except BaseException as exc:   # noqa: BLE001 (recorded, then the thread ends)
            self.failure = exc
            try:
                self.node.get_logger().error(
                    f'{sub.topic_name}: the thread serving it stopped: '
                    f'{type(exc).__name__}: {exc}')
            except Exception:   # noqa: BLE001 (the node reports self.failure all the same)
                pass
        finally:
            wait_set.destroy_when_not_in_use()
            in_use.close()

    def _loop(self, wait_set: Any, handle: Any, msg_type: Any, raw: bool, context: Any) -> None:
        wake = self._wake.handle
        events = self.event_handlers
        while not self._stopping:
            wait_set.clear_entities()
            wait_set.add_subscription(handle)
            wait_set.add_guard_condition(wake)
            for event in events:
                event.add_to_wait_set(wait_set)
            wait_set.wait(-1)             # releases the GIL
            for event in events:
                if event.is_ready(wait_set):
                    self._handle_event(event)
            while not self._stopping:
                try:
                    taken = handle.take_message(msg_type, raw)
                except Exception as exc:   # noqa: BLE001 (e.g. a message that cannot be taken)
                    if not context.ok():
                        return
                    self._take_failed(exc)
                    break
                if taken is None:
                    break
                self._serve(taken)
            if not context.ok():
                return

    def _serve(self, taken: tuple[Any, Any]) -> None:
        with self._held:
            try:
                if self.with_info:
                    self.callback(taken[0], taken[1])
                else:
                    self.callback(taken[0])
            except Exception as exc:   # noqa: BLE001 (the loop must outlive a bad message)
                if self.node.context.ok():
                    self._report(exc)

    def _take_failed(self, exc: Exception) -> None:
        """Taking a message failed: reported like a callback error; the loop waits again."""
        with self._held:
            self._report(exc)

    def _report(self, exc: Exception) -> None:
        """``on_error(exc)``; if that fails too, the node's log (the loop goes on)."""
        try:
            self.on_error(exc)
        except Exception:   # noqa: BLE001 (a failing error handler must not end the loop)
            try:
                self._log_error(exc)
            except Exception:   # noqa: BLE001
                pass

    def _handle_event(self, event: Any) -> None:
        data = event.take_data()
        if data:
            try:
                event.callback(data)
            except Exception as exc:   # noqa: BLE001
                self._log_error(exc)

    def _log_error(self, exc: Exception) -> None:
        self.node.get_logger().error(
            f'{self.subscription.topic_name}: callback failed: {type(exc).__name__}: {exc}')


def _never_called(msg: object) -> None:
    raise AssertionError('SetpointLoop subscriptions are served by their own thread')
