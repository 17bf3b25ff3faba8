"""Spanning tree, forward kinematics and the velocity / acceleration recursions over it.

The link-joint graph is cut into a spanning tree rooted at the base link (breadth-first, in
the order joints are listed); every other joint closes a loop. A tree joint may be written in
either direction: the edge remembers a sign so that the joint coordinate keeps its meaning
(motion of the joint's child attachment frame relative to its parent attachment frame).

Every joint with a coordinate of its own (revolute, prismatic), tree or loop-closing, has a
coordinate of the model; the loop-closing ones are tied to the others by the closure
equations (closure.py). Joints without one (spherical, universal, fixed) close loops where
they can, and enter the tree only where a link cannot be reached otherwise (those with the
fewest hidden coordinates first), with *hidden* coordinates that no output shows. What each
kind of joint does here (its edges, the child's pose, the twists S of its coordinates, the
bias) its kind object says (joints.py); the recursions below only ask it.

Model coordinates are the mechanism's joints with a coordinate in order, then the hidden
ones; a velocity basis, a Newton increment or a step limit has one entry per coordinate.
"""
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from ..errors import MechanismConfigError
from ..linalg import spatial as sp
from ..value_types import Lane, Ops, Rotation, Transform, Twist, Vec3

BASE = -1
ZERO3 = (0.0, 0.0, 0.0)


@dataclass
class JointSpec:
    """A declared joint: its kind object (joints.py, holding the kind's parameters such as
    the axis) between links ``parent`` and ``child`` (BASE: the base link), and its
    attachment frames on them (xyz, roll-pitch-yaw)."""
    name: str
    kind: Any
    parent: int
    child: int
    parent_xyz: tuple
    parent_rpy: tuple
    child_xyz: tuple
    child_rpy: tuple


@dataclass
class TreeEdge:
    """A tree joint oriented from tree parent to tree child, with its constants folded.

    The child link's pose in the parent link frame is L(q) = A M(sign q) B, where A and B
    are the attachment frames (A = parent side of the tree edge, B the inverse of the child
    side) and M the joint motion; ``kind`` (joints.py) folds A, B and the sign into r0 ...
    t2 and evaluates them (``kind.place``). ``joint`` is the edge's coordinate for a joint
    with one of its own (None else); ``coords`` every coordinate of the edge (one, none, or
    its kind's hidden ones); ``axis_p`` and ``origin_p`` its axis and a point of it in the
    tree-parent link frame.
    """
    joint: Any           # int; None for a joint without a coordinate of its own
    parent: int
    child: int
    kind: Any
    name: str            # the declared joint it comes from
    sign: float = 1.0
    r0: tuple = sp.IDENTITY
    r1: tuple = sp.IDENTITY
    r2: tuple = sp.IDENTITY
    t0: tuple = ZERO3
    t1: tuple = ZERO3
    t2: tuple = ZERO3
    axis_p: tuple = ZERO3
    origin_p: tuple = ZERO3
    coords: tuple = ()

    def __post_init__(self) -> None:
        if not self.coords and self.joint is not None:
            self.coords = (self.joint,)


@dataclass
class LoopJoint:
    """A constraint of the closure equations: a loop-closing joint between its declared
    parent and child links (``joint`` its coordinate, None for a joint without one), or a
    constraint a joint in the tree adds (a spherical joint's unit quaternion). ``kind``
    (joints.py) writes its rows."""
    joint: Any           # int; None for a joint without a coordinate of its own
    parent: int
    child: int
    kind: Any
    name: str
    d0: tuple = sp.IDENTITY  # R_pj, R_pj K, R_pj K^2: the parent attachment rotation after
    d1: tuple = sp.IDENTITY  # a rotation q about the axis is d0 + sin(q) d1 + (1 - cos q) d2
    d2: tuple = sp.IDENTITY
    t_pj: tuple = ZERO3
    axis_p: tuple = ZERO3    # joint axis in the parent link frame
    r_cj: tuple = sp.IDENTITY
    t_cj: tuple = ZERO3
    axis_c: tuple = ()       # a second axis (universal) in the child link frame
    cycle: list = field(default_factory=list)   # (tree joint, +1/-1): twist_child - twist_parent


class KinematicModel:
    """The spanning tree and the loop-closing joints of a mechanism, ready to evaluate."""

    def __init__(self, link_names: Iterable[str], joints: Iterable[JointSpec],
                 closures: Iterable[JointSpec] = (),
                 couplings: Iterable['LoopJoint'] = ()) -> None:
        self.link_names = list(link_names)
        self.joints = list(joints)            # joints with a coordinate
        self.closures = list(closures)        # spherical, universal, fixed
        self.n_links = len(self.link_names)   # grows by a virtual link per tree universal joint
        self.n_joints = len(self.joints)      # the declared joints with a coordinate
        #: per model coordinate: the kind object it belongs to (its ``coordinate_type``
        #: and ``step_share``), its name (a hidden one: '<joint>.<part>') and its joint
        self.coordinate_kinds = [spec.kind for spec in self.joints]
        self.coordinate_names = [spec.name for spec in self.joints]
        self.coordinate_joints = [spec.name for spec in self.joints]
        #: the hidden coordinates' values where their attachment frames coincide
        self.hidden_start: list[float] = []
        #: tree edges, loop-closing joints, and the constraints joints in the tree add
        self.edges: list[TreeEdge] = []
        self.loops: list[LoopJoint] = []
        self.units: list[LoopJoint] = []
        self.edge_of_link: list[Any] = [None] * self.n_links   # int: a reached link's edge
        self._build_tree()
        self.n_coordinates = len(self.coordinate_kinds)
        #: coupled joints (couplings.py): one equation each, between two coordinates
        self.couplings = list(couplings)
        #: every constraint of the closure equations: the loops, a unit quaternion each,
        #: then the couplings
        self.constraints = self.loops + self.units + self.couplings
        #: per coordinate, the indices of the constraints whose equations it enters
        self.loops_of_joint: list[list[int]] = [[] for _ in range(self.n_coordinates)]
        for li, lp in enumerate(self.constraints):
            for j in loop_columns(lp):
                self.loops_of_joint[j].append(li)
        self._orders: dict[tuple[int, ...], list[int]] = {}

    @property
    def coordinate_types(self) -> list[str]:
        """Per coordinate: 'revolute', 'prismatic', 'quaternion' (its kind's word)."""
        return [kind.coordinate_type for kind in self.coordinate_kinds]

    def hidden(self, spec: JointSpec) -> tuple[int, ...]:
        """New hidden coordinates of ``spec``, one per part its kind names; their indices."""
        kind = spec.kind
        first = len(self.coordinate_kinds)
        for part, value in zip(kind.hidden, kind.hidden_start):
            self.coordinate_kinds.append(kind)
            self.coordinate_names.append(f'{spec.name}.{part}')
            self.coordinate_joints.append(spec.name)
            self.hidden_start.append(value)
        return tuple(range(first, first + len(kind.hidden)))

    def virtual_link(self, name: str) -> int:
        """A new massless link of the tree (not a link of the mechanism); its index."""
        self.link_names.append(name)
        self.edge_of_link.append(None)
        self.n_links += 1
        return self.n_links - 1

    def _build_tree(self) -> None:
        """Breadth-first from the base over the joints incident to each link, in the listed
        order; then each loop-closing joint's cycle from the tree paths of its two links.

        Linear in the number of joints plus the total length of the loop cycles: every link
        keeps only its tree edge (no copied paths), and a cycle is found by walking up from
        both links to their nearest common ancestor.
        """
        incident: dict[int, list[int]] = {}
        for j, spec in enumerate(self.joints):
            incident.setdefault(spec.parent, []).append(j)
            incident.setdefault(spec.child, []).append(j)
        in_tree = [False] * self.n_joints
        closure_in_tree = [False] * len(self.closures)
        up: dict[int, Any] = {BASE: None}       # link -> (tree edge, tree parent link)
        depth = {BASE: 0}
        queue = deque([BASE])

        def grow(edge: TreeEdge, link: int, other: int) -> None:
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
                    grow(spec.kind.tree_edge(j, spec, link, other), link, other)
                    in_tree[j] = True
                    queue.append(other)
            # links out of reach of the joints with a coordinate: through a joint without a
            # coordinate of its own (the one with fewest hidden coordinates, first listed)
            reaching = [(len(spec.kind.hidden), k) for k, spec in
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
        closing: list[tuple[int | None, JointSpec]] = [
            (j, spec) for j, spec in enumerate(self.joints) if not in_tree[j]]
        closing += [(None, spec) for k, spec in enumerate(self.closures)
                    if not closure_in_tree[k]]
        for joint, spec in closing:
            loop = _loop_joint(joint, spec)
            on_child, on_parent = _paths_below_common_ancestor(up, depth, spec.child,
                                                               spec.parent)
            loop.cycle = self._cycle(on_child, 1.0) + self._cycle(on_parent, -1.0)
            self.loops.append(loop)
        self.tree_joints = [e.joint for e in self.edges if e.joint is not None]
        self.loop_joints = [lp.joint for lp in self.loops if lp.joint is not None]

    def start(self, positions: Iterable[float]) -> list[float]:
        """Every coordinate at the start of assembly: ``positions`` (one per joint), the
        hidden ones at their kinds' ``hidden_start`` (their attachment frames coincide),
        then as each tree edge's kind sets them (``kind.start``: a spherical joint turned
        to fit its link's other joints)."""
        q = list(positions) + list(self.hidden_start)
        for e in self.edges:
            e.kind.start(self, e, q)
        return q

    def fitted_rotation(self, link: int, own: Vec3, centre: Vec3, frames: 'Frames',
                        skip: str | None) -> Rotation | None:
        """The rotation of tree link ``link`` about its point ``own`` (at ``centre`` in the
        base frame) that best carries the centres of its joints but ``skip`` (those whose
        two attachment origins coincide: ``kind.origins_coincide``) to their partners'
        centres on links outside its subtree (Kabsch); None with fewer than two
        independent directions."""
        outside = self._outside(link)
        pairs = []
        for spec in self.joints + self.closures:
            if not spec.kind.origins_coincide or spec.name == skip:
                continue
            for near, far, near_xyz, far_xyz in ((spec.child, spec.parent, spec.child_xyz,
                                                  spec.parent_xyz),
                                                 (spec.parent, spec.child, spec.parent_xyz,
                                                  spec.child_xyz)):
                if near == link and far in outside:
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

    def _outside(self, link: int) -> set[int]:
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

    def _cycle(self, path: Sequence[int], sign: float) -> list[tuple[int, float]]:
        """(coordinate, sign) of every coordinate of the tree edges on ``path``."""
        return [(c, sign) for e in path for c in self.edges[e].coords]

    def _tree_closure(self, spec: JointSpec, up: Mapping[int, Any],
                      grow: Callable[[TreeEdge, int, int], None]) -> int:
        """Put a joint without a coordinate of its own into the tree (from its end that is
        already reached to the other), as its kind says; returns the link it reaches."""
        link, other = (spec.parent, spec.child) if spec.parent in up else \
            (spec.child, spec.parent)
        edges, constraints = spec.kind.enter_tree(self, spec, link, other)
        for edge in edges:
            grow(edge, edge.parent, edge.child)
        self.units.extend(constraints)
        return other

    def elimination_order(self, columns: Sequence[int]) -> list[int]:
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


def _paths_below_common_ancestor(up: Mapping[int, Any], depth: Mapping[int, int], a: int,
                                 b: int) -> tuple[list[int], list[int]]:
    """Tree joints from the nearest common ancestor of links a and b down to a, and down to
    b (each in order from the ancestor outwards, as the tree paths from the base list them)."""
    path_a: list[int] = []
    path_b: list[int] = []
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


def attachment(spec: JointSpec, side: str) -> Transform:
    """(rotation, translation) of a joint's attachment frame on ``side`` ('parent' or
    'child') in that link's frame."""
    if side == 'parent':
        return sp.rpy_matrix(spec.parent_rpy), tuple(spec.parent_xyz)
    return sp.rpy_matrix(spec.child_rpy), tuple(spec.child_xyz)


def _loop_joint(j: int | None, spec: JointSpec) -> LoopJoint:
    r_pj, r_cj = sp.rpy_matrix(spec.parent_rpy), sp.rpy_matrix(spec.child_rpy)
    axis, axis2 = spec.kind.axis, spec.kind.axis2
    k = sp.skew(axis)
    return LoopJoint(j, spec.parent, spec.child, spec.kind, spec.name,
                     r_pj, sp.mat_mat(r_pj, k), sp.mat_mat(r_pj, sp.mat_mat(k, k)),
                     tuple(spec.parent_xyz), sp.mat_vec(r_pj, axis),
                     r_cj, tuple(spec.child_xyz),
                     axis_c=sp.mat_vec(r_cj, axis2) if axis2 else ())


def loop_columns(loop: LoopJoint) -> list[int]:
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
    # filled by forward_kinematics: None until each kind places its link or joint
    rot: list[Any]
    pos: list[Any]
    xi: list[Any]


def frame_of(frames: Frames, link: int) -> tuple[Any, Any]:
    """(rotation, origin) of a link; the base is the identity."""
    if link == BASE:
        return None, None
    return frames.rot[link], frames.pos[link]


def to_base(frames: Frames, link: int, r_local: Rotation, t_local: Vec3) -> Transform:
    """Pose of a frame fixed to ``link`` (given in the link frame) in the base frame."""
    rot, pos = frame_of(frames, link)
    if rot is None:
        return r_local, t_local
    return sp.mat_mat(rot, r_local), sp.add(pos, sp.mat_vec(rot, t_local))


def point_to_base(frames: Frames, link: int, point: Vec3) -> Vec3:
    rot, pos = frame_of(frames, link)
    if rot is None:
        return point
    return sp.add(pos, sp.mat_vec(rot, point))


def vector_to_base(frames: Frames, link: int, vector: Vec3) -> Vec3:
    rot, _ = frame_of(frames, link)
    return vector if rot is None else sp.mat_vec(rot, vector)


def forward_kinematics(model: KinematicModel, q: Sequence[Lane], ops: Ops) -> Frames:
    """Link poses and joint twists for joint coordinates q (list of lanes, joints order):
    each tree edge's kind places its child and gives its coordinates' twists, then each
    loop-closing joint's kind the twist of its own coordinate."""
    frames = Frames()
    frames.rot = [None] * model.n_links
    frames.pos = [None] * model.n_links
    frames.xi = [None] * model.n_coordinates
    for e in model.edges:
        e.kind.place(frames, e, q, ops)
    for lp in model.loops:
        lp.kind.loop_twist(frames, lp)
    return frames


def link_twists(model: KinematicModel, frames: Frames, qdot: Sequence[Lane]) -> list[Twist]:
    """Twist of every link for joint rates qdot (eq. 2 before projection onto the links' COGs)."""
    twists: list[Any] = [None] * model.n_links
    for e in model.edges:
        twists[e.child] = e.kind.child_twist(
            e, frames, None if e.parent == BASE else twists[e.parent], qdot)
    return twists


def twist_of(twists: Sequence[Twist], link: int) -> Twist:
    return sp.ZERO_TWIST if link == BASE else twists[link]


def link_bias_accelerations(model: KinematicModel, frames: Frames, twists: Sequence[Twist],
                            qdot: Sequence[Lane]) -> list[Twist]:
    """Spatial acceleration of every link when all joint accelerations are zero (each
    edge's kind adds its joint's bias to its parent's; ``xi qddot`` is added separately)."""
    acc: list[Any] = [None] * model.n_links
    for e in model.edges:
        acc[e.child] = e.kind.child_bias(e, frames, twist_of(twists, e.parent),
                                         twist_of(acc, e.parent), qdot)
    return acc
