"""Coupled joints (URDF's ``<mimic>``): one joint's coordinate a linear function of another's.

    q_follower = multiplier * q_leader + offset

A gripper's fingers, a differential's two sides: the follower moves with its leader as if
geared to it. The coupling is one closure equation, written in the rows of the closure
equations like a loop's (closure.py), so everything that follows the loops follows it: the
follower is solved from its leader in every pose, its rate and acceleration from the
leader's, its share of the torques goes to the joints that drive the leader, and it appears
in every output (JointState, CSV) at the coupled value. A coupled joint that is also an
actuator makes the actuators dependent: a redundantly actuated mechanism (its setpoints
must agree with the coupling), as for any other closure (degrees_of_freedom.py).

Native parameters (docs/mechanism.md): ``joints.<follower>.mimic`` names the leader,
``joints.<follower>.mimic_multiplier`` (default 1) and ``joints.<follower>.mimic_offset``
(default 0, rad or m) the coefficients; both joints revolute or prismatic.
"""
from typing import Any

from ..errors import MechanismConfigError
from ..value_types import Lane, LaneMatrix, Lanes, MechanismLike, Ops, Twists
from . import kinematics as kin
from .loop_state import LoopState
from .parameters import ParameterReader

#: the keys a joint with a coordinate reads for its coupling
KEYS = ('mimic', 'mimic_multiplier', 'mimic_offset')


class Coupling:
    """The closure row of one coupled joint: residual q_f - m q_l - o, velocity row
    qdot_f - m qdot_l, bias 0 (the equation is linear); the other five rows zero."""

    closure_equations = 1
    name = 'coupling'

    def __init__(self, follower: int, leader: int, multiplier: float, offset: float) -> None:
        self.follower, self.leader = follower, leader
        self.multiplier, self.offset = multiplier, offset

    def closure_state(self, lp: kin.LoopJoint, frames: kin.Frames, q: Lanes,
                      ops: Ops) -> LoopState:
        st = LoopState()
        st.x = ()
        st.residual = (q[self.follower] - self.multiplier * q[self.leader] - self.offset,
                       0.0, 0.0, 0.0, 0.0, 0.0)
        st.cosine = 1.0
        return st

    def closure_columns(self, lp: kin.LoopJoint, st: LoopState, frames: kin.Frames,
                        columns: LaneMatrix, row: int) -> None:
        columns[self.follower][row] = 1.0
        columns[self.leader][row] = -self.multiplier

    def closure_bias(self, lp: kin.LoopJoint, st: LoopState, frames: kin.Frames,
                     twists: Twists, bias_acc: Twists, qdot: Lanes) -> tuple[Lane, ...]:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def constraint(name: str, follower: int, leader: int, multiplier: float,
               offset: float) -> kin.LoopJoint:
    """The constraint of the closure equations that couples coordinate ``follower`` to
    ``leader`` (indices into the model's coordinates)."""
    kind: Any = Coupling(follower, leader, multiplier, offset)
    return kin.LoopJoint(None, kin.BASE, kin.BASE, kind, name,
                         cycle=[(follower, 1.0), (leader, -multiplier)])


def read_couplings(mech: MechanismLike, r: ParameterReader, bound: float) -> None:
    """``mech.couplings``: (follower, leader, multiplier, offset) of every joint that
    ``joints.<name>.mimic`` couples to another, checked (multiplier and offset within
    +-``bound``, the mechanism's bound on coordinates)."""
    mech.couplings = []
    for spec in mech.joint_specs + mech.closure_specs:
        prefix = f'joints.{spec.name}.'
        leader = r.string(prefix + 'mimic')
        if leader is None:
            continue
        if not spec.kind.has_coordinate:
            raise MechanismConfigError(
                prefix + 'mimic', f'a {spec.kind.name} joint has no coordinate to couple '
                                  f'(only revolute and prismatic joints can mimic)')
        if leader not in mech.joints:
            raise MechanismConfigError(
                prefix + 'mimic', f"'{leader}' is not a revolute or prismatic joint of "
                                  f'mechanism.joints')
        if leader == spec.name:
            raise MechanismConfigError(prefix + 'mimic', 'a joint cannot mimic itself')
        values = []
        for key, default in (('mimic_multiplier', 1.0), ('mimic_offset', 0.0)):
            value = r.number(prefix + key, default=default)
            if abs(value) > bound:
                raise MechanismConfigError(prefix + key, f'must lie within +-{bound:g}, got '
                                                         f'{value!r}')
            values.append(value)
        mech.couplings.append((spec.name, leader, *values))
