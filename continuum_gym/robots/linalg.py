"""Small dense linear algebra as compiled kernels: the one damped Gram solve every controller uses.

Every damped inverse in the library is a solve of (J M J^T + lambda I) X = B with M = diag(mask)
(the active columns): the projected gradient (eq 22-23 of paper 000), the null-space projection of
the occlusion residual, dimension-reduced IK's damped inverses (eq 19 of paper 001) and the Newton
steps of the self-motion continuation. The systems are 3 x 3 or 6 x 6, where an unrolled Cholesky
factorisation is faster than a LAPACK call.
"""

from __future__ import annotations

import math

from continuum_gym.robots.compiled import kernel

__all__ = ["gram_matrix", "cholesky_solve_inplace", "damped_gram_solve", "twist_gram_solve", "gram_solve_3x6"]


@kernel
def gram_matrix(J, mask, damping, out):
    """out (r x r) = J diag(mask) J^T + damping I for J (r x n) and mask (n,) (1.0 keeps a column)."""
    gram_matrix_sized(J, mask, damping, out, out.shape[0], J.shape[1])


@kernel(inline="always")
def gram_matrix_sized(J, mask, damping, out, r, n):
    """``gram_matrix`` with the sizes passed: a caller that passes a constant r (the 6 rows of a twist)
    lets the compiler unroll those loops after inlining (same operations, same order)."""
    for a in range(r):
        for b in range(a + 1):
            acc = 0.0
            for k in range(n):
                acc += J[a, k] * J[b, k] * mask[k]
            out[a, b] = acc
            out[b, a] = acc
        out[a, a] += damping


@kernel
def cholesky_solve_inplace(A, B):
    """Solve A X = B for symmetric positive-definite A (n x n) and B (n x m); B becomes X, A its factor.

    Small dense systems (6 x 6 damped Gram matrices) are faster here than a LAPACK call.
    Returns False if A is not numerically positive definite.
    """
    return cholesky_solve_sized(A, B, A.shape[0], B.shape[1])


@kernel(inline="always")
def cholesky_solve_sized(A, B, n, m):
    """``cholesky_solve_inplace`` with the sizes passed (constants from the caller unroll the loops)."""
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        if s <= 0.0:
            return False
        ljj = math.sqrt(s)
        A[j, j] = ljj
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / ljj
    # The right-hand sides go through each row together: each column's substitution is a chain of
    # dependent divisions, and side by side the columns' chains overlap. Every column sees the same
    # operations in the same order as alone, so the solution is the same to the bit.
    for i in range(n):
        for col in range(m):
            s = B[i, col]
            for k in range(i):
                s -= A[i, k] * B[k, col]
            B[i, col] = s / A[i, i]
    for i in range(n - 1, -1, -1):
        for col in range(m):
            s = B[i, col]
            for k in range(i + 1, n):
                s -= A[k, i] * B[k, col]
            B[i, col] = s / A[i, i]
    return True


@kernel
def damped_gram_solve(J, mask, damping, A, B):
    """Solve (J diag(mask) J^T + damping I) X = B in place: B becomes X, A the Cholesky factor.

    Returns False if the system is not numerically positive definite (then B is undefined).
    """
    gram_matrix(J, mask, damping, A)
    return cholesky_solve_inplace(A, B)


@kernel(inline="always")
def twist_gram_solve(J, mask, damping, A, B):
    """``damped_gram_solve`` for a 6-row (twist) Jacobian and a 6 x 2 right-hand side: sizes fixed at compile time."""
    gram_matrix_sized(J, mask, damping, A, 6, J.shape[1])
    return cholesky_solve_sized(A, B, 6, 2)


@kernel(inline="always")
def gram_solve_3x6(J, mask, damping, A, B):
    """``damped_gram_solve`` for a 3 x 6 Jacobian and a 3 x 6 right-hand side (dimension-reduced IK's damped
    inverses): sizes fixed at compile time."""
    gram_matrix_sized(J, mask, damping, A, 3, 6)
    return cholesky_solve_sized(A, B, 3, 6)
