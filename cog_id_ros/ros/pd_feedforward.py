"""PD plus feed-forward: the setpoint's inverse dynamics and a joint-space PD on the error.

``tau = tau(q_d, qd_d, qdd_d) + pd_kp (q_d - q_m) + pd_kd (qd_d - qd_m)``: the feed-forward
efforts are the core's inverse dynamics of the setpoint (computed when it arrives, with the
setpoint solver); the measured pose is solved too (its loops must close: a measured state
that cannot is rejected). Gains in N m/rad and N m s/rad (N/m, N s/m for prismatic joints).
Linearised at a pose, each joint's error obeys ``H_jj e'' + pd_kd e' + pd_kp e ≈ 0``:
underdamped below ``pd_kd = 2 √(pd_kp H_jj)`` (checked at ``initial_positions`` at
start-up). Redundant actuation: the PD efforts ``p`` act through the generalized force
they make on the independent coordinates, distributed as eq. (7) distributes every force,
``S_a^T p`` (the weighted minimum-norm efforts of that force: actuators are not set
against each other by the feedback). Docs: docs/control.md.
"""
import math
from typing import Any

import numpy as np

from .config import NodeConfig
from .feedback import FeedbackMode, Setpoint, underdamped


class PdFeedForward(FeedbackMode):
    """``control_mode: pd_feedforward``."""

    def __init__(self, solver: Any, measured_solver: Any, config: NodeConfig) -> None:
        super().__init__(solver, measured_solver, config)
        self.kp = [float(k) for k in config.pd_kp]
        self.kd = [float(k) for k in config.pd_kd]
        self.redundant = measured_solver.mechanism.is_redundant
        #: command_space joint: the pd efforts are the joint space's, carried to the motors
        self.to_motors = getattr(measured_solver, 'actuator_efforts', None)

    def law(self, q_m: list[float], qd_m: list[float], setpoint: Setpoint | None,
            error: list[float], rate_error: list[float]) -> list[float]:
        assert setpoint is not None     # PD plus feed-forward tracks a setpoint
        # the measured pose closed (branch continuity), or the core's error: no command
        self.measured_solver.sample_torques(q_m, qd_m, self.zeros)
        pd = [kp * e + kd * de for kp, e, kd, de in zip(self.kp, error, self.kd, rate_error)]
        if self.redundant:      # on the independent coordinates, distributed as eq. (7)
            pd = (self.active_rate_map().T @ np.array(pd)).tolist()
        elif self.to_motors is not None:    # joint-space efforts: the motors' share, J^T pd
            pd = self.to_motors(pd).tolist()
        return [ff + p for ff, p in zip(setpoint[3], pd)]

    def gain_warnings(self) -> list[str]:
        joints = self.config.active_joints
        if not any(self.kp) and not any(self.kd):
            return ['pd_feedforward: pd_kp and pd_kd are 0: no feedback (the feed-forward '
                    'efforts at the measured rate)']
        solver = self.measured_solver
        start = solver.last_pose()[0]
        index = [solver.mechanism.joints.index(j) for j in joints]
        inertia, _ = solver.equation_of_motion([start[i] for i in index])
        solver.reset()
        ratios = [kd / (2.0 * math.sqrt(kp * h)) if kp > 0 and h > 0 else math.inf
                  for kp, kd, h in zip(self.kp, self.kd, inertia.diagonal())]
        slow = underdamped(joints, ratios)
        if not slow:
            return []
        return ['pd_feedforward: underdamped at initial_positions (pd_kd < 2 sqrt(pd_kp H_jj)), '
                'the error overshoots: ' + ', '.join(slow)]
