"""The report page: one self-contained HTML file (inline CSS and SVG, no script, nothing
fetched, system fonts), rendered from a :class:`~camtraj.report.data.ReportData` and written
atomically.
"""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

import camtraj
from camtraj.errors import frame_ranges
from camtraj.report.data import ReportData
from camtraj.report.plots import COLORS, figures, limit_text
from camtraj.shown import (
    EDGE_QUANTITIES,
    camera_moves,
    edge_use,
    frame_span,
    percent,
    seconds,
    servo,
    speed_text,
)
from camtraj.timing.limits import QUANTITIES

# ---------------------------------------------------------------------------------------------
# The page
# ---------------------------------------------------------------------------------------------

_CSS = """
:root { color-scheme: light; }
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans",
       "Liberation Sans", Arial, sans-serif; margin: 0 auto; max-width: 1320px;
       padding: 16px 28px 48px; color: #1c1c1c; background: #fff; line-height: 1.4; }
h1 { font-size: 1.5rem; margin: 0.2rem 0 0.4rem; word-break: break-all; }
h2 { font-size: 1.15rem; margin: 1.6rem 0 0.5rem; border-bottom: 1px solid #ddd; }
h3 { font-size: 1rem; margin: 1.2rem 0 0.2rem; }
.status { display: inline-block; padding: 4px 12px; border-radius: 4px; font-weight: 600; }
.status.ok { background: #e3f4e1; color: #1d5e1a; }
.status.bad { background: #fde2e1; color: #9c1c1a; }
table { border-collapse: collapse; font-size: 0.9rem; }
td, th { padding: 3px 10px; border-bottom: 1px solid #eee; text-align: left;
         vertical-align: top; }
th { background: #f6f6f6; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.warn { background: #fff3d6; } td.over { background: #fde2e1; color: #9c1c1a;
  font-weight: 600; }
ul.problems li { color: #9c1c1a; } ul.warnings li { color: #7a5200; }
nav a { margin-right: 0.8rem; } nav a.bad { color: #c62828; font-weight: 600; }
figure { margin: 0.4rem 0 1.2rem; } figcaption { font-size: 0.85rem; margin-left: 4%; }
.key { margin-right: 1.1rem; white-space: nowrap; }
svg { width: 100%; height: auto; display: block; }
footer { margin-top: 2rem; font-size: 0.8rem; color: #777; }
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)





def _facts(data: ReportData) -> list[tuple[str, str]]:
    fn = data.frame_numbers
    rows = [
        ("shot", data.shot),
        ("camera", data.camera),
        ("frames", f"{frame_span(fn[0], fn[-1])} ({fn.size} frames at {data.fps:g} fps)"),
        ("robot", data.robot),
        *([("lens", data.lens)] if data.lens else []),
        ("placement", data.placement),
        ("timing mode", data.timing),
    ]
    s = data.samples
    if s is not None:
        rows += [
            ("speed factor", f"{data.speed_factor:.3f} (shot duration in the take / its own)"),
            ("servo", servo(data.servo_rate_hz, data.servo_step_ms).removeprefix("servo ")),
            ("take", f"{seconds(s.end - s.start)} s; shot "
                     f"{seconds(data.shot_start)}-{seconds(data.shot_end)} s"),
        ]
    if math.isfinite(data.max_speed):
        rows.append(("maximum feasible speed", speed_text(data.max_speed, data.fps)
                     + (f", set by {data.max_speed_set_by}" if data.max_speed_set_by else "")))
    elif data.status not in ("unreachable", "lens_range"):
        rows.append(("maximum feasible speed", "not recorded in this file"))
    if data.has_take and s is not None:
        rows.append(("run-up / run-out",
                     f"{seconds(data.shot_start - s.start)} s / "
                     f"{seconds(s.end - data.shot_end)} s"
                     + ("" if data.edge_travel is None
                        else "; " + camera_moves(*data.edge_travel))))
    else:
        rows.append(("run-up / run-out", "not planned: the shot itself cannot be done as asked"))
    return rows


def margins(data: ReportData) -> list[dict[str, Any]]:
    """Per axis: peak use of each limit over the shot part, the run-up's and run-out's peak
    acceleration and jerk use (the larger of the two, as the terminal's "ends" columns) and
    their extents (display units: m or deg)."""
    s = data.samples
    assert s is not None
    ends = (edge_use(data.edges["runup"], data.edges["runout"], data.joint_names)
            if data.edges is not None else None)
    rows = []
    for i, name in enumerate(data.joint_names):
        scale = math.degrees(1.0) if data.revolute[i] else 1.0
        ok = data.has_take
        rows.append({
            "axis": name, "unit": "deg" if data.revolute[i] else "m",
            **{qn: float(s.shot_peak[k, i]) for k, qn in enumerate(QUANTITIES)},
            **{f"ends_{qn}": ends[name][qn] if ends is not None else math.nan
               for qn in EDGE_QUANTITIES},
            "runup": float(s.edge_extent[0, i] * scale) if ok else math.nan,
            "runout": float(s.edge_extent[1, i] * scale) if ok else math.nan,
        })
    return rows


def _margins_table(data: ReportData) -> str:
    head = "".join(f"<th>{q}</th>" for q in QUANTITIES)
    ends = "".join(f"<th>run-up/run-out {q}</th>" for q in EDGE_QUANTITIES)
    lines = [f"<table class='margins'><tr><th>axis</th>{head}{ends}<th>run-up extent</th>"
             "<th>run-out extent</th></tr>"]
    over = data.tolerance
    for row in margins(data):
        cells = []
        for q in QUANTITIES:
            v = row[q]
            cls = "over" if v > 1 + over else "warn" if v > 0.8 else ""
            cells.append(f"<td class='num {cls}'>{percent(v)}</td>")
        for q in EDGE_QUANTITIES:
            cells.append(f"<td class='num ends'>{percent(row[f'ends_{q}'])}</td>")
        ext = [("-" if not math.isfinite(row[k]) else f"{row[k]:.3f} {row['unit']}")
               for k in ("runup", "runout")]
        lines.append(f"<tr><td><a href='#axis-{_e(row['axis'])}'>{_e(row['axis'])}</a></td>"
                     + "".join(cells) + "".join(f"<td class='num'>{x}</td>" for x in ext)
                     + "</tr>")
    lines.append("</table><p>Peak use of each limit over the shot (first to last film frame); "
                 "position: 0% mid-range, 100% at a bound. Run-up/run-out: their own peak "
                 "use (the larger of the two), apart from the shot's.</p>")
    if data.margins is not None:
        lines.append(_closest_table(data, data.margins))
    return "\n".join(lines)


def _closest_table(data: ReportData, m: dict[str, Any]) -> str:
    """What the terminal's margin column and line say: each axis's nearest approach to a
    position limit and its frame, the wrist singularity and full stretch margins."""
    rows = ["<table class='closest'><tr><th>axis</th><th>nearest position limit</th>"
            "<th>at frame</th></tr>"]
    for i, name in enumerate(data.joint_names):
        if name not in m["to_limits"]:
            continue  # a file from before the lens motors had margins
        unit = "deg" if data.revolute[i] else "m"
        rows.append(f"<tr><td>{_e(name)}</td><td class='num'>{m['to_limits'][name]:.3f} "
                    f"{unit}</td><td class='num'>{m['to_limits_frame'][name]}</td></tr>")
    rows.append("</table>")
    rows.append(f"<p class='closest'>Margin to the wrist singularity "
                f"{m['wrist_singularity_deg']:.1f} deg (frame {m['wrist_singularity_frame']}), "
                f"to full stretch {m['full_stretch_deg']:.1f} deg (frame "
                f"{m['full_stretch_frame']}).</p>")
    return "\n".join(rows)


def render_html(data: ReportData) -> str:
    """The whole report as one self-contained HTML page (no scripts, nothing fetched)."""
    path_fig, axis_figs = figures(data)
    title = Path(data.shot).name
    if data.status == "ok":
        status = "<p class='status ok'>The robot can do this shot as converted.</p>"
    elif data.status == "limits":
        status = (f"<p class='status bad'>NOT POSSIBLE with --timing {_e(data.timing)}: "
                  f"{len(data.violations)} limit(s) exceeded.</p>")
    elif data.status == "collision":
        status = f"<p class='status bad'>COLLISION: {_e(data.message)}</p>"
    elif data.status == "lens_range":
        status = f"<p class='status bad'>OUTSIDE THE LENS'S RANGE: {_e(data.message)}</p>"
    else:
        status = (f"<p class='status bad'>CANNOT BE REACHED: {len(data.unreachable)} "
                  "frame(s) out of the robot's reach.</p>")
    parts = [
        "<!DOCTYPE html>", "<html lang='en'><head><meta charset='utf-8'>",
        f"<title>camtraj report: {_e(title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<header><h1>{_e(title)}</h1>{status}</header>",
        "<section id='summary'><h2>Summary</h2><table class='facts'>",
        *(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in _facts(data)),
        "</table>",
    ]
    if data.violations:
        parts.append("<h3>Limits exceeded</h3><ul class='problems'>")
        parts += [f"<li class='violation' data-axis='{_e(v.axis)}' "
                  f"data-quantity='{_e(v.quantity)}' data-frames='{_e(v.frame_text)}'>"
                  f"<a href='#axis-{_e(v.axis)}'>{_e(v.axis)}</a> "
                  f"{_e(v.text.removeprefix(v.axis).strip())}</li>"
                  for v in data.violations]
        parts.append("</ul>")
    if data.unreachable:
        parts.append(f"<h3>Unreachable frames</h3><p class='problems'>"
                     f"{_e(frame_ranges(list(data.unreachable)))}: {_e(data.message)}</p>")
    if data.warnings:
        parts.append("<h3>Warnings</h3><ul class='warnings'>")
        parts += [f"<li>{_e(w)}</li>" for w in data.warnings]
        parts.append("</ul>")
    if data.samples is not None:
        parts += ["<h3>Margins</h3>", _margins_table(data)]
    parts.append("</section>")
    if path_fig:
        parts += ["<section id='path'><h2>Camera path and robot (robot base frame, to scale)"
                  "</h2><p>Grey bar: the track from its minimum to its maximum travel. Stick "
                  "figures: the robot at a few film frames (numbered), base to camera "
                  "through the link origins. Arrows on the path: where the camera looks."
                  "</p>", f"<figure>{path_fig}</figure></section>"]
    if axis_figs:
        bad = {v.axis for v in data.violations}
        nav = " ".join(f"<a href='#axis-{_e(n)}'{' class=bad' if n in bad else ''}>{_e(n)}</a>"
                       for n in data.joint_names)
        parts += ["<section id='axes'><h2>Axes: use of the limits over take time</h2>",
                  "<p>Each quantity as a fraction of its limit (±1: the limit lines). Shaded: "
                  "the shot, from the first to the last film frame; ticks at the bottom: film "
                  "frames; red: over a limit, with its frames.</p>", f"<nav>{nav}</nav>"]
        for i, (name, svg) in enumerate(zip(data.joint_names, axis_figs, strict=True)):
            key = " ".join(
                f"<span class='key'><span style='color:{COLORS[q]}'>&#9644;</span> {q} "
                f"{_e(limit_text(data, i, q))}</span>" for q in QUANTITIES)
            parts.append(f"<figure id='axis-{_e(name)}' class='axis'>{svg}"
                         f"<figcaption>{_e(name)}, ±1 is: {key}</figcaption></figure>")
        parts.append("</section>")
    parts.append(f"<footer>camtraj {_e(camtraj.__version__)} report from {_e(data.source)}"
                 "</footer></body></html>")
    return "\n".join(parts) + "\n"


def report_mcap(mcap: str | Path, path: str | Path) -> None:
    """``camtraj report``: the report of a converted take (``mcap``) written to ``path``.

    The output is checked (not the MCAP, a writable folder, a regular file or nothing) before
    the MCAP is read.

    Raises:
        InputError: The output cannot be written, or the MCAP cannot be read or is not a
            camtraj take.
    """
    from camtraj.outputs import OutputSet
    from camtraj.report.data import report_from_mcap

    with OutputSet() as outputs:
        outputs.add(path, "-o")
        outputs.refuse_inputs([(mcap, "the MCAP the report is made from")])
        page = render_html(report_from_mcap(mcap))
        outputs.write_bytes(path, page.encode("utf-8"))
        outputs.commit()
