"""Control modes: what cog_id_node commands for a setpoint (one small object per mode).

The node serves every setpoint the same way -- the stream checks and estimates it
(:class:`.setpoint_stream.SetpointStream`: positions, velocities and accelerations of the
active joints), the mode turns it into efforts, the node clips and publishes them -- so
a mode only says how efforts follow from the setpoint, and what
holds the last pose when the stream stops (``timeout_behavior: hold``). A feedback mode
(computed torque, PD plus feed-forward, gravity compensation from measured joint states)
is one more class with these two methods that also reads the measured state.
"""
from typing import Any, Protocol, Sequence

import numpy as np


class Mode(Protocol):
    """What the node asks of a mode (both may raise the core's CogIdError: a rejection)."""

    def efforts(self, positions: list[float], velocities: list[float],
                accelerations: list[float]) -> list[float]:
        """The efforts of the active joints for the setpoint (lists in active joint order)."""

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The efforts that hold the active joints at ``pose`` (a served one)."""


class FeedForward:
    """Open loop: the efforts the setpoint's motion needs, tau = H(q) qdd + B(q, qd)
    (the core's control-rate call, warm-started from the previous setpoint)."""

    def __init__(self, solver: Any) -> None:
        self.solver = solver
        # efforts(positions, velocities, accelerations) is the solver's call itself: no
        # frame of its own on the per-setpoint path
        self.efforts = solver.sample_torques

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The gravity-holding efforts of ``pose``: zero velocity and acceleration."""
        zeros = [0.0] * len(pose)
        return self.solver.torques(pose, zeros, zeros)
