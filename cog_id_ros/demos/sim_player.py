"""The closed-loop demo's player: setpoints on the simulated time of cog_sim_node.

:class:`SimPlayer` is an rclpy node in the namespace of one ``cog_sim_node`` and one
``cog_id_node``. It records every ``joint_states`` of the simulator (stamped with
simulated time t) and, for each new t, publishes the setpoint of the target at t + one
step on ``joint_setpoint``, stamped ``start + t + step`` (the node's clock is ahead of
that, never behind: the stamps are increasing and never lead), so the setpoint in force
when the node answers the next state is that state's own. It records the stamps of the
node's ``joint_effort`` (the efforts of each ``effort_command``, stamped as the measured
state or setpoint they answer), so that a state or setpoint left without its command is
said (:meth:`results`), as is a simulated step missing from ``joint_states``.
"""
import math
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np

NS = 1_000_000_000
#: s between the connection seen here and the start of the check of answers
MATCH_SETTLE = 0.5

#: the target: t -> (positions, velocities) of the active joints
Target = Callable[[float], tuple[Sequence[float], Sequence[float]]]


class SimPlayer:
    """Setpoints of ``target`` (None: none) on the simulated time of the simulator in
    ``namespace``; ``feedback``: the node answers states (False: setpoints)."""

    def __init__(self, context: Any, namespace: str, mechanism: Any, time_step: float,
                 target: Target | None, feedback: bool) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        from ..ros.player import RECORDER_QOS
        from ..ros.topics import control_qos
        self.mechanism, self.target, self.feedback = mechanism, target, feedback
        self.step_ns = round(time_step * NS)
        self.index = [mechanism.joints.index(j) for j in mechanism.active_joints]
        self.node = rclpy.create_node('closed_loop_player', namespace=namespace,
                                      context=context)
        self.setpoints = self.node.create_publisher(JointState, 'joint_setpoint',
                                                    control_qos())
        self._msg_type = JointState
        self.lock = threading.Lock()
        #: (simulated time ns, active positions) of every joint_states, in order
        self.states: list[tuple[int, list[float]]] = []
        self.armed = False
        self.last_ns = -1                   # the simulated time of the last new state
        #: stamps (ns) of the states (feedback) or setpoints sent since armed, and of the
        #: node's answers
        self.asked: set[int] = set()
        self.answered: set[int] = set()
        self.node.create_subscription(JointState, 'joint_states', self._on_state,
                                      RECORDER_QOS)
        self._answers = self.node.create_subscription(JointState, 'joint_effort',
                                                      self._on_answer, RECORDER_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()
        self.start_ns = time.time_ns()

    def _on_state(self, msg: Any) -> None:
        t_ns = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
        with self.lock:
            self.states.append((t_ns, [msg.position[i] for i in self.index]))
            if not self.armed:
                return
            if self.feedback:
                self.asked.add(t_ns)
            if t_ns <= self.last_ns:
                return
            self.last_ns = t_ns
        if self.target is not None:
            self._send_setpoint(t_ns + self.step_ns)

    def _on_answer(self, msg: Any) -> None:
        with self.lock:
            self.answered.add(msg.header.stamp.sec * NS + msg.header.stamp.nanosec)

    def _send_setpoint(self, t_ns: int) -> None:
        assert self.target is not None
        q, qd = self.target(t_ns / NS)
        msg = self._msg_type()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(self.start_ns + t_ns, NS)
        msg.name = list(self.mechanism.active_joints)
        msg.position = [float(x) for x in q]
        msg.velocity = [float(x) for x in qd]
        with self.lock:
            if not self.feedback:
                self.asked.add(self.start_ns + t_ns)
        self.setpoints.publish(msg)

    def heard(self, timeout: float = 30.0) -> bool:
        """True once a joint_states of the simulator arrived."""
        return self._until(lambda: bool(self.states), timeout)

    def connected(self, timeout: float = 30.0) -> bool:
        """True once cog_id_node hears what it needs and both nodes hear its efforts; then,
        MATCH_SETTLE s later, the player is armed (setpoints and the check of answers start:
        in the feedback modes the node may have released the simulator before)."""
        node = self.node
        states = node.resolve_topic_name('joint_states')
        efforts = node.resolve_topic_name('effort_command')

        def ready() -> bool:     # matched, not only in the graph: the answers all arrive
            return (node.count_subscribers(states) >= (2 if self.feedback else 1)
                    and node.count_subscribers(efforts) >= 1
                    and self._answers.get_publisher_count() >= 1
                    and (self.target is None or self.setpoints.get_subscription_count() > 0))
        if not self._until(ready, timeout):
            return False
        # each side matches the other in its own time: the node's publisher may not yet
        # send to this reader when this reader already counts it (answers then lost here,
        # not on the way to the simulator)
        time.sleep(MATCH_SETTLE)
        with self.lock:
            self.armed = True
        return True

    def wait(self, seconds: float, timeout: float) -> bool:
        """True once the simulator reached ``seconds`` of simulated time."""
        end_ns = round(seconds * NS)
        return self._until(lambda: bool(self.states) and self.states[-1][0] >= end_ns,
                           timeout)

    def results(self, seconds: float, settle: float) -> dict[str, Any]:
        """'time', 'positions', 'setpoints' (active joints) of every simulated step up to
        ``seconds``, and 'lost': what was lost on the way, one line each (the commands of
        the last states are waited for up to ``settle`` s)."""
        end_ns = round(seconds * NS)
        limit = end_ns + (0 if self.feedback else self.start_ns)

        def unanswered() -> list[int]:
            with self.lock:
                return sorted(s for s in self.asked - self.answered if s <= limit)
        self._until(lambda: not unanswered(), settle)
        with self.lock:
            states = list(self.states)
        lost = self._lost(states, seconds, unanswered(), len([s for s in self.asked
                                                               if s <= limit]))
        by_time = {t: q for t, q in states if t <= end_ns}
        stamps = sorted(by_time)
        t = np.array(stamps) / NS
        out: dict[str, Any] = {'time': t, 'positions': np.array([by_time[s] for s in stamps]),
                               'lost': lost}
        if self.target is not None:
            out['setpoints'] = np.array([self.target(x)[0] for x in t])
        return out

    def _lost(self, states: list[tuple[int, list[float]]], seconds: float,
              unanswered: list[int], asked: int) -> list[str]:
        lines = []
        steps = round(seconds * NS / self.step_ns)
        have = {t // self.step_ns for t, _ in states if t % self.step_ns == 0}
        missing = [k for k in range(steps + 1) if k not in have]
        if missing:
            lines.append(f'{len(missing)} of {steps + 1} simulated steps missing from '
                         f'joint_states (the first at t = {missing[0] * self.step_ns / NS:g} s)')
        if unanswered or not asked:
            what = 'measured states' if self.feedback else 'setpoints'
            first = (unanswered[0] - (0 if self.feedback else self.start_ns)) / NS \
                if unanswered else math.nan
            lines.append(f'{len(unanswered)} of {asked} {what} up to {seconds:g} s left '
                         f'without their effort_command (the first at t = {first:g} s)')
        return lines

    def _until(self, condition: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if condition():
                return True
            time.sleep(0.01)
        return condition()

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
