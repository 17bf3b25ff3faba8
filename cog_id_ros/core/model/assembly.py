"""Assembly at load: the mechanism's loops closed near ``initial_positions``, what closing
them moved, and which loops to check when they do not close.

Robot models are published with the loops open at their zero pose and with no position for
the passive joints (nor for those the loop file's edits make): ``mechanism.found_at_assembly``
names the joints whose initial position is only where the search starts (the URDF reader
puts every joint the user left out of ``initial_positions`` there). The order, each step
only where the one before failed (the search itself: assembly_search.py):

1. the actuators whose positions ``initial_positions`` gives held there, every other joint
   found: the closed pose nearest the start;
2. every joint free but the locked ones: the closed pose nearest the start (the zero pose
   where nothing is given), as the Pinocchio loader of the published collection looks for
   it. Used as it is where no actuator's position was given or ``mechanism.assembly:
   free`` says so; else refused, the pose printed as an ``initial_positions`` block to
   paste. A move of a given actuator within ``setpoint_tolerance`` is accepted (rounded
   redundant initial positions).

Actuators whose positions the assembly chose must be able to move MOBILITY either way from
the pose it found (assembly_search.reach, the other actuators held): a pose at the edge of
the workspace is moved into it (:func:`centre`). What the assembly had to change is
reported in ``Mechanism.assembly_warnings`` and as AssemblyWarning.
"""
import math
from typing import Any, Iterable, Sequence
import warnings

import numpy as np

from ..closure import closure, continuation
from ..errors import MechanismConfigError
from ..kinematics import kinematics as kin
from ..kinematics import spherical_chains
from ..linalg import spatial as sp
from ..value_types import MechanismLike
from . import assembly_search, idle_spins

#: assembly that moves a passive joint further than this from initial_positions is reported
#: (rad for an angle; for a length this fraction of the mechanism's scale)
FAR_ANGLE = 0.1
FAR_FRACTION = 0.1
#: how far every actuator whose position the assembly chose must be able to move either way
#: from the assembled pose (rad; a prismatic one this fraction of the mechanism's scale),
#: and how many times the pose is moved into the workspace to make it so
MOBILITY = 0.05
CENTRING_ROUNDS = 8
#: the move of MOBILITY is checked in this many steps, none of which may turn another joint
#: more than STEEPEST times as far (a dead centre on the way: the pose is at an edge)
MOBILITY_PARTS, STEEPEST = 10, 20.0
#: the values of mechanism.assembly, the default first
ASSEMBLY_MODES = ('hold', 'free')


class AssemblyWarning(UserWarning):
    """Assembly at load had to move joints away from ``initial_positions``: the mechanism
    loaded, but its geometry or initial positions are probably not what was meant."""


def assemble(mech: MechanismLike, start: 'list[float] | None' = None, settled: bool = False
             ) -> tuple[list[float], str | None, MechanismConfigError | None]:
    """(q, moved, problem): every coordinate at the assembled pose (module docstring);
    when the given actuators cannot be held, which (text) and the MechanismConfigError to
    raise (after the degrees of freedom are counted: a rigid mechanism, whose actuators
    cannot be held anywhere but one pose, is the clearer message), else None, None.
    ``start``: every coordinate to start from (default: initial_positions); ``settled``: it
    is a pose this assembly found (the second pass, with the idle spins' joints locked): the
    actuators are held there. Each step is tried with Gauss-Newton alone first, the global
    search only where none succeeds."""
    if start is None:
        start = spherical_chains.with_chain_starts(
            mech, mech.model.start(mech.initial_positions))
    if settled:     # the locks are new: the actuators it chose must still move (centre)
        q, _, ok = _quick(mech, start, mech.active_index + mech.locked_index)
        if ok:
            chosen = [j for j in mech.active_index if j in set(mech.found_index)]
            return wrapped(mech, centre(mech, q, chosen)), None, None
    found = set(mech.found_index)
    given = [j for j in mech.active_index if j not in found]
    # locked joints are held during the search where their positions are given; where they
    # are found, they are found like the others (and held from then on)
    locks = [j for j in mech.locked_index if j not in found]
    chosen = [j for j in mech.active_index if j in found]
    attempts = [given] if mech.assembly == 'hold' and given else []
    best = (start, math.inf)
    for search in (_quick, _global):
        for actuators in attempts:
            q, residual, ok = search(mech, start, actuators + locks)
            if ok:
                _report_far_moves(mech, start, q)
                return wrapped(mech, centre(mech, q, [j for j in chosen if j not in actuators])
                               ), None, None
            best = min(best, (q, residual), key=lambda item: item[1])
        if search is _quick and given:
            # rounded redundant initial positions: closed by moving the actuators a little
            q, residual, ok = _quick(mech, start, locks)
            if ok and all(abs(q[j] - start[j]) <= mech.setpoint_tolerance for j in given):
                q = assembly_search.nearest(mech.model, q, start, mech.closure_tolerance,
                                            fixed=locks)
                _note_small_moves(mech, start, q)
                _report_far_moves(mech, start, q)
                return wrapped(mech, centre(mech, q, chosen)), None, None
    used = mech.assembly == 'free' or not given     # else refused, this pose offered
    healthy = _healthiest(mech, assembly_search.closest(
        mech.model, start, mech.closure_tolerance, fixed=locks,
        scale=mech.attachment_scale), report=used)
    if healthy is None:
        q, residual, _ = assembly_search.close(mech.model, start, mech.closure_tolerance,
                                               fixed=locks,
                                               scale=mech.attachment_scale, restarts=0)
        raise MechanismConfigError(
            'mechanism.initial_positions',
            f'the loops cannot be closed, not even with every joint free (closure residual '
            f'{residual:.3g} at best, from {_start_words(mech)}); {check_loops_hint(mech, q)}')
    q = healthy
    moved = [j for j in given if abs(q[j] - start[j]) > mech.setpoint_tolerance]
    if used or not moved:
        why = ('mechanism.assembly: free' if mech.assembly == 'free' else
               'no actuator position given' if not given else
               'the given actuators cannot be held')
        if not any(abs(q[j] - start[j]) > max(1e-9, 10.0 * mech.closure_tolerance)
                   for j in mech.active_index):
            return q, None, None          # the actuators are where they started: nothing to say
        note(mech, f'{why}: assembled with every joint free at the closed pose nearest '
                   f'{"initial_positions" if given else "the zero pose"} (as the Pinocchio '
                   f'loader of published closed-loop models does): '
                   f'{_actuator_words(mech, q)}. To start elsewhere, give '
                   f'mechanism.initial_positions (cog_id_inspect prints this whole pose as '
                   f'a block to paste)')
        return q, None, None
    return q, *_refusal(mech, start, q, moved, best)


def _refusal(mech: MechanismLike, start: Sequence[float], q: list[float], moved: list[int],
             best: tuple) -> tuple[str, 'PoseRefused']:
    """(moved, the refusal) where the given actuators cannot be held: the closed pose
    ``q`` nearest them (every joint free) offered to paste; ``best``: (pose, residual) of
    the closest the held search came."""
    what = '; '.join(f"active joint '{mech.joints[j]}' from {start[j]:.6g} to {q[j]:.6g} "
                     f'(by {abs(q[j] - start[j]):.3g})' for j in moved)
    return what, PoseRefused(
        'mechanism.initial_positions',
        f'the loops cannot be closed with the actuators held at initial_positions (closure '
        f'residual {best[1]:.3g} at best); the closed pose nearest it, every joint '
        f'free, moves {what}, more than mechanism.setpoint_tolerance '
        f'({mech.setpoint_tolerance:g}). To use that pose, put it under `mechanism:`: '
        f'{POSE_MARK}, or set `assembly: free` there to have it found at every load; '
        f'{check_loops_hint(mech, best[0])}',
        pose_block(mech, q))


def wrapped(mech: MechanismLike, q: list[float]) -> list[float]:
    """``q`` with every revolute joint whose position the assembly found (not an actuator,
    not a locked joint) turned by whole turns into (-pi, pi]: the same pose, polished (the
    loops stay closed to the tolerance)."""
    keep = set(mech.active_index) | set(mech.locked_index)
    out = list(q)
    for j in mech.found_index:
        if j not in keep and mech.joint_specs[j].kind.unit == 'rad' and abs(out[j]) > math.pi:
            out[j] = math.remainder(out[j], 2.0 * math.pi)
    if out == list(q):
        return out
    polished, _, ok = closure.assemble(mech.model, out, mech.closure_tolerance,
                                       fixed=sorted(keep))
    return polished if ok else list(q)


def _healthiest(mech: MechanismLike, batches: Iterable[list], report: bool
                ) -> 'list[float] | None':
    """Of the closed poses (every joint free) that ``batches`` offer (assembly_search.
    closest: the one from the start, then all found, nearest first), the first from which
    every actuator can move its mobility once centred (:func:`centre`); else the nearest,
    centred (its notes given with ``report``); None where none closes."""
    nearest = None
    for first, poses in enumerate(batches):
        for q in poses:
            if first == 0:           # the pose from the start will do only as it is
                if not stuck(mech, q, mech.active_index):
                    return wrapped(mech, q)
                continue
            moved = centre(mech, q, mech.active_index, report=False)
            if not stuck(mech, moved, mech.active_index):
                return wrapped(mech, moved)
        nearest = poses[0] if poses else nearest
    if nearest is None:
        return None
    return wrapped(mech, centre(mech, nearest, mech.active_index, report=report))


def _quick(mech: MechanismLike, start: list[float], fixed: list[int]
           ) -> tuple[list[float], float, bool]:
    """Gauss-Newton alone (closure.assemble): the common case, at no extra cost."""
    return closure.assemble(mech.model, start, mech.closure_tolerance, fixed=fixed)


def _global(mech: MechanismLike, start: list[float], fixed: list[int]
            ) -> tuple[list[float], float, bool]:
    """The global search (assembly_search.close)."""
    return assembly_search.close(mech.model, start, mech.closure_tolerance, fixed=fixed,
                                 scale=mech.attachment_scale)


class PoseRefused(MechanismConfigError):
    """The given actuators cannot be held; ``pose``: {joint: position} of the closed pose
    nearest them, every joint free, which the message offers in the native form (the
    text POSE_MARK stands for it until :func:`native_block` fills it in)."""

    def __init__(self, parameter: str, message: str, pose: dict) -> None:
        self.pose = pose
        super().__init__(parameter, message.replace(POSE_MARK, native_block(pose)))
        self.template = message


#: where a refusal's message puts the pose to paste
POSE_MARK = '<pose>'


def pose_block(mech: MechanismLike, q: Sequence[float]) -> dict:
    """{joint: position} of every joint with a coordinate at ``q``, mechanism.joints order:
    full precision, so that what is pasted closes as this pose did."""
    return {name: float(q[j]) if abs(q[j]) > 1e-12 else 0.0     # (rounding: 0)
            for j, name in enumerate(mech.joints)}


def native_block(pose: dict) -> str:
    """The pose as the native form writes it: a list, mechanism.joints order."""
    return f"`initial_positions: [{', '.join(repr(x) for x in pose.values())}]`"


def mapping_block(pose: dict) -> str:
    """The pose as the URDF form writes it: a YAML flow mapping, every name quoted."""
    return ('`initial_positions: {' + ', '.join(f'{_quoted(name)}: {value!r}'
                                                for name, value in pose.items()) + '}`')


def _quoted(name: str) -> str:
    return '"' + name.replace('\\', '\\\\').replace('"', '\\"') + '"'


def _start_words(mech: MechanismLike) -> str:
    found = set(mech.found_index)
    given = [j for j in mech.active_index if j not in found]
    return 'initial_positions' if given else 'the zero pose (no actuator position given)'


def _actuator_words(mech: MechanismLike, q: Sequence[float]) -> str:
    return 'the actuators at ' + ', '.join(
        f"'{mech.joints[j]}' {q[j] if abs(q[j]) > 1e-12 else 0.0:.6g}" for j in mech.active_index)


def _note_small_moves(mech: MechanismLike, start: Sequence[float], q: Sequence[float]) -> None:
    """A note per given actuator the assembly moved (within setpoint_tolerance); moves at the
    level of rounding are not reported."""
    for j in mech.active_index:
        if abs(q[j] - start[j]) > max(1e-9, 10.0 * mech.closure_tolerance):
            note(mech, f"assembly moved active joint '{mech.joints[j]}' from "
                       f'{start[j]:.9g} to {q[j]:.9g} (by {abs(q[j] - start[j]):.3g}, '
                       f'within mechanism.setpoint_tolerance) to close the loops: the '
                       f"actuators' initial_positions disagree slightly with the loop "
                       f'closure')


def mobility(mech: MechanismLike, j: int) -> float:
    """How far actuator (joint) ``j`` must be able to move either way: MOBILITY rad, or for
    a length MOBILITY of the mechanism's length scale (continuation.length_scale: a step
    of the solver is that much of it, as of a radian)."""
    unit = mech.joint_specs[j].kind.unit
    return MOBILITY if unit == 'rad' else MOBILITY * continuation.length_scale(mech)


def stuck(mech: MechanismLike, q: Sequence[float], joints: Iterable[int]) -> list:
    """(joint, direction) of each of ``joints`` (actuators) that cannot move its mobility
    that way from ``q`` (the loops stop closing, or pass a dead centre, or its position
    limits are in the way), the locked joints and the other actuators held; those the loops
    make it move with (a coupled or dependent actuator's partners) follow it."""
    held = list(mech.active_index) + list(mech.locked_index)
    out = []
    for j in joints:
        if not mech.model.loops_of_joint[j]:
            continue                 # in no loop or coupling: it moves freely
        partners = _partners(mech, q, j)
        fixed = [k for k in held if k not in partners]
        lower, upper = mech.position_limits[j]
        for direction in (1.0, -1.0):
            if not lower <= q[j] + direction * mobility(mech, j) <= upper or \
                    assembly_search.reach(mech.model, q, j, direction * mobility(mech, j),
                                          mech.closure_tolerance, fixed, parts=MOBILITY_PARTS,
                                          steepest=STEEPEST) is None:
                out.append((j, direction))
    return out


def _moves(mech: MechanismLike, q: Sequence[float]) -> bool:
    """The mechanism can move at ``q`` (the locked joints held): not rigid."""
    matrix, _ = closure.closure_jacobian_matrix(mech.model, q)
    rows = np.vstack([matrix, np.eye(mech.n_coordinates)[mech.locked_index]])
    return bool(idle_spins.null_rows(rows).size)


def _partners(mech: MechanismLike, q: Sequence[float], j: int) -> set:
    """The other actuators that move whenever actuator (joint) ``j`` moves, at ``q``: those
    with a rate in the motion that moves ``j`` at unit rate and the other actuators least
    (the locked joints held)."""
    matrix, _ = closure.closure_jacobian_matrix(mech.model, q)
    rows = [matrix] + [np.eye(mech.n_coordinates)[mech.locked_index]]
    motions = idle_spins.null_rows(np.vstack(rows)).T
    others = [k for k in mech.active_index if k != j]
    if not motions.size or not others:
        return set()
    # least |other actuators' rates|^2 subject to rate of j = 1
    a, b = motions[others], motions[j]
    weights = np.linalg.lstsq(np.vstack([a, 1e6 * b[None]]),
                              np.concatenate([np.zeros(len(others)), [1e6]]), rcond=None)[0]
    rates = a @ weights
    return {k for k, rate in zip(others, rates) if abs(rate) > 1e-6}


def centre(mech: MechanismLike, q: list[float], joints: Iterable[int],
           report: bool = True) -> list[float]:
    """``q`` moved into the workspace until each of ``joints`` (actuators whose positions
    the assembly chose) can move its mobility either way: an actuator stuck one way is
    moved its mobility the other way, the others held. A note names any still stuck
    (with ``report``)."""
    joints = list(joints)
    if not joints or not _moves(mech, q):
        return q                     # (a rigid mechanism is refused after: nothing to say)
    held = list(mech.active_index) + list(mech.locked_index)
    q = _into_limits(mech, q, joints, held, report)
    blocked = stuck(mech, q, joints)
    for _ in range(CENTRING_ROUNDS):
        if not blocked:
            return q
        for j, direction in blocked:
            lower, upper = mech.position_limits[j]
            if (j, -direction) in blocked or \
                    not lower <= q[j] - 2.0 * direction * mobility(mech, j) <= upper:
                continue             # stuck both ways, or no room: left for the note
            moved = assembly_search.reach(mech.model, q, j, -direction * mobility(mech, j),
                                          mech.closure_tolerance, held)
            if moved is not None:
                q = moved
        again = stuck(mech, q, joints)
        if again == blocked:
            break
        blocked = again
    if blocked and report:
        names = ', '.join(f"'{mech.joints[j]}' ({'+' if d > 0 else '-'})" for j, d in blocked)
        note(mech, f'at the assembled pose the actuator(s) {names} cannot move '
                   f'{MOBILITY:g} rad (or {MOBILITY:.0%} of the mechanism scale) that way with '
                   f'the others held: the pose is at the edge of the workspace or singular; '
                   f'give mechanism.initial_positions inside the workspace')
    return q


def _into_limits(mech: MechanismLike, q: list[float], joints: list[int],
                 held: list[int], report: bool) -> list[float]:
    """``q`` with each of ``joints`` (actuators whose positions the assembly chose) that
    lies outside its position limits (less its mobility) moved inside them: by
    continuation, the others held; failing that, the loops closed again with it there."""
    for j in joints:
        lower, upper = mech.position_limits[j]
        margin = min(mobility(mech, j), (upper - lower) / 2.0)
        target = min(max(q[j], lower + margin), upper - margin)
        if target == q[j]:
            continue
        parts = max(assembly_search.REACH_PARTS, math.ceil(abs(target - q[j]) / MOBILITY))
        fixed = [k for k in held if k not in _partners(mech, q, j)]
        moved = assembly_search.reach(mech.model, q, j, target - q[j], mech.closure_tolerance,
                                      fixed, parts=parts)
        if moved is None:
            start = list(q)
            start[j] = target
            moved, _, ok = assembly_search.close(mech.model, start, mech.closure_tolerance,
                                                 fixed=fixed, scale=mech.attachment_scale,
                                                 restarts=0)
            if not ok:
                if not lower <= q[j] <= upper and report:
                    note(mech, f"actuator '{mech.joints[j]}' is assembled at {q[j]:.6g} "
                               f'{mech.joint_specs[j].kind.unit}, outside its position limits '
                               f'[{lower:g}, {upper:g}]: the loops close nowhere near the '
                               f'start with it inside them, so every setpoint is refused as '
                               f"'limit' until the limits (joints.{mech.joints[j]}.lower and "
                               f'upper, or the URDF <limit>) or initial_positions are '
                               f'corrected')
                continue
        q = moved
    return q


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
    held = set(mech.active_index) | set(mech.locked_index) | set(mech.found_index)
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
    """Report ``text`` in mech.assembly_warnings and as an AssemblyWarning (once: the
    second pass of the assembly, with the idle spins locked, may find it again)."""
    if text in mech.assembly_warnings:
        return
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
