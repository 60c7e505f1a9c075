"""What the report shows: one plain data object, :class:`ReportData`, from either source.

- :func:`from_analysis`: the in-memory run of ``camtraj convert --report`` / ``check --report``,
  including a shot that fails (its own timing's samples with the violations, or the camera
  path with the frames the robot cannot reach);
- :func:`from_take`: a camtraj MCAP read back (``camtraj report OUT.mcap``): servo samples from
  /joint_trajectory (jerk by differences of the accelerations), frames from /shot/frames,
  limits from the ``camtraj.robot`` metadata, link origins from /tf.

Either way the servo samples are folded, a block at a time, into a
:class:`~camtraj.report.samples.Samples` (per-plot min/max per pixel column, per-frame peaks),
so the report of a long take needs memory for its film frames, not its servo samples.

:mod:`camtraj.report.page` renders it (:func:`~camtraj.report.page.render_html`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from camtraj.analysis import camera_travel, placement_text, take_axes, take_limits
from camtraj.errors import (
    InfeasibleError,
    InputError,
    LensRangeError,
    UnreachableFramesError,
)
from camtraj.report.samples import Samples, in_blocks, reduce_samples
from camtraj.shown import TIMES, frame_runs, listed
from camtraj.timing.limits import LIMIT_RTOL, QUANTITIES

if TYPE_CHECKING:
    from camtraj.analysis import Analysis
    from camtraj.mcap_io import ReportTake
    from camtraj.options import ConvertOptions

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Above 1 + LIMIT_RTOL of a limit a sample counts as over it; above 1 + this for a take read
#: back from MCAP: its jerk is by differences of the recorded accelerations, which sit on the
#: jerk limit to ~1e-8 in the run-up and run-out.
MCAP_RTOL = 1e-6
#: Robot poses drawn as stick figures in the path views.
N_POSES = 5


@dataclass(frozen=True)
class Violation:
    """One axis over one limit on runs of film frames (inclusive), e.g. pan acceleration."""

    axis: str
    quantity: str
    ratio: float  # peak / limit (position: the position use, 1 at a bound)
    frames: tuple[tuple[int, int], ...]
    text: str

    @property
    def frame_text(self) -> str:
        return frame_runs(self.frames)


@dataclass(frozen=True, eq=False)
class ReportData:
    """Everything the report shows, in SI units and the robot base frame.

    Attributes:
        shot: The shot file. camera: Its camera prim. robot: Robot name and source.
        status: ``"ok"``, ``"limits"`` (the shot's timing exceeds a limit),
            ``"unreachable"`` (frames the robot cannot reach), ``"lens_range"`` (the shot
            asks the lens for more than its calibration covers) or ``"collision"`` (a take
            inside every limit that hits the set). message: Why not (one line).
        timing: Timing mode. speed_factor: Take duration of the shot / its own duration.
        servo_rate_hz: Servo rate. fps: Film frame rate.
        servo_step_ms: The shortest and longest servo step [ms] (they differ in an optimal
            retime); None when not known (a file written before convert recorded them).
        max_speed: Maximum feasible speed as a fraction of real time (nan: not known).
        max_speed_set_by: What sets it (``TimingReport.set_by``; "" when not known).
        placement: How the base was placed (text). base2world: The placement, (4, 4).
        joint_names: Axis names (8,). revolute: Whether each axis is revolute, (8,).
        lower, upper, velocity, acceleration, jerk: The robot's limits, (8,) each.
        samples: What the report keeps of the servo samples; None without a joint path.
        frame_numbers: Film frame numbers, (n,). frame_times: Their take times [s], (n,).
        shot_start, shot_end: Take time of the first and the last film frame [s].
        camera_path: Requested camera position per frame [m], (n, 3).
        camera_look: Its viewing direction (unit), (n, 3).
        poses: Link origins of a few robot poses [m], (k, p, 3), base first, camera last.
        pose_frames: The film frame of each pose, (k,).
        track: The track's two ends (its min and max travel) [m], (2, 3).
        violations: Every limit the samples exceed, worst first.
        unreachable: Film frames the robot cannot reach.
        warnings: Things a person should know that do not stop the take.
        tolerance: Fraction above a limit that counts as over it.
        source: Where the data came from (the MCAP file, or "convert"/"check").
        margins: The terminal's margins, when the take is done.
        edges: The run-up's and run-out's own peak use, when they are planned.
        edge_travel: How far the run-up and run-out move (m) and turn (deg) the camera from the
            first and last frame's pose, when recorded.
    """

    shot: str
    camera: str
    robot: str
    status: str
    message: str
    timing: str
    speed_factor: float
    servo_rate_hz: float
    fps: float
    max_speed: float
    placement: str
    base2world: Array
    joint_names: tuple[str, ...]
    revolute: NDArray[np.bool_]
    lower: Array
    upper: Array
    velocity: Array
    acceleration: Array
    jerk: Array
    samples: Samples | None
    frame_numbers: IntArray
    frame_times: Array
    shot_start: float
    shot_end: float
    camera_path: Array
    camera_look: Array
    poses: Array
    pose_frames: IntArray
    track: Array
    violations: tuple[Violation, ...] = ()
    unreachable: tuple[int, ...] = ()
    warnings: tuple[str, ...] = ()
    tolerance: float = LIMIT_RTOL
    source: str = "convert"
    margins: dict[str, Any] | None = None  # convert's margins_summary
    # "runup"/"runout" -> axis -> quantity -> fraction of the limit
    edges: dict[str, dict[str, dict[str, float]]] | None = None
    servo_step_ms: tuple[float, float] | None = None
    max_speed_set_by: str = ""  # what sets max_speed (TimingReport.set_by); "" unknown
    # how far the run-up and run-out move [m] and turn [deg] the camera from the first / last
    # frame's pose (analysis.camera_travel); None: not recorded (older files)
    edge_travel: tuple[tuple[float, float], tuple[float, float]] | None = None
    lens: str = ""  # the lens whose motors the take drives (lens_text), "" without one

    @property
    def has_take(self) -> bool:
        """Whether the data holds a take (inside every limit, with run-up and run-out)."""
        return self.status in ("ok", "collision") and self.samples is not None

    def limit(self, quantity: str) -> Array:
        """The symmetric limit of velocity, acceleration or jerk, shape (8,)."""
        return {"velocity": self.velocity, "acceleration": self.acceleration,
                "jerk": self.jerk}[quantity]

    def violation_frames(self) -> list[int]:
        """Every film frame inside a violation's frame runs."""
        out: set[int] = set()
        for v in self.violations:
            for a, b in v.frames:
                out.update(range(a, b + 1))
        return sorted(out)


# ---------------------------------------------------------------------------------------------
# Shared pieces of the two builders
# ---------------------------------------------------------------------------------------------


def violations_from_samples(data: ReportData) -> tuple[Violation, ...]:
    """Every (axis, quantity) whose samples exceed the limit, worst first.

    A sample between two film frames counts for both (as in the timing report); run-up
    samples count for the first frame, run-out samples for the last
    (:attr:`Samples.frame_peak`).
    """
    if data.samples is None:
        return ()
    fn = data.frame_numbers
    out: list[Violation] = []
    for k, quantity in enumerate(QUANTITIES):
        peak = data.samples.frame_peak[k]
        for i, name in enumerate(data.joint_names):
            idx = np.flatnonzero(peak[:, i] > 1.0 + data.tolerance)
            if not idx.size:
                continue
            frames = _runs([int(fn[j]) for j in idx], [int(j) for j in idx])
            ratio = float(peak[:, i].max())
            text = f"{name} {quantity} {ratio:.3g}{TIMES} its limit on " + _frames_text(frames)
            out.append(Violation(name, quantity, ratio, frames, text))
    out.sort(key=lambda v: -v.ratio)
    return tuple(out)


def _runs(numbers: list[int], indices: list[int]) -> tuple[tuple[int, int], ...]:
    """Runs of consecutive frame indices as (first, last) frame numbers."""
    runs: list[tuple[int, int]] = []
    prev = -2
    for num, idx in zip(numbers, indices, strict=True):
        if runs and idx == prev + 1:
            runs[-1] = (runs[-1][0], num)
        else:
            runs.append((num, num))
        prev = idx
    return tuple(runs)


def _frames_text(frames: tuple[tuple[int, int], ...]) -> str:
    return frame_runs(frames)


def track_ends(link2base: Array, lower: float, upper: float) -> Array:
    """The track's ends in the base frame, (2, 3), from one pose's link frames (p, 4, 4).

    The track value is measured along frame 0's z axis from the base origin, so the ends are
    the base origin plus the limits along that axis (the carriage's frame 1 sits a constant
    offset further on).
    """
    origin, direction = link2base[0, :3, 3], link2base[0, :3, 2]
    return np.stack([origin + lim * direction for lim in (lower, upper)])


def pose_indices(n: int, k: int = N_POSES) -> IntArray:
    """Up to k frame indices spread over n frames, first and last included."""
    out: IntArray = np.unique(np.round(np.linspace(0, n - 1, min(n, k))).astype(np.int64))
    return out


def _base2world(desc: dict[str, Any]) -> Array:
    T = np.eye(4)
    T[:3, :3] = np.asarray(desc.get("rotation", np.eye(3)), dtype=float)
    T[:3, 3] = np.asarray(desc.get("translation_m", (0.0, 0.0, 0.0)), dtype=float)
    return T


# ---------------------------------------------------------------------------------------------
# Builder 1: the in-memory analysis of convert / check
# ---------------------------------------------------------------------------------------------


def from_analysis(
    analysis: Analysis,
    shot_path: str | Path,
    options: ConvertOptions,
    *,
    warnings: Sequence[str] = (),
    error: InfeasibleError | None = None,
    source: str = "convert",
) -> ReportData:
    """The report of a run: a finished take, or a shot that failed with ``error``.

    Args:
        analysis: What the run computed (``take`` None when the timing failed, ``path``
            None too when frames are unreachable).
        shot_path: The shot file as given.
        options: The run's options (timing mode, servo rate).
        warnings: The run's warnings (convert.summary's).
        error: The failure, when the shot cannot be done as asked.
        source: The command that ran (shown in the page's footer).
    """
    from camtraj.analysis import margins_summary
    from camtraj.timing import TimingLimitError

    shot, robot, take, path = analysis.shot, analysis.robot, analysis.take, analysis.path
    limits = take_limits(robot)
    n = shot.frames.shape[0]
    common: dict[str, Any] = {
        "shot": str(shot_path), "camera": shot.camera_path,
        "robot": f"{robot.name} ({robot.source})", "fps": float(shot.fps),
        "lens": "" if robot.lens is None else lens_text(robot.lens.describe()),
        "placement": placement_text(analysis.placement.describe()),
        "base2world": analysis.placement.base2world.copy(),
        "joint_names": tuple(limits.names), "revolute": limits.revolute.copy(),
        "lower": limits.lower.copy(), "upper": limits.upper.copy(),
        "velocity": limits.velocity.copy(), "acceleration": limits.acceleration.copy(),
        "jerk": limits.jerk.copy(), "frame_numbers": shot.frames.astype(np.int64),
        "camera_path": analysis.targets[:, :3, 3].copy(),
        "camera_look": -analysis.targets[:, :3, 2],
        "warnings": tuple(warnings), "source": source,
    }
    poses, pose_frames, track = _in_memory_poses(analysis)
    common.update(poses=poses, pose_frames=pose_frames, track=track)
    bounds = (limits.lower, limits.upper, (limits.velocity, limits.acceleration, limits.jerk))
    if take is not None:
        samples = _reduce(take.t, take.q, take.qd, take.qdd, take.qddd, take.frame_times,
                          (float(take.shot_start), float(take.shot_end)), *bounds)
        data = ReportData(
            # a take inside every limit fails only where it hits the set (collision.check_take)
            **common, status="ok" if error is None else "collision",
            message="" if error is None else str(error), timing=take.mode,
            speed_factor=float(take.speed_factor), servo_rate_hz=float(take.rate),
            servo_step_ms=take.servo_steps_ms, max_speed=float(take.report.max_speed),
            max_speed_set_by=take.report.set_by,
            samples=samples,
            frame_times=take.frame_times,
            shot_start=float(take.shot_start), shot_end=float(take.shot_end),
            tolerance=LIMIT_RTOL,
            margins=None if path is None else margins_summary(analysis),
            edges={"runup": take.report.runup.get("peak_use", {}),
                   "runout": take.report.runout.get("peak_use", {})},
            edge_travel=camera_travel(analysis),
        )
        return data
    frame_times = shot.times - shot.times[0]
    if isinstance(error, LensRangeError):  # found before the solve: nothing more to show
        return ReportData(
            **common, samples=None, status="lens_range", message=str(error),
            timing=options.timing, speed_factor=math.nan, servo_rate_hz=math.nan,
            max_speed=math.nan, frame_times=frame_times, shot_start=0.0,
            shot_end=float(frame_times[-1]),
        )
    if isinstance(error, UnreachableFramesError) or path is None:
        unreachable = tuple(sorted(int(e.frame) for e in getattr(error, "errors", ())
                                   if e.frame is not None))
        return ReportData(
            **common, samples=None, status="unreachable", message=str(error or ""),
            timing=options.timing, speed_factor=math.nan, servo_rate_hz=math.nan,
            max_speed=math.nan, frame_times=frame_times, shot_start=0.0,
            shot_end=float(frame_times[-1]), unreachable=unreachable,
        )
    # The timing failed: show the shot at its own timing, where the check measured it.
    max_speed = error.max_speed if isinstance(error, TimingLimitError) else math.nan
    t, q, qd, qdd, qddd, rate = shot_timing_samples(analysis, options.rate, max_speed)
    violations = _violations(getattr(error, "violations", []))
    shot_span = (0.0, float(frame_times[-1]))
    return ReportData(
        **common, status="limits", message=str(error or ""), timing=options.timing,
        speed_factor=1.0, servo_rate_hz=rate, max_speed=max_speed,
        samples=_reduce(t, q, qd, qdd, qddd, frame_times[:n], shot_span, *bounds),
        frame_times=frame_times[:n], shot_start=0.0,
        shot_end=float(frame_times[-1]), violations=violations,
    )


def _reduce(t: Array, q: Array, qd: Array, qdd: Array, qddd: Array, frame_times: Array,
            shot: tuple[float, float], lower: Array, upper: Array,
            limits: tuple[Array, Array, Array]) -> Samples:
    """Samples already in memory, reduced as a file's are."""
    return reduce_samples(in_blocks(t, q, qd, qdd, qddd), count=t.shape[0],
                          start=float(t[0]), end=float(t[-1]), frame_times=frame_times,
                          shot=shot, lower=lower, upper=upper, limits=limits)


def _violations(found: Sequence[Any]) -> tuple[Violation, ...]:
    """The timing stage's own LimitViolations as report records."""
    return tuple(Violation(v.axis, v.quantity, float(v.ratio), tuple(v.frames), v.describe())
                 for v in found)


def _with_violations(data: ReportData) -> ReportData:
    from dataclasses import replace

    return replace(data, violations=violations_from_samples(data))


def _in_memory_poses(analysis: Analysis) -> tuple[Array, IntArray, Array]:
    """Link origins of a few solved frames, their frame numbers and the track's ends."""
    robot, path, shot = analysis.robot, analysis.path, analysis.shot
    idx = pose_indices(0 if path is None else path.q.shape[0])
    qs = robot.home[None] if path is None else path.q[idx]
    frames = robot.link_frames(qs)
    track = track_ends(frames[0], float(robot.lower[0]), float(robot.upper[0]))
    if path is None:  # nothing solved to draw; the track still shows where the robot is
        return np.zeros((0, 11, 3)), idx, track
    cams = frames[:, -1] @ robot.camera2flange
    origins = np.concatenate(
        [np.zeros((qs.shape[0], 1, 3)), frames[:, :, :3, 3], cams[:, None, :3, 3]], axis=1)
    return origins, shot.frames[idx].astype(np.int64), track


def shot_timing_samples(
    analysis: Analysis, rate: float, max_speed: float
) -> tuple[Array, Array, Array, Array, Array, float]:
    """The shot part sampled at the film's own timing: what ``--timing shot`` checked.

    ``time_shot`` in "shot" mode samples the path at the film's timing whatever the limits;
    given limits loose enough to fit (scaled by the maximum feasible speed, positions
    widened) it returns that take instead of raising, and its shot part is exactly the
    samples the failed check measured. The run-up and run-out of that take mean nothing
    (they are planned against the loosened limits) and are cut off.

    Returns:
        ``(t, q, qd, qdd, qddd, rate)``: times from the first film frame [s], (m,), the four
        quantities (m, 8) and the servo rate [Hz].
    """
    from camtraj.ik import camera_holds
    from camtraj.timing import Limits, time_shot

    robot, shot, path = analysis.robot, analysis.shot, analysis.path
    assert path is not None
    q_frames, real = take_axes(robot, path.q, analysis.lens_q)
    f = 1.05 / max_speed if math.isfinite(max_speed) and max_speed > 0 else 1.0
    f = max(1.0, f)
    span = real.upper - real.lower
    loose = Limits(lower=real.lower - 10 * span, upper=real.upper + 10 * span,
                   velocity=real.velocity * f, acceleration=real.acceleration * f**2,
                   jerk=real.jerk * f**3, names=real.names, kinds=real.kinds)
    take = time_shot(q_frames, shot.times, loose, mode="shot", rate=rate,
                     frame_numbers=shot.frames, hold=camera_holds(analysis.targets),
                     rest=path.rest_axes(q_frames.shape[1]))
    a, b = int(take.frame_samples[0]), int(take.frame_samples[-1]) + 1
    return (take.t[a:b] - take.t[a], take.q[a:b], take.qd[a:b], take.qdd[a:b],
            take.qddd[a:b], float(take.rate))


# ---------------------------------------------------------------------------------------------
# Builder 2: a camtraj MCAP read back
# ---------------------------------------------------------------------------------------------


def from_take(take: ReportTake, source: str | Path) -> ReportData:
    """The report of a converted take, from its MCAP file read back.

    Raises:
        InputError: The file lacks what a report needs (the robot's limits, the frames).
    """
    from camtraj.mcap_io import ROBOT_METADATA_NAME

    md = take.metadata
    robot_md = take.all_metadata.get(ROBOT_METADATA_NAME)
    if not robot_md or take.frame_numbers.size < 1:
        msg = f"{source}: no robot limits or no shot frames recorded; not a camtraj take?"
        raise InputError(msg)
    where = f"{source}: the camtraj metadata"
    from camtraj.robot import JOINT_KINDS

    lens = _lens_axes(robot_md.get("lens"), f"{where} {ROBOT_METADATA_NAME}.lens")
    n = len(take.joint_names)
    if n != len(JOINT_KINDS) + len(lens) or take.point_count < 1:
        msg = (f"{source}: /joint_trajectory has {n} joints and {take.point_count} points; "
               f"a camtraj take has {len(JOINT_KINDS)} joints"
               + (f" and {len(lens)} lens axes" if lens else ""))
        raise InputError(msg)
    lim = {k: _numbers(_joined(robot_md.get(k), lens, k), n,
                       f"{where} {ROBOT_METADATA_NAME}.{k}")
           for k in ("lower", "upper", "max_velocity", "max_acceleration", "max_jerk")}
    if not np.all(lim["lower"] < lim["upper"]):
        msg = f"{where} {ROBOT_METADATA_NAME}: every lower limit must be below its upper"
        raise InputError(msg)
    for k in ("max_velocity", "max_acceleration", "max_jerk"):
        if not np.all((lim[k] > 0.0) & (lim[k] <= MAX_LIMIT)):
            msg = (f"{where} {ROBOT_METADATA_NAME}.{k} must be positive and at most "
                   f"{MAX_LIMIT:g}")
            raise InputError(msg)
    try:
        placement = json.loads(md.get("placement", "{}"))
        warnings = json.loads(md.get("warnings", "[]"))
        margins = json.loads(md["margins"]) if "margins" in md else None  # older files: none
        edges = json.loads(md["edge_peak_use"]) if "edge_peak_use" in md else None
        steps = json.loads(md["servo_step_ms"]) if "servo_step_ms" in md else None
        travel = json.loads(md["edge_camera_travel"]) if "edge_camera_travel" in md else None
    except (RecursionError, ValueError) as exc:
        msg = f"{where} cannot be read ({exc})"
        raise InputError(msg) from None
    _check_placement(placement, f"{where} placement")
    if margins is not None and not _margins_ok(margins):
        msg = f"{where} margins must hold to_limits, to_limits_frame (per axis) and the wrist " \
              "and stretch margins with their frames"
        raise InputError(msg)
    if edges is not None and not _edges_ok(edges):
        msg = f"{where} edge_peak_use must map runup and runout to axis -> quantity -> number"
        raise InputError(msg)
    if travel is not None and not _travel_ok(travel):
        msg = f"{where} edge_camera_travel must map runup and runout to m and deg (numbers >= 0)"
        raise InputError(msg)
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        msg = f"{where} warnings must be a list of texts"
        raise InputError(msg)
    if steps is not None and not (isinstance(steps, list) and len(steps) == 2 and all(
            isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in steps)):
        msg = f"{where} servo_step_ms must be the shortest and longest step [ms], two numbers"
        raise InputError(msg)
    for key in ("fps", "servo_rate_hz", "speed_factor"):
        value = _float(md.get(key))
        if not (math.isfinite(value) and value > 0.0):
            msg = f"{where} {key} = {md.get(key)!r} must be a positive number"
            raise InputError(msg)
    if take.tf_count == 0 or take.tf_times.size == 0:
        msg = f"{source}: no /tf messages; the report's robot views need them"
        raise InputError(msg)
    from camtraj.report.samples import jerk_by_differences

    names = tuple(take.joint_names)
    revolute = np.array([k == "revolute" for k in JOINT_KINDS] + [True] * len(lens))
    mode = md.get("timing_mode", "?")
    poses, pose_frames, track = _tf_poses(take, float(lim["lower"][0]), float(lim["upper"][0]))
    ft = take.frame_times
    first, last = take.count_before(ft[[0, -1]] - 1e-9).tolist()
    shot = (float(ft[0]), float(ft[-1]))
    limits = (lim["max_velocity"], lim["max_acceleration"], lim["max_jerk"])
    samples = reduce_samples(
        jerk_by_differences(take.trajectory_blocks(), take.point_count, (first, last)),
        count=take.point_count, start=take.first_time, end=take.last_time, frame_times=ft,
        shot=shot, lower=lim["lower"], upper=lim["upper"], limits=limits)
    if edges is None:  # older files: the run-up's and run-out's samples
        edges = {side: {name: dict(zip(QUANTITIES[1:], samples.edge_peak[k, 1:, i].tolist(),
                                       strict=True)) for i, name in enumerate(names)}
                 for k, side in enumerate(("runup", "runout"))}
    data = ReportData(
        shot=md.get("source_file", "?"), camera=md.get("camera_prim", "?"),
        robot=md.get("robot", "?"), status="ok", message="", timing=mode,
        lens=lens_text(json.loads(robot_md["lens"])) if lens else "",
        speed_factor=_float(md.get("speed_factor")), servo_rate_hz=_float(
            md.get("servo_rate_hz")), fps=_float(md.get("fps")),
        max_speed=_float(md.get("max_speed")), max_speed_set_by=md.get("max_speed_set_by", ""),
        placement=placement_text(placement),
        base2world=_base2world(placement), joint_names=names, revolute=revolute,
        lower=lim["lower"], upper=lim["upper"], velocity=lim["max_velocity"],
        acceleration=lim["max_acceleration"], jerk=lim["max_jerk"], samples=samples,
        frame_numbers=take.frame_numbers, frame_times=ft, shot_start=shot[0], shot_end=shot[1],
        camera_path=take.target[:, :3, 3].copy(), camera_look=-take.target[:, :3, 2],
        poses=poses, pose_frames=pose_frames, track=track, warnings=tuple(warnings),
        tolerance=MCAP_RTOL, source=str(source), margins=margins, edges=edges,
        servo_step_ms=None if steps is None else (float(steps[0]), float(steps[1])),
        edge_travel=None if travel is None else (
            (float(travel["runup"]["m"]), float(travel["runup"]["deg"])),
            (float(travel["runout"]["m"]), float(travel["runout"]["deg"]))),
    )
    return _with_violations(data)


MAX_LIMIT = 1.0e6
"""Largest velocity, acceleration or jerk limit a report takes [m or rad per s^k]."""


def _lens_axes(text: str | None, where: str) -> dict[str, dict[str, Any]]:
    """The lens motors recorded with the robot's limits (ring angles, after the joints)."""
    if text is None:
        return {}
    try:
        axes = json.loads(text)["axes"]
    except (RecursionError, ValueError, KeyError, TypeError):
        axes = None
    if not isinstance(axes, dict) or not all(isinstance(v, dict) for v in axes.values()):
        msg = f"{where} must name the lens axes and their limits"
        raise InputError(msg)
    return axes


def _joined(text: str | None, lens: dict[str, dict[str, Any]], key: str) -> str | None:
    """A robot limit's JSON list with the lens motors' values after the joints'."""
    if not lens or text is None:
        return text
    try:
        values = json.loads(text)
    except (RecursionError, ValueError):
        return text
    extra = [axis.get(key) for axis in lens.values()]
    return json.dumps(values + extra) if isinstance(values, list) else text


def _numbers(text: str | None, n: int, where: str) -> Array:
    """``n`` finite numbers from a JSON list, or InputError naming ``where``."""
    try:
        value = json.loads(text) if text is not None else None
    except (RecursionError, ValueError):
        value = None
    ok = isinstance(value, list) and len(value) == n and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in value)
    if not ok:
        msg = f"{where} must be a list of {n} finite numbers"
        raise InputError(msg)
    return np.asarray(value, dtype=float)


def _check_placement(desc: Any, where: str) -> None:
    """The recorded placement: translation_m 3 numbers, rotation 3x3, yaw_deg a number."""
    def finite(v: Any, shape: tuple[int, ...]) -> bool:
        try:
            a = np.asarray(v)
        except ValueError:  # ragged lists
            return False
        return (a.shape == shape and a.dtype.kind in "iuf"
                and bool(np.all(np.isfinite(a.astype(float)))))

    ok = (isinstance(desc, dict)
          and finite(desc.get("translation_m", (0.0, 0.0, 0.0)), (3,))
          and finite(desc.get("rotation", np.eye(3)), (3, 3))
          and finite(desc.get("yaw_deg", 0.0), ()))
    if not ok:
        msg = f"{where} must hold translation_m (3 numbers), rotation (3x3) and yaw_deg"
        raise InputError(msg)


def _margins_ok(m: Any) -> bool:
    def number(x: Any) -> bool:
        return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)

    return (isinstance(m, dict)
            and all(isinstance(m.get(k), dict) and len(m[k]) >= 8  # the joints, the lens
                    and all(number(v) for v in m[k].values())
                    for k in ("to_limits", "to_limits_frame"))
            and all(number(m.get(k)) for k in ("wrist_singularity_deg", "wrist_singularity_frame",
                                                "full_stretch_deg", "full_stretch_frame")))


def _edges_ok(e: Any) -> bool:
    return (isinstance(e, dict) and set(e) == {"runup", "runout"}
            and all(isinstance(side, dict) and all(
                isinstance(use, dict) and all(
                    isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                    for v in use.values()) for use in side.values()) for side in e.values()))


def lens_text(desc: dict[str, Any]) -> str:
    """'Cine zoom 24-290 mm T2.8 (lens file lenses/zoom.toml): zoom, focus and iris motors'
    of a lens's ``describe()``."""
    axes = list(desc.get("axes", {}))
    return (f"{desc.get('name', '?')} (lens file {desc.get('source', '?')}): {listed(axes)} "
            f"motor{'s' if len(axes) > 1 else ''}")


def _travel_ok(t: Any) -> bool:
    return (isinstance(t, dict) and set(t) == {"runup", "runout"}
            and all(isinstance(side, dict) and set(side) == {"m", "deg"} and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                and v >= 0.0 for v in side.values()) for side in t.values()))


def _float(text: str | None) -> float:
    try:
        return float(text) if text is not None else math.nan
    except (RecursionError, ValueError):
        return math.nan


def _pose_times(frame_times: Array) -> Array:
    """The take times of the frames drawn as robot poses (the /tf samples a report reads)."""
    out: Array = frame_times[pose_indices(frame_times.size)]
    return out


def _tf_poses(take: ReportTake, lower: float, upper: float) -> tuple[Array, IntArray, Array]:
    """Link origins from /tf at a few film frames (the nearest /tf sample), and the track."""
    from camtraj.urdf import BASE_FRAME, CAMERA_FRAME, LINK_FRAMES

    chain = [*LINK_FRAMES, CAMERA_FRAME]
    k_idx = pose_indices(take.frame_numbers.size)
    tf_i = np.arange(take.tf_times.size)  # read at _pose_times, one per pose

    def to_base(frame: str, j: int) -> Array:
        T = np.eye(4)
        for _ in range(len(take.tf) + len(take.tf_static) + 1):  # no loop in a bad tree
            if frame == BASE_FRAME:
                return T
            if frame in take.tf:
                parent, mats = take.tf[frame]
                T = mats[j] @ T
            elif frame in take.tf_static:
                parent, mat = take.tf_static[frame]
                T = mat @ T
            else:
                break
            frame = parent
        msg = f"/tf has no path from {frame} to {BASE_FRAME}"
        raise InputError(msg)

    frames = np.array([[to_base(f, int(j)) for f in chain] for j in tf_i])
    origins = np.concatenate([np.zeros((len(tf_i), 1, 3)), frames[:, :, :3, 3]], axis=1)
    track = track_ends(frames[0], lower, upper)
    return origins, take.frame_numbers[k_idx].astype(np.int64), track


def report_from_mcap(path: str | Path) -> ReportData:
    """Read a camtraj MCAP and build its report data (``camtraj report``)."""
    from camtraj.mcap_io import read_take_for_report

    return from_take(read_take_for_report(path, _pose_times), path)
