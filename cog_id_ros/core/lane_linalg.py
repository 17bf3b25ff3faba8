"""Small dense linear algebra on lanes (floats or (N,) arrays, see spatial.py).

The closure Jacobian of a planar loop written in 3-D has 6 rows of rank 3 per loop, so its
least-squares problems are rank-deficient in the rows. A QR factorisation by Gram-Schmidt
with re-orthogonalisation (CGS2) handles that exactly: the redundant rows add nothing to
the column space, and the factor R stays square and invertible as long as the columns are
independent. Loss of column rank is a singular configuration; ``condition_number`` measures
how close a configuration is to it.
"""
def _dot(a, b):
    s = 0.0
    for x, y in zip(a, b):
        s = s + x * y
    return s


class QRLeastSquares:
    """Least squares min ||A x - b|| for A given as a list of columns (each a list of lanes)."""

    def __init__(self, columns, ops):
        self.ops = ops
        self.n = len(columns)
        self.q = []
        self.r = [[0.0] * self.n for _ in range(self.n)]
        for j, col in enumerate(columns):
            v = list(col)
            for _ in range(2):  # CGS2: a second pass makes the columns orthogonal to working precision
                for i, qi in enumerate(self.q):
                    rij = _dot(qi, v)
                    self.r[i][j] = self.r[i][j] + rij
                    v = [vk - rij * qk for vk, qk in zip(v, qi)]
            rjj = ops.sqrt(_dot(v, v))
            self.r[j][j] = rjj
            inv = ops.recip(rjj)
            self.q.append([vk * inv for vk in v])
        self.r_diag_inv = [ops.recip(self.r[i][i]) for i in range(self.n)]

    def solve(self, b):
        """x minimising ||A x - b|| (b: list of lanes, one per row)."""
        y = [_dot(qi, b) for qi in self.q]
        return self._back_substitute(y)

    def _back_substitute(self, y):
        n, r = self.n, self.r
        x = [0.0] * n
        for i in range(n - 1, -1, -1):
            s = y[i]
            for k in range(i + 1, n):
                s = s - r[i][k] * x[k]
            x[i] = s * self.r_diag_inv[i]
        return x

    def condition_number(self):
        """Frobenius-norm condition number ||A||_F ||A^+||_F = ||R||_F ||R^-1||_F.

        It bounds the 2-norm condition number from above (by at most a factor n) and is
        infinite when the columns are dependent.
        """
        if self.n == 0:
            return 1.0
        n, r = self.n, self.r
        norm_a = 0.0
        for i in range(n):
            for k in range(i, n):
                norm_a = norm_a + r[i][k] * r[i][k]
        norm_inv = 0.0
        for j in range(n):  # column j of R^-1
            e = [0.0] * n
            e[j] = 1.0
            x = self._back_substitute(e)
            for xi in x[:j + 1]:
                norm_inv = norm_inv + xi * xi
        return self.ops.sqrt(norm_a) * self.ops.sqrt(norm_inv)


def solve_spd(a, rhs, ops):
    """Solve A X = RHS for a small symmetric positive-definite A (list of rows of lanes)
    by Cholesky; RHS is a list of rows (each a list of lanes). Returns X as a list of rows."""
    n = len(a)
    lower = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            s = a[i][j]
            for k in range(j):
                s = s - lower[i][k] * lower[j][k]
            if i == j:
                lower[i][i] = ops.sqrt(s)
            else:
                lower[i][j] = s * ops.recip(lower[j][j])
    m = len(rhs[0]) if rhs else 0
    out = [[0.0] * m for _ in range(n)]
    for c in range(m):
        y = [0.0] * n
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

