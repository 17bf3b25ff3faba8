"""The straight-line per-sample code agrees with the general lane path, and hands over to it.

sample_program.py promises the same operations in the same order as the float path, so
the comparisons here are exact up to a few ulps, not a tolerance of the method.
"""
import math

import numpy as np
import pytest

import cog_id_ros
from cog_id_ros.core.continuation import prediction
from cog_id_ros.core.sample_program import SampleProgram
from cog_id_ros.core.straight_line import Graph, Sym, SymOps, compile_function
from mechanisms import four_bar, from_yaml
from trajectories import TRAJECTORIES, config_path, sample

NON_REDUNDANT = [name for name in TRAJECTORIES
                 if not cog_id_ros.Mechanism.from_params_file(config_path(name)).is_redundant]


def solvers(params):
    mechanism = cog_id_ros.Mechanism.from_parameters(params)
    fast = cog_id_ros.InverseDynamics(mechanism)
    general = cog_id_ros.InverseDynamics(mechanism)
    general._program = None
    return fast, general


class Counting:
    """Wraps a SampleProgram and counts the samples it served itself."""

    def __init__(self, program):
        self.program, self.served, self.handed_over, self.stepped = program, 0, 0, 0

    def step(self, *args):
        """The unrolled glue: served here, or (None) left to the loops of torques()."""
        done = self.program.step(*args)
        if done is not None:
            self.served += 1
            self.stepped += 1
        return done

    def solve(self, *args):
        done = self.program.solve(*args)
        if done is None:
            self.handed_over += 1
        else:
            self.served += 1
        return done


@pytest.mark.parametrize('name', NON_REDUNDANT)
def test_straight_line_torques_equal_the_general_path_at_control_rate(name):
    fast, general = solvers(from_yaml(config_path(name)))
    assert isinstance(fast._program, SampleProgram)
    counter = fast._program = Counting(fast._program)
    _, q, qd, qdd = sample(name, 2001)           # 1 kHz along the test motion
    peak = 0.0
    for k in range(0, 2001, 4):
        a, b = fast.torques(q[k], qd[k], qdd[k]), general.torques(q[k], qd[k], qdd[k])
        peak = max(peak, np.max(np.abs(b)))
        assert np.max(np.abs(a - b)) <= 1e-13 * max(peak, 1.0), k
        assert np.allclose(fast._state[0], general._state[0], rtol=0, atol=1e-13)
    assert counter.served >= 495 and counter.handed_over <= 6
    assert counter.stepped >= 490       # nearly every sample takes the unrolled glue


@pytest.mark.parametrize('name', NON_REDUNDANT)
def test_unrolled_step_is_the_glue_to_the_last_bit(name):
    """step() and the loops of torques() give identical torques and states, sample by sample."""
    fast, _ = solvers(from_yaml(config_path(name)))
    program = fast._program
    _, q, qd, qdd = sample(name, 2001)          # 1 kHz, as in the test above
    served = 0
    for k in range(0, 2001, 2):
        target, v, a = q[k].tolist(), qd[k].tolist(), qdd[k].tolist()
        state = fast._state
        stepped = program.step(state, target, v, a, fast._limits, fast._bounds)
        looped = program.solve(prediction(fast.mechanism, state, target)[0], v, a)
        if stepped is not None:
            served += 1
            assert list(stepped[0]) == list(looped[0]), k
            assert stepped[1][0] == looped[1][0] and stepped[1][1] == looped[1][1], k
        fast.torques(q[k], qd[k], qdd[k])
    assert served >= 990


def test_far_setpoint_takes_the_same_continuation_steps_as_the_general_path():
    fast, general = solvers(from_yaml('config/paper_four_bar_a.yaml'))
    start = fast._state[0][fast.mechanism.active_index[0]]
    counter = fast._program = Counting(fast._program)
    a, b = fast.torques([2.5], [0.3], [1.0]), general.torques([2.5], [0.3], [1.0])
    assert np.max(np.abs(a - b)) <= 1e-13 * max(1.0, np.max(np.abs(b)))
    assert counter.served == math.ceil(abs(2.5 - start) / fast.continuation_step - 1e-9) > 3
    assert counter.handed_over == 0


def test_singular_and_unreachable_poses_raise_the_general_errors_and_keep_the_state():
    fast, _ = solvers(from_yaml('config/paper_four_bar_a.yaml'))
    fast.torques([0.05], [0.0], [0.0])
    state = fast._state
    assert fast._program.solve(prediction(fast.mechanism, state, [0.0])[0], [0.0], [0.0]) is None
    with pytest.raises(cog_id_ros.SingularConfigurationError):
        fast.torques([0.0], [0.0], [0.0])
    assert fast._state is state

    fast, _ = solvers(four_bar(ground=0.9, active=('joint1',), init=[1.2, -1.2332, 2.0244, 2.0576]))
    for target in np.arange(1.2, 1.8, 0.02):   # the loop closes up to 1.504 rad, then no more
        try:
            fast.torques([target], [0.0], [0.0])
        except cog_id_ros.CogIdError:
            assert target > 1.45
            break
    else:
        pytest.fail('the crank went past where the loop can close')
    assert np.all(np.isfinite(fast.torques([1.3], [0.0], [0.0])))


def test_redundant_mechanisms_keep_the_general_path():
    mechanism = cog_id_ros.Mechanism.from_params_file('config/five_bar_redundant.yaml')
    assert cog_id_ros.InverseDynamics(mechanism)._program is None


def test_one_trace_serves_every_solver_of_a_mechanism():
    mechanism = cog_id_ros.Mechanism.from_params_file('config/slider_crank.yaml')
    assert cog_id_ros.InverseDynamics(mechanism)._program is \
        cog_id_ros.InverseDynamics(mechanism)._program


# --- the tracer ----------------------------------------------------------------------------

def test_constants_fold_and_common_subexpressions_are_shared():
    g = Graph()
    x, y = g.inputs('v', 2)
    assert x * 0.0 == 0.0 and 0 * x == 0.0
    assert x * 1.0 is x and x + 0.0 is x and 0 + x is x and x - 0.0 is x and x / 1.0 is x
    assert (x - x) == 0.0
    assert (-(-x)).k == x.k
    assert (x * y).k == (x * y).k and (x * y).k != (y * x).k
    assert sum([x, 0.0, y]).k == (x + y).k
    with pytest.raises(TypeError, match='branch-free'):
        bool(x < 1.0)


def test_compiled_function_computes_what_floats_compute():
    g = Graph()
    a, b = g.inputs('a', 1), g.inputs('b', 2)

    def f(ops, u, v, w):
        s = ops.sqrt(u * v - w)
        return [s * ops.recip(w), ops.sin(u) * 2.0 - ops.cos(v) / 3.0, 1.5 - u, -v * 0.0 + w]

    outputs = f(SymOps, a[0], b[0], b[1])
    fn, source, count = compile_function('f', [('a', a), ('b', b)], outputs)
    assert count == 11 and source.count('\n') == count + 4

    class Floats:
        sin, cos = staticmethod(math.sin), staticmethod(math.cos)
        sqrt = staticmethod(lambda x: math.sqrt(x) if x >= 0.0 else math.nan)
        recip = staticmethod(lambda x: 1.0 / x if x != 0.0 else math.inf)

    for u, v, w in [(1.3, 0.7, 0.2), (0.1, 0.2, 5.0), (2.0, 3.0, 0.0)]:
        expected = f(Floats, u, v, w)
        got = fn([u], [v, w])
        for e, x in zip(expected, got):
            assert (math.isnan(e) and math.isnan(x)) or e == x


@pytest.mark.parametrize('name', list(TRAJECTORIES))
def test_sample_torques_is_torques_without_numpy(name):
    """Lists in, a list out: the same numbers and state as torques(), redundant ones too."""
    mechanism = cog_id_ros.Mechanism.from_params_file(config_path(name))
    lists, arrays = cog_id_ros.InverseDynamics(mechanism), cog_id_ros.InverseDynamics(mechanism)
    _, q, qd, qdd = sample(name, 2001)
    for k in range(0, 2001, 5):
        got = lists.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        assert type(got) is list and all(type(x) is float for x in got)
        assert got == arrays.torques(q[k], qd[k], qdd[k]).tolist(), k
    assert lists._state[0] == arrays._state[0]


def test_sample_torques_reports_bad_input_like_torques_and_keeps_the_state():
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(
        'config/paper_four_bar_a.yaml'))
    solver.sample_torques([1.5], [0.0], [0.0])
    state = solver._state
    for q, qd, qdd in (([math.nan], [0.0], [0.0]), ([1.5], [math.inf], [0.0]),
                       ([1.5], [0.0], [math.nan]), ([1.5, 1.0], [0.0], [0.0]),
                       (['x'], [0.0], [0.0])):
        with pytest.raises(cog_id_ros.SetpointError):
            solver.sample_torques(q, qd, qdd)
        assert solver._state is state
    with pytest.raises(cog_id_ros.SingularConfigurationError):
        solver.sample_torques([0.0], [0.0], [0.0])
    assert solver._state is state
    assert solver.sample_torques([1.5], None, None) == solver.torques([1.5]).tolist()
