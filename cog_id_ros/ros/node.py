"""cog_id_node: joint setpoints in, actuator effort commands out (the ROS face of the core).

Run::

    cog_id_node --ros-args --params-file config/paper_four_bar_a.yaml
    python -m cog_id_ros.node --ros-args -r __ns:=/arm --params-file config/paper_four_bar_b.yaml

Topics (relative names: namespaces and ``-r old:=new`` remaps apply; the table with their
QoS is :mod:`cog_id_ros.ros.topics`)

* ``joint_setpoint`` (in, sensor_msgs/JointState): positions (required) and velocities
  (optional) by joint name; accelerations are estimated from the header stamps.
* ``joint_trajectory`` (in, trajectory_msgs/JointTrajectory): whole trajectories with
  positions, velocities and accelerations per point.
* ``effort_command`` (out, std_msgs/Float64MultiArray): efforts in ``active_joints`` order,
  one per accepted setpoint.
* ``joint_effort`` (out, sensor_msgs/JointState): the same with names, the setpoint's
  header, its positions and the velocities used.
* ``joint_states`` (out, sensor_msgs/JointState): every ``joint_states_decimation``-th
  served setpoint, every joint of the mechanism at the closed pose the efforts were
  computed at (positions and velocities), for robot_state_publisher and RViz.
* ``effort_trajectory`` (out, trajectory_msgs/JointTrajectory): the trajectory, active
  joints only, with ``effort`` filled on every point.
* ``/diagnostics`` (out, diagnostic_msgs/DiagnosticArray): counts, closure residual and
  condition number, compute time.

QoS: every topic but ``/diagnostics`` is reliable, keep-last, volatile, depth
``topics.CONTROL_QOS_DEPTH`` (history, depth and reliability can be overridden per topic with
rclpy's QoS override parameters, e.g.
``-p qos_overrides./joint_setpoint.subscription.depth:=1``). See docs/node.md for why.

Parameters: the mechanism (``mechanism.*``, ``links.*``, ``joints.*``; see the README's
mechanism parameter file section; or in the URDF form, ``robot_description`` or
``mechanism.urdf_file`` with ``loop_closures.*``, docs/urdf.md: a relative urdf_file is
relative to the params file that gives it) and the node's own, written once with their types,
defaults, bounds and meaning in :mod:`cog_id_ros.ros.parameters` (``NODE_PARAMETERS``).
All are read once at start-up and are read-only afterwards,
``use_sim_time`` included. A parameter that cannot be honoured (or a params file rcl cannot
parse) ends the process with exit status 2 and one line naming the parameter.
``cog_id_node --help`` prints the usage. Diagnostics keys: ``DIAGNOSTIC_KEYS``.

Threads: ``joint_setpoint`` is served by a thread of its own (:mod:`.setpoint_loop`),
trajectories by a thread and a process of their own (:class:`TrajectoryWorker`), everything
else by the executor in the main thread; shared state is under ``self.lock``. No exception
in a callback ends the node: it is counted (``internal_errors``) and logged with its type.

The physics is in :mod:`cog_id_ros.core`, the acceleration estimator in
:mod:`cog_id_ros.ros.setpoint_filter`, the message checks in :mod:`cog_id_ros.ros.conversions`.
"""
import collections
import contextlib
import functools
import gc
import math
import multiprocessing
import os
import re
import signal
import sys
import tempfile
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
import rclpy
from rclpy.event_handler import PublisherEventCallbacks
import rclpy.exceptions
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory
import yaml

from ..core import CogIdError, InverseDynamics, MechanismConfigError
from ..description import Mechanism, params_file
from . import stop_signals
from .conversions import (
    NANOSECONDS,
    REASONS,
    TRAJECTORY_REASONS,
    EffortMessages,
    JointSelector,
    Rejected,
    nearest_turn,
    rejection,
    setpoint_arrays,
    stamp_to_ns,
    trajectory_point_count,
    trajectory_process,
)
from .parameters import (
    MAX_QOS_DEPTH,
    NODE_PARAMETERS,
    QOS_OVERRIDE_VALUES,
    is_mechanism_parameter,
)
from .setpoint_filter import SetpointFilter, StampError
from .setpoint_loop import SetpointLoop
from .topics import DIAGNOSTICS_QOS_DEPTH, TOPICS, control_qos

NODE_NAME = 'cog_id_node'

USAGE = f"""usage: {NODE_NAME} [-h] --ros-args --params-file FILE [-p NAME:=VALUE ...] [-r OLD:=NEW ...]

Closed-link inverse dynamics as a ROS 2 node: JointState setpoints in on joint_setpoint,
actuator efforts out on effort_command and joint_effort (one per accepted setpoint);
the closed pose of every joint on joint_states (every joint_states_decimation-th one);
whole trajectories in on joint_trajectory, out on effort_trajectory; counts and health
on /diagnostics.

The mechanism (mechanism.*, links.*, joints.*; or a URDF: robot_description or
mechanism.urdf_file, with loop_closures.*) and the node's own parameters come from a
ROS 2 parameter file, e.g.

    {NODE_NAME} --ros-args --params-file config/paper_four_bar_a.yaml
    {NODE_NAME} --ros-args --params-file config/paper_four_bar_b.yaml -r __ns:=/arm
    {NODE_NAME} --ros-args --params-file config/crank_rocker_urdf.yaml

A parameter that cannot be honoured ends the node with exit status 2 and one line naming
it. Ctrl-C or SIGTERM stop it (exit status 0).

Documentation: docs/node.md (topics, parameters, diagnostics) and README.md (the
mechanism parameter file) of the cog_id_ros package.
"""  # noqa: E501 (the usage line as printed)

#: keys of /diagnostics besides rejected.<reason> and trajectories_rejected.<reason>
DIAGNOSTIC_KEYS = {
    'mechanism': 'the mechanism name',
    'active_joints': 'the active joints, in effort order',
    'backend': "who computes the kernels: native, python or reference (parameter 'backend')",
    'setpoints_accepted': 'setpoints served since start',
    'setpoints_rejected': 'setpoints rejected since start (sum of rejected.<kind>)',
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
    'internal_errors': 'exceptions the node caught in its own callbacks (a bug: please report)',
    'nodes_with_this_name': "nodes in the ROS graph with this node's name and namespace "
                            '(more than 1: every setpoint gets several commands)',
    'last_closure_residual': 'max closure equation residual at the last served pose, m or rad',
    'closure_condition_number': 'condition number of the closure Jacobian there',
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

#: compute times kept for the diagnostics median and max (the last N setpoints)
COMPUTE_TIME_WINDOW = 1000

#: Python's thread switch interval in the node: the longest a thread holding the GIL keeps
#: the setpoint thread waiting (Python's default is 5 ms)
SWITCH_INTERVAL = 0.001


def _guarded(method):
    """A callback of the node that never ends it: an exception is counted and logged."""
    @functools.wraps(method)
    def guarded(self, *args):
        try:
            return method(self, *args)
        except Exception as exc:   # noqa: BLE001 (no callback may end the node)
            if self.context.ok():
                self.internal_error(method.__name__, exc)
            return None
    return guarded


class CogIdNode(Node):
    """Inverse dynamics of the mechanism in its parameters, served over topics."""

    def __init__(self, command_line=None, interruptible=contextlib.nullcontext, **kwargs):
        """``command_line``: the process's arguments (main() passes them), for the directory
        a relative ``mechanism.urdf_file`` is relative to (:func:`urdf_base_dir`).
        ``interruptible``: a context manager around the parts of start-up that may take long
        and build no rclpy object (loading the mechanism, compiling its kernels), in which
        main() lets a stop signal raise (stop_signals.DeferredStop.interruptible)."""
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._build(command_line, interruptible)
        except BaseException:
            self.destroy_node()     # no half-built node left to rclpy's clean-up
            raise

    def _build(self, command_line, interruptible):
        overrides = self._override_values()
        base_dir = urdf_base_dir(command_line, self.get_name()) \
            if 'mechanism.urdf_file' in overrides else None
        with interruptible():
            self.mechanism = Mechanism.from_parameters(
                self._declare_mechanism_parameters(overrides), base_dir=base_dir)
        mech = self.mechanism
        self.active_joints = list(mech.active_joints)
        n_act = len(self.active_joints)
        self.active_types = [mech.joint_types[mech.joints.index(j)] for j in self.active_joints]
        # the mechanism's effort limits (joints.<j>.effort, URDF <limit effort>) are the
        # default of effort_limits; the node's parameter, when given, wins
        mechanism_limits = getattr(mech, 'effort_limits', None)
        cfg = self._declare_node_parameters(
            overrides, self.active_types,
            {'effort_limits': list(mechanism_limits) if mechanism_limits else None})
        self._check_qos_overrides(overrides)
        self._make_use_sim_time_read_only()
        # The node's time in integer ns, read per setpoint (stamp checks): without
        # use_sim_time (read-only, so fixed from here on) the node's clock is the system
        # clock, which time.time_ns reads too (CLOCK_REALTIME, like rcl's system time) in
        # 0.1 us instead of the 4.7 us of get_clock().now() (measured on the reference VM)
        self._now_ns = self._ros_now_ns if self.get_parameter('use_sim_time').value \
            else time.time_ns
        self.effort_limits = cfg['effort_limits']
        self.setpoint_timeout = cfg['setpoint_timeout']
        self.timeout_behavior = cfg['timeout_behavior']
        self.warning_period = cfg['warning_period']
        self.unwrap = [cfg['unwrap_angles'] and kind.wraps for kind in mech.active_kinds]
        self.max_step = cfg['max_setpoint_step']
        self.max_stamp_lead_ns = cfg['max_stamp_lead'] * NANOSECONDS \
            if math.isfinite(cfg['max_stamp_lead']) else math.inf
        self.max_stamp_rejections = cfg['max_stamp_rejections']
        self.max_trajectory_points = cfg['max_trajectory_points']
        self.max_age_ns = cfg['max_setpoint_age'] * NANOSECONDS

        self.backend = cfg['backend']
        with interruptible():
            self.solver = InverseDynamics(mech, backend=self.backend)   # the setpoint stream
            self.report_solver = InverseDynamics(mech, backend=self.backend)   # diagnostics
        self.filter = SetpointFilter(n_act, cfg['estimator_window'], cfg['max_setpoint_interval'])
        self.selector = JointSelector(self.active_joints)
        self.outputs = EffortMessages(self.active_joints, mech.joints)
        self.joint_states_decimation = cfg['joint_states_decimation']
        self._joint_states_countdown = 1      # served setpoints until the next joint_states

        # bookkeeping for diagnostics and the timeout
        self.counts = collections.Counter({'accepted': 0, 'trajectories_accepted': 0,
                                           'trajectories_rejected': 0, 'effort_clipped': 0,
                                           'timeouts': 0, 'internal_errors': 0,
                                           'setpoints_lost': 0, 'stamp_restarts': 0,
                                           'setpoints_unstamped': 0})
        self.rejected = collections.Counter(dict.fromkeys(REASONS, 0))
        self.trajectory_rejected = collections.Counter(
            dict.fromkeys((*REASONS, *TRAJECTORY_REASONS), 0))
        self.compute_times = collections.deque(maxlen=COMPUTE_TIME_WINDOW)
        self.publish_times = collections.deque(maxlen=COMPUTE_TIME_WINDOW)
        self.last_rejection = ''
        self.last_was_rejected = False
        self.last_pose = None                 # active positions of the last served setpoint
        self.limited = bool(np.isfinite(self.effort_limits).any())
        self.checks_steps = bool(np.isfinite(self.max_step).any())
        self.last_setpoint_time = None        # monotonic receipt time of the last accepted one
        self.stream_stopped = True
        self._stamp_rejections = 0            # consecutive setpoints rejected for their stamp
        self._last_sequence = None            # publication sequence number of the last setpoint
        self.same_name_nodes = 1              # nodes in the graph with this full name
        self._period_problems = 0             # rejections + clipping since the last report
        self._period_unstamped = 0            # setpoints stamped 0 since the last report
        self._warned = {}                     # reason -> (monotonic time, suppressed count)
        # joint_setpoint is served by a thread of its own (setpoint_loop.py), trajectories by
        # a thread and a process of their own (TrajectoryWorker), everything else by the
        # executor: callbacks that touch the state above hold this lock
        self.lock = threading.Lock()

        qos_options = QoSOverridingOptions.with_default_policies
        # Publishers go without rclpy's default QoS-event handlers: each costs the executor
        # ~7 us per wake-up, and an incompatible subscriber logs the mismatch on its side.
        # The subscriptions keep theirs: a setpoint publisher we cannot hear is reported here.
        lean = PublisherEventCallbacks(use_default_callbacks=False)
        try:
            self.command_pub = self.create_publisher(
                Float64MultiArray, TOPICS['effort_command'].name, control_qos(),
                event_callbacks=lean, qos_overriding_options=qos_options())
            self.effort_pub = self.create_publisher(
                JointState, TOPICS['joint_effort'].name, control_qos(),
                event_callbacks=lean, qos_overriding_options=qos_options())
            self.joint_states_pub = None if not self.joint_states_decimation else \
                self.create_publisher(
                    JointState, TOPICS['joint_states'].name, control_qos(),
                    event_callbacks=lean, qos_overriding_options=qos_options())
            self.trajectory_pub = self.create_publisher(
                JointTrajectory, TOPICS['effort_trajectory'].name, control_qos(),
                event_callbacks=lean, qos_overriding_options=qos_options())
            self.diagnostics_pub = self.create_publisher(
                DiagnosticArray, TOPICS['/diagnostics'].name, DIAGNOSTICS_QOS_DEPTH,
                                                         event_callbacks=lean)
            # The control-rate input: its own thread and wait set, outside the executor (see
            # setpoint_loop.py). start() once the node is built; stop() before destroying it.
            self.setpoint_loop = SetpointLoop(
                self, JointState, TOPICS['joint_setpoint'].name, self.serve_setpoint,
                control_qos(), lock=self.lock, on_error=self._serve_failed, with_info=True,
                qos_overriding_options=qos_options())
            # taken serialized: the executor never deserialises a long trajectory (a C call
            # that holds the GIL for seconds); the trajectory process does
            self.create_subscription(JointTrajectory, TOPICS['joint_trajectory'].name,
                                     self.on_trajectory,
                                     control_qos(), qos_overriding_options=qos_options(),
                                     raw=True)
        except (rclpy.exceptions.ParameterException, RuntimeError, TypeError, ValueError) as exc:
            raise MechanismConfigError(
                'qos_overrides', f'cannot be honoured: {_one_line(exc)}') from None
        for name in sorted(overrides):
            if name.startswith('qos_overrides.') and not self.has_parameter(name):
                self.get_logger().warning(
                    f"ignoring unknown parameter '{name}' (no topic of the node by that "
                    'fully qualified name)')
        self.trajectory_worker = TrajectoryWorker(
            {'mechanism': dict(mech.parameters), 'active_joints': self.active_joints,
             'unwrap': self.unwrap, 'max_step': self.max_step.tolist(),
             'effort_limits': self.effort_limits.tolist() if self.limited else None,
             'max_points': self.max_trajectory_points, 'backend': self.backend},
            self._trajectory_done, timeout=cfg['trajectory_timeout'])
        self.create_timer(cfg['diagnostics_period'], self.publish_diagnostics)
        if self.setpoint_timeout > 0.0:
            self.create_timer(min(self.setpoint_timeout / 4.0, 0.25), self.check_timeout)

        limits = ', '.join(f'{j} {lim:g}'
                           for j, lim in zip(self.active_joints, self.effort_limits))
        self.get_logger().info(
            f"mechanism '{mech.name}': {len(mech.links)} links, {len(mech.joints)} joints, "
            f"{mech.dof} DOF, active joints {', '.join(self.active_joints)}"
            f"{' (redundant)' if mech.is_redundant else ''}; effort limits: {limits}; "
            f'setpoint timeout {self.setpoint_timeout:g} s ({self.timeout_behavior})'
            + (f'; {len(mech.spherical_chains)} chains of three revolute joints through '
               f'massless links solved as spherical joints' if mech.spherical_chains else ''))
        for warning in getattr(mech, 'assembly_warnings', None) or ():
            self.get_logger().warning(f'mechanism: {warning}')
        # last: declaring a parameter (rclpy declares the QoS overrides) runs these callbacks
        self.add_on_set_parameters_callback(self._refuse_parameter_changes)
        self._built = True

    def start(self):
        """Start the setpoint thread and the trajectory worker (once the node is built)."""
        self.setpoint_loop.start()
        self.trajectory_worker.start()
        self._threads_started = True

    def stopped_threads(self):
        """'<thread>: <why>' of every thread of the node that ended although the node did
        not stop it (a bug: none may end silently; /diagnostics says ERROR, and the process
        exits with status 1)."""
        if not getattr(self, '_threads_started', False):
            return []
        out = []
        for name, thread in (('setpoint thread', self.setpoint_loop),
                             ('trajectory worker', self.trajectory_worker)):
            if not thread.running:
                failure = thread.failure
                out.append(f'{name}: ' + (f'{type(failure).__name__}: {failure}'
                                          if failure is not None else 'ended'))
        return out

    def stop(self):
        """Stop both (before the node is destroyed); returns stopped_threads() as it was
        before (what ended by itself)."""
        stopped = self.stopped_threads()
        self._threads_started = False
        self.setpoint_loop.stop()
        self.trajectory_worker.stop()
        return stopped

    # --- parameters --------------------------------------------------------------------------

    def _override_values(self):
        """name -> value of every parameter given to the node (params files, -p).

        Read from rclpy's overrides instead of declared from them automatically: rclpy
        cannot declare a typed parameter from an empty YAML list (it has no type), which
        must become a message naming the parameter, not a traceback. An empty list is [].
        """
        return {name: ([] if param.type_ == Parameter.Type.NOT_SET else param.value)
                for name, param in self._parameter_overrides.items()}

    def _declare(self, name, value, description):
        """Declare ``name`` read-only with ``value`` (an empty list: no type, dynamic)."""
        if isinstance(value, (list, tuple)) and len(value) == 0:
            self.declare_parameter(name, None, ParameterDescriptor(
                read_only=True, dynamic_typing=True, description=description),
                ignore_override=True)
            return
        self.declare_parameter(name, value, ParameterDescriptor(
            read_only=True, description=description), ignore_override=True)

    def _declare_mechanism_parameters(self, overrides):
        """Declare every mechanism parameter of the overrides read-only, native or URDF form
        (``is_mechanism_parameter``); return them."""
        values = {name: value for name, value in overrides.items()
                  if is_mechanism_parameter(name)}
        for name, value in values.items():
            self._declare(name, value, 'mechanism (read at start-up)')
        return values

    def _declare_node_parameters(self, overrides, active_types, defaults=None):
        """Declare the node's parameters read-only, from the overrides or the defaults
        (``defaults``: name -> value instead of the table's default, None: the table's; an
        empty list given for it counts as not given)."""
        known = set(NODE_PARAMETERS) | {'use_sim_time', 'start_type_description_service'}
        for name in sorted(overrides):
            if not (is_mechanism_parameter(name) or name.startswith('qos_overrides.')) \
                    and name not in known:
                self.get_logger().warning(f"ignoring unknown parameter '{name}'")
        cfg = {}
        defaults = defaults or {}
        for name, param in NODE_PARAMETERS.items():
            value = overrides.get(name, param.default)
            if defaults.get(name) is not None and (value is None or value == []):
                value = defaults[name]
            value = param.check(value, active_types)
            declared = value.tolist() if isinstance(value, np.ndarray) else value
            self._declare(name, declared, param.ros_description)
            cfg[name] = value
        return cfg

    def _check_qos_overrides(self, overrides):
        """Every qos_overrides.* parameter names a policy the node honours, with a valid value.

        rclpy would fail on them with a traceback while it creates the topics (a bogus
        reliability, a negative or huge depth); here each becomes MechanismConfigError.
        """
        for name, value in overrides.items():
            if not name.startswith('qos_overrides.'):
                continue
            policy = name.rsplit('.', 1)[-1]
            if policy in QOS_OVERRIDE_VALUES:
                if value not in QOS_OVERRIDE_VALUES[policy]:
                    raise MechanismConfigError(
                        name, f"must be one of {', '.join(QOS_OVERRIDE_VALUES[policy])}, "
                              f'got {value!r}')
            elif policy == 'depth':
                if isinstance(value, bool) or not isinstance(value, int) \
                        or not 1 <= value <= MAX_QOS_DEPTH:
                    raise MechanismConfigError(
                        name, f'must be an integer from 1 to {MAX_QOS_DEPTH}, got {value!r}')
            else:
                raise MechanismConfigError(
                    name, 'the node honours only history, depth and reliability overrides '
                          '(qos_overrides./<topic>.<publisher|subscription>.<policy>)')

    def _make_use_sim_time_read_only(self):
        """use_sim_time is read at start-up like every other parameter, then read-only.

        Switched on at runtime without a /clock publisher it would freeze the node's clock:
        no more /diagnostics, no hold command. rclpy declares it writable; the node
        declares it again read-only, and once built refuses every parameter change with a
        reason (``_refuse_parameter_changes``).
        """
        value = self.get_parameter('use_sim_time').value
        self.undeclare_parameter('use_sim_time')
        self.declare_parameter('use_sim_time', bool(value), ParameterDescriptor(
            read_only=True, description='ROS time from /clock (read at start-up only)'),
            ignore_override=True)

    @_guarded
    def _refuse_parameter_changes(self, parameters):
        names = ', '.join(p.name for p in parameters)
        return SetParametersResult(
            successful=False,
            reason=f'{names}: {NODE_NAME} reads its parameters once at start-up; they are '
                   'read-only (restart the node with the new value)')

    # rclpy checks a descriptor's read_only before any callback and refuses with its own
    # words ("Trying to set a read-only parameter"); a change of a declared parameter at
    # runtime gets the node's reason instead (the descriptors still say read-only)
    def set_parameters(self, parameter_list):
        if self._refuses(parameter_list):
            return [self._refuse_parameter_changes([p]) for p in parameter_list]
        return super().set_parameters(parameter_list)

    def set_parameters_atomically(self, parameter_list):
        if self._refuses(parameter_list):
            return self._refuse_parameter_changes(parameter_list)
        return super().set_parameters_atomically(parameter_list)

    def _refuses(self, parameter_list):
        """Once the node is built, a change of any parameter it declared is refused."""
        return getattr(self, '_built', False) and \
            any(self.has_parameter(p.name) for p in parameter_list)

    # --- setpoints ---------------------------------------------------------------------------

    def serve_setpoint(self, msg, info=None):
        """One JointState setpoint -> effort_command + joint_effort, or a counted rejection.

        Called by the setpoint loop's thread with ``self.lock`` held, once per message, in
        the order received; every message that queued up while it worked is served next.
        ``info``: rclpy's message info (the publisher's sequence number counts lost ones).
        """
        start = time.perf_counter()
        if info is not None:
            self._count_lost(info.get('publication_sequence_number'))
        try:
            if info is not None and self.max_age_ns:
                self._check_age(info.get('source_timestamp'))
            received, v = setpoint_arrays(msg, self.selector)
            stamp = stamp_to_ns(msg.header.stamp)
            unstamped = not stamp
            if unstamped:
                stamp = self._now_ns()
            elif self.max_stamp_lead_ns != math.inf and 0 < (
                    now := self._now_ns()) < stamp - self.max_stamp_lead_ns:
                # (a clock at 0 has not started: use_sim_time before the first /clock)
                raise Rejected('stamp', f'stamp {stamp / NANOSECONDS:.9f} is '
                               f"{(stamp - now) / NANOSECONDS:.6g} s ahead of the node's clock "
                               f'(max_stamp_lead {self.max_stamp_lead_ns / NANOSECONDS:g} s): '
                               'check the clock of the setpoint source')
            try:
                self.filter.check_stamp(stamp)
            except StampError as exc:
                self._stamp_rejections += 1
                if not self.max_stamp_rejections or \
                        self._stamp_rejections < self.max_stamp_rejections:
                    raise Rejected('stamp', str(exc)) from None
                self._restart_after_stamps(exc)
            q = self._positions_used(stamp, received)
            v_used, a = self.filter.estimate(stamp, q, v)
            efforts = self.solver.sample_torques(q, v_used, a)   # the core's control-rate call
            if not all(map(math.isfinite, efforts)):
                raise Rejected('out_of_range', 'the torques are not finite at this setpoint')
        except Rejected as exc:
            self.reject(exc.reason, str(exc))
            return
        except CogIdError as exc:
            bad = rejection(exc)
            self.reject(bad.reason, str(bad))
            return
        if self.limited:
            tau = np.array(efforts)
            if self.clip(tau):
                efforts = tau.tolist()
        # first the command: what control waits for, published serialized
        # (conversions.EffortMessages.command_for, cdr.py); the compute time ends when it is
        # ready to send, the DDS write after that is timed apart (the publish time)
        command = self.outputs.command_for(efforts)
        ready = time.perf_counter()
        self.command_pub.publish(command)
        self.publish_times.append(time.perf_counter() - ready)
        self.compute_times.append(ready - start)
        self.effort_pub.publish(self.outputs.state_for(msg.header, received, v_used, efforts))
        self.filter.accept(stamp, q, v)
        self._stamp_rejections = 0
        self.counts['accepted'] += 1
        if unstamped:
            self._unstamped()
        self.last_pose = q
        self.last_was_rejected = False
        self.last_setpoint_time = time.monotonic()
        self.stream_stopped = False
        if self.joint_states_pub is not None:       # last: nothing waits for it
            self._joint_states_countdown -= 1
            if not self._joint_states_countdown:
                self._joint_states_countdown = self.joint_states_decimation
                try:
                    self.publish_joint_states(msg.header.frame_id, stamp, v_used)
                except Exception as exc:   # noqa: BLE001 (the setpoint was served: no rejection)
                    self.counts['internal_errors'] += 1
                    self._period_problems += 1
                    self.warn_throttled('internal.joint_states', 'joint_states failed (the '
                                        f'node goes on): {type(exc).__name__}: {exc}',
                                        error=True)

    def _check_age(self, published):
        """Rejected ('stale') when the setpoint was published more than max_setpoint_age
        ago (``published``: DDS's source timestamp, ns of the publisher's system clock,
        which time.time_ns reads on this machine): after the node was stopped and continued,
        or while it is behind, a command for a past setpoint would reach the motors late."""
        if not published:
            return
        age = time.time_ns() - published
        if age > self.max_age_ns:
            raise Rejected('stale', f'published {age / NANOSECONDS:.3g} s ago, more than '
                           f'max_setpoint_age ({self.max_age_ns / NANOSECONDS:g} s): the node '
                           'was stopped or fell behind (or the clocks of the two machines '
                           'disagree)')

    def _unstamped(self):
        """A setpoint stamped 0 was served at its receipt time: counted, warned about (the
        time between receipts jitters against the motion, and its second difference is in
        the accelerations: torques many times too large at 1 kHz)."""
        self.counts['setpoints_unstamped'] += 1
        self._period_unstamped += 1
        self.warn_throttled(
            'unstamped', 'setpoint stamped 0: served at its receipt time, so the jitter of '
            'receipt times against the motion goes into the estimated accelerations (at 1 kHz, '
            'torques can be many times too large); stamp each setpoint with the time its '
            'positions are meant for (header.stamp), or send whole trajectories with their '
            'velocities and accelerations to joint_trajectory')

    def _ros_now_ns(self):
        """The node's clock (ROS time: /clock with use_sim_time) in integer ns."""
        return self.get_clock().now().nanoseconds

    def publish_joint_states(self, frame_id, stamp, rates):
        """joint_states: the closed pose the solver served the setpoint at (every joint) and
        the joint rates there from the active ``rates`` used, read from the core."""
        try:
            q, qdot = self.solver.last_pose(rates)
        except CogIdError:      # rates too large for the joint rates: positions alone
            q, qdot = self.solver.last_pose()[0], []
        self.joint_states_pub.publish(self.outputs.pose_for(frame_id, stamp, q, qdot))

    def _positions_used(self, stamp, received):
        """The positions the setpoint is served at: unwrapped, checked for a jump.

        Within a stream (the estimator has a history and no gap restarts it), revolute
        active joints are taken as the 2 pi equivalent nearest the previous accepted
        position (unwrap_angles), and a step larger than max_setpoint_step is rejected
        ('jump'; the estimator restarts, so the next setpoint starts a new stream). The
        first setpoint of a stream is taken as received.
        """
        previous = self.filter.last_positions
        if previous is None or self.filter.restarts_at(stamp):
            return received
        q = [nearest_turn(x, ref) if wrap else x
             for x, ref, wrap in zip(received, previous, self.unwrap)]
        if self.checks_steps:
            for joint, x, ref, limit in zip(self.active_joints, q, previous, self.max_step):
                if abs(x - ref) > limit:
                    self.filter.reset()
                    raise Rejected('jump', f'{joint} moves by {abs(x - ref):.6g} from the '
                                   f'previous setpoint (max_setpoint_step {limit:g}); the '
                                   'estimator restarts: the next setpoint starts a new stream')
        return q

    def _restart_after_stamps(self, exc):
        """max_stamp_rejections setpoints in a row came before the last accepted stamp: the
        source's clock went back (or an earlier stamp was far ahead). Start a new stream."""
        self.filter.reset()
        self._stamp_rejections = 0
        self.counts['stamp_restarts'] += 1
        self.get_logger().warning(
            f'{self.max_stamp_rejections} setpoints in a row stamped before the previous '
            f'accepted one ({exc}): the estimator restarts, this setpoint starts a new stream')

    def _count_lost(self, sequence):
        """Count setpoints lost before they were taken (the publisher's sequence numbers).

        Counted only while a single publisher feeds the topic: rclpy does not say which
        publisher a message came from, so several publishers' numbers cannot be told apart.
        """
        last = self._last_sequence
        self._last_sequence = sequence
        if sequence is None or last is None or sequence == last + 1:
            return
        if sequence > last + 1 and self.setpoint_loop.subscription.get_publisher_count() == 1:
            lost = sequence - last - 1
            self.counts['setpoints_lost'] += lost
            self._period_problems += 1
            self.warn_throttled('lost', f'{lost} setpoint(s) lost before the node could take '
                                        'them (subscription queue full, or the network)')

    def _serve_failed(self, exc):
        """A setpoint that failed in a way serve_setpoint does not expect (a bug): no
        command, counted as 'solver' and in internal_errors, logged with its type; the
        next one is served."""
        self.counts['internal_errors'] += 1
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
        self.warn_throttled(reason, f'setpoint rejected, no command ({reason}): {text}')

    def warn_throttled(self, key, text, error=False):
        """Log a warning at most once a warning_period per key; count the ones left out."""
        now = time.monotonic()
        last, suppressed = self._warned.get(key, (-math.inf, 0))
        if now - last < self.warning_period:
            self._warned[key] = (last, suppressed + 1)
            return
        more = f' ({suppressed} more like it since the last warning)' if suppressed else ''
        self._warned[key] = (now, 0)
        # Two call sites, one per severity: rclpy's logger remembers the severity of each call
        # site and raises ValueError when one site logs at another (an error after a warning
        # from one line killed the thread that logged it)
        if error:
            self.get_logger().error(text + more)
        else:
            self.get_logger().warning(text + more)

    def internal_error(self, where, exc):
        """An exception in one of the node's callbacks: counted, logged with its type."""
        with self.lock:
            self.counts['internal_errors'] += 1
            self._period_problems += 1
            try:
                self.warn_throttled('internal.' + where, f'{where} failed (the node goes on): '
                                    f'{type(exc).__name__}: {exc}', error=True)
            except Exception:   # noqa: BLE001 (counted: a failing log must not raise again)
                pass

    # --- trajectories ------------------------------------------------------------------------

    @_guarded
    def on_trajectory(self, raw):
        """A serialized JointTrajectory: refused at once when too long, else handed to the
        trajectory worker (a process of its own, see TrajectoryWorker; queue of one)."""
        points = trajectory_point_count(raw)
        if points is not None and points > self.max_trajectory_points:
            self._trajectory_rejected(Rejected(
                'too_long', f'{points} points, more than max_trajectory_points '
                            f'({self.max_trajectory_points})'), points)
            return
        replaced = self.trajectory_worker.submit(raw)
        if replaced is not None:
            self._trajectory_rejected(Rejected(
                'busy', 'a newer trajectory arrived while it waited for the one being solved '
                        '(one waits at most; the newest wins)'),
                trajectory_point_count(replaced))

    def _trajectory_rejected(self, exc, points):
        with self.lock:
            self.counts['trajectories_rejected'] += 1
            self.trajectory_rejected[exc.reason] += 1
            self._period_problems += 1
            size = '' if points is None else f' of {points} points'
            self.warn_throttled('trajectory.' + exc.reason,
                                f'trajectory{size} rejected ({exc.reason}), no '
                                f'effort_trajectory: {exc}')

    @_guarded
    def _trajectory_done(self, result):
        """Called by the trajectory worker's thread with the trajectory process's answer."""
        kind = result[0]
        if kind == 'ok':
            _, out, clipped, _ = result
            self.trajectory_pub.publish(out)
            with self.lock:
                self.counts['trajectories_accepted'] += 1
                if clipped:
                    self.counts['effort_clipped'] += 1
                    self._period_problems += 1
        elif kind == 'rejected':
            _, reason, text, points = result
            self._trajectory_rejected(Rejected(reason, text), points)
        else:   # 'internal': the trajectory process failed or ended
            self.internal_error('trajectory', RuntimeError(result[1]))
            self._trajectory_rejected(Rejected('solver', result[1]), None)

    # --- timeout -----------------------------------------------------------------------------

    @_guarded
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
        self._stamp_rejections = 0
        n_act = len(self.active_joints)
        if self.timeout_behavior == 'none':
            what = 'nothing published'
        elif self.timeout_behavior == 'zero':
            self.command_pub.publish(self.outputs.command_for([0.0] * n_act))
            what = 'zero efforts published'
        else:
            try:
                tau = self.solver.torques(self.last_pose, [0.0] * n_act, [0.0] * n_act)
            except CogIdError as exc:   # cannot happen for a pose just served; be safe
                self.get_logger().error(f'cannot compute holding efforts: {exc}')
                return
            self.clip(tau)
            self.command_pub.publish(self.outputs.command_for(tau.tolist()))
            what = 'gravity-holding efforts of the last pose published'
        self.get_logger().info(
            f'no setpoint for {self.setpoint_timeout:g} s: stream stopped, {what}')

    # --- diagnostics -------------------------------------------------------------------------

    @_guarded
    def publish_diagnostics(self):
        self.check_duplicate_names()
        try:
            health = self.closure_health(self.last_pose)   # solved outside the lock
        except CogIdError:
            health = (math.nan, math.nan)
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        with self.lock:
            msg.status = [self.diagnostic_status(*health)]
        self.diagnostics_pub.publish(msg)

    def check_duplicate_names(self):
        """Warn when other nodes in the graph have this node's name and namespace (each
        would answer every setpoint too); checked at each diagnostics period."""
        me = (self.get_name(), self.get_namespace())
        count = sum(1 for entry in self.get_node_names_and_namespaces() if tuple(entry) == me)
        count = max(count, 1)
        if count > 1 and count != self.same_name_nodes:
            self.get_logger().warning(
                f'{count} nodes named {self.get_fully_qualified_name()} in the ROS graph: every '
                'setpoint gets a command from each; give each node a namespace of its own '
                '(-r __ns:=/name) or stop the others')
        self.same_name_nodes = count

    def diagnostic_status(self, residual, condition):
        """The DiagnosticStatus of the node (``residual``, ``condition``: closure_health)."""
        status = DiagnosticStatus()
        status.name = f'{self.get_fully_qualified_name()}: inverse dynamics'
        status.hardware_id = self.mechanism.name
        n_rejected = sum(self.rejected.values())
        stopped = self.stopped_threads()
        if stopped:
            status.level = DiagnosticStatus.ERROR
            status.message = (f"stopped serving ({'; '.join(stopped)}): a bug, please report "
                              'it; restart the node')
        elif self.last_was_rejected:
            status.level = DiagnosticStatus.ERROR
            status.message = f'last setpoint rejected ({self.last_rejection})'
        elif self._period_problems:
            status.level = DiagnosticStatus.WARN
            status.message = (f'{self._period_problems} setpoint(s) or trajectories rejected, '
                              'clipped or lost, or internal errors, in the last period')
        elif self.same_name_nodes > 1:
            status.level = DiagnosticStatus.WARN
            status.message = (f'{self.same_name_nodes} nodes with this name: every setpoint '
                              'gets a command from each')
        elif self._period_unstamped:
            status.level = DiagnosticStatus.WARN
            status.message = (f'{self._period_unstamped} setpoint(s) stamped 0 in the last '
                              'period: accelerations estimated from receipt times (noisy)')
        else:
            status.level = DiagnosticStatus.OK
            if self.last_setpoint_time is None:
                status.message = 'ready, no setpoint yet'
            elif self.stream_stopped:
                status.message = f'setpoint stream stopped ({self.timeout_behavior})'
            else:
                status.message = 'serving setpoints'
        self._period_problems = self._period_unstamped = 0
        times = np.array(self.compute_times) * 1e6
        sends = np.array(self.publish_times) * 1e6
        since = '' if self.last_setpoint_time is None else \
            f'{time.monotonic() - self.last_setpoint_time:.3f}'
        values = [
            ('mechanism', self.mechanism.name),
            ('active_joints', ', '.join(self.active_joints)),
            ('backend', self.solver.backend),
            ('setpoints_accepted', self.counts['accepted']),
            ('setpoints_rejected', n_rejected),
            *((f'rejected.{reason}', count) for reason, count in self.rejected.items()),
            ('setpoints_lost', self.counts['setpoints_lost']),
            ('stamp_restarts', self.counts['stamp_restarts']),
            ('setpoints_unstamped', self.counts['setpoints_unstamped']),
            ('trajectories_accepted', self.counts['trajectories_accepted']),
            ('trajectories_rejected', self.counts['trajectories_rejected']),
            *((f'trajectories_rejected.{reason}', count)
              for reason, count in self.trajectory_rejected.items()),
            ('trajectory_in_progress', str(self.trajectory_worker.busy).lower()),
            ('effort_clipped', self.counts['effort_clipped']),
            ('timeouts', self.counts['timeouts']),
            ('internal_errors', self.counts['internal_errors']),
            ('nodes_with_this_name', self.same_name_nodes),
            ('last_closure_residual', f'{residual:.3g}'),
            ('closure_condition_number', f'{condition:.4g}'),
            ('compute_time_median_us', f'{np.median(times):.1f}' if times.size else ''),
            ('compute_time_max_us', f'{times.max():.1f}' if times.size else ''),
            ('compute_time_samples', times.size),
            ('publish_time_median_us', f'{np.median(sends):.1f}' if sends.size else ''),
            ('publish_time_max_us', f'{sends.max():.1f}' if sends.size else ''),
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


class TrajectoryWorker:
    """Trajectories solved in a process of their own, fed by a thread of this process.

    Deserialising, checking, solving and serialising a long trajectory takes seconds of
    Python and C that hold the GIL (a 100,000-point one: ~7 s on the reference VM); done in
    the node's process it stalled the setpoint thread and the timers. Here the node only
    passes the serialized message (bytes) through a pipe to a process started with
    ``spawn`` from the mechanism's parameters (:func:`conversions.trajectory_process`),
    and publishes the serialized answer it gets back: the node's threads are never held up
    by more than copying bytes. One trajectory is solved at a time and at most one waits
    (:meth:`submit` returns the one a newer one replaced).

    Nothing here waits without a bound: the process has ``STARTUP_BOUND`` s to say it is
    ready (its kernels loaded or compiled) and :meth:`answer_bound` s to answer a
    trajectory; a process that dies (killed, out of memory) or does not answer in time
    (stopped, stuck) is killed, the trajectory in progress is answered with ('internal',
    text) and a new process is started for the next one. :meth:`stop` kills a process
    that does not end within its timeout (SIGKILL: a stopped process ignores SIGTERM
    until it is continued, and multiprocessing's exit handler would wait for it).
    """

    #: s a new trajectory process may take to load the mechanism and its kernels (a cold
    #: compile of a large mechanism, on a loaded machine)
    STARTUP_BOUND = 300.0
    #: s per point added to ``timeout`` for a trajectory's answer: 10-15x the measured cost
    #: (a 100,000-point trajectory takes 4-8 s on the reference VM)
    SECONDS_PER_POINT = 1e-3

    def __init__(self, config, on_done, timeout=10.0):
        self.config = config
        self.on_done = on_done
        self.timeout = timeout
        self._cond = threading.Condition()
        self._next = None        # taken next, never replaced (it came while nothing was solved)
        self._pending = None     # the one that waits; a newer one replaces it
        self.busy = False
        self._stopping = False
        self._process = self._conn = None
        self._ready = False
        #: the exception that ended the worker thread, if one did (reported by the node)
        self.failure = None
        self._thread = threading.Thread(target=self._run, name='trajectory worker', daemon=True)

    def start(self):
        self._start_process()
        self._thread.start()

    @property
    def running(self):
        return self._thread.is_alive()

    def answer_bound(self, points):
        """s the process has to answer a trajectory of ``points`` points (None: unknown)."""
        return self.timeout + self.SECONDS_PER_POINT * (points or 0)

    def submit(self, raw):
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

    def stop(self, timeout=5.0):
        """End the process (at once if it is solving: nobody waits for its answer) and
        the thread; never waits longer than about ``timeout`` for each."""
        with self._cond:
            self._stopping = True
            self._next = self._pending = None
            self._cond.notify()
        self._end_process(0.2 if self.busy else timeout)
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _start_process(self):
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

    def _end_process(self, timeout=5.0):
        process, conn = self._process, self._conn
        self._process = self._conn = None
        if conn is not None:
            conn.close()            # the process reads EOF and ends
        if process is not None:
            process.join(timeout)
            if process.is_alive():
                process.kill()      # SIGKILL: ends a stopped process too
                process.join(timeout)

    def _run(self):
        try:
            self._serve()
        except BaseException as exc:   # noqa: BLE001 (recorded: the node reports it)
            self.failure = exc
            raise

    def _serve(self):
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

    def _receive(self, bound, what):
        """The process's next message within ``bound`` s; TimeoutError naming ``what``."""
        if not self._conn.poll(bound):
            raise TimeoutError(f'the trajectory process did not {what} within {bound:.3g} s '
                               '(stopped or stuck)')
        return self._conn.recv()

    def _solve(self, raw):
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


def main(args: list[str] | None = None) -> int:
    """Start the node and spin until Ctrl-C or SIGTERM (exit status 0).

    ``-h``/``--help`` (before ``--ros-args``): the usage, exit status 0. A parameter that
    cannot be honoured, or a params file rcl cannot parse: exit status 2 and one line
    naming it. A stop signal that arrives while the node is being built ends start-up at
    once while the mechanism loads and its kernels compile, and is noted and acted on
    once the rclpy objects are built otherwise (:mod:`cog_id_ros.ros.stop_signals`): it
    stops the node cleanly too (exit status 0). No exception of a callback ends the node
    (they are counted in diagnostics as ``internal_errors``); a thread of the node that
    ended anyway makes the exit status 1.
    """
    argv = sys.argv[1:] if args is None else list(args[1:])
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    if '-h' in own or '--help' in own:
        print(USAGE, end='')
        return 0
    problem = params_file_problem(argv)
    if problem:
        print(f'{NODE_NAME}: cannot start: {problem}', file=sys.stderr)
        return 2
    stop = stop_signals.DeferredStop()
    try:
        with _stderr_held() as held:
            rclpy.init(args=args, signal_handler_options=stop.RCLPY_OPTIONS)
    except Exception as exc:   # noqa: BLE001 (e.g. a params file rcl cannot parse)
        print(f'{NODE_NAME}: cannot start: {_rcl_message(exc)}', file=sys.stderr)
        return 2
    held.replay()
    sys.setswitchinterval(SWITCH_INTERVAL)
    node = None
    stopped = []
    try:
        node = CogIdNode(command_line=argv, interruptible=stop.interruptible)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        # Start-up left tens of thousands of long-lived objects (rclpy, numpy, the traced
        # program). Frozen, a full collection during the stream no longer walks them: its
        # pause (~10 ms on the reference VM) becomes microseconds.
        gc.collect()
        gc.freeze()
        node.start()
        if stop.hand_over() is None:   # no stop asked for during start-up
            _spin(executor, node)
    except (MechanismConfigError, rclpy.exceptions.InvalidParameterTypeException,
            rclpy.exceptions.InvalidParameterValueException) as exc:
        print(f'{NODE_NAME}: cannot start: {_one_line(exc)}', file=sys.stderr)
        return 2
    except (ExternalShutdownException, stop_signals.StopRequested):
        pass   # Ctrl-C or SIGTERM: rclpy's signal handler has shut the context down, or
        # start-up was interrupted while it loaded the mechanism or compiled its kernels
    except Exception as exc:   # noqa: BLE001
        if rclpy.ok():
            if node is None:   # start-up: an error rclpy raised for something we did not check
                print(f'{NODE_NAME}: cannot start: {type(exc).__name__}: {_one_line(exc)}',
                      file=sys.stderr)
                return 2
            raise
        # the signal shut the context down between two turns of spin(), whose next wait set
        # then fails on the dead context (an RCLError): a clean stop too
    finally:
        if node is not None:
            stopped = node.stop()
            node.destroy_node()
        rclpy.try_shutdown()
    if stopped:
        print(f"{NODE_NAME}: stopped serving before the end: {'; '.join(stopped)}",
              file=sys.stderr)
        return 1
    return 0


def _spin(executor, node):
    """executor.spin(), except that an exception out of a callback does not end it.

    Every callback of the node is guarded (_guarded); this catches what is left, e.g. an
    exception rclpy raises around a callback, counts and logs it, and spins on.
    """
    while True:
        try:
            executor.spin()
            return
        except ExternalShutdownException:
            raise
        except Exception as exc:   # noqa: BLE001
            if not rclpy.ok():
                raise
            node.internal_error('executor', exc)
            time.sleep(0.01)   # an error that repeats must not turn into a busy loop


def params_file_problem(argv: list[str]) -> str | None:
    """A sentence naming the first parameter of a ``--params-file`` rcl would refuse, or None.

    rcl's own message names a line of the file, not the parameter, and comes with a
    second log line; the files are read here first, by the API's reader and its one rule of
    what rcl refuses (:mod:`cog_id_ros.description.params_file`: ``read_document``, numbers
    read as rcl reads them, and ``check_rcl_values``: arrays that mix integers and doubles or other
    types), so the node and ``Mechanism.from_params_file`` refuse the same files with the
    same message. Keys written twice are left to rcl (the last one wins).
    """
    files = [argv[i + 1] for i, arg in enumerate(argv[:-1]) if arg == '--params-file']
    for path in files:
        try:
            params_file.check_rcl_values(params_file.read_document(path, duplicate_keys=True),
                                         path)
        except MechanismConfigError as exc:
            text = _one_line(exc)
            if exc.parameter == 'params_file':      # the file itself: say it as given
                text = '--params-file' + text[len('params_file'):]
            return text
    return None


def urdf_base_dir(command_line, node_name):
    """The directory a relative ``mechanism.urdf_file`` is relative to: that of the
    ``--params-file`` that gives it to the node called ``node_name`` (rcl applies the files
    and ``-p`` rules in their order on the command line: the last one that gives it counts);
    None (the working directory) when a ``-p`` rule gives it, or nothing does."""
    base = None
    args = list(command_line or ())
    for arg, value in zip(args, args[1:]):
        if arg == '--params-file':
            try:
                given = 'mechanism.urdf_file' in params_file.load_params_file(value, node_name)
            except MechanismConfigError:
                given = False
            if given:
                base = os.path.dirname(os.path.abspath(value))
        elif arg in ('-p', '--param') and \
                value.split(':=', 1)[0].rsplit(':', 1)[-1] == 'mechanism.urdf_file':
            base = None
    return base


def _rcl_message(exc):
    """rcl's message for a command line it refused, in one line without its source lines;
    a parse error in a params file names the parameter at the line rcl names."""
    text = _one_line(exc)
    text = text.replace('failed to initialize rcl: ', '')
    text = re.sub(r',? at /\S+:\d+', '', text)
    found = re.search(r"params file: '--params-file (.+?)'.*?line(?:_num)? (\d+)", text)
    if found:
        name = _parameter_at_line(found.group(1), int(found.group(2)))
        if name:
            return f'{name}: {text}'
    return text


def _parameter_at_line(path, line):
    """The dotted name (below ros__parameters) of the entry at ``line`` (1-based) of a
    params file, or None."""
    try:
        with open(path, encoding='utf-8') as stream:
            root = yaml.compose(stream)
    except (OSError, yaml.YAMLError):
        return None
    best = None

    def walk(node, prefix):
        nonlocal best
        if not isinstance(node, yaml.MappingNode):
            return
        for key, value in node.value:
            name = f'{prefix}{key.value}'
            if key.start_mark.line + 1 <= line <= max(value.end_mark.line + 1,
                                                     key.start_mark.line + 1):
                best = name
                walk(value, name + '.')

    if isinstance(root, yaml.MappingNode):
        for _, body in root.value:
            if isinstance(body, yaml.MappingNode):
                for key, params in body.value:
                    if key.value == 'ros__parameters':
                        walk(params, '')
    return best


class _stderr_held:
    """Holds what C code writes to file descriptor 2 (rcl's "Failed to parse global
    arguments" log line) until replay(); dropped when the block raises."""

    def __enter__(self):
        self._saved = None
        self._file = tempfile.TemporaryFile()
        try:
            sys.stderr.flush()
            self._saved = os.dup(2)
            os.dup2(self._file.fileno(), 2)
        except OSError:
            self._saved = None
        return self

    def __exit__(self, *exc_info):
        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
            self._saved = None
        return False

    def replay(self):
        self._file.seek(0)
        text = self._file.read()
        self._file.close()
        if text:
            sys.stderr.buffer.write(text)
            sys.stderr.flush()


def _one_line(exc):
    return ' '.join(str(exc).split())


if __name__ == '__main__':
    sys.exit(main())
