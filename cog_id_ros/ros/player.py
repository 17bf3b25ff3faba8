"""cog_id_player: play a CSV trajectory into ``joint_setpoint``, record ``joint_effort``.

    cog_id_player --input motion.csv [--rate 1000] [--output efforts.csv] \
        [--ros-args -r __ns:=/arm]

The CSV is the one of the offline tool ``cog_id_torques``: a ``time`` column (seconds,
strictly increasing) and ``<joint>.position`` per joint, optionally ``<joint>.velocity``
(other columns are ignored). Every ``<joint>.position`` column becomes a joint of the
setpoints, so the player works with any mechanism.

Timing: setpoint ``i`` is published at ``start + (time[i] - time[0])`` on the wall clock and
stamped with exactly that time, so the stamps say when each setpoint is meant for and the
node's acceleration estimator sees the trajectory's own time steps, whatever the jitter of
the publishing loop. ``--rate`` resamples the trajectory first (cubic spline through the
positions, and through the velocities when the file has them).

``--output`` records ``joint_effort`` (matched to the setpoints by stamp) to a CSV of the
offline tool's output format: ``time`` and ``<joint>.effort``, an empty cell where no
effort came back. The recording is done by a process of its own
(:class:`cog_id_ros.ros.recorder.Recorder`); the first setpoint goes alone until its effort
is recorded (proof that the node and the recorder are connected both ways), the others
follow on their schedule, stamped as above. At the end the setpoints sent, the node's
counters (its ``/diagnostics``) and the efforts recorded are compared: when any setpoint
went unanswered or unrecorded the CSV is still written and a line says where they went
(``node: ...`` or ``recorder: ...``), exit status 3.

Exit status: 0 every setpoint answered (and recorded, with ``--output``); 1 no node, or
no effort at all; 2 bad arguments or CSV; 3 setpoints unanswered or unrecorded (without
``--output``: not acknowledged by the node); 4 ``--output`` cannot be written; 130 Ctrl-C.
"""
import argparse
import sys
import time
from typing import Any, Iterable

import numpy as np
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from ..offline import trajectory_io
from . import recorder as recording
from . import stop_signals
from .conversions import NANOSECONDS
from .topics import control_qos

#: s to wait for the node's first /diagnostics report before a recorded run (three of its
#: default diagnostics_period); without one, losses are counted but not placed
REPORT_WAIT = 3.0
#: exit status when setpoints went unanswered or unrecorded
LOST = 3

#: a deep reliable subscription for probes that record what the node sends (the tests')
RECORDER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000,
                          reliability=ReliabilityPolicy.RELIABLE)


class Player(Node):
    """Publishes setpoints on a schedule.

    ``joints``: names of the setpoints' joints; ``topic``: where setpoints go (relative
    names follow the node's namespace); ``depth``: keep-last depth of the setpoint
    publisher (default the node's, CONTROL_QOS_DEPTH). A reliable writer can resend only
    what its history still holds: give the length of a recorded run, and a setpoint the
    node was slow to acknowledge is resent instead of lost (what the node then drops from
    its own queue it counts as ``setpoints_lost``). The efforts are recorded by
    :class:`cog_id_ros.ros.recorder.Recorder`, in a process of its own.
    """

    def __init__(self, joints: Iterable[str], topic: str = 'joint_setpoint',
                 node_name: str = 'cog_id_player', depth: int | None = None,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.joints = list(joints)
        qos = control_qos()
        if depth is not None:
            qos.depth = int(depth)
        self.publisher = self.create_publisher(JointState, topic, qos)
        self._spinner = SingleThreadedExecutor(context=self.context)
        self._spinner.add_node(self)

    def spin_for(self, seconds: float) -> None:
        """Handle incoming messages for ``seconds`` of wall time."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self._spinner.spin_once(timeout_sec=left)

    def wait_for_subscriber(self, timeout: float = 10.0) -> bool:
        """Wait until the setpoint topic has a matched subscriber."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.publisher.get_subscription_count() > 0:
                self.spin_for(0.2)   # let the other side's discovery finish too
                return True
            self._spinner.spin_once(timeout_sec=0.02)
        return False

    def play(self, times: Any, positions: Any, velocities: Any = None, start_ns: int | None = None,
             pace: float = 1.0) -> list[int]:
        """Publish one setpoint per row at its time; returns the stamps (ns) used.

        ``times`` (N,) seconds, ``positions`` and ``velocities`` (N, n_joints).
        ``start_ns``: the stamp of the first row (default: now on the node's clock).
        ``pace``: wall-clock seconds per trajectory second (2: half speed); the stamps
        always follow ``times``.
        """
        times = np.asarray(times, dtype=float)
        positions = np.asarray(positions, dtype=float)
        velocities = None if velocities is None else np.asarray(velocities, dtype=float)
        offsets = np.round((times - times[0]) * NANOSECONDS).astype(np.int64)
        if start_ns is None:
            start_ns = self.get_clock().now().nanoseconds
        stamps = [start_ns + int(o) for o in offsets]
        msg = JointState()
        msg.name = self.joints
        t0 = time.monotonic()
        for i, stamp in enumerate(stamps):
            due = t0 + pace * offsets[i] / NANOSECONDS
            while (left := due - time.monotonic()) > 0:
                self._spinner.spin_once(timeout_sec=left)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NANOSECONDS)
            msg.position = positions[i].tolist()
            if velocities is not None:
                msg.velocity = velocities[i].tolist()
            self.publisher.publish(msg)
        return stamps

    def wait_delivered(self, timeout: float = 10.0) -> bool:
        """True once every matched subscriber acknowledged every setpoint published.

        Call it before destroying the player: a reliable writer destroyed right after its
        last publish takes the setpoints not yet acknowledged with it, and the node never
        gets (nor counts) the end of the stream.
        """
        return self.publisher.wait_for_all_acked(Duration(nanoseconds=int(timeout * 1e9)))


def play_recorded(player: Player, recorder: recording.Recorder, effort_topic: str, status: str,
                  times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None = None,
                  where: str | None = None
                  ) -> tuple[list[int], recording.Account, recording.Received]:
    """Play a run into the node and record its answers: returns ``(stamps, account,
    received)`` (see :meth:`Recorder.settle`; ``where`` names the node in the account,
    default ``effort_topic``).

    The first setpoint goes alone until its effort is recorded (the node's side of both
    matches, see :meth:`Recorder.answer_first`), then the rest on their schedule; the
    stamps stay those of one stream (``start + times[i] - times[0]``). The player must
    stay alive until this returns: its writer resends what the node has not acknowledged
    yet.
    """
    before = recorder.first_report(status, timeout=REPORT_WAIT)
    first_v = None if velocities is None else velocities[:1]
    rest_v = None if velocities is None else velocities[1:]
    start = player.get_clock().now().nanoseconds
    recorder.answer_first(effort_topic, status, start,
                          lambda: player.play(times[:1], positions[:1], first_v, start_ns=start),
                          before, lambda: player.wait_delivered(0.0))
    stamps = [start]
    if len(times) > 1:
        offset = int(round((times[1] - times[0]) * NANOSECONDS))
        stamps += player.play(times[1:], positions[1:], rest_v, start_ns=start + offset)
    result, received = recorder.settle(where or effort_topic, effort_topic, status, stamps,
                                       before)
    result.setpoint_topic = player.publisher.topic_name
    return stamps, result, received


def joints_of(path: str) -> list[str]:
    """Joint names of a trajectory CSV: every ``<joint>.position`` column, in file order."""
    with open(path, encoding='utf-8-sig') as f:
        header = f.readline()
    names = [c.strip().strip('"') for c in header.split(',')]
    return [c[:-len('.position')] for c in names if c.endswith('.position')]


def load_csv(path: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, list[str]]:
    """(times, positions (N, J), velocities (N, J) or None, joints) of a trajectory CSV."""
    joints = joints_of(path)
    if not joints:
        raise trajectory_io.TrajectoryError(path, 'no <joint>.position column', header=True)
    traj = trajectory_io.read_trajectory(path, joints, joints)
    for note in traj.notes:
        print(f'cog_id_player: {note}', file=sys.stderr)
    q = np.column_stack([traj.columns[f'{j}.position'] for j in joints])
    has_v = [f'{j}.velocity' in traj.columns for j in joints]
    qd = np.column_stack([traj.columns[f'{j}.velocity'] for j in joints]) if all(has_v) else None
    return traj.time, q, qd, joints


def resample(times: np.ndarray, positions: np.ndarray, velocities: np.ndarray | None,
             rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The trajectory at ``rate`` Hz from its first to its last time (cubic splines)."""
    from scipy.interpolate import CubicSpline
    new = times[0] + np.arange(int(np.floor((times[-1] - times[0]) * rate + 1e-9)) + 1) / rate
    q = CubicSpline(times, positions, axis=0)(new)
    qd = None if velocities is None else CubicSpline(times, velocities, axis=0)(new)
    return new, q, qd


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='cog_id_player',
        description='Play a CSV trajectory into joint_setpoint (sensor_msgs/JointState) and '
                    'optionally record joint_effort. ROS arguments go after --ros-args.')
    p.add_argument('--input', required=True,
                   help='CSV: time, <joint>.position[, <joint>.velocity]')
    p.add_argument('--rate', type=float, help='resample to this many setpoints per second '
                   '(default: the rows as they are)')
    p.add_argument('--topic', default='joint_setpoint',
                   help='setpoint topic (default %(default)s)')
    p.add_argument('--no-velocity', action='store_true', help='do not send the velocity columns')
    p.add_argument('--output', help='record joint_effort to this CSV (time, <joint>.effort)')
    p.add_argument('--effort-topic', default='joint_effort', help='default %(default)s')
    p.add_argument('--node', default='cog_id_node',
                   help='name of the node (in the namespace of --ros-args) whose /diagnostics '
                        'say where unanswered setpoints went (default %(default)s)')
    p.add_argument('--wait', type=float, default=10.0,
                   help='seconds to wait for the node to appear (default %(default)s)')
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    cli_args = rclpy.utilities.remove_ros_args(argv)[1:]
    args = build_parser().parse_args(cli_args)
    if args.rate is not None and not args.rate > 0:
        print('cog_id_player: --rate must be > 0', file=sys.stderr)
        return 2
    try:
        times, q, qd, joints = load_csv(args.input)
    except (OSError, ValueError) as exc:
        print(f'cog_id_player: {exc}', file=sys.stderr)
        return 2
    if args.no_velocity:
        qd = None
    if args.rate:
        times, q, qd = resample(times, q, qd, args.rate)
    stop = stop_signals.DeferredStop()   # a Ctrl-C while the node is built stops it cleanly
    rclpy.init(args=argv, signal_handler_options=stop.RCLPY_OPTIONS)
    # the whole file in the writer's history (see Player): no setpoint is lost for want of
    # a copy to resend
    player = Player(joints, args.topic, depth=len(times))
    recorder: recording.Recorder | None = None
    try:
        if stop.hand_over(restore_python_handlers=True) is not None:
            return 130
        if not player.wait_for_subscriber(args.wait):
            print(f'cog_id_player: nothing subscribes to {player.publisher.topic_name} '
                  f'after {args.wait:g} s (is cog_id_node running, in this namespace and '
                  'ROS_DOMAIN_ID?)', file=sys.stderr)
            return 1
        if args.output:
            effort_topic = player.resolve_topic_name(args.effort_topic)
            # at most one effort per setpoint: a queue of the file's length never drops one
            recorder = recording.Recorder([effort_topic], len(times))
            if not recorder.wait_matched(timeout=args.wait):
                print(f'cog_id_player: nothing publishes {effort_topic} after {args.wait:g} s',
                      file=sys.stderr)
                return 1
        print(f'cog_id_player: playing {len(times)} setpoints of {", ".join(joints)} over '
              f'{times[-1] - times[0]:.3f} s into {player.publisher.topic_name}', file=sys.stderr)
        if not args.output:
            player.play(times, q, qd)
            if not player.wait_delivered():
                print(f'cog_id_player: {player.publisher.topic_name}: the node did not '
                      'acknowledge every setpoint in 10 s', file=sys.stderr)
                return LOST
            return 0
        status = recording.diagnostics_name(player.get_namespace(), args.node)
        assert recorder is not None       # made above: args.output
        stamps, account, received = play_recorded(player, recorder, effort_topic, status,
                                                  times, q, qd, where=args.node)
        found = np.array([s in received for s in stamps])
        if not found.any():
            print(f'cog_id_player: no effort came back on {effort_topic}', file=sys.stderr)
            return 1
        names = next(received[s][0] for s in stamps if s in received)
        efforts = np.full((len(stamps), len(names)), np.nan)
        for i, s in enumerate(stamps):
            if s in received:
                efforts[i] = received[s][1]
        try:
            trajectory_io.write_efforts(args.output, times, efforts, found, names)
        except OSError as exc:     # also a FIFO or device refused as --output
            print(f'cog_id_player: --output {args.output}: cannot write: '
                  f'{exc.strerror or exc}', file=sys.stderr)
            return 4
        print(f'cog_id_player: {int(found.sum())} of {len(stamps)} efforts recorded to '
              f'{args.output}', file=sys.stderr)
        if not account.complete:
            # the CSV is written (an empty cell per missing effort) but the run is not whole
            print(f'cog_id_player: {account.where}: {account.losses()}', file=sys.stderr)
            return LOST
    except KeyboardInterrupt:
        return 130
    finally:
        player.destroy_node()
        if recorder is not None:
            recorder.close()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
