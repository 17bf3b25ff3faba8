"""The timeout timers' view of this process's own stalls (no physics, no rclpy).

A stream's timeout (``setpoint_timeout``, ``measurement_timeout``) is judged on a timer.
A run of it more than two periods after the run before means this process was stopped
or starved meanwhile: what was sent to it then may still be on its way into the
subscription, so the timeout is judged a period after the process runs again, on what
arrived by then, and the stream's silence counts from then at the earliest. That wait is
granted once per silence of the stream: on a machine loaded for good every run is late,
and a silent stream must still time out (at most a period and one timeout later).
"""
import math
import time
from typing import Callable


class LateTimer:
    """The runs of one timeout timer of period ``period`` s (``clock``: monotonic s)."""

    def __init__(self, period: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.period = period
        self.clock = clock
        self.last_run: float | None = None
        #: when this process last ran again after a stop or starvation seen by this timer
        #: (-inf: never): the stream's silence counts from then at the earliest
        self.resumed = -math.inf

    def woke_late(self, heard: float | None) -> bool:
        """A run of the timer: whether it is to wait (it ran late, less than a period
        ago). ``heard``: when the stream last accepted a message (None: never); one wait
        per silence, none once it waited after that."""
        now = self.clock()
        if self.last_run is not None and now - self.last_run > 2.0 * self.period and \
                (heard is None or self.resumed < heard):
            self.resumed = now
        self.last_run = now
        return now - self.resumed < self.period
