"""Tests of the read stage: USD shot -> per-frame camera poses in metres, Z-up."""

from __future__ import annotations

import importlib.util
import logging
import math
import re
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from pxr import Gf, Sdf, Usd, UsdGeom

from camtraj.errors import ShotFileError
from camtraj.usd_shot import Shot, list_cameras, read_shot

Array = NDArray[np.float64]

REPO = Path(__file__).resolve().parents[1]
SHOTS = REPO / "samples" / "shots"
SAMPLE_NAMES = (
    "maya_dolly_push_in.usda",
    "blender_crane_up.usda",
    "orbit_animated_parent.usda",
    "whip_pan.usda",
    "unreachable.usda",
)
# The robot's comfortable camera reach in its base frame [m] (x along the track, z up).
REACH_MIN = np.array([3.0, -2.0, -0.5])
REACH_MAX = np.array([10.0, 2.0, 2.2])


def _load_make_samples() -> ModuleType:
    name = "camtraj_samples_make_samples"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, SHOTS / "make_samples.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up while the file runs
    spec.loader.exec_module(module)
    return module


make_samples = _load_make_samples()


# --------------------------------------------------------------------------------------------
# Hand-written geometry (column vectors), independent of the module under test


def rx(deg: float) -> Array:
    a = math.radians(deg)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def ry(deg: float) -> Array:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def rz(deg: float) -> Array:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def hom(rotation: Array, translation: Any) -> Array:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = translation
    return m


def _new_stage(
    path: Path,
    *,
    up_axis: str = "Z",
    meters_per_unit: float = 1.0,
    frames: tuple[int, int] | None = (1, 10),
    fps: float = 24.0,
) -> Any:
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetMetadata("upAxis", up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    if frames is not None:
        stage.SetStartTimeCode(frames[0])
        stage.SetEndTimeCode(frames[1])
    return stage


def _save(stage: Any) -> Path:
    stage.GetRootLayer().Save()
    return Path(stage.GetRootLayer().realPath)


def _static_camera(tmp_path: Path, name: str = "shot.usda", **kwargs: Any) -> Path:
    stage = _new_stage(tmp_path / name, **kwargs)
    cam = UsdGeom.Camera.Define(stage, "/World/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    return _save(stage)


# --------------------------------------------------------------------------------------------
# Units and frames


def test_zup_metres_pose_matches_hand_computation(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "zup.usda")
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(5.0, 1.0, 1.5))
    # rotateXYZ (90, 0, -90): a USD camera (looks down -Z) turned to look along world +x.
    cam.AddRotateXYZOp().Set(Gf.Vec3f(90.0, 0.0, -90.0))
    shot = read_shot(_save(stage))
    m = shot.cam2world[0]
    np.testing.assert_allclose(m[:3, 3], [5.0, 1.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(-m[:3, 2], [1.0, 0.0, 0.0], atol=1e-7)  # view direction
    np.testing.assert_allclose(m[:3, 1], [0.0, 0.0, 1.0], atol=1e-7)  # image up
    np.testing.assert_allclose(m[3], [0.0, 0.0, 0.0, 1.0])
    assert shot.up_axis == "Z"
    assert shot.meters_per_unit == 1.0


def test_yup_centimetres_become_zup_metres(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "yup.usda", up_axis="Y", meters_per_unit=0.01)
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(100.0, 150.0, -200.0))  # cm, Y up
    shot = read_shot(_save(stage))
    m = shot.cam2world[0]
    # Stage Y (150 cm) is height; stage -Z (200 cm) is world +Y.
    np.testing.assert_allclose(m[:3, 3], [1.0, 2.0, 1.5], atol=1e-12)
    # An unrotated Y-up camera looks down stage -Z = world +Y, with stage +Y = world +Z up.
    np.testing.assert_allclose(-m[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(m[:3, 1], [0.0, 0.0, 1.0], atol=1e-12)
    assert shot.up_axis == "Y"
    assert shot.meters_per_unit == pytest.approx(0.01)


def _physical_move(n: int) -> tuple[Array, Array]:
    """(n, 3) positions [m] and (n, 3) rotateXYZ angles [deg] of a wandering Z-up camera."""
    k = np.arange(n, dtype=np.float64)
    pos = np.stack([4.0 + 0.05 * k, 0.3 * np.sin(0.2 * k), 1.2 + 0.02 * k], axis=1)
    angles = np.stack([80.0 + 2.0 * np.sin(0.3 * k), 3.0 * np.cos(0.1 * k), -90.0 + 4.0 * k], 1)
    return pos, angles


def test_yup_cm_and_zup_m_versions_of_one_move_agree(tmp_path: Path) -> None:
    n = 10
    pos, angles = _physical_move(n)
    zup = _new_stage(tmp_path / "zup_m.usda", frames=(1, n))
    cam = UsdGeom.Camera.Define(zup, "/cam")
    translate = cam.AddTranslateOp()
    rotate = cam.AddRotateXYZOp(UsdGeom.XformOp.PrecisionDouble)
    for i in range(n):
        translate.Set(Gf.Vec3d(*pos[i]), i + 1)
        rotate.Set(Gf.Vec3d(*angles[i]), i + 1)

    # The same move authored by hand in a Y-up centimetre world, as a row-vector matrix.
    yup = _new_stage(tmp_path / "yup_cm.usda", up_axis="Y", meters_per_unit=0.01, frames=(1, n))
    cam_y = UsdGeom.Camera.Define(yup, "/cam")
    transform = cam_y.AddTransformOp()
    zup2yup = rx(-90.0)
    for i in range(n):
        a, b, c = angles[i]
        rotation = rz(c) @ ry(b) @ rx(a)  # rotateXYZ: X first, then Y, then Z
        m = hom(zup2yup @ rotation, zup2yup @ pos[i] * 100.0)
        transform.Set(Gf.Matrix4d(m.T.tolist()), i + 1)

    shot_z = read_shot(_save(zup))
    shot_y = read_shot(_save(yup))
    np.testing.assert_allclose(shot_y.cam2world, shot_z.cam2world, rtol=0, atol=1e-9)
    np.testing.assert_allclose(shot_z.cam2world[:, :3, 3], pos, atol=1e-12)
    expected = [rz(c) @ ry(b) @ rx(a) for a, b, c in angles]
    np.testing.assert_allclose(shot_z.cam2world[:, :3, :3], expected, atol=1e-12)


def test_scale_is_removed_from_the_pose(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "scaled.usda")
    rig = UsdGeom.Xform.Define(stage, "/rig")
    rig.AddTranslateOp().Set(Gf.Vec3d(2.0, 0.0, 0.0))
    rig.AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 2.0))
    cam = UsdGeom.Camera.Define(stage, "/rig/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(1.0, 0.5, 0.25))
    cam.AddRotateZOp().Set(30.0)
    cam.AddScaleOp().Set(Gf.Vec3f(1.0, 2.0, 3.0))  # non-uniform: the polar factor is Rz(30)
    shot = read_shot(_save(stage))
    m = shot.cam2world[0]
    np.testing.assert_allclose(m[:3, :3], rz(30.0), atol=1e-7)
    np.testing.assert_allclose(m[:3, 3], [4.0, 1.0, 0.5], atol=1e-12)  # parent scale moves it
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0)


def test_times_fps_and_time_code_step(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "tc48.usda", frames=(0, 10))
    stage.SetTimeCodesPerSecond(48.0)  # two time codes per 24 fps frame
    UsdGeom.Camera.Define(stage, "/cam").AddTranslateOp().Set(Gf.Vec3d(0, 0, 0))
    shot = read_shot(_save(stage))
    assert shot.fps == 24.0
    np.testing.assert_array_equal(shot.time_codes, [0, 2, 4, 6, 8, 10])
    np.testing.assert_array_equal(shot.frames, [0, 1, 2, 3, 4, 5])  # film frames = tc * 24/48
    np.testing.assert_allclose(shot.times, np.arange(6) / 24.0)


def test_fps_falls_back_to_time_codes_per_second(tmp_path: Path) -> None:
    stage = Usd.Stage.CreateNew(str(tmp_path / "tc30.usda"))
    stage.SetMetadata("upAxis", "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(30.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(31)
    UsdGeom.Camera.Define(stage, "/cam")
    shot = read_shot(_save(stage))
    assert shot.fps == 30.0
    assert shot.n_frames == 31
    assert shot.times[-1] == pytest.approx(1.0)


def test_range_from_time_samples_when_stage_has_none(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "norange.usda", frames=None)
    op = UsdGeom.Camera.Define(stage, "/cam").AddTranslateOp()
    for f in range(5, 16):
        op.Set(Gf.Vec3d(f, 0, 0), f)
    shot = read_shot(_save(stage))
    np.testing.assert_array_equal(shot.frames, np.arange(5, 16))
    np.testing.assert_allclose(shot.cam2world[:, 0, 3], np.arange(5, 16))


def test_lens_units_follow_the_usd_camera_schema(tmp_path: Path) -> None:
    # UsdGeomCamera: focalLength in tenths of a scene unit, focusDistance in scene units.
    cm = _new_stage(tmp_path / "cm.usda", meters_per_unit=0.01)
    cam = UsdGeom.Camera.Define(cm, "/cam")
    cam.GetFocalLengthAttr().Set(50.0)
    cam.GetFocusDistanceAttr().Set(300.0)
    cam.GetFStopAttr().Set(2.8)
    m = _new_stage(tmp_path / "m.usda", meters_per_unit=1.0)
    cam_m = UsdGeom.Camera.Define(m, "/cam")
    cam_m.GetFocalLengthAttr().Set(0.5)
    cam_m.GetFocusDistanceAttr().Set(3.0)
    for shot in (read_shot(_save(cm)), read_shot(_save(m))):
        np.testing.assert_allclose(shot.focal_length_mm, 50.0, rtol=1e-6)
        np.testing.assert_allclose(shot.focus_distance_m, 3.0, rtol=1e-6)
    assert read_shot(tmp_path / "m.usda").f_stop[0] == 0.0  # unset: pinhole, kept as 0


def test_animated_lens_channels(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "lens.usda", frames=(1, 3))
    cam = UsdGeom.Camera.Define(stage, "/cam")
    for f, (fl, fd, fs) in enumerate([(0.35, 2.0, 2.8), (0.40, 2.5, 4.0), (0.50, 3.0, 5.6)], 1):
        cam.GetFocalLengthAttr().Set(fl, f)
        cam.GetFocusDistanceAttr().Set(fd, f)
        cam.GetFStopAttr().Set(fs, f)
    shot = read_shot(_save(stage))
    np.testing.assert_allclose(shot.focal_length_mm, [35.0, 40.0, 50.0], rtol=1e-6)
    np.testing.assert_allclose(shot.focus_distance_m, [2.0, 2.5, 3.0], rtol=1e-6)
    np.testing.assert_allclose(shot.f_stop, [2.8, 4.0, 5.6], rtol=1e-6)


def test_shot_arrays_are_read_only(tmp_path: Path) -> None:
    shot = read_shot(_static_camera(tmp_path))
    assert isinstance(shot, Shot)
    with pytest.raises(ValueError, match="read-only"):
        shot.cam2world[0, 0, 0] = 2.0


# --------------------------------------------------------------------------------------------
# Frame range


def test_frame_range_override() -> None:
    full = read_shot(SHOTS / "maya_dolly_push_in.usda")
    part = read_shot(SHOTS / "maya_dolly_push_in.usda", frames=(1010, 1020))
    np.testing.assert_array_equal(part.frames, np.arange(1010, 1021))
    np.testing.assert_allclose(part.times, np.arange(11) / 24.0)
    np.testing.assert_allclose(part.cam2world, full.cam2world[9:20], atol=1e-12)
    np.testing.assert_allclose(part.focal_length_mm, full.focal_length_mm[9:20])
    one = read_shot(SHOTS / "maya_dolly_push_in.usda", frames=(1120, 1120))
    assert one.frames.tolist() == [1120]


@pytest.mark.parametrize(
    ("frames", "words"),
    [
        ((1000, 1010), ["1000-1010", "outside", "1001-1120"]),
        ((1100, 1121), ["outside", "1001-1120"]),
        ((1020, 1010), ["1020-1010", "backwards"]),
    ],
)
def test_bad_frame_range(frames: tuple[int, int], words: list[str]) -> None:
    with pytest.raises(ShotFileError) as info:
        read_shot(SHOTS / "maya_dolly_push_in.usda", frames=frames)
    for word in words:
        assert word in str(info.value)


def test_negative_frames_are_written_as_a_to_b_not_with_a_double_hyphen(tmp_path: Path) -> None:
    path = _static_camera(tmp_path, frames=(-24, 23))
    with pytest.raises(ShotFileError) as info:
        read_shot(path, frames=(-30, -1))
    assert "frames -30 to -1 are outside" in str(info.value)
    assert "film frames -24 to 23" in str(info.value)
    assert "--" not in str(info.value)
    assert read_shot(path, frames=(-3, 2)).frames.tolist() == [-3, -2, -1, 0, 1, 2]
    # every printed range: limit violations (check, the report), numpy's integers too
    from camtraj.shown import frame_runs, frame_span
    from camtraj.timing import LimitViolation

    v = LimitViolation("pan", "jerk", 9.0, 1.0, 9.0, ((-30, -25), (-3, -3), (4, 9)), True)
    assert v.frame_text == "frames -30 to -25, -3, 4-9"
    assert frame_span(np.int64(-3), np.int64(-1)) == "-3 to -1"
    assert frame_runs([(np.int64(1001), np.int64(1096))]) == "frames 1001-1096"


def test_static_camera_without_any_range_is_an_error(tmp_path: Path) -> None:
    path = _static_camera(tmp_path, frames=None)
    with pytest.raises(ShotFileError, match="no frame range"):
        read_shot(path)
    assert read_shot(path, frames=(3, 5)).frames.tolist() == [3, 4, 5]


# --------------------------------------------------------------------------------------------
# Animated parent


def test_animated_parent_pose_is_parent_times_child() -> None:
    path = SHOTS / "orbit_animated_parent.usda"
    shot = read_shot(path)
    assert shot.camera_path == "/World/orbit_rig/orbit_cam"
    stage = Usd.Stage.Open(str(path))
    rig = stage.GetPrimAtPath("/World/orbit_rig")
    cam = stage.GetPrimAtPath("/World/orbit_rig/orbit_cam")
    for i, tc in enumerate(shot.time_codes):
        # Compose by hand from the raw authored op values (column vectors).
        p_t = rig.GetAttribute("xformOp:translate").Get(tc)
        p_rz = rig.GetAttribute("xformOp:rotateZ").Get(tc)
        c_t = cam.GetAttribute("xformOp:translate").Get(tc)
        a, b, c = cam.GetAttribute("xformOp:rotateXYZ").Get(tc)
        rig2world = hom(rz(p_rz), list(p_t))
        cam2rig = hom(rz(c) @ ry(b) @ rx(a), list(c_t))
        np.testing.assert_allclose(shot.cam2world[i], rig2world @ cam2rig, atol=1e-9)
    pos = shot.cam2world[:, :3, 3]
    subject = np.array([6.5, 1.0, 1.0])
    np.testing.assert_allclose(np.hypot(*(pos - subject)[:, :2].T), 1.5, atol=1e-9)
    start, end = (pos[k, :2] - subject[:2] for k in (0, -1))
    arc = math.degrees(math.acos(start @ end / (np.linalg.norm(start) * np.linalg.norm(end))))
    assert arc == pytest.approx(90.0, abs=1e-3)
    # The camera keeps its subject in view: its view direction is within 10° of the subject.
    view = -shot.cam2world[:, :3, 2]
    to_subject = (subject - pos) / np.linalg.norm(subject - pos, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.sum(view * to_subject, axis=1))).max() < 10.0


# --------------------------------------------------------------------------------------------
# Camera choice


def _two_cameras(tmp_path: Path) -> Path:
    stage = _new_stage(tmp_path / "two.usda")
    UsdGeom.Xform.Define(stage, "/World")
    UsdGeom.Camera.Define(stage, "/World/camA").AddTranslateOp().Set(Gf.Vec3d(1, 0, 0))
    UsdGeom.Camera.Define(stage, "/World/camB").AddTranslateOp().Set(Gf.Vec3d(2, 0, 0))
    return _save(stage)


def test_list_cameras(tmp_path: Path) -> None:
    assert list_cameras(_two_cameras(tmp_path)) == ["/World/camA", "/World/camB"]
    assert list_cameras(SHOTS / "orbit_animated_parent.usda") == ["/World/orbit_rig/orbit_cam"]


def test_choose_camera_by_path(tmp_path: Path) -> None:
    shot = read_shot(_two_cameras(tmp_path), camera="/World/camB")
    assert shot.camera_path == "/World/camB"
    assert shot.cam2world[0, 0, 3] == 2.0


def test_two_cameras_without_a_choice_lists_them(tmp_path: Path) -> None:
    with pytest.raises(ShotFileError, match="2 cameras") as info:
        read_shot(_two_cameras(tmp_path))
    assert "/World/camA" in str(info.value)
    assert "/World/camB" in str(info.value)


@pytest.mark.parametrize(
    ("camera", "words"),
    [
        ("/World/camC", ["no camera at /World/camC", "/World/camA", "/World/camB"]),
        ("/World", ["/World is a Xform, not a Camera", "/World/camA"]),
        ("camA", ["not an absolute prim path", "/World/camB"]),
    ],
)
def test_wrong_camera_lists_what_exists(tmp_path: Path, camera: str, words: list[str]) -> None:
    with pytest.raises(ShotFileError) as info:
        read_shot(_two_cameras(tmp_path), camera=camera)
    for word in words:
        assert word in str(info.value)


def test_no_camera(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "nocam.usda")
    UsdGeom.Xform.Define(stage, "/World")
    path = _save(stage)
    with pytest.raises(ShotFileError, match="no camera"):
        read_shot(path)
    assert list_cameras(path) == []


# --------------------------------------------------------------------------------------------
# Unreadable files and bad transforms: one clear line, no USD noise


def _assert_clean(error: ShotFileError, capfd: pytest.CaptureFixture[str]) -> None:
    text = str(error)
    assert "\n" not in text
    assert "pxrInternal" not in text
    assert "Error in" not in text
    assert error.__cause__ is None  # no pxr exception chained into the traceback
    assert error.__context__ is None or error.__suppress_context__
    assert capfd.readouterr().err == ""


def test_missing_file(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ShotFileError, match="no such file") as info:
        read_shot(tmp_path / "nope.usd")
    assert "nope.usd" in str(info.value)
    _assert_clean(info.value, capfd)


def test_text_file_renamed_usd(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "notes.usd"
    path.write_text("camera notes: push in on the hero, 35mm\n")
    with pytest.raises(ShotFileError, match="not a USD file") as info:
        read_shot(path)
    _assert_clean(info.value, capfd)


def test_empty_file(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "empty.usda"
    path.write_bytes(b"")
    with pytest.raises(ShotFileError, match="empty") as info:
        read_shot(path)
    _assert_clean(info.value, capfd)


def test_truncated_usdc(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "good.usdc"
    Sdf.Layer.FindOrOpen(str(SHOTS / "whip_pan.usda")).Export(str(good))
    assert read_shot(good).n_frames == 48
    data = good.read_bytes()
    bad = tmp_path / "cut.usdc"
    bad.write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    with pytest.raises(ShotFileError, match="corrupt or truncated") as info:
        read_shot(bad)
    assert "cut.usdc" in str(info.value)
    _assert_clean(info.value, capfd)


def test_usda_syntax_error(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cut.usda"
    text = (SHOTS / "whip_pan.usda").read_text()
    path.write_text(text[: len(text) // 2])
    with pytest.raises(ShotFileError, match="syntax error") as info:
        read_shot(path)
    _assert_clean(info.value, capfd)


def test_nan_in_transform_names_the_frame(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    stage = _new_stage(tmp_path / "nan.usda", frames=(1, 10))
    op = UsdGeom.Camera.Define(stage, "/World/cam").AddTranslateOp()
    for f in range(1, 11):
        op.Set(Gf.Vec3d(float("nan") if f == 7 else f, 0, 0), f)
    path = _save(stage)
    with pytest.raises(ShotFileError, match="at frame 7") as info:
        read_shot(path)
    assert "/World/cam" in str(info.value)
    assert "NaN" in str(info.value)
    _assert_clean(info.value, capfd)
    assert read_shot(path, frames=(1, 6)).n_frames == 6  # the frames before are fine


def test_unsupported_up_axis(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    path = _static_camera(tmp_path, up_axis="X")
    with pytest.raises(ShotFileError, match="unsupported upAxis 'X'") as info:
        read_shot(path)
    _assert_clean(info.value, capfd)


def test_mirrored_transform(tmp_path: Path) -> None:
    stage = _new_stage(tmp_path / "mirror.usda", frames=(1, 4))
    op = UsdGeom.Camera.Define(stage, "/cam").AddScaleOp()
    for f in range(1, 5):
        op.Set(Gf.Vec3f(-1.0 if f >= 3 else 1.0, 1.0, 1.0), f)
    with pytest.raises(ShotFileError, match=r"mirrored .* at frame 3 \(2 frames"):
        read_shot(_save(stage))


def test_missing_reference_is_logged_not_printed(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    stage = _new_stage(tmp_path / "ref.usda")
    UsdGeom.Camera.Define(stage, "/cam")
    stage.DefinePrim("/set").GetReferences().AddReference("./missing_set.usda")
    path = _save(stage)
    capfd.readouterr()
    with caplog.at_level(logging.WARNING, logger="camtraj.usd_shot"):
        shot = read_shot(path)
    assert shot.camera_path == "/cam"
    assert "missing_set.usda" in caplog.text
    assert "missing_set.usda" not in capfd.readouterr().err


# --------------------------------------------------------------------------------------------
# Samples


def test_committed_samples_equal_a_fresh_run(tmp_path: Path) -> None:
    written = make_samples.write_all(tmp_path)
    assert sorted(p.name for p in written) == sorted(SAMPLE_NAMES)
    for name in SAMPLE_NAMES:
        fresh = (tmp_path / name).read_text(encoding="utf-8")
        committed = (SHOTS / name).read_text(encoding="utf-8")
        assert committed == fresh, f"{name} differs from make_samples.py output; rerun it"


def _speeds(shot: Shot) -> tuple[Array, Array]:
    """(n-1,) linear speed [m/s] and rotation rate [deg/s] between consecutive frames."""
    pos = shot.cam2world[:, :3, 3]
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) * shot.fps
    rot = shot.cam2world[:, :3, :3]
    rel = np.einsum("nji,njk->nik", rot[:-1], rot[1:])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return speed, np.degrees(np.arccos(cos)) * shot.fps


def _assert_realistic(shot: Shot, max_turn: float = 40.0) -> None:
    pos = shot.cam2world[:, :3, 3]
    assert (pos >= REACH_MIN).all()
    assert (pos <= REACH_MAX).all()
    speed, turn = _speeds(shot)
    assert speed.max() <= 1.0
    assert turn.max() <= max_turn
    assert speed[0] < 0.01  # eased start and stop
    assert speed[-1] < 0.01
    view_elevation = np.degrees(np.arcsin(-shot.cam2world[:, 2, 2]))
    assert np.abs(view_elevation).max() <= 45.0
    assert np.abs(shot.cam2world[:, 2, 0]).max() < 1e-6  # no roll: image x stays level


@pytest.mark.parametrize(
    ("name", "camera", "first", "last", "up", "mpu"),
    [
        ("maya_dolly_push_in.usda", "/shotCam", 1001, 1120, "Y", 0.01),
        ("blender_crane_up.usda", "/root/Camera", 1, 96, "Z", 1.0),
        ("orbit_animated_parent.usda", "/World/orbit_rig/orbit_cam", 1, 120, "Z", 1.0),
    ],
)
def test_feasible_samples_are_realistic(
    name: str, camera: str, first: int, last: int, up: str, mpu: float
) -> None:
    shot = read_shot(SHOTS / name)
    assert (shot.camera_path, shot.frames[0], shot.frames[-1]) == (camera, first, last)
    assert shot.up_axis == up
    assert shot.meters_per_unit == pytest.approx(mpu)
    assert shot.fps == 24.0
    _assert_realistic(shot)


def test_dolly_and_crane_samples() -> None:
    dolly = read_shot(SHOTS / "maya_dolly_push_in.usda")
    x = dolly.cam2world[:, 0, 3]
    assert x[-1] - x[0] == pytest.approx(2.5, abs=1e-6)  # pushes in along the track
    np.testing.assert_allclose(dolly.focal_length_mm[[0, -1]], [32.0, 40.0], atol=1e-4)
    crane = read_shot(SHOTS / "blender_crane_up.usda")
    z = crane.cam2world[:, 2, 3]
    assert (z[0], z[-1]) == (pytest.approx(0.2, abs=1e-6), pytest.approx(1.8, abs=1e-6))
    tilt = np.degrees(np.arcsin(-crane.cam2world[:, 2, 2]))
    assert tilt[0] > -5.0  # tilts down to hold the floor subject
    assert tilt[-1] < -35.0
    np.testing.assert_allclose(crane.focal_length_mm[[0, -1]], [35.0, 28.0], atol=1e-4)
    assert np.ptp(crane.f_stop) > 1.0
    assert np.ptp(crane.focus_distance_m) > 0.1


def test_whip_pan_sample_is_too_fast_for_the_pan_axis() -> None:
    shot = read_shot(SHOTS / "whip_pan.usda")
    assert shot.n_frames == 48
    view = -shot.cam2world[:, :3, 2]
    heading = np.degrees(np.unwrap(np.arctan2(view[:, 1], view[:, 0])))
    assert abs(heading[-1] - heading[0]) == pytest.approx(150.0, abs=1e-3)
    _, turn = _speeds(shot)
    moving = np.flatnonzero(turn > 1e-3)
    assert len(moving) <= 8  # the whole turn happens within 8 frames
    assert turn.max() > 200.0  # beyond the robot's 200°/s pan limit
    np.testing.assert_allclose(np.ptp(shot.cam2world[:, :3, 3], axis=0), 0.0, atol=1e-12)


def test_unreachable_sample_leaves_reach_only_mid_shot() -> None:
    shot = read_shot(SHOTS / "unreachable.usda")
    assert shot.n_frames == 60
    pos = shot.cam2world[:, :3, 3]
    outside = ((pos < REACH_MIN) | (pos > REACH_MAX)).any(axis=1)
    out_frames = shot.frames[outside]
    assert out_frames.min() >= 27
    assert out_frames.max() <= 48
    assert set(range(30, 46)) <= set(out_frames.tolist())
    np.testing.assert_allclose(pos[(shot.frames >= 30) & (shot.frames <= 45), 1], 7.0)


def test_long_shot_is_realistic(tmp_path: Path) -> None:
    path = make_samples.write_long_shot(tmp_path / "long.usda", n_frames=1440, fps=24)
    shot = read_shot(path)  # (its read time is in make bench, not in a test)
    assert shot.n_frames == 1440
    assert shot.times[-1] == pytest.approx(1439 / 24)
    _assert_realistic(shot)
    spans = np.ptp(shot.cam2world[:, :3, 3], axis=0)
    assert (spans > [3.0, 1.5, 0.9]).all()  # track travel, side move and crane together


# --------------------------------------------------------------------------------------------
# Holds authored as equal keys


def _sparse_hold(tmp_path: Path, second_key_deg: float, pan_deg: float = -75.963757) -> Path:
    """A camera under an animated parent: rotateXYZ (float3) keyed at frames 1 and 12 (equal
    keys when ``second_key_deg`` is 0), then turning; the parent's translate keyed equal at
    1 and 12, then moving."""
    stage = _new_stage(tmp_path / f"hold_{second_key_deg}_{pan_deg}.usda", frames=(1, 20))
    rig = UsdGeom.Xform.Define(stage, "/World/rig")
    move = rig.AddTranslateOp()
    cam = UsdGeom.Camera.Define(stage, "/World/rig/cam")
    turn = cam.AddRotateXYZOp(precision=UsdGeom.XformOp.PrecisionFloat)
    key = Gf.Vec3f(88.610646, 0.0, pan_deg)
    for frame, pan, x in ((1, 0.0, 5.0), (12, second_key_deg, 5.0), (20, 3.0, 5.4)):
        turn.Set(key + Gf.Vec3f(0.0, 0.0, pan), frame)
        move.Set(Gf.Vec3d(x, -0.5, 1.4), frame)
    return _save(stage)


@pytest.mark.parametrize("pan_deg", [-75.963757, 1434.5678])
def test_a_hold_between_equal_keys_is_exact(tmp_path: Path, pan_deg: float) -> None:
    """USD interpolates a float3 between two equal keys with a rounding error (about 1e-7
    rad; 2e-6 rad for a pan four turns in): the frames between equal keys are a hold, each
    exactly the first frame's pose, so the solver keeps the whole robot still there; frames
    after the hold move."""
    from camtraj.ik import camera_holds

    path = _sparse_hold(tmp_path, 0.0, pan_deg)
    shot = read_shot(path)
    assert np.array_equal(shot.cam2world[:12], np.broadcast_to(shot.cam2world[0], (12, 4, 4)))
    assert camera_holds(shot.cam2world).tolist() == [True] * 11 + [False] * 8
    # the exact pose is USD's own at the key, and every frame of the hold is within
    # rounding of what USD interpolates there
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/World/rig/cam")
    cache = UsdGeom.XformCache()
    raw = []
    for frame in range(1, 13):
        cache.SetTime(Usd.TimeCode(frame))
        raw.append(np.array(cache.GetLocalToWorldTransform(prim)).T)
    assert np.abs(shot.cam2world[0] - raw[0]).max() < 1e-12  # Z-up metres: as read
    assert 0.0 < np.abs(np.array(raw) - raw[0]).max() < 1e-5  # USD's rounding, snapped


def test_keys_that_differ_are_motion_however_small(tmp_path: Path) -> None:
    """Keys 0.001 deg apart are a (very slow) move: no frame is snapped, every pose is USD's
    (to the reader's orthonormalisation's round-off; a snap would be 1.7e-5 rad off)."""
    shot = read_shot(_sparse_hold(tmp_path, 1e-3))
    assert not camera_holds_any(shot.cam2world[:12])
    stage = Usd.Stage.Open(str(shot.source))
    prim = stage.GetPrimAtPath("/World/rig/cam")
    cache = UsdGeom.XformCache()
    for i, frame in enumerate(range(1, 21)):
        cache.SetTime(Usd.TimeCode(frame))
        usd = np.array(cache.GetLocalToWorldTransform(prim)).T
        assert np.abs(shot.cam2world[i] - usd).max() < 1e-12, frame


def _baked(tmp_path: Path, name: str, xs: np.ndarray) -> Path:
    """A camera baked frame by frame in Y-up centimetres: translate x per frame (m)."""
    stage = _new_stage(tmp_path / name, up_axis="Y", meters_per_unit=0.01,
                       frames=(1, len(xs)))
    cam = UsdGeom.Camera.Define(stage, "/World/cam")
    move = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(Gf.Vec3f(-10.0, 30.0, 0.0))
    for frame, x in enumerate(xs, start=1):
        move.Set(Gf.Vec3d(100.0 * x, 150.0, -200.0), frame)
    return _save(stage)


def test_a_baked_hold_with_jitter_is_a_hold_and_a_slow_creep_is_not(tmp_path: Path) -> None:
    """A hold baked with jitter of a few 1e-7 m (as evaluated and baked float values have) is
    a hold: every frame of it takes its first frame's pose, within 1e-6 m of USD's own, so
    the robot holds still and ``--timing optimal`` keeps its length. A creep of 5 mm in 10 s
    (2e-5 m a frame) is motion: every pose is USD's."""
    from camtraj.ik import camera_holds

    rng = np.random.default_rng(5)
    xs = np.concatenate([np.linspace(4.0, 4.5, 12), np.full(30, 4.5), np.linspace(4.5, 5.0, 12)])
    xs[12:42] += rng.uniform(-3e-7, 3e-7, 30)
    shot = read_shot(_baked(tmp_path, "jitter.usda", xs))
    held = camera_holds(shot.cam2world)
    assert held[11:41].all() and not held[:10].any() and not held[42:].any()
    assert np.array_equal(shot.cam2world[12:42],
                          np.broadcast_to(shot.cam2world[11], (30, 4, 4)))
    assert np.abs(shot.cam2world[12:42, :3, 3] - shot.cam2world[11, :3, 3]).max() == 0.0
    # Y-up centimetres to Z-up metres keeps x: the read x is the authored one, moved by
    # less than 1e-6 m in the hold and not at all elsewhere
    x = shot.cam2world[:, 0, 3]
    assert np.abs(x - xs).max() < 1e-6
    assert np.abs(x[:12] - xs[:12]).max() < 1e-12 and np.abs(x[42:] - xs[42:]).max() < 1e-12

    creep = 4.0 + 0.005 * np.arange(240) / 239.0
    slow = read_shot(_baked(tmp_path, "creep.usda", creep))
    assert not camera_holds(slow.cam2world).any()
    assert np.abs(slow.cam2world[:, 0, 3] - creep).max() < 1e-12


def camera_holds_any(poses: Array) -> bool:
    from camtraj.ik import camera_holds

    return bool(camera_holds(poses).any())


# --------------------------------------------------------------------------------------------
# Layers USD could not open


def test_a_missing_layer_the_camera_is_composed_from_is_an_error(tmp_path: Path) -> None:
    """A missing sublayer of the shot, or of the camera's own asset, or a missing camera
    reference would turn the move into a still (or no camera at all): an error naming the
    layer. A missing reference on a parent, or anywhere else on the stage (set dressing a
    farm node lacks, a set asset's own missing sublayer), is a warning: the camera is read."""
    stage = _new_stage(tmp_path / "sub.usda")
    UsdGeom.Camera.Define(stage, "/cam").AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    stage.GetRootLayer().subLayerPaths.append("./anim_missing.usda")
    with pytest.raises(ShotFileError, match=r"USD could not compose the camera /cam as written, "
                       r"so its move would be read without part of it: Could not load "
                       r"sublayer @.*anim_missing\.usda@") as err:
        read_shot(_save(stage))
    assert "\n" not in str(err.value) and not str(err.value).endswith("skipping.")

    asset = _new_stage(tmp_path / "cam_asset.usda")
    UsdGeom.Camera.Define(asset, "/Cam").AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    asset.SetDefaultPrim(asset.GetPrimAtPath("/Cam"))
    asset.GetRootLayer().subLayerPaths.append("./cam_fx_missing.usda")
    _save(asset)
    stage = _new_stage(tmp_path / "payload.usda")
    stage.DefinePrim("/World/shotCam").GetPayloads().AddPayload("./cam_asset.usda")
    with pytest.raises(ShotFileError, match=r"camera /World/shotCam as written.*"
                       r"cam_fx_missing\.usda"):
        read_shot(_save(stage))

    stage = _new_stage(tmp_path / "ref.usda")
    UsdGeom.Xform.Define(stage, "/World")
    stage.DefinePrim("/World/shotCam").GetReferences().AddReference("./cam_missing.usda")
    for camera in (None, "/World/shotCam", "/World/shotCam/nothing"):
        with pytest.raises(ShotFileError, match=r"USD could not compose the stage: Could not "
                           r"open asset @.*cam_missing\.usda@ for reference"):
            read_shot(_save(stage), camera=camera)

    set_asset = _new_stage(tmp_path / "set_ok.usda")
    set_asset.SetDefaultPrim(set_asset.DefinePrim("/Set"))
    set_asset.GetRootLayer().subLayerPaths.append("./lookdev_missing.usda")
    _save(set_asset)
    stage = _new_stage(tmp_path / "set.usda")
    UsdGeom.Xform.Define(stage, "/World").GetPrim().GetReferences().AddReference(
        "./world_missing.usda")
    UsdGeom.Camera.Define(stage, "/World/cam").AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    stage.DefinePrim("/World/set").GetReferences().AddReference("./set_missing.usda")
    stage.DefinePrim("/World/set2").GetReferences().AddReference("./set_ok.usda")
    shot = read_shot(_save(stage))
    np.testing.assert_allclose(shot.cam2world[0, :3, 3], [1.0, 2.0, 3.0])
    (parent,) = [w for w in shot.warnings if "a parent of the camera /World/cam" in w]
    assert "world_missing.usda" in parent
    (elsewhere,) = [w for w in shot.warnings if "away from the camera (2 error(s))" in w]
    assert "set_missing.usda" in elsewhere or "lookdev_missing.usda" in elsewhere


@pytest.mark.parametrize(("start", "end", "frames"), [
    (8, None, (8, 15)), (None, 12, (5, 12)), (20, None, None)])
def test_one_authored_end_of_the_range_bounds_the_shot(
        tmp_path: Path, start: int | None, end: int | None,
        frames: tuple[int, int] | None) -> None:
    """startTimeCode or endTimeCode alone (USD's HasAuthoredTimeCodeRange wants both) still
    cuts the shot where it says; the keys give the other end. Past the keys it is an error."""
    stage = _new_stage(tmp_path / "one_end.usda", frames=None)
    if start is not None:
        stage.SetStartTimeCode(start)
    if end is not None:
        stage.SetEndTimeCode(end)
    op = UsdGeom.Camera.Define(stage, "/cam").AddTranslateOp()
    for f in range(5, 16):
        op.Set(Gf.Vec3d(f, 0, 0), f)
    path = _save(stage)
    if frames is None:
        with pytest.raises(ShotFileError, match="range from startTimeCode to the last key is "
                           "backwards: time codes 20 to 15"):
            read_shot(path)
        return
    shot = read_shot(path)
    np.testing.assert_array_equal(shot.frames, np.arange(frames[0], frames[1] + 1))
    np.testing.assert_allclose(shot.cam2world[:, 0, 3], shot.frames)


def test_a_camera_layer_in_other_units_is_named(tmp_path: Path) -> None:
    """USD converts no units across a reference: a camera animated in a metre, Z-up layer
    and referenced into a centimetre, Y-up stage is read in centimetres and Y-up (the move a
    hundredth as long). The shot is read as USD composes it, with a warning naming the
    layer; a layer in the stage's own units gets none."""
    def camera_layer(name: str, up: str, mpu: float) -> str:
        stage = _new_stage(tmp_path / name, up_axis=up, meters_per_unit=mpu)
        op = UsdGeom.Camera.Define(stage, "/cam").AddTranslateOp()
        for f in range(1, 11):
            op.Set(Gf.Vec3d(0.2 * f, 0.0, 1.5), f)
        stage.SetDefaultPrim(stage.GetPrimAtPath("/cam"))
        return str(_save(stage))

    for layer, up, mpu, warned in (("m_zup.usda", "Z", 1.0, True),
                                   ("cm_yup.usda", "Y", 0.01, False)):
        stage = _new_stage(tmp_path / f"shot_{layer}", up_axis="Y", meters_per_unit=0.01)
        stage.DefinePrim("/shotCam").GetReferences().AddReference(camera_layer(layer, up, mpu))
        shot = read_shot(_save(stage))
        np.testing.assert_allclose(shot.cam2world[-1, 0, 3], 0.02)  # 2 units, read as cm
        named = [w for w in shot.warnings if layer in w]
        assert len(named) == warned, shot.warnings
        if warned:
            assert ("written with metersPerUnit 1 (the stage's: 0.01) and upAxis Z (the "
                    "stage's: Y)") in named[0]


def test_a_set_layer_in_other_units_that_does_not_move_the_camera_is_not_named(
        tmp_path: Path) -> None:
    """A set-dressing sublayer in centimetres, Y-up, that defines /World (the camera's
    parent) and a box, but no transform of /World: nothing of the move comes from it (a
    reviewer's case)."""
    dressing = _new_stage(tmp_path / "set_cm.usda", up_axis="Y", meters_per_unit=0.01)
    UsdGeom.Xform.Define(dressing, "/World")
    UsdGeom.Cube.Define(dressing, "/World/set/box")
    _save(dressing)
    stage = _new_stage(tmp_path / "shot.usda")
    stage.GetRootLayer().subLayerPaths.append("./set_cm.usda")
    op = UsdGeom.Camera.Define(stage, "/World/cam").AddTranslateOp()
    for f in range(1, 11):
        op.Set(Gf.Vec3d(0.1 * f, 0.0, 1.5), f)
    shot = read_shot(_save(stage))
    assert not [w for w in shot.warnings if "set_cm.usda" in w], shot.warnings


@pytest.mark.parametrize(("attr", "value", "meaning"), [
    ("focalLength", -0.35, "a focal length is above zero"),
    ("focalLength", 0.0, "a focal length is above zero"),
    ("focusDistance", -2.0, "a focus distance is zero (unset) or more"),
    ("fStop", -2.8, "an f-stop is zero (unset) or more"),
    ("horizontalAperture", -3.6, "a film back is above zero"),
])
def test_a_lens_value_of_the_wrong_sign_is_bad_input(tmp_path: Path, attr: str, value: float,
                                                     meaning: str) -> None:
    """A negative focal length, focus distance, f-stop or film back on some frames is a
    broken export: an input error naming the frames, as NaN is (a new user's negative
    focal length converted with exit 0 into a camera_info with fx = -1867)."""
    stage = _new_stage(tmp_path / "sign.usda", frames=(1, 12))
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(1.0, 0.0, 1.5))
    good = {"focalLength": 0.35, "focusDistance": 3.0, "fStop": 2.8,
            "horizontalAperture": 0.36}[attr]
    prop = cam.GetPrim().GetAttribute(attr)
    for f in range(1, 13):
        prop.Set(value if f >= 10 else good, f)
    with pytest.raises(ShotFileError, match=re.escape(
            f"has {attr} {value:g} at frame 10 (3 frames in all: frames 10-12): {meaning}")):
        read_shot(_save(stage))
    for f in range(10, 13):  # zero is "unset" for focus and stop, and reads
        prop.Set(0.0 if attr in ("focusDistance", "fStop") else good, f)
    read_shot(_save(stage))
