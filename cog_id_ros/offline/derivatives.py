"""Missing velocities and accelerations: the rule, and the scheme for whole trajectories.

**The rule** (one place: :func:`estimates`; docs/derivatives.md): a velocity that is not
given is estimated from the positions; an acceleration that is not given is estimated from
the *given* velocities when there are any, else from the positions. ``cog_id_torques``
(per CSV column) and cog_id_node's ``joint_trajectory`` both call :func:`fill_in`, which
applies it with the scheme below; the node's setpoint stream applies the same rule causally
(:mod:`cog_id_ros.ros.setpoint_filter`, which cannot use samples that have not come yet).
The Python API does not estimate: ``torques(q)`` takes missing ``qd`` and ``qdd`` as zeros.

The scheme for a whole trajectory (pure numpy, uneven time grids):

* Every derivative at sample ``i`` is the derivative, at ``t[i]``, of the polynomial
  of degree 4 that interpolates 5 neighbouring samples. The stencil is centred
  (samples ``i-2 .. i+2``) wherever it fits and is shifted inward at the two ends
  (the first two and last two samples use the first or last five samples), so it is
  one-sided there. The weights come from Fornberg's recurrence (B. Fornberg,
  "Generation of finite difference formulas on arbitrarily spaced grids",
  Math. Comp. 51, 1988), evaluated for all samples at once; time steps may differ
  from sample to sample.
* Order of accuracy, for smooth signals and steps whose ratios stay bounded:
  first derivative O(h^4), second derivative O(h^3) (O(h^4) at interior samples of
  an even grid, where the centred stencil is symmetric). ``h`` is the largest step
  in the stencil.
* The differences are formed as ``sum_j w_j (y_j - y_i)`` (the weights of a derivative
  sum to zero), so large unwrapped angles (a crank at 1000 rad) lose no more digits
  than small ones.

The public functions take ``t`` of shape (N,) and ``y`` of shape (N,) or (N, K) and
return an array shaped like ``y``. They need ``N >= STENCIL`` samples and a strictly
increasing ``t``; anything else raises ``ValueError``. Any time unit works: each stencil
is scaled by a power of two before its weights are computed (exact, so results do not
change), and no floating-point warning is ever emitted; a derivative whose true value
lies beyond the range of a double (e.g. positions that change by 1 over steps of 1e-300 s
give accelerations of 1e600) comes out as +-inf or NaN, for the caller to check with
``np.isfinite``.
"""

from typing import Callable

import numpy as np

#: samples per stencil (degree of the local interpolating polynomial + 1)
STENCIL = 5

#: order of accuracy of each derivative on any grid with bounded step ratios
ORDER = {1: STENCIL - 1, 2: STENCIL - 2}

#: one-paragraph description, shared by ``--help``, the JSON summary and the docs
SCHEME = (
    'derivative at each sample of the degree-4 polynomial through 5 neighbouring samples '
    '(centred stencil i-2..i+2, shifted inward at the first and last two samples; '
    'Fornberg weights, uneven steps allowed): velocity O(h^4), acceleration O(h^3)'
)


def stencil_indices(n, width=STENCIL):
    """(n, width) sample indices of each sample's stencil: centred, clipped to [0, n)."""
    if n < width:
        raise ValueError(f'need at least {width} samples, got {n}')
    start = np.arange(n) - width // 2
    np.clip(start, 0, n - width, out=start)
    return start[:, None] + np.arange(width)[None, :]


def fornberg_weights(offsets, order):
    """Finite-difference weights for the ``order``-th derivative at 0.

    ``offsets`` has shape (N, S): for each of N evaluation points, the positions of its
    S stencil nodes relative to the evaluation point (distinct values). Returns (N, S)
    weights ``w`` with ``f^(order)(0) ~= sum_j w[:, j] * f(offsets[:, j])``, exact for
    polynomials of degree < S. Fornberg's recurrence, vectorised over the N points.
    """
    x = np.asarray(offsets, dtype=float)
    if x.ndim != 2:
        raise ValueError(f'offsets must have shape (N, S), got {x.shape}')
    n_points, size = x.shape
    if not 0 <= order < size:
        raise ValueError(f'derivative order {order} needs more than {size} nodes')
    m = order
    # c[j][k]: weight of node j for derivative k (arrays over the N points)
    c = [[np.zeros(n_points) for _ in range(m + 1)] for _ in range(size)]
    c[0][0][:] = 1.0
    c1 = np.ones(n_points)
    c4 = x[:, 0].copy()
    for i in range(1, size):
        mn = min(i, m)
        c2 = np.ones(n_points)
        c5 = c4
        c4 = x[:, i]
        for j in range(i):
            c3 = x[:, i] - x[:, j]
            c2 = c2 * c3
            if j == i - 1:
                for k in range(mn, 0, -1):
                    c[i][k] = c1 * (k * c[i - 1][k - 1] - c5 * c[i - 1][k]) / c2
                c[i][0] = -c1 * c5 * c[i - 1][0] / c2
            for k in range(mn, 0, -1):
                c[j][k] = (c4 * c[j][k] - k * c[j][k - 1]) / c3
            c[j][0] = c4 * c[j][0] / c3
        c1 = c2
    return np.stack([c[j][m] for j in range(size)], axis=1)


def derivative(t, y, order):
    """``order``-th time derivative (1 or 2) of samples ``y`` taken at times ``t``."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if order not in ORDER:
        raise ValueError(f'order must be 1 or 2, got {order}')
    if t.ndim != 1:
        raise ValueError(f't must be one-dimensional, got shape {t.shape}')
    if y.shape[:1] != t.shape or y.ndim > 2:
        raise ValueError(f'y must have shape ({t.size},) or ({t.size}, K), got {y.shape}')
    if t.size >= 2 and not np.all(np.diff(t) > 0):
        raise ValueError('t must be strictly increasing')
    idx = stencil_indices(t.size)
    with np.errstate(all='ignore'):
        offsets = t[idx] - t[:, None]
        # Scale each stencil by the power of two nearest its span, so the weights are
        # computed on offsets of order 1 whatever the time unit: steps of 1e-300 s or
        # 1e300 s no longer over/underflow inside the recurrence. Multiplying by a power
        # of two is exact, so the result is bit-identical to the unscaled one whenever
        # that one does not over/underflow. The weights of the scaled stencil are applied
        # first and the power of two (2^-order*e) last, so only a derivative that is itself
        # beyond the range of a double comes out infinite (never NaN, never a warning).
        _, exponent = np.frexp(offsets[:, -1] - offsets[:, 0])
        w = fornberg_weights(np.ldexp(offsets, -exponent[:, None]), order)
        if y.ndim == 1:
            d = np.einsum('ij,ij->i', w, y[idx] - y[:, None])
            return np.ldexp(d, -order * exponent)
        d = np.einsum('ij,ijk->ik', w, y[idx] - y[:, None, :])
        return np.ldexp(d, -order * exponent[:, None])


def first_derivative(t, y):
    """Velocity from positions (or acceleration from velocities): O(h^4)."""
    return derivative(t, y, 1)


def second_derivative(t, y):
    """Acceleration from positions: O(h^3) (O(h^4) inside an even grid)."""
    return derivative(t, y, 2)


#: what a missing derivative is estimated from: (given quantity, order of the derivative)
FROM_POSITIONS_1 = ('position', 1)
FROM_POSITIONS_2 = ('position', 2)
FROM_VELOCITIES_1 = ('velocity', 1)


def estimates(velocity_given: bool, acceleration_given: bool) -> dict[str, tuple[str, int]]:
    """The rule: {missing quantity: (what it is estimated from, derivative order)}.

    A missing velocity comes from the positions; a missing acceleration from the given
    velocities, or from the positions when no velocities are given. Given quantities are
    used as they are and never estimated.
    """
    plan = {}
    if not velocity_given:
        plan['velocity'] = FROM_POSITIONS_1
    if not acceleration_given:
        plan['acceleration'] = FROM_VELOCITIES_1 if velocity_given else FROM_POSITIONS_2
    return plan


def fill_in(t, q, qd=None, qdd=None,
            check: Callable[[str, str, np.ndarray], None] | None = None):
    """(qd, qdd) of a sampled trajectory: given ones as they are, missing ones estimated.

    ``t`` (N,), ``q`` and the given ``qd``/``qdd`` of shape (N,) or (N, K); ``None`` marks a
    missing one. Missing ones follow :func:`estimates` with the scheme of
    :func:`derivative` (needs ``STENCIL`` samples, increasing ``t``; ``ValueError``
    otherwise). ``check(quantity, source, values)``, optional, sees each estimate in turn
    (velocity first) and may raise, e.g. for values beyond the range of a double.
    """
    given = {'position': q, 'velocity': qd}
    out = {'velocity': qd, 'acceleration': qdd}
    for quantity, (source, order) in estimates(qd is not None, qdd is not None).items():
        values = derivative(t, given[source], order)
        if check is not None:
            check(quantity, source, values)
        out[quantity] = values
    return out['velocity'], out['acceleration']
