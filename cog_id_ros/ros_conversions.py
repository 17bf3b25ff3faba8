"""ROS messages <-> arrays for the node: setpoints in, efforts out (no physics, no node).

Everything here checks what a message carries before a number reaches the solver, and
says what is wrong with a :class:`Rejected` that carries a short ``reason`` (the key the
node counts in diagnostics) and a sentence for the log.
"""
import math

import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from . import derivatives
from .core import ClosureError, SetpointError, SingularConfigurationError

NANOSECONDS = 1_000_000_000

#: every reason a setpoint or trajectory can be rejected for, as counted in diagnostics
REASONS = {
    'empty': 'the message carries no joints or no points',
    'malformed': 'arrays of unequal length, or duplicate joint names',
    'missing_joint': 'an active joint is not in the message',
    'non_finite': 'a position, velocity or acceleration of an active joint is NaN or infinite',
    'stamp': 'the header stamp does not come after the previous accepted setpoint',
    'closure': 'the loops cannot be closed at this pose',
    'singular': 'the pose is singular (closure Jacobian condition number too large)',
    'inconsistent': 'the redundant active coordinates disagree with the loop closure',
    'solver': 'any other setpoint the solver refuses',
}


class Rejected(ValueError):
    """A setpoint or trajectory that gets no command: ``reason`` is a key of REASONS."""

    def __init__(self, reason, message):
        assert reason in REASONS, reason
        self.reason = reason
        super().__init__(message)


def rejection(exc, redundant):
    """The Rejected for a core exception (ClosureError, SingularConfigurationError, ...)."""
    if isinstance(exc, SingularConfigurationError):
        return Rejected('singular', str(exc))
    if isinstance(exc, ClosureError):
        # the core raises ClosureError both for a loop that cannot close and for a
        # redundant setpoint that over-determines the pose inconsistently
        if redundant and 'redundant setpoint' in str(exc):
            return Rejected('inconsistent', str(exc))
        return Rejected('closure', str(exc))
    if isinstance(exc, SetpointError):
        return Rejected('non_finite' if 'finite' in str(exc) else 'malformed', str(exc))
    return Rejected('solver', str(exc))


def stamp_to_ns(stamp):
    """A builtin_interfaces/Time as integer nanoseconds."""
    return stamp.sec * NANOSECONDS + stamp.nanosec


def duration_to_s(duration):
    return duration.sec + duration.nanosec * 1e-9


class JointSelector:
    """Picks the active joints out of messages that name joints in any order.

    The index of each active joint in a message's name list is cached per name list, so a
    stream that always sends the same names pays for one dict lookup.
    """

    def __init__(self, active_joints):
        self.active_joints = list(active_joints)
        self._cache = {}

    def indices(self, names):
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

    def _lookup(self, names):
        if not names:
            return Rejected('empty', 'no joint names')
        where = {}
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


def _pick(values, index, what):
    """The active entries of a message array as floats; Rejected for NaN or infinity."""
    out = [values[i] for i in index]
    if not all(map(math.isfinite, out)):
        bad = next(v for v in out if not math.isfinite(v))
        raise Rejected('non_finite', f'{what} {bad} (setpoints must be finite)')
    return out


def setpoint_arrays(msg, selector):
    """(positions, velocities or None) of the active joints of a JointState setpoint.

    Positions are required; velocities are optional (an empty array); efforts are ignored
    but, like velocities, must have one entry per name when present. Raises Rejected.
    """
    names, position, velocity = msg.name, msg.position, msg.velocity   # each read is a property
    n = len(names)
    if n == 0 and len(position) == 0:
        raise Rejected('empty', 'empty setpoint: no joint names and no positions')
    for field, values in (('position', position), ('velocity', velocity),
                          ('effort', msg.effort)):
        size = len(values)
        if size != n and (field == 'position' or size):
            raise Rejected('malformed', f'{n} names but {size} {field} values')
    index = selector.indices(names)
    q = _pick(position, index, 'position')
    v = _pick(velocity, index, 'velocity') if len(velocity) else None
    return q, v


def trajectory_arrays(msg, selector):
    """(time_from_start (N,), q (N, M), qd (N, M), qdd (N, M)) of a JointTrajectory.

    Every point needs positions; velocities and accelerations are either on every point
    or on none (then estimated from the positions over time_from_start, the scheme of
    :mod:`cog_id_ros.derivatives`, which needs 5 or more points). Raises Rejected.
    """
    points = msg.points
    if not points:
        raise Rejected('empty', 'trajectory without points')
    index = selector.indices(msg.joint_names)
    n_names = len(msg.joint_names)
    times = np.array([duration_to_s(p.time_from_start) for p in points])
    fields = {}
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
    if qd is None or qdd is None:
        if len(points) < derivatives.STENCIL or not (np.diff(times) > 0).all():
            raise Rejected('malformed', 'trajectory without velocities or accelerations needs '
                           f'{derivatives.STENCIL} or more points with increasing time_from_start '
                           'to estimate them')
        if qd is None:
            qd = derivatives.first_derivative(times, q)
        if qdd is None:
            qdd = derivatives.second_derivative(times, q) if fields['velocities'] is None \
                else derivatives.first_derivative(times, qd)
    return times, q, qd, qdd


def effort_trajectory(msg, active_joints, q, qd, qdd, tau):
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
    """Reusable output messages of the setpoint path (filled in place, then published)."""

    def __init__(self, active_joints):
        self.command = Float64MultiArray()
        self.state = JointState()
        self.state.name = list(active_joints)

    def command_for(self, efforts):
        """effort_command for one setpoint (a list of floats)."""
        self.command.data = efforts
        return self.command

    def state_for(self, header, positions, velocities, efforts):
        """joint_effort for one setpoint (lists of floats)."""
        state = self.state
        state.header = header
        state.position = positions
        state.velocity = velocities
        state.effort = efforts
        return state
