"""The search for a closed pose at load: from any start, as robot models come.

Published closed-loop models give a tree whose loops are open at its zero pose, and the
motors' positions at most; the passive joints, and those the loop file's edits make, have
no value at all. Gauss-Newton from such a start (closure.assemble: minimum-norm steps on
the closure Jacobian A) often stops in a local minimum of the residual. This module makes
the search global, in the order a cheap success is likeliest:

1. Gauss-Newton from the start (closure.assemble): minimum-norm steps, the closed pose it
   reaches is near the start;
2. Levenberg-Marquardt on |Phi|^2 from the start (:func:`levenberg_marquardt`). A is the
   Jacobian of the loops' *velocities* (closure.py), exact only where the loops are closed;
   far from closure its gradient is not that of |Phi|^2, so this step takes the residual's
   own Jacobian by central differences, all 2n evaluations in one batch (spatial.ArrayOps
   lanes), then hands the result to Gauss-Newton to polish;
3. restarts from starts spread about the given one (a fixed seed: the same model always
   gives the same pose), each as 1. and 2.

:func:`nearest` then slides a closed pose along the closed set toward a target (the given
pose): the pose the collection's own loader looks for (the closed pose nearest the zero
pose). :func:`reach` moves one coordinate by continuation, the others held or solved: how
the assembly checks that every actuator can move from the pose it found (assembly.py).
Everything here runs at load only.
"""
from typing import Iterable, Iterator, Sequence

import numpy as np

from ..closure import closure
from ..kinematics import kinematics as kin
from ..linalg import spatial as sp
from ..value_types import FloatArray

#: Levenberg-Marquardt: iterations per start, the damping it starts with and its bounds;
#: it stops where STALL iterations lowered |Phi|^2 by less than STALL_FRACTION together
LM_ITERATIONS = 200
LM_DAMPING = 1e-2
LM_MAX_DAMPING = 1e14
#: the dampings an iteration tries together, as multiples of the current one
DAMPINGS = (0.1, 1.0, 10.0, 100.0, 1000.0)
STALL, STALL_FRACTION = 20, 0.01
#: central-difference step of the residual's Jacobian (rad or m)
DIFFERENCE_STEP = 1e-7
#: restarts after the given start fails, and how far their revolute coordinates are spread
#: from it (rad; a prismatic one by this fraction of the mechanism's scale)
RESTARTS = 3
SPREAD = 0.6
SEED = 20241
#: nearest: slides along the closed set at most this many times
NEAREST_STEPS = 20
#: reach: a move is made in this many parts, each closed before the next
REACH_PARTS = 5


def residuals(model: kin.KinematicModel, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(Phi, least cosine) of the closure equations at each column of ``q`` (n, N):
    (6 constraints, N) and (N,); one batch of lane code."""
    lanes = [q[j] for j in range(q.shape[0])]
    frames = kin.forward_kinematics(model, lanes, sp.ArrayOps)
    states = closure.loop_closure(model, frames, lanes, sp.ArrayOps)
    width = q.shape[1]
    phi = np.array([np.broadcast_to(np.asarray(r, dtype=float), (width,))
                    for st in states for r in st.residual]).reshape(-1, width)
    cosines = np.array([np.broadcast_to(np.asarray(st.cosine, dtype=float), (width,))
                        for st in states] + [np.ones(width)])
    return phi, cosines.min(axis=0)


def residual_jacobian(model: kin.KinematicModel, q: FloatArray,
                      moving: Sequence[int]) -> tuple[FloatArray, FloatArray, float]:
    """(Phi, dPhi/dq of the coordinates ``moving``, least cosine) at ``q``: central
    differences, evaluated together."""
    columns = np.repeat(q[:, None], 1 + 2 * len(moving), axis=1)
    for k, j in enumerate(moving):
        columns[j, 1 + 2 * k] += DIFFERENCE_STEP
        columns[j, 2 + 2 * k] -= DIFFERENCE_STEP
    phi, cosines = residuals(model, columns)
    jacobian = (phi[:, 1::2] - phi[:, 2::2]) / (2.0 * DIFFERENCE_STEP)
    return phi[:, 0], jacobian, float(cosines[0])


def levenberg_marquardt(model: kin.KinematicModel, start: Sequence[float],
                        fixed: Iterable[int] = (), tol: float = 1e-10,
                        iterations: int = LM_ITERATIONS) -> FloatArray:
    """``start`` moved (all coordinates but ``fixed``) to a least-squares minimum of the
    closure residual, or as close to one as ``iterations`` go: damped steps on the
    residual's own Jacobian, a step kept only when it lowers |Phi|. Each iteration tries
    DAMPINGS times the current damping together (one batch) and keeps the best. Closed to
    about ``tol`` at best; closure.assemble polishes."""
    q = np.array(start, dtype=float)
    held = set(fixed)
    moving = [j for j in range(len(q)) if j not in held]
    if not moving:
        return q
    phi, jac, _ = residual_jacobian(model, q, moving)
    value = float(phi @ phi)
    damping = LM_DAMPING
    history = [value]
    eye = np.eye(len(moving))
    for _ in range(iterations):
        if not np.isfinite(value) or np.max(np.abs(phi), initial=0.0) < tol:
            break
        if len(history) > STALL and value > (1.0 - STALL_FRACTION) * history[-STALL - 1]:
            break
        gradient = jac.T @ phi
        normal = jac.T @ jac
        scaling = np.diag(np.diag(normal)) + 1e-9 * eye
        trials, dampings = [], []
        for factor in DAMPINGS:
            try:
                step = np.linalg.solve(normal + damping * factor * scaling, -gradient)
            except np.linalg.LinAlgError:
                continue
            trial = q.copy()
            trial[moving] += step
            trials.append(trial)
            dampings.append(damping * factor)
        if not trials:
            break
        trial_phi = residuals(model, np.array(trials).T)[0]
        values = np.sum(trial_phi * trial_phi, axis=0)
        values[~np.isfinite(values)] = np.inf
        best = int(np.argmin(values))
        if not values[best] < value:
            damping *= DAMPINGS[-1] * 4.0
            if damping > LM_MAX_DAMPING:
                break
            continue
        q, value = trials[best], float(values[best])
        phi, jac, _ = residual_jacobian(model, q, moving)
        damping = max(dampings[best] / 3.0, 1e-12)
        history.append(value)
    return q


def _attempt(model: kin.KinematicModel, start: Sequence[float], tol: float,
             fixed: Sequence[int]) -> tuple[list[float], float, bool]:
    """Gauss-Newton from ``start``; failing that, Levenberg-Marquardt then Gauss-Newton."""
    q, residual, ok = closure.assemble(model, start, tol, fixed=fixed)
    if ok:
        return q, residual, ok
    best = (q, residual)
    moved = levenberg_marquardt(model, start, fixed, tol)
    q, residual, ok = closure.assemble(model, moved.tolist(), tol, fixed=fixed)
    if ok or residual < best[1]:
        return q, residual, ok
    return best[0], best[1], False


def close(model: kin.KinematicModel, start: Sequence[float], tol: float,
          fixed: Iterable[int] = (), scale: float = 1.0,
          restarts: int = RESTARTS) -> tuple[list[float], float, bool]:
    """(q, residual, closed): every loop closed from ``start``, the coordinates ``fixed``
    held (module docstring: Gauss-Newton, Levenberg-Marquardt, then ``restarts`` spread
    starts). Not closed: the pose with the least residual found."""
    fixed = sorted(set(fixed))
    best: tuple[list[float], float] = (list(start), float('inf'))
    for trial in _starts(model, start, fixed, scale, restarts):
        q, residual, ok = _attempt(model, trial, tol, fixed)
        if ok:
            return q, residual, ok
        if residual < best[1]:
            best = (q, residual)
    return best[0], best[1], False


def closest(model: kin.KinematicModel, start: Sequence[float], tol: float,
            fixed: Iterable[int] = (), scale: float = 1.0,
            restarts: int = RESTARTS) -> Iterator[list[list[float]]]:
    """Closed poses found from ``start`` and from ``restarts`` spread starts (each as
    :func:`close` tries one, then slid to the :func:`nearest` pose), nearest to ``start``
    first: the loops of a mechanism close in several ways (assembly modes), and the first
    one found is not always the nearest. Lazily: first [the pose from ``start``] alone
    (where it will do, nothing more is searched), then every pose found, sorted; empty
    lists where none closes."""
    fixed = sorted(set(fixed))
    goal = np.asarray(start[:model.n_joints], dtype=float)
    found = []
    for k, trial in enumerate(_starts(model, start, fixed, scale, restarts)):
        q, _, ok = _attempt(model, trial, tol, fixed)
        if ok:
            found.append(nearest(model, q, start, tol, fixed))
        if k == 0:
            yield list(found)
    yield sorted(found, key=lambda q: float(np.linalg.norm(np.asarray(q[:model.n_joints])
                                                           - goal)))


def _starts(model: kin.KinematicModel, start: Sequence[float], fixed: Sequence[int],
            scale: float, restarts: int) -> list[list[float]]:
    """``start``, then ``restarts`` starts spread about it (a fixed seed)."""
    rng = np.random.default_rng(SEED)
    spread = _spread(model, fixed, scale)
    return [list(start)] + [
        (np.array(start, dtype=float) + spread * rng.uniform(-1.0, 1.0, len(spread))).tolist()
        for _ in range(restarts)]


def _spread(model: kin.KinematicModel, fixed: Sequence[int], scale: float) -> FloatArray:
    """Per coordinate, how far a restart may move it: SPREAD rad for an angle, SPREAD of the
    scale for a length; 0 for the held ones and the hidden quaternions."""
    held = set(fixed)
    out = np.zeros(model.n_coordinates)
    for j, kind in enumerate(model.coordinate_kinds):
        if j in held or j >= model.n_joints:      # held, or a hidden one
            continue
        out[j] = SPREAD if kind.unit == 'rad' else SPREAD * scale
    return out


def nearest(model: kin.KinematicModel, q: Sequence[float], target: Sequence[float],
            tol: float, fixed: Iterable[int] = ()) -> list[float]:
    """The closed pose ``q`` slid along the closed set toward ``target`` (the coordinates
    ``fixed`` held): each step goes the tangent part of the way and closes the loops
    again, and is kept only while the distance to ``target`` shrinks."""
    held = sorted(set(fixed))
    free = [j for j in range(model.n_coordinates) if j not in set(held)]
    current = list(q)
    goal = np.asarray(target, dtype=float)
    distance = float(np.linalg.norm(np.asarray(current)[free] - goal[free]))
    for _ in range(NEAREST_STEPS):
        matrix, _ = closure.closure_jacobian_matrix(model, current)
        tangent = _null_space(matrix[:, free])
        if not tangent.shape[1]:
            break
        offset = np.asarray(current)[free] - goal[free]
        step = tangent @ (tangent.T @ offset)
        if not np.linalg.norm(step) > 1e-12 * max(1.0, distance):
            break
        trial = np.asarray(current, dtype=float)
        trial[free] -= step
        moved, _, ok = closure.assemble(model, trial.tolist(), tol, fixed=held)
        if not ok:
            break
        moved_distance = float(np.linalg.norm(np.asarray(moved)[free] - goal[free]))
        if not moved_distance < distance * (1.0 - 1e-9):
            break
        current, distance = moved, moved_distance
    return current


def reach(model: kin.KinematicModel, q: Sequence[float], joint: int, delta: float,
          tol: float, fixed: Iterable[int], parts: int = REACH_PARTS,
          steepest: float = float('inf')) -> 'list[float] | None':
    """``q`` with coordinate ``joint`` moved by ``delta`` (the coordinates ``fixed`` held,
    the others solved), in ``parts`` closed steps; None where a step cannot close, or
    moves another joint more than ``steepest`` times as far as ``joint`` (near a dead
    centre the others turn ever faster: Newton may close past it on another branch)."""
    held = sorted(set(fixed) | {joint})
    current = list(q)
    step = abs(delta) / parts
    for _ in range(parts):
        before = current[:model.n_joints]
        current[joint] += delta / parts
        current, _, ok = closure.assemble(model, current, tol, fixed=held)
        if not ok or max((abs(a - b) for a, b in zip(current, before)), default=0.0) > \
                steepest * step:
            return None
    return current


def _null_space(a: FloatArray) -> FloatArray:
    """Orthonormal columns spanning the null space of ``a`` (relative tolerance 1e-9)."""
    if not a.size:
        return np.eye(a.shape[1])
    _, values, vt = np.linalg.svd(a)
    scale = max(1.0, values[0]) if values.size else 1.0
    return vt[int(np.sum(values > 1e-9 * scale)):].T
