"""cog_id_node as a managed node (``managed:=true``): rclpy's lifecycle node.

:class:`ManagedCogIdNode` is the node of :mod:`.node` with rclpy.lifecycle's state machine
and its services (``~/change_state``, ``~/get_state``, ``~/get_available_states``,
``~/get_available_transitions``, ``~/get_transition_graph``). It starts unconfigured with
nothing but those services. ``configure`` declares the parameters (the first time; they
stay read-only), loads the mechanism and makes everything that serves (solvers with their
kernels compiled, topics, the setpoint and measured state threads, the trajectory
process, timers), again at every configure (a configure that failed, e.g. on a URDF not
there yet, is logged and may be tried again); ``activate`` opens the stream: until then
nothing is published (setpoints and measured states that arrive are counted, not served,
/diagnostics is silent);
``deactivate`` publishes ``timeout_behavior``'s command at the last pose served (or
measured) and again every ``inactive_period`` while inactive: an inactive controller holds
the mechanism as a drive's brakes would (a plant that zeroes efforts when commands stop
would otherwise let it fall); setpoints and measured states that arrive meanwhile are
counted (``*_while_inactive``), not served; ``cleanup`` releases what configure made
(threads, the trajectory process, topics, timers, solvers); ``shutdown`` does the same from
any state (from active, after the command deactivate publishes, once) and ends the
process. A transition that is not
available from the current state is answered ``success: false``.
"""
import contextlib
from typing import Any, Callable, ContextManager, Sequence

from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn

from ..core import CogIdError, MechanismConfigError
from .node import CogIdNode


class ManagedCogIdNode(LifecycleNodeMixin, CogIdNode):
    """cog_id_node under a lifecycle state machine (built at configure, serving while
    active)."""

    def __init__(self, command_line: Sequence[str] | None = None,
                 interruptible: Callable[[], ContextManager] = contextlib.nullcontext,
                 **kwargs: Any) -> None:
        self.active = False
        self._made = False
        self._command_line = command_line
        CogIdNode.__init__(self, command_line, interruptible, build=False, **kwargs)
        LifecycleNodeMixin.__init__(self)
        service = self._service_change_state
        service.callback = self._refusing_unavailable(service.callback)

    def _refusing_unavailable(self, change_state: Callable[[Any, Any], Any]
                              ) -> Callable[[Any, Any], Any]:
        """~/change_state with a transition id that is not available from the current state
        answered ``success: false`` (and logged). rclpy raises instead (ros2/rclpy#1209):
        the request then got no answer, and before the first configure the process ended."""
        def serve(request: Any, response: Any) -> Any:
            wanted = request.transition.id
            available = {t[0]: t[1] for t in self._state_machine.available_transitions}
            if not request.transition.label and wanted not in available:
                state = self._state_machine.current_state[1]
                self.get_logger().warning(
                    f'change_state: transition {wanted} is not available in state {state}: '
                    'refused (available: ' + ', '.join(f'{i} {label}' for i, label in
                                                       sorted(available.items())) + ')')
                response.success = False
                return response
            return change_state(request, response)
        return serve

    def internal_error(self, where: str, exc: BaseException) -> None:
        if 'counts' not in self.__dict__:       # before the first configure: nothing to count
            self.get_logger().error(f'{where} failed: {type(exc).__name__}: {exc}')
            return
        CogIdNode.internal_error(self, where, exc)

    # --- the node's threads: started at configure, not by main() --------------------------

    def start(self) -> None:
        """Nothing: the threads start at configure."""

    def stop(self) -> list[str]:
        return CogIdNode.stop(self) if self._made else []

    def destroy_node(self) -> None:
        if self._made:
            self._release()
        super().destroy_node()

    # --- transitions ------------------------------------------------------------------------

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the mechanism and make everything that serves. A failure (a URDF not there
        yet, a gain out of range, anything else) is logged, what was made is released, and
        the node stays unconfigured: configure may be tried again (it reads the parameters
        as given again; those the failed attempt declared stay declared, read-only)."""
        try:
            overrides = self._read_parameters(self._command_line, contextlib.nullcontext)
            self._made = True          # (released below if what follows fails)
            self._make(overrides, contextlib.nullcontext)
            if not self._refusing:
                self.refuse_changes()
            CogIdNode.start(self)
        except Exception as exc:   # noqa: BLE001 (every failure: logged, released, FAILURE)
            what = str(exc) if isinstance(exc, (MechanismConfigError, CogIdError)) else \
                f'{type(exc).__name__}: {exc}'
            self.get_logger().error(f'configure failed: {what}; configure may be tried again')
            self._release()
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info('configured: activate to serve')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_holding()
        with self.lock:
            # a new stream: no estimate, jump or unwrap across the inactive time
            self.setpoints.stopped = True
            self.setpoints.filter.reset()
            if self.measurements is not None:
                self.measurements.stopped = True
            self.active = True
        self.get_logger().info('active: serving')
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._leave_active('inactive')
        return TransitionCallbackReturn.SUCCESS

    def _leave_active(self, now: str, hold: bool = True) -> None:
        """Stop serving and publish timeout_behavior's command (deactivate, or shutdown
        from active: the motors are not left with the last command); with ``hold`` and an
        inactive_period, again every period while inactive (a drive's brakes)."""
        with self.lock:
            self.active = False
            stream = self.measurements if self.measurements is not None else self.setpoints
            what = self.apply_timeout_behavior(stream.last_pose)
        period = self.config.inactive_period
        if hold and period > 0.0 and self.timeout_command is not None:
            self._holding = self.create_timer(period, self._hold_while_inactive)
            then = f'again every {period:g} s until activate, cleanup or shutdown'
        else:
            then = 'then nothing'
        log = self.get_logger().warning if self.config.timeout_behavior == 'zero' and hold \
            else self.get_logger().info
        log(f'{now}: {what or "nothing published"}, {then}'
            + ('; zero efforts: the mechanism is not held (it may fall)'
               if self.config.timeout_behavior == 'zero' else ''))

    def _hold_while_inactive(self) -> None:
        """Inactive: timeout_behavior's command again (the one deactivate published)."""
        command = getattr(self, 'timeout_command', None)
        if command is not None and not self.active and self._made:
            self.command_pub.publish(command)

    def _stop_holding(self) -> None:
        timer = self.__dict__.pop('_holding', None)
        if timer is not None:
            self.destroy_timer(timer)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_holding()
        self._release()
        self.get_logger().info('cleaned up: configure to load again')
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """From any state: from active the command of timeout_behavior once; then what
        configure made is released, and the process ends (main() spins until
        ``finished``)."""
        self._stop_holding()
        if self.active:
            self._leave_active('shutting down', hold=False)
        self.active = False
        if self._made:
            self._release()
        self.finished = True
        self.get_logger().info('finalized: the process ends')
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_holding()
        self.active = False
        if self._made:
            self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        """Stop the threads and the trajectory process, destroy the topics and timers, drop
        the solvers: what configure made, as far as it got (a configure that failed half
        way is released too)."""
        self.active = False
        self._made = False
        made = self.__dict__
        if 'trajectory_worker' in made:
            CogIdNode.stop(self)
        else:
            for loop in (made.get('setpoint_loop'), made.get('measurement_loop')):
                if loop is not None:
                    loop.stop()
        if made.get('floating') is not None:    # its thread, topics and run-time parameter
            made.pop('floating').release()
        for timer in made.get('timers_made', []):
            self.destroy_timer(timer)
        diagnostics = made.get('diagnostics')
        for publisher in (made.get('command_pub'), made.get('effort_pub'),
                          made.get('joint_states_pub'), made.get('trajectory_pub'),
                          None if diagnostics is None else diagnostics.publisher):
            if publisher is not None:
                self.destroy_publisher(publisher)
        for loop in (made.get('setpoint_loop'), made.get('measurement_loop')):
            if loop is not None:
                self.destroy_subscription(loop.subscription)
        if made.get('trajectory_sub') is not None:
            self.destroy_subscription(made['trajectory_sub'])
        for name in ('solver', 'report', 'mode', 'timers_made', 'command_pub', 'effort_pub',
                     'joint_states_pub', 'trajectory_pub', 'diagnostics', 'setpoint_loop',
                     'measurement_loop', 'trajectory_sub', 'trajectory_worker'):
            made.pop(name, None)        # (the kernels go with the solvers)
