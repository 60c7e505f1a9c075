"""Zoom, focus and iris driven from the previs lens (issue 16 §2-4).

A dolly zoom (the camera backs away from a subject while the lens zooms in, 24 -> 57.6 mm, and
focus pulls with the subject distance) is converted with the shipped cine zoom. The MCAP is
decoded with the mcap-ros2 reader; the lens motors' positions at every film frame, mapped back
through the calibration, are the shot's focal length and focus distance as USD itself reads
them (pxr, not camtraj's reader). A zoom motor half as fast as the move needs fails at shot
timing naming ``zoom``; ``--timing scale`` then fits every servo sample inside the motor's
limits (checked by divided differences of the stream, the mean value theorem's bound).
"""

from __future__ import annotations

import html
import json
import math
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pxr import Usd, UsdGeom

from camtraj.convert import analyse, convert, take_data
from camtraj.lens import Lens
from camtraj.options import ConvertOptions
from camtraj.robot import JOINT_NAMES
from camtraj.ros2 import IMAGE_WIDTH
from tests.shot_set import make_samples
from tests.test_convert import ROOT, SHOTS, error_line, run_cli

LENSES = ROOT / "camtraj" / "data" / "lenses"
ZOOM = LENSES / "cine_zoom_24-290.toml"
PRIME = LENSES / "prime_50.toml"
ZOOM_TEXT = ZOOM.read_text(encoding="utf-8")
SUBJECT = np.array([9.0, 0.0, 1.5])
FIRST = 1001


def _dolly_zoom(folder: Path) -> Path:
    """A 4 s dolly zoom at 24 fps on a Z-up metre stage: the camera backs away from the
    subject (x 6.5 -> 3.0 m, eased) while the focal length grows with the distance
    (24 -> 57.6 mm, the subject's size held) and focus follows the subject; f/2.8 held."""
    ms = make_samples()
    frames = np.arange(FIRST, FIRST + 97, dtype=np.float64)
    s = ms.ease(np.linspace(0.0, 1.0, frames.size))
    pos = np.stack([6.5 - 3.5 * s, np.zeros_like(s), np.full_like(s, 1.4)], axis=1)
    pan, tilt = ms.look_at(pos, SUBJECT)
    dist = np.linalg.norm(SUBJECT - pos, axis=1)
    focal = 24.0 + (57.6 - 24.0) * (dist - dist[0]) / (dist[-1] - dist[0])
    move = ms.Move(frames, pos, pan, tilt, focal_mm=focal, focus_m=dist, f_stop=2.8)
    text = (ms._header("camtraj test: dolly zoom", "Z", 1.0, frames, 24.0, "cam") + "\n"
            + ms._camera_prim_trs("cam", move, "Z", 1.0, "") + "\n")
    path = folder / "dolly_zoom.usda"
    path.write_text(text, encoding="utf-8")
    return path


def _usd_lens(path: Path) -> dict[str, np.ndarray]:
    """Focal length [mm] and focus distance [m] per frame, as USD reads them."""
    stage = Usd.Stage.Open(str(path))
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/cam"))
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    codes = range(int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode()) + 1)
    return {
        "frames": np.array(list(codes)),
        "focal_mm": np.array([cam.GetFocalLengthAttr().Get(t) for t in codes]) * mpu * 100.0,
        "focus_m": np.array([cam.GetFocusDistanceAttr().Get(t) for t in codes]) * mpu,
        "f_stop": np.array([cam.GetFStopAttr().Get(t) for t in codes]),
        "aperture_mm": np.array([cam.GetHorizontalApertureAttr().Get(t) for t in codes])
        * mpu * 100.0,
    }


def _decode(path: Path) -> dict[str, Any]:
    """/joint_states (names, log times [ns], positions, velocities), /shot/frames,
    /camera/camera_info and the metadata, read with the mcap-ros2 decoder."""
    out: dict[str, Any] = {"ns": [], "q": [], "qd": [], "frame_ns": [], "frames": [],
                           "frame_names": None, "k": []}
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        topics = ["/joint_states", "/shot/frames", "/camera/camera_info"]
        for _schema, channel, message, msg in reader.iter_decoded_messages(topics=topics):
            if channel.topic == "/joint_states":
                out["names"] = list(msg.name)
                out["ns"].append(message.log_time)
                out["q"].append(list(msg.position))
                out["qd"].append(list(msg.velocity))
            elif channel.topic == "/shot/frames":
                out["frame_ns"].append(message.log_time)
                out["frames"].append(int(msg.frame))
                out["frame_names"] = list(msg.name)
            else:
                out["k"].append(list(msg.k))
        stream.seek(0)
        out["metadata"] = {rec.name: dict(rec.metadata) for rec in
                           make_reader(stream).iter_metadata()}
    for key in ("ns", "q", "qd", "frame_ns", "k"):
        out[key] = np.array(out[key])
    return out


@pytest.fixture(scope="module")
def dolly(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    folder = tmp_path_factory.mktemp("dolly")
    shot = _dolly_zoom(folder)
    out = folder / "lens.mcap"
    rig = folder / "lens.rig.usda"
    summary = convert(shot, out, ConvertOptions(lens=str(ZOOM)), rig_layer=rig)
    return {"folder": folder, "shot": shot, "mcap": out, "rig": rig, "summary": summary,
            "usd": _usd_lens(shot), "decoded": _decode(out)}


def _at_frames(d: dict[str, Any]) -> np.ndarray:
    """Rows of /joint_states at the film frames (log times equal to /shot/frames')."""
    idx = np.searchsorted(d["ns"], d["frame_ns"])
    assert np.array_equal(d["ns"][idx], d["frame_ns"])
    rows: np.ndarray = d["q"][idx]
    return rows


def test_dolly_zoom_focal_length_round_trips_at_every_frame(dolly: dict[str, Any]) -> None:
    d, usd = dolly["decoded"], dolly["usd"]
    assert d["names"] == [*JOINT_NAMES, "zoom", "focus", "iris"]
    assert d["frame_names"] == list(JOINT_NAMES)  # /shot/frames: the IK solution, as before
    assert d["frames"] == usd["frames"].tolist()
    lens = Lens.from_toml(ZOOM)
    zoom = lens.axis("zoom")
    assert zoom is not None
    q = _at_frames(d)
    focal = zoom.calibration.value(q[:, 8])
    assert usd["focal_mm"][0] == pytest.approx(24.0) and usd["focal_mm"][-1] == pytest.approx(
        57.6, rel=1e-6)
    assert np.abs(focal - usd["focal_mm"]).max() < 1e-9
    # the positions are the calibration's: an independent bracketed root of position(x) = q
    from scipy.optimize import brentq

    for k in (0, 30, 60, 96):
        x = brentq(lambda f, k=k: float(zoom.calibration.position(f)) - q[k, 8], 23.9, 290.0,
                   xtol=1e-13, rtol=1e-15)
        assert x == pytest.approx(usd["focal_mm"][k], abs=1e-9)
    # CameraInfo follows the commanded focal length: fx = f / aperture width * image width
    fx = d["k"][:, 0]
    assert np.abs(fx / IMAGE_WIDTH * usd["aperture_mm"] - usd["focal_mm"]).max() < 1e-9


def test_focus_pull_round_trips_to_usd_focus_distance(dolly: dict[str, Any]) -> None:
    d, usd = dolly["decoded"], dolly["usd"]
    lens = Lens.from_toml(ZOOM)
    focus, iris = lens.axis("focus"), lens.axis("iris")
    assert focus is not None and iris is not None
    q = _at_frames(d)
    back = focus.calibration.value(q[:, 9])
    assert np.abs(back - usd["focus_m"]).max() < 1e-9 * usd["focus_m"].max()
    assert np.ptp(usd["focus_m"]) > 3.0  # a real pull
    # f/2.8 is held: the iris motor stands at the table's T2.8 the whole take
    assert np.ptp(usd["f_stop"]) == 0.0 and usd["f_stop"][0] == pytest.approx(2.8)
    assert np.all(d["q"][:, 10] == d["q"][0, 10])
    assert d["q"][0, 10] == pytest.approx(float(iris.calibration.position(usd["f_stop"][0])),
                                          abs=1e-15)
    assert abs(d["q"][0, 10]) < 1e-7  # T2.8 is the table's first row, at 0 deg
    # the rig layer's camera carries the commanded lens (USD keeps 32-bit floats)
    stage = Usd.Stage.Open(str(dolly["rig"]))
    cams = [p for p in stage.Traverse() if p.GetName() == "camtraj_camera"]
    assert len(cams) == 1
    cam = UsdGeom.Camera(cams[0])
    for k, code in enumerate(usd["frames"].tolist()):
        assert cam.GetFocalLengthAttr().Get(code) / 10.0 * 1000.0 == pytest.approx(
            usd["focal_mm"][k], rel=1e-6)
        assert cam.GetFocusDistanceAttr().Get(code) == pytest.approx(usd["focus_m"][k],
                                                                     rel=1e-6)


def test_metadata_and_summary_name_the_lens_axes(dolly: dict[str, Any]) -> None:
    md = dolly["decoded"]["metadata"]
    lens = json.loads(md["camtraj"]["lens"])
    assert list(lens["axes"]) == ["zoom", "focus", "iris"]
    assert lens["axes"]["zoom"]["quantity_unit"] == "mm"
    assert lens["axes"]["zoom"]["position_unit"].startswith("rad")
    # the focus is calibrated to infinity: null, as every JSON non-finite value (it was "inf")
    assert lens["axes"]["focus"]["range"] == [0.6, None]
    assert "lens" in md["camtraj.robot"]
    assert set(json.loads(md["camtraj"]["peak_use"])) == {*JOINT_NAMES, "zoom", "focus", "iris"}
    summary = dolly["summary"]
    assert {"zoom", "focus", "iris"} <= set(summary["peak_use"])
    assert summary["runup"]["extent"]["zoom"] >= 0.0
    info = run_cli("info", dolly["mcap"])
    assert info.returncode == 0, info.stderr
    assert re.search(r"^  zoom\s+\d+%", info.stdout, re.M)
    assert "lens Cine zoom 24-290 mm T2.8" in info.stdout
    assert re.search(r"^  focus .* focus distance 0.6 m to infinity$", info.stdout, re.M)
    assert re.search(r"^  iris .* stop T2.8 to T22$", info.stdout, re.M)
    assert summary["lens"]["axes"]["focus"]["range"] == [0.6, None]
    # the lens file's [controller.zoom] (65536 counts a turn): the counts the take commands,
    # from the zoom motor's column of /joint_states as mcap_ros2 decodes it
    zoom = dolly["decoded"]["q"][:, dolly["decoded"]["names"].index("zoom")]
    counts = json.loads(md["camtraj"]["controller"])
    assert list(counts) == ["zoom"]
    assert counts["zoom"]["counts_range"] == pytest.approx(
        [10430.378 * zoom.min(), 10430.378 * zoom.max()], rel=1e-12)
    assert re.search(r"^  zoom     0 \+ 10430.4 x q   \[-?\d+, \d+\]$", info.stdout, re.M)


def test_the_lens_motors_have_position_margins_like_the_joints(
        dolly: dict[str, Any]) -> None:
    """The summary's (and the file's) nearest approach to a position limit covers the lens
    motors: the decoded motor positions' smallest distance to the lens file's limits, at the
    frame where it occurs (24 mm sits near the zoom's end stop)."""
    lens = Lens.from_toml(ZOOM)
    lim = lens.limits()
    d = dolly["decoded"]
    q = _at_frames(d)[:, 8:]
    room = np.minimum(q - lim.lower, lim.upper - q)
    for key in ("summary", "file"):
        margins = (dolly["summary"]["margins"] if key == "summary"
                   else json.loads(d["metadata"]["camtraj"]["margins"]))
        for j, name in enumerate(lens.names):
            k = int(np.argmin(room[:, j]))
            assert margins["to_limits"][name] == pytest.approx(math.degrees(room[k, j]),
                                                               abs=1e-9), (key, name)
            assert margins["to_limits_frame"][name] == d["frames"][k], (key, name)
    assert margins["to_limits"]["zoom"] < 5.0  # degrees of ring travel left at 24 mm


def _lens_file(folder: Path, name: str, old: str, new: str) -> Path:
    assert old in ZOOM_TEXT
    path = folder / name
    path.write_text(ZOOM_TEXT.replace(old, new, 1), encoding="utf-8")
    return path


def test_a_zoom_too_fast_fails_and_scale_fits_the_motor(dolly: dict[str, Any]) -> None:
    d, folder = dolly["decoded"], dolly["folder"]
    peak = float(np.abs(d["qd"][:, 8]).max())  # rad/s the zoom motor needs at shot timing
    assert 0.0 < peak < math.radians(60.0)
    slow_deg = math.degrees(peak) / 2.0
    slow = _lens_file(folder, "slow_zoom.toml", "max_velocity = 60.0",
                      f"max_velocity = {slow_deg!r}")
    proc = run_cli("check", dolly["shot"], "--lens", slow)
    assert proc.returncode == 3, proc.stderr
    report = proc.stdout  # check reports a shot it cannot do on stdout
    assert "NOT POSSIBLE with --timing shot" in report, report
    m = re.search(r"zoom velocity ([0-9.]+) deg/s exceeds ([0-9.]+) deg/s on frames \d+-\d+",
                  report)
    assert m is not None, report
    assert float(m.group(1)) / float(m.group(2)) == pytest.approx(2.0, rel=2e-2)
    # the zoom's velocity, halved, is what sets the speed: the line says so
    assert re.search(r"maximum feasible speed (49|50)% of real time \(could be shot at "
                     r"[0-9.]+ fps\), set by zoom velocity; try --timing scale", report), report
    checked = json.loads(run_cli("check", dolly["shot"], "--lens", slow, "--json").stdout)
    assert checked["max_speed_set_by"] == "zoom velocity", checked
    assert "--timing scale" in report
    out = folder / "scaled.mcap"
    proc = run_cli("convert", dolly["shot"], "-o", out, "--lens", slow, "--timing", "scale",
                   "-q")
    assert proc.returncode == 0, proc.stderr
    s = _decode(out)
    t = s["ns"] * 1e-9
    z = s["q"][:, 8]
    axis = Lens.from_toml(slow).axis("zoom")
    assert axis is not None
    assert z.min() >= axis.lower - 1e-12 and z.max() <= axis.upper + 1e-12
    # k-th divided difference * k! = the k-th derivative somewhere between the samples
    slack = 1e-6
    v = np.diff(z) / np.diff(t)
    assert np.abs(v).max() <= axis.velocity * (1 + slack)
    assert np.abs(v).max() >= 0.9 * axis.velocity  # slowed just enough, not more
    a = 2.0 * np.diff(v) / (t[2:] - t[:-2])
    assert np.abs(a).max() <= axis.acceleration * (1 + slack) + 1e-6
    j = 3.0 * np.diff(a) / (t[3:] - t[:-3])
    assert np.abs(j).max() <= axis.jerk * (1 + 1e-3) + 1e-3
    # the focal length still round-trips at every frame, slowed
    lens = _at_frames(s)[:, 8]
    assert np.abs(axis.calibration.value(lens) - dolly["usd"]["focal_mm"]).max() < 1e-9


def test_a_focal_length_beyond_the_lens_is_an_error_at_that_frame(
        dolly: dict[str, Any]) -> None:
    short = _lens_file(dolly["folder"], "short_zoom.toml",
                       "[70.0, 52.0],\n    [100.0, 68.5], [135.0, 82.0], [180.0, 95.5], "
                       "[240.0, 109.0], [290.0, 120.0],", "")
    assert Lens.from_toml(short).axis("zoom").calibration.high == 50.0  # type: ignore[union-attr]
    usd = dolly["usd"]
    beyond = usd["frames"][usd["focal_mm"] > 50.0 * (1 + 1e-6)]
    first, last = int(beyond[0]), int(beyond[-1])
    assert np.array_equal(beyond, np.arange(first, last + 1))  # one stretch, the dolly's end
    # check reports it as it reports any shot it cannot do: on stdout, in the HTML report,
    # and as JSON
    page = dolly["folder"] / "short.html"
    proc = run_cli("check", dolly["shot"], "--lens", short, "--report", page)
    assert proc.returncode == 3, proc.stderr
    head, line = proc.stdout.splitlines()
    assert head == f"{dolly['shot']}: OUTSIDE THE LENS'S RANGE", proc.stdout
    assert (f"at frame {first} (outside on frames {first}-{last}) is beyond the lens's 50 mm"
            in line), line
    assert re.search(r"focal length 5\d\.\d+ mm at frame", line), line
    text = html.unescape(page.read_text(encoding="utf-8"))
    assert f"OUTSIDE THE LENS'S RANGE: {line.strip()}" in text
    assert "CANNOT BE REACHED" not in text
    proc = run_cli("check", dolly["shot"], "--lens", short, "--json")
    assert proc.returncode == 3, proc.stderr
    assert json.loads(proc.stdout) == {"status": "lens_range", "shot": str(dolly["shot"]),
                                       "message": line.strip(), "warnings": []}
    proc = run_cli("convert", dolly["shot"], "-o", dolly["folder"] / "short.mcap", "--lens",
                   short)
    assert proc.returncode == 3 and line.strip() in error_line(proc), proc.stderr
    assert not (dolly["folder"] / "short.mcap").exists()


def test_a_prime_warns_and_the_camera_shows_its_focal_length(dolly: dict[str, Any]) -> None:
    analysis = analyse(dolly["shot"], ConvertOptions(lens=str(PRIME)))
    data = take_data(analysis)
    assert data.camera_focal_length_mm is not None
    assert np.all(data.camera_focal_length_mm == 50.0)
    assert data.joint_names == (*JOINT_NAMES, "focus", "iris")
    result = convert(dolly["shot"], None, ConvertOptions(lens=str(PRIME)))
    assert any("not reachable with the 50 mm prime" in w for w in result["warnings"])


def test_animated_focus_and_stop_without_motors_warn(tmp_path: Path) -> None:
    text = ZOOM_TEXT.split("[focus]", 1)[0] + "[controller.zoom]" + ZOOM_TEXT.split(
        "[controller.zoom]", 1)[1]
    path = tmp_path / "zoom_only.toml"
    path.write_text(text, encoding="utf-8")
    assert Lens.from_toml(path).names == ("zoom",)
    result = convert(SHOTS / "maya_dolly_push_in.usda", None, ConvertOptions(lens=str(path)))
    warnings = " | ".join(result["warnings"])
    assert "focus distance" in warnings and "no focus calibration" in warnings
    assert "f-stop" in warnings and "no iris calibration" in warnings
    # with their units: metres of focus, f-numbers
    focus = next(w for w in result["warnings"] if "no focus calibration" in w)
    iris = next(w for w in result["warnings"] if "no iris calibration" in w)
    assert re.search(r"focus distance \([0-9.]+ m to [0-9.]+ m\)", focus), focus
    assert re.search(r"f-stop \(f/[0-9.]+ to f/[0-9.]+\)", iris), iris


def _eased_truck(path: Path, n: int, focus_m: float, f_stop: float) -> Path:
    """A shot of n frames on a Z-up metre stage: the camera trucks 1 m towards the subject,
    eased, at 35 mm with the focus distance and f-stop given (0: unset)."""
    ms = make_samples()
    frames = np.arange(FIRST, FIRST + n, dtype=np.float64)
    s = ms.ease(np.linspace(0.0, 1.0, frames.size))
    pos = np.stack([6.5 - 1.0 * s, np.zeros_like(s), np.full_like(s, 1.4)], axis=1)
    pan, tilt = ms.look_at(pos, SUBJECT)
    move = ms.Move(frames, pos, pan, tilt, focal_mm=35.0, focus_m=focus_m, f_stop=f_stop)
    path.write_text(ms._header(f"camtraj test: {path.stem}", "Z", 1.0, frames, 24.0, "cam")
                    + "\n" + ms._camera_prim_trs("cam", move, "Z", 1.0, "") + "\n",
                    encoding="utf-8")
    return path


def test_a_focus_and_stop_the_shot_leaves_unset_hold_at_home_and_say_so(tmp_path: Path) -> None:
    """A shot that authors no focus distance or f-stop (0: a pinhole camera): the motors hold
    at their homes (the lens file's first rows: 0.6 m, T2.8), and the run says so."""
    shot = _eased_truck(tmp_path / "pinhole.usda", 49, focus_m=0.0, f_stop=0.0)
    result = convert(shot, None, ConvertOptions(lens=str(ZOOM)))
    assert any(w.startswith("the shot does not set its focus distance: the focus motor holds "
                            "at its home (0.6 m") for w in result["warnings"]), result["warnings"]
    assert any(w.startswith("the shot does not set its f-stop: the iris motor holds at its "
                            "home (T2.8") for w in result["warnings"]), result["warnings"]
    analysis = analyse(shot, ConvertOptions(lens=str(ZOOM)))
    assert analysis.lens_q is not None
    assert np.all(analysis.lens_q[:, 1:] == 0.0)  # both homes: the first rows' 0 deg


def test_focus_at_infinity_reads_writes_and_drives_the_ring_to_its_infinity_mark(
        tmp_path: Path) -> None:
    """A focus distance of inf (how exporters write focus at infinity) is read as infinity,
    written to /shot/frames as inf (decoded by mcap-ros2), and with the lens the focus
    motor stands on the table's infinity row until the pull to 2 m starts."""
    ms = make_samples()
    frames = np.arange(FIRST, FIRST + 73, dtype=np.float64)
    shot = _eased_truck(tmp_path / "infinity.usda", 73, focus_m=2.0, f_stop=4.0)
    stage = Usd.Stage.Open(str(shot))
    focus_attr = UsdGeom.Camera(stage.GetPrimAtPath("/cam")).GetFocusDistanceAttr()
    focus_attr.Clear()
    with np.errstate(divide="ignore"):  # 1/m eased from 0 (infinity) to 0.5 (2 m)
        pull = 1.0 / (0.5 * ms.ease(np.linspace(0.0, 1.0, 37)))
    want = np.concatenate([np.full(36, np.inf), pull])
    for code, value in zip(frames.tolist(), want.tolist(), strict=True):
        focus_attr.Set(value, code)
    stage.GetRootLayer().Save()
    plain, with_lens = tmp_path / "plain.mcap", tmp_path / "lens.mcap"
    convert(shot, plain, ConvertOptions())
    convert(shot, with_lens, ConvertOptions(lens=str(ZOOM)))
    for out in (plain, with_lens):
        with out.open("rb") as stream:
            got = np.array([m.focus_distance_m for _s, _c, _m, m in make_reader(
                stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                    topics=["/shot/frames"])])
        assert np.all(np.isposinf(got[:37])), got[:38]
        np.testing.assert_allclose(got[37:], want[37:], rtol=1e-6)  # USD keeps 32-bit floats
    q = _at_frames(_decode(with_lens))
    infinity_mark = 300.0  # deg: the zoom's table's [inf, 300.0] row
    np.testing.assert_allclose(np.degrees(q[:37, 9]), infinity_mark, rtol=0, atol=1e-9)
    assert np.degrees(q[-1, 9]) == pytest.approx(211.0, abs=1e-4)  # the table's [2.0, 211.0]
    # a lens without focus calibration says what the shot's focus does, infinity by name
    zoom_only = tmp_path / "zoom_only.toml"
    zoom_only.write_text(ZOOM_TEXT.split("[focus]", 1)[0] + "[controller.zoom]"
                         + ZOOM_TEXT.split("[controller.zoom]", 1)[1], encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning on the infinite span
        result = convert(shot, None, ConvertOptions(lens=str(zoom_only)))
    assert any("focus distance (2 m to infinity)" in w for w in result["warnings"]), \
        result["warnings"]


def test_without_a_lens_nothing_changes(dolly: dict[str, Any]) -> None:
    """No --lens: the eight joints only, no lens metadata (byte identity with the code before
    issue 16 was checked by hand: see the branch's report)."""
    out = dolly["folder"] / "plain.mcap"
    convert(dolly["shot"], out, ConvertOptions())
    d = _decode(out)
    assert d["names"] == list(JOINT_NAMES) and d["q"].shape[1] == 8
    assert "lens" not in d["metadata"]["camtraj"]
    assert "lens" not in d["metadata"]["camtraj.robot"]
    # CameraInfo is the shot's focal length, as before
    usd = dolly["usd"]
    assert np.abs(d["k"][:, 0] / IMAGE_WIDTH * usd["aperture_mm"] - usd["focal_mm"]).max() < 1e-9


def test_the_collision_check_runs_with_a_lens(dolly: dict[str, Any]) -> None:
    """The set's obstacles are checked on the joints of a take that has lens axes too."""
    folder = dolly["folder"]
    shot = folder / "dolly_zoom_set.usda"
    shot.write_text(dolly["shot"].read_text(encoding="utf-8") + '''
def Cube "wall"
{
    double size = 1
    double3 xformOp:translate = (4.5, 3, 1)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
''', encoding="utf-8")
    set_file = folder / "set.toml"
    set_file.write_text('[collision]\nprims = ["/wall"]\nclearance_m = 0.05\n',
                        encoding="utf-8")
    result = convert(shot, None, ConvertOptions(lens=str(ZOOM), set_file=str(set_file)))
    closest = result["collision"]["closest_m"]
    assert closest is None or closest > 0.05
    assert {"zoom", "focus", "iris"} <= set(result["peak_use"])


def test_read_take_reads_a_take_with_lens_axes(dolly: dict[str, Any]) -> None:
    from camtraj.mcap_io import read_take

    take = read_take(dolly["mcap"])
    assert take.joint_names == (*JOINT_NAMES, "zoom", "focus", "iris")
    assert take.q.shape[1] == 11 and take.trajectory_q.shape[1] == 11
    assert take.frame_names == JOINT_NAMES and take.frame_q.shape[1] == 8
    assert np.abs(take.focal_length_mm - dolly["usd"]["focal_mm"]).max() < 1e-9


def test_a_motor_limit_on_a_calibration_end_takes_the_shots_float_round_off(
        dolly: dict[str, Any]) -> None:
    """USD keeps lens values as 32-bit floats: the dolly zoom's f/2.8 reads 2.7999999. With
    the iris motor's limit set on the calibration's T2.8 end (min = that row's 0, the natural
    way to write a lens file) those frames map onto the end, not a hair beyond the limit: the
    shot converts and the iris motor sits exactly on its limit. Where the limit leaves room
    (the zoom's min 2 deg below its 24 mm end), the round-off maps as it is: the 24 mm, read
    back as 23.9999995, a hair below the end's position, so the lens round-trips exactly."""
    lens = _lens_file(dolly["folder"], "iris_on_limit.toml", "min = -1.0", "min = 0.0")
    usd = dolly["usd"]
    assert usd["f_stop"].max() < 2.8 and usd["focal_mm"].min() < 24.0  # the floats' round-off
    analysis = analyse(dolly["shot"], ConvertOptions(lens=str(lens)))
    assert analysis.take is not None and analysis.lens_q is not None
    zoom, _, iris = analysis.lens_q.T
    assert np.all(iris == 0.0) and -1e-6 < zoom[0] < 0.0


def test_a_table_that_turns_the_ring_many_times_warns_of_its_angle_unit(tmp_path: Path) -> None:
    """Degrees written under angle_unit = "rad": the zoom table's 0-120 would turn the ring
    19 times. The run goes on (the file is well formed) and warns, naming the table."""
    text = ZOOM_TEXT.replace('angle_unit = "deg"', 'angle_unit = "rad"', 1)
    path = tmp_path / "rad.toml"
    path.write_text(text, encoding="utf-8")
    lens = Lens.from_toml(path)
    from camtraj.lens import lens_warnings
    from camtraj.usd_shot import read_shot

    out = lens_warnings(lens, read_shot(SHOTS / "maya_dolly_push_in.usda"))
    zoom = next(w for w in out if w.startswith("the lens file's zoom table"))
    assert "spans 6,875 deg of the ring (19.1 turns" in zoom and "angle_unit" in zoom
    assert not any("of the ring" in w for w in lens_warnings(Lens.from_toml(ZOOM),
                                                             read_shot(SHOTS /
                                                                       "maya_dolly_push_in.usda")))


def test_the_report_names_the_lens(dolly: dict[str, Any]) -> None:
    """The report of a take with a lens says which lens and which motors, from the file (it
    named the lens nowhere, where info does), and a take without one has no lens row."""
    page = dolly["folder"] / "lens_report.html"
    assert run_cli("report", dolly["mcap"], "-o", page).returncode == 0
    text = html.unescape(page.read_text(encoding="utf-8"))
    assert (f"Cine zoom 24-290 mm T2.8 (lens file {ZOOM}): zoom, focus and iris motors"
            in text)
    plain = dolly["folder"] / "plain.mcap"
    convert(dolly["shot"], plain, ConvertOptions())
    assert run_cli("report", plain, "-o", dolly["folder"] / "plain.html").returncode == 0
    assert "lens file" not in (dolly["folder"] / "plain.html").read_text(encoding="utf-8")
