"""Spherical joints written as three revolute joints through two massless links.

A URDF has no ball joint, so a Stewart platform or a delta robot from a URDF writes each of
its S joints as three revolute joints whose axes meet in one point, through two helper
links without mass. As written, every such chain costs the solver three coordinates, and a
loop it closes six equations. The solver instead takes the chain as the spherical joint it
is (kinematics.py: three closure equations where it closes a loop, one quaternion where the
tree needs it) and reads the three angles back from the pose wherever they are shown. The
torques are the same (the helper links carry no mass); the work is about half.

A chain P -j1- a -j2- b -j3- C qualifies when:

* j1, j2, j3 are revolute and passive (not in active_joints);
* a and b have zero mass and inertia and no joint but these;
* consecutive axes meet at right angles in one point: j1 and j2 in link a, j2 and j3 in
  link b, at the same point of j2's axis;
* at the assembled initial positions the chain is away from its gimbal lock (the first and
  last axes not parallel), so that the joints as written determine the motion there.

Anything else is solved as written. The relative rotation of C in P is, with the joint
frames folded in (:class:`SphericalChain`), the product of three rotations about constant
unit axes e1, e2, e3 (e1 . e2 = e2 . e3 = 0)::

    T = Rot(e1, q1) Rot(e2, q2) Rot(e3, q3)

so (:func:`chain_angles`) e1 . T e3 = cos(q2) e1 . e3 + sin(q2) e1 . (e2 x e3) gives q2 (the
root nearest the assembled angle), then q1 and q3 each turn one known vector onto another.
The angles' rates follow from the relative angular velocity, w = W qdot with W = [e1,
Rot(e1, q1) e2, Rot(e1, q1) Rot(e2, q2) e3] (:func:`chain_rates`).

W is singular where the first and last axes are parallel (the chain's gimbal lock, where
three revolutes as written have no unique angles). The spherical joint has no such pose, so
the torques go on through it; only the angles read back change branch there (the root of
q2 nearest its assembled value is taken: past the lock that is the other one, q1 and q3
half a turn away, the same rotation), and their rates at the lock itself are huge or not
finite (``last_pose`` then raises ``out_of_range``, and the node publishes positions alone).
The angles are read back within pi of their assembled values: where a chain winds on with
the motion (a ball joint on a turning crank), as written they would count the turns.
"""
from dataclasses import dataclass
import math

import numpy as np

from . import spatial as sp

#: cosine below which two axes count as perpendicular, and the distance (times the
#: mechanism's length scale) within which axes count as meeting
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
    axes: tuple          # e1, e2, e3 (frame_p, angles 0), signed as the coordinates turn C
    reference: tuple     # the three joint coordinates at the initial positions


def find_chains(links, base_link, massless, specs, closure_specs, active, positions):
    """The qualifying chains (module docstring) among revolute and prismatic ``specs``
    (JointSpec, link indices into ``links``, -1 the base), with ``positions`` one per spec.

    ``massless``: per link, True for zero mass and inertia. Returns [SphericalChain]."""
    degree = [0] * len(links)
    for spec in list(specs) + list(closure_specs):
        for link in (spec.parent, spec.child):
            if link >= 0:
                degree[link] += 1
    by_link = {}
    for j, spec in enumerate(specs):
        for link in (spec.parent, spec.child):
            by_link.setdefault(link, []).append(j)
    helper = [massless[k] and degree[k] == 2 and len(by_link.get(k, ())) == 2 and
              all(specs[j].kind == 'revolute' and specs[j].name not in active
                  for j in by_link[k]) for k in range(len(links))]
    scale = _length_scale(specs)
    used, chains, taken = set(), [], set()
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
        if chain is None:
            continue
        used |= {a, b}
        taken.add(chain.name)
        chains.append(chain)
    ends = {chain.parent for chain in chains} | {chain.child for chain in chains}
    helpers = {h for chain in chains for h in chain.helpers}
    return [chain for chain in chains if not ends & set(chain.helpers)] \
        if ends & helpers else chains


def _other(spec, link):
    return spec.child if spec.parent == link else spec.parent


def _length_scale(specs):
    lengths = [math.hypot(*xyz) for spec in specs for xyz in (spec.parent_xyz, spec.child_xyz)]
    return max(lengths + [1.0])


def _side(spec, link):
    """(rotation, origin, sign) of ``spec``'s attachment frame on ``link``; sign +1 when the
    joint moves the other link relative to this one by +q."""
    if spec.parent == link:
        return sp.rpy_matrix(spec.parent_rpy), tuple(spec.parent_xyz), 1.0
    return sp.rpy_matrix(spec.child_rpy), tuple(spec.child_xyz), -1.0


def _meeting(r1, o1, axis1, r2, o2, axis2, scale):
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


def _chain(links, base_link, specs, joints, chain_links, positions, scale, names):
    (j1, j2, j3), (p, a, b, c) = joints, chain_links
    r1p, o1p, s1 = _side(specs[j1], p)
    r1a, o1a, _ = _side(specs[j1], a)
    r2a, o2a, s2 = _side(specs[j2], a)
    r2b, o2b, _ = _side(specs[j2], b)
    r3b, o3b, s3 = _side(specs[j3], b)
    r3c, o3c, _ = _side(specs[j3], c)
    axis1, axis2, axis3 = (specs[j].axis for j in joints)
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
    w1 = e1
    w3 = sp.mat_vec(_rotation(e1, e2, e3, reference), e3)
    if math.hypot(*sp.cross(w1, w3)) < MIN_LOCK_DISTANCE:
        return None
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
        centre_p=centre_p, centre_c=centre_c, axes=(e1, e2, e3), reference=reference)


def solver_parameters(params, chains, joints, positions):
    """The parameters (flat, dotted) of the same mechanism with every chain one spherical
    joint: its helper links and joints gone, the spherical joint listed where its first
    joint was, and initial_positions ``positions`` (one per joint of ``joints``, the
    revolute and prismatic ones) without the chains' entries."""
    links = {h for chain in chains for h in chain.helpers}
    chain_of = {j: chain for chain in chains for j in chain.joints}
    out = {key: value for key, value in params.items()
           if not (key.startswith('links.') and key.split('.')[1] in links or
                   key.startswith('joints.') and key.split('.')[1] in chain_of)}
    out['mechanism.links'] = [name for name in params['mechanism.links'] if name not in links]
    out['mechanism.joints'] = [chain_of[name].name if name in chain_of else name
                               for name in params['mechanism.joints']
                               if name not in chain_of or name == chain_of[name].joints[0]]
    out['mechanism.initial_positions'] = [float(x) for name, x in zip(joints, positions)
                                          if name not in chain_of]
    for chain in chains:
        prefix = f'joints.{chain.name}.'
        out.update({prefix + 'type': 'spherical', prefix + 'parent': chain.parent,
                    prefix + 'child': chain.child,
                    prefix + 'parent_xyz': list(chain.centre_p),
                    prefix + 'parent_rpy': list(sp.matrix_rpy(chain.frame_p)),
                    prefix + 'child_xyz': list(chain.centre_c),
                    prefix + 'child_rpy': list(sp.matrix_rpy(chain.frame_c))})
    return out


def initial_turn(chain):
    """T at the chain's initial angles."""
    return _rotation(*chain.axes, chain.reference)


def _rotation(e1, e2, e3, angles):
    rot = sp.IDENTITY
    for axis, angle in zip((e1, e2, e3), angles):
        rot = sp.mat_mat(rot, sp.rotation_about(axis, angle))
    return rot


# --- reading the angles back (numpy, one sample or N at once) ---------------------------

def chain_turn(chain, rot_p, rot_c):
    """T (..., 3, 3) from the link rotations of P and C (..., 3, 3) (base frame; identity
    arrays for the base link)."""
    fp, fc = np.array(chain.frame_p).reshape(3, 3), np.array(chain.frame_c).reshape(3, 3)
    return fp.T @ np.swapaxes(rot_p, -1, -2) @ rot_c @ fc


def chain_angles(chain, turn):
    """The three joint coordinates (..., 3) of T (..., 3, 3): the
    middle one on the root nearest its assembled value, each within pi of it."""
    e1, e2, e3 = (np.array(e) for e in chain.axes)
    ref = np.array(chain.reference)
    te3 = turn @ e3
    c13, b = float(e1 @ e3), float(e1 @ np.cross(e2, e3))
    phi = math.atan2(b, c13)
    spread = np.arccos(np.clip(te3 @ e1, -1.0, 1.0))
    q2 = np.where(np.abs(_wrap(phi + spread - ref[1])) <= np.abs(_wrap(phi - spread - ref[1])),
                  phi + spread, phi - spread)
    v = _rotate(e2, q2, e3)                                     # Rot(e2, q2) e3
    q1 = _turn_angle(e1, v, te3)
    p = _rotate(e2, -q2, e1)                                    # Rot(e2, -q2) e1
    q3 = -_turn_angle(e3, p, np.swapaxes(turn, -1, -2) @ e1)
    angles = np.stack([q1, q2, q3], axis=-1)
    return ref + _wrap(angles - ref)


def chain_rates(chain, angles, omega):
    """The three joint rates (..., 3) from the angles (chain_angles) and the
    angular velocity of C relative to P in frame_p (..., 3)."""
    e1, e2, e3 = (np.array(e) for e in chain.axes)
    q = angles
    w2 = _rotate(e1, q[..., 0], e2)
    w3 = _rotate(e1, q[..., 0], _rotate(e2, q[..., 1], e3))
    w1 = np.broadcast_to(e1, w2.shape)
    # Cramer's rule: at the lock (det 0) the rates are not finite, never an exception
    with np.errstate(divide='ignore', invalid='ignore'):
        det = np.sum(w1 * np.cross(w2, w3), axis=-1)
        return np.stack([np.sum(omega * np.cross(w2, w3), axis=-1),
                         np.sum(w1 * np.cross(omega, w3), axis=-1),
                         np.sum(w1 * np.cross(w2, omega), axis=-1)], axis=-1) / det[..., None]


def _rotate(axis, angle, v):
    """Rot(axis, angle) v for (...,) angles and a constant or (..., 3) v (Rodrigues)."""
    angle = np.asarray(angle)[..., None]
    v = np.broadcast_to(v, angle.shape[:-1] + (3,))
    k = np.broadcast_to(axis, v.shape)
    return (v * np.cos(angle) + np.cross(k, v) * np.sin(angle) +
            k * (v @ np.asarray(axis))[..., None] * (1.0 - np.cos(angle)))


def _turn_angle(axis, v, w):
    """The angle of the rotation about ``axis`` that takes v onto w (both (..., 3), at the
    same angle to the axis)."""
    axis = np.asarray(axis)
    sine = np.cross(v, w) @ axis
    cosine = np.sum(v * w, axis=-1) - (v @ axis) * (w @ axis)
    return np.arctan2(sine, cosine)


def _wrap(x):
    return (x + np.pi) % (2.0 * np.pi) - np.pi


# --- the joints as written, from the solver's coordinates --------------------------------

class JointReadout:
    """Positions and rates of ``mechanism.joints`` from the coordinates of its solver form
    (``mechanism.solver_mechanism``): the joints it kept are copied, the chains' angles read
    back from the link rotations (numpy; one sample on floats, N on (N,) lanes)."""

    def __init__(self, mechanism, solver):
        from .kinematics import BASE
        kept = [(k, solver.joint_index[name]) for k, name in enumerate(mechanism.joints)
                if name in solver.joint_index]
        self.kept_joints = [k for k, _ in kept]
        self.kept_coordinates = [c for _, c in kept]
        link = {solver.base_link: BASE, **solver.link_index}
        self.chains = [(chain, [mechanism.joint_index[j] for j in chain.joints],
                        link[chain.parent], link[chain.child])
                       for chain in mechanism.spherical_chains]
        self.n_joints = len(mechanism.joints)
        self.model = solver.model

    def __call__(self, coordinates, rates=None):
        """(positions, rates or None): (n_joints,) for coordinates (n,), (N, n_joints) for
        (N, n); ``rates`` the coordinates' rates, the same shape."""
        from . import kinematics as kin
        q = np.asarray(coordinates, dtype=float)
        single = q.ndim == 1
        q = np.atleast_2d(q)
        n = len(q)
        positions = np.empty((n, self.n_joints))
        positions[:, self.kept_joints] = q[:, self.kept_coordinates]
        ops, lanes = ((sp.ScalarOps, q[0].tolist()) if single else
                      (sp.ArrayOps, [q[:, j] for j in range(q.shape[1])]))
        frames = kin.forward_kinematics(self.model, lanes, ops)
        twists = qdot = None
        if rates is not None:
            qdot = np.atleast_2d(np.asarray(rates, dtype=float))
            twists = kin.link_twists(self.model, frames, qdot[0].tolist() if single else
                                     [qdot[:, j] for j in range(qdot.shape[1])])
            out_rates = np.empty((n, self.n_joints))
            out_rates[:, self.kept_joints] = qdot[:, self.kept_coordinates]
        for chain, columns, parent, child in self.chains:
            rot_p, rot_c = _rotation_of(frames, parent, n), _rotation_of(frames, child, n)
            angles = chain_angles(chain, chain_turn(chain, rot_p, rot_c))
            positions[:, columns] = angles
            if twists is not None:
                relative = (_vector(kin.twist_of(twists, child)[0], n) -
                            _vector(kin.twist_of(twists, parent)[0], n))
                frame = np.swapaxes(rot_p, -1, -2) @ relative[..., None]   # in P
                omega = np.array(chain.frame_p).reshape(3, 3).T @ frame
                out_rates[:, columns] = chain_rates(chain, angles, omega[..., 0])
        if single:
            return positions[0], None if rates is None else out_rates[0]
        return positions, None if rates is None else out_rates


def _rotation_of(frames, link, n):
    """A link's rotation (base frame) as (n, 3, 3); the identity for the base link."""
    if link < 0:
        return np.broadcast_to(np.eye(3), (n, 3, 3))
    return np.stack([np.broadcast_to(np.asarray(x, dtype=float), (n,))
                     for x in frames.rot[link]], axis=-1).reshape(n, 3, 3)


def _vector(v, n):
    return np.stack([np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in v], axis=-1)
