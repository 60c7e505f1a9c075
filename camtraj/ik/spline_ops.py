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
from functools import cached_property, lru_cache

import numpy as np
from numpy.typing import NDArray

from camtraj.timing.path import end_jerk, runs
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

    @cached_property
    def inner_pairs(self) -> Array:
        """The shift-invariant kernel's tap pairs (width, k, width): [o, i, d] the product of
        taps o and o + d of operator i (zero past the kernel)."""
        width = self.coef.shape[1]
        kern = self.coef[self.inner[0]]
        out = np.zeros((width, self.coef.shape[2], width))
        for d in range(width):
            out[:width - d, :, d] = kern[:width - d] * kern[d:]
        return out

    @cached_property
    def edge_pairs(self) -> tuple[Array, Array]:
        """The tap pairs of the rows before and after the shift-invariant ones (all rows when
        there are none), each (rows, width * width, k): index o * width + d for taps o and
        o + d."""
        a, b = self.inner
        ranges = ((0, a), (b, self.coef.shape[0])) if b > a else ((0, self.coef.shape[0]),
                                                                    (0, 0))
        return _pair_products(self.coef[ranges[0][0]:ranges[0][1]]), \
            _pair_products(self.coef[ranges[1][0]:ranges[1][1]])

    def apply(self, q: Array) -> Array:
        """Values (rows, m, k) for frame values q (n, m)."""
        rows, width, k = self.coef.shape
        padded = self._padded(q)
        win = windows(padded, width, count=rows)
        a, b = self.inner
        if b <= a:  # rows with their own weights: one batched product (row, m, w) @ (row, w, k)
            return np.asarray(win @ self.coef)
        out = np.empty((rows, q.shape[1], k))
        # the shift-invariant rows: one product, over windows along contiguous frame rows
        frames = np.ascontiguousarray(padded.T)  # (m, rows + width)
        inner = windows(frames, width, axis=1, count=b)[:, a:b]
        out[a:b] = (inner @ self.coef[a]).transpose(1, 0, 2)
        out[:a] = win[:a] @ self.coef[:a]
        out[b:] = win[b:] @ self.coef[b:]
        return out

    def _padded(self, q: Array) -> Array:
        """q with zero frames before and after, so row r reads pad[r:r + width]."""
        rows, width, _ = self.coef.shape
        pad = np.zeros((rows + width, q.shape[1]))
        lo = -self.offset  # q[j] sits at padded index j + lo
        pad[lo:lo + q.shape[0]] = q[: rows + width - lo]
        return pad


def windows(a: Array, width: int, axis: int = 0, count: int | None = None) -> Array:
    """A read-only view of the first ``count`` (default: all) windows of ``width`` along
    ``axis``: window i holds a[i:i + width] there, as a new last axis (numpy's
    ``sliding_window_view`` without its argument checks, which cost more than the products
    that read these views)."""
    total = a.shape[axis] - width + 1
    count = total if count is None else min(count, total)
    shape = (*a.shape[:axis], count, *a.shape[axis + 1:], width)
    strides = (*a.strides, a.strides[axis])
    return np.lib.stride_tricks.as_strided(a, shape, strides, writeable=False)


def _pair_products(coef: Array) -> Array:
    """coef[r, o, i] coef[r, o + d, i] (zero where o + d is past the row) as (rows,
    width * width, k), index o * width + d."""
    rows, width, k = coef.shape
    out = np.zeros((rows, width, width, k))
    for d in range(width):
        out[:, :width - d, d] = coef[:, :width - d] * coef[:, d:]
    return out.reshape(rows, width * width, k)


def _derivative(c: Array, d: int, tau: float) -> Array:
    acc = c[:, DEGREE] * math.perm(DEGREE, d)
    for k in range(DEGREE - 1, d - 1, -1):
        acc = acc * tau + c[:, k] * math.perm(k, d)
    return np.asarray(acc)


def _responses(n: int, ends: tuple[str, str] = ("free", "free")
               ) -> dict[tuple[int, float], Array]:
    """Dense (rows, n) responses of each (order, evaluation point): knots 0..n-1 (tau 0, the
    last knot as the end of the last piece) and piece middles (tau 0.5). ``ends``: each of the
    first and last knot is ``"free"`` (a free end of the shot), ``"rest"`` (a free end where
    the camera is at rest: zero velocity, :func:`~camtraj.ik.shot.camera_rests`),
    ``"settled"`` (an end where the camera settles: velocity and acceleration zero) or
    ``"hold"`` (next to a hold: velocity and acceleration zero, the held frames equal), as the
    timing stage fits them."""
    y = np.eye(n)
    none = np.zeros((n, n), dtype=bool)
    clamped = none.copy()
    clamped[0], clamped[-1] = (end in ("hold", "settled") for end in ends)
    rest = np.array([[end == "rest"] * n for end in ends])
    v, w = solve_knot_derivatives(y, clamped, np.zeros((n, n)), np.zeros((n, n)),
                                  end_jerk(y, none[1:]), rest=rest)
    c = hermite_coefficients(y, v, w)  # (n - 1, 6, n)
    out = {}
    for d in (1, 2, 3):
        knots = np.concatenate([_derivative(c, d, 0.0), _derivative(c[-1:], d, 1.0)])
        out[(d, 0.0)] = knots
        out[(d, 0.5)] = _derivative(c, d, 0.5)
    return out


def hold_runs(held: NDArray[np.bool_]) -> tuple[tuple[int, int], ...]:
    """The frames (first, last) of each run of held frame pairs (n - 1,): the camera holds
    still from ``first`` to ``last`` (the timing stage's :func:`~camtraj.timing.path.runs`,
    as a tuple: :func:`spline_ops` caches by it)."""
    return tuple(runs(held))


@lru_cache(maxsize=4)  # per path length and holds: the solve's own, not kept for long
def spline_ops(n: int, holds: tuple[tuple[int, int], ...] = (),
               rests: tuple[int, int] = (0, 0)) -> BandOps:
    """The six operators (orders 1-3 at knots and at piece middles, in that order: velocity
    at knots, at middles, acceleration at knots, ...) for a path of n >= 3 frames, side by
    side (n rows; the middles' last row is empty).

    ``holds`` (:func:`hold_runs`): where the camera holds, the robot holds (its frames are
    equal), and the timing stage fits each moving stretch between holds as its own spline,
    its knots next to a hold clamped to rest: each stretch gets its own operators, and the
    rows of a hold are zero (a still robot uses no limit). ``rests``: how the camera rests on
    the first / last frame (:func:`~camtraj.ik.shot.camera_rests`, the levels of
    :meth:`~camtraj.timing.path.FramePath.fit`): at rest, the spline's velocity is zero
    there; settled, its velocity and acceleration, as next to a hold.

    A derivative of order d of the spline is zero on polynomials below degree d (the natural
    quintic spline reproduces them), so it is a weighted sum of the path's d-th differences;
    those weights are what is cut to the band, which keeps the operator exact on such
    polynomials (a long path far from zero loses nothing to the cut).
    """
    k = HALF_WIDTH
    width = 2 * k + 2
    orders = (1, 1, 2, 2, 3, 3)
    counts = (n, n - 1, n, n - 1, n, n - 1)
    free = tuple(("free", "rest", "settled")[int(r)] for r in rests)
    if not holds:
        coef, inner = _stretch(n, (free[0], free[1]))
        return BandOps(orders, counts, coef, -k, inner)
    coef = np.zeros((n, width, len(orders)))
    inner = (0, 0)
    start = 0
    for a, b in (*holds, (n - 1, n - 1)):
        if a > start:  # the moving stretch of frames start..a
            part, (ia, ib) = _stretch(a - start + 1, ("hold" if start > 0 else free[0],
                                                      "hold" if a < n - 1 else free[1]))
            coef[start:a + 1] = part
            if ib - ia > inner[1] - inner[0]:  # one shift-invariant range: the longest
                inner = (start + ia, start + ib)
        start = b
    return BandOps(orders, counts, coef, -k, inner)


REST_ROWS = 12
"""Rows next to an end at rest whose band is cut as first differences (:func:`_stretch`); the
rest as d-th differences. Measured on eased paths of 40-400 frames, the operators' worst
error against the spline: 6 rows 4.1%, 12 rows 2.4% (the same path with free ends: 2.4%), 24
rows 5.4%; all rows as first differences 8%, none 13%."""


def _band_cut(resp: Array, undo: int, m: int, d: int) -> Array:
    """The dense responses ``resp`` (rows, m) of order ``d`` cut to the band (rows, width):
    as weights of ``undo``-th differences, those weights kept within the band."""
    k = HALF_WIDTH
    width = 2 * k + 2
    weights = resp
    for _ in range(undo):  # resp == weights @ (difference matrix): undo one at a time
        weights = -np.cumsum(weights, axis=1)[:, :-1]
    rows_m = resp.shape[0]
    wa, oa = width - undo, -k
    idx = np.arange(rows_m)[:, None] + oa + np.arange(wa)[None, :]
    inside = (idx >= 0) & (idx < m - undo)
    if m > d:
        band = np.where(inside,
                        weights[np.arange(rows_m)[:, None], np.clip(idx, 0, m - undo - 1)],
                        0.0)
    else:  # d or fewer frames lie on a polynomial below degree d: the derivative is zero
        band = np.zeros(idx.shape)
    stencil = np.diff(np.eye(undo + 1), undo, axis=0)[0]  # the differences' weights
    cut = np.zeros((rows_m, width))
    for j, c in enumerate(stencil):
        cut[:, j:j + wa] += c * band
    return cut


def _stretch(n: int, ends: tuple[str, str]) -> tuple[Array, tuple[int, int]]:
    """:func:`spline_ops`' weights (n, width, 6) of one spline of n >= 2 frames, with its
    ends free, at rest or next to a hold (:func:`_responses`), and its shift-invariant
    rows."""
    k = HALF_WIDTH
    small = n <= 2 * _END + 4 * k
    m = n if small else 2 * _END + 4 * k
    dense = _responses(m, ends)
    coef = np.zeros((n, 2 * k + 2, len(dense)))
    inner = (0, n)
    for i, ((d, _tau), resp) in enumerate(dense.items()):
        # A free spline reproduces polynomials below degree 5, so its order-d responses are
        # weights of d-th differences; clamped to rest next to a hold it reproduces only
        # constants among them, so its responses are weights of first differences. At rest
        # (or settled) at a shot's end it reproduces only constants near that end, and
        # nearly all of them further in: the rows near it are cut as first differences, the
        # others as d-th (settled ends cut like holds throughout were up to 9% off the
        # spline in jerk mid-shot on eased paths of 40-150 frames; so, 5% and under).
        if "hold" in ends:
            cut = _band_cut(resp, 1, m, d)
        else:
            cut = _band_cut(resp, d, m, d)
            near = np.zeros(resp.shape[0], dtype=bool)
            near[:REST_ROWS] = ends[0] != "free"
            near[max(0, resp.shape[0] - REST_ROWS):] |= ends[1] != "free"
            if near.any():
                cut[near] = _band_cut(resp, 1, m, d)[near]
        cut = _polynomials_kept(resp, cut, -k)
        rows_m = resp.shape[0]
        rows = rows_m + (n - m)
        if small:
            coef[:rows, :, i] = cut
            inner = (0, 0)
        else:
            half = rows_m // 2
            coef[:half, :, i] = cut[:half]
            coef[rows - (rows_m - half):rows, :, i] = cut[half:]
            coef[half:rows - (rows_m - half), :, i] = cut[half]  # the shift-invariant kernel
            inner = (max(inner[0], half), min(inner[1], rows - (rows_m - half)))
    return coef, inner


CUT_DEGREE = 4
"""Each operator row keeps its exact value on every polynomial of degree up to this."""


def _polynomials_kept(resp: Array, cut: Array, offset: int) -> Array:
    """The band rows ``cut`` (rows, width) of the dense responses ``resp`` (rows, m) (row r
    reads frames r + offset ...), each changed as little as can be so that it gives its dense
    row's value on every polynomial of degree up to :data:`CUT_DEGREE` (zero weight outside
    the path).

    Next to a hold the spline reproduces only constants, so its rows are cut as weights of
    first differences, and the cut tail multiplies the path's velocity: on a minute-long
    eased move clamped to rest at both ends, the cut rows gave jerk 2,000 times the spline's
    own in the middle of the move, and the refinement lowered that phantom instead of the
    take's use. Kept exact on polynomials, the rows are exact wherever the path is locally
    one (a free spline's cut of d-th differences already is below degree d and changes
    little)."""
    rows, m = resp.shape
    width = cut.shape[1]
    r = np.arange(rows)[:, None]
    cols = r + offset + np.arange(width)[None, :]  # (rows, width)
    inside = (cols >= 0) & (cols < m)
    # each row's polynomials in frames from the row, scaled by the band's width
    basis = np.vander(((np.arange(m)[None, :] - r) / width).ravel(), CUT_DEGREE + 1,
                      increasing=True).reshape(rows, m, CUT_DEGREE + 1)
    want = np.einsum("rm,rmd->rd", resp, basis)  # each row's values on them
    band = np.take_along_axis(basis, np.clip(cols, 0, m - 1)[:, :, None], axis=1)
    band *= inside[:, :, None]  # (rows, width, degree + 1); no weight outside the path
    kept = np.where(inside, cut, 0.0)
    miss = want - np.einsum("rw,rwd->rd", kept, band)
    # the least change of each row's weights that gives its values: pinv of (degree + 1, width)
    fix = np.einsum("rwd,rd->rw", np.linalg.pinv(band.transpose(0, 2, 1)), miss)
    return np.asarray(kept + fix * inside)


__all__ = ["HALF_WIDTH", "BandOps", "hold_runs", "spline_ops", "windows"]
