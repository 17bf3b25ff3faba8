"""cog_sim_node's integration: a thread of its own steps the Simulation, paced to wall time.

* :class:`Pacer`: when the next step is due for a real-time factor (0: at once);
* :class:`StateOutputs`: ``joint_states`` and ``/clock`` messages, reused and published;
* :class:`Integrator`: one step with the held efforts (:class:`.sim_efforts.EffortHold`),
  then the outputs; the first error of the Simulation (a singular or unreachable pose)
  stops it, named, until a reset;
* :class:`SimLoop`: the thread: steps when due, serves reset requests between steps; with
  ``wait_for_effort`` it holds the state (no step, the state published again) until the
  first accepted effort after start or reset.

The Simulation belongs to the thread alone: the executor (effort messages, ``~/reset``,
diagnostics) reaches it only through the held efforts (under the node's lock, held for
the copy of a list) and reset requests, and reads the snapshot the integrator keeps after
every step (time, steps, closure residual). So the executor never waits for a step, and no
step waits for the executor. All physics is ``cog_id_ros.Simulation``'s.
"""
import math
import threading
import time
from typing import Any, Callable, Sequence

from sensor_msgs.msg import JointState

from ..core import CogIdError
from . import cdr
from .setpoint_filter import NANOSECONDS
from .sim_efforts import EffortHold

#: s of wall time the simulation may fall behind its schedule before the pacer gives up
#: catching up and starts again from now (counted in ``lag_restarts``): a pause of the
#: machine is not followed by a sprint of simulated time
MAX_LAG = 0.1
#: s of wall time the thread sleeps at most at once (it wakes at once for a request)
MAX_SLEEP = 0.1
#: s of wall time between the publications of the held state while ``wait_for_effort``
#: holds the simulation before its first effort, or lockstep waits for the next one
#: (sim_parameters' text says the same)
HELD_STATE_PERIOD = 0.1
#: s of wall time the thread sleeps at once while it waits for the first effort
EFFORT_POLL = 0.001
#: s the ~/reset service waits for the integration thread to do the reset
RESET_TIMEOUT = 5.0


class Pacer:
    """Steps due at ``factor`` simulated seconds per wall-clock second (0: always due)."""

    def __init__(self, time_step: float, factor: float,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.period = time_step / factor if factor > 0.0 else 0.0
        self.clock = clock
        self.lag_restarts = 0
        self.restart()

    def restart(self) -> None:
        """The schedule starts now (at start-up and after a reset)."""
        self._origin, self._steps = self.clock(), 0

    def wait(self) -> float:
        """Wall seconds until the next step is due (<= 0: due now)."""
        if not self.period:
            return 0.0
        now = self.clock()
        late = now - (self._origin + self._steps * self.period)
        if late > MAX_LAG:
            self.lag_restarts += 1
            self._origin = now - self._steps * self.period
            return 0.0
        return -late

    def stepped(self) -> None:
        self._steps += 1


class StateOutputs:
    """The simulated state as messages: ``joint_states`` (every joint) and ``/clock``.

    ``joints``: every joint (``mechanism.joints``); ``active_index``: where each active
    joint is among them. ``clock_pub``: None without ``publish_clock``.
    """

    def __init__(self, joints: Sequence[str], active_index: Sequence[int],
                 joint_states_pub: Any, clock_pub: Any | None) -> None:
        self.state = JointState()
        self.state.name = list(joints)
        self.active_index = list(active_index)
        self.joint_states_pub, self.clock_pub = joint_states_pub, clock_pub

    def publish_clock(self, stamp_ns: int) -> None:
        if self.clock_pub is not None:
            self.clock_pub.publish(cdr.clock(stamp_ns))     # serialized: no conversion

    def publish_state(self, stamp_ns: int, positions: list[float], velocities: list[float],
                      efforts: Sequence[float]) -> None:
        """joint_states: every joint's position and velocity, the active joints' efforts."""
        state = self.state
        state.header.stamp.sec, state.header.stamp.nanosec = divmod(stamp_ns, NANOSECONDS)
        effort = [0.0] * len(positions)
        for i, value in zip(self.active_index, efforts):
            effort[i] = value
        state.position, state.velocity, state.effort = positions, velocities, effort
        self.joint_states_pub.publish(state)


def _finite(values: Sequence[float]) -> bool:
    return all(map(math.isfinite, values))


class Integrator:
    """The Simulation stepped with the held efforts, and its outputs after each step.

    ``every``: steps between joint_states (the state at time 0 is published too). The
    attributes ``time``, ``steps``, ``residual`` (closure residual at ``time``) and
    ``error`` (None while it integrates; else why it stopped) are the snapshot the
    executor reads; ``sim_diagnostics`` the Simulation's diagnostics (error estimates,
    energy), taken after the first step that follows :meth:`want_diagnostics`.
    """

    def __init__(self, simulation: Any, hold: EffortHold, lock: threading.Lock,
                 outputs: StateOutputs, every: int, logger: Any,
                 wait_for_effort: bool = False, lockstep: bool = False) -> None:
        self.simulation, self.hold, self.lock = simulation, hold, lock
        self.outputs, self.every, self.logger = outputs, every, logger
        self.wait_for_effort = wait_for_effort
        #: lockstep: a step only once an effort was accepted after the last one
        self.lockstep = lockstep
        self._stepped_on = 0        # hold.accepted at the last step (lockstep)
        self.error: str | None = None
        self.error_reason = ''
        self.stops = 0              # times an error stopped the integration
        self.sim_diagnostics: Any = None
        self._diagnostics_wanted = False
        self._snapshot()

    def want_diagnostics(self) -> None:
        """Have the integration thread take the Simulation's diagnostics after its next
        step (the energies cost tens of microseconds to a millisecond: once a report, in
        the thread that owns the Simulation)."""
        self._diagnostics_wanted = True

    def _snapshot(self) -> None:
        sim = self.simulation
        self.time, self.residual = sim.time, sim.closure_residual
        self.steps = round(sim.time / sim.time_step)
        self.stamp_ns = round(self.time * NANOSECONDS)

    def begin(self) -> None:
        """Publish the state as it is (time 0: start, reset), and the clock."""
        self.outputs.publish_clock(self.stamp_ns)
        self._publish([0.0] * self.hold.size)

    def waiting(self) -> bool:
        """Whether ``wait_for_effort`` holds the state: no effort accepted since the start
        or the last reset."""
        return self.wait_for_effort and self.hold.received_at is None

    def awaits_effort(self) -> bool:
        """Lockstep: no effort accepted since the last step (the next step waits for it)."""
        return self.lockstep and self.hold.accepted <= self._stepped_on

    def republish(self) -> None:
        """The held state again, as it is (at its own stamp), and the clock."""
        self.outputs.publish_clock(self.stamp_ns)
        self._publish([0.0] * self.hold.size)

    def step(self) -> bool:
        """One step with the efforts held now; False when it stopped the integration.

        The per-step path: the Simulation's step, the clock; every ``every`` steps the
        joint state, checked finite first (a Simulation raises for a pose it cannot close:
        a state that is not finite, e.g. efforts that throw a link to 1e300 rad/s, stops
        it here, and nothing that is not finite is published)."""
        with self.lock:
            tau = self.hold.acting(self.time)
            self._stepped_on = self.hold.accepted
        sim = self.simulation
        try:
            sim.step(tau)
        except CogIdError as exc:
            self.stop(getattr(exc, 'reason', None) or type(exc).__name__, str(exc))
            return False
        self.steps += 1
        self.time = time_now = sim.time
        self.residual = sim.closure_residual
        if self._diagnostics_wanted:
            self._diagnostics_wanted = False
            self.sim_diagnostics = sim.diagnostics
        self.stamp_ns = stamp = round(time_now * NANOSECONDS)
        self.outputs.publish_clock(stamp)
        if self.steps % self.every == 0:
            return self._publish(tau)
        return True

    def _publish(self, efforts: Sequence[float]) -> bool:
        positions_, velocities_ = self.simulation.joint_state()      # one read-out
        positions, velocities = positions_.tolist(), velocities_.tolist()
        if not (_finite(positions) and _finite(velocities)):
            self.stop('non_finite', f'the state is not finite at t = {self.time:.6g} s (efforts '
                                    f'{list(efforts)}): the motion diverged')
            return False
        self.outputs.publish_state(self.stamp_ns, positions, velocities, efforts)
        return True

    def stop(self, reason: str, text: str) -> None:
        """Stop integrating: nothing more is published until a reset."""
        self.error, self.error_reason = text, reason
        self.stops += 1
        self.logger.error(f'integration stopped ({reason}): {text}; call ~/reset to start '
                          'again')

    def reset(self) -> str:
        """Back to the initial state (time 0, no effort held); the message of ~/reset."""
        self.simulation.reset()
        with self.lock:
            self.hold.reset()
            self._stepped_on = 0
        self.error, self.error_reason = None, ''
        self.sim_diagnostics = None
        self._snapshot()
        self.begin()
        return 'reset: initial_positions at rest, time 0, no effort held'


class SimLoop:
    """The integration thread: steps when the pacer says, serves reset requests between
    steps, waits while the integration is stopped. ``start()`` once the node is built,
    ``stop()`` before it is destroyed."""

    def __init__(self, integrator: Integrator, pacer: Pacer, context: Any, logger: Any,
                 on_internal_error: Callable[[str, BaseException], None]) -> None:
        self.integrator, self.pacer, self.context, self.logger = integrator, pacer, context, logger
        self.on_internal_error = on_internal_error
        self.failure: BaseException | None = None
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._wake = threading.Event()
        self._requests: list[tuple[threading.Event, list[Any]]] = []
        self._requests_lock = threading.Lock()
        self._held_published = time.monotonic()     # begin() published the state

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name='cog_sim_node integration',
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 5.0) -> None:
        self._stopping = True
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout)

    @property
    def ended_by_itself(self) -> bool:
        """Whether the thread ended with an exception, or while nobody stopped it and the
        context was still ok (a bug)."""
        if self._thread is None or self._thread.is_alive():
            return False
        return self.failure is not None or not (self._stopping or not self.context.ok())

    def wake(self) -> None:
        """An effort was accepted: a lockstep step may be due now."""
        self._wake.set()

    def request_reset(self) -> tuple[bool, str]:
        """Have the thread reset the simulation between two steps; (success, message)."""
        if self._thread is None or not self._thread.is_alive():
            return False, 'the integration thread is not running'
        done, answer = threading.Event(), [False, '']
        with self._requests_lock:
            self._requests.append((done, answer))
        self._wake.set()
        if not done.wait(RESET_TIMEOUT):
            return False, f'the integration thread did not reset within {RESET_TIMEOUT:g} s'
        return bool(answer[0]), str(answer[1])

    def _run(self) -> None:
        try:
            self.integrator.begin()
            self._loop()
        except BaseException as exc:   # noqa: BLE001 (recorded, then the thread ends)
            if self.context.ok() and not self._stopping:
                self.failure = exc
                try:
                    self.logger.error(f'the integration thread stopped: '
                                      f'{type(exc).__name__}: {exc}')
                except Exception:   # noqa: BLE001 (the node reports self.failure all the same)
                    pass

    def _loop(self) -> None:
        integrator, pacer, wake = self.integrator, self.pacer, self._wake
        while not self._stopping and self.context.ok():
            if self._requests:
                self._serve_requests()
            if integrator.error is not None:
                self._sleep(MAX_SLEEP)
                continue
            if integrator.waiting():
                self._hold_state()
                continue
            if integrator.awaits_effort():
                self._await_effort()
                continue
            wait = pacer.wait()
            if wait > 0.0:
                self._sleep(min(wait, MAX_SLEEP))
                continue
            try:
                integrator.step()
            except Exception as exc:   # noqa: BLE001 (a bug: stops the integration, named)
                if self._stopping or not self.context.ok():
                    return          # Ctrl-C shut the context down: publishing failed
                self.on_internal_error('integration', exc)
                integrator.stop('internal', f'{type(exc).__name__}: {exc}')
            pacer.stepped()
            if wake.is_set():
                wake.clear()
            if integrator.lockstep:
                self._held_published = time.monotonic()

    def _hold_state(self) -> None:
        """wait_for_effort: no step before the first effort; the held state published
        again every HELD_STATE_PERIOD s; the pacing starts when the effort comes."""
        now = time.monotonic()
        if now - self._held_published >= HELD_STATE_PERIOD:
            self._held_published = now
            self.integrator.republish()
        self._sleep(EFFORT_POLL)
        self.pacer.restart()

    def _await_effort(self) -> None:
        """Lockstep: no step before the next effort; the state published again every
        HELD_STATE_PERIOD s meanwhile (a controller that missed it, or started late, gets
        a state to answer, so neither side waits for the other for ever)."""
        now = time.monotonic()
        if now - self._held_published >= HELD_STATE_PERIOD:
            self._held_published = now
            self.integrator.republish()
        self._sleep(HELD_STATE_PERIOD)     # woken at once by the next accepted effort

    def _sleep(self, seconds: float) -> None:
        if self._wake.wait(seconds):
            self._wake.clear()

    def _serve_requests(self) -> None:
        with self._requests_lock:
            requests, self._requests = self._requests, []
        for done, answer in requests:
            try:
                answer[1] = self.integrator.reset()
                answer[0] = True
            except Exception as exc:   # noqa: BLE001 (answered: the service says why)
                answer[1] = f'reset failed: {type(exc).__name__}: {exc}'
            finally:
                done.set()
        self.pacer.restart()
        self._held_published = time.monotonic()     # reset() published the state
