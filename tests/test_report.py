"""The HTML report (issue 9, item 2): ``camtraj report``, ``convert --report``, ``check --report``.

Every command runs in a subprocess (the real command line), once, in a module fixture. The page
is rendered by headless Chromium (Debian package ``chromium``; ``make chromium`` installs it)
and the screenshot is read back as pixels. Independent facts: the violations ``check --json``
prints (the timing stage's own check), forward kinematics of the solved frames against the
link origins read from the MCAP's /tf, the SVG geometry of the drawn curves, spans and ticks.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj import report as rp
from camtraj.convert import analyse
from camtraj.errors import InputError
from camtraj.options import build_options
from camtraj.report.samples import in_blocks
from camtraj.robot import JOINT_NAMES, Robot
from tests.test_convert import ROOT, SHOTS, error_line, leftovers, run_all, run_cli, usd_camera

Array = NDArray[np.float64]

MAYA = SHOTS / "maya_dolly_push_in.usda"
WHIP = SHOTS / "whip_pan.usda"
ROBOT_TOML = ROOT / "camtraj" / "data" / "robot.toml"
UNREACHABLE = SHOTS / "unreachable.usda"
PLACEMENT = "0.5,0.3,0.0,10.0"  # x, y, z [m], yaw [deg]
SVG_NS = "{http://www.w3.org/2000/svg}"
WINDOW = (1400, 6400)  # tall enough for the whole page of a shot


def chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def screenshot(html: Path, png: Path) -> NDArray[np.float32]:
    """Render ``html`` with headless Chromium (no network) and return the PNG's RGB pixels."""
    exe = chromium()
    if exe is None:
        pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium, "
                    "or `make chromium`)")
    with tempfile.TemporaryDirectory(prefix="camtraj-chromium-") as profile:
        proc = subprocess.run(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
             f"--screenshot={png}", f"--window-size={WINDOW[0]},{WINDOW[1]}",
             html.resolve().as_uri()],
            capture_output=True, text=True, timeout=300, check=False,
        )
    assert png.is_file(), f"chromium wrote no screenshot:\n{proc.stderr[-2000:]}"
    from matplotlib.image import imread

    pixels: NDArray[np.float32] = imread(str(png))[..., :3]
    return pixels


@dataclass(frozen=True)
class Runs:
    folder: Path
    procs: dict[str, subprocess.CompletedProcess[str]]

    def html(self, name: str) -> str:
        return (self.folder / f"{name}.html").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    d = tmp_path_factory.mktemp("report")
    (d / "a_file").write_text("a file where a folder should be")
    slow = d / "slow_robot.toml"  # the built-in robot, 15x slower: violations in several runs
    slow.write_text(re.sub(r"^(max_(?:velocity|acceleration|jerk)) = ([\d.]+)",
                           lambda m: f"{m.group(1)} = {float(m.group(2)) / 15.0:g}",
                           ROBOT_TOML.read_text(encoding="utf-8"), flags=re.M))
    first = run_all({
        "convert": ["convert", MAYA, "-o", d / "maya.mcap", "--placement", PLACEMENT,
                    "--report", d / "convert.html", "--summary", d / "maya.json", "-q"],
        "whip": ["check", WHIP, "--report", d / "whip.html", "--json"],
        "unreachable": ["check", UNREACHABLE, "--report", d / "unreachable.html", "--json"],
        "slow": ["check", MAYA, "--robot", slow, "--report", d / "slow.html", "--json"],
        "no_folder": ["check", MAYA, "--report", d / "a_file" / "r.html"],
        "convert_fails": ["convert", WHIP, "-o", d / "whip.mcap", "--report",
                          d / "whip_convert.html"],
    })
    second = run_all({
        "report": ["report", d / "maya.mcap", "-o", d / "report.html"],
        "again": ["report", d / "maya.mcap", "-o", d / "again.html"],
        "not_mcap": ["report", MAYA, "-o", d / "bad.html"],
        "report_no_folder": ["report", d / "maya.mcap", "-o", d / "a_file" / "r.html"],
    })
    return Runs(d, {**first, **second})


def svgs(page: str) -> list[ET.Element]:
    """Every inline <svg> of the page, parsed."""
    return [ET.fromstring(m) for m in re.findall(r"<svg.*?</svg>", page, flags=re.DOTALL)]


def by_id(root: ET.Element, gid: str) -> ET.Element:
    found = [el for el in root.iter() if el.get("id") == gid]
    assert len(found) == 1, f"expected one element {gid!r}, found {len(found)}"
    return found[0]


def subpaths(group: ET.Element) -> list[Array]:
    """The points of every subpath (M ... L ...) of the <path>s under an element, SVG coords."""
    out: list[Array] = []
    for path in group.iter(f"{SVG_NS}path"):
        for part in re.split(r"(?=M)", path.get("d", "")):
            nums = [float(x) for x in re.findall(r"-?\d+(?:\.\d*)?(?:e-?\d+)?", part)]
            if nums:
                out.append(np.array(nums).reshape(-1, 2))
    return out


def axis_svg(page: str, axis: str) -> ET.Element:
    for root in svgs(page):
        if any(el.get("id") == f"{axis}-axes" for el in root.iter()):
            return root
    raise AssertionError(f"no figure for axis {axis}")


# --------------------------------------------------------------------------------------------
# The page: self-contained, with the summary and every plot
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["convert", "report", "whip", "unreachable"])
def test_page_is_self_contained(runs: Runs, name: str) -> None:
    page = runs.html(name)
    assert page.startswith("<!DOCTYPE html>")
    lowered = page.lower()
    for bad in ("<script", "<link", "<img", "<iframe", "@import", "src=", "@font-face"):
        assert bad not in lowered, f"{name}: the page holds {bad!r}"
    assert not re.findall(r"url\((?!#)", lowered)  # only references inside the page
    hrefs = re.findall(r"href\s*=\s*['\"]([^'\"]*)", page)
    assert hrefs and all(h.startswith("#") for h in hrefs), [h for h in hrefs if h[:1] != "#"]
    # the only URLs left are XML namespace names, which nothing fetches
    urls = set(re.findall(r"https?://[^\s'\"<>]+", page))
    assert urls <= {"http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink"}, urls
    assert leftovers(runs.folder) == []
    ids = re.findall(r"\bid=['\"]([^'\"]+)", page)
    assert len(ids) == len(set(ids)), "element ids repeat in the page"
    refs = set(re.findall(r"url\(#([^)]+)\)", page)) | set(re.findall(r"href=\"#([^\"]+)", page))
    assert refs <= set(ids), refs - set(ids)  # every reference inside the page resolves


@pytest.mark.parametrize("name", ["convert", "report"])
def test_page_has_the_summary_and_every_plot(runs: Runs, name: str) -> None:
    assert runs.procs[name].returncode == 0, runs.procs[name].stderr
    page = runs.html(name)
    summary = json.loads((runs.folder / "maya.json").read_text())
    assert len(svgs(page)) == 1 + len(JOINT_NAMES)  # the views and one figure per axis
    for axis, kind in zip(JOINT_NAMES, ("prismatic", "revolute", "revolute", "prismatic",
                                        "revolute", "revolute", "revolute", "revolute"),
                          strict=True):
        root = axis_svg(page, axis)
        texts = " ".join(t.text or "" for t in root.iter(f"{SVG_NS}text"))
        assert f"{axis}  ({kind})" in texts
        caption = re.search(rf"<figure id='axis-{axis}'.*?<figcaption>(.*?)</figcaption>",
                            page, flags=re.DOTALL)
        assert caption is not None
        for quantity in rp.QUANTITIES:
            assert quantity in caption.group(1)
            by_id(root, f"{axis}-{quantity}-curve")
    assert "top view" in page and "side view" in page
    for fact in ("shot", "robot", "placement", "timing mode", "speed factor",
                 "maximum feasible speed", "run-up / run-out", "Margins"):
        assert f">{fact}<" in page
    assert f"{math.floor(100 * summary['max_speed'])}% of real time" in page
    assert "yaw 10.00 deg" in page
    assert "Limits exceeded" not in page  # a feasible take exceeds nothing


def test_both_sources_render_the_same_report(runs: Runs) -> None:
    """convert --report (in memory) and camtraj report (the MCAP) agree, number for number."""
    conv, rep = runs.html("convert"), runs.html("report")
    summary_rows = re.compile(r"<tr><th>([^<]+)</th><td>([^<]*)</td></tr>")
    assert summary_rows.findall(conv) == summary_rows.findall(rep)
    cells = re.compile(r"<td class='num[^']*'>([^<]+)</td>")
    a, b = cells.findall(conv), cells.findall(rep)
    # margins table (shot use, run-up/run-out use, extents), then nearest position limits
    assert len(a) == len(b) == 8 * (8 + 2)
    for x, y in zip(a, b, strict=True):
        if x.endswith("%"):  # jerk: exact in memory, by differences from the file
            assert abs(int(x[:-1]) - int(y[:-1])) <= 1, (x, y)
        else:
            assert x == y


def test_report_from_the_file_matches_the_run(runs: Runs, robot: Robot) -> None:
    """Servo samples, frames, link origins (from /tf) and camera path agree with the run."""
    options = build_options(camera=None, robot=None, placement=PLACEMENT, frames=None,
                            rate=250.0, timing="shot")
    analysis = analyse(MAYA, options)
    mem = rp.from_analysis(analysis, MAYA, options)
    disk = rp.report_from_mcap(runs.folder / "maya.mcap")
    ds, ms = disk.samples, mem.samples
    assert ds is not None and ms is not None
    assert ds.count == ms.count and abs(ds.start - ms.start) + abs(ds.end - ms.end) < 1e-9
    # every frame's peak use of position, velocity and acceleration, and the plotted curves
    np.testing.assert_allclose(ds.frame_peak[:3], ms.frame_peak[:3], atol=1e-9)
    for key, (_te, ye) in ms.curves.items():  # (sample times in ns in the file: a sample on
        if key[0] != "jerk":                    # a column's edge may fall on either side)
            got = ds.curves[key][1]
            np.testing.assert_allclose([got.min(), got.max()], [ye.min(), ye.max()], atol=1e-9)
    # jerk by differences against the exact jerk: close over the shot (a smooth spline),
    # and never above the true peak (ruckig's run-up and run-out switch jerk within a step)
    inner = slice(1, -1)  # frames whose samples are all the shot's
    assert np.max(np.abs(ds.frame_peak[3, inner] - ms.frame_peak[3, inner])) < 0.02
    assert np.all(ds.frame_peak[3].max(axis=0) <= ms.frame_peak[3].max(axis=0) * (1 + 1e-6))
    assert disk.edges == mem.edges  # the run-up's and run-out's use, recorded in the file
    np.testing.assert_array_equal(disk.frame_numbers, usd_camera(MAYA).frames)
    np.testing.assert_allclose(disk.poses, mem.poses, atol=1e-9)  # /tf chain == FK
    np.testing.assert_allclose(disk.track, mem.track, atol=1e-9)
    np.testing.assert_allclose(disk.camera_path, mem.camera_path, atol=1e-9)
    np.testing.assert_allclose(disk.base2world, mem.base2world, atol=1e-12)
    assert disk.max_speed == mem.max_speed
    # the stick figures end at the camera: FK of the solved frames
    assert analysis.path is not None
    idx = rp.pose_indices(analysis.path.q.shape[0])
    cam = robot.camera_pose(analysis.path.q[idx])[:, :3, 3]
    np.testing.assert_allclose(mem.poses[:, -1], cam, atol=1e-12)
    # the track bar runs from the track's minimum to its maximum, along base x
    np.testing.assert_allclose(np.diff(mem.track[:, 0]), robot.upper[0] - robot.lower[0])


def test_report_files_are_deterministic(runs: Runs) -> None:
    assert runs.procs["again"].returncode == 0
    assert (runs.folder / "report.html").read_bytes() == (runs.folder / "again.html").read_bytes()


# --------------------------------------------------------------------------------------------
# The infeasible shot: the violation on the right axis and frames
# --------------------------------------------------------------------------------------------


def test_check_report_names_every_violation_with_axis_and_frames(runs: Runs) -> None:
    proc = runs.procs["whip"]
    assert proc.returncode == 3
    expected = json.loads(proc.stdout)["violations"]
    assert any(v["axis"] == "pan" and v["quantity"] == "acceleration" for v in expected)
    page = runs.html("whip")
    assert "NOT POSSIBLE" in page
    items = re.findall(r"<li class='violation' data-axis='(\w+)' data-quantity='(\w+)' "
                       r"data-frames='([^']+)'>(.*?)</li>", page)
    assert sorted((a, q, f) for a, q, f, _ in items) == sorted(
        (v["axis"], v["quantity"], v["frames"]) for v in expected)
    for a, _q, f, text in items:
        assert a in text and f.removeprefix("frames ") in text


def test_check_report_highlights_the_violating_frames(runs: Runs) -> None:
    """In each axis's SVG: a red span per violation run sits exactly over its frames' ticks,
    and every drawn point beyond the limit lines lies inside the spans of that quantity."""
    expected = json.loads(runs.procs["whip"].stdout)["violations"]
    frames = usd_camera(WHIP).frames
    page = runs.html("whip")
    checked = 0
    for axis in JOINT_NAMES:
        root = axis_svg(page, axis)
        ticks = subpaths(by_id(root, f"{axis}-frames"))
        tick_x = np.array([p[0, 0] for p in ticks])
        assert tick_x.size == frames.size  # one tick per film frame, in frame order
        upper = subpaths(by_id(root, f"{axis}-limit-upper"))[0][0, 1]
        lower = subpaths(by_id(root, f"{axis}-limit-lower"))[0][0, 1]
        ids = {el.get("id") for el in root.iter()}
        mine = [v for v in expected if v["axis"] == axis]
        if not mine:
            assert not any("violation" in (i or "") for i in ids), axis
        for quantity in rp.QUANTITIES:
            runs_q = [v for v in mine if v["quantity"] == quantity]
            spans = []
            for v in runs_q:
                for part in v["frames"].removeprefix("frames ").split(", "):
                    a, _, b = part.partition("-")
                    fa, fb = int(a), int(b or a)
                    span = subpaths(by_id(root, f"{axis}-{quantity}-violation-{fa}-{fb}"))[0]
                    x0, x1 = span[:, 0].min(), span[:, 0].max()
                    ia, ib = np.searchsorted(frames, [fa, fb])
                    assert x0 == pytest.approx(tick_x[ia], abs=0.05)
                    assert x1 == pytest.approx(tick_x[ib], abs=0.05)
                    spans.append((x0, x1))
                    checked += 1
            curve = np.concatenate(subpaths(by_id(root, f"{axis}-{quantity}-curve")))
            beyond = curve[(curve[:, 1] < upper - 0.3) | (curve[:, 1] > lower + 0.3)]
            if not runs_q:
                assert beyond.size == 0, (axis, quantity)
                continue
            assert beyond.size > 0, (axis, quantity)
            # a drawn segment may cross the limit line up to one servo step before a frame
            slack = 0.15 * float(np.diff(tick_x).mean())
            inside = np.zeros(beyond.shape[0], dtype=bool)
            for x0, x1 in spans:
                inside |= (beyond[:, 0] >= x0 - slack) & (beyond[:, 0] <= x1 + slack)
            assert inside.all(), (axis, quantity, beyond[~inside][:5])
    assert checked >= len(expected)


def test_check_report_of_unreachable_frames_marks_them(runs: Runs) -> None:
    proc = runs.procs["unreachable"]
    assert proc.returncode == 3
    unreachable = [u["frame"] for u in json.loads(proc.stdout)["unreachable"]]
    page = runs.html("unreachable")
    assert "CANNOT BE REACHED" in page
    assert f"frames {min(unreachable)}-{max(unreachable)}" in page
    (view,) = [r for r in svgs(page) if any(e.get("id") == "view-1" for e in r.iter())]
    marks = subpaths(by_id(view, "view-1-unreachable"))
    assert sum(len(m) for m in marks) >= 1


def test_convert_of_an_infeasible_shot_writes_neither_file(runs: Runs) -> None:
    """All or nothing: convert writes the report only with the MCAP (check reports why)."""
    proc = runs.procs["convert_fails"]
    assert proc.returncode == 3
    error_line(proc)
    assert not (runs.folder / "whip.mcap").exists()
    assert not (runs.folder / "whip_convert.html").exists()
    assert "report from check" in runs.html("whip")


def test_reports_refuse_bad_input_with_exit_2(runs: Runs) -> None:
    for key in ("not_mcap", "no_folder", "report_no_folder"):  # (missing folders are made)
        proc = runs.procs[key]
        assert proc.returncode == 2, (key, proc.stderr)
        error_line(proc)
    assert "a_file is a file, not a folder" in error_line(runs.procs["no_folder"])
    assert not (runs.folder / "bad.html").exists()


# --------------------------------------------------------------------------------------------
# Rendered for real: headless Chromium
# --------------------------------------------------------------------------------------------


def shading_bands(pixels: NDArray[np.float32], *, red: bool = False) -> int:
    """Horizontal bands of the page holding the plots' shot shading (#e6eef8), or (``red``)
    that shading or a violation's red shading over it (a violation may cover a whole plot)."""
    shade = np.array([0xE6, 0xEE, 0xF8]) / 255.0
    near = np.all(np.abs(pixels - shade) < 4 / 255.0, axis=2)
    if red:  # the violation span (#d62728 at alpha 0.15) over the shading
        over = 0.15 * np.array([0xD6, 0x27, 0x28]) / 255.0 + 0.85 * shade
        near |= np.all(np.abs(pixels - over) < 4 / 255.0, axis=2)
    rows = np.flatnonzero(near.sum(axis=1) > 300)
    if rows.size == 0:
        return 0
    return int(1 + np.count_nonzero(np.diff(rows) > 40))  # grid lines cut a band, not 40 px


def test_chromium_renders_the_report(runs: Runs) -> None:
    pixels = screenshot(runs.folder / "report.html", runs.folder / "report.png")
    assert pixels.shape[:2] == (WINDOW[1], WINDOW[0])
    non_white = np.any(pixels < 0.94, axis=2)
    assert non_white.mean() > 0.08, "the page looks blank"
    assert pixels.std() > 0.05
    assert shading_bands(pixels) == len(JOINT_NAMES)  # every axis plot drawn
    # the curves: pixels of the velocity and acceleration colours (a curve near zero is
    # partly hidden under the others, so a few hundred pixels, not whole plot widths)
    for colour in ("#1f5fa8", "#e08a00"):
        rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
        assert np.count_nonzero(np.all(np.abs(pixels - rgb) < 0.12, axis=2)) > 500, colour


def test_chromium_shows_the_violation_in_red(runs: Runs) -> None:
    pixels = screenshot(runs.folder / "whip.html", runs.folder / "whip.png")
    red = (pixels[..., 0] > 0.75) & (pixels[..., 1] < 0.35) & (pixels[..., 2] < 0.35)
    assert np.count_nonzero(red) > 3000
    assert shading_bands(pixels, red=True) == len(JOINT_NAMES)


# --------------------------------------------------------------------------------------------
# Small pieces
# --------------------------------------------------------------------------------------------


def test_a_one_minute_take_renders_under_1_5_mb(runs: Runs) -> None:
    """15 000 servo samples (a minute at 250 Hz) of a busy move: the envelope keeps it small."""
    base = rp.report_from_mcap(runs.folder / "maya.mcap")
    t = np.linspace(0.0, 60.0, 15000)
    wiggle = np.sin(t[:, None] * np.arange(1, 9)[None, :] * 3.1)
    frame_times = np.arange(1440) / 24.0 + 0.5
    samples = rp.reduce_samples(
        in_blocks(t, 0.5 * (base.lower + base.upper) + 0.4 * wiggle * (base.upper - base.lower),
                  0.9 * wiggle * base.velocity, 0.9 * wiggle * base.acceleration,
                  0.9 * np.cos(t[:, None] * 7.0) * base.jerk),
        count=t.size, start=0.0, end=60.0, frame_times=frame_times,
        shot=(0.5, 0.5 + 1439 / 24.0), lower=base.lower, upper=base.upper,
        limits=(base.velocity, base.acceleration, base.jerk))
    long = dataclasses.replace(
        base, samples=samples, frame_numbers=np.arange(1, 1441), frame_times=frame_times,
        shot_start=0.5, shot_end=0.5 + 1439 / 24.0, violations=())
    page = rp.render_html(long)
    assert len(page.encode()) < 1.5e6
    assert len(svgs(page)) == 1 + len(JOINT_NAMES)


def test_report_does_not_slow_the_start_of_convert() -> None:
    """matplotlib is imported only when a report is asked for."""
    code = ("import sys, camtraj.cli, camtraj.convert, camtraj.report; "
            "print('matplotlib' in sys.modules)")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, check=True, timeout=120)
    assert out.stdout.strip() == "False"


def test_the_report_replaces_a_file_atomically_and_refuses_its_source(
    tmp_path: Path, runs: Runs
) -> None:
    mcap = runs.folder / "maya.mcap"
    (tmp_path / "plain").write_text("a file")
    with pytest.raises(InputError, match="is a file, not a folder"):
        rp.report_mcap(mcap, tmp_path / "plain" / "r.html")
    good = tmp_path / "r.html"
    rp.report_mcap(mcap, good)
    first = good.read_bytes()
    rp.report_mcap(mcap, good)
    assert good.read_bytes() == first and leftovers(tmp_path) == []
    copy = tmp_path / "copy.mcap"
    shutil.copyfile(mcap, copy)
    with pytest.raises(InputError, match="it is the MCAP the report is made from"):
        rp.report_mcap(copy, copy)
    assert copy.read_bytes() == mcap.read_bytes()


def test_cli_help_lists_the_report(runs: Runs) -> None:
    for args in (["report", "--help"], ["convert", "--help"], ["check", "--help"]):
        proc = run_cli(*args)
        assert proc.returncode == 0 and "REPORT.html" in proc.stdout


# --------------------------------------------------------------------------------------------
# What the crew reads (issue 15, §2): labels apart, per-span peaks, margins, the track, rounding
# --------------------------------------------------------------------------------------------

_BOXES_SCRIPT = """<script>
const out = [];
document.querySelectorAll('svg').forEach((svg, i) => {
  const s = svg.getBoundingClientRect();
  svg.querySelectorAll('text').forEach(t => {
    const r = t.getBoundingClientRect();
    if (t.textContent.trim()) out.push({svg: i, text: t.textContent, box: [r.left, r.top,
      r.right, r.bottom], frame: [s.left, s.top, s.right, s.bottom]});
  });
});
const pre = document.createElement('pre'); pre.id = 'boxes';
pre.textContent = JSON.stringify(out); document.body.appendChild(pre);
</script>"""


def text_boxes(page: str, folder: Path) -> list[dict[str, object]]:
    """The browser's bounding box of every SVG text of ``page`` (a copy with a script that
    measures them; the page itself has none), from headless Chromium's DOM."""
    exe = chromium()
    if exe is None:
        pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium, "
                    "or `make chromium`)")
    copy = folder / "measured.html"
    copy.write_text(page.replace("</body>", _BOXES_SCRIPT + "</body>"), encoding="utf-8")
    with tempfile.TemporaryDirectory(prefix="camtraj-chromium-") as profile:
        proc = subprocess.run(
            [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             f"--user-data-dir={profile}", f"--window-size={WINDOW[0]},{WINDOW[1]}",
             "--dump-dom", copy.resolve().as_uri()],
            capture_output=True, text=True, timeout=300, check=False)
    found = re.search(r'<pre id="boxes">(.*?)</pre>', proc.stdout, re.DOTALL)
    assert found, f"chromium measured nothing:\n{proc.stderr[-2000:]}"
    import html

    boxes: list[dict[str, object]] = json.loads(html.unescape(found.group(1)))
    return boxes


@pytest.mark.parametrize("name", ["convert", "whip", "unreachable"])
def test_no_svg_text_overlaps_another_or_is_cut_off(runs: Runs, name: str) -> None:
    boxes = text_boxes(runs.html(name), runs.folder)
    assert len(boxes) > 40
    tol = 0.5  # px
    for i, a in enumerate(boxes):
        ax0, ay0, ax1, ay1 = a["box"]  # type: ignore[misc]
        fx0, fy0, fx1, fy1 = a["frame"]  # type: ignore[misc]
        assert fx0 - tol <= ax0 and ax1 <= fx1 + tol and fy0 - tol <= ay0 and ay1 <= fy1 + tol, a
        for b in boxes[i + 1:]:
            if b["svg"] != a["svg"]:
                continue
            bx0, by0, bx1, by1 = b["box"]  # type: ignore[misc]
            overlap = min(ax1, bx1) - max(ax0, bx0) > tol and min(ay1, by1) - max(ay0, by0) > tol
            assert not overlap, (a["text"], b["text"])


def test_each_violation_span_is_labelled_with_its_own_peak(runs: Runs) -> None:
    """A violation over several runs of frames: each label gives the peak of its own run (the
    largest of them the whole violation's peak), never more: the dolly sample on a robot 15
    times slower, whose violations come in several runs of frames."""
    page = runs.html("slow")
    whole = {(v["axis"], v["quantity"]): v["ratio"]
             for v in json.loads(runs.procs["slow"].stdout)["violations"]}
    label = re.compile(rf"(\w+) ([\d.]+){rp.plots.TIMES} limit, frames? (\d+)(?:-(\d+))?")
    several = 0
    for root in svgs(page):
        axes = [el.get("id", "") for el in root.iter() if el.get("id", "").endswith("-axes")]
        if not axes:
            continue
        axis = axes[0].removesuffix("-axes")
        texts = ["".join(t.itertext()) for t in root.iter(f"{SVG_NS}text")]
        peaks: dict[str, list[float]] = {}
        for quantity, ratio, _a, _b in (m.groups() for t in texts if (m := label.search(t))):
            peaks.setdefault(quantity, []).append(float(ratio))
        for quantity, found in peaks.items():
            peak = whole[(axis, quantity)]
            assert max(found) == pytest.approx(peak, rel=5e-3), (axis, quantity, found)
            assert all(r <= peak * 1.005 for r in found)
            if len(found) > 1 and min(found) < 0.8 * peak:
                several += 1
    assert several >= 1  # a violation whose runs peak differently


def test_feasible_report_gives_the_terminal_margins(runs: Runs) -> None:
    summary = json.loads((runs.folder / "maya.json").read_text())
    m = summary["margins"]
    for name in ("convert", "report"):  # in memory and from the MCAP
        page = runs.html(name)
        rows = dict(re.findall(r"<tr><td>(\w+)</td><td class='num'>([^<]+)</td>"
                               r"<td class='num'>\d+</td></tr>", page))
        assert set(rows) == set(JOINT_NAMES)
        for axis in JOINT_NAMES:
            unit = "deg" if axis not in ("track", "extend") else "m"
            assert rows[axis] == f"{m['to_limits'][axis]:.3f} {unit}"
        frames = re.findall(r"<tr><td>(\w+)</td><td class='num'>[^<]+</td>"
                            r"<td class='num'>(\d+)</td></tr>", page)
        assert {a: int(f) for a, f in frames} == m["to_limits_frame"]
        assert (f"wrist singularity {m['wrist_singularity_deg']:.1f} deg (frame "
                f"{m['wrist_singularity_frame']})") in page
        assert f"full stretch {m['full_stretch_deg']:.1f} deg" in page


def test_the_track_bar_spans_the_track_limits(robot: Robot) -> None:
    """The bar's ends are where the carriage stands at the track's limits, less the carriage's
    constant offset from the track value (FK at both limits)."""
    q = np.radians([0.0, 30.0, 10.0, 0.0, -40.0, 10.0, 5.0, 0.0])
    q[0], q[3] = 3.0, 0.5
    ends = rp.data.track_ends(robot.link_frames(q[None])[0], float(robot.lower[0]),
                              float(robot.upper[0]))
    offset = robot.link_frames(np.zeros((1, 8)))[0, 1, :3, 3]  # carriage at track value 0
    for k, limit in enumerate((robot.lower[0], robot.upper[0])):
        at = q.copy()
        at[0] = limit
        carriage = robot.link_frames(at[None])[0, 1, :3, 3]
        np.testing.assert_allclose(ends[k] + offset, carriage, atol=1e-12)
    np.testing.assert_allclose(ends[:, 0], [robot.lower[0], robot.upper[0]], atol=1e-12)


def test_report_and_terminal_print_the_same_numbers(tmp_path: Path) -> None:
    """check's table and the report of the same run: limit use, take, run-up and run-out."""
    html = tmp_path / "r.html"
    proc = run_cli("check", SHOTS / "blender_crane_up.usda", "--timing", "scale",
                   "--report", html)
    assert proc.returncode == 0, proc.stderr
    page = html.read_text(encoding="utf-8")
    out = proc.stdout
    table = {ln.split()[0]: ln.split()[1:7] for ln in out.splitlines()
             if ln.split() and ln.split()[0] in JOINT_NAMES}
    cells = re.findall(r"<td><a href='#axis-(\w+)'>\w+</a></td>((?:<td class='num[^']*'>"
                       r"[^<]+</td>){6})", page)
    assert len(cells) == 8
    for axis, row in cells:
        assert re.findall(r">([^<]+)<", row) == table[axis], axis
    take = re.search(r"take (\S+) s \(shot (\S+)-(\S+) s\)", out)
    assert take and f"{take[1]} s; shot {take[2]}-{take[3]} s" in page
    ends = re.search(r"run-up (\S+) s, run-out (\S+) s", out)
    assert ends and f"{ends[1]} s / {ends[2]} s" in page
    speed = re.search(r"maximum feasible speed (\d+%) of real time", out)
    assert speed and f"{speed[1]} of real time" in page


def test_durations_and_use_round_one_way() -> None:
    from camtraj.shown import percent, seconds

    assert seconds(0.0449999999) == seconds(0.0450000001) == "0.05"
    assert seconds(0.04) == "0.04" and seconds(5.165) == "5.17"
    assert percent(0.995) == "100%" and percent(0.994) == "99%" and percent(math.nan) == "-"


def test_a_speed_below_one_percent_is_not_shown_as_zero() -> None:
    """Rounded down (never more than the robot can do), whole percent from 1% up, and two
    significant digits below (a new user read "0% of real time (could be shot at 0.07 fps)")."""
    from camtraj.shown import speed_percent

    assert speed_percent(2.069) == "206%" and speed_percent(0.0999) == "9%"
    assert speed_percent(0.0029) == "0.29%" and speed_percent(0.0023999) == "0.23%"
    assert speed_percent(0.000123) == "0.012%" and speed_percent(0.0) == "0%"


def test_a_speed_above_a_hundred_times_real_time_shows_as_a_bound() -> None:
    """One rule for every output (terminal, report, batch's and place's tables): above 100x
    real time, '>10000%' (the report had printed 15000% where the terminal said >10000%)."""
    from camtraj.shown import speed_percent, speed_text

    assert speed_percent(100.0) == "10000%" and speed_percent(150.0) == ">10000%"
    assert speed_text(150.0, 24.0) == ">10000% of real time (could be shot at more than 2400 fps)"
    assert speed_text(2.069, 24.0, 49.66) == "206% of real time (could be shot at 49.66 fps)"
    assert speed_text(math.inf, 24.0).startswith("unbounded")


def _ends_cells(page: str) -> dict[str, list[str]]:
    rows = re.findall(r"<td><a href='#axis-(\w+)'>\w+</a></td>(.*?)</tr>", page)
    return {axis: re.findall(r"<td class='num ends'>([^<]+)</td>", row) for axis, row in rows}


def test_report_shows_the_run_up_and_run_out_use_the_terminal_prints(tmp_path: Path) -> None:
    """Issue 15 §1: the run-up's and run-out's peak acceleration and jerk use, apart from the
    shot's, in convert's table, convert --report's page and camtraj report's page of the file
    (recorded in its metadata), the same text in all three."""
    mcap, html, again = tmp_path / "d.mcap", tmp_path / "convert.html", tmp_path / "file.html"
    # gentle ends: the push-in settles at both ends, so with still ones it has no run-up
    proc = run_cli("convert", MAYA, "-o", mcap, "--report", html, "--edges", "gentle")
    assert proc.returncode == 0, proc.stderr
    assert run_cli("report", mcap, "-o", again).returncode == 0
    header = next(ln for ln in proc.stdout.splitlines() if "ends: accel" in ln)
    assert header.split()[5:8] == ["ends:", "accel", "jerk"]
    terminal = {ln.split()[0]: ln.split()[5:7] for ln in proc.stdout.splitlines()
                if ln.split() and ln.split()[0] in JOINT_NAMES}
    assert set(terminal) == set(JOINT_NAMES)
    assert any(v != "0%" for row in terminal.values() for v in row)  # something to compare
    # and how far they move the camera around the first and last frame (gentle ends on a
    # camera at rest there: the robot's axes already move, so it does move)
    moves = re.search(r"the camera moves .* after the last", proc.stdout)
    assert moves and "0.0 mm before" not in moves[0]
    for page in (html.read_text(encoding="utf-8"), again.read_text(encoding="utf-8")):
        assert "<th>run-up/run-out acceleration</th><th>run-up/run-out jerk</th>" in page
        assert _ends_cells(page) == terminal
        assert moves[0] in page
