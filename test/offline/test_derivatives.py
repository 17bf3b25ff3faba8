"""The finite-difference scheme of cog_id_ros.derivatives: weights, exactness, order, edge cases."""
import numpy as np
import pytest

from cog_id_ros.offline import derivatives as d


def f(t):
    return np.sin(3.0 * t) + 0.3 * t ** 2


def f1(t):
    return 3.0 * np.cos(3.0 * t) + 0.6 * t


def f2(t):
    return -9.0 * np.sin(3.0 * t) + 0.6


EXACT = {1: f1, 2: f2}
PATTERN = 0.5 + np.random.default_rng(7).random(16)   # relative steps in [0.5, 1.5)


def grid(kind, n, length=2.0):
    """n + 1 samples on [0, ~length]: even, smoothly uneven, or randomly uneven steps.

    The random pattern is tiled and scaled, so refining keeps the step ratios (what the
    order of accuracy is about) while the largest step halves."""
    if kind == 'even':
        return np.linspace(0.0, length, n + 1)
    if kind == 'smooth':
        s = np.linspace(0.0, length, n + 1)
        return s + 0.2 * np.sin(2.0 * s)          # step ratio varies smoothly, within [0.6, 1.4]
    if kind == 'random':
        steps = np.tile(PATTERN, n // PATTERN.size) * (length / n)
        return np.concatenate([[0.0], np.cumsum(steps)])
    raise ValueError(kind)


def observed_order(kind, order, interior=False):
    """Least-squares slope of log(max error) against log(largest step)."""
    hs, errs = [], []
    for n in (32, 64, 128, 256, 512):
        t = grid(kind, n)
        err = np.abs(d.derivative(t, f(t), order) - EXACT[order](t))
        if interior:
            err = err[2:-2]
        hs.append(np.max(np.diff(t)))
        errs.append(err.max())
    return np.polyfit(np.log(hs), np.log(errs), 1)[0]


@pytest.mark.parametrize('kind', ['even', 'smooth', 'random'])
@pytest.mark.parametrize('order', [1, 2])
def test_converges_at_the_stated_order(kind, order):
    # stated: velocity O(h^4), acceleration O(h^3), on any grid with bounded step ratios
    assert d.ORDER == {1: 4, 2: 3}
    slope = observed_order(kind, order)
    assert abs(slope - d.ORDER[order]) < 0.25, (kind, order, slope)


def test_acceleration_is_fourth_order_inside_an_even_grid():
    # the centred 5-point stencil is symmetric there; the one-sided ends keep O(h^3)
    assert observed_order('even', 2, interior=True) == pytest.approx(4.0, abs=0.2)


def test_weights_on_an_even_grid_are_the_classical_ones():
    offsets = np.array([[-2.0, -1.0, 0.0, 1.0, 2.0]])
    np.testing.assert_allclose(d.fornberg_weights(offsets, 1)[0],
                               np.array([1, -8, 0, 8, -1]) / 12.0, atol=1e-15)
    np.testing.assert_allclose(d.fornberg_weights(offsets, 2)[0],
                               np.array([-1, 16, -30, 16, -1]) / 12.0, atol=1e-14)
    one_sided = np.array([[0.0, 1.0, 2.0]])
    np.testing.assert_allclose(d.fornberg_weights(one_sided, 1)[0], [-1.5, 2.0, -0.5], atol=1e-15)


def test_exact_for_polynomials_up_to_degree_four_on_uneven_grids():
    rng = np.random.default_rng(3)
    t = np.cumsum(0.05 + rng.random(12))
    for degree in range(5):
        c = rng.normal(size=degree + 1)
        p = np.polynomial.Polynomial(c)
        np.testing.assert_allclose(d.first_derivative(t, p(t)), p.deriv(1)(t), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(d.second_derivative(t, p(t)), p.deriv(2)(t), rtol=1e-8, atol=1e-8)


def test_stencils_are_centred_and_shifted_inward_at_the_ends():
    idx = d.stencil_indices(8)
    assert idx[0].tolist() == [0, 1, 2, 3, 4]
    assert idx[1].tolist() == [0, 1, 2, 3, 4]
    assert idx[2].tolist() == [0, 1, 2, 3, 4]
    assert idx[4].tolist() == [2, 3, 4, 5, 6]
    assert idx[7].tolist() == [3, 4, 5, 6, 7]


def test_columns_are_differentiated_independently():
    t = grid('random', 64)
    y = np.column_stack([f(t), 2.0 * f(t) + 5.0, t ** 2])
    dy = d.first_derivative(t, y)
    assert dy.shape == y.shape
    np.testing.assert_allclose(dy[:, 1], 2.0 * d.first_derivative(t, f(t)), rtol=1e-12)
    np.testing.assert_allclose(dy[:, 2], 2.0 * t, atol=1e-9)


def test_unwrapped_angles_lose_no_accuracy_to_the_offset():
    # a crank at 1000 rad differentiates like one at 0 rad, up to the representation of the
    # samples themselves (eps * 1000 / h^2 for the acceleration)
    t = np.arange(2001) * 1e-3
    base = d.second_derivative(t, np.sin(t))
    shifted = d.second_derivative(t, 1000.0 + np.sin(t))
    assert np.max(np.abs(shifted - base)) < 1e-6   # summing w_j * y_j directly gives ~1.4e-6
    np.testing.assert_allclose(d.first_derivative(t, 1000.0 + np.sin(t)), np.cos(t), atol=1e-9)


def test_rejects_what_it_cannot_differentiate():
    with pytest.raises(ValueError, match='at least 5 samples'):
        d.first_derivative(np.arange(4.0), np.arange(4.0))
    with pytest.raises(ValueError, match='strictly increasing'):
        d.second_derivative(np.array([0.0, 1.0, 1.0, 2.0, 3.0]), np.zeros(5))
    with pytest.raises(ValueError, match='order'):
        d.derivative(np.arange(5.0), np.zeros(5), 3)
    with pytest.raises(ValueError, match='shape'):
        d.derivative(np.arange(5.0), np.zeros(6), 1)


@pytest.mark.parametrize('unit', [1e-300, 1e300 / 64])
def test_any_time_unit_without_overflow_or_warnings(unit):
    """Reliability item 20: steps of 1e-300 s or times of 1e300 s gave NaN and RuntimeWarnings.

    The same motion in another time unit has the same derivatives in that unit; where the
    true value lies beyond a double (1/unit^2 = 1e600 or 1e-596) the result is infinite
    (never NaN) or underflows to (nearly) 0, and no floating-point warning is raised."""
    t0 = grid('random', 32, length=2.0)
    y = f(t0)
    t = t0 * unit
    with np.errstate(all='raise'):          # any floating-point warning would raise here
        v = d.first_derivative(t, y)
        a = d.second_derivative(t, y)
    np.testing.assert_allclose(v * unit, d.first_derivative(t0, y), rtol=1e-12, atol=1e-12)
    assert not np.isnan(a).any()
    if unit < 1:
        assert np.all(np.isinf(a[np.abs(d.second_derivative(t0, y)) > 1e-6]))
    else:
        assert np.all(np.abs(a) <= 1e-300)
