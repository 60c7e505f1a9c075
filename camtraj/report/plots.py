"""The report's figures: matplotlib (no pyplot, SVG backend), returned as inline SVG text.

Two kinds of figure, both drawn from a :class:`camtraj.report.ReportData`:

- :func:`axis_svg`: one axis of the robot, four stacked plots (position, velocity,
  acceleration, jerk) as a fraction of the limit over take time. The shot span is shaded, the
  film frames are ticked (and numbered on the top axis), the limit lines are at ±1 and every
  violation is a red span over its frames, labelled with them.
- :func:`path_svg`: a top view (x-y) and a side view (x-z) of the camera path in the robot base
  frame, to scale, with the track from its min to its max, the base, the stage origin (the
  placement) and a few robot poses as stick figures through the link origins.

Servo samples are drawn as their minimum and maximum per pixel column
(:class:`camtraj.report.samples.Samples`), so a long take stays a small SVG while every peak
is kept. Output is deterministic: a fixed SVG hash
salt per figure (unique ids in one HTML page) and no date in the metadata.

Element ids (``gid``) the tests and a reader of the page can rely on, per axis ``A`` and
quantity ``Q``: ``A-Q-axes`` (the plot's background), ``A-Q-curve``, ``A-Q-limit-upper``,
``A-Q-limit-lower``, ``A-Q-frames`` (one tick per film frame, in frame order, when every
frame is ticked) and ``A-Q-violation-F1-F2`` (one span per run of violating frames F1..F2).
"""

from __future__ import annotations

import io
import math
import re
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from camtraj.shown import TIMES, frame_span
from camtraj.timing.limits import QUANTITIES

if TYPE_CHECKING:
    from camtraj.report.data import ReportData

Array = NDArray[np.float64]

#: At most this many film frames get a tick; longer shots tick every k-th frame.
MAX_FRAME_TICKS = 240
#: The camera path in the views is drawn through at most about 5x this many frames.
PATH_RUNS = 600

_WIDTH_IN = 12.0
_DPI = 100
_BLUE = "#1f5fa8"
_RED = "#d62728"
_SHOT = "#e6eef8"
_GREY = "#8a8a8a"
COLORS = {"position": "#404040", "velocity": "#1f5fa8", "acceleration": "#e08a00",
           "jerk": "#8e44ad"}
#: The y scale of the axis plots stops here [x limit], so a large violation leaves the rest
#: readable.
Y_MAX = 2.5


def _unit(data: ReportData, axis: int, quantity: str) -> tuple[str, float]:
    """Display unit and the factor from SI to it."""
    base, factor = ("deg", 180.0 / math.pi) if data.revolute[axis] else ("m", 1.0)
    power = QUANTITIES.index(quantity)
    suffix = {0: "", 1: "/s", 2: "/s²", 3: "/s³"}[power]
    return base + suffix, factor


def _frame_axis_functions(data: ReportData) -> tuple[Any, Any]:
    """Take time <-> film frame number (piecewise linear, extended linearly past the ends)."""
    ft = data.frame_times.astype(float)
    fn = data.frame_numbers.astype(float)
    if ft.shape[0] < 2 or ft[-1] <= ft[0]:
        return (lambda x: np.asarray(x, float)), (lambda x: np.asarray(x, float))
    s0 = (fn[1] - fn[0]) / (ft[1] - ft[0])
    s1 = (fn[-1] - fn[-2]) / (ft[-1] - ft[-2])

    def to_frame(x: Any) -> Any:
        x = np.asarray(x, float)
        y = np.interp(x, ft, fn)
        y = np.where(x < ft[0], fn[0] + (x - ft[0]) * s0, y)
        return np.where(x > ft[-1], fn[-1] + (x - ft[-1]) * s1, y)

    def to_time(f: Any) -> Any:
        f = np.asarray(f, float)
        y = np.interp(f, fn, ft)
        y = np.where(f < fn[0], ft[0] + (f - fn[0]) / s0, y)
        return np.where(f > fn[-1], ft[-1] + (f - fn[-1]) / s1, y)

    return to_frame, to_time


def frame_tick_stride(n_frames: int) -> int:
    """Every how many film frames a tick is drawn (1 for shots up to MAX_FRAME_TICKS)."""
    return max(1, math.ceil(n_frames / MAX_FRAME_TICKS))


def figures(data: ReportData) -> tuple[str, list[str]]:
    """Every figure of the report: the path views (empty without camera poses) and one
    per-axis figure per axis (none without servo samples), as SVG text."""
    import matplotlib

    with matplotlib.rc_context(_RC):
        path = path_svg(data) if data.camera_path.shape[0] else ""
        axes = axis_svgs(data) if data.samples is not None else []
    return path, axes


def axis_svgs(data: ReportData) -> list[str]:
    """Per axis: position, velocity, acceleration and jerk / limit over take time, as SVG.

    All four share the y scale (±1: the limits). The scale stops at ``Y_MAX`` (or the
    highest peak, if lower), so a violation many times a limit does not flatten the rest:
    its curve runs off the top in red, and its label gives the peak as a multiple of the limit.

    The axes share the time axis, the shading and the frame ticks, so one figure is drawn
    once and reused: each axis's curves, limit lines and spans are added, the figure is
    saved, and they are removed again (matplotlib then keeps its tick objects).
    """
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    fig = Figure(figsize=(_WIDTH_IN, 2.9), dpi=_DPI)
    fig.subplots_adjust(left=0.055, right=0.985, top=0.86, bottom=0.2)
    ax = fig.add_subplot()
    ax.axvspan(data.shot_start, data.shot_end, color=_SHOT, zorder=0, lw=0)
    ticks = data.frame_times[:: frame_tick_stride(data.frame_numbers.shape[0])]
    tick_x = np.repeat(ticks, 3)  # one path for every tick: (x, 0) (x, h) (gap) ...
    tick_y = np.tile([0.0, 0.05, np.nan], ticks.shape[0])
    (frame_ticks,) = ax.plot(tick_x, tick_y, transform=ax.get_xaxis_transform(),
                             color="#4a4a4a", lw=0.6, zorder=5)
    assert data.samples is not None
    ax.set_xlim(data.samples.start, data.samples.end)
    ax.set_ylabel(f"{TIMES} limit", fontsize=9)
    ax.set_xlabel("take time [s] / film frame   (shaded: the shot; ticks: film frames)",
                  fontsize=8)
    ax.xaxis.set_major_locator(MaxNLocator(9))
    ax.yaxis.set_major_locator(MaxNLocator(5, symmetric=True))
    to_frame, _ = _frame_axis_functions(data)
    first, last = data.frame_numbers[0], data.frame_numbers[-1]

    def tick(x: float, _pos: int) -> str:
        f = float(to_frame(x))
        frame = f"\n{round(f)}" if first - 0.01 <= f <= last + 0.01 else "\n"
        return f"{x:g}{frame}"

    ax.xaxis.set_major_formatter(FuncFormatter(tick))
    ax.tick_params(labelsize=8)
    ax.grid(True, axis="y", color="#e6e6e6", lw=0.6)
    out = []
    for axis, name in enumerate(data.joint_names):
        ax.patch.set_gid(f"{name}-axes")
        frame_ticks.set_gid(f"{name}-frames")
        added = _draw_axis(ax, data, axis)
        out.append(_svg(fig, salt=f"camtraj-axis-{name}"))
        for artist in added:
            artist.remove()
    return out


def _draw_axis(ax: Any, data: ReportData, axis: int) -> list[Any]:
    """One axis's curves, limit lines, violation spans and title; returns what it added."""
    name = data.joint_names[axis]
    added: list[Any] = []
    violated = {v.quantity: v for v in data.violations if v.axis == name}
    peak = 1.0
    assert data.samples is not None
    for quantity in QUANTITIES:
        te, ye = data.samples.curves[(quantity, axis)]  # every column's extremes
        peak = max(peak, float(np.max(np.abs(ye))) if ye.size else 0.0)
        added += ax.plot(te, ye, color=COLORS[quantity], lw=1.0, zorder=3,
                         gid=f"{name}-{quantity}-curve")
        over = np.where(np.abs(ye) > 1.0 + data.tolerance, ye, np.nan)
        if np.any(np.isfinite(over)):
            added += ax.plot(te, over, color=_RED, lw=2.0, zorder=4)
    top = min(peak * 1.06, Y_MAX) if peak > 1.0 else 1.12
    ax.set_ylim(-top, top)
    bad = bool(violated)
    for sign, side in ((1.0, "upper"), (-1.0, "lower")):
        added.append(ax.axhline(sign, color=_RED if bad else _GREY, lw=1.0 if bad else 0.8,
                                ls="-" if bad else "--", zorder=2,
                                gid=f"{name}-limit-{side}"))
    labels = []
    for quantity, v in violated.items():
        for a, b in v.frames:
            ta, tb = _span(data, a, b)
            added.append(ax.axvspan(ta, tb, color=_RED, alpha=0.15, lw=0, zorder=1,
                                    gid=f"{name}-{quantity}-violation-{a}-{b}"))
            label = f"frames {frame_span(a, b)}" if b != a else f"frame {a}"
            ratio = span_peak(data, axis, quantity, a, b, v.ratio)
            labels.append(ax.text(
                0.5 * (ta + tb), 0.96, f"{quantity} {ratio:.3g}{TIMES} limit, {label}",
                transform=ax.get_xaxis_transform(), ha="center", va="top", color=_RED,
                fontsize=8, fontweight="bold", zorder=6,
                gid=f"{name}-{quantity}-violation-{a}-{b}-label",
                bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 0.8}))
    _place_labels(ax, labels)
    added += labels
    added.append(ax.text(
        0.0, 1.04, f"{name}  ({'revolute' if data.revolute[axis] else 'prismatic'})",
        transform=ax.transAxes, fontsize=10, fontweight="bold", gid=f"{name}-title"))
    return added


def span_peak(data: ReportData, axis: int, quantity: str, a: int, b: int,
              whole: float) -> float:
    """The peak of ``|fraction|`` over the servo samples that count for frames a..b (those
    between the frames before and after the run, as the timing check measures a frame's
    neighbourhood), never above the whole violation's peak ``whole``."""
    assert data.samples is not None
    fn = data.frame_numbers
    inside = (fn >= a) & (fn <= b)
    if not np.any(inside):
        return whole
    peak = data.samples.frame_peak[QUANTITIES.index(quantity), inside, axis]
    return min(float(peak.max()), whole)


def _renderer(fig: Any) -> Any:
    """A renderer that measures text as the figure will draw it."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    return canvas.get_renderer()  # type: ignore[no-untyped-call]


def _place_labels(ax: Any, labels: list[Any], row: float = 0.11) -> None:
    """Violation labels (x in data, y in axes fraction) inside the plot and apart: each one is
    moved sideways into the plot, then down a row at a time until it overlaps none placed."""
    if not labels:
        return
    renderer = _renderer(ax.figure)
    frame = ax.get_window_extent(renderer)
    placed: list[Any] = []
    for text in labels:
        box = text.get_window_extent(renderer)
        shift = max(frame.x0 - box.x0, 0.0) + min(frame.x1 - box.x1, 0.0)
        if shift:
            x_display = ax.transData.transform((text.get_position()[0], 0.0))[0] + shift
            text.set_x(float(ax.transData.inverted().transform((x_display, 0.0))[0]))
        y = text.get_position()[1]
        for _ in range(int(0.9 / row)):
            box = text.get_window_extent(renderer)
            if not any(box.overlaps(p) for p in placed):
                break
            y -= row
            text.set_y(y)
        placed.append(text.get_window_extent(renderer))


def _stack_annotations(ax: Any, notes: list[Any], step_pt: float = 9.0) -> None:
    """Frame numbers in a view: one that would print over another moves up a line."""
    if not notes:
        return
    renderer = _renderer(ax.figure)
    placed: list[Any] = []
    for note in notes:
        for _ in range(len(notes)):
            box = note.get_window_extent(renderer)
            if not any(box.overlaps(p) for p in placed):
                break
            x, y = note.xyann
            note.xyann = (x, y + step_pt)
        placed.append(note.get_window_extent(renderer))


def _span(data: ReportData, a: int, b: int) -> tuple[float, float]:
    """Take times of frames a..b; a single frame gets a frame's width."""
    ta = float(np.interp(a, data.frame_numbers, data.frame_times))
    tb = float(np.interp(b, data.frame_numbers, data.frame_times))
    half = 0.5 / data.fps
    return (ta - half, tb + half) if a == b else (ta, tb)


def limit_text(data: ReportData, axis: int, quantity: str) -> str:
    """What ±1 means for one quantity of one axis, e.g. ``±500 deg/s²``."""
    unit, factor = _unit(data, axis, quantity)
    if quantity == "position":
        lo, hi = data.lower[axis] * factor, data.upper[axis] * factor
        return f"{lo:.4g} to {hi:.4g} {unit}"
    return f"±{data.limit(quantity)[axis] * factor:.4g} {unit}"


# ---------------------------------------------------------------------------------------------
# Top and side views
# ---------------------------------------------------------------------------------------------


def path_frames(xy: Array, runs: int = PATH_RUNS,
                must: NDArray[np.int64] | None = None) -> NDArray[np.int64]:
    """Indices of the film frames the camera path is drawn through, in frame order.

    A path of at most ``5 * runs`` frames keeps them all. A longer one is cut into ``runs``
    runs of consecutive frames, and each run keeps its first frame and those with the least
    and the greatest of each coordinate of ``xy`` (n, 2), so every excursion of the path
    stays drawn; ``must`` frames are kept too.
    """
    n = xy.shape[0]
    if n <= 5 * runs:
        return np.arange(n, dtype=np.int64)
    starts = np.linspace(0, n, runs + 1).astype(np.int64)[:-1]
    lengths = np.diff(np.r_[starts, n])
    where = np.arange(n)[:, None]
    keep = [starts, np.array([n - 1])]
    for reduce in (np.minimum, np.maximum):
        value = np.repeat(reduce.reduceat(xy, starts, axis=0), lengths, axis=0)
        first = np.minimum.reduceat(np.where(xy == value, where, n), starts, axis=0)
        keep.append(np.minimum(first, n - 1).ravel())
    if must is not None:
        keep.append(must)
    out: NDArray[np.int64] = np.unique(np.concatenate(keep).astype(np.int64))
    return out


def _view_points(data: ReportData) -> Array:
    """Every point a view must show [m], (p, 3)."""
    pts: list[Any] = [data.track, np.zeros((1, 3)), data.camera_path, data.poses.reshape(-1, 3)]
    if not np.allclose(data.base2world, np.eye(4)):
        pts.append(np.linalg.inv(data.base2world)[None, :3, 3])
    return np.concatenate(pts)


def path_svg(data: ReportData) -> str:
    """Top view (x-y) above side view (x-z) of the camera path and the robot, to scale.

    Both views share the x range (the track and everything else, with a margin) and the
    scale, so lengths compare across them; each view's height follows its y (or z) range.
    """
    from matplotlib.figure import Figure

    pts = _view_points(data)
    lo, hi = pts.min(axis=0) - 0.6, pts.max(axis=0) + 0.6
    width_in = 0.92 * _WIDTH_IN
    per_m = width_in / (hi[0] - lo[0])  # inches per metre, both views
    heights = [float(np.clip((hi[k] - lo[k]) * per_m, 1.3, 6.0)) for k in (1, 2)]
    fig_h = sum(heights) + 2.1
    fig = Figure(figsize=(_WIDTH_IN, fig_h), dpi=_DPI)
    views = (("top view (looking down)", 1, "y [m]"), ("side view (looking along +y)", 2,
                                                         "z (up) [m]"))
    cam = data.camera_path
    bad_frames = data.violation_frames()
    top = fig_h - 0.35
    for (title, k, ylabel), h in zip(views, heights, strict=True):
        bottom = top - h
        ax = fig.add_axes((0.06, bottom / fig_h, 0.92, h / fig_h))
        top = bottom - 0.6
        half = 0.5 * h / per_m
        mid = 0.5 * (lo[k] + hi[k])
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(mid - half, mid + half)
        ax.set_aspect("equal", adjustable="box")
        ax.set_gid(f"view-{k}")
        ax.text(0.0, 1.02, title, transform=ax.transAxes, fontsize=10, fontweight="bold")
        ax.set_ylabel(ylabel, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(True, color="#ececec", lw=0.6)
        tr = data.track
        ax.plot(tr[:, 0], tr[:, k], color="#b8b8b8", lw=6, solid_capstyle="butt", zorder=1,
                gid=f"view-{k}-track", label="track (min to max travel)")
        ax.annotate(f"track {data.lower[0]:.2f} to {data.upper[0]:.2f} m",
                    (tr[1, 0], tr[1, k]), xytext=(-4, -13), textcoords="offset points",
                    fontsize=8, color="#606060", ha="right")
        _frame_arrows(ax, np.eye(4), k, "robot base", "#202020")
        if not np.allclose(data.base2world, np.eye(4)):
            _frame_arrows(ax, np.linalg.inv(data.base2world), k, "stage origin", "#7a4ea3",
                          dy=8)
        notes = []
        for j, pose in enumerate(data.poses):
            ax.plot(pose[:, 0], pose[:, k], "-o", color="#3b3b4f", lw=1.4, ms=2.2, zorder=2,
                    alpha=0.45 + 0.4 * j / max(1, len(data.poses) - 1),
                    label="robot at a frame" if j == 0 else None)
            notes.append(ax.annotate(
                f"{data.pose_frames[j]}", (pose[-1, 0], pose[-1, k]), xytext=(0, 5),
                textcoords="offset points", fontsize=7, color="#3b3b4f", ha="center",
                gid=f"view-{k}-frame-{data.pose_frames[j]}"))
        _stack_annotations(ax, notes)
        if cam.shape[0]:
            mask = np.isin(data.frame_numbers, bad_frames)
            edges = np.flatnonzero(np.diff(np.r_[False, mask, False]))  # runs' ends
            drawn = path_frames(cam[:, [0, k]], must=np.clip(np.r_[edges, edges - 1], 0,
                                                              cam.shape[0] - 1))
            ax.plot(cam[drawn, 0], cam[drawn, k], color=_BLUE, lw=1.8, zorder=3,
                    gid=f"view-{k}-path", label="camera path")
            look = data.camera_look
            step = max(1, cam.shape[0] // 12)
            ax.quiver(cam[::step, 0], cam[::step, k], look[::step, 0], look[::step, k],
                      color=_BLUE, alpha=0.55, width=0.0025, scale=1.0 / (0.5 * per_m),
                      scale_units="inches", angles="xy", zorder=3)
            ax.plot(cam[0, 0], cam[0, k], "o", color=_BLUE, ms=6, zorder=4,
                    label=f"first frame {data.frame_numbers[0]}")
            ax.plot(cam[-1, 0], cam[-1, k], "s", color=_BLUE, ms=6, zorder=4,
                    label=f"last frame {data.frame_numbers[-1]}")
            if np.any(mask):
                ax.plot(cam[drawn, 0], np.where(mask[drawn], cam[drawn, k], np.nan),
                        color=_RED, lw=3.0, zorder=4, label="frames over a limit",
                        gid=f"view-{k}-over")
            if data.unreachable:
                um = np.isin(data.frame_numbers, data.unreachable)
                ax.plot(cam[um, 0], cam[um, k], "x", color=_RED, ms=5, zorder=5,
                        label="unreachable frames", gid=f"view-{k}-unreachable")
    ax.set_xlabel("x (along the track) [m]", fontsize=9)
    handles, labels = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncols=min(len(handles), 4), fontsize=8,
               frameon=False)
    return _svg(fig, salt="camtraj-path")


def _frame_arrows(ax: Any, T: NDArray[np.floating[Any]], k: int, label: str, color: str,
                  dy: float = -12) -> None:
    """A frame's x and (k-th) axis as 0.5 m arrows at its origin, in view coordinates."""
    o = T[:3, 3]
    for axis, col in ((0, _RED), (k, "#2ca02c" if k == 1 else "#1f77b4")):
        d = 0.5 * T[:3, axis]
        ax.annotate("", (o[0] + d[0], o[k] + d[k]), (o[0], o[k]),
                    arrowprops={"arrowstyle": "->", "color": col, "lw": 1.4})
    ax.plot(o[0], o[k], "o", color=color, ms=4, zorder=5)
    ax.annotate(label, (o[0], o[k]), xytext=(4, dy), textcoords="offset points", fontsize=8,
                color=color)


# ---------------------------------------------------------------------------------------------
# SVG text
# ---------------------------------------------------------------------------------------------

_RC: Any = {  # matplotlib's rc types list every key as a Literal
    "svg.fonttype": "none",  # text stays text: system fonts, searchable, small
    "font.family": "sans-serif",
    "font.sans-serif": ["DejaVu Sans", "Liberation Sans", "Arial", "Helvetica"],
    "path.simplify": False,  # every vertex drawn is a real sample (the envelope thins them)
    "axes.spines.top": False,
    "axes.spines.right": False,
}


def _svg(fig: Any, salt: str) -> str:
    """The figure as an ``<svg>`` element for inline HTML (no XML prolog, no metadata)."""
    import matplotlib

    buf = io.StringIO()
    rc: Any = {"svg.hashsalt": salt}
    with matplotlib.rc_context(rc):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None,
                                                 "Format": None, "Type": None})
    text = buf.getvalue()
    text = text[text.index("<svg"):]
    text = re.sub(r"<metadata>.*?</metadata>\s*", "", text, flags=re.DOTALL)
    # matplotlib numbers its groups per figure (axes_1, line2d_3, ...): make them unique in
    # the page. Nothing refers to them; clip paths and markers have hashed, salted ids.
    text = re.sub(r'id="([A-Za-z][\w.]*_\d+)"', rf'id="{salt}-\1"', text)
    # Let CSS size the picture: keep the viewBox, drop the fixed width and height in pt.
    return re.sub(r'(<svg[^>]*?) width="[^"]*" height="[^"]*"', r"\1", text, count=1)
