"""The one rule for missing velocities and accelerations (docs/derivatives.md): what the
offline tool, the node's trajectories and the node's setpoint stream estimate them from."""
import numpy as np
import pytest

from cog_id_ros.offline import derivatives
from cog_id_ros.ros.setpoint_filter import NANOSECONDS, SetpointFilter


def test_the_rule():
    assert derivatives.estimates(False, False) == {'velocity': ('position', 1),
                                                   'acceleration': ('position', 2)}
    assert derivatives.estimates(True, False) == {'acceleration': ('velocity', 1)}
    assert derivatives.estimates(False, True) == {'velocity': ('position', 1)}
    assert derivatives.estimates(True, True) == {}


def test_fill_in_keeps_what_is_given_and_estimates_the_rest():
    t = np.linspace(0.0, 1.0, 11)
    q = t ** 3
    qd, qdd = derivatives.fill_in(t, q)
    np.testing.assert_allclose(qd, 3 * t ** 2, atol=1e-12)        # exact for a cubic
    np.testing.assert_allclose(qdd, 6 * t, atol=1e-9)
    given = np.full_like(t, 7.0)
    assert derivatives.fill_in(t, q, given, given)[0] is given
    # an acceleration comes from the given velocities, not from the positions
    _, qdd = derivatives.fill_in(t, q, qd=t.copy())
    np.testing.assert_allclose(qdd, 1.0, atol=1e-12)


def test_fill_in_lets_the_caller_check_each_estimate_in_turn():
    seen = []
    t = np.linspace(0.0, 1.0, 6)
    derivatives.fill_in(t, t, check=lambda quantity, source, values: seen.append(
        (quantity, source, values.shape)))
    assert seen == [('velocity', 'position', (6,)), ('acceleration', 'position', (6,))]
    with pytest.raises(ValueError):
        derivatives.fill_in(t[:4], t[:4])        # fewer than STENCIL samples


def test_the_setpoint_stream_follows_the_same_rule():
    """Positions that stand still with velocities that grow: both the batch estimate and the
    node's causal one take the acceleration from the velocities (1), not the positions (0)."""
    t = np.arange(10) * 1e-3
    q = np.zeros((10, 1))
    v = t[:, None].copy()
    _, batch = derivatives.fill_in(t, q, qd=v)
    stream = SetpointFilter(1, window=4, max_interval=None)
    for k in range(10):
        stamp = int(round(t[k] * NANOSECONDS))
        v_used, a = stream.estimate(stamp, q[k].tolist(), v[k].tolist())
        stream.accept(stamp, q[k].tolist(), v[k].tolist())
    assert v_used == v[-1].tolist()
    np.testing.assert_allclose(batch[-1], 1.0, atol=1e-9)
    np.testing.assert_allclose(a, 1.0, atol=1e-6)
    # and without velocities both take them from the positions
    stream.reset()
    _, batch = derivatives.fill_in(t, v)
    for k in range(10):
        stamp = int(round(t[k] * NANOSECONDS))
        v_used, a = stream.estimate(stamp, v[k].tolist())
        stream.accept(stamp, v[k].tolist())
    np.testing.assert_allclose(v_used, 1.0, atol=1e-6)
    np.testing.assert_allclose(a, 0.0, atol=1e-3)
    np.testing.assert_allclose(batch[-1], 0.0, atol=1e-6)
