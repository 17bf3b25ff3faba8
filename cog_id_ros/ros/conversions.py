"""ROS messages <-> arrays for the node: setpoints in, efforts out (no physics, no node).

Everything here checks what a message carries before a number reaches the solver, and
says what is wrong with a :class:`Rejected` that carries a short ``reason`` (the key the
node counts in diagnostics) and a sentence for the log.
"""
import math
import re
import struct
import time
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..offline import derivatives
from . import cdr
from .setpoint_filter import NANOSECONDS

if TYPE_CHECKING:
    from ..core import InverseDynamics

#: every reason a setpoint or trajectory can be rejected for, as counted in diagnostics
REASONS = {
    'empty': 'the message carries no joints or no points',
    'malformed': 'arrays of unequal length, or duplicate joint names',
    'missing_joint': 'an active joint is not in the message',
    'non_finite': 'a position, velocity or acceleration of an active joint is NaN or infinite',
    'out_of_range': 'a finite value too large to compute with (the torques would overflow)',
    'stamp': 'the header stamp does not come after the previous accepted setpoint, or is '
             "more than max_stamp_lead ahead of the node's clock",
    'stale': 'taken more than max_setpoint_age after it was published (the node was '
             'stopped, or fell behind): too late to serve',
    'jump': 'an active joint moved farther than max_setpoint_step since the previous '
            'setpoint (after unwrapping revolute joints)',
    'velocity': 'a measured velocity of an active joint beyond max_measured_velocity '
                '(feedback modes)',
    'limit': "an active joint's position outside its limits (joints.<name>.lower / upper, "
             'or the URDF <limit>)',
    'closure': 'the loops cannot be closed at this pose',
    'unreachable': 'the pose cannot be reached from the previous one by continuation',
    'singular': 'the pose is singular (closure Jacobian condition number too large)',
    'inconsistent': 'the redundant active coordinates disagree with the loop closure',
    'solver': 'any other setpoint the solver refuses',
}

#: the reasons of REASONS a measured state can be rejected for (feedback modes): not
#: ``stamp`` (a measurement's header may carry the plant's time; its age is DDS's) nor
#: ``limit`` (a measured pose beyond a limit is commanded from)
MEASUREMENT_REASONS = tuple(r for r in REASONS if r not in ('stamp', 'limit'))

#: reasons only a measured state can be rejected for (feedback modes)
MEASUREMENT_ONLY_REASONS = {
    'publishers': 'more publishers feed measured_joint_states than max_measured_publishers '
                  '(a second source must never take over the controller)',
    'restart': 'the first measured state after measurement_timeout, not yet confirmed by a '
               'next one within max_measurement_step (the new stream starts from the second)',
}
MEASUREMENT_REASONS += tuple(MEASUREMENT_ONLY_REASONS)

#: reasons a whole trajectory can be refused for besides those of REASONS (its points)
TRAJECTORY_REASONS = {
    'too_long': 'more points than max_trajectory_points',
    'busy': 'a newer trajectory arrived while this one waited for the solver (queue of one)',
}

#: reasons only a floating base's setpoints and trajectories are rejected for
#: (cog_id_ros.ros.floating_mode)
FLOATING_REASONS = {
    'base_state': 'no base_state received yet, or none for base_state_timeout (a setpoint); '
                  'a trajectory carries no base motion (joint_trajectory)',
}

#: every core error reason (cog_id_ros.core.errors.REASONS) is a key of REASONS
_CORE_REASONS = ('malformed', 'non_finite', 'out_of_range', 'limit', 'closure', 'unreachable',
                 'singular', 'inconsistent')


class Rejected(ValueError):
    """A setpoint or trajectory that gets no command: ``reason`` is a key of REASONS."""

    #: the trajectory's number of points, where a trajectory is refused
    points: int

    def __init__(self, reason: str, message: str) -> None:
        assert reason in REASONS or reason in TRAJECTORY_REASONS or \
            reason in MEASUREMENT_ONLY_REASONS or reason in FLOATING_REASONS, reason
        self.reason = reason
        super().__init__(message)


def rejection(exc: BaseException | None, redundant: object = None) -> Rejected:
    """The Rejected for a core exception, by its machine-readable ``reason``.

    Every reason of the core's errors (cog_id_ros.core.errors.REASONS) is a reason here
    too; an exception without one (or with one this module does not know) is 'solver'.
    ``redundant`` is no longer needed (kept for callers that still pass it).
    """
    reason = getattr(exc, 'reason', None)
    if reason not in REASONS or reason in ('empty', 'missing_joint', 'stamp', 'stale', 'jump',
                                           'velocity'):
        reason = 'solver'
    return Rejected(reason, str(exc))


def stamp_to_ns(stamp: Any) -> int:
    """A builtin_interfaces/Time as integer nanoseconds."""
    return stamp.sec * NANOSECONDS + stamp.nanosec


def check_age(stamp: int | None, max_age_ns: int, what: str, parameter: str,
                now: int | None = None) -> None:
    """Rejected ('stale') when ``stamp`` (DDS's source or received timestamp: ns of the
    publisher's or this machine's system clock, which time.time_ns reads; None or 0: not
    known, no check) lies more than ``max_age_ns`` before ``now`` (time.time_ns()): after
    the node was stopped and continued, or while it is behind, what it would send for an
    old message reaches the motors late. ``what`` ("setpoint published", ...) and
    ``parameter`` (the bound's name) word the message."""
    if not stamp:
        return
    age = (time.time_ns() if now is None else now) - stamp
    if age > max_age_ns:
        raise Rejected('stale', f'{what} {age / NANOSECONDS:.3g} s ago, more than {parameter} '
                                f'({max_age_ns / NANOSECONDS:g} s): the node was stopped or '
                                'fell behind (or the clocks of the two machines disagree)')


def duration_to_s(duration: Any) -> float:
    return duration.sec + duration.nanosec * 1e-9


class JointSelector:
    """Picks the active joints out of messages that name joints in any order.

    The index of each active joint in a message's name list is cached per name list, so a
    stream that always sends the same names pays for one dict lookup.
    """

    def __init__(self, active_joints: Sequence[str]) -> None:
        self.active_joints = list(active_joints)
        self._cache: dict[tuple[str, ...], list[int] | Rejected] = {}

    def indices(self, names: Sequence[str]) -> list[int]:
        """Indices of the active joints in ``names``; raises Rejected."""
        key = tuple(names)
        found = self._cache.get(key)
        if found is None:
            found = self._lookup(key)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = found
        if isinstance(found, Rejected):
            raise found
        return found

    def _lookup(self, names: Sequence[str]) -> list[int] | Rejected:
        if not names:
            return Rejected('empty', 'no joint names')
        where: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in where:
                return Rejected('malformed', f"joint '{name}' appears twice")
            where[name] = i
        missing = [j for j in self.active_joints if j not in where]
        if missing:
            return Rejected(
                'missing_joint', f"active joint(s) {', '.join(missing)} missing (the message "
                f"names {', '.join(names)}; active joints: {', '.join(self.active_joints)})")
        return [where[j] for j in self.active_joints]


#: rad or m: the largest position a joint may have (the core's bound, MAX_ANGLE); a larger
#: one is refused before anything is done with it (unwrapped, compared with the last)
MAX_POSITION = 1e9


def _pick(values: Sequence[float], index: Sequence[int], what: str,
          kind: str) -> list[float]:
    """The active entries of a message array as floats; Rejected for NaN or infinity, and
    for a position beyond MAX_POSITION ('out_of_range': unwrapped, 1e20 would have become
    an ordinary angle)."""
    out = [values[i] for i in index]
    if not all(map(math.isfinite, out)):
        bad = next(v for v in out if not math.isfinite(v))
        raise Rejected('non_finite', f'{what} {bad} ({kind}s must be finite)')
    if what == 'position' and not all(abs(v) <= MAX_POSITION for v in out):
        bad = next(v for v in out if not abs(v) <= MAX_POSITION)
        raise Rejected('out_of_range', f'position {bad:g} of a {kind} is beyond +-'
                                       f'{MAX_POSITION:g} (rad or m): not a joint position')
    return out


def setpoint_arrays(msg: JointState, selector: JointSelector, kind: str = 'setpoint'
                    ) -> tuple[list[float], list[float] | None]:
    """(positions, velocities or None) of the active joints of a JointState setpoint (or
    of what ``kind`` names in the messages: 'measured state').

    Positions are required; velocities are optional (an empty array); efforts are ignored
    but, like velocities, must have one entry per name when present. Raises Rejected.
    """
    names, position, velocity = msg.name, msg.position, msg.velocity   # each read is a property
    n = len(names)
    if n == 0 and len(position) == 0:
        raise Rejected('empty', f'empty {kind}: no joint names and no positions')
    for field, values in (('position', position), ('velocity', velocity),
                          ('effort', msg.effort)):
        size = len(values)
        if size != n and (field == 'position' or size):
            raise Rejected('malformed', f'{n} names but {size} {field} values')
    index = selector.indices(names)
    q = _pick(position, index, 'position', kind)
    v = _pick(velocity, index, 'velocity', kind) if len(velocity) else None
    return q, v


def trajectory_arrays(msg: JointTrajectory, selector: JointSelector,
                      unwrap: Sequence[bool] | None = None,
                      max_step: Sequence[float] | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time_from_start (N,), q (N, M), qd (N, M), qdd (N, M)) of a JointTrajectory.

    Every point needs positions; velocities and accelerations are either on every point
    or on none (then estimated over time_from_start by the package's one rule,
    :func:`cog_id_ros.offline.derivatives.fill_in`, as the offline tool does: 5 or more
    points). Raises Rejected.

    ``unwrap`` (M booleans, optional): those columns (revolute joints) are unwrapped
    before they are differentiated, each point taken as the 2 pi equivalent nearest the
    previous one; ``q`` is returned as received. ``max_step`` (M numbers, optional): a
    larger step between consecutive points (after unwrapping) is rejected ('jump').
    """
    points = msg.points
    if not points:
        raise Rejected('empty', 'trajectory without points')
    index = selector.indices(msg.joint_names)
    n_names = len(msg.joint_names)
    times = np.array([duration_to_s(p.time_from_start) for p in points])
    fields: dict[str, Any] = {}         # positions, and velocities and accelerations or None
    for field in ('positions', 'velocities', 'accelerations'):
        sizes = {len(getattr(p, field)) for p in points}
        if sizes == {0} and field != 'positions':
            fields[field] = None
            continue
        if sizes != {n_names}:
            k, p = next((k, p) for k, p in enumerate(points) if len(getattr(p, field)) != n_names)
            raise Rejected('malformed', f'point {k}: {len(getattr(p, field))} {field} for '
                           f'{n_names} joint names')
        values = np.array([getattr(p, field) for p in points])[:, index]
        if not np.isfinite(values).all():
            k, a = np.argwhere(~np.isfinite(values))[0]
            raise Rejected('non_finite', f'point {k}: {field} of {selector.active_joints[a]} is '
                           f'{values[k, a]} (must be finite)')
        fields[field] = values
    q, qd, qdd = fields['positions'], fields['velocities'], fields['accelerations']
    q_used = unwrapped_columns(q, unwrap)
    if max_step is not None and len(q_used) > 1:
        steps = np.abs(np.diff(q_used, axis=0))
        over = steps > np.asarray(max_step, float)
        if over.any():
            k, a = np.argwhere(over)[0]
            raise Rejected('jump', f'point {k + 1}: {selector.active_joints[a]} moves by '
                           f'{steps[k, a]:.6g} from the previous point (max_setpoint_step '
                           f'{max_step[a]:g}; revolute joints are compared after unwrapping)')
    if qd is None or qdd is None:
        if len(points) < derivatives.STENCIL or not (np.diff(times) > 0).all():
            raise Rejected('malformed', 'trajectory without velocities or accelerations needs '
                           f'{derivatives.STENCIL} or more points with increasing time_from_start '
                           'to estimate them')
        qd, qdd = derivatives.fill_in(times, q_used, qd, qdd)   # the package's one rule
    return times, q, qd, qdd


def unwrapped_columns(q: np.ndarray, unwrap: Sequence[bool] | None) -> np.ndarray:
    """``q`` (N, M) with the columns flagged in ``unwrap`` unwrapped (a copy), else ``q``."""
    if unwrap is None or not any(unwrap) or len(q) < 2:
        return q
    out = np.array(q, dtype=float)
    cols = np.flatnonzero(np.asarray(unwrap, bool))
    out[:, cols] = np.unwrap(out[:, cols], axis=0)
    return out


def clip_efforts(tau: np.ndarray, limits: np.ndarray) -> bool:
    """Clip efforts ``tau`` (an array of any shape, in place) to +-``limits`` (one per
    active joint, the last axis); True if any was clipped. The node's one clip: setpoints,
    the hold command and trajectories."""
    if (np.abs(tau) <= limits).all():
        return False
    np.clip(tau, -limits, limits, out=tau)
    return True


def nearest_turn(value: float, reference: float) -> float:
    """``value`` plus the multiple of 2 pi that brings it nearest ``reference``."""
    turns = round((reference - value) / (2.0 * math.pi))
    return value + turns * 2.0 * math.pi if turns else value


def trajectory_point_count(raw: bytes) -> int | None:
    """Number of points of a serialized (CDR) JointTrajectory, read from its header alone.

    Cheap (no deserialisation), so a trajectory too long to solve can be refused before it
    costs anything. None when the bytes are not a JointTrajectory this function can read.
    """
    try:
        if len(raw) < 4 or raw[0] != 0 or raw[1] not in (0, 1):
            return None
        order = '<' if raw[1] == 1 else '>'
        body = memoryview(raw)[4:]
        pos = 8                                          # stamp: int32 sec, uint32 nanosec

        def u32(at: int) -> tuple[int, int]:
            at = (at + 3) & ~3
            return struct.unpack_from(order + 'I', body, at)[0], at + 4

        length, pos = u32(pos)                           # frame_id (length with its NUL)
        pos += length
        count, pos = u32(pos)                            # joint_names
        if count > len(body):
            return None
        for _ in range(count):
            length, pos = u32(pos)
            pos += length
        points, _ = u32(pos)
        return points
    except (struct.error, IndexError, TypeError):
        return None


def solve_trajectory_message(raw: bytes, solver: 'InverseDynamics', selector: JointSelector, *,
                             unwrap: Sequence[bool] | None = None,
                             max_step: Sequence[float] | None = None,
                             effort_limits: Sequence[float] | None = None,
                             max_points: int | None = None) -> tuple[bytes, bool, int]:
    """A serialized JointTrajectory -> (serialized effort_trajectory, clipped, points).

    The whole trajectory path of the node, run in its trajectory process
    (:mod:`cog_id_ros.ros.trajectory_worker`): deserialise, check, solve in one vectorised
    core call, clip to ``effort_limits``, build and serialise the answer. Raises Rejected
    (with the number of points in ``points``) for a trajectory that gets no answer.
    """
    from rclpy.serialization import deserialize_message, serialize_message
    count = trajectory_point_count(raw)
    if max_points is not None and count is not None and count > max_points:
        exc = Rejected('too_long', f'{count} points, more than max_trajectory_points '
                                   f'({max_points})')
        exc.points = count
        raise exc
    msg = deserialize_message(raw, JointTrajectory)
    points = len(msg.points)
    try:
        if max_points is not None and points > max_points:
            raise Rejected('too_long', f'{points} points, more than max_trajectory_points '
                                       f'({max_points})')
        _, q, qd, qdd = trajectory_arrays(msg, selector, unwrap, max_step)
        if in_joint_space(solver, selector):
            q, qd, qdd, tau = _joint_space_trajectory(solver, unwrapped_columns(q, unwrap),
                                                      qd, qdd)
            names = list(solver.mechanism.active_joints)
        else:
            tau, names = _trajectory_torques(solver, q, qd, qdd, unwrap), selector.active_joints
        if not np.isfinite(tau).all():
            k = int(np.argwhere(~np.isfinite(tau))[0][0])
            raise Rejected('out_of_range', f'point {k}: the torques are not finite')
    except Rejected as exc:
        exc.points = points
        raise
    clipped = effort_limits is not None and clip_efforts(tau, np.asarray(effort_limits, float))
    out = effort_trajectory(msg, names, q, qd, qdd, tau)
    return serialize_message(out), clipped, points


def _trajectory_torques(solver: 'InverseDynamics', q: np.ndarray, qd: np.ndarray,
                        qdd: np.ndarray, unwrap: Sequence[bool] | None) -> np.ndarray:
    """The motors' efforts (N, M) of a trajectory of the motors; raises Rejected."""
    solver.reset()
    # solved at the unwrapped positions (the same poses, and the solver's continuation
    # from point to point never crosses a wrap); answered with the positions received
    result = solver.evaluate(unwrapped_columns(q, unwrap), qd, qdd, on_invalid='skip')
    if not result.valid.all():
        k = int(np.flatnonzero(~result.valid)[0])
        bad = rejection(result.errors[k])
        raise Rejected(bad.reason, f'point {k}: {bad}')
    return np.array(result.torques, dtype=float)


def in_joint_space(solver: Any, selector: JointSelector) -> bool:
    """Whether the trajectory names the mechanism's joint space, not its motors (the node
    with ``command_space: joint`` hands its trajectory process a selector of those)."""
    mechanism = solver.mechanism
    space = list(getattr(mechanism, 'joint_space', None) or ())
    return bool(space) and selector.active_joints == space \
        and space != list(mechanism.active_joints)


def _joint_space_trajectory(solver: 'InverseDynamics', q: np.ndarray, qd: np.ndarray,
                            qdd: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A joint-space trajectory (N, D) carried to the motors: (motor positions, motor
    velocities, no accelerations (N, 0), motor efforts), the efforts those of
    ``InverseDynamics.torques(q, qd, qdd, space='joint')``; raises Rejected naming the point."""
    from ..core import CogIdError
    transmission = solver.transmission
    for each in (transmission.joints, transmission.actuators):
        each.reset()
    try:
        tau = np.asarray(solver.torques(q, qd, qdd, space='joint'), dtype=float)
        theta = transmission.to_actuator_space(q)
        theta_dot = transmission.actuator_velocities(q, qd)
    except CogIdError as exc:
        bad = rejection(exc)
        sample = getattr(exc, 'sample', None)
        raise Rejected(bad.reason, str(bad) if sample is None else f'point {sample}: {bad}'
                       ) from None
    return theta, theta_dot, np.zeros((len(q), 0)), tau


def effort_trajectory(msg: JointTrajectory, active_joints: Sequence[str], q: np.ndarray,
                      qd: np.ndarray, qdd: np.ndarray, tau: np.ndarray) -> JointTrajectory:
    """The received trajectory's points, active joints only, with ``effort`` filled."""
    out = JointTrajectory()
    out.header = msg.header
    out.joint_names = list(active_joints)
    rows = zip(msg.points, q.tolist(), qd.tolist(), qdd.tolist(), tau.tolist())
    out.points = [JointTrajectoryPoint(positions=a, velocities=b, accelerations=c, effort=d,
                                       time_from_start=p.time_from_start)
                  for p, a, b, c, d in rows]
    return out


class EffortMessages:
    """Output messages of the setpoint path: ``effort_command`` serialized (bytes, for
    ``publish``: see :mod:`.cdr`), the JointStates reused (filled in place, then published).

    ``joints``: every joint of the mechanism, the names of ``joint_states``.
    """

    def __init__(self, active_joints: Sequence[str], joints: Sequence[str] = ()) -> None:
        self._pack_command = cdr.float64_multiarray_packer(len(active_joints))
        self.state = JointState()
        self.state.name = list(active_joints)
        self.pose = JointState()
        self.pose.name = list(joints)

    def command_for(self, efforts: Sequence[float]) -> bytes:
        """effort_command for one setpoint (one float per active joint), serialized: a
        Float64MultiArray for subscribers, without rclpy's conversion of a Python message."""
        return self._pack_command(*efforts)

    def state_for(self, header: Any, positions: list[float], velocities: list[float],
                  efforts: list[float]) -> JointState:
        """joint_effort for one setpoint (lists of floats)."""
        state = self.state
        state.header = header
        state.position = positions
        state.velocity = velocities
        state.effort = efforts
        return state

    def pose_for(self, frame_id: str, stamp_ns: int, positions: list[float],
                 velocities: list[float]) -> JointState:
        """joint_states for one setpoint: every joint's position and velocity (lists of
        floats; velocities may be empty), stamped ``stamp_ns``."""
        pose = self.pose
        pose.header.stamp.sec, pose.header.stamp.nanosec = divmod(stamp_ns, NANOSECONDS)
        pose.header.frame_id = frame_id
        pose.position = positions
        pose.velocity = velocities
        return pose


#: the core's advice for a setpoint it cannot reach (core/solve/sample_solve.py), and what it
#: means for a measured state: the robot does not move in such steps, its encoders jump
UNREACHABLE_ADVICE = ('. Send setpoints closer together (the solver follows the assembly '
                      'branch in short steps)')
MEASURED_ADVICE = ('; a measured pose that far from the last one is a jump of the encoders '
                   '(or max_measurement_step is too large)')


#: "setpoint(s)" as a word (not in a parameter name: mechanism.setpoint_tolerance)
_SETPOINT_WORD = re.compile(r'(?<![\w.])setpoint(s?)(?!\w)')


def of_measured_state(text: str) -> str:
    """A core message about the sample it solved ("cannot reach the setpoint ...", "the
    loops cannot be closed at this setpoint"), said of the measured state it was."""
    text = text.replace(UNREACHABLE_ADVICE, MEASURED_ADVICE)
    return _SETPOINT_WORD.sub(r'measured state\1', text)
