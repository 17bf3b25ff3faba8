"""What cog_id_node counts and reports on /diagnostics, and the pieces any node of the
package uses to report (the guard of its callbacks, throttled warnings, the publisher).

* :class:`Counts`: the counters of the node (``DIAGNOSTIC_KEYS``), the compute and
  publish times, and what the status of the last period says;
* :class:`Report`: the node's DiagnosticStatus, from its counts, its setpoint stream and
  its threads, with the closure health of the last served pose;
* reusable: :func:`guarded` (no exception of a callback ends the node),
  :class:`ThrottledWarnings`, :class:`DiagnosticsPublisher` (``/diagnostics`` and the
  warning about other nodes with the node's name), :class:`PythonLogsToRos` (the
  package's Python log records in ROS's log format).
"""
import collections
import functools
import logging
import math
import statistics
import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import PublisherEventCallbacks

from ..core import CogIdError
from .conversions import MEASUREMENT_REASONS, REASONS, TRAJECTORY_REASONS
from .topics import DIAGNOSTICS_QOS_DEPTH, TOPICS

#: keys of /diagnostics besides rejected.<reason> and trajectories_rejected.<reason>
DIAGNOSTIC_KEYS = {
    'mechanism': 'the mechanism name',
    'active_joints': 'the active joints, in effort order',
    'backend': "who computes the kernels: native, python or reference (parameter 'backend')",
    'setpoints_accepted': 'setpoints served since start',
    'setpoints_rejected': 'setpoints rejected since start (sum of rejected.<kind>)',
    'setpoint_publishers': "publishers of joint_setpoint matched to the node's subscription, "
                           'as the node sees them (a publisher may see the node first: wait '
                           'for this before the first setpoint, or it may be lost unseen)',
    'setpoints_lost': 'setpoints the single publisher of joint_setpoint sent that never reached '
                      'the node (gaps in its sequence numbers, e.g. a full subscription queue)',
    'stamp_restarts': 'times the estimator restarted after max_stamp_rejections stamp rejections',
    'setpoints_unstamped': 'accepted setpoints stamped 0, served at their receipt time (its '
                           'jitter becomes acceleration noise)',
    'trajectories_accepted': 'trajectories answered since start',
    'trajectories_rejected': 'trajectories refused since start (sum of '
                             'trajectories_rejected.<kind>)',
    'trajectory_in_progress': 'true while a trajectory is being solved',
    'effort_clipped': 'setpoints, trajectories and hold commands that were clipped',
    'timeouts': 'times the stream stopped',
    'setpoints_while_inactive': 'setpoints that arrived while the managed node was not '
                                'active: taken, not served (nothing is published then)',
    'internal_errors': 'exceptions the node caught in its own callbacks (a bug: please report)',
    'nodes_with_this_name': "nodes in the ROS graph with this node's name and namespace "
                            '(more than 1: every setpoint gets several commands)',
    'last_closure_residual': 'max closure equation residual at the last served pose (feedback '
                             'modes: the last measured pose commanded from), m or rad; '
                             "'' before one",
    'closure_condition_number': "condition number of the closure Jacobian there; '' before one",
    'compute_time_median_us': "from receipt of a setpoint to its command ready to send (the "
                              "solve and the node's own work), last 1000",
    'compute_time_max_us': 'the same, maximum',
    'compute_time_samples': 'setpoints in the two figures above',
    'publish_time_median_us': "the command's publish (the DDS write to its subscribers) "
                              'after that, last 1000',
    'publish_time_max_us': 'the same, maximum',
    'seconds_since_last_setpoint': 'monotonic seconds since the last accepted setpoint',
    'last_rejection': 'kind and message of the last rejected setpoint',
}

#: keys of /diagnostics in the feedback modes, besides measurements_rejected.<reason> and
#: tracking_error.<joint> (q_d - q_m of each active joint at the last command, rad or m)
FEEDBACK_DIAGNOSTIC_KEYS = {
    'control_mode': "the node's control_mode",
    'measurements_accepted': 'measured states commanded from since start',
    'measurements_rejected': 'measured states rejected since start, never commanded from '
                             '(sum of measurements_rejected.<kind>)',
    'measured_state_publishers': 'publishers of measured_joint_states matched to the '
                                 "node's subscription, as the node sees them (more than "
                                 'max_measured_publishers: none is commanded from)',
    'measurements_lost': 'measured states the single publisher sent that never reached the '
                         'node (gaps in its sequence numbers: a full subscription queue)',
    'measurements_while_inactive': 'measured states that arrived while the managed node was '
                                   'not active: taken, not commanded from',
    'measurement_age': 's since the last accepted measured state was received',
    'tracking_error_max': 'largest |q_d - q_m| of any active joint over the last period, rad '
                          'or m',
    'last_measurement_rejection': 'kind and message of the last rejected measured state',
}

#: compute times kept for the diagnostics median and max (the last N setpoints)
COMPUTE_TIME_WINDOW = 1000


def guarded(method: Callable) -> Callable:
    """A callback of a node that never ends it: an exception is counted and logged
    (``node.internal_error(name, exc)``)."""
    @functools.wraps(method)
    def guarded(self: Any, *args: Any) -> Any:
        try:
            return method(self, *args)
        except Exception as exc:   # noqa: BLE001 (no callback may end the node)
            if self.context.ok():
                self.internal_error(method.__name__, exc)
            return None
    return guarded


class ThrottledWarnings:
    """Log a warning at most once a ``period`` (s) per key; count the ones left out."""

    def __init__(self, logger: Any, period: float) -> None:
        self.logger = logger
        self.period = period
        self._warned: dict[str, tuple[float, int]] = {}   # key -> (time, suppressed count)

    def warn(self, key: str, text: str, error: bool = False) -> None:
        now = time.monotonic()
        last, suppressed = self._warned.get(key, (-math.inf, 0))
        if now - last < self.period:
            self._warned[key] = (last, suppressed + 1)
            return
        more = f' ({suppressed} more like it since the last warning)' if suppressed else ''
        self._warned[key] = (now, 0)
        # Two call sites, one per severity: rclpy's logger remembers the severity of each call
        # site and raises ValueError when one site logs at another (an error after a warning
        # from one line killed the thread that logged it)
        if error:
            self.logger.error(text + more)
        else:
            self.logger.warning(text + more)


class PythonLogsToRos(logging.Handler):
    """A handler of Python's logging that hands each record to an rclpy logger at its
    level: the lines the package logs with Python's ``logging`` (logger ``cog_id_ros``: the
    core's "compiled kernels unavailable ...", "not loaded from the cache ...") come out
    in ROS's log format, under the node's name, like the node's own.

    :meth:`attach` adds one to the package's logger, :meth:`detach` removes it (a node
    does so for its lifetime). Which records are emitted stays Python's choice (the logger's
    level: WARNING and above unless configured).
    """

    PACKAGE_LOGGER = 'cog_id_ros'

    def __init__(self, ros_logger: Any) -> None:
        super().__init__()
        self.ros_logger = ros_logger

    @classmethod
    def attach(cls, ros_logger: Any) -> 'PythonLogsToRos':
        handler = cls(ros_logger)
        logging.getLogger(cls.PACKAGE_LOGGER).addHandler(handler)
        return handler

    def detach(self) -> None:
        logging.getLogger(self.PACKAGE_LOGGER).removeHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = self.format(record)
            level = record.levelno
            # one call site per severity: rclpy's logger remembers the severity of each call
            # site and raises ValueError when one site logs at another
            if level >= logging.CRITICAL:
                self.ros_logger.fatal(text)
            elif level >= logging.ERROR:
                self.ros_logger.error(text)
            elif level >= logging.WARNING:
                self.ros_logger.warning(text)
            elif level >= logging.INFO:
                self.ros_logger.info(text)
            else:
                self.ros_logger.debug(text)
        except Exception:   # noqa: BLE001 (logging's own way: a line, never an exception)
            self.handleError(record)


class Counts:
    """What the node counts since start (``DIAGNOSTIC_KEYS``) and in the current period.

    Callers hold the node's lock: the setpoint thread, the trajectory worker's thread and
    the executor all count here.
    """

    def __init__(self, warnings: ThrottledWarnings) -> None:
        self.warnings = warnings
        self.totals = collections.Counter({'accepted': 0, 'trajectories_accepted': 0,
                                           'trajectories_rejected': 0, 'effort_clipped': 0,
                                           'timeouts': 0, 'internal_errors': 0,
                                           'setpoints_lost': 0, 'stamp_restarts': 0,
                                           'setpoints_unstamped': 0})
        #: publishers matched to the node's subscriptions, from their side: topic -> count
        self.matched = {'joint_setpoint': 0, 'measured_joint_states': 0}
        self.rejected = collections.Counter(dict.fromkeys(REASONS, 0))
        self.trajectory_rejected = collections.Counter(
            dict.fromkeys((*REASONS, *TRAJECTORY_REASONS), 0))
        self.compute_times: collections.deque = collections.deque(maxlen=COMPUTE_TIME_WINDOW)
        self.publish_times: collections.deque = collections.deque(maxlen=COMPUTE_TIME_WINDOW)
        self.last_rejection = ''
        self.last_was_rejected = False
        self.period_problems = 0              # rejections + clipping since the last report
        self.period_unstamped = 0             # setpoints stamped 0 since the last report
        # feedback modes: measured states
        self.measurement_rejected = collections.Counter(dict.fromkeys(MEASUREMENT_REASONS, 0))
        self.last_measurement_rejection = ''
        self.last_measurement_was_rejected = False
        self.tracking_error: list[float] = []     # q_d - q_m at the last command
        self.period_tracking_max = 0.0

    def measured(self, error: list[float]) -> None:
        """A measured state was commanded from; ``error``: q_d - q_m there (or [])."""
        self.totals['measurements_accepted'] += 1
        self.last_measurement_was_rejected = False
        self.tracking_error = error
        if error:
            self.period_tracking_max = max(self.period_tracking_max, max(map(abs, error)))

    def reject_measurement(self, reason: str, text: str) -> None:
        """Count a rejected measured state (no command) and warn about it, throttled."""
        self.measurement_rejected[reason] += 1
        self.last_measurement_rejection = f'{reason}: {text}'
        self.last_measurement_was_rejected = True
        self.period_problems += 1
        self.warnings.warn('measured.' + reason,
                           f'measured state rejected, no command ({reason}): {text}')

    def served(self, unstamped: bool) -> None:
        """A setpoint was served (``unstamped``: stamped 0, served at its receipt time)."""
        self.totals['accepted'] += 1
        self.last_was_rejected = False
        if unstamped:
            self._unstamped()

    def _unstamped(self) -> None:
        """A setpoint stamped 0 was served at its receipt time: counted, warned about (the
        time between receipts jitters against the motion, and its second difference is in
        the accelerations: torques many times too large at 1 kHz)."""
        self.totals['setpoints_unstamped'] += 1
        self.period_unstamped += 1
        self.warnings.warn(
            'unstamped', 'setpoint stamped 0: served at its receipt time, so the jitter of '
            'receipt times against the motion goes into the estimated accelerations (at 1 kHz, '
            'torques can be many times too large); stamp each setpoint with the time its '
            'positions are meant for (header.stamp), or send whole trajectories with their '
            'velocities and accelerations to joint_trajectory')

    def reject(self, reason: str, text: str) -> None:
        """Count a rejected setpoint (no command) and warn about it, throttled."""
        self.rejected[reason] += 1
        self.last_rejection = f'{reason}: {text}'
        self.last_was_rejected = True
        self.period_problems += 1
        self.warnings.warn(reason, f'setpoint rejected, no command ({reason}): {text}')

    def reject_trajectory(self, reason: str, text: str, points: int | None) -> None:
        """Count a trajectory that gets no effort_trajectory and warn about it, throttled."""
        self.totals['trajectories_rejected'] += 1
        self.trajectory_rejected[reason] += 1
        self.period_problems += 1
        size = '' if points is None else f' of {points} points'
        self.warnings.warn('trajectory.' + reason, f'trajectory{size} rejected ({reason}), no '
                                                   f'effort_trajectory: {text}')

    def problem(self, key: str, amount: int = 1) -> None:
        """Count ``amount`` of ``key`` (clipping, lost setpoints): a problem of the period."""
        self.totals[key] += amount
        self.period_problems += 1

    def internal_error(self, where: str, exc: BaseException) -> None:
        """An exception in one of the node's callbacks: counted, logged with its type."""
        self.problem('internal_errors')
        try:
            self.warnings.warn('internal.' + where, f'{where} failed (the node goes on): '
                               f'{type(exc).__name__}: {exc}', error=True)
        except Exception:   # noqa: BLE001 (counted: a failing log must not raise again)
            pass

    def end_period(self) -> tuple[int, int]:
        """(problems, unstamped setpoints) of the period that ends with this report."""
        period = (self.period_problems, self.period_unstamped)
        self.period_problems = self.period_unstamped = 0
        return period


class Report:
    """cog_id_node's DiagnosticStatus: its counts, its setpoint stream, its threads.

    ``solver``: an InverseDynamics of its own for the closure health of the last served
    pose, solved once a report (outside the node's lock), so the per-setpoint path stays
    on the core's lean single-sample call.
    """

    def __init__(self, node: Any, solver: Any) -> None:
        self.node = node
        self.solver = solver

    def closure_health(self, pose: list[float] | None) -> tuple[float, float]:
        """(closure residual, closure Jacobian condition number) at ``pose``, a served pose;
        NaN without one, or when the solver refuses it."""
        if pose is None:
            return math.nan, math.nan
        try:
            result = self.solver.evaluate(pose, on_invalid='skip')
        except CogIdError:
            return math.nan, math.nan
        return float(result.closure_residual[0]), float(result.condition_number[0])

    def status(self, residual: float, condition: float) -> DiagnosticStatus:
        """The DiagnosticStatus of the node (``residual``, ``condition``: closure_health)."""
        node = self.node
        same_name_nodes = node.diagnostics.same_name_nodes
        status = DiagnosticStatus()
        status.name = f'{node.get_fully_qualified_name()}: inverse dynamics'
        status.hardware_id = node.mechanism.name
        feedback = self._feedback() if node.config.feedback else []
        status.level, status.message = self._level(same_name_nodes)
        if node.config.feedback and node.counts.last_measurement_was_rejected:
            status.level = DiagnosticStatus.ERROR
            status.message = ('last measured state rejected '
                              f'({node.counts.last_measurement_rejection})')
        publishers, most = node.counts.matched['measured_joint_states'], \
            node.config.max_measured_publishers
        if node.config.feedback and most and publishers > most:   # whatever was rejected last
            status.level = DiagnosticStatus.ERROR
            status.message = (f'{publishers} publishers feed measured_joint_states, more than '
                              f'max_measured_publishers ({most}): not commanded from')
        values = [('mechanism', node.mechanism.name),
                  ('active_joints', ', '.join(node.config.motors)),
                  ('backend', node.solver.backend),
                  *self._counted(),
                  ('nodes_with_this_name', same_name_nodes),
                  ('last_closure_residual', _finite(residual, '.3g')),
                  ('closure_condition_number', _finite(condition, '.4g')),
                  *self._times(), *feedback,
                  *(node.floating.diagnostics() if node.floating is not None else ())]
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values]
        return status

    def _feedback(self) -> list[tuple[str, Any]]:
        """The feedback modes' keys (FEEDBACK_DIAGNOSTIC_KEYS); the period's maximum
        tracking error restarts."""
        node = self.node
        counts = node.counts
        age = node.measurements.age()
        largest, counts.period_tracking_max = counts.period_tracking_max, 0.0
        errors = counts.tracking_error or [math.nan] * len(node.config.active_joints)
        return [('control_mode', node.config.control_mode),
                ('measurements_accepted', counts.totals['measurements_accepted']),
                ('measurements_rejected', sum(counts.measurement_rejected.values())),
                *((f'measurements_rejected.{reason}', count)
                  for reason, count in counts.measurement_rejected.items()),
                ('measured_state_publishers', counts.matched['measured_joint_states']),
                ('measurements_lost', node.measurements.lost.total),
                ('measurements_while_inactive', counts.totals['measurements_while_inactive']),
                ('measurement_age', '' if age is None else f'{age:.4f}'),
                *((f'tracking_error.{joint}', f'{e:.6g}')
                  for joint, e in zip(node.config.active_joints, errors)),
                ('tracking_error_max', f'{largest:.6g}'),
                ('last_measurement_rejection', counts.last_measurement_rejection)]

    def _level(self, same_name_nodes: int) -> tuple[bytes, str]:
        """The level and message: the worst of what the period saw."""
        counts, stream = self.node.counts, self.node.setpoints
        problems, unstamped = counts.end_period()
        stopped = self.node.stopped_threads()
        if stopped:
            return DiagnosticStatus.ERROR, (f"stopped serving ({'; '.join(stopped)}): a bug, "
                                            'please report it; restart the node')
        if counts.last_was_rejected:
            return DiagnosticStatus.ERROR, f'last setpoint rejected ({counts.last_rejection})'
        if problems:
            return DiagnosticStatus.WARN, (f'{problems} setpoint(s) or trajectories rejected, '
                                           'clipped or lost, or internal errors, in the last '
                                           'period')
        if same_name_nodes > 1:
            return DiagnosticStatus.WARN, (f'{same_name_nodes} nodes with this name: every '
                                           'setpoint gets a command from each')
        if unstamped:
            return DiagnosticStatus.WARN, (f'{unstamped} setpoint(s) stamped 0 in the last '
                                           'period: accelerations estimated from receipt times '
                                           '(noisy)')
        measured = self.node.measurements if self.node.config.feedback else None
        if measured is not None:        # a feedback mode: commands follow measured states
            mode = self.node.config.control_mode
            if measured.last_time is None:
                return DiagnosticStatus.OK, f'{mode}: ready, no measured state yet'
            if measured.stopped:
                return DiagnosticStatus.WARN, (f'{mode}: measured states stopped '
                                               f'({self.node.config.timeout_behavior})')
            return DiagnosticStatus.OK, f'{mode}: serving measured states'
        if stream.last_time is None:
            return DiagnosticStatus.OK, 'ready, no setpoint yet'
        if stream.stopped:
            return DiagnosticStatus.OK, (f'setpoint stream stopped '
                                         f'({self.node.config.timeout_behavior})')
        return DiagnosticStatus.OK, 'serving setpoints'

    def _counted(self) -> list[tuple[str, Any]]:
        counts = self.node.counts
        c = counts.totals
        return [('setpoint_publishers', counts.matched['joint_setpoint']),
                ('setpoints_accepted', c['accepted']),
                ('setpoints_rejected', sum(counts.rejected.values())),
                *((f'rejected.{reason}', count) for reason, count in counts.rejected.items()),
                ('setpoints_lost', c['setpoints_lost']),
                ('stamp_restarts', c['stamp_restarts']),
                ('setpoints_unstamped', c['setpoints_unstamped']),
                ('trajectories_accepted', c['trajectories_accepted']),
                ('trajectories_rejected', c['trajectories_rejected']),
                *((f'trajectories_rejected.{reason}', count)
                  for reason, count in counts.trajectory_rejected.items()),
                ('trajectory_in_progress', str(self.node.trajectory_worker.busy).lower()),
                ('effort_clipped', c['effort_clipped']),
                ('timeouts', c['timeouts']),
                ('setpoints_while_inactive', c['setpoints_while_inactive']),
                ('internal_errors', c['internal_errors'])]

    def _times(self) -> list[tuple[str, Any]]:
        # (statistics, not numpy: numpy's median imports numpy.ma on its first call, 18 ms
        # with the node's lock held, which stalled the control loop once a run)
        counts, last = self.node.counts, self.node.setpoints.last_time
        times, sends = list(counts.compute_times), list(counts.publish_times)
        since = '' if last is None else f'{time.monotonic() - last:.3f}'
        return [('compute_time_median_us', _us(statistics.median, times)),
                ('compute_time_max_us', _us(max, times)),
                ('compute_time_samples', len(times)),
                ('publish_time_median_us', _us(statistics.median, sends)),
                ('publish_time_max_us', _us(max, sends)),
                ('seconds_since_last_setpoint', since),
                ('last_rejection', counts.last_rejection)]


def _finite(value: float, spec: str) -> str:
    """``value`` formatted by ``spec``; '' where it is not finite (no pose served yet, or
    the solver refused it): never 'nan' in a message."""
    return format(value, spec) if math.isfinite(value) else ''


def _us(statistic: Callable[[list], float], seconds: list) -> str:
    """``statistic`` of ``seconds`` in microseconds, one decimal ('' when there are none)."""
    return f'{statistic(seconds) * 1e6:.1f}' if seconds else ''


class DiagnosticsPublisher:
    """A node's ``/diagnostics`` (keep-last DIAGNOSTICS_QOS_DEPTH), and the count of the
    nodes in the ROS graph with its name and namespace (each would answer every message
    the node answers too)."""

    def __init__(self, node: Any, event_callbacks: PublisherEventCallbacks) -> None:
        self.node = node
        self.same_name_nodes = 1
        self.publisher = node.create_publisher(
            DiagnosticArray, TOPICS['/diagnostics'].name, DIAGNOSTICS_QOS_DEPTH,
            event_callbacks=event_callbacks)

    def count_same_name_nodes(self) -> int:
        """Nodes with this node's name and namespace; a warning when there are others
        (when their number changes)."""
        node = self.node
        me = (node.get_name(), node.get_namespace())
        count = sum(1 for entry in node.get_node_names_and_namespaces() if tuple(entry) == me)
        count = max(count, 1)
        if count > 1 and count != self.same_name_nodes:
            node.get_logger().warning(
                f'{count} nodes named {node.get_fully_qualified_name()} in the ROS graph: every '
                'setpoint gets a command from each; give each node a namespace of its own '
                '(-r __ns:=/name) or stop the others')
        self.same_name_nodes = count
        return count

    def publish(self, status: DiagnosticStatus) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.status = [status]
        self.publisher.publish(msg)
