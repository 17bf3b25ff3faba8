"""cog_id_node: joint setpoints in, actuator effort commands out (the ROS face of the core).

Topics (relative names: namespaces and ``-r old:=new`` remaps apply; the table with their
types, QoS and meaning is :mod:`.topics`, documented in docs/node.md): ``joint_setpoint``
and ``joint_trajectory`` in; ``effort_command`` and ``joint_effort`` out (one per accepted
setpoint), ``joint_states`` (every ``joint_states_decimation``-th), ``effort_trajectory``
and ``/diagnostics``; with a floating base (:mod:`.floating_mode`) ``base_state`` in and
``contact_wrenches/<name>`` and ``base_wrench`` out too. The parameters, read once at
start-up and read-only afterwards (all but ``active_contacts``), are the mechanism's and
the node's own (:mod:`.parameters`, made into a :class:`.NodeConfig`).

This module is the wiring: publishers, subscriptions, timers, and the callback that
serves a setpoint. The setpoint is checked and estimated by :mod:`.setpoint_stream`,
turned into efforts by a control mode (:mod:`.modes`), clipped
(:func:`.conversions.clip_efforts`) and published; what is counted and reported is in
:mod:`.diagnostics`. Threads: ``joint_setpoint`` is served by a thread of its own
(:mod:`.setpoint_loop`), trajectories by a thread and a process of their own
(:mod:`.trajectory_worker`), everything else by the executor in the main thread; shared
state is under ``self.lock``. No exception in a callback ends the node: it is counted
(``internal_errors``) and logged with its type. ``main`` is in :mod:`.main`.
"""
import contextlib
import math
import threading
import time
from typing import Any, Callable, ContextManager, Sequence, cast

import numpy as np
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from ..core import CogIdError, InverseDynamics
from ..description import Mechanism
from .command_line import urdf_base_dir
from .config import NodeConfig, start_up_summary
from .conversions import (
    EffortMessages,
    Rejected,
    clip_efforts,
    of_measured_state,
    rejection,
    trajectory_point_count,
)
from .diagnostics import (
    Counts,
    DiagnosticsPublisher,
    Report,
    ThrottledWarnings,
    guarded,
)
from .feedback import FeedbackMode
from .floating_mode import NO_TRAJECTORIES, FloatingBase
from .joint_space_solver import JointSpaceSolver
from .late_timer import LateTimer
from .measurement_stream import MeasurementStream
from .modes import Mode, make_mode
from .parameters import NODE_PARAMETERS, is_mechanism_parameter
from .read_only_node import ReadOnlyNode, assembly_warnings_logged
from .setpoint_loop import SetpointLoop
from .setpoint_stream import SetpointStream
from .topics import FEEDBACK_TOPICS, TOPICS, control_qos, stream_qos
from .trajectory_worker import TrajectoryWorker

NODE_NAME = 'cog_id_node'


class CogIdNode(ReadOnlyNode):
    """Inverse dynamics of the mechanism in its parameters, served over topics."""

    #: whether it serves and publishes (a managed node: only while active)
    active = True
    #: a floating base's topics, parameter and mode (:mod:`.floating_mode`); None: fixed
    floating: FloatingBase | None = None

    def __init__(self, command_line: Sequence[str] | None = None,
                 interruptible: Callable[[], ContextManager] = contextlib.nullcontext,
                 build: bool = True, **kwargs: Any) -> None:
        """``command_line``: the process's arguments (main() passes them), for the directory
        a relative ``mechanism.urdf_file`` is relative to (:func:`.urdf_base_dir`).
        ``interruptible``: a context manager around the parts of start-up that may take long
        and build no rclpy object (loading the mechanism, compiling its kernels), in which
        main() lets a stop signal raise (stop_signals.DeferredStop.interruptible).
        ``build``: False leaves the node bare (a managed node builds at configure)."""
        super().__init__(NODE_NAME, **kwargs)
        if build:
            self.build_or_destroy(lambda: self._build(command_line, interruptible))

    def _build(self, command_line: Sequence[str] | None,
               interruptible: Callable[[], ContextManager]) -> None:
        overrides = self._read_parameters(command_line, interruptible)
        self._make(overrides, interruptible)
        self.refuse_changes()

    def _read_parameters(self, command_line: Sequence[str] | None,
                         interruptible: Callable[[], ContextManager]) -> dict[str, Any]:
        """Declare the parameters (read-only), load the mechanism, make the NodeConfig;
        the values given to the node."""
        overrides = self.override_values()
        base_dir = {name: urdf_base_dir(command_line, self.get_name(), name)
                    for name in ('mechanism.urdf_file', 'mechanism.loop_closure_file')
                    if name in overrides}
        with interruptible(), assembly_warnings_logged():
            self.mechanism = Mechanism.from_parameters(self.declare_given(
                overrides, is_mechanism_parameter, 'mechanism (read at start-up)'),
                base_dir=base_dir)
        self.warn_unknown(overrides, lambda name: name in NODE_PARAMETERS
                          or is_mechanism_parameter(name))
        self.config = NodeConfig.declare(self, overrides, self.mechanism)
        self.check_qos_overrides(overrides)
        # The node's time in integer ns, read per setpoint (stamp checks): without
        # use_sim_time (read-only, so fixed from here on) the node's clock is the system
        # clock, which time.time_ns reads too (CLOCK_REALTIME, like rcl's system time) in
        # 0.1 us instead of the 4.7 us of get_clock().now() (measured on the reference VM)
        self._now_ns = self._ros_now_ns if self.make_use_sim_time_read_only() else time.time_ns
        return overrides

    def _make(self, overrides: dict[str, Any],
              interruptible: Callable[[], ContextManager]) -> None:
        """Everything that serves: solvers (kernels compiled), mode, streams, topics,
        trajectory worker, timers (a managed node: at configure; cleanup releases them)."""
        config = self.config
        with interruptible():
            self.solver = self._new_solver()        # setpoints
            self.report = Report(self, self._new_solver())
            # setpoint -> efforts; a feedback mode: measured state -> efforts too (a solver
            # of its own: the measured stream's branch continuity)
            self.mode: Mode = make_mode(config, self.solver, self._new_solver)
        # joint_setpoint is served by a thread of its own, trajectories are answered by the
        # trajectory worker's, everything else by the executor: what they share is under it
        self.lock = threading.Lock()
        self.counts = Counts(ThrottledWarnings(self.get_logger(), config.warning_period))
        self.setpoints = SetpointStream(
            config, self.counts, self.get_logger(), self._now_ns,
            lambda: self.setpoint_loop.subscription.get_publisher_count())
        self.measurements = MeasurementStream(
            config, self.mode.needs_velocities,
            lambda: self.counts.matched['measured_joint_states']) if self.mode.measured else None
        self.effort_limits = config.effort_limits if config.limited else None  # None: no clip
        self.outputs = EffortMessages(config.motors, self.mechanism.joints)
        self._joint_states_countdown = 1      # served setpoints until the next joint_states
        with self.qos_overrides_honoured(overrides):
            self._create_topics()
            if self.mechanism.floating_base:    # base_state in, wrenches out, its mode
                self.floating = FloatingBase(self, overrides,
                                             QoSOverridingOptions.with_default_policies)
                self.mode = cast(Mode, self.floating.mode)
        # the trajectory process builds the kernels the node's solver uses: never again
        # the ones the node gave up on ('auto' that fell back to 'python': a hung compiler)
        self.trajectory_worker = TrajectoryWorker(
            config, self._trajectory_done, backend=self._trajectory_backend(),
            logger_name=self.get_logger().get_child('trajectories').name)
        self.timers_made = [self.create_timer(config.diagnostics_period,
                                              self.publish_diagnostics)]
        self.timeout_timers = {                   # the timeout timers and their late runs
            'setpoints': LateTimer(min(config.setpoint_timeout / 4.0, 0.25)),
            'measured': LateTimer(min(config.measurement_timeout / 4.0, 0.25))}
        if config.setpoint_timeout > 0.0:
            self.timers_made.append(self.create_timer(self.timeout_timers['setpoints'].period,
                                                      self.check_timeout))
        if self.measurements is not None:
            self.timers_made.append(self.create_timer(self.timeout_timers['measured'].period,
                                                      self.check_measurement_timeout))
        self.get_logger().info(start_up_summary(self.mechanism, config))
        for warning in getattr(self.mechanism, 'assembly_warnings', None) or ():
            self.get_logger().warning(f'mechanism: {warning}')
        for warning in cast(FeedbackMode, self.mode).gain_warnings() if self.mode.measured \
                else ():
            self.get_logger().warning(warning)

    def _new_solver(self) -> Any:
        """A solver of the commanded joints: InverseDynamics, or its joint-space twin
        (``command_space: joint``: motor efforts of a joint-space motion)."""
        make = JointSpaceSolver if self.config.joint_space else InverseDynamics
        return make(self.mechanism, backend=self.config.backend)

    def _create_topics(self) -> None:
        qos_options = QoSOverridingOptions.with_default_policies
        # Publishers go without rclpy's default QoS-event handlers: each costs the executor
        # ~7 us per wake-up, and an incompatible subscriber logs the mismatch on its side.
        # The subscriptions keep theirs: a setpoint publisher we cannot hear is reported here.
        lean = PublisherEventCallbacks(use_default_callbacks=False)

        def publisher(msg_type: type, topic: str) -> Any:
            return self.create_publisher(msg_type, TOPICS[topic].name, control_qos(),
                                         event_callbacks=lean,
                                         qos_overriding_options=qos_options())

        self.command_pub = publisher(Float64MultiArray, 'effort_command')
        self.effort_pub = publisher(JointState, 'joint_effort')
        self.joint_states_pub = publisher(JointState, 'joint_states') \
            if self.config.joint_states_decimation else None
        self.trajectory_pub = publisher(JointTrajectory, 'effort_trajectory')
        self.diagnostics = DiagnosticsPublisher(self, lean)
        # The control-rate input: its own thread and wait set, outside the executor (see
        # setpoint_loop.py). start() once the node is built; stop() before destroying it.
        self.setpoint_loop = SetpointLoop(
            self, JointState, TOPICS['joint_setpoint'].name, self.serve_setpoint,
            stream_qos(), lock=self.lock, on_error=self._serve_failed, with_info=True,
            qos_overriding_options=qos_options(), event_callbacks=self._matched('joint_setpoint'))
        # feedback modes: the measured states, served like setpoints by a thread of their own
        self.measurement_loop = SetpointLoop(
            self, JointState, FEEDBACK_TOPICS['measured_joint_states'].name,
            self.serve_measurement, stream_qos(), lock=self.lock,
            on_error=self._measurement_failed, with_info=True,
            qos_overriding_options=qos_options(),
            event_callbacks=self._matched('measured_joint_states')) \
            if self.measurements is not None else None
        # taken serialized: the executor never deserialises a long trajectory (a C call
        # that holds the GIL for seconds); the trajectory process does
        self.trajectory_sub = self.create_subscription(
            JointTrajectory, TOPICS['joint_trajectory'].name, self.on_trajectory, control_qos(),
            qos_overriding_options=qos_options(), raw=True)

    def _matched(self, topic: str) -> SubscriptionEventCallbacks:
        """The event callbacks of a subscription to ``topic``: rclpy's defaults (an
        incompatible publisher is logged), and its matched publishers counted for
        /diagnostics (the node's side of the match: a publisher can see the node before the
        node sees it, and what it sends meanwhile is lost without a trace)."""
        def matched(status: Any) -> None:
            self.counts.matched[topic] = status.current_count
        return SubscriptionEventCallbacks(matched=matched)

    def _trajectory_backend(self) -> str:
        """The backend of the trajectory process: the node's solver's, except that compiled
        kernels the node has (from its cache) are asked for as the parameter asked (with
        'auto', a process that cannot load them falls back to the Python ones)."""
        used = self.solver.backend
        return self.config.backend if used == 'native' else used

    def _ros_now_ns(self) -> int:
        """The node's clock (ROS time: /clock with use_sim_time) in integer ns."""
        return self.get_clock().now().nanoseconds

    # --- threads -----------------------------------------------------------------------------

    def _threads(self) -> list[tuple[str, Any]]:
        """(name, thread) of each thread of the node: the setpoint thread, the measured state
        and base state threads where there are, the trajectory worker."""
        floating = self.floating
        return [(name, thread) for name, thread in (
            ('setpoint thread', self.setpoint_loop), ('measured state thread',
                                                      self.measurement_loop),
            ('base state thread', None if floating is None else floating.loop),
            ('trajectory worker', self.trajectory_worker)) if thread is not None]

    def start(self) -> None:
        """Start the node's threads and the trajectory worker (once the node is built)."""
        for _, thread in self._threads():
            thread.start()
        self._threads_started = True

    def stopped_threads(self) -> list[str]:
        """'<thread>: <why>' of every thread of the node that ended by itself: with an
        exception, or while the context was still ok and the node had not stopped it (a
        bug: none may end silently; /diagnostics says ERROR, and the process exits with
        status 1). The setpoint thread ends when the context is shut down (a stop signal),
        maybe before the node stops it: that is not a thread that stopped."""
        if not getattr(self, '_threads_started', False):
            return []
        out = []
        for name, thread in self._threads():
            if thread.ended_by_itself:
                failure = thread.failure
                out.append(f'{name}: ' + (f'{type(failure).__name__}: {failure}'
                                          if failure is not None else 'ended'))
        return out

    def stop(self) -> list[str]:
        """Stop them all (before the node is destroyed); returns stopped_threads() as it was
        before (what ended by itself)."""
        stopped = self.stopped_threads()
        self._threads_started = False
        for _, thread in self._threads():
            thread.stop()
        return stopped

    def internal_error(self, where: str, exc: BaseException) -> None:
        """An exception in one of the node's callbacks: counted, logged with its type."""
        with self.lock:
            self.counts.internal_error(where, exc)

    # --- setpoints ---------------------------------------------------------------------------

    def serve_setpoint(self, msg: JointState, info: dict | None = None) -> None:
        """One JointState setpoint -> effort_command + joint_effort, or a counted rejection.

        Called by the setpoint loop's thread with ``self.lock`` held, once per message, in
        the order received; every message that queued up while it worked is served next.
        ``info``: rclpy's message info (lost and stale setpoints, :class:`.SetpointStream`).
        """
        if not self.active:         # a managed node before activate: nothing is published
            self._while_inactive('setpoints_while_inactive', self.setpoints.lost, info)
            return
        start = time.perf_counter()
        stream, counts = self.setpoints, self.counts
        try:
            q, v, a = stream.take(msg, info)      # checked, unwrapped, estimated
            efforts = self.mode.efforts(q, v, a)
            if efforts is None:     # a feedback mode: in force; commands follow measurements
                stream.accept()
                return
            if not all(map(math.isfinite, efforts)):
                raise Rejected('out_of_range', 'the torques are not finite at this setpoint')
        except Rejected as exc:
            counts.reject(exc.reason, str(exc))
            return
        except CogIdError as exc:
            bad = rejection(exc)
            counts.reject(bad.reason, str(bad))
            return
        efforts = self._send(efforts, start)
        self.effort_pub.publish(self.outputs.state_for(
            msg.header, *self._motor_state(stream.received, v, self.solver), efforts))
        stream.accept()
        if self.floating is not None:               # the wrenches, after the command
            self.floating.publish(stream.stamp)
        if self.joint_states_pub is not None:       # last: nothing waits for it
            self._joint_states_due(msg.header.frame_id, stream.stamp, v, self.solver)

    def _motor_state(self, positions: list[float], rates: list[float],
                     solver: Any) -> tuple[list[float], list[float]]:
        """joint_effort's positions and velocities: the motors' (at ``solver``'s pose)."""
        if self.config.joint_space:
            return solver.actuator_state(rates)
        return positions, rates

    def _joint_states_due(self, frame_id: str, stamp: int, rates: list[float],
                          solver: Any) -> None:
        """joint_states for every joint_states_decimation-th command (``solver``: the one
        whose last pose the command was computed at)."""
        self._joint_states_countdown -= 1
        if not self._joint_states_countdown:
            self._joint_states_countdown = self.config.joint_states_decimation
            try:
                self.publish_joint_states(frame_id, stamp, rates, solver)
            except Exception as exc:   # noqa: BLE001 (the command is out: no rejection)
                self.counts.internal_error('joint_states', exc)

    def _send(self, efforts: list[float], start: float) -> list[float]:
        """Clip ``efforts`` and publish them on effort_command; the efforts sent. The
        compute time (from ``start``, the message's receipt) ends when the command is ready
        to send; the DDS write after that is timed apart (the publish time)."""
        if self.effort_limits is not None:
            tau = np.array(efforts)
            if self.clip(tau):
                efforts = tau.tolist()
        # first the command: what control waits for, published serialized
        # (conversions.EffortMessages.command_for, cdr.py)
        command = self.outputs.command_for(efforts)
        ready = time.perf_counter()
        self.command_pub.publish(command)
        counts = self.counts
        counts.publish_times.append(time.perf_counter() - ready)
        counts.compute_times.append(ready - start)
        return efforts

    def serve_measurement(self, msg: JointState, info: dict | None = None) -> None:
        """Feedback modes: one measured JointState -> effort_command + joint_effort from the
        mode's law with the setpoint in force, or a counted rejection (never a command from
        a stale, jumping, non-finite or unclosable measurement). Called by the measured
        state thread with ``self.lock`` held, once per message, in the order received."""
        if not self.active:
            self._while_inactive('measurements_while_inactive',
                                 cast(MeasurementStream, self.measurements).lost, info)
            return
        start = time.perf_counter()
        # the setpoints that arrived before this measured state are in force before it is
        # served, whether or not the setpoint thread has woken up yet
        self.setpoint_loop.serve_queued()
        stream, counts = cast(MeasurementStream, self.measurements), self.counts
        mode = cast(FeedbackMode, self.mode)
        try:
            q, v = stream.take(msg, info)       # checked, unwrapped
            efforts = mode.command(q, v)
            if not all(map(math.isfinite, efforts)):
                raise Rejected('out_of_range', 'the efforts are not finite at this measured '
                                               'state')
        except Rejected as exc:
            counts.reject_measurement(exc.reason, str(exc))
            return
        except CogIdError as exc:
            bad = rejection(exc)
            counts.reject_measurement(bad.reason, of_measured_state(str(bad)))
            return
        efforts = self._send(efforts, start)
        self.effort_pub.publish(self.outputs.state_for(
            msg.header, *self._motor_state(q, v, mode.measured_solver), efforts))
        stream.accept()
        counts.measured(mode.error)
        if self.joint_states_pub is not None:       # when given: the measured pose, closed
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            self._joint_states_due(msg.header.frame_id, stamp, v, mode.measured_solver)

    def _while_inactive(self, key: str, lost: Any, info: dict | None) -> None:
        """A message taken while a managed node is not active: counted as such (``key``),
        not served; its sequence number kept, so that it is not counted lost later."""
        self.counts.totals[key] += 1
        lost.count(info)

    def _measurement_failed(self, exc: Exception) -> None:
        """A measured state that failed in a way serve_measurement does not expect (a
        bug): no command, counted as 'solver' and in internal_errors."""
        self.counts.totals['internal_errors'] += 1
        self.counts.reject_measurement('solver', f'unexpected {type(exc).__name__}: {exc}')

    def publish_joint_states(self, frame_id: str, stamp: int, rates: list[float],
                             solver: Any = None) -> None:
        """joint_states: the closed pose the solver served the setpoint at (every joint) and
        the joint rates there from the active ``rates`` used, read from the core (``solver``:
        the node's setpoint solver by default; a feedback mode's measured one)."""
        solver = self.solver if solver is None else solver
        try:
            q, qdot = solver.last_pose(rates)
        except CogIdError:      # rates too large for the joint rates: positions alone
            q, qdot = solver.last_pose()[0], []
        # (called where joint_states_pub is not None; qdot: rates were given)
        self.joint_states_pub.publish(  # type: ignore[union-attr]
            self.outputs.pose_for(frame_id, stamp, q, qdot))

    def clip(self, tau: np.ndarray) -> bool:
        """Clip efforts (an array, in place) to +-effort_limits; count it; True if clipped."""
        if self.effort_limits is None or not clip_efforts(tau, self.effort_limits):
            return False
        self.counts.problem('effort_clipped')
        return True

    def _serve_failed(self, exc: Exception) -> None:
        """A setpoint that failed in a way serve_setpoint does not expect (a bug): no
        command, counted as 'solver' and in internal_errors, logged with its type; the
        next one is served."""
        self.counts.totals['internal_errors'] += 1
        self.counts.reject('solver', f'unexpected {type(exc).__name__}: {exc}')

    # --- when the stream stops ---------------------------------------------------------------

    @guarded
    def check_timeout(self) -> None:
        """When setpoints stop: restart the estimator and apply timeout_behavior, once (a
        feedback mode: the last setpoint stays in force, at rest). Judged on what has
        arrived: setpoints queued for the setpoint thread are served first (after a stall of
        the node the timer may wake before that thread does)."""
        timer = self.timeout_timers['setpoints']
        with self.lock:
            if not self.active or timer.woke_late(self.setpoints.last_time):
                return
            self.setpoint_loop.serve_queued()
            self._check_timeout()

    def _check_timeout(self) -> None:
        config = self.config
        resumed = self.timeout_timers['setpoints'].resumed
        if not self.setpoints.stopped_for(config.setpoint_timeout, resumed):
            return
        if self.mode.measured:
            cast(FeedbackMode, self.mode).setpoints_stopped()
            self.get_logger().info(
                f'no setpoint for {config.setpoint_timeout:g} s: the last one stays in force, '
                'at rest')
            return
        self.counts.totals['timeouts'] += 1
        what = self.apply_timeout_behavior(self.setpoints.last_pose)
        if what is not None:
            self.get_logger().info(
                f'no setpoint for {config.setpoint_timeout:g} s: stream stopped, {what}')

    @guarded
    def check_measurement_timeout(self) -> None:
        """Feedback modes: no measured state accepted for measurement_timeout (none came,
        or each was rejected): timeout_behavior at the last measured pose, once. The
        measured states (and setpoints) queued are served first."""
        stream = cast(MeasurementStream, self.measurements)
        timer = self.timeout_timers['measured']
        with self.lock:
            if not self.active or timer.woke_late(stream.last_time):
                return
            # judged on what has arrived, not on when this process last ran: after a stall
            # the timer may wake before the measured state thread, with fresh states queued
            self.setpoint_loop.serve_queued()
            cast(Any, self.measurement_loop).serve_queued()
            warning = stream.silence_to_tell(    # none accepted for a while: say why
                self.counts.matched['measured_joint_states'],
                cast(Any, self.measurement_loop).subscription.topic_name)
            if warning:
                self.get_logger().warning(warning)
            if not stream.stopped_for(self.config.measurement_timeout, timer.resumed):
                return
            self.counts.totals['timeouts'] += 1
            what = self.apply_timeout_behavior(stream.last_pose)
            if what is not None:
                self.get_logger().warning(
                    f'no measured state accepted for {self.config.measurement_timeout:g} s: '
                    f'{what}')

    def apply_timeout_behavior(self, pose: Sequence[float] | None) -> str | None:
        """Publish timeout_behavior's command once (hold: the gravity-holding efforts of
        ``pose``, or of initial_positions without one); what was done, None if it failed."""
        config = self.config
        self.timeout_command = None
        if config.timeout_behavior == 'none':
            return 'nothing published'
        if config.timeout_behavior == 'zero':
            efforts = [0.0] * len(config.motors)
            what = 'zero efforts published'
        else:
            if pose is None:
                pose = self._initial_active_positions()
            try:
                tau = self.mode.hold(pose)
            except CogIdError as exc:   # cannot happen for a pose just served; be safe
                self.get_logger().error(f'cannot compute holding efforts: {exc}')
                return None
            self.clip(tau)
            efforts = tau.tolist()
            what = 'gravity-holding efforts of the last pose published'
        #: the command published last by a timeout (a managed node repeats it while inactive)
        self.timeout_command = self.outputs.command_for(efforts)
        self.command_pub.publish(self.timeout_command)
        return what

    def _initial_active_positions(self) -> list[float]:
        """The commanded joints' assembled initial_positions (hold before any pose)."""
        m = self.mechanism
        return [float(m.assembled_positions[m.joints.index(j)])
                for j in self.config.active_joints]

    # --- trajectories ------------------------------------------------------------------------

    @guarded
    def on_trajectory(self, raw: bytes) -> None:
        """A serialized JointTrajectory: refused at once when too long, else handed to the
        trajectory worker (a process of its own; queue of one)."""
        points, most = trajectory_point_count(raw), self.config.max_trajectory_points
        if self.floating is not None:       # no base motion in a trajectory
            self._trajectory_rejected('base_state', NO_TRAJECTORIES, points)
            return
        if points is not None and points > most:
            self._trajectory_rejected(
                'too_long', f'{points} points, more than max_trajectory_points ({most})', points)
            return
        replaced = self.trajectory_worker.submit(raw)
        if replaced is not None:
            self._trajectory_rejected(
                'busy', 'a newer trajectory arrived while it waited for the one being solved '
                        '(one waits at most; the newest wins)', trajectory_point_count(replaced))

    def _trajectory_rejected(self, reason: str, text: str, points: int | None) -> None:
        with self.lock:
            self.counts.reject_trajectory(reason, text, points)

    @guarded
    def _trajectory_done(self, result: tuple) -> None:
        """Called by the trajectory worker's thread with the trajectory process's answer."""
        kind = result[0]
        if kind == 'ok':
            _, out, clipped, _ = result
            self.trajectory_pub.publish(out)
            with self.lock:
                self.counts.totals['trajectories_accepted'] += 1
                if clipped:
                    self.counts.problem('effort_clipped')
        elif kind == 'rejected':
            _, reason, text, points = result
            self._trajectory_rejected(reason, text, points)
        else:   # 'internal': the trajectory process failed or ended
            self.internal_error('trajectory', RuntimeError(result[1]))
            self._trajectory_rejected('solver', result[1], None)

    # --- diagnostics -------------------------------------------------------------------------

    @guarded
    def publish_diagnostics(self) -> None:
        if not self.active:
            return
        self.diagnostics.count_same_name_nodes()
        served = self.measurements.last_pose if self.measurements is not None else \
            self.setpoints.last_pose              # the last pose a command came from
        health = self.report.closure_health(served)   # outside the lock
        with self.lock:
            status = self.report.status(*health)
        self.diagnostics.publish(status)
