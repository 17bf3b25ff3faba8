"""``cog_id_node``: the console script (``python -m cog_id_ros.node`` too).

Run::

    cog_id_node --ros-args --params-file config/paper_four_bar_a.yaml
    python -m cog_id_ros.node --ros-args -r __ns:=/arm --params-file config/paper_four_bar_b.yaml

This module imports nothing heavy (the package's ``__init__`` neither): :func:`main` takes
charge of SIGINT and SIGTERM first, then imports numpy, rclpy and the node (about a second
on a busy machine), so that a stop signal at any moment ends the process with exit status 0
and no traceback.
"""
import faulthandler
import os
import signal
import sys
from typing import Any, Callable

#: the console script (setup.py); the node has the same name (node.NODE_NAME)
PROGRAM = 'cog_id_node'

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

USAGE = f"""usage: {PROGRAM} [-h] --ros-args --params-file FILE [-p NAME:=VALUE ...] [-r OLD:=NEW ...]

Closed-link inverse dynamics as a ROS 2 node: JointState setpoints in on joint_setpoint,
actuator efforts out on effort_command and joint_effort (one per accepted setpoint);
the closed pose of every joint on joint_states (every joint_states_decimation-th one);
whole trajectories in on joint_trajectory, out on effort_trajectory; counts and health
on /diagnostics.

The mechanism (mechanism.*, links.*, joints.*; or a URDF: robot_description or
mechanism.urdf_file, with loop_closures.*) and the node's own parameters come from a
ROS 2 parameter file, e.g.

    {PROGRAM} --ros-args --params-file config/paper_four_bar_a.yaml
    {PROGRAM} --ros-args --params-file config/paper_four_bar_b.yaml -r __ns:=/arm
    {PROGRAM} --ros-args --params-file config/crank_rocker_urdf.yaml

A parameter that cannot be honoured ends the node with exit status 2 and one line naming
it. Ctrl-C or SIGTERM stop it (exit status 0).

Documentation: docs/node.md (topics, parameters, diagnostics) and
docs/parameter_file.md (the mechanism parameter file) of the cog_id_ros package.
"""  # noqa: E501 (the usage line as printed)


def main(args: list[str] | None = None) -> int:
    """Start the node and spin until Ctrl-C or SIGTERM (exit status 0): :func:`console_main`
    of this node.

    ``-h``/``--help`` (before ``--ros-args``): the usage, exit status 0; the rest as
    :func:`console_main` says."""
    return console_main(_main, args)


def console_main(body: Callable[[list[str] | None], int], args: list[str] | None) -> int:
    """The main of a node's console script: ``body(args)`` with stop signals in hand
    (``body`` builds and runs the node with :func:`.startup.run`; cog_sim_node's main
    is this too).

    No parameters on the command line, a parameter that cannot be honoured, or a params
    file rcl cannot parse: exit status 2 and one line saying what to do or naming the
    parameter. A stop signal while Python imports and the node starts stops it cleanly
    too (exit status 0; here until rclpy is initialised, then :mod:`.startup`). A thread
    of the node that ended by itself makes the exit status 1.

    The process's main: it returns with SIGINT and SIGTERM ignored. The node is stopped by
    then, and what is left is Python's own exit (a few hundred ms: modules, DDS), during
    which Python has put back the default action of every signal it handled, so a second
    stop signal there killed the process (exit status -15 after a clean stop).
    """
    for signum in STOP_SIGNALS:     # first: Python is still to import numpy, rclpy, ...
        signal.signal(signum, _exit_at_once)
    # SIGUSR1 prints every thread's Python stack to stderr (a node that seems stuck:
    # `kill -USR1 <pid>`, docs/node.md); the process goes on
    faulthandler.register(signal.SIGUSR1, all_threads=True)
    try:
        return body(args)
    finally:
        for signum in STOP_SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


def _exit_at_once(signum: int, frame: object) -> None:
    """A stop signal before rclpy is initialised (Python imports numpy, rclpy, the node,
    or reads the params files): nothing exists that needs cleaning up, so exit status 0 at
    once, without the KeyboardInterrupt traceback of Python's own handler or SIGTERM's
    -15. :class:`.stop_signals.DeferredStop` takes over before rclpy.init."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:   # noqa: BLE001 (e.g. interrupted in a write to it: exit anyway)
            pass
    os._exit(0)


def _main(args: list[str] | None) -> int:
    from .command_line import modes_help
    return node_main(args, PROGRAM, USAGE + modes_help(), lambda: _cog_id_node(args))


def _cog_id_node(args: list[str] | None) -> tuple[str, Callable[..., Any]]:
    """cog_id_node's name and class: the managed node when the command line or a params
    file gives it ``managed: true`` (read before rclpy does: it decides the class)."""
    from .command_line import given_value, node_arguments, node_name
    from .node import NODE_NAME, CogIdNode
    argv = node_arguments(args)
    if given_value(argv, node_name(argv, NODE_NAME), 'managed', False) is True:
        from .managed_node import ManagedCogIdNode  # rclpy.lifecycle: only when asked for
        return NODE_NAME, ManagedCogIdNode
    return NODE_NAME, CogIdNode


def node_main(args: list[str] | None, program: str, usage: str,
              node: Callable[[], tuple[str, Callable[..., Any]]]) -> int:
    """The body of a node's console script: ``--help``, the check that parameters are
    given, then :func:`.startup.run` of the node ``node()`` names and builds
    ((its name, its class); imported there, after the stop signals are in hand)."""
    import functools

    from .command_line import no_parameters_problem, node_arguments, wants_help
    from .startup import cannot_start, run

    argv = node_arguments(args)
    if wants_help(argv):
        print(usage, end='')
        return 0
    problem = no_parameters_problem(argv, program)
    if problem:
        return cannot_start(program, problem)     # the node's name is the program's
    name, node_class = node()
    return run(name, functools.partial(node_class, command_line=argv), args)


#: cog_transmission_node's console script (setup.py; transmission_node.NODE_NAME)
TRANSMISSION_PROGRAM = 'cog_transmission_node'

TRANSMISSION_USAGE = f"""usage: {TRANSMISSION_PROGRAM} [-h] --ros-args --params-file FILE [-p NAME:=VALUE ...] [-r OLD:=NEW ...]

The map between a mechanism's joint space (mechanism.joint_space, e.g. an ankle's pitch and
roll) and its motors (mechanism.active_joints), at message rate: joint_command
(sensor_msgs/JointState in joint space: positions, velocities, efforts) in, actuator_command
(the motors) out; actuator_states (the motors' measured state) in, joint_states (every
joint) out; counts on /diagnostics. The parameters: cog_id_node's parameter file, e.g.

    {TRANSMISSION_PROGRAM} --ros-args --params-file config/parallel_ankle.yaml

A parameter that cannot be honoured ends the node with exit status 2 and one line naming
it. Ctrl-C or SIGTERM stop it (exit status 0). Documentation: docs/node.md.
"""  # noqa: E501 (the usage line as printed)


def transmission_main(args: list[str] | None = None) -> int:
    """cog_transmission_node's console script: as :func:`main`, for the map alone."""
    return console_main(lambda argv: node_main(argv, TRANSMISSION_PROGRAM, TRANSMISSION_USAGE,
                                               _cog_transmission_node), args)


def _cog_transmission_node() -> tuple[str, Callable[..., Any]]:
    from .transmission_node import NODE_NAME, CogTransmissionNode
    return NODE_NAME, CogTransmissionNode


if __name__ == '__main__':
    sys.exit(main())
