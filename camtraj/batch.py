"""Convert many shots at once: ``camtraj batch SHOTS... -o OUTDIR``.

Each shot is converted by :func:`camtraj.convert.convert` in a worker process (one process per
job slot, reused from shot to shot), so a batch on N cores takes about 1/N of the time of
converting the shots one after the other. A shot that fails does not stop the others.

Outputs, for a shot ``path/to/NAME.usda``:

- ``OUTDIR/NAME.mcap``: the move, written atomically by ``convert`` (byte-identical to what
  ``camtraj convert path/to/NAME.usda -o OUTDIR/NAME.mcap`` writes).
- ``OUTDIR/NAME.summary.json``: the summary ``convert`` returns, plus the convert options used
  (``convert_options``).
- ``OUTDIR/NAME.rig.usda`` with ``--usd``: the USD rig layer (``camtraj convert --usd``).
- ``OUTDIR/batch_report.json``: one entry per shot (status ``ok``, ``failed`` or ``skipped``,
  reason, frames, max speed, the run's warnings, time), and the batch's exit code.

A shot whose MCAP and summary are both at least as new as the shot file, the robot file and the
set file, and whose summary records the same convert options, is skipped (make-style) unless
``--force``. A shot that fails writes nothing and removes nothing (as ``convert``): an
earlier result of it stays, ``batch_report.json`` says that the shot failed this time and
names that earlier MCAP (``earlier_output``), and the failure's line on stderr says it is
not this version's take.

Exit codes (design.md §5): 0 when every shot converted or was skipped; 2 when any failed shot
was bad input (or the batch itself was: duplicate output names, bad options); 3 when every
failed shot was infeasible (unreachable frames, limits exceeded); 1 when a shot failed for an
unexpected reason (a bug) and none was bad input.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import json
import logging
import math
import os
import signal
import sys
import time
import unicodedata
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import click

from camtraj import __version__, interrupts, jsonsafe
from camtraj.errors import (
    CamtrajError,
    InfeasibleError,
    InputError,
    failure_lines,
    note_lines,
)
from camtraj.folders import check_can_make, make_parent, remove_empty
from camtraj.inputs import (
    files_read,
    one_line,
    parse_json,
    read_text,
    require_regular_file,
    require_regular_layers,
)
from camtraj.options import (
    ConvertOptions,
    build_options,
    convert_options,
    more_convert_options,
    options_to_json,
    rig_layer_flag,
    rig_layer_for,
)
from camtraj.outputs import (
    OutputSet,
    check_destination,
    refuse_overlaps,
    remove_stale_temps,
)
from camtraj.scene_file import Scene, SceneShot
from camtraj.shown import frame_span, speed_percent
from camtraj.workers import default_jobs, mp_context, start_workers_early, worker_environment

__all__ = [
    "REPORT_NAME",
    "SHOT_SUFFIXES",
    "BatchReport",
    "ShotResult",
    "batch_command",
    "output_names",
    "run_batch",
    "write_json_atomic",
    "write_text_atomic",
]

OPTIONS_KEY = "convert_options"
"""Key under which a batch records the convert options in each shot's summary JSON."""
SOURCE_KEY = "batch_source"
"""Key under which a batch records the shot's real path: a shot of the same name from another
folder is not up to date with its take (a new user's batch skipped such a shot and kept the
other's take)."""


def recorded_options(options: ConvertOptions) -> dict[str, Any]:
    """The convert options a batch records in each summary (``convert_options``) and compares
    to skip a shot: the robot, set and lens files as absolute paths with links resolved, so
    ``setA.toml`` and ``./setA.toml`` (or the same file from another folder) are one option."""
    recorded = options_to_json(options)
    for key in ("robot", "set_file", "lens"):
        if recorded[key] is not None:
            recorded[key] = os.path.realpath(recorded[key])
    return recorded


REPORT_NAME = "batch_report.json"
"""File name of the batch report inside OUTDIR."""

SHOT_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
"""File name endings of USD shots."""

REASON_WIDTH = 72  # characters of a failure reason shown in the table (all of it is in the JSON)

Status = Literal["ok", "failed", "skipped"]


# --------------------------------------------------------------------------------------------
# Small file helpers.
# --------------------------------------------------------------------------------------------


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (:class:`camtraj.outputs.OutputSet`).

    Creates missing folders (:mod:`camtraj.folders`). Raises InputError when it cannot be
    written.
    """
    with OutputSet() as outputs:
        outputs.add(path)
        outputs.write_bytes(path, text.encode("utf-8"))
        outputs.commit()


def write_json_atomic(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON (with a final newline) to ``path`` atomically.

    Numbers that are not finite are written as null (:mod:`camtraj.jsonsafe`).
    """
    write_text_atomic(path, jsonsafe.dumps(data) + "\n")


def output_names(shots: Sequence[str | SceneShot], outdir: Path) -> list[tuple[Path, Path]]:
    """The MCAP and summary paths of each shot: ``OUTDIR/<stem>.mcap``, ``<stem>.summary.json``;
    a scene's shot that names its camera or frames adds them (several cameras or spans of
    one stage file): ``<stem>_World_cam_<first>-<last>`` for camera /World/cam.

    Raises:
        InputError: A shot is not a USD file, or two shots share a stem (they would write the
            same outputs; stems are compared ignoring case, as some file systems do).
    """
    members = [s if isinstance(s, SceneShot) else SceneShot(s) for s in shots]
    seen: dict[str, str] = {}
    names: list[tuple[Path, Path]] = []
    for m in members:
        path = Path(m.path)
        if path.suffix.lower() not in SHOT_SUFFIXES:
            msg = f"{m.path}: not a USD shot (expected one of {', '.join(SHOT_SUFFIXES)})"
            raise InputError(msg)
        stem = path.stem + "".join([f"_{m.camera.strip('/').replace('/', '_')}" if m.camera
                                    else "",
                                    f"_{m.frames[0]}-{m.frames[1]}" if m.frames else ""])
        key = stem.casefold()
        if key in seen:
            msg = (
                f"{seen[key]} and {m.name} would both write {outdir / stem}.mcap; "
                "rename one of them or convert them in separate batches"
            )
            raise InputError(msg)
        seen[key] = m.name
        names.append((outdir / f"{stem}.mcap", outdir / f"{stem}.summary.json"))
    return names


def _columns(text: str) -> int:
    """How many terminal columns ``text`` takes: East Asian wide and full-width characters
    two, combining marks none (a shot named in Japanese shifted the table by two columns)."""
    return sum(0 if unicodedata.combining(c) else
               2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text)


def _mtime_ns(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


def _up_to_date(outputs: Iterable[Path], inputs: Iterable[Path]) -> bool:
    """Make's rule: every output exists and is at least as new as every input."""
    out_times = [_mtime_ns(p) for p in outputs]
    if any(t is None for t in out_times):
        return False
    oldest_out = min(t for t in out_times if t is not None)
    for path in inputs:
        t = _mtime_ns(path)
        if t is None or t > oldest_out:
            return False
    return True


# --------------------------------------------------------------------------------------------
# The batch.
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShotResult:
    """What happened to one shot of a batch.

    Attributes:
        shot: The shot path as given.
        output: The MCAP path.
        summary_path: The summary JSON path.
        status: ``ok`` (converted now), ``failed`` or ``skipped`` (up to date).
        reason: Why it failed or was skipped, else ``None``.
        exit_code: ``camtraj convert``'s exit code for this shot (0 for ok and skipped).
        error: The error class name when it failed, else ``None``.
        seconds: Conversion wall time in [s] (0 when skipped).
        cpu_seconds: CPU time of the conversion in [s] (0 when skipped).
        summary: The convert summary (read back from the summary file when skipped).
        warnings: What the shot's conversion warned, each naming the shot (said on stderr
            when it converts now, and when it cannot be done as asked: what reading it
            warned of is often why; a skipped shot's are its summary's, from the run that
            made it).
        earlier_output: For a failed shot, its MCAP path when a file is there from an
            earlier run (the batch removes nothing), else None.
        notes: For a failed shot, what ``convert`` says with its error (what to try, where a
            hold or a jump is), each naming the shot.
        camera, frame_range, timing: A scene's shot's own camera, frames and timing
            (``--scene``), else None (the batch's options).
    """

    shot: str
    output: str
    summary_path: str
    status: Status
    reason: str | None = None
    exit_code: int = 0
    error: str | None = None
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    summary: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    earlier_output: str | None = None
    notes: tuple[str, ...] = ()
    camera: str | None = None
    frame_range: tuple[int, int] | None = None
    timing: str | None = None

    @property
    def name(self) -> str:
        """The shot in messages: its path, and a scene's camera and frames."""
        return SceneShot(self.shot, self.camera, self.frame_range).name

    @property
    def label(self) -> str:
        """The shot in the table: its file's name, and a scene's camera (the frames have
        their column)."""
        return SceneShot(Path(self.shot).name, self.camera).name

    def to_json(self) -> dict[str, Any]:
        """This result as a JSON-able dict."""
        return {
            "shot": self.shot,
            "output": self.output,
            "summary_path": self.summary_path,
            "status": self.status,
            "reason": self.reason,
            "exit_code": self.exit_code,
            "error": self.error,
            "frames": self.summary.get("frames"),
            "max_speed": self.summary.get("max_speed"),
            "warnings": list(self.warnings),
            "duration": self.summary.get("duration"),
            "seconds": round(self.seconds, 3),
            "cpu_seconds": round(self.cpu_seconds, 3),
            "earlier_output": self.earlier_output,
            "notes": list(self.notes),
            "camera": self.camera,
            "frame_range": list(self.frame_range) if self.frame_range else None,
            "timing": self.timing,
        }


@dataclass(frozen=True)
class BatchReport:
    """The outcome of :func:`run_batch`.

    Attributes:
        outdir: The output folder.
        jobs: Shots converted at once, as asked (``--jobs``, default the CPU count).
        workers: Worker processes used: at most ``jobs``, at most one per shot that needed
            converting, 0 when every shot was up to date.
        wall_seconds: Wall time of the whole batch in [s].
        results: One result per shot, in the order the shots were given.
        options: The convert options, JSON-able.
    """

    outdir: str
    jobs: int
    workers: int
    wall_seconds: float
    results: tuple[ShotResult, ...]
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def failed(self) -> tuple[ShotResult, ...]:
        """The results of the shots that failed."""
        return tuple(r for r in self.results if r.status == "failed")

    @property
    def exit_code(self) -> int:
        """0 if nothing failed; 2 if any failure was bad input; 3 if all were infeasible; else 1."""
        codes = {r.exit_code for r in self.failed}
        if not codes:
            return 0
        if 2 in codes:
            return 2
        if codes == {3}:
            return 3
        return 1

    def to_json(self) -> dict[str, Any]:
        """The report as written to ``OUTDIR/batch_report.json``."""
        counts = {s: sum(r.status == s for r in self.results) for s in ("ok", "failed", "skipped")}
        return {
            "camtraj_version": __version__,
            "outdir": self.outdir,
            "jobs": self.jobs,
            "workers": self.workers,
            "options": self.options,
            "wall_seconds": round(self.wall_seconds, 3),
            "counts": counts,
            "exit_code": self.exit_code,
            "shots": [r.to_json() for r in self.results],
        }

    def table(self) -> str:
        """A plain-text table: shot, frames, status, max feasible speed, time."""
        header = ("shot", "frames", "status", "max speed", "time")
        rows = [header]
        for r in self.results:
            status: str = r.status
            if r.status == "failed" and r.reason:
                reason = r.reason.splitlines()[0]
                if len(reason) > REASON_WIDTH:
                    reason = reason[: REASON_WIDTH - 3].rstrip() + "..."
                status = f"failed: {reason}"
            time_text = f"{r.seconds:.1f} s" if r.status != "skipped" else "-"
            rows.append(
                (
                    r.label,
                    _format_frames(r.summary.get("frames")),
                    status,
                    _format_speed(r.summary.get("max_speed")),
                    time_text,
                )
            )
        widths = [max(_columns(row[i]) for row in rows) for i in range(len(header) - 1)]
        lines = []
        for row in rows:
            cells = [cell + " " * (w - _columns(cell))
                     for cell, w in zip(row[:-1], widths, strict=True)]
            lines.append("  ".join([*cells, row[-1]]).rstrip())
        counts = self.to_json()["counts"]
        lines.append(
            f"{counts['ok']} converted, {counts['skipped']} up to date, {counts['failed']} failed"
            f" in {self.wall_seconds:.1f} s{self._jobs_text()}"
        )
        return "\n".join(lines)


    def _jobs_text(self) -> str:
        if self.workers == 0:
            return " (nothing to convert)"
        text = f" with {self.workers} job{'s' if self.workers != 1 else ''}"
        if self.workers < self.jobs:
            text += f" ({self.jobs} asked; {self.workers} shot(s) to convert)"
        return text


def _format_frames(frames: Any) -> str:
    if frames is None:
        return "-"
    if isinstance(frames, dict):
        first, last = frames.get("first"), frames.get("last")
        count = frames.get("count")
        if first is not None and last is not None:
            return frame_span(first, last)
        return str(count) if count is not None else "-"
    if isinstance(frames, list | tuple) and len(frames) == 2:
        return frame_span(frames[0], frames[1])
    return str(frames)


def _format_speed(speed: Any) -> str:
    """The maximum feasible speed as convert and check show it: '390%' of real time."""
    if speed is None:
        return "-"
    if isinstance(speed, int | float):
        return speed_percent(float(speed)) if math.isfinite(speed) else "-"
    return str(speed)


def _convert_one(
    shot: str, output: str, summary_path: str, options: ConvertOptions, rig_layer: str | None,
    name: str | None = None,
) -> dict[str, Any]:
    """Worker: convert one shot; never raises (the outcome comes back as a plain dict).

    SIGINT and SIGTERM stop the shot (its outputs are discarded, as ``convert``'s); between
    shots the worker ignores them. A shot that starts after the batch was stopped is not run.
    ``name``: the shot in its warnings and notes (a scene's: with its camera and frames).
    """
    name = name or str(Path(shot))
    start = time.perf_counter()
    cpu_start = time.process_time()
    held = _ShotWarnings()  # said by the batch if the shot converts or cannot be done
    logging.getLogger().addHandler(held)
    interrupts.install()  # before looking at the stop: a stop sent before this is seen there
    try:
        if _stop is not None and _stop.is_set():
            raise interrupts.Interrupted(signal.SIGTERM)
        from camtraj.convert import convert

        # The options are recorded so that a later batch with other options does not skip
        # this shot.
        summary = convert(shot, output, options, summary_path=summary_path,
                          summary_extra={OPTIONS_KEY: recorded_options(options),
                                         SOURCE_KEY: os.path.realpath(shot)},
                          rig_layer=rig_layer)
    except CamtrajError as exc:
        # the batch names the shot on every line: a message that starts with it says it once
        reason = str(exc).removeprefix(f"{shot}: ") or type(exc).__name__
        outcome: dict[str, Any] = {
            "status": "failed",
            "reason": reason,
            "exit_code": exc.exit_code,
            "error": type(exc).__name__,
        }
        speed = getattr(exc, "max_speed", None)  # a take over its limits: how fast it can go
        if isinstance(speed, float) and math.isfinite(speed):
            outcome["summary"] = {"max_speed": speed}
        if isinstance(exc, InfeasibleError):  # what reading the shot warned of is often why
            outcome["warnings"] = _named(name, [*held.texts, *exc.shot_warnings], shot)
        outcome["notes"] = _named(name, note_lines(exc), shot)
    except Exception as exc:  # a bug: report it as this shot's failure and go on
        outcome = {
            "status": "failed",
            "reason": f"internal error: {type(exc).__name__}: {exc}",
            "exit_code": 1,
            "error": type(exc).__name__,
        }
    except KeyboardInterrupt as exc:
        stop = exc if isinstance(exc, interrupts.Interrupted) else None
        outcome = {
            "status": "failed",
            "reason": f"stopped by {stop.signal_name if stop else 'SIGINT'}",
            "exit_code": stop.exit_code if stop else 130,
            "error": "Interrupted",
        }
    else:
        # what the shot's reader logged, then the run's own warnings (the summary's, which
        # convert prints with its report), each once, naming the shot as the reader does
        outcome = {"status": "ok", "summary": summary,
                   "warnings": _named(name, [*held.texts, *summary.get("warnings", [])],
                                              shot)}
    finally:
        interrupts.ignore()
        logging.getLogger().removeHandler(held)
    outcome["seconds"] = time.perf_counter() - start
    outcome["cpu_seconds"] = time.process_time() - cpu_start
    return outcome


def _named(named: str, warnings: list[str], shot: str) -> list[str]:
    """Each warning once, naming the shot (``named``, a scene's with its camera and frames)
    as the reader's own name its file (``shot``): once, at the start."""
    path = f"{Path(shot)}: "
    return list(dict.fromkeys(f"{named}: {w.removeprefix(path)}" for w in warnings))


class _ShotWarnings(logging.Handler):
    """A worker's log messages during one shot (warnings and above), held until it ends."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.texts: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.texts.append(record.getMessage())


_stop: Any = None
"""In a worker: the batch's stop event (a ``multiprocessing.Event``), set when it is stopped."""


def _warm_up(stop: Any) -> None:
    """Worker initializer: import the pipeline once per worker, not once per shot."""
    global _stop
    _stop = stop
    interrupts.ignore()  # between shots; a shot handles them (_convert_one)
    import camtraj.convert  # noqa: F401


def _stop_workers(pool: cf.ProcessPoolExecutor, stop: Any, signum: int) -> None:
    """Stop the batch: no more shots start, the running ones stop (their outputs discarded)."""
    stop.set()
    for process in list((pool._processes or {}).values()):  # no public list of them
        with contextlib.suppress(OSError):
            if process.pid is not None:
                os.kill(process.pid, signum)
    pool.shutdown(wait=True, cancel_futures=True)  # the stopped shots end quickly


def _unreadable(shot: str) -> str | None:
    """Why a shot cannot be read at all (missing, a FIFO, a folder, or a layer of it that is
    one), else None."""
    try:
        require_regular_file(shot, "shot", InputError)
        require_regular_layers(shot)
    except InputError as exc:
        return str(exc)
    return None if os.path.exists(shot) else "no such file"


def _read_summary(path: Path) -> dict[str, Any]:
    try:
        data = parse_json(read_text(path, "summary", InputError), str(path), InputError)
    except InputError:
        return {}
    # a summary edited or damaged into another shape is as good as none: the shot converts
    ok = isinstance(data, dict) and isinstance(data.get("warnings", []), list)
    return data if ok else {}


def _result(shot: str, names: tuple[Path, Path], future: cf.Future[dict[str, Any]]) -> ShotResult:
    try:
        outcome = future.result()
    except Exception as exc:  # the worker process died (crash, out of memory)
        outcome = {
            "status": "failed",
            "reason": f"worker died: {type(exc).__name__}: {exc}",
            "exit_code": 1,
            "error": type(exc).__name__,
            "seconds": 0.0,
        }
    return ShotResult(
        shot,
        str(names[0]),
        str(names[1]),
        status=outcome["status"],
        reason=outcome.get("reason"),
        exit_code=outcome.get("exit_code", 0),
        error=outcome.get("error"),
        seconds=outcome["seconds"],
        cpu_seconds=outcome.get("cpu_seconds", 0.0),
        summary=outcome.get("summary", {}),
        warnings=tuple(outcome.get("warnings", ())),
        notes=tuple(outcome.get("notes", ())),
    )


def run_batch(
    shots: Sequence[str | SceneShot],
    outdir: str | os.PathLike[str],
    *,
    jobs: int | None = None,
    force: bool = False,
    options: ConvertOptions,
    progress: bool = False,
    rig_layers: bool = False,
    scene_file: str | None = None,
) -> BatchReport:
    """Convert ``shots`` into ``outdir`` in parallel and write ``outdir/batch_report.json``.

    Args:
        shots: USD shot paths (their stems distinct), or a scene's shots, each with its own
            camera, frames and timing (:func:`output_names` names them).
        outdir: Output folder, created with its parents if missing (:mod:`camtraj.folders`).
        jobs: Worker processes (default: the CPUs this process may use); at most one per shot.
        force: Convert every shot even if its outputs are up to date.
        options: Convert options, the same for every shot (but a scene's shot's own camera,
            frames and timing).
        progress: Show one overall tqdm progress bar on stderr.
        rig_layers: Also write each shot's USD rig layer, ``OUTDIR/NAME.rig.usda``; a shot
            whose rig layer is missing or older than the shot is not up to date.
        scene_file: The scene file the shots come from (no output may replace it).

    Returns:
        The report. Failed shots are in it; they do not raise.

    Raises:
        InputError: Before anything runs: no shots, duplicate stems, bad ``jobs``, a robot,
            lens or set file that cannot be read.
    """
    start = time.perf_counter()
    if not shots:
        msg = "no shots given"
        raise InputError(msg)
    out = Path(outdir)
    names = output_names(shots, out)
    jobs = default_jobs(jobs)
    paths = [s.path if isinstance(s, SceneShot) else s for s in shots]
    each = [replace(options, camera=s.camera, frames=s.frames, timing=s.timing)
            if isinstance(s, SceneShot) else options for s in shots]

    # The workers' outputs are checked here, all together, before any shot runs: no output
    # is an input of the batch (a shot, a layer it uses, the robot or set file), no two
    # outputs are the same file.
    labels = ("-o", "--summary", "--usd")
    planned = [(p, f"{label} {one_line(p)}") for pair in names
               for p, label in zip(_shot_outputs(*pair, rig_layers), labels, strict=False)]
    refuse_overlaps([*planned, (out / REPORT_NAME, str(out / REPORT_NAME))],
                    [*files_read(paths, options),
                     *([] if scene_file is None else [(Path(scene_file), "the scene file")])])

    # The files every shot reads (robot, lens, set file) are read once, here: a bad one is
    # one error before anything runs, not the same failure on every shot.
    from camtraj.convert import read_shared_inputs

    read_shared_inputs(options)

    check_can_make(out / REPORT_NAME, "-o")
    made = make_parent(out / REPORT_NAME, "-o")
    try:
        check_destination(out / REPORT_NAME, "the batch report")  # written last: checked first
        return _run_shots(shots, names, out, options, each, jobs, force, progress, rig_layers,
                          start)
    except BaseException:  # stopped before its report: the folders it made go if still empty
        remove_empty(made)
        raise


def _shot_outputs(mcap: Path, summary: Path, rig_layers: bool) -> list[Path]:
    """The files one shot's conversion writes."""
    return [mcap, summary, *([rig_layer_for(mcap)] if rig_layers else [])]


def _run_shots(given: Sequence[str | SceneShot], names: list[tuple[Path, Path]], out: Path,
               options: ConvertOptions, each: list[ConvertOptions], jobs: int, force: bool,
               progress: bool, rig_layers: bool, start: float) -> BatchReport:
    """:func:`run_batch`'s work once its outputs are checked and its folder is made
    (``each``: every shot's own options)."""
    remove_stale_temps(out)

    shots = [s.path if isinstance(s, SceneShot) else s for s in given]
    # a scene's shots: their own camera, frames and timing, and their names in messages
    scene: dict[int, dict[str, Any]] = {
        i: {"camera": s.camera, "frame_range": s.frames, "timing": s.timing}
        for i, s in enumerate(given) if isinstance(s, SceneShot)}
    named = {i: s.name if isinstance(s, SceneShot) else str(Path(s))
             for i, s in enumerate(given)}
    results: list[ShotResult | None] = [None] * len(shots)
    todo: list[int] = []
    for i, (shot, (mcap, summary)) in enumerate(zip(shots, names, strict=True)):
        outputs = _shot_outputs(mcap, summary, rig_layers)
        own = scene.get(i, {})
        reason = _unreadable(shot)
        if reason is not None:
            results[i] = ShotResult(
                shot,
                str(mcap),
                str(summary),
                status="failed",
                reason=reason,
                exit_code=2,
                error="ShotFileError",
                **own,
            )
            continue
        # every file the run reads (the shot, the USD layers it uses, the robot, set and lens
        # files): an edited sublayer makes the take out of date too
        inputs = [path for path, _ in files_read([shot], each[i])]
        if not force and _up_to_date(outputs, inputs):
            previous = _read_summary(summary)
            wanted = json.loads(json.dumps(recorded_options(each[i])))  # as read back
            if (previous.get(OPTIONS_KEY) == wanted
                    and previous.get(SOURCE_KEY) == os.path.realpath(shot)):
                results[i] = ShotResult(
                    shot,
                    str(mcap),
                    str(summary),
                    status="skipped",
                    reason="up to date",
                    summary=previous,
                    warnings=tuple(_named(named[i], previous.get("warnings", []), shot)),
                    **own,
                )
                continue
        todo.append(i)

    workers = min(jobs, len(todo))
    if todo:
        from tqdm import tqdm

        context = mp_context()
        stop = context.Event()
        with (
            cf.ProcessPoolExecutor(
                max_workers=workers, mp_context=context, initializer=_warm_up,
                initargs=(stop,),
            ) as pool,
            tqdm(
                total=len(todo),
                unit="shot",
                desc="camtraj batch",
                disable=not progress,
                file=sys.stderr,
                dynamic_ncols=True,
            ) as bar,
        ):
            with worker_environment():  # workers (and the forkserver) start on submit
                futures = {
                    pool.submit(
                        _convert_one,
                        shots[i],
                        str(names[i][0]),
                        str(names[i][1]),
                        each[i],
                        str(rig_layer_for(names[i][0])) if rig_layers else None,
                        named[i],
                    ): i
                    for i in todo
                }
            try:
                for future in cf.as_completed(futures):
                    i = futures[future]
                    result = replace(_result(shots[i], names[i], future), **scene.get(i, {}))
                    results[i] = result
                    for text in (*result.notes, *result.warnings):  # as convert says them
                        bar.write(text, file=sys.stderr)
                    bar.set_postfix_str(f"{result.label}: {result.status}", refresh=False)
                    bar.update(1)
            except KeyboardInterrupt as exc:
                # A SIGTERM may have been sent to this process alone (a farm scheduler
                # cancelling the task): pass it on to the workers.
                signum = exc.signum if isinstance(exc, interrupts.Interrupted) else signal.SIGINT
                _stop_workers(pool, stop, signum)
                raise

    # A failed shot's earlier take stays (nothing is removed): the report names it
    for i, r in enumerate(results):
        if r is not None and r.status == "failed" and os.path.lexists(names[i][0]):
            results[i] = replace(r, earlier_output=str(names[i][0]))

    report = BatchReport(
        outdir=str(out),
        jobs=jobs,
        workers=workers,
        wall_seconds=time.perf_counter() - start,
        results=tuple(r for r in results if r is not None),
        options=options_to_json(options),
    )
    write_json_atomic(out / REPORT_NAME, report.to_json())
    return report


# --------------------------------------------------------------------------------------------
# The command.
# --------------------------------------------------------------------------------------------


@click.command(
    "batch",
    epilog=(
        "Exit codes: 0 all shots converted or up to date; 2 a shot (or the batch) was bad "
        "input; 3 every failed shot was infeasible; 1 an unexpected error."
    ),
)
@click.argument("shots", nargs=-1, type=click.Path(), metavar="[SHOT]...")
@click.option("--scene", type=click.Path(), metavar="SCENE.toml",
              help="Convert a scene file's shots, each with its camera, frames and timing.")
@click.option(
    "-o",
    "--outdir",
    required=True,
    type=click.Path(),
    help="Folder for NAME.mcap, NAME.summary.json and batch_report.json.",
)
@click.option(
    "-j",
    "--jobs",
    type=click.IntRange(min=1),
    default=None,
    help="Shots converted at once (default: the number of CPUs).",
)
@click.option("--force", is_flag=True, help="Reconvert shots whose outputs are up to date.")
@convert_options
@more_convert_options
@rig_layer_flag
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@click.pass_context
def batch_command(
    ctx: click.Context,
    /,
    shots: tuple[str, ...],
    scene: str | None,
    outdir: str,
    jobs: int | None,
    force: bool,
    rig_layers: bool,
    quiet: bool,
    **option_args: Any,
) -> None:
    """Convert many SHOTS in parallel into OUTDIR, skipping shots that are up to date.

    With --scene, the scene file's shots (each with its camera, frames and timing; the
    scene's set file unless --set-file names one, such as the one place -o wrote).
    Prints a table (shot, frames, status, max feasible speed, time) and writes
    OUTDIR/batch_report.json. Failed shots do not stop the others.
    """
    if (scene is None) == (not shots):
        raise click.UsageError("give the shots or --scene SCENE.toml (one of them)")
    per_shot = (option_args["camera"] is not None or option_args["frames"] is not None
                or ctx.get_parameter_source("timing") is not click.core.ParameterSource.DEFAULT)
    if scene is not None and per_shot:
        raise click.UsageError("with --scene, give --camera, --frames and --timing per shot in "
                               "the scene file")
    start_workers_early()
    try:
        given: Sequence[str | SceneShot] = shots
        if scene is not None:
            parsed = Scene.read(scene)
            given = parsed.shots
            option_args["set_file"] = option_args["set_file"] or parsed.set_file
        options = build_options(**option_args)
        report = run_batch(
            given,
            outdir,
            scene_file=scene,
            jobs=jobs,
            force=force,
            options=options,
            progress=not quiet and sys.stderr.isatty(),
            rig_layers=rig_layers,
        )
    except CamtrajError as exc:
        for line in failure_lines(exc):
            click.echo(line, err=True)
        ctx.exit(exc.exit_code)
    click.echo(report.table())
    for r in report.failed:
        click.echo(one_line(f"ERROR: {r.name}: {r.reason}"), err=True)
        if r.earlier_output is not None:
            click.echo(one_line(f"note: {r.earlier_output} is from an earlier run, not this "
                                f"version of {Path(r.shot).name}"), err=True)
    ctx.exit(report.exit_code)
