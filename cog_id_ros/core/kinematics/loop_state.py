"""The state of one closure constraint at a pose (LoopState), and the constraint a spherical
joint's quaternion adds (UnitQuaternion): what the kinds of joint write their closure rows
from (joints.py), below the closure itself (closure.py).
"""
from typing import Any

from ..value_types import Lane, LaneMatrix, Lanes, Ops, Twists
from . import kinematics as kin


class LoopState:
    """Per loop: closure point x (base frame), residual (6 lanes), and the cosine of the
    angle between the two attachment frames (a half-turn also zeroes the residual; 1.0
    where the orientation is free); universal: its two axes a, b (base frame)."""
    __slots__ = ('x', 'residual', 'cosine', 'a', 'b')
    x: Any
    residual: Any
    cosine: Lane
    a: Any
    b: Any


class UnitQuaternion:
    """The closure row of a spherical tree joint's quaternion (its LoopJoint's ``cycle``
    lists the four coordinates): |q|^2 - 1 = 0, velocity row 2 q . qdot, bias 2 |qdot|^2
    (d2/dt2 |q|^2 = 2 q . qddot + 2 |qdot|^2); the other five rows zero."""

    closure_equations = 1

    def closure_state(self, lp: kin.LoopJoint, frames: kin.Frames, q: Lanes,
                      ops: Ops) -> LoopState:
        st = LoopState()
        st.x = tuple(q[c] for c, _ in lp.cycle)
        st.residual = (sum(v * v for v in st.x) - 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        st.cosine = 1.0
        return st

    def closure_columns(self, lp: kin.LoopJoint, st: LoopState, frames: kin.Frames,
                        columns: LaneMatrix, row: int) -> None:
        for (c, _), v in zip(lp.cycle, st.x):
            columns[c][row] = 2.0 * v

    def closure_bias(self, lp: kin.LoopJoint, st: LoopState, frames: kin.Frames, twists: Twists,
                     bias_acc: Twists, qdot: Lanes) -> tuple[Lane, ...]:
        return (2.0 * sum(qdot[c] * qdot[c] for c, _ in lp.cycle), 0.0, 0.0, 0.0, 0.0, 0.0)
