"""A whole shot solved: the ``shot`` objective (default) or the papers' per-frame ``paper``."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from threadpoolctl import threadpool_limits

from camtraj.choices import OBJECTIVES
from camtraj.errors import UnreachableError, UnreachableFramesError
from camtraj.ik.closed_form import EXTEND, TRACK
from camtraj.ik.margins import PathMargins, path_margins
from camtraj.ik.refine import REFINE_STAGES, Refinement
from camtraj.ik.shot import (
    Candidates,
    camera_holds,
    camera_rests,
    candidates,
    choose_ranked,
    measures,
)
from camtraj.ik.shot_cost import ShotCost
from camtraj.ik.sm import check_joints, solve_ik
from camtraj.ik.spline_ops import hold_runs
from camtraj.robot import Robot
from camtraj.timing import Limits, feasible_speed
from camtraj.timing.path import FREE

Array = NDArray[np.float64]

#: Starts whose take after the first refinement stage is within this share of the fastest
#: one's all run the remaining stages.
CLOSE_STARTS = 0.01
#: An arm configuration whose start ends the refinement's first stage below this share of the
#: fastest start's speed gets a second start from the programme on twice the track values:
#: on the coarse grid its path can be forced into steps between far grid points that no
#: refinement takes out (a 15 s eased orbit: that arm's start 0.019x real time after its first
#: stage, the take 1.64x; from the finer grid 1.78x and 2.51x; 10x the effort 2.50x). On the
#: shot set it runs for a few shots and changes none of their speeds.
SLOW_ARM = 0.1
#: The margin weight of the programme's second ranking of starts, as a share of the robot
#: file's ``margin_weight``. The programme weighs margin intrusions on every frame, the
#: refinement only at the worst frame and against the peak use, and it leaves most of a
#: start's intrusion behind, so a basin next to a limit can be the fast one; and the
#: programme's run-out cost weighs only the margins of the stop, while the take slows down
#: until its stop fits. The second ranking weighs both as the take does (light margins, the
#: ends' room need as a use: :attr:`ShotCost.edge_room`); its cheapest path on each grid is
#: refined too where it is not alike the first ranking's starts (a 0.8 s crane down ending
#: near the elbow's limit: 1.95x -> 2.58x real time; a truck ending past the track's end,
#: whose arm takes over early: 0.79x -> 0.98x). It is added beside the first ranking, not
#: instead of it: as the only ranking (margins a tenth or a fifth as heavy, the ends' room
#: as a use) it put shots that are fine today in slower basins (the car mount -1.4%, the
#: 2 min walk-along -2%, a new user's vertigo pull-out -3.9%).
LIGHT_MARGIN = 0.1

#: Answers within this share of the fastest run at the same speed as far as the refinement
#: can tell (its later stages stop at a relative change of a thousandth): the first of them
#: in the starts' order wins, not the fastest by a hair. Round-off that differs between
#: machines (BLAS kernels, SIMD maths) moves each answer by about that much, and picking by
#: it chose another basin on another CPU (the whip sample: two starts 3e-4 apart swapped
#: places under AVX2 kernels, and axes the pan does not limit moved by up to 6% of a limit).
SAME_SPEED = 1e-3
#: With a start pose given (``--start-from``: the take begins there, its run-up is part of
#: it), the answer whose first frame the robot reaches soonest from the start, among those
#: within this share of the fastest. The robot set up on a stop-hard shot's own first frame
#: got another solution 1.7% faster whose run-up drove the track 6.15 m and the pan 149 deg
#: for 4.86 s next to the set (a new user's trial).
NEAR_START = 0.05


@dataclass(frozen=True)
class MoveToStart:
    """The move from the start (home or ``--start-from``) to a pose, at rest at both ends
    (``convert``: to where the take begins, the run-up's start).

    Attributes:
        start: Start joint vector (8,) [m, rad].
        travel: The pose minus start (8,) [m, rad]; the move's extent on each axis (a
            rest-to-rest move of one axis does not overshoot).
        duration: Time of the slowest axis's fastest rest-to-rest move within its velocity,
            acceleration and jerk limits [s] (all axes synchronised to it).
    """

    start: Array
    travel: Array
    duration: float


@dataclass(frozen=True)
class PathSolution:
    """A solved shot.

    Attributes:
        q: Joint path (n, 8) [m, rad].
        cost: F of each frame against the frame before (n,); the first against the start.
        within_step: (n,) False where a step from the previous frame exceeds an axis's
            velocity limit times the frame interval (always True without a frame interval).
        objective: ``"shot"`` or ``"paper"``.
        start: The joint vector the robot starts from (8,) [m, rad]: home or ``start``.
        margins: The smallest distances to limits and singularities over the shot.
        rest: How the path rests on its first / last frame (``still_ends`` asked: the
            camera's rest there; else free): whatever times it gives those ends zero
            velocity, and zero acceleration too where the camera settles (:meth:`rest_axes`).
        camera_rest: How the camera rests on its first / last frame
            (:func:`~camtraj.ik.shot.camera_rests`), whatever ``still_ends`` asked.
    """

    q: Array
    cost: Array
    within_step: NDArray[np.bool_]
    objective: str
    start: Array
    margins: PathMargins
    rest: tuple[int, int] = (FREE, FREE)
    camera_rest: tuple[int, int] = (FREE, FREE)

    def rest_axes(self, axes: int = 8) -> NDArray[np.int8] | None:
        """``time_shot``'s ``rest`` for this path and ``axes - 8`` lens axes after its
        joints (:func:`rest_mask`)."""
        return rest_mask(self.rest, axes)


def rest_mask(rest: tuple[int, int], axes: int = 8) -> NDArray[np.int8] | None:
    """``time_shot``'s ``rest`` (2, axes) for a path resting on its first / last frame as
    ``rest`` says (:data:`~camtraj.timing.path.FREE`, ``AT_REST``, ``SETTLED``), with
    ``axes - 8`` lens axes after its joints: the joints rest there, the lens motors are free
    (a focus pull may start while the camera stands still); None where nothing rests."""
    if not any(rest):
        return None
    out = np.zeros((2, axes), dtype=np.int8)
    out[:, :8] = np.array(rest)[:, None]
    return out


def solve_path(
    robot: Robot,
    targets: ArrayLike,
    start: ArrayLike | None = None,
    *,
    objective: str | None = None,
    frame_interval: float | None = None,
    frame_numbers: ArrayLike | None = None,
    progress: Callable[[int], None] | None = None,
    still_ends: bool = False,
) -> Array:
    """The joint path (n, 8) of :func:`solve_path_report`."""
    return solve_path_report(robot, targets, start, objective=objective,
                             frame_interval=frame_interval, frame_numbers=frame_numbers,
                             progress=progress, still_ends=still_ends).q


def solve_path_report(
    robot: Robot,
    targets: ArrayLike,
    start: ArrayLike | None = None,
    *,
    objective: str | None = None,
    frame_interval: float | None = None,
    frame_numbers: ArrayLike | None = None,
    progress: Callable[[int], None] | None = None,
    still_ends: bool = False,
) -> PathSolution:
    """Solve a whole shot.

    Args:
        robot: The robot.
        targets: Flange poses in the base frame, shape (n, 4, 4) [m].
        start: Joint vector (8,) the robot starts from (before its run-up); default home.
        objective: ``"shot"`` (whole-shot choice, :mod:`camtraj.ik.shot`) or ``"paper"`` (the
            papers' per-frame optimum, each frame from the previous one, the first from
            ``start``); default the robot file's ``[ik] objective``.
        frame_interval: Seconds between frames (1 / fps); the shot objective needs it (default
            1/24 s); with it, ``within_step`` flags steps beyond the velocity limits.
        frame_numbers: Film frame numbers (n,) used in error messages; default 0..n-1.
        progress: Called with the number of frames just finished (for a progress bar).
        still_ends: Where the camera is at rest on the first or last frame (an eased start
            or stop, :func:`~camtraj.ik.shot.camera_rests`), the robot stands still there
            too: the path is timed with zero velocity on that frame, and zero acceleration
            where the camera settles into it (:attr:`PathSolution.rest`), and the shot
            objective solves for that timing. Default: free ends, where the
            redundant axes may already move on a frame the camera holds still (the faster
            take; its run-up moves the camera before the first frame).

    Raises:
        ValueError: A malformed argument (named in the message).
        UnreachableFramesError: One or more frames have no solution; lists every such frame
            and by how much it misses.
    """
    Ts = _check_targets(targets)
    n = Ts.shape[0]
    frames = np.arange(n) if frame_numbers is None else np.asarray(frame_numbers)
    if frames.shape != (n,):
        msg = f"frame_numbers must have one number per target ({n}), got shape {frames.shape}"
        raise ValueError(msg)
    first = robot.home.copy() if start is None else check_joints(start, "start")
    obj = objective or robot.ik.objective
    if obj not in OBJECTIVES:
        msg = f"objective must be one of {', '.join(OBJECTIVES)}, got {obj!r}"
        raise ValueError(msg)
    if frame_interval is not None and not (
            isinstance(frame_interval, int | float) and math.isfinite(frame_interval)
            and 0.0 < frame_interval <= 60.0):
        msg = f"frame_interval must be a positive number of seconds (at most 60), got " \
              f"{frame_interval!r}"
        raise ValueError(msg)
    dt = frame_interval or 1.0 / 24.0
    camera_rest = camera_rests(Ts, dt)
    rest = camera_rest if still_ends else (FREE, FREE)
    if obj == "shot":
        # scipy's own OpenBLAS (the refinement's banded solve) must be loaded before the limit
        # is set, or the limit does not reach it: two spinning BLAS threads per tiny solve
        # cost 100x the wall time on a shared machine
        import scipy.linalg  # noqa: F401

        with threadpool_limits(limits=1, user_api="blas"):
            q = solve_shot(robot, Ts, first, dt, frames, progress, rest,
                           start_given=start is not None)
    else:
        q = _solve_sequence(robot, Ts, first, frames, progress)
    prev = np.vstack([first, q[:-1]])
    cost = np.abs(q - prev) @ robot.weights
    steps = np.ones(n, dtype=bool)
    if frame_interval is not None and n > 1:
        bound = robot.max_velocity * frame_interval * (1.0 + 1e-9) + 1e-12
        steps[1:] = np.all(np.abs(np.diff(q, axis=0)) <= bound, axis=1)
    return PathSolution(q, cost, steps, obj, first, path_margins(robot, q), rest, camera_rest)


def _check_targets(targets: ArrayLike) -> Array:
    Ts = np.asarray(targets, dtype=float)
    if Ts.ndim != 3 or Ts.shape[1:] != (4, 4) or Ts.shape[0] < 1:
        msg = f"targets must have shape (n, 4, 4) with n >= 1, got {Ts.shape}"
        raise ValueError(msg)
    bad = np.flatnonzero(~np.isfinite(Ts).all(axis=(1, 2)))
    if bad.size:
        msg = f"targets must be finite poses: target {int(bad[0])} contains NaN or infinity"
        raise ValueError(msg)
    R = Ts[:, :3, :3]
    gram = np.einsum("nji,njk->nik", R, R)
    # orthonormal (as np.allclose(R.T @ R, I, atol=1e-6)) and not mirrored (det > 0)
    bad = np.flatnonzero((np.abs(gram - np.eye(3)) > 1e-6 + 1e-5 * np.eye(3)).any(axis=(1, 2))
                         | (np.linalg.det(R) < 0))
    if bad.size:
        msg = (f"targets[{int(bad[0])}]: its rotation is not a proper rotation matrix (scaled, "
               f"sheared or mirrored)")
        raise ValueError(msg)
    return Ts


def _solve_sequence(robot: Robot, Ts: Array, first: Array, frames: NDArray[np.int_],
                    progress: Callable[[int], None] | None) -> Array:
    """The paper objective: frame after frame, each from the previous frame's solution."""
    n = Ts.shape[0]
    q = np.full((n, 8), np.nan)
    errors: list[UnreachableError] = []
    prev = first
    for i in range(n):
        try:
            sol = solve_ik(robot, Ts[i], prev)
        except UnreachableError as exc:
            errors.append(exc.at_frame(int(frames[i])))
        else:
            q[i] = prev = sol.q
        if progress is not None:
            progress(1)
    if errors:
        raise UnreachableFramesError(errors)
    return q


def solve_shot(robot: Robot, targets: Array, start: Array, dt: float,
               frames: NDArray[np.int_],
               progress: Callable[[int], None] | None = None,
               rest: tuple[int, int] = (FREE, FREE), start_given: bool = False) -> Array:
    """The shot objective's joint path (n, 8) (see :mod:`camtraj.ik.shot`), timed resting on
    the first / last frame as ``rest`` says (:meth:`~camtraj.timing.path.FramePath.fit`).

    The dynamic programme chooses by frame-to-frame differences, a proxy for the take's
    speed, so the refinement starts from several of its answers: on the robot file's
    candidate grid, the cheapest path of each arm configuration (rotate towards or away
    from the target, elbow up or down: the proxy often ranks them wrongly, most of all when
    the shot is faster than the robot), and on the grid with half the track values its
    cheapest (a different set of points, so another basin where the proxy misleads); and on
    each grid the cheapest path of a second ranking closer to the take's (margins
    :data:`LIGHT_MARGIN` times as heavy, the ends' room as a use), where that is another
    path on most frames. Each runs the continuation's first stage, which settles the
    basin (an arm whose start ends it far behind the fastest, :data:`SLOW_ARM`, starts again
    from the programme on twice the track values); the fastest take, as the timing stage
    measures it, runs the remaining stages (with every start within :data:`CLOSE_STARTS` of
    it, and the starts that would have gone on without the other arms' and the second
    ranking's starts: the answer is never slower than theirs by more than :data:`SAME_SPEED`),
    and the fastest answer wins (the first in that order of those within :data:`SAME_SPEED`
    of it; with ``start_given``, a start pose the take begins at, the one of those within
    :data:`NEAR_START` of it whose first frame the robot reaches soonest from ``start``).
    ``progress`` is called after each step (a start's programme, a refinement stage) with
    that step's share of the n frames (the shares add up to n).
    """
    s = robot.ik
    n = targets.shape[0]
    held = camera_holds(targets)  # where the camera holds, the robot holds (every stage)
    cost = replace(ShotCost.for_robot(robot, dt), holds=hold_runs(held), rests=rest)
    limits = Limits.from_robot(robot)
    times = np.arange(n) * dt
    rest_axes = rest_mask(rest)

    def take_speed(q: Array) -> float:  # to compare answers: a thousandth is plenty
        return (feasible_speed(q, times, limits, rest=rest_axes, precision=1e-3) if n > 1
                else math.inf)

    grids = dict.fromkeys([(s.track_samples, s.extend_samples),
                           (max(1, s.track_samples // 2), s.extend_samples)])
    total = 2 * len(grids) + REFINE_STAGES - 1
    done = [0]

    def step() -> None:
        if progress is not None:
            progress(round(n * (done[0] + 1) / total) - round(n * done[0] / total))
        done[0] += 1

    def first_stage(st: _Start) -> Refinement:
        branch, x0, y0, lo1, hi1 = st
        run = Refinement(robot, cost, targets, branch, x0, y0, lo1, hi1,
                         rounds=s.refine_rounds, tolerance=s.refine_tolerance,
                         take_speed=take_speed, held=held)
        run.stage()
        return run

    light_cost = replace(cost, margin=cost.margin * LIGHT_MARGIN, edge_room=True)
    runs: list[Refinement] = []
    firsts: list[Refinement] = []
    light: list[Refinement] = []  # the second ranking's starts
    for i, (n_track, n_extend) in enumerate(grids):
        heavy, lite = _programme(robot, (cost, light_cost), targets, start, frames, n_track,
                                 n_extend, held)
        starts = _one_per_arm(heavy) if i == 0 else heavy[:1]
        more = [st for st in lite[:1] if not any(_alike(st, o) for o in starts)]
        step()
        grid_runs = [first_stage(st) for st in starts]
        runs += grid_runs
        light += [first_stage(st) for st in more]
        firsts.append(grid_runs[0])
        if i == 0:
            per_arm = grid_runs  # the first grid's: one per arm configuration
        step()
    # an arm whose first stage ended far behind the fastest start may only be held back by
    # the grid: its programme again on twice the track values
    top = max(r.best[0] for r in runs + light)
    behind = {_arm(r.branch) for r in per_arm if r.best[0] < SLOW_ARM * top}
    if behind:
        (dense,) = _programme(robot, (cost,), targets, start, frames, 2 * s.track_samples,
                              s.extend_samples, held)
        runs += [first_stage(st) for st in _one_per_arm(dense) if _arm(st[0]) in behind]
    # the starts within a hundredth of the fastest all go on (a near tie after one stage
    # says little about which basin is better), and so do the grids' own choices that would
    # have gone on without the other arms' starts: the answer is never slower than theirs
    # (but for :data:`SAME_SPEED`)
    top = max(r.best[0] for r in runs)
    going = [r for r in runs if r.best[0] >= (1.0 - CLOSE_STARTS) * top]
    top_first = max(r.best[0] for r in firsts)
    going += [r for r in firsts
              if r not in going and r.best[0] >= (1.0 - CLOSE_STARTS) * top_first]
    # the second ranking's starts within a hundredth of the fastest of all go on too
    top = max([top] + [r.best[0] for r in light])
    going += [r for r in light if r.best[0] >= (1.0 - CLOSE_STARTS) * top]
    if start_given:  # and, from a start pose, the nearest of the fast ones (NEAR_START)
        nearest = min((r for r in runs + light if r.best[0] >= (1.0 - NEAR_START) * top),
                      key=lambda r: move_to_start(robot, start, r.best[2][0, :8]).duration)
        going += [nearest] if nearest not in going else []
    for _ in range(REFINE_STAGES - 1):
        for r in going:
            r.stage()
        step()
    answers = [r.result() for r in going]
    top = max(a.speed for a in answers)
    if start_given:  # the run-up from the start is the take's: the nearest of the fast ones
        fast = [a for a in answers if a.speed >= (1.0 - NEAR_START) * top]
        best = min(fast, key=lambda a: move_to_start(robot, start, a.y[0, :8]).duration)
        return np.asarray(best.y[:, :8])
    return next(a for a in answers if a.speed >= (1.0 - SAME_SPEED) * top).y[:, :8]


_Start = tuple[NDArray[np.intp], Array, Array, Array, Array]
"""A refinement's start: branch per frame, track/extend (n, 2), measures (n, 10) and the
track interval each frame stays in (lo, hi) (n,) each."""


def _programme(robot: Robot, costs: tuple[ShotCost, ...], targets: Array, start: Array,
               frames: NDArray[np.int_], n_track: int, n_extend: int,
               held: NDArray[np.bool_]) -> list[list[_Start]]:
    """The dynamic programme's answers on a candidate grid for each of ``costs`` (one per
    branch label that reaches every frame, cheapest first), as refinements' starts: branch
    per frame, track/extend (n, 2), measures (n, 10) and the track interval each frame stays
    in (its candidates are freed on return: they are the solver's largest arrays).
    ``held``: the frame pairs where the camera holds still."""
    n = targets.shape[0]
    cand = candidates(robot, targets, n_track, n_extend)
    cand = _rescue_empty_frames(robot, targets, cand, frames)
    rows = np.arange(n)
    res = []
    for choices in choose_ranked(costs, cand, start, held):
        if not choices:  # pragma: no cover - every frame has a feasible candidate by now
            msg = "internal error: no candidate path through the shot"
            raise RuntimeError(msg)
        out = []
        for choice in choices:
            x0 = np.stack([cand.r1[rows, choice.point], cand.r4[rows, choice.point]], axis=1)
            j = cand.interval[rows, choice.point]
            lo1, hi1 = cand.track_lo[rows, j], cand.track_hi[rows, j]
            out.append((choice.branch, x0, choice.y, np.minimum(lo1, x0[:, 0]),
                        np.maximum(hi1, x0[:, 0])))
        res.append(out)
    return res


def _alike(a: _Start, b: _Start) -> bool:
    """Whether two starts take the same candidate (branch, track and extend) on at least
    half of the frames: refined, they settle in the same basin (a 2 min walk-along's second
    ranking differs on a fifth of its frames, by at most 9 cm)."""
    same = (a[0] == b[0]) & np.all(a[1] == b[1], axis=1)
    return bool(2 * np.count_nonzero(same) >= same.size)


def _arm(branch: NDArray[np.intp]) -> int:
    """A start's arm configuration: its first frame's branch bits but the wrist flip (branch
    bits: rotate back 4, elbow 2, wrist flip 1)."""
    return int(branch[0]) >> 1


def _one_per_arm(starts: list[_Start]) -> list[_Start]:
    """The cheapest of the programme's answers (cheapest first) for each arm configuration:
    rotate towards or away from the target, elbow up or down. The two wrist flips of one arm
    move the wrist axes by the same amounts (pan and roll half a turn apart, tilt mirrored):
    the programme's margins choose between them."""
    seen: set[int] = set()
    out = []
    for st in starts:
        arm = _arm(st[0])
        if arm not in seen:
            seen.add(arm)
            out.append(st)
    return out


def _rescue_empty_frames(robot: Robot, targets: Array, cand: Candidates,
                         frames: NDArray[np.int_]) -> Candidates:
    """Frames whose grid missed a thin feasible set get the SM optimum from home as their
    first candidate; frames with no solution at all are reported together."""
    empty = np.flatnonzero(~cand.ok.any(axis=(1, 2)))
    if empty.size == 0:
        return cand
    errors: list[UnreachableError] = []
    r1, r4, y, ok = cand.r1.copy(), cand.r4.copy(), cand.y.copy(), cand.ok.copy()
    interval = cand.interval.copy()
    for k in empty:
        try:
            sol = solve_ik(robot, targets[k], robot.home)
        except UnreachableError as exc:
            errors.append(exc.at_frame(int(frames[k])))
            continue
        r1[k, 0], r4[k, 0] = sol.q[TRACK], sol.q[EXTEND]
        yk, okk = measures(robot, targets[k:k + 1], r1[k, :1], r4[k, :1], robot.home)
        y[k, 0], ok[k, 0] = yk[0], okk[0]
        r = sol.q[TRACK]
        inside = (cand.track_lo[k] <= r + 1e-9) & (r - 1e-9 <= cand.track_hi[k])
        interval[k, 0] = int(np.argmax(inside))
    if errors:
        raise UnreachableFramesError(errors)
    return Candidates(r1, r4, interval, y, ok, cand.track_lo, cand.track_hi)


def move_to_start(robot: Robot, start: Array, q0: Array) -> MoveToStart:
    """The fastest synchronised rest-to-rest move from ``start`` to the pose ``q0`` (per-axis
    time-optimal jerk-limited profiles; the slowest axis sets the duration)."""
    travel = q0 - start
    durations = [
        _rest_to_rest(abs(float(d)), float(v), float(a), float(j))
        for d, v, a, j in zip(travel, robot.max_velocity, robot.max_acceleration,
                              robot.max_jerk, strict=True)
    ]
    return MoveToStart(start.copy(), travel, float(max(durations)))


def _rest_to_rest(d: float, v: float, a: float, j: float) -> float:
    """Shortest time [s] of a rest-to-rest move over distance d within v, a, j (7 segments)."""
    if d <= 0.0:
        return 0.0
    reach_a = v * j >= a * a  # the acceleration limit is reached before the velocity limit
    to_v = v / a + a / j if reach_a else 2.0 * math.sqrt(v / j)  # time to accelerate to v
    if d >= v * to_v:  # cruises at v
        return d / v + to_v
    if d >= 2.0 * a ** 3 / (j * j):  # peak velocity below v, acceleration reaches a
        vp = (-a * a / j + math.sqrt(a ** 4 / (j * j) + 4.0 * a * d)) / 2.0
        return 2.0 * (vp / a + a / j)
    return 4.0 * math.cbrt(d / (2.0 * j))


__all__ = ["OBJECTIVES", "MoveToStart", "PathSolution", "solve_path", "solve_path_report",
           "solve_shot"]
