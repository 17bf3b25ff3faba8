"""cog_id_node as a managed node (``managed:=true``): rclpy's lifecycle node.

:class:`ManagedCogIdNode` is the node of :mod:`.node` with rclpy.lifecycle's state machine
and its services (``~/change_state``, ``~/get_state``, ``~/get_available_states``,
``~/get_available_transitions``, ``~/get_transition_graph``). It starts unconfigured with
nothing but those services. ``configure`` declares the parameters (the first time; they
stay read-only), loads the mechanism and makes everything that serves (solvers with their
kernels compiled, topics, the setpoint and measured state threads, the trajectory
process, timers); ``activate`` opens the stream: until then nothing is published
(setpoints and measured states that arrive are dropped, /diagnostics is silent);
``deactivate`` publishes ``timeout_behavior``'s command once, at the last pose served (or
measured), and then nothing; ``cleanup`` releases what configure made (threads, the
trajectory process, topics, timers, solvers); ``shutdown`` does the same from any state
(from active, after the command deactivate publishes). A transition that is not
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
        self._overrides: dict[str, Any] | None = None     # given values, once declared
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
        try:
            if self._overrides is None:
                self._overrides = self._read_parameters(self._command_line,
                                                        contextlib.nullcontext)
            self._make(self._overrides, contextlib.nullcontext)
            if not self._refusing:
                self.refuse_changes()
            self._made = True
            CogIdNode.start(self)
        except (MechanismConfigError, CogIdError) as exc:
            self.get_logger().error(f'configure failed: {exc}')
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info('configured: activate to serve')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
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

    def _leave_active(self, now: str) -> None:
        """Stop serving and publish timeout_behavior's command once (deactivate, or shutdown
        from active: the motors are not left with the last command)."""
        with self.lock:
            self.active = False
            stream = self.measurements if self.measurements is not None else self.setpoints
            what = self.apply_timeout_behavior(stream.last_pose)
        self.get_logger().info(f'{now}: {what or "nothing published"}, then nothing')

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        self.get_logger().info('cleaned up: configure to load again')
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.active:
            self._leave_active('shutting down')
        self.active = False
        if self._made:
            self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        if self._made:
            self._release()
        return TransitionCallbackReturn.SUCCESS

    def _release(self) -> None:
        """Stop the threads and the trajectory process, destroy the topics and timers, drop
        the solvers: what configure made."""
        self.active = False
        self._made = False
        CogIdNode.stop(self)
        for timer in self.timers_made:
            self.destroy_timer(timer)
        for publisher in (self.command_pub, self.effort_pub, self.joint_states_pub,
                          self.trajectory_pub, self.diagnostics.publisher):
            if publisher is not None:
                self.destroy_publisher(publisher)
        for loop in (self.setpoint_loop, self.measurement_loop):
            if loop is not None:
                self.destroy_subscription(loop.subscription)
        self.destroy_subscription(self.trajectory_sub)
        self.timers_made = []
        for made in ('solver', 'report', 'mode'):     # the kernels go with them
            self.__dict__.pop(made, None)
