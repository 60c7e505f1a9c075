"""The ``camtraj`` command line: a thin edge over :mod:`camtraj.convert`.

Exit codes (design.md §5): 0 success; 2 bad input or usage; 3 the shot cannot be done as asked.
Errors are printed as one ``ERROR:`` line naming the frames, axes and margins; no traceback.
"""

from __future__ import annotations

import json
import logging
import math
import sys
from typing import Any, NoReturn

import click

import camtraj
from camtraj.batch import batch_command, write_json_atomic
from camtraj.errors import CamtrajError, CollisionError, InputError, UnreachableFramesError
from camtraj.options import ConvertOptions, build_options, convert_options, more_convert_options
from camtraj.place import place_command
from camtraj.robot import JOINT_NAMES, REVOLUTE

EXIT_OK, EXIT_INPUT, EXIT_INFEASIBLE = 0, 2, 3


def _fail(exc: CamtrajError) -> NoReturn:
    click.echo(f"ERROR: {exc}", err=True)
    sys.exit(exc.exit_code)


def _progress_wanted(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def _options(kw: dict[str, Any]) -> ConvertOptions:
    return build_options(**kw)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(camtraj.__version__, prog_name="camtraj")
def main() -> None:
    """Turn a previs USD camera move into a motion-control camera robot move.

    \b
    camtraj convert shot.usd -o shot.mcap   the main job
    camtraj check shot.usd                  can the robot do it? (no output file)
    camtraj place shot.usd -o set.toml      where to lay the track for it
    camtraj info shot.mcap                  what a converted file holds
    camtraj batch / farm                    many shots, locally or on a render farm

    Units: metres and degrees on the command line; metres and radians in files.
    Exit codes: 0 ok, 2 bad input or usage, 3 the shot cannot be done as asked.
    """
    logging.basicConfig(format="warning: %(message)s", level=logging.WARNING)


@main.command()
@click.argument("shot", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              metavar="OUT.mcap", help="The MCAP file to write (atomically).")
@convert_options
@more_convert_options
@click.option("--summary", type=click.Path(dir_okay=False), metavar="FILE.json",
              help="Also write the run's summary as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no report.")
def convert(shot: str, output: str, summary: str | None, quiet: bool, **kw: Any) -> None:
    """Convert SHOT (a USD camera animation) into a motion-control MCAP file.

    Every frame is solved for the robot (SM inverse kinematics), the move is timed at the
    servo rate inside the axis limits, with a run-up from rest and a run-out to rest, and
    written as ROS 2 messages that Foxglove and ros2 bag tools read.
    """
    from camtraj.convert import convert as run

    try:
        if summary is not None:
            _check_writable(summary, "--summary")
        result = run(shot, output, _options(kw), progress=_progress_wanted(quiet))
        if summary is not None:
            try:
                write_json_atomic(_path(summary), result)
            except OSError as exc:
                _path(output).unlink(missing_ok=True)  # all or nothing
                msg = f"cannot write {summary}: {exc.strerror or exc}"
                raise InputError(msg) from exc
    except CamtrajError as exc:
        _fail(exc)
    if not quiet:
        click.echo(_report(result))


@main.command()
@click.argument("shot", type=click.Path(dir_okay=False))
@convert_options
@more_convert_options
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def check(shot: str, as_json: bool, quiet: bool, **kw: Any) -> None:
    """Check whether the robot can do SHOT as asked, writing nothing.

    Reports reachability per frame, each axis's use of its limits, the maximum feasible speed,
    and the run-up / run-out extents. Exit code 3 when the shot cannot be done as asked.
    """
    from camtraj.convert import convert as run
    from camtraj.timing import TimingLimitError

    options = None
    try:
        options = _options(kw)
        result = run(shot, None, options, progress=_progress_wanted(quiet))
    except UnreachableFramesError as exc:
        result = _unreachable_report(shot, exc)
    except TimingLimitError as exc:
        result = _limit_report(shot, exc, options)
    except CollisionError as exc:
        result = {"status": "collision", "shot": shot, "message": str(exc), "frame": exc.frame,
                  "link": exc.link, "prim": exc.prim, "distance_m": exc.distance,
                  "clearance_m": exc.clearance}
    except CamtrajError as exc:
        _fail(exc)
    if as_json:
        click.echo(json.dumps(result, indent=2, sort_keys=True, default=_json_default))
    else:
        click.echo(_report(result))
    sys.exit(EXIT_OK if result["status"] == "ok" else EXIT_INFEASIBLE)


@main.command()
@click.argument("mcap_file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(mcap_file: str, as_json: bool) -> None:
    """Show what a camtraj MCAP file holds: shot, frames, duration, rate, topics, limits."""
    from camtraj.mcap_io import describe

    try:
        d = describe(mcap_file)
    except CamtrajError as exc:
        _fail(exc)
    if as_json:
        click.echo(json.dumps(d, indent=2, sort_keys=True, default=_json_default))
        return
    meta = d.get("metadata") or {}
    fr = d.get("frames") or {}
    lines = [
        f"file       {d['path']}  ({d['size_bytes'] / 1e6:.2f} MB, profile {d['profile']})",
        f"shot       {d.get('source_file')}  camera {d.get('camera_prim')}",
        f"frames     {fr.get('first')}-{fr.get('last')} ({fr.get('count')} frames at "
        f"{d.get('frame_rate_hz')} fps)",
        f"take       {d['duration_s']:.3f} s at {d.get('servo_rate_hz'):.1f} Hz, timing "
        f"{meta.get('timing_mode')}, speed factor {meta.get('speed_factor')}",
        f"robot      {meta.get('robot')}",
        f"written by {meta.get('tool_version')}",
        "topics:",
    ]
    lines += [f"  {t['topic']:<20} {t['type']:<40} {t['count']:>7} messages"
              for t in d["topics"]]
    limits = d.get("limits")
    if limits:
        lines.append("limits used (position range, max velocity; deg for revolute axes):")
        for i, name in enumerate(limits.get("joints", JOINT_NAMES)):
            conv = math.degrees if REVOLUTE[i] else float
            unit = "deg" if REVOLUTE[i] else "m"
            lo, hi = conv(limits["lower"][i]), conv(limits["upper"][i])
            v = conv(limits["max_velocity"][i])
            lines.append(f"  {name:<7} [{lo:9.3f}, {hi:9.3f}] {unit:<3}  {v:8.3f} {unit}/s")
    click.echo("\n".join(lines))


main.add_command(batch_command, "batch")
main.add_command(place_command, "place")
try:  # the farm commands need nothing optional until they run
    from camtraj.farm import farm_group

    main.add_command(farm_group, "farm")
except ImportError:  # pragma: no cover - farm.py is part of the package
    pass


# ---------------------------------------------------------------------------------------------
# Reports
# ---------------------------------------------------------------------------------------------


def _check_writable(path: str, option: str) -> None:
    """Fail early (exit 2) when the folder of an output file does not exist."""
    folder = _path(path).parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        msg = f"cannot write {option} {path}: folder {folder} {what}"
        raise InputError(msg)


def _path(p: str) -> Any:
    from pathlib import Path

    return Path(p)


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, float) and not math.isfinite(obj):
        return str(obj)
    return str(obj)


def _unreachable_report(shot: str, exc: UnreachableFramesError) -> dict[str, Any]:
    return {
        "status": "unreachable",
        "shot": shot,
        "message": str(exc),
        "unreachable": [
            {"frame": e.frame, "miss": e.miss, "miss_unit": e.miss_unit, "axis": e.axis,
             "reason": e.reason}
            for e in exc.errors
        ],
    }


def _limit_report(shot: str, exc: Any, options: Any) -> dict[str, Any]:
    return {
        "status": "limits",
        "shot": shot,
        "message": str(exc),
        "timing": getattr(options, "timing", None),
        "max_speed": exc.max_speed,
        "feasible_fps": exc.feasible_fps,
        "violations": [
            {"axis": v.axis, "quantity": v.quantity, "peak": v.peak, "limit": v.limit,
             "ratio": v.ratio, "frames": v.frame_text, "text": v.describe()}
            for v in exc.violations
        ],
    }


def _floor(x: float, digits: int) -> str:
    """Rounded down, so a speed that is said to fit does fit."""
    scale = 10.0**digits
    return f"{math.floor(x * scale) / scale:.{digits}f}"


def _floor_pct(x: float) -> int:
    return math.floor(100.0 * x)


def _pct(x: float) -> str:
    return "   -" if not math.isfinite(x) else f"{100 * x:4.0f}%"


def _report(r: dict[str, Any]) -> str:
    """The human-readable report of a convert / check run."""
    if r["status"] == "unreachable":
        lines = [f"{r['shot']}: CANNOT BE REACHED", f"  {r['message']}", "  frame  misses by"]
        for u in r["unreachable"]:
            amount = (f"{u['miss']:.3f} m" if u["miss_unit"] == "m"
                      else f"{math.degrees(u['miss']):.1f} deg")
            lines.append(f"  {u['frame']:>5}  {amount:>10}  {u['reason']}")
        return "\n".join(lines)
    if r["status"] == "collision":
        return f"{r['shot']}: COLLISION\n  {r['message']}"
    if r["status"] == "limits":
        lines = [f"{r['shot']}: NOT POSSIBLE with --timing {r['timing']}"]
        lines += [f"  {v['text']}" for v in r["violations"]]
        if math.isfinite(r["max_speed"]):
            lines.append(f"  maximum feasible speed {_floor_pct(r['max_speed'])}% of real time "
                         f"(shoot at {_floor(r['feasible_fps'], 2)} fps); try --timing scale")
        return "\n".join(lines)
    fr = r["frames"]
    lines = [
        f"{r['shot']}  camera {r['camera']}  frames {fr['first']}-{fr['last']} "
        f"({fr['count']} at {r['fps']:g} fps)",
        f"  timing {r['timing']}: take {r['duration']:.2f} s (shot {r['shot_start']:.2f}-"
        f"{r['shot_end']:.2f} s), speed factor {r['speed_factor']:.3f}, "
        f"servo {r['servo_rate_hz']:.1f} Hz",
        f"  maximum feasible speed {_floor_pct(r['max_speed'])}% of real time "
        f"(could be shot at {_floor(r['feasible_fps'], 2)} fps)",
        "  axis      position velocity  accel   jerk   run-up   run-out (extent)",
    ]
    for i, name in enumerate(JOINT_NAMES):
        use = r["peak_use"].get(name, {})
        unit = "deg" if REVOLUTE[i] else "m"
        up = r["runup"]["extent"].get(name, 0.0)
        out = r["runout"]["extent"].get(name, 0.0)
        lines.append(
            f"  {name:<8} {_pct(use.get('position', math.nan))}    "
            f"{_pct(use.get('velocity', math.nan))}   {_pct(use.get('acceleration', math.nan))}"
            f"  {_pct(use.get('jerk', math.nan))}  {up:7.3f}  {out:7.3f} {unit}"
        )
    lines.append(f"  run-up {r['runup']['duration_s']:.2f} s, run-out "
                 f"{r['runout']['duration_s']:.2f} s")
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
