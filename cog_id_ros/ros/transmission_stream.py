"""cog_transmission_node's two maps, message to message (no node): a JointState of one space
-> the JointState of the other, or a :class:`.conversions.Rejected` that says why.

* :class:`CommandMap`: ``joint_command`` (mechanism.joint_space) -> ``actuator_command``
  (mechanism.active_joints): positions by ``Transmission.to_actuator_space``, velocities by
  ``actuator_velocities``, efforts by ``actuator_efforts``;
* :class:`StateMap`: ``actuator_states`` (the motors) -> ``joint_states`` (every joint of
  mechanism.joints): positions of the closed pose (the actuators' solve: the joint space
  and every passive joint), velocities qdot = S thetadot (their joint-space rows are
  ``joint_velocities``), efforts ``joint_efforts`` on the joint space, the measured effort on
  a motor outside it, 0 on a passive joint.

Velocities and efforts need the pose: a message that carries them without positions is
``malformed``. The physics is the core's :class:`Transmission`; each map has its own (its
warm start follows its stream).
"""
import math
from typing import Any, Sequence

import numpy as np
from sensor_msgs.msg import JointState

from ..core import CogIdError, Transmission
from . import conversions
from .conversions import JointSelector, Rejected, rejection, setpoint_arrays
from .setpoint_filter import NANOSECONDS

#: the reasons a message of cog_transmission_node is rejected for (keys of
#: conversions.REASONS), in the order /diagnostics lists them
TRANSMISSION_REASONS = ('empty', 'malformed', 'missing_joint', 'non_finite', 'out_of_range',
                        'stale', 'limit', 'closure', 'unreachable', 'singular', 'inconsistent',
                        'solver')


def state_arrays(msg: JointState, selector: JointSelector, kind: str
                 ) -> tuple[list[float], list[float] | None, list[float] | None]:
    """(positions, velocities or None, efforts or None) of the selector's joints in ``msg``;
    raises Rejected: velocities or efforts without positions are ``malformed`` (the map
    needs the pose), NaN or infinity ``non_finite``."""
    if not len(msg.position) and (len(msg.velocity) or len(msg.effort)):
        raise Rejected('malformed', f'{kind} with velocities or efforts but no positions: '
                                    'the map needs the pose (positions of every joint named)')
    q, v = setpoint_arrays(msg, selector, kind)
    if not len(msg.effort):
        return q, v, None
    effort = msg.effort
    e = [float(effort[i]) for i in selector.indices(msg.name)]
    if not all(map(math.isfinite, e)):
        bad = next(x for x in e if not math.isfinite(x))
        raise Rejected('non_finite', f'{kind}: effort {bad} (efforts must be finite)')
    return q, v, e


def check_age(info: Any, max_age: float, kind: str) -> None:
    """Rejected ('stale') when the message was published more than ``max_age`` s ago
    (DDS's source timestamp; 0: no check): :func:`.conversions.check_age`."""
    if max_age and info is not None:
        conversions.check_age(info.get('source_timestamp'), int(max_age * NANOSECONDS),
                              f'{kind} published', 'max_setpoint_age')


def _finite(kind: str, *arrays: Any) -> None:
    for values in arrays:
        if values is not None and not np.isfinite(values).all():
            raise Rejected('out_of_range', f'{kind}: the mapped values are not finite')


def _as_list(values: Any) -> list[float]:
    return [] if values is None else np.asarray(values, dtype=float).tolist()


class CommandMap:
    """joint_command -> actuator_command (joint space -> the motors)."""

    def __init__(self, transmission: Transmission) -> None:
        self.transmission = transmission
        self.selector = JointSelector(transmission.joint_space)
        self.names = list(transmission.active_joints)

    def map(self, msg: JointState) -> JointState:
        """The actuator_command of the joint command ``msg``; raises Rejected."""
        q, v, e = state_arrays(msg, self.selector, 'joint command')
        t = self.transmission
        try:
            theta = t.to_actuator_space(q)
            theta_dot = None if v is None else t.actuator_velocities(q, v)
            tau = None if e is None else t.actuator_efforts(theta, e)
        except CogIdError as exc:
            raise rejection(exc) from None
        _finite('joint command', theta, theta_dot, tau)
        return JointState(header=msg.header, name=self.names, position=_as_list(theta),
                          velocity=_as_list(theta_dot), effort=_as_list(tau))


class StateMap:
    """actuator_states -> joint_states (the motors -> every joint, the joint space first
    among them as mechanism.joints orders them)."""

    def __init__(self, transmission: Transmission) -> None:
        self.transmission = transmission
        mechanism = transmission.mechanism
        self.selector = JointSelector(transmission.active_joints)
        self.names = list(mechanism.joints)
        self.rows_q = [mechanism.joint_index[j] for j in transmission.joint_space]
        self.rows_m = [(mechanism.joint_index[j], a)
                       for a, j in enumerate(transmission.active_joints)
                       if j not in transmission.joint_space]

    def map(self, msg: JointState) -> JointState:
        """The joint_states of the motors' measured state ``msg``; raises Rejected."""
        theta, theta_dot, tau_m = state_arrays(msg, self.selector, 'actuator state')
        t = self.transmission
        try:
            # (one solve; singular poses named by both sets of joints)
            positions, rates = t.joint_state(theta, theta_dot)
            efforts = None if tau_m is None else self._efforts(theta, tau_m)
        except CogIdError as exc:
            raise rejection(exc) from None
        _finite('actuator state', positions, rates, efforts)
        return JointState(header=msg.header, name=self.names, position=_as_list(positions),
                          velocity=_as_list(rates), effort=_as_list(efforts))

    def _efforts(self, theta: Sequence[float], tau_m: Sequence[float]) -> np.ndarray:
        """Every joint's effort: K^T tau_m on the joint space, the measured effort on a
        motor outside it, 0 on a passive joint (the linkage massless, as the map is)."""
        out = np.zeros(len(self.names))
        for row, a in self.rows_m:
            out[row] = tau_m[a]
        out[self.rows_q] = self.transmission.joint_efforts(theta, tau_m)
        return out
