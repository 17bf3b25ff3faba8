"""cog_sim_node's own parameters, written once: name, type, default, bounds and meaning.

``SIM_PARAMETERS`` is the one table, made of the same :class:`~.parameters.NodeParameter`
entries as cog_id_node's (``backend``, ``effort_limits`` and ``diagnostics_period`` are
cog_id_node's own entries, shared); docs/sim_node.md's parameter table is generated from it
(a test compares the two)::

    python -m cog_id_ros.ros.sim_parameters --markdown
    python -m cog_id_ros.ros.sim_parameters --write docs/sim_node.md

The parameter file is cog_id_node's (the mechanism), plus these. cog_id_node's own
parameters (``setpoint_timeout`` ...) may be in it too (one file for both nodes): the
simulator ignores them without a warning. Plain Python: importing this needs no ROS.
"""
import dataclasses
import math
import sys

from . import parameters
from .parameters import NODE_PARAMETERS, OTHER_PARAMETERS, NodeParameter, docs_main

#: what the simulator applies once the effort stream has stopped (effort_timeout_behavior)
EFFORT_TIMEOUT_BEHAVIORS = ('zero', 'hold')

#: the largest |effort| (N m or N) a message may carry by default (max_effort)
DEFAULT_MAX_EFFORT = 1e6


def _table(*params: NodeParameter) -> dict[str, NodeParameter]:
    return {p.name: p for p in params}


#: cog_sim_node's own parameters, in the order they are declared and documented
SIM_PARAMETERS: dict[str, NodeParameter] = _table(
    NodeParameter(
        'time_step', 'double', 0.001, 'number', unit='s', low=1e-6, high=1.0,
        description='s of simulated time per integration step: classic fourth-order '
                    'Runge-Kutta on the independent coordinates, the efforts held over the '
                    'step, every passive joint solved from the closure (docs/simulation.md)'),
    NodeParameter(
        'tolerance', 'double', 1e-7, 'number', low=1e-12, high=1e-2,
        description="the Simulation's error tolerance per step: a step whose error estimate "
                    'is above it is divided (the published step stays `time_step`); '
                    '/diagnostics reports the estimates and the energy drift '
                    '(docs/simulation.md, "Error control and diagnostics")'),
    NodeParameter(
        'real_time_factor', 'double', 1.0, 'number', low=1e-3, high=1000.0,
        special=(0.0, 'as fast as possible'),
        description='simulated seconds per wall-clock second the node keeps to (1: real '
                    'time); 0: as fast as the machine allows. `/diagnostics` says what it '
                    'achieved (`real_time_factor_achieved`)'),
    NodeParameter(
        'publish_clock', 'bool', False, 'bool',
        description='publish `/clock` (rosgraph_msgs/Clock) with the simulated time after '
                    'every step (and at start and reset), so nodes with `use_sim_time` follow '
                    'the simulation'),
    NodeParameter(
        'joint_states_period', 'double', 0.01, 'number', unit='s', low=1e-6, high=3600.0,
        special=(0.0, 'every step'),
        description='s of simulated time between `joint_states` messages, rounded to a '
                    'whole number of steps (at least one); the state at time 0 (start, '
                    'reset) is published too; 0: after every step'),
    NodeParameter(
        'wait_for_effort', 'bool', False, 'bool',
        description='hold the state after start and after `~/reset` until the first '
                    'accepted effort message, like a plant whose brakes release when the '
                    'drive starts: simulated time does not advance, `/clock` stays at 0, '
                    'and the held state (stamped 0) is published again every '
                    f'{0.1:g} s of wall time so that a controller closing the loop on it '
                    'can answer; false: the integration starts at once, with zero effort '
                    'until the first message'),
    NodeParameter(
        'lockstep', 'bool', False, 'bool',
        description='one step per effort message: `joint_states` after every step, then the '
                    'next step only once an effort message was accepted after it, whatever '
                    'the load of the machine (a controller that answers each measured state '
                    'closes the loop in lockstep with the simulation; `real_time_factor` still '
                    'caps the rate, 0: as fast as both go). The safe way to close a simulated '
                    'loop on a busy machine: no measured state times out, no step runs on an '
                    'old command. While it waits, the state is published again (same stamp) '
                    f'every {0.1:g} s of wall time, so that a controller that missed it or '
                    'started later answers. false: steps are paced by `real_time_factor` alone'),
    NodeParameter(
        'effort_timeout', 'double', 0.5, 'number', unit='s', low=1e-6, high=3600.0,
        special=(0.0, 'never'),
        description='s of simulated time after the last accepted effort message at which '
                    'the effort stream counts as stopped: from then on '
                    '`effort_timeout_behavior` applies, until the next accepted message '
                    '(counted in `effort_timeouts`); 0: never (the last efforts act for ever)'),
    NodeParameter(
        'effort_timeout_behavior', 'string', 'zero', 'choice',
        choices=EFFORT_TIMEOUT_BEHAVIORS,
        description='what acts once the effort stream has stopped: `zero` no effort (a '
                    'motor driver whose command watchdog fired: the mechanism falls under '
                    'gravity); `hold` the last accepted efforts, for ever'),
    NodeParameter(
        'max_effort', 'double', DEFAULT_MAX_EFFORT, 'number', unit='N m or N', low=1e-6,
        high=math.inf, special=(math.inf, 'no check'), default_text=f'{DEFAULT_MAX_EFFORT:g}',
        description='N m or N: an effort message with an effort of larger magnitude is '
                    'rejected (`magnitude`), never integrated (1e300 is a corrupt message, '
                    'not a command); `.inf`: no check. Efforts within it are clipped to '
                    '`effort_limits`'),
    dataclasses.replace(
        NODE_PARAMETERS['effort_limits'],
        description='N m or N, one per active joint or one for all: the actuators saturate '
                    'there, as a motor driver does: accepted efforts beyond ±limit act '
                    'clipped to it, each clipped message counted (`effort_clipped`); `.inf`: '
                    "no limit. Not given (or `[]`): the mechanism's effort limits of its "
                    'active joints (`Mechanism.effort_limits`); given, it wins'),
    NODE_PARAMETERS['backend'],
    NODE_PARAMETERS['diagnostics_period'],
    dataclasses.replace(
        NODE_PARAMETERS['warning_period'],
        description='s: each kind of rejected effort message is logged at most once a '
                    'period (with the number left out)'),
)

#: rows of the docs' table for parameters the node does not declare from SIM_PARAMETERS
SIM_OTHER_PARAMETERS = (
    *(row[:4] + (row[4].replace('see QoS below', 'see the QoS after the topic table'),)
      for row in OTHER_PARAMETERS if not row[0].startswith('`use_sim_time`')),
    ('`use_sim_time`', 'bool', '`false`', 'true, false',
     "rclpy's: the node's clock from `/clock` (the stamp of `/diagnostics`); the simulated "
     'time itself never depends on it; read-only like the rest'),
    ("cog_id_node's own (`setpoint_timeout`, `timeout_behavior`, ...)", '', '', '',
     'accepted and ignored, so one parameter file serves both nodes'),
)


def markdown_table() -> str:
    """docs/sim_node.md's parameter table, generated from SIM_PARAMETERS."""
    return parameters.markdown_table(SIM_PARAMETERS, SIM_OTHER_PARAMETERS)


if __name__ == '__main__':
    sys.exit(docs_main('cog_id_ros.ros.sim_parameters', markdown_table(), sys.argv[1:]))
