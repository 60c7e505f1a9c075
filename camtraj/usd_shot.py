"""Read stage: a camera move out of a USD shot, per film frame, in metres and Z-up.

This is the first stage of the pipeline (design.md §1–2). It opens a USD stage, picks its
camera, samples the camera's *world* transform (animated parents included) at every frame of
the shot and converts it to SI units and a Z-up world:

* ``metersPerUnit`` scales translations to metres (Maya writes centimetres, 0.01; Blender
  metres, 1). An unauthored value means USD's fallback, centimetres.
* ``upAxis`` ``"Y"`` stages are rotated to Z-up with ``YUP2ZUP`` (+90° about X: stage Y
  becomes Z, stage Z becomes -Y); an unauthored ``upAxis`` means USD's fallback, Y. The
  camera's *local* frame keeps the USD convention: it looks down its local -Z with +Y up.
* USD matrices use row vectors (translation in the last row); here every transform is a
  column-vector 4x4 with the translation in the last column.
* Scale is removed from the camera's rotation (polar decomposition); a mirrored (negative
  determinant) or degenerate transform is an error.

Lens units follow the UsdGeom.Camera schema ("Units of Measure for Camera Properties"):
``focalLength`` (like the apertures) is in *tenths of a scene unit*, so on a centimetre stage
``50`` is 50 mm and on a metre stage a 50 mm lens is authored as ``0.5``. Hence
``focal_length_mm = focalLength * metersPerUnit * 100``. ``focusDistance`` is in plain scene
units. ``fStop`` is unitless; 0 means unset (a pinhole, no depth of field) and is kept as 0.

Every read failure is a :class:`~camtraj.errors.ShotFileError` with a one-line message; USD's
own errors (``pxr.Tf.ErrorException``) never escape, and its warnings (for example a missing
referenced set file) are trapped and passed to this module's logger instead of stderr.
"""

from __future__ import annotations

import contextlib
import logging
import math
import operator
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pxr import Sdf, Tf, Usd, UsdGeom

from camtraj.errors import ShotFileError, frame_ranges

__all__ = ["YUP2ZUP", "Shot", "list_cameras", "read_shot"]

logger = logging.getLogger(__name__)

YUP2ZUP: NDArray[np.float64] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""(3, 3) rotation from Y-up stage coordinates to Z-up: +90° about X."""
YUP2ZUP.setflags(write=False)

_CRATE_MAGIC = b"PXR-USDC"
_TEXT_MAGIC = b"#usda"
_ZIP_MAGIC = b"PK\x03\x04"
_SUPPORTED_UP_AXES = ("Y", "Z")
# Relative tolerance on singular values: below this the camera transform has (nearly) zero scale.
_DEGENERATE_SCALE = 1e-9


@dataclass(frozen=True)
class Shot:
    """A camera move sampled at every film frame, in metres, Z-up world.

    The arrays are read-only copies. ``n`` is the number of sampled frames.

    Attributes:
        source: The shot file path as given to :func:`read_shot`.
        camera_path: Prim path of the camera used, e.g. ``"/shotCam"``.
        frames: (n,) film frame numbers: the sampled USD time codes rounded to integers
            (consecutive when ``timeCodesPerSecond == framesPerSecond``, the usual case).
        time_codes: (n,) the USD time codes sampled.
        times: (n,) time in [s] from the first sampled frame:
            ``(time_codes - time_codes[0]) / timeCodesPerSecond``.
        fps: Frames per second of the shot (the stage's ``framesPerSecond`` if authored,
            else its ``timeCodesPerSecond``).
        cam2world: (n, 4, 4) camera pose in the converted world (metres, Z-up), column-vector
            convention; the rotation is orthonormal with determinant +1 (scale removed). The
            camera looks down its local -Z axis with local +Y up.
        focal_length_mm: (n,) focal length in [mm].
        focus_distance_m: (n,) focus distance in [m]; 0 when unset.
        f_stop: (n,) f-number; 0 when unset (pinhole).
        meters_per_unit: The stage's ``metersPerUnit`` (scene unit length in [m]).
        up_axis: The stage's up axis, ``"Y"`` or ``"Z"``.
        time_codes_per_second: The stage's ``timeCodesPerSecond``.
        horizontal_aperture_mm: (n,) film back width in [mm].
        vertical_aperture_mm: (n,) film back height in [mm].
        clipping_range_m: (n, 2) near and far clipping distances in [m].
    """

    source: str
    camera_path: str
    frames: NDArray[np.int64]
    time_codes: NDArray[np.float64]
    times: NDArray[np.float64]
    fps: float
    cam2world: NDArray[np.float64]
    focal_length_mm: NDArray[np.float64]
    focus_distance_m: NDArray[np.float64]
    f_stop: NDArray[np.float64]
    meters_per_unit: float
    up_axis: str
    time_codes_per_second: float
    horizontal_aperture_mm: NDArray[np.float64]
    vertical_aperture_mm: NDArray[np.float64]
    clipping_range_m: NDArray[np.float64]

    def __post_init__(self) -> None:
        n = len(self.frames)
        shapes: dict[str, tuple[int, ...]] = {
            "frames": (n,),
            "time_codes": (n,),
            "times": (n,),
            "cam2world": (n, 4, 4),
            "focal_length_mm": (n,),
            "focus_distance_m": (n,),
            "f_stop": (n,),
            "horizontal_aperture_mm": (n,),
            "vertical_aperture_mm": (n,),
            "clipping_range_m": (n, 2),
        }
        for name, shape in shapes.items():
            dtype = np.int64 if name == "frames" else np.float64
            value = np.array(getattr(self, name), dtype=dtype)
            if value.shape != shape:
                msg = f"Shot.{name} has shape {value.shape}, expected {shape}"
                raise ValueError(msg)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if self.up_axis not in _SUPPORTED_UP_AXES:
            msg = f"Shot.up_axis must be 'Y' or 'Z', not {self.up_axis!r}"
            raise ValueError(msg)

    @property
    def n_frames(self) -> int:
        """Number of sampled frames."""
        return len(self.frames)


def list_cameras(path: str | Path) -> list[str]:
    """Prim paths of every UsdGeom.Camera on a stage, in stage traversal order.

    Args:
        path: A USD file (``.usd``, ``.usda``, ``.usdc``, ``.usdz``).

    Returns:
        The camera prim paths, e.g. ``["/World/cam_A", "/World/cam_B"]``; empty if none.

    Raises:
        ShotFileError: The file is missing or is not a readable USD stage.
    """
    p = Path(path)
    with _usd_diagnostics(p):
        stage = _open_stage(p)
        return _camera_paths(stage)


def read_shot(
    path: str | Path,
    camera: str | None = None,
    frames: tuple[int, int] | None = None,
) -> Shot:
    """Read a camera's move from a USD shot, one sample per film frame.

    Args:
        path: A USD file (``.usd``, ``.usda``, ``.usdc``, ``.usdz``).
        camera: Prim path of the camera, e.g. ``"/shotCam"``. Without one the stage must have
            exactly one UsdGeom.Camera.
        frames: Inclusive ``(first, last)`` time codes to read, inside the stage's
            ``startTimeCode``/``endTimeCode``. Default: the whole authored range. A stage
            with no authored range uses the span of the camera's (and its ancestors')
            transform time samples.

    Returns:
        The sampled :class:`Shot`; the sampling step is ``timeCodesPerSecond /
        framesPerSecond`` time codes (normally 1).

    Raises:
        ShotFileError: Missing or unreadable file, no/ambiguous/unknown camera, unsupported
            ``upAxis`` or ``metersPerUnit``, a bad frame range, or a camera transform or lens
            value that is not finite, mirrored or degenerate at some frame (the message names
            the frame).
    """
    p = Path(path)
    with _usd_diagnostics(p):
        stage = _open_stage(p)
        try:
            return _read(stage, p, str(path), camera, frames)
        except Tf.ErrorException as exc:
            msg = f"{p}: USD failed while reading the shot: {_tf_detail(exc)}"
            raise ShotFileError(msg) from None


# --------------------------------------------------------------------------------------------
# Opening the stage


def _open_stage(path: Path) -> Any:
    """Open ``path`` as a USD stage, turning every failure into a one-line ShotFileError."""
    if not path.exists():
        msg = f"{path}: no such file"
        raise ShotFileError(msg)
    if path.is_dir():
        msg = f"{path}: is a directory, not a USD file"
        raise ShotFileError(msg)
    try:
        with path.open("rb") as f:
            head = f.read(8)
    except OSError as exc:
        msg = f"{path}: cannot read: {exc.strerror or exc}"
        raise ShotFileError(msg) from None
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise ShotFileError(_open_error_message(path, head, exc)) from None
    if not stage:
        msg = f"{path}: USD could not open the file"
        raise ShotFileError(msg)
    return stage


def _open_error_message(path: Path, head: bytes, exc: Exception) -> str:
    """One line saying what kind of file ``path`` looks like and USD's root cause."""
    if not head:
        kind = "the file is empty, not a USD stage"
    elif head.startswith(_CRATE_MAGIC):
        kind = "corrupt or truncated USD binary (usdc) file"
    elif head.startswith(_TEXT_MAGIC):
        kind = "USD text (usda) file with a syntax error"
    elif head.startswith(_ZIP_MAGIC):
        kind = "unreadable usdz package"
    else:
        kind = "not a USD file (it starts with neither '#usda' nor the usdc signature)"
    detail = _tf_detail(exc, skip_generic=True)
    # "/abs/shot.usda:25:48: parse error matching <C++ grammar rule> at '{' in </cam>"
    # -> "line 25, column 48: parse error at '{' in </cam>"
    where = _PARSE_LOCATION.match(detail)
    if where and Path(where["file"]).name == path.name:
        detail = f"line {where['line']}, column {where['col']}: {detail[where.end() :]}"
    detail = _PARSER_RULE.sub("parse error at ", detail)
    return f"{path}: {kind}" + (f": {detail}" if detail else "")


_GENERIC_OPEN_FAILURE = re.compile(r"^Failed to open layer @.*@$")
_PARSE_LOCATION = re.compile(r"^(?P<file>.+?):(?P<line>\d+):(?P<col>\d+): ")
_STAGE_POINTER = re.compile(r"\s*\(instantiating stage on stage @[^@]*@ <0x[0-9a-fA-F]+>\)")
_PARSER_RULE = re.compile(r"parse error matching .*? at (?=')")


def _tf_detail(exc: Exception, *, skip_generic: bool = False) -> str:
    """USD's own error text from a Tf.ErrorException, collapsed to one line.

    The first (innermost) error is the root cause; ``skip_generic`` drops USD's closing
    "Failed to open layer" which adds nothing to the file name already in the message.
    """
    texts = []
    for arg in exc.args:
        text = " ".join(str(getattr(arg, "commentary", arg)).split())
        if not text or (skip_generic and _GENERIC_OPEN_FAILURE.match(text)):
            continue
        texts.append(text)
    return texts[0] if texts else ""


@contextlib.contextmanager
def _usd_diagnostics(path: Path) -> Iterator[None]:
    """Keep USD's warnings and status messages off stderr; send warnings to the logger.

    Errors still raise ``Tf.ErrorException`` inside the block (callers convert them).
    ``Tf.DiagnosticTrap`` is new in OpenUSD 25.x; with older USD this does nothing.
    """
    trap_type = getattr(Tf, "DiagnosticTrap", None)
    if trap_type is None:
        yield
        return
    with trap_type() as trap:
        try:
            yield
        finally:
            for warning in trap.GetWarnings():
                text = _STAGE_POINTER.sub("", " ".join(str(warning.commentary).split()))
                logger.warning("%s: USD warning: %s", path, text)
            trap.Clear()


# --------------------------------------------------------------------------------------------
# Reading


def _read(
    stage: Any,
    path: Path,
    source: str,
    camera: str | None,
    frames: tuple[int, int] | None,
) -> Shot:
    up_axis = str(UsdGeom.GetStageUpAxis(stage))
    if up_axis not in _SUPPORTED_UP_AXES:
        msg = f"{path}: unsupported upAxis {up_axis!r}; only 'Y' and 'Z' stages can be read"
        raise ShotFileError(msg)
    if not stage.HasAuthoredMetadata("metersPerUnit"):
        logger.warning(
            "%s: metersPerUnit is not authored; using USD's fallback 0.01 (centimetres)", path
        )
    meters_per_unit = float(UsdGeom.GetStageMetersPerUnit(stage))
    if not (math.isfinite(meters_per_unit) and meters_per_unit > 0.0):
        msg = f"{path}: metersPerUnit must be a positive number, not {meters_per_unit}"
        raise ShotFileError(msg)

    prim = _select_camera(stage, path, camera)
    cam_path = str(prim.GetPath())

    tcps = float(stage.GetTimeCodesPerSecond())
    fps = (
        float(stage.GetFramesPerSecond()) if stage.HasAuthoredMetadata("framesPerSecond") else tcps
    )
    for name, rate in (("timeCodesPerSecond", tcps), ("framesPerSecond", fps)):
        if not (math.isfinite(rate) and rate > 0.0):
            msg = f"{path}: {name} must be a positive number, not {rate}"
            raise ShotFileError(msg)

    time_codes = _time_codes(stage, path, prim, frames, step=tcps / fps)
    frame_numbers = np.rint(time_codes).astype(np.int64)

    cam2world = _world_poses(prim, path, time_codes, frame_numbers, meters_per_unit, up_axis)

    cam = UsdGeom.Camera(prim)
    lens = {}
    for name, attr in (
        ("focalLength", cam.GetFocalLengthAttr()),
        ("focusDistance", cam.GetFocusDistanceAttr()),
        ("fStop", cam.GetFStopAttr()),
        ("horizontalAperture", cam.GetHorizontalApertureAttr()),
        ("verticalAperture", cam.GetVerticalApertureAttr()),
        ("clippingRange", cam.GetClippingRangeAttr()),
    ):
        values = _sample_attribute(attr, time_codes, 2 if name == "clippingRange" else 0)
        bad = ~np.isfinite(values.reshape(len(time_codes), -1)).all(axis=1)
        if bad.any():
            msg = f"{path}: camera {cam_path} has no finite {name} {_where(frame_numbers, bad)}"
            raise ShotFileError(msg)
        lens[name] = values

    return Shot(
        source=source,
        camera_path=cam_path,
        frames=frame_numbers,
        time_codes=time_codes,
        times=(time_codes - time_codes[0]) / tcps,
        fps=fps,
        cam2world=cam2world,
        # Tenths of a scene unit -> scene units (/10) -> metres (*mpu) -> millimetres (*1000).
        focal_length_mm=lens["focalLength"] * meters_per_unit * 100.0,
        focus_distance_m=lens["focusDistance"] * meters_per_unit,
        f_stop=lens["fStop"],
        meters_per_unit=meters_per_unit,
        up_axis=up_axis,
        time_codes_per_second=tcps,
        # Apertures are in tenths of a scene unit, like the focal length.
        horizontal_aperture_mm=lens["horizontalAperture"] * meters_per_unit * 100.0,
        vertical_aperture_mm=lens["verticalAperture"] * meters_per_unit * 100.0,
        clipping_range_m=lens["clippingRange"] * meters_per_unit,
    )


def _camera_paths(stage: Any) -> list[str]:
    """Prim paths of the cameras on ``stage`` (active, defined, loaded; instances included)."""
    predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    return [str(p.GetPath()) for p in stage.Traverse(predicate) if p.IsA(UsdGeom.Camera)]


def _camera_list(paths: list[str]) -> str:
    return ", ".join(paths) if paths else "none"


def _select_camera(stage: Any, path: Path, camera: str | None) -> Any:
    """The camera prim: the one asked for, else the stage's only camera."""
    found = _camera_paths(stage)
    if camera is None:
        if len(found) == 1:
            return stage.GetPrimAtPath(found[0])
        if not found:
            msg = f"{path}: no camera (UsdGeom.Camera prim) on the stage"
        else:
            msg = (
                f"{path}: {len(found)} cameras on the stage, choose one by prim path: "
                f"{_camera_list(found)}"
            )
        raise ShotFileError(msg)

    if not (
        Sdf.Path.IsValidPathString(camera)
        and Sdf.Path(camera).IsAbsolutePath()
        and Sdf.Path(camera).IsPrimPath()
    ):
        msg = (
            f"{path}: {camera!r} is not an absolute prim path; cameras on the stage: "
            f"{_camera_list(found)}"
        )
        raise ShotFileError(msg)
    prim = stage.GetPrimAtPath(camera)
    if not prim or not prim.IsActive() or not prim.IsDefined():
        msg = f"{path}: no camera at {camera}; cameras on the stage: {_camera_list(found)}"
        raise ShotFileError(msg)
    if not prim.IsA(UsdGeom.Camera):
        kind = str(prim.GetTypeName()) or "typeless prim"
        msg = (
            f"{path}: {camera} is a {kind}, not a Camera; cameras on the stage: "
            f"{_camera_list(found)}"
        )
        raise ShotFileError(msg)
    return prim


def _time_codes(
    stage: Any,
    path: Path,
    prim: Any,
    frames: tuple[int, int] | None,
    *,
    step: float,
) -> NDArray[np.float64]:
    """(n,) time codes to sample: ``first, first + step, ...`` up to ``last`` inclusive."""
    authored: tuple[float, float] | None
    if stage.HasAuthoredTimeCodeRange():
        authored = (float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode()))
        what = "authored range"
    else:
        authored = _sample_span(prim)
        what = "animated range (the stage has no startTimeCode/endTimeCode)"
    if authored is not None and not (authored[0] <= authored[1]):
        msg = f"{path}: startTimeCode {_fmt(authored[0])} is after endTimeCode {_fmt(authored[1])}"
        raise ShotFileError(msg)

    if frames is None:
        if authored is None:
            msg = (
                f"{path}: no frame range: the stage has no startTimeCode/endTimeCode and the "
                "camera is not animated; give the frames to read"
            )
            raise ShotFileError(msg)
        first, last = authored
    else:
        try:
            first, last = (float(operator.index(f)) for f in frames)
        except (TypeError, ValueError):
            msg = f"frame range must be two integers (first, last), not {frames!r}"
            raise ShotFileError(msg) from None
        if first > last:
            msg = f"{path}: frame range {_fmt(first)}-{_fmt(last)} is backwards (first > last)"
            raise ShotFileError(msg)
        if authored is not None and (first < authored[0] - 1e-9 or last > authored[1] + 1e-9):
            msg = (
                f"{path}: frames {_fmt(first)}-{_fmt(last)} are outside the shot's {what} "
                f"{_fmt(authored[0])}-{_fmt(authored[1])}"
            )
            raise ShotFileError(msg)

    n = math.floor((last - first) / step + 1e-9) + 1
    return first + step * np.arange(n, dtype=np.float64)


def _sample_span(prim: Any) -> tuple[float, float] | None:
    """First and last time sample of the transform ops of ``prim`` and its ancestors."""
    times: list[float] = []
    p = prim
    while p and not p.IsPseudoRoot():
        xformable = UsdGeom.Xformable(p)
        if xformable:
            times.extend(xformable.GetTimeSamples())
        p = p.GetParent()
    if not times:
        return None
    return min(times), max(times)


def _world_poses(
    prim: Any,
    path: Path,
    time_codes: NDArray[np.float64],
    frames: NDArray[np.int64],
    meters_per_unit: float,
    up_axis: str,
) -> NDArray[np.float64]:
    """(n, 4, 4) cam2world in metres, Z-up, column vectors, scale removed."""
    n = len(time_codes)
    rows = np.empty((n, 4, 4))
    cache = UsdGeom.XformCache()
    for i, tc in enumerate(time_codes):
        cache.SetTime(Usd.TimeCode(float(tc)))
        rows[i] = cache.GetLocalToWorldTransform(prim)
    cam2stage = np.transpose(rows, (0, 2, 1))  # row-vector USD -> column-vector convention
    cam_path = prim.GetPath()

    bad = ~np.isfinite(cam2stage).all(axis=(1, 2))
    if bad.any():
        msg = (
            f"{path}: camera {cam_path} has a non-finite (NaN or infinite) world transform "
            f"{_where(frames, bad)}"
        )
        raise ShotFileError(msg)
    bad = np.abs(cam2stage[:, 3, :] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 1e-9
    if bad.any():
        msg = (
            f"{path}: camera {cam_path} has a projective (non-affine) world transform "
            f"{_where(frames, bad)}"
        )
        raise ShotFileError(msg)

    linear = cam2stage[:, :3, :3]
    u, s, vt = np.linalg.svd(linear)
    bad = s[:, -1] <= _DEGENERATE_SCALE * np.maximum(s[:, 0], 1e-300)
    if bad.any():
        msg = (
            f"{path}: camera {cam_path} has a degenerate (zero-scale) world transform "
            f"{_where(frames, bad)}"
        )
        raise ShotFileError(msg)
    bad = np.linalg.det(linear) < 0.0
    if bad.any():
        msg = (
            f"{path}: camera {cam_path} has a mirrored (negative-scale) world transform "
            f"{_where(frames, bad)}; a real camera cannot follow it"
        )
        raise ShotFileError(msg)

    rotation = u @ vt  # nearest rotation: the polar factor, scale and shear removed
    translation = cam2stage[:, :3, 3] * meters_per_unit
    if up_axis == "Y":
        rotation = YUP2ZUP @ rotation
        translation = translation @ YUP2ZUP.T
    cam2world = np.zeros((n, 4, 4))
    cam2world[:, :3, :3] = rotation
    cam2world[:, :3, 3] = translation
    cam2world[:, 3, 3] = 1.0
    return cam2world


def _sample_attribute(
    attr: Any, time_codes: NDArray[np.float64], width: int = 0
) -> NDArray[np.float64]:
    """(n,) values of a scalar attribute, or (n, width) of a vector one; NaN where unset."""
    query = Usd.AttributeQuery(attr)
    values = np.full((len(time_codes), width) if width else len(time_codes), np.nan)
    for i, tc in enumerate(time_codes):
        value = query.Get(Usd.TimeCode(float(tc)))
        if value is not None:
            values[i] = value
    return values


def _where(frames: NDArray[np.int64], bad: ArrayLike) -> str:
    """'at frame 12' or 'at frame 12 (4 frames in all: frames 12-15)'.

    Args:
        frames: (n,) film frame numbers.
        bad: (n,) bool, True on the frames to name (at least one).
    """
    hits = [int(f) for f in frames[np.asarray(bad, dtype=bool)]]
    text = f"at frame {hits[0]}"
    if len(hits) > 1:
        text += f" ({len(hits)} frames in all: {frame_ranges(hits)})"
    return text


def _fmt(value: float) -> str:
    """A time code as text: '1001' for whole numbers, else '1001.5'."""
    return str(int(value)) if float(value).is_integer() else repr(float(value))
