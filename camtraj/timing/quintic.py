"""Quintic splines on unit-spaced knots, in numpy only (no per-axis or per-knot Python loops).

A piece between knots ``i`` and ``i + 1`` is the quintic Hermite polynomial fixed by the
value, first and second derivative at both of its knots (``y``, ``v``, ``w``), so any choice
of knot derivatives gives a C2 curve through the knots. A C4 spline (continuous jerk and
snap) follows from two more conditions at every interior knot; at the ends of a stretch the
derivatives are either given (*clamped*) or left free with zero third and fourth derivative
(*natural*). The natural quintic spline is the interpolant with the least integrated squared
third derivative (jerk) of all curves through the knots: nothing about the ends is made up.

The conditions form a block-tridiagonal system in ``(v_i, w_i)`` with 2x2 blocks; it is
solved for all axes at once by parallel cyclic reduction (log2(n) vectorised steps).

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
) -> tuple[Array, Array]:
    """First and second knot derivatives of the C4 quintic spline through ``y``.

    Every knot is one of:

    * clamped (``clamped[i]``): ``v = v_given[i]``, ``w = w_given[i]``; the curve on either
      side is fitted independently, so a clamped knot splits the spline into stretches;
    * the first or last knot, not clamped: a natural end (zero jerk and snap there);
    * otherwise an interior knot: jerk and snap continuous across it.

    Two knots, both natural, are joined by the straight line.

    Args:
        y: Knot values, shape (n, m), n >= 2.
        clamped: Which knots are clamped, shape (n, m).
        v_given: First derivatives of the clamped knots, shape (n, m) (others ignored).
        w_given: Second derivatives of the clamped knots, shape (n, m) (others ignored).

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
    # Clamped knots.
    cl = clamped.T  # (m, n)
    lo[cl] = 0.0
    up[cl] = 0.0
    di[cl] = np.eye(2)
    rhs[cl] = np.stack([v_given.T[cl], w_given.T[cl]], axis=-1)
    lo[:, 0] = 0.0
    up[:, -1] = 0.0
    x = _solve_block_tridiagonal(
        lo.transpose(2, 3, 0, 1), di.transpose(2, 3, 0, 1), up.transpose(2, 3, 0, 1),
        rhs.transpose(2, 0, 1),
    )  # [r, m, n]
    v = np.where(clamped, v_given, x[0].T)
    w = np.where(clamped, w_given, x[1].T)
    return v, w


def _inv(a: Array) -> Array:
    """Inverses of 2x2 matrices stored as ``a[r, c, ...]``."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    out = np.empty_like(a)
    np.divide(a[1, 1], det, out=out[0, 0])
    np.divide(a[0, 0], det, out=out[1, 1])
    np.divide(a[0, 1], -det, out=out[0, 1])
    np.divide(a[1, 0], -det, out=out[1, 0])
    return out


def _mul(a: Array, b: Array) -> Array:
    """Products of 2x2 matrices ``a[r, c, ...]`` with matrices ``b[r, c, ...]`` or vectors
    ``b[r, ...]`` (einsum with the block index first is fast; matmul on 2x2 blocks is not)."""
    if b.ndim == a.ndim:
        out: Array = np.einsum("ij...,jk...->ik...", a, b)
        return out
    vec: Array = np.einsum("ij...,j...->i...", a, b)
    return vec


def _pad(a: Array, size: int, *, front: bool, fill: Array | None = None) -> Array:
    """``a`` (blocks along the last axis) with one block of ``fill`` (default zero) in front
    or behind, cut to ``size`` blocks."""
    out = np.zeros((*a.shape[:-1], size))
    if fill is not None:
        out[..., 0 if front else size - 1] = fill.reshape(fill.shape + (1,) * (a.ndim - 3))
    k = min(a.shape[-1], size - 1) if front else min(a.shape[-1], size)
    if front:
        out[..., 1 : 1 + k] = a[..., :k]
    else:
        out[..., :k] = a[..., :k]
    return out


_EYE = np.eye(2)
_DENSE = 48  # systems this small are solved as dense matrices


def _solve_dense(lo: Array, di: Array, up: Array, rhs: Array) -> Array:
    """The block-tridiagonal system as one dense (2n x 2n) matrix per system."""
    n, m = di.shape[-1], di.shape[-2]
    mat = np.zeros((m, n, 2, n, 2))
    i = np.arange(n)
    mat[:, i, :, i, :] = di.transpose(3, 2, 0, 1)
    mat[:, i[1:], :, i[1:] - 1, :] = lo[..., 1:].transpose(3, 2, 0, 1)
    mat[:, i[:-1], :, i[:-1] + 1, :] = up[..., :-1].transpose(3, 2, 0, 1)
    b = rhs.transpose(1, 2, 0).reshape(m, 2 * n, 1)
    x = np.linalg.solve(mat.reshape(m, 2 * n, 2 * n), b)
    return np.ascontiguousarray(x.reshape(m, n, 2).transpose(2, 0, 1))


def _solve_block_tridiagonal(lo: Array, di: Array, up: Array, rhs: Array) -> Array:
    """Solve ``lo_i x_{i-1} + di_i x_i + up_i x_{i+1} = rhs_i`` by cyclic reduction.

    Args:
        lo, di, up: 2x2 blocks stored as ``[r, c, m, n]`` (m independent systems of n
            block rows); ``lo[..., 0]`` and ``up[..., -1]`` must be zero.
        rhs: Right-hand sides, ``[r, m, n]``.

    Returns:
        ``x`` as ``[r, m, n]``.

    The odd-numbered unknowns are eliminated from the even-numbered equations, which
    leaves a block-tridiagonal system of half the size; solved the same way, its answer
    gives back the odd unknowns. Every step is vectorised over all systems and rows.
    """
    n = di.shape[-1]
    if n <= _DENSE:
        return _solve_dense(lo, di, up, rhs)
    ne = (n + 1) // 2
    inv_odd = _inv(di[..., 1::2])
    lo_o, up_o, rhs_o = lo[..., 1::2], up[..., 1::2], rhs[..., 1::2]
    # Odd neighbours of every even row: left (index k-1) and right (index k).
    inv_l = _pad(inv_odd, ne, front=True, fill=_EYE)
    inv_r = _pad(inv_odd, ne, front=False, fill=_EYE)
    lo_e, di_e, up_e, rhs_e = lo[..., 0::2], di[..., 0::2], up[..., 0::2], rhs[..., 0::2]
    alpha = -_mul(lo_e, inv_l)
    gamma = -_mul(up_e, inv_r)
    di2 = (di_e + _mul(alpha, _pad(up_o, ne, front=True))
           + _mul(gamma, _pad(lo_o, ne, front=False)))
    rhs2 = (rhs_e + _mul(alpha, _pad(rhs_o, ne, front=True))
            + _mul(gamma, _pad(rhs_o, ne, front=False)))
    lo2 = _mul(alpha, _pad(lo_o, ne, front=True))
    up2 = _mul(gamma, _pad(up_o, ne, front=False))
    x_e = _solve_block_tridiagonal(lo2, di2, up2, rhs2)
    no = n // 2
    x_next = _pad(x_e[..., 1:], no, front=False)
    x_o = _mul(inv_odd, rhs_o - _mul(lo_o, x_e[..., :no]) - _mul(up_o, x_next))
    x = np.empty_like(rhs)
    x[..., 0::2] = x_e
    x[..., 1::2] = x_o
    return x
