"""``cog_id_torques`` for a floating-base robot (``mechanism.floating_base``): the base's
columns in (:mod:`cog_id_ros.offline.base_samples`), ``--contacts``, and the efforts, the
contact wrenches and the base wrench out.

The samples are solved as ``InverseDynamics.whole_body_torques`` solves them (one batch
call per chunk; core/solve/whole_body.py). :class:`WholeBodySolver` has the face of
``InverseDynamics.evaluate`` that :func:`cog_id_ros.offline.solving.solve` calls (the base
packed beside the actuators' columns), so the chunks, --skip-invalid and the row messages
are the fixed-base tool's. Output columns after the efforts: per contact in --contacts
order ``<contact>.fx .fy .fz .mx .my .mz`` (a 3d contact: ``.fx .fy .fz``; N and N m, world
axes, at the contact point, what the ground applies to the robot), then
``base_wrench.fx .. base_wrench.mz`` (N, N m: what the world must still apply at the base,
base frame, at its origin).
"""

from types import SimpleNamespace

import numpy as np

from . import base_samples, trajectory_io
from .console import EXIT_USAGE, ToolError

#: --contacts NONE: no contact (the whole residual in the base wrench)
NONE = 'none'
WRENCH = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')
BASE_WRENCH = 'base_wrench'


def contact_names(args, mech) -> list[str] | None:
    """The contacts of --contacts (default: all of ``mechanism.contacts``; ``none``: none),
    or None for a fixed-base mechanism. ToolError (EXIT_USAGE) for an unknown or repeated
    name, for --contacts with a fixed base and for --space joint with a floating one."""
    option = getattr(args, 'contacts', None)
    if not mech.floating_base:
        if option is not None:
            raise ToolError(f'--contacts {option}: {mech.name} has a fixed base '
                            '(mechanism.floating_base is false): contacts are for a robot '
                            'whose base floats; drop --contacts', EXIT_USAGE)
        return None
    if getattr(args, 'space', 'actuator') == 'joint':
        raise ToolError(f'--space joint: not available for {mech.name}, whose base floats '
                        "(mechanism.floating_base): give the motors' trajectory "
                        f"({', '.join(mech.active_joints)}) and the base columns without "
                        '--space joint', EXIT_USAGE)
    known = list(mech.contacts)
    if option is None:
        return known
    if option.strip() == NONE and NONE not in mech.contacts:
        return []
    names = [name.strip() for name in option.split(',')]
    for k, name in enumerate(names):
        if name not in mech.contacts or name in names[:k]:
            what = ('an empty name' if not name else f"'{name}' twice" if name in names[:k]
                    else f"'{name}' is not a contact of {mech.name}")
            raise ToolError(f"--contacts {option}: {what}; its contacts (mechanism.contacts) "
                            f"are {', '.join(known) or 'none'} (comma-separated, or "
                            f'{NONE})', EXIT_USAGE)
    return names


def wrench_columns(mech, contacts: list[str]) -> list[str]:
    """The output's columns after the efforts: each contact's wrench, then the base's."""
    columns = [f'{name}.{f}' for name in contacts for f in WRENCH[:mech.contacts[name].size]]
    return columns + [f'{BASE_WRENCH}.{f}' for f in WRENCH]


class WholeBodySolver:
    """``evaluate(q, qd, qdd, on_invalid)`` of a floating robot: ``q`` is the actuators'
    positions then the base pose (N, M + 7), ``qd`` and ``qdd`` the actuators' rates then
    the base velocity or acceleration (N, M + 6) (:meth:`pack`); its ``torques`` are the
    efforts, the contacts' wrenches and the base wrench (N, ``width``). A sample the core
    refuses raises (``.sample`` is its row in the call): solving.solve skips it or names
    it."""

    def __init__(self, solver, contacts: list[str]):
        self.solver = solver
        self.mechanism = mech = solver.mechanism
        self.contacts = list(contacts)
        self.m = len(mech.active_joints)
        self.extra_columns = wrench_columns(mech, self.contacts)
        self.width = self.m + len(self.extra_columns)
        active = list(mech.active_joints)
        pose = [trajectory_io.joint_column(j, 'position') for j in active]
        # the columns solving.solve names: a refused pose by the actuators' positions, a
        # value out of range by the column of each packed value
        self.message_columns = (pose, [
            pose + list(base_samples.POSE),
            [trajectory_io.joint_column(j, 'velocity') for j in active]
            + list(base_samples.VELOCITY),
            [trajectory_io.joint_column(j, 'acceleration') for j in active]
            + list(base_samples.ACCELERATION)])

    @staticmethod
    def pack(q, qd, qdd, base: base_samples.BaseSamples):
        """The actuators' samples (N, M) and the base's, side by side (see the class)."""
        return (np.hstack([q, base.pose]), np.hstack([qd, base.velocity]),
                np.hstack([qdd, base.acceleration]))

    def evaluate(self, q, qd, qdd, on_invalid='raise'):
        m = self.m
        part = np.ascontiguousarray
        out = self.solver.whole_body_torques(
            part(q[:, m:]), part(qd[:, m:]), part(qdd[:, m:]), part(q[:, :m]),
            part(qd[:, :m]), part(qdd[:, :m]), contacts=self.contacts)
        n = len(q)
        torques = np.hstack([np.asarray(out.efforts, dtype=float).reshape(n, m)]
                            + [np.asarray(out.wrenches[name], dtype=float).reshape(n, -1)
                               for name in self.contacts]
                            + [np.asarray(out.base_wrench, dtype=float).reshape(n, 6)])
        return SimpleNamespace(torques=torques, valid=np.ones(n, bool), errors=[None] * n)

    def vertical_forces(self, values: np.ndarray) -> dict:
        """{contact: its fz column (N,)} of the solved ``values`` (N, width), for the plot."""
        return {name: values[:, self.m + self.extra_columns.index(f'{name}.fz')]
                for name in self.contacts}
