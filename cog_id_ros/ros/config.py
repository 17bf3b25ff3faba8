"""What cog_id_node reads at start-up, frozen: :class:`NodeConfig` (plain Python, no ROS).

Made once from the declared values of ``NODE_PARAMETERS`` (:mod:`.parameters`, the one
table) and the mechanism; the node and its trajectory process both take it (it crosses to
the spawned process pickled). Every parameter of the table is an attribute by its name
(a NodeConfig's ``setpoint_timeout``): a parameter added to the table needs no edit here nor in
the node's constructor.
"""
import dataclasses
import re
from typing import Any, Mapping, Sequence

import numpy as np

from ..core import MechanismConfigError
from .parameters import NODE_PARAMETERS, NodeParameter

#: per-joint parameters of the motors (the rest are per commanded joint)
ACTUATOR_PARAMETERS = ('effort_limits',)


def commanded_joints(mechanism: Any, command_space: Any) -> list[str]:
    """The joints setpoints and measured states name: the motors, or with
    ``command_space`` 'joint' mechanism.joint_space (MechanismConfigError naming both
    parameters when the mechanism names none)."""
    if command_space != 'joint':
        return list(mechanism.active_joints)
    if not getattr(mechanism, 'joint_space', None):
        raise MechanismConfigError(
            'command_space', f"is 'joint' but mechanism '{mechanism.name}' names no "
                             'mechanism.joint_space (the joints a controller commands, e.g. '
                             "the ankle's pitch and roll): give mechanism.joint_space, or "
                             'command_space: actuator (setpoints naming the motors)')
    return list(mechanism.joint_space)


#: a contact's name as it appears in a topic name (contact_wrenches/<name>)
_TOPIC_TOKEN = re.compile(r'[A-Za-z][A-Za-z0-9_]*')


def contact_set_problem(value: Any, mechanism: Any) -> str:
    """Why ``value`` cannot be the set of active contacts of ``mechanism`` ('' when it can):
    a list of distinct names of mechanism.contacts ([] or any empty array: none)."""
    known = list(getattr(mechanism, 'contacts', None) or ())
    if value is None or isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        return (f"must be a list of contact names (of {', '.join(known) or 'none'}; [] for "
                f'none), got {value!r}')
    names = list(value)
    if not all(isinstance(name, str) for name in names):
        return f'must be a list of contact names, got {names!r}'
    unknown = [name for name in names if name not in known]
    if unknown:
        return (f"{', '.join(repr(n) for n in unknown)} not in mechanism.contacts "
                f"({', '.join(known) or 'none: mechanism.floating_base is false'})")
    if len(set(names)) != len(names):
        return f'names a contact twice: {names}'
    return ''


def check_floating(mechanism: Any, overrides: Mapping[str, Any]) -> None:
    """A floating base (mechanism.floating_base) the node can serve, or MechanismConfigError
    naming the parameter: contacts in the mechanism (the node balances the motion with
    them), control_mode feedforward, command_space actuator; active_contacts (when given)
    names some of them. Without a floating base, active_contacts names none."""
    given = overrides.get('active_contacts')
    if given is not None and given != []:
        NODE_PARAMETERS['active_contacts'].check(given, [])
        problem = contact_set_problem(given, mechanism)
        if problem:
            raise MechanismConfigError('active_contacts', problem)
    if not getattr(mechanism, 'floating_base', False):
        return
    if not mechanism.contacts:
        raise MechanismConfigError(
            'mechanism.contacts', 'mechanism.floating_base is true but the mechanism names no '
                                  'contact: cog_id_node balances the motion of a floating base '
                                  'with contact wrenches; give mechanism.contacts.<name> '
                                  '({link: <link>, type: 6d or 3d}), or a fixed base')
    for name in mechanism.contacts:
        if not _TOPIC_TOKEN.fullmatch(name):
            raise MechanismConfigError(
                f'mechanism.contacts.{name}', 'the name must be a letter then letters, digits '
                                              'or _ (it names the topic contact_wrenches/<name>)')
    for parameter, value, served in (('control_mode', 'feedforward', 'feedforward'),
                                     ('command_space', 'actuator', 'actuator')):
        if overrides.get(parameter, value) != value:
            raise MechanismConfigError(
                parameter, f'is {overrides[parameter]!r}, but a floating base '
                           f'(mechanism.floating_base) is served with {parameter} {served} only')


@dataclasses.dataclass(frozen=True, eq=False)
class NodeConfig:
    """The node's configuration: ``values`` holds every parameter of NODE_PARAMETERS as
    checked (per-joint ones as arrays in ``active_joints`` order, ``effort_limits`` in
    ``actuators`` order), read as attributes."""

    #: the mechanism's parameters (``Mechanism.from_parameters`` builds it again from them)
    mechanism: dict[str, Any]
    #: the commanded joints, the one place their names come from: what setpoints,
    #: trajectories and measured states name (the streams' selectors, unwrap, steps, gains):
    #: mechanism.active_joints, or mechanism.joint_space with ``command_space: joint``
    active_joints: tuple[str, ...]
    #: per commanded joint: taken as the 2 pi equivalent nearest the previous position
    unwrap: list[bool]
    values: dict[str, Any]
    #: the motors (mechanism.active_joints), the efforts' order (effort_command,
    #: joint_effort, effort_limits); () : the same as active_joints
    actuators: tuple[str, ...] = ()

    @classmethod
    def declare(cls, node: Any, overrides: dict[str, Any], mechanism: Any,
                table: Mapping[str, NodeParameter] = NODE_PARAMETERS) -> 'NodeConfig':
        """Declare every parameter of ``table`` (NODE_PARAMETERS; cog_sim_node's:
        ``cog_id_ros.ros.sim_parameters.SIM_PARAMETERS``) on ``node`` (a ReadOnlyNode)
        read-only, given or by default, and make the configuration of ``mechanism`` from them.

        The mechanism's effort limits (joints.<j>.effort, URDF <limit effort>) are the
        default of effort_limits; the node's parameter, when given, wins. In a feedback
        control_mode, joint_states_decimation is 0 unless given. Parameters that may change
        at run time (``runtime``: active_contacts) are not declared here: the part of the
        node that uses them declares them (:class:`.floating_mode.FloatingBase`); a floating
        base is checked here (:func:`check_floating`).
        """
        commanded = commanded_joints(mechanism, overrides.get('command_space', 'actuator')
                                     if 'command_space' in table else 'actuator')
        if table is NODE_PARAMETERS:
            check_floating(mechanism, overrides)
        table = {name: p for name, p in table.items() if not p.runtime}

        def types(joint_names: Sequence[str]) -> list[str]:
            return [mechanism.joint_types[mechanism.joints.index(j)] for j in joint_names]

        limits = getattr(mechanism, 'effort_limits', None)
        defaults: dict[str, Any] = {'effort_limits': list(limits) if limits else None}
        if overrides.get('control_mode', 'feedforward') != 'feedforward':
            defaults['joint_states_decimation'] = 0     # the robot publishes joint_states
        # effort_limits are the motors'; every other per-joint parameter the commanded joints'
        by_motor = {name: p for name, p in table.items() if name in ACTUATOR_PARAMETERS}
        values = node.declare_table(by_motor, overrides, types(mechanism.active_joints),
                                    defaults)
        values.update(node.declare_table(
            {name: p for name, p in table.items() if name not in by_motor}, overrides,
            types(commanded), defaults))
        values = {name: values[name] for name in table}     # the table's order
        wraps = [mechanism.joint_specs[mechanism.joint_index[j]].kind.wraps for j in commanded]
        return cls(mechanism=mechanism.settled_parameters(),
                   active_joints=tuple(commanded),
                   unwrap=[values.get('unwrap_angles', False) and w for w in wraps],
                   values=values, actuators=tuple(mechanism.active_joints))

    def __getattr__(self, name: str) -> Any:
        # only what the dataclass does not hold itself; __dict__, not self.values: unpickling
        # asks for attributes (__setstate__) before the fields are set
        if not name.startswith('__'):
            values = self.__dict__.get('values', {})
            if name in values:
                return values[name]
        raise AttributeError(f'{type(self).__name__} has no attribute {name!r}')

    def with_backend(self, backend: str) -> 'NodeConfig':
        """The same configuration with ``backend`` (e.g. the one the node's solver resolved
        'auto' to)."""
        return dataclasses.replace(self, values={**self.values, 'backend': backend})

    @property
    def feedback(self) -> bool:
        """Whether commands follow measured states (a control_mode other than feedforward)."""
        return self.values['control_mode'] != 'feedforward'

    @property
    def motors(self) -> tuple[str, ...]:
        """The motors, in effort order (``actuators``; active_joints when not given)."""
        return self.actuators or self.active_joints

    @property
    def joint_space(self) -> bool:
        """Whether setpoints and measured states name mechanism.joint_space
        (``command_space: joint``)."""
        return self.values.get('command_space', 'actuator') == 'joint'

    @property
    def limited(self) -> bool:
        """Whether any active joint has a finite effort limit."""
        return bool(np.isfinite(self.values['effort_limits']).any())


def start_up_summary(mechanism: Any, config: NodeConfig) -> str:
    """The node's start-up log line: the mechanism, its limits, the timeout."""
    limits = ', '.join(f'{j} {lim:g}' for j, lim in zip(config.motors,
                                                         config.effort_limits))
    return (f"mechanism '{mechanism.name}': {len(mechanism.links)} links, "
            f"{len(mechanism.joints)} joints, {mechanism.dof} DOF, "
            + (f"floating base '{mechanism.base_link}' (its state from base_state), contacts "
               + ', '.join(f'{c.name} ({c.size}d)' for c in mechanism.contacts.values())
               if getattr(mechanism, 'floating_base', False) else
               f"base link '{mechanism.base_link}' held fixed")
            + ', active joints '
            f"{', '.join(config.motors)}{' (redundant)' if mechanism.is_redundant else ''}"
            + (f"; setpoints in joint space: {', '.join(config.active_joints)}"
               if config.joint_space else '')
            + f'; effort limits: {limits}; setpoint timeout {config.setpoint_timeout:g} s '
            f'({config.timeout_behavior})'
            + (f'; {len(mechanism.spherical_chains)} chains of three revolute joints through '
               f'massless links solved as spherical joints' if mechanism.spherical_chains
               else '')
            + (f"; locked joints (held at their initial positions): "
               f"{', '.join(mechanism.locked_joints)}" if mechanism.locked_joints else ''))
