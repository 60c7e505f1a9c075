"""Benchmark of ``camtraj batch``: parallel speed-up and per-shot overhead.

``run()`` converts ``copies`` copies of a long sample shot (``make_samples.write_long_shot``,
``frames`` frames) with ``camtraj batch --jobs 1`` and ``--jobs 2`` (each ``repeats`` times,
``--force``, through the real command line) and returns medians:

- ``batch_jobs1_s``, ``batch_jobs2_s``: wall time of the whole batch [s].
- ``speedup_jobs2``: jobs-1 time over jobs-2 time (target >= 1.8 on 2 cores).
- ``convert_mean_s``: mean time of one shot's ``convert`` inside a worker [s].
- ``batch_overhead_per_shot_s``: (jobs-1 wall time - sum of in-worker convert times) / shots:
  what the batch adds per shot (process pool start-up, imports, scheduling, report) [s].
- ``worker_cpu_per_shot_jobs1_s`` / ``..._jobs2_s``: CPU time per shot inside the workers;
  equal values mean the workers do not slow each other down (a jobs-2 wall time above the
  estimate below then means other processes were using the cores: see
  ``load_average_at_start``).
- ``speedup_jobs2_idle_estimate``: the jobs-2 speed-up an idle 2-core machine gives, from the
  measured fixed overhead and per-shot time.
- ``startup_imports_s``: a fresh ``python -c 'import camtraj.convert'`` [s]: what every single
  ``camtraj convert`` process pays before it starts working.
- ``long_shot_feasible``: 1 if the long shot converts under ``--timing shot``; else 0 and the
  batch uses copies of ``blender_crane_up.usda`` instead (96 frames).

Run it alone with ``python bench/bench_batch.py``.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples" / "shots"


def _camtraj() -> list[str]:
    if (ROOT / "camtraj" / "__main__.py").is_file():
        return [sys.executable, "-m", "camtraj"]
    return [str(Path(sys.executable).parent / "camtraj")]


def _long_shot(path: Path, frames: int) -> Path:
    maker = SAMPLES / "make_samples.py"
    spec = importlib.util.spec_from_file_location("camtraj_make_samples", maker)
    if spec is not None and spec.loader is not None:
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module  # dataclasses look their module up while executing
        spec.loader.exec_module(module)
        if hasattr(module, "write_long_shot"):
            module.write_long_shot(path, n_frames=frames, part=frames / 1440)
            return path
    shutil.copyfile(SAMPLES / "blender_crane_up.usda", path)
    return path


def _feasible(shot: Path, out: Path) -> bool:
    from camtraj.convert import ConvertOptions, convert
    from camtraj.errors import CamtrajError

    try:
        convert(shot, out, ConvertOptions())
    except CamtrajError:
        return False
    return True


def _timed(cmd: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run(cmd, check=False, capture_output=True)
    return time.perf_counter() - start


def run(
    report: Callable[[str], None] = print,
    *,
    copies: int = 20,
    frames: int = 240,
    repeats: int = 3,
) -> dict[str, float]:
    """Measure batch conversion; see the module docstring for the numbers returned.

    Args:
        report: Called with one line of progress text at a time.
        copies: Shots in the batch.
        frames: Frames per shot (240 = 10 s at 24 fps).
        repeats: Runs per configuration; medians are returned.
    """
    with tempfile.TemporaryDirectory(prefix="camtraj-bench-batch-") as tmp:
        work = Path(tmp)
        shots_dir = work / "shots"
        shots_dir.mkdir()
        first = _long_shot(shots_dir / "long_00.usda", frames)
        feasible = _feasible(first, work / "probe.mcap")
        if not feasible:
            report(f"the {frames}-frame long shot is infeasible; using blender_crane_up.usda")
            shutil.copyfile(SAMPLES / "blender_crane_up.usda", first)
        shots = [first]
        for i in range(1, copies):
            copy = shots_dir / f"long_{i:02d}.usda"
            shutil.copyfile(first, copy)
            shots.append(copy)

        walls: dict[int, list[float]] = {1: [], 2: []}
        cpu: dict[int, list[float]] = {1: [], 2: []}
        convert_sums: list[float] = []
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
        failed = 0
        for rep in range(repeats):
            for jobs in (1, 2):
                out = work / f"out{jobs}"
                cmd = [*_camtraj(), "batch", *map(str, shots), "-o", str(out)]
                cmd += ["--jobs", str(jobs), "--force", "--quiet"]
                wall = _timed(cmd)
                data = json.loads((out / "batch_report.json").read_text())
                failed += data["counts"]["failed"]
                walls[jobs].append(wall)
                cpu[jobs].append(sum(s.get("cpu_seconds", 0.0) for s in data["shots"]) / copies)
                if jobs == 1:
                    convert_sums.append(sum(s["seconds"] for s in data["shots"]))
                report(f"batch run {rep + 1}/{repeats}, --jobs {jobs}: {wall:.2f} s")
        startup = [_timed([sys.executable, "-c", "import camtraj.convert"]) for _ in range(repeats)]

    j1 = statistics.median(walls[1])
    j2 = statistics.median(walls[2])
    overheads = [(w - c) / copies for w, c in zip(walls[1], convert_sums, strict=True)]
    fixed = max(0.0, j1 - statistics.median(convert_sums))  # start-up, imports, report
    per_shot = statistics.median(convert_sums) / copies
    result = {
        "shots": float(copies),
        "frames_per_shot": float(frames),
        "batch_jobs1_s": j1,
        "batch_jobs2_s": j2,
        "speedup_jobs2": j1 / j2,
        "convert_mean_s": statistics.median(convert_sums) / copies,
        "batch_overhead_per_shot_s": statistics.median(overheads),
        "startup_imports_s": statistics.median(startup),
        "batch_fixed_overhead_s": fixed,
        "worker_cpu_per_shot_jobs1_s": statistics.median(cpu[1]),
        "worker_cpu_per_shot_jobs2_s": statistics.median(cpu[2]),
        # What --jobs 2 gives on an otherwise idle 2-core machine: the shots split over two
        # workers, the fixed overhead does not.
        "speedup_jobs2_idle_estimate": (fixed + copies * per_shot)
        / (fixed + math.ceil(copies / 2) * per_shot),
        "load_average_at_start": load,
        "failed_shots": float(failed),
        "long_shot_feasible": float(feasible),
    }
    for key, value in result.items():
        report(f"{key}: {value:.3f}")
    return result


if __name__ == "__main__":
    run()
