"""``cog_sim_node``: the console script of the simulator (``python -m cog_id_ros.ros.sim_main``
too).

Run::

    cog_sim_node --ros-args --params-file config/paper_four_bar_a.yaml
    cog_sim_node --ros-args --params-file config/paper_four_bar_a.yaml -p real_time_factor:=0.0

Like ``cog_id_node``'s main (:mod:`.main`, whose :func:`.main.console_main` and
:func:`.main.node_main` this is): nothing heavy imported before the stop signals are in
hand, exit status 0 after Ctrl-C or SIGTERM, 2 with one line for a parameter that cannot be
honoured, 1 when the integration thread ended by itself.
"""
import sys
from typing import Any, Callable

from .main import console_main, node_main

#: the console script (setup.py); the node has the same name (sim_node.NODE_NAME)
PROGRAM = 'cog_sim_node'

USAGE = f"""usage: {PROGRAM} [-h] --ros-args --params-file FILE [-p NAME:=VALUE ...] [-r OLD:=NEW ...]

The closed-link mechanism of a cog_id_node parameter file, simulated: efforts in on
effort_command (std_msgs/Float64MultiArray, active_joints order: what cog_id_node
publishes) or joint_effort_command (sensor_msgs/JointState, by name); every joint's
position, velocity and effort out on joint_states, stamped with the simulated time;
/clock with publish_clock:=true; ~/reset (std_srvs/Trigger); health on /diagnostics.

The parameters: cog_id_node's parameter file (the mechanism), plus time_step (0.001 s),
real_time_factor (1; 0: as fast as possible), publish_clock (false), joint_states_period
(0.01 s), wait_for_effort (false: true holds the state until the first effort),
effort_timeout (0.5 s of simulated time) and effort_timeout_behavior (zero or
hold), max_effort (1e6), effort_limits, e.g.

    {PROGRAM} --ros-args --params-file config/paper_four_bar_a.yaml
    {PROGRAM} --ros-args --params-file config/paper_four_bar_a.yaml -p publish_clock:=true

A parameter that cannot be honoured ends the node with exit status 2 and one line naming
it. Ctrl-C or SIGTERM stop it (exit status 0).

Documentation: docs/sim_node.md (topics, parameters, diagnostics) of the cog_id_ros
package.
"""  # noqa: E501 (the usage line as printed)


def main(args: list[str] | None = None) -> int:
    """Start the simulator and spin until Ctrl-C or SIGTERM (exit status 0); ``-h``: the
    usage."""
    return console_main(_main, args)


def _main(args: list[str] | None) -> int:
    return node_main(args, PROGRAM, USAGE, _cog_sim_node)


def _cog_sim_node() -> tuple[str, Callable[..., Any]]:
    from .sim_node import NODE_NAME, CogSimNode
    return NODE_NAME, CogSimNode


if __name__ == '__main__':
    sys.exit(main())
