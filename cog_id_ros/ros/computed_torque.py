"""Computed-torque control: the model in the loop, gains on the acceleration.

``tau = H(q_m) (qdd_d + kd (qd_d - qd_m) + kp (q_d - q_m)) + B(q_m, qd_m)``, computed as the
core's inverse dynamics at the measured state with the commanded acceleration
(``torques(q_m, qd_m, qdd_d + kd e_dot + kp e)``: H and B of eq. (7) at the measured pose,
nothing else). With an exact model each joint's error obeys ``e'' + kd e' + kp e = 0``
(kp in 1/s², kd in 1/s; critically damped at kd = 2 √kp). Docs: docs/control.md.
"""
import math
from typing import Any

from .config import NodeConfig
from .feedback import FeedbackMode, Setpoint, underdamped


class ComputedTorque(FeedbackMode):
    """``control_mode: computed_torque``."""

    def __init__(self, solver: Any, measured_solver: Any, config: NodeConfig) -> None:
        super().__init__(solver, measured_solver, config)
        self.kp = [float(k) for k in config.kp]
        self.kd = [float(k) for k in config.kd]

    def law(self, q_m: list[float], qd_m: list[float], setpoint: Setpoint | None,
            error: list[float], rate_error: list[float]) -> list[float]:
        assert setpoint is not None     # computed torque tracks a setpoint (tracks = True)
        commanded = [a + kd * de + kp * e for a, kd, de, kp, e in
                     zip(setpoint[2], self.kd, rate_error, self.kp, error)]
        return self.measured_solver.sample_torques(q_m, qd_m, commanded)

    def gain_warnings(self) -> list[str]:
        joints = self.config.active_joints
        ratios = [kd / (2.0 * math.sqrt(kp)) if kp > 0 else math.inf
                  for kp, kd in zip(self.kp, self.kd)]
        out = []
        slow = underdamped(joints, ratios)
        if slow:
            out.append('computed_torque: underdamped (kd < 2 sqrt(kp)), the error overshoots: '
                       + ', '.join(slow))
        idle = [j for j, kp, kd in zip(joints, self.kp, self.kd) if kp == 0 and kd == 0]
        if idle:
            out.append(f"computed_torque: kp and kd are 0 for {', '.join(idle)}: no feedback "
                       'there (feed-forward at the measured pose)')
        return out
