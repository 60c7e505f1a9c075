"""``camtraj place``: where to lay the track so the robot can do the shot.

The search is over the robot base's x, y and yaw about up on the floor (z is the set file's
floor height). Placements rank by: every frame reachable, no collision with the set's
obstacles, feasible at the shot's own timing, then the largest maximum feasible speed (to 1 %),
then the largest margins (position limits, wrist singularity, full stretch).

1. Cheap tests first, on every candidate of a coarse grid at once: the camera path against the
   robot's reach envelope (a solid of revolution about the rotate axis, swept along the track),
   the rail's footprint against the floor region and the keep-out polygons. A shot that fails
   them everywhere (path longer than track plus reach, heights beyond the lift's) is refused
   with the reason before any solve.
2. The most promising, spread-out survivors are solved on a subsample of the frames and timed.
3. Local refinement around the best few at half and quarter the grid step.
4. The best few are solved and timed on every frame, and collision-checked on the take.

Candidates are evaluated in worker processes; the solver is called through :func:`_solve` only.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import click
import numpy as np
from numpy.typing import NDArray

from camtraj.errors import CamtrajError, InputError, PlacementError, UnreachableFramesError
from camtraj.ik import PathSolution, solve_path_report
from camtraj.reach import check_can_reach, floor_ok, reach_envelope, reach_slack
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.set_file import SetFile, floor_polygon
from camtraj.timing import Limits, TimingLimitError, time_shot

Array = NDArray[np.float64]

COARSE_FRAMES = 12  # frames solved per candidate in the coarse stages
COARSE_KEEP = 24  # at most this many survivors of the cheap tests solved on the subsample
REFINE = ((2, 0.5), (2, 0.25), (1, 0.125))  # (best placements refined, fraction of the step)
FULL_KEEP = 3  # placements solved on every frame (at least; --top more)
YAW_STEP_DEG = 15.0
_SPEED_CAP = 100.0


def _solve(robot: Robot, flange2base: Array, start: Array | None, objective: str | None,
           frame_interval: float, frame_numbers: NDArray[np.int64]) -> PathSolution:
    """The whole-shot solver, in one place (re-point it here when the solver changes)."""
    return solve_path_report(robot, flange2base, start, objective=objective,
                             frame_interval=frame_interval, frame_numbers=frame_numbers)


# ---------------------------------------------------------------------------------------------
# The problem and one candidate's evaluation (runs in the workers)
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """Everything a worker needs, as plain picklable data (converted world: metres, Z-up)."""

    robot: Robot
    cam2world: Array  # (n, 4, 4)
    times: Array
    frames: NDArray[np.int64]
    time_codes: Array
    base_z: float
    rate: float
    objective: str | None = None
    start: Array | None = None
    obstacles: tuple[Any, ...] = ()
    clearance: float = 0.0


@dataclass(frozen=True)
class Result:
    """One evaluated placement. ``full`` says whether every frame was solved."""

    x: float
    y: float
    yaw_deg: float
    full: bool
    reachable: float  # fraction of the solved frames reached
    collision_free: bool
    feasible: bool  # at the shot's own timing
    max_speed: float
    binding: str
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
        speed = math.floor(100.0 * min(self.max_speed, _SPEED_CAP)) if self.max_speed > 0 else 0
        return (self.reachable, float(self.collision_free), float(self.feasible), speed, margin)

    def base2world(self, z: float) -> Array:
        return pose(self.x, self.y, z, self.yaw_deg)

    def to_json(self) -> dict[str, Any]:
        return {"x": self.x, "y": self.y, "yaw_deg": self.yaw_deg, "ok": self.ok,
                "full": self.full, "reachable": self.reachable,
                "collision_free": self.collision_free, "feasible": self.feasible,
                "max_speed": self.max_speed if math.isfinite(self.max_speed) else None,
                "binding": self.binding, "margins": self.margins, "reason": self.reason}


def pose(x: float, y: float, z: float, yaw_deg: float) -> Array:
    """Base-to-world transform of a placement."""
    a = math.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                 [0.0, 0.0, 1.0]]
    T[:3, 3] = (x, y, z)
    return T


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


def _binding(peak_use: dict[str, dict[str, float]]) -> str:
    """The axis and quantity that limit the speed (velocity, sqrt accel, cbrt jerk use)."""
    best, name = -1.0, ""
    for axis, use in peak_use.items():
        for quantity, power in (("velocity", 1.0), ("acceleration", 0.5), ("jerk", 1 / 3)):
            value = use.get(quantity, 0.0) ** power
            if value > best:
                best, name = value, f"{axis} {quantity}"
    return name


_WORKER: dict[str, Any] = {}


def _init_worker(problem: Problem) -> None:
    _WORKER.clear()
    _WORKER["problem"] = problem


def _model(problem: Problem) -> Any:
    from camtraj.collision import CollisionModel

    if "model" not in _WORKER or _WORKER.get("model_for") is not problem:
        _WORKER["model"] = CollisionModel(problem.robot, list(problem.obstacles))
        _WORKER["model_for"] = problem
    return _WORKER["model"]


def evaluate(problem: Problem, x: float, y: float, yaw_deg: float, stride: int) -> Result:
    """Solve, time and collision-check one placement on every ``stride``-th frame."""
    from camtraj.collision import collision_error, sample_times, take_samples

    robot = problem.robot
    base2world = pose(x, y, problem.base_z, yaw_deg)
    idx = np.arange(0, problem.cam2world.shape[0], stride)
    flange2base = (np.linalg.inv(base2world) @ problem.cam2world[idx]
                   @ np.linalg.inv(robot.camera2flange))
    frames = problem.frames[idx]
    times = problem.times[idx]
    full = stride == 1
    try:
        path = _solve(robot, flange2base, problem.start, problem.objective,
                      float(times[1] - times[0]), frames)
    except UnreachableFramesError as exc:
        return Result(x, y, yaw_deg, full, 1.0 - len(exc.errors) / len(idx), False, False, 0.0,
                      "", {}, str(exc))
    except CamtrajError as exc:
        return Result(x, y, yaw_deg, full, 0.0, False, False, 0.0, "", {}, str(exc))
    marg = margins(robot, path.q)
    try:
        take = time_shot(path.q, times, Limits.from_robot(robot), mode="scale",
                         rate=problem.rate if full else min(problem.rate, 100.0),
                         frame_numbers=frames)
    except TimingLimitError as exc:
        speed = exc.max_speed if math.isfinite(exc.max_speed) else 0.0
        return Result(x, y, yaw_deg, full, 1.0, True, False, speed, "position", marg, str(exc))
    rep = take.report
    feasible = not rep.limiting
    reason = "" if feasible else "; ".join(v.describe() for v in rep.limiting[:2])
    free = True
    if problem.obstacles:
        model = _model(problem)
        if full:
            s = take_samples(robot, take.q, take.frame_samples)
            q, tcs = take.q[s], sample_times(take.t[s], take.frame_times, problem.time_codes)
            at = np.searchsorted(take.frame_times, take.t[s] - 1e-12).clip(0, len(idx) - 1)
            sample_frames = frames[at]
        else:
            q, tcs, sample_frames = path.q, problem.time_codes[idx], frames
        dist, worst = model.closest(q, tcs, base2world, problem.clearance)
        marg["obstacle_m"] = float(dist.min()) if math.isfinite(dist.min()) else math.inf
        if worst is not None:
            free = False
            reason = str(collision_error(worst, int(sample_frames[worst.sample]),
                                         problem.clearance))
    return Result(x, y, yaw_deg, full, 1.0, free, feasible, float(rep.max_speed),
                  _binding(rep.peak_use), marg, reason)


def _evaluate_batch(batch: list[tuple[float, float, float, int]]) -> list[Result]:
    problem = _WORKER["problem"]
    return [evaluate(problem, *c) for c in batch]


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
# The search
# ---------------------------------------------------------------------------------------------


@dataclass
class PlaceReport:
    """What ``camtraj place`` found: the ranked placements solved on every frame."""

    shot: str
    base_z: float
    results: list[Result]
    evaluated: int
    screened: int
    seconds: float
    set_file: SetFile
    region: dict[str, Any]

    @property
    def best(self) -> Result:
        return self.results[0]

    def to_json(self) -> dict[str, Any]:
        return {"shot": self.shot, "status": "ok" if self.best.ok else "infeasible",
                "base_z": self.base_z, "placements": [r.to_json() for r in self.results],
                "evaluated": self.evaluated, "screened": self.screened,
                "seconds": self.seconds, "candidates_per_second": self.evaluated / self.seconds,
                "region": self.region}


class _Runner:
    """Evaluates candidates inline (one job) or in worker processes, with one progress bar."""

    def __init__(self, problem: Problem, jobs: int, progress: bool) -> None:
        from tqdm import tqdm

        self.problem = problem
        self.jobs = jobs
        self.pool: cf.ProcessPoolExecutor | None = None
        self.bar = tqdm(total=0, unit="placement", desc="camtraj place", disable=not progress,
                        file=sys.stderr, dynamic_ncols=True, leave=False)
        self.count = 0
        if jobs > 1:
            from camtraj.batch import _mp_context, _worker_environment

            with _worker_environment():
                self.pool = cf.ProcessPoolExecutor(max_workers=jobs, mp_context=_mp_context(),
                                                   initializer=_init_worker, initargs=(problem,))

    def run(self, cands: list[tuple[float, float, float, int]]) -> list[Result]:
        self.bar.total += len(cands)
        self.bar.refresh()
        self.count += len(cands)
        if self.pool is None:
            if _WORKER.get("problem") is not self.problem:
                _init_worker(self.problem)
            out = []
            for c in cands:
                out.append(evaluate(self.problem, *c))
                self.bar.update(1)
            return out
        size = max(1, math.ceil(len(cands) / (4 * self.jobs)))
        chunks = [cands[i:i + size] for i in range(0, len(cands), size)]
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


def search(problem: Problem, set_file: SetFile, *, meters_per_unit: float, up_axis: str,
           jobs: int = 1, progress: bool = False, top: int = 3) -> tuple[list[Result],
                                                                         int, int, dict[str, Any]]:
    """Coarse-to-fine search. Returns ranked full results, evaluated and screened counts and
    the search region.

    Raises:
        PlacementError: The cheap tests rule out every placement (the reason says which).
    """
    robot = problem.robot
    env = reach_envelope(robot)
    pts = problem.cam2world[:, :3, 3]
    n = pts.shape[0]
    stride = max(1, math.ceil(n / COARSE_FRAMES))
    sub = pts[::stride]
    check_can_reach(env, pts, problem.base_z)

    src = set_file.source
    region = None if set_file.region is None else floor_polygon(
        set_file.region, meters_per_unit, up_axis, src, "floor.region")
    keep_out = [floor_polygon(p, meters_per_unit, up_axis, src, f"floor.keep_out[{i}]")
                for i, p in enumerate(set_file.keep_out)]
    reach = env.reach + env.offset + max(abs(env.axis_lo), abs(env.axis_hi))
    lo, hi = pts[:, :2].min(axis=0) - reach, pts[:, :2].max(axis=0) + reach
    if region is not None:
        lo, hi = np.maximum(lo, region.min(axis=0)), np.minimum(hi, region.max(axis=0))
        if np.any(lo > hi):
            msg = "the set file's floor region is out of the robot's reach of the camera path"
            raise PlacementError(msg)
    dxy = max(0.25, float(np.max(hi - lo)) / 40.0)
    yaw_lo, yaw_hi = set_file.yaw_range_deg or (-180.0, 180.0 - YAW_STEP_DEG)
    n_yaw = max(1, math.ceil((yaw_hi - yaw_lo) / YAW_STEP_DEG) + 1) if yaw_hi > yaw_lo else 1
    yaws = np.linspace(yaw_lo, yaw_hi, n_yaw)
    dyaw = (yaw_hi - yaw_lo) / max(n_yaw - 1, 1) if n_yaw > 1 else 0.0
    xs = np.arange(lo[0], hi[0] + 1e-9, dxy)
    ys = np.arange(lo[1], hi[1] + 1e-9, dxy)
    grid = np.stack(np.meshgrid(xs, ys, yaws, indexing="ij"), axis=-1).reshape(-1, 3)
    slack = np.concatenate([reach_slack(env, sub, g[:, 0], g[:, 1], g[:, 2], problem.base_z)
                            for g in np.array_split(grid, max(1, len(grid) // 4000))])
    ok = slack >= 0
    ok[ok] = floor_ok(robot, grid[ok, 0], grid[ok, 1], grid[ok, 2], region, keep_out)
    screened = len(grid)
    info = {"x": [float(lo[0]), float(hi[0])], "y": [float(lo[1]), float(hi[1])],
            "yaw_deg": [float(yaw_lo), float(yaw_hi)], "step_m": dxy, "yaw_step_deg": dyaw,
            "grid": screened, "passed_cheap_tests": int(ok.sum())}
    if not ok.any():
        msg = ("no placement in the search region keeps the whole camera path within the "
               "robot's reach" + (" with the rail inside the floor region and off the keep-out "
                                  "areas" if region is not None or keep_out else ""))
        raise PlacementError(msg)
    cand = grid[ok]
    order = np.argsort(-slack[ok], kind="stable")
    keep = min(COARSE_KEEP, max(8, len(cand) // 4))  # a small region needs fewer
    picked = _spread(order, cand, keep, dxy, dyaw)
    runner = _Runner(problem, jobs, progress)
    try:
        coarse = runner.run([(*map(float, cand[i]), stride) for i in picked])
        for keep, frac in REFINE:  # pattern search: +-x, +-y, +-yaw around the best few
            best = _distinct(sorted(coarse, key=lambda r: r.key(), reverse=True), keep)
            h, hy = dxy * frac, dyaw * frac
            steps: list[tuple[float, float, float]] = [(h, 0, 0), (-h, 0, 0), (0, h, 0),
                                                       (0, -h, 0)]
            steps += [(0, 0, hy), (0, 0, -hy)] if hy else []
            arr = np.array([(r.x + a, r.y + b, r.yaw_deg + c) for r in best for a, b, c in steps])
            good = (reach_slack(env, sub, arr[:, 0], arr[:, 1], arr[:, 2], problem.base_z) >= 0)
            good &= floor_ok(robot, arr[:, 0], arr[:, 1], arr[:, 2], region, keep_out)
            if set_file.yaw_range_deg is not None:
                good &= (arr[:, 2] >= yaw_lo - 1e-9) & (arr[:, 2] <= yaw_hi + 1e-9)
            else:
                arr[:, 2] = (arr[:, 2] + 180.0) % 360.0 - 180.0
            seen = {(round(r.x, 6), round(r.y, 6), round(r.yaw_deg, 6)) for r in coarse}
            todo = {(round(float(c[0]), 6), round(float(c[1]), 6), round(float(c[2]), 6)): c
                    for c in arr[good]}
            coarse += runner.run([(*map(float, c), stride) for k, c in todo.items()
                                  if k not in seen])
        ranked = sorted(coarse, key=lambda r: r.key(), reverse=True)
        finalists = _distinct(ranked, max(FULL_KEEP, min(top, len(ranked))))
        full = runner.run([(r.x, r.y, r.yaw_deg, 1) for r in finalists])
        evaluated = runner.count
    finally:
        runner.close()
    return sorted(full, key=lambda r: r.key(), reverse=True)[:top], evaluated, screened, info


def _distinct(ranked: list[Result], k: int) -> list[Result]:
    out: list[Result] = []
    for r in ranked:
        if all(abs(r.x - o.x) > 1e-9 or abs(r.y - o.y) > 1e-9 or abs(r.yaw_deg - o.yaw_deg)
               > 1e-9 for o in out):
            out.append(r)
        if len(out) == k:
            break
    return out


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
) -> PlaceReport:
    """Search the placement of the robot for a shot (see the module docstring).

    Raises:
        InputError: Unreadable shot, robot or set file, bad jobs.
        PlacementError: No placement passes the cheap tests (exit 3).
    """
    from camtraj.collision import read_obstacles
    from camtraj.convert import load_shot
    from camtraj.inputs import require_regular_files
    from camtraj.options import ConvertOptions

    start = time.perf_counter()
    if jobs is None:
        jobs = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
            os.cpu_count() or 1)
    if jobs < 1:
        msg = f"jobs must be at least 1, got {jobs}"
        raise InputError(msg)
    # the options convert would take: the same checks of the clearance and of every input file
    options = ConvertOptions(robot=robot, set_file=set_file, camera=camera, frames=frames,
                             clearance=clearance)
    require_regular_files(shot_path, options)
    rob = Robot.default() if robot is None else Robot.from_toml(robot)
    sf = SetFile.read(set_file) if set_file is not None else SetFile()
    shot = load_shot(shot_path, options)
    obstacles = read_obstacles(shot_path, sf.prims, shot.time_codes)
    base_z = sf.floor_height * shot.meters_per_unit
    problem = Problem(rob, np.array(shot.cam2world), np.array(shot.times),
                      np.array(shot.frames), np.array(shot.time_codes), base_z, rate,
                      obstacles=tuple(obstacles),
                      clearance=sf.clearance_m if clearance is None else clearance)
    results, evaluated, screened, region = search(
        problem, sf, meters_per_unit=shot.meters_per_unit, up_axis=shot.up_axis, jobs=jobs,
        progress=progress, top=top)
    if clearance is not None:
        raw = dict(sf.raw)
        raw["collision"] = {**raw.get("collision", {}), "clearance_m": clearance}
        sf = replace(sf, raw=raw)
    return PlaceReport(str(shot_path), base_z, results, evaluated, screened,
                       time.perf_counter() - start, sf, region)


def table(report: PlaceReport) -> str:
    """The ranked placements for people."""
    lines = [f"{report.shot}: {report.evaluated} placements solved, {report.screened} screened, "
             f"in {report.seconds:.1f} s (floor z {report.base_z:.3f} m)",
             "  #     x [m]     y [m]  yaw [deg]  speed  binding           limits use  wrist"
             "  stretch  obstacle",
             "  (limits use: peak position use, 0% mid-range, 100% touching a limit; wrist, "
             "stretch: margins)"]
    for i, r in enumerate(report.results, 1):
        m = r.margins
        speed = f"{math.floor(100 * min(r.max_speed, 99.99)):4d}%" if r.max_speed > 0 else "   -"
        obst = m.get("obstacle_m")
        ob = "       -" if obst is None else ("   clear" if not math.isfinite(obst)
                                              else f"{obst:6.2f} m")
        lines.append(
            f"  {i:<2} {r.x:9.3f} {r.y:9.3f} {r.yaw_deg:9.1f}  {speed:>5}  {r.binding:<20}"
            f"  {100 * m.get('limits_use', 1.0):5.0f}%  {m.get('wrist_deg', 0.0):4.0f}°"
            f"  {m.get('stretch_deg', 0.0):6.0f}°  {ob}")
        if not r.ok:
            lines.append(f"     not possible: {r.reason}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# The command
# ---------------------------------------------------------------------------------------------


@click.command("place", epilog="Exit codes: 0 a placement can do the shot; 2 bad input; "
               "3 no placement can (the reason is printed).")
@click.argument("shot", type=click.Path(dir_okay=False))
@click.option("--robot", type=click.Path(exists=True, dir_okay=False), metavar="ROBOT.toml",
              help="Robot description file (default: the built-in robot).")
@click.option("--set-file", type=click.Path(exists=True, dir_okay=False), metavar="SET.toml",
              help="Floor height and region, keep-out polygons, yaw range, obstacles.")
@click.option("--camera", metavar="PRIM", help="Camera prim path (default: the only camera).")
@click.option("--frames", metavar="A:B", help="Film frame range (inclusive).")
@click.option("--clearance", type=click.FloatRange(0.0, 5.0), metavar="M",
              help="Distance [m] to keep from the obstacles (default: the set file's).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Worker processes (default: the number of CPUs).")
@click.option("--top", type=click.IntRange(1, 20), default=3, show_default=True,
              help="Placements to list.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")
@click.option("-o", "--output", type=click.Path(dir_okay=False), metavar="PLACED.toml",
              help="Write the best placement as a set file for convert --set-file.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@click.pass_context
def place_command(ctx: click.Context, /, shot: str, robot: str | None, set_file: str | None,
                  camera: str | None, frames: str | None, clearance: float | None,
                  jobs: int | None, top: int, as_json: bool, output: str | None,
                  quiet: bool) -> None:
    """Find where to lay the track for SHOT: the robot base's x, y and yaw on the floor.

    Prints the best placements (x, y, yaw, maximum feasible speed, the axis that limits it,
    margins) and with -o writes the best as a set file that convert --set-file takes.
    """
    import json

    from camtraj.errors import CamtrajError
    from camtraj.inputs import run_inputs
    from camtraj.options import ConvertOptions, _parse_frames
    from camtraj.outputs import OutputSet
    from camtraj.set_file import to_toml

    with OutputSet() as outputs:
        try:
            if output is not None:  # checked before the search, like every command's outputs
                outputs.add(output, "-o")
                outputs.refuse_inputs(run_inputs(shot, ConvertOptions(robot=robot,
                                                                      set_file=set_file)))
            report = place(shot, robot=robot, set_file=set_file, camera=camera,
                           frames=_parse_frames(frames) if frames else None,
                           clearance=clearance, jobs=jobs,
                           progress=not quiet and sys.stderr.isatty(), top=top)
        except CamtrajError as exc:
            click.echo(f"ERROR: {exc}", err=True)
            ctx.exit(exc.exit_code)
        click.echo(json.dumps(report.to_json(), indent=2) if as_json else table(report))
        best = report.best
        if not best.ok:
            click.echo(f"ERROR: no placement can do the shot as asked; the best: {best.reason}",
                       err=True)
            ctx.exit(3)
        if output is not None:
            text = to_toml(best.base2world(report.base_z), report.set_file.raw)
            try:
                outputs.write_bytes(output, text.encode("utf-8"))
                outputs.commit()
            except CamtrajError as exc:
                click.echo(f"ERROR: {exc}", err=True)
                ctx.exit(exc.exit_code)
            if not as_json:
                click.echo(f"  wrote {output}")
