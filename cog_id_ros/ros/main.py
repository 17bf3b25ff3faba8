"""``cog_id_node``: the console script (``python -m cog_id_ros.node`` too).

Run::

    cog_id_node --ros-args --params-file config/paper_four_bar_a.yaml
    python -m cog_id_ros.node --ros-args -r __ns:=/arm --params-file config/paper_four_bar_b.yaml
"""
import functools
import sys

from .command_line import no_parameters_problem, node_arguments, wants_help
from .node import NODE_NAME, CogIdNode
from .startup import cannot_start, run

USAGE = f"""usage: {NODE_NAME} [-h] --ros-args --params-file FILE [-p NAME:=VALUE ...] [-r OLD:=NEW ...]

Closed-link inverse dynamics as a ROS 2 node: JointState setpoints in on joint_setpoint,
actuator efforts out on effort_command and joint_effort (one per accepted setpoint);
the closed pose of every joint on joint_states (every joint_states_decimation-th one);
whole trajectories in on joint_trajectory, out on effort_trajectory; counts and health
on /diagnostics.

The mechanism (mechanism.*, links.*, joints.*; or a URDF: robot_description or
mechanism.urdf_file, with loop_closures.*) and the node's own parameters come from a
ROS 2 parameter file, e.g.

    {NODE_NAME} --ros-args --params-file config/paper_four_bar_a.yaml
    {NODE_NAME} --ros-args --params-file config/paper_four_bar_b.yaml -r __ns:=/arm
    {NODE_NAME} --ros-args --params-file config/crank_rocker_urdf.yaml

A parameter that cannot be honoured ends the node with exit status 2 and one line naming
it. Ctrl-C or SIGTERM stop it (exit status 0).

Documentation: docs/node.md (topics, parameters, diagnostics) and README.md (the
mechanism parameter file) of the cog_id_ros package.
"""  # noqa: E501 (the usage line as printed)


def main(args: list[str] | None = None) -> int:
    """Start the node and spin until Ctrl-C or SIGTERM (exit status 0).

    ``-h``/``--help`` (before ``--ros-args``): the usage, exit status 0. A parameter that
    cannot be honoured, or a params file rcl cannot parse: exit status 2 and one line
    naming it. A stop signal during start-up stops the node cleanly too (exit status 0;
    :mod:`.startup`). A thread of the node that ended by itself makes the exit status 1.
    """
    argv = node_arguments(args)
    if wants_help(argv):
        print(USAGE, end='')
        return 0
    problem = no_parameters_problem(argv, NODE_NAME)
    if problem:
        return cannot_start(NODE_NAME, problem)
    return run(NODE_NAME, functools.partial(CogIdNode, command_line=argv), args)


if __name__ == '__main__':
    sys.exit(main())
