"""Gravity compensation: hold any pose, by hand or by a setpoint-free plant.

``tau = B(q_m, 0)``: the core's inverse dynamics at the measured pose at rest,
``torques(q_m, 0, 0)``, the passive joints solved from the measured actuators. No gains,
no setpoint needed (setpoints, when sent, only give the tracking error in /diagnostics),
no measured velocities needed. Docs: docs/control.md.
"""
from .feedback import FeedbackMode, Setpoint


class GravityCompensation(FeedbackMode):
    """``control_mode: gravity_compensation``."""

    needs_velocities = False
    tracks = False

    def law(self, q_m: list[float], qd_m: list[float], setpoint: Setpoint | None,
            error: list[float], rate_error: list[float]) -> list[float]:
        return self.measured_solver.sample_torques(q_m, self.zeros, self.zeros)
