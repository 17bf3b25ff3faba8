"""The node's own parameters, written once: name, type, default, bounds and meaning.

``NODE_PARAMETERS`` is the one table. The node declares every entry read-only with its
description and checks every value with :meth:`NodeParameter.check`; docs/node.md's
parameter table is generated from it (a test compares the two)::

    python -m cog_id_ros.ros.parameters --markdown          # print the table
    python -m cog_id_ros.ros.parameters --write docs/node.md  # refresh it in the docs

``OTHER_PARAMETERS`` lists what the table of the docs shows besides the node's own (the
mechanism, ``use_sim_time``, QoS overrides), declared by rclpy or from the mechanism.
Plain Python: importing this needs no ROS.
"""
import argparse
import dataclasses
import math
import sys
from typing import Any, Callable, NoReturn, Sequence

from ..core import MechanismConfigError
from ..core.kinematics import joints
from ..core.native.kernels import BACKENDS
from ..offline.jumps import DEFAULT_MAX_STEP

#: parameter prefixes that describe the mechanism (handed to Mechanism.from_parameters):
#: the native form (links.*, joints.*) and the URDF form (loop_closures.*; docs/urdf.md)
MECHANISM_PREFIXES = ('mechanism.', 'links.', 'joints.', 'loop_closures.')
#: whole parameter names that describe the mechanism: the URDF as a string (ROS's name)
MECHANISM_NAMES = ('robot_description',)


def is_mechanism_parameter(name: str) -> bool:
    """Whether the node hands parameter ``name`` to Mechanism.from_parameters."""
    return name in MECHANISM_NAMES or name.startswith(MECHANISM_PREFIXES)


TIMEOUT_BEHAVIORS = ('hold', 'zero', 'none')

#: control_mode: feed-forward (setpoints alone) and the feedback modes (measured states too)
CONTROL_MODES = ('feedforward', 'computed_torque', 'pd_feedforward', 'gravity_compensation')
#: command_space: what setpoints, trajectories and measured states name (efforts: the motors)
COMMAND_SPACES = ('actuator', 'joint')
#: base_acceleration (floating base): what the base's acceleration is taken to be
BASE_ACCELERATIONS = ('estimated', 'zero')
#: default largest move of an active joint between two measured states (rad, m): 200 rad/s
#: or 20 m/s at 1 kHz, far beyond a physical robot's, far below an encoder glitch's turn
MEASUREMENT_MAX_STEP = {'rad': 0.2, 'm': 0.02}
#: default largest measured speed of an active joint (rad/s, m/s): the rate that
#: MEASUREMENT_MAX_STEP allows at 1 kHz
MEASUREMENT_MAX_VELOCITY = {'rad': 200.0, 'm': 20.0}

#: QoS overrides the node honours: the policies and their values (depth: 1..MAX_QOS_DEPTH)
QOS_OVERRIDE_VALUES = {
    'history': ('keep_last', 'keep_all', 'system_default'),
    'reliability': ('reliable', 'best_effort', 'system_default'),
}
MAX_QOS_DEPTH = 10_000


@dataclasses.dataclass(frozen=True)
class NodeParameter:
    """One parameter of the node.

    ``kind`` says how a value is checked: ``'number'`` (a float from ``low`` to ``high``,
    or ``special``), ``'integer'`` (an int from ``low`` to ``high``), ``'choice'`` (one of
    ``choices``), ``'bool'``, ``'per_joint'`` (one positive float per active joint or one
    for all; ``None`` or an empty list: ``per_joint_default``), ``'gains'`` (one finite
    float >= 0 per active joint or one for all; ``None`` or an empty list: ``default``) or
    ``'names'`` (a list of distinct strings; ``None``: not given).
    ``description`` is the meaning (markdown: the docs' table; the node's
    ParameterDescriptor without backticks);
    ``default_text`` the docs' default column where ``default`` alone does not say it.
    ``runtime``: the parameter may change while the node runs (declared and checked by the
    part of the node that uses it, not read-only); every other one is read-only.
    """

    name: str
    type: str
    default: Any
    kind: str
    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    special: tuple[float, str] | None = None   # (value, what it means) allowed besides bounds
    choices: tuple[str, ...] = ()
    per_joint_default: Callable[[str], float] | None = None   # joint type -> default
    what: str = ''                                             # 'limit', 'step' in messages
    default_text: str = ''
    runtime: bool = False

    def check(self, value: Any, active_types: Sequence[str]) -> Any:
        """``value`` as the node uses it (per_joint: a numpy array); MechanismConfigError
        naming the parameter when it cannot be honoured."""
        return _CHECKS[self.kind](self, value, list(active_types))

    def fail(self, message: str) -> NoReturn:
        raise MechanismConfigError(self.name, message)

    @property
    def ros_description(self) -> str:
        """The description as the node declares it (``ros2 param describe``)."""
        return self.description.replace('`', '')

    def bounds_text(self) -> str:
        """The accepted values, for the docs' table."""
        if self.kind == 'choice':
            return ', '.join(f'`{c}`' for c in self.choices)
        if self.kind == 'bool':
            return 'true, false'
        if self.kind == 'per_joint':
            return '> 0 each (`.inf`: none); one per active joint or one for all'
        if self.kind == 'gains':
            return '≥ 0 each, finite; one per active joint or one for all'
        if self.kind == 'names':
            return 'names of `mechanism.contacts`, each once (`[]`: none)'
        if self.kind == 'integer':
            text = f'{self.low} to {self.high}'
        elif self.high == math.inf:
            text = f'≥ {self.low:g}'
        else:
            text = f'{self.low:g} to {self.high:g}'
        if self.special is not None:
            text = f'{_number(self.special[0])} ({self.special[1]}), or {text}'
        return text

    def default_cell(self) -> str:
        if self.default_text:
            return self.default_text
        if isinstance(self.default, bool):
            return f'`{str(self.default).lower()}`'
        if isinstance(self.default, str):
            return f'`{self.default}`'
        return repr(self.default)


def _plain(x: float) -> str:
    return '.inf' if x == math.inf else f'{x:g}'


def _number(x: float) -> str:
    return '`.inf`' if x == math.inf else f'{x:g}'


def _as_number(param: NodeParameter, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        param.fail(f'must be a number, got {v!r}')
    return float(v)


def _check_number(param: NodeParameter, value: Any, active_types: list[str]) -> float:
    value = _as_number(param, value)
    if param.special is not None and value == param.special[0]:
        return value
    if not param.low <= value <= param.high:
        extra = ''
        if param.special is not None:
            extra = f' (or {_plain(param.special[0])}: {param.special[1]})'
        unit = f' {param.unit}' if param.unit else ''
        param.fail(f'must be from {param.low:g} to {param.high:g}{unit}{extra}, '
                   f'got {value!r}')
    return value


def _check_integer(param: NodeParameter, value: Any, active_types: list[str]) -> int:
    low, high = param.low, param.high       # (an integer parameter has both bounds)
    if isinstance(value, bool) or not isinstance(value, int) or \
            not low <= value <= high:  # type: ignore[operator]
        param.fail(f'must be an integer from {low} to {high}, got {value!r}')
    return value


def _check_choice(param: NodeParameter, value: Any, active_types: list[str]) -> str:
    if value not in param.choices:
        param.fail(f"must be one of {', '.join(param.choices)}, got {value!r}")
    return value


def _check_bool(param: NodeParameter, value: Any, active_types: list[str]) -> bool:
    if not isinstance(value, bool):
        param.fail(f'must be true or false, got {value!r}')
    return value


def _check_per_joint(param: NodeParameter, value: Any, active_types: list[str]) -> Any:
    import numpy as np
    n_act = len(active_types)
    if value is None or (isinstance(value, (list, tuple)) and len(value) == 0):
        # (a per_joint parameter has its per_joint_default)
        return np.array([param.per_joint_default(t)  # type: ignore[misc]
                         for t in active_types], dtype=float)
    if not isinstance(value, (list, tuple)):
        value = [value]
    limits = [_as_number(param, v) for v in value]
    if len(limits) == 1:
        limits = limits * n_act
    if len(limits) != n_act:
        param.fail(f'needs one {param.what} per active joint ({n_act}) or one for all, '
                   f'got {len(limits)}')
    if not all(lim > 0 for lim in limits):
        param.fail(f'every {param.what} must be > 0 (.inf for none), got {limits}')
    return np.array(limits)


def _check_gains(param: NodeParameter, value: Any, active_types: list[str]) -> Any:
    import numpy as np
    n_act = len(active_types)
    if value is None or (isinstance(value, (list, tuple)) and len(value) == 0):
        value = param.default
    if not isinstance(value, (list, tuple)):
        value = [value]
    gains = [_as_number(param, v) for v in value]
    if len(gains) == 1:
        gains = gains * n_act
    if len(gains) != n_act:
        param.fail(f'needs one gain per active joint ({n_act}) or one for all, got {len(gains)}')
    if not all(math.isfinite(g) and g >= 0.0 for g in gains):
        param.fail(f'every gain must be finite and >= 0 {param.unit}, got {gains}')
    return np.array(gains)


def _check_names(param: NodeParameter, value: Any, active_types: list[str]) -> Any:
    if value is None:
        return None
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple)) or \
            not all(isinstance(v, str) for v in value):
        param.fail(f'must be a list of names, got {value!r}')
    if len(set(value)) != len(value):
        param.fail(f'names one twice: {list(value)}')
    return list(value)


_CHECKS = {'number': _check_number, 'integer': _check_integer, 'choice': _check_choice,
           'bool': _check_bool, 'per_joint': _check_per_joint, 'gains': _check_gains,
           'names': _check_names}


def by_unit(values: dict[str, float], per: str = '') -> dict[str, Any]:
    """``per_joint_default`` and ``default_text`` of a per-joint parameter whose default
    follows the joint's unit: ``values`` unit ('rad', 'm') -> value; ``per``: '/s' for a
    rate. (An active joint's type is a registered kind, with a unit.)"""
    def default(joint_type: str) -> float:
        return values[joints.kind(joint_type).unit]  # type: ignore[union-attr, index]
    return {'per_joint_default': default,
            'default_text': f'{values["rad"]!r} rad{per} revolute, '
                            f'{values["m"]!r} m{per} prismatic'}


def _table(*params: NodeParameter) -> dict[str, NodeParameter]:
    return {p.name: p for p in params}


#: the node's own parameters, in the order they are declared and documented
NODE_PARAMETERS: dict[str, NodeParameter] = _table(
    NodeParameter(
        'effort_limits', 'double[]', None, 'per_joint', what='limit',
        per_joint_default=lambda joint_type: math.inf,
        default_text="the mechanism's (`joints.<j>.effort`, URDF `<limit effort>`), else "
                     '`.inf`',
        description='N m or N, one per active joint or one for all: efforts are clipped to '
                    '±limit and every clipping is counted in diagnostics (`.inf`: no limit). '
                    "Not given (or `[]`): the mechanism's effort limits of its active joints "
                    '(`Mechanism.effort_limits`); given, it wins'),
    NodeParameter(
        'setpoint_timeout', 'double', 0.5, 'number', unit='s', low=0.005, high=3600.0,
        special=(0.0, 'no timeout'),
        description='s without a setpoint after which the stream counts as stopped: '
                    '`timeout_behavior` applies once, the estimator restarts and the next '
                    'setpoint may carry any stamp (and is not a `jump`); 0 disables it (then '
                    'stamps must increase for the whole life of the node, see '
                    '`max_stamp_rejections`: to publish nothing at a stop, prefer '
                    '`timeout_behavior: none`)'),
    NodeParameter(
        'backend', 'string', 'auto', 'choice', choices=BACKENDS,
        description='who computes the kernels (docs/how_it_computes.md): `auto` compiled C '
                    'where a C compiler or a cached library is there, else Python; `native` '
                    'compiled C or refuse to start; `python` never compile; `reference` the '
                    'plain lane code (slow: for checking)'),
    NodeParameter(
        'timeout_behavior', 'string', 'hold', 'choice', choices=TIMEOUT_BEHAVIORS,
        description='what is published on `effort_command` when the stream stops, once: '
                    '`hold` the gravity-holding efforts of the last valid pose (zero velocity '
                    'and acceleration, clipped to `effort_limits`); `zero` zeros; `none` '
                    'nothing'),
    NodeParameter(
        'max_setpoint_interval', 'double', 0.1, 'number', unit='s', low=1e-4, high=3600.0,
        description='s: two setpoints whose stamps are farther apart are not differentiated '
                    'across the gap: the estimator restarts'),
    NodeParameter(
        'estimator_window', 'int', 4, 'integer', low=3, high=8,
        description='setpoints in the local polynomial of the velocity and acceleration '
                    'estimator (3: least noise, 4: no lag to O(h²); see "Setpoints: the '
                    'acceleration estimator" below)'),
    NodeParameter(
        'unwrap_angles', 'bool', True, 'bool',
        description='revolute active joints: within a stream, a setpoint is taken as the 2π '
                    'equivalent nearest the previous accepted one, so an encoder of a '
                    'continuous joint that wraps from +π to −π is not a jump of 2π (which the '
                    'estimator would turn into an acceleration of ~2π/h², 1e5 N m and more). '
                    '`joint_effort` carries the positions as received. The first setpoint of '
                    'a stream is taken as received. false: positions are used as received'),
    NodeParameter(
        'max_setpoint_step', 'double[]', None, 'per_joint', what='step',
        **by_unit(DEFAULT_MAX_STEP),
        description='rad or m: within a stream, a setpoint that moves an active joint farther '
                    'than this from the previous accepted one (after unwrapping) is rejected '
                    '(`jump`) and the estimator restarts, so the next setpoint starts a new '
                    'stream at rest (acceleration 0); `.inf`: no check. Not checked for the '
                    'first setpoint of a stream (after a timeout, a restart or a gap longer '
                    'than `max_setpoint_interval`)'),
    NodeParameter(
        'max_stamp_lead', 'double', 1.0, 'number', unit='s', low=0.0, high=math.inf,
        special=(math.inf, 'no check'),
        description="s: a setpoint stamped farther than this ahead of the node's clock is "
                    'rejected (`stamp`): one far-future stamp (a source whose clock is wrong) '
                    'would otherwise be served and make every later setpoint come "before" '
                    "it; `.inf`: no check (nor while the node's clock reads 0: "
                    '`use_sim_time` before the first `/clock`)'),
    NodeParameter(
        'max_stamp_rejections', 'int', 5, 'integer', low=0, high=1000,
        description='when this many setpoints in a row are rejected because their stamp does '
                    "not come after the previous accepted one (the source's clock went back, "
                    'or restarted), the estimator restarts and that setpoint starts a new '
                    'stream (counted in `stamp_restarts`; 4 setpoints lost with the default); '
                    '0: never (the stream then waits for `setpoint_timeout`)'),
    NodeParameter(
        'max_trajectory_points', 'int', 100_000, 'integer', low=1, high=10_000_000,
        description='a `joint_trajectory` with more points is rejected (`too_long`) from its '
                    'header alone, before it costs anything. 100,000 points take about 4-8 s '
                    'to solve on the reference VM'),
    NodeParameter(
        'trajectory_timeout', 'double', 10.0, 'number', unit='s', low=0.1, high=3600.0,
        description='s the trajectory process may take to answer a `joint_trajectory`, plus '
                    '1 ms per point (10-15x what solving takes), from the moment the node '
                    'starts writing it to the process; a process that does not take it and '
                    'answer in time (stopped, stuck) is killed and replaced, and the '
                    'trajectory is rejected (`solver`) with the reason'),
    NodeParameter(
        'max_setpoint_age', 'double', 0.5, 'number', unit='s', low=1e-3, high=3600.0,
        special=(0.0, 'no check'),
        description='s: a setpoint taken more than this after it was published (by the '
                    "publisher's clock, from DDS's source timestamp: e.g. after the node was "
                    'stopped and continued, or fell behind) is rejected (`stale`), never '
                    'served late; across machines their clocks must agree to well within it '
                    '(0: no check)'),
    NodeParameter(
        'joint_states_decimation', 'int', 10, 'integer', low=0, high=1_000_000,
        default_text='10 (`feedforward`), 0 in the feedback modes',
        description='`joint_states` carries the closed pose of every Nth served setpoint '
                    '(the first one of the node included); the default 10 is 100 Hz at a 1 kHz '
                    'setpoint rate, enough for robot_state_publisher and RViz; 1: every one; '
                    '0: no `joint_states` topic. Published after the command, so it never '
                    'delays it. In the feedback modes it is off unless given (the robot '
                    'publishes that name)'),
    NodeParameter(
        'diagnostics_period', 'double', 1.0, 'number', unit='s', low=0.05, high=3600.0,
        description='s between `/diagnostics` messages'),
    NodeParameter(
        'warning_period', 'double', 1.0, 'number', unit='s', low=1e-3, high=3600.0,
        description='s: each kind of rejected setpoint is logged at most once a period (with '
                    'the number left out)'),
    NodeParameter(
        'control_mode', 'string', 'feedforward', 'choice', choices=CONTROL_MODES,
        description='what a command is computed from (docs/control.md): `feedforward` the '
                    "setpoint's motion alone, one command per setpoint; `computed_torque`, "
                    '`pd_feedforward`, `gravity_compensation` the measured state on '
                    '`measured_joint_states` too, one command per measured state with the '
                    'latest setpoint in force. Read-only: switching modes needs a restart'),
    NodeParameter(
        'command_space', 'string', 'actuator', 'choice', choices=COMMAND_SPACES,
        description='what setpoints, trajectories and measured states name: `actuator` the '
                    'motors (`mechanism.active_joints`); `joint` the joints of '
                    '`mechanism.joint_space` (e.g. ankle pitch and roll), carried to the '
                    "motors exactly (`Transmission`); efforts are always the motors'. With "
                    '`joint`, the per-joint parameters other than `effort_limits` are per '
                    'joint of the joint space. A mechanism without `mechanism.joint_space` is '
                    'refused'),
    NodeParameter(
        'kp', 'double[]', 100.0, 'gains', unit='1/s²',
        description='`computed_torque`: position gain on the acceleration, '
                    '`qdd_d + kd (qd_d - qd_m) + kp (q_d - q_m)`, one per active joint or one '
                    'for all (the error of each joint then obeys e¨ + kd e˙ + kp e = 0; '
                    'underdamped below kd = 2 √kp: a warning at start-up)'),
    NodeParameter(
        'kd', 'double[]', 20.0, 'gains', unit='1/s',
        description='`computed_torque`: velocity gain on the acceleration (see `kp`)'),
    NodeParameter(
        'pd_kp', 'double[]', 0.0, 'gains', unit='N m/rad or N/m',
        description='`pd_feedforward`: stiffness added to the feed-forward efforts, '
                    '`pd_kp (q_d - q_m) + pd_kd (qd_d - qd_m)`, one per active joint or one '
                    'for all (0 and `pd_kd` 0: feed-forward at the measured rate, a warning at '
                    'start-up)'),
    NodeParameter(
        'pd_kd', 'double[]', 0.0, 'gains', unit='N m s/rad or N s/m',
        description='`pd_feedforward`: damping added to the feed-forward efforts (see '
                    '`pd_kp`; a warning at start-up where a joint would be underdamped, '
                    'pd_kd < 2 √(pd_kp H_jj) at `initial_positions`)'),
    NodeParameter(
        'measurement_timeout', 'double', 0.1, 'number', unit='s', low=1e-3, high=3600.0,
        description='feedback modes: s without an accepted measured state (none arrived, or '
                    'each was rejected) after which `timeout_behavior` applies, once, at the '
                    'last measured pose; a measured state published longer ago than this '
                    '(by its time of publication and receipt, not its header stamp: the plant '
                    'may stamp sim time) is rejected (`stale`)'),
    NodeParameter(
        'max_measurement_step', 'double[]', None, 'per_joint', what='step',
        **by_unit(MEASUREMENT_MAX_STEP),
        description='feedback modes, rad or m: a measured state that moves an active joint '
                    'farther than this from the last accepted one (after unwrapping) is '
                    'rejected (`jump`), never commanded from; after `measurement_timeout` '
                    'without an accepted one the next starts a new stream (`.inf`: no check)'),
    NodeParameter(
        'max_measured_velocity', 'double[]', None, 'per_joint', what='velocity',
        **by_unit(MEASUREMENT_MAX_VELOCITY, '/s'),
        description='feedback modes, rad/s or m/s: a measured state whose velocity of an '
                    'active joint is larger than this in magnitude is rejected (`velocity`), '
                    'never commanded from: a corrupt velocity would reach the motors through '
                    'kd and the velocity terms (`.inf`: no check)'),
    NodeParameter(
        'max_measured_publishers', 'int', 1, 'integer', low=0, high=1_000_000,
        description='feedback modes: measured states are commanded from only while at most '
                    'this many publishers feed `measured_joint_states`, as the node sees them '
                    '(`measured_state_publishers` in `/diagnostics`); with more, every measured '
                    'state is rejected (`publishers`), `/diagnostics` says ERROR and after '
                    '`measurement_timeout` `timeout_behavior` applies: a stale recording or a '
                    'second plant never takes over the controller. 0: any number'),
    NodeParameter(
        'inactive_period', 'double', 0.1, 'number', unit='s', low=1e-3, high=3600.0,
        special=(0.0, 'once'),
        description='`managed:=true`: while the node is inactive (after `deactivate`) the '
                    "command of `timeout_behavior` is published again every this many s, as a "
                    'drive holds with its brakes: a plant that zeroes its efforts when commands '
                    "stop (cog_sim_node's `effort_timeout`) is still held; `zero` is said in "
                    'the log as the plant falling. 0: once, at deactivate, then nothing'),
    NodeParameter(
        'managed', 'bool', False, 'bool',
        description='a lifecycle node (`~/change_state`, `~/get_state`): it starts '
                    'unconfigured; `configure` loads the mechanism and compiles its kernels, '
                    '`activate` opens the stream (nothing is published before), `deactivate` '
                    "publishes `timeout_behavior`'s command, again every `inactive_period`, "
                    '`cleanup` releases what configure made, `shutdown` ends the process. '
                    'false: the node serves from the start'),
    NodeParameter(
        'base_state_timeout', 'double', 0.1, 'number', unit='s', low=1e-3, high=3600.0,
        description='floating base (`mechanism.floating_base: true`): a setpoint is served '
                    'with the latest `base_state` only while that was received less than this '
                    'ago (else rejected, `base_state`); a `base_state` published longer ago '
                    'than this is rejected (`stale`), and after this long without one the '
                    "base acceleration's estimator starts again"),
    NodeParameter(
        'base_acceleration', 'string', 'estimated', 'choice', choices=BASE_ACCELERATIONS,
        description='floating base: the base acceleration `whole_body_torques` is given '
                    '(`nav_msgs/Odometry` carries none): `estimated` the time derivative of '
                    "`base_state`'s twist, by the setpoints' estimator (`estimator_window` "
                    'twists, restarted across a gap longer than `max_setpoint_interval`: 0 '
                    'for the first base state of a stream); `zero` always 0'),
    NodeParameter(
        'active_contacts', 'string[]', None, 'names', runtime=True,
        default_text='every contact of `mechanism.contacts`',
        description='floating base: the contacts touching the world now, whose wrenches '
                    'balance the motion (published on `contact_wrenches/<name>`); the only '
                    'parameter that may change while the node runs (a parameter set: an '
                    'unknown name is refused with the reason, the contacts stay as they '
                    'were); `[]`: none (the robot in flight: everything left in '
                    '`base_wrench`). A mechanism without a floating base has no contacts'),
)

#: rows of the docs' table for parameters the node does not declare from NODE_PARAMETERS:
#: (name, type, default, accepted values, meaning)
OTHER_PARAMETERS = (
    ('`mechanism.*`, `links.*`, `joints.*`', '', '', '',
     'the mechanism (docs/parameter_file.md)'),
    ('`robot_description`, `mechanism.urdf_file`, `mechanism.loop_closures`, '
     '`loop_closures.*`, `mechanism.loop_closure_file`, `mechanism.initial_positions.<joint>`',
     '', '', '',
     "the mechanism in the URDF form instead (docs/urdf.md): the URDF as a string (ROS's "
     'standard parameter) or a file (relative to the params file that gives it), the joints '
     'that close its loops, or the loop list published with it for Pinocchio (a file, '
     'relative to the params file that gives it), and the assembly mode by joint name'),
    ('`use_sim_time`', 'bool', '`false`', 'true, false',
     "rclpy's: the node's clock from `/clock` (stamps of zero, `max_stamp_lead`, the stamp "
     'of `/diagnostics`); read-only like the rest'),
    ('`qos_overrides./<topic>.<publisher|subscription>.<history|depth|reliability>`', '', '',
     f"history {', '.join(f'`{v}`' for v in QOS_OVERRIDE_VALUES['history'])}; reliability "
     f"{', '.join(f'`{v}`' for v in QOS_OVERRIDE_VALUES['reliability'])}; depth 1 to "
     f'{MAX_QOS_DEPTH}',
     "rclpy's QoS overrides (see QoS below); anything else: exit status 2, one line"),
)


def markdown_table(table: dict[str, NodeParameter] | None = None,
                   others: Sequence[tuple[str, ...]] = OTHER_PARAMETERS) -> str:
    """docs/node.md's parameter table, generated from ``table`` (NODE_PARAMETERS) and
    ``others`` (OTHER_PARAMETERS); cog_sim_node's (docs/sim_node.md) from its own."""
    rows = ['| name | type | default | accepted values | meaning |', '|---|---|---|---|---|']
    for p in (NODE_PARAMETERS if table is None else table).values():
        unit = f', {p.unit}' if p.unit else ''
        rows.append(f'| `{p.name}` | {p.type}{unit} | {p.default_cell()} | {p.bounds_text()} '
                    f'| {p.description} |')
    for name, kind, default, accepted, meaning in others:
        rows.append(f'| {name} | {kind} | {default} | {accepted} | {meaning} |'
                    .replace('<publisher|subscription>', '<publisher\\|subscription>')
                    .replace('<history|depth|reliability>', '<history\\|depth\\|reliability>'))
    return '\n'.join(rows) + '\n'


def replace_generated(text: str, name: str, table: str) -> str:
    """``text`` with the block between the markers of ``name`` replaced by ``table``."""
    begin = f'<!-- generated: {name} (do not edit; see its --write) -->\n'
    end = f'<!-- end of generated: {name} -->'
    if begin not in text or end not in text:
        raise ValueError(f'the markers of {name} are missing')
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return head + begin + table + end + tail


def generated_block(text: str, name: str) -> str:
    """The block between the markers of ``name`` in ``text`` (as replace_generated writes)."""
    begin = f'<!-- generated: {name} (do not edit; see its --write) -->\n'
    end = f'<!-- end of generated: {name} -->'
    return text.split(begin, 1)[1].split(end, 1)[0]


def docs_main(name: str, table: str, argv: Sequence[str] | None) -> int:
    """``--markdown``: print ``table``; ``--write FILE``: refresh it in FILE (docs/node.md)."""
    parser = argparse.ArgumentParser(prog=f'python -m {name}',
                                     description=f'The table of {name} as markdown.')
    parser.add_argument('--markdown', action='store_true', help='print the table')
    parser.add_argument('--write', metavar='FILE', help='replace the table in FILE')
    args = parser.parse_args(argv)
    if args.write:
        with open(args.write, encoding='utf-8') as stream:
            text = stream.read()
        with open(args.write, 'w', encoding='utf-8') as stream:
            stream.write(replace_generated(text, name, table))
    if args.markdown or not args.write:
        sys.stdout.write(table)
    return 0


if __name__ == '__main__':
    sys.exit(docs_main('cog_id_ros.ros.parameters', markdown_table(), sys.argv[1:]))
