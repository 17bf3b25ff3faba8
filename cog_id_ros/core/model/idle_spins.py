"""Locked joints and idle spins: free motions that no actuator drives and nothing needs to.

A rod between two ball joints can turn about the line through the balls' centres while every
other link stands still: an *idle spin*. Real rods spin freely and nothing drives them, but
the torques of a mechanism are defined only when its actuators determine every coordinate,
so each spin must be taken out: by locking one passive revolute or prismatic joint that the
spin moves (``mechanism.locked_joints``: held at its initial position, its coordinate still
in ``Mechanism.joints`` and in every output), by hand or with ``mechanism.idle_spins: lock``.

Published models write rods in many ways: one link between two balls, or two halves welded
together by a loop file's ``6d`` pair; each ball a native spherical joint, a ``SPHERICAL``
edit or three revolute joints through massless links; a body welded between two coaxial
revolute joints (a five-bar's end effector written once on each arm); a linear actuator and
its rod spinning as one about the line through their balls. So spins are found from the
motion, not from a pattern. At load, when the actuators (and the joints already locked)
leave free motion (degrees_of_freedom.count), :func:`resolve` takes an orthonormal basis of
the motions left with every actuator and locked joint held, at the assembled pose, and the
*rigid sets*: links joined by welds (fixed joints) or by held joints move as one body. A
spin is a motion in which exactly one rigid set with mass moves, turning about a fixed line
(a twist without pitch), while every other link with mass stands still (massless links, such
as those of a ball written as three revolutes, may move); a motion in which no link with mass
moves at all is idle too. The spins found must make up all of the free motion: anything else
(a forgotten actuator; a set that could move more than one way) is refused, whatever
``idle_spins`` says. With ``refuse`` (the default) the mechanism is refused naming each
spinning set, the joints that could be locked and the parameters; with ``lock`` one joint
per spin is locked: the passive joint with the largest share of the spin (its rate when the
set turns at 1 rad/s; ties: the first in ``Mechanism.joints``) that takes out a motion no
joint locked before takes out, named in ``assembly_warnings``, with a warning when the set's
centre of mass is off the spin axis (then gravity turns it: the spin is not idle, and which
joint is locked changes the torques).
"""
from dataclasses import dataclass, field

import numpy as np

from ..errors import MechanismConfigError
from ..kinematics import kinematics as kin
from ..kinematics.parameters import ParameterReader
from ..linalg import spatial as sp
from ..value_types import FloatArray, MechanismLike

#: the values of mechanism.idle_spins, the default first
IDLE_SPINS = ('refuse', 'lock')
#: a motion counts as the spin of a link when it is that to this relative residual
SPIN_TOLERANCE = 1e-6
#: a joint takes part in a spin when its rate in a unit spin is above this (rad/s or m/s)
SHARE_TOLERANCE = 1e-6
#: shares within this fraction of the largest are a tie (the first joint wins)
TIE = 1e-6
#: the centre of mass counts as off the spin axis beyond this fraction of the rod's length
OFF_AXIS = 1e-9
#: a set whose centre of mass is further from the axis than this fraction of the distance
#: between the joints it hangs on (and not on the axis) swings (a pendulum, a door): a
#: forgotten actuator
SWING = 0.1


def read_locks(mech: MechanismLike, r: ParameterReader) -> None:
    """``mech.locked_joints`` and ``mech.idle_spins`` from mechanism.locked_joints and
    mechanism.idle_spins (a parameters.ParameterReader), checked; ``mech.locked_index``
    their indices into ``mech.joints``."""
    names = r.string_list('mechanism.locked_joints') or []
    for name in names:
        if name in mech.closure_joints:
            kind = mech.closure_specs[mech.closure_joints.index(name)].kind.name
            raise MechanismConfigError(
                'mechanism.locked_joints',
                f"'{name}' is a {kind} joint: only revolute and prismatic joints can be "
                f'locked (held at their initial position)')
        if name not in mech.joints:
            raise MechanismConfigError(
                'mechanism.locked_joints',
                f"'{name}' is not a revolute or prismatic joint of the mechanism")
        if name in mech.active_joints:
            raise MechanismConfigError(
                'mechanism.locked_joints',
                f"'{name}' is in mechanism.active_joints: an actuator is driven, not locked")
    mode = r.string('mechanism.idle_spins', default=IDLE_SPINS[0])
    if mode not in IDLE_SPINS:
        raise MechanismConfigError(
            'mechanism.idle_spins', f"must be {' or '.join(map(repr, IDLE_SPINS))}, got "
                                    f'{mode!r}')
    mech.idle_spins = mode
    mech.locked_joints = list(names)
    mech.locked_index = sorted(mech.joints.index(name) for name in names)


class LockThem(Exception):
    """Raised during the degrees-of-freedom count with ``idle_spins: lock``: lock
    ``joints`` (indices into Mechanism.joints) and analyse again; ``notes`` are the
    assembly warnings that say so, ``spins`` the records of what spun (:func:`record`)."""

    def __init__(self, joints: list, notes: list, spins: list) -> None:
        super().__init__(', '.join(map(str, joints)))
        self.joints, self.notes, self.spins = joints, notes, spins


def record(mech: MechanismLike, spin: 'Spin', locked: 'int | None') -> dict:
    """What inspect shows of a spin (``Mechanism.idle_spin_sets``): the set's links
    (``links``; the massless ones that move with it in ``moving``), the joints it hangs on
    (``ends``), the joint locked (or None) and the others that could be."""
    return {'links': [mech.links[k] for k in spin.links],
            'moving': [mech.links[k] for k in spin.moving],
            'ends': list(spin.ends),
            'locked': None if locked is None else mech.joints[locked],
            'others': [mech.joints[j] for j, _ in spin.shares if j != locked]}


@dataclass
class Spin:
    """An idle spin: ``links`` (indices into Mechanism.links) the rigid set with mass that
    turns (empty: only massless links move), ``moving`` every link that moves in it;
    ``rates`` the coordinate rates of a unit spin (the set at 1 rad/s), ``shares`` (joint
    index, |rate|) of the joints that could be locked, largest first (ties in joint order);
    ``ends`` the joints through which the moving links hang on those standing still;
    ``balls`` the joints without a coordinate that it turns; ``offset`` the distance of the
    set's centre of mass from the axis (m), ``span`` the distance along the axis between the
    joints it hangs on (m)."""
    links: tuple
    moving: tuple
    rates: FloatArray
    offset: float
    ends: tuple = ()
    balls: tuple = ()
    span: float = 0.0
    shares: list = field(default_factory=list)


def with_locks(mech: MechanismLike, matrix: FloatArray) -> FloatArray:
    """The closure Jacobian A with a unit row per locked joint: the equations of the
    mechanism with its locked joints held (A itself when none is)."""
    if not mech.locked_index:
        return matrix
    n = mech.n_coordinates
    return np.vstack([matrix.reshape(-1, n), np.eye(n)[mech.locked_index]])


def held(mech: MechanismLike) -> set:
    """The coordinates held at load: the actuators and the locked joints."""
    return set(mech.active_index) | set(mech.locked_index)


def resolve(mech: MechanismLike, basis: FloatArray, rank: int, dof: int) -> None:
    """Called when the actuators and locked joints leave free motion (``basis``: those
    motions, :func:`free_motions`; the closure Jacobian of ``rank`` with the locks, ``dof``
    degrees of freedom): LockThem with ``idle_spins: lock`` when that motion is idle spins
    with a joint to lock each; else MechanismConfigError saying what moves."""
    spins = find_spins(mech, basis)
    others = other_motion(mech, basis, spins)
    if others is not None:
        raise MechanismConfigError(
            'mechanism.active_joints',
            f'{len(mech.active_joints)} active joint(s) for {dof} degrees of freedom (closure '
            f'rank {rank} of {mech.n_coordinates} coordinates, at the assembled initial '
            f'positions): the motion is not determined; {others}')
    unlockable = [spin for spin, j in zip(spins, picks(mech, spins, basis)) if j is None]
    if mech.idle_spins == 'lock' and not unlockable and not mech.spins_locked:
        raise LockThem(*_choose(mech, spins, basis))
    parameter = 'mechanism.locked_joints'
    if unlockable and unlockable[0].balls:
        parameter = f'joints.{unlockable[0].balls[0]}.type'
    raise MechanismConfigError(parameter, _refusal(mech, spins, basis))


def free_motions(mech: MechanismLike, matrix: FloatArray) -> FloatArray:
    """(n_coordinates, k): an orthonormal basis of the coordinate rates that keep the
    loops closed with every actuator and locked joint held."""
    n = mech.n_coordinates
    keep = held(mech)
    free = [j for j in range(n) if j not in keep]
    if not free:
        return np.zeros((n, 0))
    null = null_rows(matrix[:, free]) if matrix.size else np.eye(len(free))
    basis = np.zeros((n, len(null)))
    basis[free, :] = null.T
    return basis


def rigid_sets(mech: MechanismLike) -> list:
    """Per link index, a representative of its rigid set: links joined by fixed joints or
    by held joints (actuators, locked joints) move as one body."""
    root = list(range(len(mech.links)))

    def find(link: int) -> int:
        while root[link] != link:
            root[link] = root[root[link]]
            link = root[link]
        return link

    joined = [spec for spec in mech.closure_specs if spec.kind.closure_equations == 6]
    joined += [mech.joint_specs[j] for j in held(mech)]
    for spec in joined:
        if spec.parent >= 0 and spec.child >= 0:
            root[find(spec.parent)] = find(spec.child)
    return [find(link) for link in range(len(mech.links))]


def _has_mass(mech: MechanismLike, link: int) -> bool:
    return mech.link_mass[link] > 0.0 or any(x != 0.0 for x in mech.link_inertia[link])


def find_spins(mech: MechanismLike, basis: FloatArray) -> list:
    """The idle spins (Spin) within the free motions ``basis`` (free_motions), in the order
    of their sets' first links; massless-only motions last."""
    k = basis.shape[1]
    if not k:
        return []
    model = mech.model
    q = list(mech.assembled_coordinates)
    frames = kin.forward_kinematics(model, q, sp.ScalarOps)
    columns = [kin.link_twists(model, frames, basis[:, c].tolist()) for c in range(k)]
    scale = max(1.0, mech.attachment_scale)
    # per link: its twist per free motion, (6, k): [w; v at the base origin]
    twists = [np.array([[*tw[link][0], *tw[link][1]] for tw in columns]).T
              for link in range(len(mech.links))]
    weighted = [np.vstack([t[:3], t[3:] / scale]) for t in twists]
    heavy = [link for link in range(len(mech.links)) if _has_mass(mech, link)]
    massless = _null_columns(np.vstack([weighted[link] for link in heavy])) if heavy \
        else np.eye(k)
    sets: dict = {}
    for link, rep in zip(heavy, [rigid_sets(mech)[link] for link in heavy]):
        sets.setdefault(rep, []).append(link)
    spins = []
    for members in sorted(sets.values()):
        others = [link for link in heavy if link not in members]
        alone = _null_columns(np.vstack([weighted[link] for link in others])) if others \
            else np.eye(k)
        extra = _complement(alone, massless)
        if extra.shape[1] != 1:
            continue
        y = extra[:, 0]
        w, v = twists[members[0]][:3] @ y, twists[members[0]][3:] @ y
        size = float(np.linalg.norm(w))
        if not size > SPIN_TOLERANCE * float(np.linalg.norm(v)) / scale or \
                abs(float(w @ v)) > SPIN_TOLERANCE * size * (size * scale + float(
                    np.linalg.norm(v))):
            continue                      # a translation or a screw: not a spin
        spin = _spin(mech, frames, tuple(members), basis @ (y / size),
                     (w / size, np.cross(w, v) / size ** 2))
        if spin.offset <= max(SWING * spin.span, SPIN_TOLERANCE * scale):
            spins.append(spin)            # else a body that swings about one joint's line
    for c in range(massless.shape[1]):
        rates = basis @ massless[:, c]
        spins.append(_spin(mech, frames, (), rates / np.max(np.abs(rates)), None))
    return spins


def _spin(mech: MechanismLike, frames: kin.Frames, members: tuple, rates: FloatArray,
          axis: 'tuple | None') -> Spin:
    """The Spin of the unit motion ``rates`` of the set ``members`` about ``axis``
    (direction, a point; base frame): what moves, the joints it hangs on (``ends``, and
    ``span``: how far apart along the axis), the balls it turns, its centre of mass's
    offset from the axis."""
    motion = kin.link_twists(mech.model, frames, rates.tolist())
    moving = tuple(link for link in range(len(mech.links))
                   if max(map(abs, (*motion[link][0], *motion[link][1]))) > SHARE_TOLERANCE)
    ends, balls, along = [], [], []
    for spec in mech.joint_specs + mech.closure_specs:
        sides = [spec.parent in moving, spec.child in moving]
        if any(sides) and not all(sides):
            ends.append(spec.name)
            link, xyz = (spec.child, spec.child_xyz) if sides[1] else \
                (spec.parent, spec.parent_xyz)
            if axis is not None:
                along.append(float(np.dot(kin.point_to_base(frames, link, xyz), axis[0])))
        if any(sides) and not spec.kind.has_coordinate and _turns(motion, spec):
            balls.append(spec.name)
    offset = 0.0
    mass = sum(mech.link_mass[link] for link in members)
    if axis is not None and mass > 0.0:
        centre = sum(np.array(kin.point_to_base(frames, link, mech.link_com[link]))
                     * mech.link_mass[link] for link in members) / mass
        direction, point = axis
        arm = centre - point
        offset = float(np.linalg.norm(arm - (arm @ direction) * direction))
    spin = Spin(members, moving, rates, offset, tuple(ends), tuple(balls))
    spin.span = max(along) - min(along) if along else 0.0
    spin.shares = _shares(mech, rates)
    return spin


def _turns(motion: list, spec: kin.JointSpec) -> bool:
    """The joint's two links turn relative to each other in ``motion`` (link twists)."""
    parent, child = (motion[k][0] if k >= 0 else (0.0, 0.0, 0.0)
                     for k in (spec.parent, spec.child))
    return max(abs(a - b) for a, b in zip(child, parent)) > SHARE_TOLERANCE


def _null_columns(a: FloatArray) -> FloatArray:
    """Orthonormal columns spanning the null space of ``a``."""
    return null_rows(a).T


def _complement(space: FloatArray, sub: FloatArray) -> FloatArray:
    """Orthonormal columns spanning the part of ``space`` orthogonal to ``sub`` (both given
    as orthonormal columns, ``sub`` within ``space``)."""
    if not sub.shape[1]:
        return space
    rest = space - sub @ (sub.T @ space)
    if not rest.size:
        return rest
    u, values, _ = np.linalg.svd(rest, full_matrices=False)
    return u[:, values > 1e-6]


def _shares(mech: MechanismLike, rates: FloatArray) -> list:
    """(joint index, |rate|) of the passive joints a unit spin moves, largest first (ties:
    joint order)."""
    keep = held(mech)
    shares = [(j, abs(float(rates[j]))) for j in range(len(mech.joints))
              if j not in keep and abs(rates[j]) > SHARE_TOLERANCE]
    if not shares:
        return []
    top = max(share for _, share in shares)

    def order(item: tuple) -> tuple:
        tied = item[1] >= top * (1.0 - TIE)         # ties with the largest: joint order
        return (not tied, 0.0 if tied else -item[1], item[0])
    return sorted(shares, key=order)


def other_motion(mech: MechanismLike, basis: FloatArray, spins: list) -> 'str | None':
    """None when the spins make up all of the free motion ``basis``; else the message of
    the refusal: what else moves with every actuator held."""
    k = basis.shape[1]
    if spins:
        spun = np.column_stack([spin.rates for spin in spins])
        q_spun, _ = np.linalg.qr(spun)
        rest = basis - q_spun @ (q_spun.T @ basis)
    else:
        rest = basis
    values = np.linalg.svd(rest, compute_uv=False) if rest.size else np.zeros(0)
    if not np.any(values > 1e-6) and len(spins) >= k:
        return None
    u, values, _ = np.linalg.svd(rest, full_matrices=False)
    moving = u[:, values > 1e-6]
    names = mech.model.coordinate_joints
    joints = list(dict.fromkeys(names[j] for j in
                                np.flatnonzero(np.abs(moving).max(axis=1) > 1e-6)))
    text = ('with every actuator' + (' and locked joint' if mech.locked_index else '')
            + f" held, {', '.join(joints)} can still move; add active (revolute or "
              f'prismatic) joints for that motion (mechanism.active_joints)')
    if spins:
        text += ('; besides, ' + _spin_list(mech, spins) + ' spin idly about their own axes '
                 '(mechanism.locked_joints or mechanism.idle_spins: lock take those out, '
                 'never a forgotten actuator)')
    return text + ('; or, if the mechanism has fewer freedoms than that, it is at a singular '
                   'pose there (change initial_positions)')


def _spin_list(mech: MechanismLike, spins: list) -> str:
    return ', '.join(_what(mech, spin) for spin in spins)


def _what(mech: MechanismLike, spin: Spin) -> str:
    """The spinning set in words: "link 'rod'", "links 'a', 'b' (one rigid body)", or the
    massless links that move."""
    if len(spin.links) == 1:
        return f"link '{mech.links[spin.links[0]]}'"
    if spin.links:
        return ('links ' + ', '.join(f"'{mech.links[k]}'" for k in spin.links)
                + ' (one rigid body)')
    return 'the massless links ' + ', '.join(f"'{mech.links[k]}'" for k in spin.moving)


def picks(mech: MechanismLike, spins: list, basis: FloatArray) -> list:
    """Per spin, the joint (index) to lock, or None: the largest share of the spin (ties:
    joint order) that takes out a motion the joints picked before do not."""
    chosen: list = []
    out = []
    for spin in spins:
        pick = None
        for j, _ in spin.shares:
            rows = basis[chosen + [j]]
            if j not in chosen and np.linalg.matrix_rank(rows, tol=1e-9) == len(chosen) + 1:
                pick = j
                break
        if pick is not None:
            chosen.append(pick)
        out.append(pick)
    return out


def _choose(mech: MechanismLike, spins: list, basis: FloatArray) -> tuple[list, list, list]:
    """(joint indices, assembly notes, records): one joint per spin (:func:`picks`)."""
    chosen, notes, records = [], [], []
    for spin, j in zip(spins, picks(mech, spins, basis)):
        if j is None:
            continue
        chosen.append(j)
        records.append(record(mech, spin, j))
        share = dict(spin.shares)[j]
        one = len(spin.links) <= 1
        text = (f'{_what(mech, spin)} {"spins" if one else "spin"} freely about '
                f'{"its" if one else "their"} own axis ({_ends(spin)}); '
                f"mechanism.idle_spins: lock locked joint '{mech.joints[j]}' at "
                f'{mech.assembled_positions[j]:.9g} (its share of the spin {share:.3g}, the '
                f'largest'
                + (f'; others that could be locked: {_names(mech, spin.shares, skip=j)}'
                   if len(spin.shares) > 1 else '') + ')')
        if spin.offset > OFF_AXIS * max(1.0, mech.attachment_scale):
            text += (f"; the set's centre of mass is {spin.offset:.3g} m off that axis, so "
                     f'the spin is not idle (gravity and motion turn the link about it) and '
                     f'which joint is locked changes the torques: lock the joint that is '
                     f'locked in the real mechanism (mechanism.locked_joints)')
        notes.append(text)
    return chosen, notes, records


def _ends(spin: Spin) -> str:
    return 'the line through the joints ' + ', '.join(spin.ends) if spin.ends else 'no joint'


def _names(mech: MechanismLike, shares: list, skip: 'int | None' = None) -> str:
    return ', '.join(f"'{mech.joints[j]}' ({share:.3g})" for j, share in shares if j != skip)


def _refusal(mech: MechanismLike, spins: list, basis: FloatArray) -> str:
    """The refusal of idle spins: each set, the joints that could be locked, what to write."""
    parts, chosen = [], []
    for spin, j in zip(spins, picks(mech, spins, basis)):
        if j is not None:
            chosen.append(mech.joints[j])
            parts.append(f'{_what(mech, spin)} (about {_ends(spin)}) could be held by '
                         f'locking one of {_names(mech, spin.shares)} (share of the spin in '
                         f'parentheses, largest first)')
        else:
            parts.append(f'{_what(mech, spin)} spins between the spherical joints '
                         f"{' and '.join(map(repr, spin.balls))}, which have no coordinate to "
                         f'lock: write one of them as `type: universal` (with `axis` and '
                         f'`axis2` perpendicular to the line through the two centres)')
    count = sum(max(1, len(spin.links)) for spin in spins)
    text = (f'{count} link(s) spin freely about their own axes ({len(spins)} spin(s): a rod '
            f'between two ball joints, or a body between coaxial joints), a motion no actuator '
            f'drives and the torques do not need: ' + '; '.join(parts) + '.')
    if chosen:
        text += (f" Lock one joint per spin, in the parameters under `mechanism:`: "
                 f"`locked_joints: [{', '.join(chosen)}]`, or set `idle_spins: lock` there to "
                 f'have the joint with the largest share locked for each (docs/mechanism.md, '
                 f'"Locked joints and idle spins")')
    return text


def dependent_actuators(mech: MechanismLike, matrix: FloatArray) -> list:
    """Names of the actuators whose motions determine each other's with the loops closed
    (and the locked joints held): those that some combination of actuator rates that no
    motion of the mechanism gives involves. Empty unless the mechanism is redundant."""
    if len(mech.active_index) <= mech.dof:
        return []
    stacked = with_locks(mech, matrix)
    n = mech.n_coordinates
    motions = null_rows(stacked) if stacked.size else np.eye(n)
    unreachable = null_rows(motions[:, mech.active_index])   # no motion gives these
    involved = np.flatnonzero(np.abs(unreachable).max(axis=0) > 1e-6)
    return [mech.active_joints[a] for a in involved]


def null_rows(a: FloatArray) -> FloatArray:
    """Orthonormal rows spanning the null space of ``a`` (relative tolerance 1e-9)."""
    _, values, vt = np.linalg.svd(a)
    scale = max(1.0, values[0]) if values.size else 1.0
    return vt[int(np.sum(values > 1e-9 * scale)):]
