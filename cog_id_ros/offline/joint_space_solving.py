"""``cog_id_torques --space joint``: a trajectory of ``mechanism.joint_space`` in, the motor
torques (``mechanism.active_joints``) out.

The motion is solved as ``InverseDynamics.torques(q, qd, qdd, space='joint')`` solves it
(core/transmission/transmission.py, ``Transmission.torques``): the joint-space efforts of
the whole mechanism (the mechanism driven at its joint space: the linkage's inertia and
gravity included), carried to the motors by tau_m = J(theta)^T tau_q at the motors' pose
theta of each row. :class:`JointSpaceSolver` has the face of
``InverseDynamics.evaluate`` that :func:`cog_id_ros.offline.solving.solve` calls, so the
chunks, --skip-invalid and the messages are the actuator-space tool's; its
``mechanism`` is the mechanism driven at its joint space, whose active joints are the
joint space (a message names the input's columns).
"""

from types import SimpleNamespace

import numpy as np

from .console import EXIT_PARAMS, ToolError, one_line

#: what the input's columns are named after, in --space joint's messages
ROLE = 'joint-space joint'


def transmission_of(mech, solver, params_file):
    """The solver's Transmission; ToolError (EXIT_PARAMS) naming mechanism.joint_space when
    the mechanism names none or cannot be driven at it."""
    import cog_id_ros
    if not getattr(mech, 'joint_space', None):
        raise ToolError(
            f'{params_file}: --space joint needs mechanism.joint_space (the joints a '
            f'controller commands, one per degree of freedom: {mech.dof} here; e.g. the knee, '
            'the ankle pitch and roll), and '
            f'{mech.name} names none: add it under mechanism: (docs/transmission.md), or '
            f"give the motors' trajectory ({', '.join(mech.active_joints)}) without --space "
            'joint', EXIT_PARAMS, 'mechanism.joint_space')
    try:
        return solver.transmission
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'{params_file}: {one_line(exc)}', EXIT_PARAMS,
                        'mechanism.joint_space') from None


class JointSpaceSolver:
    """``evaluate(q, qd, qdd, on_invalid)`` of a joint-space motion: the motors' exact
    torques, with the motors' rates (theta_dot = K q_dot) for the summary's power."""

    def __init__(self, transmission):
        self.transmission = transmission
        self.mechanism = transmission.joint_mechanism
        self.width = len(transmission.active_joints)

    def evaluate(self, q, qd, qdd, on_invalid='raise'):
        import cog_id_ros
        tr = self.transmission
        ev = tr.joints.evaluate(q, qd, qdd, on_invalid=on_invalid)
        n = len(q)
        tau_q = np.asarray(ev.torques, dtype=float).reshape(n, -1)
        valid = np.array(ev.valid, bool).reshape(n)
        errors = list(ev.errors)
        torques = np.zeros((n, self.width))
        rates = np.zeros((n, self.width))
        for i in np.flatnonzero(valid).tolist():
            try:
                theta = tr.to_actuator_space(q[i])
                rates[i] = tr.actuator_velocities(q[i], qd[i])      # K q_dot
                torques[i] = tr.actuator_efforts(theta, tau_q[i])   # J^T tau_q
            except cog_id_ros.CogIdError as exc:
                if on_invalid == 'raise':
                    exc.sample = i          # the row in this chunk (solving.solve names it)
                    raise
                valid[i], errors[i] = False, exc
        return SimpleNamespace(torques=torques, valid=valid, errors=errors, rates=rates)
