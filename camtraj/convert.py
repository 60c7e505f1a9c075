"""The whole job: USD shot -> placed flange targets -> joint path -> timed take -> MCAP.

This module strings the stages together and owns the pieces that belong to no single stage:
the robot placement on set, the summary a person or a pipeline reads, and stage timings.
File I/O happens in the stage modules at the two ends (``usd_shot``, ``mcap_io``).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import camtraj
from camtraj import jsonsafe
from camtraj.analysis import (
    Analysis,
    Placement,
    axis_value,
    camera_travel,
    margins_summary,
    placement_text,
    take_axes,
)
from camtraj.errors import (
    InfeasibleError,
    InputError,
    LensFileError,
    RobotFileError,
    ShotFileError,
)
from camtraj.ik import PathSolution, camera_holds, solve_path_report
from camtraj.ik.path import move_to_start
from camtraj.inputs import require_regular_file, require_regular_files, run_inputs
from camtraj.mcap_io import TakeData, write_take_to
from camtraj.options import ConvertOptions
from camtraj.outputs import OutputSet
from camtraj.progress import Progress, Silent
from camtraj.robot import JOINT_NAMES, REVOLUTE, WRIST_FRAME, Robot
from camtraj.set_file import SetFile
from camtraj.shown import frame_runs, frame_span
from camtraj.timing import LimitViolation, TimingLimitError, time_shot
from camtraj.timing.path import REST_NAMES, runs
from camtraj.usd_shot import Shot, read_shot, stage_to_world

Array = NDArray[np.float64]


MAX_DISTANCE_M = 1.0e6
"""Farthest a camera may be from the stage origin [m]; beyond is a unit or export error."""
MAX_FPS = 100_000.0
"""Highest film frame rate [frames/s] a shot may have (USD falls back on it for time codes)."""


def check_shot(shot: Shot) -> None:
    """Refuse an absurd frame rate, or a camera farther than :data:`MAX_DISTANCE_M` out."""
    if not shot.fps <= MAX_FPS:
        msg = (f"{shot.source}: framesPerSecond {shot.fps:.6g} is more than {MAX_FPS:.0f}; "
               "check the stage's framesPerSecond and timeCodesPerSecond")
        raise ShotFileError(msg)
    dist = np.abs(shot.cam2world[:, :3, 3]).max(axis=1)  # no overflow, unlike a norm
    far = np.flatnonzero(~(dist <= MAX_DISTANCE_M))
    if far.size:
        i = int(far[0])
        msg = (f"{shot.source}: the camera is {dist[i]:.3g} m out from the stage origin at frame "
               f"{int(shot.frames[i])}, more than {MAX_DISTANCE_M:.0f} m "
               f"(metersPerUnit {shot.meters_per_unit:g}); check the stage units")
        raise ShotFileError(msg)


def load_shot(shot_path: str | Path, options: ConvertOptions) -> Shot:
    """Read the shot as ``convert`` and ``place`` both take it: checked, at least 2 frames.

    Raises:
        InputError: Unreadable shot, absurd rate or distances, fewer than 2 frames.
    """
    try:
        shot = read_shot(shot_path, camera=options.camera, frames=options.frames,
                         focal_length_unit=options.focal_length_unit)
    except UnicodeDecodeError:  # USD passes the file's bytes on in its messages
        msg = f"{shot_path}: not a readable USD file: it holds bytes that are not text"
        raise ShotFileError(msg) from None
    check_shot(shot)
    if shot.frames.shape[0] < 2:
        msg = f"{shot_path}: the shot has {shot.frames.shape[0]} frame(s); need at least 2"
        raise InputError(msg)
    return shot


def load_robot(options: ConvertOptions) -> Robot:
    """The robot of a run, with the lens of ``--lens`` (else the robot file's ``[lens]``)."""
    robot = Robot.default() if options.robot is None else Robot.from_toml(options.robot)
    if options.lens is not None:
        from dataclasses import replace

        from camtraj.lens import Lens

        robot = replace(robot, lens=Lens.from_toml(options.lens))
    return robot


def read_shared_inputs(options: ConvertOptions) -> None:
    """Read the robot, lens and set files of ``options`` as each shot's run will, for the
    commands that run many shots on them (batch, farm export): a bad one is one error
    before any shot runs. Raises the file's typed error (an :class:`InputError`)."""
    for path, what, error in ((options.robot, "robot file", RobotFileError),
                              (options.lens, "lens file", LensFileError),
                              (options.set_file, "set file", InputError)):
        if path is not None:
            require_regular_file(path, what, error)
    load_robot(options)
    load_set_file(options)


def load_set_file(options: ConvertOptions) -> SetFile | None:
    """``--set-file``, read once for the run (placement, its warnings, the collision check)."""
    return SetFile.read(options.set_file) if options.set_file is not None else None


def load_placement(options: ConvertOptions, sf: SetFile | None) -> Placement:
    """The robot base's placement: ``--placement``, else the set file's (``sf``, read from
    ``options.set_file``), else the stage origin. ``--placement`` over a set file's
    placement says which one it replaces (:attr:`Placement.overrides`, a warning of the
    run)."""
    from_file = None
    if sf is not None and sf.base2world is not None:
        layout = "" if sf.layout is None else f", layout {sf.layout}"
        from_file = Placement(sf.base2world, f"{options.set_file}{layout}")
    if options.placement is not None:
        x, y, z, yaw = options.placement
        given = Placement.from_xyz_yaw(x, y, z, yaw)
        # the same place however written (a rotation matrix, yaw 360 against 0): no warning
        if from_file is None or np.allclose(from_file.base2world, given.base2world,
                                            rtol=0.0, atol=1e-9):
            return given
        return replace(given, overrides=placement_text(from_file.describe()))
    return from_file or Placement()


def placement_notes(options: ConvertOptions, sf: SetFile | None, placement: Placement,
                    robot: Robot, shot: Shot) -> tuple[str, ...]:
    """Warnings about where the robot stands, against the set file: it has no placement of
    its own (the robot at the stage origin, where a wrong file given by mistake puts it), or
    the rail at the placement leaves its floor region or crosses a keep-out (checked as
    ``place`` checks its candidates: the rail's footprint). ``sf``: the set file read from
    ``options.set_file``."""
    if sf is None:
        return ()
    where = sf.source
    if sf.base2world is None and options.placement is None:
        return (f"the set file {where} has no [placement]: the robot base stands at the "
                "stage origin (camtraj place -o writes a set file with one)",)
    if sf.region is None and not sf.keep_out:
        return ()
    from camtraj.reach import floor_ok
    from camtraj.set_file import floor_polygon

    def polygon(points: Array, key: str) -> Array:
        return floor_polygon(points, shot.meters_per_unit, shot.up_axis, f"set file {where}",
                             key)

    try:  # a polygon place would refuse is not this run's error: said, not raised
        region = None if sf.region is None else polygon(sf.region, "floor.region")
        keep_out = [polygon(k, f"floor.keep_out[{i}]") for i, k in enumerate(sf.keep_out)]
    except InputError as exc:
        return (f"the rail's footprint was not checked against the floor: {exc}",)
    where_is = placement.describe()
    (x, y, _z), yaw = where_is["translation_m"], where_is["yaw_deg"]
    at = (np.array([x]), np.array([y]), np.array([yaw]))
    notes = []
    if region is not None and not floor_ok(robot, *at, region, [])[0]:
        notes.append(f"the rail at this placement is not wholly inside the floor region of "
                     f"{where}")
    crossed = [i for i, k in enumerate(keep_out) if not floor_ok(robot, *at, None, [k])[0]]
    if crossed:
        which = ", ".join(f"keep_out[{i}]" for i in crossed)
        notes.append(f"the rail at this placement crosses {which} of {where}")
    return tuple(notes)


CUT_RATIO = 8.0
"""A camera step this many times the largest of the steps around it is a jump (a cut)."""
CUT_MIN_M, CUT_MIN_RAD = 0.05, math.radians(5.0)
"""Steps smaller than these are never called a cut."""


def _turns(a: Array, b: Array) -> Array:
    """The angle [rad] (k,) the camera turns from each pose a (k, 4, 4) to b (k, 4, 4)."""
    rel = np.einsum("kji,kjl->kil", a[:, :3, :3], b[:, :3, :3])
    return np.asarray(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0,
                                        -1.0, 1.0)))


def camera_cuts(targets: Array, frames: NDArray[np.int_], around: int = 3) -> list[str]:
    """Where the camera jumps: a frame off the path alone (a bad or blocked key: the camera
    goes away on one frame and comes straight back, so its two steps are equal and neither is
    a jump against the other), and a step between two frames (a cut left in the shot). A
    jump is a translation or rotation :data:`CUT_RATIO` times the largest step within
    ``around`` frames of it (for a frame off the path: of its two steps, and the step from the
    frame before it to the frame after it), and above :data:`CUT_MIN_M` / :data:`CUT_MIN_RAD`;
    a frame off the path at a cut is both. One line per jump, then one with the ``--frames``
    ranges of the parts between the cuts (without the frames off the path there)."""
    n = targets.shape[0]
    if n < 3:
        return []
    kinds = []  # per kind: steps, steps across a frame, floor, unit; the steps either side
    for steps, across, floor, unit in (
            (np.linalg.norm(np.diff(targets[:, :3, 3], axis=0), axis=1),
             np.linalg.norm(targets[2:, :3, 3] - targets[:-2, :3, 3], axis=1), CUT_MIN_M, "m"),
            (_turns(targets[:-1], targets[1:]), _turns(targets[:-2], targets[2:]), CUT_MIN_RAD,
             "deg")):
        padded = np.concatenate([np.zeros(around), steps, np.zeros(around)])
        window = np.lib.stride_tricks.sliding_window_view(padded, around).max(axis=-1)
        before, after = window[:-around - 1], window[around + 1:]  # the steps on either side
        kinds.append((steps, across, floor, unit, before, after))
    pops: dict[int, str] = {}  # frame index -> its line
    for steps, across, floor, unit, before, after in kinds:
        away = np.minimum(steps[:-1], steps[1:])  # frame k = 1 .. n - 2: there and back
        others = np.maximum(np.maximum(before[:-1], after[1:]), across)
        for k in (np.flatnonzero((away > floor) & (away > CUT_RATIO * others)) + 1).tolist():
            agree = all(float(a[k - 1]) <= f for _, a, f, *_ in kinds)
            pops.setdefault(k, (
                f"the camera jumps {_jump(float(away[k - 1]), unit)} off its path on frame "
                f"{int(frames[k])} alone and back"
                + (f" (frames {int(frames[k - 1])} and {int(frames[k + 1])} agree)" if agree
                   else "") + f": a bad or blocked key at frame {int(frames[k])}?"))
    cuts: dict[int, tuple[int, str]] = {}  # last frame before a cut -> (first after, its line)
    for steps, across, floor, unit, before, after in kinds:
        near = np.maximum(before, after)
        for k in np.flatnonzero((steps > floor) & (steps > CUT_RATIO * near)).tolist():
            if k in pops or k + 1 in pops or k in cuts:
                continue  # a step to or from a frame off the path
            ratio = (f"{steps[k] / near[k]:.0f}x the steps around it" if near[k] > 1e-6 * floor
                     else "the camera holds still around it")
            cuts[k] = (k + 1, f"the camera jumps {_jump(float(steps[k]), unit)} between frames "
                              f"{int(frames[k])} and {int(frames[k + 1])} ({ratio}): a cut in "
                              f"the shot?")
        # across a frame off the path: the frames either side of it are apart as at a cut
        others = np.maximum(before[:-1], after[1:])
        for k in pops:
            if k - 1 in pops or k + 1 in pops:
                continue  # its neighbour is off the path too: no good frame either side
            if (k - 1 not in cuts and across[k - 1] > floor
                    and across[k - 1] > CUT_RATIO * others[k - 1]):
                size = _jump(float(across[k - 1]), unit)
                cuts[k - 1] = (k + 1, f"the camera jumps {size} between frames "
                                      f"{int(frames[k - 1])} and {int(frames[k + 1])} across "
                                      f"frame {int(frames[k])}: a cut in the shot?")
    out = [pops[k] for k in sorted(pops)] + [cuts[k][1] for k in sorted(cuts)]
    if cuts:
        ends = sorted(cuts)
        firsts = [0, *(cuts[k][0] for k in ends)]
        lasts = [*ends, n - 1]
        # a part of one frame is no shot (convert needs two): it is left out, and said
        parts = [(a, b) for a, b in zip(firsts, lasts, strict=True) if b > a]
        kept = np.zeros(n, dtype=bool)
        for a, b in parts:
            kept[a:b + 1] = True
        if parts:
            left = [(int(frames[a]), int(frames[b - 1])) for a, b in runs(~kept)]
            said = (f"frame {left[0][0]}" if len(left) == 1 and left[0][0] == left[0][1]
                    else frame_runs(left))
            out.append("to split the shot there, convert each part on its own: "
                       + ", ".join(f"--frames {int(frames[a])}:{int(frames[b])}"
                                   for a, b in parts)
                       + (f" (leaving out {said})" if left else ""))
    return out


def _jump(size: float, unit: str) -> str:
    """A jump's size as :func:`camera_cuts` says it: metres, or a turn in degrees."""
    return f"{size:.3f} m" if unit == "m" else f"{math.degrees(size):.1f} deg"


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
    progress: Progress | None = None,
    on_start: Callable[[Analysis], None] | None = None,
) -> Analysis:
    """Read, place, solve and time a shot. Raises the stage's typed error on failure.

    Args:
        shot_path: The USD shot.
        options: What to do.
        progress: Told of each stage (``read``, ``solve`` frame by frame, ``time``).
        on_start: Called once with the analysis before the IK starts; it is filled in as the
            stages finish, so after a failure it holds what was computed (for a report).
    """
    progress = progress or Silent()
    timings: dict[str, float] = {}
    progress.stage("read")
    with _stage(timings, "read"):
        require_regular_files(shot_path, options)
        robot = load_robot(options)
        start = (None if options.start_from is None
                 else robot.joint_vector(options.start_from, "--start-from"))
        set_file = load_set_file(options)
        placement = load_placement(options, set_file)
        shot = load_shot(shot_path, options)
        placement = replace(placement,
                            notes=placement_notes(options, set_file, placement, robot, shot))
        targets = np.linalg.inv(placement.base2world) @ shot.cam2world
    analysis = Analysis(shot, robot, placement, targets, timings=timings)
    if on_start is not None:
        on_start(analysis)
    try:
        _solve_and_time(analysis, shot_path, options, set_file, start, progress)
    except InfeasibleError as exc:  # what reading the shot warned of is often why
        exc.shot_warnings = tuple(shot.warnings)
        raise
    return analysis


def _solve_and_time(analysis: Analysis, shot_path: str | Path, options: ConvertOptions,
                    set_file: SetFile | None, start: Array | None, progress: Progress) -> None:
    """:func:`analyse`'s IK, timing and collision stages, filling in ``analysis``
    (``set_file``: the one ``options.set_file`` names, read)."""
    shot, robot, targets, timings = (analysis.shot, analysis.robot, analysis.targets,
                                     analysis.timings)
    if robot.lens is not None:  # a frame beyond the lens's calibration is an error up front
        from camtraj.lens import lens_positions

        analysis.lens_q = lens_positions(robot.lens, shot)
    # frame by frame (paper), or the whole shot in steps, each worth its share of the frames
    progress.stage("solve", int(shot.frames.shape[0]), unit="frame")
    with _stage(timings, "ik"):
        flange2base = targets @ np.linalg.inv(robot.camera2flange)
        analysis.path = solve_path_report(
            robot, flange2base, start, objective=options.objective,
            frame_interval=1.0 / shot.fps, frame_numbers=shot.frames, progress=progress.advance,
            still_ends=options.edges == "still",
        )
    progress.stage("time")
    with _stage(timings, "timing"):
        q_frames, limits = take_axes(robot, analysis.path.q, analysis.lens_q)
        if start is not None and analysis.lens_q is not None:
            start = np.concatenate([start, analysis.lens_q[0]])  # the lens where frame 1 needs it
        try:
            analysis.take = time_shot(
                q_frames, shot.times, limits, mode=options.timing,
                rate=options.rate, frame_numbers=shot.frames, start=start,
                hold=camera_holds(targets), rest=analysis.path.rest_axes(q_frames.shape[1]),
                edges=options.timing_edges,
            )
        except TimingLimitError as exc:
            # a jump between frames (a cut in the shot, or a flip) smears over the frames
            # around it as the spline's jerk: say where it is
            cuts = camera_cuts(targets, shot.frames)
            jump = step_warning(robot, analysis.path, targets, shot.frames, 1.0 / shot.fps)
            for note in cuts or ([jump] if jump else []):
                exc.add_note(note)
            held = hold_note(camera_holds(targets), shot.frames, exc.violations)
            if held and not cuts:
                exc.add_note(held)
            raise
    if set_file is not None and set_file.prims:
        from camtraj.collision import NEAR, check_take

        clearance = set_file.clearance_m if options.clearance is None else options.clearance
        with _stage(timings, "collision"):
            closest = check_take(shot_path, robot, analysis.placement.base2world, analysis.take,
                                 shot.time_codes,
                                 stage_to_world(shot.meters_per_unit, shot.up_axis),
                                 set_file.prims, clearance,
                                 floor_z=set_file.floor_height * shot.meters_per_unit)
        analysis.collision = {"prims": list(set_file.prims), "clearance_m": clearance,
                              "closest_m": closest if math.isfinite(closest) else None,
                              "measured_within_m": clearance + NEAR}


def convert(
    shot_path: str | Path,
    output_path: str | Path | None,
    options: ConvertOptions | None = None,
    *,
    progress: Progress | None = None,
    summary_path: str | Path | None = None,
    summary_extra: Mapping[str, Any] | None = None,
    rig_layer: str | Path | None = None,
    foxglove_layout: str | Path | None = None,
    report: str | Path | None = None,
    more_inputs: Sequence[tuple[Path, str]] = (),
) -> dict[str, Any]:
    """Convert one shot to a motion-control MCAP; returns the JSON-able summary.

    With ``output_path`` None no MCAP is written (``camtraj check``). Every other output is
    written with it as one result (all replaced or none): ``summary_path`` the summary (plus
    ``summary_extra``) as JSON, ``rig_layer`` the USD rig layer (:mod:`camtraj.usd_rig`),
    ``foxglove_layout`` a Foxglove layout for the MCAP, ``report`` the HTML report
    (:mod:`camtraj.report`). Every output path is checked before the solve (its folder, that
    it is a regular file or nothing, that it is no input and not another output). Raises
    ``InputError`` (exit 2) or ``InfeasibleError`` (exit 3) with the frames, axes and margins
    named; a failed or interrupted run writes nothing and leaves existing outputs untouched,
    except that a report asked for alone (``check --report``) is written for a shot that
    cannot be done, showing why. ``progress`` is told of each stage (see
    :mod:`camtraj.progress`; the CLI shows it on a terminal). ``more_inputs``: other files
    the caller read for the run, (path, what it is) (a farm task's manifest), which no
    output may be either.
    """
    options = options or ConvertOptions()
    progress = progress or Silent()
    if rig_layer is not None:
        from camtraj.usd_rig import check_rig_path

        check_rig_path(rig_layer)
    with OutputSet() as outputs:
        for path, label in ((output_path, "-o"), (summary_path, "--summary"),
                            (rig_layer, "--usd"), (foxglove_layout, "--foxglove-layout"),
                            (report, "--report")):
            if path is not None:
                outputs.add(path, label)
        if outputs.paths:
            require_regular_files(shot_path, options)
            outputs.refuse_inputs([*run_inputs(shot_path, options), *more_inputs])
        started: list[Analysis] = []
        try:
            analysis = analyse(shot_path, options, progress=progress, on_start=started.append)
        except InfeasibleError as exc:
            if report is not None and started and len(outputs.paths) == 1:
                from camtraj import report as html_report

                page = html_report.render_html(html_report.from_analysis(
                    started[0], shot_path, options, error=exc, source="check"))
                outputs.write_bytes(report, page.encode("utf-8"))
                outputs.commit()
            raise
        if output_path is not None:
            progress.stage("write")
            with _stage(analysis.timings, "write"), outputs.open(output_path) as stream:
                write_take_to(stream, take_data(analysis), analysis.robot,
                              metadata(analysis, shot_path, options))
        if rig_layer is not None:
            progress.stage("rig layer")
            with _stage(analysis.timings, "rig"):
                outputs.write_bytes(rig_layer, _rig_bytes(analysis, rig_layer))
        if foxglove_layout is not None:
            from camtraj.ros2 import foxglove_layout as layout

            outputs.write_bytes(foxglove_layout, layout().encode("utf-8"))
        if report is not None:
            from camtraj import report as html_report

            progress.stage("report")
            with _stage(analysis.timings, "report"):
                page = html_report.render_html(html_report.from_analysis(
                    analysis, shot_path, options, warnings=run_warnings(analysis),
                    source="convert" if output_path is not None else "check"))
            outputs.write_bytes(report, page.encode("utf-8"))
        result = summary(analysis, shot_path, output_path, options)
        if summary_path is not None:
            text = jsonsafe.dumps({**result, **(summary_extra or {})}) + "\n"
            outputs.write_bytes(summary_path, text.encode("utf-8"))
        outputs.commit()
    return result


def _rig_bytes(analysis: Analysis, rig_layer: str | Path) -> bytes:
    from camtraj.usd_rig import rig_layer_bytes

    assert analysis.path is not None
    return rig_layer_bytes(rig_layer, analysis.shot, analysis.robot,
                           analysis.placement.base2world, analysis.path.q,
                           lens=_commanded_lens(analysis))


def _commanded_lens(analysis: Analysis) -> dict[str, NDArray[np.float64]] | None:
    """The lens the motors give per frame (:func:`camtraj.lens.commanded_lens`), or None."""
    lens = analysis.robot.lens
    if lens is None or analysis.lens_q is None:
        return None
    from camtraj.lens import commanded_lens

    return commanded_lens(lens, analysis.lens_q, analysis.shot)


def take_data(analysis: Analysis) -> TakeData:
    """The writer's view of a finished analysis."""
    take, shot, path = analysis.take, analysis.shot, analysis.path
    assert take is not None and path is not None
    lens_names = () if analysis.robot.lens is None else analysis.robot.lens.names
    commanded = _commanded_lens(analysis)
    return TakeData(
        joint_names=(*JOINT_NAMES, *lens_names), lens_names=lens_names,
        camera_focal_length_mm=None if commanded is None else commanded["focal_length_mm"],
        t=take.t, q=take.q, qd=take.qd, qdd=take.qdd,
        frame_numbers=shot.frames, frame_times=take.frame_times, frame_q=path.q,
        target=analysis.targets, achieved=analysis.robot.camera_pose(path.q),
        focal_length_mm=shot.focal_length_mm, focus_distance_m=shot.focus_distance_m,
        f_stop=shot.f_stop, fps=shot.fps,
        horizontal_aperture_mm=shot.horizontal_aperture_mm,
        vertical_aperture_mm=shot.vertical_aperture_mm,
        base2world=analysis.placement.base2world,
        horizontal_aperture_offset_mm=shot.horizontal_aperture_offset_mm,
        vertical_aperture_offset_mm=shot.vertical_aperture_offset_mm,
    )


def metadata(analysis: Analysis, shot_path: str | Path, options: ConvertOptions) -> dict[str, str]:
    """The ``camtraj`` metadata record (design.md §4)."""
    take, shot, robot = analysis.take, analysis.shot, analysis.robot
    assert take is not None and analysis.path is not None
    mount = {"camera2flange": robot.camera2flange.tolist()}
    counts = controller_counts(analysis)
    return {
        "source_file": str(shot_path),
        "camera_prim": shot.camera_path,
        "frame_range": frame_span(int(shot.frames[0]), int(shot.frames[-1])),
        "fps": repr(float(shot.fps)),
        "robot": f"{robot.name} ({robot.source})",
        "ik_objective": options.objective or robot.ik.objective,
        "placement": json.dumps(analysis.placement.describe(), sort_keys=True),
        "mount": json.dumps(mount, sort_keys=True),
        "timing_mode": take.mode,
        "speed_factor": repr(float(take.speed_factor)),
        "servo_rate_hz": repr(round(float(take.rate), 9)),  # 240.0, not 239.99999999999997
        "servo_step_ms": json.dumps(take.servo_steps_ms),
        "max_speed": repr(float(take.report.max_speed)),
        "max_speed_set_by": take.report.set_by,
        "warnings": json.dumps(run_warnings(analysis)),
        "tool_version": f"camtraj {camtraj.__version__}",
        # What the shot used, for `camtraj info` (fractions of each limit, SI ranges).
        "peak_use": json.dumps(take.report.peak_use, sort_keys=True),
        "position_range": json.dumps(take.report.position_range, sort_keys=True),
        # The margins the terminal prints, for the report of the file.
        "margins": json.dumps(margins_summary(analysis), sort_keys=True),
        # The run-up's and run-out's own peak use, for the report's "ends" columns.
        "edge_peak_use": json.dumps({"runup": take.report.runup.get("peak_use", {}),
                                     "runout": take.report.runout.get("peak_use", {})},
                                    sort_keys=True),
        # How far the run-up and run-out move [m] and turn [deg] the camera from the first and
        # last frame's pose, for the report's run-up / run-out row.
        "edge_camera_travel": json.dumps(
            {side: {"m": m, "deg": deg}
             for side, (m, deg) in zip(("runup", "runout"), camera_travel(analysis),
                                       strict=True)}, sort_keys=True),
        # With a lens only: its axes after the joints, their units and calibrated ranges.
        **({} if robot.lens is None else {"lens": json.dumps(robot.lens.describe())}),
        # With [controller.AXIS] units only: each axis's counts = offset + sign * scale * q
        # and the range of counts the whole take (run-up and run-out included) commands.
        **({"controller": json.dumps(counts, sort_keys=True)} if counts else {}),
    }


def controller_counts(analysis: Analysis) -> dict[str, dict[str, Any]]:
    """Per axis with controller units (the robot file's ``[controller.AXIS]``, the lens
    file's): the units and the lowest and highest motor count the take commands."""
    take, robot = analysis.take, analysis.robot
    assert take is not None
    q = take.q  # (samples, axes): the joints, then any lens motors
    units = dict(robot.controller)
    if robot.lens is not None:
        units |= {a.name: a.controller for a in robot.lens.axes if a.controller is not None}
    names = [*JOINT_NAMES, *(a.name for a in robot.lens.axes)] if robot.lens else [*JOINT_NAMES]
    out = {}
    for name, unit in units.items():
        counts = unit.counts(q[:, names.index(name)])
        out[name] = {"scale": unit.scale, "offset": unit.offset, "sign": unit.sign,
                     "counts_range": [float(counts.min()), float(counts.max())]}
    return out


def run_warnings(analysis: Analysis) -> list[str]:
    """Things a person should know about a finished run that do not stop the take (worked
    out once per run: the metadata, the summary and the report each ask)."""
    if analysis.warnings is None:
        analysis.warnings = _run_warnings(analysis)
    return list(analysis.warnings)


def _run_warnings(analysis: Analysis) -> list[str]:
    take, shot, path = analysis.take, analysis.shot, analysis.path
    assert take is not None and path is not None
    warnings = [*shot.warnings, *take.report.warnings]
    # a bad key or a cut that a slowed-down take (scale, optimal) still runs through
    warnings += camera_cuts(analysis.targets, shot.frames)
    warnings += analysis.placement.notes
    if analysis.placement.overrides is not None:
        warnings.append(f"--placement replaces the set file's placement "
                        f"{analysis.placement.overrides}: the take is for the robot where "
                        f"--placement puts it")
    if analysis.robot.lens is not None:
        from camtraj.lens import lens_warnings

        warnings += lens_warnings(analysis.robot.lens, shot)
    flip = step_warning(analysis.robot, path, analysis.targets, shot.frames, 1.0 / shot.fps)
    if flip:
        warnings.append(flip)
    return warnings


HOLD_EDGE_FRAMES = 3
"""Frames either side of a hold's edge where a run over a limit is the edge's doing: the
spline's jerk from a stop within one frame spreads over the two or three frames around it."""


def hold_note(held: NDArray[np.bool_], frames: NDArray[np.int_],
              violations: list[LimitViolation]) -> str | None:
    """A note where the limits are exceeded next to holds of the camera: the robot holds
    still wherever the camera does, so an animation that runs into a hold still moving, or
    still accelerating (an ease whose last key is flat in speed but not in acceleration, as
    a smoothstep or a flat Bezier tangent), asks the robot to stop or start within one
    frame interval; a move animated on twos (each pose held for two frames) asks it at every
    other frame. ``held``: the camera's held frame pairs (n - 1,); ``violations``: the
    timing stage's, their frames as film frame numbers."""
    n = held.size + 1
    starts = np.flatnonzero(held & ~np.concatenate([[False], held[:-1]]))  # first pairs
    ends = np.flatnonzero(held & ~np.concatenate([held[1:], [False]])) + 1  # last frames
    edges = [(int(frames[k]), "stops dead into") for k in starts if k > 0]
    edges += [(int(frames[k]), "starts out of") for k in ends if k < n - 1]
    # every frame over a limit lies within HOLD_EDGE_FRAMES of an edge, and no velocity is
    # over: a move too fast for an axis between two holds (a whip pan) is over along the
    # whole move, or in speed
    if not edges or any(v.quantity == "velocity" for v in violations):
        return None
    runs = [r for v in violations if v.quantity in ("acceleration", "jerk") for r in v.frames]
    at = np.array(sorted({f for f, _ in edges}))

    def covered(run: tuple[int, int]) -> bool:
        f = np.arange(run[0], run[1] + 1)
        i = np.searchsorted(at, f)
        gap = np.minimum(np.abs(f - at[np.maximum(i - 1, 0)]),
                         np.abs(f - at[np.minimum(i, at.size - 1)]))
        return bool(np.all(gap <= HOLD_EDGE_FRAMES))

    if not runs or not all(covered(r) for r in runs):
        return None
    near = sorted({(f, what) for f, what in edges
                   if any(r[0] - HOLD_EDGE_FRAMES <= f <= r[1] + HOLD_EDGE_FRAMES for r in runs)})
    said = " and ".join(f"{what} a hold at frame {f}" for f, what in near[:4])
    more = f" (and {len(near) - 4} more)" if len(near) > 4 else ""
    note = (f"the limits are exceeded where the camera {said}{more}: the robot holds still "
            "where the camera does, so a move that reaches a hold still decelerating (or "
            "leaves it at once) must stop (or start) within a frame; ")
    one_pair = starts[(starts + 1 >= held.size) | ~held[np.minimum(starts + 1, held.size - 1)]]
    lone = sum(any(r[0] - HOLD_EDGE_FRAMES <= frames[k] <= r[1] + HOLD_EDGE_FRAMES for r in runs)
               for k in one_pair)  # holds of two frames beside the limits' runs
    if lone >= TWOS_HOLDS:
        return note + (f"the camera holds a pose for just two frames {lone} times (a move "
                       "animated on twos?): bake it on ones for a smooth move")
    return note + ("ease the animation into and out of holds over more frames, or --timing "
                   "optimal slows only the frames around them")


TWOS_HOLDS = 4
"""Holds of a single frame pair, at least this many, make a shot read as animated on twos
(:func:`hold_note`)."""


JUMP_OFF_PATH_M = 0.02
"""A joint step beyond an axis's one-frame reach is a jump (a reconfiguration of the arm)
where, half-way through it, the camera is this far [m] from the middle of its two frames'
positions, beyond what the camera's own turn accounts for (and more than half its own step
off it): the arm swings the camera through the set between two frames. A camera mounted R
from the wrist centre and turning by an angle a between the frames swings R (1 - cos(a / 2))
off the middle by itself; along the shot set's fast steps (whip pans, a truck at the arm's
full reach) the rest stays under 3 mm, and a reconfiguration moving the track 0.2 m is 5 cm
off."""


def step_warning(robot: Robot, path: PathSolution, targets: Array, frames: NDArray[np.int_],
                 dt: float) -> str | None:
    """A warning where the joint path jumps: a frame-to-frame step beyond what an axis can
    do in one frame at its velocity limit that is not the camera's own motion. For the
    papers' per-frame objective every such step (a flip, or a wrap around a limit); for any
    objective a revolute step of more than a quarter turn, or a step where the camera at the
    joints' half-way point leaves the path between its two frames by more than
    :data:`JUMP_OFF_PATH_M` beyond its own turn's swing (the arm reconfigures). The take then
    has to slow the whole shot to cover it (``--timing optimal`` slows only the frames around
    it); the largest such step is named. (A move that is simply faster than an axis, like a
    whip pan, is the timing stage's to report.) ``targets``: the camera poses (n, 4, 4) in
    the base frame."""
    if path.within_step.all():
        return None
    delta = np.diff(path.q, axis=0)
    steps = np.abs(delta) / (robot.max_velocity * dt)
    over = steps > 1.0
    off = np.zeros(delta.shape[0])
    swings = np.zeros(delta.shape[0], dtype=bool)
    pairs = np.flatnonzero(over.any(axis=1))  # the camera half-way, where an axis is over
    if pairs.size:
        half = robot.camera_pose(path.q[pairs] + 0.5 * delta[pairs])[:, :3, 3]
        ends = targets[:, :3, 3]
        chord = ends[pairs + 1] - ends[pairs]
        off[pairs] = np.linalg.norm(half - (ends[pairs] + 0.5 * chord), axis=1)
        # the swing a turn of the camera about the wrist centre makes by itself
        wrist = robot.link_frames(path.q[pairs])[:, WRIST_FRAME, :3, 3]
        lever = np.linalg.norm(ends[pairs] - wrist, axis=1)
        own = lever * (1.0 - np.cos(0.5 * _turns(targets[pairs], targets[pairs + 1])))
        swings[pairs] = ((off[pairs] - own > JUMP_OFF_PATH_M)
                         & (off[pairs] > 0.5 * np.linalg.norm(chord, axis=1)))
    jump = over if path.objective == "paper" else over & (
        (REVOLUTE & (np.abs(delta) > 0.5 * math.pi)) | swings[:, None])
    if not jump.any():
        return None
    steps = np.where(jump, steps, 0.0)
    k, j = np.unravel_index(int(np.argmax(steps)), steps.shape)
    step = float(delta[k, j])
    size = f"{math.degrees(step):+.1f} deg" if REVOLUTE[j] else f"{step:+.3f} m"
    count = int(jump.any(axis=1).sum())
    which = "" if path.objective == "shot" else f" of the {path.objective} objective"
    what = (f"the arm reconfigures{which}: half-way the camera is {off[k]:.2f} m off its "
            "path" if swings[k] else f"a flip{which}")
    return (f"{count} frame(s) jump: {JOINT_NAMES[j]} moves {size} between frames "
            f"{int(frames[k])} and {int(frames[k + 1])}, {float(steps[k, j]):.1f}x what it can "
            f"move in one frame ({what}); the take is slowed to cover it (--timing optimal "
            f"slows only the frames around it; camtraj place looks for a track placement "
            f"that needs no jump)")


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

    travel = camera_travel(analysis)
    resting = path.camera_rest  # as the solver decided it (for --edges still)

    # as the file has them: from the take's start to the first frame and from the last frame
    # to the take's end (the ruckig moves plus the holds that put the frames on servo ticks)
    edge_time = (float(take.shot_start), float(take.t[-1] - take.shot_end))

    def extents(part: dict[str, Any], side: int) -> dict[str, Any]:
        return {
            "duration_s": edge_time[side],
            # how far the camera moves from the first (last) frame's position before (after)
            "camera_travel_m": travel[side][0],
            # and how far it turns [deg] (a pan alone moves it little)
            "camera_turn_deg": travel[side][1],
            # whether the authored camera is at rest on that frame (--edges still keeps the
            # robot still there too)
            "camera_at_rest": bool(resting[side]),
            # how: "at_rest" (stopping hard into it) or "settled" (eased in: the robot does
            # not even accelerate there), else "free"
            "camera_rest": REST_NAMES[resting[side]],
            **({"from_start_pose": options.start_from is not None} if side == 0 else {}),
            "extent": {k: axis_value(k, v) for k, v in part.get("extent", {}).items()},
            # Its own peak use of the limits (fractions), apart from the shot's peak_use.
            "peak_use": part.get("peak_use", {}),
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
        # as built: gentle where it fits; still where the robot rests on an end frame
        "edges": ("still" if any(path.rest) and rep.runup.get("edges") == "gentle"
                  else rep.runup.get("edges", options.edges)),
        "edges_asked": options.edges,
        "speed_factor": float(take.speed_factor),
        "servo_rate_hz": round(float(take.rate), 9),  # 250.0, not 249.99999999999977
        # an optimal retime cuts each frame interval into its own equal steps: they vary
        "servo_step_ms": list(take.servo_steps_ms),
        "duration": float(take.duration),
        "shot_start": float(take.shot_start),
        "shot_end": float(take.shot_end),
        "max_speed": float(rep.max_speed),
        "max_speed_set_by": rep.set_by,
        "feasible_fps": float(rep.feasible_fps),
        "peak_use": rep.peak_use,
        "runup": extents(rep.runup, 0),
        "move_to_start": _move_to_start(analysis),
        "margins": margins_summary(analysis),
        "runout": extents(rep.runout, 1),
        "warnings": warnings,
        "collision": analysis.collision,
        **({} if analysis.robot.lens is None else {"lens": analysis.robot.lens.describe()}),
        "timings": {k: round(v, 4) for k, v in analysis.timings.items()},
        "tool_version": camtraj.__version__,
    }


def _move_to_start(analysis: Analysis) -> dict[str, Any]:
    """The move from the start pose (home or --start-from) to where the take begins at rest
    (the run-up's start: the first frame itself only where there is no run-up; nothing with
    --start-from, where the take begins), for the summary."""
    assert analysis.path is not None and analysis.take is not None
    m = move_to_start(analysis.robot, analysis.path.start, analysis.take.q[0, :8])
    return {
        "duration_s": m.duration,
        "start": {k: axis_value(k, float(v)) for k, v in zip(JOINT_NAMES, m.start, strict=True)},
        "extent": {k: axis_value(k, abs(float(v)))
                   for k, v in zip(JOINT_NAMES, m.travel, strict=True)},
    }


__all__ = [
    "Analysis",
    "ConvertOptions",
    "Placement",
    "analyse",
    "convert",
    "summary",
]
