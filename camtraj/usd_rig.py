"""The rig back in the previs stage: a USD layer with the robot driving the shot's move.

The layer is meant to be sublayered onto the shot (or opened beside it in usdview): it has the
shot's ``metersPerUnit``, ``upAxis``, ``timeCodesPerSecond``, ``framesPerSecond`` and the
converted frame range as ``startTimeCode``/``endTimeCode``, so nothing is rescaled or retimed
when it is composed. Everything lives under one prim, ``/camtraj_rig`` (the layer's
``defaultPrim``), so it never collides with the shot's own prims.

The prims mirror the robot's frame tree (:mod:`camtraj.urdf`), nested parent to child::

    /camtraj_rig                      base_link, placed in the stage by the placement
      link0/track_axis/link1/rotate_axis/.../link8
        camtraj_camera                UsdGeom.Camera on the flange (camera2flange)

Fixed edges carry one ``xformOp:transform``; each moving joint carries one animated op, a
``xformOp:rotateZ`` [deg] or a ``xformOp:translate`` along z, with a time sample at every
converted film frame's time code, from the solved joints. So the camera's world pose at a time
code is the forward kinematics of the solution at that frame, placed and converted to the
stage's units and up axis. ``camtraj_camera`` carries the shot's lens (focal length, apertures,
lens shift, clipping range, f-stop, focus distance), animated where the shot's lens is; with a
lens file, the focal length, focus distance and f-stop the lens's motors give instead. The
lens shift (``horizontalApertureOffset``/``verticalApertureOffset``, authored only when the
shot has one) is the principal point offset the MCAP's CameraInfo carries.

The solids are the URDF's visuals (:func:`camtraj.urdf.robot_solids`): UsdGeom.Cube (size 1,
scaled) and UsdGeom.Cylinder (axis z) with a display colour. The camera body and lens sit on
``camtraj_camera`` itself and have purpose ``guide``, so looking through the camera (or
rendering it) does not look out through the inside of the lens; usdview shows them with
"Display Guide" on.

All transforms in the layer are rigid, with translations in stage units: the metre-based robot
frames are conjugated by the unit scale, so no prim carries a scale except the boxes' own.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

from camtraj.errors import InputError
from camtraj.robot import Robot
from camtraj.urdf import (
    BASE_FRAME,
    CAMERA_FRAME,
    MATERIALS,
    Solid,
    joint_axes,
    robot_solids,
    static_transforms,
)
from camtraj.usd_shot import YUP2ZUP, Shot

Array = NDArray[np.float64]

__all__ = [
    "CAMERA_NAME",
    "RIG_ROOT",
    "RIG_SUFFIXES",
    "build_rig_layer",
    "check_rig_path",
    "rig_layer_bytes",
]

RIG_ROOT = "/camtraj_rig"
"""Path of the rig's root prim (the robot base, ``base_link``) in the layer."""
CAMERA_NAME = "camtraj_camera"
"""Name of the UsdGeom.Camera prim on the flange."""
RIG_SUFFIXES = (".usda", ".usd", ".usdc")
"""File name endings the rig layer can be written as (``.usd`` is binary, like ``.usdc``)."""


def world2stage(shot: Shot) -> Array:
    """(3, 3) rotation from camtraj's Z-up world to the shot's stage axes (no scale)."""
    out: Array = YUP2ZUP.T.copy() if shot.up_axis == "Y" else np.eye(3)
    return out


def _in_stage_units(T: ArrayLike, units_per_m: float) -> Gf.Matrix4d:
    """A rigid metre transform (4, 4) as a USD row-vector matrix in stage units."""
    M = np.array(T, dtype=float)
    M[:3, 3] *= units_per_m
    return Gf.Matrix4d(M.T.tolist())


def _frame_tree(robot: Robot) -> dict[str, list[tuple[str, Any]]]:
    """parent frame -> [(child frame, fixed child2parent (4, 4) or the joint's JointAxis)]."""
    tree: dict[str, list[tuple[str, Any]]] = {}
    for tr in static_transforms(robot):
        tree.setdefault(tr.parent, []).append((tr.child, tr.child2parent))
    for axis in joint_axes(robot):
        tree.setdefault(axis.parent, []).append((axis.child, axis))
    return tree


def _author_visual(stage: Any, path: Sdf.Path, visual: Solid, units_per_m: float,
                   purpose: str | None) -> None:
    k = units_per_m
    if visual.shape == "box":
        gprim: Any = UsdGeom.Cube.Define(stage, path)
        gprim.CreateSizeAttr(1.0)
        gprim.CreateExtentAttr(Vt.Vec3fArray([(-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)]))
        gprim.AddTranslateOp().Set(Gf.Vec3d(*(k * v for v in visual.xyz)))
        gprim.AddScaleOp().Set(Gf.Vec3f(*(k * v for v in visual.size)))
    else:
        radius, length = k * visual.size[0], k * visual.size[1]
        gprim = UsdGeom.Cylinder.Define(stage, path)
        gprim.CreateRadiusAttr(radius)
        gprim.CreateHeightAttr(length)
        gprim.CreateAxisAttr(UsdGeom.Tokens.z)
        gprim.CreateExtentAttr(
            Vt.Vec3fArray([(-radius, -radius, -length / 2), (radius, radius, length / 2)])
        )
        gprim.AddTranslateOp().Set(Gf.Vec3d(*(k * v for v in visual.xyz)))
    rgba = MATERIALS[visual.material]
    gprim.CreateDisplayColorAttr(Vt.Vec3fArray([Gf.Vec3f(*rgba[:3])]))
    if purpose is not None:
        gprim.CreatePurposeAttr(purpose)


def _set_samples(attr: Any, time_codes: Array, values: list[Any]) -> None:
    """One time sample per time code, authored on the layer in one change block (fast)."""
    layer = attr.GetStage().GetEditTarget().GetLayer()
    path = attr.GetPath()
    with Sdf.ChangeBlock():
        for tc, value in zip(time_codes.tolist(), values, strict=True):
            layer.SetTimeSample(path, tc, value)


def _set_channel(attr: Any, values: Array, time_codes: Array) -> None:
    """A constant value as the default, else a time sample at every time code."""
    if np.all(values == values[0]):
        attr.Set(_value(values[0]))
        return
    _set_samples(attr, time_codes, [_value(v) for v in values])


def _value(v: Any) -> Any:
    return Gf.Vec2f(*map(float, v)) if np.ndim(v) else float(v)


def _author_lens(camera: Any, shot: Shot, lens: dict[str, Array] | None = None) -> None:
    tenths = 1.0 / (shot.meters_per_unit * 100.0)  # mm -> tenths of a scene unit
    per_m = 1.0 / shot.meters_per_unit
    tc = shot.time_codes
    camera.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    lens = lens or {}
    focal = lens.get("focal_length_mm", shot.focal_length_mm)
    focus = lens.get("focus_distance_m", shot.focus_distance_m)
    _set_channel(camera.CreateFocalLengthAttr(), focal * tenths, tc)
    _set_channel(camera.CreateHorizontalApertureAttr(), shot.horizontal_aperture_mm * tenths, tc)
    _set_channel(camera.CreateVerticalApertureAttr(), shot.vertical_aperture_mm * tenths, tc)
    for offset, create in ((shot.horizontal_aperture_offset_mm,
                            camera.CreateHorizontalApertureOffsetAttr),
                           (shot.vertical_aperture_offset_mm,
                            camera.CreateVerticalApertureOffsetAttr)):
        if offset is not None and np.any(offset != 0.0):
            _set_channel(create(), offset * tenths, tc)
    _set_channel(camera.CreateClippingRangeAttr(), shot.clipping_range_m * per_m, tc)
    _set_channel(camera.CreateFStopAttr(), lens.get("f_stop", shot.f_stop), tc)
    _set_channel(camera.CreateFocusDistanceAttr(), focus * per_m, tc)


def build_rig_layer(shot: Shot, robot: Robot, base2world: ArrayLike, frame_q: ArrayLike,
                    lens: dict[str, Array] | None = None) -> Any:
    """The rig layer (an anonymous ``Sdf.Layer``) for a solved shot.

    Args:
        shot: The shot as read (units, up axis, time codes, lens per frame).
        robot: The robot it was solved for.
        base2world: (4, 4) the placement: robot base into camtraj's converted world [m].
        frame_q: (n, 8) the IK solution at each of the shot's n frames [m, rad].
        lens: The lens the motors give per frame (:func:`camtraj.lens.commanded_lens`:
            ``focal_length_mm``, ``focus_distance_m``, ``f_stop``, each (n,)); None: the
            shot's.

    Returns:
        The layer; see the module docstring for its contents.
    """
    q = np.asarray(frame_q, dtype=float)
    if q.shape != (shot.n_frames, len(robot.joint_names)):
        msg = f"frame_q must have shape {(shot.n_frames, len(robot.joint_names))}, got {q.shape}"
        raise ValueError(msg)
    k = 1.0 / shot.meters_per_unit
    tc = shot.time_codes
    layer = Sdf.Layer.CreateAnonymous(".usda")
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageMetersPerUnit(stage, shot.meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if shot.up_axis == "Y" else UsdGeom.Tokens.z)
    # the shot's rates as it writes them: USD retimes a sublayer whose timeCodesPerSecond
    # differs from the stage's (59.94 against 60000/1001 put every key 1 ppm off its frame)
    tcps, fps = shot.stage_rates or (shot.time_codes_per_second, shot.fps)
    stage.SetTimeCodesPerSecond(tcps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(float(tc[0]))
    stage.SetEndTimeCode(float(tc[-1]))
    layer.documentation = (
        f"camtraj rig layer for {shot.source} (camera {shot.camera_path}): "
        f"sublayer it onto the shot; {CAMERA_NAME} follows the robot's solved move."
    )

    base2stage = np.eye(4)
    base2stage[:3, :3] = world2stage(shot)
    base2stage = base2stage @ np.asarray(base2world, dtype=float)
    root = UsdGeom.Xform.Define(stage, RIG_ROOT)
    root.AddTransformOp().Set(_in_stage_units(base2stage, k))
    stage.SetDefaultPrim(root.GetPrim())

    tree = _frame_tree(robot)
    by_frame: dict[str, list[Solid]] = {}
    for visual in robot_solids(robot):
        by_frame.setdefault(visual.frame, []).append(visual)

    def add(frame: str, path: Sdf.Path) -> None:
        for i, visual in enumerate(by_frame.get(frame, [])):
            purpose = UsdGeom.Tokens.guide if frame == CAMERA_FRAME else None
            _author_visual(stage, path.AppendChild(f"visual{i}"), visual, k, purpose)
        for child, edge in tree.get(frame, []):
            if child == CAMERA_FRAME:
                child_path = path.AppendChild(CAMERA_NAME)
                camera = UsdGeom.Camera.Define(stage, child_path)
                camera.AddTransformOp().Set(_in_stage_units(edge, k))
                _author_lens(camera, shot, lens)
            elif child not in tree and child not in by_frame:
                continue  # an empty leaf frame (camera_optical): nothing to show
            else:
                child_path = path.AppendChild(child)
                xform = UsdGeom.Xform.Define(stage, child_path)
                if isinstance(edge, np.ndarray):
                    xform.AddTransformOp().Set(_in_stage_units(edge, k))
                else:
                    _author_joint(xform, edge, q, tc, k)
            add(child, child_path)

    add(BASE_FRAME, root.GetPath())
    return layer


def _author_joint(xform: Any, axis: Any, q: Array, time_codes: Array, units_per_m: float) -> None:
    values = axis.sign * q[:, axis.joint]
    if axis.kind == "revolute":
        op = xform.AddRotateZOp(UsdGeom.XformOp.PrecisionDouble)
        samples: list[Any] = np.degrees(values).tolist()
    else:
        op = xform.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
        samples = [Gf.Vec3d(0.0, 0.0, v) for v in (units_per_m * values).tolist()]
    _set_samples(op.GetAttr(), time_codes, samples)


def rig_layer_bytes(
    path: str | Path, shot: Shot, robot: Robot, base2world: ArrayLike, frame_q: ArrayLike,
    lens: dict[str, Array] | None = None,
) -> bytes:
    """The rig layer (:func:`build_rig_layer`) as the file ``path`` names it: ``.usda`` is
    text, ``.usd`` and ``.usdc`` binary (crate). The caller writes the bytes (atomically,
    with the run's other outputs: :class:`camtraj.outputs.OutputSet`).

    Raises:
        InputError: Not a ``.usda``/``.usd``/``.usdc`` name, or USD could not export it.
    """
    path = check_rig_path(path)
    layer = build_rig_layer(shot, robot, base2world, frame_q, lens)
    if path.suffix.lower() == ".usda":
        return str(layer.ExportToString()).encode("utf-8")
    with tempfile.TemporaryDirectory(prefix="camtraj-rig-") as folder:
        scratch = Path(folder) / f"rig{path.suffix.lower()}"
        if not layer.Export(str(scratch)):
            msg = f"cannot write the rig layer {path}: USD could not export it"
            raise InputError(msg)
        return scratch.read_bytes()


def check_rig_path(path: str | Path) -> Path:
    """``path`` if its name is one of a USD layer (checked before any work is done; the
    folder and the file are checked with the run's other outputs).

    Raises:
        InputError: Not a ``.usda``/``.usd``/``.usdc`` name.
    """
    path = Path(path)
    if path.suffix.lower() not in RIG_SUFFIXES:
        msg = f"cannot write the rig layer {path}: the name must end in {', '.join(RIG_SUFFIXES)}"
        raise InputError(msg)
    return path
