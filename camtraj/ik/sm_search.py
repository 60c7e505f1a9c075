"""The SM method's search over (track, extend) for one frame (see :mod:`camtraj.ik.sm`).

:class:`Problem` holds one target, one previous solution and one set of bounds, and remembers
the best point evaluated; its certificate, 1-D line search, 2-D box search and boundary search
are the steps :func:`camtraj.ik.sm.solve_ik` runs in turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.ik.closed_form import (
    AX,
    EXTEND,
    IDX,
    N_BRANCHES,
    TRACK,
    USES,
    packed_limits,
    six_axis_packed,
)
from camtraj.ik.region import Region
from camtraj.robot import REVOLUTE, Robot

Array = NDArray[np.float64]

_FAST_RADIUS = 1e-3  # [m] certificate only when the competing region is this small
_CERT_SAFETY = 0.5  # sensitivity must stay below this fraction of the prismatic weights
_PROBE_OFFSETS = np.geomspace(1e-7, 0.05, 10)  # extend probe around the 1-D search's best [m]

@dataclass(frozen=True)
class Bounds:
    """Limits in force for one solve: position limits, stretch margin, branch restriction."""

    lower: Array
    upper: Array
    stretch_margin: float = 0.0
    wrist_margin: float = 0.0
    branch: int | None = None  # restrict the solve to one closed-form branch


# ---------------------------------------------------------------------------------------------
# The search
# ---------------------------------------------------------------------------------------------


class Problem:
    """One target, one previous solution, one set of bounds; remembers the best point seen."""

    def __init__(self, robot: Robot, target: Array, previous: Array, bounds: Bounds) -> None:
        self.robot = robot
        self.target = target
        self.prev = previous
        self.bounds = bounds
        self.w = robot.weights
        self.w_min = float(min(self.w[TRACK], self.w[EXTEND]))
        self.region = Region(
            robot.dh, target[:3, 3].copy(),
            float(bounds.lower[TRACK]), float(bounds.upper[TRACK]),
            float(bounds.lower[EXTEND]), float(bounds.upper[EXTEND]),
            bounds.stretch_margin,
        )
        self.intervals, self.miss = self.region.r1_intervals()
        self.best_q: Array | None = None
        self.best_cost = math.inf
        self.best_branch = -1
        self._prev_packed = previous[AX]
        self._limits = packed_limits(previous, bounds.lower, bounds.upper)
        self._cost_matrix = USES * self.w[AX, None]  # (36, 8): F of each branch
        self.near_line = False
        self.probe_shift = math.inf  # how far the extend probe moved the best point [m]

    def evaluate(self, r1: Array, r4: Array) -> tuple[Array, Array]:
        """Cost (N, 8) with inf where infeasible, and the packed solutions (N, 36) (branch
        ``br``'s joint vectors are ``packed[:, IDX[br]]``). Records the best."""
        b = self.bounds
        packed, ok = six_axis_packed(self.robot.dh, self.target, r1, r4, self.prev,
                                      self._limits, b.stretch_margin, b.wrist_margin)
        if b.branch is not None:
            ok = ok & (np.arange(N_BRANCHES) == b.branch)
        cost = np.where(ok, np.abs(packed - self._prev_packed) @ self._cost_matrix, np.inf)
        flat = int(np.argmin(cost))
        c = float(cost.flat[flat])
        if c < self.best_cost:
            i, br = divmod(flat, N_BRANCHES)
            self.best_cost, self.best_q, self.best_branch = c, packed[i, IDX[br]], br
        return cost, packed

    def ball(self) -> float:
        """Half-width [m] of the box that must hold the optimum (prismatic cost alone)."""
        if self.w_min <= 0 or not math.isfinite(self.best_cost):
            return math.inf
        return self.best_cost / self.w_min

    def clip_r4(self, r1: Array) -> tuple[Array, NDArray[np.bool_]]:
        """Extend nearest its previous value inside the reach interval, and where one exists."""
        lo, hi = self.region.r4_interval(r1)
        return np.minimum(np.maximum(self.prev[EXTEND], lo), hi), lo <= hi

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
        r1p, r4p = float(self.prev[TRACK]), float(self.prev[EXTEND])
        h = 1e-7
        kinks = [r1p] if any(a <= r1p <= b for a, b in self.intervals) else []
        kinks += self.region.r1_kinks(r4p)
        kinks += [x for ab in self.intervals for x in ab]
        kinks_a = np.array(kinks)
        r4k, okk = self.clip_r4(kinks_a)
        # a first guess of the ball: prismatic cost of the cheapest kink + some revolute motion
        prism = self.w[TRACK] * np.abs(kinks_a - r1p) + self.w[EXTEND] * np.abs(r4k - r4p)
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
            and f_kink[k] <= all_f.min()
            and f[nk + k] >= f_kink[k]
            and f[2 * nk + k] >= f_kink[k]
        )
        if not at_kink:
            self._zoom_line(all_r1, all_f)
        if self._on_revolute_limit():
            # a revolute limit (e.g. the elbow on -180 deg) binds at the best point: the
            # optimum may slide along that limit's boundary, moving track and extend together,
            # which the 1-D reduction cannot see
            return False
        if at_kink and self._extend_flat(cost[k::nk][[0, 3, 4]], packed[k::nk][[0, 3, 4]], h):
            return True
        if self._extend_sensitivity_ok():
            return True
        self.near_line = True  # the optimum is off the held-extend curve, but close to it
        return False

    def _on_revolute_limit(self, tol: float = 1e-7) -> bool:
        """Whether the best point has a revolute axis within ``tol`` of a position limit."""
        q = self.best_q
        if q is None:
            return False
        b = self.bounds
        near = (q - b.lower <= tol) | (b.upper - q <= tol)
        return bool(np.any(near & REVOLUTE))

    def _zoom_line(self, r1s: Array, fs: Array, tol: float = 1e-9) -> None:
        """Refine the best track value of the 1-D curve by shrinking brackets."""
        order = np.argsort(r1s)
        r1s, fs = r1s[order], fs[order]
        i = int(np.argmin(fs))
        lo = r1s[max(i - 1, 0)]
        hi = r1s[min(i + 1, len(r1s) - 1)]
        r1p = float(self.prev[TRACK])
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
        w4 = float(self.w[EXTEND])
        prism = (self.w[TRACK] * abs(q[TRACK] - self.prev[TRACK])
                 + w4 * abs(q[EXTEND] - self.prev[EXTEND]))
        radius = max(fstar - prism, 0.0) / w4
        if w4 <= 0 or radius > _FAST_RADIUS:
            return False
        wr = self.w * REVOLUTE
        for br in range(N_BRANCHES):
            if not math.isfinite(cost[0, br]):
                continue
            fin = np.isfinite(cost[1:, br])
            qb = packed[:, IDX[br]]
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
        r4 = np.concatenate([q0[EXTEND] - offsets, q0[EXTEND] + offsets])
        r1 = np.full(r4.shape, q0[TRACK])
        self.evaluate(r1, r4)
        self.probe_shift = abs(float(self.best_q[EXTEND]) - float(q0[EXTEND]))
        return self.best_cost >= f0 - 1e-9 * max(1.0, f0)

    # -- the vertex certificate (hold track and extend) ------------------------------------
    def try_certificate(self) -> bool:
        """Settle the frame at (r1_prev, r4_prev) if no other point can be cheaper."""
        r1p, r4p = self.prev[TRACK], self.prev[EXTEND]
        if self.w_min <= 0:
            return False
        b = self.bounds
        if np.any(((self.prev - b.lower <= 1e-7) | (b.upper - self.prev <= 1e-7)) & REVOLUTE):
            return False  # a limit binds: the optimum may slide along its boundary
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
            qb = q[:, IDX[br]]
            slopes = np.abs(qb[1:] - qb[0]) @ wr / h
            g = float(np.max(np.where(fin[1:], slopes, 0.0)))
            if g <= _CERT_SAFETY * self.w_min:
                continue
            # a steeper branch is still safe if it cannot dip below fstar before the
            # prismatic cost alone exceeds fstar
            if g < self.w_min or (f0[br] - fstar) < (g - self.w_min) * radius:
                return False
        return bool(self.best_cost == fstar)

    # -- a binding revolute limit ----------------------------------------------------------
    def binding_axes(self, tol: float = 1e-7) -> list[tuple[int, float]]:
        """Revolute axes (and the limit value) on which the previous or the best solution sits."""
        b = self.bounds
        out: list[tuple[int, float]] = []
        for q in (self.prev, self.best_q):
            if q is None:
                continue
            for i in np.flatnonzero(REVOLUTE):
                for lim in (float(b.lower[i]), float(b.upper[i])):
                    if abs(q[i] - lim) <= tol and (int(i), lim) not in out:
                        out.append((int(i), lim))
        return out

    def boundary_search(self, axis: int, limit: float, n1: int = 33, rounds: int = 6) -> None:
        """Search along the curve where ``axis`` sits exactly on ``limit``.

        Where a revolute limit binds, the optimum may lie on that limit's boundary in the
        (track, extend) plane, a curve no grid meets exactly. For track values across the
        ball, extend is solved onto the curve by Newton steps (the closed form's axis value
        is smooth in extend) on the branches whose axis is near that limit, all in one
        closed-form call per step, and the best point zooms in track.
        """
        if not self.intervals or self.w_min <= 0:
            return
        r1p, r4p = float(self.prev[TRACK]), float(self.prev[EXTEND])
        free = packed_limits(self.prev, np.full(8, -np.inf), np.full(8, np.inf))
        packed0, _ = six_axis_packed(self.robot.dh, self.target, np.array([r1p]),
                                     np.array([r4p]), self.prev, free)
        cols = IDX[:, axis]
        near = np.abs(packed0[0, cols] - limit) < 0.2
        if self.best_branch >= 0:
            near[self.best_branch] = True
        cols = np.unique(cols[near])
        if cols.size == 0:
            return
        ball = self.ball()
        if not math.isfinite(ball):
            ball = 0.5
        lo, hi = r1p - ball, r1p + ball
        h = 1e-7
        for _ in range(rounds):
            r1s = self.r1_grid(lo, hi, n1)
            if lo <= r1p <= hi:
                r1s = np.append(r1s, r1p)
            if r1s.size == 0:
                return
            ilo, ihi = self.region.r4_interval(r1s)
            r1b = np.tile(r1s, cols.size)  # (c * m,): one Newton iteration per column
            r4 = np.full(r1b.size, r4p)
            lo_b, hi_b = np.tile(ilo, cols.size), np.tile(np.maximum(ilo, ihi), cols.size)
            pick = np.repeat(cols, r1s.size)
            rows = np.arange(r1b.size)
            for _it in range(5):
                packed, _ = six_axis_packed(self.robot.dh, self.target,
                                            np.concatenate([r1b, r1b]),
                                            np.concatenate([r4, r4 + h]), self.prev, free)
                f = packed[rows, pick] - limit
                df = (packed[rows + r1b.size, pick] - packed[rows, pick]) / h
                safe = np.where(np.abs(df) > 1e-12, df, 1.0)
                r4 = np.clip(r4 - np.where(np.abs(df) > 1e-12, f / safe, 0.0), lo_b, hi_b)
            self.evaluate(np.concatenate([r1b] * 3),
                          np.concatenate([r4, r4 - 1e-11, r4 + 1e-11]))
            if self.best_q is None:
                return
            step = (hi - lo) / max(n1 - 1, 1)
            if step < 1e-10:
                return
            c = float(self.best_q[TRACK])
            lo, hi = c - 2 * step, c + 2 * step

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
        r1p, r4p = float(self.prev[TRACK]), float(self.prev[EXTEND])
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
            r1b, r4b = float(self.best_q[TRACK]), float(self.best_q[EXTEND])
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
