"""``make bench``: how fast and how good camtraj's IK and conversion are, on this machine.

Prints plain tables of medians (and writes them to ``bench/results.json``); every speed figure
comes with a ratio against a baseline measured in the same run:

1. Sequential IK over a smooth one-minute path (1440 frames at 24 fps): the default ``shot``
   objective (whole-shot solver) against ``paper`` (the papers' per-frame SM optimum) and scipy
   SLSQP warm-started frame by frame, frames/s and ratios from the same run; for ``paper``,
   every frame's F against a dense traversal seeded with the solver's previous frame; a
   cProfile of one ``shot`` run (where the time goes).
2. Cold single-pose solves from home to random reachable poses and to the GA paper's case:
   SM against generic SLSQP, the GA paper's GM method rebuilt, and a dense traversal
   (``bench/ik_baselines.py``).
3. End-to-end ``camtraj.convert.convert`` of the one-minute shot, split by stage, the MCAP
   writer's peak memory per film frame (tracemalloc), and the
   ``camtraj convert`` command in a new process (start-up and imports included). 3b:
   convert's peak memory per film frame in each stage (tracemalloc) on a 10,000-frame shot.
   3c: ``--timing optimal`` against ``--timing scale`` (the shot's own timing where it fits)
   on the same joint paths (the samples; the one-minute shot too in a full run): the timing
   stage's CPU and the takes' lengths.
4. ``camtraj batch`` (``bench/bench_batch.py``, owned separately).
5. Maximum feasible speed (the timing stage's ``max_speed``) per shot of issue 13's shot set
   (``tests/shot_set.py``): the default objective vs ``paper`` vs the default at 10x effort vs
   the default of the tree at git revision ``--base-rev`` (exported to a temporary folder and
   run in a subprocess), with how many run at real time. 5b: the default's frames/s on the
   1440-frame path in a fresh call and warm, ``paper``'s, and the cost and memory per frame
   for 240 to 23040 frames, this tree against ``--base-rev``, each in a new process.
6. ``camtraj place`` on a 10-second shot and the collision check's cost per frame, and on a
   scene of five 10-second shots against its first shot alone (``bench/bench_place.py``).
7. What ``--report`` adds to the convert of the one-minute shot, and ``camtraj report`` of two
   long takes against ``camtraj info`` of the same files: time ratio, peak memory per film
   frame and at the frame cap (``bench/bench_report.py``).

numpy, not numba: a numba version of the closed form measured 5x numpy on the old per-frame call
mix but only 2.4x at >= 256 candidates per call, and costs ~11 s of JIT compilation per process;
every farm task is a new process, and the whole-shot solver makes few large calls. So camtraj
stays with numpy.

Usage: ``python bench/run.py [--quick] [--json PATH] [--base-rev REV]``. The full run takes a
few minutes on two cores; ``--quick`` uses a shorter shot, fewer poses and one repeat.
"""

from __future__ import annotations

import argparse
import cProfile
import datetime as dt
import importlib.util
import json
import math
import os
import platform
import pstats
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import scipy

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import ik_baselines as base  # noqa: E402  (bench/ is not a package)

import camtraj  # noqa: E402
from camtraj import ik  # noqa: E402
from camtraj.errors import UnreachableError  # noqa: E402
from camtraj.robot import PRISMATIC, Robot  # noqa: E402
from camtraj.usd_shot import read_shot  # noqa: E402

TARGET_FPS = 5000.0  # issue 7's target for sequential IK, default objective [frames/s]
TARGET_CONVERT_S = 1.5  # issue 7's target for converting a one-minute shot, end to end [s]
BASE_REV = "dcd02a3"  # the solver issue 13's rewrite is measured against (main before it)
PAPER_REV = "d5b7e68^"  # the last revision before the shot objective (issue 13's paper goal)
NUMBA_NOTE = ("numpy kept over numba: numba's JIT costs ~11 s per process (every farm task is a "
              "new process) and gained only 2.4x at >= 256 candidates per call; the whole-shot "
              "solver makes few large numpy calls instead.")
WITHIN = 1e-3  # "within 0.1 %" of the traversal
FPS = 24.0


def log(msg: str) -> None:
    """Progress on stderr (the tables go to stdout)."""
    print(f"  .. {msg}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# Output helpers
# ---------------------------------------------------------------------------------------------


def table(
    title: str, headers: list[str], rows: list[list[str]], notes: Sequence[str] = ()
) -> None:
    """Print a plain table: first column left-aligned, the rest right-aligned."""
    cols = list(zip(headers, *rows, strict=True))
    widths = [max(len(c) for c in col) for col in cols]

    def line(cells: list[str]) -> str:
        parts = [cells[0].ljust(widths[0])]
        parts += [c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]
        return "  ".join(parts).rstrip()

    print()
    print(title)
    print(line(headers))
    print("  ".join("-" * w for w in widths))
    for row in rows:
        print(line(row))
    for note in notes:
        print(f"  {note}")
    sys.stdout.flush()


def fmt(x: float, digits: int = 3) -> str:
    """A number in a table cell: ``digits`` significant digits, no exponent for usual sizes."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if math.isinf(x):
        return "inf"
    if x == 0:
        return "0"
    a = abs(x)
    if a >= 10 ** digits or a < 1e-3:
        return f"{x:.{max(digits - 1, 1)}e}"
    decimals = max(digits - 1 - math.floor(math.log10(a)), 0)
    return f"{x:.{decimals}f}"


def ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.nan


def load_make_samples() -> ModuleType:
    """``samples/shots/make_samples.py`` as a module.

    Registered in ``sys.modules`` before it runs (its dataclasses need that), under the name
    ``bench/bench_batch.py`` also loads it by, so both share one module object.
    """
    name = "camtraj_make_samples"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, ROOT / "samples/shots/make_samples.py")
    if spec is None or spec.loader is None:
        msg = "cannot load samples/shots/make_samples.py"
        raise ImportError(msg)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def machine_header() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    try:
        for text_line in Path("/proc/cpuinfo").read_text().splitlines():
            if text_line.startswith("model name"):
                cpu = text_line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "date": dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "cores": os.cpu_count(),
        "cpu": cpu,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "camtraj": getattr(camtraj, "__version__", "?"),
        "platform": platform.platform(),
        "load_avg_1min_at_start": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
    }


# ---------------------------------------------------------------------------------------------
# Table 1: sequential IK over the one-minute path
# ---------------------------------------------------------------------------------------------


def profile_summary(prof: cProfile.Profile, n_frames: int, top: int = 5) -> dict[str, Any]:
    """Top functions by cumulative time below the entry wrappers, and by own time."""
    stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
    rows = []
    for (file, lineno, func), (_cc, nc, tt, ct, _callers) in stats.items():
        where = "builtin" if file == "~" else f"{Path(file).name}:{lineno}"
        rows.append({"function": func, "where": where, "calls": nc, "own_s": tt, "cum_s": ct})
    total = max(r["cum_s"] for r in rows)

    # the entry chain (solve_path > solve_path_report > solve_ik > ...): called once per run or
    # once per frame, holding nearly all the time; the work below it is what limits the speed
    def is_wrapper(r: dict[str, Any]) -> bool:
        return bool(r["cum_s"] >= 0.9 * total and r["calls"] in (1, n_frames))

    wrappers = sorted((r for r in rows if is_wrapper(r)), key=lambda r: -r["cum_s"])
    inner = sorted((r for r in rows if not is_wrapper(r)),
                   key=lambda r: r["cum_s"], reverse=True)[:top]
    own = sorted(rows, key=lambda r: r["own_s"], reverse=True)[:3]
    for r in inner + own:
        r["pct"] = 100.0 * r["cum_s"] / total
        r["own_pct"] = 100.0 * r["own_s"] / total
        r["calls_per_frame"] = r["calls"] / n_frames
    return {"total_s": total, "wrappers": [r["function"] for r in wrappers],
            "top_cumulative": inner, "top_own": own}


def bench_sequential(robot: Robot, targets: np.ndarray, repeats: int, slsqp_frames: int,
                     traverse_every: int) -> dict[str, Any]:
    n = targets.shape[0]
    out: dict[str, Any] = {"frames": n, "repeats": repeats}
    reports: dict[str, ik.PathSolution] = {}
    ik.solve_path_report(robot, targets[:24], frame_interval=1.0 / FPS)  # lazy imports
    for obj in ("shot", "paper"):
        walls = []
        for r in range(repeats):
            log(f"table 1: solve_path objective={obj}, run {r + 1}/{repeats}")
            t0 = time.perf_counter()
            rep = ik.solve_path_report(robot, targets, robot.home, objective=obj,
                                       frame_interval=1.0 / FPS)
            walls.append(time.perf_counter() - t0)
        reports[obj] = rep
        wall = statistics.median(walls)
        out[obj] = {
            "wall_s": walls, "median_wall_s": wall, "fps": n / wall,
            "sum_F": float(rep.cost.sum()),
            "over_velocity_frames": int((~rep.within_step).sum()),
        }

    # baseline: generic SLSQP warm-started frame by frame (paper objective), first frames only
    m = min(slsqp_frames, n)
    log(f"table 1: SLSQP warm-started over the first {m} frames")
    t0 = time.perf_counter()
    _, sl_cost, sl_failed = base.slsqp_path(robot, targets[:m], robot.home)
    sl_wall = time.perf_counter() - t0
    out["slsqp"] = {"frames": m, "wall_s": sl_wall, "fps": m / sl_wall,
                    "failed_frames": sl_failed, "sum_F": float(sl_cost.sum()),
                    "sm_sum_F_same_frames": float(reports["paper"].cost[:m].sum())}

    # optimality: every (or every k-th) frame against a dense traversal from the same previous
    rep = reports["paper"]
    idx = np.arange(0, n, traverse_every)
    log(f"table 1: dense traversal check of {idx.size} frames (paper objective)")
    f_sm = rep.cost[idx]
    f_tr = np.empty(idx.size)
    t0 = time.perf_counter()
    w_min = float(min(robot.weights[0], robot.weights[3]))
    for j, i in enumerate(idx):
        prev = robot.home if i == 0 else rep.q[i - 1]
        radius = f_sm[j] / w_min * 1.001 + 1e-6
        f_tr[j] = ik.traverse(robot, targets[i], prev, radius=radius, n1=41, n4=21,
                              refine=3).cost
    tr_wall = time.perf_counter() - t0
    gap = f_sm - f_tr
    rel = gap / np.maximum(f_tr, 1e-12)
    within = f_sm <= f_tr * (1.0 + WITHIN) + 1e-9
    k = int(np.argmax(rel))
    out["check"] = {
        "frames_checked": int(idx.size), "within_0.1pct": int(within.sum()),
        "worst_rel_gap": float(rel[k]), "worst_abs_gap": float(gap[k]),
        "worst_frame": int(idx[k]), "worst_F_solver": float(f_sm[k]),
        "worst_F_traversal": float(f_tr[k]),
        "solver_better_frames": int((gap < -1e-9).sum()),
        "traversal_wall_s": tr_wall, "traversal_fps": idx.size / tr_wall,
    }

    log("table 1: cProfile of one shot run")
    prof = cProfile.Profile()
    prof.enable()
    ik.solve_path(robot, targets, robot.home, frame_interval=1.0 / FPS)
    prof.disable()
    out["profile"] = profile_summary(prof, n)
    return out


def print_sequential(res: dict[str, Any]) -> None:
    n = res["frames"]
    sl = res["slsqp"]
    paper_fps = res["paper"]["fps"]
    rows = []
    for obj in ("shot", "paper"):
        r = res[obj]
        rows.append([
            f"camtraj {obj}" + (" (default)" if obj == "shot" else ""), str(n),
            fmt(r["median_wall_s"]), fmt(r["fps"]), fmt(r["fps"] / TARGET_FPS),
            fmt(ratio(r["fps"], paper_fps)), fmt(ratio(r["fps"], sl["fps"])),
            str(r["over_velocity_frames"]),
        ])
    rows.append([f"SLSQP warm (paper F, first {sl['frames']} frames)", str(sl["frames"]),
                 fmt(sl["wall_s"]), fmt(sl["fps"]), fmt(sl["fps"] / TARGET_FPS),
                 fmt(ratio(sl["fps"], paper_fps)), "1.00", "-"])
    table(
        f"1a. Sequential IK over {n} frames of the 1-minute path (24 fps; median of "
        f"{res['repeats']} runs)",
        ["method / objective", "frames", "median wall [s]", "frames/s",
         f"x target ({TARGET_FPS:g} frames/s)", "x paper (same run)", "x SLSQP warm (same run)",
         "steps over v_max"],
        rows,
        [f"SLSQP warm-started: {sl['failed_frames']} of {sl['frames']} frames missed the pose; "
         f"its summed F over those frames {fmt(sl['sum_F'], 5)} vs SM "
         f"{fmt(sl['sm_sum_F_same_frames'], 5)} "
         f"(x{fmt(ratio(sl['sum_F'], sl['sm_sum_F_same_frames']), 4)}).",
         "steps over v_max: frames whose step from the previous frame exceeds an axis's velocity "
         "limit times the frame interval (a branch flip is one).",
         "The machine is shared: read the ratios (same run), not the absolute frames/s.",
         NUMBA_NOTE],
    )
    c = res["check"]
    table(
        "1b. Optimality of SM (paper objective) vs a dense traversal seeded with the solver's "
        "previous frame (n1=41, n4=21, refine=3)",
        ["frames checked", "within 0.1% of traversal F", "worst gap [% of F]",
         "worst gap [F units]", "at frame (0-based)", "F solver / F traversal there",
         "frames where SM < traversal"],
        [[str(c["frames_checked"]), f"{c['within_0.1pct']}/{c['frames_checked']}",
          fmt(100 * c["worst_rel_gap"]), fmt(c["worst_abs_gap"]), str(c["worst_frame"]),
          f"{fmt(c['worst_F_solver'], 6)} / {fmt(c['worst_F_traversal'], 6)}",
          str(c["solver_better_frames"])]],
        [f"traversal speed (baseline, same run): {fmt(c['traversal_fps'])} frames/s; SM paper is "
         f"x{fmt(ratio(res['paper']['fps'], c['traversal_fps']))} that."],
    )
    p = res["profile"]
    rows = [[r["function"], r["where"], str(r["calls"]), fmt(r["calls_per_frame"]),
             fmt(r["cum_s"]), fmt(r["pct"]), fmt(r["own_pct"])] for r in p["top_cumulative"]]
    top, own = p["top_cumulative"][0], p["top_own"][0]
    table(
        f"1c. cProfile of one shot run ({fmt(p['total_s'])} s under the profiler's overhead): "
        f"top 5 by "
        f"cumulative time below the entry chain ({' > '.join(p['wrappers'])})",
        ["function", "where", "calls", "calls per frame", "cumulative [s]", "cumulative [%]",
         "own time [%]"],
        rows,
        [f"what limits it: {fmt(top['pct'])}% of the time is inside {top['function']} "
         f"({top['calls']} calls); the largest own "
         f"time is {own['function']} ({own['where']}, {fmt(own['own_pct'])}%, "
         f"{own['calls']} calls, {fmt(1e6 * own['own_s'] / max(own['calls'], 1))} us each)."],
    )


# ---------------------------------------------------------------------------------------------
# Table 2: cold single-pose solves
# ---------------------------------------------------------------------------------------------


def sm_cold(robot: Robot, target: np.ndarray, prev: np.ndarray) -> base.BaselineResult:
    try:
        sol = ik.solve_ik(robot, target, prev)
    except UnreachableError as exc:
        return base.BaselineResult(np.full(8, np.nan), math.inf, 0, False, str(exc))
    return base.BaselineResult(sol.q, sol.cost, 0, True, "ok")


METHODS: dict[str, Callable[[Robot, np.ndarray, np.ndarray], base.BaselineResult]] = {
    "SM (solve_ik, paper)": sm_cold,
    "generic SLSQP (8 axes)": base.slsqp_ik,
    "GM rebuilt (DE + pattern search)": base.gm_ik,
    "dense traversal (401x101, refine 2)": base.dense_ik,
}


def cold_poses(robot: Robot, n: int, seed: int = 0) -> list[tuple[str, np.ndarray]]:
    """``n`` random reachable poses (FK inside limits shrunk by 4 cm / 4 deg), then the GA
    paper's target."""
    rng = np.random.default_rng(seed)
    m = np.where(PRISMATIC, 0.04, math.radians(4.0))
    qs = rng.uniform(robot.lower + m, robot.upper - m, size=(n, 8))
    poses = [(f"random {i}", robot.fk(q)) for i, q in enumerate(qs)]
    paper = np.eye(4)
    paper[:3, 3] = (5.0, 1.5, 1.5)
    poses.append(("GA paper case", paper))
    return poses


def bench_cold(robot: Robot, n_random: int) -> dict[str, Any]:
    poses = cold_poses(robot, n_random)
    prev = np.zeros(8)
    # warm-up: first calls pay for lazy imports and caches
    for fn in METHODS.values():
        fn(robot, poses[0][1], prev)
    times: dict[str, list[float]] = {name: [] for name in METHODS}
    costs: dict[str, list[float]] = {name: [] for name in METHODS}
    ok: dict[str, list[bool]] = {name: [] for name in METHODS}
    msgs: dict[str, list[str]] = {name: [] for name in METHODS}
    for k, (label, target) in enumerate(poses):
        log(f"table 2: pose {k + 1}/{len(poses)} ({label})")
        for name, fn in METHODS.items():
            t0 = time.perf_counter()
            res = fn(robot, target, prev)
            times[name].append(time.perf_counter() - t0)
            good = base.reaches(robot, res.q, target)
            ok[name].append(good)
            costs[name].append(res.cost if good else math.inf)
            if not good:
                msgs[name].append(f"{label}: {res.message}")
    cost = np.array([costs[name] for name in METHODS])  # (methods, poses)
    best = cost.min(axis=0)
    out: dict[str, Any] = {"poses": len(poses), "methods": {}}
    sm_median = statistics.median(times[next(iter(METHODS))])
    for m_i, name in enumerate(METHODS):
        reached = np.array(ok[name])
        gaps = (cost[m_i] - best) / np.maximum(best, 1e-12)
        gaps = gaps[reached & np.isfinite(best)]
        med_t = statistics.median(times[name])
        out["methods"][name] = {
            "median_s": med_t, "solves_per_s": len(poses) / sum(times[name]),
            "x_sm_time": med_t / sm_median,
            "median_gap": float(np.median(gaps)) if gaps.size else math.nan,
            "worst_gap": float(gaps.max()) if gaps.size else math.nan,
            "success": int(reached.sum()), "failures": msgs[name][:5],
            "paper_case_F": float(cost[m_i, -1]), "paper_case_s": times[name][-1],
        }
    return out


def print_cold(res: dict[str, Any]) -> None:
    n = res["poses"]
    rows = []
    for name, r in res["methods"].items():
        rows.append([name, fmt(1e3 * r["median_s"]), fmt(r["solves_per_s"]), fmt(r["x_sm_time"]),
                     fmt(100 * r["median_gap"]), fmt(100 * r["worst_gap"]),
                     f"{r['success']}/{n}"])
    notes = ["F gap = (F - best F any method found for that pose) / best F, over the poses the "
             "method reached; reached = within 1e-6 m and 1e-6 rad and inside the limits."]
    for name, r in res["methods"].items():
        for f in r["failures"][:3]:
            notes.append(f"{name} missed {f[:110]}")
    table(
        f"2a. Cold single-pose solves from home (zeros): {n - 1} random reachable poses + the "
        "GA paper's case",
        ["method", "median time/pose [ms]", "solves/s (poses / total time)",
         "time x SM (median, same run)", "median F gap [%]", "worst F gap [%]", "reached"],
        rows, notes,
    )
    rows = [[name, fmt(r["paper_case_F"], 7), fmt(1e3 * r["paper_case_s"])]
            for name, r in res["methods"].items()]
    table(
        "2b. The GA paper's case: target (5, 1.5, 1.5) m, identity rotation, from zeros "
        "(the paper's published best: F = 70283)",
        ["method", "F [per-m/per-rad weights]", "time [ms]"], rows,
    )


# ---------------------------------------------------------------------------------------------
# Table 3: end-to-end convert
# ---------------------------------------------------------------------------------------------


def bench_convert(shot: Path, repeats: int, work: Path) -> dict[str, Any]:
    """Time ``convert`` with default options and the USD rig layer (``--usd``, its own stage
    "rig"); if the default (film timing) is infeasible, record why and time
    ``timing="scale"`` instead."""
    if importlib.util.find_spec("camtraj.convert") is None:
        return {"skipped": "convert not available (camtraj/convert.py does not exist yet)"}
    try:
        from camtraj.convert import ConvertOptions, convert
        from camtraj.errors import InfeasibleError
        options = ConvertOptions()
    except Exception as exc:  # report whatever stops it, keep benchmarking
        return {"skipped": f"convert not usable: {type(exc).__name__}: {exc}"}
    walls: list[float] = []
    stages: dict[str, list[float]] = {}
    size = 0
    default_error = None
    r = 0
    while r < repeats:
        log(f"table 3: convert run {r + 1}/{repeats} (timing={options.timing})")
        output = work / f"convert_{r}.mcap"
        t0 = time.perf_counter()
        try:
            summary = convert(shot, output, options,
                              rig_layer=work / f"convert_{r}.rig.usda")
        except InfeasibleError as exc:
            if default_error is not None:
                return {"skipped": f"convert failed: {type(exc).__name__}: {exc}",
                        "default_error": default_error}
            default_error = f"{type(exc).__name__}: {exc}"
            options = ConvertOptions(timing="scale")
            continue
        except Exception as exc:
            return {"skipped": f"convert failed: {type(exc).__name__}: {exc}"}
        walls.append(time.perf_counter() - t0)
        for key, value in dict(summary.get("timings", {})).items():
            stages.setdefault(key, []).append(float(value))
        size = output.stat().st_size if output.exists() else 0
        r += 1
    # the stage split of the median run (medians of parts would not add up to the median)
    mid = sorted(range(len(walls)), key=lambda i: walls[i])[len(walls) // 2]
    # the command in a new process: start-up and imports included
    exe = Path(sys.executable).with_name("camtraj")
    cli_walls = []
    for r in range(repeats):
        log(f"table 3: camtraj convert in a new process, run {r + 1}/{repeats}")
        cmd = [str(exe), "convert", str(shot), "-o", str(work / "cli.mcap"), "--quiet",
               "--timing", options.timing]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        cli_walls.append(time.perf_counter() - t0)
        if proc.returncode != 0:
            cli_walls = [math.nan]
            break
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    python_start = time.perf_counter() - t0
    log("table 3: the MCAP writer's peak memory (tracemalloc)")
    return {"writer_memory": writer_memory(shot, options, work / "writer.mcap"),
            "wall_s": walls, "median_wall_s": walls[mid],
            "cli_wall_s": cli_walls, "cli_median_wall_s": statistics.median(cli_walls),
            "python_start_s": python_start,
            "stages_s": {k: v[mid] for k, v in stages.items() if len(v) == len(walls)},
            "stages_all_runs_s": stages,
            "mcap_bytes": size, "repeats": repeats, "timing": options.timing,
            "default_error": default_error}


def writer_memory(shot: Path, options: Any, output: Path) -> dict[str, Any]:
    """tracemalloc's peak while ``write_take_to`` writes the converted shot (issue 14 §5), per
    film frame, against two sizes from the same take: its arrays (``TakeData``) and its one
    /joint_trajectory message (every servo sample, which the MCAP writer copies while it
    compresses the chunk holding it)."""
    import tracemalloc

    from mcap.reader import make_reader

    from camtraj.convert import analyse, metadata, take_data
    from camtraj.mcap_io import TOPIC_TRAJECTORY, write_take_to

    analysis = analyse(shot, options)
    take = take_data(analysis)
    info = metadata(analysis, shot, options)
    n = len(take.frame_times)
    arrays = sum(v.nbytes for v in vars(take).values() if isinstance(v, np.ndarray))
    tracemalloc.start()
    with output.open("wb") as stream:
        write_take_to(stream, take, analysis.robot, info)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    with output.open("rb") as stream:
        traj = sum(len(m.data) for _s, _c, m in
                   make_reader(stream).iter_messages(topics=[TOPIC_TRAJECTORY]))
    return {"frames": n, "servo_samples": len(take.t), "peak_bytes": peak,
            "take_array_bytes": arrays, "trajectory_message_bytes": traj,
            "mcap_bytes": output.stat().st_size}


def convert_memory(work: Path, n_frames: int) -> dict[str, Any]:
    """tracemalloc's peak in each stage of one ``convert`` (issue 14 §5) of make_samples' long
    move spread over ``n_frames`` at FPS (table 3's move, slower), and what each stage found
    held when it began, against the size of the take's servo-rate arrays (same run)."""
    import tracemalloc
    from contextlib import contextmanager

    import camtraj.convert as conv

    shot = load_make_samples().write_long_shot(work / f"memory_{n_frames}.usda",
                                               n_frames=n_frames, fps=FPS)
    stages: dict[str, dict[str, int]] = {}
    plain = conv._stage
    takes: list[Any] = []

    @contextmanager
    def measured(timings: dict[str, float], name: str) -> Any:
        held = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        with plain(timings, name):
            yield
        stages[name] = {"held_bytes": held, "peak_bytes": tracemalloc.get_traced_memory()[1]}

    real_analyse = conv.analyse

    def analyse(*args: Any, **kwargs: Any) -> Any:
        analysis = real_analyse(*args, **kwargs)
        takes.append(analysis.take)
        return analysis

    conv._stage, conv.analyse = measured, analyse  # type: ignore[assignment]
    tracemalloc.start()
    try:
        conv.convert(shot, work / "memory.mcap", conv.ConvertOptions())
    except Exception as exc:
        return {"skipped": f"convert failed: {type(exc).__name__}: {exc}"}
    finally:
        tracemalloc.stop()
        conv._stage, conv.analyse = plain, real_analyse  # type: ignore[assignment]
    take = takes[0]
    arrays = sum(a.nbytes for a in (take.t, take.q, take.qd, take.qdd, take.qddd))
    return {"frames": n_frames, "servo_samples": int(take.t.size), "stages": stages,
            "take_array_bytes": arrays}


def print_convert_memory(mem: dict[str, Any]) -> None:
    if "skipped" in mem:
        print(f"\n3b. convert's memory by stage: skipped: {mem['skipped']}")
        return
    n, take = mem["frames"], mem["take_array_bytes"]
    rows = [[name, fmt(v["held_bytes"] / n / 1e3), fmt(v["peak_bytes"] / n / 1e3),
             fmt(ratio(v["peak_bytes"], take))] for name, v in mem["stages"].items()]
    table(
        f"3b. convert's peak memory per film frame by stage (tracemalloc, one run of a "
        f"{n}-frame shot, default options)",
        ["stage", "held at start [KB/frame]", "peak [KB/frame]", "peak x take arrays"], rows,
        [f"the take's servo-rate arrays (t, q, qd, qdd, qddd; {mem['servo_samples']} samples): "
         f"{fmt(take / n / 1e3)} KB per film frame; the peak counts everything traced, what "
         "was held when the stage began included; numpy's own allocations are traced, "
         "USD's and the interpreter's start-up are not"],
    )


def bench_optimal(robot: Robot, shots: dict[str, Path]) -> list[dict[str, Any]]:
    """Table 3c: per shot, the timing stage (``time_shot``) with ``optimal`` and with ``scale``
    timing (the shot's own where it fits) on the default objective's joint path: CPU [s], one
    call each, and the take's length [s]."""
    from camtraj.ik import camera_holds, solve_path
    from camtraj.timing import Limits, time_shot

    limits = Limits.from_robot(robot)
    rows = []
    for name, path in shots.items():
        log(f"table 3c: --timing optimal on {name}")
        shot = read_shot(path)
        q = solve_path(robot, shot.cam2world @ np.linalg.inv(robot.camera2flange),
                       frame_interval=1.0 / shot.fps)
        hold = camera_holds(shot.cam2world)
        row: dict[str, Any] = {"shot": name, "frames": int(q.shape[0])}
        for mode in ("scale", "optimal"):
            t0 = time.process_time()
            take = time_shot(q, shot.times, limits, mode=mode, frame_numbers=shot.frames,
                             hold=hold)
            row[f"{mode}_cpu_s"] = time.process_time() - t0
            row[f"{mode}_take_s"] = float(take.t[-1])
        rows.append(row)
    return rows


def print_optimal(rows: list[dict[str, Any]]) -> None:
    table(
        "3c. --timing optimal against --timing scale on the same joint path (the timing stage "
        "alone, one call each, CPU)",
        ["shot", "frames", "scale: take [s]", "optimal: take [s]", "scale: CPU [s]",
         "optimal: CPU [s]", "optimal CPU / frame [ms]"],
        [[r["shot"], str(r["frames"]), fmt(r["scale_take_s"]), fmt(r["optimal_take_s"]),
          fmt(r["scale_cpu_s"]), fmt(r["optimal_cpu_s"]),
          fmt(1e3 * r["optimal_cpu_s"] / r["frames"])] for r in rows],
    )


def print_convert(res: dict[str, Any], shot_seconds: float, bare_ik_s: float) -> None:
    if "skipped" in res:
        print(f"\n3. End-to-end convert: skipped: {res['skipped']}")
        return
    wall = res["median_wall_s"]
    stages = {k: v for k, v in res["stages_s"].items() if k != "total"}
    rows = [[k, fmt(v), fmt(100 * v / wall)] for k, v in stages.items()]
    rest = wall - sum(stages.values())
    rows.append(["(outside the stages)", fmt(rest), fmt(100 * rest / wall)])
    rows.append(["total wall", fmt(wall), "100"])
    ik_s = res["stages_s"].get("ik", math.nan)
    dominant = max(stages, key=lambda k: stages[k]) if stages else "?"
    table(
        f"3. End-to-end convert of the 1-minute shot (timing={res['timing']}; the median of "
        f"{res['repeats']} runs by wall time; MCAP {res['mcap_bytes'] / 1e6:.2f} MB)",
        ["stage", "wall [s]", "share [%]"], rows,
        [*([f"default options (timing=shot) FAILED, so timed with timing=scale: "
            f"{res['default_error'][:300]}"] if res.get("default_error") else []),
         f"`camtraj convert` in a new process (start-up, imports, convert, write): "
         f"{fmt(res['cli_median_wall_s'])} s (median of {len(res['cli_wall_s'])}), "
         f"x target ({TARGET_CONVERT_S:g} s): {fmt(res['cli_median_wall_s'] / TARGET_CONVERT_S)}"
         f"; a bare `python -c pass` takes {fmt(res['python_start_s'])} s here",
         f"in-process total x target ({TARGET_CONVERT_S:g} s): {fmt(wall / TARGET_CONVERT_S)}; "
         f"x real time ({shot_seconds:g} s shot): {fmt(shot_seconds / wall)} faster; "
         f"dominant stage: {dominant}",
         f"IK stage vs bare solve_path at table 1's shot speed (same run, same frames): "
         f"x{fmt(ratio(ik_s, bare_ik_s))}",
         f"USD rig layer (--usd, stage 'rig') adds "
         f"{fmt(100 * ratio(stages.get('rig', math.nan), wall - stages.get('rig', math.nan)))}"
         f" % to the convert without it (same runs)",
         *_writer_memory_note(res.get("writer_memory"))],
    )


def _writer_memory_note(mem: dict[str, Any] | None) -> list[str]:
    if not mem:
        return []
    n = mem["frames"]
    return [f"MCAP writer peak memory (tracemalloc, writing the same take): "
            f"{fmt(mem['peak_bytes'] / n / 1e3)} KB per film frame; x the take's arrays "
            f"({fmt(mem['take_array_bytes'] / n / 1e3)} KB/frame): "
            f"{fmt(ratio(mem['peak_bytes'], mem['take_array_bytes']))}; x its /joint_trajectory "
            f"message ({fmt(mem['trajectory_message_bytes'] / n / 1e3)} KB/frame, "
            f"{mem['servo_samples']} servo samples): "
            f"{fmt(ratio(mem['peak_bytes'], mem['trajectory_message_bytes']))}"]


# ---------------------------------------------------------------------------------------------
# Table 4: batch
# ---------------------------------------------------------------------------------------------


def bench_batch(quick: bool, est_shot_s: float) -> dict[str, Any]:
    path = HERE / "bench_batch.py"
    if not path.is_file():
        return {"skipped": "bench/bench_batch.py does not exist"}
    if importlib.util.find_spec("camtraj.convert") is None:
        return {"skipped": "camtraj batch needs camtraj/convert.py, which does not exist yet"}
    if not (ROOT / "camtraj" / "cli.py").is_file() and not (ROOT / "camtraj/__main__.py").is_file():
        return {"skipped": "camtraj batch needs the camtraj command line (camtraj/cli.py)"}
    spec = importlib.util.spec_from_file_location("bench_batch", path)
    if spec is None or spec.loader is None:
        return {"skipped": "cannot load bench/bench_batch.py"}
    module = importlib.util.module_from_spec(spec)
    sys.modules["bench_batch"] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        return {"skipped": f"bench_batch.py does not import: {type(exc).__name__}: {exc}"}
    if not hasattr(module, "run"):
        return {"skipped": "bench/bench_batch.py has no run()"}
    # the setting: 20 copies of a 10-second shot (fewer with --quick)
    frames = 120 if quick else 240
    copies = 8 if quick else 20
    repeats = 1 if quick or copies * est_shot_s * 1.5 * 3 > 120.0 else 3
    log(f"table 4: bench_batch.run(copies={copies}, frames={frames}, repeats={repeats})")
    try:
        result = module.run(lambda s: log(f"table 4: {s}"), copies=copies, frames=frames,
                            repeats=repeats)
    except Exception as exc:
        return {"skipped": f"bench_batch.run failed: {type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=3)}
    return {"args": {"copies": copies, "frames": frames, "repeats": repeats},
            "result": dict(result)}


def print_batch(res: dict[str, Any]) -> None:
    if "skipped" in res:
        print(f"\n4. Batch: skipped: {res['skipped']}")
        return
    a = res["args"]
    rows = []
    for key, value in res["result"].items():
        unit = "[s]" if key.endswith("_s") else "[x, jobs-1 time / jobs-2 time]" if (
            key.startswith("speedup")) else ""
        rows.append([f"{key} {unit}".strip(), fmt(float(value))])
    notes = ["meanings: see the docstring of bench/bench_batch.py"]
    if float(res["result"].get("long_shot_feasible", 1.0)) == 0.0:
        notes.insert(0, f"the {a['frames']}-frame long shot is infeasible under --timing shot, so "
                        "bench_batch.py batched copies of blender_crane_up.usda (96 frames)")
    failed = float(res["result"].get("failed_shots", 0.0))
    if failed:
        runs = a["copies"] * a["repeats"] * 2
        notes.insert(0, f"WARNING: {failed:g} of {runs} shot conversions FAILED, so these times "
                        "are of failing conversions (see table 3 for why the default fails)")
    table(
        f"4. Batch (bench/bench_batch.py run(copies={a['copies']}, frames={a['frames']}, "
        f"repeats={a['repeats']}); its medians",
        ["figure", "value"], rows, notes,
    )


# ---------------------------------------------------------------------------------------------
# Table 5: maximum feasible speed per shot of the set (issue 13): default vs paper vs 10x effort
# ---------------------------------------------------------------------------------------------

_BASE_SOLVE = """
import sys, numpy as np
from camtraj.ik import solve_path_report
from camtraj.robot import Robot
data = np.load(sys.argv[1])
robot = Robot.default()
out = {}
for key in data.files:
    if not key.startswith("t_"):
        continue
    name = key[len("t_"):]
    fps = float(data["fps_" + name])
    try:
        out[name] = solve_path_report(robot, data[key], frame_interval=1.0 / fps).q
    except Exception as exc:  # report it as a missing value
        print(f"{name}: {type(exc).__name__}: {exc}", file=sys.stderr)
np.savez(sys.argv[2], **out)
"""


def export_revision(rev: str, work: Path) -> tuple[Path | None, str]:
    """The tree at git revision ``rev`` in ``work`` (once), or None and why not."""
    tree = work / f"camtraj-{rev}"
    if tree.is_dir():
        return tree, ""
    tree.mkdir()
    try:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], capture_output=True,
                                 check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        return None, f"cannot export revision {rev}: {exc}"
    return tree, ""


def base_paths(shots: list[Any], rev: str, work: Path) -> tuple[dict[str, Any], str]:
    """Solve the shots with the default objective of the tree at git revision ``rev``."""
    tree, why = export_revision(rev, work)
    if tree is None:
        return {}, why
    keys = {s.name: f"s{i}" for i, s in enumerate(shots)}  # npz keys: no odd characters
    np.savez(work / "set.npz", **{f"t_{keys[s.name]}": s.targets for s in shots},
             **{f"fps_{keys[s.name]}": np.array(s.fps) for s in shots})
    env = dict(os.environ, PYTHONPATH=str(tree))
    proc = subprocess.run([sys.executable, "-c", _BASE_SOLVE, str(work / "set.npz"),
                           str(work / "base.npz")], env=env, capture_output=True, text=True,
                          check=False, cwd=str(work))
    if proc.returncode != 0:
        return {}, f"revision {rev} failed: {proc.stderr.strip()[-300:]}"
    data = np.load(work / "base.npz")
    return {name: data[k] for name, k in keys.items() if k in data.files}, proc.stderr.strip()


def bench_speeds(robot: Robot, rev: str, work: Path, quick: bool) -> dict[str, Any]:
    sys.path.insert(0, str(ROOT))
    from tests.shot_set import (
        EFFORT,
        acceptance_set,
        gentle_speed,
        max_speed,
        motion_end_set,
        speeds,
    )

    folder = work / "set"
    folder.mkdir()
    shots = acceptance_set(robot, folder, quick=quick)
    ends = motion_end_set(robot, folder)
    if quick:  # a subset: every third move, every third end-in-motion move
        shots, ends = shots[::3], ends[::3]
    log(f"table 5: the default objective of revision {rev} in a subprocess")
    base, note = base_paths(shots + ends, rev, work)
    rows = []
    for which, s in [("set", s) for s in shots] + [("end", s) for s in ends]:
        log(f"table 5: {s.name}")
        sp = speeds(robot, s, EFFORT)
        gentle = gentle_speed(robot, s)
        q_base = base.get(s.name)
        base_speed = (max_speed(robot, q_base, s.fps, s.targets) if q_base is not None
                      else math.nan)
        rows.append({"shot": s.name, "set": which,
                     "frames": int(s.targets.shape[0]), "fps": s.fps,
                     "default": sp.default, "paper": sp.paper, "effort": sp.effort,
                     "base": base_speed, "gentle": gentle})
    return {"rows": rows, "base_rev": rev, "base_note": note, "effort": EFFORT, "quick": quick}


def _speed_summary(rows: list[dict[str, Any]], effort: float, rev: str) -> list[str]:
    def real(key: str) -> str:
        ok = [r for r in rows if math.isfinite(r[key])]
        return f"{sum(r[key] >= 1.0 for r in ok)}/{len(ok)}"

    def med(key: str) -> str:
        xs = [ratio(r["default"], r[key]) for r in rows if r[key] > 0 and math.isfinite(r[key])]
        return f"x{fmt(statistics.median(xs))} (smallest x{fmt(min(xs))})" if xs else "-"

    return [f"at real time: default {real('default')}, paper {real('paper')}, {effort:g}x effort "
            f"{real('effort')}, default of {rev} {real('base')}",
            f"median default / paper {med('paper')}; default / {effort:g}x effort {med('effort')}; "
            f"default / default of {rev} {med('base')}"]


def _gentle_summary(rows: list[dict[str, Any]]) -> str:
    """What free ends (--edges gentle) gain over the default's still ends, where they differ."""
    pairs = [(r["default"], r["gentle"]) for r in rows
             if math.isfinite(r.get("gentle", math.nan)) and r["gentle"] > 0
             and abs(r["default"] / r["gentle"] - 1.0) > 1e-6]
    if not pairs:
        return "no move rests at an end"
    xs = [ratio(a, b) for a, b in pairs]
    lost = sum(b >= 1.0 > a for a, b in pairs)
    return (f"{len(pairs)} moves differ: default / gentle median x{fmt(statistics.median(xs))} "
            f"(x{fmt(min(xs))} to x{fmt(max(xs))}); moves at real time only with free ends: "
            f"{lost}")


def print_speeds(res: dict[str, Any]) -> None:
    k, rev = res["effort"], res["base_rev"]
    rows = []
    for r in res["rows"]:
        gentle = r.get("gentle", math.nan)
        rows.append([r["shot"], str(r["frames"]), fmt(r["fps"], 5), fmt(r["default"]),
                     fmt(r["paper"]), fmt(r["effort"]), fmt(r["base"]),
                     "yes" if r["default"] >= 1.0 else "no",
                     fmt(ratio(r["default"], r["paper"])), fmt(ratio(r["default"], r["effort"])),
                     fmt(gentle) if math.isfinite(gentle) else "-"])
    main_rows = [r for r in res["rows"] if r["set"] == "set"]
    end_rows = [r for r in res["rows"] if r["set"] == "end"]
    table(
        "5. Maximum feasible speed per shot (timing stage max_speed, fraction of real time): "
        f"default vs paper vs the default at {k:g}x effort vs the default of {rev}"
        + (" (--quick: a subset)" if res["quick"] else ""),
        ["shot", "frames", "fps", "default", "paper", f"{k:g}x effort", f"default {rev}",
         "real time", "default / paper", f"default / {k:g}x", "--edges gentle"],
        rows,
        [f"shot set ({len(main_rows)}): " + "; ".join(_speed_summary(main_rows, k, rev)),
         f"end-in-motion moves ({len(end_rows)}): "
         + "; ".join(_speed_summary(end_rows, k, rev)),
         f"{k:g}x effort: tests/shot_set.py with_effort (refine rounds, track and extend "
         "samples); the default of the base revision is solved there in a subprocess and timed "
         "by this tree's timing stage",
         "a path whose spline leaves a position limit between frames is given the speed its "
         "velocities, accelerations and jerks allow (the timing stage's number with the error); "
         "0: no speed at all (its run-up or run-out leaves a position limit)",
         "default: as convert runs it (--edges still: the robot still on an end frame where "
         "the camera rests), and so the 10x effort; paper with free ends (the papers' method); "
         "--edges gentle: the default with free ends (the robot may move on a still end "
         "frame); " + _gentle_summary(res["rows"]),
         *([f"base revision: {res['base_note'][:200]}"] if res.get("base_note") else [])],
    )


# ---------------------------------------------------------------------------------------------
# Table 5b: solver performance against the base revision (issue 13's figures)
# ---------------------------------------------------------------------------------------------

_PERF = """
import json, sys, time, tracemalloc, statistics
import numpy as np
t_import = time.perf_counter()
from camtraj.ik import solve_path
from camtraj.robot import Robot
t_import = time.perf_counter() - t_import
data = np.load(sys.argv[1])
repeats = int(sys.argv[3])
robot = Robot.default()
dt = 1.0 / 24.0
path = data["n1440"]
out = {"import_s": t_import}
t0 = time.perf_counter()
solve_path(robot, path, frame_interval=dt)
out["fresh_s"] = time.perf_counter() - t0
walls = []
for _ in range(repeats):
    t0 = time.perf_counter()
    solve_path(robot, path, frame_interval=dt)
    walls.append(time.perf_counter() - t0)
out["warm_s"] = statistics.median(walls)
t0 = time.perf_counter()
solve_path(robot, path, objective="paper", frame_interval=dt)
out["paper_s"] = time.perf_counter() - t0
sizes = {}
for key in sorted(data.files, key=lambda k: int(k[1:])):
    targets = data[key]
    runs = []
    for _ in range(max(1, min(repeats, 2880 // targets.shape[0]))):
        t0 = time.perf_counter()
        solve_path(robot, targets, frame_interval=dt)
        runs.append(time.perf_counter() - t0)
    wall = statistics.median(runs)
    tracemalloc.start()
    solve_path(robot, targets, frame_interval=dt)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    sizes[key[1:]] = {"wall_s": wall, "peak_bytes": peak}
out["sizes"] = sizes
json.dump(out, open(sys.argv[2], "w"))
"""


def long_targets(robot: Robot, n: int) -> np.ndarray:
    """Flange targets of make_samples' long move over ``n`` frames (no USD round trip)."""
    ms = load_make_samples()
    move = ms.long_move(n)
    cams = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        cams[i, :3, :3] = ms.cam2world_rotation(float(move.pan[i]), float(move.tilt[i]))
    cams[:, :3, 3] = move.positions
    out: np.ndarray = cams @ np.linalg.inv(robot.camera2flange)
    return out


def bench_perf(robot: Robot, targets_1440: np.ndarray, rev: str, work: Path,
               quick: bool) -> dict[str, Any]:
    """The default on the 1440-frame path fresh and warm, paper, cost per frame by length:
    this tree and the tree at ``rev``, each in its own new process."""
    sizes = (240, 1440) if quick else (240, 1440, 5760, 23040)
    arrays = {f"n{n}": targets_1440 if n == 1440 else long_targets(robot, n) for n in sizes}
    np.savez(work / "perf.npz", **arrays)
    out: dict[str, Any] = {"rev": rev, "sizes": list(sizes)}
    base_tree, why = export_revision(rev, work)
    runs: dict[str, list[dict[str, Any]]] = {"this tree": [], rev: []}
    for r in range(1 if quick else 2):  # alternate the trees: both see the same load
        for label, tree in (("this tree", ROOT), (rev, base_tree)):
            if tree is None:
                out[label] = {"error": why}
                continue
            log(f"table 5b: solver performance of {label} in a new process, run {r + 1}")
            env = dict(os.environ, PYTHONPATH=str(tree))
            result = work / "perf.json"
            proc = subprocess.run([sys.executable, "-c", _PERF, str(work / "perf.npz"),
                                   str(result), "1" if quick else "3"], env=env,
                                  capture_output=True, text=True, check=False, cwd=str(work))
            if proc.returncode != 0:
                out[label] = {"error": proc.stderr.strip()[-300:]}
                continue
            runs[label].append(json.loads(result.read_text()))
    for label, results in runs.items():
        if results and label not in out:  # the fastest of the runs: least disturbed by load
            best = {k: min(r[k] for r in results) for k in ("import_s", "fresh_s", "warm_s",
                                                            "paper_s")}
            best["sizes"] = {n: {"wall_s": min(r["sizes"][n]["wall_s"] for r in results),
                                 "peak_bytes": results[0]["sizes"][n]["peak_bytes"]}
                             for n in results[0]["sizes"]}
            out[label] = best
    out["paper_before"] = bench_paper_before(work, quick)
    return out


_PAPER = """
import json, sys, time
import numpy as np
from camtraj.ik import solve_path
from camtraj.robot import Robot
path = np.load(sys.argv[1])["n1440"]
robot = Robot.default()
solve_path(robot, path[:48], objective="paper", frame_interval=1.0 / 24.0)  # imports, caches
walls = []
for _ in range(int(sys.argv[3])):
    t0 = time.perf_counter()
    q = solve_path(robot, path, objective="paper", frame_interval=1.0 / 24.0)
    walls.append(time.perf_counter() - t0)
np.save(sys.argv[2] + ".npy", q)
with open(sys.argv[2] + ".json", "w") as f:
    json.dump({"paper_s": min(walls)}, f)
"""


def bench_paper_before(work: Path, quick: bool) -> dict[str, Any]:
    """``paper`` on the 1440-frame path, this tree and :data:`PAPER_REV` (before the shot
    objective) alternately in new processes: the faster run of each, and the largest
    difference between their joint paths (the same answers are expected)."""
    old, why = export_revision(PAPER_REV, work)
    if old is None:
        return {"error": why}
    walls: dict[str, list[float]] = {"this tree": [], PAPER_REV: []}
    paths: dict[str, Any] = {}
    for r in range(2 if quick else 3):
        for label, tree in (("this tree", ROOT), (PAPER_REV, old)):
            log(f"table 5b: paper of {label} in a new process, run {r + 1}")
            out = work / f"paper-{label.replace(' ', '-')}-{r}"
            proc = subprocess.run([sys.executable, "-c", _PAPER, str(work / "perf.npz"),
                                   str(out), "2"], env=dict(os.environ, PYTHONPATH=str(tree)),
                                  capture_output=True, text=True, check=False, cwd=str(work))
            try:
                if proc.returncode != 0:
                    raise ValueError(proc.stderr.strip()[-300:])
                walls[label].append(float(json.loads(
                    out.with_suffix(".json").read_text())["paper_s"]))
                paths[label] = np.load(out.with_suffix(".npy"))
            except (OSError, ValueError, KeyError) as exc:
                return {"error": f"{label}: {exc}"}
    return {"rev": PAPER_REV, **{k: min(v) for k, v in walls.items()},
            "max_joint_difference": float(np.abs(paths["this tree"] - paths[PAPER_REV]).max())}


def print_perf(res: dict[str, Any]) -> None:
    rev = res["rev"]
    now, base = res["this tree"], res[rev]
    if "error" in now:
        print(f"\n5b. Solver performance: failed: {now['error']}")
        return
    have_base = "error" not in base

    def cell(r: dict[str, Any], key: str, n: int = 1440) -> float:
        return n / r[key] if key in r else math.nan

    rows = []
    for label, key in (("default, fresh call (first in a new process) [frames/s]", "fresh_s"),
                       ("default, warm [frames/s]", "warm_s"),
                       ("paper [frames/s]", "paper_s")):
        a = cell(now, key)
        b = cell(base, key) if have_base else math.nan
        rows.append([label, f"{a:,.0f}", f"{b:,.0f}" if math.isfinite(b) else "-",
                     fmt(ratio(a, b))])
    for n in res["sizes"]:
        a = now["sizes"][str(n)]
        b = base["sizes"].get(str(n)) if have_base else None
        us_a, us_b = 1e6 * a["wall_s"] / n, 1e6 * b["wall_s"] / n if b else math.nan
        kb_a, kb_b = a["peak_bytes"] / n / 1e3, b["peak_bytes"] / n / 1e3 if b else math.nan
        rows.append([f"default, {n} frames: cost per frame [us]", fmt(us_a), fmt(us_b),
                     fmt(ratio(us_a, us_b))])
        rows.append([f"default, {n} frames: peak memory per frame [KB]", fmt(kb_a), fmt(kb_b),
                     fmt(ratio(kb_a, kb_b))])
    table(
        f"5b. Solver performance on the 1-minute path (1440 frames, 24 fps) and by length, this "
        f"tree vs revision {rev}, each in a new process",
        ["figure", "this tree", rev, f"this / {rev}"], rows,
        ["fresh: the first solve_path call after import (lazy imports and caches included); "
         "warm: median of the next calls; cost per frame (median of up to 3 calls) and memory "
         "(tracemalloc peak, a separate call) on make_samples' long move spread over n frames; "
         "the trees run alternately (twice each, the faster run kept; once with --quick)",
         "the machine is shared: read the ratios (same run), not the absolute figures",
         *([f"revision {rev}: {base['error'][:200]}"] if not have_base else []),
         _paper_before_note(res.get("paper_before"))],
    )


def _paper_before_note(res: dict[str, Any] | None) -> str:
    if not res:
        return "paper before the shot objective: not measured"
    if "error" in res:
        return f"paper before the shot objective: {res['error'][:200]}"
    rev, a, b = res["rev"], 1440 / res["this tree"], 1440 / res[res["rev"]]
    return (f"paper against revision {rev} (the last before the shot objective), alternating new "
            f"processes: {a:,.0f} vs {b:,.0f} frames/s, x{ratio(a, b):.3f}; largest joint "
            f"difference between their paths {res['max_joint_difference']:.3g}")


# ---------------------------------------------------------------------------------------------
# Table 6: placement search and collision checks
# ---------------------------------------------------------------------------------------------


def bench_place(quick: bool) -> dict[str, Any]:
    """``bench/bench_place.py``: camtraj place on a 10-second shot, collision cost per frame."""
    spec = importlib.util.spec_from_file_location("bench_place", HERE / "bench_place.py")
    if spec is None or spec.loader is None:
        return {"skipped": "cannot load bench/bench_place.py"}
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
        frames = 120 if quick else 240
        result = module.run(lambda s: log(f"table 6: {s}"), frames=frames)
        result.update(module.scene(lambda s: log(f"table 6: {s}"), frames=frames))
        return {"frames": frames, "result": result}
    except Exception as exc:
        return {"skipped": f"bench_place failed: {type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=3)}


def print_place(res: dict[str, Any]) -> None:
    if "skipped" in res:
        print(f"\n6. Placement: skipped: {res['skipped']}")
        return
    r = res["result"]
    rows = [
        ["camtraj place wall time [s] (target <= 30)", fmt(r["place_wall_s"])],
        ["placements solved / screened", f"{r['place_candidates']:.0f} / "
                                         f"{r['place_screened']:.0f}"],
        ["placements solved per second", fmt(r["place_candidates_per_s"])],
        ["place time / one full solve of the shot [x]", fmt(r["place_in_full_solves"])],
        ["collision check per film frame, 10,000 triangles [ms]",
         fmt(r["collision_ms_per_frame"])],
        ["  servo samples checked per frame", fmt(r["collision_samples_per_frame"])],
        ["  its cost / the IK's per frame [x]", fmt(r["collision_vs_ik"])],
        ["scene of 5 shots: place time [s] (its first shot alone)",
         f"{fmt(r['place_scene_s'])} ({fmt(r['place_single_s'])})"],
        ["  scene / first shot alone [x] (goal <= 2)", fmt(r["place_scene_ratio"])],
        ["  shot placements solved; one layout for all",
         f"{r['place_scene_solves']:.0f}; {'yes' if r['place_scene_ok'] else 'no'}"],
    ]
    table(f"6. Placement search ({res['frames']} frames, --jobs 2, default region) and "
          "collision checks (bench/bench_place.py)", ["figure", "value"], rows,
          ["placements solved: subsampled and full solves; screened: the cheap tests"])


# ---------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="shorter shot, fewer poses, one repeat (about a minute)")
    parser.add_argument("--json", type=Path, default=HERE / "results.json",
                        help="where to write the numbers (default: bench/results.json)")
    parser.add_argument("--base-rev", default=BASE_REV,
                        help="git revision whose default objective tables 5 and 5b compare "
                             f"against (default {BASE_REV})")
    args = parser.parse_args(argv)
    quick: bool = args.quick
    t_start = time.perf_counter()

    head = machine_header()
    head["mode"] = "quick" if quick else "full"
    print(f"camtraj bench ({head['mode']})  {head['date']}")
    print(f"machine: {head['cores']} cores, {head['cpu']}; Python {head['python']}, "
          f"numpy {head['numpy']}, scipy {head['scipy']}; {head['platform']}")
    print(f"load average (1 min) at start: {head['load_avg_1min_at_start']} "
          "(above 0 means other work shares the cores: timings are then noisier)")
    sys.stdout.flush()

    robot = Robot.default()
    n_frames = 1440  # long_move spreads one move over the frames: fewer frames = faster move
    results: dict[str, Any] = {"machine": head}
    with tempfile.TemporaryDirectory(prefix="camtraj-bench-") as tmp:
        work = Path(tmp)
        shot = work / "long_shot.usda"
        load_make_samples().write_long_shot(shot, n_frames=n_frames, fps=FPS)
        cam2worlds = read_shot(shot).cam2world
        targets = cam2worlds @ np.linalg.inv(robot.camera2flange)
        print(f"shot: write_long_shot, {targets.shape[0]} frames at {FPS:g} fps "
              f"({targets.shape[0] / FPS:g} s); robot: {robot.name}")

        seq_targets = targets[:360] if quick else targets
        seq = bench_sequential(robot, seq_targets, repeats=1 if quick else 3,
                               slsqp_frames=48 if quick else 72, traverse_every=1)
        results["sequential_ik"] = seq
        print_sequential(seq)

        cold = bench_cold(robot, n_random=8 if quick else 30)
        results["cold_solves"] = cold
        print_cold(cold)

        conv = bench_convert(shot, repeats=1 if quick else 3, work=work)
        results["convert"] = conv
        bare_ik = seq["shot"]["median_wall_s"] * targets.shape[0] / seq_targets.shape[0]
        print_convert(conv, targets.shape[0] / FPS, bare_ik)
        log("table 3b: convert's memory by stage (tracemalloc)")
        mem = convert_memory(work, 2000 if quick else 10_000)
        results["convert_memory"] = mem
        print_convert_memory(mem)

        samples = ROOT / "samples" / "shots"
        optimal_shots = {n: samples / f"{n}.usda"
                         for n in ("blender_crane_up", "maya_dolly_push_in", "whip_pan")}
        if not quick:
            optimal_shots["one-minute shot"] = shot
        results["optimal"] = bench_optimal(robot, optimal_shots)
        print_optimal(results["optimal"])

        speeds = bench_speeds(robot, args.base_rev, work, quick)
        results["speeds"] = speeds
        print_speeds(speeds)

        perf = bench_perf(robot, targets, args.base_rev, work, quick)
        results["solver_performance"] = perf
        print_perf(perf)

        from bench_report import bench_report, bench_report_file, print_report, print_report_file

        results["report"] = bench_report(shot, work)
        print_report(results["report"])
        try:
            results["report_file"] = bench_report_file(work, load_make_samples(), quick)
        except (subprocess.SubprocessError, OSError, ValueError) as exc:
            results["report_file"] = {"skipped": f"{type(exc).__name__}: {exc}"[-300:]}
        print_report_file(results["report_file"])

    est_shot = 240.0 / seq["shot"]["fps"] + 0.5
    batch = bench_batch(quick, est_shot)
    results["batch"] = batch
    print_batch(batch)

    place_res = bench_place(quick)
    results["place"] = place_res
    print_place(place_res)

    total = time.perf_counter() - t_start
    results["bench_wall_s"] = total
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    results["load_avg_1min_at_end"] = load
    print(f"\nbench wall time: {total:.0f} s; load average (1 min) at end: {load:.2f}; "
          f"numbers in {args.json}")
    args.json.write_text(json.dumps(results, indent=2, default=float) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
