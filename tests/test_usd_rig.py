"""The rig layer: composed with its shot, camtraj_camera sits where the shot camera is.

Shots are written here with pxr from a reachable move designed in the robot base frame, placed
in the stage by a placement with a yaw, in a Y-up centimetre and a Z-up metre stage. They are
converted through the public ``convert`` (so the joints come from the solver), the MCAP is
decoded, and the layer is checked by composing it with the shot in a fresh stage.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from pxr import Gf, Sdf, Usd, UsdGeom

from camtraj.convert import convert
from camtraj.errors import InputError
from camtraj.mcap_io import ReadTake, read_take
from camtraj.options import ConvertOptions
from camtraj.robot import Robot
from camtraj.urdf import LINK_FRAMES
from camtraj.usd_rig import CAMERA_NAME, RIG_ROOT
from tests.conftest import camera_path, pose_error

Array = NDArray[np.float64]

# Z-up world (X, Y, Z) -> Y-up stage (X, Z, -Y), written out here rather than imported.
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
PLACEMENT = (1.5, -0.75, 0.25, 35.0)  # x, y, z [m], yaw [deg]
N_FRAMES = 72
# Scaled timing: the joints (not the timing) are what the layer is made of.
OPTIONS = ConvertOptions(placement=PLACEMENT, timing="scale")
FIRST_FRAME = 1001
LENS = {"focal_mm": (35.0, 50.0), "h_ap_mm": 36.0, "v_ap_mm": 20.25, "clip_m": (0.05, 500.0),
        "f_stop": 2.8, "focus_m": 3.5}


def base2world() -> Array:
    x, y, z, yaw = PLACEMENT
    a = math.radians(yaw)
    T = np.eye(4)
    T[:3, :3] = [[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]]
    T[:3, 3] = (x, y, z)
    return T


def world2stage(up_axis: str, meters_per_unit: float) -> Array:
    """Z-up metres -> stage axes and units (a similarity: rotation and scale)."""
    S = np.eye(4)
    S[:3, :3] = (ZUP_TO_YUP if up_axis == "Y" else np.eye(3)) / meters_per_unit
    return S


def write_shot(path: Path, robot: Robot, up_axis: str, meters_per_unit: float, fps: float) -> Array:
    """A shot whose camera follows a reachable move; returns cam2stage (n, 4, 4) authored."""
    flange2base = camera_path(robot, N_FRAMES)
    cam2stage = world2stage(up_axis, meters_per_unit) @ base2world() @ flange2base @ \
        robot.camera2flange
    # Rigid in stage units: undo the scale on the rotation part.
    cam2stage[:, :3, :3] *= meters_per_unit
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(FIRST_FRAME)
    stage.SetEndTimeCode(FIRST_FRAME + N_FRAMES - 1)
    UsdGeom.Xform.Define(stage, "/World")
    cam = UsdGeom.Camera.Define(stage, "/World/shotCam")
    op = cam.AddTransformOp()
    tenths = 1.0 / (meters_per_unit * 100.0)
    focal = cam.CreateFocalLengthAttr()
    for i in range(N_FRAMES):
        tc = Usd.TimeCode(FIRST_FRAME + i)
        op.Set(Gf.Matrix4d(cam2stage[i].T.tolist()), tc)
        f0, f1 = LENS["focal_mm"]
        focal.Set((f0 + (f1 - f0) * i / (N_FRAMES - 1)) * tenths, tc)
    cam.CreateHorizontalApertureAttr(LENS["h_ap_mm"] * tenths)
    cam.CreateVerticalApertureAttr(LENS["v_ap_mm"] * tenths)
    near, far = LENS["clip_m"]
    cam.CreateClippingRangeAttr(Gf.Vec2f(near / meters_per_unit, far / meters_per_unit))
    cam.CreateFStopAttr(LENS["f_stop"])
    cam.CreateFocusDistanceAttr(LENS["focus_m"] / meters_per_unit)
    stage.GetRootLayer().Save()
    return cam2stage


@dataclass
class Converted:
    shot: Path
    rig: Path
    mcap: Path
    up_axis: str
    meters_per_unit: float
    fps: float
    take: ReadTake


CASES = {"yup_cm": ("Y", 0.01, 24.0), "zup_m": ("Z", 1.0, 25.0)}


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory, robot: Robot) -> dict[str, Converted]:
    out: dict[str, Converted] = {}

    for key, (up, mpu, fps) in CASES.items():
        folder = tmp_path_factory.mktemp(key)
        shot = folder / "shot.usda"
        write_shot(shot, robot, up, mpu, fps)
        rig, mcap = folder / "shot.rig.usda", folder / "shot.mcap"
        convert(shot, mcap, OPTIONS, rig_layer=rig)
        out[key] = Converted(shot, rig, mcap, up, mpu, fps, read_take(mcap))
    return out


def composed(c: Converted) -> Usd.Stage:
    """A new stage that sublayers the rig layer and the shot, as an artist would.

    The new root layer takes the shot's timeCodesPerSecond (as the shot's own root layer has
    when the rig is sublayered onto it): with another rate USD would retime both sublayers and
    sample them between their time samples.
    """
    stage = Usd.Stage.CreateInMemory()
    stage.SetTimeCodesPerSecond(c.fps)
    stage.GetRootLayer().subLayerPaths.append(str(c.rig))
    stage.GetRootLayer().subLayerPaths.append(str(c.shot))
    return stage


def world_matrices(stage: Usd.Stage, prim_path: str, time_codes: list[float]) -> Array:
    prim = stage.GetPrimAtPath(prim_path)
    assert prim, prim_path
    cache = UsdGeom.XformCache()
    out = []
    for tc in time_codes:
        cache.SetTime(Usd.TimeCode(tc))
        out.append(np.array(cache.GetLocalToWorldTransform(prim)).T)
    return np.array(out)


def find_prim(stage: Usd.Stage, name: str) -> str:
    hits = [str(p.GetPath()) for p in stage.Traverse() if p.GetName() == name]
    assert len(hits) == 1, hits
    return hits[0]


@pytest.mark.parametrize("key", list(CASES))
def test_rig_camera_equals_shot_camera_at_every_frame(
    converted: dict[str, Converted], key: str
) -> None:
    c = converted[key]
    stage = composed(c)
    frames = [float(FIRST_FRAME + i) for i in range(N_FRAMES)]
    rig_cam = world_matrices(stage, find_prim(stage, CAMERA_NAME), frames)
    shot_cam = world_matrices(stage, "/World/shotCam", frames)
    dp, dr = pose_error(rig_cam, shot_cam)  # stage units, radians
    assert dp <= 1e-6
    assert dr <= 1e-6
    # Not trivially equal: the camera moves metres, and it is not scaled.
    assert np.ptp(rig_cam[:, :3, 3], axis=0).max() > 1.0 / c.meters_per_unit
    np.testing.assert_allclose(np.linalg.svd(rig_cam[:, :3, :3])[1], 1.0, atol=1e-12)


@pytest.mark.parametrize("key", list(CASES))
def test_layer_has_the_shot_units_axis_and_time_codes(
    converted: dict[str, Converted], key: str
) -> None:
    c = converted[key]
    layer = Sdf.Layer.FindOrOpen(str(c.rig))
    shot = Sdf.Layer.FindOrOpen(str(c.shot))
    for field in ("metersPerUnit", "upAxis", "timeCodesPerSecond", "framesPerSecond",
                  "startTimeCode", "endTimeCode"):
        assert layer.pseudoRoot.GetInfo(field) == shot.pseudoRoot.GetInfo(field), field
    assert layer.defaultPrim == RIG_ROOT.strip("/")


@pytest.mark.parametrize("key", list(CASES))
def test_link_prims_follow_fk_of_the_solved_joints(
    converted: dict[str, Converted], key: str, robot: Robot
) -> None:
    c = converted[key]
    stage = composed(c)
    q = c.take.frame_q  # decoded from the MCAP
    frames = [float(f) for f in c.take.frame_numbers]
    S = world2stage(c.up_axis, c.meters_per_unit)
    expected = S @ base2world() @ robot.link_frames(q)  # (n, 9, 4, 4), scaled
    expected[..., :3, :3] *= c.meters_per_unit  # rigid: scale only on translations
    for i, name in enumerate(LINK_FRAMES):
        got = world_matrices(stage, find_prim(stage, name), frames)
        dp, dr = pose_error(got, expected[:, i])
        assert dp <= 1e-9 / c.meters_per_unit, name
        assert dr <= 1e-9, name
    # The joints really move the links: the flange travels more than a metre.
    assert np.ptp(expected[:, -1, :3, 3], axis=0).max() > 1.0 / c.meters_per_unit


@pytest.mark.parametrize("key", list(CASES))
def test_camera_carries_the_shot_lens(converted: dict[str, Converted], key: str) -> None:
    c = converted[key]
    stage = composed(c)
    rig = UsdGeom.Camera(stage.GetPrimAtPath(find_prim(stage, CAMERA_NAME)))
    shot = UsdGeom.Camera(stage.GetPrimAtPath("/World/shotCam"))
    for i in (0, N_FRAMES // 2, N_FRAMES - 1):
        tc = Usd.TimeCode(FIRST_FRAME + i)
        a, b = rig.GetCamera(tc), shot.GetCamera(tc)
        for attr in ("focalLength", "horizontalAperture", "verticalAperture", "fStop",
                     "focusDistance"):
            assert getattr(a, attr) == pytest.approx(getattr(b, attr), rel=1e-6), attr
        for end in ("min", "max"):
            got, want = getattr(a.clippingRange, end), getattr(b.clippingRange, end)
            assert got == pytest.approx(want, rel=1e-6), end
    assert rig.GetFocalLengthAttr().GetNumTimeSamples() == N_FRAMES  # animated like the shot
    assert not rig.GetFStopAttr().GetNumTimeSamples()  # constant: one value


def test_rig_layer_opens_in_a_fresh_process(converted: dict[str, Converted], robot: Robot) -> None:
    """As a DCC would: a new Python with only pxr opens the layer file on its own."""
    c = converted["yup_cm"]
    script = textwrap.dedent(
        f"""
        import json
        from pxr import Usd, UsdGeom
        stage = Usd.Stage.Open({str(c.rig)!r})
        cams = [p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
        cache = UsdGeom.XformCache(Usd.TimeCode({FIRST_FRAME + N_FRAMES - 1}))
        m = cache.GetLocalToWorldTransform(cams[0])
        print(json.dumps({{
            "cameras": [c.GetName() for c in cams],
            "prims": len(list(stage.Traverse())),
            "default": stage.GetDefaultPrim().GetName(),
            "units": UsdGeom.GetStageMetersPerUnit(stage),
            "up": UsdGeom.GetStageUpAxis(stage),
            "range": [stage.GetStartTimeCode(), stage.GetEndTimeCode()],
            "last": [list(m.GetRow(i)) for i in range(4)],
        }}))
        """
    )
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    got = json.loads(proc.stdout)
    assert got["cameras"] == [CAMERA_NAME]
    assert got["default"] == RIG_ROOT.strip("/")
    assert got["units"] == 0.01
    assert got["up"] == "Y"
    assert got["range"] == [FIRST_FRAME, FIRST_FRAME + N_FRAMES - 1]
    assert got["prims"] > 30
    S = world2stage("Y", 0.01)
    cam = S @ base2world() @ robot.camera_pose(c.take.frame_q[-1])
    cam[:3, :3] *= 0.01
    dp, dr = pose_error(np.array(got["last"]).T, cam)
    assert dp <= 1e-6
    assert dr <= 1e-6


def test_rig_layer_is_deterministic(
    converted: dict[str, Converted], tmp_path: Path
) -> None:
    c = converted["zup_m"]
    again = tmp_path / "again.rig.usda"
    convert(c.shot, tmp_path / "again.mcap", OPTIONS,
            rig_layer=again)
    assert again.read_bytes() == c.rig.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.mcap", "again.rig.usda"]


def test_binary_rig_layer(converted: dict[str, Converted], tmp_path: Path) -> None:
    c = converted["zup_m"]
    rig = tmp_path / "rig.usdc"
    convert(c.shot, None, OPTIONS, rig_layer=rig)
    assert rig.read_bytes()[:8] == b"PXR-USDC"
    stage = Usd.Stage.Open(str(rig))
    assert stage.GetPrimAtPath(find_prim(stage, CAMERA_NAME)).IsA(UsdGeom.Camera)


def test_bad_rig_paths_fail_before_work_and_keep_old_files(
    converted: dict[str, Converted], tmp_path: Path
) -> None:
    c = converted["zup_m"]
    with pytest.raises(InputError, match=r"must end in \.usda"):
        convert(c.shot, tmp_path / "x.mcap", rig_layer=tmp_path / "rig.txt")
    (tmp_path / "a_file").write_text("not a folder")
    with pytest.raises(InputError, match="is a file, not a folder"):
        convert(c.shot, tmp_path / "x.mcap", rig_layer=tmp_path / "a_file" / "rig.usda")
    assert [p.name for p in tmp_path.iterdir()] == ["a_file"]
    before = c.shot.read_bytes()
    with pytest.raises(InputError, match="it is the shot"):
        convert(c.shot, tmp_path / "x.mcap", OPTIONS, rig_layer=c.shot)
    assert c.shot.read_bytes() == before


@pytest.mark.parametrize("key", list(CASES))
def test_rig_camera_carries_the_lens_shift_camera_info_carries(
    tmp_path: Path, robot: Robot, key: str
) -> None:
    """Issue 15 §4: a shot with a lens shift (constant across, animated up-down): the rig
    layer, read back alone with pxr, has the shot's apertureOffsets at every frame, and they
    give the principal point the MCAP's CameraInfo holds."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from camtraj.mcap_io import TOPIC_CAMERA_INFO

    up, mpu, fps = CASES[key]
    shot = tmp_path / "shift.usda"
    write_shot(shot, robot, up, mpu, fps)
    stage = Usd.Stage.Open(str(shot))
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/shotCam"))
    tenths = 1.0 / (mpu * 100.0)
    ox_mm, oy_mm = 2.5, 1.2 * np.sin(np.arange(N_FRAMES))  # oy: film shake
    cam.CreateHorizontalApertureOffsetAttr(ox_mm * tenths)
    attr = cam.CreateVerticalApertureOffsetAttr()
    for i in range(N_FRAMES):
        attr.Set(float(oy_mm[i] * tenths), Usd.TimeCode(FIRST_FRAME + i))
    stage.GetRootLayer().Save()
    rig, mcap = tmp_path / "shift.rig.usda", tmp_path / "shift.mcap"
    convert(shot, mcap, OPTIONS, rig_layer=rig)

    alone = Usd.Stage.Open(str(rig))
    got = UsdGeom.Camera(alone.GetPrimAtPath(find_prim(alone, CAMERA_NAME)))
    assert got.GetHorizontalApertureOffsetAttr().GetNumTimeSamples() == 0  # constant
    assert got.GetVerticalApertureOffsetAttr().GetNumTimeSamples() == N_FRAMES
    with mcap.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        infos = [m for _s, _c, _m, m in reader.iter_decoded_messages(
            topics=[TOPIC_CAMERA_INFO])]
    assert len(infos) == N_FRAMES
    for i, info in enumerate(infos):
        tc = Usd.TimeCode(FIRST_FRAME + i)
        gf = got.GetCamera(tc)
        want = cam.GetCamera(tc)
        assert gf.horizontalApertureOffset == pytest.approx(ox_mm * tenths, rel=1e-6)
        assert gf.verticalApertureOffset == pytest.approx(want.verticalApertureOffset,
                                                          rel=1e-6, abs=1e-9)
        # CameraInfo's principal point from the rig camera's own lens, in millimetres
        h_mm, v_mm = gf.horizontalAperture / tenths, gf.verticalAperture / tenths
        cx = info.width / 2 - gf.horizontalApertureOffset / tenths / h_mm * info.width
        cy = info.height / 2 + gf.verticalApertureOffset / tenths / v_mm * info.height
        assert (info.k[2], info.k[5]) == pytest.approx((cx, cy), abs=1e-6)


def test_info_on_a_rig_layer_says_what_it_is(converted: dict[str, Converted]) -> None:
    """A rig layer given to a command that reads MCAP files is named as camtraj's own output
    (it used to be told to convert it, as if it were a shot)."""
    rig = converted["zup_m"].rig
    with pytest.raises(InputError, match=r"is camtraj's USD rig layer \(convert --usd\), "
                                         r"not an MCAP: the take is in the MCAP written"):
        read_take(rig)
