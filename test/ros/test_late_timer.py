"""LateTimer: the timeout timers' view of the node's own stalls, on a clock set by hand."""
import math

from cog_id_ros.ros.late_timer import LateTimer


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_runs_on_time_never_wait():
    clock = Clock()
    timer = LateTimer(0.025, clock)
    for _ in range(10):
        assert not timer.woke_late(heard=99.0)
        clock.now += 0.025
    assert timer.resumed == -math.inf


def test_a_late_run_waits_one_period_and_the_silence_counts_from_it():
    clock = Clock()
    timer = LateTimer(0.025, clock)
    timer.woke_late(heard=100.0)
    clock.now += 3.0                          # the process was stopped 3 s
    assert timer.woke_late(heard=100.0)       # wait a period for what was on its way
    assert timer.resumed == clock.now
    clock.now += 0.025
    assert not timer.woke_late(heard=100.0)   # then judge, the silence counted from resumed


def test_the_wait_is_granted_once_per_silence():
    """On a machine loaded for good every run is late: one wait, then no more until a
    message is accepted (``heard`` moves past the wait); then one again."""
    clock = Clock()
    timer = LateTimer(0.025, clock)
    timer.woke_late(heard=100.0)
    waits = []
    for _ in range(20):
        clock.now += 0.06                     # every run more than two periods late
        waits.append(timer.woke_late(heard=100.0))
    assert waits.count(True) == 1 and waits[0], waits
    first = timer.resumed
    clock.now += 0.06
    assert timer.woke_late(heard=clock.now - 0.01)    # heard after the wait: a new silence
    assert timer.resumed > first


def test_no_message_ever_heard_still_waits_after_a_stall():
    clock = Clock()
    timer = LateTimer(0.1, clock)
    timer.woke_late(heard=None)
    clock.now += 1.0
    assert timer.woke_late(heard=None)
