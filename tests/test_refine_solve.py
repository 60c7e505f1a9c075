"""The refinement's banded normal-equation solve against a dense solve of the same system."""

from __future__ import annotations

import numpy as np
import pytest

from camtraj.ik.refine import _solve_banded


def dense(H: np.ndarray, mu: float) -> np.ndarray:
    """The (2n, 2n) matrix the blocks H (n, D, 2, 2) stand for, damped as documented."""
    n, width = H.shape[:2]
    A = np.zeros((2 * n, 2 * n))
    for d in range(width):
        for i in range(n - d):
            A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2] = H[i, d]
            if d > 0:
                A[2 * (i + d):2 * (i + d) + 2, 2 * i:2 * i + 2] = H[i, d].T
    diag = np.diag(A).copy()
    A[np.diag_indices(2 * n)] = diag * (1.0 + mu) + 1e-9 * max(diag.max(), 1e-12) + 1e-12
    return A


@pytest.mark.parametrize("width", [4, 14])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7, 8, 13, 14, 15, 64, 97])
def test_banded_solve_equals_a_dense_solve(n: int, width: int) -> None:
    """Frames coupled up to ``width - 1`` apart (third differences: 4; the refinement's
    spline operators: 14)."""
    rng = np.random.default_rng(n)
    rows = []  # each row of a Gauss-Newton Jacobian reads `width` consecutive frames
    for first in range(-width + 1, n):
        for _ in range(2):
            row = np.zeros(2 * n)
            cols = np.arange(max(0, 2 * first), min(2 * n, 2 * (first + width)))
            row[cols] = rng.normal(size=cols.size)
            rows.append(row)
    J = np.array(rows)
    A = J.T @ J + np.diag(rng.uniform(0.1, 1.0, 2 * n))
    H = np.zeros((n, width, 2, 2))
    for d in range(width):
        for i in range(n - d):
            H[i, d] = A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2]
    g = rng.normal(size=(n, 2))
    for mu in (0.0, 0.3):
        want = np.linalg.solve(dense(H, mu), -g.ravel()).reshape(n, 2)
        got = _solve_banded(H, g, mu)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-11)
