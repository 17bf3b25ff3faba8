"""A plant in lockstep with cog_id_node over real topics: the closed-loop tests'.

:class:`LockstepPlant` is an rclpy node around a :class:`cog_id_ros.Simulation` of the same
mechanism. Each step of length h it publishes the setpoint of the motion at the step's time
on ``joint_setpoint`` (when there is one), then the simulated state on
``measured_joint_states`` (every joint of ``mechanism.joints``, positions and velocities,
as a robot's ``/joint_states``), waits for the node's answer (``joint_effort`` with that
state's stamp: the efforts of its ``effort_command``) and integrates one step with them
held (zero-order hold). So the loop is closed through DDS as on a robot, but
deterministically: one command per measured state, whatever the load of the machine (real
time is given up for it; the node sees setpoints and measurements stamped h apart).
"""
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np

NS = 1_000_000_000
#: times a measured state is sent again when no command answers it in time (the first after
#: discovery may arrive late and be refused as stale)
RESENDS = 10

#: the target of a run: t -> (positions, velocities) of the active joints, or None
Target = Callable[[float], tuple[Sequence[float], Sequence[float]] | None]


class LockstepPlant:
    """A Simulation stepped by the commands of one cog_id_node (namespace ``namespace``)."""

    def __init__(self, context: Any, namespace: str, simulation: Any,
                 name: str = 'lockstep_plant', settle: float = 0.001) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64MultiArray

        from ..ros.topics import control_qos
        self.sim = simulation
        self.mechanism = simulation.mechanism
        #: s between a setpoint and the measured state after it (the node's two threads)
        self.settle = settle
        self.node = rclpy.create_node(name, namespace=namespace, context=context)
        self.setpoints = self.node.create_publisher(JointState, 'joint_setpoint', control_qos())
        self.states = self.node.create_publisher(JointState, 'measured_joint_states',
                                                 control_qos())
        self._command: list[float] | None = None
        self._waiting_for = -1                # the stamp (ns) of the state sent last
        self._arrived = threading.Event()
        #: every effort_command received (what reached the motors), in order
        self.commands: list[list[float]] = []
        #: the stamps of the states the node answered (joint_effort), in order
        self.answered: list[int] = []
        self.node.create_subscription(Float64MultiArray, 'effort_command',
                                      self._on_command,
                                      control_qos())
        # the answer to a state: joint_effort carries its header (the efforts are the
        # command's), so a command is never taken for another state's
        self.node.create_subscription(JointState, 'joint_effort', self._on_effort,
                                      control_qos())
        self._msg_type = JointState
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()
        self._start_ns = time.time_ns()

    def _on_command(self, msg: Any) -> None:
        self.commands.append(list(msg.data))

    def _on_effort(self, msg: Any) -> None:
        stamp = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
        self.answered.append(stamp)
        if stamp == self._waiting_for:
            self._command = list(msg.effort)
            self._arrived.set()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()

    def connected(self, timeout: float = 20.0, feedback: bool = True) -> bool:
        """True once the node subscribes both inputs (``feedback`` False: the setpoints)
        and publishes effort_command."""
        end = time.monotonic() + timeout
        topic = self.node.resolve_topic_name('effort_command')
        while time.monotonic() < end:
            if (self.states.get_subscription_count() or not feedback) and \
                    self.setpoints.get_subscription_count() and \
                    self.node.count_publishers(topic):
                return True
            time.sleep(0.02)
        return False

    def stamp(self, t: float) -> int:
        return self._start_ns + int(round(t * NS))

    def send_setpoint(self, t: float, q: Sequence[float], qd: Sequence[float] | None) -> None:
        msg = self._msg_type()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.stamp(t), NS)
        msg.name = list(self.mechanism.active_joints)
        msg.position = [float(x) for x in q]
        msg.velocity = [] if qd is None else [float(x) for x in qd]
        self.setpoints.publish(msg)

    def send_state(self, t: float, positions: Sequence[float] | None = None,
                   velocities: Sequence[float] | None = None) -> None:
        """The simulated state (or the one given, e.g. a corrupted one) on
        measured_joint_states, every joint of the mechanism."""
        msg = self._msg_type()
        stamp = self.stamp(t)
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, NS)
        msg.name = list(self.mechanism.joints)
        msg.position = [float(x) for x in (self.sim.joint_positions() if positions is None
                                           else positions)]
        msg.velocity = [float(x) for x in (self.sim.joint_velocities() if velocities is None
                                           else velocities)]
        self._arrived.clear()
        self._waiting_for = stamp
        self.states.publish(msg)

    def _answer_to_setpoint(self, t: float, wanted: tuple, timeout: float
                            ) -> list[float] | None:
        """Feed-forward: the efforts that answer the setpoint at ``t`` (its joint_effort)."""
        for _ in range(RESENDS):
            self._arrived.clear()
            self._waiting_for = self.stamp(t)
            self.send_setpoint(t, *wanted)
            tau = self.command(timeout / RESENDS)
            if tau is not None:
                return tau
            t += 1e-6           # sent again: a later stamp (the node wants them increasing)
        return None

    def command(self, timeout: float) -> list[float] | None:
        """The efforts that answered the last state (its joint_effort), or None within
        ``timeout`` s."""
        if not self._arrived.wait(timeout):
            return None
        return self._command

    def run(self, seconds: float, target: Target | None = None, timeout: float = 5.0,
            feedback: bool = True) -> dict[str, np.ndarray]:
        """Step for ``seconds``: per step the setpoint of ``target`` (if any), the state,
        the command, one step. Returns 'time', 'positions', 'setpoints' (NaN without one)
        and 'efforts' per step (active joints); RuntimeError when a command never came.
        ``feedback`` False: a node in feedforward mode, which answers the setpoint (no
        state is sent)."""
        h = self.sim.time_step
        steps = int(round(seconds / h))
        m = len(self.mechanism.active_joints)
        out: dict[str, np.ndarray] = {key: np.full((steps, m), np.nan)
                                      for key in ('positions', 'setpoints', 'efforts')}
        out['time'] = np.zeros(steps)
        for k in range(steps):
            t = self.sim.time
            wanted = target(t) if target is not None else None
            tau = None
            if not feedback:
                assert wanted is not None, 'feed-forward needs a target'
                tau = self._answer_to_setpoint(t, wanted, timeout)
            elif wanted is not None:
                self.send_setpoint(t, *wanted)
                time.sleep(self.settle)
            if wanted is not None:
                out['setpoints'][k] = wanted[0]
            for _ in range(RESENDS if feedback else 0):   # a state lost or refused (stale:
                self.send_state(t)                          # the first, just matched)
                tau = self.command(timeout / RESENDS)
                if tau is not None:
                    break
            if tau is None:
                raise RuntimeError(f'no effort_command within {timeout:g} s for the measured '
                                   f'state at t = {t:.4f} s')
            out['time'][k] = t
            out['positions'][k] = self.sim.positions
            out['efforts'][k] = tau
            self.sim.step(tau)
        return out
