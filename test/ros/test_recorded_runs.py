"""The Fig. 4 demo and cog_id_player: every setpoint answered and recorded, or a non-zero exit
that says where they went (the issue "Reliability 2", item 13).

The demo runs as a user runs it (``python -m cog_id_ros.demos.fig4`` from this checkout);
losses are forced by stopping a process with SIGSTOP for a while, the way a loaded machine
stops it, only longer. The CPU hogs and stopped processes are this test's own children
and always ended.
"""
from cog_id_ros.ros.recorder import Account, account

# --- the account: where missing setpoints went (no ROS) ---------------------------------------


def test_account_places_every_missing_setpoint():
    """Reliability 2, item 13: the three numbers (sent, the node's counters, recorded) say
    whether the node or the recorder lost a setpoint; the places add up to what is missing."""
    full = account('/a', 2001, 2001, None, {'setpoints_accepted': 2001,
                                            'setpoints_rejected': 0, 'setpoints_lost': 0})
    assert full.complete and full.losses() == ''
    # the node's counters run since its start: a report before the run is subtracted
    before = {'setpoints_accepted': 50, 'setpoints_rejected': 2, 'setpoints_lost': 1}
    after = {'setpoints_accepted': 50 + 1640, 'setpoints_rejected': 2 + 3,
             'setpoints_lost': 1 + 16}
    mixed = account('/a', 2001, 1297, before, after)
    assert (mixed.accepted, mixed.rejected, mixed.lost) == (1640, 3, 16)
    assert not mixed.complete
    text = mixed.losses()
    assert 'node: 16 setpoints lost before the node took them' in text
    assert 'node: 3 setpoints rejected' in text
    assert 'node: 342 setpoints never reached the node' in text       # 2001 - 1640 - 3 - 16
    assert 'recorder: 343 efforts the node sent were not recorded' in text
    assert 16 + 3 + 342 + 343 == 2001 - 1297
    # no report from the node: the loss is still a loss, its place unknown
    blind = account('/a', 2001, 1990, None, None)
    assert not blind.complete and '11 of 2001 setpoints have no recorded effort' in blind.losses()
    # counters that do not add up are not guessed into a place
    odd = Account('/a', 2001, 1990, accepted=2005, rejected=0, lost=0)
    assert 'do not tell where' in odd.losses()
    # a full recording with a node that says it dropped some is not complete either
    assert not Account('/a', 2001, 2001, accepted=2001, rejected=0, lost=3).complete
