"""The backends compute the same numbers, and the one per-sample glue drives them all.

``backend='reference'`` runs the lane code on floats; ``backend='python'`` runs the same
code traced into straight-line kernels. They promise the same operations in the same order,
so the comparisons here are exact, not a tolerance of the method.
"""
import math
from typing import NamedTuple

from mechanisms import four_bar, from_yaml
import numpy as np
import pytest
from trajectories import TRAJECTORIES, config_path, sample

import cog_id_ros
from cog_id_ros.core.native.emitter import python_function, python_source
from cog_id_ros.core.native.kernels import (
    BACKENDS,
    ClosureRecord,
    PoseRecord,
    PythonKernels,
    ReferenceKernels,
    kernels_for,
)
from cog_id_ros.core.native.straight_line import Graph, SymOps
from cog_id_ros.core.solve.sample_solve import SampleSolver

MECHANISMS = {name: cog_id_ros.Mechanism.from_params_file(config_path(name))
              for name in TRAJECTORIES}


def native_or_skip(mechanism):
    try:
        return kernels_for(mechanism, 'native')
    except cog_id_ros.MechanismConfigError as exc:
        pytest.skip(f'no compiled kernels here: {exc}')


@pytest.mark.parametrize('pair', [('python', 'reference'), ('native', 'python')])
@pytest.mark.parametrize('name', list(TRAJECTORIES))
def test_backends_agree_to_the_bit_along_the_test_motion(name, pair):
    """Every example, redundant ones included: 1 kHz single samples, then the whole motion
    as one batch, then a far setpoint (continuation) and H, B of eq. (7)."""
    mechanism = MECHANISMS[name]
    if 'native' in pair:
        native_or_skip(mechanism)
    one, other = (cog_id_ros.InverseDynamics(mechanism, backend=b) for b in pair)
    assert (one.backend, other.backend) == pair
    _, q, qd, qdd = sample(name, 2001)
    for k in range(0, 2001, 4):
        a, b = one.torques(q[k], qd[k], qdd[k]), other.torques(q[k], qd[k], qdd[k])
        assert np.array_equal(a, b), k
    assert np.array_equal(one.solve_positions(q[-1]), other.solve_positions(q[-1]))
    for solver in (one, other):
        solver.reset()
    assert np.array_equal(one.torques(q, qd, qdd), other.torques(q, qd, qdd))
    for solver in (one, other):
        solver.reset()
    assert np.array_equal(one.torques(q[-1], qd[-1], qdd[-1]),
                          other.torques(q[-1], qd[-1], qdd[-1]))
    for x, y in zip(one.equation_of_motion(q[::100], qd[::100]),
                    other.equation_of_motion(q[::100], qd[::100])):
        assert np.array_equal(x, y)


class Counting:
    """Kernels that count their calls."""

    def __init__(self, kernels):
        self.kernels, self.name = kernels, kernels.name
        self.calls = {'prediction': 0, 'closure': 0, 'dynamics': 0}

    def prediction(self, q, basis, goal):
        self.calls['prediction'] += 1
        return self.kernels.prediction(q, basis, goal)

    def closure(self, q):
        self.calls['closure'] += 1
        return self.kernels.closure(q)

    def dynamics(self, q, target, qd, qdd):
        self.calls['dynamics'] += 1
        return self.kernels.dynamics(q, target, qd, qdd)


def _state_at(mechanism, positions):
    """(q, V) at a closed pose, by the reference kernels."""
    record = ReferenceKernels(mechanism).dynamics(positions.tolist(),
                                                  [positions[j] for j in mechanism.active_index],
                                                  [0.0] * len(mechanism.active_joints),
                                                  [0.0] * len(mechanism.active_joints))
    serial = SampleSolver(mechanism, ReferenceKernels(mechanism), 0.1)
    return positions.tolist(), serial.basis(record)


@pytest.mark.parametrize('name', list(TRAJECTORIES))
def test_at_control_rate_a_sample_costs_a_few_kernel_calls(name):
    """The glue calls the kernels, redundant mechanisms included: a setpoint one step away
    is predicted, closed by Newton from the prediction and evaluated, without a second try.
    (The mechanism the kernels are made for: a chain of revolutes that is a spherical joint
    is solved as one, spherical_chains.py.)"""
    mechanism = MECHANISMS[name].solver_mechanism
    kernels = Counting(kernels_for(mechanism, 'python'))
    serial = SampleSolver(mechanism, kernels, cog_id_ros.InverseDynamics.continuation_step)
    solver = cog_id_ros.InverseDynamics(mechanism, backend='reference')
    _, q, qd, qdd = sample(name, 2001)
    solver.solve_positions(q[0])
    state = serial.solve(_state_at(mechanism, np.array(mechanism.assembled_coordinates)),
                         q[0].tolist())[1]
    kernels.calls = dict.fromkeys(kernels.calls, 0)
    n = 0
    for k in range(1, 2001, 2):
        record, state = serial.solve(state, q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        assert np.array_equal(record.torques, solver.torques(q[k], qd[k], qdd[k]))
        n += 1
    calls = kernels.calls
    if mechanism.is_redundant:       # + a projection step, closed again, on most samples
        assert n <= calls['closure'] <= 2 * n and n <= calls['dynamics'] <= 2 * n, calls
    else:                            # one prediction, closed in one or two Newton steps
        assert calls['closure'] == n and n <= calls['dynamics'] <= 2 * n, calls


def test_far_setpoint_takes_one_kernel_pass_per_continuation_step():
    mechanism = MECHANISMS['paper_four_bar_a.yaml']
    kernels = Counting(kernels_for(mechanism, 'python'))
    serial = SampleSolver(mechanism, kernels, 0.1)
    state = _state_at(mechanism, cog_id_ros.InverseDynamics(mechanism).solve_positions([1.6]))
    record, _ = serial.solve(state, [2.5], [0.3], [1.0])
    steps = math.ceil(abs(2.5 - 1.6) / 0.1 - 1e-9)
    assert kernels.calls['closure'] == steps > 3
    fresh = cog_id_ros.InverseDynamics(mechanism, backend='reference')
    fresh.torques([1.6])
    assert np.array_equal(record.torques, fresh.torques([2.5], [0.3], [1.0]))


@pytest.mark.parametrize('backend', ['python', 'reference', 'native'])
def test_singular_and_unreachable_poses_raise_and_leave_the_warm_start(backend):
    if backend == 'native':
        native_or_skip(MECHANISMS['paper_four_bar_a.yaml'])
    mechanism = cog_id_ros.Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    solver = cog_id_ros.InverseDynamics(mechanism, backend=backend)
    twin = cog_id_ros.InverseDynamics(mechanism, backend=backend)
    for s in (solver, twin):
        s.torques([0.05], [0.0], [0.0])
    with pytest.raises(cog_id_ros.SingularConfigurationError) as info:
        solver.torques([0.0], [0.0], [0.0])
    assert info.value.reason == 'singular'
    assert np.array_equal(solver.solve_positions([0.07]), twin.solve_positions([0.07]))

    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_parameters(
        four_bar(ground=0.9, active=('joint1',), init=[1.2, -1.2332, 2.0244, 2.0576])),
        backend=backend)
    for target in np.arange(1.2, 1.8, 0.02):   # the loop closes up to 1.504 rad, then no more
        try:
            solver.torques([target], [0.0], [0.0])
        except cog_id_ros.CogIdError as exc:
            assert target > 1.45 and exc.reason in ('closure', 'unreachable')
            break
    else:
        pytest.fail('the crank went past where the loop can close')
    assert np.all(np.isfinite(solver.torques([1.3], [0.0], [0.0])))


def test_backend_is_a_public_switch():
    mechanism = MECHANISMS['five_bar_redundant.yaml']
    assert set(BACKENDS) == {'auto', 'reference', 'python', 'native'}
    for backend in ('reference', 'python'):
        assert cog_id_ros.InverseDynamics(mechanism, backend=backend).backend == backend
    assert cog_id_ros.InverseDynamics(mechanism).backend in ('native', 'python')
    with pytest.raises(cog_id_ros.MechanismConfigError, match='backend.*auto.*reference'):
        cog_id_ros.InverseDynamics(mechanism, backend='fast')


def test_auto_leaves_large_mechanisms_to_the_reference_kernels(monkeypatch):
    import cog_id_ros.core.native.kernels as kernels
    mechanism = cog_id_ros.Mechanism.from_parameters(from_yaml('config/slider_crank.yaml'))
    monkeypatch.setattr(kernels, 'TRACE_BUDGET', len(mechanism.links) * 1 - 1)
    assert cog_id_ros.InverseDynamics(mechanism).backend == 'reference'
    assert cog_id_ros.InverseDynamics(mechanism, backend='python').backend == 'python'


def test_one_trace_serves_every_solver_of_a_mechanism():
    mechanism = MECHANISMS['slider_crank.yaml']
    assert kernels_for(mechanism, 'python') is kernels_for(mechanism, 'python')
    assert isinstance(kernels_for(mechanism, 'python'), PythonKernels)


def test_traced_kernels_read_as_named_records():
    kernels = kernels_for(MECHANISMS['paper_four_bar_a.yaml'], 'python')
    source = kernels.source['dynamics']
    assert source.startswith('def dynamics(q, target, qd, qdd):\n')
    assert kernels.source['prediction'].startswith('def prediction(q, basis, goal):\n')
    for field in PoseRecord._fields:
        assert f'# {field}\n' in source
    assert kernels.source['closure'].startswith('def closure(q):\n')
    assert kernels.operations['closure'] < kernels.operations['dynamics']
    record = kernels.closure([1.6, 0.0, 0.0, 0.0])
    assert isinstance(record, ClosureRecord) and len(record.residual) == 6


# --- the tracer and the emitter ----------------------------------------------------------

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


class Out(NamedTuple):
    first: tuple
    second: float
    rows: tuple


def test_emitted_function_computes_what_floats_compute():
    g = Graph()
    a, b = g.inputs('a', 1), g.inputs('b', 2)

    def f(ops, u, v, w):
        s = ops.sqrt(u * v - w)
        return [s * ops.recip(w), ops.sin(u) * 2.0 - ops.cos(v) / 3.0, 1.5 - u, -v * 0.0 + w]

    outputs = f(SymOps, a[0], b[0], b[1])
    fields = [('first', outputs[:2]), ('second', outputs[2]), ('rows', [[outputs[3]], []])]
    fn, source, count = python_function('f', [('a', a), ('b', b)], Out, fields)
    assert count == 11
    assert source == python_source('f', [('a', a), ('b', b)], 'Out', fields)[0]
    # a statement per operation, but those used once are written where they are used
    lines = source.count('\n') - (3 + 2 + len(fields))
    assert '# rows' in source and 0 < lines < count
    assert all(op in source for op in ('sqrt(', 'sin(', 'cos(', '1.0 / ', ' - ', ' * '))

    class Floats:
        sin, cos = staticmethod(math.sin), staticmethod(math.cos)
        sqrt = staticmethod(lambda x: math.sqrt(x) if x >= 0.0 else math.nan)
        recip = staticmethod(lambda x: 1.0 / x if x != 0.0 else math.inf)

    for u, v, w in [(1.3, 0.7, 0.2), (0.1, 0.2, 5.0), (2.0, 3.0, 0.0)]:
        expected = f(Floats, u, v, w)
        got = fn([u], [v, w])
        assert isinstance(got, Out) and got.rows[1] == ()
        for e, x in zip(expected, [*got.first, got.second, got.rows[0][0]]):
            assert (math.isnan(e) and math.isnan(x)) or e == x


# --- sample_torques ----------------------------------------------------------------------

@pytest.mark.parametrize('name', list(TRAJECTORIES))
def test_sample_torques_is_torques_without_numpy(name):
    """Lists in, a list out: the same numbers and state as torques(), redundant ones too."""
    mechanism = MECHANISMS[name]
    lists, arrays = cog_id_ros.InverseDynamics(mechanism), cog_id_ros.InverseDynamics(mechanism)
    _, q, qd, qdd = sample(name, 2001)
    for k in range(0, 2001, 5):
        got = lists.sample_torques(q[k].tolist(), qd[k].tolist(), qdd[k].tolist())
        assert type(got) is list and all(type(x) is float for x in got)
        assert got == arrays.torques(q[k], qd[k], qdd[k]).tolist(), k
    assert np.array_equal(lists.solve_positions(q[-1]), arrays.solve_positions(q[-1]))


def test_sample_torques_reports_bad_input_like_torques_and_keeps_the_warm_start():
    mechanism = MECHANISMS['paper_four_bar_a.yaml']
    solver, twin = cog_id_ros.InverseDynamics(mechanism), cog_id_ros.InverseDynamics(mechanism)
    for s in (solver, twin):
        s.sample_torques([1.5], [0.0], [0.0])
    for q, qd, qdd in (([math.nan], [0.0], [0.0]), ([1.5], [math.inf], [0.0]),
                       ([1.5], [0.0], [math.nan]), ([1.5, 1.0], [0.0], [0.0]),
                       (['x'], [0.0], [0.0]), ([2e9], [0.0], [0.0])):
        with pytest.raises(cog_id_ros.SetpointError):
            solver.sample_torques(q, qd, qdd)
    with pytest.raises(cog_id_ros.SingularConfigurationError):
        solver.sample_torques([0.0], [0.0], [0.0])
    assert solver.sample_torques([1.52], [0.1], [0.0]) == twin.sample_torques([1.52], [0.1], [0.0])
    assert solver.sample_torques([1.5], None, None) == solver.torques([1.5]).tolist()
    # large finite rates are out_of_range, not an OverflowError of the input check
    with pytest.raises(cog_id_ros.SetpointError) as info:
        solver.sample_torques([1.5], [1e308], [1e308])
    assert info.value.reason == 'out_of_range'


def test_a_mechanism_is_read_only_so_every_backend_computes_the_same_one():
    """Review of issue 10: setting gravity after a solver was made left the traced kernels
    on the old value while the reference followed the new one."""
    mechanism = cog_id_ros.Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    with pytest.raises(AttributeError, match='gravity is read-only.*from_parameters'):
        mechanism.gravity = (0.0, 0.0, 0.0)
    assert mechanism.gravity == MECHANISMS['paper_four_bar_a.yaml'].gravity


def test_batch_eq7_overflows_as_a_setpoint_error_without_numpy_warnings():
    """Review of issue 10: equation_of_motion and cog_drifts on a batch leaked numpy's
    overflow RuntimeWarning (an exception under -W error) instead of out_of_range."""
    import warnings
    solver = cog_id_ros.InverseDynamics(MECHANISMS['paper_four_bar_a.yaml'])
    q = np.linspace(1.5, 1.7, 40)[:, None]
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for call in (solver.equation_of_motion, solver.cog_drifts):
            with pytest.raises(cog_id_ros.SetpointError) as info:
                call(q, np.full((40, 1), 1e200))
            assert info.value.reason == 'out_of_range'


def test_kernels_go_when_their_mechanism_goes():
    """Review of issue 11: traced and compiled kernels were kept forever by a cache keyed
    on the mechanism they referenced (9 MB a Stewart platform with the Python kernels)."""
    import gc
    import weakref
    mechanism = cog_id_ros.Mechanism.from_params_file('config/slider_crank.yaml')
    for backend in ('python', 'auto'):
        cog_id_ros.InverseDynamics(mechanism, backend=backend).torques([0.4])
    gone = weakref.ref(mechanism)
    del mechanism
    gc.collect()
    assert gone() is None
