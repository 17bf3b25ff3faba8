"""What every feedback mode shares: the setpoint in force, the measured pose solved, the
tracking error, the gain checks at start-up (the laws: one small file each).

A feedback mode is a :class:`.modes.Mode` whose ``efforts`` for a setpoint is None: the
setpoint is checked (its loops closed by the node's setpoint solver, warm-started along
the setpoint stream) and put in force, and commands come from :meth:`FeedbackMode.command`,
one per measured state: the law of the mode (``law``) at the measured positions and
velocities ``q_m``, ``qd_m`` of the active joints, with the setpoint ``q_d``, ``qd_d``,
``qdd_d`` in force. The passive joints are solved from ``q_m`` by a solver of the measured
stream's own (warm-started from the previous measured pose: branch continuity), so a
measured state whose loops cannot close raises the core's error (a rejection, no command).

Before the first setpoint a mode that tracks one holds the first measured pose at rest
(``q_d = q_m``, ``qd_d = qdd_d = 0``); when the setpoint stream stops (``setpoint_timeout``)
the last setpoint stays in force at rest. Redundant mechanisms: the core's solve projects
the measured active coordinates on the loop closure (docs/api.md) and distributes the
efforts as eq. (7) does (``tau = S^T Q``, weighted minimum norm), so each law acts on the
independent coordinates.
"""
import math
from typing import Any, Sequence

import numpy as np

from .config import NodeConfig
from .conversions import nearest_turn

#: a setpoint in force: positions, velocities, accelerations and its feed-forward efforts
Setpoint = tuple[list[float], list[float], list[float], list[float]]


class FeedbackMode:
    """The base of the feedback modes; a subclass gives ``law`` (and ``tracks``)."""

    #: commands follow measured states (the node subscribes measured_joint_states)
    measured = True
    #: the law uses the measured velocities (else a measurement may carry none)
    needs_velocities = True
    #: the law needs a setpoint (before the first one, the first measured pose is held)
    tracks = True

    def __init__(self, solver: Any, measured_solver: Any, config: NodeConfig) -> None:
        self.solver = solver                      # setpoints: the node's solver
        self.measured_solver = measured_solver    # measured states: a solver of their own
        # a measured pose beyond a position limit is commanded from (the law pulls it back
        # toward the setpoint, which is checked against the limits): refused, the robot
        # would be left without its controller exactly where it overshot
        measured_solver.check_position_limits = False
        self.config = config
        self.unwrap = list(config.unwrap)
        self.zeros = [0.0] * len(config.active_joints)
        self.setpoint: Setpoint | None = None
        #: q_d - q_m of each active joint at the last command (empty: no setpoint yet)
        self.error: list[float] = []

    def efforts(self, positions: list[float], velocities: list[float],
                accelerations: list[float]) -> None:
        """Put the setpoint in force (its loops closed, its feed-forward efforts computed:
        the core's errors are its rejection); no command: commands follow measurements."""
        tau = self.solver.sample_torques(positions, velocities, accelerations)
        self.setpoint = (positions, velocities, accelerations, tau)

    def setpoints_stopped(self) -> None:
        """The setpoint stream stopped: its last pose stays in force, at rest."""
        if self.setpoint is not None:
            self.efforts(self.setpoint[0], self.zeros, self.zeros)

    def command(self, q_m: list[float], qd_m: list[float]) -> list[float]:
        """The efforts of the active joints at measured state (q_m, qd_m); raises the core's
        errors (a rejection: the measured pose cannot be closed, ...)."""
        if self.setpoint is None and self.tracks:
            self.efforts(q_m, self.zeros, self.zeros)       # hold where it is
        setpoint = self.setpoint
        if setpoint is None:
            self.error = []
            return self.law(q_m, qd_m, None, self.zeros, self.zeros)
        q_d, qd_d = setpoint[0], setpoint[1]
        error = [nearest_turn(d, m) - m if wrap else d - m
                 for d, m, wrap in zip(q_d, q_m, self.unwrap)]
        rate_error = [d - m for d, m in zip(qd_d, qd_m)]
        efforts = self.law(q_m, qd_m, setpoint, error, rate_error)
        self.error = error
        return efforts

    def law(self, q_m: list[float], qd_m: list[float], setpoint: Setpoint | None,
            error: list[float], rate_error: list[float]) -> list[float]:
        """The mode's efforts (``error``: q_d - q_m, ``rate_error``: qd_d - qd_m)."""
        raise NotImplementedError

    def active_rate_map(self, columns: Sequence[int] | None = None) -> np.ndarray:
        """S_a (M x M): the active rows of the joint-rate map S (qdot = S thetadot, eq. (7)'s
        distribution is tau = S^T Q) at the measured pose solved last; column a is the
        rates of the active joints when active joint a moves at unit rate, as the closure
        moves it (the identity without redundant actuation). ``columns``: only those."""
        solver = self.measured_solver
        joints = solver.mechanism.joints
        rows = [joints.index(j) for j in self.config.active_joints]
        out = []
        for a in range(len(rows)) if columns is None else columns:
            unit = [0.0] * len(rows)
            unit[a] = 1.0
            rates = solver.last_pose(unit)[1]
            out.append([rates[i] for i in rows])
        return np.array(out).T

    def hold(self, pose: Sequence[float]) -> np.ndarray:
        """The gravity-holding efforts of ``pose`` (the last measured one), B(q, 0)."""
        return self.measured_solver.torques(list(pose), self.zeros, self.zeros)

    def gain_warnings(self) -> list[str]:
        """What the start-up log warns about the mode's gains (none by default)."""
        return []


def underdamped(joints: Sequence[str], ratios: Sequence[float]) -> list[str]:
    """'<joint> (damping ratio r)' of each joint whose closed loop would be underdamped."""
    return [f'{j} (damping ratio {r:.3g})' for j, r in zip(joints, ratios)
            if math.isfinite(r) and r < 1.0]
