"""Control modes: what cog_id_node commands (one small object per mode).

The node serves every setpoint the same way -- the stream checks and estimates it
(:class:`.setpoint_stream.SetpointStream`: positions, velocities and accelerations of the
active joints), the mode turns it into efforts, the node clips and publishes them -- so
a mode says how efforts follow from the setpoint, and what holds the last pose when the
stream stops (``timeout_behavior: hold``). The feedback modes (``control_mode``:
:class:`.computed_torque.ComputedTorque`, :class:`.pd_feedforward.PdFeedForward`,
:class:`.gravity_compensation.GravityCompensation`, on :class:`.feedback.FeedbackMode`)
answer a setpoint with None (it is put in force) and command from each measured state
(``command``); :func:`make_mode` builds the one ``control_mode`` names.
"""
from typing import Any, Callable, Protocol, Sequence

import numpy as np

from .computed_torque import ComputedTorque
from .config import NodeConfig
from .gravity_compensation import GravityCompensation
from .pd_feedforward import PdFeedForward


class Mode(Protocol):
    """What the node asks of a mode (both may raise the core's CogIdError: a rejection)."""

    #: whether commands follow measured states (then ``command(q_m, qd_m)`` gives them)
    measured: bool

    def efforts(self, positions: list[float], velocities: list[float],
                accelerations: list[float]) -> list[float] | None:
        """The efforts of the active joints for the setpoint (lists in active joint order),
        or None: a feedback mode put the setpoint in force."""

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The efforts that hold the active joints at ``pose`` (a served one)."""


class FeedForward:
    """Open loop: the efforts the setpoint's motion needs, tau = H(q) qdd + B(q, qd)
    (the core's control-rate call, warm-started from the previous setpoint)."""

    measured = False

    def __init__(self, solver: Any) -> None:
        self.solver = solver
        # efforts(positions, velocities, accelerations) is the solver's call itself: no
        # frame of its own on the per-setpoint path
        self.efforts = solver.sample_torques

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The gravity-holding efforts of ``pose``: zero velocity and acceleration."""
        zeros = [0.0] * len(pose)
        return self.solver.torques(pose, zeros, zeros)


#: control_mode -> the feedback mode's class
FEEDBACK_MODES = {'computed_torque': ComputedTorque, 'pd_feedforward': PdFeedForward,
                  'gravity_compensation': GravityCompensation}


def make_mode(config: NodeConfig, solver: Any, measured_solver: Callable[[], Any]) -> Any:
    """The mode the control_mode parameter names; ``solver`` serves setpoints,
    ``measured_solver()`` makes the solver of the measured states (feedback modes only)."""
    if config.control_mode == 'feedforward':
        return FeedForward(solver)
    return FEEDBACK_MODES[config.control_mode](solver, measured_solver(), config)
