"""Computed-torque control: the model in the loop, gains on the acceleration.

``tau = H(q_m) (qdd_d + kd (qd_d - qd_m) + kp (q_d - q_m)) + B(q_m, qd_m)``, computed as the
core's inverse dynamics at the measured state with the commanded acceleration
(``torques(q_m, qd_m, qdd_d + kd e_dot + kp e)``: H and B of eq. (7) at the measured pose,
nothing else). With an exact model each joint's error obeys ``e'' + kd e' + kp e = 0``
(kp in 1/s², kd in 1/s; critically damped at kd = 2 √kp).

Redundant actuation: the law acts on the independent coordinates (the primary actuators,
``mechanism.primary``): their commanded accelerations ``w`` are expanded to every active
joint as the closure moves them, ``qdd_d + V_a w`` (``V_a``: the active rows of the
velocity basis at the measured pose, read from the core's joint rates ``last_pose``), and
the core distributes the efforts as eq. (7) does. Docs: docs/control.md.
"""
import math
from typing import Any

import numpy as np

from .config import NodeConfig
from .feedback import FeedbackMode, Setpoint, underdamped


class ComputedTorque(FeedbackMode):
    """``control_mode: computed_torque``."""

    def __init__(self, solver: Any, measured_solver: Any, config: NodeConfig) -> None:
        super().__init__(solver, measured_solver, config)
        self.kp = [float(k) for k in config.kp]
        self.kd = [float(k) for k in config.kd]
        mech = measured_solver.mechanism
        self.redundant = mech.is_redundant
        self.primary = list(mech.primary)

    def law(self, q_m: list[float], qd_m: list[float], setpoint: Setpoint | None,
            error: list[float], rate_error: list[float]) -> list[float]:
        assert setpoint is not None     # computed torque tracks a setpoint (tracks = True)
        commanded = [a + kd * de + kp * e for a, kd, de, kp, e in
                     zip(setpoint[2], self.kd, rate_error, self.kp, error)]
        if self.redundant:
            commanded = self._on_independent(q_m, qd_m, setpoint[2], commanded)
        return self.measured_solver.sample_torques(q_m, qd_m, commanded)

    def _on_independent(self, q_m: list[float], qd_m: list[float],
                        qdd_d: list[float], commanded: list[float]) -> list[float]:
        """qdd_d + V_a w, w the feedback accelerations of the primary actuators."""
        self.measured_solver.sample_torques(q_m, qd_m, qdd_d)   # the pose closed at q_m
        y = self.active_rate_map(self.primary)         # (M, dof) = V_a G: S u_p
        v_a = y @ np.linalg.inv(y[self.primary])      # G: the primary rows of y
        w = np.array([c - a for c, a in zip(commanded, qdd_d)])[self.primary]
        return (np.array(qdd_d) + v_a @ w).tolist()

    def gain_warnings(self) -> list[str]:
        joints = list(self.config.active_joints)
        used = self.primary if self.redundant else range(len(joints))   # the law's joints
        names = [joints[a] for a in used]
        kp, kd = [self.kp[a] for a in used], [self.kd[a] for a in used]
        ratios = [d / (2.0 * math.sqrt(p)) if p > 0 else math.inf for p, d in zip(kp, kd)]
        out = []
        slow = underdamped(names, ratios)
        if slow:
            out.append('computed_torque: underdamped (kd < 2 sqrt(kp)), the error overshoots: '
                       + ', '.join(slow))
        idle = [j for j, p, d in zip(names, kp, kd) if p == 0 and d == 0]
        if idle:
            out.append(f"computed_torque: kp and kd are 0 for {', '.join(idle)}: no feedback "
                       'there (feed-forward at the measured pose)')
        used_gains = set(zip(kp, kd))
        unused = [a for a in range(len(joints)) if a not in used and
                  (self.kp[a], self.kd[a]) not in used_gains]
        if unused:
            out.append('computed_torque: redundant actuation: the law acts on the primary '
                       f"actuators ({', '.join(names)}); the gains given for "
                       f"{', '.join(joints[a] for a in unused)} are not used")
        return out
