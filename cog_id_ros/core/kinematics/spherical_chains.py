"""Spherical joints written as three revolute joints through two massless links.

A URDF has no ball joint, so a Stewart platform or a delta robot from a URDF writes each of
its S joints as three revolute joints whose axes meet in one point, through two helper
links without mass. As written, every such chain costs the solver three coordinates, and a
loop it closes six equations. The solver instead takes the chain as the spherical joint it
is (kinematics.py: three closure equations where it closes a loop, one quaternion where the
tree needs it) and reads the three angles back from the pose wherever they are shown. The
torques are the same (the helper links carry no mass); the work is about half.

A chain P -j1- a -j2- b -j3- C qualifies when:

* j1, j2, j3 are revolute and passive (not in active_joints, not locked);
* a and b have zero mass and inertia and no joint but these;
* consecutive axes meet at right angles in one point: j1 and j2 in link a, j2 and j3 in
  link b, at the same point of j2's axis;
* at the assembled initial positions the chain is away from its gimbal lock (the first and
  last axes not parallel), so that the joints as written determine the motion there.

Anything else is solved as written. The relative rotation of C in P is, with the joint
frames folded in (:class:`SphericalChain`), the product of three rotations about constant
unit axes e1, e2, e3 (e1 . e2 = e2 . e3 = 0)::

    T = Rot(e1, q1) Rot(e2, q2) Rot(e3, q3)

so (:func:`chain_angles`, joint_readout.py) e1 . T e3 = cos(q2) e1 . e3 + sin(q2) e1 . (e2
x e3) gives q2 (the root nearest the assembled angle), then q1 and q3 each turn one known
vector onto another. The angles' rates follow from the relative angular velocity, w = W qdot
with W = [e1, Rot(e1, q1) e2, Rot(e1, q1) Rot(e2, q2) e3] (:func:`chain_rates`).

W is singular where the first and last axes are parallel (the chain's gimbal lock, where
three revolutes as written have no unique angles). The spherical joint has no such pose, so
the torques go on through it; only the angles read back change branch there (the root of
q2 nearest its assembled value is taken: past the lock that is the other one, q1 and q3
half a turn away, the same rotation), and their rates at the lock itself are huge or not
finite (``last_pose`` then raises ``out_of_range``, and the node publishes positions alone).
The angles are read back within pi of their assembled values: where a chain winds on with
the motion (a ball joint on a turning crank), as written they would count the turns.
``Mechanism.joints_at`` reads them back (joint_readout.JointReadout): from the links the
chains need alone, by the compiled or traced read-out kernel where a solver has made one.
"""
from dataclasses import dataclass
import math
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ..linalg import spatial as sp
from ..value_types import FloatArray, MechanismLike, Rotation, Vec3
from . import kinematics as kin
from .joint_readout import JointReadout, chain_angles, chain_rates, chain_turn
from .joints import Revolute, Spherical
from .parameters import massless, split_owner

#: (with the read-out of the joints as written, joint_readout.py, used from here)
__all__ = ['JointReadout', 'SphericalChain', 'chain_angles', 'chain_rates', 'chain_turn',
           'chains_of', 'find_chains', 'solver_parameters', 'with_chain_starts']

#: cosine below which two axes count as perpendicular, and the distance (times the
#: mechanism's largest joint offset, at least 1 m) within which axes count as meeting
PERPENDICULAR = 1e-6
MEETING = 1e-9
#: |w1 x w3| at the assembled pose below which a chain is left as written (near its lock)
MIN_LOCK_DISTANCE = 1e-3


@dataclass
class SphericalChain:
    """Three revolute joints that are one spherical joint (module docstring).

    Rotations and points are constants of the chain, in the frames named: ``frame_p``
    (in P) and ``frame_c`` (in C) are the spherical joint's attachment frames, whose
    relative rotation is T; ``centre_p`` and ``centre_c`` the centre in P and in C.
    """
    name: str            # the spherical joint the solver uses instead
    joints: tuple        # the three revolute joints, from P to C (names)
    helpers: tuple       # the two massless links (names)
    parent: str          # P and C (link names; P may be the base link)
    child: str
    frame_p: tuple
    frame_c: tuple
    centre_p: tuple
    centre_c: tuple
    axes: tuple[Vec3, Vec3, Vec3]  # e1, e2, e3 (frame_p, angles 0), signed as the coordinates
    #                                turn C
    reference: tuple     # the three joint coordinates at the initial positions
    lock_distance: float = 1.0   # |e1 x T e3| there: 0 at the gimbal lock


def chains_of(mechanism: MechanismLike, near_lock: bool = False) -> list[SphericalChain]:
    """:func:`find_chains` of a Mechanism at its assembled pose."""
    m = mechanism
    return find_chains(
        m.links, m.base_link,
        [massless(mass, inertia) for mass, inertia in zip(m.link_mass, m.link_inertia)],
        m.joint_specs, m.closure_specs, set(m.active_joints) | set(m.locked_joints),
        m.assembled_positions,
        max(1.0, m.attachment_scale), near_lock)


def find_chains(links: Sequence[str], base_link: str, massless: Sequence[bool],
                specs: Sequence[kin.JointSpec], closure_specs: Sequence[kin.JointSpec],
                active: set[str], positions: Sequence[float], scale: float,
                near_lock: bool = False) -> list[SphericalChain]:
    """The qualifying chains (module docstring) among revolute and prismatic ``specs``
    (JointSpec, link indices into ``links``, -1 the base), with ``positions`` one per spec.

    ``massless``: per link, True for zero mass and inertia; ``scale`` (m) the length that
    MEETING is a fraction of. Returns [SphericalChain]. ``near_lock``: also those too near
    their gimbal lock to qualify (for messages)."""
    degree = [0] * len(links)
    for spec in list(specs) + list(closure_specs):
        for link in (spec.parent, spec.child):
            if link >= 0:
                degree[link] += 1
    by_link: dict[int, list[int]] = {}
    for j, spec in enumerate(specs):
        for link in (spec.parent, spec.child):
            by_link.setdefault(link, []).append(j)
    helper = [massless[k] and degree[k] == 2 and len(by_link.get(k, ())) == 2 and
              all(specs[j].kind.name == Revolute.name and specs[j].name not in active
                  for j in by_link[k]) for k in range(len(links))]
    used: set[int] = set()
    chains: list[SphericalChain] = []
    taken: set[str] = set()
    names = {spec.name for spec in list(specs) + list(closure_specs)}
    for j2, middle in enumerate(specs):
        a, b = middle.parent, middle.child
        if a < 0 or b < 0 or not (helper[a] and helper[b]) or {a, b} & used:
            continue
        j1 = next(j for j in by_link[a] if j != j2)
        j3 = next(j for j in by_link[b] if j != j2)
        p, c = _other(specs[j1], a), _other(specs[j3], b)
        if j1 == j3 or p == c or {p, c} & {a, b} or {p, c} & used:
            continue
        chain = _chain(links, base_link, specs, (j1, j2, j3), (p, a, b, c), positions, scale,
                       names | taken)
        if chain is None or chain.lock_distance < MIN_LOCK_DISTANCE and not near_lock:
            continue
        used |= {a, b}
        taken.add(chain.name)
        chains.append(chain)
    # a chain whose helper is another chain's end link is not one joint: left as written
    ends = {chain.parent for chain in chains} | {chain.child for chain in chains}
    return [chain for chain in chains if not ends & set(chain.helpers)]


def _other(spec: kin.JointSpec, link: int) -> int:
    return spec.child if spec.parent == link else spec.parent


def _side(spec: kin.JointSpec, link: int) -> tuple[Rotation, Vec3, float]:
    """(rotation, origin, sign) of ``spec``'s attachment frame on ``link``; sign +1 when the
    joint moves the other link relative to this one by +q."""
    if spec.parent == link:
        return sp.rpy_matrix(spec.parent_rpy), tuple(spec.parent_xyz), 1.0
    return sp.rpy_matrix(spec.child_rpy), tuple(spec.child_xyz), -1.0


def _meeting(r1: Rotation, o1: Vec3 | FloatArray, axis1: Vec3, r2: Rotation,
             o2: Vec3 | FloatArray, axis2: Vec3, scale: float) -> tuple[float, float] | None:
    """Distances along the two lines (o1 + s d1, o2 + t d2, d = r axis) to where they meet
    at right angles, or None."""
    d1, d2 = np.array(sp.mat_vec(r1, axis1)), np.array(sp.mat_vec(r2, axis2))
    if abs(float(d1 @ d2)) > PERPENDICULAR:
        return None
    o1, o2 = np.array(o1), np.array(o2)
    # perpendicular unit directions: the nearest points are s = d1.(o2-o1), t = -d2.(o2-o1)
    s, t = float(d1 @ (o2 - o1)), float(-d2 @ (o2 - o1))
    if np.linalg.norm(o1 + s * d1 - (o2 + t * d2)) > MEETING * scale:
        return None
    return s, t


def _chain(links: Sequence[str], base_link: str, specs: Sequence[kin.JointSpec],
           joints: tuple[int, int, int], chain_links: tuple[int, int, int, int],
           positions: Sequence[float], scale: float, names: set[str]) -> SphericalChain | None:
    (j1, j2, j3), (p, a, b, c) = joints, chain_links
    r1p, o1p, s1 = _side(specs[j1], p)
    r1a, o1a, _ = _side(specs[j1], a)
    r2a, o2a, s2 = _side(specs[j2], a)
    r2b, o2b, _ = _side(specs[j2], b)
    r3b, o3b, s3 = _side(specs[j3], b)
    r3c, o3c, _ = _side(specs[j3], c)
    axis1, axis2, axis3 = (specs[j].kind.axis for j in joints)
    in_a = _meeting(r1a, o1a, axis1, r2a, o2a, axis2, scale)
    in_b = _meeting(r2b, o2b, axis2, r3b, o3b, axis3, scale)
    if in_a is None or in_b is None or abs(in_a[1] - in_b[0]) > MEETING * scale:
        return None
    m1 = sp.mat_mat(sp.transpose(r1a), r2a)
    m2 = sp.mat_mat(sp.transpose(r2b), r3b)
    e1 = sp.scale(axis1, s1)
    e2 = sp.mat_vec(m1, sp.scale(axis2, s2))
    e3 = sp.mat_vec(sp.mat_mat(m1, m2), sp.scale(axis3, s3))
    reference = tuple(positions[j] for j in joints)
    lock_distance = math.hypot(*sp.cross(e1, sp.mat_vec(_rotation(e1, e2, e3, reference), e3)))
    centre_p = sp.add(o1p, sp.mat_vec(r1p, sp.scale(axis1, in_a[0])))
    centre_c = sp.add(o3c, sp.mat_vec(r3c, sp.scale(axis3, in_b[1])))
    name = f'{specs[j1].name}_to_{specs[j3].name}'
    while name in names:
        name += '_'
    parent_name, child_name = (base_link if k < 0 else links[k] for k in (p, c))
    # the frames as the solver reads them back from their roll, pitch and yaw
    frame_c = sp.mat_mat(r3c, sp.transpose(sp.mat_mat(m1, m2)))
    return SphericalChain(
        name=name, joints=tuple(specs[j].name for j in joints),
        helpers=(links[a], links[b]), parent=parent_name, child=child_name,
        frame_p=sp.rpy_matrix(sp.matrix_rpy(r1p)), frame_c=sp.rpy_matrix(sp.matrix_rpy(frame_c)),
        centre_p=centre_p, centre_c=centre_c, axes=(e1, e2, e3), reference=reference,
        lock_distance=lock_distance)


def solver_parameters(params: Mapping[str, Any], chains: Sequence[SphericalChain],
                      joints: Sequence[str], positions: Iterable[float]) -> dict[str, Any]:
    """The parameters (flat, dotted) of the same mechanism with every chain one spherical
    joint: its helper links and joints gone, the spherical joint listed where its first
    joint was, and initial_positions ``positions`` (one per joint of ``joints``, the
    revolute and prismatic ones) without the chains' entries."""
    links = {h for chain in chains for h in chain.helpers}
    chain_of = {j: chain for chain in chains for j in chain.joints}
    # (names may hold '.': a key's owner is the longest name it starts with)
    out = {key: value for key, value in params.items()
           if not (key.startswith('links.') and split_owner(
                       key[len('links.'):], params['mechanism.links'])[0] in links or
                   key.startswith('joints.') and split_owner(
                       key[len('joints.'):], params['mechanism.joints'])[0] in chain_of)}
    out['mechanism.links'] = [name for name in params['mechanism.links'] if name not in links]
    out['mechanism.joints'] = [chain_of[name].name if name in chain_of else name
                               for name in params['mechanism.joints']
                               if name not in chain_of or name == chain_of[name].joints[0]]
    out['mechanism.initial_positions'] = [float(x) for name, x in zip(joints, positions)
                                          if name not in chain_of]
    for chain in chains:
        prefix = f'joints.{chain.name}.'
        out.update({prefix + 'type': Spherical.name, prefix + 'parent': chain.parent,
                    prefix + 'child': chain.child,
                    prefix + 'parent_xyz': list(chain.centre_p),
                    prefix + 'parent_rpy': list(sp.matrix_rpy(chain.frame_p)),
                    prefix + 'child_xyz': list(chain.centre_c),
                    prefix + 'child_rpy': list(sp.matrix_rpy(chain.frame_c))})
    return out


def with_chain_starts(mechanism: MechanismLike, start: list[float]) -> list[float]:
    """The start of assembly ``start`` of a mechanism that is another's solver form, with
    the quaternion of every spherical tree joint that stands for a chain of three
    revolutes (``mechanism.stands_for``) at the chain's initial angles T."""
    chains: dict[str, SphericalChain] = {chain.name: chain for chain in mechanism.stands_for}
    for e in mechanism.model.edges:
        chain = chains.get(e.name)     # the spherical joint's edge: it has the chain's name
        if chain is None:
            continue
        turn = _rotation(*chain.axes, chain.reference)
        if e.child != mechanism.link_index.get(chain.child, kin.BASE):   # reached from C
            turn = sp.transpose(turn)
        for c, value in zip(e.coords, sp.rotation_quaternion(turn)):
            start[c] = value
    return start


def _rotation(e1: Vec3, e2: Vec3, e3: Vec3, angles: Iterable[float]) -> Rotation:
    rot = sp.IDENTITY
    for axis, angle in zip((e1, e2, e3), angles):
        rot = sp.mat_mat(rot, sp.rotation_about(axis, angle))
    return rot
