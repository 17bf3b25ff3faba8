"""cog_sim_node: the mechanism simulated over ROS 2, efforts in, joint states out.

Topics and service (relative names: namespaces and remaps apply; the table with their
types, QoS and meaning is :mod:`.sim_topics`, documented in docs/sim_node.md):
``effort_command`` (cog_id_node's, no remap needed) and ``joint_effort_command`` in;
``joint_states``, ``/clock`` (with ``publish_clock``) and ``/diagnostics`` out;
``~/reset``. The parameters are cog_id_node's parameter file (the mechanism) plus the
simulator's own (:mod:`.sim_parameters`), read once at start-up, read-only afterwards.

This module is the wiring. The physics is ``cog_id_ros.Simulation``'s alone; the
integration thread (:mod:`.sim_loop`) steps it with the held efforts
(:class:`.sim_efforts.EffortHold`); effort messages are checked by :mod:`.sim_efforts`
in the executor, ``~/reset`` and ``/diagnostics`` (:mod:`.sim_diagnostics`) are served
there too. No exception in a callback ends the node: it is counted (``internal_errors``)
and logged. ``main`` is in :mod:`.sim_main`.
"""
import contextlib
import threading
from typing import Any, Callable, ContextManager, Sequence

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.qos_overriding_options import QoSOverridingOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from ..core import Simulation
from ..description import Mechanism
from .command_line import urdf_base_dir
from .config import NodeConfig
from .conversions import JointSelector
from .diagnostics import DiagnosticsPublisher, ThrottledWarnings, guarded
from .lost_messages import LostMessages
from .parameters import NODE_PARAMETERS, is_mechanism_parameter
from .read_only_node import ReadOnlyNode, assembly_warnings_logged
from .sim_diagnostics import EffortCounts, SimReport
from .sim_efforts import EffortHold, EffortRejected, command_efforts, named_efforts
from .sim_loop import Integrator, Pacer, SimLoop, StateOutputs
from .sim_parameters import SIM_PARAMETERS
from .sim_topics import SIM_TOPICS, clock_qos
from .topics import control_qos, stream_qos

NODE_NAME = 'cog_sim_node'


class CogSimNode(ReadOnlyNode):
    """The mechanism in its parameters, simulated: efforts in, joint states out."""

    def __init__(self, command_line: Sequence[str] | None = None,
                 interruptible: Callable[[], ContextManager] = contextlib.nullcontext,
                 **kwargs: Any) -> None:
        """``command_line`` and ``interruptible`` as for cog_id_node
        (:class:`cog_id_ros.ros.node.CogIdNode`)."""
        super().__init__(NODE_NAME, **kwargs)
        self.build_or_destroy(lambda: self._build(command_line, interruptible))

    def _build(self, command_line: Sequence[str] | None,
               interruptible: Callable[[], ContextManager]) -> None:
        overrides = self.override_values()
        base_dir = urdf_base_dir(command_line, self.get_name()) \
            if 'mechanism.urdf_file' in overrides else None
        with interruptible(), assembly_warnings_logged():
            self.mechanism = Mechanism.from_parameters(self.declare_given(
                overrides, is_mechanism_parameter, 'mechanism (read at start-up)'),
                base_dir=base_dir)
        # cog_id_node's own parameters may be in the file both nodes read: not unknown here
        self.warn_unknown(overrides, lambda name: name in SIM_PARAMETERS
                          or name in NODE_PARAMETERS or is_mechanism_parameter(name))
        self.config = config = NodeConfig.declare(self, overrides, self.mechanism,
                                                  SIM_PARAMETERS)
        self.check_qos_overrides(overrides)
        self.make_use_sim_time_read_only()
        with interruptible():
            self.simulation = Simulation(self.mechanism, time_step=config.time_step,
                                         backend=config.backend, tolerance=config.tolerance)
        self.lock = threading.Lock()        # the held efforts and the counts
        self.counts = EffortCounts(ThrottledWarnings(self.get_logger(), config.warning_period))
        active = config.active_joints
        self.hold = EffortHold(len(active), config.effort_timeout,
                               config.effort_timeout_behavior,
                               config.effort_limits if config.limited else None)
        self.selector = JointSelector(active)
        with self.qos_overrides_honoured(overrides):
            outputs = self._create_topics()
        every = 1 if config.lockstep else \
            max(1, round(config.joint_states_period / config.time_step))
        self.integrator = Integrator(self.simulation, self.hold, self.lock, outputs, every,
                                     self.get_logger(), config.wait_for_effort,
                                     config.lockstep)
        self.pacer = Pacer(config.time_step, config.real_time_factor)
        self.loop = SimLoop(self.integrator, self.pacer, self.context, self.get_logger(),
                            self.internal_error)
        self.report = SimReport(self)
        self.create_timer(config.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(self._summary(every))
        for warning in getattr(self.mechanism, 'assembly_warnings', None) or ():
            self.get_logger().warning(f'mechanism: {warning}')
        self.refuse_changes()

    def _create_topics(self) -> StateOutputs:
        qos_options = QoSOverridingOptions.with_default_policies
        lean = PublisherEventCallbacks(use_default_callbacks=False)
        joint_states = self.create_publisher(
            JointState, SIM_TOPICS['joint_states'].name, control_qos(), event_callbacks=lean,
            qos_overriding_options=qos_options())
        clock = self.create_publisher(Clock, SIM_TOPICS['/clock'].name, clock_qos(),
                                      event_callbacks=lean) \
            if self.config.publish_clock else None
        self.diagnostics = DiagnosticsPublisher(self, lean)
        subscriptions = {
            topic: self.create_subscription(msg_type, SIM_TOPICS[topic].name, callback,
                                            stream_qos(), qos_overriding_options=qos_options())
            for topic, msg_type, callback in (
                ('effort_command', Float64MultiArray, self.on_effort_command),
                ('joint_effort_command', JointState, self.on_joint_effort_command))}
        #: per effort topic, the gaps in its single publisher's sequence numbers
        self.lost = {topic: LostMessages(sub.get_publisher_count)
                     for topic, sub in subscriptions.items()}
        self.create_service(Trigger, SIM_TOPICS['~/reset'].name, self.on_reset)
        joints = self.mechanism.joints
        return StateOutputs(joints, [joints.index(j) for j in self.config.active_joints],
                            joint_states, clock)

    def _summary(self, every: int) -> str:
        config, mechanism = self.config, self.mechanism
        factor = config.real_time_factor
        pace = f'{factor:g}x real time' if factor else 'as fast as possible'
        return (f"mechanism '{mechanism.name}': {len(mechanism.joints)} joints, active joints "
                f"{', '.join(config.active_joints)}; simulating with time step "
                f'{config.time_step:g} s ({self.simulation.backend} kernels), {pace}; '
                f'joint_states every {every} step(s)'
                f"{'; /clock published' if config.publish_clock else ''}"
                f"{'; the state held until the first effort' if config.wait_for_effort else ''}"
                f"{'; lockstep: one step per effort message' if config.lockstep else ''}"
                f'; effort timeout {config.effort_timeout:g} s '
                f'({config.effort_timeout_behavior})')

    # --- threads -----------------------------------------------------------------------------

    def start(self) -> None:
        """Start the integration thread (once the node is built)."""
        self.loop.start()
        self._started = True

    def stopped_threads(self) -> list[str]:
        """'integration thread: <why>' if it ended by itself (a bug), else []."""
        if not getattr(self, '_started', False) or not self.loop.ended_by_itself:
            return []
        failure = self.loop.failure
        return ['integration thread: ' + (f'{type(failure).__name__}: {failure}'
                                          if failure is not None else 'ended')]

    def stop(self) -> list[str]:
        """Stop the integration thread; returns stopped_threads() as it was before."""
        stopped = self.stopped_threads()
        self._started = False
        self.loop.stop()
        return stopped

    def internal_error(self, where: str, exc: BaseException) -> None:
        """An exception in one of the node's callbacks: counted, logged with its type."""
        with self.lock:
            self.counts.internal_error(where, exc)

    # --- efforts -----------------------------------------------------------------------------

    @guarded
    def on_effort_command(self, msg: Float64MultiArray, info: dict) -> None:
        """Efforts in active_joints order: held from the next step on, or rejected
        (``info``: rclpy's message info: lost messages are counted)."""
        self._take('effort_command', command_efforts, msg, self.config.active_joints, info)

    @guarded
    def on_joint_effort_command(self, msg: JointState, info: dict) -> None:
        """Efforts by joint name: held from the next step on, or rejected."""
        self._take('joint_effort_command', named_efforts, msg, self.selector, info)

    def _take(self, topic: str, read: Callable[..., list[float]], msg: Any, joints: Any,
              info: dict) -> None:
        lost = self.lost[topic].count(info)
        if lost:
            with self.lock:
                self.counts.count_lost(topic, lost)
        try:
            efforts = read(msg, joints, self.config.max_effort)
        except EffortRejected as exc:
            with self.lock:
                self.counts.reject(exc.reason, topic, str(exc))
            return
        with self.lock:
            self.counts.accept(self.hold.accept(efforts, self.integrator.time))
        if self.config.lockstep:
            self.loop.wake()

    # --- reset and diagnostics ---------------------------------------------------------------

    def on_reset(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """~/reset: the integration thread resets the simulation between two steps.
        Never raises (a service callback must answer): a failure is the answer."""
        try:
            response.success, response.message = self.loop.request_reset()
            if response.success:
                with self.lock:
                    self.counts.resets += 1
                self.get_logger().info(response.message)
        except Exception as exc:   # noqa: BLE001 (answered, counted)
            self.internal_error('reset', exc)
            response.success, response.message = False, f'{type(exc).__name__}: {exc}'
        return response

    @guarded
    def publish_diagnostics(self) -> None:
        self.diagnostics.count_same_name_nodes()
        publishers = self.count_publishers(self.resolve_topic_name(
            SIM_TOPICS['joint_states'].name))
        with self.lock:
            status = self.report.status(publishers)
        self.diagnostics.publish(status)
