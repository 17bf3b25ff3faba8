"""Spanning tree, forward kinematics and the velocity / acceleration recursions over it.

The link-joint graph is cut into a spanning tree rooted at the base link (breadth-first, in
the order joints are listed); every other joint closes a loop. A tree joint may be written in
either direction: the edge remembers a sign so that the joint coordinate keeps its meaning
(motion of the joint's child attachment frame relative to its parent attachment frame).

Every revolute or prismatic joint, tree or loop-closing, has a coordinate of the model; the
loop-closing ones are tied to the others by the closure equations (closure.py). Spherical,
universal and fixed joints have no coordinate of their own: they close loops where they can
(their closure equations hold the two attachment frames together, closure.py), and enter
the tree only where a link cannot be reached otherwise (fixed first, then universal, then
spherical), with *hidden* coordinates that no output shows:

* fixed: none, a constant transform;
* universal: two angles, about ``axis`` and then ``axis2``, through a massless virtual link
  (the cross); the two axes stay perpendicular, so the pair never locks;
* spherical: a quaternion (w, x, y, z), the rotation of the child attachment frame in the
  parent attachment frame, R = R_h(q) / |q|^2, whose rates give the angular velocity
  2 G(q) qdot / |q|^2 (no angle triple, so no gimbal lock anywhere); one extra closure
  equation, |q|^2 = 1, takes up the fourth coordinate (a ``unit`` constraint).

Model coordinates are the mechanism's revolute and prismatic joints in order, then the hidden
ones; a velocity basis, a Newton increment or a step limit has one entry per coordinate.
"""
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from . import spatial as sp
from .errors import MechanismConfigError

BASE = -1
ZERO3 = (0.0, 0.0, 0.0)


#: joint types with one coordinate, and those without one of their own (kinematics docstring)
COORDINATE_TYPES = ('revolute', 'prismatic')
CLOSURE_TYPES = ('spherical', 'universal', 'fixed')
#: which of them enters the tree first where a link is out of reach otherwise (fewest
#: hidden coordinates first)
TREE_PREFERENCE = ('fixed', 'universal', 'spherical')


@dataclass
class JointSpec:
    name: str
    revolute: bool
    parent: int          # link index, BASE for the base link
    child: int
    parent_xyz: tuple
    parent_rpy: tuple
    child_xyz: tuple
    child_rpy: tuple
    axis: tuple          # unit vector in the joint frame (universal: parent attachment frame)
    kind: str = ''       # one of COORDINATE_TYPES or CLOSURE_TYPES ('' : from ``revolute``)
    axis2: tuple = ()    # universal: unit second axis in the child attachment frame

    def __post_init__(self):
        if not self.kind:
            self.kind = 'revolute' if self.revolute else 'prismatic'


@dataclass
class TreeEdge:
    """A tree joint oriented from tree parent to tree child, with its constants folded.

    The child link's pose in the parent link frame is L(q) = A M(sign q) B, where A and B
    are the attachment frames (A = parent side of the tree edge, B the inverse of the child
    side) and M the joint motion. For a revolute joint with K = skew(axis):
      R_L = r0 + sin(q) r1 + (1 - cos q) r2,  t_L = t0 + sin(q) t1 + (1 - cos q) t2
    and for a prismatic one R_L = r0, t_L = t0 + q t1. The sign is folded into r1, t1.
    A fixed edge (``kind`` 'fixed') is r0, t0 alone; a spherical one ('ball') is
    A R(q) B with the quaternion coordinates ``coords`` (r1 = B's rotation, t1 = B's
    translation). ``joint`` is the coordinate of a revolute or prismatic edge (None else).
    """
    joint: 'int | None'
    parent: int
    child: int
    sign: float
    revolute: bool
    r0: tuple
    r1: tuple
    r2: tuple
    t0: tuple
    t1: tuple
    t2: tuple
    axis_p: tuple        # joint axis in the tree-parent link frame
    origin_p: tuple      # a point of the joint axis in the tree-parent link frame
    kind: str = ''       # 'revolute', 'prismatic', 'fixed' or 'ball'
    coords: tuple = ()   # the coordinates of the edge (one, none, or a quaternion's four)
    name: str = ''       # the declared joint it comes from

    def __post_init__(self):
        if not self.kind:
            self.kind = 'revolute' if self.revolute else 'prismatic'
        if not self.coords and self.joint is not None:
            self.coords = (self.joint,)


@dataclass
class LoopJoint:
    """A loop-closing joint between its declared parent and child links. ``joint`` is its
    coordinate, None for a spherical, universal or fixed joint (``kind``)."""
    joint: 'int | None'
    parent: int
    child: int
    revolute: bool
    d0: tuple            # R_pj, R_pj K, R_pj K^2: parent attachment rotation after motion q is
    d1: tuple            # d0 + sin(q) d1 + (1 - cos q) d2 (revolute) or d0 (prismatic)
    d2: tuple
    t_pj: tuple
    axis_p: tuple        # joint axis in the parent link frame
    r_cj: tuple
    t_cj: tuple
    cycle: list = field(default_factory=list)   # (tree joint, +1/-1): twist_child - twist_parent
    kind: str = 'revolute'
    name: str = ''
    axis_c: tuple = ()   # universal: the second axis in the child link frame


class KinematicModel:
    """The spanning tree and the loop-closing joints of a mechanism, ready to evaluate."""

    def __init__(self, link_names, joints, closures=()):
        self.link_names = list(link_names)
        self.joints = list(joints)            # joints with a coordinate
        self.closures = list(closures)        # spherical, universal, fixed
        self.n_links = len(self.link_names)   # grows by a virtual link per tree universal joint
        self.n_joints = len(self.joints)      # the declared joints with a coordinate
        #: per model coordinate: 'revolute', 'prismatic' or 'quaternion', its name (a hidden
        #: one: '<joint>.<part>') and the declared joint it belongs to
        self.coordinate_kinds = [spec.kind for spec in self.joints]
        self.coordinate_names = [spec.name for spec in self.joints]
        self.coordinate_joints = [spec.name for spec in self.joints]
        #: the hidden coordinates' values where their attachment frames coincide
        self.hidden_start = []
        self.edges, self.loops, self.units = [], [], []
        self.edge_of_link = [None] * self.n_links
        self._build_tree()
        self.n_coordinates = len(self.coordinate_kinds)
        #: every constraint of the closure equations: the loops, then a unit quaternion each
        self.constraints = self.loops + self.units
        #: per coordinate, the indices of the constraints whose equations it enters
        self.loops_of_joint = [[] for _ in range(self.n_coordinates)]
        for li, lp in enumerate(self.constraints):
            for j in loop_columns(lp):
                self.loops_of_joint[j].append(li)
        self._orders = {}

    def _hidden(self, spec, parts, kind, start):
        """New hidden coordinates of ``spec`` (one per part); their indices."""
        first = len(self.coordinate_kinds)
        for part, value in zip(parts, start):
            self.coordinate_kinds.append(kind)
            self.coordinate_names.append(f'{spec.name}.{part}')
            self.coordinate_joints.append(spec.name)
            self.hidden_start.append(value)
        return tuple(range(first, first + len(parts)))

    def _virtual_link(self, name):
        self.link_names.append(name)
        self.edge_of_link.append(None)
        self.n_links += 1
        return self.n_links - 1

    def _build_tree(self):
        """Breadth-first from the base over the joints incident to each link, in the listed
        order; then each loop-closing joint's cycle from the tree paths of its two links.

        Linear in the number of joints plus the total length of the loop cycles: every link
        keeps only its tree edge (no copied paths), and a cycle is found by walking up from
        both links to their nearest common ancestor.
        """
        incident = {}
        for j, spec in enumerate(self.joints):
            incident.setdefault(spec.parent, []).append(j)
            incident.setdefault(spec.child, []).append(j)
        in_tree = [False] * self.n_joints
        closure_in_tree = [False] * len(self.closures)
        up = {BASE: None}       # link -> (tree edge, tree parent link)
        depth = {BASE: 0}
        queue = deque([BASE])

        def grow(edge, link, other):
            self.edge_of_link[other] = len(self.edges)
            up[other] = (len(self.edges), link)
            depth[other] = depth[link] + 1
            self.edges.append(edge)

        while True:
            while queue:
                link = queue.popleft()
                for j in incident.get(link, ()):
                    if in_tree[j]:
                        continue
                    spec = self.joints[j]
                    other = spec.child if spec.parent == link else spec.parent
                    if other in up:
                        continue
                    grow(_tree_edge(j, spec, link, other), link, other)
                    in_tree[j] = True
                    queue.append(other)
            # links out of reach of revolute and prismatic joints: through a joint without a
            # coordinate of its own (the one with fewest hidden coordinates, first listed)
            reaching = [(TREE_PREFERENCE.index(spec.kind), k) for k, spec in
                        enumerate(self.closures) if not closure_in_tree[k] and
                        (spec.parent in up) != (spec.child in up)]
            if not reaching:
                break
            k = min(reaching)[1]
            closure_in_tree[k] = True
            queue.append(self._tree_closure(self.closures[k], up, grow))
        missing = [self.link_names[k] for k in range(self.n_links) if k not in up]
        if missing:
            raise MechanismConfigError(
                'mechanism.links',
                f"link '{missing[0]}' is not connected to the base link by any chain of joints")
        closing = [(j, spec) for j, spec in enumerate(self.joints) if not in_tree[j]]
        closing += [(None, spec) for k, spec in enumerate(self.closures)
                    if not closure_in_tree[k]]
        for j, spec in closing:
            loop = _loop_joint(j, spec)
            on_child, on_parent = _paths_below_common_ancestor(up, depth, spec.child,
                                                               spec.parent)
            loop.cycle = self._cycle(on_child, 1.0) + self._cycle(on_parent, -1.0)
            self.loops.append(loop)
        self.tree_joints = [e.joint for e in self.edges if e.joint is not None]
        self.loop_joints = [lp.joint for lp in self.loops if lp.joint is not None]

    def start(self, positions):
        """Every coordinate at the start of assembly: ``positions`` (one per joint), the
        universal joints' angles at 0 (their attachment frames coincide), and each spherical
        tree joint turned so that the link it reaches puts its other joint centres where
        their partners are (a least-squares fit of the rotation, :func:`_fitted_rotation`);
        with fewer than two such centres, its frame parallel to the base frame."""
        q = list(positions) + list(self.hidden_start)
        for e in self.edges:
            if e.kind != 'ball':
                continue
            frames = forward_kinematics(self, q, sp.ScalarOps)
            parent = frames.rot[e.parent] if e.parent != BASE else sp.IDENTITY
            child = self._fitted_rotation(e, frames) or sp.IDENTITY
            turn = sp.mat_mat(sp.mat_mat(sp.transpose(e.r0), sp.transpose(parent)),
                              sp.mat_mat(child, sp.transpose(e.r1)))
            for c, value in zip(e.coords, sp.rotation_quaternion(turn)):
                q[c] = value
        return q

    def _fitted_rotation(self, e, frames):
        """The rotation of ``e``'s child link that best carries the centres of its other
        joints (revolute, spherical, universal, fixed: their two attachment origins
        coincide) to their partners' centres on links outside its subtree, about the ball's
        centre (Kabsch); None with fewer than two independent directions."""
        outside = self._outside(e.child)
        centre = point_to_base(frames, e.parent, e.origin_p)
        own = sp.mat_t_vec(e.r1, sp.scale(e.t1, -1.0))      # the ball's centre on the child
        pairs = []
        for spec in self.joints + self.closures:
            if spec.kind == 'prismatic' or spec.name == e.name:
                continue
            for near, far, near_xyz, far_xyz in ((spec.child, spec.parent, spec.child_xyz,
                                                  spec.parent_xyz),
                                                 (spec.parent, spec.child, spec.parent_xyz,
                                                  spec.child_xyz)):
                if near == e.child and far in outside:
                    pairs.append((sp.sub(near_xyz, own),
                                  sp.sub(point_to_base(frames, far, far_xyz), centre)))
        if len(pairs) < 2:
            return None
        u = np.array([a for a, _ in pairs])
        v = np.array([b for _, b in pairs])
        left, values, right = np.linalg.svd(u.T @ v)
        if values[1] <= 1e-9 * max(values[0], 1e-300):
            return None
        d = np.sign(np.linalg.det(right.T @ left.T)) or 1.0
        rotation = right.T @ np.diag([1.0, 1.0, d]) @ left.T
        return tuple(float(x) for x in rotation.ravel())

    def _outside(self, link):
        """The links (and the base) not in the subtree of ``link``."""
        out = {BASE}
        for k in range(self.n_links):
            j = k
            while j != BASE and j != link:
                index = self.edge_of_link[j]
                j = self.edges[index].parent
            if j == BASE:
                out.add(k)
        return out

    def _cycle(self, path, sign):
        """(coordinate, sign) of every coordinate of the tree edges on ``path``."""
        return [(c, sign) for e in path for c in self.edges[e].coords]

    def _tree_closure(self, spec, up, grow):
        """Put a spherical, universal or fixed joint into the tree (from its end that is
        already reached to the other); returns the link it reaches."""
        if spec.parent in up:
            link, other, near, far = spec.parent, spec.child, 'parent', 'child'
        else:
            link, other, near, far = spec.child, spec.parent, 'child', 'parent'
        if spec.kind == 'universal':         # two revolutes through a massless cross
            cross = self._virtual_link(f'{spec.name}.cross')
            first, second = self._hidden(spec, ('axis', 'axis2'), 'revolute', (0.0, 0.0))
            outer = JointSpec(spec.name, True, spec.parent, cross, spec.parent_xyz,
                              spec.parent_rpy, ZERO3, ZERO3, spec.axis)
            inner = JointSpec(spec.name, True, cross, spec.child, ZERO3, ZERO3,
                              spec.child_xyz, spec.child_rpy, spec.axis2)
            hops = ((first, outer, cross), (second, inner, other)) if near == 'parent' else \
                ((second, inner, cross), (first, outer, other))
            for coordinate, half, ahead in hops:
                grow(_tree_edge(coordinate, half, link, ahead), link, ahead)
                link = ahead
            return other
        a = _attachment(spec, near)
        b = sp.inverse_transform(*_attachment(spec, far))
        if spec.kind == 'fixed':
            r0, t0 = sp.compose(a, b)
            edge = TreeEdge(None, link, other, 1.0, False, r0, sp.IDENTITY, sp.IDENTITY, t0,
                            ZERO3, ZERO3, ZERO3, a[1], kind='fixed', name=spec.name)
        else:                                # spherical: a quaternion
            coords = self._hidden(spec, ('w', 'x', 'y', 'z'), 'quaternion',
                                  (1.0, 0.0, 0.0, 0.0))
            edge = TreeEdge(None, link, other, 1.0, False, a[0], b[0], sp.IDENTITY, a[1],
                            b[1], ZERO3, ZERO3, a[1], kind='ball', coords=coords,
                            name=spec.name)
            unit = LoopJoint(None, link, other, False, sp.IDENTITY, sp.IDENTITY, sp.IDENTITY,
                             ZERO3, ZERO3, sp.IDENTITY, ZERO3, kind='unit', name=spec.name)
            unit.cycle = [(c, 1.0) for c in coords]
            self.units.append(unit)
        grow(edge, link, other)
        return other

    def elimination_order(self, columns):
        """Positions into ``columns`` (joint indices) in the order the closure's least squares
        factorises them: joints of fewer loops first, grouped by loop. A leg of a parallel
        robot enters only its own loop and comes first; the joints shared by every loop (the
        path to the platform) come last, so each leg adds a fixed amount of work."""
        key = tuple(columns)
        order = self._orders.get(key)
        if order is None:
            loops = self.loops_of_joint
            order = self._orders[key] = sorted(
                range(len(columns)),
                key=lambda k: (len(loops[columns[k]]), loops[columns[k]], k))
        return order


def _paths_below_common_ancestor(up, depth, a, b):
    """Tree joints from the nearest common ancestor of links a and b down to a, and down to
    b (each in order from the ancestor outwards, as the tree paths from the base list them)."""
    path_a, path_b = [], []
    while depth[a] > depth[b]:
        j, a = up[a]
        path_a.append(j)
    while depth[b] > depth[a]:
        j, b = up[b]
        path_b.append(j)
    while a != b:
        j, a = up[a]
        path_a.append(j)
        j, b = up[b]
        path_b.append(j)
    path_a.reverse()
    path_b.reverse()
    return path_a, path_b


def _attachment(spec, side):
    """(rotation, translation) of a joint's attachment frame on ``side`` ('parent' or
    'child') in that link's frame."""
    if side == 'parent':
        return sp.rpy_matrix(spec.parent_rpy), tuple(spec.parent_xyz)
    return sp.rpy_matrix(spec.child_rpy), tuple(spec.child_xyz)


def _tree_edge(j, spec, tree_parent, tree_child, name=''):
    r_pj, r_cj = sp.rpy_matrix(spec.parent_rpy), sp.rpy_matrix(spec.child_rpy)
    if spec.parent == tree_parent:   # written from the tree parent outwards
        sign, r_a, t_a, r_c, t_c = 1.0, r_pj, spec.parent_xyz, r_cj, spec.child_xyz
    else:                            # written towards the base: the tree sees -q
        sign, r_a, t_a, r_c, t_c = -1.0, r_cj, spec.child_xyz, r_pj, spec.parent_xyz
    r_b = sp.transpose(r_c)
    t_b = sp.scale(sp.mat_vec(r_b, t_c), -1.0)
    k = sp.skew(spec.axis)
    k2 = sp.mat_mat(k, k)
    r_ak = sp.mat_mat(r_a, k)
    r_ak2 = sp.mat_mat(r_a, k2)
    axis_p = sp.mat_vec(r_a, spec.axis)
    t0 = sp.add(t_a, sp.mat_vec(r_a, t_b))
    if spec.revolute:
        r1 = sp.mat_mat(r_ak, r_b)
        return TreeEdge(j, tree_parent, tree_child, sign, True,
                        sp.mat_mat(r_a, r_b), tuple(sign * x for x in r1), sp.mat_mat(r_ak2, r_b),
                        t0, sp.scale(sp.mat_vec(r_ak, t_b), sign), sp.mat_vec(r_ak2, t_b),
                        axis_p, tuple(t_a), name=name or spec.name)
    return TreeEdge(j, tree_parent, tree_child, sign, False,
                    sp.mat_mat(r_a, r_b), sp.IDENTITY, sp.IDENTITY,
                    t0, sp.scale(axis_p, sign), sp.ZERO3, axis_p, tuple(t_a),
                    name=name or spec.name)


def _loop_joint(j, spec):
    r_pj, r_cj = sp.rpy_matrix(spec.parent_rpy), sp.rpy_matrix(spec.child_rpy)
    k = sp.skew(spec.axis)
    return LoopJoint(j, spec.parent, spec.child, spec.revolute,
                     r_pj, sp.mat_mat(r_pj, k), sp.mat_mat(r_pj, sp.mat_mat(k, k)),
                     tuple(spec.parent_xyz), sp.mat_vec(r_pj, spec.axis),
                     r_cj, tuple(spec.child_xyz), kind=spec.kind, name=spec.name,
                     axis_c=sp.mat_vec(r_cj, spec.axis2) if spec.axis2 else ())


def loop_columns(loop):
    """The joint coordinates a loop's closure equations depend on: its cycle through the
    tree, and its own coordinate if it has one."""
    return [j for j, _ in loop.cycle] + ([] if loop.joint is None else [loop.joint])


class Frames:
    """Poses of every link and the unit twist of every joint, at one configuration.

    ``rot[k]``, ``pos[k]``: rotation and origin of link k in the base frame.
    ``xi[j]``: twist (base frame, Pluecker) of the joint's outer body relative to its inner
    body per unit joint rate: tree child w.r.t. tree parent for tree joints (sign folded in),
    declared child w.r.t. declared parent for loop-closing joints.
    """
    __slots__ = ('rot', 'pos', 'xi')


def frame_of(frames, link):
    """(rotation, origin) of a link; the base is the identity."""
    if link == BASE:
        return None, None
    return frames.rot[link], frames.pos[link]


def to_base(frames, link, r_local, t_local):
    """Pose of a frame fixed to ``link`` (given in the link frame) in the base frame."""
    rot, pos = frame_of(frames, link)
    if rot is None:
        return r_local, t_local
    return sp.mat_mat(rot, r_local), sp.add(pos, sp.mat_vec(rot, t_local))


def point_to_base(frames, link, point):
    rot, pos = frame_of(frames, link)
    if rot is None:
        return point
    return sp.add(pos, sp.mat_vec(rot, point))


def vector_to_base(frames, link, vector):
    rot, _ = frame_of(frames, link)
    return vector if rot is None else sp.mat_vec(rot, vector)


def joint_twist(revolute, axis, origin):
    """Unit twist of a joint: rotation about the line (origin, axis) or translation along axis."""
    if revolute:
        return (axis, sp.cross(origin, axis))
    return (sp.ZERO3, axis)


def forward_kinematics(model, q, ops):
    """Link poses and joint twists for joint coordinates q (list of lanes, joints order)."""
    frames = Frames()
    rot = [None] * model.n_links
    pos = [None] * model.n_links
    xi = [None] * model.n_coordinates
    frames.rot, frames.pos, frames.xi = rot, pos, xi
    for e in model.edges:
        if e.kind == 'fixed':
            rot[e.child], pos[e.child] = to_base(frames, e.parent, e.r0, e.t0)
            continue
        if e.kind == 'ball':
            _ball(frames, e, [q[c] for c in e.coords], ops)
            continue
        qj = q[e.joint]
        if e.revolute:
            s, c1 = ops.sin(qj), 1.0 - ops.cos(qj)
            r_local = sp.mat_combination(e.r0, e.r1, s, e.r2, c1)
            t_local = sp.vec_combination(e.t0, e.t1, s, e.t2, c1)
        else:
            r_local = e.r0
            t_local = sp.add_scaled(e.t0, e.t1, qj)
        rot[e.child], pos[e.child] = to_base(frames, e.parent, r_local, t_local)
        axis = sp.scale(vector_to_base(frames, e.parent, e.axis_p), e.sign)
        xi[e.joint] = joint_twist(e.revolute, axis, point_to_base(frames, e.parent, e.origin_p))
    for lp in model.loops:
        if lp.joint is not None:
            axis = vector_to_base(frames, lp.parent, lp.axis_p)
            xi[lp.joint] = joint_twist(lp.revolute, axis,
                                       point_to_base(frames, lp.parent, lp.t_pj))
    return frames


def _ball(frames, e, quaternion, ops):
    """Pose of a spherical tree edge's child, A R(q) B, and the twists of its quaternion
    coordinates: rotations about 2 G(q)[:, k] / |q|^2 (parent attachment frame) through
    the joint centre, where the angular velocity is 2 G(q) qdot / |q|^2."""
    rotation, rates = sp.quaternion_rotation(quaternion, ops)
    r_local = sp.mat_mat(sp.mat_mat(e.r0, rotation), e.r1)
    t_local = sp.add(e.t0, sp.mat_vec(e.r0, sp.mat_vec(rotation, e.t1)))
    frames.rot[e.child], frames.pos[e.child] = to_base(frames, e.parent, r_local, t_local)
    centre = point_to_base(frames, e.parent, e.origin_p)
    for c, rate in zip(e.coords, rates):
        axis = vector_to_base(frames, e.parent, sp.mat_vec(e.r0, rate))
        frames.xi[c] = joint_twist(True, axis, centre)


def link_twists(model, frames, qdot):
    """Twist of every link for joint rates qdot (eq. 2 before projection onto the links' COGs)."""
    twists = [None] * model.n_links
    for e in model.edges:
        twist = None if e.parent == BASE else twists[e.parent]
        for c in e.coords:
            xi, rate = frames.xi[c], qdot[c]
            if twist is None:
                twist = (sp.scale(xi[0], rate), sp.scale(xi[1], rate))
            else:
                twist = sp.twist_add_scaled(twist, xi, rate)
        twists[e.child] = sp.ZERO_TWIST if twist is None else twist
    return twists


def twist_of(twists, link):
    return sp.ZERO_TWIST if link == BASE else twists[link]


def link_bias_accelerations(model, frames, twists, qdot):
    """Spatial acceleration of every link when all joint accelerations are zero.

    A joint twist is fixed in the inner body, so it changes at the rate twist_parent x xi:
    a_child = a_parent + (v_parent x xi) qdot  (+ xi qddot, added separately).
    A spherical edge's quaternion twists also change with q, but their rates add up to
    2 G(qdot) qdot / |q|^2 = 0 (and a term in q . qdot, zero on the unit sphere).
    """
    acc = [None] * model.n_links
    for e in model.edges:
        if e.parent == BASE:
            acc[e.child] = sp.ZERO_TWIST     # the joint twist of a grounded joint is constant
            continue
        a = acc[e.parent]
        for c in e.coords:
            rate_of_xi = sp.motion_cross(twists[e.parent], frames.xi[c])
            a = sp.twist_add_scaled(a, rate_of_xi, qdot[c])
        acc[e.child] = a
    return acc
