"""Assembly at load: the mechanism's loops closed near ``initial_positions``, what closing
them moved, and which loops to check when they do not close.

The loops are closed with the actuators (and the locked joints, idle_spins.py) held at
their initial positions (Gauss-Newton on the closure equations, closure.assemble); failing
that (e.g. rounded redundant initial positions), with every joint but the locked ones
free, but a move of an actuator by more than
setpoint_tolerance is refused. What the assembly had to change is reported in
``Mechanism.assembly_warnings`` and as AssemblyWarning.
"""
import math
from typing import Any, Iterable, Sequence
import warnings

from . import closure, spherical_chains
from . import kinematics as kin
from . import spatial as sp
from .errors import MechanismConfigError
from .value_types import MechanismLike

#: assembly that moves a passive joint further than this from initial_positions is reported
#: (rad for an angle; for a length this fraction of the mechanism's scale)
FAR_ANGLE = 0.1
FAR_FRACTION = 0.1


class AssemblyWarning(UserWarning):
    """Assembly at load had to move joints away from ``initial_positions``: the mechanism
    loaded, but its geometry or initial positions are probably not what was meant."""


def assemble(mech: MechanismLike) -> tuple[list[float], str | None, MechanismConfigError | None]:
    """(q, moved, problem): every coordinate at the assembled pose; when closing the loops
    moved actuators by more than setpoint_tolerance, which (text) and the
    MechanismConfigError to raise (after the degrees of freedom are counted: a rigid
    mechanism, whose actuators cannot be held anywhere but one pose, is the clearer
    message), else None, None. Far moves of passive joints are reported."""
    start = spherical_chains.with_chain_starts(
        mech, mech.model.start(mech.initial_positions))
    q, residual, ok = closure.assemble(mech.model, start, mech.closure_tolerance,
                                       fixed=mech.active_index + mech.locked_index)
    if not ok:
        held_q, held_residual = q, residual
        q, residual, ok = closure.assemble(mech.model, start, mech.closure_tolerance,
                                           fixed=mech.locked_index)
        if not ok:
            raise MechanismConfigError(
                'mechanism.initial_positions',
                f'the loops cannot be closed near these positions, not even by moving '
                f'the actuators (closure residual {held_residual:.3g} with the actuators '
                f'held at initial_positions); {check_loops_hint(mech, held_q)}')
        moved = [(a, j) for a, j in enumerate(mech.active_index)
                 if abs(q[j] - start[j]) > mech.setpoint_tolerance]
        if moved:
            what = '; '.join(f"active joint '{mech.joints[j]}' from {start[j]:.6g} to "
                             f'{q[j]:.6g} (by {abs(q[j] - start[j]):.3g})' for _, j in moved)
            return q, what, MechanismConfigError(
                'mechanism.initial_positions',
                f'the loops cannot be closed with the actuators held at initial_positions '
                f'(closure residual {held_residual:.3g}); they close only by moving {what}, '
                f'more than mechanism.setpoint_tolerance ({mech.setpoint_tolerance:g}); '
                f'{check_loops_hint(mech, held_q)}')
        for j in mech.active_index:
            if q[j] != start[j]:
                note(mech, f"assembly moved active joint '{mech.joints[j]}' from "
                           f'{start[j]:.9g} to {q[j]:.9g} (by {abs(q[j] - start[j]):.3g}, '
                           f'within mechanism.setpoint_tolerance) to close the loops: the '
                           f"actuators' initial_positions disagree slightly with the loop "
                           f'closure')
    _report_far_moves(mech, start, q)
    return q, None, None


def far_move_limit(mech: MechanismLike, j: int) -> tuple[float, str | None]:
    """(limit, unit): a move of joint j at assembly beyond this is reported as far
    (FAR_ANGLE rad; for a joint whose coordinate is a length, FAR_FRACTION of the
    mechanism's scale, its largest attachment offset)."""
    unit = mech.joint_specs[j].kind.unit
    if unit == 'rad':
        return FAR_ANGLE, unit
    return FAR_FRACTION * mech.attachment_scale, unit


def attachment_scale(specs: Sequence[kin.JointSpec]) -> float:
    """The largest attachment offset of the joints ``specs`` (m; 1.0 if there is none)."""
    scale = max([math.hypot(*spec.parent_xyz) for spec in specs]
                + [math.hypot(*spec.child_xyz) for spec in specs] + [0.0])
    return scale if scale > 0.0 else 1.0


def _report_far_moves(mech: MechanismLike, start: Sequence[float], q: Sequence[float]) -> None:
    """A note for every passive joint the assembly moved far from initial_positions."""
    held = set(mech.active_index) | set(mech.locked_index)
    far: list[str] = []
    moved: list[int] = []
    for j, (a, b) in enumerate(zip(start[:len(mech.joints)], q)):
        if j in held:
            continue
        limit, unit = far_move_limit(mech, j)
        if abs(b - a) > limit:
            far.append(f"'{mech.joints[j]}' from {a:.6g} to {b:.6g} {unit}")
            moved.append(j)
    if far:
        note(mech,
             f'closing the loops with the actuators held at initial_positions moved passive '
             f'joint(s) {", ".join(far)} (more than {FAR_ANGLE:g} rad or {FAR_FRACTION:.0%} of '
             f'the mechanism scale {mech.attachment_scale:.3g} m): the geometry (xyz, '
             f'rpy, axis) or '
             f'initial_positions are probably not what was meant; '
             f'{check_loops_hint(mech, None, moved)}')


def note(mech: MechanismLike, text: str) -> None:
    """Report ``text`` in mech.assembly_warnings and as an AssemblyWarning."""
    mech.assembly_warnings.append(text)
    warnings.warn(f'{mech.name}: {text}', AssemblyWarning, stacklevel=4)


def _loops_of(mech: MechanismLike,
              q: Iterable[float] | None = None) -> list[tuple[str, list[str], float | None]]:
    """(loop-closing joint, joints of its loop, residual at q or None) of every loop."""
    model = mech.model
    residuals: list[Any] = [None] * len(model.loops)
    if q is not None:
        frames = kin.forward_kinematics(model, list(q), sp.ScalarOps)
        states = closure.loop_closure(model, frames, list(q), sp.ScalarOps)
        residuals = [max(map(abs, st.residual)) for st in states]
    out = []
    names = model.coordinate_joints
    for lp, res in zip(model.loops, residuals):
        joints = list(dict.fromkeys(names[j] for j in sorted(set(kin.loop_columns(lp)))))
        out.append((lp.name, joints + ([lp.name] if lp.joint is None else []), res))
    return out


def check_loops_hint(mech: MechanismLike, q: Iterable[float] | None,
                     joints: Iterable[int] | None = None) -> str:
    """What to check: the joints of the loops that stay open at q, or else of the loops
    through any of ``joints`` (indices), or else of all loops."""
    loops = _loops_of(mech, q)
    names = {mech.joints[j] for j in joints or ()}
    bad = ([lp for lp in loops if lp[2] is not None and lp[2] >= mech.closure_tolerance]
           or [lp for lp in loops if names & set(lp[1])] or loops)
    which = '; '.join(f"loop closed by '{name}' (joints {', '.join(js)}"
                      + (f', residual {res:.3g})' if res is not None else ')')
                      for name, js, res in bad[:5])
    more = f' and {len(bad) - 5} more loops' if len(bad) > 5 else ''
    return (f'check the geometry (parent_xyz, child_xyz, *_rpy and axis) of the joints of '
            f'{which}{more}, and initial_positions (the assembly mode)')
