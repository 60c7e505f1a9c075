"""The refinement's banded normal-equation solve against a dense solve of the same system."""

from __future__ import annotations

import numpy as np
import pytest

from camtraj.ik.refine import _solve_banded


def dense(H: list[np.ndarray], mu: float) -> np.ndarray:
    """The (2n, 2n) matrix the blocks stand for, damped as the solver documents it."""
    n = H[0].shape[0]
    A = np.zeros((2 * n, 2 * n))
    for d, blk in enumerate(H):
        for i in range(n - d):
            A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2] = blk[i]
            if d > 0:
                A[2 * (i + d):2 * (i + d) + 2, 2 * i:2 * i + 2] = blk[i].T
    diag = np.diag(A).copy()
    A[np.diag_indices(2 * n)] = diag * (1.0 + mu) + 1e-9 * max(diag.max(), 1e-12) + 1e-12
    return A


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7, 8, 13, 64, 97])
def test_banded_solve_equals_a_dense_solve(n: int) -> None:
    rng = np.random.default_rng(n)
    J = np.zeros((2 * n + 6, 2 * n))  # third differences of two curves: a banded Gauss-Newton
    for row in range(J.shape[0]):
        cols = np.arange(max(0, row - 7), min(2 * n, row + 1))
        J[row, cols] = rng.normal(size=cols.size)
    A = J.T @ J + np.diag(rng.uniform(0.1, 1.0, 2 * n))
    H = [np.zeros((n, 2, 2)) for _ in range(4)]
    for d in range(4):
        for i in range(n - d):
            H[d][i] = A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2]
    # the matrix has no entries beyond three frames apart (else the blocks could not hold it)
    far = np.abs(np.subtract.outer(np.arange(2 * n) // 2, np.arange(2 * n) // 2)) > 3
    A[far] = 0.0
    g = rng.normal(size=(n, 2))
    for mu in (0.0, 0.3):
        want = np.linalg.solve(dense(H, mu), -g.ravel()).reshape(n, 2)
        got = _solve_banded(H, g, mu)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-11)
