"""The stream of JointState setpoints -> the setpoint a mode serves, or a Rejected (no physics).

:class:`SetpointStream` takes each message of ``joint_setpoint`` through the node's checks
in order -- lost and stale messages, the active joints' positions and velocities
(:func:`.conversions.setpoint_arrays`), the stamp, unwrapping and the step since the
previous setpoint -- and estimates the velocities and accelerations
(:mod:`.setpoint_filter`). What comes out, positions, velocities and accelerations of
the active joints, is what every control mode serves (:mod:`.modes`); the node calls
:meth:`SetpointStream.accept` once its command is published, so a setpoint that got no
command never enters the estimator. The stream also knows when it stopped
(:meth:`SetpointStream.stopped_for`: the timeout).
"""
import math
import time
from typing import Any, Callable

import numpy as np

from .config import NodeConfig
from .conversions import (
    JointSelector,
    Rejected,
    check_age,
    nearest_turn,
    setpoint_arrays,
    stamp_to_ns,
)
from .diagnostics import Counts
from .lost_messages import LostMessages
from .setpoint_filter import NANOSECONDS, SetpointFilter, StampError


class SetpointStream:
    """Checks and estimates the setpoints of one stream, by the node's parameters.

    ``now_ns``: the node's clock in integer ns; ``publisher_count``: publishers of the
    setpoint topic now (lost setpoints are counted only while there is one); ``counts``
    and ``logger``: where served and lost setpoints and estimator restarts are counted
    and logged.
    """

    def __init__(self, config: NodeConfig, counts: Counts, logger: Any,
                 now_ns: Callable[[], int], publisher_count: Callable[[], int]) -> None:
        self.active_joints = list(config.active_joints)
        self.selector = JointSelector(self.active_joints)
        self.filter = SetpointFilter(len(self.active_joints), config.estimator_window,
                                     config.max_setpoint_interval)
        self.unwrap = config.unwrap
        self.max_step = config.max_setpoint_step
        self.checks_steps = bool(np.isfinite(self.max_step).any())
        self.max_stamp_lead_ns = config.max_stamp_lead * NANOSECONDS \
            if math.isfinite(config.max_stamp_lead) else math.inf
        self.max_stamp_rejections = config.max_stamp_rejections
        self.max_age_ns = config.max_setpoint_age * NANOSECONDS
        self.counts, self.logger = counts, logger
        self.now_ns, self.publisher_count = now_ns, publisher_count
        self.last_pose: list[float] | None = None   # positions of the last accepted setpoint
        self.last_time: float | None = None   # monotonic receipt time of the last accepted one
        self.stopped = True                   # no setpoint yet, or none for the timeout
        self._stamp_rejections = 0            # consecutive setpoints rejected for their stamp
        self.lost = LostMessages(publisher_count)   # gaps in the publisher's numbers
        # the setpoint taken last, until the next one (accept() makes it part of the
        # stream): its stamp in ns (its receipt time when the header's is 0) and its
        # positions as received; (unstamped, positions served, velocities as received)
        self.stamp = 0
        self.received: list[float] = []
        self._taken: tuple[bool, list[float], list[float] | None] = (False, [], None)

    def take(self, msg: Any, info: dict | None = None
             ) -> tuple[list[float], list[float], list[float]]:
        """(positions, velocities, accelerations) of the active joints at the setpoint of
        JointState ``msg`` (positions unwrapped within the stream, velocities given or
        estimated); raises Rejected. ``info``: rclpy's message info (the publisher's
        sequence number counts lost ones, its source timestamp rejects stale ones)."""
        if info is not None:
            self._count_lost(info)
            if self.max_age_ns:
                check_age(info.get('source_timestamp'), self.max_age_ns, 'published',
                          'max_setpoint_age')
        received, v = setpoint_arrays(msg, self.selector)
        stamp = stamp_to_ns(msg.header.stamp)
        unstamped = not stamp
        if unstamped:
            stamp = self.now_ns()
        elif self.max_stamp_lead_ns != math.inf and 0 < (
                now := self.now_ns()) < stamp - self.max_stamp_lead_ns:
            # (a clock at 0 has not started: use_sim_time before the first /clock)
            raise Rejected('stamp', f'stamp {stamp / NANOSECONDS:.9f} is '
                           f"{(stamp - now) / NANOSECONDS:.6g} s ahead of the node's clock "
                           f'(max_stamp_lead {self.max_stamp_lead_ns / NANOSECONDS:g} s): '
                           'check the clock of the setpoint source')
        estimator = self.filter
        try:
            estimator.check_stamp(stamp)
        except StampError as exc:
            self._stamp_rejections += 1
            if not self.max_stamp_rejections or \
                    self._stamp_rejections < self.max_stamp_rejections:
                raise Rejected('stamp', str(exc)) from None
            self._restart_after_stamps(exc)
        q = self._positions_used(stamp, received)
        v_used, a = estimator.estimate(stamp, q, v)
        self.stamp, self.received, self._taken = stamp, received, (unstamped, q, v)
        return q, v_used, a

    def accept(self) -> None:
        """The setpoint taken last was served: counted, and it enters the estimator's
        history."""
        unstamped, q, v = self._taken
        self.filter.accept(self.stamp, q, v)
        self._stamp_rejections = 0
        self.last_pose = q
        self.last_time = time.monotonic()
        self.stopped = False
        self.counts.served(unstamped)

    def stopped_for(self, timeout: float, since: float = -math.inf) -> bool:
        """True, once, when no setpoint was accepted for ``timeout`` s: the stream counts as
        stopped and the estimator restarts (the next setpoint may carry any stamp). ``since``
        (monotonic): the silence counts from then at the earliest (the node itself did not
        run before: stopped or starved)."""
        if self.stopped or self.last_time is None:
            return False
        if time.monotonic() - max(self.last_time, since) < timeout:
            return False
        self.stopped = True
        self.filter.reset()
        self._stamp_rejections = 0
        return True

    def _positions_used(self, stamp: int, received: list[float]) -> list[float]:
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

    def _restart_after_stamps(self, exc: StampError) -> None:
        """max_stamp_rejections setpoints in a row came before the last accepted stamp: the
        source's clock went back (or an earlier stamp was far ahead). Start a new stream."""
        self.filter.reset()
        self._stamp_rejections = 0
        self.counts.totals['stamp_restarts'] += 1
        self.logger.warning(
            f'{self.max_stamp_rejections} setpoints in a row stamped before the previous '
            f'accepted one ({exc}): the estimator restarts, this setpoint starts a new stream')

    def _count_lost(self, info: dict) -> None:
        """Count setpoints lost before they were taken (:class:`.LostMessages`: the
        publisher's sequence numbers, while a single publisher feeds the topic)."""
        lost = self.lost.count(info)
        if lost:
            self.counts.problem('setpoints_lost', lost)
            self.counts.warnings.warn('lost', f'{lost} setpoint(s) lost before the node could '
                                              'take them (subscription queue full, or the '
                                              'network)')
