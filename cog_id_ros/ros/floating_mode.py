"""cog_id_node's floating mode: a robot whose base is free in space (``mechanism.floating_base``).

The setpoint path is the node's as for a fixed base (:mod:`.setpoint_stream` checks and
estimates the actuators' motion, the node clips and publishes the efforts); what differs
is the control mode and three topics, all here:

* :class:`FloatingMode`, the mode: a setpoint's efforts are the core's
  ``InverseDynamics.whole_body_torques`` of the actuators' motion with the base state in
  force (the latest ``base_state``, :mod:`.base_state_stream`) and the active contacts;
  ``hold`` (``timeout_behavior``) the efforts that hold the last pose at rest, the base
  where it was last, on the active contacts.
* :class:`FloatingBase`, the wiring: ``base_state`` (nav_msgs/Odometry) served by a
  thread of its own (:class:`.setpoint_loop.SetpointLoop`; the base states that arrived
  before a setpoint are taken before it is served); the parameter ``active_contacts``,
  the one the node lets change at run time (:meth:`.read_only_node.ReadOnlyNode.allow_changes`;
  the check is :func:`.config.contact_set_problem`); after each served setpoint, one
  ``contact_wrenches/<name>`` (geometry_msgs/WrenchStamped) per active contact and
  ``base_wrench``; its keys of /diagnostics (``FLOATING_DIAGNOSTIC_KEYS``).

What the node refuses at start-up (no contacts, a feedback control_mode, command_space
joint, an unknown active contact) is :func:`.config.check_floating`. Trajectories carry no
base motion: the node rejects them (``base_state``).
"""
import math
from typing import Any, Callable, Sequence

from geometry_msgs.msg import WrenchStamped  # type: ignore[import-untyped]
from nav_msgs.msg import Odometry  # type: ignore[import-untyped]
import numpy as np
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks

from .base_state_stream import BaseStateStream
from .config import contact_set_problem
from .conversions import Rejected
from .parameters import NODE_PARAMETERS
from .setpoint_filter import NANOSECONDS
from .setpoint_loop import SetpointLoop
from .topics import FLOATING_TOPICS, control_qos, stream_qos

#: the base pose ``hold`` uses before any base_state came: at the origin, upright
UPRIGHT = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
#: why a trajectory is rejected with a floating base
NO_TRAJECTORIES = ('a joint_trajectory carries no motion of the floating base: serve it as '
                   'setpoints on joint_setpoint, with base_state')

#: keys of /diagnostics with a floating base, besides base_states_rejected.<reason>
FLOATING_DIAGNOSTIC_KEYS = {
    'active_contacts': 'the contacts whose wrenches balance the motion now (parameter '
                       'active_contacts)',
    'base_state_publishers': "publishers of base_state matched to the node's subscription, "
                             'as the node sees them',
    'base_states_accepted': 'base states accepted since start',
    'base_states_rejected': 'base states rejected since start (sum of '
                            'base_states_rejected.<kind>: stale, non_finite, malformed, stamp)',
    'base_states_lost': 'base states the single publisher of base_state sent that never '
                        'reached the node (gaps in its sequence numbers)',
    'base_state_age': 's since the latest accepted base state was received',
    'last_base_state_rejection': 'kind and message of the last rejected base state',
}


class FloatingMode:
    """Open loop with a floating base: the efforts of the actuators' motion with the base
    state in force and the active contacts (``whole_body_torques``); ``last`` holds what
    the last served setpoint gave (its wrenches and base state: published after it)."""

    measured = False

    def __init__(self, solver: Any, base: BaseStateStream, catch_up: Callable[[], None],
                 contacts: Sequence[str]) -> None:
        self.solver = solver
        self.base = base
        self.catch_up = catch_up
        self.contacts = list(contacts)
        self.last: tuple[Any, Any] | None = None

    def efforts(self, positions: list[float], velocities: list[float],
                accelerations: list[float]) -> list[float]:
        """The efforts of the setpoint (Rejected 'base_state' without a base state in
        force; the core's errors as for a fixed base)."""
        self.catch_up()     # the base states that arrived before this setpoint are in force
        base = self.base.current()
        out = self.solver.whole_body_torques(base.pose, base.velocity, base.acceleration,
                                             positions, velocities, accelerations,
                                             contacts=self.contacts)
        if not np.isfinite(out.base_wrench).all() or \
                not all(np.isfinite(w).all() for w in out.wrenches.values()):
            raise Rejected('out_of_range', 'the contact wrenches are not finite at this '
                                           'setpoint')
        self.last = (out, base)
        return out.efforts.tolist()

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The efforts that hold ``pose`` at rest on the active contacts, the base at its
        latest pose (upright at the origin before any base_state)."""
        base_pose = UPRIGHT if self.base.last is None else self.base.last.pose
        zeros = [0.0] * len(pose)
        return self.solver.whole_body_torques(base_pose, None, None, list(pose), zeros, zeros,
                                              contacts=self.contacts).efforts


class FloatingBase:
    """The floating mode's topics and its run-time parameter, on cog_id_node ``node``
    (built: its config, mechanism, solver, lock, counts; ``qos_options()``: the node's QoS
    override options of a topic; ``overrides``: the values given to the node)."""

    def __init__(self, node: Any, overrides: dict[str, Any],
                 qos_options: Callable[[], Any]) -> None:
        config = node.config
        self.node = node
        self.publishers = 0         # base_state publishers matched, as the node sees them
        self.stream = BaseStateStream(
            config.base_state_timeout, config.base_acceleration == 'estimated',
            config.estimator_window, config.max_setpoint_interval, node._now_ns,
            lambda: self.publishers)
        self.loop = SetpointLoop(
            node, Odometry, FLOATING_TOPICS['base_state'].name, self.on_base_state,
            stream_qos(), lock=node.lock, on_error=self._base_state_failed, with_info=True,
            qos_overriding_options=qos_options(),
            event_callbacks=SubscriptionEventCallbacks(matched=self._matched))
        self.mode = FloatingMode(node.solver, self.stream, self.loop.serve_queued,
                                 self._declare_active_contacts(overrides))
        lean = PublisherEventCallbacks(use_default_callbacks=False)

        def publisher(topic: str) -> Any:
            return node.create_publisher(WrenchStamped, topic, control_qos(),
                                         event_callbacks=lean,
                                         qos_overriding_options=qos_options())
        self.wrench_pubs = {name: publisher(f'contact_wrenches/{name}')
                            for name in node.mechanism.contacts}
        self.base_wrench_pub = publisher(FLOATING_TOPICS['base_wrench'].name)
        self._messages = {name: WrenchStamped() for name in (*self.wrench_pubs, '')}
        node.counts.rejected['base_state'] += 0             # listed from the start
        node.counts.trajectory_rejected['base_state'] += 0
        node.allow_changes('active_contacts', self.contacts_problem, self.set_contacts)

    def _declare_active_contacts(self, overrides: dict[str, Any]) -> list[str]:
        """Declare active_contacts (changeable: dynamic typing, so that [] of any array
        type means none) from the value given (checked at start-up by check_floating) or
        every contact; a managed node configured again keeps the value it has."""
        node = self.node
        if node.has_parameter('active_contacts'):
            value = node.get_parameter('active_contacts').value
            return list(value) if value else []
        given = overrides.get('active_contacts')
        names = list(node.mechanism.contacts) if given is None else list(given)
        node.declare_parameter('active_contacts', names, ParameterDescriptor(
            dynamic_typing=True,
            description=NODE_PARAMETERS['active_contacts'].ros_description),
            ignore_override=True)
        return names

    # --- active_contacts --------------------------------------------------------------------

    def contacts_problem(self, value: Any) -> str:
        """Why ``value`` cannot be the active contacts ('' when it can)."""
        return contact_set_problem(value, self.node.mechanism)

    def set_contacts(self, value: Any) -> None:
        """The active contacts from now on (the next setpoint is served with them)."""
        names = list(value) if value else []
        with self.node.lock:
            self.mode.contacts = names
        self.node.get_logger().info(f"active_contacts: {', '.join(names) or 'none'}")

    # --- base_state -------------------------------------------------------------------------

    def on_base_state(self, msg: Odometry, info: dict | None = None) -> None:
        """One base_state (the base state thread, or the setpoint thread catching up; the
        node's lock held): the latest base state, or a counted rejection."""
        try:
            self.stream.take(msg, info)
        except Rejected as exc:
            self.stream.reject(exc.reason, str(exc))
            counts = self.node.counts
            counts.period_problems += 1
            counts.warnings.warn('base_state.' + exc.reason,
                                 f'base_state rejected ({exc.reason}): {exc}')

    def _base_state_failed(self, exc: Exception) -> None:
        """A base state that failed in a way on_base_state does not expect (a bug)."""
        self.stream.reject('malformed', f'unexpected {type(exc).__name__}: {exc}')
        self.node.counts.internal_error('base_state', exc)

    def _matched(self, status: Any) -> None:
        self.publishers = status.current_count

    # --- outputs ----------------------------------------------------------------------------

    def publish(self, stamp_ns: int) -> None:
        """The wrenches of the setpoint served last (stamped ``stamp_ns``): one per active
        contact, in world axes at the contact point, and base_wrench (base frame). After
        the command: a failure is counted, the command is out."""
        try:
            self._publish(stamp_ns)
        except Exception as exc:   # noqa: BLE001 (the command is out: no rejection)
            self.node.counts.internal_error('contact_wrenches', exc)

    def _publish(self, stamp_ns: int) -> None:
        if self.mode.last is None:
            return
        out, base = self.mode.last
        sec, nanosec = divmod(stamp_ns, NANOSECONDS)
        for name, wrench in out.wrenches.items():
            self.wrench_pubs[name].publish(self._message(name, sec, nanosec, base.frame_id,
                                                         wrench))
        self.base_wrench_pub.publish(self._message('', sec, nanosec,
                                                   self.node.mechanism.base_link,
                                                   out.base_wrench))

    def _message(self, name: str, sec: int, nanosec: int, frame_id: str,
                 wrench: np.ndarray) -> WrenchStamped:
        """The WrenchStamped of contact ``name`` ('' : the base), filled in place: (f, m),
        or (f, 0) for a force alone."""
        msg = self._messages[name]
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.header.frame_id = frame_id
        values = [float(x) for x in wrench] + [0.0] * (6 - len(wrench))
        force, torque = msg.wrench.force, msg.wrench.torque
        force.x, force.y, force.z = values[:3]
        torque.x, torque.y, torque.z = values[3:]
        return msg

    # --- diagnostics, release ---------------------------------------------------------------

    def diagnostics(self) -> list[tuple[str, Any]]:
        """Its keys of /diagnostics (FLOATING_DIAGNOSTIC_KEYS; the node's lock held)."""
        stream = self.stream
        age = stream.age()
        return [('active_contacts', ', '.join(self.mode.contacts)),
                ('base_state_publishers', self.publishers),
                ('base_states_accepted', stream.accepted),
                ('base_states_rejected', sum(stream.rejected.values())),
                *((f'base_states_rejected.{reason}', count)
                  for reason, count in stream.rejected.items()),
                ('base_states_lost', stream.lost.total),
                ('base_state_age', '' if age is None or not math.isfinite(age)
                 else f'{age:.4f}'),
                ('last_base_state_rejection', stream.last_rejection)]

    def release(self) -> None:
        """A managed node's cleanup: the thread stopped, the topics destroyed, changes of
        active_contacts refused again (the parameter stays declared, with its value)."""
        node = self.node
        node.forbid_changes('active_contacts')
        self.loop.stop()
        node.destroy_subscription(self.loop.subscription)
        for pub in (*self.wrench_pubs.values(), self.base_wrench_pub):
            node.destroy_publisher(pub)
