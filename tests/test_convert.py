"""End-to-end acceptance tests of ``camtraj convert`` (the convert issue, design.md §1-5).

Every conversion runs the real command line in a subprocess. The outputs are decoded with
``read_take`` (mcap_ros2, an independent reader) and compared with facts computed here
without camtraj's own pipeline: the USD camera's world pose straight from pxr, forward
kinematics of the decoded joints, finite differences of the written positions, and the
robot's workspace found by a plain numerical optimisation.

Each sample is converted once per option set, all of them concurrently, in a module fixture.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from pxr import Usd, UsdGeom
from scipy.optimize import minimize
from scipy.spatial.transform import Rotation

import camtraj
from camtraj.mcap_io import ReadTake, read_take
from camtraj.robot import JOINT_NAMES, Robot
from tests.conftest import pose_error

Array = NDArray[np.float64]

ROOT = Path(__file__).resolve().parent.parent
SHOTS = ROOT / "samples" / "shots"

#: Y-up stage coordinates to Z-up: +90 degrees about X (design.md §2).
YUP2ZUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

#: Relative slack on every velocity / acceleration / jerk limit (the issue: +0.1 %).
SLACK = 1e-3
EPS = float(np.finfo(np.float64).eps)


# --------------------------------------------------------------------------------------------
# Helpers shared with test_cli.py
# --------------------------------------------------------------------------------------------


def run_cli(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``python -m camtraj ARGS`` (the real command line), capturing its output."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p
    )}
    return subprocess.run(
        [sys.executable, "-m", "camtraj", *(str(a) for a in args)],
        capture_output=True, text=True, cwd=cwd, env=env, timeout=600, check=False,
    )


def run_all(
    jobs: dict[str, Sequence[object]], cwds: dict[str, Path] | None = None
) -> dict[str, subprocess.CompletedProcess[str]]:
    """Run several command lines concurrently (submitted in order; ``cwds`` per job)."""
    workers = min(4, (os.cpu_count() or 2) + 1)
    cwds = cwds or {}
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures = {
            key: pool.submit(run_cli, *args, cwd=cwds.get(key)) for key, args in jobs.items()
        }
        return {key: fut.result() for key, fut in futures.items()}


def error_line(proc: subprocess.CompletedProcess[str]) -> str:
    """The one ``ERROR:`` line a failed run prints on stderr (asserting it is all there is)."""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, f"expected one line on stderr, got:\n{proc.stderr}"
    assert lines[0].startswith("ERROR: "), lines[0]
    assert "Traceback" not in proc.stderr
    return lines[0]


def leftovers(folder: Path) -> list[str]:
    """Temporary files a writer may have left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if ".tmp" in p.name)


@dataclass(frozen=True)
class UsdCamera:
    """A USD camera's world pose per frame, computed directly with pxr (not with camtraj)."""

    prim_path: str
    frames: NDArray[np.int64]
    fps: float
    poses: Array  # (n, 4, 4) camera2world, metres, Z-up, column vectors, scale removed


@cache
def usd_camera(path: Path) -> UsdCamera:
    """The only camera of the stage at ``path``, sampled at every frame of its time range."""
    stage = Usd.Stage.Open(str(path))
    cams = [p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
    assert len(cams) == 1, f"{path}: expected one camera"
    prim = cams[0]
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    up = str(UsdGeom.GetStageUpAxis(stage))
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond()
    first, last = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    frames = np.arange(first, last + 1, dtype=np.int64)
    xf = UsdGeom.Xformable(prim)
    poses = np.zeros((frames.size, 4, 4))
    for i, f in enumerate(frames):
        m = np.array(xf.ComputeLocalToWorldTransform(Usd.TimeCode(float(f)))).T
        u, _, vt = np.linalg.svd(m[:3, :3])
        rot, pos = u @ vt, m[:3, 3] * mpu  # scale removed; scene units to metres
        if up == "Y":
            rot, pos = YUP2ZUP @ rot, YUP2ZUP @ pos
        poses[i, :3, :3], poses[i, :3, 3], poses[i, 3, 3] = rot, pos, 1.0
    return UsdCamera(str(prim.GetPath()), frames, float(stage.GetFramesPerSecond()), poses)


def workspace_miss(robot: Robot, point: Array, starts: int = 4) -> float:
    """Distance [m] from ``point`` to the positions the camera can reach (0 if reachable).

    With the default mount (no nodal offset) the camera sits at the flange origin, the wrist
    centre, which depends only on track, rotate, lift, extend and elbow (design.md §3). The
    distance is minimised over those five axes inside their limits from several starts.
    """
    axes = [0, 1, 2, 3, 4]
    lo, hi = robot.lower[axes], robot.upper[axes]
    assert np.allclose(robot.camera2flange[:3, 3], 0.0)

    def sq(x: Array) -> float:
        q = np.zeros(8)
        q[axes] = x
        return float(np.sum((robot.camera_pose(q)[:3, 3] - point) ** 2))

    rng = np.random.default_rng(12345)
    x0s = [(lo + hi) / 2] + [rng.uniform(lo, hi) for _ in range(starts - 1)]
    best = min(
        minimize(sq, x0, bounds=list(zip(lo, hi, strict=True)), method="L-BFGS-B",
                 options={"ftol": 1e-15, "gtol": 1e-12}).fun
        for x0 in x0s
    )
    return math.sqrt(max(best, 0.0))


def numbers_before(unit: str, text: str) -> list[float]:
    """Every number in ``text`` directly followed by ``unit`` (e.g. ``" m"``, ``"%"``)."""
    return [float(x) for x in re.findall(r"(-?\d+(?:\.\d+)?)" + re.escape(unit) + r"(?!\w)", text)]


# --------------------------------------------------------------------------------------------
# The conversions
# --------------------------------------------------------------------------------------------

FEASIBLE = ("maya_dolly_push_in", "blender_crane_up", "orbit_animated_parent")


@dataclass(frozen=True)
class Run:
    shot: Path
    mcap: Path
    summary: Path
    proc: subprocess.CompletedProcess[str]

    def take(self) -> ReadTake:
        assert self.proc.returncode == 0, self.proc.stderr
        return _decode(self.mcap)

    def summary_json(self) -> dict[str, Any]:
        assert self.proc.returncode == 0, self.proc.stderr
        data: dict[str, Any] = json.loads(self.summary.read_text())
        return data


@cache
def _decode(path: Path) -> ReadTake:
    return read_take(path)


SENTINEL = b"an earlier, good take\n"

# key: (sample, options)
CONVERSIONS: dict[str, tuple[str, tuple[str, ...]]] = {
    "blender_crane_up": ("blender_crane_up", ()),
    "maya_dolly_push_in": ("maya_dolly_push_in", ()),
    "orbit_animated_parent": ("orbit_animated_parent", ()),
    "whip_scale": ("whip_pan", ("--timing", "scale")),
    "maya_optimal": ("maya_dolly_push_in", ("--timing", "optimal")),
    "whip_optimal": ("whip_pan", ("--timing", "optimal")),
    "maya_again": ("maya_dolly_push_in", ()),
    "whip_shot": ("whip_pan", ("--timing", "shot")),
    "unreachable": ("unreachable", ()),
    "crane_still": ("blender_crane_up", ("--edges", "still")),
    "crane_still_optimal": ("blender_crane_up", ("--edges", "still", "--timing", "optimal")),
    "crane_optimal": ("blender_crane_up", ("--timing", "optimal", "--edges", "gentle")),
    "crane_gentle": ("blender_crane_up", ("--edges", "gentle")),
}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Run]:
    base = tmp_path_factory.mktemp("convert")
    jobs: dict[str, list[object]] = {}
    out: dict[str, tuple[Path, Path, Path]] = {}
    for key, (sample, options) in CONVERSIONS.items():
        folder = base / key
        folder.mkdir()
        shot = SHOTS / f"{sample}.usda"
        mcap, summary = folder / "shot.mcap", folder / "shot.summary.json"
        if key == "unreachable":  # a failed run must leave an existing output alone
            mcap.write_bytes(SENTINEL)
        out[key] = (shot, mcap, summary)
        jobs[key] = ["convert", shot, "-o", mcap, "--summary", summary, *options]
    procs = run_all(jobs)
    return {key: Run(*out[key], procs[key]) for key in jobs}


# --------------------------------------------------------------------------------------------
# 1. Round trip: USD -> convert -> MCAP -> FK == the USD camera's world pose
# --------------------------------------------------------------------------------------------

ROUND_TRIP = (*FEASIBLE, "whip_scale", "crane_still")


@pytest.mark.parametrize("key", ROUND_TRIP)
def test_round_trip_fk_of_written_joints_equals_usd_camera(
    runs: dict[str, Run], robot: Robot, key: str
) -> None:
    run = runs[key]
    assert run.proc.returncode == 0, run.proc.stderr
    cam = usd_camera(run.shot)
    take = run.take()
    np.testing.assert_array_equal(take.frame_numbers, cam.frames)
    assert take.frame_names == JOINT_NAMES
    assert take.joint_names == JOINT_NAMES
    # Default placement is identity: the robot base frame is the converted stage world.
    fk = robot.camera_pose(take.frame_q)
    dp, dr = pose_error(fk, cam.poses)
    assert dp <= 1e-6 and dr <= 1e-6, f"FK vs USD: {dp:.3g} m, {dr:.3g} rad"
    dp, dr = pose_error(take.target, cam.poses)  # the request itself: only encoding error
    assert dp <= 1e-9 and dr <= 1e-9, f"target vs USD: {dp:.3g} m, {dr:.3g} rad"
    dp, dr = pose_error(take.achieved, cam.poses)
    assert dp <= 1e-6 and dr <= 1e-6, f"achieved vs USD: {dp:.3g} m, {dr:.3g} rad"
    # achieved is FK of the same solution (only the quaternion encoding in between)
    dp, dr = pose_error(take.achieved, fk)
    assert dp <= 1e-9 and dr <= 1e-9
    assert np.all(robot.within_limits(take.frame_q))


@pytest.mark.parametrize("key", ROUND_TRIP)
def test_frames_are_timed_as_the_shot(runs: dict[str, Run], key: str) -> None:
    """Shot timing keeps 1/fps between frames; scale stretches it by exactly the factor."""
    run = runs[key]
    take, summary, cam = run.take(), run.summary_json(), usd_camera(run.shot)
    factor = summary["speed_factor"]
    assert float(take.metadata["speed_factor"]) == pytest.approx(factor, rel=1e-12)
    if summary["timing"] == "shot":
        assert factor == 1.0
    spacing = np.diff(take.frame_times)
    np.testing.assert_allclose(spacing, factor / cam.fps, rtol=0, atol=1e-9)
    assert take.t[0] == 0.0  # the take starts at t = 0 (design.md §4)
    # on the file's nanosecond clock (a shot that ends still has no run-out: its last frame
    # is the last sample, logged at its time rounded to the nanosecond)
    assert take.t[-1] >= take.frame_times[-1] - 0.5e-9


@pytest.mark.parametrize("key", ["maya_dolly_push_in", "crane_still", "crane_gentle",
                                 "whip_scale", "maya_optimal", "crane_optimal"])
def test_every_film_frame_has_a_tf_sample_at_its_own_stamp(runs: dict[str, Run],
                                                          key: str) -> None:
    """/tf holds a message on every film frame's own stamp, the last frame too where the take
    ends on it (a settled end, no run-out: the nanosecond clock put the take's end half a
    nanosecond before the grid's last point, and /tf lost the last frame), also in a retimed
    take (a new user found one /tf sample in eight frames of an optimal take), and on the
    take's first and last sample; the rest of the take at the film's frame rate, so no two
    are more than a frame interval apart. Read with the mcap library's own reader."""
    from mcap.reader import make_reader

    with runs[key].mcap.open("rb") as stream:
        reader = make_reader(stream)
        tf = sorted({m.log_time for _s, _c, m in reader.iter_messages(topics=["/tf"])})
        stream.seek(0)
        frames = [m.log_time for _s, _c, m in make_reader(stream).iter_messages(
            topics=["/shot/frames"])]
        stream.seek(0)
        servo = [m.log_time for _s, _c, m in make_reader(stream).iter_messages(
            topics=["/joint_states"])]
    assert frames and set(frames) <= set(tf), sorted(set(frames) - set(tf))
    assert tf[0] == servo[0] and tf[-1] == servo[-1]
    fps = runs[key].summary_json()["fps"]
    assert np.diff(tf).max() <= 1e9 / fps + 1
    assert np.diff(tf).min() > 0


# --------------------------------------------------------------------------------------------
# 2. Every frame is a servo sample of /joint_states
# --------------------------------------------------------------------------------------------

ALL_OK = (*ROUND_TRIP, "maya_optimal", "whip_optimal")


@pytest.mark.parametrize("key", ALL_OK)
def test_every_frame_solution_is_a_joint_states_sample(runs: dict[str, Run], key: str) -> None:
    take = runs[key].take()
    t = take.t
    assert np.all(np.diff(t) > 0)
    i = np.clip(np.searchsorted(t, take.frame_times), 1, t.size - 1)
    i = np.where(np.abs(t[i - 1] - take.frame_times) < np.abs(t[i] - take.frame_times), i - 1, i)
    assert np.abs(t[i] - take.frame_times).max() <= 1e-9  # a sample at every frame time
    np.testing.assert_allclose(take.q[i], take.frame_q, rtol=0, atol=1e-9)
    # The trajectory message carries the same samples.
    assert take.trajectory_joint_names == JOINT_NAMES
    np.testing.assert_allclose(take.trajectory_t, t, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(take.trajectory_q, take.q)
    np.testing.assert_array_equal(take.trajectory_qd, take.qd)
    # Servo rate: at least the 250 Hz default asks for within the frame-rate quantisation.
    steps = np.diff(t)
    assert steps.max() <= 1.0 / 200.0


# --------------------------------------------------------------------------------------------
# 3. Limits, measured by finite differences of the written positions
# --------------------------------------------------------------------------------------------


def stamp_times(t: Array) -> tuple[Array, float]:
    """Sample times to difference over, and their error [s]: the stamps themselves.

    Stamps are whole nanoseconds, and every written position is the take's at its stamp
    (``camtraj.timing.clock``), so the only time error left is float's in rebuilding seconds
    from them. (Before, positions were the take's at times up to 0.5 ns from their stamps: a
    uniform take's third differences over the stamps read up to 0.14% over the jerk limit.)
    """
    return t, 4.0 * EPS * float(np.abs(t).max(initial=0.0))


def derivative_estimates(t: Array, q: Array, k: int) -> Array:
    """k! times the k-th divided differences: (m - k, 8) estimates of the k-th derivative.

    By the Peano kernel theorem each is a weighted mean (non-negative weights summing to 1)
    of the true k-th derivative over its k + 1 samples, for a trajectory that is C^(k-1)
    with a bounded k-th derivative. So it can never exceed the largest true value: a limit
    the trajectory keeps, these keep too, up to floating-point and time-stamp error.
    """
    d = q
    for j in range(1, k + 1):
        d = j * (d[1:] - d[:-1]) / (t[j:] - t[:-j])[:, None]
    return d


def fd_tolerance(t: Array, q: Array, k: int, t_err: float) -> Array:
    """(8,) bound on the error of ``derivative_estimates`` from rounding alone.

    Its numerator is a combination of positions whose weights sum in magnitude to at most
    2^k / h_min^k (h_min the shortest step): a position error e (float round-off, EPS *
    max|q|) and a time error t_err (which moves a sample by up to |velocity| * t_err) give
    2^k * (EPS * max|q| + v_peak * t_err) / h_min^k. Doubled for safety; at 250 Hz this is
    below 1e-4 of every limit, far inside the 0.1 % slack.
    """
    h = float(np.diff(t).min())
    v_peak = np.abs(derivative_estimates(t, q, 1)).max(axis=0)
    q_max = np.abs(q).max(axis=0)
    tol: Array = 2.0 * 2.0**k * (4 * EPS * q_max + v_peak * t_err) / h**k
    return tol


def assert_within(values: Array, limit: Array, tol: Array, what: str, t: Array) -> None:
    excess = np.abs(values) - (limit * (1.0 + SLACK) + tol)
    if excess.max() > 0:
        i, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
        pytest.fail(
            f"{what} of {JOINT_NAMES[j]} near t = {t[i]:.4f} s is {values[i, j]:.6g}, "
            f"limit {limit[j]:.6g} (+{SLACK:.1%} +{tol[j]:.2g})"
        )


def frame_indices(take: ReadTake) -> NDArray[np.int64]:
    idx: NDArray[np.int64] = np.argmin(
        np.abs(take.t[None, :] - take.frame_times[:, None]), axis=1
    ).astype(np.int64)
    return idx


TIMED = ("whip_scale", "maya_optimal", "whip_optimal", "maya_dolly_push_in", "blender_crane_up",
         "crane_still", "crane_still_optimal",
         "orbit_animated_parent")
#: Takes on a uniform servo grid (an optimal retime cuts each frame interval its own way).
UNIFORM = frozenset(TIMED) - {"maya_optimal", "whip_optimal", "crane_still_optimal"}


@pytest.mark.parametrize("key", TIMED)
def test_finite_differences_stay_within_limits(
    runs: dict[str, Run], robot: Robot, key: str
) -> None:
    take = runs[key].take()
    t, t_err = stamp_times(take.t)
    q = take.q
    v = derivative_estimates(t, q, 1)
    a = derivative_estimates(t, q, 2)
    assert_within(v, robot.max_velocity, fd_tolerance(t, q, 1, t_err), "velocity", t)
    assert_within(a, robot.max_acceleration, fd_tolerance(t, q, 2, t_err), "acceleration", t)
    j = derivative_estimates(t, q, 3)
    assert_within(j, robot.max_jerk, fd_tolerance(t, q, 3, t_err), "jerk", t)
    # Positions inside the limits at every sample.
    assert np.all(robot.within_limits(q))


@pytest.mark.parametrize("key", TIMED)
def test_stored_velocities_agree_with_finite_differences(
    runs: dict[str, Run], robot: Robot, key: str
) -> None:
    """Central differences of the positions against the written velocities.

    For steps h1, h2 around a sample the central difference differs from the true velocity by
    at most A (h1² + h2²) / (2 (h1 + h2)) with A the largest |acceleration| (which the limit
    bounds); with a bounded jerk J and equal steps by at most J h² / 6.
    """
    take = runs[key].take()
    t, t_err = stamp_times(take.t)
    q, qd = take.q, take.qd
    h1, h2 = np.diff(t)[:-1, None], np.diff(t)[1:, None]
    central = (q[2:] - q[:-2]) / (h1 + h2)
    err = np.abs(central - qd[1:-1])
    a_max = robot.max_acceleration * (1 + SLACK)
    tol = fd_tolerance(t, q, 1, t_err)
    bound = a_max * (h1**2 + h2**2) / (2 * (h1 + h2)) + tol
    assert np.all(err <= bound), f"worst {float((err / bound).max()):.3f} of the bound"
    if key in UNIFORM:
        h = float(np.diff(t).mean())
        tight = robot.max_jerk * (1 + SLACK) * h**2 / 6 + tol
        assert np.all(err <= tight), f"worst {float((err / tight).max()):.3f} of J h²/6"


@pytest.mark.parametrize("key", ALL_OK)
def test_take_starts_and_ends_at_rest(runs: dict[str, Run], key: str) -> None:
    take = runs[key].take()
    for i in (0, -1):
        assert np.abs(take.qd[i]).max() <= 1e-12
        assert np.abs(take.trajectory_qd[i]).max() <= 1e-12
        assert np.abs(take.trajectory_qdd[i]).max() <= 1e-12
    # on the file's nanosecond clock (see test_frames_are_timed_as_the_shot)
    assert take.t[0] <= take.frame_times[0] and take.frame_times[-1] <= take.t[-1] + 0.5e-9


def _end_motion(robot: Robot, take: ReadTake) -> tuple[Array, Array]:
    """From the decoded samples: how far the camera (FK) moves from the first frame's position
    during the run-up and from the last frame's during the run-out (2,) [m], and each end
    frame's joint velocity as the central difference of its neighbouring samples (2, 8)
    (one-sided where the frame is the take's first or last sample)."""
    idx = frame_indices(take)
    cams = robot.camera_pose(take.q)[:, :3, 3]
    travel = np.array([np.linalg.norm(cams[:idx[0] + 1] - cams[idx[0]], axis=1).max(),
                       np.linalg.norm(cams[idx[-1]:] - cams[idx[-1]], axis=1).max()])
    last = take.q.shape[0] - 1  # a frame on the take's first or last sample: one-sided
    speed = np.array([(take.q[min(i + 1, last)] - take.q[max(i - 1, 0)])
                      / (take.t[min(i + 1, last)] - take.t[max(i - 1, 0)])
                      for i in (idx[0], idx[-1])])
    return travel, speed


def test_still_edges_keep_the_robot_still_where_the_camera_rests(
        runs: dict[str, Run], robot: Robot) -> None:
    """The crane-up eases from rest and to rest (settling: its acceleration fades too). With
    free ends (``--edges gentle``) the solver already moves the redundant axes on the first
    frame, and the run-up swings the camera around it; with ``--edges still`` (the default)
    every axis stands still on the first and last frame (the central difference of the
    samples around them: a thousandth of the velocity limit, where free ends move some axis
    by a tenth of it) with no acceleration to build, so the camera does not move before or
    after them (free: over a centimetre before), also when an optimal retime plays the ends
    faster, and the take is at most 15% slower (measured: 0.90x). The summary's camera
    travel is what FK of the decoded samples measures."""
    travel, speed = {}, {}
    for key in ("crane_gentle", "crane_still", "crane_still_optimal", "crane_optimal"):
        take = runs[key].take()
        travel[key], speed[key] = _end_motion(robot, take)
        data = runs[key].summary_json()
        got = [data["runup"]["camera_travel_m"], data["runout"]["camera_travel_m"]]
        np.testing.assert_allclose(got, travel[key], rtol=0, atol=1e-6)
        # and its turn: the angle between the camera's orientation (FK) and the end frame's
        idx = frame_indices(take)
        rots = robot.camera_pose(take.q)[:, :3, :3]
        turn = [max(np.degrees(Rotation.from_matrix(rots[i].T @ r).magnitude())
                    for r in rots[part]) for i, part in ((idx[0], slice(0, idx[0] + 1)),
                                                        (idx[-1], slice(idx[-1], None)))]
        got = [data["runup"]["camera_turn_deg"], data["runout"]["camera_turn_deg"]]
        np.testing.assert_allclose(got, turn, rtol=0, atol=1e-6)
        if max(turn) >= 0.1:  # said with the distance
            assert re.search(r"the camera moves [0-9.]+ c?m?m and turns [0-9.]+ deg",
                             runs[key].proc.stdout), runs[key].proc.stdout
    for key in ("crane_still", "crane_still_optimal"):
        use = np.abs(speed[key]) / robot.max_velocity
        assert use.max() <= 1e-3, f"{key}: the ends move at {use.max():.2g} of a velocity limit"
    for key in ("crane_still", "crane_still_optimal"):
        assert travel[key].max() <= 1e-9, (key, travel[key])
    assert travel["crane_optimal"].max() >= 1e-2
    assert (np.abs(speed["crane_gentle"]) / robot.max_velocity).max() >= 0.1
    assert travel["crane_gentle"][0] >= 1e-2
    still, free = runs["crane_still"].summary_json(), runs["crane_gentle"].summary_json()
    assert runs["blender_crane_up"].summary_json()["edges"] == "still"  # the default
    assert still["edges"] == "still" and free["edges"] == "gentle"
    assert still["runup"]["camera_at_rest"] and free["runout"]["camera_at_rest"]
    assert still["runup"]["camera_rest"] == still["runout"]["camera_rest"] == "settled"
    note = "but the robot's axes are already moving there, so the run-up/run-out swings the camera"
    assert note in runs["crane_gentle"].proc.stdout
    assert note not in runs["crane_still"].proc.stdout
    assert 0.85 * free["max_speed"] <= still["max_speed"] <= free["max_speed"] * (1 + 1e-9)


def test_info_says_the_servo_rate_the_summary_says(runs: dict[str, Run]) -> None:
    """``info --json``'s servo rate is the run's, as the summary and the metadata have it,
    also for an optimal take whose steps vary (it read 259.3 Hz off the stamps of a 250 Hz
    take, and 240.00000002704223 for 240)."""
    for key in ("maya_dolly_push_in", "maya_optimal"):
        info = json.loads(run_cli("info", runs[key].mcap, "--json").stdout)
        assert info["servo_rate_hz"] == runs[key].summary_json()["servo_rate_hz"], key


def test_run_up_and_run_out_durations_are_the_files(runs: dict[str, Run]) -> None:
    """The summary's run-up lasts from the take's first sample to the first frame's and its
    run-out from the last frame's to the take's last (the ruckig moves plus the holds that
    put the frames on servo ticks), as the decoded file has them (a new user found them up to
    3.9 ms short: ruckig's move alone)."""
    for key in ("crane_gentle", "crane_optimal", "whip_scale", "maya_dolly_push_in"):
        take, data = runs[key].take(), runs[key].summary_json()
        idx = frame_indices(take)
        assert data["runup"]["duration_s"] == pytest.approx(take.t[idx[0]] - take.t[0],
                                                            abs=1e-9), key
        assert data["runout"]["duration_s"] == pytest.approx(take.t[-1] - take.t[idx[-1]],
                                                             abs=1e-9), key


def test_the_still_ends_fallback_note_needs_a_camera_moving_at_both_ends(
        runs: dict[str, Run]) -> None:
    """--edges still with the camera at rest on an end frame keeps the robot still there, even
    where the ends fall back to full-limit ones (a lens axis with no room for a gentle run-up:
    ``edges`` is then ``fast``); only a camera moving on both end frames makes the ends
    gentle ones, and only then is that said (a new user read "at rest on neither end frame"
    on a settled dolly zoom)."""
    from camtraj.cli import _report

    note = "the camera is at rest on neither end frame"
    data = runs["crane_still"].summary_json()
    assert data["runup"]["camera_at_rest"] and note not in _report(data)
    assert note not in _report({**data, "edges": "fast"})
    moving = {**data, "edges": "gentle",
              "runup": {**data["runup"], "camera_at_rest": False},
              "runout": {**data["runout"], "camera_at_rest": False}}
    assert note in _report(moving)


# --------------------------------------------------------------------------------------------
# 4. The whip pan: too fast for shot timing, fine when scaled
# --------------------------------------------------------------------------------------------


def test_whip_pan_fails_under_shot_timing_naming_axis_frames_and_speed(
    runs: dict[str, Run],
) -> None:
    run = runs["whip_shot"]
    assert run.proc.returncode == 3, run.proc.stderr
    line = error_line(run.proc)
    assert re.search(r"\bpan\b", line), line
    # The whip happens between frames 16 and 24 (samples/shots/make_samples.py): the worst
    # violation, named first, is pan's there. (The solver spreads the move over every axis
    # up to the speed the take can run at, so at shot timing others exceed too.)
    ranges = [(int(a), int(b or a)) for a, b in re.findall(r"frames? (\d+)(?:-(\d+))?", line)]
    assert ranges, line
    assert line.startswith("ERROR: pan "), line
    a, b = ranges[0]
    assert 14 <= a <= b <= 30 and a <= 24 and b >= 16, (a, b, line)
    # The speed that would work matches what --timing scale found.
    factor = runs["whip_scale"].summary_json()["speed_factor"]
    pct = numbers_before("%", line)
    fps = numbers_before(" fps", line)
    assert pct and fps, line
    assert abs(pct[-1] - 100.0 / factor) <= 1.5, (pct, factor)
    assert abs(fps[-1] - 24.0 / factor) <= 0.15, (fps, factor)
    assert not run.mcap.exists() and not run.summary.exists()
    assert leftovers(run.mcap.parent) == []


def test_whip_pan_succeeds_when_scaled_by_the_smallest_factor(
    runs: dict[str, Run], robot: Robot
) -> None:
    run = runs["whip_scale"]
    assert run.proc.returncode == 0, run.proc.stderr
    summary = run.summary_json()
    assert summary["timing"] == "scale"
    assert summary["speed_factor"] > 1.0
    assert run.take().metadata["timing_mode"] == "scale"
    # The smallest factor: some axis uses (nearly) all of some limit in the shot part.
    take = run.take()
    t, _ = stamp_times(take.t)
    f = frame_indices(take)
    part = slice(f[0], f[-1] + 1)
    use = max(
        float((np.abs(derivative_estimates(t[part], take.q[part], k)) / lim).max())
        for k, lim in ((1, robot.max_velocity), (2, robot.max_acceleration),
                       (3, robot.max_jerk))
    )
    assert use >= 0.99, f"the scaled take uses only {use:.1%} of its tightest limit"


def test_optimal_timing_is_not_slower_than_scale(runs: dict[str, Run]) -> None:
    scale, optimal = runs["whip_scale"].summary_json(), runs["whip_optimal"].summary_json()
    assert optimal["timing"] == "optimal"
    length = {k: s["shot_end"] - s["shot_start"] for k, s in (("scale", scale),
                                                               ("optimal", optimal))}
    assert length["optimal"] <= length["scale"] * (1 + 1e-9), length


def test_a_uniform_take_whose_step_is_no_whole_nanosecond_prints_its_rate() -> None:
    """At 1200 Hz the step is 833,333.33 ns: on the file's clock its steps are 833,333 and
    833,334 ns, one period (it printed as "servo steps ... not a fixed period")."""
    from camtraj.shown import servo

    assert servo(1200.0, (0.833333, 0.833334)) == "servo 1200.0 Hz"
    assert servo(9600.0, (0.104166, 0.104167)) == "servo 9600.0 Hz"
    assert "not a fixed period" in servo(250.0, (3.92495, 3.92667))  # an optimal retime's


def test_the_servo_steps_printed_are_the_takes(runs: dict[str, Run]) -> None:
    """A uniform take prints its rate; an optimal retime, whose steps vary from frame
    interval to frame interval, prints their range: both as read back from the MCAP."""
    for name in ("whip_scale", "whip_optimal"):
        run = runs[name]
        steps = np.diff(run.take().t) * 1e3  # ms
        summary = run.summary_json()
        assert summary["servo_step_ms"] == pytest.approx([steps.min(), steps.max()], abs=2e-6)
        line = next(x for x in run.proc.stdout.splitlines() if "timing " in x)
        varies = np.ptp(steps) > max(1e-6 * steps.max(), 1.5e-6)  # a ns: the file's clock
        assert varies == (name == "whip_optimal")
        if varies:
            assert (f"servo steps {steps.min():.3f}-{steps.max():.3f} ms" in line
                    and "not a fixed period" in line), line
        else:
            assert f"servo {1e3 / steps.max():.1f} Hz" in line, line
        # info on the file says the same: the rate of a uniform take, not a mean over steps
        # that vary (an optimal take was shown as "at 255.1 Hz" while its steps were 4 ms)
        shown = subprocess.run([sys.executable, "-m", "camtraj", "info", str(run.mcap)],
                               capture_output=True, text=True, check=True).stdout
        take_line = next(x for x in shown.splitlines() if x.startswith("take "))
        factor = f"speed factor {summary['speed_factor']:.4g}"
        assert take_line.endswith(f"timing {summary['timing']}, {factor}"), take_line
        if varies:  # (it said "servo steps vary", also of an optimal take with equal steps)
            assert f", servo steps {steps.min():.3f}-{steps.max():.3f} ms" in take_line
        else:
            assert f" at {1e3 / steps.max():.1f} Hz," in take_line, take_line
        # and so does the report's summary of the file (it showed the longest step's rate)
        from camtraj.report.data import report_from_mcap
        from camtraj.report.page import _facts

        facts = dict(_facts(report_from_mcap(run.mcap)))
        assert f"servo {facts['servo']}" in line, (facts["servo"], line)


# --------------------------------------------------------------------------------------------
# 5. Frames outside the workspace
# --------------------------------------------------------------------------------------------


def test_unreachable_frames_exit_3_naming_frames_and_miss(
    runs: dict[str, Run], robot: Robot
) -> None:
    run = runs["unreachable"]
    assert run.proc.returncode == 3, run.proc.stderr
    line = error_line(run.proc)
    assert "29-46" in line, line
    # The worst frames (y = 7 m, frames 30-45) miss by a distance found independently here.
    cam = usd_camera(run.shot)
    worst = workspace_miss(robot, cam.poses[list(cam.frames).index(30), :3, 3])
    assert worst > 1.0
    metres = numbers_before(" m", line)
    assert any(abs(m - worst) <= 2e-3 for m in metres), (worst, line)
    assert run.mcap.read_bytes() == SENTINEL  # the existing output is left alone
    assert not run.summary.exists()
    assert leftovers(run.mcap.parent) == []


# --------------------------------------------------------------------------------------------
# 6. Determinism
# --------------------------------------------------------------------------------------------


def test_two_runs_write_byte_identical_files(runs: dict[str, Run]) -> None:
    a, b = runs["maya_dolly_push_in"], runs["maya_again"]
    assert a.proc.returncode == 0 and b.proc.returncode == 0, a.proc.stderr + b.proc.stderr
    assert a.mcap.read_bytes() == b.mcap.read_bytes()


# --------------------------------------------------------------------------------------------
# 8. The camtraj metadata record
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("key", ["maya_dolly_push_in", "whip_scale", "orbit_animated_parent"])
def test_metadata_record_describes_the_run(
    runs: dict[str, Run], robot: Robot, key: str
) -> None:
    run = runs[key]
    take, summary, cam = run.take(), run.summary_json(), usd_camera(run.shot)
    md = take.metadata
    assert set(take.all_metadata) >= {"camtraj"}
    assert md["source_file"] == str(run.shot)
    assert md["camera_prim"] == cam.prim_path
    assert md["frame_range"] == f"{cam.frames[0]}-{cam.frames[-1]}"
    assert float(md["fps"]) == cam.fps
    assert robot.name in md["robot"]
    placement = json.loads(md["placement"])
    np.testing.assert_allclose(placement["translation_m"], [0.0, 0.0, 0.0], atol=0)
    np.testing.assert_allclose(placement["rotation"], np.eye(3), atol=0)
    mount = json.loads(md["mount"])
    np.testing.assert_allclose(mount["camera2flange"], robot.camera2flange, atol=0)
    options = CONVERSIONS[key][1]
    mode = dict(zip(options[::2], options[1::2], strict=True)).get("--timing", "shot")
    assert md["timing_mode"] == summary["timing"] == mode
    assert float(md["speed_factor"]) == pytest.approx(summary["speed_factor"], rel=1e-12)
    assert camtraj.__version__ in md["tool_version"]
    assert "camtraj" in md["tool_version"]


@pytest.mark.parametrize("key", ALL_OK)
def test_summary_matches_the_shot(runs: dict[str, Run], key: str) -> None:
    run = runs[key]
    summary, cam = run.summary_json(), usd_camera(run.shot)
    assert summary["status"] == "ok"
    assert summary["camera"] == cam.prim_path
    assert summary["frames"] == {"first": int(cam.frames[0]), "last": int(cam.frames[-1]),
                                 "count": int(cam.frames.size)}
    assert summary["fps"] == cam.fps
    assert summary["output"] == str(run.mcap)
    take = run.take()
    assert summary["duration"] == pytest.approx(take.t[-1], abs=1e-9)
    assert summary["shot_start"] == pytest.approx(take.frame_times[0], abs=1e-9)
    assert summary["shot_end"] == pytest.approx(take.frame_times[-1], abs=1e-9)


def test_an_arm_reconfiguring_between_two_frames_is_named_and_a_fast_move_is_not() -> None:
    """Half-way through the shot the arm switches to another solution of the same poses (the
    track 0.2 m or 0.8 m further, every other axis re-solved on the same branch): each frame
    is reached, but between two frames the arm swings the camera off its path, which
    ``step_warning`` names (axis, frames, step, how far off, and that optimal timing slows
    only around it). Not called jumps: the smooth path before the switch, the whip pan's fast
    steps (beyond the pan's one-frame reach, the camera on its path), and the same whip pan
    with every third frame (up to 93 deg a frame) on a camera mounted 0.3 m from the wrist
    centre, which swings off the middle of its frames by its own turn."""
    from dataclasses import replace

    from camtraj.convert import step_warning
    from camtraj.ik import solve_path_report
    from camtraj.ik.shot import branch_measures
    from camtraj.usd_shot import read_shot

    robot = Robot.default()
    shot = read_shot(SHOTS / "maya_dolly_push_in.usda")
    dt = 1.0 / shot.fps
    flange = shot.cam2world @ np.linalg.inv(robot.camera2flange)
    path = replace(solve_path_report(robot, flange, objective="paper", frame_interval=dt),
                   objective="shot")
    q, n = path.q, path.q.shape[0]
    assert step_warning(robot, path, shot.cam2world, shot.frames, dt) is None
    k = n // 2
    tail = slice(k, n)
    for b in range(8):  # the branch the solver's frames are on
        branch = np.full(n - k, b)
        y, ok = branch_measures(robot, flange[tail], q[tail, 0], q[tail, 3], q[tail], branch)
        if ok.all() and np.allclose(y[:, :8], q[tail], atol=1e-9):
            break
    else:
        pytest.fail("no branch reproduces the solver's frames")
    for size in (0.2, 0.8):
        for shift in (size, -size):
            y, ok = branch_measures(robot, flange[tail], q[tail, 0] + shift, q[tail, 3],
                                    q[tail], branch)
            if ok.all():
                break
        else:
            pytest.fail(f"no track {size} m away reaches the second half")
        switched = np.concatenate([q[:k], y[:, :8]])
        assert pose_error(robot.fk(switched), flange)[0] < 1e-9  # every frame still reached
        within = np.concatenate([[True], (np.abs(np.diff(switched, axis=0))
                                          <= robot.max_velocity * dt).all(axis=1)])
        warning = step_warning(robot, replace(path, q=switched, within_step=within),
                               shot.cam2world, shot.frames, dt)
        assert warning is not None, size
        step = switched[k] - switched[k - 1]  # the axis named: the largest step for its reach
        j = int(np.argmax(np.abs(step) / (robot.max_velocity * dt)))
        text = (f"{math.degrees(step[j]):+.1f} deg" if JOINT_NAMES[j] not in ("track", "extend")
                else f"{step[j]:+.3f} m")
        assert (f"{JOINT_NAMES[j]} moves {text} between frames {shot.frames[k - 1]} and "
                f"{shot.frames[k]}") in warning, warning
        found = re.search(r"the arm reconfigures: half-way the camera is ([0-9.]+) m off", warning)
        assert found is not None and float(found.group(1)) >= 0.02, warning
        assert "--timing optimal slows only the frames around it" in warning
        assert "camtraj place looks for a track placement that needs no jump" in warning
    whip = read_shot(SHOTS / "whip_pan.usda")
    whip_dt = 1.0 / whip.fps
    fast = solve_path_report(robot, whip.cam2world @ np.linalg.inv(robot.camera2flange),
                             frame_interval=whip_dt)
    assert not fast.within_step.all()  # steps beyond an axis's one-frame reach
    assert step_warning(robot, fast, whip.cam2world, whip.frames, whip_dt) is None
    mount = robot.camera2flange.copy()
    mount[:3, 3] = [0.0, 0.0, 0.3]
    mounted = replace(robot, camera2flange=mount)
    cams = whip.cam2world[::3]
    rel = np.einsum("kji,kjl->kil", cams[:-1, :3, :3], cams[1:, :3, :3])
    turn = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert turn.max() > 80.0  # the camera turns up to 93 deg a frame
    sparse = solve_path_report(mounted, cams @ np.linalg.inv(mount), frame_interval=whip_dt)
    assert not sparse.within_step.all()
    assert step_warning(mounted, sparse, cams, whip.frames[::3], whip_dt) is None


def test_a_jump_between_frames_is_named_with_its_axis_frames_and_size() -> None:
    """The papers' per-frame objective swings the wrist half a turn between two frames of the
    crane-up (its pan wraps round): check says so, with the axis, the frames and the step,
    recomputed here from the joint path the IK gives; the default objective does not jump."""
    from camtraj.ik import solve_path
    from camtraj.usd_shot import read_shot

    shot_path = SHOTS / "blender_crane_up.usda"
    proc = run_cli("check", shot_path, "--objective", "paper", "--timing", "scale", "--json")
    assert proc.returncode == 0, proc.stderr
    jumps = [w for w in json.loads(proc.stdout)["warnings"] if "jump" in w]
    assert len(jumps) == 1, jumps
    robot = Robot.default()
    shot = read_shot(shot_path)
    q = solve_path(robot, shot.cam2world @ np.linalg.inv(robot.camera2flange),
                   objective="paper")
    steps = np.abs(np.diff(q, axis=0)) / (robot.max_velocity / shot.fps)
    k, j = np.unravel_index(int(np.argmax(steps)), steps.shape)
    assert steps[k, j] > 1.0
    step = math.degrees(float(q[k + 1, j] - q[k, j]))
    assert (f"{JOINT_NAMES[j]} moves {step:+.1f} deg between frames {shot.frames[k]} and "
            f"{shot.frames[k + 1]}") in jumps[0]
    plain = run_cli("check", shot_path, "--json")
    assert plain.returncode == 0, plain.stderr
    assert not [w for w in json.loads(plain.stdout)["warnings"] if "jump" in w]


def test_the_placement_is_shown_and_placement_over_a_set_file_says_what_it_replaces(
        tmp_path: Path) -> None:
    """A scene's layout comes from its set file; --placement wins over it, but not silently
    (a take for another track position than the one laid, with nothing on screen, was a
    new user's finding). The output names the placement each take is for."""
    set_file = tmp_path / "set.toml"
    set_file.write_text('[placement]\nx = 0.05\ny = 0.0\nz = 0.0\nyaw_deg = 1.5\n'
                        'layout = "scA"\n')
    shot = SHOTS / "maya_dolly_push_in.usda"
    runs = run_all({
        "file": ("check", shot, "--set-file", set_file, "--json"),
        "both": ("check", shot, "--set-file", set_file, "--placement", "0,0,0,0"),
        "same": ("check", shot, "--set-file", set_file, "--placement", "0.05,0,0,1.5"),
        "none": ("check", shot),
    })
    assert all(r.returncode == 0 for r in runs.values()), {k: r.stderr for k, r in runs.items()}
    placed = json.loads(runs["file"].stdout)
    assert placed["placement"]["source"] == f"{set_file}, layout scA"
    assert placed["placement"]["translation_m"] == [0.05, 0.0, 0.0]
    assert not placed["warnings"]
    both = runs["both"].stdout
    assert "  placement x 0.000 m, y 0.000 m, z 0.000 m, yaw 0.00 deg (--placement)\n" in both
    assert (f"  warning: --placement replaces the set file's placement x 0.050 m, y 0.000 m, "
            f"z 0.000 m, yaw 1.50 deg ({set_file}, layout scA): the take is for the robot "
            f"where --placement puts it\n") in both
    assert "  placement x 0.050 m" in runs["same"].stdout  # the same place: nothing replaced
    assert "warning" not in runs["same"].stdout
    assert "placement" not in runs["none"].stdout  # the stage origin, as in the README


def test_controller_counts_are_recorded_for_the_take(tmp_path: Path) -> None:
    """The robot file's [controller.AXIS] units (counts = offset + sign scale q) reach the
    file: the metadata and `info` give each axis's units and the range of counts the take
    commands, here checked against the /joint_states an independent reader decodes (they
    were read, then used nowhere: a new user's controller engineer found them in no output).
    A scale that is not positive is a robot file error."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    robot = tmp_path / "robot.toml"
    base = (ROOT / "camtraj" / "data" / "robot.toml").read_text(encoding="utf-8")
    robot.write_text(base + "\n[controller.track]\nscale = 1284092.0\noffset = 1000.0\n"
                     "sign = -1\n\n[controller.pan]\nscale = 52152.0\n", encoding="utf-8")
    out = tmp_path / "crane.mcap"
    conv = run_cli("convert", SHOTS / "blender_crane_up.usda", "-o", out, "--robot", robot, "-q")
    assert conv.returncode == 0, conv.stderr
    q = []
    with out.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, _channel, _message, msg in reader.iter_decoded_messages(
                topics=["/joint_states"]):
            names = list(msg.name)
            q.append(list(msg.position))
    qa = np.array(q)
    track = 1000.0 - 1284092.0 * qa[:, names.index("track")]
    pan = 52152.0 * qa[:, names.index("pan")]
    info = run_cli("info", out, "--json")
    counts = json.loads(info.stdout)["controller"]
    assert sorted(counts) == ["pan", "track"]
    assert counts["track"]["counts_range"] == pytest.approx([track.min(), track.max()],
                                                           rel=1e-12)
    assert counts["pan"]["counts_range"] == pytest.approx([pan.min(), pan.max()], rel=1e-12)
    text = run_cli("info", out).stdout
    assert (f"  track    1000 - 1.28409e+06 x q   [{track.min():.0f}, {track.max():.0f}]"
            in text), text
    robot.write_text(base + "\n[controller.track]\nscale = 0.0\n", encoding="utf-8")
    bad = run_cli("check", SHOTS / "blender_crane_up.usda", "--robot", robot)
    assert bad.returncode == 2
    assert "[controller.track.scale] = 0: must be positive" in bad.stderr, bad.stderr
