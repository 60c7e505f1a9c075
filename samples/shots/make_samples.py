"""Write the sample shots in this folder (and long benchmark shots) as USD text files.

Run ``python samples/shots/make_samples.py [OUT_DIR]`` to (re)write the five samples, or
``--long-shot PATH [--frames N]`` to write the one-minute shot ``make bench`` converts; the
committed ``.usda`` files are exactly what this script writes. The output is deterministic:
plain text with every number rounded to 6 decimals, no time stamps, no USD version strings.

Every move is designed in the robot's frame (design.md §2): metres, Z up, x along the track.
The robot's camera reaches x in [3, 10] m, |y| <= 2 m, z in [-0.5, 2.2] m comfortably; every
feasible sample stays inside with margin, moves at up to ~1 m/s and turns at up to ~40°/s
with eased (quintic) starts and stops. The files are then written the way different tools do
it: Maya (Y-up, centimetres, translate + rotateXYZ), Blender (Z-up, metres, a 4x4
``xformOp:transform``), Houdini-like (Y-up, metres) and a centimetre Z-up stage.

Camera orientation is given as ``pan`` (heading of the view direction, degrees from +x
towards +y about +z) and ``tilt`` (degrees above horizontal). A USD camera looks down its
local -Z with +Y up, so in a Z-up world its rotation is ``Rz(pan - 90) @ Rx(90 + tilt)``.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

HERE = Path(__file__).resolve().parent

# Z-up coordinates (X, Y, Z) -> Y-up stage coordinates (X, Z, -Y): the inverse of +90° about X.
_ZUP2YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


# --------------------------------------------------------------------------------------------
# Motion helpers (Z-up metres, degrees)


def ease(u: Array) -> Array:
    """Quintic smoothstep: 0 -> 1 with zero velocity and acceleration at both ends.

    Args:
        u: (n,) progress, clipped to [0, 1].

    Returns:
        (n,) eased progress in [0, 1]; its peak slope is 1.875.
    """
    u = np.clip(u, 0.0, 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


def ramp(frames: Array, first: float, last: float) -> Array:
    """(n,) eased 0 -> 1 between film frames ``first`` and ``last``, held outside."""
    return ease((frames - first) / (last - first))


def look_at(positions: Array, target: Array) -> tuple[Array, Array]:
    """Pan and tilt in [deg] that aim cameras at ``positions`` (n, 3) at ``target`` (3,)."""
    d = np.asarray(target, dtype=np.float64) - positions
    pan = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    tilt = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    return pan, tilt


def _rx(deg: float) -> Array:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(deg: float) -> Array:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def cam2world_rotation(pan: float, tilt: float, roll: float = 0.0) -> Array:
    """(3, 3) Z-up world rotation of a USD camera (looks down -Z, +Y up) at pan/tilt [deg],
    turned by ``roll`` [deg] about its view axis (a dutch angle; positive turns the camera's
    up vector to its left)."""
    rot = _rz(pan - 90.0) @ _rx(90.0 + tilt)
    return rot @ _rz(roll) if roll else rot


@dataclass(frozen=True)
class Move:
    """A camera move in Z-up metres, one row per film frame.

    Attributes:
        frames: (n,) film frame numbers (time codes), consecutive.
        positions: (n, 3) camera positions in [m], Z-up.
        pan: (n,) heading in [deg]; tilt: (n,) elevation in [deg].
        focal_mm, focus_m, f_stop: (n,) lens channels, or one float when constant.
        roll: (n,) turn about the view axis in [deg] (see :func:`cam2world_rotation`), or 0;
            only the matrix writer (:func:`_camera_prim_matrix`) writes it.
    """

    frames: Array
    positions: Array
    pan: Array
    tilt: Array
    focal_mm: Array | float
    focus_m: Array | float
    f_stop: Array | float
    roll: Array | float = 0.0


# --------------------------------------------------------------------------------------------
# USD text writing


def _num(value: float) -> str:
    """A number rounded to 6 decimals, without trailing zeros or a negative zero."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _tuple(values: Array) -> str:
    return "(" + ", ".join(_num(float(v)) for v in values) + ")"


def _matrix(m: Array) -> str:
    return "(" + ", ".join(_tuple(row) for row in m) + ")"


def _samples(type_name: str, name: str, frames: Array, values: list[str], indent: str) -> str:
    lines = [f"{indent}{type_name} {name}.timeSamples = {{"]
    lines += [f"{indent}    {int(f)}: {v}," for f, v in zip(frames, values, strict=True)]
    lines.append(f"{indent}}}")
    return "\n".join(lines)


def _channel(
    type_name: str, name: str, frames: Array, value: Array | float, scale: float, indent: str
) -> str:
    """A float attribute: constant if ``value`` is a float, else time samples (times scale)."""
    if isinstance(value, float | int):
        return f"{indent}{type_name} {name} = {_num(float(value) * scale)}"
    return _samples(type_name, name, frames, [_num(float(v) * scale) for v in value], indent)


def _header(
    doc: str, up_axis: str, meters_per_unit: float, frames: Array, fps: float, default_prim: str,
    time_codes_per_second: float | None = None,
) -> str:
    """The stage's metadata; ``frames`` are time codes, ``time_codes_per_second`` defaults to
    ``fps`` (one time code per film frame)."""
    tcps = fps if time_codes_per_second is None else time_codes_per_second
    lines = [
        "#usda 1.0",
        "(",
        f'    defaultPrim = "{default_prim}"',
        f'    doc = """{doc}"""',
        f"    endTimeCode = {int(frames[-1])}",
        f"    framesPerSecond = {_num(fps)}",
        f"    metersPerUnit = {_num(meters_per_unit)}",
        f"    startTimeCode = {int(frames[0])}",
        f"    timeCodesPerSecond = {_num(tcps)}",
        f'    upAxis = "{up_axis}"',
        ")",
        "",
    ]
    return "\n".join(lines)


def _lens(
    frames: Array,
    focal_mm: Array | float,
    focus_m: Array | float,
    f_stop: Array | float,
    meters_per_unit: float,
    indent: str,
) -> list[str]:
    """Camera lens attributes in USD units: lens and filmback in tenths of a scene unit."""
    tenth = 1.0 / (meters_per_unit * 100.0)  # millimetres -> tenths of a scene unit
    per_m = 1.0 / meters_per_unit  # metres -> scene units
    return [
        f"{indent}float2 clippingRange = {_tuple(np.array([0.1, 1000.0]) * per_m)}",
        _channel("float", "focalLength", frames, focal_mm, tenth, indent),
        _channel("float", "focusDistance", frames, focus_m, per_m, indent),
        _channel("float", "fStop", frames, f_stop, 1.0, indent),
        f"{indent}float horizontalAperture = {_num(36.0 * tenth)}",
        f"{indent}float verticalAperture = {_num(20.25 * tenth)}",
        f'{indent}token projection = "perspective"',
    ]


def _euler_xyz(move: Move, up_axis: str) -> list[str]:
    """``xformOp:rotateXYZ`` angles [deg] per frame that give the move's pan and tilt."""
    if up_axis == "Z":
        angles = np.stack([90.0 + move.tilt, np.zeros_like(move.pan), move.pan - 90.0], axis=1)
    else:  # Y-up: yaw about stage +Y (the Z-up world's +Z), tilt about the camera's X
        angles = np.stack([move.tilt, move.pan - 90.0, np.zeros_like(move.pan)], axis=1)
    return [_tuple(a) for a in angles]


def _stage_points(points: Array, up_axis: str, meters_per_unit: float) -> Array:
    """(n, 3) Z-up metres -> (n, 3) stage coordinates in scene units."""
    pts = np.atleast_2d(points) / meters_per_unit
    return pts @ _ZUP2YUP.T if up_axis == "Y" else pts


def _camera_prim_trs(
    name: str, move: Move, up_axis: str, meters_per_unit: float, indent: str
) -> str:
    """A Camera prim with time-sampled ``translate`` and ``rotateXYZ`` ops (Maya style)."""
    if np.any(np.asarray(move.roll) != 0.0):
        msg = "the translate/rotateXYZ writer has no roll: write the move as a matrix"
        raise ValueError(msg)
    inner = indent + "    "
    pts = _stage_points(move.positions, up_axis, meters_per_unit)
    static = bool(np.all(pts == pts[0]))
    if static:
        translate = f"{inner}double3 xformOp:translate = {_tuple(pts[0])}"
    else:
        translate = _samples(
            "double3", "xformOp:translate", move.frames, [_tuple(p) for p in pts], inner
        )
    lines = [
        f'{indent}def Camera "{name}"',
        f"{indent}{{",
        *_lens(move.frames, move.focal_mm, move.focus_m, move.f_stop, meters_per_unit, inner),
        translate,
        _samples("float3", "xformOp:rotateXYZ", move.frames, _euler_xyz(move, up_axis), inner),
        f'{inner}uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]',
        f"{indent}}}",
    ]
    return "\n".join(lines)


def _camera_prim_matrix(
    name: str, move: Move, meters_per_unit: float, indent: str, up_axis: str = "Z"
) -> str:
    """A Camera prim with a time-sampled 4x4 ``xformOp:transform`` (Blender style; Z-up, or
    Y-up with ``up_axis="Y"``)."""
    inner = indent + "    "
    pts = _stage_points(move.positions, up_axis, meters_per_unit)
    to_stage = _ZUP2YUP if up_axis == "Y" else np.eye(3)
    roll = np.broadcast_to(np.asarray(move.roll, dtype=np.float64), np.shape(move.pan))
    mats = []
    for p, pan, tilt, r in zip(pts, move.pan, move.tilt, roll, strict=True):
        m = np.eye(4)
        m[:3, :3] = to_stage @ cam2world_rotation(float(pan), float(tilt), float(r))
        m[:3, 3] = p
        mats.append(_matrix(m.T))  # USD stores row-vector matrices: translation in the last row
    lines = [
        f'{indent}def Camera "{name}"',
        f"{indent}{{",
        *_lens(move.frames, move.focal_mm, move.focus_m, move.f_stop, meters_per_unit, inner),
        _samples("matrix4d", "xformOp:transform", move.frames, mats, inner),
        f'{inner}uniform token[] xformOpOrder = ["xformOp:transform"]',
        f"{indent}}}",
    ]
    return "\n".join(lines)


def _subject(name: str, where: Array, up_axis: str, meters_per_unit: float, indent: str) -> str:
    """A small sphere marking what the camera looks at (for viewing in usdview)."""
    inner = indent + "    "
    p = _stage_points(np.asarray(where, dtype=np.float64), up_axis, meters_per_unit)[0]
    lines = [
        f'{indent}def Sphere "{name}"',
        f"{indent}{{",
        f"{inner}double radius = {_num(0.15 / meters_per_unit)}",
        f"{inner}double3 xformOp:translate = {_tuple(p)}",
        f'{inner}uniform token[] xformOpOrder = ["xformOp:translate"]',
        f"{indent}}}",
    ]
    return "\n".join(lines)


def _scope(kind: str, name: str, children: list[str], indent: str = "") -> str:
    return "\n".join(
        [f'{indent}def {kind} "{name}"', f"{indent}{{", "\n\n".join(children), f"{indent}}}"]
    )


# --------------------------------------------------------------------------------------------
# The samples


def maya_dolly_push_in() -> str:
    """Maya-style (Y-up, cm, 24 fps) dolly push-in along the track with a slight pan.

    Frames 1001-1120. The camera at y = -1.0 m, z = 1.4 m tracks x 4.0 -> 6.5 m while
    aiming at a subject at (9.0, 0.0, 1.3) m (pan about 11° -> 22°); the focal length
    creeps 32 -> 40 mm, focus follows the subject, the iris closes f/2.8 -> f/4.
    """
    frames = np.arange(1001, 1121, dtype=np.float64)
    s = ramp(frames, 1001, 1120)
    subject = np.array([9.0, 0.0, 1.3])
    pos = np.stack([4.0 + 2.5 * s, np.full_like(s, -1.0), np.full_like(s, 1.4)], axis=1)
    pan, tilt = look_at(pos, subject)
    move = Move(
        frames,
        pos,
        pan,
        tilt,
        focal_mm=32.0 + 8.0 * s,
        focus_m=np.linalg.norm(subject - pos, axis=1),
        f_stop=2.8 + 1.2 * s,
    )
    mpu, up = 0.01, "Y"
    doc = "camtraj sample: Maya-style dolly push-in (Y-up, centimetres)."
    body = [
        _camera_prim_trs("shotCam", move, up, mpu, ""),
        _scope("Xform", "set", [_subject("subject", subject, up, mpu, "    ")]),
    ]
    return _header(doc, up, mpu, frames, 24.0, "shotCam") + "\n" + "\n\n".join(body) + "\n"


def blender_crane_up() -> str:
    """Blender-style (Z-up, m, 24 fps, 4x4 transform) crane up while tilting down.

    Frames 1-96. The camera rises z 0.2 -> 1.8 m (and creeps x 5.0 -> 5.4 m at y = 0.5 m)
    while holding a subject on the floor at (7.5, 0.5, 0.1) m: tilt about -2° -> -39°. The
    lens widens 35 -> 28 mm, focus follows, the iris goes f/4 -> f/5.6.
    """
    frames = np.arange(1, 97, dtype=np.float64)
    s = ramp(frames, 1, 96)
    subject = np.array([7.5, 0.5, 0.1])
    pos = np.stack([5.0 + 0.4 * s, np.full_like(s, 0.5), 0.2 + 1.6 * s], axis=1)
    pan, tilt = look_at(pos, subject)
    move = Move(
        frames,
        pos,
        pan,
        tilt,
        focal_mm=35.0 - 7.0 * s,
        focus_m=np.linalg.norm(subject - pos, axis=1),
        f_stop=4.0 + 1.6 * s,
    )
    mpu = 1.0
    doc = "camtraj sample: Blender-style crane up (Z-up, metres, matrix transform)."
    body = _scope(
        "Xform",
        "root",
        [
            _camera_prim_matrix("Camera", move, mpu, "    "),
            _subject("subject", subject, "Z", mpu, "    "),
        ],
    )
    return _header(doc, "Z", mpu, frames, 24.0, "root") + "\n" + body + "\n"


ORBIT_SUBJECT = (6.5, 1.0, 1.0)
"""Pivot of the orbit sample's rig [m], Z-up."""


def orbit_animated_parent() -> str:
    """A 90° orbit (radius 1.5 m) carried by an animated parent Xform (Z-up, m, 24 fps).

    Frames 1-120. ``/World/orbit_rig`` sits on the subject at (6.5, 1.0, 1.0) m and turns
    rotateZ -135° -> -45°; its child ``/World/orbit_rig/orbit_cam`` is offset 1.5 m along
    the rig's +x, rising 0.2 -> 0.4 m above the pivot, and faces the pivot (pan 180°, tilt
    -10° in the rig frame). The camera's own transform alone barely moves.
    """
    frames = np.arange(1, 121, dtype=np.float64)
    s = ramp(frames, 1, 120)
    angle = -135.0 + 90.0 * s
    height = 0.2 + 0.2 * s
    ind, inner = "        ", "            "
    rig_rotate = _samples("float", "xformOp:rotateZ", frames, [_num(a) for a in angle], ind)
    cam_translate = _samples(
        "double3",
        "xformOp:translate",
        frames,
        [_tuple(np.array([1.5, 0.0, h])) for h in height],
        inner,
    )
    camera = "\n".join(
        [
            f'{ind}def Camera "orbit_cam"',
            f"{ind}{{",
            *_lens(frames, 40.0, 1.5, 2.8, 1.0, inner),
            cam_translate,
            f"{inner}float3 xformOp:rotateXYZ = {_tuple(np.array([80.0, 0.0, 90.0]))}",
            f'{inner}uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]',
            f"{ind}}}",
        ]
    )
    rig = "\n".join(
        [
            '    def Xform "orbit_rig"',
            "    {",
            f"{ind}double3 xformOp:translate = {_tuple(np.array(ORBIT_SUBJECT))}",
            rig_rotate,
            f'{ind}uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateZ"]',
            "",
            camera,
            "    }",
        ]
    )
    doc = "camtraj sample: orbit carried by an animated parent Xform (Z-up, metres)."
    body = _scope(
        "Xform", "World", [rig, _subject("subject", np.array(ORBIT_SUBJECT), "Z", 1.0, "    ")]
    )
    return _header(doc, "Z", 1.0, frames, 24.0, "World") + "\n" + body + "\n"


def whip_pan() -> str:
    """A whip pan (Y-up, m, 24 fps): 150° of pan in 8 frames, held before and after.

    Frames 1-48. The camera stands low at (6.0, 0.0, -0.3) m (the robot's track on risers),
    tilt -5°, where the robot can hang its forearm and pan about the vertical; pan holds 0°
    to frame 16, whips to 150° by frame 24 (peak about 840°/s) and holds to frame 48.
    """
    frames = np.arange(1, 49, dtype=np.float64)
    pan = 150.0 * ramp(frames, 16, 24)
    pos = np.tile([6.0, 0.0, -0.3], (len(frames), 1))
    move = Move(frames, pos, pan, np.full_like(pan, -5.0), 32.0, 4.0, 4.0)
    doc = "camtraj sample: whip pan, 150 degrees in 8 frames (Y-up, metres)."
    body = _scope("Xform", "World", [_camera_prim_trs("whip_cam", move, "Y", 1.0, "    ")])
    return _header(doc, "Y", 1.0, frames, 24.0, "World") + "\n" + body + "\n"


def unreachable() -> str:
    """A move that leaves the robot's reach (Z-up, cm, 24 fps).

    Frames 1-60. The camera tracks x 5.0 -> 6.0 m at z = 1.4 m looking down the track, but
    swings out to y = 7 m: up between frames 27 and 30, held to 45, back by frame 48.
    """
    frames = np.arange(1, 61, dtype=np.float64)
    y = 7.0 * (ramp(frames, 27, 30) - ramp(frames, 45, 48))
    pos = np.stack([5.0 + 1.0 * ramp(frames, 1, 60), y, np.full_like(y, 1.4)], axis=1)
    move = Move(frames, pos, np.zeros_like(y), np.full_like(y, -5.0), 35.0, 5.0, 2.8)
    doc = "camtraj sample: frames ~28-47 swing out to y = 7 m, out of reach (Z-up, cm)."
    body = _scope("Xform", "World", [_camera_prim_trs("cam", move, "Z", 0.01, "    ")])
    return _header(doc, "Z", 0.01, frames, 24.0, "World") + "\n" + body + "\n"


SAMPLES: dict[str, Callable[[], str]] = {
    "maya_dolly_push_in.usda": maya_dolly_push_in,
    "blender_crane_up.usda": blender_crane_up,
    "orbit_animated_parent.usda": orbit_animated_parent,
    "whip_pan.usda": whip_pan,
    "unreachable.usda": unreachable,
}
"""File name -> function returning the file's text."""


def long_move(n_frames: int = 1440, part: float = 1.0) -> Move:
    """A smooth, feasible combined move: track travel, crane, pan and tilt (Z-up, m).

    Frames 1..n_frames cover the first ``part`` of the move (1: all of it; 1/6 of a one-minute
    move in 240 frames keeps its speeds). Over the whole take (eased start and stop) the camera
    travels x 4 ->
    9 m with a weave, y swings ±1.2 m, z cranes between 0.2 and 1.2 m, pan wanders -30° to
    +45°, tilt -5° to -17° (lower when high); focal 35 -> 50 -> 35 mm, focus 2-4 m. (A camera
    high above the shoulder looking level is where this robot's wrist nears its singularity:
    the elbow cannot hang the forearm below a raised arm.)
    """
    if n_frames < 2:
        msg = f"n_frames must be at least 2, not {n_frames}"
        raise ValueError(msg)
    if not 0.0 < part <= 1.0:
        msg = f"part must be in (0, 1], not {part}"
        raise ValueError(msg)
    frames = np.arange(1, n_frames + 1, dtype=np.float64)
    u = ease(part * (frames - 1.0) / (n_frames - 1.0))
    pos = np.stack(
        [
            4.0 + 5.0 * u + 0.6 * np.sin(4.0 * np.pi * u),
            1.2 * np.sin(3.0 * np.pi * u),
            0.7 - 0.5 * np.cos(4.0 * np.pi * u),
        ],
        axis=1,
    )
    pan = 15.0 * u + 30.0 * np.sin(3.0 * np.pi * u)
    tilt = -5.0 - 6.0 * (1.0 - np.cos(4.0 * np.pi * u))
    focal = 35.0 + 7.5 * (1.0 - np.cos(2.0 * np.pi * u))
    focus = 3.0 + 1.0 * np.sin(2.0 * np.pi * u)
    return Move(frames, pos, pan, tilt, focal, focus, 2.8)


def write_long_shot(
    path: str | Path, n_frames: int = 1440, fps: float = 24, part: float = 1.0
) -> Path:
    """Write :func:`long_move` as a Z-up metre stage (camera ``/World/cam``), for benchmarks.

    Args:
        path: Output ``.usda`` file.
        n_frames: Number of frames (1 .. n_frames); 1440 at 24 fps is one minute.
        fps: Frames (and time codes) per second.
        part: Fraction of the one-minute move to write (see :func:`long_move`), e.g.
            ``n_frames=240, part=1/6`` for its first ten seconds at the same speeds.

    Returns:
        The written path.
    """
    move = long_move(n_frames, part)
    doc = f"camtraj long benchmark shot: {n_frames} frames at {_num(fps)} fps (Z-up, metres)."
    body = _scope("Xform", "World", [_camera_prim_trs("cam", move, "Z", 1.0, "    ")])
    text = _header(doc, "Z", 1.0, move.frames, float(fps), "World") + "\n" + body + "\n"
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    return out


def write_all(out_dir: str | Path = HERE) -> list[Path]:
    """Write the five samples into ``out_dir``; returns the written paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, build in SAMPLES.items():
        path = out / name
        path.write_text(build(), encoding="utf-8")
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    """Command line: ``make_samples.py [OUT_DIR] [--long-shot PATH [--frames N]]``."""
    parser = argparse.ArgumentParser(description="Write the sample shots (and long shots).")
    parser.add_argument("out_dir", nargs="?", default=HERE, type=Path,
                        help="folder for the five samples (default: this script's folder)")
    parser.add_argument("--long-shot", type=Path, metavar="PATH",
                        help="write only the long benchmark shot to PATH (.usda), as "
                             "`make bench` converts it")
    parser.add_argument("--frames", type=int, default=1440, metavar="N",
                        help="frames of the long shot at 24 fps (default 1440: one minute)")
    args = parser.parse_args(argv)
    if args.long_shot is not None:
        if args.frames < 2:
            parser.error(f"--frames must be at least 2, not {args.frames}")
        print(write_long_shot(args.long_shot, n_frames=args.frames))
        return 0
    for path in write_all(args.out_dir):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
