"""The ``camtraj`` command line: a thin edge over :mod:`camtraj.convert`.

Exit codes (design.md §5): 0 success; 2 bad input or usage; 3 the shot cannot be done as asked.
Errors are printed as one ``ERROR:`` line naming the frames, axes and margins; no traceback.
"""

from __future__ import annotations

import contextlib
import errno
import importlib
import logging
import logging.handlers
import math
import os
import shlex
import signal
import sys
import warnings
from typing import Any, ClassVar, NoReturn

import click

import camtraj
from camtraj import interrupts, jsonsafe
from camtraj.analysis import DEFAULT_SOURCE, placement_text
from camtraj.errors import (
    CamtrajError,
    CollisionError,
    InfeasibleError,
    InputError,
    LensRangeError,
    UnreachableFramesError,
    failure_lines,
    one_line,
    os_reason,
)
from camtraj.options import (
    ConvertOptions,
    build_options,
    convert_options,
    more_convert_options,
    option_values,
)
from camtraj.progress import Silent, TerminalProgress, progress_for
from camtraj.robot import JOINT_NAMES, REVOLUTE
from camtraj.shown import (
    SHOWN_TURN_DEG,
    camera_moves,
    edge_use,
    frame_span,
    listed,
    percent,
    scale_fit,
    seconds,
    servo,
    speed_text,
)

EXIT_OK, EXIT_INPUT, EXIT_INFEASIBLE = 0, 2, 3


def _fail(exc: CamtrajError) -> NoReturn:
    for line in failure_lines(exc):
        click.echo(line, err=True)
    sys.exit(exc.exit_code)


def _suffix_note(label: str, path: str, suffix: str, kind: str) -> None:
    """A warning when an output's name does not say what it will be."""
    if os.path.splitext(path)[1].lower() != suffix:
        logging.getLogger("camtraj").warning(
            "%s %s does not end in %s; it will be %s all the same", label, path, suffix, kind)


def _progress_wanted(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def _progress(shot: str, enabled: bool) -> TerminalProgress | Silent:
    """The run's progress display, already showing that the pipeline is being loaded."""
    progress = progress_for(os.path.basename(shot), enabled=enabled)
    progress.stage("start")  # importing USD and the solvers takes a second or more
    return progress


def _options(kw: dict[str, Any]) -> ConvertOptions:
    return build_options(**kw)


def stopped(exc: KeyboardInterrupt, command: str | None = None) -> NoReturn:
    """One line and exit 128 + signal (130 for Ctrl-C) for a run stopped by a signal.

    Every command writes nothing then (its outputs are committed together at its end); a
    ``batch`` keeps the shots it finished.
    """
    if isinstance(exc, interrupts.Interrupted):
        name, code = exc.signal_name, exc.exit_code
    else:
        name, code = "SIGINT", 130
    what = "" if command == "batch" else "; nothing was written"
    with contextlib.suppress(OSError, ValueError):
        click.echo(f"ERROR: stopped by {name}{what}", err=True)
    sys.exit(code)


class _Main(click.Group):
    """The ``camtraj`` group: a stop by signal or a failing standard output is one line.

    Commands in :attr:`LAZY` are imported only when they run (or ``--help`` lists them), so
    ``convert`` does not pay for the placement search's imports, nor for the batch and farm
    commands' (their process pools, logging and job-file code).
    """

    LAZY: ClassVar[dict[str, tuple[str, str]]] = {
        "place": ("camtraj.place_command", "place_command"),
        "batch": ("camtraj.batch", "batch_command"),
        "farm": ("camtraj.farm", "farm_group"),
    }

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.LAZY})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.LAZY:
            module, name = self.LAZY[cmd_name]
            command: click.Command = getattr(importlib.import_module(module), name)
            return command
        return super().get_command(ctx, cmd_name)

    def invoke(self, ctx: click.Context) -> Any:
        code: Any = 1
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("default")
                try:
                    result = super().invoke(ctx)
                    code = 0
                except SystemExit as exc:
                    code = exc.code or 0
                    raise
                except click.exceptions.Exit as exc:  # ctx.exit(code) of a lazy command
                    code = exc.exit_code
                    raise
                finally:
                    _pass_on_warnings(caught, code)
            sys.stdout.flush()
        except KeyboardInterrupt as exc:
            stopped(exc, ctx.invoked_subcommand)
        except OSError as exc:
            if exc.filename is not None:  # a named file, not standard output
                _file_failed(exc)
            _stdout_failed(exc)  # stdout is a full disk, /dev/full or a closed pipe
        return result

    def main(self, *args: Any, **kwargs: Any) -> Any:
        if not kwargs.get("standalone_mode", True):
            return super().main(*args, **kwargs)
        kwargs["standalone_mode"] = False
        for stream in (sys.stdout, sys.stderr):  # a file name that is not UTF-8 prints too
            with contextlib.suppress(AttributeError, ValueError):
                stream.reconfigure(errors="backslashreplace")  # type: ignore[union-attr]
        code: Any = 0
        try:
            rv = super().main(*args, **kwargs)
            code = rv if isinstance(rv, int) else 0
        except SystemExit as exc:
            code = exc.code
        except click.exceptions.Abort as exc:
            stopped(interrupts.interruption(exc) or KeyboardInterrupt())
        except KeyboardInterrupt as exc:
            stopped(exc)
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()
            code = exc.exit_code
        except click.ClickException as exc:  # usage errors: one line, like every error
            hint = ""
            ctx = getattr(exc, "ctx", None)
            if isinstance(exc, click.UsageError) and ctx is not None:
                hint = f" (see '{ctx.command_path} --help')"
            click.echo(f"ERROR: {' '.join(exc.format_message().split())}{hint}", err=True)
            code = exc.exit_code
        except Exception as exc:  # a stop can come wrapped (an import's __set_name__)
            stop = interrupts.interruption(exc)
            if stop is None:
                raise
            stopped(stop)
        try:
            sys.stdout.flush()
        except OSError as err:
            _stdout_failed(err, code)
        sys.exit(code)


_HELD_LOG = logging.handlers.MemoryHandler(capacity=10_000, flushLevel=logging.CRITICAL + 1)
"""Warnings of a run, held until it ends: printed if it succeeds or cannot be done as asked,
dropped if it fails otherwise."""


def _pass_on_warnings(caught: list[warnings.WarningMessage], code: Any) -> None:
    """Logged and Python warnings (numpy overflow…) as one line each, on success; on exit 3
    (the shot cannot be done as asked) the logged ones, what reading the shot warned of (a
    metersPerUnit left to USD's fallback, a layer USD could not open: often why), after the
    failure's own lines (:func:`~camtraj.errors.failure_lines`).

    Any other failed run says what went wrong in its ERROR line on stderr, and nothing else.
    """
    if code not in (0, None):
        if code == EXIT_INFEASIBLE:
            with contextlib.suppress(OSError, ValueError):
                _HELD_LOG.flush()
        _HELD_LOG.acquire()
        try:
            _HELD_LOG.buffer.clear()
        finally:
            _HELD_LOG.release()
        return
    for text in dict.fromkeys(" ".join(str(w.message).split()) for w in caught):
        logging.getLogger("camtraj").warning("%s", text)
    with contextlib.suppress(OSError, ValueError):
        _HELD_LOG.flush()


def _file_failed(exc: OSError) -> NoReturn:
    """One line and exit 1 for a file a command did not expect to fail (a file of camtraj's
    own installation gone, say): the file and the reason, not a traceback."""
    name = exc.filename
    name = os.fsdecode(name) if isinstance(name, (str, bytes, os.PathLike)) else str(name)
    _fail(CamtrajError(f"cannot use {name}: {os_reason(exc)}"))  # exit 1


def _stdout_failed(exc: OSError, code: Any = 0) -> NoReturn:
    with contextlib.suppress(OSError, ValueError):
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())  # what is still buffered goes nowhere, quietly
    if exc.errno == errno.EPIPE:  # `camtraj check ... | head`: the reader has what it wanted
        sys.exit(code if isinstance(code, int) and code != 0 else 128 + signal.SIGPIPE)
    with contextlib.suppress(OSError, ValueError):
        click.echo(f"ERROR: cannot write to standard output: {os_reason(exc)}", err=True)
    sys.exit(code if isinstance(code, int) and code != 0 else EXIT_INPUT)


@click.group(cls=_Main,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(camtraj.__version__, prog_name="camtraj")
def main() -> None:
    """Turn a previs USD camera move into a motion-control camera robot move.

    \b
    camtraj convert shot.usd -o shot.mcap   the main job
    camtraj check shot.usd                  can the robot do it? (no output file)
    camtraj place shot.usd -o set.toml      where to lay the track for it
    camtraj place a.usd b.usd -o set.toml   one track layout for a scene's shots
    camtraj info shot.mcap                  what a converted file holds
    camtraj report shot.mcap -o shot.html   the HTML report of a converted take
    camtraj batch / farm                    many shots, locally or on a render farm

    Units: metres and degrees on the command line; metres and radians in files.
    Exit codes: 0 ok, 2 bad input or usage, 3 the shot cannot be done as asked.
    """
    stderr = logging.StreamHandler()
    stderr.setFormatter(logging.Formatter("warning: %(message)s"))
    _HELD_LOG.setTarget(stderr)
    logging.basicConfig(handlers=[_HELD_LOG], level=logging.WARNING, force=True)


@main.command()
@click.argument("shot", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(),
              metavar="OUT.mcap", help="The MCAP file to write (atomically).")
@convert_options
@more_convert_options
@click.option("--summary", type=click.Path(), metavar="FILE.json",
              help="Also write the run's summary as JSON.")
@click.option("--usd", "rig_layer", type=click.Path(), metavar="RIG.usda",
              help="Also write a USD layer of the robot driving the move, to sublayer onto "
              "the shot.")
@click.option("--foxglove-layout", "layout", type=click.Path(),
              metavar="FILE.json", help="Also write a Foxglove layout for the MCAP (3-D robot "
              "and frustum, axis plots, shot frames).")
@click.option("--report", type=click.Path(), metavar="REPORT.html",
              help="Also write the HTML report (plots of every axis, top and side views).")
@click.option("-q", "--quiet", is_flag=True,
              help="No progress display and nothing on stdout (the files asked for are still "
              "written; warnings and errors still go to stderr).")
def convert(shot: str, output: str, summary: str | None, rig_layer: str | None,
            layout: str | None, report: str | None, quiet: bool, **kw: Any) -> None:
    """Convert SHOT (a USD camera animation) into a motion-control MCAP file.

    Every frame is solved for the robot (SM inverse kinematics), the move is timed at the
    servo rate inside the axis limits, with a run-up from rest and a run-out to rest, and
    written as ROS 2 messages that Foxglove and ros2 bag tools read.
    """
    _suffix_note("-o", output, ".mcap", "an MCAP file")  # held: shown if the run succeeds
    if report is not None:
        _suffix_note("--report", report, ".html", "an HTML page")
    progress = _progress(shot, _progress_wanted(quiet))
    with interrupts.deferred():  # USD's module loader swallows a KeyboardInterrupt
        from camtraj.convert import convert as run

    try:
        result = run(shot, output, _options(kw), progress=progress, summary_path=summary,
                     rig_layer=rig_layer, foxglove_layout=layout, report=report)
    except CamtrajError as exc:
        progress.close()
        _fail(exc)
    finally:
        progress.close()
    if not quiet:
        click.echo(_report(result))
        for extra in (rig_layer, layout, report):
            if extra is not None:
                click.echo(f"  wrote {extra}")
    else:  # the report's warnings are the shot's: -q moves them to stderr, not away
        for warning in result.get("warnings", []):
            click.echo(one_line(f"warning: {warning}"), err=True)


@main.command()
@click.argument("shot", type=click.Path())
@convert_options
@more_convert_options
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("--report", type=click.Path(), metavar="REPORT.html",
              help="Also write the HTML report; for a shot that cannot be done it shows "
              "where and why.")
@click.option("-q", "--quiet", is_flag=True, help="No progress display (the report is printed).")
def check(shot: str, as_json: bool, report: str | None, quiet: bool, **kw: Any) -> None:
    """Check whether the robot can do SHOT as asked, writing nothing.

    Reports reachability per frame, each axis's use of its limits, the maximum feasible speed,
    and the run-up / run-out extents. Exit code 3 when the shot cannot be done as asked.
    """
    if report is not None:
        _suffix_note("--report", report, ".html", "an HTML page")
    progress = _progress(shot, _progress_wanted(quiet or as_json))
    with interrupts.deferred():  # USD's module loader swallows a KeyboardInterrupt
        from camtraj.convert import convert as run
        from camtraj.timing import TimingLimitError

    options = None
    try:
        options = _options(kw)
        result = run(shot, None, options, progress=progress, report=report)
    except (UnreachableFramesError, TimingLimitError, CollisionError, LensRangeError) as exc:
        result = _failure_report(shot, exc, options)
    except CamtrajError as exc:
        progress.close()
        _fail(exc)
    finally:
        progress.close()
    if as_json:
        click.echo(jsonsafe.dumps(result, sort_keys=True))
    else:
        click.echo(_report(result))
        if result["status"] == "ok":
            click.echo(_verdict(result))
    sys.exit(EXIT_OK if result["status"] == "ok" else EXIT_INFEASIBLE)


@main.command()
@click.argument("mcap_file", type=click.Path())
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(mcap_file: str, as_json: bool) -> None:
    """Show what a camtraj MCAP file holds: shot, frames, duration, rate, topics, limits."""
    from camtraj.mcap_io import describe

    try:
        d = describe(mcap_file)
    except CamtrajError as exc:
        _fail(exc)
    if as_json:
        click.echo(jsonsafe.dumps(d, sort_keys=True))
        return
    try:
        click.echo(_info_text(d))
    except (AttributeError, IndexError, KeyError, TypeError, ValueError) as exc:
        _fail(InputError(f"{one_line(mcap_file)}: its camtraj metadata is not as camtraj writes "
                         f"it ({type(exc).__name__}: {one_line(str(exc))}): the file was edited "
                         "or written by another program"))


def _info_text(d: dict[str, Any]) -> str:
    """``camtraj info``'s text of :func:`camtraj.mcap_io.describe`'s dict."""
    meta = d.get("metadata") or {}
    fr = d.get("frames") or {}
    mode = meta.get("timing_mode")
    steps = d.get("servo_step_ms")
    if steps is not None:  # written by convert: the grid's shortest and longest step
        grid = servo(d["servo_rate_hz"] or 0.0, steps)
        grid = ", " + grid if grid.startswith("servo steps") else grid.replace("servo", " at")
    else:  # an older file: optimal steps vary (their mean rate would mislead)
        grid = (", servo steps vary" if mode == "optimal" else
                f" at {d['servo_rate_hz']:.1f} Hz" if d.get("servo_rate_hz") else "")
    try:
        factor = f"{float(meta['speed_factor']):.4g}"
    except (KeyError, TypeError, ValueError):
        factor = str(meta.get("speed_factor"))
    rate = d.get("frame_rate_hz")
    lines = [
        f"file       {d['path']}  ({d['size_bytes'] / 1e6:.2f} MB, profile {d['profile']})",
        f"shot       {d.get('source_file')}  camera {d.get('camera_prim')}",
        f"frames     {frame_span(fr.get('first'), fr.get('last'))} ({fr.get('count')} frames at "
        f"{f'{rate:.6g}' if isinstance(rate, float) else rate} fps)",
        f"take       {d['duration_s']:.3f} s{grid}, timing {mode}, speed factor {factor}",
        f"robot      {meta.get('robot')}",
        *_start_and_end(d),
        f"written by {meta.get('tool_version')}",
        "topics:",
    ]
    lines += [f"  {t['topic']:<20} {t['type']:<40} {t['count']:>7} messages"
              for t in d["topics"]]
    lines += _limits_used(d)
    lines += _controller_counts(d.get("controller"))
    return "\n".join(lines)


def _start_and_end(d: dict[str, Any]) -> list[str]:
    """``camtraj info``: where the robot stands when the take begins and when it ends, as
    ``--start-from`` takes them (m and deg): a next take chained on this one starts from
    its end."""
    from camtraj.options import start_from_text

    lines = []
    for label, key in (("starts at ", "start_joints"), ("ends at   ", "end_joints")):
        q = d.get(key) or {}
        if all(name in q for name in JOINT_NAMES):
            lines.append(f"{label} --start-from {start_from_text([q[n] for n in JOINT_NAMES])}")
    return lines


def _controller_counts(controller: dict[str, Any] | None) -> list[str]:
    """``camtraj info``: each axis's motor counts (the robot or lens file's
    ``[controller.AXIS]``) and the range of them the take commands."""
    if not controller:
        return []
    lines = ["controller counts (counts = offset + sign x scale x q, q in m or rad; the "
             "take's range, run-up and run-out included):"]
    for name, c in controller.items():
        lo, hi = c["counts_range"]
        lines.append(f"  {name:<8} {c['offset']:g} {'+' if c['sign'] > 0 else '-'} "
                     f"{c['scale']:g} x q   [{lo:.0f}, {hi:.0f}]")
    return lines


@main.command("report")
@click.argument("mcap_file", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(),
              metavar="REPORT.html", help="The HTML file to write (atomically).")
def report_command(mcap_file: str, output: str) -> None:
    """Write the HTML report of a converted take (MCAP_FILE): one self-contained page with
    the summary, every axis's use of its limits over take time, and top and side views."""
    from camtraj.report import report_mcap

    _suffix_note("-o", output, ".html", "an HTML page")
    try:
        report_mcap(mcap_file, output)
    except CamtrajError as exc:
        _fail(exc)


# ---------------------------------------------------------------------------------------------
# Reports
# ---------------------------------------------------------------------------------------------


def _limits_used(d: dict[str, Any]) -> list[str]:
    """``camtraj info``: what the shot used of each limit, then the robot's limits."""
    use, ranges, limits = d.get("peak_use"), d.get("position_range") or {}, d.get("limits")
    lines = []
    if use:
        lines.append("limits used (peak over the shot, % of each limit; position: 0% mid-range, "
                     "100% at a limit):")
        lines.append("  axis      position velocity  accel   jerk   range used")
        for name, revolute in _axes(use):
            u = use.get(name, {})
            conv = math.degrees if revolute else float
            unit = "deg" if revolute else "m"
            # rounded, then + 0.0: a value that rounds to zero shows 0.000, not -0.000
            lo, hi = (round(conv(v), 3) + 0.0 for v in ranges.get(name, (math.nan, math.nan)))
            lines.append(
                f"  {name:<8} {_pct(u.get('position', math.nan))}    "
                f"{_pct(u.get('velocity', math.nan))}   {_pct(u.get('acceleration', math.nan))}"
                f"  {_pct(u.get('jerk', math.nan))}  [{lo:9.3f}, {hi:9.3f}] {unit}"
            )
    else:
        lines.append("limits used: not recorded in this file (written by an older camtraj)")
    if limits:
        lines.append("robot limits (position range, max velocity; deg for revolute axes):")
        for i, name in enumerate(limits.get("joints", JOINT_NAMES)):
            conv = math.degrees if REVOLUTE[i] else float
            unit = "deg" if REVOLUTE[i] else "m"
            lo, hi = conv(limits["lower"][i]), conv(limits["upper"][i])
            v = conv(limits["max_velocity"][i])
            lines.append(f"  {name:<7} [{lo:9.3f}, {hi:9.3f}] {unit:<3}  {v:8.3f} {unit}/s")
        lens = limits.get("lens")
        if lens:
            lines.append(f"lens {lens['name']} ({lens['source']}): motor positions are ring "
                         "angles; calibrated range of each axis's lens quantity:")
            for name, ax in lens["axes"].items():
                lo, hi = math.degrees(ax["lower"]), math.degrees(ax["upper"])
                v = math.degrees(ax["max_velocity"])
                lines.append(f"  {name:<7} [{lo:9.3f}, {hi:9.3f}] deg  {v:8.3f} deg/s  "
                             f"{ax['quantity']} {_range_end(ax['range'][0], ax)} to "
                             f"{_range_end(ax['range'][1], ax)}")
    return lines


def _range_end(x: float | str | None, axis: dict[str, Any]) -> str:
    """A lens range's end as info prints it: '0.4572 m', 'infinity' (null, or "inf" in files
    of camtraj before 2026-12), 'T2.8'."""
    if x is None or x == "inf":
        return "infinity"
    unit = axis["quantity_unit"]
    return f"T{float(x):.6g}" if unit == "T-stop" else (
        f"f/{float(x):.6g}" if unit == "f-stop" else f"{float(x):.6g} {unit}")


def _axes(table: dict[str, Any]) -> list[tuple[str, bool]]:
    """(name, revolute) of the eight joints, then any lens motors (ring angles) ``table``
    (an axis -> values mapping) has."""
    lens = [(name, True) for name in ("zoom", "focus", "iris") if name in table]
    return [*zip(JOINT_NAMES, REVOLUTE.tolist(), strict=True), *lens]


def _failure_report(shot: str, exc: InfeasibleError, options: ConvertOptions | None,
                    ) -> dict[str, Any]:
    """check's report of a shot that cannot be done as asked, with what reading the shot
    warned of (often the reason: a layer in other units puts the camera hundreds of metres
    away)."""
    from camtraj.timing import TimingLimitError

    if isinstance(exc, UnreachableFramesError):
        result = _unreachable_report(shot, exc, options)
    elif isinstance(exc, TimingLimitError):
        result = _limit_report(shot, exc, options)
    elif isinstance(exc, CollisionError):
        result = {"status": "collision", "shot": shot, "message": str(exc), "frame": exc.frame,
                  "phase": exc.phase, "link": exc.link, "prim": exc.prim,
                  "distance_m": exc.distance, "clearance_m": exc.clearance}
    else:
        result = {"status": "lens_range", "shot": shot, "message": str(exc)}
    return {**result, "warnings": list(exc.shot_warnings)}


def _unreachable_report(shot: str, exc: UnreachableFramesError,
                        options: ConvertOptions | None) -> dict[str, Any]:
    return {
        "status": "unreachable",
        "shot": shot,
        "message": str(exc),
        "advice": _place_command(shot, options),
        "unreachable": [
            {"frame": e.frame, "miss": e.miss, "miss_unit": e.miss_unit, "axis": e.axis,
             "reason": e.reason}
            for e in exc.errors
        ],
    }


PLACE_FLAGS = ("--camera", "--robot", "--set-file", "--frames", "--timing", "--clearance",
               "--lens", "--edges")
"""The convert options ``camtraj place`` takes too (the unreachable note carries them)."""


def _place_command(shot: str, options: ConvertOptions | None) -> str:
    """The ``camtraj place`` command line that searches a placement for the shot as it was
    checked: its convert options that place takes (the set file's floor, region, yaw range
    and obstacles bind place too), ``--timing shot`` left out as place's default."""
    pairs = option_values(options) if options is not None else []
    words = ["camtraj", "place", shot]
    for flag, value in pairs:
        if flag in PLACE_FLAGS and (flag, value) != ("--timing", "shot"):
            words += [flag, value]
    return shlex.join(words)


def _limit_report(shot: str, exc: Any, options: Any) -> dict[str, Any]:
    return {
        "status": "limits",
        "shot": shot,
        "message": str(exc),
        "timing": getattr(options, "timing", None),
        "max_speed": exc.max_speed,
        "max_speed_set_by": getattr(exc, "set_by", ""),  # as a feasible run's summary
        "feasible_fps": exc.feasible_fps,
        # The slow-down --timing scale takes (it was run); null when it fails too.
        "scale_factor": (exc.scale_factor if math.isfinite(exc.scale_factor) else None),
        # why the run-up or run-out does not fit, apart from the shot's own violations
        "room": exc.room or None,
        "violations": [
            {"axis": v.axis, "quantity": v.quantity, "peak": v.peak, "limit": v.limit,
             "ratio": v.ratio, "frames": v.frame_text, "text": v.describe()}
            for v in exc.violations
        ],
        "notes": list(getattr(exc, "__notes__", [])),
    }


SWING_NOTE_M = 1e-3
"""[m] A run-up or run-out that moves the camera further than this around a frame where the
camera is at rest (or turns it further than :data:`SWING_NOTE_DEG`) gets a note pointing at
``--edges still``."""
SWING_NOTE_DEG = SHOWN_TURN_DEG
"""[deg] The camera's turn in a run-up or run-out that gets the note (:data:`SWING_NOTE_M`)."""


def _moved(part: dict[str, Any]) -> tuple[float, float]:
    """The camera's travel [m] and turn [deg] in a summary's run-up or run-out."""
    return part["camera_travel_m"], part.get("camera_turn_deg", 0.0)


def _verdict(r: dict[str, Any]) -> str:
    """A feasible check's last line: 'SHOT: FEASIBLE at shot timing, 206% of real time ...'."""
    timing, factor = r["timing"], r["speed_factor"]
    how = (f"{timing} timing" if factor == 1.0
           else f"{timing} timing, {factor:.3f}x slower than the shot" if factor > 1.0
           else f"{timing} timing, {1.0 / factor:.3f}x faster than the shot")
    return (f"{r['shot']}: FEASIBLE at {how}; maximum feasible speed "
            f"{speed_text(r['max_speed'], r['fps'], r['feasible_fps'])}")


def _pct(x: float) -> str:
    return percent(x).rjust(5)


def _by_axis(violations: list[dict[str, Any]]) -> list[str]:
    """One line per axis: its worst excess (the violations come worst first, by the slow-down
    each needs), then the axis's other exceeded quantities by name ("--json" has them all)."""
    axes: dict[str, list[dict[str, Any]]] = {}
    for v in violations:
        axes.setdefault(v["axis"], []).append(v)
    lines = []
    for worst, *others in axes.values():
        names = [v["quantity"] for v in others]
        also = f" (also {listed(names)})" if names else ""
        lines.append(worst["text"] + also)
    return lines


def _report(r: dict[str, Any]) -> str:
    """The human-readable report of a convert / check run."""
    if r["status"] == "ok":
        return _take_report(r)
    return "\n".join([_failure_text(r), *(f"  warning: {w}" for w in r.get("warnings", []))])


def _failure_text(r: dict[str, Any]) -> str:
    """The report of a check that cannot be done as asked (its warnings apart)."""
    if r["status"] == "unreachable":
        lines = [f"{r['shot']}: CANNOT BE REACHED", f"  {r['message']}", "  frame  misses by"]
        for u in r["unreachable"]:
            amount = (f"{u['miss']:.3f} m" if u["miss_unit"] == "m"
                      else f"{math.degrees(u['miss']):.1f} deg")
            lines.append(f"  {u['frame']:>5}  {amount:>10}  {u['reason']}")
        lines.append(f"  note: {r['advice']} looks for a track placement that reaches "
                     "every frame")
        return "\n".join(lines)
    if r["status"] == "collision":
        return f"{r['shot']}: COLLISION\n  {r['message']}"
    if r["status"] == "lens_range":
        return f"{r['shot']}: OUTSIDE THE LENS'S RANGE\n  {r['message']}"
    if r["status"] == "limits":
        lines = [f"{r['shot']}: NOT POSSIBLE with --timing {r['timing']}"]
        lines += [f"  {line}" for line in _by_axis(r["violations"])]
        if r["violations"] and r.get("room"):  # without violations the message says it
            lines.append(f"  {r['room']}")
        lines += [f"  note: {note}" for note in r.get("notes", [])]
        message, either = r["message"], "--timing scale does not fit it either: "
        if not r["violations"]:
            lines.append(f"  {message}")
        elif either in message:
            lines.append(f"  {either}{message.split(either, 1)[1]}")
        speed, factor = r["max_speed"], r.get("scale_factor")
        if speed is not None and math.isfinite(speed) and speed > 0:
            fps = r["feasible_fps"] / speed
            advice = (f"; try --timing scale: the move {scale_fit(factor, fps)}"
                      if factor is not None and r["timing"] != "scale" else "")
            lines.append(f"  maximum feasible speed {speed_text(speed, fps, r['feasible_fps'])}"
                         + (f", set by {r['max_speed_set_by']}" if r.get("max_speed_set_by")
                            else "") + advice)
        return "\n".join(lines)
    msg = f"internal error: no report for status {r['status']!r}"
    raise AssertionError(msg)


def _take_report(r: dict[str, Any]) -> str:
    """The report of a run that made a take (convert, or a feasible check)."""
    fr = r["frames"]
    lines = [
        f"{r['shot']}  camera {r['camera']}  frames {frame_span(fr['first'], fr['last'])} "
        f"({fr['count']} at {r['fps']:g} fps)",
        f"  timing {r['timing']}: take {seconds(r['duration'])} s (shot "
        f"{seconds(r['shot_start'])}-{seconds(r['shot_end'])} s), "
        f"speed factor {r['speed_factor']:.3f}, "
        f"{servo(r['servo_rate_hz'], r.get('servo_step_ms'))}",
        f"  maximum feasible speed {speed_text(r['max_speed'], r['fps'], r['feasible_fps'])}"
        + (f", set by {r['max_speed_set_by']}" if r.get("max_speed_set_by") else ""),
        *([f"  placement {placement_text(r['placement'])}"]
          if r["placement"]["source"] != DEFAULT_SOURCE else []),
        "  axis      position velocity  accel   jerk   ends: accel  jerk   run-up   run-out "
        "(extent)   margin  to start",
    ]
    ends = edge_use(r["runup"].get("peak_use", {}), r["runout"].get("peak_use", {}),
                    [name for name, _ in _axes(r["peak_use"])])
    margins, start = r["margins"], r["move_to_start"]
    for name, revolute in _axes(r["peak_use"]):
        use = r["peak_use"].get(name, {})
        unit = "deg" if revolute else "m"
        up = r["runup"]["extent"].get(name, 0.0)
        out = r["runout"]["extent"].get(name, 0.0)
        margin = margins["to_limits"].get(name)
        travel = start["extent"].get(name)  # the lens motors start where the shot does
        lines.append(
            f"  {name:<8} {_pct(use.get('position', math.nan))}    "
            f"{_pct(use.get('velocity', math.nan))}   {_pct(use.get('acceleration', math.nan))}"
            f"  {_pct(use.get('jerk', math.nan))}        {_pct(ends[name]['acceleration'])}"
            f" {_pct(ends[name]['jerk'])}  {up:7.3f}  {out:7.3f} {unit:<3}"
            + (f" {margin:8.3f}" if margin is not None else "        -")
            + (f" {travel:8.3f}" if travel is not None else "        -")
        )
    lines.append(f"  margin: wrist singularity {margins['wrist_singularity_deg']:.1f} deg (frame "
                 f"{margins['wrist_singularity_frame']}), full stretch "
                 f"{margins['full_stretch_deg']:.1f} deg (frame {margins['full_stretch_frame']}); "
                 f"margin column: nearest position limit")
    lines.append(f"  move to start: {start['duration_s']:.2f} s from the start pose (to start "
                 f"column: travel per axis)")
    # from the take's start to the first frame and from the last frame to its end (the
    # ruckig moves plus the holds that put the frames on servo ticks), as the report shows
    lines.append(f"  run-up {seconds(r['shot_start'])} s, run-out "
                 f"{seconds(r['duration'] - r['shot_end'])} s ({r.get('edges', 'gentle')}; "
                 "ends column: their peak use of the limits); "
                 + camera_moves(_moved(r["runup"]), _moved(r["runout"])))
    fr = r["frames"]
    swung = [(frame, part) for frame, part in ((fr["first"], r["runup"]),
                                               (fr["last"], r["runout"]))
             if part.get("camera_at_rest") and (part["camera_travel_m"] > SWING_NOTE_M
                                               or part.get("camera_turn_deg", 0.0)
                                               > SWING_NOTE_DEG)
             and not part.get("from_start_pose")]
    if swung and r.get("edges_asked", r.get("edges")) != "still":
        where = listed([f"frame {frame}" for frame, _ in swung])
        lines.append(f"  the camera is still on {where} but the robot's axes are already "
                     "moving there, so the run-up/run-out swings the camera around "
                     f"{'it' if len(swung) == 1 else 'them'}: --edges still (the default) "
                     "keeps the robot still there, for a slower take")
    hard = [frame for frame, part in swung if part.get("camera_rest") == "at_rest"]
    if hard and r.get("edges_asked", r.get("edges")) == "still":
        where = listed([f"frame {frame}" for frame in hard])
        them = "it" if len(hard) == 1 else "them"
        lines.append(f"  the camera stops hard on {where}: still there but accelerating (a "
                     "cubic ease, a move from standstill), so the run-up/run-out carries the "
                     f"robot past {them} and back, swinging the camera around {them}; a smooth "
                     "(quintic) ease settles with no run-up at all, and --timing optimal "
                     "starts and ends such a move at a tenth of its pace")
    if r.get("edges_asked") == "still" and not any(
            part.get("camera_at_rest") for part in (r["runup"], r["runout"])):
        lines.append("  --edges still: the camera is at rest on neither end frame, so the "
                     "ends are as --edges gentle makes them")
    if r.get("collision"):
        c = r["collision"]
        near = (f"nothing within {c['measured_within_m']:.3f} m" if c["closest_m"] is None
                else f"closest {c['closest_m']:.3f} m")
        lines.append(f"  obstacles {', '.join(c['prims'])}: clearance {c['clearance_m']:.3f} m, "
                     f"{near}")
    lines += [f"  warning: {w}" for w in r["warnings"]]
    if r.get("output"):
        lines.append(f"  wrote {r['output']}")
    return "\n".join(lines)
