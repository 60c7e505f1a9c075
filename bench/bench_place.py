"""Benchmark of ``camtraj place`` and of the collision check.

``run()`` returns:

- ``place_wall_s``: wall time of ``camtraj place --json`` (the real command line, default
  search region, ``--jobs 2``) on the first 10 seconds of the long sample move (240 frames),
  moved to (-37, 52) m and turned by 121° on the floor [s] (target <= 30 s on 2 cores).
- ``place_candidates``, ``place_candidates_per_s``: placements solved (subsampled or full) and
  solved per second; ``place_screened``: candidates of the coarse grid put through the cheap
  tests.
- ``full_solve_s``: one full solve and timing of the same shot at its best placement, in this
  process (the baseline: ``place_wall_s / full_solve_s`` is what the search costs in full
  solves).
- ``collision_ms_per_frame``: the collision check of the placed take against a 10,000-triangle
  corrugated (non-convex) sheet beside the move, per film frame [ms];
  ``collision_samples_per_frame``: servo samples checked per film frame;
  ``collision_vs_ik``: its cost over the IK's cost per frame in the same run.

``scene()`` returns ``place_scene_s`` (``camtraj place`` of a scene of five 10-second shots:
consecutive parts of the one-minute long move), ``place_single_s`` (its first part placed
alone, in the same run) and ``place_scene_ratio`` (the issue's goal: <= 2).

Run it alone with ``python bench/bench_place.py``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _make_samples() -> object:
    """``samples/shots/make_samples.py`` as a module (the tests' loader)."""
    sys.path.insert(0, str(ROOT))
    from tests.shot_set import make_samples

    return make_samples()


def _far_shot(path: Path, frames: int) -> np.ndarray:
    """The first ``frames`` / 24 s of the long move, placed far from the origin."""
    from camtraj.usd_shot import read_shot

    near = path.with_name("near.usda")
    _make_samples().write_long_shot(near, n_frames=frames, part=frames / 1440)  # type: ignore[attr-defined]
    return _write_far(path, read_shot(near).cam2world)


def _write_far(path: Path, near2world: np.ndarray) -> np.ndarray:
    """A Z-up metre stage of the camera poses ``near2world`` (n, 4, 4) moved to (-37, 52) m
    and turned by 121 deg on the floor, frames 1..n at 24 fps; returns the moved poses."""
    from pxr import Gf, Usd, UsdGeom

    frames = near2world.shape[0]
    a = math.radians(121.0)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:2, 3] = (-37.0, 52.0)
    cam2world = T @ near2world
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(24.0)
    stage.SetFramesPerSecond(24.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(frames)
    cam = UsdGeom.Camera.Define(stage, "/World/cam")
    op = cam.AddTransformOp()
    for i in range(frames):
        op.Set(Gf.Matrix4d(cam2world[i].T.tolist()), Usd.TimeCode(i + 1))
    stage.GetRootLayer().Save()
    return cam2world


def _place(*args: str) -> tuple[float, dict[str, object]]:
    """Wall time [s] and JSON report of ``camtraj place ARGS --json -q``."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "camtraj", "place", *args, "--json", "-q"],
                          capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode not in (0, 3) or not proc.stdout:
        msg = f"camtraj place failed: {proc.stderr.strip()}"
        raise RuntimeError(msg)
    report: dict[str, object] = json.loads(proc.stdout)
    return seconds, report


def scene(log: Callable[[str], None] = print, shots: int = 5, frames: int = 240,
          jobs: int = 2) -> dict[str, float]:
    """``camtraj place`` of a scene: ``shots`` consecutive ``frames``-frame parts of the
    one-minute long move (placed far from the origin), against placing its first (longest)
    part alone, in the same run. ``place_scene_ratio`` is the issue's figure (goal <= 2)."""
    from camtraj.usd_shot import read_shot

    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="camtraj-bench-scene-") as tmp:
        work = Path(tmp)
        near = work / "near.usda"
        _make_samples().write_long_shot(near, n_frames=shots * frames,  # type: ignore[attr-defined]
                                        part=shots * frames / 1440)
        moves = read_shot(near).cam2world
        paths = []
        for k in range(shots):
            paths.append(work / f"part{k + 1}.usda")
            _write_far(paths[-1], moves[k * frames:(k + 1) * frames])
        log(f"camtraj place of part 1 alone ({frames} frames), --jobs {jobs}")
        out["place_single_s"], _ = _place(str(paths[0]), "-j", str(jobs))
        log(f"camtraj place of the {shots}-part scene, --jobs {jobs}")
        out["place_scene_s"], rep = _place(*map(str, paths), "-j", str(jobs))
        out["place_scene_ratio"] = out["place_scene_s"] / out["place_single_s"]
        out["place_scene_ok"] = float(rep["status"] == "ok")
        out["place_scene_solves"] = float(rep["evaluated"])  # type: ignore[arg-type]
        placement = rep["placement"]
        if isinstance(placement, dict):
            out["place_scene_worst_speed"] = min(
                float(s["max_speed"] or 0.0) for s in placement["shots"])
    return out


def _sheet(path: Path, cam2world: np.ndarray) -> None:
    """A 10,000-triangle corrugated sheet 0.6 m beside the camera path (world frame)."""
    from pxr import Gf, Usd, UsdGeom

    p = cam2world[:, :3, 3]
    centre = p.mean(axis=0)
    d = p[-1, :2] - p[0, :2]
    u = d / max(np.linalg.norm(d), 1e-9)
    v = np.array([-u[1], u[0]])
    side = float(np.max((p[:, :2] - centre[:2]) @ v)) + 0.6
    s, t = np.meshgrid(np.linspace(-6.0, 6.0, 101), np.linspace(0.0, 3.0, 51), indexing="ij")
    wave = 0.05 * np.sin(8.0 * s)
    xy = centre[:2] + s[..., None] * u + (side + wave)[..., None] * v
    pts = np.concatenate([xy, t[..., None]], axis=-1).reshape(-1, 3)
    quads = [(i * 51 + j, (i + 1) * 51 + j, (i + 1) * 51 + j + 1, i * 51 + j + 1)
             for i in range(100) for j in range(50)]
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    mesh = UsdGeom.Mesh.Define(stage, "/set/sheet")
    mesh.CreatePointsAttr([Gf.Vec3f(*map(float, q)) for q in pts])
    mesh.CreateFaceVertexCountsAttr([4] * len(quads))
    mesh.CreateFaceVertexIndicesAttr([k for q in quads for k in q])
    stage.GetRootLayer().Save()


def run(log: Callable[[str], None] = print, frames: int = 240, jobs: int = 2) -> dict[str, float]:
    from camtraj.collision import CollisionModel, read_obstacles, sample_times, take_samples
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions
    from camtraj.usd_shot import stage_to_world

    out: dict[str, float] = {}
    with tempfile.TemporaryDirectory(prefix="camtraj-bench-place-") as tmp:
        work = Path(tmp)
        shot = work / "far.usda"
        cam2world = _far_shot(shot, frames)
        log(f"camtraj place on a {frames}-frame shot, --jobs {jobs}")
        out["place_wall_s"], rep = _place(str(shot), "-j", str(jobs))
        out["place_ok"] = float(rep["status"] == "ok")
        out["place_candidates"] = float(rep["evaluated"])  # type: ignore[arg-type]
        out["place_candidates_per_s"] = out["place_candidates"] / out["place_wall_s"]
        out["place_screened"] = float(rep["screened"])  # type: ignore[arg-type]
        best = rep["placements"][0]  # type: ignore[index]
        out["place_best_speed"] = float(best["max_speed"] or 0.0)

        log("one full solve at the best placement (baseline)")
        options = ConvertOptions(placement=(best["x"], best["y"], float(rep["base_z"]),  # type: ignore[arg-type]
                                            best["yaw_deg"]),
                                 timing="scale")
        t0 = time.perf_counter()
        analysis = analyse(shot, options)
        out["full_solve_s"] = time.perf_counter() - t0
        ik_per_frame = analysis.timings["ik"] / frames
        out["place_in_full_solves"] = out["place_wall_s"] / out["full_solve_s"]

        log("collision check against a 10,000-triangle sheet")
        sheet = work / "sheet.usda"
        _sheet(sheet, cam2world)
        take = analysis.take
        assert take is not None
        shot = analysis.shot
        obstacles = read_obstacles(sheet, ("/set/*",), shot.time_codes,
                                   stage_to_world(shot.meters_per_unit, shot.up_axis))
        model = CollisionModel(analysis.robot, obstacles)
        t0 = time.perf_counter()
        idx = take_samples(analysis.robot, take.q, take.frame_samples)
        tcs = sample_times(take.t[idx], take.frame_times, analysis.shot.time_codes)
        dist, _ = model.closest(take.q[idx], tcs, analysis.placement.base2world, 0.0)
        seconds = time.perf_counter() - t0
        out["collision_triangles"] = float(obstacles[0].triangles.shape[0])
        out["collision_ms_per_frame"] = 1e3 * seconds / frames
        out["collision_samples_per_frame"] = idx.size / frames
        out["collision_vs_ik"] = (seconds / frames) / ik_per_frame
        out["collision_closest_m"] = float(dist.min()) if np.isfinite(dist.min()) else -1.0
    return out


if __name__ == "__main__":
    for key, value in {**run(), **scene()}.items():
        print(f"{key:32} {value:10.4g}")
