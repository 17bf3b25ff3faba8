"""The joints as written, read back from the coordinates of a mechanism's solver form.

Where chains of three revolute joints are solved as the spherical joints they are
(spherical_chains.py), every output still shows the joints as written: the joints the solver
form kept are copied, and each chain's three angles, and their rates, are read back from
the relative rotation and angular velocity of its end links P and C. Here:

* the lane code of that read-out: :func:`chain_turn`, :func:`chain_angles`,
  :func:`chain_rates` of one chain, and :func:`readout_record` of them all, which places
  only the links the chains need (their paths in the spanning tree, :class:`ReadoutPlan`)
  and gives their angular velocities only where rates are asked for;
* the same lane code traced into the kernel ``readout(q, qdot)`` (kernels.py, with the
  torque kernels of a mechanism that has chains; straight-line Python for 'python',
  compiled with the others for 'native'), which the kernels of a solver form offer here
  when they are made (:func:`offer`);
* :class:`JointReadout`, ``Mechanism.joints_at``'s way back: one sample by the fastest
  read-out offered for its solver form (compiled, else traced Python, else the lane code
  on floats; the same numbers, kernels.py), N samples by the lane code on (N,) arrays.
"""
import math
from typing import Any, Callable, NamedTuple, Sequence
import weakref

import numpy as np

from ..linalg import spatial as sp
from ..linalg.lanes import flat
from ..value_types import FloatArray, Lane, Lanes, MechanismLike, Ops, Rotation, Vec3
from . import kinematics as kin

#: a chain of three revolutes (spherical_chains.SphericalChain: ``axes``, ``reference``,
#: ``frame_p``, ``frame_c``, ``parent``, ``child``, ``joints``)
Chain = Any


# --- one chain (on lanes: floats for one sample, (N,) arrays for N, Syms when traced) -----

def chain_turn(chain: Chain, rot_p: Rotation | None, rot_c: Rotation | None) -> Rotation:
    """T = frame_p^T R_P^T R_C frame_c from the link rotations of P and C (9-tuples of
    lanes, base frame; None for the base link)."""
    if rot_p is None:
        relative = sp.IDENTITY if rot_c is None else rot_c
    elif rot_c is None:                    # C is the base link
        relative = sp.transpose(rot_p)
    else:
        relative = sp.mat_mat(sp.transpose(rot_p), rot_c)
    return sp.mat_mat(sp.mat_mat(sp.transpose(chain.frame_p), relative), chain.frame_c)


def chain_angles(chain: Chain, turn: Rotation, ops: Ops) -> tuple[Lane, ...]:
    """The three joint coordinates (lanes) of T (a 9-tuple of lanes): the middle one on the
    root nearest its assembled value, each within pi of its assembled value."""
    e1, e2, e3 = chain.axes
    ref = chain.reference
    te3 = sp.mat_vec(turn, e3)
    phi = math.atan2(sp.dot(e1, sp.cross(e2, e3)), sp.dot(e1, e3))
    spread = ops.acos(sp.dot(e1, te3))
    up, down = phi + spread, phi - spread
    q2 = ops.select(abs(_wrap(up - ref[1])) <= abs(_wrap(down - ref[1])), up, down)
    q1 = _turn_angle(e1, _rotate(e2, q2, e3, ops), te3, ops)
    q3 = -_turn_angle(e3, _rotate(e2, -q2, e1, ops), sp.mat_t_vec(turn, e1), ops)
    return tuple(r + _wrap(q - r) for q, r in zip((q1, q2, q3), ref))


def chain_rates(chain: Chain, angles: Sequence[Lane], omega: Vec3,
                ops: Ops) -> tuple[Lane, Lane, Lane]:
    """The three joint rates (lanes) from the angles (chain_angles) and the angular
    velocity of C relative to P in frame_p (3 lanes), by Cramer's rule: at the lock (det 0)
    they are not finite, never an exception."""
    e1, e2, e3 = chain.axes
    w2 = _rotate(e1, angles[0], e2, ops)
    w3 = _rotate(e1, angles[0], _rotate(e2, angles[1], e3, ops), ops)
    cross23 = sp.cross(w2, w3)
    scale = ops.recip(sp.dot(e1, cross23))
    return (sp.dot(omega, cross23) * scale, sp.dot(e1, sp.cross(omega, w3)) * scale,
            sp.dot(e1, sp.cross(w2, omega)) * scale)


def _rotate(axis: Vec3, angle: Lane, v: Vec3, ops: Ops) -> Vec3:
    """Rot(axis, angle) v (Rodrigues) for a constant unit axis and lanes."""
    c, s = ops.cos(angle), ops.sin(angle)
    along = sp.dot(axis, v) * (1.0 - c)
    return tuple(x * c + k * s + a * along for x, k, a in zip(v, sp.cross(axis, v), axis))


def _turn_angle(axis: Vec3, v: Vec3, w: Vec3, ops: Ops) -> Lane:
    """The angle of the rotation about ``axis`` that takes v onto w (at the same angle to
    the axis)."""
    return ops.atan2(sp.dot(sp.cross(v, w), axis),
                     sp.dot(v, w) - sp.dot(v, axis) * sp.dot(w, axis))


def _wrap(x: Lane) -> Lane:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


# --- every chain of a solver form ---------------------------------------------------------

class ReadoutRecord(NamedTuple):
    """The chains' joints at a pose (``stands_for`` order, three per chain, from P to C)."""
    angles: Lanes       # their coordinates
    rates: Lanes        # their rates (empty where no rates were given to the lane code)


class ReadoutPlan:
    """What the read-out of a solver form (a Mechanism whose ``stands_for`` lists its
    chains) walks: per chain (chain, P, C) as link indices (kin.BASE for the base link),
    and the tree edges from the base to every P and C, in the model's order (each after
    its parent's), the only ones whose links it places."""

    def __init__(self, solver: MechanismLike) -> None:
        model = solver.model
        link = {solver.base_link: kin.BASE, **solver.link_index}
        self.chains = [(chain, link[chain.parent], link[chain.child])
                       for chain in solver.stands_for]
        needed: set[int] = set()
        for _, *ends in self.chains:
            for k in ends:
                while k != kin.BASE and k not in needed:
                    needed.add(k)
                    k = model.edges[model.edge_of_link[k]].parent
        self.edges = [e for e in model.edges if e.child in needed]
        self.n_links, self.n_coordinates = model.n_links, model.n_coordinates


def readout_record(plan: ReadoutPlan, q: Sequence[Lane], qdot: Sequence[Lane] | None,
                   ops: Ops) -> ReadoutRecord:
    """The chains' angles and, given the coordinates' rates ``qdot``, their rates at the
    solver form's coordinates ``q`` (lanes): forward kinematics and link twists
    (kinematics.py) of the edges of ``plan`` alone, each edge as its kind places it, so
    every number is the one the whole recursion gives."""
    frames = kin.Frames()
    frames.rot = [None] * plan.n_links
    frames.pos = [None] * plan.n_links
    frames.xi = [None] * plan.n_coordinates
    for e in plan.edges:
        e.kind.place(frames, e, q, ops)
    twists: list[Any] = [None] * plan.n_links
    if qdot is not None:
        for e in plan.edges:
            twists[e.child] = e.kind.child_twist(
                e, frames, None if e.parent == kin.BASE else twists[e.parent], qdot)
    angles: list[Lane] = []
    rates: list[Lane] = []
    for chain, parent, child in plan.chains:
        rot_p = frames.rot[parent] if parent >= 0 else None
        rot_c = frames.rot[child] if child >= 0 else None
        found = chain_angles(chain, chain_turn(chain, rot_p, rot_c), ops)
        angles.extend(found)
        if qdot is None:
            continue
        relative = sp.sub(kin.twist_of(twists, child)[0], kin.twist_of(twists, parent)[0])
        if rot_p is not None:
            relative = sp.mat_t_vec(rot_p, relative)
        omega = sp.mat_t_vec(chain.frame_p, relative)
        rates.extend(chain_rates(chain, found, omega, ops))
    return ReadoutRecord(angles, rates)


# --- the traced read-outs made for a solver form -----------------------------------------

#: a traced read-out: readout(q, qdot) -> ReadoutRecord of floats (lists of floats in)
Readout = Callable[[Sequence[float], Sequence[float]], ReadoutRecord]
#: the backends whose kernels offer a read-out, the fastest first
OFFERING = ('native', 'python')
#: per solver form (held weakly, as kernels.KERNELS holds it), {backend: its read-out}
_OFFERED: 'weakref.WeakKeyDictionary[Any, dict[str, Readout]]' = weakref.WeakKeyDictionary()


def offer(solver: MechanismLike, backend: str, readout: Readout) -> None:
    """Make the traced read-out of ``backend`` ('native' or 'python') of ``solver`` (a
    solver form, kernels.py calls this when it makes its kernels) the one its
    JointReadout uses, unless a faster one is there."""
    _OFFERED.setdefault(solver, {})[backend] = readout


def offered(solver: MechanismLike) -> tuple[Readout | None, bool]:
    """(the fastest read-out offered for ``solver`` or None, whether it is the fastest
    there can be)."""
    made = _OFFERED.get(solver) or {}
    for backend in OFFERING:
        if backend in made:
            return made[backend], backend == OFFERING[0]
    return None, False


class JointReadout:
    """Positions and rates of ``mechanism.joints`` from the coordinates of its solver form
    (``mechanism.solver_mechanism``): the joints it kept are copied, the chains' angles read
    back from the link rotations (module docstring)."""

    def __init__(self, mechanism: MechanismLike, solver: MechanismLike) -> None:
        kept = [(k, solver.joint_index[name]) for k, name in enumerate(mechanism.joints)
                if name in solver.joint_index]
        self.kept_joints = np.array([k for k, _ in kept], dtype=np.intp)
        self.kept_coordinates = np.array([c for _, c in kept], dtype=np.intp)
        self.chain_columns = np.array([mechanism.joint_index[j] for chain in solver.stands_for
                                       for j in chain.joints], dtype=np.intp)
        self.n_joints = len(mechanism.joints)
        self.plan = ReadoutPlan(solver)
        # one sample: each joint's value in (coordinates or rates, then the chains' values)
        order = np.zeros(self.n_joints, dtype=np.intp)
        order[self.kept_joints] = self.kept_coordinates
        order[self.chain_columns] = solver.n_coordinates + np.arange(len(self.chain_columns))
        self.order = order
        self.solver = solver             # the key its traced read-outs are offered under
        self._zeros = [0.0] * solver.n_coordinates
        self._fastest: Readout | None = None

    def __call__(self, coordinates: Any,
                 rates: Any = None) -> tuple[FloatArray, FloatArray | None]:
        """(positions, rates or None): (n_joints,) for coordinates (n,), (N, n_joints) for
        (N, n); ``rates`` the coordinates' rates, the same shape."""
        q = np.asarray(coordinates, dtype=float)
        if q.ndim != 1:
            return self._many(np.atleast_2d(q), rates)
        qdot = None if rates is None else np.asarray(rates, dtype=float)
        if qdot is not None and qdot.ndim != 1:
            qdot = np.atleast_2d(qdot)[0]        # (1, n) rates of one sample
        readout = self._fastest
        if readout is None:
            readout, fastest = offered(self.solver)
            if fastest:
                self._fastest = readout
        if readout is not None:
            angles, chain_rates = readout(q.tolist(),
                                          self._zeros if qdot is None else qdot.tolist())
        else:
            angles, chain_rates = readout_record(self.plan, q.tolist(), None if qdot is None
                                                 else qdot.tolist(), sp.ScalarOps)
        positions = np.concatenate((q, angles))[self.order]
        if qdot is None:
            return positions, None
        return positions, np.concatenate((qdot, chain_rates))[self.order]

    def _many(self, q: FloatArray, rates: Any) -> tuple[FloatArray, FloatArray | None]:
        """N samples: the lane code on (N,) arrays (spatial.ArrayOps)."""
        qdot = None if rates is None else np.atleast_2d(np.asarray(rates, dtype=float))
        record = readout_record(self.plan, list(q.T), None if qdot is None else list(qdot.T),
                                sp.ArrayOps)
        n, width = len(q), len(self.chain_columns)
        values = flat(record, n)
        positions = np.empty((n, self.n_joints))
        positions[:, self.kept_joints] = q[:, self.kept_coordinates]
        positions[:, self.chain_columns] = values[:, :width]
        if qdot is None:
            return positions, None
        joint_rates = np.empty((n, self.n_joints))
        joint_rates[:, self.kept_joints] = qdot[:, self.kept_coordinates]
        joint_rates[:, self.chain_columns] = values[:, width:]
        return positions, joint_rates
