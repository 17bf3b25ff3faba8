"""The Python API's contract for any input: only CogIdError subclasses come out (each with
a machine-readable ``reason``), never NaN or Inf from finite input, never a numpy
RuntimeWarning, and a plain number is a setpoint of a one-actuator mechanism."""
import math
import warnings

import numpy as np
import pytest

import cog_id_ros

ONE = 'config/paper_four_bar_a.yaml'      # one actuator
TWO = 'config/five_bar.yaml'              # two actuators


@pytest.fixture(scope='module')
def mechanisms():
    return {path: cog_id_ros.Mechanism.from_params_file(path) for path in (ONE, TWO)}


CALLS = {
    'torques': lambda s, q: s.torques(q, None, None),
    'sample_torques': lambda s, q: s.sample_torques(q, [0.0], [0.0]),
    'evaluate': lambda s, q: s.evaluate(q, on_invalid='skip'),
    'solve_positions': lambda s, q: s.solve_positions(q),
    'cog_jacobians': lambda s, q: s.cog_jacobians(q),
    'cog_poses': lambda s, q: s.cog_poses(q),
    'equation_of_motion': lambda s, q: s.equation_of_motion(q),
}

MALFORMED = {
    'None': None, 'dict': {'joint3': 1.5}, 'string': 'abc', 'numeric string': '1.5',
    'bools': [True], 'ragged': [[1.5], [1.5, 2.0]], 'huge int': [10 ** 400],
    'complex': [1.5 + 2j], '3-D': np.zeros((2, 2, 1)), 'object': [object()],
    'nested None': [None], 'bytes': b'1.5',
}


@pytest.mark.parametrize('call', list(CALLS))
@pytest.mark.parametrize('label', list(MALFORMED))
def test_anything_that_is_not_numbers_is_a_setpoint_error(mechanisms, call, label):
    """Reliability item 5: None, a dict or a string where an array belongs raised
    AttributeError, KeyError, IndexError or OverflowError; now SetpointError('malformed')."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    with pytest.raises(cog_id_ros.SetpointError) as info:
        result = CALLS[call](s, MALFORMED[label])
        if call == 'evaluate' and not result.valid.all():   # skip mode: an invalid row
            raise result.errors[0]
    assert info.value.reason == 'malformed'


def test_a_plain_number_is_a_setpoint_of_a_one_actuator_mechanism(mechanisms):
    """Reliability item 5: solver.torques(1.0, 0.0, 0.0) raised IndexError."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    assert s.torques(1.5, 0.0, 0.0).tolist() == s.torques([1.5], [0.0], [0.0]).tolist()
    assert s.sample_torques(1.5, 0.0, 0.0) == s.torques([1.5], [0.0], [0.0]).tolist()
    assert s.solve_positions(1.5).shape == (4,)
    two = cog_id_ros.InverseDynamics(mechanisms[TWO])
    with pytest.raises(cog_id_ros.SetpointError, match='one number per active joint'):
        two.torques(1.0, 0.0, 0.0)


@pytest.mark.parametrize('call', list(CALLS))
@pytest.mark.parametrize('value', [1e307, -1e307, 1e300, 1e10])
def test_huge_positions_are_out_of_range_not_overflow(mechanisms, call, value):
    """Reliability item 5: positions near 1e307 raised OverflowError (math.ceil(inf))."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        with pytest.raises(cog_id_ros.SetpointError) as info:
            result = CALLS[call](s, [value])
            if call == 'evaluate':
                raise result.errors[0]
    assert info.value.reason == 'out_of_range'
    assert s.torques([1.5]).shape == (1,)        # the solver serves the next setpoint


@pytest.mark.parametrize('qd, qdd', [(1e200, 0.0), (1e160, 1e300)])
def test_finite_input_never_gives_nan_or_inf(mechanisms, qd, qdd):
    """Reliability items 5 and 19: qd = 1e200 returned [nan]; overflowing torques are
    'out_of_range', not 'singular' with a condition number."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        for call in (lambda: s.torques([1.5], [qd], [qdd]),
                     lambda: s.sample_torques([1.5], [qd], [qdd]),
                     lambda: s.torques([[1.5], [1.51]], [[qd], [qd]], [[qdd], [qdd]]),
                     lambda: s.equation_of_motion([1.5], [qd])):
            with pytest.raises(cog_id_ros.SetpointError) as info:
                call()
            assert info.value.reason == 'out_of_range'
            assert 'singular' not in str(info.value)
        ev = s.evaluate([[1.5], [1.51]], [[qd], [0.0]], [[qdd], [0.0]], on_invalid='skip')
    assert ev.valid.tolist() == [False, True]
    assert np.isfinite(ev.torques).all() and ev.errors[0].reason == 'out_of_range'


def test_every_error_carries_a_reason_the_caller_can_map(mechanisms):
    """Reliability item 19: callers map ``reason``, never message text."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    seen = {}
    for q in ([math.nan], [0.0], [1.5, 1.0], [1e300]):
        try:
            s.torques(q)
        except cog_id_ros.CogIdError as exc:
            seen[exc.reason] = exc
    assert set(seen) == {'non_finite', 'singular', 'malformed', 'out_of_range'}
    assert set(seen) <= set(cog_id_ros.REASONS)


class Floaty:
    """An object whose conversion to float fails with an unexpected exception."""

    def __float__(self):
        raise RuntimeError('no float here')


@pytest.mark.parametrize('q', [[True], [np.bool_(True)], [[True]], [Floaty()], True],
                         ids=['bool', 'numpy bool', 'nested bool', 'strange __float__', 'bare bool'])
def test_booleans_and_strange_objects_are_malformed(mechanisms, q):
    """Reliability item 5 (found by the adversarial test): [True, 0.0] was taken as numbers,
    a raising __float__ passed its RuntimeError through."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    for call in (lambda: s.torques(q), lambda: s.sample_torques(q, [0.0], [0.0]),
                 lambda: s.torques([1.5], q, None)):
        with pytest.raises(cog_id_ros.SetpointError) as info:
            call()
        assert info.value.reason == 'malformed'


def test_misuse_of_the_api_is_a_cog_id_error(mechanisms):
    """Reliability item 5: only CogIdError subclasses, also for a wrong argument."""
    s = cog_id_ros.InverseDynamics(mechanisms[ONE])
    with pytest.raises(cog_id_ros.CogIdError, match="on_invalid must be 'raise' or 'skip'"):
        s.evaluate([[1.5]], on_invalid='SKIP')
    with pytest.raises(cog_id_ros.MechanismConfigError, match='must be a cog_id_ros.Mechanism'):
        cog_id_ros.InverseDynamics(None)
    assert s.sample_torques([1.5]) == s.torques([1.5]).tolist()     # qd, qdd default to 0


@pytest.mark.parametrize('kind', [np.uint8, np.uint32, np.float16, np.float32, np.int64])
def test_sample_torques_computes_in_double_whatever_the_scalar_type(kind):
    """Reliability item 5 (found by the adversarial test): numpy unsigned velocities wrapped
    around in -qd (silently wrong torques), float16 ones were computed in float16."""
    mech = cog_id_ros.Mechanism.from_params_file(TWO)
    s, ref = cog_id_ros.InverseDynamics(mech), cog_id_ros.InverseDynamics(mech)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        got = s.sample_torques([2.0, 1.14], [kind(5)] * 2, [kind(3)] * 2)
    assert got == ref.sample_torques([2.0, 1.14], [5.0, 5.0], [3.0, 3.0])
    assert all(type(x) is float for x in got)
