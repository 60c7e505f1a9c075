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
class BandOp:
    """Rows ``r`` of ``value[r] = sum_o coef[r, o] * q[r + offset + o]`` (per knot interval^order).

    Attributes:
        order: Derivative order 1..3.
        coef: (rows, width) weights; columns that fall outside the path are zero.
        offset: Column of ``coef[:, 0]`` relative to the row index.
        inner: Rows [a, b) that all have the same weights (the shift-invariant kernel);
            empty for a short path.
    """

    order: int
    coef: Array
    offset: int
    inner: tuple[int, int] = (0, 0)

    def apply(self, q: Array) -> Array:
        """Values (rows, m) for frame values q (n, m)."""
        rows, width = self.coef.shape
        win = np.lib.stride_tricks.sliding_window_view(self._padded(q), width, axis=0)[:rows]
        a, b = self.inner
        if b <= a:
            return np.asarray(np.einsum("rw,rmw->rm", self.coef, win))
        out = np.empty((rows, q.shape[1]))
        out[a:b] = win[a:b] @ self.coef[a]  # the shift-invariant rows: one product
        out[:a] = np.einsum("rw,rmw->rm", self.coef[:a], win[:a])
        out[b:] = np.einsum("rw,rmw->rm", self.coef[b:], win[b:])
        return out

    def rows_at(self, q: Array, rows: list[int]) -> Array:
        """Values (len(rows), m) of the given rows only."""
        pad = self._padded(q)
        width = self.coef.shape[1]
        return np.stack([self.coef[r] @ pad[r:r + width] for r in rows])

    def _padded(self, q: Array) -> Array:
        """q with zero frames before and after, so row r reads pad[r:r + width]."""
        rows, width = self.coef.shape
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


@lru_cache(maxsize=32)
def spline_ops(n: int) -> tuple[BandOp, ...]:
    """The six operators (orders 1-3 at knots and at piece middles) for a path of n >= 3
    frames.

    A derivative of order d of the spline is zero on polynomials below degree d (the natural
    quintic spline reproduces them), so it is a weighted sum of the path's d-th differences;
    those weights are what is cut to the band, which keeps the operator exact on such
    polynomials (a long path far from zero loses nothing to the cut).
    """
    k = HALF_WIDTH
    small = n <= 2 * _END + 4 * k
    m = n if small else 2 * _END + 4 * k
    dense = _responses(m)
    ops = []
    for (d, _tau), resp in dense.items():
        weights = resp
        for _ in range(d):  # resp == weights @ (d-th difference matrix): undo one at a time
            weights = -np.cumsum(weights, axis=1)[:, :-1]
        rows_m = resp.shape[0]
        wa, oa = 2 * k + 2 - d, -k
        idx = np.arange(rows_m)[:, None] + oa + np.arange(wa)[None, :]
        inside = (idx >= 0) & (idx < m - d)
        band = np.where(inside, weights[np.arange(rows_m)[:, None], np.clip(idx, 0, m - d - 1)],
                        0.0)
        rows = rows_m + (n - m)
        a = np.zeros((rows, wa))
        inner = (0, 0)
        if small:
            a[:] = band
        else:
            half = rows_m // 2
            a[:half] = band[:half]
            a[rows - (rows_m - half):] = band[half:]
            a[half:rows - (rows_m - half)] = band[half]  # the shift-invariant kernel
            inner = (half, rows - (rows_m - half))
        stencil = np.diff(np.eye(d + 1), d, axis=0)[0]  # d-th difference weights
        coef = np.zeros((rows, wa + d))
        for j, c in enumerate(stencil):
            coef[:, j:j + wa] += c * a
        ops.append(BandOp(d, coef, oa, inner))
    return tuple(ops)


__all__ = ["HALF_WIDTH", "BandOp", "spline_ops"]
