"""What cog_sim_node counts and reports on /diagnostics (``SIM_DIAGNOSTIC_KEYS``).

:class:`EffortCounts` counts the effort messages (accepted, rejected by reason, clipped);
:class:`SimReport` makes the node's DiagnosticStatus from them, the integrator's snapshot
and the real-time factor achieved since the last report. The publisher, the guard of the
callbacks and the throttled warnings are cog_id_node's (:mod:`.diagnostics`).
"""
import collections
import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from .diagnostics import ThrottledWarnings
from .sim_efforts import EFFORT_REASONS
from .sim_loop import MAX_LAG

#: keys of /diagnostics besides rejected.<reason> (one per reason of EFFORT_REASONS)
SIM_DIAGNOSTIC_KEYS = {
    'mechanism': 'the mechanism name',
    'active_joints': 'the active joints, in effort order',
    'backend': "who computes the kernels: native, python or reference (parameter 'backend')",
    'integrating': 'true while the simulation steps; false once an error stopped it (the '
                   'status is ERROR and names it) until ~/reset',
    'sim_time': 's of simulated time since start or the last reset',
    'steps': 'steps since start or the last reset',
    'time_step': 's per step (parameter time_step)',
    'real_time_factor': 'the factor asked for (parameter real_time_factor; 0: as fast as '
                        'possible)',
    'real_time_factor_achieved': 'simulated seconds per wall-clock second since the last '
                                 'report (empty while stopped)',
    'lag_restarts': f'times the simulation fell more than {MAX_LAG:g} s behind its schedule and '
                    'went on from there instead of catching up',
    'closure_residual': 'largest closure equation residual at the simulated pose, m or rad',
    'error_estimate_last': "the last step's error estimate (the Simulation's tolerance "
                           'measure, docs/simulation.md: "Error control and diagnostics")',
    'error_estimate_total': 'error estimates summed since start or the last reset',
    'divided_steps': 'steps divided into substeps to keep the estimate within the tolerance',
    'near_singular_substeps': 'substeps that passed close to a singular pose',
    'inaccurate_substeps': 'substeps accepted with their rounding near a singular pose '
                           'reported (not within the tolerance)',
    'condition_number': 'condition number of the closure at the simulated pose',
    'energy': 'kinetic plus potential energy of the model, J',
    'work': "the efforts' work since start or the last reset, J",
    'energy_drift': 'energy - energy at start - work: what the integration gained (or '
                    'lost) on its own, J',
    'efforts_accepted': 'effort messages accepted since start (both topics)',
    'efforts_rejected': 'effort messages rejected since start (sum of rejected.<reason>)',
    'efforts_lost': 'effort messages the single publisher of a topic sent that never '
                    'reached the node (gaps in its sequence numbers: a flood beyond the '
                    'subscription queue, a stalled node)',
    'effort_clipped': 'accepted effort messages clipped to effort_limits',
    'effort_stream': "'no effort yet', 'receiving', or 'stopped (zero|hold)' after "
                     'effort_timeout',
    'effort_timeouts': 'times the effort stream stopped',
    'resets': 'calls of ~/reset that reset the simulation',
    'stops': 'times an error stopped the integration',
    'stop_reason': 'why the integration stopped (empty while it integrates)',
    'internal_errors': 'exceptions the node caught in its own callbacks (a bug: please report)',
    'nodes_with_this_name': "nodes in the ROS graph with this node's name and namespace",
    'joint_states_publishers': 'publishers of joint_states in the namespace, this node '
                               "included (more than 1: another node's poses are mixed with "
                               "the simulated ones, e.g. cog_id_node's: set its "
                               'joint_states_decimation to 0)',
    'last_rejection': 'reason and message of the last rejected effort message',
}


#: the keys taken from the Simulation's diagnostics: key -> its field
_ACCURACY = {'error_estimate_last': 'error_estimate',
             'error_estimate_total': 'total_error_estimate', 'divided_steps': 'divided_steps',
             'near_singular_substeps': 'near_singular_substeps',
             'inaccurate_substeps': 'inaccurate_substeps', 'condition_number': 'condition_number',
             'energy': 'energy', 'work': 'work', 'energy_drift': 'energy_drift'}


class EffortCounts:
    """The effort messages since start; callers hold the node's lock."""

    def __init__(self, warnings: ThrottledWarnings) -> None:
        self.warnings = warnings
        self.accepted = self.clipped = self.internal_errors = self.resets = 0
        self.rejected = collections.Counter(dict.fromkeys(EFFORT_REASONS, 0))
        self.lost = 0                       # effort messages lost (gaps in sequence numbers)
        self.last_rejection = ''
        self.period_problems = 0            # rejections and clipping since the last report

    def reject(self, reason: str, topic: str, text: str) -> None:
        """An effort message that is not integrated: counted, warned about (throttled)."""
        self.rejected[reason] += 1
        self.last_rejection = f'{reason}: {text}'
        self.period_problems += 1
        self.warnings.warn(reason, f'{topic} rejected, not integrated ({reason}): {text}')

    def count_lost(self, topic: str, lost: int) -> None:
        """``lost`` effort messages of ``topic`` never reached the node: counted, warned."""
        if lost:
            self.lost += lost
            self.period_problems += 1
            self.warnings.warn('lost.' + topic, f'{lost} {topic} message(s) lost before the '
                                                'node could take them (subscription queue '
                                                'full, or the node was stalled)')

    def accept(self, clipped: bool) -> None:
        self.accepted += 1
        if clipped:
            self.clipped += 1
            self.period_problems += 1

    def internal_error(self, where: str, exc: BaseException) -> None:
        self.internal_errors += 1
        self.period_problems += 1
        try:
            self.warnings.warn('internal.' + where, f'{where} failed (the node goes on): '
                               f'{type(exc).__name__}: {exc}', error=True)
        except Exception:   # noqa: BLE001 (counted: a failing log must not raise again)
            pass


class SimReport:
    """cog_sim_node's DiagnosticStatus. ``node`` offers ``mechanism``, ``config``,
    ``integrator``, ``pacer``, ``hold``, ``counts``, ``diagnostics`` (the publisher) and
    ``stopped_threads()``; ``clock`` is the wall clock of the real-time factor."""

    def __init__(self, node: Any, clock: Callable[[], float] = time.monotonic) -> None:
        self.node, self.clock = node, clock
        self._last: tuple[float, float, int] | None = None   # (wall, sim time, steps)

    def achieved_factor(self) -> str:
        """Simulated seconds per wall second since the last call ('' when none elapsed or
        the integration was stopped or reset in between)."""
        integrator = self.node.integrator
        now = (self.clock(), integrator.time, integrator.steps)
        last, self._last = self._last, now
        if last is None or integrator.error is not None or now[2] < last[2] \
                or now[0] <= last[0]:
            return ''
        return f'{(now[1] - last[1]) / (now[0] - last[0]):.4g}'

    def status(self, joint_states_publishers: int) -> DiagnosticStatus:
        node, integrator = self.node, self.node.integrator
        status = DiagnosticStatus()
        status.name = f'{node.get_fully_qualified_name()}: simulation'
        status.hardware_id = node.mechanism.name
        achieved = self.achieved_factor()
        status.level, status.message = self._level(achieved, joint_states_publishers)
        counts, config = node.counts, node.config
        values = [('mechanism', node.mechanism.name),
                  ('active_joints', ', '.join(config.active_joints)),
                  ('backend', node.simulation.backend),
                  ('integrating', str(integrator.error is None).lower()),
                  ('sim_time', f'{integrator.time:.6f}'),
                  ('steps', integrator.steps),
                  ('time_step', f'{config.time_step:g}'),
                  ('real_time_factor', f'{config.real_time_factor:g}'),
                  ('real_time_factor_achieved', achieved),
                  ('lag_restarts', node.pacer.lag_restarts),
                  ('closure_residual', f'{integrator.residual:.3g}'),
                  *self._accuracy(),
                  ('efforts_accepted', counts.accepted),
                  ('efforts_rejected', sum(counts.rejected.values())),
                  ('efforts_lost', counts.lost),
                  *((f'rejected.{reason}', n) for reason, n in counts.rejected.items()),
                  ('effort_clipped', counts.clipped),
                  ('effort_stream', node.hold.state()),
                  ('effort_timeouts', node.hold.timeouts),
                  ('resets', counts.resets),
                  ('stops', integrator.stops),
                  ('stop_reason', integrator.error or ''),
                  ('internal_errors', counts.internal_errors),
                  ('nodes_with_this_name', node.diagnostics.same_name_nodes),
                  ('joint_states_publishers', joint_states_publishers),
                  ('last_rejection', counts.last_rejection)]
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values]
        return status

    def _accuracy(self) -> list[tuple[str, str]]:
        """The Simulation's error estimates and energy, as taken by the integration thread
        after a step (empty before the first step and after a reset); the next one asked."""
        integrator = self.node.integrator
        taken, _ = integrator.sim_diagnostics, integrator.want_diagnostics()
        if taken is None:
            return [(key, '') for key in _ACCURACY]
        return [(key, f'{getattr(taken, field):.6g}' if isinstance(getattr(taken, field), float)
                 else str(getattr(taken, field))) for key, field in _ACCURACY.items()]

    def _level(self, achieved: str, joint_states_publishers: int) -> tuple[bytes, str]:
        """The level and message: the worst of what the period saw."""
        node, integrator = self.node, self.node.integrator
        problems, node.counts.period_problems = node.counts.period_problems, 0
        stopped = node.stopped_threads()
        if stopped:
            return DiagnosticStatus.ERROR, (f"stopped ({'; '.join(stopped)}): a bug, please "
                                            'report it; restart the node')
        if integrator.error is not None:
            return DiagnosticStatus.ERROR, (f'integration stopped ({integrator.error_reason}): '
                                            f'{integrator.error}; call ~/reset')
        if problems:
            return DiagnosticStatus.WARN, (f'{problems} effort message(s) rejected, clipped '
                                           'or lost, or internal errors, in the last period')
        if node.diagnostics.same_name_nodes > 1 or joint_states_publishers > 1:
            return DiagnosticStatus.WARN, ('another node publishes joint_states here, or has '
                                           "this node's name")
        target = node.config.real_time_factor
        if target > 0.0 and achieved and float(achieved) < 0.9 * target:
            return DiagnosticStatus.WARN, (f'behind real time: {achieved} of the '
                                           f'{target:g} asked for')
        return DiagnosticStatus.OK, f'integrating, effort stream: {node.hold.state()}'
