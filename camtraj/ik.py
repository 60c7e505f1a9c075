"""Inverse kinematics of the PRRPR-S camera robot by the SM method.

The SM method (He 2018) fixes the two redundant prismatic axes, track (r1) and extend (r4), solves
the remaining six axes in closed form, and searches (r1, r4) for the solution that minimises the
weighted axis motion ``F = sum(w_i * |q_i - q_i,prev|)``.

Closed-form six-axis substructure (design.md §3). The flange origin is the wrist centre W, so
with r1 and r4 fixed:

* the shoulder S = (r1 + r10, 0, r2) lies on the vertical rotate axis; rotate points the arm's
  vertical plane at W (front branch) or away from it (back branch);
* in that plane the arm is a planar chain S -> U (l3, perpendicular to the arm) -> E
  (r4 + r40 along the arm) -> W (r6, forearm), a triangle S-E-W with two elbow branches;
* pan/tilt/roll form a spherical wrist with two branches (tilt flip); where pan and roll align
  (tilt = ±90°) the previous pan is kept.

Search. For one r1 the feasible extend values form an interval known in closed form (reach with
the stretch margin, and a superset bound from the elbow's range); r1 itself is confined to at
most two intervals around the target. Because moving a prismatic axis by d costs at least
``w_min * |d|``, the optimum lies within ``F_best / w_min`` (L1) of the previous (r1, r4): the
search box shrinks to that ball as soon as any feasible point is known. Inside the box a grid
that contains the objective's kinks exactly (r1 = r1_prev, r4 = r4_prev, the box and reach
boundaries) is zoomed around the best candidates. On smooth paths most frames are settled by a
certificate instead: when holding track and extend still is feasible and the other axes'
sensitivity to them is far below their weights, no other point can be cheaper. The same
argument, in extend alone, settles most frames of the 1-D search without probing extend.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.errors import UnreachableError, UnreachableFramesError
from camtraj.robot import JOINT_NAMES, PRISMATIC, REVOLUTE, DHConstants, Robot

Array = NDArray[np.float64]

TWO_PI = 2.0 * math.pi
N_BRANCHES = 8  # rotate front/back x elbow up/down x wrist flip
_TRACK, _ROTATE, _LIFT, _EXTEND, _ELBOW, _PAN, _TILT, _ROLL = range(8)
_WRIST_EPS = 1e-10  # |cos tilt| below this is the wrist singularity
_FAST_RADIUS = 1e-3  # [m] certificate only when the competing region is this small
_CERT_SAFETY = 0.5  # sensitivity must stay below this fraction of the prismatic weights
_SURVEY_STRIDE = 4  # frames between samples when comparing first-frame branches
_SMOOTH_TUBE = math.radians(20.0)  # most a revolute axis may move away from its SM solution
_EDGE = 1e-12  # rounding allowance at closed-form boundaries (reach, limits) [-, m, rad]
_FRONT_BACK = np.array([0.0, math.pi])
_SIGN2 = np.array([1.0, -1.0])
_PROBE_OFFSETS = np.geomspace(1e-7, 0.05, 10)  # extend probe around the 1-D search's best [m]
_EYE3 = np.eye(3)
_ORTHO_TOL = 1e-6 + 1e-5 * _EYE3  # np.allclose(R.T @ R, I, atol=1e-6)


@dataclass(frozen=True)
class IKSolution:
    """One solved pose.

    Attributes:
        q: Joint vector (8,) [m, rad].
        cost: F = sum(w * |q - previous|) with the robot's weights (per m / per rad).
        branch: Index 0..7 of the closed-form branch (rotate back, elbow, wrist flip bits).
        margin_level: How far the smooth objective's margins had to be relaxed for this pose
            (see ``MARGIN_LEVELS``): 0 all kept (always 0 for the paper objective).
        within_step: False when a requested per-frame step bound could not be kept.
    """

    q: Array
    cost: float
    branch: int
    margin_level: int = 0
    within_step: bool = True

    @property
    def within_margins(self) -> bool:
        """Whether every margin of the smooth objective held."""
        return self.margin_level == 0


@dataclass(frozen=True)
class _Bounds:
    """Limits in force for one solve: position limits, stretch margin, objective name."""

    lower: Array
    upper: Array
    stretch_margin: float
    wrist_margin: float = 0.0
    branch: int | None = None  # restrict the solve to one closed-form branch


# ---------------------------------------------------------------------------------------------
# Closed-form six-axis substructure
# ---------------------------------------------------------------------------------------------


# Packed layout of the closed-form solutions of one candidate: each distinct value once
# (track, extend, 2 rotate, 4 lift, 4 elbow, 8 pan, 8 tilt, 8 roll). Wrapping, limit checks
# and costs run on these 36 columns instead of the 8 x 8 expanded joint vectors; _IDX maps
# every branch's joint vector back to its columns.
_AX = np.array([_TRACK, _EXTEND, *[_ROTATE] * 2, *[_LIFT] * 4, *[_ELBOW] * 4,
                *[_PAN] * 8, *[_TILT] * 8, *[_ROLL] * 8])
_IDX = np.array([[0, 2 + i, 4 + 2 * i + j, 1, 8 + 2 * i + j, 12 + b, 20 + b, 28 + b]
                 for b in range(N_BRANCHES) for i, j in [divmod(b >> 1, 2)]])
_PAIR = np.repeat(np.arange(4), 2)  # the wrist's two flips share the arm (rotate, elbow)
_USES = np.zeros((_AX.size, N_BRANCHES))  # _USES[c, b] = 1 where branch b uses column c
for _b in range(N_BRANCHES):
    _USES[_IDX[_b], _b] = 1.0


def six_axis_solutions(
    dh: DHConstants,
    target: Array,
    r1: ArrayLike,
    r4: ArrayLike,
    previous: Array,
    lower: Array,
    upper: Array,
    stretch_margin: float | Array = 0.0,
    wrist_margin: float | Array = 0.0,
) -> tuple[Array, NDArray[np.bool_]]:
    """All closed-form branches for fixed track and extend values.

    Args:
        dh: The robot's DH constants.
        target: Flange pose in the base frame (``flange2base``), shape (4, 4) [m], or one
            pose per candidate, shape (N, 4, 4).
        r1: Track values, shape (N,) [m].
        r4: Extend values, shape (N,) [m].
        previous: Joint vector the revolute axes stay nearest to (2π-equivalents), (8,), or
            one per candidate, (N, 8).
        lower, upper: Position limits (8,) the solutions must respect, or per candidate (N, 8).
        stretch_margin: Minimum elbow angle away from full stretch [rad], scalar or (N,).
        wrist_margin: Minimum tilt angle away from the wrist singularity (±90°) [rad], scalar
            or (N,).

    Returns:
        ``q`` of shape (N, 8, 8): for each candidate and branch, the joint vector; and the
        feasibility mask of shape (N, 8). Infeasible entries hold NaN or out-of-limit values.
    """
    packed, ok = _six_axis_packed(dh, target, r1, r4, previous,
                                  _packed_limits(previous, lower, upper), stretch_margin,
                                  wrist_margin)
    return packed[:, _IDX], ok


def _packed_limits(previous: Array, lower: Array, upper: Array) -> tuple[Array, ...]:
    """Previous values and limits per packed column, (36,) or (N, 36), for _six_axis_packed:
    previous, lower, upper of the revolute columns, then lower and upper with the rounding
    allowance of all columns."""
    lo, hi = lower[..., _AX], upper[..., _AX]
    return (np.asarray(previous, dtype=float)[..., _AX[2:]], lo[..., 2:], hi[..., 2:],
            lo - _EDGE, hi + _EDGE)


def _six_axis_packed(
    dh: DHConstants,
    target: Array,
    r1: ArrayLike,
    r4: ArrayLike,
    previous: Array,
    limits: tuple[Array, ...],
    stretch_margin: float | Array = 0.0,
    wrist_margin: float | Array = 0.0,
) -> tuple[Array, NDArray[np.bool_]]:
    """:func:`six_axis_solutions` in the packed layout: values (N, 36) and feasibility (N, 8).

    ``limits`` is :func:`_packed_limits` of the previous joint vector and the limits.
    """
    r1a = np.asarray(r1, dtype=float)
    r4a = np.asarray(r4, dtype=float)
    n = r1a.shape[0]
    batched = target.ndim == 3  # one target per candidate
    W = target[..., :3, 3].T  # (3,) or (3, N)
    # rotation entries: scalars, or (N, 1) columns that broadcast against (N, 2) arrays
    R = target[:, :3, :3].transpose(1, 2, 0)[..., None] if batched else target[:3, :3]
    prev = np.asarray(previous, dtype=float)
    prev_rotate, prev_pan = prev[..., _ROTATE], prev[..., _PAN]
    dx = W[0] - dh.r10 - r1a  # (N,)
    dy = W[1]
    dz = W[2] - dh.r2
    hor = np.hypot(dx, dy)
    ws2 = np.maximum(hor * hor + dz * dz, 1e-300)
    dz_col = np.asarray(dz)[..., None]  # (1,) or (N, 1)

    # rotate: front (arm plane towards W) and back (plane turned by pi, arm reaching over)
    th2f = np.arctan2(dy, dx)
    if hor.min() <= 1e-12:  # wrist centre right above the rotate axis: keep the previous
        th2f = np.where(hor > 1e-12, th2f, prev_rotate)
    th2 = th2f[:, None] + _FRONT_BACK  # (N, 2)
    rho = hor[:, None] * _SIGN2  # (N, 2) signed horizontal distance in the arm plane

    L = r4a + dh.r40
    dse2 = L * L + dh.l3 * dh.l3
    cos_g = (ws2 + dse2 - dh.r6 * dh.r6) / (2.0 * np.sqrt(dse2 * ws2))
    # interior angle at the elbow E (pi at full stretch)
    cos_e = (dse2 + dh.r6 * dh.r6 - ws2) / (2.0 * dh.r6 * np.sqrt(dse2))
    reach_ok = (np.abs(cos_g) <= 1.0 + _EDGE) & (cos_e >= -np.cos(stretch_margin) - _EDGE)
    gamma = np.arccos(np.minimum(np.maximum(cos_g, -1.0), 1.0))  # (N,)
    beta = np.arctan2(dh.l3, L)

    # elbow branches: arm elevation a = angle(w) - beta -/+ gamma   -> (N, 2, 2)
    a = (np.arctan2(dz_col, rho) - beta[:, None])[:, :, None] - gamma[:, None, None] * _SIGN2
    ca, sa = np.cos(a), np.sin(a)
    Lb = L[:, None, None]
    dpx = rho[:, :, None] - (Lb * ca - dh.l3 * sa)  # forearm vector W - E in the plane
    dpz = dz_col[..., None] - (Lb * sa + dh.l3 * ca)
    psi = np.arctan2(dpx, -dpz)  # forearm angle; theta3 + theta5 = -psi
    cs, ss = np.cos(psi), -np.sin(psi)  # cos/sin of sigma = theta3 + theta5

    # spherical wrist: R58 = R05^T R. With c2, s2 of rotate, the columns of R05 are
    # x5 = (c2 cs, s2 cs, -ss), y5 = (s2, -c2, 0), z5 = (-c2 ss, -s2 ss, -cs).
    c2 = np.cos(th2)
    s2 = np.sin(th2)
    P0 = (c2 * R[0, 0] + s2 * R[1, 0])[:, :, None]
    P1 = (c2 * R[0, 1] + s2 * R[1, 1])[:, :, None]
    P2 = (c2 * R[0, 2] + s2 * R[1, 2])[:, :, None]
    R2 = R[2][..., None] if batched else R[2]  # bottom row, broadcast against (N, 2, 2)
    m02 = cs * P2 - ss * R2[2]
    m12 = (s2 * R[0, 2] - c2 * R[1, 2])[:, :, None]
    m22 = -ss * P2 - cs * R2[2]
    m20 = -ss * P0 - cs * R2[0]
    m21 = -ss * P1 - cs * R2[1]
    c7abs = np.hypot(m02, m12)
    s7 = np.minimum(np.maximum(m22, -1.0), 1.0)

    # wrist flip: cos(tilt) = +|c7| / -|c7|   -> (N, 2, 2, 2)
    sg = _SIGN2
    th7 = np.arctan2(s7[..., None], c7abs[..., None] * sg)
    th6 = np.arctan2(m12[..., None] * sg, m02[..., None] * sg)  # (N,2,2,2) by broadcasting
    th8 = np.arctan2(m21[..., None] * -sg, m20[..., None] * -sg)
    singular = c7abs < _WRIST_EPS
    if singular.any():
        # pan and roll aligned: keep the previous pan, roll takes the rest
        m00 = cs * P0 - ss * R2[0]
        m10 = (s2 * R[0, 0] - c2 * R[1, 0])[:, :, None]
        s7s = np.where(s7 >= 0, 1.0, -1.0)[..., None]
        combo = np.arctan2(s7s * m10[..., None], s7s * m00[..., None])
        th6_keep = np.broadcast_to(np.asarray(prev_pan).reshape(-1, 1, 1, 1), th6.shape)
        th8_keep = np.where(s7s > 0, th6_keep - combo, combo - th6_keep)
        th6 = np.where(singular[..., None], th6_keep, th6)
        th8 = np.where(singular[..., None], th8_keep, th8)

    packed = np.concatenate([
        r1a[:, None], r4a[:, None], th2, (-a).reshape(n, 4), (a - psi).reshape(n, 4),
        th6.reshape(n, 8), th7.reshape(n, 8), th8.reshape(n, 8)], axis=1)
    prev_rev, lo_rev, hi_rev, lo_e, hi_e = limits
    # every column after track and extend is revolute: its 2π-equivalent nearest previous
    packed[:, 2:] = _nearest_equivalent(packed[:, 2:], prev_rev, lo_rev, hi_rev)
    bad = (packed < lo_e) | (packed > hi_e)
    ok = (bad @ _USES == 0.0) & reach_ok[:, None]
    if np.ndim(wrist_margin) == 0:
        if wrist_margin > 0.0:
            ok &= (c7abs.reshape(n, 4) >= math.sin(float(wrist_margin)))[:, _PAIR]
    elif np.max(wrist_margin) > 0.0:
        ok &= (c7abs.reshape(n, 4) >= np.sin(wrist_margin).reshape(-1, 1))[:, _PAIR]
    return packed, ok


def _nearest_equivalent(x: Array, prev: Array, lo: Array, hi: Array) -> Array:
    """The 2π-equivalent of each angle nearest ``prev`` inside [lo, hi] (else the nearest)."""
    y = x + TWO_PI * np.rint((prev - x) * (1.0 / TWO_PI))
    out_y = (y < lo) | (y > hi)
    if not out_y.any():
        return y
    alt = y - TWO_PI * np.sign(y - prev)
    alt_in = (alt >= lo) & (alt <= hi)
    return np.where(out_y & alt_in, alt, y)


# ---------------------------------------------------------------------------------------------
# Feasible region of (track, extend)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Region:
    """Closed-form superset of the feasible (r1, r4) region for one target."""

    dh: DHConstants
    W: Array
    r1_lo: float
    r1_hi: float
    r4_lo: float
    r4_hi: float
    stretch: float

    @functools.cached_property
    def _reach(self) -> tuple[Any, ...]:
        """Constants of :meth:`r4_interval` (scalars, or arrays for one region per frame)."""
        dh = self.dh
        cm, sm = np.cos(self.stretch), np.sin(self.stretch)
        return (self.W[0] - dh.r10, self.W[1] ** 2 + (self.W[2] - dh.r2) ** 2, -dh.r6 * cm,
                (dh.r6 * sm) ** 2, dh.l3 * dh.l3, (dh.r6 - dh.l3) ** 2, dh.r40)

    def r4_interval(self, r1: Array) -> tuple[Array, Array]:
        """Extend range [lo, hi] that can reach W from track r1 (empty where lo > hi)."""
        c, perp2, a, b2, l3_2, e2, r40 = self._reach
        dx = c - r1
        ws2 = dx * dx + perp2  # squared distance shoulder -> wrist centre
        dse_min = a + np.sqrt(np.maximum(ws2 - b2, 0.0))
        l_min = np.sqrt(np.maximum(dse_min * dse_min - l3_2, 0.0))
        l_max = np.sqrt(np.maximum(ws2 - e2, 0.0))
        lo = np.maximum(l_min - r40, self.r4_lo)
        hi = np.minimum(l_max - r40, self.r4_hi)
        return lo, hi

    def r1_kinks(self, r4: float) -> list[float]:
        """Track values where extend ``r4`` is exactly at the end of its reach interval."""
        dh = self.dh
        cm, sm = math.cos(self.stretch), math.sin(self.stretch)
        L = r4 + dh.r40
        dse = math.hypot(L, dh.l3)
        perp2 = self.W[1] ** 2 + (self.W[2] - dh.r2) ** 2
        c = self.W[0] - dh.r10
        out: list[float] = []
        for ws2 in ((dse + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2, L * L + (dh.r6 - dh.l3) ** 2):
            if ws2 > perp2:
                d = math.sqrt(ws2 - perp2)
                out += [c - d, c + d]
        return [r for r in out if self.r1_lo <= r <= self.r1_hi]

    def r1_intervals(self) -> tuple[list[tuple[float, float]], float]:
        """Track intervals from which W is within reach, and the miss distance [m] if none."""
        dh = self.dh
        cm, sm = math.cos(self.stretch), math.sin(self.stretch)
        dse_max = math.hypot(self.r4_hi + dh.r40, dh.l3)
        ws_out = math.sqrt((dse_max + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2)
        ws_in = math.sqrt((self.r4_lo + dh.r40) ** 2 + (dh.r6 - dh.l3) ** 2)
        perp = math.hypot(self.W[1], self.W[2] - dh.r2)
        if perp > ws_out:
            return [], perp - ws_out
        a_out = math.sqrt(ws_out * ws_out - perp * perp)
        a_in = math.sqrt(max(ws_in * ws_in - perp * perp, 0.0))
        c = self.W[0] - dh.r10
        out: list[tuple[float, float]] = []
        miss = math.inf
        for lo, hi in ((c - a_out, c - a_in), (c + a_in, c + a_out)):
            clo, chi = max(lo, self.r1_lo), min(hi, self.r1_hi)
            if clo <= chi:
                out.append((clo, chi))
            else:
                miss = min(miss, lo - self.r1_hi if lo > self.r1_hi else self.r1_lo - hi)
        if len(out) == 2 and out[0][1] >= out[1][0]:
            out = [(out[0][0], out[1][1])]
        return out, miss


# ---------------------------------------------------------------------------------------------
# The search
# ---------------------------------------------------------------------------------------------


class _Problem:
    """One target, one previous solution, one set of bounds; remembers the best point seen."""

    def __init__(self, robot: Robot, target: Array, previous: Array, bounds: _Bounds) -> None:
        self.robot = robot
        self.target = target
        self.prev = previous
        self.bounds = bounds
        self.w = robot.weights
        self.w_min = float(min(self.w[_TRACK], self.w[_EXTEND]))
        self.region = _Region(
            robot.dh, target[:3, 3].copy(),
            float(bounds.lower[_TRACK]), float(bounds.upper[_TRACK]),
            float(bounds.lower[_EXTEND]), float(bounds.upper[_EXTEND]),
            bounds.stretch_margin,
        )
        self.intervals, self.miss = self.region.r1_intervals()
        self.best_q: Array | None = None
        self.best_cost = math.inf
        self.best_branch = -1
        self._prev_packed = previous[_AX]
        self._limits = _packed_limits(previous, bounds.lower, bounds.upper)
        self._cost_matrix = _USES * self.w[_AX, None]  # (36, 8): F of each branch
        self.evaluations = 0
        self.calls = 0
        self.near_line = False
        self.probe_shift = math.inf  # how far the extend probe moved the best point [m]

    def evaluate(self, r1: Array, r4: Array) -> tuple[Array, Array]:
        """Cost (N, 8) with inf where infeasible, and the packed solutions (N, 36) (branch
        ``br``'s joint vectors are ``packed[:, _IDX[br]]``). Records the best."""
        b = self.bounds
        packed, ok = _six_axis_packed(self.robot.dh, self.target, r1, r4, self.prev,
                                      self._limits, b.stretch_margin, b.wrist_margin)
        if b.branch is not None:
            ok = ok & (np.arange(N_BRANCHES) == b.branch)
        cost = np.where(ok, np.abs(packed - self._prev_packed) @ self._cost_matrix, np.inf)
        self.evaluations += r1.shape[0]
        self.calls += 1
        flat = int(np.argmin(cost))
        c = float(cost.flat[flat])
        if c < self.best_cost:
            i, br = divmod(flat, N_BRANCHES)
            self.best_cost, self.best_q, self.best_branch = c, packed[i, _IDX[br]], br
        return cost, packed

    def ball(self) -> float:
        """Half-width [m] of the box that must hold the optimum (prismatic cost alone)."""
        if self.w_min <= 0 or not math.isfinite(self.best_cost):
            return math.inf
        return self.best_cost / self.w_min

    def clip_r4(self, r1: Array) -> tuple[Array, NDArray[np.bool_]]:
        """Extend nearest its previous value inside the reach interval, and where one exists."""
        lo, hi = self.region.r4_interval(r1)
        return np.minimum(np.maximum(self.prev[_EXTEND], lo), hi), lo <= hi

    def r1_grid(self, lo: float, hi: float, n: int) -> Array:
        """Up to n track values over [lo, hi] intersected with the reachable intervals."""
        parts = []
        for a, b in self.intervals:
            a2, b2 = max(a, lo), min(b, hi)
            if a2 <= b2:
                parts.append(np.linspace(a2, b2, max(3, n // len(self.intervals))))
        return np.concatenate(parts) if parts else np.empty(0)

    # -- the line search: hold extend where it can (r4 = clip(r4_prev)), search track -------
    def line_search(self) -> bool:
        """Settle the frame on the curve r4 = clip(r4_prev, reach interval(r1)).

        For a fixed track value, moving extend costs ``w_extend`` per metre, so while the other
        axes' sensitivity to extend stays below that weight the best extend is the one nearest
        its previous value inside the reach interval. That leaves a 1-D problem in track whose
        kinks (track held, extend reaching the end of its interval) are known in closed form.
        Returns False when the reduction cannot be trusted (the caller then searches in 2-D).
        """
        if not self.intervals or self.w_min <= 0:
            return False
        r1p, r4p = float(self.prev[_TRACK]), float(self.prev[_EXTEND])
        h = 1e-7
        kinks = [r1p] if any(a <= r1p <= b for a, b in self.intervals) else []
        kinks += self.region.r1_kinks(r4p)
        kinks += [x for ab in self.intervals for x in ab]
        kinks_a = np.array(kinks)
        r4k, okk = self.clip_r4(kinks_a)
        # a first guess of the ball: prismatic cost of the cheapest kink + some revolute motion
        prism = self.w[_TRACK] * np.abs(kinks_a - r1p) + self.w[_EXTEND] * np.abs(r4k - r4p)
        guess = (float(np.min(np.where(okk, prism, np.inf))) + 500.0) / self.w_min
        if not math.isfinite(guess):
            return False
        grid = self.r1_grid(r1p - guess, r1p + guess, 24)
        # stencils: along the curve (track +-h) and across it (extend +-h) at every kink
        r1_pts = np.concatenate([kinks_a, kinks_a - h, kinks_a + h, kinks_a, kinks_a, grid])
        r4_curve, ok_curve = self.clip_r4(r1_pts)
        nk = len(kinks)
        r4_pts = r4_curve.copy()
        r4_pts[3 * nk: 4 * nk] -= h
        r4_pts[4 * nk: 5 * nk] += h
        if not ok_curve[:nk].any() and not ok_curve[5 * nk:].any():
            return False
        cost, packed = self.evaluate(r1_pts, r4_pts)
        f = cost.min(axis=1)
        f_kink, f_grid = f[:nk], f[5 * nk:]
        samples_r1, samples_f = [kinks_a, grid], [f_kink, f_grid]

        # the grid must cover the whole ball; widen it once if it did not
        ball = self.ball()
        if ball > guess:
            grid2 = self.r1_grid(r1p - ball, r1p + ball, 48)
            cost2, _ = self.evaluate(grid2, self.clip_r4(grid2)[0])
            samples_r1.append(grid2)
            samples_f.append(cost2.min(axis=1))
        all_r1 = np.concatenate(samples_r1)
        all_f = np.concatenate(samples_f)

        # holes: reachable track values in the ball whose held-extend point is infeasible on
        # every branch (another limit binds there): the 1-D reduction cannot see past them
        ball = self.ball()
        in_ball = (all_r1 >= r1p - ball) & (all_r1 <= r1p + ball)
        if np.any(in_ball & self.clip_r4(all_r1)[1] & ~np.isfinite(all_f)):
            return False

        # done without zooming when the best sample is a kink that is a local minimum
        k = int(np.argmin(f_kink)) if nk else -1
        at_kink = (
            k >= 0
            and math.isfinite(f_kink[k])
            and f_kink[k] <= np.min(all_f)
            and f[nk + k] >= f_kink[k]
            and f[2 * nk + k] >= f_kink[k]
        )
        if not at_kink:
            self._zoom_line(all_r1, all_f)
        elif self._extend_flat(cost[k::nk][[0, 3, 4]], packed[k::nk][[0, 3, 4]], h):
            return True
        if self._extend_sensitivity_ok():
            return True
        self.near_line = True  # the optimum is off the held-extend curve, but close to it
        return False

    def _zoom_line(self, r1s: Array, fs: Array, tol: float = 1e-9) -> None:
        """Refine the best track value of the 1-D curve by shrinking brackets."""
        order = np.argsort(r1s)
        r1s, fs = r1s[order], fs[order]
        i = int(np.argmin(fs))
        lo = r1s[max(i - 1, 0)]
        hi = r1s[min(i + 1, len(r1s) - 1)]
        r1p = float(self.prev[_TRACK])
        while hi - lo > tol:
            pts = np.linspace(lo, hi, 9)
            if lo < r1p < hi:
                pts = np.append(pts, r1p)
            r4, ok = self.clip_r4(pts)
            cost, _ = self.evaluate(pts[ok], r4[ok]) if ok.any() else (np.empty((0, 8)), None)
            if cost.shape[0] == 0:
                return
            f = cost.min(axis=1)
            pts = pts[ok]
            j = int(np.argmin(f))
            step = (hi - lo) / 8
            lo, hi = max(pts[j] - step, lo), min(pts[j] + step, hi)

    def _extend_flat(self, cost: Array, packed: Array, h: float) -> bool:
        """The extend probe's question settled by a certificate at a kink of the 1-D search.

        Row 0 of ``cost`` / ``packed`` is the best point (r1*, r4*), rows 1, 2 the same track
        with extend -h, +h. At fixed track, a point r4 beats F* only if the extend it moves
        away from the previous value, w_extend * |r4 - r4*| (r4* is the previous extend or
        the end of its reach interval, beyond which nothing is feasible), is less than the
        revolute part of F*: the competing interval has that radius. As for the vertex
        certificate, when it is small and the revolute slopes there are far below w_extend
        (or too shallow to dip below F* within it), no extend value is cheaper.
        """
        q = self.best_q
        fstar = float(cost[0].min())
        if q is None or not math.isfinite(fstar) or self.best_cost != fstar:
            return False
        w4 = float(self.w[_EXTEND])
        prism = (self.w[_TRACK] * abs(q[_TRACK] - self.prev[_TRACK])
                 + w4 * abs(q[_EXTEND] - self.prev[_EXTEND]))
        radius = max(fstar - prism, 0.0) / w4
        if w4 <= 0 or radius > _FAST_RADIUS:
            return False
        wr = self.w * REVOLUTE
        for br in range(N_BRANCHES):
            if not math.isfinite(cost[0, br]):
                continue
            fin = np.isfinite(cost[1:, br])
            qb = packed[:, _IDX[br]]
            g = float(np.max(np.where(fin, np.abs(qb[1:] - qb[0]) @ wr / h, 0.0)))
            if g <= _CERT_SAFETY * w4:
                continue
            if g < w4 or (cost[0, br] - fstar) < (g - w4) * radius:
                return False
        return True

    def _extend_sensitivity_ok(self) -> bool:
        """Check the reduction at the best point: no extend value nearby is cheaper.

        Holding extend at clip(r4_prev) is optimal for a fixed track value as long as the
        other axes do not gain more than ``w_extend`` per metre of extend. Probe extend on both
        sides of the best point at geometrically spaced offsets up to a few centimetres.
        """
        if self.best_q is None:
            return False
        q0 = self.best_q
        f0 = self.best_cost
        offsets = _PROBE_OFFSETS
        r4 = np.concatenate([q0[_EXTEND] - offsets, q0[_EXTEND] + offsets])
        r1 = np.full(r4.shape, q0[_TRACK])
        self.evaluate(r1, r4)
        self.probe_shift = abs(float(self.best_q[_EXTEND]) - float(q0[_EXTEND]))
        return self.best_cost >= f0 - 1e-9 * max(1.0, f0)

    # -- the vertex certificate (hold track and extend) ------------------------------------
    def try_certificate(self) -> bool:
        """Settle the frame at (r1_prev, r4_prev) if no other point can be cheaper."""
        r1p, r4p = self.prev[_TRACK], self.prev[_EXTEND]
        if self.w_min <= 0:
            return False
        lo, hi = self.region.r4_interval(np.array([r1p]))
        if not lo[0] <= r4p <= hi[0]:
            return False
        h = 1e-6
        r1 = np.array([r1p, r1p + h, r1p - h, r1p, r1p])
        r4 = np.array([r4p, r4p, r4p, r4p + h, r4p - h])
        cost, q = self.evaluate(r1, r4)
        f0 = cost[0]
        fstar = float(f0.min())
        if not math.isfinite(fstar):
            return False
        radius = fstar / self.w_min
        if radius > _FAST_RADIUS:
            return False
        wr = self.w * REVOLUTE
        for br in range(N_BRANCHES):
            if not math.isfinite(f0[br]):
                continue
            # one-sided slopes where a stencil point is infeasible (that side is blocked)
            fin = np.isfinite(cost[:, br])
            qb = q[:, _IDX[br]]
            slopes = np.abs(qb[1:] - qb[0]) @ wr / h
            g = float(np.max(np.where(fin[1:], slopes, 0.0)))
            if g <= _CERT_SAFETY * self.w_min:
                continue
            # a steeper branch is still safe if it cannot dip below fstar before the
            # prismatic cost alone exceeds fstar
            if g < self.w_min or (f0[br] - fstar) < (g - self.w_min) * radius:
                return False
        return bool(self.best_cost == fstar)

    # -- the 2-D search ---------------------------------------------------------------------
    def box_search(self, n1: int = 48, n4: int = 12, keep: int = 3, zoom: float = 0.4,
                   tol1: float = 1e-10, tol_t: float = 1e-9) -> None:
        """Grid over the box that must hold the optimum, then zoom around the best cells.

        Each of the ``keep`` best coarse cells zooms in its own window (all windows in one
        vectorised evaluation per round); a window whose best point lands on its edge moves
        there without shrinking, since the optimum may lie beyond it.
        """
        if not self.intervals:
            return
        r1p, r4p = float(self.prev[_TRACK]), float(self.prev[_EXTEND])
        ball = self.ball()
        if ball < 0.01:  # the box of a frame in a smooth move: a centimetre or less
            n1, n4 = 24, 8
        r1s = self.r1_grid(r1p - ball, r1p + ball, n1)
        if r1s.size == 0:
            return
        if any(a <= r1p <= b for a, b in self.intervals):
            r1s = np.append(r1s, r1p)
        span = float(np.ptp(r1s)) if r1s.size > 1 else 1e-3
        w1_0, wt_0 = span / max(n1 - 1, 2), 1.0 / max(n4 - 1, 2)
        if self.near_line and self.best_q is not None:
            # the 1-D search got within a hair of the optimum: zoom around its best point only
            r1b, r4b = float(self.best_q[_TRACK]), float(self.best_q[_EXTEND])
            lo, hi = self.region.r4_interval(np.array([r1b]))
            lo_b, hi_b = max(lo[0], r4p - ball), min(hi[0], r4p + ball)
            tb = (r4b - lo_b) / (hi_b - lo_b) if hi_b > lo_b else 0.0
            # the extend probe found the cheaper point this far off the curve: start the zoom
            # at that scale (a window whose best lands on its edge still follows and grows)
            s = 5.0 * self.probe_shift
            wt = min(wt_0, s / (hi_b - lo_b)) if hi_b > lo_b else wt_0
            windows = [(r1b, min(max(tb, 0.0), 1.0), min(w1_0, s), wt)]
        else:
            coarse = self._grid_windows([r1s], [(0.0, 1.0)], n4, r4p, ball, ranked=keep)
            windows = [(r1c, tc, w1_0, wt_0) for r1c, tc in coarse]
        history: list[float] = []
        quiet, rel = (3, 1e-6) if self.near_line else (4, 1e-8)
        for rnd in range(60):
            # stop when three rounds improved the best by less than a part in 1e8 (when
            # zooming in on the 1-D search's best point, which is within ~1e-4 of the optimum
            # already: two rounds, a part in 1e6)
            history.append(self.best_cost)
            if len(history) > quiet and history[-quiet] - history[-1] <= rel * history[-1]:
                break
            # the cost moves at most ~2 w_min per metre of prismatic motion: stop when the
            # windows are too small to change it by a millionth
            if math.isfinite(self.best_cost) and self.w_min > 0:
                tol1 = max(tol1, 5e-7 * self.best_cost / (2 * self.w_min))
                tol_t = max(tol_t, tol1 / max(2 * ball, 1e-12))
            windows = [w for w in windows if w[2] > tol1 or w[3] > tol_t]
            if not windows:
                break
            cols, tw = [], []
            for r1c, tc, w1, wt in windows:
                col = np.linspace(r1c - w1, r1c + w1, 5)
                if r1c - w1 <= r1p <= r1c + w1:
                    col = np.append(col, r1p)
                cols.append(col)
                tw.append((tc - wt, tc + wt))
            found = self._grid_windows(cols, tw, 5, r4p, self.ball())
            # windows that stay clearly worse than the best are other, worse basins
            slack = 1e-3 if rnd < 4 else 1e-7
            nxt = []
            for (r1c, tc, w1, wt), best in zip(windows, found, strict=True):
                if best is None or best[2] > self.best_cost * (1 + slack) + 1e-12:
                    continue
                r1n, tn, _ = best
                # a best point on the window's edge: the optimum may lie beyond, so the
                # window follows it and grows instead of shrinking
                edge1 = abs(abs(r1n - r1c) - w1) < 1e-12 * max(1.0, abs(r1c))
                edge_t = abs(abs(tn - tc) - wt) < 1e-12 and 0.0 < tn < 1.0
                nxt.append((r1n, tn, min(2 * w1, w1_0) if edge1 else w1 * zoom,
                            min(2 * wt, wt_0) if edge_t else wt * zoom))
            windows = nxt

    def _grid_windows(self, cols: list[Array], windows: list[tuple[float, float]], n4: int,
                      r4p: float, ball: float, ranked: int = 0) -> list[Any]:
        """Evaluate track columns x normalised extend rows for several windows at once.

        Each column's extend range is its closed-form reach interval clipped to the ball; the
        rows spread over that window of it, plus the held extend and the interval ends.
        Returns the best (r1, t, cost) of each window (None where nothing is feasible), or
        with ``ranked`` the best ``ranked`` distinct (r1, t) columns of the first window.
        """
        out: list[Any] = [None] * len(cols)
        grp = np.repeat(np.arange(len(cols)), [c.size for c in cols])
        r1s = np.concatenate(cols)
        lo, hi = self.region.r4_interval(r1s)
        lo = np.maximum(lo, r4p - ball)
        hi = np.minimum(hi, r4p + ball)
        sel = (r1s >= self.region.r1_lo) & (r1s <= self.region.r1_hi) & (lo <= hi)
        if not sel.any():
            return [] if ranked else out
        r1s, lo, hi, grp = r1s[sel], lo[sel], hi[sel], grp[sel]
        # rows of each window (normalised extend), then the interval ends and the held extend
        ts = np.array([np.linspace(max(t0, 0.0), min(t1, 1.0), n4) for t0, t1 in windows])
        ts = np.concatenate([ts, np.zeros((len(cols), 1)), np.ones((len(cols), 1))], axis=1)
        span = hi - lo
        r4 = lo[:, None] + span[:, None] * ts[grp]
        held = np.minimum(np.maximum(r4p, lo), hi)
        r4 = np.concatenate([r4, held[:, None]], axis=1)
        safe_span = np.where(span > 0, span, 1.0)[:, None]
        t = np.where(span[:, None] > 0, (r4 - lo[:, None]) / safe_span, 0.0).ravel()
        r1 = np.repeat(r1s, r4.shape[1])
        grp = np.repeat(grp, r4.shape[1])
        r4 = r4.ravel()
        cost, _ = self.evaluate(r1, r4)
        best = cost.min(axis=1)
        if ranked:
            order = np.argsort(best)
            picks: list[tuple[float, float]] = []
            seen: set[float] = set()
            for k in order[: 64 * ranked]:
                if not math.isfinite(best[k]) or float(r1[k]) in seen:
                    continue
                seen.add(float(r1[k]))
                picks.append((float(r1[k]), float(t[k])))
                if len(picks) == ranked:
                    break
            return picks
        for g in range(len(cols)):
            idx = np.flatnonzero(grp == g)
            if idx.size == 0:
                continue
            k = idx[int(np.argmin(best[idx]))]
            if math.isfinite(best[k]):
                out[g] = (float(r1[k]), float(t[k]), float(best[k]))
        return out

# How far the smooth objective's margins are relaxed when a pose needs it, in order:
# 0 all kept; 1 the wrist margin dropped; 2 also the limit margins (hard limits); 3 also the
# stretch margin (the papers' constraints). The paper objective always uses level 3.
MARGIN_LEVELS = 4


def _level_margins(robot: Robot, level: ArrayLike) -> tuple[Array, Array, Array, Array]:
    """Limits and margins per relaxation level: lower, upper (..., 8), stretch, wrist (...)."""
    lv = np.asarray(level)
    m = np.where((lv < 2)[..., None], robot.ik.limit_margin, 0.0)
    stretch = np.where(lv < 3, robot.ik.stretch_margin, 0.0)
    wrist = np.where(lv < 1, robot.ik.wrist_margin, 0.0)
    return robot.lower + m, robot.upper - m, stretch, wrist


def _bounds_for(robot: Robot, objective: str, level: int, previous: Array,
                max_step: Array | None) -> _Bounds:
    lower, upper, stretch, wrist = _level_margins(
        robot, level if objective == "smooth" else MARGIN_LEVELS - 1)
    if max_step is not None:
        # a step bound is a per-frame box around the previous solution; where the previous
        # solution lies outside the (margin) limits the box is clamped, never inverted
        lower = np.minimum(np.maximum(lower, previous - max_step), upper)
        upper = np.maximum(np.minimum(upper, previous + max_step), lower)
    return _Bounds(lower, upper, float(stretch), float(wrist))


def _solve_one(robot: Robot, target: Array, previous: Array, bounds: _Bounds) -> _Problem:
    prob = _Problem(robot, target, previous, bounds)
    if prob.try_certificate() or prob.line_search():
        return prob
    prob.box_search()
    return prob


def solve_ik(
    robot: Robot,
    target: ArrayLike,
    previous: ArrayLike | None = None,
    *,
    objective: str | None = None,
    max_step: ArrayLike | None = None,
    branch: int | None = None,
) -> IKSolution:
    """Solve one flange pose, minimising weighted motion from ``previous``.

    Args:
        robot: The robot (limits, weights, IK settings).
        target: Flange pose in the base frame (``flange2base``), shape (4, 4) [m].
        previous: Joint vector (8,) the move starts from; default the robot's home.
        objective: ``"smooth"`` or ``"paper"``; default the robot file's ``[ik] objective``.
        max_step: Optional per-axis bound on |q - previous| (8,) [m, rad], e.g. what each axis
            can travel in one frame at its velocity limit. It keeps consecutive frames on one
            branch; where no solution respects it, it is widened (x2, x4, x8, x16) and only
            then dropped (``within_step`` is False in either case).
        branch: Restrict the solution to this closed-form branch (0..7), e.g. to start a shot
            elbow-up instead of elbow-down.

    Returns:
        The solution. When a pose needs it, the margins are relaxed first (hard limits), then
        the step bound widened; ``within_margins`` / ``within_step`` tell which held.

    Raises:
        UnreachableError: No solution inside the joint limits; says by how much it misses.
    """
    T = _check_target(target)
    prev = robot.home.copy() if previous is None else np.asarray(previous, dtype=float).copy()
    if prev.shape != (8,) or not np.all(np.isfinite(prev)):
        msg = f"previous must be 8 finite joint values, got {prev!r}"
        raise ValueError(msg)
    obj = objective or robot.ik.objective
    if obj not in ("smooth", "paper"):
        msg = f"objective must be 'smooth' or 'paper', got {obj!r}"
        raise ValueError(msg)
    step = None if max_step is None else np.asarray(max_step, dtype=float)
    levels = range(MARGIN_LEVELS) if obj == "smooth" else [MARGIN_LEVELS - 1]
    # a step bound that cannot be kept is widened before it is dropped, so a move too fast
    # for the robot stays continuous (the timing stage then reports its speed honestly)
    scales: list[float | None] = [1.0, 2.0, 4.0, 8.0, 16.0, None] if step is not None else [None]
    for scale in scales:
        for level in levels:
            bounds = _bounds_for(robot, obj, level, prev,
                                 None if scale is None or step is None else step * scale)
            if branch is not None:
                bounds = dataclasses.replace(bounds, branch=branch)
            prob = _solve_one(robot, T, prev, bounds)
            if prob.best_q is not None:
                return IKSolution(prob.best_q, prob.best_cost, prob.best_branch,
                                  margin_level=level if obj == "smooth" else 0,
                                  within_step=scale == 1.0 or step is None)
    raise _diagnose(robot, T, prev)


def solve_path(
    robot: Robot,
    targets: ArrayLike,
    start: ArrayLike | None = None,
    *,
    objective: str | None = None,
    frame_interval: float | None = None,
    frame_numbers: ArrayLike | None = None,
    progress: Callable[[int], None] | None = None,
) -> Array:
    """Solve a whole shot, each frame seeded from the previous frame's solution.

    Args:
        robot: The robot.
        targets: Flange poses in the base frame, shape (n, 4, 4) [m].
        start: Joint vector (8,) before the first frame; default the robot's home.
        objective: ``"smooth"`` or ``"paper"``; default the robot file's setting.
        frame_interval: Seconds between frames. With the smooth objective it bounds each
            axis's step between consecutive frames by its velocity limit times this interval
            (no branch flips) and enables the track/extend smoothing of
            :func:`smooth_redundancy` (``[ik] smoothing`` seconds wide); ignored by the paper
            objective.
        frame_numbers: Film frame numbers (n,) used in error messages; default 0..n-1.
        progress: Called with the number of frames just finished (for a progress bar).

    Returns:
        Joint path, shape (n, 8) [m, rad].

    Raises:
        UnreachableFramesError: One or more frames have no solution; lists every such frame
            and by how much it misses (later frames continue from the last good solution).
    """
    return solve_path_report(robot, targets, start, objective=objective,
                             frame_interval=frame_interval, frame_numbers=frame_numbers,
                             progress=progress).q


@dataclass(frozen=True)
class PathSolution:
    """A solved shot: joint path and per-frame flags.

    Attributes:
        q: Joint path (n, 8) [m, rad].
        cost: F of each frame against the frame before (n,).
        margin_level: (n,) how far the smooth margins had to be relaxed (0: all kept).
        within_step: (n,) False where the per-frame step bound had to be dropped.
        smoothed: (n,) True where the smooth objective's track/extend smoothing was applied.
    """

    q: Array
    cost: Array
    margin_level: NDArray[np.int_]
    within_step: NDArray[np.bool_]
    smoothed: NDArray[np.bool_]

    @property
    def within_margins(self) -> NDArray[np.bool_]:
        """(n,) whether every margin of the smooth objective held."""
        return np.asarray(self.margin_level == 0)


def solve_path_report(
    robot: Robot,
    targets: ArrayLike,
    start: ArrayLike | None = None,
    *,
    objective: str | None = None,
    frame_interval: float | None = None,
    frame_numbers: ArrayLike | None = None,
    progress: Callable[[int], None] | None = None,
) -> PathSolution:
    """:func:`solve_path` with per-frame costs and relaxation flags.

    With the smooth objective and a frame interval, a shot whose frames needed relaxed margins
    or a widened step bound is surveyed from each branch of its first frame (elbow up or down,
    wrist flipped, arm turned over) on every fourth frame, and the most promising branch is
    solved in full; the run needing the fewest relaxed frames (then the least motion) is kept.
    Consecutive frames cannot change branch, so the first frame's branch decides where the
    whole move can go.
    """
    Ts = np.asarray(targets, dtype=float)
    if Ts.ndim != 3 or Ts.shape[1:] != (4, 4):
        msg = f"targets must have shape (n, 4, 4), got {Ts.shape}"
        raise ValueError(msg)
    n = Ts.shape[0]
    frames = np.arange(n) if frame_numbers is None else np.asarray(frame_numbers)
    first = robot.home.copy() if start is None else np.asarray(start, dtype=float).copy()
    obj = objective or robot.ik.objective
    step = None
    if frame_interval is not None and obj == "smooth":
        step = robot.max_velocity * float(frame_interval)
    run = _solve_sequence(robot, Ts, first, obj, step, frames, None, progress)
    if run.errors:
        raise UnreachableFramesError(run.errors)
    if step is not None and run.relaxed > 0 and n > 2 * _SURVEY_STRIDE:
        # survey every branch of the first frame on every few frames (cheap), then solve the
        # most promising one in full if it is not the one already solved
        k = _SURVEY_STRIDE
        survey: dict[int, tuple[int, float]] = {}
        for branch in range(N_BRANCHES):
            trial = _solve_sequence(robot, Ts[::k], first, obj, step * k, frames[::k], branch,
                                    None, give_up=min(survey.values(), default=None))
            if trial.complete and not trial.errors:
                survey[branch] = trial.score
        best = min(survey, key=lambda b: survey[b], default=run.first_branch)
        if best != run.first_branch and survey[best][0] * k < run.relaxed:
            other = _solve_sequence(robot, Ts, first, obj, step, frames, best, None,
                                    give_up=run.score)
            if other.complete and not other.errors and other.score < run.score:
                run = other
    out, cost, levels, steps = run.q, run.cost, run.levels, run.steps
    smoothed = np.zeros(n, dtype=bool)
    if obj == "smooth" and frame_interval is not None and robot.ik.smoothing > 0:
        out, smoothed = smooth_redundancy(robot, Ts, out, robot.ik.smoothing / frame_interval,
                                          margin_level=levels, max_step=step)
        cost = motion_cost(robot, out, np.vstack([first, out[:-1]]))
    return PathSolution(out, cost, levels, steps, smoothed)


@dataclass
class _Run:
    """One frame-by-frame pass over a shot."""

    q: Array
    cost: Array
    levels: NDArray[np.int_]
    steps: NDArray[np.bool_]
    errors: list[UnreachableError]
    first_branch: int
    complete: bool

    @property
    def relaxed(self) -> int:
        return int(np.count_nonzero(self.levels) + np.count_nonzero(~self.steps))

    @property
    def score(self) -> tuple[int, float]:
        return self.relaxed, float(self.cost.sum())


def _solve_sequence(
    robot: Robot,
    Ts: Array,
    first: Array,
    obj: str,
    step: Array | None,
    frames: NDArray[Any],
    first_branch: int | None,
    progress: Callable[[int], None] | None,
    give_up: tuple[int, float] | None = None,
) -> _Run:
    """Solve frame after frame; stop early once the run cannot beat ``give_up``."""
    n = Ts.shape[0]
    run = _Run(np.full((n, 8), np.nan), np.zeros(n), np.zeros(n, dtype=int),
               np.ones(n, dtype=bool), [], -1, False)
    prev = first
    for i in range(n):
        try:
            # the first frame is reached by the run-up, not within one frame interval
            sol = solve_ik(robot, Ts[i], prev, objective=obj,
                           max_step=step if i > 0 and not run.errors else None,
                           branch=first_branch if i == 0 else None)
        except UnreachableError as exc:
            if first_branch is not None:
                return run  # a forced branch that cannot even start: not a candidate
            run.errors.append(exc.at_frame(int(frames[i])))
        else:
            run.q[i], run.cost[i] = sol.q, sol.cost
            run.levels[i], run.steps[i] = sol.margin_level, sol.within_step
            if i == 0:
                run.first_branch = sol.branch
            prev = sol.q
        if progress is not None:
            progress(1)
        if give_up is not None and run.relaxed > give_up[0]:
            return run
    run.complete = True
    return run


def motion_cost(robot: Robot, q: ArrayLike, previous: ArrayLike) -> Array:
    """F = sum(w * |q - previous|) for joint vectors q (..., 8)."""
    return np.asarray(np.abs(np.asarray(q) - np.asarray(previous)) @ robot.weights)


def _check_target(target: ArrayLike) -> Array:
    T = np.asarray(target, dtype=float)
    if T.shape != (4, 4):
        msg = f"target must be a 4x4 pose, got shape {T.shape}"
        raise ValueError(msg)
    if not np.isfinite(T).all():
        raise UnreachableError("the target pose contains NaN or infinity", miss=math.inf)
    R = T[:3, :3]
    # orthonormal (as np.allclose(R.T @ R, I, atol=1e-6)) and not mirrored (det > 0)
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (np.abs(R.T @ R - _EYE3) <= _ORTHO_TOL).all() or det < 0:
        msg = "target rotation is not a proper rotation matrix (scaled, sheared or mirrored)"
        raise ValueError(msg)
    return T


def _diagnose(robot: Robot, T: Array, prev: Array) -> UnreachableError:
    """Say why a pose has no solution and by how much it misses."""
    bounds = _bounds_for(robot, "paper", MARGIN_LEVELS - 1, prev, None)
    prob = _Problem(robot, T, prev, bounds)
    intervals, miss = prob.intervals, prob.miss
    W = T[:3, 3]
    where = f"camera at ({W[0]:.3f}, {W[1]:.3f}, {W[2]:.3f}) m"
    if not intervals:
        return UnreachableError(
            f"{where} is out of reach by {miss:.3f} m (arm fully extended, track "
            f"[{robot.lower[_TRACK]:.2f}, {robot.upper[_TRACK]:.2f}] m)",
            miss=miss,
        )
    # position reachable: find the candidate whose worst limit overrun is smallest
    free = _Bounds(np.full(8, -np.inf), np.full(8, np.inf), 0.0)
    best: tuple[float, int] | None = None
    for a, b in intervals:
        r1s = np.linspace(a, b, 61)
        lo, hi = prob.region.r4_interval(r1s)
        sel = lo <= hi
        if not np.any(sel):
            continue
        t = np.linspace(0, 1, 21)
        r4 = (lo[sel, None] + (hi[sel] - lo[sel])[:, None] * t).ravel()
        r1 = np.repeat(r1s[sel], t.size)
        q_free, ok_free = six_axis_solutions(robot.dh, T, r1, r4, prev, free.lower, free.upper)
        over = np.maximum(q_free - robot.upper, 0) + np.maximum(robot.lower - q_free, 0)
        over = np.where(ok_free[..., None], over, np.inf)
        worst = over.max(axis=-1)
        k = int(np.argmin(worst))
        i, br = divmod(k, N_BRANCHES)
        cand = (float(worst.flat[k]), int(np.argmax(over[i, br])))
        if best is None or cand[0] < best[0]:
            best = cand
    if best is None or not math.isfinite(best[0]):
        return UnreachableError(f"{where}: no arm configuration reaches it", miss=math.inf)
    amount, axis = best
    name = JOINT_NAMES[axis]
    if PRISMATIC[axis]:
        return UnreachableError(
            f"{where} needs {name} {amount:.3f} m beyond its limit", miss=amount, axis=name
        )
    return UnreachableError(
        f"{where} needs {name} {math.degrees(amount):.1f} deg beyond its limit",
        miss=amount, miss_unit="rad", axis=name,
    )


def traverse(
    robot: Robot,
    target: ArrayLike,
    previous: ArrayLike,
    *,
    objective: str = "paper",
    radius: float | None = None,
    n1: int = 401,
    n4: int = 101,
    refine: int = 2,
) -> IKSolution:
    """Dense traversal of (track, extend): the brute-force check the SM paper used.

    Every point of an n1 x n4 grid over the track and extend limits (or over the box of
    half-width ``radius`` around the previous values, which must contain the optimum when
    ``radius >= F_known / min(w_track, w_extend)``) is solved in closed form on all branches;
    each extend column also holds the previous extend value and the ends of its reach interval.
    The best ``refine`` times: a grid ten times finer over the 2 x 2 cells around the best point.
    Slow by design (no search logic to trust); for tests and benchmarks.

    Raises:
        UnreachableError: Nothing on the grid is feasible.
    """
    T = _check_target(target)
    prev = np.asarray(previous, dtype=float)
    bounds = _bounds_for(robot, objective, 0, prev, None)
    prob = _Problem(robot, T, prev, bounds)
    r1p, r4p = float(prev[_TRACK]), float(prev[_EXTEND])
    lo1, hi1 = float(bounds.lower[_TRACK]), float(bounds.upper[_TRACK])
    lo4, hi4 = float(bounds.lower[_EXTEND]), float(bounds.upper[_EXTEND])
    if radius is not None:
        lo1, hi1 = max(lo1, r1p - radius), min(hi1, r1p + radius)
        lo4, hi4 = max(lo4, r4p - radius), min(hi4, r4p + radius)

    def sweep(a1: float, b1: float, a4: float, b4: float, m1: int, m4: int) -> None:
        r1s = np.linspace(a1, b1, m1)
        if a1 <= r1p <= b1:
            r1s = np.append(r1s, r1p)
        ilo, ihi = prob.region.r4_interval(r1s)
        rows = np.linspace(a4, b4, m4)
        for k in range(0, r1s.size, 64):
            c = r1s[k:k + 64]
            extra = np.stack([np.full(c.size, r4p), ilo[k:k + 64], ihi[k:k + 64]], axis=1)
            r4 = np.concatenate([np.broadcast_to(rows, (c.size, rows.size)), extra], axis=1)
            keep = (r4 >= a4) & (r4 <= b4)
            r1 = np.broadcast_to(c[:, None], r4.shape)[keep]
            if r1.size:
                prob.evaluate(r1, r4[keep])

    sweep(lo1, hi1, lo4, hi4, n1, n4)
    d1, d4 = (hi1 - lo1) / max(n1 - 1, 1), (hi4 - lo4) / max(n4 - 1, 1)
    for _ in range(refine):
        if prob.best_q is None:
            break
        c1, c4 = prob.best_q[_TRACK], prob.best_q[_EXTEND]
        sweep(max(c1 - 2 * d1, lo1), min(c1 + 2 * d1, hi1),
              max(c4 - 2 * d4, lo4), min(c4 + 2 * d4, hi4), 41, 41)
        d1, d4 = d1 / 10, d4 / 10
    if prob.best_q is None:
        raise UnreachableError("no grid point of the traversal reaches the target", miss=math.inf)
    return IKSolution(prob.best_q, prob.best_cost, prob.best_branch)




def _corridor_project(dh: DHConstants, wrist: Array, red: Array, lower: Array, upper: Array,
                      stretch: Array, samples: int = 48) -> Array:
    """Nearest point of each frame's closed-form (track, extend) feasible set.

    The set is bounded by the track and extend limits and by the reach curves: for an extend
    value the track must lie where the wrist centre is within reach (two intervals, behind and
    ahead of the target). Points inside stay; others move to the nearest of: the clipped extend
    at the same track, or a sampled point on the reach curves.

    Args:
        dh: DH constants.
        wrist: Wrist centres (n, 3) [m].
        red: Track and extend per frame (n, 2) [m].
        lower, upper: Position limits per frame (n, 8).
        stretch: Stretch margin per frame (n,) [rad].
        samples: Points per reach curve.
    """
    t_lo, t_hi = lower[:, _TRACK], upper[:, _TRACK]
    e_lo, e_hi = lower[:, _EXTEND], upper[:, _EXTEND]
    r1 = np.clip(red[:, 0], t_lo, t_hi)
    region = _Region(dh, wrist.T, -np.inf, np.inf, e_lo, e_hi, stretch)  # type: ignore[arg-type]
    lo, hi = region.r4_interval(r1)
    inside = (lo <= hi) & (red[:, 1] >= lo) & (red[:, 1] <= hi)
    out = np.stack([r1, np.where(lo <= hi, np.clip(red[:, 1], lo, hi), red[:, 1])], axis=1)
    bad = np.flatnonzero(~inside)
    if bad.size == 0:
        return out
    # reach curves: track values where extend e sits exactly at an end of its interval
    u = np.linspace(0.0, 1.0, samples)
    e = e_lo[bad, None] + (e_hi - e_lo)[bad, None] * u  # (b, s)
    L = e + dh.r40
    dse = np.hypot(L, dh.l3)
    cm, sm = np.cos(stretch[bad])[:, None], np.sin(stretch[bad])[:, None]
    ws_out2 = (dse + dh.r6 * cm) ** 2 + (dh.r6 * sm) ** 2  # (b, s)
    ws_in2 = L * L + (dh.r6 - dh.l3) ** 2
    W = wrist[bad]
    perp2 = (W[:, 1] ** 2 + (W[:, 2] - dh.r2) ** 2)[:, None]  # (b, 1)
    c = (W[:, 0] - dh.r10)[:, None]
    tl, th = t_lo[bad, None], t_hi[bad, None]
    cands_r1, cands_r4 = [], []
    for ws2 in (ws_out2, ws_in2):
        d = np.sqrt(np.maximum(ws2 - perp2, 0.0))  # (b, s)
        valid = ws2 >= perp2
        for sign in (-1.0, 1.0):
            r1c = c + sign * d
            ok = valid & (r1c >= tl) & (r1c <= th)
            cands_r1.append(np.where(ok, r1c, np.nan))
            cands_r4.append(e)
    cr1 = np.concatenate(cands_r1, axis=1)
    cr4 = np.concatenate(cands_r4, axis=1)
    # clipped-extend candidate (only where the interval is non-empty)
    clip_ok = (lo <= hi)[bad]
    cr1 = np.concatenate([cr1, np.where(clip_ok, r1[bad], np.nan)[:, None]], axis=1)
    cr4 = np.concatenate([cr4, out[bad, 1][:, None]], axis=1)
    dist = (cr1 - red[bad, 0][:, None]) ** 2 + (cr4 - red[bad, 1][:, None]) ** 2
    dist = np.where(np.isnan(dist), np.inf, dist)
    k = np.argmin(dist, axis=1)
    rows = np.arange(bad.size)
    good = np.isfinite(dist[rows, k])
    out[bad[good], 0] = cr1[rows, k][good]
    out[bad[good], 1] = cr4[rows, k][good]
    return out


def smooth_redundancy(
    robot: Robot,
    targets: ArrayLike,
    q: ArrayLike,
    sigma_frames: float,
    iterations: int = 60,
    margin_level: ArrayLike | None = None,
    max_step: Array | None = None,
) -> tuple[Array, NDArray[np.bool_]]:
    """Smooth the track/extend path of a solved shot and re-solve the other six axes.

    Frame-by-frame minimisation of the weighted L1 motion holds the prismatic axes still until
    a target forces them, then moves them only as far as needed and hands over from one to the
    other abruptly: their velocity jumps, an acceleration spike on a real axis. This pass
    low-passes track and extend with a Gaussian of ``sigma_frames`` and then, while any frame
    lies outside its feasible set (on the branch nearest the frame's own solution, within the
    bounds that solution kept), pushes the path back in with a smooth correction (the
    projection's offset, itself low-passed), so corners round off instead of being clipped.
    The six axes are then solved in closed form at the smoothed track/extend on that branch.
    A frame the
    correction could not bring inside keeps its frame-by-frame solution.

    Args:
        robot: The robot.
        targets: Flange poses (n, 4, 4) [m].
        q: The frame-by-frame solution (n, 8) [m, rad], continuous from frame to frame.
        sigma_frames: Width of the Gaussian in frames (0: no smoothing).
        iterations: Most correction rounds.
        margin_level: Per frame (n,), how far its solution relaxed the smooth objective's
            margins (``MARGIN_LEVELS``); each frame is smoothed within those bounds. Default 0.
        max_step: Per-axis step between frames (8,) the smoothed path may always take (e.g.
            velocity limit x frame interval); faster steps than the input's blend back.

    Returns:
        The smoothed joint path (n, 8) and, per frame, whether the smoothed value was used.
    """
    from scipy.ndimage import gaussian_filter1d

    Ts = np.asarray(targets, dtype=float)
    q1 = np.asarray(q, dtype=float)
    n = q1.shape[0]
    if sigma_frames <= 0 or n < 3:
        return q1.copy(), np.ones(n, dtype=bool)
    # each frame keeps the bounds its frame-by-frame solution was found under
    level = np.zeros(n, dtype=int) if margin_level is None else np.asarray(margin_level)
    lower, upper, stretch, wrist_m = _level_margins(robot, level)
    wrist = Ts[:, :3, 3]
    rows = np.arange(n)
    base = q1[:, [_TRACK, _EXTEND]]

    def solve(red: Array, idx: NDArray[np.intp]) -> tuple[Array, NDArray[np.bool_]]:
        qs, ok = six_axis_solutions(robot.dh, Ts[idx], red[:, 0], red[:, 1], q1[idx],
                                    lower[idx], upper[idx], stretch[idx], wrist_m[idx])
        # the branch nearest the frame's own solution (branch labels swap where two branches
        # meet, e.g. at full stretch, while the configuration stays continuous)
        k = np.arange(idx.size)
        dev = np.abs(qs - q1[idx, None, :])[..., REVOLUTE].max(axis=2)
        near = np.argmin(dev, axis=1)
        # stay in a tube around the frame-by-frame solution: near the wrist singularity pan
        # and roll swing wildly with track/extend, and the smoothing must not swing them
        return qs[k, near], ok[k, near] & (dev[k, near] <= _SMOOTH_TUBE)

    def project(red: Array) -> Array:
        out = _corridor_project(robot.dh, wrist, red, lower, upper, stretch)
        _, ok = solve(out, rows)
        bad = np.flatnonzero(~ok)
        # other limits (lift, elbow, tilt, wrist margin) bind: nearest feasible point of a
        # local probe towards the frame-by-frame solution, which is feasible
        for frac in (0.1, 0.25, 0.5, 0.75, 1.0):
            if bad.size == 0:
                break
            trial = out[bad] + frac * (base[bad] - out[bad])
            _, ok_b = solve(trial, bad)
            out[bad[ok_b]] = trial[ok_b]
            bad = bad[~ok_b]
        return out

    red = gaussian_filter1d(base, sigma_frames, axis=0, mode="nearest")
    for _ in range(iterations):
        delta = project(red) - red
        if not np.any(np.abs(delta) > 1e-9):
            break
        red = red + 1.5 * gaussian_filter1d(delta, max(sigma_frames / 2, 1.0), axis=0,
                                           mode="nearest")
    red = project(red)
    out, ok = solve(red, rows)
    out = np.where(ok[:, None], out, q1)
    # where the smoothed path steps faster than the frame-by-frame one (and faster than the
    # step bound), blend that stretch back towards the frame-by-frame path
    limit = np.maximum(np.abs(np.diff(q1, axis=0)), max_step if max_step is not None else 0.0)
    for _ in range(8 if max_step is not None else 0):
        jumps = np.any(np.abs(np.diff(out, axis=0)) > 1.05 * limit + 1e-9, axis=1)
        if not jumps.any():
            break
        mark = np.zeros(n)
        mark[:-1][jumps] = 1.0
        mark[1:][jumps] = 1.0
        pull = np.minimum(3.0 * gaussian_filter1d(mark, max(sigma_frames / 2, 1.0)) + mark, 1.0)
        red = red + pull[:, None] * (base - red)
        out, ok = solve(red, rows)
        out = np.where(ok[:, None], out, q1)
    return out, ok
