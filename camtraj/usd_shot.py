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
Some older exporters (Blender before 3.x among them) write ``focalLength`` in millimetres
whatever the stage units; ``focal_length_unit="mm"`` reads it that way, and a focal length
that is implausible for a real lens gets a warning that says which reading would fit.

Film frames are not time codes. A stage's ``timeCodesPerSecond`` (tcps) and
``framesPerSecond`` (fps) may differ (Houdini and some Maya exports write 240 tcps at 24 fps):
film frame ``f`` is time code ``f * tcps / fps``. The shot is sampled on whole film frames
inside the stage's ``startTimeCode``/``endTimeCode`` (or, without them, inside the span of the
camera's time samples, so motion-blur sub-frame keys at f-1/4, f, f+1/4 still sample at f; one
of them alone bounds its end of that span).
Rates are exact fractions: 23.976 and 23.976023976 both mean 24000/1001, so an NTSC stage that
writes one as tcps and the other as fps keeps every frame.

Every read failure is a :class:`~camtraj.errors.ShotFileError` with a one-line message; USD's
own errors (``pxr.Tf.ErrorException``) never escape, and its warnings (for example a missing
referenced set file) are trapped and passed to this module's logger instead of stderr.
"""

from __future__ import annotations

import contextlib
import logging
import math
import numbers
import operator
import re
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pxr import Sdf, Tf, Usd, UsdGeom, UsdRender

from camtraj.choices import FOCAL_LENGTH_UNITS
from camtraj.errors import ShotFileError, frame_ranges
from camtraj.shown import frame_span

__all__ = ["YUP2ZUP", "Shot", "list_cameras", "read_shot", "stage_to_world"]

logger = logging.getLogger(__name__)

YUP2ZUP: NDArray[np.float64] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""(3, 3) rotation from Y-up stage coordinates to Z-up: +90° about X."""
YUP2ZUP.setflags(write=False)


def stage_to_world(meters_per_unit: float, up_axis: str) -> NDArray[np.float64]:
    """The linear map (3, 3) from a stage's coordinates [stage units] to the world camtraj
    works in [m, Z up]: scaled by ``metersPerUnit``, a Y-up stage turned by :data:`YUP2ZUP`
    (points of the set: obstacles, floor polygons; the camera pose is read the same way)."""
    turn = YUP2ZUP if up_axis == "Y" else np.eye(3)
    return np.asarray(turn * meters_per_unit)


_CRATE_MAGIC = b"PXR-USDC"
_TEXT_MAGIC = b"#usda"
_ZIP_MAGIC = b"PK\x03\x04"
_SUPPORTED_UP_AXES = ("Y", "Z")
MAX_FRAMES = 100_000
"""The most film frames one shot may have (69 minutes at 24 fps)."""
# Focal lengths of real cine and photo lenses [mm]: fisheyes to the longest telephotos.
_PLAUSIBLE_FOCAL_MM = (4.0, 1200.0)
# Film back widths of real cameras [mm]: small 1/4" sensors to 65 mm and 70 mm film.
_PLAUSIBLE_FILM_BACK_MM = (2.0, 80.0)
# A rendered view direction this far from the orthonormalised one is worth a warning [deg].
_SHEAR_WARN_DEG = 0.01
# ShotFrame.frame is an int32.
_MAX_FRAME_NUMBER = 2**31 - 1
# Film-frame tolerance when a time-code range is turned into whole frames (float round-off).
_FRAME_TOL = Fraction(1, 1_000_000)
# Relative tolerance on singular values: below this the camera transform has (nearly) zero scale.
_DEGENERATE_SCALE = 1e-9


@dataclass(frozen=True)
class Shot:
    """A camera move sampled at every film frame, in metres, Z-up world.

    The arrays are read-only copies. ``n`` is the number of sampled frames.

    Attributes:
        source: The shot file path as given to :func:`read_shot`.
        camera_path: Prim path of the camera used, e.g. ``"/shotCam"``.
        frames: (n,) consecutive film frame numbers (``time_code * fps / tcps``).
        time_codes: (n,) the USD time codes sampled (``frame * tcps / fps``).
        times: (n,) time in [s] from the first sampled frame: ``(frames - frames[0]) / fps``.
        fps: Frames per second of the shot (the stage's ``framesPerSecond`` if authored,
            else its ``timeCodesPerSecond``), NTSC rates exact (23.976 is 24000/1001).
        cam2world: (n, 4, 4) camera pose in the converted world (metres, Z-up), column-vector
            convention; the rotation is orthonormal with determinant +1 (scale removed). The
            camera looks down its local -Z axis with local +Y up.
        focal_length_mm: (n,) focal length in [mm].
        focus_distance_m: (n,) focus distance in [m]; 0 when unset, inf at infinity.
        f_stop: (n,) f-number; 0 when unset (pinhole).
        meters_per_unit: The stage's ``metersPerUnit`` (scene unit length in [m]).
        up_axis: The stage's up axis, ``"Y"`` or ``"Z"``.
        warnings: One-line notes about the shot that do not stop it (an implausible focal
            length or film back, lens shift or film shake, an orthographic camera, a sheared
            camera transform or parent, non-square render pixels).
        time_codes_per_second: The stage's ``timeCodesPerSecond`` (NTSC rates exact).
        stage_rates: The stage's ``timeCodesPerSecond`` and ``framesPerSecond`` exactly as
            written (None: not read from a stage). A layer composed with the shot must say
            the same: USD retimes a sublayer by the ratio of the two layers' rates.
        horizontal_aperture_mm: (n,) film back width in [mm].
        vertical_aperture_mm: (n,) film back height in [mm].
        clipping_range_m: (n, 2) near and far clipping distances in [m].
        horizontal_aperture_offset_mm: (n,) lens shift: the film back's offset from the lens
            axis, +x right [mm] (``horizontalApertureOffset``); None: zeros.
        vertical_aperture_offset_mm: (n,) the same, +y up [mm] (``verticalApertureOffset``).
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
    warnings: tuple[str, ...] = ()
    horizontal_aperture_offset_mm: NDArray[np.float64] | None = None
    vertical_aperture_offset_mm: NDArray[np.float64] | None = None
    stage_rates: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        n = len(self.frames)
        for name in ("horizontal_aperture_offset_mm", "vertical_aperture_offset_mm"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(n))
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
            "horizontal_aperture_offset_mm": (n,),
            "vertical_aperture_offset_mm": (n,),
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
    *,
    focal_length_unit: str = "schema",
) -> Shot:
    """Read a camera's move from a USD shot, one sample per film frame.

    Args:
        path: A USD file (``.usd``, ``.usda``, ``.usdc``, ``.usdz``).
        camera: Prim path of the camera, e.g. ``"/shotCam"``. Without one the stage must have
            exactly one UsdGeom.Camera.
        frames: Inclusive ``(first, last)`` film frames to read, inside the stage's
            ``startTimeCode``/``endTimeCode`` (converted to film frames). Default: every
            whole film frame of the authored range. A stage with no authored range uses the
            span of the camera's (and its ancestors') transform and lens time samples.
        focal_length_unit: ``"schema"``: ``focalLength`` is in tenths of a scene unit (the
            UsdGeom.Camera schema); ``"mm"``: it is in millimetres (older exporters).

    Returns:
        The sampled :class:`Shot`, one sample per film frame (every ``timeCodesPerSecond /
        framesPerSecond`` time codes, normally 1).

    Raises:
        ShotFileError: Missing or unreadable file, no/ambiguous/unknown camera, unsupported
            ``upAxis`` or ``metersPerUnit``, a bad frame range, or a camera transform or lens
            value that is not finite, mirrored or degenerate at some frame (the message names
            the frame).
        ValueError: An unknown ``focal_length_unit``.
    """
    if focal_length_unit not in FOCAL_LENGTH_UNITS:
        msg = (
            f"focal_length_unit must be one of {', '.join(FOCAL_LENGTH_UNITS)}, "
            f"not {focal_length_unit!r}"
        )
        raise ValueError(msg)
    p = Path(path)
    with _usd_diagnostics(p):
        stage = _open_stage(p)
        try:
            return _read(stage, p, str(path), camera, frames, focal_length_unit)
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
    focal_length_unit: str,
) -> Shot:
    up_axis = str(UsdGeom.GetStageUpAxis(stage))
    if up_axis not in _SUPPORTED_UP_AXES:
        msg = f"{path}: unsupported upAxis {up_axis!r}; only 'Y' and 'Z' stages can be read"
        raise ShotFileError(msg)
    meters_per_unit = _meters_per_unit(stage, path)

    try:
        prim = _select_camera(stage, path, camera)
    except ShotFileError as exc:
        why = _why_no_camera(stage, camera)
        if why is None:
            raise
        msg = f"{exc}; USD could not compose the stage: {why}"
        raise ShotFileError(msg) from None
    cam_path = str(prim.GetPath())
    own, parents = _composition_errors(prim, parents=False), _composition_errors(prim)
    if own:
        msg = (f"{path}: USD could not compose the camera {cam_path} as written, so its move "
               f"would be read without part of it: {own[0]}")
        raise ShotFileError(msg)
    elsewhere = [e for e in _stage_composition_errors(stage) if e not in parents]
    composition = [
        f"USD could not compose a parent of the camera {cam_path}, whose move is read without "
        f"what it would have added: {parents[0]}" if parents else None,
        f"USD could not compose part of the stage away from the camera ({len(elsewhere)} "
        f"error(s)): {elsewhere[0]}" if elsewhere else None,
    ]
    tcps = _rate(stage, path, "timeCodesPerSecond", stage.GetTimeCodesPerSecond)
    fps = (
        _rate(stage, path, "framesPerSecond", stage.GetFramesPerSecond)
        if stage.HasAuthoredMetadata("framesPerSecond")
        else tcps
    )
    written_tcps = _positive_metadata(stage, path, "timeCodesPerSecond",
                                      stage.GetTimeCodesPerSecond)
    written_fps = (_positive_metadata(stage, path, "framesPerSecond", stage.GetFramesPerSecond)
                   if stage.HasAuthoredMetadata("framesPerSecond") else written_tcps)
    frame_numbers = _film_frames(stage, path, prim, frames, frames_per_code=fps / tcps)
    time_codes = frame_numbers.astype(np.float64) * float(tcps / fps)

    cam2world, shear_deg = _world_poses(
        prim, path, time_codes, frame_numbers, meters_per_unit, up_axis
    )
    cam2world = _keep_holds(cam2world, _keyed_holds(prim, time_codes))
    cam2world = _keep_holds(cam2world, _still_runs(cam2world))

    cam = UsdGeom.Camera(prim)
    lens = {}
    for name, attr in (
        ("focalLength", cam.GetFocalLengthAttr()),
        ("focusDistance", cam.GetFocusDistanceAttr()),
        ("fStop", cam.GetFStopAttr()),
        ("horizontalAperture", cam.GetHorizontalApertureAttr()),
        ("verticalAperture", cam.GetVerticalApertureAttr()),
        ("horizontalApertureOffset", cam.GetHorizontalApertureOffsetAttr()),
        ("verticalApertureOffset", cam.GetVerticalApertureOffsetAttr()),
        ("clippingRange", cam.GetClippingRangeAttr()),
    ):
        values = _sample_attribute(attr, time_codes, 2 if name == "clippingRange" else 0)
        usable = np.isfinite(values)
        if name == "focusDistance":  # focus at infinity, as some exporters write it
            usable |= np.isposinf(values)
        bad = ~usable.reshape(len(time_codes), -1).all(axis=1)
        if bad.any():
            what = "finite or infinite" if name == "focusDistance" else "finite"
            msg = f"{path}: camera {cam_path} has no {what} {name} {_where(frame_numbers, bad)}"
            raise ShotFileError(msg)
        if name in _SIGN_RULES:  # a negative length or stop is a broken export, not a lens
            positive, meaning = _SIGN_RULES[name]
            bad = values <= 0.0 if positive else values < 0.0
            if bad.any():
                first = float(values[np.flatnonzero(bad)[0]])
                msg = (f"{path}: camera {cam_path} has {name} {first:g} "
                       f"{_where(frame_numbers, bad)}: {meaning}")
                raise ShotFileError(msg)
        lens[name] = values

    # Tenths of a scene unit -> scene units (/10) -> metres (*mpu) -> millimetres (*1000).
    def to_mm(values: NDArray[np.float64]) -> NDArray[np.float64]:
        if focal_length_unit == "mm":
            return values
        return values * (meters_per_unit * 100.0)

    focal_length_mm = to_mm(lens["focalLength"])
    aperture_mm = to_mm(lens["horizontalAperture"]), to_mm(lens["verticalAperture"])
    offset_mm = to_mm(lens["horizontalApertureOffset"]), to_mm(lens["verticalApertureOffset"])
    warnings = [
        w
        for w in (
            _focal_length_warning(
                cam_path, lens["focalLength"], focal_length_mm, meters_per_unit,
                focal_length_unit, frame_numbers,
                is_authored=cam.GetFocalLengthAttr().HasAuthoredValue(),
            ),
            _film_back_warning(
                cam_path, lens["horizontalAperture"], aperture_mm[0], meters_per_unit,
                focal_length_unit, frame_numbers,
            )
            # USD's fallback (20.955 tenths of a unit) is only a film back on a cm stage.
            if cam.GetHorizontalApertureAttr().HasAuthoredValue()
            else None,
            _lens_shift_warning(cam_path, offset_mm, frame_numbers),
            _orthographic_warning(cam, cam_path),
            _shear_warning(cam_path, shear_deg, frame_numbers, _has_moving_parent(prim)),
            _pixel_aspect_warning(stage),
            _layer_units_warning(prim, cam_path, meters_per_unit, up_axis),
            *composition,
        )
        if w
    ]
    for warning in warnings:
        logger.info("%s: %s", path, warning)

    return Shot(
        source=source,
        camera_path=cam_path,
        frames=frame_numbers,
        time_codes=time_codes,
        times=(frame_numbers - frame_numbers[0]) / float(fps),
        fps=float(fps),
        cam2world=cam2world,
        focal_length_mm=focal_length_mm,
        focus_distance_m=lens["focusDistance"] * meters_per_unit,
        f_stop=lens["fStop"],
        meters_per_unit=meters_per_unit,
        up_axis=up_axis,
        warnings=tuple(warnings),
        time_codes_per_second=float(tcps),
        # Apertures are in the focal length's unit (tenths of a scene unit, or millimetres).
        horizontal_aperture_mm=aperture_mm[0],
        vertical_aperture_mm=aperture_mm[1],
        clipping_range_m=lens["clippingRange"] * meters_per_unit,
        horizontal_aperture_offset_mm=offset_mm[0],
        vertical_aperture_offset_mm=offset_mm[1],
        stage_rates=(written_tcps, written_fps),
    )


def _metadata_number(stage: Any, key: str, typed_get: Any) -> Any:
    """A numeric stage metadatum of any numeric type.

    USD's typed getters insist on the schema's type (double); some exporters (Blender 2.93
    writes ``metersPerUnit`` as a float in .usdc) store another numeric type, which the
    untyped ``GetMetadata`` returns as a Python number.
    """
    try:
        return typed_get()
    except Tf.ErrorException:
        return stage.GetMetadata(key)


_CAMERA_ATTRIBUTES = ("focalLength", "focusDistance", "fStop", "horizontalAperture",
                      "verticalAperture", "horizontalApertureOffset", "verticalApertureOffset")


def _layer_units_warning(prim: Any, cam_path: str, meters_per_unit: float,
                         up_axis: str) -> str | None:
    """A warning when a layer that authors the camera's or a parent's transform (or the
    camera's lens) declares other units or another up axis than the stage: USD reads every
    layer in the stage's (it converts neither across a reference nor a sublayer), so a camera
    animated in a metre, Z-up layer referenced into a centimetre, Y-up stage moves a
    hundredth as far, turned. Layers that author nothing of the move are not named."""
    here = prim
    while here and not here.IsPseudoRoot():
        for spec in here.GetPrimStack():
            names = list(spec.properties.keys())
            moves = any(n == "xformOpOrder" or n.startswith("xformOp:") for n in names) or (
                here == prim and any(n in _CAMERA_ATTRIBUTES for n in names))
            root = spec.layer.pseudoRoot
            theirs = []
            if moves and root.HasInfo("metersPerUnit"):
                mpu = float(root.GetInfo("metersPerUnit"))
                if not math.isclose(mpu, meters_per_unit, rel_tol=1e-9):
                    theirs.append(f"metersPerUnit {mpu:g} (the stage's: {meters_per_unit:g})")
            if moves and root.HasInfo("upAxis") and str(root.GetInfo("upAxis")) != up_axis:
                theirs.append(f"upAxis {root.GetInfo('upAxis')} (the stage's: {up_axis})")
            if theirs:
                return (f"{here.GetPath()} (the camera {cam_path} or a parent) is moved by layer "
                        f"{spec.layer.identifier}, written with {' and '.join(theirs)}: USD "
                        f"reads it in the stage's units and up axis (it converts neither across "
                        f"a reference nor a sublayer), so its move may be scaled or turned; "
                        f"re-export that layer in the stage's units and up axis, or scale and "
                        f"turn the prim that brings it in to match")
        here = here.GetParent()
    return None


def _meters_per_unit(stage: Any, path: Path) -> float:
    if not stage.HasAuthoredMetadata("metersPerUnit"):
        logger.warning(
            "%s: metersPerUnit is not authored; using USD's fallback 0.01 (centimetres)", path
        )
    return _positive_metadata(stage, path, "metersPerUnit",
                              lambda: UsdGeom.GetStageMetersPerUnit(stage))


def _positive_metadata(stage: Any, path: Path, key: str, typed_get: Any) -> float:
    """A stage metadatum that must be a finite positive number (of any numeric type)."""
    value = _metadata_number(stage, key, typed_get)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        msg = f"{path}: {key} must be a number, not {value!r}"
        raise ShotFileError(msg)
    number = float(value)
    if not (math.isfinite(number) and number > 0.0):
        msg = f"{path}: {key} must be a positive number, not {number}"
        raise ShotFileError(msg)
    return number


def _rate(stage: Any, path: Path, key: str, typed_get: Any) -> Fraction:
    """A frame or time-code rate as an exact fraction.

    Whole rates stay whole; a rate within 10 ppm of an NTSC rate (24000/1001 written as
    23.976, 29.97, 59.94 or in full) becomes that fraction, so a stage that spells the same
    rate two ways samples every frame; anything else is taken exactly as written.
    """
    rate = _positive_metadata(stage, path, key, typed_get)
    whole = round(rate)
    if whole >= 1 and abs(rate - whole) <= 1e-9 * rate:
        return Fraction(whole)
    ntsc = round(rate * 1.001)
    if ntsc >= 1 and abs(rate - ntsc / 1.001) <= 1e-5 * rate:
        return Fraction(ntsc * 1000, 1001)
    return Fraction(rate)


def _composition_errors(prim: Any, *, parents: bool = True) -> list[str]:
    """USD's composition errors of a prim (and, with ``parents``, of its parents instead),
    one line each: an arc it could not follow (a reference or payload whose layer is missing,
    or whose prim path is not in it) and a layer missing from a layer stack that contributes
    to it (a sublayer of the shot, or of a referenced asset). Such an error on the camera
    itself can hold its animation: read without it, a dolly becomes a still."""
    found: list[str] = []
    here = prim.GetParent() if parents else prim
    while here and not here.IsPseudoRoot():
        index = here.GetPrimIndex()
        errors = list(index.localErrors)
        nodes = [index.rootNode]
        while nodes:
            node = nodes.pop()
            errors += node.layerStack.localErrors
            nodes += node.children
        found += [text for text in _one_line_errors(errors) if text not in found]
        if not parents:
            break
        here = here.GetParent()
    return found


def _why_no_camera(stage: Any, camera: str | None) -> str | None:
    """What USD could not compose that may have held the camera that was not found: an
    error on the asked prim path (its nearest prim on the stage) or its parents; without a
    path, the stage's first error when it has no camera at all."""
    if camera is None:
        errors = _stage_composition_errors(stage) if not _camera_paths(stage) else []
    elif Sdf.Path.IsValidPathString(camera) and Sdf.Path(camera).IsAbsolutePath():
        at = Sdf.Path(camera)
        while not stage.GetPrimAtPath(at) and at != Sdf.Path.absoluteRootPath:
            at = at.GetParentPath()
        prim = stage.GetPrimAtPath(at)
        errors = (_composition_errors(prim, parents=False) + _composition_errors(prim)
                  if prim and not prim.IsPseudoRoot() else [])
    else:
        errors = []
    return errors[0] if errors else None


def _stage_composition_errors(stage: Any) -> list[str]:
    """Every composition error of the stage, one line each (:func:`_composition_errors`)."""
    return _one_line_errors(stage.GetCompositionErrors())


def _one_line_errors(errors: Any) -> list[str]:
    """USD's composition errors as distinct one-line messages, in order."""
    texts = [" ".join(str(e).split()).removesuffix("; skipping.") for e in errors]
    return list(dict.fromkeys(texts))


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


def _film_frames(
    stage: Any,
    path: Path,
    prim: Any,
    frames: tuple[int, int] | None,
    *,
    frames_per_code: Fraction,
) -> NDArray[np.int64]:
    """(n,) whole film frames to sample: ``first, first + 1, ..., last``.

    Args:
        frames_per_code: ``framesPerSecond / timeCodesPerSecond``: film frame = time code
            times this.
    """
    authored: tuple[float, float] | None
    has_start, has_end = (stage.HasAuthoredMetadata(key)
                          for key in ("startTimeCode", "endTimeCode"))
    if has_start and has_end:
        authored = (float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode()))
        what = "authored range"
    else:
        authored = _sample_span(prim)
        what = "animated range (the stage has no startTimeCode/endTimeCode)"
        if authored is not None and (has_start or has_end):
            # one end authored: it bounds the shot, the keys give the other end
            authored = (float(stage.GetStartTimeCode()) if has_start else authored[0],
                        float(stage.GetEndTimeCode()) if has_end else authored[1])
            what = ("range from startTimeCode to the last key" if has_start
                    else "range from the first key to endTimeCode")
    span: tuple[int, int] | None = None
    if authored is not None:
        if not all(math.isfinite(t) for t in authored):
            msg = f"{path}: the shot's {what} {_fmt(authored[0])}-{_fmt(authored[1])} is not finite"
            raise ShotFileError(msg)
        if not authored[0] <= authored[1]:
            msg = (
                f"{path}: startTimeCode {_fmt(authored[0])} is after endTimeCode "
                f"{_fmt(authored[1])}" if has_start and has_end else
                f"{path}: the shot's {what} is backwards: time codes {_fmt(authored[0])} to "
                f"{_fmt(authored[1])}"
            )
            raise ShotFileError(msg)
        # Whole film frames inside the range (a sub-frame first key at f - 1/4 starts at f).
        span = (
            math.ceil(Fraction(authored[0]) * frames_per_code - _FRAME_TOL),
            math.floor(Fraction(authored[1]) * frames_per_code + _FRAME_TOL),
        )
        if span[0] > span[1]:
            msg = (
                f"{path}: the shot's {what}, time codes {_fmt(authored[0])}-"
                f"{_fmt(authored[1])}, holds no whole film frame"
            )
            raise ShotFileError(msg)

    if frames is None:
        if span is None:
            animation = (
                "is animated with splines, which give no frame range"
                if _has_splines(prim)
                else "has no time samples"
            )
            stage_has = ("only a startTimeCode" if has_start else
                         "only an endTimeCode" if has_end else "no startTimeCode/endTimeCode")
            msg = (
                f"{path}: no frame range: the stage has {stage_has} and the "
                f"camera {animation}; give the frames to read with --frames FIRST:LAST"
            )
            raise ShotFileError(msg)
        first, last = span
    else:
        try:
            first, last = (operator.index(f) for f in frames)
        except (TypeError, ValueError):
            msg = f"frame range must be two integers (first, last), not {frames!r}"
            raise ShotFileError(msg) from None
        if first > last:
            msg = f"{path}: frame range {frame_span(first, last)} is backwards (first > last)"
            raise ShotFileError(msg)
        if span is not None and (first < span[0] or last > span[1]):
            msg = (
                f"{path}: frames {frame_span(first, last)} are outside the shot's {what}, "
                f"film frames {frame_span(*span)}"
            )
            raise ShotFileError(msg)
    count = last - first + 1
    span_text = frame_span(first, last, _big)
    if count > MAX_FRAMES:
        msg = (
            f"{path}: frames {span_text} are {_big(count)} film frames; camtraj reads at most "
            f"{MAX_FRAMES} in one shot: give a shorter range (--frames)"
        )
        raise ShotFileError(msg)
    if max(abs(first), abs(last)) > _MAX_FRAME_NUMBER:
        msg = (
            f"{path}: frames {span_text}: film frame numbers must lie within "
            f"±{_MAX_FRAME_NUMBER} (the MCAP stores them as 32-bit integers)"
        )
        raise ShotFileError(msg)
    return np.arange(first, last + 1, dtype=np.int64)


def _sample_span(prim: Any) -> tuple[float, float] | None:
    """First and last time sample of the camera's transform (its ancestors' too) and lens."""
    times: list[float] = []
    p = prim
    while p and not p.IsPseudoRoot():
        xformable = UsdGeom.Xformable(p)
        if xformable:
            times.extend(xformable.GetTimeSamples())
        p = p.GetParent()
    cam = UsdGeom.Camera(prim)
    for attr in (cam.GetFocalLengthAttr(), cam.GetFocusDistanceAttr(), cam.GetFStopAttr()):
        times.extend(attr.GetTimeSamples())
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
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(n, 4, 4) cam2world in metres, Z-up, column vectors, scale removed.

    Also returns (n,) the angle [deg] between the view direction a renderer uses (the
    transform applied to the camera's -Z) and the orthonormalised pose's: non-zero only
    under a sheared or non-uniformly scaled parent.
    """
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
    rendered = linear[:, :, 2] / np.linalg.norm(linear[:, :, 2], axis=1, keepdims=True)
    cos = np.clip(np.sum(rendered * rotation[:, :, 2], axis=1), -1.0, 1.0)
    shear_deg = np.degrees(np.arccos(cos))
    translation = cam2stage[:, :3, 3] * meters_per_unit
    if up_axis == "Y":
        rotation = YUP2ZUP @ rotation
        translation = translation @ YUP2ZUP.T
    cam2world = np.zeros((n, 4, 4))
    cam2world[:, :3, :3] = rotation
    cam2world[:, :3, 3] = translation
    cam2world[:, 3, 3] = 1.0
    return cam2world, shear_deg


def _keyed_holds(prim: Any, time_codes: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per frame pair (n - 1,), whether the camera holds still as authored: every transform
    op of the camera and its ancestors keeps its value over the pair's interval (its time
    samples from the last one at or before the first frame to the first one at or after the
    second are all equal). A spline-valued op is never taken as holding."""
    held = np.ones(max(len(time_codes) - 1, 0), dtype=bool)
    a, b = time_codes[:-1], time_codes[1:]
    p = prim
    while p and not p.IsPseudoRoot() and held.any():
        xformable = UsdGeom.Xformable(p)
        for op in xformable.GetOrderedXformOps() if xformable else ():
            attr = op.GetAttr()
            if attr.HasSpline():
                return np.zeros_like(held)
            times = np.asarray(attr.GetTimeSamples(), dtype=float)
            if times.size < 2:
                continue  # a constant
            changed = _key_changes(attr, times)
            run = np.concatenate([[0], np.cumsum(changed)])  # equal keys in a row: one run
            lo = np.clip(np.searchsorted(times, a, side="right") - 1, 0, times.size - 1)
            hi = np.clip(np.searchsorted(times, b, side="left"), 0, times.size - 1)
            held &= run[lo] == run[hi]
            if not held.any():
                break
        p = p.GetParent()
    return held


def _key_changes(attr: Any, times: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per pair of consecutive time samples (k - 1,), whether the op's value changes: keys
    compared as arrays, all pairs at once (a blocked key, read as one NaN, equals nothing)."""
    query = Usd.AttributeQuery(attr)  # resolved once, not per key
    keys = [_key_value(query.Get(t)) for t in times.tolist()]
    width = max(key.size for key in keys)
    rows = np.array([key if key.size == width else np.full(width, np.nan) for key in keys])
    changed: NDArray[np.bool_] = np.any(rows[1:] != rows[:-1], axis=1)
    return changed


def _key_value(value: Any) -> NDArray[np.float64]:
    """An xform op's authored value as numbers (quaternions: real part, then imaginary)."""
    if hasattr(value, "GetImaginary"):
        return np.array([value.GetReal(), *value.GetImaginary()], dtype=float)
    return np.asarray(value, dtype=float).ravel()


HOLD_JITTER = 1e-6
"""[m] and [rad]: a camera within this of a hold's first frame holds (baked float values
jitter by about 1e-7 around a still pose; a slow creep of 5 mm in 10 s moves 2e-5 m a frame
at 24 fps)."""


def _still_runs(cam2world: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per frame pair (n - 1,), whether the camera holds still: the second frame's pose is
    within :data:`HOLD_JITTER` of the first frame of the run the pair is in (position, and
    rotation by the angle between the two orientations). A run is measured from its first
    frame, not frame to frame, so a creep below the threshold per frame still moves."""
    n = cam2world.shape[0]
    held = np.zeros(max(n - 1, 0), dtype=bool)
    if n < 2:
        return held
    pos, rot = cam2world[:, :3, 3], cam2world[:, :3, :3]
    # |R_a - R_b| (Frobenius) is sqrt(8) sin(angle / 2): sqrt(2) x the angle when small
    close = ((np.linalg.norm(np.diff(pos, axis=0), axis=1) <= HOLD_JITTER)
             & (np.linalg.norm(np.diff(rot, axis=0), axis=(1, 2)) <= np.sqrt(2.0) * HOLD_JITTER))
    first = 0
    for k in np.flatnonzero(close):  # pair k: frames k and k + 1
        if k == 0 or not held[k - 1]:
            first = int(k)  # a run starts with this pair
        held[k] = (np.linalg.norm(pos[k + 1] - pos[first]) <= HOLD_JITTER
                   and np.linalg.norm(rot[k + 1] - rot[first]) <= np.sqrt(2.0) * HOLD_JITTER)
    return held


def _keep_holds(cam2world: NDArray[np.float64],
                held: NDArray[np.bool_]) -> NDArray[np.float64]:
    """The poses with every authored hold exact: each frame of a run of held pairs takes the
    run's first pose (USD interpolates float values between two equal keys a few rounding
    steps off: 1.3e-7 rad for a float3 rotation near 90 deg, 2e-6 rad four turns in)."""
    n = cam2world.shape[0]
    starts = np.concatenate([[True], ~held]) if n else np.zeros(0, dtype=bool)
    first = np.maximum.accumulate(np.where(starts, np.arange(n), 0))
    return np.asarray(cam2world[first])


def _sample_attribute(
    attr: Any, time_codes: NDArray[np.float64], width: int = 0
) -> NDArray[np.float64]:
    """(n,) values of a scalar attribute, or (n, width) of a vector one; NaN where unset.

    An attribute that cannot vary (at most one time sample, no spline) is read once: most
    of a camera's are constant, and a query per frame of each took most of the read."""
    query = Usd.AttributeQuery(attr)
    values = np.full((len(time_codes), width) if width else len(time_codes), np.nan)
    read = time_codes if query.ValueMightBeTimeVarying() else time_codes[:1]
    for i, tc in enumerate(read.tolist()):
        value = query.Get(tc)
        if value is not None:
            values[i] = value
    values[len(read):] = values[:1]  # the frames not read: the one value
    return values


def _focal_length_warning(
    cam_path: str,
    authored: NDArray[np.float64],
    focal_length_mm: NDArray[np.float64],
    meters_per_unit: float,
    unit: str,
    frames: NDArray[np.int64],
    *,
    is_authored: bool = True,
) -> str | None:
    """A note when the focal length is outside what real lenses have, saying which reading fits.

    Args:
        authored: (n,) ``focalLength`` as authored (USD's fallback where it is not).
        focal_length_mm: (n,) the focal length as read [mm].
        is_authored: Whether the camera has a ``focalLength`` at all.
    """
    lo, hi = _PLAUSIBLE_FOCAL_MM
    bad = (focal_length_mm < lo) | (focal_length_mm > hi)
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad)[0])
    value, mm = float(authored[i]), float(focal_length_mm[i])
    where = f"at frame {int(frames[i])}"
    if not is_authored:
        return (
            f"camera {cam_path} has no focalLength: USD's fallback {value:g} (tenths of a "
            f"scene unit, here {meters_per_unit:g} m) reads as {mm:g} mm, outside the "
            f"{lo:g}-{hi:g} mm of real lenses; author the focal length to record it"
        )
    plausible_raw = bool(np.all((authored >= lo) & (authored <= hi)))
    if unit == "schema" and plausible_raw:
        return (
            f"camera {cam_path} focalLength {value:g} reads as {mm:g} mm {where} (USD's "
            f"focalLength is in tenths of a scene unit, here {meters_per_unit:g} m); it is "
            "likely millimetres written by an older exporter: try --focal-length-unit mm"
        )
    spelled = "millimetres" if unit == "mm" else "tenths of a scene unit"
    return (
        f"camera {cam_path} focal length {mm:g} mm {where} (focalLength {value:g} read as "
        f"{spelled}) is outside the {lo:g}-{hi:g} mm of real lenses"
    )


def _orthographic_warning(cam: Any, cam_path: str) -> str | None:
    projection = cam.GetProjectionAttr().Get()
    if projection != UsdGeom.Tokens.orthographic:
        return None
    return (
        f"camera {cam_path} is orthographic: no real lens gives its view; the robot follows "
        "its pose and the focal length is only recorded"
    )


def _film_back_warning(
    cam_path: str,
    authored: NDArray[np.float64],
    width_mm: NDArray[np.float64],
    meters_per_unit: float,
    unit: str,
    frames: NDArray[np.int64],
) -> str | None:
    """A note when the film back's width is outside real sensor sizes (a unit mix-up).

    Args:
        authored: (n,) ``horizontalAperture`` as authored.
        width_mm: (n,) the film back width as read [mm].
    """
    lo, hi = _PLAUSIBLE_FILM_BACK_MM
    bad = (width_mm < lo) | (width_mm > hi)
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad)[0])
    text = (
        f"camera {cam_path} film back {float(width_mm[i]):g} mm wide at frame {int(frames[i])} "
        f"(horizontalAperture {float(authored[i]):g}) is outside the {lo:g}-{hi:g} mm of real "
        "sensors"
    )
    if unit == "schema" and bool(np.all((authored >= lo) & (authored <= hi))):
        text += (
            f"; USD's apertures are in tenths of a scene unit (here {meters_per_unit:g} m): "
            "millimetres written by the exporter? try --focal-length-unit mm"
        )
    return text


def _lens_shift_warning(
    cam_path: str,
    offset_mm: tuple[NDArray[np.float64], NDArray[np.float64]],
    frames: NDArray[np.int64],
) -> str | None:
    """A note when the film back is off the lens axis (lens shift, or film shake if it moves)."""
    offsets = np.stack(offset_mm, axis=1)
    size = np.linalg.norm(offsets, axis=1)
    if not np.any(size > 0.0):
        return None
    i = int(np.argmax(size))
    moving = bool(np.ptp(offsets, axis=0).max() > 0.0)
    what = "film shake (animated aperture offset)" if moving else "lens shift"
    return (
        f"camera {cam_path} has {what}: horizontalApertureOffset {float(offsets[i, 0]):g} mm, "
        f"verticalApertureOffset {float(offsets[i, 1]):g} mm at frame {int(frames[i])}; an "
        "off-centre frame cannot come from moving the robot (it needs a shift lens or a "
        "reframe in post); the offset is carried in CameraInfo's principal point (cx, cy)"
    )


def _pixel_aspect_warning(stage: Any) -> str | None:
    """A note when render settings or products ask for non-square pixels."""
    for prim in stage.Traverse():
        if not prim.IsA(UsdRender.SettingsBase):
            continue
        attr = UsdRender.SettingsBase(prim).GetPixelAspectRatioAttr()
        value = attr.Get() if attr.HasAuthoredValue() else None
        if value is not None and abs(float(value) - 1.0) > 1e-6:
            return (
                f"render settings {prim.GetPath()} have pixelAspectRatio {float(value):g} "
                "(non-square pixels, an anamorphic frame?): camtraj ignores it; the robot "
                "follows the camera and CameraInfo assumes square pixels"
            )
    return None


def _has_moving_parent(prim: Any) -> bool:
    """Whether any ancestor of the camera has transform ops of its own."""
    p = prim.GetParent()
    while p and not p.IsPseudoRoot():
        xformable = UsdGeom.Xformable(p)
        if xformable and xformable.GetOrderedXformOps():
            return True
        p = p.GetParent()
    return False


def _has_splines(prim: Any) -> bool:
    """Whether the camera or an ancestor has a spline-valued attribute (no time samples)."""
    p = prim
    while p and not p.IsPseudoRoot():
        if any(attr.HasSpline() for attr in p.GetAttributes()):
            return True
        p = p.GetParent()
    return False


def _shear_warning(
    cam_path: str, shear_deg: NDArray[np.float64], frames: NDArray[np.int64], parent: bool
) -> str | None:
    worst = int(np.argmax(shear_deg))
    angle = float(shear_deg[worst])
    if not angle > _SHEAR_WARN_DEG:
        return None
    what = ("a sheared or non-uniformly scaled parent" if parent
            else "a sheared camera transform (a non-uniform scale outside its rotation)")
    return (
        f"camera {cam_path} has {what}: the rendered view "
        f"direction differs from the orthonormalised pose the robot follows by up to "
        f"{angle:.1f} deg (frame {int(frames[worst])})"
    )


#: The camera attributes whose sign means something: (must be above zero, else at least
#: zero; what a value there means).
_SIGN_RULES = {
    "focalLength": (True, "a focal length is above zero"),
    "focusDistance": (False, "a focus distance is zero (unset) or more"),
    "fStop": (False, "an f-stop is zero (unset) or more"),
    "horizontalAperture": (True, "a film back is above zero"),
    "verticalAperture": (True, "a film back is above zero"),
}


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


def _big(n: int) -> str:
    """A frame number or count as text, in short scientific form beyond 12 digits."""
    return str(n) if abs(n) < 10**12 else f"{float(n):.3g}"


def _fmt(value: float) -> str:
    """A time code as text: '1001' for whole numbers, else '1001.5'."""
    return str(int(value)) if float(value).is_integer() else repr(float(value))
