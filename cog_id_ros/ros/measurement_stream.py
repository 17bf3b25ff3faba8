"""The stream of measured JointStates -> the measured state a feedback mode closes its loop
on, or a Rejected (no physics).

:class:`MeasurementStream` takes each message of ``measured_joint_states`` through the
checks that keep a bad measurement from the motors, in order: its age (published longer
than ``measurement_timeout`` ago: ``stale``), the active joints' positions and velocities
(:func:`.conversions.setpoint_arrays`: names, lengths, ``non_finite``; velocities required
where the mode needs them, none faster than ``max_measured_velocity``: ``velocity``),
and, within a stream, unwrapping and the step since the last accepted measurement
(``jump``). A topic fed by more publishers than ``max_measured_publishers`` is not
commanded from at all (``publishers``: a stale recording or a second simulator never takes
over the controller), and after a timeout the new stream starts only once two measured
states in a row agree within ``max_measurement_step`` (``restart``: the first message after
a timeout is not trusted as the reference alone; after a stall of the node itself, which
its timer has not judged yet, the first fresh one is). Whether the loops close at the measured pose
is the mode's solve (:mod:`.feedback`). The node calls :meth:`MeasurementStream.accept` once the
command is published; :meth:`MeasurementStream.stopped_for` says when no measurement was
accepted for the timeout (``timeout_behavior`` then applies, once, and the next
measurement starts a new stream).
"""
import math
import time
from typing import Any, Callable

from .config import NodeConfig
from .conversions import JointSelector, Rejected, check_age, nearest_turn, setpoint_arrays
from .lost_messages import LostMessages
from .setpoint_filter import NANOSECONDS

#: s a feedback mode waits for its first measured state before it says so (and between
#: two reminders)
NO_STATE_PERIOD = 5.0


class MeasurementStream:
    """Checks the measured states of one stream by the node's parameters.

    ``needs_velocities``: the mode's law uses the measured velocities (a measurement
    without them is rejected, ``malformed``); else they are taken as zero. ``publishers``:
    the publishers of the topic now, as the node sees them.
    """

    def __init__(self, config: NodeConfig, needs_velocities: bool,
                 publishers: Callable[[], int] = lambda: 1) -> None:
        self.active_joints = list(config.active_joints)
        self.selector = JointSelector(self.active_joints)
        self.unwrap = config.unwrap
        self.max_step = list(config.max_measurement_step)
        self.max_velocity = list(config.max_measured_velocity)
        self.timeout = config.measurement_timeout
        self.max_age_ns = int(config.measurement_timeout * NANOSECONDS)
        self.needs_velocities = needs_velocities
        self.publishers = publishers
        self.max_publishers = config.max_measured_publishers
        self.lost = LostMessages(publishers)   # gaps in the single publisher's numbers
        self.candidate: list[float] | None = None   # a restart's first measured state
        self.last_pose: list[float] | None = None   # positions of the last accepted one
        self.last_time: float | None = None   # monotonic receipt time of the last accepted one
        self.stopped = True                   # no measurement yet, or none for the timeout
        self.accepted = 0
        self._taken: list[float] = []
        self._waiting_since: float | None = None    # the first silence_to_tell
        self._told: float | None = None             # when the last one said something

    def take(self, msg: Any, info: dict | None = None) -> tuple[list[float], list[float]]:
        """(positions, velocities) of the active joints of JointState ``msg`` (positions
        unwrapped within the stream); raises Rejected. ``info``: rclpy's message info (the
        source and reception timestamps: a measurement published or received longer than
        measurement_timeout ago is stale)."""
        if info is not None:
            self.lost.count(info)
            self._check_age(info)
        count = self.publishers()
        if self.max_publishers and count > self.max_publishers:
            raise Rejected('publishers', f'{count} publishers feed measured_joint_states, more '
                                         f'than max_measured_publishers '
                                         f'({self.max_publishers}): not commanded from; stop '
                                         f'the others (a recording, a second plant)')
        q, v = setpoint_arrays(msg, self.selector, 'measured state')
        if v is None:
            if self.needs_velocities:
                raise Rejected('malformed', 'no velocities: this control_mode needs the '
                                            'measured velocity of every active joint')
            v = [0.0] * len(q)
        for joint, rate, limit in zip(self.active_joints, v, self.max_velocity):
            if abs(rate) > limit:
                raise Rejected('velocity', f'measured velocity of {joint} is {rate:.6g}, beyond '
                               f'max_measured_velocity ({limit:g}): not commanded from')
        # a new stream after the timeout (two states that agree); or after a gap as long
        # that the timer has not judged yet: this node did not run (stopped or starved), the
        # plant went on, and the first fresh state is the new reference as it comes (a
        # plant in lockstep sends the next one only after a command)
        gap = not self.stopped and self.last_time is not None and \
            time.monotonic() - self.last_time >= self.timeout
        if self.stopped and self.last_pose is not None:
            self._confirm_restart(q)
        previous = self.candidate if self.stopped else None if gap else self.last_pose
        if previous is not None:
            q = [nearest_turn(x, ref) if wrap else x
                 for x, ref, wrap in zip(q, previous, self.unwrap)]
            for joint, x, ref, limit in zip(self.active_joints, q, previous, self.max_step):
                if abs(x - ref) > limit:
                    raise Rejected('jump', f'measured {joint} moves by {abs(x - ref):.6g} from '
                                   f'the last accepted measurement (max_measurement_step '
                                   f'{limit:g}): not commanded from')
        self._taken = q
        return q, v

    def _confirm_restart(self, q: list[float]) -> None:
        """After a timeout: the first measured state is held as a candidate, not commanded
        from (Rejected 'restart'); the stream starts again with the next one that agrees
        with the candidate within max_measurement_step (else that one is the candidate)."""
        candidate = self.candidate
        if candidate is not None and all(
                abs((nearest_turn(x, ref) if wrap else x) - ref) <= limit
                for x, ref, wrap, limit in zip(q, candidate, self.unwrap, self.max_step)):
            return
        self.candidate = list(q)
        raise Rejected('restart', 'the first measured state after measurement_timeout: the '
                                  'stream starts again when the next one agrees with it '
                                  '(within max_measurement_step)')

    def accept(self) -> None:
        """The measurement taken last was commanded from: it is the stream's last pose."""
        self.candidate = None
        self.last_pose = self._taken
        self.last_time = time.monotonic()
        self.stopped = False
        self.accepted += 1

    def silence_to_tell(self, publishers: int, topic: str) -> str:
        """The warning of a feedback mode with no measured state accepted since it started
        serving (the first call) or since the last one, every NO_STATE_PERIOD s ('' : not
        now); ``publishers`` of ``topic``, as the node sees them. A plant that stopped (a
        simulator at a singular pose), or stopped before the controller connected, or
        publishes elsewhere, leaves a controller that commands nothing: it says why."""
        now, last = time.monotonic(), self.last_time
        if self._waiting_since is None:
            self._waiting_since = now
        since = self._waiting_since if last is None else last
        told = max(since if self._told is None else self._told, since)
        if now - told < NO_STATE_PERIOD:
            return ''
        self._told = now
        return (f"no measured state accepted {'in' if last is None else 'since the last one,'} "
                f'{now - since:.0f} s, on {topic} ({publishers} publisher(s)): '
                'nothing is commanded until one comes; is the plant running (a simulator whose '
                'integration stopped publishes no more states: its log and /diagnostics say '
                'why), and does it publish on this topic (remap it with -r '
                'measured_joint_states:=...)? Those that came and were rejected are counted in '
                '/diagnostics (measurements_rejected.<reason>)')

    def age(self) -> float | None:
        """Seconds since the last accepted measurement was received (None: none yet)."""
        return None if self.last_time is None else time.monotonic() - self.last_time

    def stopped_for(self, timeout: float, since: float = -math.inf) -> bool:
        """True, once, when no measurement was accepted for ``timeout`` s: the stream
        counts as stopped, and the next measurement starts a new one (no jump check). ``since``
        (monotonic): the silence counts from then at the earliest (the node itself did not
        run before: stopped or starved)."""
        if self.stopped or self.last_time is None:
            return False
        if time.monotonic() - max(self.last_time, since) < timeout:
            return False
        self.stopped = True
        return True

    def _check_age(self, info: dict) -> None:
        """Rejected ('stale') when the measurement was published (DDS's source timestamp,
        the plant's system clock) or received more than measurement_timeout ago: after the
        node was stopped and continued, or while it is behind, a command from an old state
        would close the loop on the past."""
        now = time.time_ns()
        for key in ('source_timestamp', 'received_timestamp'):
            check_age(info.get(key), self.max_age_ns, f'measured state {key.split("_")[0]}',
                      'measurement_timeout', now)
