"""The joint path through the film frames: a quintic spline per axis, in frame units.

Frame ``i`` sits at the frame coordinate ``x = i``; piece ``i`` (between frames i and i+1) is
``sum_k coef[i, k, :] * (x - i)**k``, k <= 5. How it is built (:meth:`FramePath.fit`):

* **Quintic, C4.** The jerk is checked, so it must be meaningful: a quintic spline has
  continuous jerk and snap (a cubic's jerk is piecewise constant and jumps at every frame).
* **Holds stay still.** A hold is a hold of the camera: a frame pair where every joint moves
  by at most :data:`HOLD_TOL` (the whole robot still; optionally also where the caller says
  the camera holds). There every axis is a straight line (exactly constant for equal
  solutions) and every moving stretch is its own spline, clamped to the hold's velocity and
  zero acceleration. One axis passing a turning point is no hold: it stays on the spline.
* **An end at rest stays at rest.** Where the camera is at rest at the first or last frame,
  the caller says how (:data:`AT_REST`, :data:`SETTLED`). Stopping hard into it (at rest
  but decelerating), the spline's velocity there is zero, its acceleration stays free and
  its jerk is set as at a free end, so a move eased from rest (any polynomial with zero
  slope at the end, up to a cubic) is reproduced exactly. Settled into it (eased so its
  acceleration also fades), the end is clamped as next to a hold: velocity and acceleration
  zero, so the run-up and run-out neither move nor accelerate the robot on that frame. The
  robot then stands still on that frame, however its redundant axes move after it.
* **Free ends do not extrapolate.** At the first and last frame of the shot nothing is known
  beyond the frames. The spline's velocity and acceleration there follow from the frames
  themselves; only its jerk is set, to that of a least-squares cubic through the end frames,
  and its snap to zero (:func:`end_jerk`). This reproduces any cubic motion exactly, and a
  disturbance of one end frame moves the acceleration and jerk no more than it would in the
  interior. Setting velocity and acceleration from the interpolating polynomial through the
  end frames instead (as before) amplified a curvature change near the end about five-fold in
  jerk, into acceleration and jerk spikes on the last frame intervals.
* **Never outside the limits.** Where a piece overshoots an axis's position range between
  frames that are inside it, the velocity and acceleration at its two knots are changed as
  little as possible to bring the Bezier control points next to them inside (at a knot on
  the limit: stop there, curve back), those knots are clamped and the rest refitted. A piece
  lies in the convex hull of its control points, so it then stays inside the range. A frame
  beyond the range (by round-off, or a violation the checks report) widens the range of its
  own pieces to that frame and no further.

The constant coefficient of every piece is the frame solution itself, so the path passes
exactly (bit for bit) through every frame. Time derivatives are ``d^k q/dx^k * (dx/dt)^k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.timing.quintic import (
    DEGREE,
    hermite_coefficients,
    solve_knot_derivatives,
)

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Two consecutive frame solutions whose every joint is closer than this [m or rad] are a hold
#: (the robot still): the path is a straight line between them (constant when they are equal).
HOLD_TOL = 1e-9
#: How an end of the path rests (``FramePath.fit``'s ``rest``, per end and axis): free; at
#: rest (velocity zero, the camera stopping hard into it); settled (velocity and acceleration
#: zero, the camera eased into it).
FREE, AT_REST, SETTLED = 0, 1, 2
#: The levels' names, as the summary gives them.
REST_NAMES = ("free", "at_rest", "settled")
#: Frames of the least-squares cubic that gives the jerk at a free end.
END_FRAMES = 6
#: Rounds of clamp-and-refit at knots whose pieces could leave the position range; after
#: these, any knot still out is scaled without a refit (which always certifies).
_REFIT_ROUNDS = 4


@dataclass(frozen=True, eq=False)
class Samples:
    """Positions and time derivatives at a set of samples, each (m, 8), SI."""

    q: Array
    qd: Array
    qdd: Array
    qddd: Array

    @staticmethod
    def join(parts: list[Samples]) -> Samples:
        return Samples(*(np.concatenate([getattr(p, f) for p in parts])
                         for f in ("q", "qd", "qdd", "qddd")))


@dataclass(frozen=True, eq=False)
class FramePath:
    """The joint path as a function of the frame coordinate (see the module docstring).

    Attributes:
        coef: Piece coefficients, shape (n - 1, 6, 8).
        q_frames: The frame solutions, shape (n, 8) [m, rad].
        dt: Film frame interval [s].
        still: Per axis, whether each frame interval is a straight (hold) line, (n - 1, 8).
        clamped_for_limits: Per axis, the knots whose derivatives were reduced to keep the
            path inside the position range, (n, 8).
        piece_lo, piece_hi: The range each piece stays in, (n - 1, 8): the position range,
            widened only to a frame that lies beyond it. Positions are clipped to it when
            evaluated, which removes the evaluation's round-off (a few ulp) and nothing else.
    """

    coef: Array
    q_frames: Array
    dt: float
    still: BoolArray
    clamped_for_limits: BoolArray
    piece_lo: Array
    piece_hi: Array

    @classmethod
    def fit(cls, q: Array, dt: float, lower: Array, upper: Array,
            hold: BoolArray | None = None, rest: ArrayLike | None = None) -> FramePath:
        """The path through frame solutions ``q`` (n, 8) inside ``[lower, upper]`` (8,).

        ``hold`` (n - 1,): the frame pairs where the camera holds still (default: every
        pair). A pair is a hold when it is one and every joint moves by at most
        :data:`HOLD_TOL` (the whole robot still); one axis passing a turning point is not.
        ``rest`` (2, 8): per axis, how the first / last frame rests (the camera's rest there,
        :func:`~camtraj.ik.shot.camera_rests`): :data:`FREE` (or False), :data:`AT_REST` (or
        True): the spline's velocity there is zero; :data:`SETTLED`: its velocity and
        acceleration are (default: free ends).
        """
        n, m = q.shape
        level = np.zeros((2, m), dtype=np.int8) if rest is None else np.asarray(rest, np.int8)
        diff = np.diff(q, axis=0)
        robot_still = np.all(np.abs(diff) <= HOLD_TOL, axis=1)
        if hold is not None:
            robot_still &= hold
        still = np.repeat(robot_still[:, None], m, axis=1)
        # A knot next to a hold is clamped to the hold's slope and zero acceleration.
        clamped = np.zeros((n, m), dtype=bool)
        v_given = np.zeros((n, m))
        w_given = np.zeros((n, m))
        clamped[1:] |= still
        clamped[:-1] |= still
        v_given[1:] = np.where(still, diff, 0.0)
        v_given[:-1] = np.where(still, diff, v_given[:-1])
        # a settled end is clamped as next to a hold: velocity and acceleration zero
        clamped[[0, -1]] |= level >= SETTLED
        v_given[[0, -1]] = np.where(level >= SETTLED, 0.0, v_given[[0, -1]])
        rest = level >= AT_REST
        jerk = end_jerk(q, still)
        v, w = solve_knot_derivatives(q, clamped, v_given, w_given, jerk, rest=rest)
        # Each knot's room: the range, widened to the frame itself where a frame lies beyond
        # it (by round-off, or a violation the limit checks report): never further out.
        lo, hi = np.minimum(lower, q), np.maximum(upper, q)
        limited = np.zeros((n, m), dtype=bool)
        for _ in range(_REFIT_ROUNDS):
            out = _overshooting_knots(q, v, w, still, lo, hi) & ~limited
            if not np.any(out):
                break
            v_in, w_in = _pulled_inside(q, v, w, lo, hi)
            limited |= out
            clamped |= out
            v_given = np.where(out, v_in, v_given)
            w_given = np.where(out, w_in, w_given)
            v, w = solve_knot_derivatives(q, clamped, v_given, w_given, jerk, rest=rest)
        # Still out after the refits: pull knots in without refitting until no piece leaves
        # its range. A piece whose two knots are both pulled in is inside (convex hull), so
        # this ends after at most n passes.
        for _ in range(n):
            out = _overshooting_knots(q, v, w, still, lo, hi)
            if not np.any(out):
                break
            v_in, w_in = _pulled_inside(q, v, w, lo, hi)
            limited |= out
            v, w = np.where(out, v_in, v), np.where(out, w_in, w)
        coef = hermite_coefficients(q, v, w)
        # Holds are exact straight lines.
        coef[:, 1] = np.where(still, diff, coef[:, 1])
        coef[:, 2:] = np.where(still[:, None, :], 0.0, coef[:, 2:])
        return cls(coef=coef, q_frames=q, dt=dt, still=still, clamped_for_limits=limited,
                   piece_lo=np.minimum(lo[:-1], lo[1:]), piece_hi=np.maximum(hi[:-1], hi[1:]))

    @property
    def n(self) -> int:
        return int(self.q_frames.shape[0])

    def at(self, x: Array, order: int = 3) -> list[Array]:
        """Derivatives 0..order with respect to x at frame coordinates x, each (m, 8)."""
        last = self.n - 2
        idx = np.clip(np.floor(x).astype(np.int64), 0, last)
        tau = (x - idx)[:, None]
        c = self.coef[idx]  # (m, 6, 8)
        out: list[Array] = []
        for d in range(order + 1):
            # Horner on the d-th derivative's coefficients k!/(k-d)! c_k.
            acc = c[:, DEGREE] * math.perm(DEGREE, d)
            for k in range(DEGREE - 1, d - 1, -1):
                acc = acc * tau + c[:, k] * math.perm(k, d)
            out.append(acc)
        out[0] = np.clip(out[0], self.piece_lo[idx], self.piece_hi[idx])
        out[0] = np.where((x >= self.n - 1)[:, None], self.q_frames[-1], out[0])
        on_knot = x == idx
        out[0][on_knot] = self.q_frames[idx[on_knot]]
        return out

    def on_grid(self, ticks: int) -> tuple[Array, list[Array]]:
        """Frame coordinates and derivatives 0..3 on ``ticks`` equal steps per frame.

        Frame i is sample ``i * ticks``, exactly at its solution. Every frame interval has
        the same local coordinates, so this is one matrix product.
        """
        n, m = self.n, self.coef.shape[2]
        tau = np.arange(ticks, dtype=np.float64) / ticks
        k = np.arange(DEGREE + 1)
        fac = np.array([[math.perm(int(kk), d) for kk in k] for d in range(4)], dtype=np.float64)
        powers = tau[:, None] ** np.maximum(k[None, :] - np.arange(4)[:, None, None], 0)
        basis = np.where(k >= np.arange(4)[:, None, None], fac[:, None, :] * powers, 0.0)
        end = fac @ self.coef[-1]  # tau = 1 on the last piece, (4, 8)
        out = []
        for d in range(4):  # each written in place: no temporary of the grid's size
            values = np.empty(((n - 1) * ticks + 1, m))
            np.matmul(basis[d], self.coef, out=values[:-1].reshape(n - 1, ticks, m))
            values[-1] = end[d]
            out.append(values)
        pos = out[0][:-1].reshape(n - 1, ticks, m)
        np.clip(pos, self.piece_lo[:, None], self.piece_hi[:, None], out=pos)
        out[0][::ticks] = self.q_frames
        return uniform_x(n, ticks), out

    def knot_jerk_from_left(self) -> Array:
        """Third x-derivative at each knot 1..n-1 from the piece before it, (n - 1, 8).

        Jerk may step at a knot next to a hold or clamped for the limits; the stream's
        samples show the value after the step, the checks need both sides.
        """
        c = self.coef
        out: Array = 6.0 * c[:, 3] + 24.0 * c[:, 4] + 60.0 * c[:, 5]
        return out

    def timed_grid(self, ticks: int, xd: float) -> tuple[Array, Samples]:
        """Samples at constant path speed ``xd`` [frames/s] on ``ticks`` steps per frame."""
        x, (p0, p1, p2, p3) = self.on_grid(ticks)
        p1 *= xd  # in place: the grid's arrays become the samples
        p2 *= xd**2
        p3 *= xd**3
        return x, Samples(q=p0, qd=p1, qdd=p2, qddd=p3)


def end_jerk(q: Array, still: BoolArray) -> Array:
    """Jerk (frame units) at the free first and last frame, shape (2, 8).

    That of the least-squares cubic through the (up to) :data:`END_FRAMES` frames of the
    moving stretch at each end; zero (natural) when the stretch has fewer than five frames.
    """
    n, m = q.shape
    jerk = np.zeros((2, m))
    for side in (0, 1):
        # Frames of each axis's end stretch: up to END_FRAMES, stopping at a hold.
        order = slice(None) if side == 0 else slice(None, None, -1)
        moving = ~still[order][: END_FRAMES - 1]
        length = 1 + np.cumprod(moving, axis=0).sum(axis=0)
        for count in range(5, END_FRAMES + 1):
            cols = length == count
            if np.any(cols):
                x = np.arange(count, dtype=np.float64)
                weights = 6.0 * np.linalg.pinv(np.vander(x, 4, increasing=True))[3]
                values = q[:count] if side == 0 else q[n - count :]
                jerk[side, cols] = weights @ values[:, cols]
    return jerk


def _overshooting_knots(
    y: Array, v: Array, w: Array, still: BoolArray, lo: Array, hi: Array
) -> BoolArray:
    """Knots of the moving pieces that leave their range between their frames, (n, 8).

    ``lo``, ``hi`` (n, 8): each knot's range; a piece's range is the union of its two
    knots'. The Bernstein (Bezier) control points of a piece bound it (convex hull); only
    pieces whose control points poke out are solved exactly for their extremes (the roots of
    the derivative).
    """
    n, m = y.shape
    p_lo, p_hi = np.minimum(lo[:-1], lo[1:]), np.maximum(hi[:-1], hi[1:])
    pts = np.stack([y[:-1], y[:-1] + v[:-1] / 5.0, y[:-1] + 0.4 * v[:-1] + w[:-1] / 20.0,
                    y[1:] - 0.4 * v[1:] + w[1:] / 20.0, y[1:] - v[1:] / 5.0, y[1:]])
    maybe = ~still & ((pts.max(axis=0) > p_hi) | (pts.min(axis=0) < p_lo))
    out = np.zeros((n, m), dtype=bool)
    for i, j in zip(*np.nonzero(maybe), strict=True):
        c = hermite_coefficients(y[i : i + 2, j : j + 1], v[i : i + 2, j : j + 1],
                                 w[i : i + 2, j : j + 1])[0, :, 0]
        deriv = np.arange(1, DEGREE + 1) * c[1:]  # increasing powers
        roots = np.roots(deriv[::-1]) if np.any(deriv[1:] != 0.0) else np.zeros(0)
        # Near-double roots (an extreme touching the limit) come out slightly complex.
        tau = roots.real[(np.abs(roots.imag) < 1e-6) & (roots.real > 0) & (roots.real < 1)]
        values = np.polynomial.polynomial.polyval(tau, c)
        if np.any(values > p_hi[i, j]) or np.any(values < p_lo[i, j]):
            out[i, j] = out[i + 1, j] = True
    return out


def _pulled_inside(
    y: Array, v: Array, w: Array, lower: Array, upper: Array
) -> tuple[Array, Array]:
    """Knot derivatives changed as little as possible so that the four control points next
    to each knot are inside ``[lower, upper]`` (per knot, (n, 8), containing the knot).

    The control points of a piece from (y0, v0, w0) to (y1, v1, w1) are y0, y0 + v0/5,
    y0 + 2 v0/5 + w0/20, y1 - 2 v1/5 + w1/20, y1 - v1/5, y1. Next to a knot that leaves
    ``room`` to the nearer limit this needs ``|v| <= 5 room`` and then ``w / 20`` within
    ``0.4 |v|`` of both limits: at a knot on a limit the path stops there (v = 0) and may
    only curve back. With all its control points inside, a piece stays inside (convex hull).
    """
    room_up = np.maximum(upper - y, 0.0)
    room_down = np.maximum(y - lower, 0.0)
    speed = np.minimum(np.abs(v), 5.0 * np.minimum(room_up, room_down))
    v2 = np.copysign(speed, v)
    w2 = np.clip(w, -20.0 * (room_down - 0.4 * speed), 20.0 * (room_up - 0.4 * speed))
    return v2, w2


def runs(mask: BoolArray) -> list[tuple[int, int]]:
    """Half-open index ranges [a, b) of the True runs of a 1-D mask."""
    padded = np.concatenate([[0], mask.astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def uniform_x(n: int, ticks: int) -> Array:
    """Frame coordinates of a uniform grid with ``ticks`` samples per frame interval.

    Frame i is sample i*ticks and its coordinate is exactly i.
    """
    return np.arange((n - 1) * ticks + 1, dtype=np.float64) / ticks

