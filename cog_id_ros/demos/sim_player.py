"""The closed-loop demo's player: setpoints on the simulated time of cog_sim_node.

:class:`SimPlayer` is an rclpy node in the namespace of one ``cog_sim_node`` and one
``cog_id_node``. It records every ``joint_states`` of the simulator (stamped with
simulated time t) and the stamps of the node's ``joint_effort`` (the efforts of each
``effort_command``, stamped as the measured state or setpoint they answer).

**Connecting.** A subscription counted on one side of DDS may not yet be matched on the
other: a setpoint published then is lost without a trace, and a demo once drew a mode
holding its start pose for half of its run while the node never heard the target. So
the run starts only when every path was seen carrying data (:meth:`connect`): for the
modes that track a setpoint, *probes* (the plant's pose as last heard, at rest, stamped
with the wall clock: holding it is the command the node gives anyway before its first
setpoint) are published on each simulated state until the node's ``/diagnostics`` count
one accepted, the node's ``joint_effort`` is heard here and the simulator steps (it
holds its start pose until it takes a command). Then the node's counters are
read once more (the baseline) and the run starts at the next simulated state, t0.

**The run.** For each new simulated time t it publishes the target at t - t0 + one step
on ``joint_setpoint``, stamped ``start + t - t0 + step`` (start: the wall clock when the
run began, after every probe; the stamps are increasing and never lead the node's
clock), so the setpoint in force when the node answers the next state is that state's
own. :meth:`results` gives every step from t0 on, on the time t - t0, and says what was
lost: a simulated step missing from ``joint_states``, a state or setpoint left without
its command, a setpoint the node's counters do not account for as accepted.
"""
import math
import threading
import time
from typing import Any, Callable, Sequence

import numpy as np

NS = 1_000_000_000

#: the target: t -> (positions, velocities) of the active joints
Target = Callable[[float], tuple[Sequence[float], Sequence[float]]]

#: phases: before any probe, probing, waiting for the baseline, running, stopped
CONNECTING, PROBING, SETTLING, RUNNING, DONE = range(5)


class SimPlayer:
    """Setpoints of ``target`` (None: none) on the simulated time of the simulator in
    ``namespace``; ``feedback``: the node answers states (False: setpoints)."""

    def __init__(self, context: Any, namespace: str, mechanism: Any, time_step: float,
                 target: Target | None, feedback: bool) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import JointState

        from ..ros.player import RECORDER_QOS
        from ..ros.recorder import diagnostics_name
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
        self.phase = CONNECTING
        #: (simulated time ns, active positions) of every joint_states, in order
        self.states: list[tuple[int, list[float]]] = []
        self.t0_ns: int | None = None       # the simulated time the run starts at
        self.start_ns = 0                   # the wall clock (ns) the run's stamps start at
        self.last_ns = -1                   # the simulated time of the last new state
        #: stamps (ns) of the states (feedback) or setpoints sent in the run, and of the
        #: node's answers (all of them)
        self.asked: set[int] = set()
        self.answered: set[int] = set()
        self.sent = 0                       # setpoints sent in the run
        #: the node's counters (diagnostics: accepted, rejected, lost) and when heard
        self.counters: dict[str, int] | None = None
        self.counters_at = 0.0
        self.baseline: dict[str, int] | None = None
        self._status = diagnostics_name(namespace)
        self.node.create_subscription(JointState, 'joint_states', self._on_state,
                                      RECORDER_QOS)
        self._answers = self.node.create_subscription(JointState, 'joint_effort',
                                                      self._on_answer, RECORDER_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                      10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._thread = threading.Thread(target=self.executor.spin, daemon=True)
        self._thread.start()

    # ---- callbacks (the executor's thread)
    def _on_state(self, msg: Any) -> None:
        t_ns = msg.header.stamp.sec * NS + msg.header.stamp.nanosec
        q = [msg.position[i] for i in self.index]
        with self.lock:
            self.states.append((t_ns, q))
            phase = self.phase
            new = t_ns > self.last_ns
            self.last_ns = max(t_ns, self.last_ns)
            if phase == RUNNING:
                if self.t0_ns is None:
                    self.t0_ns = t_ns       # the run starts at the first state it hears
                if self.feedback:
                    self.asked.add(t_ns)
        if self.target is None:
            return
        if phase == PROBING:        # every state, a held one again too: a probe may be lost
            self._publish(time.time_ns(), q, [0.0] * len(q))
        elif phase == RUNNING and new:
            assert self.t0_ns is not None
            t_run = t_ns - self.t0_ns + self.step_ns
            q_d, qd_d = self.target(t_run / NS)
            with self.lock:
                self.sent += 1
                if not self.feedback:
                    self.asked.add(self.start_ns + t_run)
            self._publish(self.start_ns + t_run, q_d, qd_d)

    def _on_answer(self, msg: Any) -> None:
        with self.lock:
            self.answered.add(msg.header.stamp.sec * NS + msg.header.stamp.nanosec)

    def _on_diagnostics(self, msg: Any) -> None:
        from ..ros.recorder import counters
        for status in msg.status:
            if status.name == self._status:
                values = counters({kv.key: kv.value for kv in status.values})
                if values is not None:
                    with self.lock:
                        self.counters, self.counters_at = values, time.monotonic()

    def _publish(self, stamp_ns: int, q: Sequence[float], qd: Sequence[float]) -> None:
        msg = self._msg_type()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
        msg.name = list(self.mechanism.active_joints)
        msg.position = [float(x) for x in q]
        msg.velocity = [float(x) for x in qd]
        self.setpoints.publish(msg)

    # ---- the demo's steps
    def heard(self, timeout: float = 30.0) -> bool:
        """True once a joint_states of the simulator arrived."""
        return self._until(lambda: bool(self.states), timeout)

    def connect(self, timeout: float = 30.0) -> str:
        """Wait until every path carried data, then start the run; '' when it started, else
        what was not seen."""
        if self.target is not None:
            with self.lock:
                self.phase = PROBING
            if not self._until(lambda: self._accepted() >= 1, timeout):
                return 'cog_id_node did not count a setpoint of the player as accepted'
        if not self._until(lambda: bool(self.answered), timeout):
            return 'no joint_effort of cog_id_node heard'
        # the simulator heard a command: it steps (wait_for_effort held it until then)
        if not self._until(lambda: self.last_ns > 0, timeout):
            return 'cog_sim_node did not take a command of cog_id_node (no step)'
        if self.target is not None:
            with self.lock:
                self.phase = SETTLING
            stopped = time.monotonic()
            # the baseline: a report from after the last probe was served
            if not self._until(lambda: self.counters_at > stopped + 0.3, timeout):
                return 'no /diagnostics of cog_id_node after the probes'
            with self.lock:
                self.baseline = self.counters
        with self.lock:
            self.start_ns = time.time_ns()
            self.phase = RUNNING
        return ''

    def _accepted(self) -> int:
        with self.lock:
            return -1 if self.counters is None else self.counters['setpoints_accepted']

    def wait(self, seconds: float, timeout: float) -> bool:
        """True once the simulator reached ``seconds`` of simulated time into the run."""
        end_ns = round(seconds * NS)

        def reached() -> bool:
            with self.lock:
                return self.t0_ns is not None and bool(self.states) and \
                    self.states[-1][0] - self.t0_ns >= end_ns
        return self._until(reached, timeout)

    def results(self, seconds: float, settle: float) -> dict[str, Any]:
        """'time' (from t0), 'positions', 'setpoints' (active joints) of every simulated
        step of the run up to ``seconds``, and 'lost': what was lost on the way, one line
        each (the commands of the last states and the node's count are waited for up to
        ``settle`` s)."""
        with self.lock:
            self.phase = DONE       # no more setpoints: the node's count can catch up
        assert self.t0_ns is not None
        t0 = self.t0_ns
        end_ns = round(seconds * NS)
        limit = t0 + end_ns if self.feedback else self.start_ns + end_ns

        def unanswered() -> list[int]:
            with self.lock:
                return sorted(s for s in self.asked - self.answered if s <= limit)
        self._until(lambda: not unanswered() and self._counted() >= self.sent, settle)
        with self.lock:
            states = [(t - t0, q) for t, q in self.states if t >= t0]
            asked = len([s for s in self.asked if s <= limit])
        lost = self._lost(states, seconds, unanswered(), asked)
        by_time = {t: q for t, q in states if t <= end_ns}
        stamps = sorted(by_time)
        t = np.array(stamps) / NS
        out: dict[str, Any] = {'time': t, 'positions': np.array([by_time[s] for s in stamps]),
                               'lost': lost}
        if self.target is not None:
            out['setpoints'] = np.array([self.target(x)[0] for x in t])
        return out

    def _delta(self) -> dict[str, int] | None:
        """The node's counters over the run (None: no report before or after)."""
        with self.lock:
            now, base = self.counters, self.baseline
        if now is None or base is None:
            return None
        return {key: now[key] - base[key] for key in now}

    def _counted(self) -> int:
        delta = self._delta()
        return -1 if delta is None else sum(delta.values())

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
            origin = (self.t0_ns or 0) if self.feedback else self.start_ns
            first = (unanswered[0] - origin) / NS if unanswered else math.nan
            lines.append(f'{len(unanswered)} of {asked} {what} up to {seconds:g} s left '
                         f'without their effort_command (the first at t = {first:g} s)')
        if self.target is not None:
            delta = self._delta()
            if delta is None:
                lines.append('no /diagnostics of cog_id_node to count the setpoints by')
            elif delta['setpoints_accepted'] != self.sent:
                lines.append(f"{self.sent} setpoints sent, cog_id_node accepted "
                             f"{delta['setpoints_accepted']}, rejected "
                             f"{delta['setpoints_rejected']}, counted "
                             f"{delta['setpoints_lost']} lost")
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
