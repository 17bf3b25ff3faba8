"""cog_sim_node's parts without DDS: effort messages checked (every reason), the held
efforts (clipping, the stream that stops), the pacer, the parameter and topic tables."""
import math
import os

import numpy as np
import pytest

pytest.importorskip('rclpy')

from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from cog_id_ros import MechanismConfigError  # noqa: E402
from cog_id_ros.ros import parameters, sim_parameters, sim_topics  # noqa: E402
from cog_id_ros.ros.conversions import JointSelector  # noqa: E402
from cog_id_ros.ros.sim_efforts import (  # noqa: E402
    EFFORT_REASONS,
    EffortHold,
    EffortRejected,
    command_efforts,
    named_efforts,
)
from cog_id_ros.ros.sim_loop import MAX_LAG, Pacer  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ACTIVE = ('a', 'b')


def array(*data):
    return Float64MultiArray(data=list(data))


def state(names, efforts, positions=()):
    return JointState(name=list(names), effort=list(efforts), position=list(positions))


def reason_of(call):
    with pytest.raises(EffortRejected) as error:
        call()
    assert error.value.reason in EFFORT_REASONS
    return error.value.reason


# --- messages ---------------------------------------------------------------------------------

def test_command_efforts_in_active_joint_order():
    assert command_efforts(array(1.5, -2.0), ACTIVE, 1e6) == [1.5, -2.0]


@pytest.mark.parametrize('data, reason', [
    ((1.0,), 'length'),
    ((1.0, 2.0, 3.0), 'length'),
    ((), 'length'),
    ((math.nan, 1.0), 'non_finite'),
    ((1.0, math.inf), 'non_finite'),
    ((1.0, -math.inf), 'non_finite'),
    ((1e300, 0.0), 'magnitude'),
    ((0.0, -1.0000001e6), 'magnitude'),
])
def test_command_efforts_rejected(data, reason):
    assert reason_of(lambda: command_efforts(array(*data), ACTIVE, 1e6)) == reason


def test_magnitude_bound_is_inclusive_and_infinite_means_no_check():
    assert command_efforts(array(1e6, -1e6), ACTIVE, 1e6) == [1e6, -1e6]
    assert command_efforts(array(1e300, 0.0), ACTIVE, math.inf) == [1e300, 0.0]


def test_named_efforts_by_name_any_order_extra_names_ignored():
    selector = JointSelector(ACTIVE)
    msg = state(['x', 'b', 'a'], [9.0, 2.0, 1.0], positions=[math.nan] * 3)
    assert named_efforts(msg, selector, 1e6) == [1.0, 2.0]


@pytest.mark.parametrize('names, efforts, reason', [
    (['a'], [1.0], 'names'),                    # b missing
    (['a', 'c'], [1.0, 2.0], 'names'),          # names that do not match
    (['a', 'a', 'b'], [1.0, 1.0, 2.0], 'names'),
    ([], [], 'names'),
    (['a', 'b'], [1.0], 'length'),
    (['a', 'b'], [], 'length'),
    (['a', 'b'], [1.0, math.nan], 'non_finite'),
    (['b', 'a'], [1e300, 1.0], 'magnitude'),
    (['x', 'a', 'b'], [math.nan, 1.0, 2.0], None),   # another joint's NaN is not read
])
def test_named_efforts_rejected(names, efforts, reason):
    call = lambda: named_efforts(state(names, efforts), JointSelector(ACTIVE), 1e6)  # noqa: E731
    if reason is None:
        assert call() == [1.0, 2.0]
    else:
        assert reason_of(call) == reason


# --- the held efforts -------------------------------------------------------------------------

def test_hold_zeros_until_first_message_then_newest():
    hold = EffortHold(2, 0.5, 'zero', None)
    assert hold.acting(0.0) == [0.0, 0.0] and hold.state() == 'no effort yet'
    hold.accept([1.0, 2.0], 0.1)
    hold.accept([3.0, 4.0], 0.1)
    assert hold.acting(0.2) == [3.0, 4.0] and hold.state() == 'receiving'


@pytest.mark.parametrize('behavior, after', [('zero', [0.0, 0.0]), ('hold', [3.0, 4.0])])
def test_stream_that_stops(behavior, after):
    hold = EffortHold(2, 0.5, behavior, None)
    hold.accept([3.0, 4.0], 1.0)
    assert hold.acting(1.499) == [3.0, 4.0] and hold.timeouts == 0
    assert hold.acting(1.5) == after and hold.timeouts == 1
    assert hold.acting(9.0) == after and hold.timeouts == 1     # counted once
    assert hold.state() == f'stopped ({behavior})'
    hold.accept([5.0, 6.0], 9.0)                                # a new stream
    assert hold.acting(9.1) == [5.0, 6.0] and hold.state() == 'receiving'
    hold.reset()
    assert hold.acting(0.0) == [0.0, 0.0] and hold.state() == 'no effort yet'


def test_no_timeout_holds_for_ever():
    hold = EffortHold(1, 0.0, 'zero', None)
    hold.accept([2.0], 0.0)
    assert hold.acting(1e6) == [2.0] and hold.timeouts == 0


def test_clipped_to_effort_limits():
    hold = EffortHold(2, 0.5, 'zero', np.array([1.0, math.inf]))
    assert hold.accept([-5.0, 50.0], 0.0) is True
    assert hold.acting(0.0) == [-1.0, 50.0]
    assert hold.accept([0.5, 50.0], 0.0) is False


# --- the pacer --------------------------------------------------------------------------------

class FakeClock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_pacer_real_time_and_faster():
    clock = FakeClock()
    pacer = Pacer(0.001, 2.0, clock)      # a step every 0.5 ms of wall time
    assert pacer.wait() == pytest.approx(0.0)
    pacer.stepped()
    assert pacer.wait() == pytest.approx(0.0005)
    clock.now += 0.0005
    assert pacer.wait() == pytest.approx(0.0)
    assert Pacer(0.001, 0.0, clock).wait() == 0.0     # as fast as possible


def test_pacer_does_not_sprint_after_a_pause():
    clock = FakeClock()
    pacer = Pacer(0.001, 1.0, clock)
    for _ in range(10):
        pacer.stepped()
    clock.now += 0.011                     # one step behind: caught up, not restarted
    assert pacer.wait() < 0.0 and pacer.lag_restarts == 0
    clock.now += MAX_LAG + 1.0             # the machine paused
    assert pacer.wait() == 0.0 and pacer.lag_restarts == 1
    pacer.stepped()
    assert pacer.wait() == pytest.approx(0.001)


# --- the tables -------------------------------------------------------------------------------

@pytest.mark.parametrize('module', [sim_parameters, sim_topics], ids=['parameters', 'topics'])
def test_docs_table_is_the_generated_one(module):
    with open(os.path.join(REPO, 'docs', 'sim_node.md'), encoding='utf-8') as stream:
        text = stream.read()
    name = module.__name__
    assert parameters.generated_block(text, name) == module.markdown_table(), (
        f'docs/sim_node.md differs from the table in the code: run '
        f'python -m {name} --write docs/sim_node.md')


def test_every_parameter_default_passes_its_check():
    for name, param in sim_parameters.SIM_PARAMETERS.items():
        assert param.name == name and param.description and param.type
        param.check(param.default, ['revolute'])


def test_no_parameter_of_both_nodes_means_two_things():
    """One parameter file serves both nodes: a name both declare is the same entry (or
    the same check with a description of its own)."""
    for name, param in sim_parameters.SIM_PARAMETERS.items():
        other = parameters.NODE_PARAMETERS.get(name)
        if other is not None:
            assert (other.kind, other.default, other.low, other.high, other.choices) == \
                (param.kind, param.default, param.low, param.high, param.choices), name


@pytest.mark.parametrize('name, value, message', [
    ('real_time_factor', -1.0, 'must be from 0.001 to 1000 (or 0: as fast as possible), got -1.0'),
    ('time_step', 0.0, 'must be from 1e-06 to 1 s, got 0.0'),
    ('effort_timeout_behavior', 'none', "must be one of zero, hold, got 'none'"),
    ('publish_clock', 'yes', "must be true or false, got 'yes'"),
    ('max_effort', 0.0, 'must be from 1e-06 to inf N m or N (or .inf: no check), got 0.0'),
])
def test_checks_name_the_parameter(name, value, message):
    with pytest.raises(MechanismConfigError) as error:
        sim_parameters.SIM_PARAMETERS[name].check(value, ['revolute'])
    assert error.value.parameter == name and message in str(error.value)
