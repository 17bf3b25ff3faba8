"""Small dense linear algebra on lanes (floats or (N,) arrays, see spatial.py).

The closure Jacobian of a planar loop written in 3-D has 6 rows of rank 3 per loop, so its
least-squares problems are rank-deficient in the rows. A QR factorisation by Gram-Schmidt
with re-orthogonalisation (CGS2) handles that exactly: the redundant rows add nothing to
the column space, and the factor R stays square and invertible as long as the columns are
independent. Loss of column rank is a singular configuration; ``condition_number`` measures
how close a configuration is to it.
"""
from operator import mul
from typing import Sequence

from ..value_types import Lane, Ops


def _dot(a: Sequence[Lane], b: Sequence[Lane]) -> Lane:
    return sum(map(mul, a, b))


class QRLeastSquares:
    """Least squares min ||A x - b|| for A given as a list of columns (each a list of lanes).

    A = Q R with Q's columns orthonormal and R square upper triangular; R^-1 is formed once
    (it serves every solve and the condition number), so a solve is Q^T b and a product.

    ``order`` (a permutation) factorises the columns in that order; solve() still answers
    in the order given. Columns that touch few rows first keep Q and R sparse: a column
    with no row in common with an earlier one needs no work against it, and traced code
    (straight_line.py) drops operations on structural zeros.
    """

    def __init__(self, columns: Sequence[Sequence[Lane]], ops: Ops,
                 order: Sequence[int] | None = None) -> None:
        self.ops = ops
        n = self.n = len(columns)
        self.order = None if order is None or list(order) == list(range(n)) else list(order)
        if self.order is not None:
            columns = [columns[i] for i in self.order]
        q: list[list[Lane]] = []
        self.q = q
        r: list[list[Lane]] = [[0.0] * n for _ in range(n)]
        for j, col in enumerate(columns):
            v = col
            for _ in range(2):  # CGS2: a second pass makes them orthogonal to working precision
                for i, qi in enumerate(q):
                    rij = _dot(qi, v)
                    r[i][j] = r[i][j] + rij
                    v = [vk - rij * qk for vk, qk in zip(v, qi)]
            rjj = ops.sqrt(_dot(v, v))
            r[j][j] = rjj
            inv = ops.recip(rjj)
            q.append([vk * inv for vk in v])
        self.r = r
        # R^-1, column by column (upper triangular)
        rinv: list[list[Lane]] = [[0.0] * n for _ in range(n)]
        diag_inv = [ops.recip(r[i][i]) for i in range(n)]
        for j in range(n):
            rinv[j][j] = diag_inv[j]
            for i in range(j - 1, -1, -1):
                s = 0.0
                for k in range(i + 1, j + 1):
                    s = s + r[i][k] * rinv[k][j]
                rinv[i][j] = -s * diag_inv[i]
        self.rinv = rinv

    def solve(self, b: Sequence[Lane]) -> list[Lane]:
        """x minimising ||A x - b|| (b: list of lanes, one per row)."""
        y = [_dot(qi, b) for qi in self.q]
        x = [_dot(row[i:], y[i:]) for i, row in enumerate(self.rinv)]
        if self.order is None:
            return x
        out: list[Lane] = [None] * self.n
        for k, i in enumerate(self.order):
            out[i] = x[k]
        return out

    def condition_number(self) -> Lane:
        """Frobenius-norm condition number ||A||_F ||A^+||_F = ||R||_F ||R^-1||_F.

        It bounds the 2-norm condition number from above (by at most a factor n) and is
        infinite when the columns are dependent.
        """
        if self.n == 0:
            return 1.0
        norm_a = sum(_dot(row, row) for row in self.r)
        norm_inv = sum(_dot(row, row) for row in self.rinv)
        return self.ops.sqrt(norm_a) * self.ops.sqrt(norm_inv)


def solve_spd(a: Sequence[Sequence[Lane]], rhs: Sequence[Sequence[Lane]],
              ops: Ops) -> list[list[Lane]]:
    """Solve A X = RHS for a small symmetric positive-definite A (list of rows of lanes)
    by Cholesky; RHS is a list of rows (each a list of lanes). Returns X as a list of rows."""
    return cholesky_solve(cholesky(a, ops), rhs, ops)


def cholesky(a: Sequence[Sequence[Lane]], ops: Ops) -> list[list[Lane]]:
    """The lower Cholesky factor L of a small symmetric positive-definite A, A = L L^T
    (list of rows of lanes; a pivot that is not positive gives NaN, as ops.sqrt does)."""
    n = len(a)
    lower: list[list[Lane]] = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = a[i][j]
            for k in range(j):
                s = s - lower[i][k] * lower[j][k]
            if i == j:
                lower[i][i] = ops.sqrt(s)
            else:
                lower[i][j] = s * ops.recip(lower[j][j])
    return lower


def cholesky_solve(lower: Sequence[Sequence[Lane]], rhs: Sequence[Sequence[Lane]],
                   ops: Ops) -> list[list[Lane]]:
    """X with L L^T X = RHS, L from :func:`cholesky`; RHS and X lists of rows of lanes."""
    n = len(lower)
    m = len(rhs[0]) if rhs else 0
    out: list[list[Lane]] = [[0.0] * m for _ in range(n)]
    for c in range(m):
        y: list[Lane] = [0.0] * n
        for i in range(n):
            s = rhs[i][c]
            for k in range(i):
                s = s - lower[i][k] * y[k]
            y[i] = s * ops.recip(lower[i][i])
        for i in range(n - 1, -1, -1):
            s = y[i]
            for k in range(i + 1, n):
                s = s - lower[k][i] * out[k][c]
            out[i][c] = s * ops.recip(lower[i][i])
    return out
