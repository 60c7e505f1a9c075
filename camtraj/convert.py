"""The whole job: USD shot -> placed flange targets -> joint path -> timed take -> MCAP.

This module strings the stages together and owns the pieces that belong to no single stage:
the robot placement on set, the summary a person or a pipeline reads, and stage timings.
File I/O happens in the stage modules at the two ends (``usd_shot``, ``mcap_io``).
"""

from __future__ import annotations

import json
import math
import time
import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import camtraj
from camtraj.errors import InfeasibleError, InputError
from camtraj.ik import PathSolution, solve_path_report
from camtraj.mcap_io import TakeData, write_take
from camtraj.options import ConvertOptions
from camtraj.robot import JOINT_NAMES, REVOLUTE, Robot
from camtraj.timing import Limits, Take, time_shot
from camtraj.usd_shot import Shot, read_shot

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Placement:
    """Where the robot base stands in the stage (metres, Z-up after unit/axis conversion).

    ``base2world`` maps robot base coordinates into the converted stage world.
    """

    base2world: Array = field(default_factory=lambda: np.eye(4))
    source: str = "default (identity)"

    @classmethod
    def from_xyz_yaw(cls, x: float, y: float, z: float, yaw_deg: float,
                     source: str = "--placement") -> Placement:
        a = math.radians(yaw_deg)
        T = np.eye(4)
        T[:3, :3] = [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                     [0.0, 0.0, 1.0]]
        T[:3, 3] = (x, y, z)
        return cls(T, source)

    @classmethod
    def from_set_file(cls, path: str | Path) -> Placement:
        """A ``[placement]`` table: x, y, z [m], yaw_deg, or a full ``rotation`` 3x3 matrix."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            msg = f"set file {path}: cannot read it ({exc.strerror or exc})"
            raise InputError(msg) from exc
        except tomllib.TOMLDecodeError as exc:
            msg = f"set file {path}: not valid TOML ({exc})"
            raise InputError(msg) from exc
        table = data.get("placement")
        if not isinstance(table, dict):
            msg = f"set file {path}: needs a [placement] table"
            raise InputError(msg)
        allowed = {"x", "y", "z", "yaw_deg", "rotation"}
        unknown = sorted(set(table) - allowed)
        if unknown:
            msg = (f"set file {path}: unknown key(s) {', '.join(unknown)} in [placement]; "
                   f"allowed: {', '.join(sorted(allowed))}")
            raise InputError(msg)
        vals = {}
        for key in ("x", "y", "z", "yaw_deg"):
            v = table.get(key, 0.0)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                msg = f"set file {path}: [placement] {key} = {v!r} must be a finite number"
                raise InputError(msg)
            vals[key] = float(v)
        place = cls.from_xyz_yaw(vals["x"], vals["y"], vals["z"], vals["yaw_deg"], str(path))
        if "rotation" in table:
            if "yaw_deg" in table:
                msg = f"set file {path}: give either yaw_deg or rotation in [placement], not both"
                raise InputError(msg)
            R = np.asarray(table["rotation"], dtype=float)
            if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or \
                    np.linalg.det(R) < 0:
                msg = f"set file {path}: [placement] rotation must be a 3x3 proper rotation"
                raise InputError(msg)
            place.base2world[:3, :3] = R
        return place

    def describe(self) -> dict[str, Any]:
        R = self.base2world[:3, :3]
        return {
            "source": self.source,
            "translation_m": self.base2world[:3, 3].tolist(),
            "yaw_deg": math.degrees(math.atan2(R[1, 0], R[0, 0])),
            "rotation": R.tolist(),
        }


@dataclass
class Analysis:
    """Everything one run computed; ``take`` is None when the IK or timing stage failed."""

    shot: Shot
    robot: Robot
    placement: Placement
    targets: Array  # (n, 4, 4) camera2base
    path: PathSolution | None = None
    take: Take | None = None
    timings: dict[str, float] = field(default_factory=dict)


def load_robot(options: ConvertOptions) -> Robot:
    return Robot.default() if options.robot is None else Robot.from_toml(options.robot)


def load_placement(options: ConvertOptions) -> Placement:
    if options.placement is not None:
        x, y, z, yaw = options.placement
        return Placement.from_xyz_yaw(x, y, z, yaw)
    if options.set_file is not None:
        return Placement.from_set_file(options.set_file)
    return Placement()


@contextmanager
def _stage(timings: dict[str, float], name: str) -> Iterator[None]:
    t0 = time.perf_counter()
    try:
        yield
    finally:
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0


def analyse(
    shot_path: str | Path,
    options: ConvertOptions,
    *,
    progress: Callable[[int], None] | None = None,
    on_frames: Callable[[int], None] | None = None,
    on_start: Callable[[Analysis], None] | None = None,
) -> Analysis:
    """Read, place, solve and time a shot. Raises the stage's typed error on failure.

    Args:
        shot_path: The USD shot.
        options: What to do.
        progress: Called with the number of frames the IK just finished.
        on_frames: Called once with the frame count before the IK starts.
        on_start: Called once with the analysis before the IK starts; it is filled in as the
            stages finish, so after a failure it holds what was computed (for a report).
    """
    timings: dict[str, float] = {}
    with _stage(timings, "read"):
        robot = load_robot(options)
        placement = load_placement(options)
        shot = read_shot(shot_path, camera=options.camera, frames=options.frames)
        if shot.frames.shape[0] < 2:
            msg = f"{shot_path}: the shot has {shot.frames.shape[0]} frame(s); need at least 2"
            raise InputError(msg)
        targets = np.linalg.inv(placement.base2world) @ shot.cam2world
    analysis = Analysis(shot, robot, placement, targets, timings=timings)
    if on_start is not None:
        on_start(analysis)
    if on_frames is not None:
        on_frames(int(shot.frames.shape[0]))
    with _stage(timings, "ik"):
        flange2base = targets @ np.linalg.inv(robot.camera2flange)
        start = None if options.start_from is None else np.asarray(options.start_from, float)
        analysis.path = solve_path_report(
            robot, flange2base, start, objective=options.objective,
            frame_interval=1.0 / shot.fps, frame_numbers=shot.frames, progress=progress,
        )
    with _stage(timings, "timing"):
        analysis.take = time_shot(
            analysis.path.q, shot.times, Limits.from_robot(robot), mode=options.timing,
            rate=options.rate, frame_numbers=shot.frames,
        )
    return analysis


def convert(
    shot_path: str | Path,
    output_path: str | Path | None,
    options: ConvertOptions | None = None,
    *,
    progress: bool = False,
    report: str | Path | None = None,
) -> dict[str, Any]:
    """Convert one shot to a motion-control MCAP; returns the JSON-able summary.

    With ``output_path`` None nothing is written (``camtraj check``). Raises ``InputError``
    (exit 2) or ``InfeasibleError`` (exit 3) with the frames, axes and margins named; a failed
    run writes nothing and leaves an existing output untouched.

    ``report``: also write the HTML report (camtraj.report) there: rendered before the MCAP
    is written and written after it (if writing it fails, the MCAP is removed again). Without
    an MCAP (``check``) a shot that cannot be done gets its report too, showing why, before
    the error is raised.
    """
    options = options or ConvertOptions()
    bar = _ProgressBar(enabled=progress, label=Path(shot_path).name)
    started: list[Analysis] = []
    try:
        analysis = analyse(shot_path, options, progress=bar.update, on_frames=bar.start,
                           on_start=started.append)
    except InfeasibleError as exc:
        if report is not None and output_path is None and started:
            from camtraj import report as html_report

            html_report.write_report(report, html_report.from_analysis(
                started[0], shot_path, options, error=exc, source="check"))
        raise
    finally:
        bar.close()
    page = None
    if report is not None:  # rendered first: a failure here leaves no file behind
        from camtraj import report as html_report

        with _stage(analysis.timings, "report"):
            page = html_report.render_html(html_report.from_analysis(
                analysis, shot_path, options, warnings=run_warnings(analysis),
                source="convert" if output_path is not None else "check"))
    if output_path is not None:
        with _stage(analysis.timings, "write"):
            write_take(output_path, take_data(analysis), analysis.robot,
                       metadata(analysis, shot_path, options))
    if report is not None and page is not None:  # (both or neither)
        from camtraj.report import write_html

        try:
            write_html(report, page)
        except BaseException:
            if output_path is not None:  # all or nothing
                Path(output_path).unlink(missing_ok=True)
            raise
    return summary(analysis, shot_path, output_path, options)


def take_data(analysis: Analysis) -> TakeData:
    """The writer's view of a finished analysis."""
    take, shot, path = analysis.take, analysis.shot, analysis.path
    assert take is not None and path is not None
    return TakeData(
        joint_names=JOINT_NAMES,
        t=take.t, q=take.q, qd=take.qd, qdd=take.qdd,
        frame_numbers=shot.frames, frame_times=take.frame_times, frame_q=path.q,
        target=analysis.targets, achieved=analysis.robot.camera_pose(path.q),
        focal_length_mm=shot.focal_length_mm, focus_distance_m=shot.focus_distance_m,
        f_stop=shot.f_stop, fps=shot.fps,
    )


def metadata(analysis: Analysis, shot_path: str | Path, options: ConvertOptions) -> dict[str, str]:
    """The ``camtraj`` metadata record (design.md §4)."""
    take, shot, robot = analysis.take, analysis.shot, analysis.robot
    assert take is not None
    mount = {"camera2flange": robot.camera2flange.tolist()}
    return {
        "source_file": str(shot_path),
        "camera_prim": shot.camera_path,
        "frame_range": f"{int(shot.frames[0])}-{int(shot.frames[-1])}",
        "fps": repr(float(shot.fps)),
        "robot": f"{robot.name} ({robot.source})",
        "ik_objective": options.objective or robot.ik.objective,
        "placement": json.dumps(analysis.placement.describe(), sort_keys=True),
        "mount": json.dumps(mount, sort_keys=True),
        "timing_mode": take.mode,
        "speed_factor": repr(float(take.speed_factor)),
        "servo_rate_hz": repr(float(take.rate)),
        "max_speed": repr(float(take.report.max_speed)),
        "warnings": json.dumps(run_warnings(analysis)),
        "tool_version": f"camtraj {camtraj.__version__}",
    }


def _axis_value(name: str, value: float) -> float:
    """SI value for display: degrees for revolute axes, metres otherwise."""
    return math.degrees(value) if REVOLUTE[JOINT_NAMES.index(name)] else value


def run_warnings(analysis: Analysis) -> list[str]:
    """Things a person should know about a finished run that do not stop the take."""
    take, shot, path = analysis.take, analysis.shot, analysis.path
    assert take is not None and path is not None
    relaxed_margin = shot.frames[~path.within_margins].tolist()
    relaxed_step = shot.frames[~path.within_step].tolist()
    warnings = list(take.report.warnings)
    if relaxed_margin:
        warnings.append(f"{len(relaxed_margin)} frame(s) needed the hard joint limits "
                        f"(smooth margins relaxed): first {relaxed_margin[0]}")
    if relaxed_step and take.mode == "shot":
        warnings.append(f"{len(relaxed_step)} frame(s) move an axis faster than its velocity "
                        f"limit between frames: first {relaxed_step[0]}")
    return warnings


def summary(
    analysis: Analysis,
    shot_path: str | Path,
    output_path: str | Path | None,
    options: ConvertOptions,
) -> dict[str, Any]:
    """JSON-able summary of a successful run (angles in degrees, lengths in metres)."""
    take, shot, path = analysis.take, analysis.shot, analysis.path
    assert take is not None and path is not None
    rep = take.report
    warnings = run_warnings(analysis)

    def extents(part: dict[str, Any]) -> dict[str, Any]:
        return {
            "duration_s": part.get("duration", 0.0),
            "extent": {k: _axis_value(k, v) for k, v in part.get("extent", {}).items()},
        }

    return {
        "status": "ok",
        "shot": str(shot_path),
        "output": None if output_path is None else str(output_path),
        "camera": shot.camera_path,
        "frames": {"first": int(shot.frames[0]), "last": int(shot.frames[-1]),
                   "count": int(shot.frames.shape[0])},
        "fps": float(shot.fps),
        "robot": analysis.robot.name,
        "placement": analysis.placement.describe(),
        "timing": take.mode,
        "speed_factor": float(take.speed_factor),
        "servo_rate_hz": float(take.rate),
        "duration": float(take.duration),
        "shot_start": float(take.shot_start),
        "shot_end": float(take.shot_end),
        "max_speed": float(rep.max_speed),
        "feasible_fps": float(rep.feasible_fps),
        "peak_use": rep.peak_use,
        "runup": extents(rep.runup),
        "runout": extents(rep.runout),
        "warnings": warnings,
        "timings": {k: round(v, 4) for k, v in analysis.timings.items()},
        "tool_version": camtraj.__version__,
    }


class _ProgressBar:
    """A tqdm bar over the IK frames; silent unless enabled (the CLI enables it on a TTY)."""

    def __init__(self, *, enabled: bool, label: str) -> None:
        self.enabled = enabled
        self.label = label
        self.bar: Any = None

    def start(self, total: int) -> None:
        if self.enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=f"IK {self.label}", unit="frame", leave=False)

    def update(self, n: int) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


__all__ = [
    "Analysis",
    "ConvertOptions",
    "Placement",
    "analyse",
    "convert",
    "summary",
]
