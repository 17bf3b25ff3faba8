"""The node's solver for ``command_space: joint``: joint-space motion in, motor efforts out.

:class:`JointSpaceSolver` has the calls the node, its control modes and its report make on
an ``InverseDynamics`` (``sample_torques``, ``torques``, ``last_pose``, ``evaluate``,
``reset``, ``equation_of_motion``, ``forward_dynamics``, ``backend``,
``check_position_limits``, ``mechanism``), taking the positions, velocities and
accelerations of ``mechanism.joint_space`` and returning the motors' efforts (in
``mechanism.active_joints`` order). The physics is the core's :class:`Transmission`:
the joint-space efforts of the whole mechanism (its joints' solver, warm-started from the
previous sample as the node's solver is) carried to the motors, tau_m = J^T tau_q, exactly
what ``InverseDynamics.torques(q, qd, qdd, space='joint')`` computes. So the node serves a
joint-space stream with the same code as a motor one: only the commanded joints' names
(``NodeConfig.active_joints``) and this solver differ.
"""
from typing import Any, Optional, Sequence

import numpy as np

from ..core import Transmission


class JointSpaceSolver:
    """InverseDynamics' per-setpoint calls with joint-space arguments and motor efforts.

    ``mechanism``: the node's (it names ``joint_space``). Its ``mechanism`` attribute is
    the mechanism driven at its joint space (its active joints: the joint space, not
    redundant), which is what the control modes' laws read (joint names, redundancy).
    Positions of the joint space are checked against their limits (``joints.<j>.lower``,
    ``upper``), the motors' positions they lead to against theirs, unless
    ``check_position_limits`` is set False (a feedback mode's measured solver).
    """

    def __init__(self, mechanism: Any, backend: str = 'auto') -> None:
        self.transmission = Transmission(mechanism, backend)
        self.joints = self.transmission.joints          # q (joint space) -> every joint
        self.actuators = self.transmission.actuators    # theta (motors) -> every joint
        self.mechanism = self.transmission.joint_mechanism
        self.joints.check_position_limits = True       # the commanded joints' limits
        self._motors = list(mechanism.active_index)     # the motors' rows of a pose

    @property
    def backend(self) -> str:
        return self.actuators.backend

    @property
    def check_position_limits(self) -> bool:
        return bool(self.joints.check_position_limits)

    @check_position_limits.setter
    def check_position_limits(self, value: bool) -> None:
        self.joints.check_position_limits = value
        self.actuators.check_position_limits = value

    # --- the node's per-sample calls ---------------------------------------------------

    def sample_torques(self, q: Sequence[float], qd: Optional[Sequence[float]] = None,
                       qdd: Optional[Sequence[float]] = None) -> list[float]:
        """The motors' efforts (a list) of the joint-space motion (q, qd, qdd): the
        mechanism's joint-space efforts at its closed pose, J(theta)^T tau_q."""
        tau_q = self.joints.sample_torques(q, qd, qdd)
        return self.actuator_efforts(tau_q).tolist()

    def actuator_efforts(self, tau_q: Sequence[float]) -> np.ndarray:
        """tau_m = J^T tau_q at the pose solved last (the motors' share of joint-space
        efforts, the linkage massless: pd terms of a joint-space law)."""
        return self.transmission.actuator_efforts(self.actuator_positions(), tau_q)

    def actuator_positions(self) -> list[float]:
        """The motors' positions at the pose solved last."""
        pose = self.joints.last_pose()[0]
        return [pose[i] for i in self._motors]

    def actuator_state(self, qd: Sequence[float]) -> tuple[list[float], list[float]]:
        """(motor positions, motor rates theta_dot = K qd) at the pose solved last, for
        the joint-space rates ``qd``: what joint_effort carries."""
        pose, rates = self.joints.last_pose(qd)
        assert rates is not None
        return [pose[i] for i in self._motors], [rates[i] for i in self._motors]

    def last_pose(self, qd: Optional[Sequence[float]] = None
                  ) -> tuple[list[float], Optional[list[float]]]:
        """(every joint's position, every joint's rate for the joint-space rates ``qd``)
        at the pose solved last (InverseDynamics.last_pose with joint-space rates)."""
        return self.joints.last_pose(qd)

    # --- whole calls -------------------------------------------------------------------

    def torques(self, q: Any, qd: Any = None, qdd: Any = None) -> np.ndarray:
        """Transmission.torques: the motors' efforts (M,) or (N, M) of a joint-space motion."""
        return self.transmission.torques(q, qd, qdd)

    def forward_dynamics(self, q: Any, qd: Any, tau: Any) -> np.ndarray:
        """Joint-space accelerations under the motors' efforts ``tau``."""
        return self.transmission.forward_dynamics(q, qd, tau)

    def evaluate(self, q: Any, *args: Any, **kwargs: Any) -> Any:
        """The joints' solver's evaluate at joint-space ``q`` (closure health of a pose)."""
        return self.joints.evaluate(q, *args, **kwargs)

    def equation_of_motion(self, q: Any, qd: Any = None) -> Any:
        """(H, B) in joint space at ``q``."""
        return self.joints.equation_of_motion(q, qd)

    def reset(self) -> None:
        """Both solvers back to the assembled pose (their warm starts)."""
        self.joints.reset()
        self.actuators.reset()
