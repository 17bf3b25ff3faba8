"""What cog_id_node reads at start-up, frozen: :class:`NodeConfig` (plain Python, no ROS).

Made once from the declared values of ``NODE_PARAMETERS`` (:mod:`.parameters`, the one
table) and the mechanism; the node and its trajectory process both take it (it crosses to
the spawned process pickled). Every parameter of the table is an attribute by its name
(a NodeConfig's ``setpoint_timeout``): a parameter added to the table needs no edit here nor in
the node's constructor.
"""
import dataclasses
from typing import Any, Mapping

import numpy as np

from .parameters import NODE_PARAMETERS, NodeParameter


@dataclasses.dataclass(frozen=True, eq=False)
class NodeConfig:
    """The node's configuration: ``values`` holds every parameter of NODE_PARAMETERS as
    checked (per-joint ones as arrays in ``active_joints`` order), read as attributes."""

    #: the mechanism's parameters (``Mechanism.from_parameters`` builds it again from them)
    mechanism: dict[str, Any]
    active_joints: tuple[str, ...]
    #: per active joint: taken as the 2 pi equivalent nearest the previous position
    unwrap: list[bool]
    values: dict[str, Any]

    @classmethod
    def declare(cls, node: Any, overrides: dict[str, Any], mechanism: Any,
                table: Mapping[str, NodeParameter] = NODE_PARAMETERS) -> 'NodeConfig':
        """Declare every parameter of ``table`` (NODE_PARAMETERS; cog_sim_node's:
        ``cog_id_ros.ros.sim_parameters.SIM_PARAMETERS``) on ``node`` (a ReadOnlyNode)
        read-only, given or by default, and make the configuration of ``mechanism`` from them.

        The mechanism's effort limits (joints.<j>.effort, URDF <limit effort>) are the
        default of effort_limits; the node's parameter, when given, wins. In a feedback
        control_mode, joint_states_decimation is 0 unless given.
        """
        active_types = [mechanism.joint_types[mechanism.joints.index(j)]
                        for j in mechanism.active_joints]
        limits = getattr(mechanism, 'effort_limits', None)
        defaults: dict[str, Any] = {'effort_limits': list(limits) if limits else None}
        if overrides.get('control_mode', 'feedforward') != 'feedforward':
            defaults['joint_states_decimation'] = 0     # the robot publishes joint_states
        values = node.declare_table(table, overrides, active_types, defaults)
        wraps = [kind.wraps for kind in mechanism.active_kinds]
        return cls(mechanism=mechanism.settled_parameters(),
                   active_joints=tuple(mechanism.active_joints),
                   unwrap=[values.get('unwrap_angles', False) and w for w in wraps],
                   values=values)

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
    def limited(self) -> bool:
        """Whether any active joint has a finite effort limit."""
        return bool(np.isfinite(self.values['effort_limits']).any())


def start_up_summary(mechanism: Any, config: NodeConfig) -> str:
    """The node's start-up log line: the mechanism, its limits, the timeout."""
    limits = ', '.join(f'{j} {lim:g}' for j, lim in zip(config.active_joints,
                                                         config.effort_limits))
    return (f"mechanism '{mechanism.name}': {len(mechanism.links)} links, "
            f"{len(mechanism.joints)} joints, {mechanism.dof} DOF, base link "
            f"'{mechanism.base_link}' held fixed, active joints "
            f"{', '.join(config.active_joints)}{' (redundant)' if mechanism.is_redundant else ''}"
            f'; effort limits: {limits}; setpoint timeout {config.setpoint_timeout:g} s '
            f'({config.timeout_behavior})'
            + (f'; {len(mechanism.spherical_chains)} chains of three revolute joints through '
               f'massless links solved as spherical joints' if mechanism.spherical_chains
               else '')
            + (f"; locked joints (held at their initial positions): "
               f"{', '.join(mechanism.locked_joints)}" if mechanism.locked_joints else ''))
