"""Baseline inverse-kinematics solvers that ``bench/run.py`` compares the SM method against.

Every baseline minimises the same objective as :func:`camtraj.ik.solve_ik` (the
``paper`` objective): ``F = sum(w_i * |q_i - q_i,prev|)`` over the joint vector q (8,) [m, rad]
that puts the flange on ``target`` (``flange2base``, (4, 4) [m]) inside the robot's position
limits, and returns a :class:`BaselineResult`.

- :func:`slsqp_ik`: a generic numerical solver, scipy SLSQP over all eight axes, as a user of
  scipy without the closed-form substructure would set it up (smoothed |d|, pose equality
  constraint with finite-difference Jacobian, joint bounds, seeded from the previous solution).
- :func:`gm_ik`: the GA paper's improved method rebuilt (Zhang, He & Wang 2017, §3.2): a
  population search over (track, extend) on the closed-form branches, infeasible points scored
  with a constant penalty, an initial population spread over the track range with extend in the
  middle of its feasible interval, then a pattern search (:func:`pattern_search`) as its hybrid
  polish. scipy's ``differential_evolution`` stands in for MATLAB's ``ga``.
- :func:`dense_ik`: the dense brute-force traversal of (track, extend),
  :func:`camtraj.ik.traverse` over the full limits.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import differential_evolution, minimize
from scipy.spatial.transform import Rotation

from camtraj.errors import UnreachableError
from camtraj.ik import six_axis_solutions, traverse
from camtraj.robot import Robot

Array = NDArray[np.float64]

TRACK, EXTEND = 0, 3
#: The GA paper's fitness of an invalid (track, extend) individual (its nCRMAWF).
PAPER_PENALTY = 600000.0


@dataclass(frozen=True)
class BaselineResult:
    """What one baseline solve returns.

    Attributes:
        q: Joint vector (8,) [m, rad]; NaN when the method found no feasible point.
        cost: F of ``q`` against the previous joint vector (inf when none was found).
        evaluations: Objective evaluations: (track, extend) points for the closed-form methods
            (for the dense traversal, the grid size before clipping to the reach intervals),
            objective calls for SLSQP.
        converged: The method's own success flag (SLSQP's ``success``; for the others, whether
            any feasible point was found).
        message: The method's own status text.
    """

    q: Array
    cost: float
    evaluations: int
    converged: bool
    message: str


def pose_error(robot: Robot, q: Array, target: Array) -> tuple[float, float]:
    """Position error [m] and rotation error angle [rad] of the flange at ``q`` vs ``target``.

    Args:
        robot: The robot.
        q: Joint vector (8,) [m, rad].
        target: Flange pose (4, 4) [m].
    """
    if not np.all(np.isfinite(q)):
        return math.inf, math.inf
    T = robot.fk(q)
    pos = float(np.linalg.norm(T[:3, 3] - target[:3, 3]))
    R = target[:3, :3].T @ T[:3, :3]
    # atan2(|skew part|, cos) keeps small angles exact where acos(cos) would not
    c = (np.trace(R) - 1.0) / 2.0
    s = 0.5 * math.sqrt((R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2
                        + (R[1, 0] - R[0, 1]) ** 2)
    ang = math.atan2(s, c)
    return pos, float(ang)


# ---------------------------------------------------------------------------------------------
# Generic numerical: SLSQP over all eight axes
# ---------------------------------------------------------------------------------------------


def pose_residual(robot: Robot, q: Array, target: Array) -> Array:
    """Pose residual (6,): flange position minus target [m], then the rotation vector of
    ``R_target^T R(q)`` [rad]."""
    T = robot.fk(q)
    rotvec = Rotation.from_matrix(target[:3, :3].T @ T[:3, :3]).as_rotvec()
    return np.concatenate([T[:3, 3] - target[:3, 3], rotvec])


def slsqp_ik(
    robot: Robot,
    target: Array,
    previous: Array,
    *,
    eps: float = 1e-5,
    scale: float = 1e-3,
    maxiter: int = 500,
    ftol: float = 1e-12,
) -> BaselineResult:
    """Generic constrained optimisation: scipy SLSQP over the eight joint values.

    Minimises ``scale * sum(w_i * sqrt(d_i^2 + eps^2))`` (d = q - previous, a smooth stand-in
    for |d|, analytic gradient) subject to the six pose equalities of :func:`pose_residual`
    (finite-difference Jacobian, scipy's default) and the position limits, from ``previous``.

    Args:
        robot: The robot (weights, limits, FK).
        target: Flange pose (4, 4) [m].
        previous: Joint vector (8,) the move starts from; also the initial guess [m, rad].
        eps: Smoothing of |d| [m or rad].
        scale: Objective scale (keeps F, up to ~1e6, near the constraint residuals' size).
        maxiter: SLSQP iteration limit.
        ftol: SLSQP's objective tolerance.
    """
    w = robot.weights
    prev = np.asarray(previous, dtype=float)
    calls = 0

    def fun(q: Array) -> float:
        nonlocal calls
        calls += 1
        d = q - prev
        return float(scale * np.sum(w * np.sqrt(d * d + eps * eps)))

    def grad(q: Array) -> Array:
        d = q - prev
        g: Array = scale * w * d / np.sqrt(d * d + eps * eps)
        return g

    x0 = np.clip(prev, robot.lower, robot.upper)
    res = minimize(
        fun, x0, jac=grad, method="SLSQP",
        bounds=list(zip(robot.lower, robot.upper, strict=True)),
        constraints=[{"type": "eq", "fun": lambda q: pose_residual(robot, q, target)}],
        options={"maxiter": maxiter, "ftol": ftol},
    )
    q = np.clip(np.asarray(res.x, dtype=float), robot.lower, robot.upper)
    cost = float(np.abs(q - prev) @ w)
    return BaselineResult(q, cost, calls, bool(res.success), str(res.message))


def slsqp_path(
    robot: Robot, targets: Array, start: Array, *, tol: float = 1e-6
) -> tuple[Array, Array, int]:
    """Solve a shot frame by frame with :func:`slsqp_ik`, each frame seeded from the last.

    A frame whose result misses its pose by more than ``tol`` (m or rad) or violates a limit
    counts as failed; the next frame then starts from the last good solution.

    Args:
        robot: The robot.
        targets: Flange poses (n, 4, 4) [m].
        start: Joint vector (8,) before the first frame [m, rad].
        tol: Pose tolerance for success [m, rad].

    Returns:
        The joint path (n, 8), each frame's F against the frame before (n,), and the number of
        failed frames.
    """
    n = targets.shape[0]
    q = np.empty((n, 8))
    cost = np.empty(n)
    failed = 0
    prev = np.asarray(start, dtype=float)
    for i in range(n):
        res = slsqp_ik(robot, targets[i], prev)
        q[i], cost[i] = res.q, res.cost
        if reaches(robot, res.q, targets[i], tol):
            prev = res.q
        else:
            failed += 1
    return q, cost, failed


def reaches(robot: Robot, q: Array, target: Array, tol: float = 1e-6) -> bool:
    """Whether ``q`` is inside the limits and puts the flange on ``target`` within ``tol``
    (metres for position, radians for rotation)."""
    pos, ang = pose_error(robot, q, target)
    return bool(pos <= tol and ang <= tol and robot.within_limits(q))


# ---------------------------------------------------------------------------------------------
# GM method rebuilt: population search over (track, extend) + pattern search
# ---------------------------------------------------------------------------------------------


def closed_form_objective(
    robot: Robot, target: Array, previous: Array, penalty: float
) -> tuple[Callable[[Array, Array], tuple[Array, Array]], list[int]]:
    """F over (track, extend) points: the cheapest feasible closed-form branch at each point.

    Args:
        robot: The robot.
        target: Flange pose (4, 4) [m].
        previous: Joint vector (8,) [m, rad].
        penalty: The value of a point where no branch is feasible.

    Returns:
        A function ``(r1 (N,), r4 (N,)) -> (F (N,), q (N, 8))`` and a one-item list counting
        the points it has evaluated.
    """
    w = robot.weights
    prev = np.asarray(previous, dtype=float)
    count = [0]

    def f(r1: Array, r4: Array) -> tuple[Array, Array]:
        q, ok = six_axis_solutions(robot.dh, target, r1, r4, prev, robot.lower, robot.upper)
        cost = np.where(ok, np.abs(q - prev) @ w, np.inf)
        k = np.argmin(cost, axis=1)
        rows = np.arange(r1.shape[0])
        best = cost[rows, k]
        count[0] += r1.shape[0]
        return np.where(np.isfinite(best), best, penalty), q[rows, k]

    return f, count


def paper_initial_population(
    robot: Robot, target: Array, previous: Array, n: int = 20, n_scan: int = 64
) -> Array:
    """The GA paper's §3.2 initial population, shape (n, 2): (track, extend) individuals.

    Track values are spread evenly over the track's range; each takes the middle of the extend
    values (of ``n_scan`` scanned) at which some branch is feasible, or mid-range if none is.
    """
    lo = np.array([robot.lower[TRACK], robot.lower[EXTEND]])
    hi = np.array([robot.upper[TRACK], robot.upper[EXTEND]])
    r1 = np.linspace(lo[0], hi[0], n)
    r4_scan = np.linspace(lo[1], hi[1], n_scan)
    f, _ = closed_form_objective(robot, target, previous, math.inf)
    cost, _ = f(np.repeat(r1, n_scan), np.tile(r4_scan, n))
    feasible = np.isfinite(cost.reshape(n, n_scan))
    r4 = np.full(n, 0.5 * (lo[1] + hi[1]))
    for i in range(n):
        if feasible[i].any():
            vals = r4_scan[feasible[i]]
            r4[i] = 0.5 * (vals.min() + vals.max())
    return np.stack([r1, r4], axis=1)


def pattern_search(
    f: Callable[[Array], Array],
    x0: Array,
    lower: Array,
    upper: Array,
    *,
    mesh: float = 1e-3,
    tol: float = 1e-9,
    max_evals: int = 4000,
) -> tuple[Array, float, int]:
    """Generalised pattern search with the 2N compass poll, as MATLAB's ``patternsearch``.

    Each iteration polls ``x +- mesh * e_i`` (clipped to the bounds, all 2N points in one call
    of ``f``); the best improving point is taken and the mesh doubles, else the mesh halves.
    Stops when the mesh is below ``tol`` or after ``max_evals`` points. The defaults are
    MATLAB's (initial mesh 1, mesh tolerance 1e-6, 2000 evaluations per variable) in the
    papers' millimetres, converted to metres.

    Args:
        f: Objective on points (M, N) -> (M,).
        x0: Start point (N,).
        lower, upper: Bounds (N,).
        mesh: Initial mesh size, in the variables' units.
        tol: Final mesh size, in the variables' units.
        max_evals: Evaluation budget.

    Returns:
        The best point (N,), its value, and the number of points evaluated.
    """
    x = np.clip(np.asarray(x0, dtype=float), lower, upper)
    fx = float(f(x[None, :])[0])
    n = x.size
    basis = np.concatenate([np.eye(n), -np.eye(n)])
    evals = 1
    while mesh > tol and evals < max_evals:
        pts = np.clip(x + basis * mesh, lower, upper)
        fp = f(pts)
        evals += pts.shape[0]
        k = int(np.argmin(fp))
        if fp[k] < fx:
            x, fx = pts[k], float(fp[k])
            mesh *= 2.0
        else:
            mesh *= 0.5
    return x, fx, evals


def gm_ik(
    robot: Robot,
    target: Array,
    previous: Array,
    *,
    seed: int = 0,
    maxiter: int = 200,
    penalty: float | None = None,
) -> BaselineResult:
    """The GA paper's improved method: population search over (track, extend), then pattern
    search.

    scipy ``differential_evolution`` (vectorised: one closed-form call per generation) starts
    from :func:`paper_initial_population` and runs without its own gradient polish; the best
    individual is polished by :func:`pattern_search` down to a 1e-9 m mesh.

    Args:
        robot: The robot.
        target: Flange pose (4, 4) [m].
        previous: Joint vector (8,) [m, rad].
        seed: Seed of the population search.
        maxiter: Generation limit of the population search.
        penalty: Fitness of an infeasible individual. Default: the larger of the paper's 600000
            and an upper bound of any feasible F within the limits (on a 16 m track a feasible
            F can exceed the paper's value, which would make the penalty attractive).
    """
    prev = np.asarray(previous, dtype=float)
    if penalty is None:
        span = np.maximum(np.abs(robot.upper - prev), np.abs(prev - robot.lower))
        penalty = max(PAPER_PENALTY, float(span @ robot.weights) + 1.0)
    f, count = closed_form_objective(robot, target, prev, penalty)
    lo = np.array([robot.lower[TRACK], robot.lower[EXTEND]])
    hi = np.array([robot.upper[TRACK], robot.upper[EXTEND]])

    def fitness(x: Array) -> Array:  # x: (2, S) as scipy's vectorised mode passes it
        return f(x[0], x[1])[0]

    init = paper_initial_population(robot, target, prev)
    de = differential_evolution(
        fitness, list(zip(lo, hi, strict=True)), init=init, seed=seed, maxiter=maxiter,
        polish=False, vectorized=True, updating="deferred",
    )
    x, fx, _ = pattern_search(lambda p: f(p[:, 0], p[:, 1])[0], np.asarray(de.x), lo, hi)
    if fx >= penalty:
        return BaselineResult(np.full(8, np.nan), math.inf, count[0], False,
                              "no feasible (track, extend) found")
    cost, q = f(np.array([x[0]]), np.array([x[1]]))
    return BaselineResult(q[0], float(cost[0]), count[0], True, str(de.message))


# ---------------------------------------------------------------------------------------------
# Dense traversal
# ---------------------------------------------------------------------------------------------


def dense_ik(
    robot: Robot, target: Array, previous: Array, *, n1: int = 401, n4: int = 101,
    refine: int = 2,
) -> BaselineResult:
    """Brute force: :func:`camtraj.ik.traverse` over the full track and extend limits.

    Args:
        robot: The robot.
        target: Flange pose (4, 4) [m].
        previous: Joint vector (8,) [m, rad].
        n1, n4: Grid points along track and extend.
        refine: Zoom passes (each a 41 x 41 grid ten times finer around the best point).
    """
    try:
        sol = traverse(robot, target, previous, n1=n1, n4=n4, refine=refine)
    except UnreachableError as exc:
        return BaselineResult(np.full(8, np.nan), math.inf, 0, False, str(exc))
    evaluations = n1 * (n4 + 3) + refine * 41 * 44
    return BaselineResult(sol.q, sol.cost, evaluations, True, "grid")
