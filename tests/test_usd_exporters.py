"""USD shots as real exporters write them (issue 8 §5), each stage authored that exporter's way.

Every expected value comes from the stage as authored (the keyed values, USD's own evaluation
at the film frame's time code) or from hand geometry, never from camtraj's reader.
"""

from __future__ import annotations

import json
import math
import re
import struct
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.linalg
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from numpy.typing import NDArray
from pxr import Gf, Tf, Usd, UsdGeom

from camtraj.errors import ShotFileError
from camtraj.usd_shot import read_shot
from tests.test_convert import error_line, run_cli

Array = NDArray[np.float64]

# A camera the default robot reaches comfortably: 5 m down the track, 1.5 m up, looking along
# +x (rotateXYZ (90, 0, -90) turns USD's -Z view onto world +x with +z up).
LOOK_ALONG_X = Gf.Vec3f(90.0, 0.0, -90.0)


def _stage(path: Path, *, tcps: float, fps: float | None, start: float | None = None,
           end: float | None = None, mpu: float = 1.0) -> Any:
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetMetadata("upAxis", "Z")
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetTimeCodesPerSecond(tcps)
    if fps is not None:
        stage.SetFramesPerSecond(fps)
    if start is not None and end is not None:
        stage.SetStartTimeCode(start)
        stage.SetEndTimeCode(end)
    return stage


def _save(stage: Any) -> Path:
    stage.GetRootLayer().Save()
    return Path(stage.GetRootLayer().realPath)


def _ease(u: float) -> float:
    return u * u * (3.0 - 2.0 * u)


def _dolly(stage: Any, time_codes: list[float], *, span: tuple[float, float]) -> Any:
    """A camera easing 0.3 m along +x over ``span`` (time codes), keyed at ``time_codes``."""
    cam = UsdGeom.Camera.Define(stage, "/cam")
    move = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(LOOK_ALONG_X)
    cam.GetFocalLengthAttr().Set(0.35)  # 35 mm on a metre stage
    for tc in time_codes:
        u = min(max((tc - span[0]) / (span[1] - span[0]), 0.0), 1.0)
        move.Set(Gf.Vec3d(5.0 + 0.3 * _ease(u), 0.0, 1.5), tc)
    return cam


def _usd_x(path: Path, time_codes: Array) -> Array:
    """USD's own evaluation of the camera's world x [m] at ``time_codes``."""
    stage = Usd.Stage.Open(str(path))
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/cam"))
    return np.array([xf.ComputeLocalToWorldTransform(Usd.TimeCode(float(t)))[3][0]
                     for t in time_codes])


def _shot_frames(mcap: Path) -> list[Any]:
    with mcap.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [msg for _, _, _, msg in reader.iter_decoded_messages(topics=["/shot/frames"])]


# --------------------------------------------------------------------------------------------
# Time codes are not film frames


def _houdini_240(tmp_path: Path, name: str = "houdini.usda", nan_at: float | None = None) -> Path:
    """Houdini-style: 240 time codes per second at 24 fps, film frames 1-48 = codes 10-480."""
    stage = _stage(tmp_path / name, tcps=240.0, fps=24.0, start=10.0, end=480.0)
    codes = [10.0 * f for f in range(1, 49)]
    cam = _dolly(stage, codes, span=(10.0, 480.0))
    if nan_at is not None:
        cam.GetFocalLengthAttr().Set(float("nan"), nan_at)
        cam.GetFocalLengthAttr().Set(0.35, nan_at - 10.0)
        cam.GetFocalLengthAttr().Set(0.35, nan_at + 10.0)
    return _save(stage)


def test_240_time_codes_at_24_fps_are_film_frames_1_to_48(tmp_path: Path) -> None:
    path = _houdini_240(tmp_path)
    shot = read_shot(path)
    np.testing.assert_array_equal(shot.frames, np.arange(1, 49))
    np.testing.assert_array_equal(shot.time_codes, 10.0 * np.arange(1, 49))
    assert shot.fps == 24.0
    np.testing.assert_allclose(shot.times, np.arange(48) / 24.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(shot.cam2world[:, 0, 3], _usd_x(path, 10.0 * np.arange(1, 49)),
                               rtol=0, atol=1e-12)


def test_frames_option_takes_film_frames(tmp_path: Path) -> None:
    path = _houdini_240(tmp_path)
    part = read_shot(path, frames=(12, 24))
    np.testing.assert_array_equal(part.frames, np.arange(12, 25))
    np.testing.assert_allclose(part.cam2world[:, 0, 3], _usd_x(path, 10.0 * np.arange(12, 25)),
                               rtol=0, atol=1e-12)
    with pytest.raises(ShotFileError, match=r"frames 40-60 are outside .* film frames 1-48"):
        read_shot(path, frames=(40, 60))


def test_errors_name_film_frames(tmp_path: Path) -> None:
    path = _houdini_240(tmp_path, nan_at=250.0)  # time code 250 is film frame 25
    with pytest.raises(ShotFileError, match=r"no finite focalLength at frame 25$"):
        read_shot(path)


def test_240_tcps_convert_writes_film_frames_and_info_shows_them(tmp_path: Path) -> None:
    path = _houdini_240(tmp_path)
    out = tmp_path / "houdini.mcap"
    proc = run_cli("convert", path, "-o", out, "--frames", "1:24", "-q")
    assert proc.returncode == 0, proc.stderr
    frames = _shot_frames(out)
    assert [m.frame for m in frames] == list(range(1, 25))
    # film frames are 1/24 s apart in the take (shot timing), to the file's nanosecond
    times = np.array([m.time for m in frames])
    np.testing.assert_allclose(np.diff(times), 1.0 / 24.0, rtol=0, atol=1e-9)
    info = run_cli("info", out)
    assert info.returncode == 0, info.stderr
    assert re.search(r"^frames\s+1-24 \(24 frames at 24(\.0)? fps\)", info.stdout, re.M)
    bad = run_cli("convert", path, "-o", tmp_path / "x.mcap", "--frames", "10:480")
    assert bad.returncode == 2
    assert "film frames 1-48" in error_line(bad)


# --------------------------------------------------------------------------------------------
# Sub-frame motion-blur keys


def test_subframe_keys_without_a_range_sample_whole_frames(tmp_path: Path) -> None:
    # A motion-blur export: keys at f - 1/4, f, f + 1/4 for film frames 1-24, no stage range.
    stage = _stage(tmp_path / "blur.usda", tcps=24.0, fps=24.0)
    codes = [f + d for f in range(1, 25) for d in (-0.25, 0.0, 0.25)]
    _dolly(stage, codes, span=(1.0, 24.0))
    path = _save(stage)
    shot = read_shot(path)
    np.testing.assert_array_equal(shot.frames, np.arange(1, 25))
    np.testing.assert_array_equal(shot.time_codes, np.arange(1, 25))
    expected = [5.0 + 0.3 * _ease((f - 1.0) / 23.0) for f in range(1, 25)]  # the keyed values
    np.testing.assert_allclose(shot.cam2world[:, 0, 3], expected, rtol=0, atol=1e-12)


def test_subframe_authored_range_starts_on_the_first_whole_frame(tmp_path: Path) -> None:
    # Some exporters write the first and last sample as the range: 0.75 .. 24.25.
    stage = _stage(tmp_path / "blur_range.usda", tcps=24.0, fps=24.0, start=0.75, end=24.25)
    _dolly(stage, [f + d for f in range(1, 25) for d in (-0.25, 0.0, 0.25)], span=(1.0, 24.0))
    shot = read_shot(_save(stage))
    assert (shot.frames[0], shot.frames[-1], shot.n_frames) == (1, 24, 24)


# --------------------------------------------------------------------------------------------
# NTSC rates spelled two ways


@pytest.mark.parametrize(
    ("tcps", "fps"), [(24000 / 1001, 23.976), (23.976, 24000 / 1001), (30000 / 1001, 29.97)]
)
def test_ntsc_rates_keep_the_last_frame(tmp_path: Path, tcps: float, fps: float) -> None:
    stage = _stage(tmp_path / "ntsc.usda", tcps=tcps, fps=fps, start=1001.0, end=1240.0)
    _dolly(stage, [float(f) for f in range(1001, 1241)], span=(1001.0, 1240.0))
    path = _save(stage)
    shot = read_shot(path)
    np.testing.assert_array_equal(shot.frames, np.arange(1001, 1241))  # 240 frames, none lost
    np.testing.assert_array_equal(shot.time_codes, np.arange(1001, 1241))
    rate = Fraction(round(fps * 1.001) * 1000, 1001)
    assert shot.fps == pytest.approx(float(rate), rel=1e-12)
    assert shot.times[-1] == pytest.approx(239 / float(rate), rel=1e-12)


# --------------------------------------------------------------------------------------------
# Lens-only animation


def test_lens_only_animation_without_a_range_is_animated(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "zoom.usda", tcps=24.0, fps=24.0)
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.AddTranslateOp().Set(Gf.Vec3d(5.0, 0.0, 1.5))
    cam.AddRotateXYZOp().Set(LOOK_ALONG_X)
    for f in range(1, 13):
        cam.GetFocalLengthAttr().Set(0.24 + 0.01 * f, float(f))  # a zoom 25 -> 36 mm
    shot = read_shot(_save(stage))
    np.testing.assert_array_equal(shot.frames, np.arange(1, 13))
    np.testing.assert_allclose(shot.focal_length_mm, 24.0 + np.arange(1, 13), rtol=1e-6)


# --------------------------------------------------------------------------------------------
# Blender 2.93: metersPerUnit stored as a float, focalLength in millimetres


def _as_float_metadatum(data: bytes, value: float) -> bytes:
    """Retype the crate's one inlined double ``value`` as a float, as Blender 2.93 wrote it.

    pxr's Python API casts layer metadata to the schema's type (double), so the float has to
    be put in the file directly. A usdc file keeps the value of every field as an 8-byte
    ValueRep (bit 62 = inlined, bits 48-55 = type: 8 float, 9 double; an inlined double that
    fits a float stores the float's bits in the low 32 bits, as an inlined float does), in the
    FIELDS section: u64 field count, u64 size + token indices, u64 size + the reps (one LZ4
    chunk after a 0 byte). The section is rewritten at the end of the file with a new table of
    contents; everything else stays as USD wrote it.
    """
    lz4_block = pytest.importorskip("lz4.block")
    bits = struct.unpack("<I", struct.pack("<f", value))[0]
    double = struct.pack("<Q", (1 << 62) | (9 << 48) | bits)
    single = struct.pack("<Q", (1 << 62) | (8 << 48) | bits)
    assert data[:8] == b"PXR-USDC"
    (toc,) = struct.unpack_from("<Q", data, 16)
    (n_sections,) = struct.unpack_from("<Q", data, toc)
    sections = [list(struct.unpack_from("<16sqq", data, toc + 8 + 32 * i))
                for i in range(n_sections)]
    fields = next(s for s in sections if s[0].rstrip(b"\0") == b"FIELDS")
    pos = int(fields[1])
    (n_fields,) = struct.unpack_from("<Q", data, pos)
    (token_bytes,) = struct.unpack_from("<Q", data, pos + 8)
    reps_at = pos + 16 + token_bytes
    (rep_bytes,) = struct.unpack_from("<Q", data, reps_at)
    blob = data[reps_at + 8 : reps_at + 8 + rep_bytes]
    assert blob[0] == 0  # a single chunk
    reps = lz4_block.decompress(blob[1:], uncompressed_size=8 * n_fields)
    assert reps.count(double) == 1
    packed = b"\0" + lz4_block.compress(reps.replace(double, single), store_size=False)
    section = data[pos:reps_at] + struct.pack("<Q", len(packed)) + packed
    out = bytearray(data[:toc])
    fields[1], fields[2] = len(out), len(section)
    out += section
    new_toc = len(out)
    out += struct.pack("<Q", n_sections)
    out += b"".join(struct.pack("<16sqq", *s) for s in sections)
    struct.pack_into("<Q", out, 16, new_toc)
    return bytes(out)


def _blender_293(tmp_path: Path) -> Path:
    # Frames 101-112: no other inlined double of the crate may equal metersPerUnit's 1.0.
    stage = _stage(tmp_path / "b293_double.usdc", tcps=24.0, fps=24.0, start=101.0, end=112.0,
                   mpu=1.0)
    UsdGeom.Xform.Define(stage, "/root")
    cam = UsdGeom.Camera.Define(stage, "/root/Camera")
    move = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(LOOK_ALONG_X)
    cam.GetFocalLengthAttr().Set(50.0)  # Blender 2.93 wrote the lens in mm, whatever the units
    for f in range(1, 13):
        move.Set(Gf.Vec3d(5.0 + 0.01 * f, 0.0, 1.5), float(100 + f))
    path = _save(stage)
    out = tmp_path / "b293.usdc"
    out.write_bytes(_as_float_metadatum(path.read_bytes(), 1.0))
    return out


def test_blender_293_float_meters_per_unit_is_read(tmp_path: Path) -> None:
    path = _blender_293(tmp_path)
    stage = Usd.Stage.Open(str(path))
    with pytest.raises(Tf.ErrorException, match="does not match retrieved type float"):
        UsdGeom.GetStageMetersPerUnit(stage)  # the fixture reproduces the exporter's file
    shot = read_shot(path)
    assert shot.meters_per_unit == 1.0
    np.testing.assert_allclose(shot.cam2world[:, 0, 3], 5.0 + 0.01 * np.arange(1, 13),
                               rtol=0, atol=1e-12)


def test_millimetre_focal_length_warns_and_mm_unit_reads_it(tmp_path: Path) -> None:
    path = _blender_293(tmp_path)
    shot = read_shot(path)
    np.testing.assert_allclose(shot.focal_length_mm, 5000.0)  # what the schema says
    assert len(shot.warnings) == 1
    (warning,) = shot.warnings
    assert "\n" not in warning
    for word in ("/root/Camera", "50", "5000 mm", "likely millimetres", "--focal-length-unit mm"):
        assert word in warning
    fixed = read_shot(path, focal_length_unit="mm")
    np.testing.assert_allclose(fixed.focal_length_mm, 50.0)
    assert fixed.warnings == ()


def test_focal_length_unit_on_the_command_line(tmp_path: Path) -> None:
    path = _blender_293(tmp_path)
    summary, out = tmp_path / "s.json", tmp_path / "b.mcap"
    proc = run_cli("convert", path, "-o", out, "--summary", summary)
    assert proc.returncode == 0, proc.stderr
    warnings = json.loads(summary.read_text())["warnings"]
    assert any("--focal-length-unit mm" in w for w in warnings)
    assert [ln for ln in proc.stdout.splitlines() if "--focal-length-unit" in ln] == [
        f"  warning: {w}" for w in warnings if "--focal-length-unit" in w
    ]
    assert {m.focal_length_mm for m in _shot_frames(out)} == {5000.0}

    proc = run_cli("convert", path, "-o", out, "--summary", summary, "--focal-length-unit", "mm")
    assert proc.returncode == 0, proc.stderr
    assert not any("focal" in w for w in json.loads(summary.read_text())["warnings"])
    assert {m.focal_length_mm for m in _shot_frames(out)} == {50.0}


def test_plausible_lenses_give_no_warning(tmp_path: Path) -> None:
    for name, mpu, value in (("m.usda", 1.0, 0.5), ("cm.usda", 0.01, 50.0), ("mm.usda", 0.001,
                                                                              500.0)):
        stage = _stage(tmp_path / name, tcps=24.0, fps=24.0, start=1.0, end=2.0, mpu=mpu)
        UsdGeom.Camera.Define(stage, "/cam").GetFocalLengthAttr().Set(value)
        shot = read_shot(_save(stage))
        np.testing.assert_allclose(shot.focal_length_mm, 50.0, rtol=1e-6)
        assert shot.warnings == ()


# --------------------------------------------------------------------------------------------
# Orthographic cameras and sheared parents


def test_orthographic_camera_warns(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "ortho.usda", tcps=24.0, fps=24.0, start=1.0, end=2.0)
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.GetProjectionAttr().Set(UsdGeom.Tokens.orthographic)
    cam.GetFocalLengthAttr().Set(0.5)  # a plausible 50 mm: the only note is the projection
    (warning,) = read_shot(_save(stage)).warnings
    assert "/cam is orthographic" in warning
    assert "\n" not in warning


def _view_angles(parent_scale: tuple[float, float, float], tilt: float) -> float:
    """Angle [deg] between the rendered and the orthonormalised view, by hand (scipy polar)."""
    a = math.radians(tilt)
    rot = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    m = np.diag(parent_scale) @ rot  # world = parent scale . camera rotateX
    rendered = m @ [0.0, 0.0, -1.0]
    rendered /= np.linalg.norm(rendered)
    polar, _ = scipy.linalg.polar(m)
    ortho = polar @ [0.0, 0.0, -1.0]
    return math.degrees(math.acos(np.clip(rendered @ ortho, -1.0, 1.0)))


@pytest.mark.parametrize(("scale", "tilt"), [((1.0, 3.0, 1.0), 45.0), ((1.0, 1.0, 2.0), 30.0)])
def test_sheared_or_non_uniformly_scaled_parent_warns_with_the_angle(
    tmp_path: Path, scale: tuple[float, float, float], tilt: float
) -> None:
    stage = _stage(tmp_path / "shear.usda", tcps=24.0, fps=24.0, start=1.0, end=3.0)
    rig = UsdGeom.Xform.Define(stage, "/rig")
    rig.AddScaleOp().Set(Gf.Vec3f(*scale))
    cam = UsdGeom.Camera.Define(stage, "/rig/cam")
    cam.GetFocalLengthAttr().Set(0.35)
    tilt_op = cam.AddRotateXOp()
    for f in (1, 2, 3):
        tilt_op.Set(tilt * f / 3.0, float(f))
    (warning,) = read_shot(_save(stage)).warnings
    found = re.search(r"differs from the orthonormalised pose .* by up to ([0-9.]+) deg "
                      r"\(frame (\d+)\)", warning)
    assert found, warning
    angles = [_view_angles(scale, tilt * f / 3.0) for f in (1, 2, 3)]
    assert max(angles) > 1.0
    assert float(found[1]) == pytest.approx(max(angles), abs=0.05)
    assert int(found[2]) == 1 + int(np.argmax(angles))


def test_uniform_parent_scale_and_camera_scale_give_no_shear_warning(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "scaled.usda", tcps=24.0, fps=24.0, start=1.0, end=2.0)
    rig = UsdGeom.Xform.Define(stage, "/rig")
    rig.AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 2.0))
    rig.AddRotateZOp().Set(20.0)
    cam = UsdGeom.Camera.Define(stage, "/rig/cam")
    cam.AddRotateXYZOp().Set(Gf.Vec3f(70.0, 10.0, -80.0))
    cam.AddScaleOp().Set(Gf.Vec3f(1.0, 2.0, 3.0))  # its own scale keeps its view direction
    cam.GetFocalLengthAttr().Set(0.35)
    assert read_shot(_save(stage)).warnings == ()


# --------------------------------------------------------------------------------------------
# Absurd ranges and rates are bounded


@pytest.mark.parametrize(("tcps", "fps", "end"), [(24.0, 24.0, 1e300), (24.0, 1e12, 48.0)])
def test_huge_frame_counts_are_refused(tmp_path: Path, tcps: float, fps: float,
                                       end: float) -> None:
    stage = _stage(tmp_path / "huge.usda", tcps=tcps, fps=fps, start=1.0, end=end)
    UsdGeom.Camera.Define(stage, "/cam")
    with pytest.raises(ShotFileError, match=r"at most 100000"):
        read_shot(_save(stage))


def test_frame_numbers_beyond_32_bits_are_refused(tmp_path: Path) -> None:
    stage = _stage(tmp_path / "far.usda", tcps=24.0, fps=24.0, start=1e30, end=1e30 + 2.0)
    UsdGeom.Camera.Define(stage, "/cam")
    with pytest.raises(ShotFileError, match=r"32-bit"):
        read_shot(_save(stage))
