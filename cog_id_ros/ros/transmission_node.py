"""cog_transmission_node: the map between joint space and actuator space, at message rate.

For a stack whose controller already computes joint-space efforts: ``joint_command``
(mechanism.joint_space) in, ``actuator_command`` (the motors) out; ``actuator_states`` (the
motors' measured state) in, ``joint_states`` (every joint) out; counts on ``/diagnostics``.
The topics are :data:`.topics.TRANSMISSION_TOPICS` (QoS as cog_id_node's: the inputs best
effort, the outputs reliable), the parameters cog_id_node's parameter file (the mechanism,
which must name mechanism.joint_space) and the few of cog_id_node's this node uses
(:data:`TRANSMISSION_PARAMETERS`). The maps are :mod:`.transmission_stream`'s; this module
is the wiring. A message that cannot be mapped gets no output and a counted reason; no
exception in a callback ends the node. ``main`` is ``cog_id_ros.ros.main.transmission_main``.
"""
import collections
import contextlib
import threading
from typing import Any, Callable, ContextManager, Sequence

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import JointState

from ..core import MechanismConfigError, Transmission
from ..description import Mechanism
from .command_line import urdf_base_dir
from .config import NodeConfig
from .conversions import Rejected
from .diagnostics import DiagnosticsPublisher, ThrottledWarnings, guarded
from .lost_messages import LostMessages
from .parameters import NODE_PARAMETERS, is_mechanism_parameter
from .read_only_node import ReadOnlyNode, assembly_warnings_logged
from .topics import TRANSMISSION_TOPICS, control_qos, stream_qos
from .transmission_stream import (
    TRANSMISSION_REASONS,
    CommandMap,
    StateMap,
    check_age,
)

NODE_NAME = 'cog_transmission_node'

#: cog_id_node's parameters this node reads (the same meaning, the same file)
TRANSMISSION_PARAMETERS = {name: NODE_PARAMETERS[name] for name in (
    'backend', 'max_setpoint_age', 'diagnostics_period', 'warning_period')}

#: input topic -> (its key in /diagnostics, output topic)
STREAMS = {'joint_command': ('commands', 'actuator_command'),
           'actuator_states': ('states', 'joint_states')}


class StreamCounts:
    """What one input stream counted: accepted, rejected per reason, lost."""

    def __init__(self, publishers: Callable[[], int]) -> None:
        self.accepted = 0
        self.rejected = collections.Counter(dict.fromkeys(TRANSMISSION_REASONS, 0))
        self.lost = LostMessages(publishers)
        self.last_rejection = ''
        self.last_was_rejected = False


class CogTransmissionNode(ReadOnlyNode):
    """joint_command -> actuator_command and actuator_states -> joint_states, exactly."""

    def __init__(self, command_line: Sequence[str] | None = None,
                 interruptible: Callable[[], ContextManager] = contextlib.nullcontext,
                 **kwargs: Any) -> None:
        """``command_line`` and ``interruptible`` as for cog_id_node."""
        super().__init__(NODE_NAME, **kwargs)
        self.build_or_destroy(lambda: self._build(command_line, interruptible))

    def _build(self, command_line: Sequence[str] | None,
               interruptible: Callable[[], ContextManager]) -> None:
        overrides = self.override_values()
        base_dir = {name: urdf_base_dir(command_line, self.get_name(), name)
                    for name in ('mechanism.urdf_file', 'mechanism.loop_closure_file')
                    if name in overrides}
        with interruptible(), assembly_warnings_logged():
            self.mechanism = mechanism = Mechanism.from_parameters(self.declare_given(
                overrides, is_mechanism_parameter, 'mechanism (read at start-up)'),
                base_dir=base_dir)
        # cog_id_node's own parameters may be in the file both nodes read: not unknown here
        self.warn_unknown(overrides, lambda name: name in NODE_PARAMETERS
                          or is_mechanism_parameter(name))
        self.config = config = NodeConfig.declare(self, overrides, mechanism,
                                                  TRANSMISSION_PARAMETERS)
        self.check_qos_overrides(overrides)
        self.make_use_sim_time_read_only()
        if not getattr(mechanism, 'joint_space', None):
            raise MechanismConfigError(
                'mechanism.joint_space', f"mechanism '{mechanism.name}' names none: "
                f'{NODE_NAME} maps joint space to the motors and back (give the joints a '
                'controller commands, e.g. the ankle pitch and roll)')
        with interruptible():       # one Transmission per stream: each its own warm start
            self.maps: dict[str, Any] = {
                'joint_command': CommandMap(Transmission(mechanism, config.backend)),
                'actuator_states': StateMap(Transmission(mechanism, config.backend))}
        self.lock = threading.Lock()
        self.warnings = ThrottledWarnings(self.get_logger(), config.warning_period)
        self.internal_errors = 0
        self.period_problems = 0
        with self.qos_overrides_honoured(overrides):
            self._create_topics()
        self.create_timer(config.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(
            f"mechanism '{mechanism.name}': joint space {', '.join(mechanism.joint_space)} "
            f"<-> motors {', '.join(mechanism.active_joints)}; joint_command -> "
            'actuator_command, actuator_states -> joint_states '
            f'({self.maps["joint_command"].transmission.actuators.backend} kernels)')
        self.refuse_changes()

    def _create_topics(self) -> None:
        qos_options = QoSOverridingOptions.with_default_policies
        lean = PublisherEventCallbacks(use_default_callbacks=False)
        self.diagnostics = DiagnosticsPublisher(self, lean)
        self.publishers_out = {
            output: self.create_publisher(JointState, TRANSMISSION_TOPICS[output].name,
                                          control_qos(), event_callbacks=lean,
                                          qos_overriding_options=qos_options())
            for _, output in STREAMS.values()}
        self.subscriptions_in = {
            topic: self.create_subscription(JointState, TRANSMISSION_TOPICS[topic].name,
                                            callback, stream_qos(),
                                            qos_overriding_options=qos_options())
            for topic, callback in (('joint_command', self.on_joint_command),
                                    ('actuator_states', self.on_actuator_states))}
        self.counts = {topic: StreamCounts(sub.get_publisher_count)
                       for topic, sub in self.subscriptions_in.items()}

    # --- the node's life (startup.run) ---------------------------------------------------

    def start(self) -> None:
        """Nothing to start: the executor serves every callback."""

    def stopped_threads(self) -> list[str]:
        return []

    def stop(self) -> list[str]:
        return []

    def internal_error(self, where: str, exc: BaseException) -> None:
        """An exception in one of the node's callbacks: counted, logged with its type."""
        with self.lock:
            self.internal_errors += 1
            self.period_problems += 1
            self.warnings.warn('internal.' + where, f'{where} failed (the node goes on): '
                               f'{type(exc).__name__}: {exc}', error=True)

    # --- the maps --------------------------------------------------------------------------

    @guarded
    def on_joint_command(self, msg: JointState, info: dict) -> None:
        """joint_command -> actuator_command, or a counted rejection."""
        self._serve('joint_command', msg, info)

    @guarded
    def on_actuator_states(self, msg: JointState, info: dict) -> None:
        """actuator_states -> joint_states, or a counted rejection."""
        self._serve('actuator_states', msg, info)

    def _serve(self, topic: str, msg: JointState, info: dict) -> None:
        counts = self.counts[topic]
        lost = counts.lost.count(info)
        try:
            check_age(info, self.config.max_setpoint_age, topic)
            out = self.maps[topic].map(msg)
        except Rejected as exc:
            with self.lock:
                counts.rejected[exc.reason] += 1
                counts.last_rejection = f'{exc.reason}: {exc}'
                counts.last_was_rejected = True
                self.period_problems += 1 + bool(lost)
                self.warnings.warn(f'{topic}.{exc.reason}', f'{topic} rejected, no output '
                                   f'({exc.reason}): {exc}')
            return
        self.publishers_out[STREAMS[topic][1]].publish(out)
        with self.lock:
            counts.accepted += 1
            counts.last_was_rejected = False
            self.period_problems += bool(lost)

    # --- diagnostics -----------------------------------------------------------------------

    @guarded
    def publish_diagnostics(self) -> None:
        self.diagnostics.count_same_name_nodes()
        with self.lock:
            status = self._status()
        self.diagnostics.publish(status)

    def _status(self) -> DiagnosticStatus:
        status = DiagnosticStatus()
        status.name = f'{self.get_fully_qualified_name()}: transmission'
        status.hardware_id = self.mechanism.name
        status.level, status.message = self._level()
        values: list[tuple[str, Any]] = [
            ('mechanism', self.mechanism.name),
            ('joint_space', ', '.join(self.mechanism.joint_space)),
            ('active_joints', ', '.join(self.mechanism.active_joints)),
            ('backend', self.maps['joint_command'].transmission.actuators.backend)]
        for topic, (key, _) in STREAMS.items():
            counts = self.counts[topic]
            values += [(f'{key}_accepted', counts.accepted),
                       (f'{key}_rejected', sum(counts.rejected.values())),
                       *((f'{key}_rejected.{reason}', n) for reason, n in counts.rejected.items()),
                       (f'{key}_lost', counts.lost.total),
                       (f'{key}_publishers', self.subscriptions_in[topic].get_publisher_count()),
                       (f'last_{key}_rejection', counts.last_rejection)]
        values += [('internal_errors', self.internal_errors),
                   ('nodes_with_this_name', self.diagnostics.same_name_nodes)]
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values]
        return status

    def _level(self) -> tuple[bytes, str]:
        problems, self.period_problems = self.period_problems, 0
        for topic in STREAMS:
            if self.counts[topic].last_was_rejected:
                return DiagnosticStatus.ERROR, (f'last {topic} rejected '
                                                f'({self.counts[topic].last_rejection})')
        if problems:
            return DiagnosticStatus.WARN, (f'{problems} message(s) rejected or lost, or '
                                           'internal errors, in the last period')
        if self.diagnostics.same_name_nodes > 1:
            return DiagnosticStatus.WARN, (f'{self.diagnostics.same_name_nodes} nodes with '
                                           'this name: every message gets an answer from each')
        if not any(c.accepted for c in self.counts.values()):
            return DiagnosticStatus.OK, 'ready, nothing mapped yet'
        return DiagnosticStatus.OK, 'mapping'
