"""The efforts cog_sim_node integrates: effort messages checked, then held (no ROS node, no
physics).

:func:`command_efforts` (std_msgs/Float64MultiArray) and :func:`named_efforts`
(sensor_msgs/JointState) turn a message into one finite effort per active joint, or raise
:class:`EffortRejected` with a ``reason`` of ``EFFORT_REASONS`` (the key counted in
diagnostics): nothing of a rejected message is ever integrated. :class:`EffortHold` is
the zero-order hold: the newest accepted efforts, clipped to the effort limits, act on
every step until the stream stops (``effort_timeout`` of simulated time), then zeros or
the last efforts (``effort_timeout_behavior``).
"""
import math
from typing import Any, Sequence

import numpy as np

from .conversions import JointSelector, Rejected, clip_efforts

#: every reason an effort message can be rejected for, as counted in diagnostics
EFFORT_REASONS = {
    'length': 'not one effort per active joint (effort_command: the length of data; '
              'joint_effort_command: the length of effort against that of name)',
    'non_finite': 'an effort is NaN or infinite',
    'magnitude': 'an effort of magnitude above max_effort',
    'names': 'joint_effort_command: no names, a name twice, or an active joint missing',
}


class EffortRejected(ValueError):
    """An effort message that is not integrated: ``reason`` is a key of EFFORT_REASONS."""

    def __init__(self, reason: str, message: str) -> None:
        assert reason in EFFORT_REASONS, reason
        self.reason = reason
        super().__init__(message)


def checked_efforts(values: Sequence[float], names: Sequence[str], max_effort: float
                    ) -> list[float]:
    """``values`` (one per active joint, named ``names``) as floats; EffortRejected when one
    is not finite or larger than ``max_effort`` in magnitude."""
    out = [float(v) for v in values]
    for name, value in zip(names, out):
        if not math.isfinite(value):
            raise EffortRejected('non_finite', f'effort of {name} is {value} (must be finite)')
    for name, value in zip(names, out):
        if abs(value) > max_effort:
            raise EffortRejected('magnitude', f'effort of {name} is {value:g}, beyond '
                                              f'max_effort ({max_effort:g})')
    return out


def command_efforts(msg: Any, active_joints: Sequence[str], max_effort: float) -> list[float]:
    """The efforts of a Float64MultiArray (``data`` in ``active_joints`` order; its layout
    is not read); raises EffortRejected."""
    data = msg.data
    if len(data) != len(active_joints):
        raise EffortRejected('length', f'{len(data)} efforts for {len(active_joints)} active '
                                       f"joints ({', '.join(active_joints)})")
    return checked_efforts(data, active_joints, max_effort)


def named_efforts(msg: Any, selector: JointSelector, max_effort: float) -> list[float]:
    """The efforts of the active joints of a JointState (``name`` and ``effort``, any
    order, other joints ignored; ``position`` and ``velocity`` not read); raises
    EffortRejected."""
    names, effort = msg.name, msg.effort
    if len(effort) != len(names):
        raise EffortRejected('length', f'{len(names)} names but {len(effort)} efforts')
    try:
        index = selector.indices(names)
    except Rejected as exc:     # empty, a name twice, an active joint missing
        raise EffortRejected('names', str(exc)) from None
    return checked_efforts([effort[i] for i in index], selector.active_joints, max_effort)


class EffortHold:
    """The efforts acting on the next step: the newest accepted ones, clipped to
    ``limits`` (None: no limit), until the stream stops.

    ``timeout``: s of simulated time after the last accepted message at which the stream
    counts as stopped (0: never); ``behavior``: then 'zero' or 'hold' (the last efforts).
    Times are simulated times (s), as the caller passes them.
    """

    def __init__(self, size: int, timeout: float, behavior: str,
                 limits: np.ndarray | None) -> None:
        self.size, self.timeout, self.behavior, self.limits = size, timeout, behavior, limits
        self.timeouts = 0           # times the stream stopped
        self.reset()

    def reset(self) -> None:
        """No effort held, no stream (as at start): zeros act until a message comes."""
        self.efforts = [0.0] * self.size
        self.received_at: float | None = None     # simulated time of the last accepted
        self.stopped = False
        self.accepted = 0                         # messages accepted since then

    def accept(self, efforts: list[float], now: float) -> bool:
        """Hold ``efforts`` (checked) from simulated time ``now`` on; True if clipped."""
        clipped = False
        if self.limits is not None:
            tau = np.array(efforts)
            clipped = clip_efforts(tau, self.limits)
            if clipped:
                efforts = tau.tolist()
        self.efforts, self.received_at, self.stopped = efforts, now, False
        self.accepted += 1
        return clipped

    def acting(self, now: float) -> list[float]:
        """The efforts for the step from simulated time ``now``; the first call after the
        stream stopped counts a timeout."""
        if self.received_at is not None and self.timeout > 0.0 and not self.stopped \
                and now - self.received_at >= self.timeout:
            self.stopped = True
            self.timeouts += 1
        if self.stopped and self.behavior == 'zero':
            return [0.0] * self.size
        return self.efforts

    def state(self) -> str:
        """'no effort yet', 'receiving' or 'stopped (zero|hold)', for diagnostics."""
        if self.received_at is None:
            return 'no effort yet'
        return f'stopped ({self.behavior})' if self.stopped else 'receiving'
