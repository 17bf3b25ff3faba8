"""The stream of nav_msgs/Odometry base states -> the base state a floating base's setpoints
are served with, or a Rejected (no physics).

A floating robot's setpoint (its actuators' motion, :mod:`.setpoint_stream`) is served with
the state of its base: :class:`BaseStateStream` takes each message of ``base_state``
through its checks, in order -- its age (published longer than ``base_state_timeout`` ago:
``stale``), finite numbers (``non_finite``), a unit quaternion (``malformed`` beyond
QUATERNION_TOLERANCE, normalised within), a stamp after the previous accepted one
(``stamp``) -- and keeps the latest accepted one, with the base acceleration
(``base_acceleration``: ``estimated``, the time derivative of the twist by the setpoints'
estimator, :class:`.setpoint_filter.SetpointFilter`, or ``zero``). The conventions are the
core's ``whole_body_torques``' (Pinocchio's free flyer): the pose (x, y, z, qx, qy, qz, qw)
world from base, from ``pose.pose``; the twist (v, w) in the base frame, from
``twist.twist`` (Odometry's twist is in its ``child_frame_id``, the body frame); the
acceleration, its time derivative in the same frame. :meth:`BaseStateStream.current` gives
the state a setpoint is served with, or rejects the setpoint (``base_state``) when none came
yet or the latest is older than ``base_state_timeout``.
"""
import collections
import math
import time
from typing import Any, Callable, NamedTuple

from .conversions import Rejected, check_age, stamp_to_ns
from .lost_messages import LostMessages
from .setpoint_filter import NANOSECONDS, SetpointFilter, StampError

#: how far the orientation quaternion's norm may be from 1 (an estimator in float32, a
#: message rounded in transit): normalised within, rejected (``malformed``) beyond
QUATERNION_TOLERANCE = 1e-3
#: the world frame the wrenches are said to be in when base_state's header names none
DEFAULT_WORLD_FRAME = 'world'
#: m/s^2 or rad/s^2: an estimated base acceleration beyond this is no body's (a twist that
#: jumped, or stamps too close together for its change): the base state is rejected
#: (``jump``) rather than served as a huge inertial force
MAX_BASE_ACCELERATION = 200.0
#: the reasons a base_state is rejected for (counted per reason in /diagnostics)
BASE_STATE_REASONS = ('stale', 'non_finite', 'malformed', 'stamp', 'jump')


class BaseState(NamedTuple):
    """A base state as whole_body_torques takes it (lists of floats)."""

    pose: list[float]             # x, y, z, qx, qy, qz, qw: world from base
    velocity: list[float]         # v, w of the base frame, in the base frame
    acceleration: list[float]     # their time derivative (estimated, or zero)
    frame_id: str                 # the world frame: base_state's header.frame_id
    stamp: int                    # ns (the receipt time when the header's is 0)


class BaseStateStream:
    """Checks the base states of one stream and keeps the latest accepted one.

    ``timeout``: base_state_timeout (s); ``estimated``: the acceleration is the twist's
    estimated derivative (else zero); ``window``, ``max_interval``: the estimator's
    (estimator_window, max_setpoint_interval); ``now_ns``: the node's clock (a stamp of 0);
    ``publishers``: publishers of the topic now (losses are counted with one).
    """

    def __init__(self, timeout: float, estimated: bool, window: int, max_interval: float,
                 now_ns: Callable[[], int], publishers: Callable[[], int]) -> None:
        self.timeout = timeout
        self.max_age_ns = int(timeout * NANOSECONDS)
        self.estimated = estimated
        self.filter = SetpointFilter(6, window, max_interval)
        self.now_ns = now_ns
        self.lost = LostMessages(publishers)
        self.last: BaseState | None = None      # the latest accepted base state
        self.last_time: float | None = None     # its monotonic receipt time
        self.accepted = 0
        self.rejected = collections.Counter(dict.fromkeys(BASE_STATE_REASONS, 0))
        self.last_rejection = ''

    def take(self, msg: Any, info: dict | None = None) -> BaseState:
        """The base state of Odometry ``msg``, now the latest (accepted and counted);
        raises Rejected. ``info``: rclpy's message info (losses, the publication time)."""
        if info is not None:
            self.lost.count(info)
            check_age(info.get('source_timestamp'), self.max_age_ns, 'base_state published',
                      'base_state_timeout')
        pose, twist = msg.pose.pose, msg.twist.twist
        p, o = pose.position, pose.orientation
        quaternion = [o.x, o.y, o.z, o.w]
        velocity = [twist.linear.x, twist.linear.y, twist.linear.z,
                    twist.angular.x, twist.angular.y, twist.angular.z]
        if not all(map(math.isfinite, [p.x, p.y, p.z, *quaternion, *velocity])):
            raise Rejected('non_finite', 'base_state: a position, orientation or twist is NaN '
                                         'or infinite')
        norm = math.sqrt(sum(x * x for x in quaternion))
        if abs(norm - 1.0) > QUATERNION_TOLERANCE:
            raise Rejected('malformed', f'base_state: the orientation quaternion has norm '
                                        f'{norm:.6g}, not 1 (x, y, z, w world from base)')
        stamp = stamp_to_ns(msg.header.stamp) or self.now_ns()
        if self.last_time is not None and time.monotonic() - self.last_time > self.timeout:
            self.filter.reset()         # a new stream: any stamp, acceleration 0
        try:
            self.filter.check_stamp(stamp)
        except StampError as exc:
            raise Rejected('stamp', 'base_state ' + str(exc).replace('setpoint', 'base_state')
                           ) from None
        acceleration = self.filter.estimate(stamp, velocity)[0] if self.estimated \
            else [0.0] * 6
        largest = max(map(abs, acceleration))
        if not largest <= MAX_BASE_ACCELERATION:
            raise Rejected('jump', f'base_state: its twist changes at {largest:.6g} m/s^2 or '
                                   f'rad/s^2 from the previous one (more than '
                                   f'{MAX_BASE_ACCELERATION:g}): a jump of the twist, or stamps '
                                   'too close together for its change; not served')
        self.filter.accept(stamp, velocity)
        self.last = BaseState([p.x, p.y, p.z, *(x / norm for x in quaternion)], velocity,
                              acceleration, msg.header.frame_id or DEFAULT_WORLD_FRAME, stamp)
        self.last_time = time.monotonic()
        self.accepted += 1
        return self.last

    def reject(self, reason: str, text: str) -> None:
        """Count a rejected base state (the latest accepted one stays in force)."""
        self.rejected[reason] += 1
        self.last_rejection = f'{reason}: {text}'

    def current(self) -> BaseState:
        """The base state a setpoint is served with now: the latest accepted one; Rejected
        ('base_state') when none came yet or it was received more than the timeout ago."""
        if self.last is None or self.last_time is None:
            raise Rejected('base_state', 'no base_state received yet: a floating base is '
                                         "served with its base's pose and twist "
                                         '(nav_msgs/Odometry on base_state)')
        age = time.monotonic() - self.last_time
        if age > self.timeout:
            raise Rejected('base_state', f'the latest base_state was received {age:.3g} s ago, '
                                         f'more than base_state_timeout ({self.timeout:g} s)')
        return self.last

    def age(self) -> float | None:
        """Seconds since the latest accepted base state was received (None: none yet)."""
        return None if self.last_time is None else time.monotonic() - self.last_time
