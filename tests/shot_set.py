"""The acceptance shot set of the whole-shot solver: the samples plus generated moves.

Generated moves are written as USD stages (Y-up centimetres or Z-up metres, as Maya and Blender
write them) with the samples' own writer and read back through camtraj's reader, so the set
exercises the unit and axis conversion too. Nothing is committed: the stages go to a temporary
folder.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np
from numpy.typing import NDArray

from camtraj.robot import Robot
from camtraj.usd_shot import read_shot

Array = NDArray[np.float64]
SHOTS = Path(__file__).resolve().parent.parent / "samples" / "shots"
SAMPLES = ("maya_dolly_push_in.usda", "blender_crane_up.usda", "orbit_animated_parent.usda",
           "whip_pan.usda")


def make_samples() -> ModuleType:
    """``samples/shots/make_samples.py`` as a module (shared with test_usd_shot)."""
    name = "camtraj_samples_make_samples"
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, SHOTS / "make_samples.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@dataclass(frozen=True)
class SetShot:
    """One shot of the set: flange targets (n, 4, 4) in the robot base frame and its fps."""

    name: str
    targets: Array
    fps: float
    sample: bool


def _linear(n: int) -> Array:
    return np.linspace(0.0, 1.0, n)


def _eased(n: int) -> Array:
    return np.asarray(make_samples().ease(np.linspace(0.0, 1.0, n)))


def _moves() -> dict[str, tuple[Callable[[], tuple[Array, Array, Array]], float, str, float]]:
    """name -> (positions, pan, tilt builder; seconds; up axis; metres per unit)."""
    ms = make_samples()

    def push_in_moving() -> tuple[Array, Array, Array]:  # 1 s, in motion at both ends
        s = _linear(24)
        pos = np.stack([4.0 + 1.0 * s, np.full_like(s, -0.8), np.full_like(s, 1.3)], axis=1)
        pan, tilt = ms.look_at(pos, np.array([9.0, 0.0, 1.2]))
        return pos, pan, tilt

    def push_in_rest() -> tuple[Array, Array, Array]:  # 2 s, eased from rest to rest
        s = _eased(48)
        pos = np.stack([3.5 + 1.5 * s, np.full_like(s, 0.6), np.full_like(s, 1.0)], axis=1)
        pan, tilt = ms.look_at(pos, np.array([8.5, 0.0, 1.0]))
        return pos, pan, tilt

    def crane_up_moving() -> tuple[Array, Array, Array]:  # 2 s, rising through the ends
        s = _linear(48)
        pos = np.stack([5.0 + 0.2 * s, np.full_like(s, 0.4), 0.3 + 1.5 * s], axis=1)
        return pos, np.zeros_like(s), -5.0 - 35.0 * s

    def crane_up_steep() -> tuple[Array, Array, Array]:  # 3 s, tilting far down, at rest
        s = _eased(72)
        pos = np.stack([5.0 + 0.3 * s, np.full_like(s, 0.2), 0.4 + 1.6 * s], axis=1)
        return pos, np.full_like(s, 10.0), -10.0 - 60.0 * s

    def orbit() -> tuple[Array, Array, Array]:  # 3 s, 120 deg around a subject
        s = _eased(72)
        subject = np.array([6.0, 0.0, 1.0])
        a = np.radians(-150.0 + 120.0 * s)
        pos = np.stack([subject[0] + 2.0 * np.cos(a), subject[1] + 2.0 * np.sin(a),
                        np.full_like(s, 1.2)], axis=1)
        pan, tilt = ms.look_at(pos, subject)
        return pos, pan, tilt

    def track_fast() -> tuple[Array, Array, Array]:  # 2 s, 3 m of track, in motion
        s = _linear(48)
        pos = np.stack([3.0 + 3.0 * s, np.full_like(s, -0.5), np.full_like(s, 1.1)], axis=1)
        return pos, np.full_like(s, 5.0), np.full_like(s, -5.0)

    def track_drift() -> tuple[Array, Array, Array]:  # 4 s, track with a drift and a pan
        s = _eased(96)
        pos = np.stack([3.0 + 4.0 * s, 0.8 * np.sin(np.pi * s), 0.9 + 0.4 * s], axis=1)
        return pos, 25.0 * np.sin(np.pi * s), -8.0 * s

    def pan_tilt() -> tuple[Array, Array, Array]:  # 1 s, a nodal-ish pan and tilt
        s = _linear(24)
        pos = np.stack([5.0 + 0.05 * s, np.full_like(s, 0.3), np.full_like(s, 1.4)], axis=1)
        return pos, -20.0 + 40.0 * s, 5.0 - 15.0 * s

    def crane_track() -> tuple[Array, Array, Array]:  # 2 s, diagonal rise along the track
        s = _eased(48)
        pos = np.stack([4.0 + 2.0 * s, -0.4 + 0.8 * s, 0.5 + 1.0 * s], axis=1)
        return pos, 15.0 * s, -20.0 * s

    return {
        "push-in 1 s moving (Y-up cm)": (push_in_moving, 1.0, "Y", 0.01),
        "push-in 2 s at rest (Z-up m)": (push_in_rest, 2.0, "Z", 1.0),
        "crane-up 2 s moving (Z-up m)": (crane_up_moving, 2.0, "Z", 1.0),
        "crane-up 3 s steep tilt (Y-up cm)": (crane_up_steep, 3.0, "Y", 0.01),
        "orbit 3 s (Y-up cm)": (orbit, 3.0, "Y", 0.01),
        "track move 2 s fast, moving (Z-up m)": (track_fast, 2.0, "Z", 1.0),
        "track move 4 s drift (Z-up m)": (track_drift, 4.0, "Z", 1.0),
        "pan/tilt 1 s moving (Y-up cm)": (pan_tilt, 1.0, "Y", 0.01),
        "crane + track 2 s (Y-up cm)": (crane_track, 2.0, "Y", 0.01),
    }


def write_generated(name: str, folder: Path) -> Path:
    """Write the generated move ``name`` as a USD stage in ``folder``."""
    ms = make_samples()
    build, _seconds, up, mpu = _moves()[name]
    pos, pan, tilt = build()
    frames = np.arange(1, pos.shape[0] + 1, dtype=np.float64)
    move = ms.Move(frames, pos, pan, tilt, focal_mm=35.0, focus_m=3.0, f_stop=2.8)
    text = (ms._header(f"camtraj test shot: {name}", up, mpu, frames, 24.0, "cam") + "\n"
            + ms._camera_prim_trs("cam", move, up, mpu, "") + "\n")
    path = folder / (name.split(" (")[0].replace(" ", "_").replace("/", "_") + ".usda")
    path.write_text(text, encoding="utf-8")
    return path


def shot_set(robot: Robot, folder: Path, *, long: bool = True) -> list[SetShot]:
    """The samples (without the unreachable one), the generated moves and (``long``) the
    one-minute benchmark move."""
    flange2camera = np.linalg.inv(robot.camera2flange)
    out = []
    paths = [(SHOTS / s, True) for s in SAMPLES]
    paths += [(write_generated(name, folder), False) for name in _moves()]
    if long:
        paths.append((make_samples().write_long_shot(folder / "long.usda", 1440, 24.0), False))
    for path, sample in paths:
        shot = read_shot(path)
        out.append(SetShot(path.stem, shot.cam2world @ flange2camera, float(shot.fps), sample))
    return out
