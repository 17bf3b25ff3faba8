"""Continuation: following the assembly branch from the warm start to a setpoint.

A closed-link mechanism has several assembly modes (branches) for the same actuator
coordinates. The solver stays on the branch it is on by moving there in steps, each a
first-order prediction along the velocity basis V (``q + V dz``) corrected by Newton's
method on the loop equations. The rules, shared by every serial path of the solver:

* **Angles wrap for free.** A revolute coordinate closes the same loops at q and at
  q + 2 pi k, so an active revolute joint asked to move by more than pi is first moved
  by the multiple of 2 pi that leaves at most pi to go (:func:`wrapped_state`). The cost
  of a setpoint never grows with the absolute angle (a crank at 1e6 rad costs what a
  crank at 1 rad does), and a trajectory's first point is reached in at most pi.
* **A step bounds the motion of every joint**, not only the actuators: an actuator moves
  at most ``step`` rad (revolute) or ``step * length_scale`` m (prismatic), and the
  prediction moves no joint, passive ones included, by more than its own limit. Near a
  dead centre the passive joints move fast, so the steps get short there.
* **A step whose Newton correction is large is halved**: the corrected pose must lie
  within ``CORRECTOR_RATIO`` of a step limit of the prediction, otherwise Newton may have
  found another branch.
* **Bounded work.** At most ``MAX_STEPS`` steps (halvings included) per setpoint; a
  prismatic target farther than that many steps is refused at once. So a call costs a
  bounded amount of work whatever the input.
"""
import math
from typing import Any, Sequence

from ..value_types import Lane
from ..value_types import MechanismLike as Mechanism

#: a pose on its branch: (every coordinate, the velocity basis V there)
State = tuple[Sequence[Lane], Any]

#: largest Newton correction of a step, as a fraction of the joints' step limits
CORRECTOR_RATIO = 0.5

#: steps (including halved retries) allowed for one setpoint
MAX_STEPS = 200

#: the shortest step tried (in step limits) before a move counts as unreachable
MIN_STEP = 1.0 / 64.0

#: largest |revolute actuator coordinate| (rad) accepted: beyond it a float64 holds the
#: angle to no better than 1.2e-7 rad, and 2 pi multiples cannot be taken off exactly
MAX_ANGLE = 1e9

TWO_PI = 2.0 * math.pi


def length_scale(mechanism: 'Mechanism') -> float:
    """A length typical of the mechanism (m): the mean of its nonzero joint offsets.

    Prismatic continuation steps are ``step * length_scale``, so a mechanism of 5 cm
    takes steps of millimetres and one of 5 m steps of decimetres.
    """
    lengths: list[float] = []
    for spec in mechanism.joint_specs:
        for xyz in (spec.parent_xyz, spec.child_xyz):
            norm = math.sqrt(sum(x * x for x in xyz))
            if norm > 0.0:
                lengths.append(norm)
    return sum(lengths) / len(lengths) if lengths else 1.0


def joint_step_limits(mechanism: 'Mechanism', step: float) -> list[float]:
    """Per coordinate, the largest motion of one continuation step, as its joint's kind
    shares it out (joints.py: rad, or m for a length; a quaternion's components move by
    half the angle: step / 2)."""
    scale = length_scale(mechanism)
    return [kind.step_share(step, scale) for kind in mechanism.model.coordinate_kinds]


def wrapping_actuators(mechanism: 'Mechanism') -> list[int]:
    """Indices into active_joints of the actuators whose coordinates wrap at 2 pi (the
    revolute ones: ``kind.wraps``)."""
    return [a for a, kind in enumerate(mechanism.active_kinds) if kind.wraps]


def wrapped_state(mechanism: 'Mechanism', wrapping: Sequence[int], state: State,
                  target: Sequence[float]) -> State:
    """``state`` with every revolute actuator moved by the multiple of 2 pi that brings it
    within pi of ``target``; the same state object when none has to move."""
    q, basis = state
    shifted: list[Lane] | None = None
    for a in wrapping:
        j = mechanism.active_index[a]
        turns = round((target[a] - q[j]) / TWO_PI)
        if turns:
            if shifted is None:
                shifted = list(q)
            shifted[j] = q[j] + TWO_PI * turns
    return state if shifted is None else (shifted, basis)


def prediction(mechanism: 'Mechanism', state: State,
               goal: Sequence[Lane]) -> tuple[list[Lane], list[Lane]]:
    """The first-order predictor ``q + V dz`` (primary actuators at ``goal``) and the
    increment of every joint it makes."""
    q, basis = state
    pairs = mechanism.primary_pairs
    if len(pairs) == 1:
        (a, j), = pairs
        d = goal[a] - q[j]
        moved = [row[0] * d for row in basis]
    else:
        dz = [goal[a] - q[j] for a, j in pairs]
        moved = [sum(b * d for b, d in zip(row, dz)) for row in basis]
    predicted = [x + dx for x, dx in zip(q, moved)]
    for a, j in pairs:
        predicted[j] = goal[a]
    return predicted, moved


def fits_one_step(mechanism: 'Mechanism', limits: Sequence[float], state: State,
                  target: Sequence[float], moved: Sequence[float]) -> bool:
    """True when the move to ``target`` is one step: no primary actuator moves, and no joint
    is predicted to move (``moved``, from :func:`prediction`), by more than its limit.

    Only the ``dof`` primary actuators are moved by continuation; with redundant actuation
    the others follow from the closure, and the projection takes care of their targets
    (an inconsistent target would otherwise never be "reached")."""
    q = state[0]
    for a, j in mechanism.primary_pairs:
        if not abs(target[a] - q[j]) <= limits[j]:
            return False
    for dx, lim in zip(moved, limits):
        if not abs(dx) <= lim:
            return False
    return True


def step_ratio(mechanism: 'Mechanism', limits: Sequence[float], state: State,
               target: Sequence[float], moved: Sequence[float]) -> float:
    """How many step limits the move to ``target`` is: the largest of |actuator motion| and
    |predicted joint motion| over the joints' limits."""
    return max(actuator_ratio(mechanism, limits, state, target),
               max(abs(dx) / lim for dx, lim in zip(moved, limits)))


def actuator_ratio(mechanism: 'Mechanism', limits: Sequence[float], state: State,
                   target: Sequence[float]) -> float:
    """The actuators' share of :func:`step_ratio` (the steps a straight move needs at least)."""
    q = state[0]
    return max(abs(target[a] - q[j]) / limits[j]
               for a, j in zip(mechanism.primary, mechanism.primary_joints))


def correction_bounds(limits: Sequence[float]) -> list[float]:
    """Per joint, the largest Newton correction of a step: CORRECTOR_RATIO of its limit."""
    return [CORRECTOR_RATIO * lim for lim in limits]


def correction_ok(corrected: Sequence[Lane], predicted: Sequence[Lane],
                  bounds: Sequence[float]) -> bool:
    """True when Newton's correction of the prediction stays within ``bounds`` (from
    :func:`correction_bounds`) for every joint: the step stayed on its branch."""
    for x, p, b in zip(corrected, predicted, bounds):
        if not abs(x - p) <= b:
            return False
    return True


def intermediate_goal(mechanism: 'Mechanism', state: State, target: Sequence[float],
                      fraction: float) -> list[float]:
    """The active coordinates ``fraction`` of the way from ``state`` to ``target``."""
    q = state[0]
    return [q[j] + (t - q[j]) * fraction for t, j in zip(target, mechanism.active_index)]
