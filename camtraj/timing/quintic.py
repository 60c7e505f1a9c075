"""Quintic splines on unit-spaced knots, in numpy only (no per-axis or per-knot Python loops).

A piece between knots ``i`` and ``i + 1`` is the quintic Hermite polynomial fixed by the
value, first and second derivative at both of its knots (``y``, ``v``, ``w``), so any choice
of knot derivatives gives a C2 curve through the knots. A C4 spline (continuous jerk and
snap) follows from two more conditions at every interior knot; at the ends of a stretch the
derivatives are either given (*clamped*) or left free with zero third and fourth derivative
(*natural*). The natural quintic spline is the interpolant with the least integrated squared
third derivative (jerk) of all curves through the knots: nothing about the ends is made up.

The conditions form a block-tridiagonal system in ``(v_i, w_i)`` with 2x2 blocks, solved
as a banded system by LAPACK (one call for all axes that share their clamped knots).

Units: everything here is per knot interval ("frame units"); the caller scales to time.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

DEGREE = 5


def hermite_coefficients(y: Array, v: Array, w: Array) -> Array:
    """Polynomial coefficients of every piece from knot values and derivatives.

    Args:
        y: Knot values, shape (n, m) (n knots, m independent curves, e.g. axes).
        v: First derivatives at the knots, shape (n, m).
        w: Second derivatives at the knots, shape (n, m).

    Returns:
        ``c`` of shape (n - 1, 6, m): piece ``i`` is ``sum_k c[i, k] * tau**k``, tau in [0, 1].
        ``c[i, 0] == y[i]`` exactly, so the curve passes through every knot bit for bit.
    """
    y0, y1 = y[:-1], y[1:]
    v0, v1 = v[:-1], v[1:]
    w0, w1 = w[:-1], w[1:]
    d = y1 - y0
    c = np.empty((y.shape[0] - 1, DEGREE + 1, y.shape[1]))
    c[:, 0] = y0
    c[:, 1] = v0
    c[:, 2] = 0.5 * w0
    c[:, 3] = 10.0 * d - 6.0 * v0 - 4.0 * v1 - 1.5 * w0 + 0.5 * w1
    c[:, 4] = -15.0 * d + 8.0 * v0 + 7.0 * v1 + 1.5 * w0 - w1
    c[:, 5] = 6.0 * d - 3.0 * v0 - 3.0 * v1 - 0.5 * w0 + 0.5 * w1
    return c


def solve_knot_derivatives(
    y: Array, clamped: BoolArray, v_given: Array, w_given: Array,
    end_jerk: Array | None = None, end_snap: Array | None = None,
    rest: BoolArray | None = None,
) -> tuple[Array, Array]:
    """First and second knot derivatives of the C4 quintic spline through ``y``.

    Every knot is one of:

    * clamped (``clamped[i]``): ``v = v_given[i]``, ``w = w_given[i]``; the curve on either
      side is fitted independently, so a clamped knot splits the spline into stretches;
    * the first or last knot, not clamped: a natural end (zero jerk and snap there, or the
      given ``end_jerk`` and ``end_snap``); an end at rest (``rest``) has zero velocity and
      the given jerk instead (its acceleration is free);
    * otherwise an interior knot: jerk and snap continuous across it.

    Two knots, both natural, are joined by the straight line.

    Args:
        y: Knot values, shape (n, m), n >= 2.
        clamped: Which knots are clamped, shape (n, m).
        v_given: First derivatives of the clamped knots, shape (n, m) (others ignored).
        w_given: Second derivatives of the clamped knots, shape (n, m) (others ignored).
        end_jerk, end_snap: Third and fourth derivatives at the first and last knot, (2, m)
            (default zero), where those are free ends.
        rest: Whether the first / last knot of each axis, where free, is at rest, (2, m)
            (default: none): its snap condition becomes ``v = 0`` (a polynomial with zero
            slope there is reproduced).

    Returns:
        ``(v, w)``, each of shape (n, m); equal to the given values (bit for bit) at clamped
        knots.
    """
    n, m = y.shape
    d = np.diff(y, axis=0)  # (n-1, m)
    if n == 2:
        # One piece between two natural ends has no unique answer (every quadratic through
        # two points has zero jerk): take the straight line.
        lone = ~clamped[0] & ~clamped[1]
        clamped = clamped | lone
        v_given = np.where(lone, d[0], v_given)
        w_given = np.where(lone, 0.0, w_given)
    lo = np.zeros((m, n, 2, 2))  # couples knot i to knot i-1
    di = np.zeros((m, n, 2, 2))  # couples knot i to itself
    up = np.zeros((m, n, 2, 2))  # couples knot i to knot i+1
    rhs = np.zeros((m, n, 2))
    if n > 2:
        dl, dr = d[:-1].T, d[1:].T  # (m, n-2)
        # Jerk continuity, divided by 3; snap continuity, divided by -24.
        lo[:, 1:-1] = [[-8.0, -1.0], [7.0, 1.0]]
        di[:, 1:-1] = [[0.0, 6.0], [16.0, 0.0]]
        up[:, 1:-1] = [[8.0, -1.0], [7.0, -1.0]]
        rhs[:, 1:-1, 0] = 20.0 * (dr - dl)
        rhs[:, 1:-1, 1] = 15.0 * (dr + dl)
    # Natural ends: jerk / 3 and snap / 12 of the end piece vanish.
    di[:, 0] = [[-12.0, -3.0], [16.0, 3.0]]
    up[:, 0] = [[-8.0, 1.0], [14.0, -2.0]]
    ej = np.zeros((2, m)) if end_jerk is None else end_jerk
    es = np.zeros((2, m)) if end_snap is None else end_snap
    rhs[:, 0, 0] = -20.0 * d[0] + ej[0] / 3.0
    rhs[:, 0, 1] = 30.0 * d[0] + es[0] / 12.0
    lo[:, -1] = [[-8.0, -1.0], [-14.0, -2.0]]
    di[:, -1] = [[-12.0, 3.0], [-16.0, 3.0]]
    rhs[:, -1, 0] = -20.0 * d[-1] + ej[1] / 3.0
    rhs[:, -1, 1] = -30.0 * d[-1] + es[1] / 12.0
    at_rest = np.zeros((2, m), dtype=bool) if rest is None else np.asarray(rest, dtype=bool)
    for side, knot, far in ((0, 0, up), (1, n - 1, lo)):  # at rest: v = 0 for the snap
        axes = at_rest[side]
        di[axes, knot, 1] = [1.0, 0.0]
        far[axes, knot, 1] = 0.0
        rhs[axes, knot, 1] = 0.0
    # Clamped knots.
    cl = clamped.T  # (m, n)
    lo[cl] = 0.0
    up[cl] = 0.0
    di[cl] = np.eye(2)
    rhs[cl] = np.stack([v_given.T[cl], w_given.T[cl]], axis=-1)
    lo[:, 0] = 0.0
    up[:, -1] = 0.0
    same: dict[bytes, list[int]] = {}  # axes with the same clamped knots: the same matrix
    for axis in range(m):
        same.setdefault(cl[axis].tobytes() + at_rest[:, axis].tobytes(), []).append(axis)
    x = _solve_block_tridiagonal(
        lo.transpose(2, 3, 0, 1), di.transpose(2, 3, 0, 1), up.transpose(2, 3, 0, 1),
        rhs.transpose(2, 0, 1), list(same.values()),
    )  # [r, m, n]
    v = np.where(clamped, v_given, x[0].T)
    w = np.where(clamped, w_given, x[1].T)
    return v, w


def _solve_block_tridiagonal(lo: Array, di: Array, up: Array, rhs: Array,
                             same: list[list[int]]) -> Array:
    """Solve ``lo_i x_{i-1} + di_i x_i + up_i x_{i+1} = rhs_i`` for every system.

    Args:
        lo, di, up: 2x2 blocks stored as ``[r, c, m, n]`` (m independent systems of n
            block rows); ``lo[..., 0]`` and ``up[..., -1]`` must be zero.
        rhs: Right-hand sides, ``[r, m, n]``.
        same: The systems grouped by equal matrices (every system in one group).

    Returns:
        ``x`` as ``[r, m, n]``.

    Each system is a band of three scalars either side of the diagonal (unknowns ordered
    v_0, w_0, v_1, ...), solved by LAPACK's banded LU with partial pivoting (scipy's
    ``solve_banded``); systems with the same matrix (axes with the same clamped knots) are
    solved in one call with several right-hand sides.
    """
    from scipy.linalg import solve_banded

    n, m = di.shape[-1], di.shape[-2]
    first = [axes[0] for axes in same]  # each group's matrix, as its first system's
    # ab[3 + row - col, col] holds the entry (row, col); block row i, entry (r, c) of the
    # block coupling knot i with knot i + s sits at row 2 i + r, column 2 (i + s) + c
    ab = np.zeros((len(same), 7, 2 * n))
    for shift, blocks in ((-1, lo), (0, di), (1, up)):
        rows = np.arange(max(0, -shift), min(n, n - shift))  # knots with a partner
        for r in range(2):
            for c in range(2):
                ab[:, 3 + r - c - 2 * shift, 2 * (rows + shift) + c] = \
                    blocks[r, c][first][:, rows]
    b = rhs.transpose(1, 2, 0).reshape(m, 2 * n)  # [m, 2n], v and w interleaved
    x = np.empty_like(b)
    for k, axes in enumerate(same):
        x[axes] = solve_banded((3, 3), ab[k], b[axes].T, check_finite=False).T
    return np.ascontiguousarray(x.reshape(m, n, 2).transpose(2, 0, 1))
