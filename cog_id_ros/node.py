"""cog_id_node: joint setpoints in, actuator effort commands out (the ROS face of the core).

Run::

    cog_id_node --ros-args --params-file config/paper_four_bar_a.yaml
    python -m cog_id_ros.node --ros-args -r __ns:=/arm --params-file config/paper_four_bar_b.yaml

Topics (relative names: namespaces and ``-r old:=new`` remaps apply)

* ``joint_setpoint`` (in, sensor_msgs/JointState): positions (required) and velocities
  (optional) by joint name; accelerations are estimated from the header stamps.
* ``joint_trajectory`` (in, trajectory_msgs/JointTrajectory): whole trajectories with
  positions, velocities and accelerations per point.
* ``effort_command`` (out, std_msgs/Float64MultiArray): efforts in ``active_joints`` order,
  one per accepted setpoint.
* ``joint_effort`` (out, sensor_msgs/JointState): the same with names, the setpoint's
  header, its positions and the velocities used.
* ``effort_trajectory`` (out, trajectory_msgs/JointTrajectory): the trajectory, active
  joints only, with ``effort`` filled on every point.
* ``/diagnostics`` (out, diagnostic_msgs/DiagnosticArray): counts, closure residual and
  condition number, compute time.

QoS: every topic but ``/diagnostics`` is reliable, keep-last, volatile, depth
``CONTROL_QOS_DEPTH`` (history, depth and reliability can be overridden per topic with
rclpy's QoS override parameters, e.g.
``-p qos_overrides./joint_setpoint.subscription.depth:=1``). See docs/node.md for why.

Parameters: the mechanism (``mechanism.*``, ``links.*``, ``joints.*``; see
shared/design/mechanism-params.md) and the node's own, ``NODE_PARAMETERS`` below. All are
read once at start-up and are read-only afterwards. A parameter that cannot be honoured
ends the process with exit status 2 and one line naming the parameter.

Threads: ``joint_setpoint`` is served by a thread of its own (:mod:`cog_id_ros.setpoint_loop`),
everything else by the executor in the main thread; shared state is under ``self.lock``.

The physics is in :mod:`cog_id_ros.core`, the acceleration estimator in
:mod:`cog_id_ros.setpoint_filter`, the message checks in :mod:`cog_id_ros.ros_conversions`.
"""
import collections
import gc
import math
import sys
import threading
import time

import numpy as np
import rclpy
import rclpy.exceptions
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

from . import stop_signals
from .core import CogIdError, InverseDynamics, Mechanism, MechanismConfigError
from .ros_conversions import (REASONS, EffortMessages, JointSelector, Rejected,
                              effort_trajectory, rejection, setpoint_arrays, stamp_to_ns,
                              trajectory_arrays)
from .setpoint_filter import SetpointFilter, StampError
from .setpoint_loop import SetpointLoop

NODE_NAME = 'cog_id_node'

#: keep-last depth of the control topics: 100 setpoints are 50-100 ms of a 2-1 kHz stream.
#: Deep enough that a Python pause (garbage collection, a busy core) or a burst from the
#: setpoint source loses nothing, and that a reliable writer still holds a sample when a
#: reader asks for it again; shallow enough that a node that cannot keep up drops stale
#: setpoints instead of queueing them for seconds. Keep-last, not keep-all: a slow reader
#: never blocks the publisher. Override per topic (depth 1: only the newest setpoint).
CONTROL_QOS_DEPTH = 100


def control_qos():
    """The QoS of the control topics (a new profile each call: QoS overrides modify it)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=CONTROL_QOS_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


#: parameter prefixes that describe the mechanism (handed to Mechanism.from_parameters)
MECHANISM_PREFIXES = ('mechanism.', 'links.', 'joints.')

TIMEOUT_BEHAVIORS = ('hold', 'zero', 'none')

#: the node's own parameters: name -> (default, description). ``None`` as the default of
#: effort_limits means "one .inf per active joint" (no limit).
NODE_PARAMETERS = {
    'effort_limits': (None, 'per active joint (or one for all), N or N m, > 0: efforts are '
                            'clipped to +-limit and clipping is counted in diagnostics; .inf: '
                            'no limit (default)'),
    'setpoint_timeout': (0.5, 's without a setpoint after which the stream counts as stopped '
                              '(timeout_behavior applies, the estimator restarts, the next '
                              'setpoint may have any stamp); 0: never (stamps must then '
                              'increase for the whole life of the node)'),
    'timeout_behavior': ('hold', 'what is published on effort_command when the stream stops: '
                                 "'hold' the gravity-holding efforts of the last valid pose, "
                                 "'zero' zeros, 'none' nothing (once per stop)"),
    'max_setpoint_interval': (0.1, 's: setpoints farther apart (by stamp) are not differentiated '
                                   'across the gap; the acceleration estimator restarts'),
    'estimator_window': (4, 'setpoints in the local polynomial of the acceleration estimator '
                            '(3..8; 3: least noise, 4: no lag to O(h^2))'),
    'diagnostics_period': (1.0, 's between /diagnostics messages'),
    'warning_period': (1.0, 's: each kind of rejected setpoint is logged at most once a period'),
}

#: compute times kept for the diagnostics median and max (the last N setpoints)
COMPUTE_TIME_WINDOW = 1000


class CogIdNode(Node):
    """Inverse dynamics of the mechanism in its parameters, served over topics."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, automatically_declare_parameters_from_overrides=True, **kwargs)
        self.mechanism = Mechanism.from_parameters(self._declare_mechanism_parameters())
        mech = self.mechanism
        self.active_joints = list(mech.active_joints)
        n_act = len(self.active_joints)
        cfg = self._declare_node_parameters(n_act)
        self.effort_limits = cfg['effort_limits']
        self.setpoint_timeout = cfg['setpoint_timeout']
        self.timeout_behavior = cfg['timeout_behavior']
        self.warning_period = cfg['warning_period']

        self.solver = InverseDynamics(mech)              # the setpoint stream (warm-started)
        self.trajectory_solver = InverseDynamics(mech)   # trajectories (reset for each one)
        self.report_solver = InverseDynamics(mech)       # residual and condition for diagnostics
        self.filter = SetpointFilter(n_act, cfg['estimator_window'], cfg['max_setpoint_interval'])
        self.selector = JointSelector(self.active_joints)
        self.trajectory_selector = JointSelector(self.active_joints)
        self.outputs = EffortMessages(self.active_joints)

        # bookkeeping for diagnostics and the timeout
        self.counts = collections.Counter({'accepted': 0, 'trajectories_accepted': 0,
                                           'trajectories_rejected': 0, 'effort_clipped': 0,
                                           'timeouts': 0})
        self.rejected = collections.Counter({reason: 0 for reason in REASONS})
        self.compute_times = collections.deque(maxlen=COMPUTE_TIME_WINDOW)
        self.last_rejection = ''
        self.last_was_rejected = False
        self.last_pose = None                 # active positions of the last served setpoint
        self.limited = bool(np.isfinite(self.effort_limits).any())
        self.last_setpoint_time = None        # monotonic receipt time of the last accepted one
        self.stream_stopped = True
        self._period_problems = 0             # rejections + clipping since the last report
        self._warned = {}                     # reason -> (monotonic time, suppressed count)
        # joint_setpoint is served by a thread of its own (setpoint_loop.py), everything
        # else by the executor: callbacks that touch the state above hold this lock
        self.lock = threading.Lock()

        qos_options = QoSOverridingOptions.with_default_policies
        # Publishers go without rclpy's default QoS-event handlers: each costs the executor
        # ~7 us per wake-up, and an incompatible subscriber logs the mismatch on its side.
        # The subscriptions keep theirs: a setpoint publisher we cannot hear is reported here.
        lean = PublisherEventCallbacks(use_default_callbacks=False)
        self.command_pub = self.create_publisher(
            Float64MultiArray, 'effort_command', control_qos(), event_callbacks=lean,
            qos_overriding_options=qos_options())
        self.effort_pub = self.create_publisher(
            JointState, 'joint_effort', control_qos(), event_callbacks=lean,
            qos_overriding_options=qos_options())
        self.trajectory_pub = self.create_publisher(
            JointTrajectory, 'effort_trajectory', control_qos(), event_callbacks=lean,
            qos_overriding_options=qos_options())
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10,
                                                     event_callbacks=lean)
        # The control-rate input: its own thread and wait set, outside the executor (see
        # setpoint_loop.py). start() once the node is built; stop() before destroying it.
        self.setpoint_loop = SetpointLoop(
            self, JointState, 'joint_setpoint', self.serve_setpoint, control_qos(),
            lock=self.lock, on_error=self._serve_failed, qos_overriding_options=qos_options())
        self.create_subscription(JointTrajectory, 'joint_trajectory', self.on_trajectory,
                                 control_qos(), qos_overriding_options=qos_options())
        self.create_timer(cfg['diagnostics_period'], self.publish_diagnostics)
        if self.setpoint_timeout > 0.0:
            self.create_timer(min(self.setpoint_timeout / 4.0, 0.25), self.check_timeout)

        limits = ', '.join(f'{j} {lim:g}' for j, lim in zip(self.active_joints, self.effort_limits))
        self.get_logger().info(
            f"mechanism '{mech.name}': {len(mech.links)} links, {len(mech.joints)} joints, "
            f"{mech.dof} DOF, active joints {', '.join(self.active_joints)}"
            f"{' (redundant)' if mech.is_redundant else ''}; effort limits: {limits}; "
            f'setpoint timeout {self.setpoint_timeout:g} s ({self.timeout_behavior})')

    # --- parameters --------------------------------------------------------------------------

    def _declare_mechanism_parameters(self):
        """Re-declare every mechanism parameter of the overrides read-only; return them."""
        values = {}
        for name, param in self._declared_overrides().items():
            if name.startswith(MECHANISM_PREFIXES):
                self.undeclare_parameter(name)
                self.declare_parameters('', [(name, param.value, ParameterDescriptor(
                    read_only=True, description='mechanism (read at start-up)'))],
                    ignore_override=True)
                values[name] = param.value
        return values

    def _declare_node_parameters(self, n_act):
        """Declare the node's parameters read-only, from the overrides or the defaults."""
        overrides = self._declared_overrides()
        known = set(NODE_PARAMETERS) | {'use_sim_time', 'start_type_description_service'}
        for name in sorted(overrides):
            if not name.startswith(MECHANISM_PREFIXES + ('qos_overrides.',)) and name not in known:
                self.get_logger().warning(f"ignoring unknown parameter '{name}'")
        cfg = {}
        for name, (default, description) in NODE_PARAMETERS.items():
            value = overrides[name].value if name in overrides else default
            value = _check_node_parameter(name, value, n_act)
            if name in overrides:
                self.undeclare_parameter(name)
            declared = value.tolist() if isinstance(value, np.ndarray) else value
            self.declare_parameters('', [(name, declared, ParameterDescriptor(
                read_only=True, description=description))], ignore_override=True)
            cfg[name] = value
        for name in overrides:
            if name.startswith('qos_overrides.'):
                # declared again, read-only, when the publisher or subscription is created
                self.undeclare_parameter(name)
        return cfg

    def _declared_overrides(self):
        """Parameters declared from the overrides (params files, -p) that are still writable."""
        names = self.list_parameters([], 0).names
        return {name: self.get_parameter(name) for name in names
                if not self.describe_parameter(name).read_only}

    # --- setpoints ---------------------------------------------------------------------------

    def serve_setpoint(self, msg):
        """One JointState setpoint -> effort_command + joint_effort, or a counted rejection.

        Called by the setpoint loop's thread with ``self.lock`` held, once per message, in
        the order received; every message that queued up while it worked is served next.
        """
        start = time.perf_counter()
        try:
            q, v = setpoint_arrays(msg, self.selector)
            stamp = stamp_to_ns(msg.header.stamp) or self.get_clock().now().nanoseconds
            v_used, a = self.filter.estimate(stamp, q, v)
            efforts = self.solver.sample_torques(q, v_used, a)   # the core's control-rate call
            if not all(map(math.isfinite, efforts)):
                raise Rejected('singular', 'the torques are not finite at this setpoint')
        except Rejected as exc:
            self.reject(exc.reason, str(exc))
            return
        except StampError as exc:
            self.reject('stamp', str(exc))
            return
        except CogIdError as exc:
            bad = rejection(exc, self.mechanism.is_redundant)
            self.reject(bad.reason, str(bad))
            return
        if self.limited:
            tau = np.array(efforts)
            if self.clip(tau):
                efforts = tau.tolist()
        self.command_pub.publish(self.outputs.command_for(efforts))   # first: what control waits for
        self.effort_pub.publish(self.outputs.state_for(msg.header, q, v_used, efforts))
        self.filter.accept(stamp, q, v)
        self.counts['accepted'] += 1
        self.last_pose = q
        self.last_was_rejected = False
        self.last_setpoint_time = time.monotonic()
        self.stream_stopped = False
        self.compute_times.append(time.perf_counter() - start)

    def _serve_failed(self, exc):
        """A setpoint that failed in a way serve_setpoint does not expect (a bug): no
        command, counted as 'solver', logged with its type; the next one is served."""
        self.reject('solver', f'unexpected {type(exc).__name__}: {exc}')

    def clip(self, tau):
        """Clip efforts (in place, any shape) to +-effort_limits; count it; True if clipped."""
        limits = self.effort_limits
        if (np.abs(tau) <= limits).all():
            return False
        np.clip(tau, -limits, limits, out=tau)
        self.counts['effort_clipped'] += 1
        self._period_problems += 1
        return True

    def reject(self, reason, text):
        """Count a rejected setpoint (no command) and warn about it, throttled."""
        self.rejected[reason] += 1
        self.last_rejection = f'{reason}: {text}'
        self.last_was_rejected = True
        self._period_problems += 1
        self.warn_throttled(reason, f'setpoint rejected, no command: {text}')

    def warn_throttled(self, key, text):
        """Log a warning at most once a warning_period per key; count the ones left out."""
        now = time.monotonic()
        last, suppressed = self._warned.get(key, (-math.inf, 0))
        if now - last < self.warning_period:
            self._warned[key] = (last, suppressed + 1)
            return
        more = f' ({suppressed} more like it since the last warning)' if suppressed else ''
        self.get_logger().warning(text + more)
        self._warned[key] = (now, 0)

    # --- trajectories ------------------------------------------------------------------------

    def on_trajectory(self, msg):
        """A whole JointTrajectory -> effort_trajectory, in one vectorised core call.

        Solved without the lock (its own selector and solver), so the setpoint thread goes
        on while a long trajectory is solved (the two threads share the GIL: a setpoint may
        wait up to Python's switch interval, 5 ms); only the bookkeeping takes the lock.
        """
        try:
            _, q, qd, qdd = trajectory_arrays(msg, self.trajectory_selector)
            self.trajectory_solver.reset()
            result = self.trajectory_solver.evaluate(q, qd, qdd, on_invalid='skip')
            if not result.valid.all():
                k = int(np.flatnonzero(~result.valid)[0])
                bad = rejection(result.errors[k], self.mechanism.is_redundant)
                raise Rejected(bad.reason, f'point {k}: {bad}')
        except Rejected as exc:
            with self.lock:
                self.counts['trajectories_rejected'] += 1
                self._period_problems += 1
                self.warn_throttled('trajectory.' + exc.reason,
                                    f'trajectory of {len(msg.points)} points rejected '
                                    f'({exc.reason}), no effort_trajectory: {exc}')
            return
        tau = result.torques
        with self.lock:
            self.clip(tau)
            self.counts['trajectories_accepted'] += 1
        self.trajectory_pub.publish(effort_trajectory(msg, self.active_joints, q, qd, qdd, tau))

    # --- timeout -----------------------------------------------------------------------------

    def check_timeout(self):
        """When setpoints stop: restart the estimator and apply timeout_behavior, once."""
        with self.lock:
            self._check_timeout()

    def _check_timeout(self):
        if self.stream_stopped or self.last_setpoint_time is None:
            return
        if time.monotonic() - self.last_setpoint_time < self.setpoint_timeout:
            return
        self.stream_stopped = True
        self.counts['timeouts'] += 1
        self.filter.reset()
        n_act = len(self.active_joints)
        if self.timeout_behavior == 'none':
            what = 'nothing published'
        elif self.timeout_behavior == 'zero':
            self.command_pub.publish(Float64MultiArray(data=[0.0] * n_act))
            what = 'zero efforts published'
        else:
            try:
                tau = self.solver.torques(self.last_pose, [0.0] * n_act, [0.0] * n_act)
            except CogIdError as exc:   # cannot happen for a pose just served; be safe
                self.get_logger().error(f'cannot compute holding efforts: {exc}')
                return
            self.clip(tau)
            self.command_pub.publish(Float64MultiArray(data=tau.tolist()))
            what = 'gravity-holding efforts of the last pose published'
        self.get_logger().info(
            f'no setpoint for {self.setpoint_timeout:g} s: stream stopped, {what}')

    # --- diagnostics -------------------------------------------------------------------------

    def publish_diagnostics(self):
        health = self.closure_health(self.last_pose)   # solved outside the lock
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        with self.lock:
            msg.status = [self.diagnostic_status(*health)]
        self.diagnostics_pub.publish(msg)

    def diagnostic_status(self, residual, condition):
        """The DiagnosticStatus of the node (``residual``, ``condition``: closure_health)."""
        status = DiagnosticStatus()
        status.name = f'{self.get_fully_qualified_name()}: inverse dynamics'
        status.hardware_id = self.mechanism.name
        n_rejected = sum(self.rejected.values())
        if self.last_was_rejected:
            status.level = DiagnosticStatus.ERROR
            status.message = f'last setpoint rejected ({self.last_rejection})'
        elif self._period_problems:
            status.level = DiagnosticStatus.WARN
            status.message = (f'{self._period_problems} setpoint(s) rejected or clipped in the '
                              f'last period')
        else:
            status.level = DiagnosticStatus.OK
            if self.last_setpoint_time is None:
                status.message = 'ready, no setpoint yet'
            elif self.stream_stopped:
                status.message = f'setpoint stream stopped ({self.timeout_behavior})'
            else:
                status.message = 'serving setpoints'
        self._period_problems = 0
        times = np.array(self.compute_times) * 1e6
        since = '' if self.last_setpoint_time is None else \
            f'{time.monotonic() - self.last_setpoint_time:.3f}'
        values = [
            ('mechanism', self.mechanism.name),
            ('active_joints', ', '.join(self.active_joints)),
            ('setpoints_accepted', self.counts['accepted']),
            ('setpoints_rejected', n_rejected),
            *((f'rejected.{reason}', count) for reason, count in self.rejected.items()),
            ('trajectories_accepted', self.counts['trajectories_accepted']),
            ('trajectories_rejected', self.counts['trajectories_rejected']),
            ('effort_clipped', self.counts['effort_clipped']),
            ('timeouts', self.counts['timeouts']),
            ('last_closure_residual', f'{residual:.3g}'),
            ('closure_condition_number', f'{condition:.4g}'),
            ('compute_time_median_us', f'{np.median(times):.1f}' if times.size else ''),
            ('compute_time_max_us', f'{times.max():.1f}' if times.size else ''),
            ('compute_time_samples', times.size),
            ('seconds_since_last_setpoint', since),
            ('last_rejection', self.last_rejection),
        ]
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values]
        return status

    def closure_health(self, pose):
        """(closure residual, closure Jacobian condition number) at ``pose``, a served pose.

        Solved again here, once a report, so the per-setpoint path stays on the core's lean
        single-sample call; the pose is the last one served, so the numbers are its own.
        """
        if pose is None:
            return math.nan, math.nan
        result = self.report_solver.evaluate(pose, on_invalid='skip')
        return float(result.closure_residual[0]), float(result.condition_number[0])


def _check_node_parameter(name, value, n_act):
    """The node parameter ``name`` as the type the node uses; MechanismConfigError if wrong."""
    def fail(message):
        raise MechanismConfigError(name, message)

    def number(v):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            fail(f'must be a number, got {v!r}')
        return float(v)

    if name == 'effort_limits':
        if value is None or (isinstance(value, (list, tuple)) and len(value) == 0):
            return np.full(n_act, math.inf)
        if not isinstance(value, (list, tuple)) and not hasattr(value, '__len__'):
            value = [value]
        limits = [number(v) for v in value]
        if len(limits) == 1:
            limits = limits * n_act
        if len(limits) != n_act:
            fail(f'needs one limit per active joint ({n_act}) or one for all, got {len(limits)}')
        if not all(lim > 0 for lim in limits):
            fail(f'every limit must be > 0 (.inf for none), got {limits}')
        return np.array(limits)
    if name == 'timeout_behavior':
        if value not in TIMEOUT_BEHAVIORS:
            fail(f"must be one of {', '.join(TIMEOUT_BEHAVIORS)}, got {value!r}")
        return value
    if name == 'estimator_window':
        if isinstance(value, bool) or not isinstance(value, int) or not 3 <= value <= 8:
            fail(f'must be an integer from 3 to 8, got {value!r}')
        return value
    value = number(value)
    if name == 'setpoint_timeout':
        if not value >= 0.0:
            fail(f'must be >= 0 (0: no timeout), got {value!r}')
    elif not value > 0.0 or not math.isfinite(value):
        fail(f'must be a positive number of seconds, got {value!r}')
    return value


def main(args=None):
    """Start the node and spin until Ctrl-C or SIGTERM (exit status 0).

    A parameter that cannot be honoured: exit status 2 and one line naming it. A stop
    signal that arrives while the node is being built is noted and acted on once it is
    built (see :mod:`cog_id_ros.stop_signals`), so it stops the node cleanly too.
    """
    stop = stop_signals.DeferredStop()
    try:
        rclpy.init(args=args, signal_handler_options=stop.RCLPY_OPTIONS)
    except Exception as exc:   # noqa: BLE001 (e.g. a params file rcl cannot parse)
        print(f'{NODE_NAME}: cannot start: {_one_line(exc)}', file=sys.stderr)
        return 2
    node = None
    try:
        node = CogIdNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # Start-up left tens of thousands of long-lived objects (rclpy, numpy, the traced
        # program). Frozen, a full collection during the stream no longer walks them: its
        # pause (~10 ms on the reference VM) becomes microseconds.
        gc.collect()
        gc.freeze()
        node.setpoint_loop.start()
        if stop.hand_over() is None:   # no stop asked for during start-up
            executor.spin()
    except (MechanismConfigError, rclpy.exceptions.InvalidParameterTypeException,
            rclpy.exceptions.InvalidParameterValueException) as exc:
        print(f'{NODE_NAME}: cannot start: {_one_line(exc)}', file=sys.stderr)
        return 2
    except ExternalShutdownException:
        pass   # Ctrl-C or SIGTERM: rclpy's signal handler has shut the context down
    except Exception:   # noqa: BLE001
        if rclpy.ok():
            raise
        # the signal shut the context down between two turns of spin(), whose next wait set
        # then fails on the dead context (an RCLError): a clean stop too
    finally:
        if node is not None:
            node.setpoint_loop.stop()
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _one_line(exc):
    return ' '.join(str(exc).split())


if __name__ == '__main__':
    sys.exit(main())
