"""The closed-loop demo's player says every loss (cog_id_ros/demos/sim_player.py): its
accounting alone, on made-up records (no ROS; the demo itself runs over real topics with
``./dev control``)."""
import threading

from cog_id_ros.demos.sim_player import NS, SimPlayer

STEP = 1_000_000        # ns: 1 ms


def player(feedback, sent=0, baseline=None, counters=None):
    p = SimPlayer.__new__(SimPlayer)       # no node: only what _lost reads
    p.feedback, p.step_ns, p.t0_ns, p.start_ns = feedback, STEP, 7 * STEP, 0
    p.target = (lambda t: ([0.0], [0.0])) if sent else None
    p.sent, p.baseline, p.counters = sent, baseline, counters
    p.lock = threading.Lock()
    return p


def states(steps, skip=()):
    return [(k * STEP, [0.0]) for k in range(steps + 1) if k not in skip]


def test_a_whole_run_loses_nothing():
    base = {'setpoints_accepted': 5, 'setpoints_rejected': 0, 'setpoints_lost': 0}
    now = dict(base, setpoints_accepted=5 + 11)
    p = player(True, sent=11, baseline=base, counters=now)
    assert p._lost(states(10), 10 * STEP / NS, [], 11) == []


def test_a_missing_step_an_unanswered_state_and_an_unaccepted_setpoint_are_said():
    base = {'setpoints_accepted': 5, 'setpoints_rejected': 0, 'setpoints_lost': 0}
    now = dict(base, setpoints_accepted=5 + 9, setpoints_lost=1)
    p = player(True, sent=11, baseline=base, counters=now)
    lines = p._lost(states(10, skip={4}), 10 * STEP / NS, [p.t0_ns + 3 * STEP], 11)
    assert len(lines) == 3, lines
    assert '1 of 11 simulated steps missing' in lines[0] and 't = 0.004 s' in lines[0]
    assert '1 of 11 measured states' in lines[1] and 't = 0.003 s' in lines[1]
    assert '11 setpoints sent, cog_id_node accepted 9' in lines[2] and '1 lost' in lines[2]


def test_no_report_of_the_node_is_a_loss_too():
    p = player(False, sent=3, baseline=None, counters=None)
    lines = p._lost(states(2), 2 * STEP / NS, [], 3)
    assert lines == ['no /diagnostics of cog_id_node to count the setpoints by']


def test_nothing_asked_is_a_loss():
    p = player(True)
    assert 'left without their effort_command' in p._lost(states(2), 2 * STEP / NS, [], 0)[0]
