"""The SM method per frame (the ``paper`` objective): the papers' optimum, frame by frame.

The SM method (He 2018) fixes the two redundant prismatic axes, track (r1) and extend (r4), solves
the remaining six axes in closed form (:mod:`camtraj.ik.closed_form`), and searches (r1, r4) for
the solution that minimises the weighted axis motion ``F = sum(w_i * |q_i - q_i,prev|)``.

Search. For one r1 the feasible extend values form an interval known in closed form
(:mod:`camtraj.ik.region`); r1 itself is confined to at most two intervals around the target.
Because moving a prismatic axis by d costs at least ``w_min * |d|``, the optimum lies within
``F_best / w_min`` (L1) of the previous (r1, r4): the search box shrinks to that ball as soon as
any feasible point is known. Inside the box a grid that contains the objective's kinks exactly
(r1 = r1_prev, r4 = r4_prev, the box and reach boundaries) is zoomed around the best candidates.
On smooth paths most frames are settled by a certificate instead: when holding track and extend
still is feasible and the other axes' sensitivity to them is far below their weights, no other
point can be cheaper. The same argument, in extend alone, settles most frames of the 1-D search
without probing extend. Where a revolute limit binds, a Newton search along that limit's
boundary joins in. The search steps live in :mod:`camtraj.ik.sm_search`; this module holds the
entry point, the diagnosis of unreachable poses and the dense traversal that checks it all.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.errors import UnreachableError
from camtraj.ik.closed_form import (
    EXTEND,
    N_BRANCHES,
    TRACK,
    six_axis_solutions,
)
from camtraj.ik.sm_search import Bounds, Problem
from camtraj.robot import JOINT_NAMES, PRISMATIC, Robot

Array = NDArray[np.float64]

_EYE3 = np.eye(3)
_ORTHO_TOL = 1e-6 + 1e-5 * _EYE3  # np.allclose(R.T @ R, I, atol=1e-6)


@dataclass(frozen=True)
class IKSolution:
    """One solved pose.

    Attributes:
        q: Joint vector (8,) [m, rad].
        cost: F = sum(w * |q - previous|) with the robot's weights (per m / per rad).
        branch: Index 0..7 of the closed-form branch (rotate back, elbow, wrist flip bits).
        within_step: False when a requested per-frame step bound could not be kept.
    """

    q: Array
    cost: float
    branch: int
    within_step: bool = True


def _bounds_for(robot: Robot, previous: Array, max_step: Array | None) -> Bounds:
    """The papers' constraints: the hard position limits, with an optional step box."""
    lower, upper = robot.lower.copy(), robot.upper.copy()
    if max_step is not None:
        # a step bound is a per-frame box around the previous solution; where the previous
        # solution lies outside the limits the box is clamped, never inverted
        lower = np.minimum(np.maximum(lower, previous - max_step), upper)
        upper = np.maximum(np.minimum(upper, previous + max_step), lower)
    return Bounds(lower, upper)


def _solve_one(robot: Robot, target: Array, previous: Array, bounds: Bounds) -> Problem:
    prob = Problem(robot, target, previous, bounds)
    if prob.try_certificate() or prob.line_search():
        return prob
    prob.box_search()
    for axis, limit in prob.binding_axes():
        # only where the best point found is close to that limit: elsewhere the limit's
        # boundary is far from the optimum (e.g. a solve from home, elbow on 0 deg)
        if prob.best_q is None or abs(prob.best_q[axis] - limit) < 0.05:
            prob.boundary_search(axis, limit)
    return prob


def check_joints(value: ArrayLike, name: str, bound: float = 1e4) -> Array:
    """A joint vector argument as (8,) floats; ValueError naming ``name`` otherwise."""
    try:
        q = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        msg = f"{name} must be 8 joint values [m, rad], got {value!r}"
        raise ValueError(msg) from None
    if q.shape != (8,) or not np.all(np.isfinite(q)) or np.abs(q).max() > bound:
        msg = (f"{name} must be 8 finite joint values [m, rad] within +-{bound:g}, "
               f"got {np.array2string(q, precision=4)}")
        raise ValueError(msg)
    return q


def solve_ik(
    robot: Robot,
    target: ArrayLike,
    previous: ArrayLike | None = None,
    *,
    max_step: ArrayLike | None = None,
    branch: int | None = None,
) -> IKSolution:
    """Solve one flange pose, minimising the papers' weighted motion F from ``previous``.

    Args:
        robot: The robot (limits, weights).
        target: Flange pose in the base frame (``flange2base``), shape (4, 4) [m].
        previous: Joint vector (8,) the move starts from; default the robot's home.
        max_step: Optional per-axis bound on |q - previous| (8,) [m, rad], e.g. what each axis
            can travel in one frame at its velocity limit. It keeps consecutive frames on one
            branch; where no solution respects it, it is widened (x2, x4, x8, x16) and only
            then dropped (``within_step`` is False in either case).
        branch: Restrict the solution to this closed-form branch (0..7), e.g. to start a shot
            elbow-up instead of elbow-down.

    Returns:
        The solution.

    Raises:
        ValueError: A malformed argument (named in the message).
        UnreachableError: No solution inside the joint limits; says by how much it misses.
    """
    T = check_target(target)
    prev = robot.home.copy() if previous is None else check_joints(previous, "previous")
    step = None
    if max_step is not None:
        step = np.asarray(max_step, dtype=float)
        if step.shape != (8,) or not np.all(step >= 0) or np.isnan(step).any():
            msg = f"max_step must be 8 non-negative values [m, rad], got {max_step!r}"
            raise ValueError(msg)
    if branch is not None and (isinstance(branch, bool) or branch not in range(N_BRANCHES)):
        msg = f"branch must be an integer 0..{N_BRANCHES - 1}, got {branch!r}"
        raise ValueError(msg)
    # a step bound that cannot be kept is widened before it is dropped, so a move too fast
    # for the robot stays continuous (the timing stage then reports its speed honestly)
    scales: list[float | None] = [1.0, 2.0, 4.0, 8.0, 16.0, None] if step is not None else [None]
    for scale in scales:
        bounds = _bounds_for(robot, prev, None if scale is None or step is None else step * scale)
        if branch is not None:
            bounds = dataclasses.replace(bounds, branch=branch)
        prob = _solve_one(robot, T, prev, bounds)
        if prob.best_q is not None:
            return IKSolution(prob.best_q, prob.best_cost, prob.best_branch,
                              within_step=scale == 1.0 or step is None)
    raise _diagnose(robot, T, prev)


def motion_cost(robot: Robot, q: ArrayLike, previous: ArrayLike) -> Array:
    """F = sum(w * |q - previous|) for joint vectors q (..., 8)."""
    return np.asarray(np.abs(np.asarray(q) - np.asarray(previous)) @ robot.weights)


def check_target(target: ArrayLike) -> Array:
    T = np.asarray(target, dtype=float)
    if T.shape != (4, 4):
        msg = f"target must be a 4x4 pose, got shape {T.shape}"
        raise ValueError(msg)
    if not np.isfinite(T).all():
        msg = "target must be a finite pose (it contains NaN or infinity)"
        raise ValueError(msg)
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
    bounds = _bounds_for(robot, prev, None)
    prob = Problem(robot, T, prev, bounds)
    intervals, miss = prob.intervals, prob.miss
    W = T[:3, 3]
    where = f"camera mount at ({W[0]:.3f}, {W[1]:.3f}, {W[2]:.3f}) m in robot base coordinates"
    if not intervals:
        return UnreachableError(
            f"{where} is out of reach by {miss:.3f} m (arm fully extended, track "
            f"[{robot.lower[TRACK]:.2f}, {robot.upper[TRACK]:.2f}] m)",
            miss=miss,
        )
    # position reachable: find the candidate whose worst limit overrun is smallest
    free = Bounds(np.full(8, -np.inf), np.full(8, np.inf), 0.0)
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
    T = check_target(target)
    prev = check_joints(previous, "previous")
    bounds = _bounds_for(robot, prev, None)
    prob = Problem(robot, T, prev, bounds)
    r1p, r4p = float(prev[TRACK]), float(prev[EXTEND])
    lo1, hi1 = float(bounds.lower[TRACK]), float(bounds.upper[TRACK])
    lo4, hi4 = float(bounds.lower[EXTEND]), float(bounds.upper[EXTEND])
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
        c1, c4 = prob.best_q[TRACK], prob.best_q[EXTEND]
        sweep(max(c1 - 2 * d1, lo1), min(c1 + 2 * d1, hi1),
              max(c4 - 2 * d4, lo4), min(c4 + 2 * d4, hi4), 41, 41)
        d1, d4 = d1 / 10, d4 / 10
    if prob.best_q is None:
        raise UnreachableError("no grid point of the traversal reaches the target", miss=math.inf)
    return IKSolution(prob.best_q, prob.best_cost, prob.best_branch)
