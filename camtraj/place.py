"""``camtraj place``: where to lay the track so the robot can do the shot.

The search is over the robot base's x, y and yaw about up on the floor (the rail lies on the
set file's floor, the base :data:`~camtraj.urdf.RAIL_HEIGHT` above it). Placements rank by:
every frame reachable, no collision with the set's obstacles, feasible with the timing asked
(``--timing``: at the shot's own unless scale or optimal), then the largest maximum feasible
speed (to 1 %), then the largest margins
(position limits, wrist singularity, full stretch).

1. Cheap tests first, on every candidate of a coarse grid at once: the camera path against the
   robot's reach envelope (a solid of revolution about the rotate axis, swept along the track),
   the rail's footprint against the floor region and the keep-out polygons. A shot that fails
   them everywhere (path longer than track plus reach, heights beyond the lift's) is refused
   with the reason before any solve.
2. The most promising, spread-out survivors are solved on a subsample of the frames and timed.
3. A pattern search around the best few at half the grid step (polled again while a
   neighbour wins: :data:`REFINE`), then a quarter and an eighth of it.
4. The best few are solved and timed on every frame, and collision-checked on the take.

Candidates are evaluated in worker processes; the solver is called through :func:`_solve` only.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from camtraj.analysis import take_axes
from camtraj.errors import (
    CamtrajError,
    InfeasibleError,
    PlacementError,
    UnreachableFramesError,
)
from camtraj.ik import PathSolution, camera_holds, solve_path_report
from camtraj.inputs import one_line
from camtraj.options import timing_edges
from camtraj.reach import check_can_reach, floor_ok, reach_envelope, reach_slack
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.set_file import SetFile, floor_polygon, with_clearance_text, yaw_pose
from camtraj.shown import MAX_SHOWN_SPEED, speed_percent
from camtraj.timing import TimingLimitError, time_shot

if TYPE_CHECKING:
    from camtraj.options import ConvertOptions
    from camtraj.usd_shot import Shot

Array = NDArray[np.float64]

#: Frames solved per candidate in the coarse stages. At 12 a slider's 101 frames were solved
#: 9 apart, and a placement ranked first there ran 27% slower on every frame than one ranked
#: below it (the pattern search walked the subsample's errors); at 24 on six shots (samples
#: and trial 21's) every best placement is as fast or faster (1.00-1.51x) for 1.06x the time.
COARSE_FRAMES = 24
COARSE_KEEP = 24  # at most this many survivors of the cheap tests solved on the subsample
#: The pattern search's levels: (best placements refined, fraction of the grid step, most
#: polls). The first level polls again where a neighbour won, so the best walks on beyond a
#: grid step: with one poll per level it moved at most 7/8 of a step from the coarse grid's
#: best, and place run again from its own answer moved on (trial 21: a dolly 408% -> 466%,
#: now 452% -> 456%; from the stage origin 300% where 470% was a grid step away).
REFINE = ((2, 0.5, 4), (2, 0.25, 1), (1, 0.125, 1))
FULL_KEEP = 3  # placements solved on every frame (at least; --top more)
SCENE_FULL_KEEP = 2  # a scene's placements raced on every frame (the best solved for all)
YAW_STEP_DEG = 15.0


def _solve(robot: Robot, flange2base: Array, problem: Problem, frame_interval: float,
           frame_numbers: NDArray[np.int64]) -> PathSolution:
    """The whole-shot solver, in one place (re-point it here when the solver changes)."""
    return solve_path_report(robot, flange2base, problem.start, objective=problem.objective,
                             frame_interval=frame_interval, frame_numbers=frame_numbers,
                             still_ends=problem.edges == "still")


# ---------------------------------------------------------------------------------------------
# The problem and one candidate's evaluation (runs in the workers)
# ---------------------------------------------------------------------------------------------


def base_height(floor_z: float) -> float:
    """The robot base's height [m] with its rail lying on a floor at ``floor_z`` [m]: on the
    carriage, :data:`~camtraj.urdf.RAIL_HEIGHT` up."""
    from camtraj.urdf import RAIL_HEIGHT

    return floor_z + RAIL_HEIGHT


@dataclass(frozen=True)
class Problem:
    """Everything a worker needs, as plain picklable data (converted world: metres, Z-up)."""

    robot: Robot
    cam2world: Array  # (n, 4, 4)
    times: Array
    frames: NDArray[np.int64]
    time_codes: Array
    floor_z: float  # the set file's floor; the base stands RAIL_HEIGHT above it, on the rail
    rate: float
    objective: str | None = None
    start: Array | None = None
    obstacles: tuple[Any, ...] = ()
    clearance: float = 0.0
    name: str = ""  # the shot, for messages
    timing: str = "shot"  # "shot": must run at its own timing; "scale", "optimal": may slow down
    lens_q: Array | None = None  # (n, axes): the robot's lens motors per frame, timed with it
    edges: str = "still"  # convert's --edges: the run-up and run-out it will time the shot with

    @property
    def base_z(self) -> float:
        """The base's height [m]: on the carriage, on the rail lying on the floor."""
        return base_height(self.floor_z)


@dataclass(frozen=True)
class Result:
    """One evaluated placement. ``full`` says whether every frame was solved."""

    x: float
    y: float
    yaw_deg: float
    full: bool
    reachable: float  # fraction of the solved frames reached
    collision_free: bool
    feasible: bool  # with the timing asked (at the shot's own, unless scale or optimal)
    max_speed: float
    binding: str  # what sets the maximum feasible speed (TimingReport.set_by)
    margins: dict[str, float] = field(default_factory=dict)
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.reachable == 1.0 and self.collision_free and self.feasible

    def key(self) -> tuple[float, ...]:
        """Larger is better."""
        m = self.margins
        margin = min(1.0 - m.get("limits_use", 1.0), m.get("wrist_deg", 0.0) / 90.0,
                     m.get("stretch_deg", 0.0) / 180.0)
        # speeds above what is shown tie (to 1%: the tables' rounding)
        speed = (math.floor(100.0 * min(self.max_speed, MAX_SHOWN_SPEED)) if self.max_speed > 0
                 else 0)
        return (self.reachable, float(self.collision_free), float(self.feasible), speed, margin)

    def base2world(self, z: float) -> Array:
        return yaw_pose(self.x, self.y, z, self.yaw_deg)

    def to_json(self) -> dict[str, Any]:
        return {"x": self.x, "y": self.y, "yaw_deg": self.yaw_deg, "ok": self.ok,
                "full": self.full, "reachable": self.reachable,
                "collision_free": self.collision_free, "feasible": self.feasible,
                "max_speed": self.max_speed if math.isfinite(self.max_speed) else None,
                "binding": self.binding, "margins": self.margins, "reason": self.reason}


def margins(robot: Robot, q: Array) -> dict[str, float]:
    """Margins over the path: ``limits_use``, the peak position-limit use like every other
    use (0 mid-range, 1 touching a limit: fraction of half the range), and the smallest wrist
    (tilt from ±90° [deg]) and stretch (elbow's interior angle from 180° [deg]) margins."""
    mid, half = 0.5 * (robot.upper + robot.lower), 0.5 * (robot.upper - robot.lower)
    limits_use = float(np.max(np.abs(q - mid) / half))
    tilt = q[:, JOINT_NAMES.index("tilt")]
    wrist = float(np.min(np.abs(np.abs(np.degrees(tilt)) - 90.0)))
    dh = robot.dh
    frames = robot.link_frames(q)
    wc = frames[:, 6, :3, 3]
    shoulder = np.stack([dh.r10 + q[:, 0], np.zeros(len(q)), np.full(len(q), dh.r2)], axis=1)
    ws = np.linalg.norm(wc - shoulder, axis=1)
    dse = np.hypot(dh.r40 + q[:, JOINT_NAMES.index("extend")], dh.l3)
    cos_e = np.clip((dse**2 + dh.r6**2 - ws**2) / (2 * dh.r6 * dse), -1.0, 1.0)
    stretch = float(np.min(180.0 - np.degrees(np.arccos(cos_e))))
    return {"limits_use": limits_use, "wrist_deg": wrist, "stretch_deg": stretch}


_WORKER: dict[str, Any] = {}


def _init_worker(problems: tuple[Problem, ...]) -> None:
    _WORKER.clear()
    _WORKER["problems"] = problems
    _WORKER["models"] = {}


def _init_pool_worker(problems: tuple[Problem, ...]) -> None:
    """A worker process's start: SIGTERM ends it at once (it holds no output). It imports
    the camtraj command as its parent's main module, which installs camtraj's handlers: a
    SIGTERM to the whole process group (a farm cancelling the task) was caught as an
    interruption of the task at hand, handed to the executor, and the worker waited on for
    the next one, orphaned with the fork server's resource tracker (147 MB) for good."""
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _init_worker(problems)


def _model(problem: Problem) -> Any:
    from camtraj.collision import CollisionModel

    models = _WORKER.setdefault("models", {})
    if id(problem) not in models:
        models[id(problem)] = (problem, CollisionModel(problem.robot, list(problem.obstacles),
                                                       problem.floor_z))
    return models[id(problem)][1]


def evaluate(problem: Problem, x: float, y: float, yaw_deg: float, stride: int) -> Result:
    """Solve, time and collision-check one placement on every ``stride``-th frame."""
    from camtraj.collision import Moments, collision_error, sample_times, take_samples

    robot = problem.robot
    base2world = yaw_pose(x, y, problem.base_z, yaw_deg)
    idx = np.arange(0, problem.cam2world.shape[0], stride)
    flange2base = (np.linalg.inv(base2world) @ problem.cam2world[idx]
                   @ np.linalg.inv(robot.camera2flange))
    frames = problem.frames[idx]
    times = problem.times[idx]
    full = stride == 1
    try:
        path = _solve(robot, flange2base, problem, float(times[1] - times[0]), frames)
    except UnreachableFramesError as exc:
        return Result(x, y, yaw_deg, full, 1.0 - len(exc.errors) / len(idx), False, False, 0.0,
                      "", {}, str(exc))
    except CamtrajError as exc:
        return Result(x, y, yaw_deg, full, 0.0, False, False, 0.0, "", {}, str(exc))
    marg = margins(robot, path.q)
    q_time, limits = take_axes(robot, path.q,
                               None if problem.lens_q is None else problem.lens_q[idx])
    try:
        take = time_shot(q_time, times, limits, mode="scale",
                         rate=problem.rate if full else min(problem.rate, 100.0),
                         frame_numbers=frames, hold=camera_holds(flange2base),
                         rest=path.rest_axes(q_time.shape[1]),
                         edges=timing_edges(problem.edges))
    except TimingLimitError as exc:
        speed = exc.max_speed if math.isfinite(exc.max_speed) else 0.0
        return Result(x, y, yaw_deg, full, 1.0, True, False, speed, "position", marg, str(exc))
    rep = take.report
    feasible = not rep.limiting or problem.timing != "shot"
    reason = "" if feasible else "; ".join(v.describe() for v in rep.limiting[:2])
    free = True
    if problem.obstacles:
        model = _model(problem)
        if full:
            joints = take.q[:, :len(JOINT_NAMES)]
            s = take_samples(robot, joints, take.frame_samples)
            q, tcs = joints[s], sample_times(take.t[s], take.frame_times, problem.time_codes)
            t, t_frames = take.t[s], take.frame_times
        else:
            q, tcs = path.q, problem.time_codes[idx]
            t = t_frames = times
        dist, worst = model.closest(q, tcs, base2world, problem.clearance)
        marg["obstacle_m"] = float(dist.min()) if math.isfinite(dist.min()) else math.inf
        if worst is not None:
            free = False
            reason = str(collision_error(worst, Moments.of(t, t_frames, frames),
                                         problem.clearance))
    return Result(x, y, yaw_deg, full, 1.0, free, feasible, float(rep.max_speed),
                  rep.set_by, marg, reason)


Task = tuple[int, float, float, float, int]
"""One solve: (shot index, x [m], y [m], yaw [deg], frame stride)."""


def _evaluate_batch(batch: list[Task]) -> list[Result]:
    problems = _WORKER["problems"]
    return [evaluate(problems[i], x, y, yaw, stride) for i, x, y, yaw, stride in batch]


def _spread(order: NDArray[np.intp], cand: Array, keep: int, dxy: float,
            dyaw: float) -> list[int]:
    """Up to ``keep`` indices from ``order`` (best first), no two within one grid cell."""
    picked: list[int] = []
    for i in order:
        c = cand[i]
        close = any(abs(c[0] - cand[j][0]) < 1.5 * dxy and abs(c[1] - cand[j][1]) < 1.5 * dxy
                    and abs((c[2] - cand[j][2] + 180.0) % 360.0 - 180.0) < 1.5 * dyaw
                    for j in picked)
        if not close:
            picked.append(int(i))
            if len(picked) == keep:
                break
    return picked


# ---------------------------------------------------------------------------------------------
# One placement for one or more shots: solved shot by shot, best bound first
# ---------------------------------------------------------------------------------------------

_UNSOLVED = (math.inf,) * 5  # the bound of a placement no shot has been solved at


@dataclass
class Layout:
    """One placement and what is known of it for each shot of a scene.

    ``results`` holds the shots solved so far (by shot index); they are solved in ``order``
    (the tightest first), and :meth:`key`, the worst of their keys in each component, only
    falls as more are solved: a placement whose key is already below the ones to beat is not
    solved further.
    """

    x: float
    y: float
    yaw_deg: float
    order: tuple[int, ...]
    results: dict[int, Result] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return len(self.results) == len(self.order)

    @property
    def ok(self) -> bool:
        return self.complete and all(r.ok for r in self.results.values())

    def key(self) -> tuple[float, ...]:
        """Larger is better: per component the worst solved shot's (every shot reachable,
        none colliding, all feasible, the worst shot's speed, the smallest margin)."""
        keys = [r.key() for r in self.results.values()]
        return tuple(min(k) for k in zip(*keys, strict=True)) if keys else _UNSOLVED

    def rank(self) -> tuple[float, ...]:
        """:meth:`key`, ties broken by the position: a total order of the placements, so what
        the search keeps never depends on the order in which solves finish."""
        return (*self.key(), -self.x, -self.y, -self.yaw_deg)

    def next_shot(self) -> int:
        return next(i for i in self.order if i not in self.results)

    @property
    def limiting(self) -> int:
        """The shot whose result limits the placement."""
        return min(self.results, key=lambda i: self.results[i].key())

    def worst_first(self) -> tuple[int, ...]:
        """The shots in the order of their results, worst first (for the next stage)."""
        return tuple(sorted(self.order, key=lambda i: (self.results[i].key()
                            if i in self.results else _UNSOLVED, i)))

    def base2world(self, z: float) -> Array:
        return yaw_pose(self.x, self.y, z, self.yaw_deg)


def _race(runner: _Runner, layouts: list[Layout], strides: dict[int, int], need: int) -> None:
    """Solve the layouts' shots until the ``need`` best complete layouts are known.

    Placements no shot has been solved at go first, all together (one shot each); then the
    open placements with the best bounds get their next shot, ``jobs`` at a time. A placement
    stops once its bound is no better than the ``need``-th best complete rank: the worst of
    the shots solved already rules it out, so its other shots are never solved.

    Bounds only fall as shots are solved and :meth:`Layout.rank` orders every placement
    (no ties), so the ``need`` best complete layouts are the ``need`` best of all the layouts
    whatever the number of jobs and the order the solves finish in: only the solve count
    depends on them. The caller uses no more than the ``need`` best.
    """
    while True:
        done = sorted((lay.rank() for lay in layouts if lay.complete), reverse=True)
        bar = done[need - 1] if len(done) >= need else None
        open_ = [lay for lay in layouts if not lay.complete and (bar is None or lay.rank() > bar)]
        if not open_:
            return
        todo = [lay for lay in open_ if not lay.results] or sorted(
            open_, key=Layout.rank, reverse=True)[:runner.jobs]
        tasks = [(lay.next_shot(), lay.x, lay.y, lay.yaw_deg, strides[lay.next_shot()])
                 for lay in todo]
        for lay, task, result in zip(todo, tasks, runner.run(tasks), strict=True):
            lay.results[task[0]] = result


# ---------------------------------------------------------------------------------------------
# The search
# ---------------------------------------------------------------------------------------------


@dataclass
class PlaceReport:
    """What ``camtraj place`` found: the ranked placements solved on every frame."""

    shot: str
    floor_z: float  # [m]; the base stands RAIL_HEIGHT above it (:attr:`base_z`)
    results: list[Result]
    evaluated: int
    screened: int
    seconds: float
    set_file: SetFile
    region: dict[str, Any]

    @property
    def best(self) -> Result:
        return self.results[0]

    @property
    def base_z(self) -> float:
        """The base's height [m]: on the carriage, on the rail lying on the floor."""
        return base_height(self.floor_z)

    def to_json(self) -> dict[str, Any]:
        return {"shot": self.shot, "status": "ok" if self.best.ok else "infeasible",
                "floor_z": self.floor_z, "base_z": self.base_z,
                "placements": [r.to_json() for r in self.results],
                "evaluated": self.evaluated, "screened": self.screened,
                "seconds": self.seconds, "candidates_per_second": self.evaluated / self.seconds,
                "region": self.region}


class _Runner:
    """Solves (shot, placement) tasks inline (one job) or in worker processes, with one
    progress bar; ``problems`` are the shots (one per shot of a scene)."""

    def __init__(self, problems: tuple[Problem, ...], jobs: int, progress: bool) -> None:
        from tqdm import tqdm

        self.problems = problems
        self.jobs = jobs
        self.pool: cf.ProcessPoolExecutor | None = None
        self.bar = tqdm(total=0, unit="solve", desc="camtraj place", disable=not progress,
                        file=sys.stderr, dynamic_ncols=True, leave=False)
        self.count = 0
        if jobs > 1:
            from camtraj.workers import mp_context

            self.pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=mp_context(),
                                               initializer=_init_pool_worker,
                                               initargs=(problems,))

    def run(self, tasks: list[Task]) -> list[Result]:
        self.bar.total += len(tasks)
        self.bar.refresh()
        self.count += len(tasks)
        if self.pool is None:
            if _WORKER.get("problems") is not self.problems:
                _init_worker(self.problems)
            out = []
            for i, x, y, yaw, stride in tasks:
                out.append(evaluate(self.problems[i], x, y, yaw, stride))
                self.bar.update(1)
            return out
        size = max(1, math.ceil(len(tasks) / (4 * self.jobs)))
        chunks = [tasks[i:i + size] for i in range(0, len(tasks), size)]
        from camtraj.workers import worker_environment

        with worker_environment():  # the workers (and their fork server) start on submit
            futures = {self.pool.submit(_evaluate_batch, ch): k for k, ch in enumerate(chunks)}
        results: list[list[Result]] = [[] for _ in chunks]
        for fut in cf.as_completed(futures):
            results[futures[fut]] = fut.result()
            self.bar.update(len(results[futures[fut]]))
        return [r for part in results for r in part]

    def close(self) -> None:
        self.bar.close()
        if self.pool is not None:
            self.pool.shutdown(cancel_futures=True)


@dataclass(frozen=True)
class Screen:
    """The cheap tests of a coarse grid for the shots of a scene (every frame subsampled).

    ``slack`` (G, S): per grid placement and shot, how far the shot's camera path stays
    inside the robot's reach [m]; ``floor`` (G,): the rail inside the region, off the
    keep-outs. ``ok``: both, for every shot.
    """

    shots: tuple[int, ...]
    grid: Array  # (G, 3): x, y [m], yaw [deg]
    slack: Array
    floor: NDArray[np.bool_]
    step: float
    yaw_step: float
    yaw_range: tuple[float, float]
    region: Array | None
    keep_out: list[Array]
    info: dict[str, Any]

    @property
    def ok(self) -> NDArray[np.bool_]:
        out: NDArray[np.bool_] = np.all(self.slack >= 0, axis=1) & self.floor
        return out


def _subsample(problem: Problem) -> tuple[int, Array]:
    """A shot's frame stride in the coarse stages and its camera positions (k, 3) there."""
    n = problem.cam2world.shape[0]
    stride = max(1, math.ceil(n / COARSE_FRAMES))
    return stride, problem.cam2world[::stride, :3, 3]


def screen(problems: tuple[Problem, ...], shots: tuple[int, ...], set_file: SetFile, *,
           meters_per_unit: float, up_axis: str) -> Screen:
    """The cheap tests over a coarse grid of the placements that might serve every shot in
    ``shots`` (inside the reach of each one's camera path and the floor region).

    Raises:
        PlacementError: A shot no placement can do, or no placement in reach of every shot.
    """
    robot = problems[shots[0]].robot
    base_z = problems[shots[0]].base_z
    env = reach_envelope(robot)
    reach = env.reach + env.offset + max(abs(env.axis_lo), abs(env.axis_hi))
    lo, hi = np.full(2, -np.inf), np.full(2, np.inf)
    for i in shots:
        pts = problems[i].cam2world[:, :3, 3]
        try:
            check_can_reach(env, pts, base_z)
        except PlacementError as exc:
            msg = f"{problems[i].name}: {exc}" if len(shots) > 1 else str(exc)
            raise PlacementError(msg) from None
        lo = np.maximum(lo, pts[:, :2].min(axis=0) - reach)
        hi = np.minimum(hi, pts[:, :2].max(axis=0) + reach)
    if np.any(lo > hi):
        msg = "no placement is within the robot's reach of every shot's camera path"
        raise PlacementError(msg)
    src = set_file.source
    region = None if set_file.region is None else floor_polygon(
        set_file.region, meters_per_unit, up_axis, src, "floor.region")
    keep_out = [floor_polygon(p, meters_per_unit, up_axis, src, f"floor.keep_out[{i}]")
                for i, p in enumerate(set_file.keep_out)]
    if region is not None:
        lo, hi = np.maximum(lo, region.min(axis=0)), np.minimum(hi, region.max(axis=0))
        if np.any(lo > hi):
            msg = ("the set file's floor region is out of the robot's reach of the camera path"
                   + ("s" if len(shots) > 1 else ""))
            raise PlacementError(msg)
    dxy = max(0.25, float(np.max(hi - lo)) / 40.0)
    yaw_lo, yaw_hi = set_file.yaw_range_deg or (-180.0, 180.0 - YAW_STEP_DEG)
    n_yaw = max(1, math.ceil((yaw_hi - yaw_lo) / YAW_STEP_DEG) + 1) if yaw_hi > yaw_lo else 1
    yaws = np.linspace(yaw_lo, yaw_hi, n_yaw)
    dyaw = (yaw_hi - yaw_lo) / max(n_yaw - 1, 1) if n_yaw > 1 else 0.0
    xs = np.arange(lo[0], hi[0] + 1e-9, dxy)
    ys = np.arange(lo[1], hi[1] + 1e-9, dxy)
    grid = np.stack(np.meshgrid(xs, ys, yaws, indexing="ij"), axis=-1).reshape(-1, 3)
    slack = _slack(problems, shots, env, grid)
    floor = np.zeros(len(grid), dtype=bool)
    reachable = np.all(slack >= 0, axis=1)
    floor[reachable] = floor_ok(robot, grid[reachable, 0], grid[reachable, 1],
                                grid[reachable, 2], region, keep_out)
    info = {"x": [float(lo[0]), float(hi[0])], "y": [float(lo[1]), float(hi[1])],
            "yaw_deg": [float(yaw_lo), float(yaw_hi)], "step_m": dxy, "yaw_step_deg": dyaw,
            "grid": len(grid), "passed_cheap_tests": int(floor.sum())}
    return Screen(shots, grid, slack, floor, dxy, dyaw, (yaw_lo, yaw_hi), region, keep_out,
                  info)


def passing_screen(problems: tuple[Problem, ...], shots: tuple[int, ...], set_file: SetFile,
                   *, meters_per_unit: float, up_axis: str) -> Screen:
    """:func:`screen`, where some placement passes its cheap tests.

    Raises:
        PlacementError: None does (or :func:`screen`'s reasons), saying which tests.
    """
    scr = screen(problems, shots, set_file, meters_per_unit=meters_per_unit, up_axis=up_axis)
    if not scr.ok.any():
        msg = ("no placement in the search region keeps the whole camera path"
               + (" of every shot" if len(shots) > 1 else "") + " within the robot's reach"
               + (" with the rail inside the floor region and off the keep-out areas"
                  if scr.region is not None or scr.keep_out else ""))
        raise PlacementError(msg)
    return scr


def _slack(problems: tuple[Problem, ...], shots: tuple[int, ...], env: Any,
           places: Array) -> Array:
    """(N, S) reach slack of each placement (N, 3) for each shot: every shot's subsampled
    frames in one vectorised test."""
    subs = [_subsample(problems[i])[1] for i in shots]
    points = np.concatenate(subs)
    sizes = [len(p) for p in subs]
    base_z = problems[shots[0]].base_z
    chunk = max(1, 48_000 // len(points))
    return np.concatenate([reach_slack(env, points, g[:, 0], g[:, 1], g[:, 2], base_z, sizes)
                           for g in np.array_split(places, max(1, -(-len(places) // chunk)))])


def search(runner: _Runner, shots: tuple[int, ...], set_file: SetFile, *,
           meters_per_unit: float, up_axis: str, top: int = 3) -> tuple[list[Layout], int,
                                                                        dict[str, Any]]:
    """Coarse-to-fine search of one placement for the shots ``shots`` of ``runner``'s
    problems. Returns the ranked placements solved on every frame of every shot (at least one),
    the number of candidates screened and the search region.

    With one shot every finalist is solved in full (``top`` of them listed); with more, the
    finalists race shot by shot and only the best is solved in full for every shot.

    Raises:
        PlacementError: The cheap tests rule out every placement (the reason says which).
    """
    problems = runner.problems
    robot = problems[shots[0]].robot
    env = reach_envelope(robot)
    scr = passing_screen(problems, shots, set_file, meters_per_unit=meters_per_unit,
                         up_axis=up_axis)
    ok = scr.ok
    cand, slack = scr.grid[ok], scr.slack[ok]
    order = np.argsort(-slack.min(axis=1), kind="stable")
    keep = min(COARSE_KEEP, max(8, len(cand) // 4))  # a small region needs fewer
    picked = _spread(order, cand, keep, scr.step, scr.yaw_step)
    strides = {i: _subsample(problems[i])[0] for i in shots}
    single = len(shots) == 1
    finals = max(FULL_KEEP, top) if single else SCENE_FULL_KEEP
    needs = [keep for keep, _, _ in REFINE[1:]] + [finals]  # each race: what the next takes
    layouts = [Layout(float(cand[i, 0]), float(cand[i, 1]), float(cand[i, 2]),
                      tuple(shots[j] for j in np.argsort(slack[i], kind="stable")))
               for i in picked]
    yaw_lo, yaw_hi = scr.yaw_range
    # where the track is now races too (if it passes the cheap tests) and is solved on every
    # frame: the search never proposes a placement slower than it (a new user's walk ran at
    # 88% at the stage origin, and place's best was 80%)
    here = np.array([current_placement(set_file)])
    here_slack = _slack(problems, shots, env, here)[0]
    now: Layout | None = None
    if (np.all(here_slack >= 0)
            and floor_ok(robot, here[:, 0], here[:, 1], here[:, 2], scr.region,
                         scr.keep_out)[0]
            and (set_file.yaw_range_deg is None
                 or yaw_lo - 1e-9 <= here[0, 2] <= yaw_hi + 1e-9)):
        now = Layout(float(here[0, 0]), float(here[0, 1]), float(here[0, 2]),
                     tuple(shots[j] for j in np.argsort(here_slack, kind="stable")))
        if all(_where(now) != _where(lay) for lay in layouts):
            layouts.append(now)
        now = next(lay for lay in layouts if _where(lay) == _where(now))
    _race(runner, layouts, strides, REFINE[0][0])
    # pattern search: +-x, +-y, +-yaw around the best few, polled again at the same step while
    # the best moves (up to the level's polls), then at half the step
    for (keep, frac, polls), need in zip(REFINE, needs, strict=True):
        h, hy = scr.step * frac, scr.yaw_step * frac
        steps: list[tuple[float, float, float]] = [(h, 0, 0), (-h, 0, 0), (0, h, 0), (0, -h, 0)]
        steps += [(0, 0, hy), (0, 0, -hy)] if hy else []
        for _poll in range(polls):
            best = _distinct(_ranked(layouts), keep)
            arr = np.array([(r.x + a, r.y + b, r.yaw_deg + c) for r in best
                            for a, b, c in steps])
            orders = [r.worst_first() for r in best for _ in steps]
            good = np.all(_slack(problems, shots, env, arr) >= 0, axis=1)
            good &= floor_ok(robot, arr[:, 0], arr[:, 1], arr[:, 2], scr.region, scr.keep_out)
            if set_file.yaw_range_deg is not None:
                good &= (arr[:, 2] >= yaw_lo - 1e-9) & (arr[:, 2] <= yaw_hi + 1e-9)
            else:
                arr[:, 2] = (arr[:, 2] + 180.0) % 360.0 - 180.0
            seen = {_where(r) for r in layouts}
            added = 0
            for c, o, g in zip(arr, orders, good, strict=True):
                lay = Layout(float(c[0]), float(c[1]), float(c[2]), o)
                if g and _where(lay) not in seen:
                    seen.add(_where(lay))
                    layouts.append(lay)
                    added += 1
            _race(runner, layouts, strides, need)
            if not added or _ranked(layouts)[0] is best[0]:
                break  # the best held: the next, finer step
    finalists = _distinct(_ranked(layouts), finals)
    if now is not None and now not in finalists:  # solved in full whatever its subsample said
        finalists.append(now)
    # solved on every frame where they are printed and written: to the millimetre and the
    # hundredth of a degree (a shot's speed can change with a fraction of a millimetre)
    laid = np.array([(round(r.x, 3), round(r.y, 3), round(r.yaw_deg, 2)) for r in finalists])
    fits = floor_ok(robot, laid[:, 0], laid[:, 1], laid[:, 2], scr.region, scr.keep_out)
    at = [(float(c[0]), float(c[1]), float(c[2])) if fit else (r.x, r.y, r.yaw_deg)
          for r, c, fit in zip(finalists, laid, fits, strict=True)]
    full = [Layout(x, y, yaw, r.worst_first()) for (x, y, yaw), r in zip(at, finalists,
                                                                         strict=True)]
    _race(runner, full, dict.fromkeys(shots, 1), len(full) if single else 1)
    return _ranked(full)[:top], len(scr.grid), scr.info


def current_placement(set_file: SetFile) -> tuple[float, float, float]:
    """Where the track is now, as x, y [m] and yaw [deg] in (-180, 180]: the set file's
    placement, else convert's default (the stage origin, yaw 0)."""
    m = set_file.base2world
    if m is None:
        return 0.0, 0.0, 0.0
    # to the nanodegree: a file's yaw_deg = -136.88 back as -136.88, not -136.88000000000002
    # (a shot's speed can change with the transform's last bit)
    return float(m[0, 3]), float(m[1, 3]), round(math.degrees(math.atan2(m[1, 0], m[0, 0])), 9)


def _where(lay: Layout) -> tuple[float, float, float]:
    return round(lay.x, 6), round(lay.y, 6), round(lay.yaw_deg, 6)


def _ranked(layouts: list[Layout]) -> list[Layout]:
    """The complete layouts, best first."""
    return sorted((lay for lay in layouts if lay.complete), key=Layout.rank, reverse=True)


def _distinct(ranked: list[Layout], k: int) -> list[Layout]:
    out: list[Layout] = []
    for r in ranked:
        if all(abs(r.x - o.x) > 1e-9 or abs(r.y - o.y) > 1e-9 or abs(r.yaw_deg - o.yaw_deg)
               > 1e-9 for o in out):
            out.append(r)
        if len(out) == k:
            break
    return out


def load_problem(shot_path: str | Path, options: ConvertOptions, robot: Robot, sf: SetFile,
                 *, clearance: float | None, rate: float, timing: str = "shot",
                 ) -> tuple[Problem, Shot]:
    """One shot as the search takes it (read as convert reads it), and the shot read."""
    from camtraj.collision import read_obstacles
    from camtraj.convert import load_shot
    from camtraj.usd_shot import stage_to_world

    shot = load_shot(shot_path, options)
    lens_q = None
    if robot.lens is not None:  # a frame beyond the lens's calibration is an error up front
        from camtraj.lens import lens_positions

        try:
            lens_q = lens_positions(robot.lens, shot)
        except InfeasibleError as exc:  # what reading the shot warned of is often why
            exc.shot_warnings = tuple(shot.warnings)
            raise
    obstacles = read_obstacles(shot_path, sf.prims, shot.time_codes,
                               stage_to_world(shot.meters_per_unit, shot.up_axis))
    floor_z = sf.floor_height * shot.meters_per_unit
    problem = Problem(robot, np.array(shot.cam2world), np.array(shot.times),
                      np.array(shot.frames), np.array(shot.time_codes), floor_z, rate,
                      obstacles=tuple(obstacles),
                      clearance=sf.clearance_m if clearance is None else clearance,
                      name=one_line(shot_path), timing=timing, lens_q=lens_q,
                      edges=options.edges)
    return problem, shot


def with_clearance(sf: SetFile, clearance: float | None) -> SetFile:
    """The set file as the placed one is written: a --clearance given replaces its own."""
    if clearance is None:
        return sf
    return replace(sf, text=with_clearance_text(sf.text, clearance))


def place(
    shot_path: str | Path,
    *,
    robot: str | None = None,
    set_file: str | None = None,
    camera: str | None = None,
    frames: tuple[int, int] | None = None,
    clearance: float | None = None,
    rate: float = 250.0,
    jobs: int | None = None,
    progress: bool = False,
    top: int = 3,
    lens: str | None = None,
    timing: str = "shot",
    edges: str = "still",
) -> PlaceReport:
    """Search the placement of the robot for a shot (see the module docstring).

    Raises:
        InputError: Unreadable shot, robot or set file, bad jobs.
        PlacementError: No placement passes the cheap tests (exit 3).
    """
    from camtraj.convert import load_robot
    from camtraj.inputs import require_regular_files
    from camtraj.options import ConvertOptions
    from camtraj.workers import default_jobs

    start = time.perf_counter()
    jobs = default_jobs(jobs)
    # the options convert would take: the same checks of the clearance and of every input file
    options = ConvertOptions(robot=robot, set_file=set_file, camera=camera, frames=frames,
                             clearance=clearance, lens=lens, edges=edges)
    require_regular_files(shot_path, options)
    rob = load_robot(options)
    sf = SetFile.read(set_file) if set_file is not None else SetFile()
    problem, shot = load_problem(shot_path, options, rob, sf, clearance=clearance, rate=rate,
                                 timing=timing)
    runner = _Runner((problem,), jobs, progress)
    try:
        layouts, screened, region = search(runner, (0,), sf,
                                           meters_per_unit=shot.meters_per_unit,
                                           up_axis=shot.up_axis, top=top)
    except InfeasibleError as exc:  # what reading the shot warned of is often why
        exc.shot_warnings = tuple(shot.warnings)
        raise
    finally:
        runner.close()
    return PlaceReport(str(shot_path), problem.floor_z, [lay.results[0] for lay in layouts],
                       runner.count, screened, time.perf_counter() - start,
                       with_clearance(sf, clearance), region)


#: What the placement tables' "limits use" column is.
LIMITS_USE = ("limits use: the robot's peak position use (a lens's motors apart: no placement "
              "moves them), 0% mid-range, 100% touching a limit")


def heights(floor_z: float, base_z: float) -> str:
    """'floor z 0.000 m, base 0.180 m on the rail': the floor's height and the base's."""
    return f"floor z {floor_z:.3f} m, base {base_z:.3f} m on the rail"


def table(report: PlaceReport) -> str:
    """The ranked placements for people."""
    lines = [f"{report.shot}: {report.evaluated} placements solved, {report.screened} screened, "
             f"in {report.seconds:.1f} s ({heights(report.floor_z, report.base_z)})",
             "  #     x [m]     y [m]  yaw [deg]    speed  limits use  wrist  stretch  obstacle"
             "  set by",
             f"  ({LIMITS_USE}; wrist, stretch: margins)"]
    for i, r in enumerate(report.results, 1):
        lines.append(f"  {i:<2} {r.x:9.3f} {r.y:9.3f} {r.yaw_deg:9.2f}  {columns(r)}")
        if not r.ok:
            lines.append(f"     not possible: {r.reason}")
    return "\n".join(lines)


def columns(r: Result) -> str:
    """A result's speed, limits use, margins, obstacle distance and what sets the speed
    (the timing stage's ``set_by``, as convert says it) columns."""
    m = r.margins
    speed = speed_percent(r.max_speed) if r.max_speed > 0 else "-"
    obst = m.get("obstacle_m")
    ob = "       -" if obst is None else ("   clear" if not math.isfinite(obst)
                                          else f"{obst:6.2f} m")
    return (f"{speed:>7}  {100 * m.get('limits_use', 1.0):9.0f}%  "
            f"{m.get('wrist_deg', 0.0):4.0f}°  {m.get('stretch_deg', 0.0):6.0f}°  {ob}"
            f"  {r.binding or '-'}")
