"""Lens details a robot cannot give, or that point at a unit mix-up, are said (issue 15).

Each test builds a small USD stage with pxr and reads it with :func:`read_shot`; the principal
point written to CameraInfo is checked against USD's own projection (Gf.Camera's frustum).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from pxr import Gf, Sdf, Ts, Usd, UsdGeom, UsdRender

from camtraj.errors import ShotFileError
from camtraj.mcap_io import TOPIC_CAMERA_INFO, TakeData, write_take_to
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.ros2 import camera_matrices
from camtraj.usd_shot import read_shot


def _stage(path: Path, *, mpu: float = 1.0, frames: tuple[int, int] | None = (1, 3)) -> Any:
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetMetadata("upAxis", "Z")
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetTimeCodesPerSecond(24.0)
    if frames is not None:
        stage.SetStartTimeCode(frames[0])
        stage.SetEndTimeCode(frames[1])
    return stage


def _camera(stage: Any, path: str = "/cam", *, focal: float = 0.35) -> Any:
    cam = UsdGeom.Camera.Define(stage, path)
    cam.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1.0))
    cam.GetFocalLengthAttr().Set(focal)
    cam.GetHorizontalApertureAttr().Set(0.36)  # 36 mm on a metre stage
    cam.GetVerticalApertureAttr().Set(0.24)
    return cam


def _read(stage: Any, **kwargs: Any) -> Any:
    stage.GetRootLayer().Save()
    return read_shot(Path(stage.GetRootLayer().realPath), **kwargs)


def test_a_plain_camera_gets_no_lens_warning(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "plain.usda")
    _camera(stage)
    shot = _read(stage)
    assert shot.warnings == ()
    assert shot.horizontal_aperture_offset_mm.tolist() == [0.0, 0.0, 0.0]


def test_lens_shift_is_read_in_mm_and_warned(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "shift.usda", mpu=0.01)  # centimetres: tenths = millimetres
    cam = _camera(stage, focal=35.0)
    cam.GetHorizontalApertureAttr().Set(36.0)
    cam.GetVerticalApertureAttr().Set(24.0)
    cam.GetHorizontalApertureOffsetAttr().Set(3.0)
    cam.GetVerticalApertureOffsetAttr().Set(-1.5)
    shot = _read(stage)
    assert shot.horizontal_aperture_offset_mm.tolist() == pytest.approx([3.0] * 3)
    assert shot.vertical_aperture_offset_mm.tolist() == pytest.approx([-1.5] * 3)
    (warning,) = shot.warnings
    assert "lens shift" in warning and "off-centre" in warning and "cannot" in warning
    assert "horizontalApertureOffset 3 mm" in warning and "(cx, cy)" in warning


def test_animated_aperture_offset_is_called_film_shake(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "shake.usda")
    cam = _camera(stage)
    attr = cam.GetVerticalApertureOffsetAttr()
    for frame, value in ((1, 0.0), (2, 0.004), (3, -0.002)):
        attr.Set(value, float(frame))
    shot = _read(stage)
    assert shot.vertical_aperture_offset_mm.tolist() == pytest.approx([0.0, 0.4, -0.2])
    (warning,) = shot.warnings
    assert "film shake" in warning and "frame 2" in warning


def test_principal_point_agrees_with_usds_projection() -> None:
    """A point on the lens axis lands, in USD's own frustum, where K puts it: (cx, cy)."""
    focal, h_ap, v_ap, ox, oy = 35.0, 36.0, 24.0, 3.0, -1.5
    width, height = 1920, 1280
    (K,) = camera_matrices([focal], [h_ap], [v_ap], width, height, [ox], [oy])
    gf = Gf.Camera()
    gf.focalLength, gf.horizontalAperture, gf.verticalAperture = focal, h_ap, v_ap
    gf.horizontalApertureOffset, gf.verticalApertureOffset = ox, oy
    proj = gf.frustum.ComputeProjectionMatrix()
    for point_cam in ((0.0, 0.0, -5.0), (0.4, -0.3, -3.0)):  # USD camera: looks down -Z, +Y up
        ndc = proj.Transform(Gf.Vec3d(*point_cam))
        u_usd = (ndc[0] + 1.0) / 2.0 * width
        v_usd = (1.0 - ndc[1]) / 2.0 * height
        # The same point in the optical frame (x right, y down, z forward), projected by K.
        x, y, z = point_cam[0], -point_cam[1], -point_cam[2]
        u, v, w = K @ [x, y, z]
        assert (u / w, v / w) == pytest.approx((u_usd, v_usd), abs=1e-6)
    assert K[0, 2] == pytest.approx(width / 2 - ox / h_ap * width)
    assert K[1, 2] == pytest.approx(height / 2 + oy / v_ap * height)


def test_camera_info_carries_the_lens_shift(tmp_path: Path, robot: Robot) -> None:
    n, m = 2, 3
    ox, oy = np.array([3.0, 2.0]), np.array([-1.5, 0.0])
    take = TakeData(
        joint_names=JOINT_NAMES, t=np.array([0.0, 0.5, 1.0]), q=np.zeros((m, 8)),
        qd=np.zeros((m, 8)), qdd=np.zeros((m, 8)), frame_numbers=np.array([1, 2]),
        frame_times=np.array([0.0, 1.0]), frame_q=np.zeros((n, 8)),
        target=np.tile(np.eye(4), (n, 1, 1)), achieved=np.tile(np.eye(4), (n, 1, 1)),
        focal_length_mm=np.full(n, 35.0), focus_distance_m=np.zeros(n), f_stop=np.zeros(n),
        fps=1.0, horizontal_aperture_mm=np.full(n, 36.0), vertical_aperture_mm=np.full(n, 24.0),
        horizontal_aperture_offset_mm=ox, vertical_aperture_offset_mm=oy,
    )
    path = tmp_path / "take.mcap"
    with path.open("wb") as stream:
        write_take_to(stream, take, robot, {})
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        infos = [msg for _s, _c, _m, msg in reader.iter_decoded_messages(
            topics=[TOPIC_CAMERA_INFO])]
    assert len(infos) == n
    for info, dx, dy in zip(infos, ox, oy, strict=True):
        assert info.k[2] == pytest.approx(info.width / 2 - dx / 36.0 * info.width)
        assert info.k[5] == pytest.approx(info.height / 2 + dy / 24.0 * info.height)
        assert info.p[2] == info.k[2] and info.p[6] == info.k[5]


def test_film_back_in_millimetres_on_a_metre_stage_is_warned(tmp_path: Path) -> None:
    """A 10 mm lens and a 36 mm film back written in millimetres on a metre stage read as
    1000 mm and 3600 mm: both are said, the film back against real sensor sizes."""
    stage = _stage(tmp_path / "mm.usda")
    cam = _camera(stage, focal=10.0)
    cam.GetHorizontalApertureAttr().Set(36.0)
    cam.GetVerticalApertureAttr().Set(24.0)
    shot = _read(stage)
    assert shot.horizontal_aperture_mm[0] == pytest.approx(3600.0)
    film = [w for w in shot.warnings if "film back" in w]
    assert len(film) == 1
    assert "3600 mm" in film[0] and "real sensors" in film[0]
    assert "--focal-length-unit mm" in film[0]
    # Read as millimetres, nothing is left to warn about.
    assert _read(stage, focal_length_unit="mm").warnings == ()


def test_a_camera_without_a_focal_length_is_not_blamed_on_an_exporter(tmp_path: Path) -> None:
    """No focalLength at all: USD's fallback (50 tenths of a unit, 5000 mm on a metre stage)
    is said to be the fallback, not millimetres an exporter wrote."""
    stage = _stage(tmp_path / "nofocal.usda")
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1.0))
    shot = _read(stage)
    focal = [w for w in shot.warnings if "focal" in w]
    assert focal == ["camera /cam has no focalLength: USD's fallback 50 (tenths of a scene "
                     "unit, here 1 m) reads as 5000 mm, outside the 4-1200 mm of real lenses; "
                     "author the focal length to record it"]
    # authored, the same value is the exporter's millimetres
    cam.GetFocalLengthAttr().Set(50.0)
    assert any("older exporter" in w for w in _read(stage).warnings)


def test_millimetres_on_an_inch_stage_are_warned(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "inch.usda", mpu=0.0254)
    cam = _camera(stage, focal=35.0)
    cam.GetHorizontalApertureAttr().Set(36.0)  # 3ds Max: millimetres whatever the unit
    cam.GetVerticalApertureAttr().Set(24.0)
    shot = _read(stage)
    assert any("film back 91.44 mm" in w for w in shot.warnings), shot.warnings


def test_a_tiny_film_back_is_warned(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "tiny.usda")
    cam = _camera(stage)
    cam.GetHorizontalApertureAttr().Set(0.0036)  # 0.36 mm
    (warning,) = _read(stage).warnings
    assert "film back 0.36 mm" in warning


def test_non_square_pixel_aspect_ratio_is_warned(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "anamorphic.usda")
    _camera(stage)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateCameraRel().SetTargets([Sdf.Path("/cam")])
    settings.CreatePixelAspectRatioAttr().Set(2.0)
    (warning,) = _read(stage).warnings
    assert "pixelAspectRatio 2" in warning and "/Render/Settings" in warning
    settings.GetPixelAspectRatioAttr().Set(1.0)
    assert _read(stage).warnings == ()


def test_shear_without_a_parent_names_the_camera_transform(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "shear.usda")
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddScaleOp().Set(Gf.Vec3f(1.0, 3.0, 1.0))  # outside the rotation: shears the view
    cam.AddRotateXOp().Set(45.0)
    cam.GetFocalLengthAttr().Set(0.35)
    (warning,) = _read(stage).warnings
    assert "sheared camera transform" in warning and "parent" not in warning


def test_shear_under_a_parent_still_names_the_parent(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "shear_parent.usda")
    UsdGeom.Xform.Define(stage, "/rig").AddScaleOp().Set(Gf.Vec3f(1.0, 3.0, 1.0))
    cam = UsdGeom.Camera.Define(stage, "/rig/cam")
    cam.AddRotateXOp().Set(45.0)
    cam.GetFocalLengthAttr().Set(0.35)
    (warning,) = _read(stage).warnings
    assert "sheared or non-uniformly scaled parent" in warning


def test_spline_animated_camera_without_a_range_names_frames(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "spline.usda", frames=None)
    cam = _camera(stage)
    op = cam.AddRotateXOp(precision=UsdGeom.XformOp.PrecisionDouble)
    spline = Ts.Spline("double")
    for time, value in ((1.0, 0.0), (10.0, 30.0)):
        knot = Ts.Knot("double")
        knot.SetTime(time)
        knot.SetValue(value)
        spline.SetKnot(knot)
    op.GetAttr().SetSpline(spline)
    with pytest.raises(ShotFileError) as info:
        _read(stage)
    text = str(info.value)
    assert "splines" in text and "--frames" in text and "not animated" not in text
    assert _read(stage, frames=(1, 3)).frames.tolist() == [1, 2, 3]


def test_static_camera_without_a_range_names_frames(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "static.usda", frames=None)
    _camera(stage)
    with pytest.raises(ShotFileError, match=r"no time samples; give .* --frames"):
        _read(stage)
