"""Small USD shots for the placement and collision tests, written with pxr directly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from pxr import Gf, Sdf, Usd, UsdGeom

from camtraj.robot import Robot
from tests.conftest import rot_y, rot_z

Array = NDArray[np.float64]
ZUP2YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def base_move(robot: Robot, n: int = 32) -> Array:
    """A gentle move in the robot base frame (camera poses (n, 4, 4)): half a metre along the
    track with a drift, a crane, a pan and a tilt, eased in and out (1.3 s at 24 fps)."""
    s = np.linspace(0.0, 1.0, n)
    ease = 0.5 - 0.5 * np.cos(np.pi * s)
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    out = np.zeros((n, 4, 4))
    for i in range(n):
        out[i, :3, :3] = rot_z(0.15 * np.sin(np.pi * s[i])) @ rot_y(-0.1 * ease[i]) @ look
        out[i, :3, 3] = (4.5 + 0.5 * ease[i], 0.2 * np.sin(np.pi * s[i]), 0.8 + 0.2 * ease[i])
        out[i, 3, 3] = 1.0
    return out


def placement(x: float, y: float, yaw_deg: float, z: float = 0.0) -> Array:
    T = np.eye(4)
    T[:3, :3] = rot_z(np.radians(yaw_deg))
    T[:3, 3] = (x, y, z)
    return T


def to_stage(T: Array, up_axis: str, mpu: float) -> Array:
    """A converted-world (Z-up, metres) transform as the stage's own (column-vector) matrix."""
    S = np.eye(4)
    if up_axis == "Y":
        S[:3, :3] = ZUP2YUP
    S = S @ T
    S[:3, 3] /= mpu
    return S


def write_shot(path: Path, cam2world: Array, *, up_axis: str = "Z", mpu: float = 1.0,
               fps: float = 24.0, boxes: dict[str, tuple[Array, tuple[float, float, float]]]
               | None = None) -> Path:
    """A stage with one camera following ``cam2world`` (converted world) from frame 1, and
    optional Cube obstacles ``name -> (centre2world transform, (sx, sy, sz) edge lengths [m])``."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, mpu)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    n = cam2world.shape[0]
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(n)
    UsdGeom.Xform.Define(stage, "/World")
    cam = UsdGeom.Camera.Define(stage, "/World/cam")
    cam.CreateFocalLengthAttr(35.0 / (mpu * 100.0))
    op = cam.AddTransformOp()
    for i in range(n):
        M = to_stage(cam2world[i], up_axis, mpu)
        op.Set(Gf.Matrix4d(M.T.tolist()), Usd.TimeCode(i + 1))
    for name, (T, size) in (boxes or {}).items():
        cube = UsdGeom.Cube.Define(stage, Sdf.Path(f"/World/set/{name}"))
        cube.CreateSizeAttr(1.0)
        M = to_stage(T, up_axis, mpu)
        M[:3, :3] = M[:3, :3] @ np.diag(np.asarray(size) / mpu)
        cube.AddTransformOp().Set(Gf.Matrix4d(M.T.tolist()))
    stage.GetRootLayer().Save()
    return path
