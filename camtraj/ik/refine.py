"""Continuous refinement of a shot's track/extend curves inside the feasible corridor.

The variables are the track and extend values of every frame, x (n, 2) [m]; every other axis is
the closed-form solution on the frame's branch, so each frame reaches its pose exactly whatever
x is. :meth:`ShotCost.refine_total` (a power mean of the take's uses of the limits along the
timing stage's spline, :mod:`camtraj.ik.spline_ops`, with margins, run-up/run-out room and the
motion tie-break) is lowered by damped Gauss-Newton steps (Levenberg-Marquardt): per-frame
10 x 2 Jacobians of the measures by one-sided differences of the closed form (all frames in one
call), the spline's banded operators between frames, so the normal matrix is banded and one
banded Cholesky solve gives the step (the power mean's concave root enters as a rank-one
correction). Each step is projected into the corridor (the frame's track interval, then
extend's reach interval at that track); a frame the closed form cannot solve there keeps its
previous values; a step is kept only if the exact objective drops, so the result is never
worse than its start, and a kept step is lengthened while that keeps lowering it (a line
search: each trial at the minimum of the parabola through the objective, its slope and the
last trial, while that parabola promises a tenth of the drop so far). A continuation
raises the power in stages (:class:`Refinement`); from the second stage on, a use far below
the peak is modelled with the curvature it would have near it (:data:`_STAGES`), so a step
that would lift it there is not taken as free.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from camtraj.ik.closed_form import EXTEND
from camtraj.ik.region import Region
from camtraj.ik.shot import branch_measures
from camtraj.ik.shot_cost import CLOSE, N_MEASURES, ShotCost, TakeUse, margin_peak
from camtraj.ik.spline_ops import BandOps, windows
from camtraj.robot import Robot

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]

_H = 1e-6  # [m] central-difference step of the Jacobian
#: The peak norm's continuation, one row per stage: the power of the power mean; the share of
#: the stage's scale below which a use's model curvature is floored (``a`` = |z| / scale^k,
#: k the use's order, in :func:`_normal_equations`); and the stage's tolerance as a multiple
#: of ``refine_tolerance``.
#:
#: The Gauss-Newton model of a high power of a small use, a^(p/k), is nearly flat, so a step
#: that lifts the use towards the peak looks free and fails: from the second stage on (p / k
#: reaches 4 and more) a use below the floor gets the curvature it would have at the floor,
#: which majorises the term over the steps that matter. With the floor those stages descend
#: instead of stalling at their first step; each polishes the last one's answer, so it stops
#: at ten times the tolerance (measured on the shot set: the 100 deg arc 1.92x -> 2.35x, the
#: 60 fps follow 2.22x -> 2.43x, for about the same CPU: 0.84-1.09x over repeated runs).
_STAGES = ((6.0, 0.0, 1.0), (12.0, 0.7, 10.0), (24.0, 0.7, 10.0), (48.0, 0.7, 10.0))
REFINE_STAGES = len(_STAGES)
#: The least damping and the shift that keeps the banded factorisation positive definite, as
#: shares of the normal matrix's diagonal (its largest entry). The take's jerk is a third
#: difference of the frames: the curvature of a smooth bend of a whole curve (the step a
#: slow refinement keeps taking in the same direction, round after round) is about 1e-9 of
#: the diagonal, so a floor at that level damped exactly the steps that raise the speed
#: most. 1e-12 leaves them whole (a bend recovered to 2e-4, against 15% at 1e-9) and is
#: still far above the factorisation's round-off (band width x eps, about 1e-14). Measured
#: on the shot set (1e-9 -> 1e-12, before the run-out room was planned at the aimed speed,
#: :meth:`ShotCost.room_slowdown`): the 100 deg arc 2.35x -> 2.80x real time, the 60 fps
#: follow 2.43x -> 2.87x, median 1.002x; the smallest share of 10x the effort 0.94 -> 0.985
#: (at 1e-11 the follow stays at 0.95 of it).
DAMPING_FLOOR = 1e-12
#: The damping every stage starts from at most. A stage that ends at a corner of the
#: corridor (a frame's track on its interval's end, say) grows the damping there by 8 per
#: failed trial; carried into the next stage, that damping left every later stage without a
#: step (the truck past the track's end: stages 2-4 kept stage 1's take, 0.913x real time,
#: with the damping at 1e19-1e37; started from this it reaches 1.000x, 10x the effort 1.004x).
MU_START = 1e-3
#: A stage has converged after this many rounds in a row that each lower its objective by
#: less than the tolerance and by no more than the round before. While the damping still
#: shrinks from its start, each round gains more than the last though all gain little: on
#: the 60 fps follow the first two stages stopped after three such rounds (relative gains
#: 2e-5, 5e-5, 1.2e-4, each step lengthened 16x by the line search) and the take ran at
#: 2.92x real time; counting only rounds whose gain falls, 3.17x (10x the effort: 3.26x).
CONVERGED = 3


@dataclass
class Refined:
    """The refined curves: x (n, 2) [m], measures y (n, 10), and the take's maximum feasible
    speed (as ``take_speed`` measures it)."""

    x: Array
    y: Array
    speed: float = math.inf


class _Corridor:
    """Per frame: the chosen track interval and extend's reach interval at a track value."""

    def __init__(self, robot: Robot, targets: Array, lo1: Array, hi1: Array) -> None:
        self.lo1, self.hi1 = lo1, hi1
        self.region = Region(robot.dh, targets[:, :3, 3].T, -np.inf, np.inf,
                             float(robot.lower[EXTEND]), float(robot.upper[EXTEND]), 0.0)

    def project(self, x: Array) -> Array:
        r1 = np.clip(x[:, 0], self.lo1, self.hi1)
        lo4, hi4 = self.region.r4_interval(r1)
        r4 = np.clip(x[:, 1], lo4, np.maximum(lo4, hi4))
        return np.stack([r1, r4], axis=1)


class Refinement:
    """The refinement of one start, run stage by stage (:func:`refine` runs every stage).

    A continuation over the power of :meth:`ShotCost.refine_total`'s peak norm (6, 12, 24,
    48, :data:`_STAGES`): each stage starts from the last one's answer with the scale set to
    its peak use, and runs damped Gauss-Newton steps until three steps in a row lower the
    stage's objective by less than ``tolerance`` (relative; ten times that after the first
    stage), each by no more than the one before (:data:`CONVERGED`), no step lowers it, or
    after ``rounds`` steps. It starts from x0 or x0 low-passed (:func:`_smoothed`),
    whichever ``take_speed`` finds faster; the
    start and every stage's answer are measured with ``take_speed`` and the fastest is kept.

    Args:
        robot: The robot.
        cost: The objective (its ``power`` and ``scale`` are set per stage).
        targets: Flange poses (n, 4, 4) [m].
        branch: Closed-form branch per frame (n,).
        x0: Start track/extend per frame (n, 2) [m], feasible.
        y0: Its measures (n, 10), joints continuous.
        lo1, hi1: The track interval each frame stays in (n,) [m].
        rounds: Most Gauss-Newton steps per stage.
        tolerance: Relative decrease below which a stage has converged.
        take_speed: The maximum feasible speed of a joint path (n, 8) as the timing stage
            finds it (default: ``1 / cost.peak``, the objective's own model).
        held: The frame pairs (n - 1,) where the camera holds still: their frames keep equal
            track and extend values (x0 has them equal), so the robot holds still there.
    """

    def __init__(self, robot: Robot, cost: ShotCost, targets: Array, branch: IntArray,
                 x0: Array, y0: Array, lo1: Array, hi1: Array, rounds: int = 25,
                 tolerance: float = 1e-4,
                 take_speed: Callable[[Array], float] | None = None,
                 held: NDArray[np.bool_] | None = None) -> None:
        self.robot, self.cost, self.targets, self.branch = robot, cost, targets, branch
        self.rounds, self.tolerance = rounds, tolerance
        self.tie = _Tie.of(held) if held is not None else None
        self.x, self.y = x0.copy(), y0.copy()
        self.stages_done = 0
        self.mu = MU_START  # the damping, carried from stage to stage (at most MU_START)
        self.corridor = _Corridor(robot, targets, lo1, hi1) if x0.shape[0] >= 2 else None
        # the start and every stage's answer by the timing stage (which also sees what the
        # objective's model leaves out: gentle ends, the room they need): the fastest wins
        self.speed = take_speed or (lambda q: 1.0 / max(cost.peak(q), 1e-300))
        if self.corridor is not None:
            smooth = _smoothed(robot, targets, branch, self.corridor, x0, y0, held)
            if smooth is not None and self.speed(smooth[1][:, :8]) > self.speed(y0[:, :8]):
                self.x, self.y = smooth
        self.best = (self.speed(self.y[:, :8]) if self.corridor else math.inf, self.x, self.y)

    def stage(self) -> None:
        """Run the next stage of the continuation (nothing once all have run)."""
        if self.stages_done >= REFINE_STAGES:
            return
        power, floor, loosen = _STAGES[self.stages_done]
        self.stages_done += 1
        if self.corridor is None:
            return
        peak = self.cost.peak(self.y[:, :8])
        if not peak > 0.0:  # the robot stands still the whole shot: no peak to lower
            return
        # the ends' room joins the take's uses after the first stage, which settles the basin
        # (with it, a stop's barrier at its limit steered some first stages into slower
        # basins: a truck ending in motion 3.39x -> 3.10x real time)
        stage = replace(self.cost, power=power, scale=max(peak, 1e-6),
                        room=self.stages_done > 1)
        self.x, self.y, self.mu = _descend(self.robot, stage, self.corridor, self.targets,
                                           self.branch, self.x, self.y, self.rounds,
                                           loosen * self.tolerance, min(self.mu, MU_START),
                                           floor, self.tie)
        v = self.speed(self.y[:, :8])
        if v >= self.best[0]:
            self.best = (v, self.x, self.y)

    def result(self) -> Refined:
        """The fastest answer so far."""
        v, x, y = self.best
        return Refined(x.copy(), y.copy(), v)


def refine(robot: Robot, cost: ShotCost, targets: Array, branch: IntArray, x0: Array,
           y0: Array, lo1: Array, hi1: Array, rounds: int = 25,
           tolerance: float = 1e-4,
           take_speed: Callable[[Array], float] | None = None,
           held: NDArray[np.bool_] | None = None) -> Refined:
    """Every stage of a :class:`Refinement` (the same arguments): the fastest answer."""
    run = Refinement(robot, cost, targets, branch, x0, y0, lo1, hi1, rounds, tolerance,
                     take_speed, held)
    for _ in _STAGES:
        run.stage()
    return run.result()


SMOOTH_FRAMES = 4.0
"""The width (standard deviation, in frames) of the low-pass a start's track and extend curves
get (:func:`_smoothed`)."""


def _smoothed(robot: Robot, targets: Array, branch: IntArray, corridor: _Corridor, x: Array,
              y: Array, held: NDArray[np.bool_] | None) -> tuple[Array, Array] | None:
    """The start's track and extend curves x (n, 2) low-passed (a Gaussian of
    :data:`SMOOTH_FRAMES` frames), projected into the corridor, and their measures; frames
    the closed form cannot solve there, and held frames, keep theirs (None below 5 frames).

    The programme's points sit on a grid, and its steps from one grid point to another are
    jerk at the frame rate that the refinement spends its rounds taking out: on a 30 s orbit
    at 60 fps the programme's path ran at 0.027x real time and its first stage stopped at
    0.34x after 25 rounds, the take at 2.455x; smoothed, it starts at 0.29x and ends at 2.593x
    (10x the effort: 2.62x)."""
    from scipy.ndimage import gaussian_filter1d

    n = x.shape[0]
    if n < 5:
        return None
    xs = corridor.project(gaussian_filter1d(x, SMOOTH_FRAMES, axis=0, mode="nearest"))
    ys, ok = branch_measures(robot, targets, xs[:, 0], xs[:, 1], y[:, :8], branch)
    ok &= ~_folded(ys, y)
    if held is not None:  # a hold's frames keep their one value (the tie moves them as one)
        ok[:-1] &= ~held
        ok[1:] &= ~held
    return np.where(ok[:, None], xs, x), np.where(ok[:, None], ys, y)


def _descend(robot: Robot, cost: ShotCost, corridor: _Corridor, targets: Array,
             branch: IntArray, x: Array, y: Array, rounds: int, tolerance: float,
             mu: float, floor: float, tie: _Tie | None = None) -> tuple[Array, Array, float]:
    """Damped Gauss-Newton (Levenberg-Marquardt) on ``cost.refine_total`` until converged,
    from damping ``mu``, uses' curvature floored at ``floor`` (:data:`_STAGES`), with the
    frames of each camera hold moved together (``tie``): the curves and the damping
    reached."""
    targets2 = np.concatenate([targets] * 2)
    b2 = np.tile(branch, 2)
    use = cost.take_use(y[:, :8])
    j = cost.refine_total(y, use)
    # consecutive rounds that lowered the objective by less than the tolerance and by no more
    # than the round before: a round that gains more than the last is not converging, the
    # damping is still shrinking towards the steps the model asks for (:data:`CONVERGED`)
    slow, last_rel = 0, math.inf
    for _ in range(rounds):
        grad_y = _jacobian(robot, targets2, b2, x, y)
        H, g, w, c = _normal_equations(cost, y, grad_y, floor, use)
        tied = tie.reduce(H, g, w) if tie is not None else None
        improved = False
        for _try in range(10):
            if tie is not None and tied is not None:  # the step of the tied curves
                Hr, gr, wr = tied
                step = tie.expand(_solve_rank1(Hr, gr, mu, wr, c))
            else:
                step = _solve_rank1(H, g, mu, w, c)
            xn, yn, jn, un = _try_step(robot, cost, corridor, targets, branch, x, y, step)
            if jn < j:
                improved = True
                # The model's curvature is an upper bound (the power mean's concave outer
                # root is left out), so a good step is often too short: go on lengthening
                # it while that keeps lowering the objective, each time to the minimum of
                # the parabola through j, its slope along the step and the last value (2 to
                # 16 times as far), until that parabola promises less than a tenth of the
                # decrease already made (a trial that would most likely fail: on the shot
                # set a third fewer objective evaluations, the same speeds to +-1%).
                slope = float((g * step).sum())
                t = 1.0
                for _grow in range(6):
                    curve = (jn - j - t * slope) / (t * t)
                    if curve > 0.0:
                        far = -slope / (2.0 * curve)
                        if far <= t or curve * (far - t) ** 2 < 0.1 * (j - jn):
                            break
                    else:
                        far = math.inf
                    t_next = min(max(far, 2.0 * t), 16.0 * t)
                    xg, yg, jg, ug = _try_step(robot, cost, corridor, targets, branch, x, y,
                                               t_next * step)
                    if not jg < jn:
                        break
                    xn, yn, jn, un, t = xg, yg, jg, ug, t_next
                rel = (j - jn) / max(abs(j), 1e-300)
                x, y, j, use = xn, yn, jn, un
                mu = max(mu / 4.0, DAMPING_FLOOR)
                break
            mu *= 8.0
        if not improved:
            break
        slow = slow + 1 if rel < tolerance and rel <= last_rel else 0
        last_rel = rel
        if slow >= CONVERGED:
            break
    return x, y, mu


def _try_step(robot: Robot, cost: ShotCost, corridor: _Corridor, targets: Array,
              branch: IntArray, x: Array, y: Array,
              step: Array) -> tuple[Array, Array, float, TakeUse]:
    """The curves after a step, projected into the corridor; a frame the closed form cannot
    solve there (or only by folding a turn) keeps its values. Returns x, y, the objective
    and the take's use of the limits (the next round's normal equations reuse it)."""
    xn = corridor.project(x + step)
    yn, keep = branch_measures(robot, targets, xn[:, 0], xn[:, 1], y[:, :8], branch)
    keep &= ~_folded(yn, y)
    xn = np.where(keep[:, None], xn, x)
    yn = np.where(keep[:, None], yn, y)
    use = cost.take_use(yn[:, :8])
    return xn, yn, cost.refine_total(yn, use), use


def _folded(ya: Array, yb: Array) -> NDArray[np.bool_]:
    """Frames (n,) where a revolute axis moved by more than a quarter turn between two
    measure sets of the same frames: folded back inside its limits by whole turns (or over
    the wrist singularity), not moved."""
    return np.asarray((np.abs(ya[:, :8] - yb[:, :8]) > 0.5 * np.pi).any(axis=1))


def _jacobian(robot: Robot, targets2: Array, b2: IntArray, x: Array, y: Array) -> Array:
    """d measures / d (track, extend) per frame (n, 10, 2), by one-sided differences of the
    closed form from the measures y at x (both sides' frames in one call; ``targets2`` and
    ``b2`` are the targets and branches twice); a side the closed form cannot solve (a
    corridor edge) is taken backwards."""
    n = x.shape[0]
    grad_y = np.zeros((n, N_MEASURES, 2))
    side = np.ones((n, 2))
    for attempt in range(2):
        pts = np.concatenate([x + [_H, 0] * side[:, :1], x + [0, _H] * side[:, 1:]])
        prev = np.concatenate([y[:, :8]] * 2)
        ya, oka = branch_measures(robot, targets2, pts[:, 0], pts[:, 1], prev, b2)
        ys = ya.reshape(2, n, N_MEASURES)
        good = oka.reshape(2, n) & ~np.stack([_folded(ys[0], y), _folded(ys[1], y)])
        for v in range(2):
            grad_y[:, :, v] = np.where(good[v][:, None], (ys[v] - y) / (_H * side[:, v:v + 1]),
                                       grad_y[:, :, v])
        bad = ~good.T  # (n, 2)
        if not bad.any() or attempt:
            break
        side = np.where(bad, -1.0, side)
    return grad_y


def _normal_equations(cost: ShotCost, y: Array, grad_y: Array, floor: float = 0.0,
                      use: TakeUse | None = None) -> tuple[Array, Array, Array, float]:
    """Gauss-Newton normal matrix (n, D, 2, 2) (the 2 x 2 block of frame k with frame k + d),
    gradient, and the rank-one correction (w (n, 2), c: the curvature is H - c w w^T) of
    ``cost.refine_total``.

    The difference terms are first gathered per axis in the joints: ``M[d][p, i]`` is the
    curvature coupling frames p and p + d through axis i, ``gq`` the gradient in the joints;
    then the chain rule through the per-frame Jacobians (n, 10, 2) gives the blocks. The peak
    norm T = s (sum f)^(1/p), f = (|z| / s^k)^(p/k) for order k, enters through its
    Gauss-Newton model (the concave outer power dropped: the model overestimates curvature),
    each use's curvature taken at ``max(a, floor)`` (:data:`_STAGES`);
    the L1 motion tie-break through its majorising quadratic; margin hinges through their
    active sets. ``use`` is ``cost.take_use`` of y's joints, when already known.
    """
    n = y.shape[0]
    q, G = y[:, :8], grad_y[:, :8, :]
    p, s = cost.power, cost.scale
    use = use or cost.take_use(q)
    ops = use.ops
    width = ops.coef.shape[1]
    pad = width  # frames of padding on either side of the gathered arrays
    M = np.zeros((width, n + 2 * pad, 8))  # M[d, pad + f]: curvature coupling f and f + d
    gq = np.zeros((n + 2 * pad, 8))
    scaled = use.scaled(p, s)
    phi = scaled.phi
    kappa = (s / p) * max(phi, 1e-300) ** (1.0 / p - 1.0)
    order = np.asarray(ops.orders, dtype=float)
    ex = p / order
    c = s ** order
    lim = np.stack([(cost.vel, cost.acc, cost.jerk)[k - 1] for k in ops.orders], axis=-1)
    below = scaled.below  # a^(ex - 2), a = |z| / c
    dz = below * use.z * (kappa * ex / (c * c * lim))  # a^(ex - 1) sign(z) = a^(ex - 2) z / c
    if floor > 0.0:  # max(a, floor)^(ex - 2): the power is monotone (ex >= 2 in every stage)
        below = np.maximum(below, floor ** (ex - 2.0))
    w = below * (kappa * ex * (ex - 1.0) / (c * c * lim * lim))
    _gather(ops, dz, w, gq, M, pad)
    if use.ends is not None:  # the ends' needs: one row per need and axis
        need, lins, frames = use.ends
        a = need / s
        f1 = kappa * p * a ** (p - 1.0) / s
        f2 = kappa * p * (p - 1.0) * a ** (p - 2.0) / (s * s)
        off = ops.offset
        for k in range(need.shape[0]):
            lin = lins[k]  # d need / d q[f] per axis: (width, 8)
            lo = pad + int(frames[k]) + off
            gq[lo:lo + lin.shape[0]] += lin * f1[k]
            first, d = _upper_pairs(lin.shape[0])  # frames lo + first and lo + first + d
            M[d, lo + first] += lin[first] * lin[first + d] * f2[k]
    # the peak norm's gradient alone: its concave outer root adds -c w w^T to the curvature
    g_peak = np.einsum("ki,kip->kp", gq[pad:pad + n], G)
    concave = (1.0 - 1.0 / p) / max(kappa * phi, 1e-300)
    m = n - 1  # the motion tie-break, mean over steps, through its majorising quadratic
    if m > 0:  # step k = q[k + 1] - q[k]: frames k and k + 1, with weights -1 and +1
        z = np.diff(q, axis=0) / cost.vel
        t = cost.tie_break / m
        dz = t * cost.motion_coef * np.sign(z) / cost.vel
        w = t * cost.motion_coef / np.maximum(np.abs(z), 0.05) / (cost.vel * cost.vel)
        gq[pad:pad + m] -= dz
        gq[pad + 1:pad + n] += dz
        M[0, pad:pad + m] += w
        M[0, pad + 1:pad + n] += w
        M[1, pad:pad + m] -= w
    g = np.einsum("ki,kip->kp", gq[pad:pad + n], G)
    # H[k, d] = sum_i M[d, k, i] G[k, i]^T G[k + d, i]: frame k with frame k + d, one
    # entry (p, q) at a time over contiguous (d, k, i) arrays
    g_cols = np.zeros((2, n + width, 8))
    g_cols[:, :n] = G.transpose(2, 0, 1)
    H = np.empty((n, width, 2, 2))
    right = [windows(g_cols[col], n, count=width)
             for col in range(2)]  # right[col][d, i, k] = G[k + d, i, col]
    for row in range(2):
        left = M[:, pad:pad + n] * g_cols[row, :n]  # (d, k, i)
        for col in range(2):
            H[:, :, row, col] = np.einsum("dki,dik->kd", left, right[col])
    # margins: hinge^2 of z = 1 - d / zone, d the distance to the nearer limit (or the
    # singularity distance itself), the worst frame's through its power mean
    e = cost.intrusion(y)
    active = e > 0
    if active.any():
        lam = (cost.refine_margin * cost.scale * margin_peak(e)[1])[:, None]
        close = np.maximum(e - CLOSE, 0.0)
        lower_near = (y[:, :8] - cost.lower) <= (cost.upper - y[:, :8])
        dd = np.concatenate([np.where(lower_near, 1.0, -1.0), np.ones((n, 2))], axis=1)
        dz = -dd / cost.zone  # dz/dy
        gz = np.where(active, 2 * (lam * e + cost.close_weight * close) * dz, 0.0)
        hz = np.where(active, 2 * (lam + cost.close_weight * (close > 0)) * dz * dz, 0.0)
        g += np.einsum("ki,kip->kp", gz, grad_y)
        H[:, 0] += (grad_y * hz[..., None]).transpose(0, 2, 1) @ grad_y
    slow = cost.room_slowdown(use)
    for edge, inner in ((0, 1), (n - 1, n - 2)):  # run-up / run-out room
        pe, slope = cost.edge_excursion(q[edge], q[inner], slow)
        e = cost.edge_intrusion(pe)
        if not (e > 0).any():
            continue
        lower_near = (pe - cost.lower) <= (cost.upper - pe)
        de = np.where(e > 0, -np.where(lower_near, 1.0, -1.0) / cost.zone[:8], 0.0)
        beyond = np.maximum(e - 1.0, 0.0)
        ge = 2 * (cost.refine_margin * e + cost.overspeed * beyond) * de
        he = 2 * (cost.refine_margin + cost.overspeed * (beyond > 0)) * de * de
        a_e = slope[:, None] * G[edge]  # dp/dx_edge (8, 2)
        a_i = (1.0 - slope)[:, None] * G[inner]
        g[edge] += ge @ a_e
        g[inner] += ge @ a_i
        H[edge, 0] += (he[:, None, None] * a_e[:, :, None] * a_e[:, None, :]).sum(axis=0)
        H[inner, 0] += (he[:, None, None] * a_i[:, :, None] * a_i[:, None, :]).sum(axis=0)
        lo_f = min(edge, inner)
        a_lo, a_hi = (a_e, a_i) if edge < inner else (a_i, a_e)
        H[lo_f, 1] += (he[:, None, None] * a_lo[:, :, None] * a_hi[:, None, :]).sum(axis=0)
    return H, g, g_peak, concave


def _gather(ops: BandOps, dz: Array, w: Array, gq: Array, M: Array, pad: int) -> None:
    """Add the operators' terms to the joint-space gradient ``gq`` and curvature ``M``.

    Row r of operator i reads frames r + offset + o with weights coef[r, o, i]; its gradient
    in its value is dz[r, :, i] (rows, 8, k), its Gauss-Newton curvature w[r, :, i]: frame f
    gets sum coef[r, f - r - offset, i] dz[r, :, i], and the pair (f, f + d)
    sum coef[r, o, i] coef[r, o + d, i] w[r, :, i]. The shift-invariant rows are
    correlations (the gradient: one product, then a shifted add per tap; the curvature:
    :func:`_correlate`); the rows near the ends, each with its own weights, as one batched
    product of their taps' pair products.
    """
    coef = ops.coef
    rows, width, _ = coef.shape
    base = pad + ops.offset
    a, b = ops.inner
    if b > a:
        kern = coef[a]  # (width, k)
        span = b - a + width - 1
        taps = kern @ dz[a:b].reshape(-1, kern.shape[1]).T  # (width, rows * 8): tap o's part
        for o in range(width):
            gq[base + a + o:base + b + o] += taps[o].reshape(b - a, -1)
        M[:width, base + a:base + a + span] += _correlate(w[a:b], ops.inner_pairs)
    for (lo, hi), pair_products in zip(((0, a), (b, rows)) if b > a else ((0, rows), (0, 0)),
                                       ops.edge_pairs, strict=True):
        if hi <= lo:
            continue
        # rows with their own weights (near the ends): row r gives frame r + o the tap
        # coef[r, o] dz[r] and the pair (r + o, r + o + d) coef[r, o] coef[r, o + d] w[r],
        # one batched product per row, then every (row, tap) summed per frame at once
        f0 = base + lo
        span = hi - lo + width - 1
        taps = coef[lo:hi] @ dz[lo:hi].transpose(0, 2, 1)  # (rows, width, 8)
        pair_w = (pair_products @ w[lo:hi].transpose(0, 2, 1)).reshape(
            hi - lo, width, width, -1)  # (rows, o, d, 8)
        gq[f0:f0 + span] += _diagonal_sums(taps)
        M[:, f0:f0 + span] += _diagonal_sums(pair_w).transpose(1, 0, 2)


@lru_cache(maxsize=4)
def _upper_pairs(width: int) -> tuple[IntArray, IntArray]:
    """Every pair of taps o <= o + d < width, as (o, d) index arrays."""
    first, second = np.triu_indices(width)
    return first, second - first


def _diagonal_sums(v: Array) -> Array:
    """out[f] = sum over o of v[f - o, o] for v (rows, width, ...): what row r's tap o adds to
    frame r + o, summed per frame, (rows + width - 1, ...). Each (row, tap) is written to its
    own cell of a (frame, tap) table through a strided view, then the taps are summed: three
    array operations instead of one shifted add per tap."""
    rows, width = v.shape[:2]
    table = np.zeros((rows + width - 1, *v.shape[1:]))
    cells = np.lib.stride_tricks.as_strided(
        table, shape=v.shape,
        strides=(table.strides[0], table.strides[0] + table.strides[1], *table.strides[2:]))
    cells[...] = v
    return np.asarray(table.sum(axis=1))


def _correlate(w: Array, pairs: Array) -> Array:
    """The curvature (width, rows + width - 1, m) the shift-invariant rows w (rows, m, k) give
    the frame pairs: [d, t] sums pairs[o, i, d] w[t - o, :, i] over taps o and operators i
    (zero outside the rows), frame t counted from the first row's first tap.

    One product of the pairs (width, width * k) with a table whose row (j, i) is operator i's
    values from row j - width + 1 on, frames along the row: each table row is one contiguous
    run of an operator-major copy of w, so the table is built by block copies instead of a
    transpose of windows (the same product, term for term, as an einsum over those windows).
    """
    rows, m, k = w.shape
    width = pairs.shape[0]
    span = rows + width - 1
    by_op = np.zeros((k, rows + 2 * (width - 1), m))
    by_op[:, width - 1:width - 1 + rows] = w.transpose(2, 0, 1)
    flat = by_op.reshape(k, -1)
    item = flat.itemsize
    table = np.lib.stride_tricks.as_strided(flat, (width, k, span * m),
                                            (m * item, flat.strides[0], item))
    left = pairs[::-1].transpose(2, 0, 1).reshape(width, width * k)
    return np.asarray(left @ table.reshape(width * k, span * m)).reshape(width, span, m)


@dataclass(frozen=True)
class _Tie:
    """The frames of each camera hold as one: frame k's values are run ``run[k]``'s (runs of
    frames joined by held pairs, numbered along the shot)."""

    run: IntArray
    count: int

    @classmethod
    def of(cls, held: NDArray[np.bool_]) -> _Tie | None:
        """The tie of the held frame pairs (n - 1,); None when nothing holds."""
        if not held.any():
            return None
        run = np.concatenate([[0], np.cumsum(~held)]).astype(np.intp)
        return cls(run, int(run[-1]) + 1)

    def reduce(self, H: Array, g: Array, w: Array) -> tuple[Array, Array, Array]:
        """The normal equations (:func:`_normal_equations`' H, g and w) in the runs' values:
        P^T H P, P^T g, P^T w for the (n, runs) map P from runs to frames. A pair of frames
        d apart lies in runs at most d apart, so the band keeps its width; a pair inside one
        run adds both its off-diagonal blocks to the run's diagonal block."""
        n, width = H.shape[:2]
        k, d = np.meshgrid(np.arange(n), np.arange(width), indexing="ij")
        inside = k + d < n
        k, d = k[inside], d[inside]
        blocks = H[k, d]
        rk = self.run[k]
        e = self.run[k + d] - rk
        same = (e == 0) & (d > 0)
        blocks[same] += blocks[same].swapaxes(-1, -2)
        # bincount adds in the order of its input, as np.add.at does, at a fraction of its cost
        cell = rk * width + e
        Hr = np.empty((self.count, width, 2, 2))
        for p in range(2):
            for q in range(2):
                Hr[:, :, p, q] = np.bincount(cell, blocks[:, p, q],
                                             self.count * width).reshape(self.count, width)
        return Hr, self._sum(g), self._sum(w)

    def _sum(self, v: Array) -> Array:
        """The runs' sums (runs, 2) of per-frame values v (n, 2)."""
        return np.stack([np.bincount(self.run, v[:, c], self.count) for c in range(2)], axis=1)

    def expand(self, step: Array) -> Array:
        """The frames' values (n, 2) of the runs' values (runs, 2)."""
        return np.asarray(step[self.run])


def _solve_rank1(H: Array, g: Array, mu: float, w: Array, c: float) -> Array:
    """The step for the curvature (H damped) - c w w^T (Sherman-Morrison over two banded
    solves), with c cut so the matrix stays positive definite (c w^T A^-1 w <= 0.9)."""
    both = _solve_banded(H, np.stack([g, -w], axis=-1), mu)  # A^-1 (-g), A^-1 w
    s1, s2 = both[..., 0], both[..., 1]
    wa = float((w * s2).sum())
    if not (c > 0.0 and wa > 0.0 and np.isfinite(wa)):
        return np.asarray(s1)
    c = min(c, 0.9 / wa)
    return np.asarray(s1 + s2 * (c * float((w * s1).sum()) / (1.0 - c * wa)))


def _solve_banded(H: Array, g: Array, mu: float) -> Array:
    """Solve (H + mu diag(H) + s I) step = -g for the (n, 2) step (or (n, 2, k) for k
    right-hand sides g (n, 2, k)), s = :data:`DAMPING_FLOOR` times the largest diagonal entry
    (at least 1e-12).

    ``H[k, d]`` is the 2x2 block coupling frame k with frame k + d (the d = 0 blocks are
    symmetric): a symmetric positive definite band of 2 D - 1 scalars above the diagonal,
    solved by LAPACK's banded Cholesky (scipy's ``solveh_banded``).
    """
    from scipy.linalg import solveh_banded

    n, width = H.shape[:2]
    u = 2 * width - 1
    ab = np.zeros((u + 1, 2 * n))
    dest, src = _band_index(n, width)
    ab.reshape(-1)[dest] = H.reshape(-1)[src]
    diag = ab[u]
    top = max(float(diag.max()), 1e-12)
    # Entries far below the diagonal shift cannot change the step; dropping them keeps the
    # factorisation clear of subnormal numbers, which slow LAPACK a thousandfold.
    ab[np.abs(ab) < 1e-24 * top] = 0.0
    shift = DAMPING_FLOOR * top
    ab[u] = diag * (1.0 + mu) + shift
    rhs = -g.reshape(2 * n, -1)
    rhs[np.abs(rhs) < 1e-300] = 0.0
    return np.asarray(solveh_banded(ab, rhs, check_finite=False)).reshape(g.shape)


@lru_cache(maxsize=2)  # per path length: the solve's own, not kept for long
def _band_index(n: int, width: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Where each stored scalar of H (n, width, 2, 2) goes in the upper band form of
    ``solveh_banded`` (flat indices into ab (2 width, 2 n) and into H), for the scalars
    on or above the diagonal that exist (frame k + d < n)."""
    k, d, p, q = np.meshgrid(np.arange(n), np.arange(width), np.arange(2), np.arange(2),
                             indexing="ij")
    row, col = 2 * k + p, 2 * (k + d) + q
    keep = ((k + d) < n) & (row <= col)
    u = 2 * width - 1
    dest = (u + row - col) * (2 * n) + col
    src = np.arange(k.size).reshape(k.shape)
    return dest[keep], src[keep]


__all__ = ["REFINE_STAGES", "Refined", "Refinement", "refine"]
