"""A node whose parameters are read once at start-up and are read-only afterwards.

:class:`ReadOnlyNode` is the base of the package's nodes: it declares parameters from the
values given to the node (params files, ``-p``) or from a table of
:class:`~.parameters.NodeParameter`, each checked with an error that names it
(MechanismConfigError: main() turns it into exit status 2 and one line); it checks the
QoS overrides; and once the node is built (:meth:`ReadOnlyNode.refuse_changes`) it
refuses every parameter change with the node's own reason, naming the parameter (read-only,
or not a parameter of the node), except those of a parameter the node let change at run
time (:meth:`ReadOnlyNode.allow_changes`: cog_id_node's ``active_contacts``), checked by
their own rule and applied once set. It also routes the package's Python log lines to the
node's logger while it exists, and destroys a node whose build failed
(:meth:`ReadOnlyNode.build_or_destroy`). A subclass
provides ``internal_error(where, exc)``: the refusal is a guarded callback
(:func:`.diagnostics.guarded`).
"""
import contextlib
from typing import Any, Callable, Iterator, Mapping, Sequence, cast
import warnings

import numpy as np
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
import rclpy.exceptions
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core import AssemblyWarning, MechanismConfigError
from .diagnostics import PythonLogsToRos, guarded
from .parameters import MAX_QOS_DEPTH, QOS_OVERRIDE_VALUES, NodeParameter

#: parameters rclpy declares itself (not unknown to any node)
RCLPY_PARAMETERS = ('use_sim_time', 'start_type_description_service')


class ReadOnlyNode(Node):
    """A Node that reads its parameters once; ``node_name`` also names it in the reason
    a runtime change is refused with."""

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        self._read_only_reason = (f'{node_name} reads its parameters once at start-up; they '
                                  'are read-only (restart the node with the new value)')
        self._unknown_reason = f'not a parameter of {node_name}'
        self._refusing = False
        #: parameters that may change at run time: name -> (check, apply)
        self._changeable: dict[str, tuple[Callable[[Any], str], Callable[[Any], None]]] = {}
        super().__init__(node_name, **kwargs)
        # the package's Python log lines (the core's: e.g. a fallback to the Python kernels
        # while a solver is built) in ROS's format, under this node's name
        self._python_logs: PythonLogsToRos | None = PythonLogsToRos.attach(self.get_logger())

    def build_or_destroy(self, build: Callable[[], None]) -> None:
        """``build()`` the node; if it raises (a parameter, a stop signal), the half-built
        node is destroyed first: none is left to rclpy's clean-up."""
        try:
            build()
        except BaseException:
            self.destroy_node()
            raise

    def destroy_node(self) -> None:
        python_logs, self._python_logs = getattr(self, '_python_logs', None), None
        if python_logs is not None:
            python_logs.detach()
        super().destroy_node()

    def override_values(self) -> dict[str, Any]:
        """name -> value of every parameter given to the node (params files, -p).

        Read from rclpy's overrides instead of declared from them automatically: rclpy
        cannot declare a typed parameter from an empty YAML list (it has no type), which
        must become a message naming the parameter, not a traceback. An empty list is [].
        """
        return {name: ([] if param.type_ == Parameter.Type.NOT_SET else param.value)
                for name, param in self._parameter_overrides.items()}

    def declare_read_only(self, name: str, value: Any, description: str) -> None:
        """Declare ``name`` read-only with ``value`` (an empty list: no type, dynamic). One
        already declared stays as it is: a managed node's configure that failed after it
        declared some parameters may be tried again (the values given cannot change)."""
        if self.has_parameter(name):
            return
        if isinstance(value, (list, tuple)) and len(value) == 0:
            self.declare_parameter(name, None, ParameterDescriptor(
                read_only=True, dynamic_typing=True, description=description),
                ignore_override=True)
            return
        self.declare_parameter(name, value, ParameterDescriptor(
            read_only=True, description=description), ignore_override=True)

    def declare_given(self, overrides: Mapping[str, Any], wanted: Callable[[str], bool],
                      description: str) -> dict[str, Any]:
        """Declare every given parameter whose name is ``wanted`` read-only; return them."""
        values = {name: value for name, value in overrides.items() if wanted(name)}
        for name, value in values.items():
            self.declare_read_only(name, value, description)
        return values

    def warn_unknown(self, overrides: Mapping[str, Any], known: Callable[[str], bool]) -> None:
        """Warn about every given parameter that is not ``known``, rclpy's or a QoS override."""
        for name in sorted(overrides):
            if not (known(name) or name.startswith('qos_overrides.')) \
                    and name not in RCLPY_PARAMETERS:
                self.get_logger().warning(f"ignoring unknown parameter '{name}'")

    def declare_table(self, table: Mapping[str, NodeParameter], overrides: Mapping[str, Any],
                      active_types: Sequence[str],
                      defaults: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Declare the parameters of ``table`` read-only, from the overrides or the defaults
        (``defaults``: name -> value instead of the table's default, None: the table's; an
        empty list given for it counts as not given); return them as checked."""
        values = {}
        defaults = defaults or {}
        for name, param in table.items():
            value = overrides.get(name, param.default)
            if defaults.get(name) is not None and (name not in overrides or value is None
                                                   or value == []):
                value = defaults[name]
            value = param.check(value, active_types)
            declared = value.tolist() if isinstance(value, np.ndarray) else value
            self.declare_read_only(name, declared, param.ros_description)
            values[name] = value
        return values

    def check_qos_overrides(self, overrides: Mapping[str, Any]) -> None:
        """Every qos_overrides.* parameter names a policy the node honours, with a valid value.

        rclpy would fail on them with a traceback while it creates the topics (a bogus
        reliability, a negative or huge depth); here each becomes MechanismConfigError.
        """
        for name, value in overrides.items():
            if not name.startswith('qos_overrides.'):
                continue
            policy = name.rsplit('.', 1)[-1]
            if policy in QOS_OVERRIDE_VALUES:
                if value not in QOS_OVERRIDE_VALUES[policy]:
                    raise MechanismConfigError(
                        name, f"must be one of {', '.join(QOS_OVERRIDE_VALUES[policy])}, "
                              f'got {value!r}')
            elif policy == 'depth':
                if isinstance(value, bool) or not isinstance(value, int) \
                        or not 1 <= value <= MAX_QOS_DEPTH:
                    raise MechanismConfigError(
                        name, f'must be an integer from 1 to {MAX_QOS_DEPTH}, got {value!r}')
            else:
                raise MechanismConfigError(
                    name, 'the node honours only history, depth and reliability overrides '
                          '(qos_overrides./<topic>.<publisher|subscription>.<policy>)')

    @contextlib.contextmanager
    def qos_overrides_honoured(self, overrides: Mapping[str, Any]) -> Iterator[None]:
        """Around the creation of the node's topics: a QoS override rclpy cannot apply
        becomes MechanismConfigError; one that matches no topic is warned about."""
        try:
            yield
        except (rclpy.exceptions.ParameterException, RuntimeError, TypeError,
                ValueError) as exc:
            raise MechanismConfigError(
                'qos_overrides', f"cannot be honoured: {' '.join(str(exc).split())}") from None
        for name in sorted(overrides):
            if name.startswith('qos_overrides.') and not self.has_parameter(name):
                self.get_logger().warning(
                    f"ignoring unknown parameter '{name}' (no topic of the node by that "
                    'fully qualified name)')

    def make_use_sim_time_read_only(self) -> bool:
        """use_sim_time is read at start-up like every other parameter, then read-only;
        returns it.

        Switched on at runtime without a /clock publisher it would freeze the node's clock:
        no more /diagnostics, no hold command. rclpy declares it writable; the node
        declares it again read-only, and once built refuses every parameter change with a
        reason (:meth:`refuse_changes`).
        """
        value = self.get_parameter('use_sim_time').value
        if self.describe_parameter('use_sim_time').read_only:     # (a second configure)
            return bool(value)
        self.undeclare_parameter('use_sim_time')
        self.declare_parameter('use_sim_time', bool(value), ParameterDescriptor(
            read_only=True, description='ROS time from /clock (read at start-up only)'),
            ignore_override=True)
        return bool(value)

    def refuse_changes(self) -> None:
        """From now on (the node is built) every parameter change is refused with the
        node's reason. Last in the constructor: declaring a parameter (rclpy declares the
        QoS overrides) runs the on-set callbacks."""
        self.add_on_set_parameters_callback(self._refuse_parameter_changes)
        self._refusing = True

    def allow_changes(self, name: str, check: Callable[[Any], str],
                      apply: Callable[[Any], None]) -> None:
        """Parameter ``name`` (declared, not read-only) may change at run time: a new value
        is refused with the reason ``check(value)`` gives ('' : accepted), and
        ``apply(value)`` is called once it is set."""
        self._changeable[name] = (check, apply)

    def forbid_changes(self, name: str) -> None:
        """``name`` is refused like the rest again (what let it change is gone)."""
        self._changeable.pop(name, None)

    def _set_changeable(self, parameters: Sequence[Parameter]) -> SetParametersResult:
        """Set ``parameters`` at once if each may change and its check accepts the value
        (then each is applied), else refuse them all with the reasons."""
        reason = self._refusal(parameters)
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        result = super().set_parameters_atomically(list(parameters))
        if result.successful:
            for parameter in parameters:
                try:
                    self._changeable[parameter.name][1](parameter.value)
                except Exception as exc:   # noqa: BLE001 (no callback may end the node)
                    cast(Any, self).internal_error(f'applying {parameter.name}', exc)
        return result

    @guarded
    def _refuse_parameter_changes(self, parameters: Sequence[Parameter]) -> SetParametersResult:
        reason = self._refusal(parameters)
        return SetParametersResult(successful=not reason, reason=reason)

    def _refusal(self, parameters: Sequence[Parameter]) -> str:
        """The reason a change of ``parameters`` is refused, naming each ('' when none is):
        one the node let change is refused by its check; another one the node declared is
        read-only; any other name (even '') is not a parameter of the node."""
        changeable = [f'{_shown(p.name)}: {problem}' for p in parameters
                      if p.name in self._changeable and self.has_parameter(p.name)
                      and (problem := self._change_problem(p))]
        declared = [p.name for p in parameters if self.has_parameter(p.name)
                    and p.name not in self._changeable]
        unknown = [p.name for p in parameters if not self.has_parameter(p.name)]
        parts = changeable
        if declared:
            parts.append(f"{', '.join(map(_shown, declared))}: {self._read_only_reason}")
        if unknown:
            parts.append(f"{', '.join(map(_shown, unknown))}: {self._unknown_reason}")
        return '; '.join(parts)

    def _change_problem(self, parameter: Parameter) -> str:
        """Why the check of a changeable parameter refuses its new value ('' : it does not);
        a check that fails is a refusal that says so."""
        try:
            return self._changeable[parameter.name][0](parameter.value)
        except Exception as exc:   # noqa: BLE001 (the parameter service must answer)
            return f'cannot be checked ({type(exc).__name__}: {exc})'

    # rclpy checks a descriptor's read_only before any callback and refuses with its own
    # words ("Trying to set a read-only parameter"), and a name the node does not have with
    # "Invalid access to undeclared parameter(s): []": once the node is built every change
    # is refused here instead, with the node's reason naming the parameter (the descriptors
    # still say read-only)
    def set_parameters(self, parameter_list: list[Parameter]) -> list[SetParametersResult]:
        if self._refusing:
            return [self._set_changeable([p]) for p in parameter_list]
        return super().set_parameters(parameter_list)

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> SetParametersResult:
        if self._refusing:
            return self._set_changeable(parameter_list)
        return super().set_parameters_atomically(parameter_list)


@contextlib.contextmanager
def assembly_warnings_logged() -> Iterator[None]:
    """Around the load of the mechanism in a node: its AssemblyWarnings are not printed as
    Python warnings (the node logs each, as a ROS warning, from ``assembly_warnings``:
    printed both ways, every one came twice)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', AssemblyWarning)
        yield


def _shown(name: str) -> str:
    """A parameter name as a reason shows it: the empty name as ''."""
    return name if name else "''"
