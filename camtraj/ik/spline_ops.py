"""The timing stage's spline as banded linear operators on a path's frame values.

The take moves along the natural C4 quintic spline through the frame solutions
(:mod:`camtraj.timing.quintic`), so what limits its speed is the spline's velocity,
acceleration and jerk, not the frames' finite differences: at the highest frequencies a path
can carry (alternating from frame to frame) the spline's jerk is about four times the third
difference. Per axis the spline is linear in the frame values, and the influence of a frame
falls by a factor of about 0.43 per frame, so each derivative at each evaluation point is,
to well under one percent, a short weighted sum of nearby frames: a banded operator.

The operators are computed once per path length from the spline itself (impulse responses,
the free ends' jerk estimated as the timing stage does), exactly near the ends and as a
shift-invariant kernel inside. Holds and the timing stage's pulls inside the position limits
are not modelled: they only ever lower a path's peak.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from camtraj.timing.path import end_jerk
from camtraj.timing.quintic import DEGREE, hermite_coefficients, solve_knot_derivatives

Array = NDArray[np.float64]

HALF_WIDTH = 6  # frames on either side kept in each operator row (tail below 1% of the peak)
_END = 24  # rows at each end computed exactly (0.43^24 ~ 2e-9 of a frame's influence left)


@dataclass(frozen=True)
class BandOps:
    """k banded operators read side by side (one pass over the path gives all of them):
    ``value[r, :, i] = sum_o coef[r, o, i] * q[r + offset + o]`` (per knot interval^order).

    Attributes:
        orders: Derivative order of each operator (k,).
        rows: Rows each operator has (k,); the rows past them have zero weights.
        coef: (rows, width, k) weights; columns that fall outside the path are zero.
        offset: Column of ``coef[:, 0]`` relative to the row index.
        inner: Rows [a, b) that all have the same weights (the shift-invariant kernels);
            empty for a short path.
    """

    orders: tuple[int, ...]
    rows: tuple[int, ...]
    coef: Array
    offset: int
    inner: tuple[int, int] = (0, 0)

    def apply(self, q: Array) -> Array:
        """Values (rows, m, k) for frame values q (n, m)."""
        rows, width, k = self.coef.shape
        padded = self._padded(q)
        win = np.lib.stride_tricks.sliding_window_view(padded, width, axis=0)[:rows]
        a, b = self.inner
        if b <= a:
            return np.asarray(np.einsum("rwk,rmw->rmk", self.coef, win))
        out = np.empty((rows, q.shape[1], k))
        # the shift-invariant rows: one product, over windows along contiguous frame rows
        frames = np.ascontiguousarray(padded.T)  # (m, rows + width)
        inner = np.lib.stride_tricks.sliding_window_view(frames, width, axis=1)[:, a:b]
        out[a:b] = (inner @ self.coef[a]).transpose(1, 0, 2)
        out[:a] = np.einsum("rwk,rmw->rmk", self.coef[:a], win[:a])
        out[b:] = np.einsum("rwk,rmw->rmk", self.coef[b:], win[b:])
        return out

    def _padded(self, q: Array) -> Array:
        """q with zero frames before and after, so row r reads pad[r:r + width]."""
        rows, width, _ = self.coef.shape
        pad = np.zeros((rows + width, q.shape[1]))
        lo = -self.offset  # q[j] sits at padded index j + lo
        pad[lo:lo + q.shape[0]] = q[: rows + width - lo]
        return pad


def _derivative(c: Array, d: int, tau: float) -> Array:
    acc = c[:, DEGREE] * math.perm(DEGREE, d)
    for k in range(DEGREE - 1, d - 1, -1):
        acc = acc * tau + c[:, k] * math.perm(k, d)
    return np.asarray(acc)


def _responses(n: int) -> dict[tuple[int, float], Array]:
    """Dense (rows, n) responses of each (order, evaluation point): knots 0..n-1 (tau 0, the
    last knot as the end of the last piece) and piece middles (tau 0.5)."""
    y = np.eye(n)
    none = np.zeros((n, n), dtype=bool)
    v, w = solve_knot_derivatives(y, none, np.zeros((n, n)), np.zeros((n, n)),
                                  end_jerk(y, none[1:]))
    c = hermite_coefficients(y, v, w)  # (n - 1, 6, n)
    out = {}
    for d in (1, 2, 3):
        knots = np.concatenate([_derivative(c, d, 0.0), _derivative(c[-1:], d, 1.0)])
        out[(d, 0.0)] = knots
        out[(d, 0.5)] = _derivative(c, d, 0.5)
    return out


@lru_cache(maxsize=4)  # per path length: the solve's own, not kept for long
def spline_ops(n: int) -> BandOps:
    """The six operators (orders 1-3 at knots and at piece middles, in that order: velocity
    at knots, at middles, acceleration at knots, ...) for a path of n >= 3 frames, side by
    side (n rows; the middles' last row is empty).

    A derivative of order d of the spline is zero on polynomials below degree d (the natural
    quintic spline reproduces them), so it is a weighted sum of the path's d-th differences;
    those weights are what is cut to the band, which keeps the operator exact on such
    polynomials (a long path far from zero loses nothing to the cut).
    """
    k = HALF_WIDTH
    small = n <= 2 * _END + 4 * k
    m = n if small else 2 * _END + 4 * k
    dense = _responses(m)
    width = 2 * k + 2
    coef = np.zeros((n, width, len(dense)))
    orders, counts = [], []
    inner = (0, n)
    for i, ((d, _tau), resp) in enumerate(dense.items()):
        weights = resp
        for _ in range(d):  # resp == weights @ (d-th difference matrix): undo one at a time
            weights = -np.cumsum(weights, axis=1)[:, :-1]
        rows_m = resp.shape[0]
        wa, oa = width - d, -k
        idx = np.arange(rows_m)[:, None] + oa + np.arange(wa)[None, :]
        inside = (idx >= 0) & (idx < m - d)
        if m > d:
            band = np.where(inside,
                            weights[np.arange(rows_m)[:, None], np.clip(idx, 0, m - d - 1)],
                            0.0)
        else:  # d or fewer frames lie on a polynomial below degree d: the derivative is zero
            band = np.zeros(idx.shape)
        rows = rows_m + (n - m)
        a = np.zeros((rows, wa))
        if small:
            a[:] = band
            inner = (0, 0)
        else:
            half = rows_m // 2
            a[:half] = band[:half]
            a[rows - (rows_m - half):] = band[half:]
            a[half:rows - (rows_m - half)] = band[half]  # the shift-invariant kernel
            inner = (max(inner[0], half), min(inner[1], rows - (rows_m - half)))
        stencil = np.diff(np.eye(d + 1), d, axis=0)[0]  # d-th difference weights
        for j, c in enumerate(stencil):
            coef[:rows, j:j + wa, i] += c * a
        orders.append(d)
        counts.append(rows)
    return BandOps(tuple(orders), tuple(counts), coef, -k, inner)


__all__ = ["HALF_WIDTH", "BandOps", "spline_ops"]
