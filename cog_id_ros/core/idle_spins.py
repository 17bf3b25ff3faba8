"""Locked joints and idle spins: free motions that no actuator drives and nothing needs to.

A rod between two ball joints (a link whose only two joints are spherical: native
``spherical`` joints, or three revolute joints through massless links, spherical_chains.py)
can turn about the line through the two balls' centres while every other link stands still:
an *idle spin*. Real rods spin freely and nothing drives them, but the torques of a
mechanism are defined only when its actuators determine every coordinate, so each spin must
be taken out: by locking one passive revolute or prismatic joint that the spin moves
(``mechanism.locked_joints``: held at its initial position, its coordinate still in
``Mechanism.joints`` and in every output), by hand or with ``mechanism.idle_spins: lock``.

At load, when the actuators (and the joints already locked) leave free motion
(degrees_of_freedom.count), :func:`resolve` looks at the motions left with every actuator
and locked joint held, at the assembled pose: per candidate link, the motion in which it
turns about its balls' line at unit rate and every other link (but the massless links of its
own balls) stands still. The spins found must make up all of the free motion: anything else
(a forgotten actuator) is refused, whatever ``idle_spins`` says. With ``refuse`` (the
default) the mechanism is refused naming each spinning link, the joints that could be
locked and the parameters; with ``lock`` one joint per spin is locked: the passive joint
with the largest share of the spin (its rate when the link spins at 1 rad/s; ties: the
first in ``Mechanism.joints``), named in ``assembly_warnings``, with a warning when the
link's centre of mass is off the spin axis (then gravity turns it: the spin is not idle,
and which joint is locked changes the torques).
"""
from dataclasses import dataclass, field

import numpy as np

from . import kinematics as kin
from . import spatial as sp
from . import spherical_chains
from .errors import MechanismConfigError
from .parameters import ParameterReader
from .value_types import FloatArray, MechanismLike

#: the values of mechanism.idle_spins, the default first
IDLE_SPINS = ('refuse', 'lock')
#: a motion counts as the spin of a link when it is that to this relative residual
SPIN_TOLERANCE = 1e-6
#: a joint takes part in a spin when its rate in a unit spin is above this (rad/s or m/s)
SHARE_TOLERANCE = 1e-6
#: shares within this fraction of the largest are a tie (the first joint wins)
TIE = 1e-9
#: the centre of mass counts as off the spin axis beyond this fraction of the rod's length
OFF_AXIS = 1e-9


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
    assembly warnings that say so."""

    def __init__(self, joints: list, notes: list) -> None:
        super().__init__(', '.join(map(str, joints)))
        self.joints, self.notes = joints, notes


@dataclass
class Spin:
    """The idle spin of link ``link`` (index into Mechanism.links) between the ball joints
    ``balls`` (each a tuple of joint names): ``rates`` the coordinate rates of a unit spin,
    ``shares`` (joint index, |rate|) of the joints that could be locked, largest first
    (ties in joint order), ``offset`` the distance of its centre of mass from the axis (m)."""
    link: int
    balls: tuple
    rates: FloatArray
    offset: float
    length: float
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


def resolve(mech: MechanismLike, matrix: FloatArray, rank: int, dof: int) -> None:
    """Called when the actuators and locked joints leave free motion (A the closure
    Jacobian at the assembled pose, of that rank with the locks, ``dof`` degrees of
    freedom): LockThem with ``idle_spins: lock`` when that motion is idle spins with a
    joint to lock each; else MechanismConfigError saying what moves."""
    basis = free_motions(mech, matrix)
    spins = find_spins(mech, basis)
    others = other_motion(mech, basis, spins)
    if others is not None:
        raise MechanismConfigError(
            'mechanism.active_joints',
            f'{len(mech.active_joints)} active joint(s) for {dof} degrees of freedom (closure '
            f'rank {rank} of {mech.n_coordinates} coordinates, at the assembled initial '
            f'positions): the motion is not determined; {others}')
    unlockable = [spin for spin in spins if not spin.shares]
    if mech.idle_spins == 'lock' and not unlockable and not mech.spins_locked:
        raise LockThem(*_choose(mech, spins))
    parameter = 'mechanism.locked_joints'
    if unlockable:
        parameter = f'joints.{unlockable[0].balls[0][0]}.type'
    raise MechanismConfigError(parameter, _refusal(mech, spins))


def free_motions(mech: MechanismLike, matrix: FloatArray) -> FloatArray:
    """(n_coordinates, k): an orthonormal basis of the coordinate rates that keep the
    loops closed with every actuator and locked joint held."""
    n = mech.n_coordinates
    keep = held(mech)
    free = [j for j in range(n) if j not in keep]
    if not free:
        return np.zeros((n, 0))
    null = _null_rows(matrix[:, free]) if matrix.size else np.eye(len(free))
    basis = np.zeros((n, len(null)))
    basis[free, :] = null.T
    return basis


def _balls(mech: MechanismLike) -> tuple[dict, list]:
    """Per link index: [(joint names, centre in the link frame, helper link indices)] of
    its ball joints (native spherical ones and chains of three revolutes); and per link
    index how many joints it has."""
    degree = [0] * len(mech.links)
    balls: dict = {}
    for spec in mech.joint_specs + mech.closure_specs:
        for link, centre in ((spec.parent, spec.parent_xyz), (spec.child, spec.child_xyz)):
            if link < 0:
                continue
            degree[link] += 1
            if spec.kind.turns_freely:
                balls.setdefault(link, []).append(((spec.name,), tuple(centre), ()))
    for chain in spherical_chains.chains_of(mech):
        helpers = tuple(mech.link_index[h] for h in chain.helpers)
        for end, centre in ((chain.parent, chain.centre_p), (chain.child, chain.centre_c)):
            if end in mech.link_index:
                balls.setdefault(mech.link_index[end], []).append(
                    (chain.joints, tuple(centre), helpers))
    return balls, degree


def find_spins(mech: MechanismLike, basis: FloatArray) -> list:
    """The idle spins (Spin) within the free motions ``basis`` (free_motions)."""
    if not basis.shape[1]:
        return []
    model = mech.model
    q = list(mech.assembled_coordinates)
    frames = kin.forward_kinematics(model, q, sp.ScalarOps)
    columns = [kin.link_twists(model, frames, basis[:, k].tolist())
               for k in range(basis.shape[1])]
    scale = max(1.0, mech.attachment_scale)
    # per link: its twist per free motion, (6, k), linear rows over the length scale
    twists = [np.array([[*tw[link][0], *(v / scale for v in tw[link][1])] for tw in columns]).T
              for link in range(model.n_links)]
    balls, degree = _balls(mech)
    spins = []
    for link, ends in sorted(balls.items()):
        if len(ends) != 2 or degree[link] != 2:
            continue
        (names1, c1, helpers1), (names2, c2, helpers2) = ends
        axis = np.subtract(c2, c1)
        length = float(np.linalg.norm(axis))
        if not length > 0.0:
            continue
        u_local = tuple(axis / length)
        u = kin.vector_to_base(frames, link, u_local)
        centre = kin.point_to_base(frames, link, c1)
        target = np.array([*u, *(v / scale for v in sp.cross(centre, u))])
        still = [k for k in range(model.n_links) if k not in (link, *helpers1, *helpers2)]
        system = np.vstack([twists[link]] + [twists[k] for k in still])
        rhs = np.concatenate([target, np.zeros(6 * len(still))])
        y = np.linalg.lstsq(system, rhs, rcond=None)[0]
        if np.linalg.norm(system @ y - rhs) > SPIN_TOLERANCE:
            continue
        com = np.subtract(mech.link_com[link], c1)
        offset = float(np.linalg.norm(com - (com @ u_local) * np.array(u_local)))
        spin = Spin(link, (names1, names2), basis @ y, offset, length)
        spin.shares = _shares(mech, spin.rates)
        spins.append(spin)
    return spins


def _shares(mech: MechanismLike, rates: FloatArray) -> list:
    """(joint index, |rate|) of the passive joints a unit spin moves, largest first (ties:
    joint order)."""
    keep = held(mech)
    shares = [(j, abs(float(rates[j]))) for j in range(len(mech.joints))
              if j not in keep and abs(rates[j]) > SHARE_TOLERANCE]
    if not shares:
        return []
    top = max(share for _, share in shares)
    return sorted(shares, key=lambda item: (item[1] < top * (1.0 - TIE), -item[1], item[0]))


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
    return ', '.join(f"'{mech.links[spin.link]}'" for spin in spins)


def _choose(mech: MechanismLike, spins: list) -> tuple[list, list]:
    """(joint indices, assembly notes): one joint per spin, the largest share first."""
    chosen, notes = [], []
    for spin in spins:
        j = next((j for j, _ in spin.shares if j not in chosen), None)
        if j is None:
            continue
        chosen.append(j)
        share = dict(spin.shares)[j]
        text = (f"link '{mech.links[spin.link]}' spins freely about the line through the "
                f'centres of its ball joints ({_ball_names(spin)}); mechanism.idle_spins: '
                f"lock locked joint '{mech.joints[j]}' at {mech.assembled_positions[j]:.9g} "
                f'(its share of the spin {share:.3g}, the largest'
                + (f'; others that could be locked: {_names(mech, spin.shares, skip=j)}'
                   if len(spin.shares) > 1 else '') + ')')
        if mech.link_mass[spin.link] > 0.0 and spin.offset > OFF_AXIS * spin.length:
            text += (f"; the link's centre of mass is {spin.offset:.3g} m off that axis, so "
                     f'the spin is not idle (gravity and motion turn the link about it) and '
                     f'which joint is locked changes the torques: lock the joint that is '
                     f'locked in the real mechanism (mechanism.locked_joints)')
        notes.append(text)
    return chosen, notes


def _ball_names(spin: Spin) -> str:
    return ' and '.join(', '.join(names) for names in spin.balls)


def _names(mech: MechanismLike, shares: list, skip: 'int | None' = None) -> str:
    return ', '.join(f"'{mech.joints[j]}' ({share:.3g})" for j, share in shares if j != skip)


def _refusal(mech: MechanismLike, spins: list) -> str:
    """The refusal of idle spins: each link, the joints that could be locked, what to write."""
    parts, picks = [], []
    for spin in spins:
        link = mech.links[spin.link]
        if spin.shares:
            picks.append(mech.joints[spin.shares[0][0]])
            parts.append(f"link '{link}' (between the ball joints {_ball_names(spin)}) "
                         f'could be held by locking one of {_names(mech, spin.shares)} (share '
                         f'of the spin in parentheses, largest first)')
        else:
            balls = [names[0] for names in spin.balls if len(names) == 1]
            parts.append(f"link '{link}' spins between the spherical joints "
                         f"{' and '.join(map(repr, balls))}, which have no coordinate to "
                         f'lock: write one of them as `type: universal` (with `axis` and '
                         f'`axis2` perpendicular to the line through the two centres)')
    text = (f'{len(spins)} link(s) spin freely about the line through the centres of their '
            f'two ball joints, a motion no actuator drives and the torques do not need: '
            + '; '.join(parts) + '.')
    if picks:
        text += (f" Lock one joint per spinning link, in the parameters under `mechanism:`: "
                 f"`locked_joints: [{', '.join(picks)}]`, or set `idle_spins: lock` there to "
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
    motions = _null_rows(stacked) if stacked.size else np.eye(n)
    unreachable = _null_rows(motions[:, mech.active_index])   # no motion gives these
    involved = np.flatnonzero(np.abs(unreachable).max(axis=0) > 1e-6)
    return [mech.active_joints[a] for a in involved]


def _null_rows(a: FloatArray) -> FloatArray:
    """Orthonormal rows spanning the null space of ``a`` (relative tolerance 1e-9)."""
    _, values, vt = np.linalg.svd(a)
    scale = max(1.0, values[0]) if values.size else 1.0
    return vt[int(np.sum(values > 1e-9 * scale)):]
