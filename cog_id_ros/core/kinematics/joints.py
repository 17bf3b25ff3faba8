"""Joint kinds, one class each: everything that differs between a revolute, a prismatic, a
spherical, a universal and a fixed joint.

The algorithms never ask which kind a joint is; they call its kind object, the way every
step of Pinocchio's algorithms calls ``jmodel.calc`` (which supplies the joint's motion
subspace S and bias c) and Drake's mobilizers supply calc_X_FM, calc_V_FM and calc_A_FM.
A kind object belongs to one declared joint and holds its kind's parameters (an axis, a
second axis); its class says everything else:

* its coordinates: one of its own (:class:`CoordinateKind`: listed in mechanism.joints,
  limited, driven), or none, and then the *hidden* ones it adds where it enters the
  spanning tree (:attr:`JointKind.hidden`); their type in ``coordinate_types`` and their
  share of a continuation step (:meth:`JointKind.step_share`);
* its motion in the tree (kinematics.py): the child link's pose and the twists S of its
  coordinates (:meth:`JointKind.place`), the child's twist and bias acceleration
  (:meth:`JointKind.child_twist`, :meth:`JointKind.child_bias`);
* its rows of the closure equations where it closes a loop (closure.py):
  :meth:`JointKind.closure_state` (residual), :meth:`JointKind.closure_columns` (Jacobian),
  :meth:`JointKind.closure_bias`;
* the parameters it reads and checks (:meth:`JointKind.read`) and the keys it refuses;
* what users see: units, whether an actuator wraps at 2 pi, how inspect describes it and
  how the picture draws it.

docs/adding_a_joint_kind.md walks through writing one. :func:`register` adds a kind,
:func:`kind` finds one by the ``type`` a parameter file gives (a robot format's own names
too: URDF's 'continuous' is a revolute joint without limits, :attr:`Revolute.aliases`).
"""
import math
from typing import Callable, Iterable, Iterator, Sequence

from ..errors import MechanismConfigError
from ..linalg import spatial as sp
from ..value_types import Lane, LaneMatrix, Lanes, Ops, Rotation, Transform, Twist, Twists, Vec3
from . import kinematics as kin
from .kinematics import Frames, JointSpec, KinematicModel, LoopJoint, TreeEdge
from .loop_state import LoopState, UnitQuaternion
from .parameters import ParameterReader

#: how far from perpendicular (cosine) a universal joint's two axes may be written
AXES_PERPENDICULAR = 1e-6

#: the registered kinds by ``type``, in the order messages list them
KINDS: dict[str, type['JointKind']] = {}


def register(kind_class: type['JointKind']) -> type['JointKind']:
    """Make ``kind_class`` a ``type`` of the parameter file (usable as a decorator)."""
    KINDS[kind_class.name] = kind_class
    return kind_class


def kind(name: str, aliases: bool = False) -> type['JointKind'] | None:
    """The kind class of ``type`` ``name``, or None; with ``aliases``, also under the names
    a robot format gives it (a URDF reader's 'continuous')."""
    found = KINDS.get(name)
    if found is None and aliases:
        found = next((k for k in KINDS.values() if name in k.aliases), None)
    return found


def names() -> tuple[str, ...]:
    """The ``type`` names, in registration order."""
    return tuple(KINDS)


def parameter_names() -> tuple[str, ...]:
    """Every key some kind reads beyond those all joints have, in registration order."""
    return tuple(dict.fromkeys(key for k in KINDS.values() for key in k.parameters))


def unit_axis(r: ParameterReader, name: str, default: Sequence[float] | None) -> tuple[float, ...]:
    """A joint axis as a unit vector; MechanismConfigError for a missing (``default`` None)
    or zero-length one."""
    axis = r.vector(name, 3, default=default, required=default is None)
    assert axis is not None      # a default, or required: missing raised
    norm = math.hypot(*axis)     # no overflow near 1e308, no underflow near 1e-308
    if not norm > 0.0:
        raise MechanismConfigError(name, f'must not be zero-length, got {list(axis)}')
    return tuple(a / norm for a in axis)


def rotation_twist(axis: Vec3, origin: Vec3) -> Twist:
    """Unit twist (base frame, Pluecker) of a rotation about the line (origin, axis)."""
    return (axis, sp.cross(origin, axis))


class JointKind:
    """What every kind supplies. The defaults are those of a joint without a coordinate of
    its own that holds its two attachment frames together (all six closure rows)."""

    #: the ``type`` of the parameter file
    name: str = ''
    #: other names robot formats give this kind (see :func:`kind`)
    aliases: tuple[str, ...] = ()
    #: True: one coordinate of its own (in mechanism.joints, initial_positions; drivable)
    has_coordinate = False
    #: what Mechanism.coordinate_types shows for its coordinates (its own or hidden ones)
    coordinate_type: str | None = None
    #: the hidden coordinates it adds where it enters the spanning tree ('<joint>.<part>'),
    #: and their values where its attachment frames coincide (fewer enter the tree first)
    hidden: tuple[str, ...] = ()
    hidden_start: tuple[float, ...] = ()
    #: units of its coordinate and of its effort; whether an actuator's angle wraps at 2 pi
    unit: str | None = None
    effort_unit: str | None = None
    wraps = False
    #: its two attachment origins stay together whatever its coordinates (a joint centre)
    origins_coincide = True
    #: a ball joint: its child turns any way about the centre (a rod between two of them
    #: can spin about its own axis, idle_spins.py)
    turns_freely = False
    #: keys it reads beyond those of every joint; why it refuses the others' keys
    parameters: tuple[str, ...] = ()
    refused: dict[str, str] = {}
    #: inspect: its closure equations where it closes a loop; its hidden coordinates
    closure_equations = 6
    hidden_summary: str | None = None
    hidden_detail: str | None = None
    #: the picture: its marker and legend entry (None: the legend's joint entries show
    #: it), whether it draws its axis, and where a planar mechanism's joints of this kind
    #: have their axis ('normal' to the plane, 'in_plane', 'any'; None: never planar)
    legend: str | None
    planar_axis: str | None
    marker, legend, draws_axis, planar_axis = 'D', None, False, 'any'
    #: its axes (in its parent attachment frame; a second one in its child's)
    axis: tuple[float, ...] = (0.0, 0.0, 1.0)
    axis2: tuple[float, ...] = ()

    # a kind object is a value, its kind and its parameters (kernels.kernel_key reprs it)
    def __repr__(self) -> str:
        parameters = ', '.join(f'{key}={value!r}' for key, value in vars(self).items())
        return f'{type(self).__name__}({parameters})'

    def __eq__(self, other: object) -> bool:
        return type(self) is type(other) and vars(self) == vars(other)

    def __hash__(self) -> int:
        return hash((type(self), tuple(vars(self).items())))

    @classmethod
    def read(cls, r: ParameterReader, prefix: str) -> 'JointKind':
        """The kind object of joint ``prefix`` ('joints.<name>.') from its parameters (a
        parameters.ParameterReader), read and checked; the keys it does not read are
        refused afterwards (``refused`` says why for the keys of other kinds)."""
        return cls()

    def step_share(self, step: float, length: float) -> float:
        """The largest motion of each of its coordinates in one continuation step of
        ``step`` (rad; ``length`` the mechanism's length scale, m)."""
        return step

    # --- in the spanning tree (kinematics.py) -----------------------------------------------

    def enter_tree(self, model: KinematicModel, spec: JointSpec, link: int,
                   other: int) -> tuple[list[TreeEdge], list[LoopJoint]]:
        """([TreeEdge], [constraint LoopJoint]) that put ``spec`` into the tree from
        ``link`` (reached) to ``other``; ``model.hidden(spec)`` gives its hidden
        coordinates, ``model.virtual_link(name)`` a massless link."""
        a, b = _across(spec, link)
        r0, t0 = sp.compose(a, b)
        return [kin.TreeEdge(None, link, other, self, spec.name, r0=r0, t0=t0,
                             origin_p=a[1])], []

    def place(self, frames: Frames, e: TreeEdge, q: Lanes, ops: Ops) -> None:
        """calc_X_FM and S: the pose of tree edge ``e``'s child link (``rot`` and ``pos`` of
        ``frames``) and the unit twist ``xi[c]`` of ``frames`` of each of its coordinates c,
        from the coordinates ``q`` (lanes) and its parent's frame."""
        frames.rot[e.child], frames.pos[e.child] = kin.to_base(frames, e.parent, e.r0, e.t0)

    def child_twist(self, e: TreeEdge, frames: Frames, twist: Twist | None, qdot: Lanes) -> Twist:
        """calc_V_FM: the child's twist, v_parent + sum_c xi_c qdot_c (``twist`` None: the
        parent is the base, at rest)."""
        for c in e.coords:
            xi, rate = frames.xi[c], qdot[c]
            if twist is None:
                twist = (sp.scale(xi[0], rate), sp.scale(xi[1], rate))
            else:
                twist = sp.twist_add_scaled(twist, xi, rate)
        return sp.ZERO_TWIST if twist is None else twist

    def child_bias(self, e: TreeEdge, frames: Frames, parent_twist: Twist, parent_acc: Twist,
                   qdot: Lanes) -> Twist:
        """calc_A_FM at qddot = 0: the child's bias acceleration. A twist fixed in the
        parent body changes at the rate v_parent x xi, so a_child = a_parent + sum_c
        (v_parent x xi_c) qdot_c; a grounded joint's twists are constant."""
        if e.parent == kin.BASE:
            return sp.ZERO_TWIST
        a = parent_acc
        for c in e.coords:
            rate_of_xi = sp.motion_cross(parent_twist, frames.xi[c])
            a = sp.twist_add_scaled(a, rate_of_xi, qdot[c])
        return a

    def start(self, model: KinematicModel, e: TreeEdge, q: list[float]) -> None:
        """Set the hidden coordinates of tree edge ``e`` in ``q`` for the start of assembly
        (they start at ``hidden_start``)."""

    # --- closing a loop (closure.py) --------------------------------------------------------

    def loop_twist(self, frames: Frames, lp: LoopJoint) -> None:
        """The unit twist (``xi`` of ``frames``) of its own coordinate where it closes loop
        ``lp``."""

    def moved_attachment(self, lp: LoopJoint, q: Lanes, ops: Ops) -> Transform:
        """(rotation, origin) in the parent link of its parent attachment frame moved by
        the joint's motion, which the child attachment frame must coincide with."""
        return lp.d0, lp.t_pj

    def closure_state(self, lp: LoopJoint, frames: Frames, q: Lanes, ops: Ops) -> LoopState:
        """The loop_state.LoopState of loop ``lp``: closure point x (the child attachment
        origin), residual Phi (6 lanes) and the cosine of the frames' angle."""
        r_moved, t_moved = self.moved_attachment(lp, q, ops)
        r_p, target = kin.to_base(frames, lp.parent, r_moved, t_moved)
        r_c, x = kin.to_base(frames, lp.child, lp.r_cj, lp.t_cj)
        st = LoopState()
        st.x = x
        self.residual(st, lp, frames, target, r_p, r_c)
        return st

    def residual(self, st: LoopState, lp: LoopJoint, frames: Frames, target: Vec3, r_p: Rotation,
                 r_c: Rotation) -> None:
        """Phi = [x - o; 1/2 sum_k rP_k x rC_k]: the two frames coincide (``st.cosine`` rules
        out the half-turn that also zeroes the orientation rows)."""
        st.residual = sp.sub(st.x, target) + sp.orientation_error(r_p, r_c)
        st.cosine = sp.rotation_cosine(r_p, r_c)

    def closure_columns(self, lp: LoopJoint, st: LoopState, frames: Frames, columns: LaneMatrix,
                        row: int) -> None:
        """Its columns of A in rows ``row``..``row + 5`` of ``columns`` (per coordinate):
        [v(x); w] of every coordinate's twist on the loop, signed."""
        for col, w, sign in _position_columns(lp, st, frames, columns, row):
            col[row + 3:row + 6] = sp.scale(w, sign)

    def loop_bias(self, lp: LoopJoint, frames: Frames, twists: Twists, bias_acc: Twists,
                  qdot: Lanes) -> Twist:
        """The relative bias acceleration of the child over the parent link at qddot = 0."""
        return sp.twist_add_scaled(kin.twist_of(bias_acc, lp.child),
                                   kin.twist_of(bias_acc, lp.parent), -1.0)

    def closure_bias(self, lp: LoopJoint, st: LoopState, frames: Frames, twists: Twists,
                     bias_acc: Twists, qdot: Lanes) -> tuple[Lane, ...]:
        """Its 6 entries of beta (A qddot + beta = 0): the closure rows differentiated twice
        at qddot = 0; the full six rows need no more than the relative acceleration (their
        relative twist is zero, or along the joint's own twist)."""
        acc = self.loop_bias(lp, frames, twists, bias_acc, qdot)
        v, w = sp.twist_at(acc, st.x)
        return self.bias_rows(lp, st, twists, acc, v, w)

    def bias_rows(self, lp: LoopJoint, st: LoopState, twists: Twists, acc: Twist, v: Vec3,
                  w: Vec3) -> tuple[Lane, ...]:
        """Its 6 entries of beta from the relative acceleration ``acc`` and (v, w), that
        acceleration at the closure point x."""
        return (*v, *w)


def _across(spec: JointSpec, link: int) -> tuple[Transform, Transform]:
    """The attachment frame of ``spec`` on ``link`` and the inverse of the one on its
    other link, (rotation, translation) each: A and B of the pose A M B across it."""
    near, far = ('parent', 'child') if spec.parent == link else ('child', 'parent')
    return kin.attachment(spec, near), sp.inverse_transform(*kin.attachment(spec, far))


def _position_columns(lp: LoopJoint, st: LoopState, frames: Frames, columns: LaneMatrix,
                      row: int) -> Iterator[tuple[list[Lane], Vec3, float]]:
    """Per coordinate of loop ``lp`` (its cycle, then its own with sign -1): its column,
    the position rows v(x) written, and (column, w, sign) handed on for the others."""
    entries = list(lp.cycle) + ([] if lp.joint is None else [(lp.joint, -1.0)])
    for j, sign in entries:
        v, w = sp.twist_at(frames.xi[j], st.x)
        col = columns[j]
        col[row:row + 3] = sp.scale(v, sign)
        yield col, w, sign


def _point_bias(lp: LoopJoint, st: LoopState, twists: Twists,
                v: Vec3) -> tuple[Vec3, Vec3, Vec3, Vec3]:
    """The bias of a point constraint x_C = x_P: the relative acceleration at the moving
    point x has the term (w_C - w_P) x v_C(x). Returns (v, w_C, w_P, w_C - w_P)."""
    w_c, w_p = kin.twist_of(twists, lp.child)[0], kin.twist_of(twists, lp.parent)[0]
    w_rel = sp.sub(w_c, w_p)
    v = sp.add(v, sp.cross(w_rel, sp.twist_at(kin.twist_of(twists, lp.child), st.x)[0]))
    return v, w_c, w_p, w_rel


class CoordinateKind(JointKind):
    """A joint with one coordinate q of its own along or about ``axis``. In the tree the
    child's pose is L(q) = A M(sign q) B (A the tree parent's attachment frame, B the
    inverse of the tree child's; sign -1 where the joint is written towards the base),
    with A, B and the sign folded into the edge's constants by :meth:`tree_edge`."""

    has_coordinate = True
    parameters = ('axis', 'lower', 'upper', 'effort')
    refused = {'axis2': 'has one axis (axis2 is the second axis of a universal joint)'}
    draws_axis = True

    def __init__(self, axis: Iterable[float] = (0.0, 0.0, 1.0)) -> None:
        self.axis = tuple(axis)

    @classmethod
    def read(cls, r: ParameterReader, prefix: str) -> 'CoordinateKind':
        return cls(unit_axis(r, prefix + 'axis', (0.0, 0.0, 1.0)))

    def read_limits(self, r: ParameterReader, prefix: str) -> tuple[tuple[float, float], float]:
        """((lower, upper), effort) of its coordinate, inf where not given."""
        lower, upper, effort = (r.number(prefix + key) for key in ('lower', 'upper', 'effort'))
        lower = -math.inf if lower is None else lower
        upper = math.inf if upper is None else upper
        if not lower < upper:
            raise MechanismConfigError(prefix + 'upper',
                                       f'must be above lower ({lower!r}), got {upper!r}')
        effort = math.inf if effort is None else effort
        if not effort > 0.0:
            raise MechanismConfigError(prefix + 'effort',
                                       f'must be positive (N m or N), got {effort!r}')
        return (lower, upper), effort

    #: each coordinate kind's own: the child's pose relative to its parent at coordinate
    #: ``qj`` (e, qj, ops), and the unit twist of its coordinate (its axis, a point on it)
    local_pose: Callable[[TreeEdge, Lane, Ops], Transform]
    twist: Callable[[Vec3, Vec3], Twist]

    def oriented_edge(self, j: int, spec: JointSpec, tree_parent: int,
                      tree_child: int) -> tuple[TreeEdge, tuple[Rotation, Rotation, Vec3]]:
        """The tree edge of coordinate j with r0 = R_A R_B, t0 = t_A + R_A t_B, the axis and
        the joint origin in the tree parent's frame; and (R_A, R_B, t_B) for the rest."""
        r_pj, r_cj = sp.rpy_matrix(spec.parent_rpy), sp.rpy_matrix(spec.child_rpy)
        if spec.parent == tree_parent:   # written from the tree parent outwards
            sign, r_a, t_a, r_c, t_c = 1.0, r_pj, spec.parent_xyz, r_cj, spec.child_xyz
        else:                            # written towards the base: the tree sees -q
            sign, r_a, t_a, r_c, t_c = -1.0, r_cj, spec.child_xyz, r_pj, spec.parent_xyz
        r_b = sp.transpose(r_c)
        t_b = sp.scale(sp.mat_vec(r_b, t_c), -1.0)
        edge = kin.TreeEdge(j, tree_parent, tree_child, self, spec.name, sign=sign,
                            r0=sp.mat_mat(r_a, r_b), t0=sp.add(t_a, sp.mat_vec(r_a, t_b)),
                            axis_p=sp.mat_vec(r_a, self.axis), origin_p=tuple(t_a))
        return edge, (r_a, r_b, t_b)

    def place(self, frames: Frames, e: TreeEdge, q: Lanes, ops: Ops) -> None:
        r_local, t_local = self.local_pose(e, q[e.joint], ops)
        frames.rot[e.child], frames.pos[e.child] = kin.to_base(frames, e.parent, r_local,
                                                               t_local)
        axis = sp.scale(kin.vector_to_base(frames, e.parent, e.axis_p), e.sign)
        frames.xi[e.joint] = self.twist(axis, kin.point_to_base(frames, e.parent, e.origin_p))

    def loop_twist(self, frames: Frames, lp: LoopJoint) -> None:
        axis = kin.vector_to_base(frames, lp.parent, lp.axis_p)
        frames.xi[lp.joint] = self.twist(axis, kin.point_to_base(frames, lp.parent, lp.t_pj))

    def loop_bias(self, lp: LoopJoint, frames: Frames, twists: Twists, bias_acc: Twists,
                  qdot: Lanes) -> Twist:
        """...minus its own twist's rate: it turns with the parent link."""
        acc = super().loop_bias(lp, frames, twists, bias_acc, qdot)
        rate_of_xi = sp.motion_cross(kin.twist_of(twists, lp.parent), frames.xi[lp.joint])
        return sp.twist_add_scaled(acc, rate_of_xi, -qdot[lp.joint])


@register
class Revolute(CoordinateKind):
    """Rotation by q about ``axis``. With K = skew(axis), M(q) = I + sin(q) K + (1 - cos
    q) K^2, so L(q) is R_L = r0 + sin(q) r1 + (1 - cos q) r2, t_L = t0 + sin(q) t1 +
    (1 - cos q) t2 (sign folded into r1, t1); S is the rotation twist about the axis
    line. A revolute joint without limits is URDF's 'continuous' joint."""

    name = coordinate_type = 'revolute'
    aliases = ('continuous',)
    unit, effort_unit, wraps = 'rad', 'N m', True
    marker, planar_axis = 'o', 'normal'

    def tree_edge(self, j: int, spec: JointSpec, tree_parent: int, tree_child: int) -> TreeEdge:
        e, (r_a, r_b, t_b) = self.oriented_edge(j, spec, tree_parent, tree_child)
        k = sp.skew(self.axis)
        r_ak, r_ak2 = sp.mat_mat(r_a, k), sp.mat_mat(r_a, sp.mat_mat(k, k))
        e.r1 = tuple(e.sign * x for x in sp.mat_mat(r_ak, r_b))
        e.r2 = sp.mat_mat(r_ak2, r_b)
        e.t1 = sp.scale(sp.mat_vec(r_ak, t_b), e.sign)
        e.t2 = sp.mat_vec(r_ak2, t_b)
        return e

    def local_pose(self, e: TreeEdge, qj: Lane, ops: Ops) -> Transform:
        s, c1 = ops.sin(qj), 1.0 - ops.cos(qj)
        return (sp.mat_combination(e.r0, e.r1, s, e.r2, c1),
                sp.vec_combination(e.t0, e.t1, s, e.t2, c1))

    def twist(self, axis: Vec3, origin: Vec3) -> Twist:
        return rotation_twist(axis, origin)

    def moved_attachment(self, lp: LoopJoint, q: Lanes, ops: Ops) -> Transform:
        qc = q[lp.joint]
        return sp.mat_combination(lp.d0, lp.d1, ops.sin(qc), lp.d2, 1.0 - ops.cos(qc)), lp.t_pj


@register
class Prismatic(CoordinateKind):
    """Translation by q along ``axis``: R_L = r0, t_L = t0 + q t1 (t1 the signed axis);
    S is the translation twist (0, axis). Its step is a length: ``step * length``."""

    name = coordinate_type = 'prismatic'
    unit, effort_unit = 'm', 'N'
    origins_coincide = False
    marker, legend, planar_axis = 's', 'prismatic joint', 'in_plane'

    def step_share(self, step: float, length: float) -> float:
        return step * length

    def tree_edge(self, j: int, spec: JointSpec, tree_parent: int, tree_child: int) -> TreeEdge:
        e, _ = self.oriented_edge(j, spec, tree_parent, tree_child)
        e.t1 = sp.scale(e.axis_p, e.sign)
        return e

    def local_pose(self, e: TreeEdge, qj: Lane, ops: Ops) -> Transform:
        return e.r0, sp.add_scaled(e.t0, e.t1, qj)

    def twist(self, axis: Vec3, origin: Vec3) -> Twist:
        return (sp.ZERO3, axis)

    def moved_attachment(self, lp: LoopJoint, q: Lanes, ops: Ops) -> Transform:
        return lp.d0, sp.add_scaled(lp.t_pj, lp.axis_p, q[lp.joint])


class ClosureKind(JointKind):
    """A joint without a coordinate of its own: passive, closing a loop where it can, in
    the tree only where a link is out of reach otherwise (with hidden coordinates)."""

    refused = dict.fromkeys(('lower', 'upper', 'effort'),
                            'has no coordinate, so no position or effort limits')
    legend = 'spherical / universal / fixed'


@register
class Spherical(ClosureKind):
    """A ball joint: the attachment origins coincide, the rotation is free. Closing a loop:
    the three position rows x - o = 0. In the tree: A R(q) B with a quaternion q = (w, x,
    y, z) of hidden coordinates, R = R_h(q) / |q|^2, whose rates give the angular velocity
    2 G(q) qdot / |q|^2 (no angle triple, so no gimbal lock anywhere), and the constraint
    |q|^2 = 1 (loop_state.UnitQuaternion) that takes up the fourth coordinate."""

    name = 'spherical'
    coordinate_type = 'quaternion'
    turns_freely = True
    hidden, hidden_start = ('w', 'x', 'y', 'z'), (1.0, 0.0, 0.0, 0.0)
    refused = {**ClosureKind.refused, **dict.fromkeys(('axis', 'axis2'), 'has no axis')}
    closure_equations = 3
    hidden_summary = 'hidden coordinates: a quaternion'
    hidden_detail = 'a quaternion (4 numbers; |q| = 1 is a closure equation)'
    planar_axis = None

    def step_share(self, step: float, length: float) -> float:
        return step / 2.0          # a quaternion's components move by half the angle

    def enter_tree(self, model: KinematicModel, spec: JointSpec, link: int,
                   other: int) -> tuple[list[TreeEdge], list[LoopJoint]]:
        a, b = _across(spec, link)
        coords = model.hidden(spec)
        edge = kin.TreeEdge(None, link, other, self, spec.name, r0=a[0], r1=b[0], t0=a[1],
                            t1=b[1], origin_p=a[1], coords=coords)
        unit = kin.LoopJoint(None, link, other, UnitQuaternion(), spec.name)
        unit.cycle = [(c, 1.0) for c in coords]
        return [edge], [unit]

    def place(self, frames: Frames, e: TreeEdge, q: Lanes, ops: Ops) -> None:
        """A R(q) B (r0, t0: A; r1, t1: B), and the twists of the quaternion's components:
        rotations about 2 G(q)[:, k] / |q|^2 (parent attachment frame) through the centre."""
        rotation, rates = sp.quaternion_rotation([q[c] for c in e.coords], ops)
        r_local = sp.mat_mat(sp.mat_mat(e.r0, rotation), e.r1)
        t_local = sp.add(e.t0, sp.mat_vec(e.r0, sp.mat_vec(rotation, e.t1)))
        frames.rot[e.child], frames.pos[e.child] = kin.to_base(frames, e.parent, r_local,
                                                               t_local)
        centre = kin.point_to_base(frames, e.parent, e.origin_p)
        for c, rate in zip(e.coords, rates):
            axis = kin.vector_to_base(frames, e.parent, sp.mat_vec(e.r0, rate))
            frames.xi[c] = rotation_twist(axis, centre)

    # child_bias: the quaternion twists also change with q, but their rates add up to
    # 2 G(qdot) qdot / |q|^2 = 0 (and a term in q . qdot, zero on the unit sphere)

    def start(self, model: KinematicModel, e: TreeEdge, q: list[float]) -> None:
        """Turned so that the link it reaches puts its other joint centres where their
        partners are (a least-squares fit of the rotation about the ball's centre,
        model.fitted_rotation); with fewer than two such centres, its frame parallel to
        the base frame."""
        frames = kin.forward_kinematics(model, q, sp.ScalarOps)
        parent = frames.rot[e.parent] if e.parent != kin.BASE else sp.IDENTITY
        centre = kin.point_to_base(frames, e.parent, e.origin_p)
        own = sp.mat_t_vec(e.r1, sp.scale(e.t1, -1.0))      # the ball's centre on the child
        child = model.fitted_rotation(e.child, own, centre, frames, e.name) or sp.IDENTITY
        turn = sp.mat_mat(sp.mat_mat(sp.transpose(e.r0), sp.transpose(parent)),
                          sp.mat_mat(child, sp.transpose(e.r1)))
        for c, value in zip(e.coords, sp.rotation_quaternion(turn)):
            q[c] = value

    def residual(self, st: LoopState, lp: LoopJoint, frames: Frames, target: Vec3, r_p: Rotation,
                 r_c: Rotation) -> None:
        st.residual = sp.sub(st.x, target) + (0.0, 0.0, 0.0)
        st.cosine = 1.0

    def closure_columns(self, lp: LoopJoint, st: LoopState, frames: Frames, columns: LaneMatrix,
                        row: int) -> None:
        for _ in _position_columns(lp, st, frames, columns, row):
            pass                   # no orientation rows

    def bias_rows(self, lp: LoopJoint, st: LoopState, twists: Twists, acc: Twist, v: Vec3,
                  w: Vec3) -> tuple[Lane, ...]:
        v, *_ = _point_bias(lp, st, twists, v)
        return (*v, 0.0, 0.0, 0.0)


@register
class Universal(ClosureKind):
    """Two revolutes through a massless cross: about ``axis`` (parent attachment frame),
    then ``axis2`` (child attachment frame), kept perpendicular, so the pair never locks.
    Closing a loop: x - o = 0 and a . b = 0 (a, b the two axes in the base frame) in the
    first orientation row, velocity row (w_C - w_P) . (b x a). In the tree: two revolute
    edges through the virtual link '<joint>.cross', their two angles hidden coordinates."""

    name = 'universal'
    coordinate_type = Revolute.coordinate_type
    hidden, hidden_start = ('axis', 'axis2'), (0.0, 0.0)
    parameters = ('axis', 'axis2')
    closure_equations = 4
    hidden_summary = 'hidden coordinates: 2 angles'
    hidden_detail = '2 angles'
    draws_axis, planar_axis = True, None

    def __init__(self, axis: Iterable[float], axis2: Iterable[float]) -> None:
        self.axis, self.axis2 = tuple(axis), tuple(axis2)

    @classmethod
    def read(cls, r: ParameterReader, prefix: str) -> 'Universal':
        axis = unit_axis(r, prefix + 'axis', (0.0, 0.0, 1.0))
        axis2 = unit_axis(r, prefix + 'axis2', None)
        if abs(sum(a * b for a, b in zip(axis, axis2))) > AXES_PERPENDICULAR:
            raise MechanismConfigError(
                prefix + 'axis2',
                f'must be perpendicular to axis (a universal joint keeps its two axes '
                f'perpendicular; they are written in the parent and child attachment '
                f'frames, which coincide at rest), got axis {list(axis)} and axis2 '
                f'{list(axis2)}')
        return cls(axis, axis2)

    def enter_tree(self, model: KinematicModel, spec: JointSpec, link: int,
                   other: int) -> tuple[list[TreeEdge], list[LoopJoint]]:
        cross = model.virtual_link(f'{spec.name}.cross')
        first, second = model.hidden(spec)
        outer = kin.JointSpec(spec.name, Revolute(self.axis), spec.parent, cross,
                              spec.parent_xyz, spec.parent_rpy, kin.ZERO3, kin.ZERO3)
        inner = kin.JointSpec(spec.name, Revolute(self.axis2), cross, spec.child, kin.ZERO3,
                              kin.ZERO3, spec.child_xyz, spec.child_rpy)
        hops = ((first, outer, cross), (second, inner, other)) if spec.parent == link else \
            ((second, inner, cross), (first, outer, other))
        edges = []
        for coordinate, half, ahead in hops:
            edges.append(half.kind.tree_edge(coordinate, half, link, ahead))
            link = ahead
        return edges, []

    def residual(self, st: LoopState, lp: LoopJoint, frames: Frames, target: Vec3, r_p: Rotation,
                 r_c: Rotation) -> None:
        st.a = kin.vector_to_base(frames, lp.parent, lp.axis_p)
        st.b = kin.vector_to_base(frames, lp.child, lp.axis_c)
        st.residual = sp.sub(st.x, target) + (sp.dot(st.a, st.b), 0.0, 0.0)
        st.cosine = 1.0

    def closure_columns(self, lp: LoopJoint, st: LoopState, frames: Frames, columns: LaneMatrix,
                        row: int) -> None:
        normal = sp.cross(st.b, st.a)
        for col, w, sign in _position_columns(lp, st, frames, columns, row):
            col[row + 3] = sp.dot(w, normal) * sign

    def bias_rows(self, lp: LoopJoint, st: LoopState, twists: Twists, acc: Twist, v: Vec3,
                  w: Vec3) -> tuple[Lane, ...]:
        v, w_c, w_p, w_rel = _point_bias(lp, st, twists, v)
        normal = sp.cross(st.b, st.a)
        normal_rate = sp.add(sp.cross(sp.cross(w_c, st.b), st.a),
                             sp.cross(st.b, sp.cross(w_p, st.a)))
        return (*v, sp.dot(acc[0], normal) + sp.dot(w_rel, normal_rate), 0.0, 0.0)  # acc[0]: alpha


@register
class Fixed(ClosureKind):
    """A weld: the attachment frames coincide. Closing a loop: all six rows (a revolute
    joint held at q = 0); in the tree: a constant transform, no coordinate."""

    name = 'fixed'
    refused = Spherical.refused
    hidden_summary = 'no coordinate'
