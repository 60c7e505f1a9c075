"""The shot sets the IK solver is judged on, and the yardsticks (maximum feasible speed, the
solver at k times its effort).

``shot_set``: the samples plus a few generated moves (the whole-shot solver's regression set).
``acceptance_set`` and ``motion_end_set``: issue 13's wider set of authored previs moves and
the short moves that end in motion near the ends of the track.

Generated moves are written as USD stages (Y-up centimetres or Z-up metres, as Maya and Blender
write them) with the samples' own writer and read back through camtraj's reader, so the set
exercises the unit and axis conversion too. Nothing is committed: the stages go to a temporary
folder.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
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
LONG_SHOT = "make_samples long shot 1 min (Z-up m)"


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
    """One shot of the set: flange targets (n, 4, 4) in the robot base frame and its fps;
    the stage it was read from, the placement that brings it to the robot (x, y, z [m],
    yaw [deg]; None: the stage origin) and its kind (sample, move, long or end)."""

    name: str
    targets: Array
    fps: float
    sample: bool
    path: Path | None = None
    placement: tuple[float, float, float, float] | None = None
    kind: str = "move"


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


# --------------------------------------------------------------------------------------------
# The acceptance set of issue 13: previs moves of many kinds, written as real USD stages
# --------------------------------------------------------------------------------------------

NTSC_24 = 24000.0 / 1001.0
NTSC_30 = 30000.0 / 1001.0


@dataclass(frozen=True)
class Cam:
    """A designed camera move in the robot base frame (Z-up metres, degrees), per sample."""

    pos: Array  # (n, 3)
    pan: Array  # (n,) heading, degrees from +x towards +y
    tilt: Array  # (n,) elevation above horizontal
    roll: Array | float = 0.0  # turn about the view axis (a dutch angle)


@dataclass(frozen=True)
class Design:
    """How one move of the set is authored and written.

    ``build(t, u)`` gets the sample times [s] from the first frame and the progress u in [0, 1]
    and returns the move in the robot's frame; the writer places it in the stage (``placement``:
    the robot base in the stage as x, y, z [m], yaw [deg]) in the stage's units and up axis.
    ``keys``: a key every ``keys`` film frames (sparse keys: USD interpolates between them).
    ``tcps``: time codes per second (default: one per film frame).
    ``matrix``: written as a 4x4 transform (needed for roll) instead of translate/rotateXYZ.
    """

    name: str
    build: Callable[[Array, Array], Cam]
    seconds: float
    fps: float
    up: str = "Z"
    mpu: float = 1.0
    first: int = 1
    keys: int = 1
    tcps: float | None = None
    matrix: bool = False
    placement: tuple[float, float, float, float] | None = None
    kind: str = "move"

    @property
    def frames(self) -> int:
        return round(self.seconds * self.fps) + 1


def _noise(seed: int, t: Array, amplitude: float, f_lo: float, f_hi: float,
           parts: int = 12) -> Array:
    """Smooth seeded noise: a sum of sines with random frequencies in [f_lo, f_hi] Hz and
    random phases, amplitude falling as 1/f (hand-held motion), scaled to RMS ``amplitude``."""
    rng = np.random.default_rng(seed)
    f = rng.uniform(f_lo, f_hi, parts)
    phase = rng.uniform(0.0, 2.0 * np.pi, parts)
    a = 1.0 / f
    y = (a[:, None] * np.sin(2.0 * np.pi * f[:, None] * t[None, :] + phase[:, None])).sum(axis=0)
    rms = float(np.sqrt(0.5 * (a * a).sum()))
    out: Array = amplitude * y / rms
    return out


def _aim(pos: Array, subject: Array) -> tuple[Array, Array]:
    """Pan (unwrapped) and tilt [deg] from cameras at ``pos`` (n, 3) to ``subject`` (n, 3)."""
    v = subject - pos
    pan = np.unwrap(np.degrees(np.arctan2(v[:, 1], v[:, 0])), period=360.0)
    return pan, np.degrees(np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1])))


def _look(pos: Array, subject: tuple[float, float, float]) -> tuple[Array, Array]:
    """Pan (unwrapped) and tilt [deg] from cameras at ``pos`` (n, 3) to a fixed subject."""
    return _aim(pos, np.broadcast_to(np.asarray(subject, dtype=np.float64), pos.shape))


def _ease(u: Array) -> Array:
    return np.asarray(make_samples().ease(u))


def _line(u: Array, a: tuple[float, float, float], b: tuple[float, float, float]) -> Array:
    pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    out: Array = pa[None, :] + u[:, None] * (pb - pa)[None, :]
    return out


def _hand(seed: int, t: Array, pos_m: float, ang_deg: float, f_hi: float = 4.0) -> tuple[
        Array, Array, Array, Array]:
    """Hand-held noise: (n, 3) position [m] and pan, tilt, roll [deg]."""
    pos = np.stack([_noise(seed + i, t, pos_m, 0.3, f_hi) for i in range(3)], axis=1)
    pan, tilt, roll = (_noise(seed + 10 + i, t, ang_deg, 0.2, f_hi) for i in range(3))
    return pos, pan, tilt, roll


def _designs() -> list[Design]:
    """The authored moves (robot frame: x along the track, y to its left, z up, metres)."""
    d: list[Design] = []

    def walk(t: Array, u: Array) -> Cam:  # a hand-held walk down the set, looking ahead
        x = 4.0 + 0.55 * t
        step = 0.025 * np.abs(np.sin(np.pi * 1.8 * t))  # the bob of each step
        sway = 0.03 * np.sin(np.pi * 0.9 * t)
        hp, hpan, htilt, hroll = _hand(101, t, 0.006, 0.6, f_hi=3.0)
        pos = np.stack([x, 0.6 + sway, 1.55 + step], axis=1) + hp
        return Cam(pos, 4.0 * np.sin(0.4 * t) + hpan, -4.0 + htilt, 1.0 + hroll)

    d.append(Design("handheld walk 8 s (Y-up cm, matrix)", walk, 8.0, 24.0, "Y", 0.01,
                    first=1001, matrix=True))

    def shake(t: Array, u: Array) -> Cam:  # standing still, nervous hands, on a subject
        hp, hpan, htilt, hroll = _hand(202, t, 0.008, 0.8, f_hi=4.0)
        pos = np.array([6.0, -0.7, 1.45]) + hp
        pan, tilt = _look(pos, (9.0, 0.5, 1.2))
        return Cam(pos, pan + hpan, tilt + htilt, hroll)

    d.append(Design("handheld shake 5 s (Z-up m, 30 fps)", shake, 5.0, 30.0, matrix=True))

    def backwards(t: Array, u: Array) -> Cam:  # walking backwards in front of an actor
        hp, hpan, htilt, hroll = _hand(303, t, 0.008, 0.7, f_hi=3.0)
        x = 9.0 - 0.45 * t
        pos = np.stack([x, np.full_like(t, 0.2), 1.5 + 0.02 * np.sin(2 * np.pi * 1.7 * t)],
                       axis=1) + hp
        actor = np.stack([x - 1.8, np.full_like(t, 0.1), np.full_like(t, 1.6)], axis=1)
        pan, tilt = _aim(pos, actor)
        return Cam(pos, pan + hpan, tilt + htilt, hroll)

    d.append(Design("handheld walking backwards 6 s (Y-up m, 25 fps)", backwards, 6.0, 25.0,
                    "Y", 1.0, matrix=True))

    def run(t: Array, u: Array) -> Cam:  # a fast hand-held run alongside
        hp, hpan, htilt, hroll = _hand(404, t, 0.012, 1.0, f_hi=4.0)
        pos = np.stack([3.5 + 1.4 * t, np.full_like(t, -1.0),
                        1.3 + 0.04 * np.abs(np.sin(np.pi * 2.6 * t))], axis=1) + hp
        return Cam(pos, 10.0 + hpan, -3.0 + htilt, 2.0 + hroll)

    d.append(Design("handheld run 4 s (Z-up m, 30 fps)", run, 4.0, 30.0, matrix=True))

    def orbit(subject: tuple[float, float, float], radius: float, height: float, a0: float,
              eased: bool) -> Callable[[Array, Array], Cam]:
        def build(t: Array, u: Array) -> Cam:
            s = _ease(u) if eased else u
            a = np.radians(a0 + 360.0 * s)
            pos = np.stack([subject[0] + radius * np.cos(a), subject[1] + radius * np.sin(a),
                            np.full_like(u, height)], axis=1)
            pan, tilt = _look(pos, subject)
            return Cam(pos, pan, tilt)
        return build

    d.append(Design("orbit 360 eased 12 s (Z-up m)", orbit((6.5, 0.0, 1.0), 2.0, 1.5, 180.0,
                                                           True), 12.0, 24.0))
    d.append(Design("orbit 360 constant 10 s (Y-up cm, 25 fps)",
                    orbit((6.0, 0.5, 1.2), 1.8, 1.3, -90.0, False), 10.0, 25.0, "Y", 0.01))
    d.append(Design("orbit 360 low eased 8 s (Z-up m, 48 fps)",
                    orbit((7.0, -0.3, 1.1), 1.5, 0.5, 90.0, True), 8.0, 48.0))
    d.append(Design("orbit 360 eased 15 s (Z-up m, 60 fps)",
                    orbit((5.5, 0.8, 1.0), 2.2, 1.7, 0.0, True), 15.0, 60.0))

    def crane_top(x0: float, pan0: float, pan1: float) -> Callable[[Array, Array], Cam]:
        def build(t: Array, u: Array) -> Cam:  # rise and tilt until looking straight down
            s = _ease(u)
            pos = _line(s, (x0, 0.3, 0.5), (x0 + 0.4, 0.3, 2.6))
            return Cam(pos, pan0 + (pan1 - pan0) * s, -15.0 - 75.0 * s)
        return build

    d.append(Design("crane-up to top-down 6 s (Z-up m)", crane_top(6.0, 0.0, 0.0), 6.0, 24.0))
    d.append(Design("crane-up to top-down turning 5 s (Y-up cm, 29.97 fps)",
                    crane_top(5.0, 0.0, 45.0), 5.0, NTSC_30, "Y", 0.01))

    def push_floor(t: Array, u: Array) -> Cam:  # a low push-in, lens a hand above the floor
        s = _ease(u)
        pos = _line(s, (4.0, -0.2, 0.15), (6.2, -0.1, 0.1))
        return Cam(pos, 2.0 * s, 6.0 - 2.0 * s)

    d.append(Design("low push-in near the floor 4 s (Y-up cm)", push_floor, 4.0, 24.0, "Y",
                    0.01))

    def walk_along(t: Array, u: Array) -> Cam:  # two minutes beside an actor walking the set
        s = _ease(u)
        hp, hpan, htilt, _ = _hand(505, t, 0.006, 0.5, f_hi=2.0)
        x = -0.5 + 14.5 * s + 0.4 * np.sin(2 * np.pi * t / 23.0)
        pos = np.stack([x, 2.3 + 0.3 * np.sin(2 * np.pi * t / 37.0),
                        1.4 + 0.3 * np.sin(2 * np.pi * t / 29.0)], axis=1) + hp
        actor = np.stack([x + 0.8 + 0.5 * np.sin(2 * np.pi * t / 41.0), np.zeros_like(t),
                          np.full_like(t, 1.5)], axis=1)
        pan, tilt = _aim(pos, actor)
        return Cam(pos, pan + hpan, tilt + htilt)

    d.append(Design("walk-along 2 min on the track (Z-up m)", walk_along, 120.0, 24.0,
                    kind="long"))

    def follow(t: Array, u: Array) -> Cam:  # follow a runner passing the camera, 60 fps
        runner = np.stack([3.0 + 1.3 * t, np.full_like(t, 1.5), np.full_like(t, 1.2)], axis=1)
        pos = np.stack([4.5 + 0.9 * t, np.full_like(t, -0.8), np.full_like(t, 1.3)], axis=1)
        pan, tilt = _aim(pos, runner)
        return Cam(pos, pan, tilt)

    d.append(Design("follow a runner 5 s (Z-up m, 60 fps)", follow, 5.0, 60.0))

    def whip(at: float, frames: float, angle: float, fps: float, seconds: float,
             truck: float = 0.0) -> Callable[[Array, Array], Cam]:
        def build(t: Array, u: Array) -> Cam:
            s = _ease((t - at) / (frames / fps))
            pos = _line(u, (6.0, 0.0, 1.2), (6.0 + truck * seconds, 0.0, 1.2))
            return Cam(pos, -20.0 + angle * s, np.full_like(t, -3.0))
        return build

    d.append(Design("whip pan 90 deg in 6 frames (Y-up cm)", whip(1.0, 6, 90.0, 24.0, 2.5),
                    2.5, 24.0, "Y", 0.01))
    d.append(Design("whip pan on a truck 3 s (Z-up m, 25 fps)",
                    whip(1.2, 10, 120.0, 25.0, 3.0, truck=0.6), 3.0, 25.0))

    def whip_back(t: Array, u: Array) -> Cam:  # look at something and whip back
        s = _ease((t - 0.6) / 0.3) - _ease((t - 1.8) / 0.3)
        return Cam(_line(u, (5.5, 0.4, 1.4), (5.5, 0.4, 1.4)), 70.0 * s,
                   np.full_like(t, -2.0) - 8.0 * s)

    d.append(Design("whip pan there and back 3 s (Z-up m, 30 fps)", whip_back, 3.0, 30.0))

    def dutch(t: Array, u: Array) -> Cam:  # push in while rolling to a dutch angle
        s = _ease(u)
        pos = _line(s, (4.5, 0.5, 1.3), (6.0, 0.3, 1.2))
        pan, tilt = _look(pos, (9.0, 0.0, 1.3))
        return Cam(pos, pan, tilt, 25.0 * s)

    d.append(Design("dutch roll push-in 4 s (Z-up m, matrix)", dutch, 4.0, 24.0, matrix=True))

    def rocking(t: Array, u: Array) -> Cam:  # a ship's deck: roll rocking both ways
        pos = np.stack([np.full_like(t, 6.0), 0.05 * np.sin(np.pi * t), 1.3 + 0.04 *
                        np.sin(np.pi * t + 0.5)], axis=1)
        return Cam(pos, np.full_like(t, 5.0), -2.0 + 2.0 * np.sin(np.pi * t + 1.0),
                   15.0 * np.sin(np.pi * t))

    d.append(Design("dutch rocking roll 6 s (Y-up cm, 50 fps, matrix)", rocking, 6.0, 50.0,
                    "Y", 0.01, matrix=True))

    def rest_to_rest(t: Array, u: Array) -> Cam:  # a plain eased truck with a pan
        s = _ease(u)
        return Cam(_line(s, (4.0, -1.0, 1.2), (6.5, -1.0, 1.2)), 10.0 + 20.0 * s,
                   np.full_like(u, -5.0))

    d.append(Design("truck rest to rest 4 s (Z-up cm, 23.976 fps)", rest_to_rest, 4.0, NTSC_24,
                    "Z", 0.01))

    def in_motion(t: Array, u: Array) -> Cam:  # constant speed from the first frame to the last
        pos = _line(u, (4.0, 1.2, 1.0), (7.0, 0.9, 1.4))
        return Cam(pos, -30.0 + 25.0 * u, -10.0 + 6.0 * u)

    d.append(Design("truck motion to motion 3 s (Y-up cm, 29.97 fps)", in_motion, 3.0, NTSC_30,
                    "Y", 0.01))

    def car(t: Array, u: Array) -> Cam:  # a car mount: low, fast, a gentle bend, road buzz
        s = u
        x = 2.0 + 9.0 * s
        y = -0.6 + 0.8 * s * s
        hp, hpan, htilt, hroll = _hand(606, t, 0.003, 0.25, f_hi=12.0)
        pos = np.stack([x, y, np.full_like(t, 0.8)], axis=1) + hp
        heading = np.degrees(np.arctan2(np.gradient(y), np.gradient(x)))
        return Cam(pos, heading + 8.0 + hpan, -2.0 + htilt, hroll)

    d.append(Design("car mount 6 s (Z-up m, 30 fps, matrix)", car, 6.0, 30.0, matrix=True))

    def far(t: Array, u: Array) -> Cam:  # a crane move on a set 2.5 km from the stage origin
        s = _ease(u)
        pos = _line(s, (4.5, -0.5, 0.6), (6.0, 0.4, 1.8))
        pan, tilt = _look(pos, (9.0, 0.0, 0.8))
        return Cam(pos, pan, tilt)

    d.append(Design("far from the origin 5 s (Y-up cm, placed)", far, 5.0, 24.0, "Y", 0.01,
                    placement=(2500.0, -340.0, 12.5, 37.0)))

    def dolly_zoom(t: Array, u: Array) -> Cam:  # push in on a subject (the lens zooms out)
        s = _ease(u)
        pos = _line(s, (3.5, 0.0, 1.4), (6.5, 0.0, 1.4))
        pan, tilt = _look(pos, (9.0, 0.0, 1.5))
        return Cam(pos, pan, tilt)

    d.append(Design("dolly zoom 4 s (Z-up m)", dolly_zoom, 4.0, 24.0))

    def reveal(t: Array, u: Array) -> Cam:  # boom up while tilting up from the floor
        s = _ease(u)
        pos = _line(s, (5.5, 0.0, 0.4), (5.7, 0.0, 2.2))
        return Cam(pos, np.full_like(u, 3.0), -55.0 + 50.0 * s)

    d.append(Design("tilt reveal booming up 5 s (Y-up cm)", reveal, 5.0, 24.0, "Y", 0.01))

    def slider(t: Array, u: Array) -> Cam:  # a slider on the floor, across the track
        s = _ease(u)
        pos = _line(s, (5.5, -0.7, 0.08), (5.5, 0.7, 0.08))
        return Cam(pos, np.full_like(u, 0.0), np.full_like(u, 4.0))

    d.append(Design("ground slider 4 s (Z-up m, 25 fps)", slider, 4.0, 25.0))

    def sparse(t: Array, u: Array) -> Cam:  # a blocking pass: keys once a second
        s = _ease(u)
        pos = np.stack([4.0 + 3.0 * s, 0.8 * np.sin(np.pi * s), 0.8 + 0.8 * s], axis=1)
        return Cam(pos, -15.0 + 35.0 * s, -5.0 - 10.0 * s)

    d.append(Design("sparse keys every 24 frames 6 s (Z-up m)", sparse, 6.0, 24.0, keys=24))

    def hi_codes(t: Array, u: Array) -> Cam:  # a crane and track on a 240 time codes/s stage
        s = _ease(u)
        pos = _line(s, (4.2, 0.6, 0.7), (6.2, -0.2, 1.6))
        pan, tilt = _look(pos, (8.5, -0.5, 1.0))
        return Cam(pos, pan, tilt)

    d.append(Design("240 time codes per second 4 s (Y-up cm)", hi_codes, 4.0, 24.0, "Y", 0.01,
                    tcps=240.0))

    def fast_push(t: Array, u: Array) -> Cam:  # a quick push-in shot at 48 fps
        s = _ease(u)
        return Cam(_line(s, (4.0, 0.3, 1.1), (5.8, 0.3, 1.0)), np.full_like(u, -6.0),
                   -3.0 - 2.0 * s)

    d.append(Design("fast push-in 2 s (Z-up m, 48 fps)", fast_push, 2.0, 48.0))

    def arc(t: Array, u: Array) -> Cam:  # a half arc at 50 fps past a seated subject
        s = _ease(u)
        a = np.radians(-140.0 + 100.0 * s)
        sub = (7.0, 0.5, 1.0)
        pos = np.stack([sub[0] + 2.2 * np.cos(a), sub[1] + 2.2 * np.sin(a),
                        1.1 + 0.3 * s], axis=1)
        pan, tilt = _look(pos, sub)
        return Cam(pos, pan, tilt)

    d.append(Design("arc 100 deg 5 s (Z-up m, 50 fps)", arc, 5.0, 50.0))

    def pedestal(t: Array, u: Array) -> Cam:  # pedestal down to a low angle
        s = _ease(u)
        pos = _line(s, (6.0, -0.5, 2.0), (6.1, -0.5, 0.2))
        pan, tilt = _look(pos, (9.5, 0.0, 1.6))
        return Cam(pos, pan, tilt)

    d.append(Design("pedestal down 4 s (Y-up cm, 60 fps)", pedestal, 4.0, 60.0, "Y", 0.01))

    def overhead(t: Array, u: Array) -> Cam:  # a top-down camera flying along the track
        s = _ease(u)
        return Cam(_line(s, (4.0, 0.0, 2.4), (8.0, 0.0, 2.4)), np.full_like(u, 0.0),
                   np.full_like(u, -90.0))

    d.append(Design("overhead top-down truck 5 s (Z-up m)", overhead, 5.0, 24.0))

    def slow_push(t: Array, u: Array) -> Cam:  # a slow ten-second push with a small drift
        s = _ease(u)
        pos = _line(s, (3.8, 0.9, 1.6), (5.2, 0.6, 1.4))
        pan, tilt = _look(pos, (10.0, -0.4, 1.3))
        return Cam(pos, pan, tilt)

    d.append(Design("slow push 10 s (Z-up m, 23.976 fps)", slow_push, 10.0, NTSC_24))

    def swing_across(t: Array, u: Array) -> Cam:  # cross the track line, turning to keep framing
        s = _ease(u)
        pos = _line(s, (6.0, -1.6, 1.0), (6.5, 1.6, 1.5))
        pan, tilt = _look(pos, (9.0, 0.0, 1.0))
        return Cam(pos, pan, tilt)

    d.append(Design("swing across the track 4 s (Y-up cm, 30 fps)", swing_across, 4.0, 30.0,
                    "Y", 0.01))

    def handheld_push(t: Array, u: Array) -> Cam:  # a hand-held push towards a table
        s = _ease(u)
        hp, hpan, htilt, hroll = _hand(707, t, 0.006, 0.5, f_hi=3.0)
        pos = _line(s, (4.0, -0.4, 1.2), (5.5, -0.2, 1.0)) + hp
        pan, tilt = _look(pos, (8.0, 0.0, 0.75))
        return Cam(pos, pan + hpan, tilt + htilt, hroll)

    d.append(Design("handheld push to a table 5 s (Z-up cm, 24 fps, matrix)", handheld_push,
                    5.0, 24.0, "Z", 0.01, matrix=True))

    def reach_truck(end_x: float) -> Callable[[Array, Array], Cam]:
        def build(t: Array, u: Array) -> Cam:
            # away from rest to 1.5 m/s in a second, then on at that speed to the last frame
            # at camera x = end_x, past the track's end (the arm reaches on): the track and
            # the extend both end near their limits, still moving, and the run-out's room
            # decides the speed
            v = 1.5 * np.clip(t, 0.0, 1.0)
            x = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
            pos = np.stack([end_x - x[-1] + x, np.full_like(t, -1.0), np.full_like(t, 1.3)],
                           axis=1)
            return Cam(pos, np.full_like(t, 90.0), np.full_like(t, -3.0))
        return build

    # 5.7 m past the track's end: both prismatic axes end on their limits
    d.append(Design("truck ends moving at the arm's full reach 8 s (Z-up m)", reach_truck(19.7),
                    8.0, 24.0))
    # 5.5 m past it: the arm takes over from the track before the end (a new user's move the
    # programme ranked into a slow basin, 0.90 of 10x the effort)
    d.append(Design("truck ends moving past the track's end 8 s (Z-up m)", reach_truck(19.5),
                    8.0, 24.0))

    def crane_down_end(t: Array, u: Array) -> Cam:  # ends moving with the elbow near its limit
        pos = _line(u, (16.8, -0.4, 1.9), (17.6, -0.4, 0.9))
        return Cam(pos, -20.0 + 50.0 * u, -25.0 + 20.0 * u)

    d.append(Design("crane down with pan ends moving at the track's end 0.8 s (Y-up cm, 25 fps)",
                    crane_down_end, 0.8, 25.0, "Y", 0.01))
    return d


def _stage_pose(cam: Cam, placement: tuple[float, float, float, float] | None) -> Cam:
    """The move in the stage's (Z-up metre) frame: the placement maps the robot base into it."""
    if placement is None:
        return cam
    x, y, z, yaw = placement
    a = np.radians(yaw)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    return Cam(cam.pos @ rot.T + np.array([x, y, z]), cam.pan + yaw, cam.tilt, cam.roll)


def write_design(design: Design, folder: Path) -> Path:
    """Write one designed move as a USD stage in ``folder`` (keys on film frames, or every
    ``design.keys`` frames, at ``design.tcps`` time codes per second)."""
    ms = make_samples()
    n = design.frames
    keyed = np.unique(np.r_[np.arange(0, n, design.keys), n - 1])
    t = keyed / design.fps
    cam = _stage_pose(design.build(t, t / ((n - 1) / design.fps)), design.placement)
    per_frame = (design.tcps or design.fps) / design.fps
    codes = (design.first + keyed) * per_frame
    roll = cam.roll if isinstance(cam.roll, float) else np.asarray(cam.roll)
    move = ms.Move(codes, cam.pos, cam.pan, cam.tilt, focal_mm=35.0, focus_m=3.0, f_stop=2.8,
                   roll=roll)
    if design.matrix:
        prim = ms._camera_prim_matrix("cam", move, design.mpu, "    ", design.up)
    else:
        prim = ms._camera_prim_trs("cam", move, design.up, design.mpu, "    ")
    text = (ms._header(f"camtraj acceptance shot: {design.name}", design.up, design.mpu, codes,
                       design.fps, "World", design.tcps) + "\n"
            + ms._scope("Xform", "World", [prim]) + "\n")
    path = folder / (_file_stem(design.name) + ".usda")
    path.write_text(text, encoding="utf-8")
    return path


def _file_stem(name: str) -> str:
    stem = name.split(" (")[0]
    return "".join(c if c.isalnum() else "_" for c in stem)


#: Where the short end-in-motion moves happen: camera x [m] and the way out (+1: towards the
#: track's far end, -1: towards its start).
TRACK_SPOTS = {"start": (-3.8, -1.0), "middle": (6.0, 1.0), "end": (17.8, 1.0)}


def _end_designs() -> list[Design]:
    """Short moves (12-48 frames) that end (or start) in motion at the start, middle and end
    of the track: trucks, whips, swing-ins and a crane."""
    d: list[Design] = []
    for where, (x_end, way) in TRACK_SPOTS.items():

        def truck_out(t: Array, u: Array, x_end: float = x_end, way: float = way) -> Cam:
            # accelerating (1.2 m/s^2) into a 1.6 m/s truck still running at the last frame
            left = t[-1] - t
            x = x_end - way * (1.6 * left - 0.6 * left * left)
            pos = np.stack([x, np.full_like(t, 0.8), np.full_like(t, 1.2)], axis=1)
            return Cam(pos, np.full_like(t, 90.0 - 90.0 * way), np.full_like(t, -4.0))

        d.append(Design(f"truck ends moving, {where} (Z-up m)", truck_out, 1.0, 24.0,
                        kind="end"))

        def truck_in(t: Array, u: Array, x_end: float = x_end, way: float = way) -> Cam:
            # starts at full speed at the spot and brakes inwards to rest
            x = x_end - way * (1.0 * t - 0.5 * t * t / t[-1])
            pos = np.stack([x, np.full_like(t, -0.6), np.full_like(t, 1.0)], axis=1)
            return Cam(pos, np.full_like(t, 20.0), np.full_like(t, -2.0))

        d.append(Design(f"truck starts moving, {where} (Y-up cm, 30 fps)", truck_in, 1.5, 30.0,
                        "Y", 0.01, kind="end"))

        def whip_end(t: Array, u: Array, x_end: float = x_end) -> Cam:
            # an accelerating whip cut at its fastest (12 frames)
            pos = np.tile([x_end, 0.3, 1.3], (t.size, 1))
            return Cam(pos, -10.0 + 120.0 * u**3, np.full_like(t, -3.0))

        d.append(Design(f"whip pan ends moving, {where} (Z-up m)", whip_end, 11.0 / 24.0, 24.0,
                        kind="end"))

        def swing_in(t: Array, u: Array, x_end: float = x_end, way: float = way) -> Cam:
            # an arc that swings in towards the spot, still turning and moving at the end
            a = np.radians(-90.0 + 90.0 * u)
            centre = np.array([x_end - way * 1.5, 0.0, 1.0])
            pos = np.stack([centre[0] + way * 1.5 * np.cos(a), centre[1] + 1.5 * np.sin(a),
                            0.8 + 0.6 * u], axis=1)
            pan, tilt = _look(pos, (float(centre[0]), 0.0, 1.0))
            return Cam(pos, pan, tilt)

        d.append(Design(f"swing-in ends moving, {where} (Y-up cm, 48 fps)", swing_in, 0.75,
                        48.0, "Y", 0.01, kind="end"))

    def crane_end(t: Array, u: Array) -> Cam:  # rising and tilting, still going at the end
        x_end = TRACK_SPOTS["end"][0]
        pos = _line(u, (x_end - 0.8, 0.5, 0.6), (x_end, 0.5, 1.8))
        return Cam(pos, np.full_like(u, -10.0), -5.0 - 30.0 * u)

    d.append(Design("crane ends moving, end (Z-up m, 25 fps)", crane_end, 1.6, 25.0,
                    kind="end"))

    def whip_start(t: Array, u: Array) -> Cam:  # starts in a whip and settles
        pos = np.tile([TRACK_SPOTS["start"][0], -0.5, 1.1], (t.size, 1))
        return Cam(pos, 150.0 - 100.0 * (1.0 - (1.0 - u) ** 3), np.full_like(t, -6.0))

    d.append(Design("whip pan starts moving, start (Z-up m, 30 fps)", whip_start, 0.8, 30.0,
                    kind="end"))
    return d


def _read(robot: Robot, path: Path, name: str, kind: str,
          placement: tuple[float, float, float, float] | None) -> SetShot:
    """A written stage read back through camtraj's reader, placed as ``convert`` places it."""
    from camtraj.convert import Placement

    shot = read_shot(path)
    base2world = (np.eye(4) if placement is None
                  else Placement.from_xyz_yaw(*placement).base2world)
    targets = np.linalg.inv(base2world) @ shot.cam2world @ np.linalg.inv(robot.camera2flange)
    return SetShot(name, targets, float(shot.fps), kind == "sample", path, placement, kind)


def acceptance_set(robot: Robot, folder: Path, *, quick: bool = False) -> list[SetShot]:
    """Issue 13's shot set: the samples (without the unreachable one), the one-minute move
    ``make bench`` converts (``make_samples.py --long-shot``) and the authored moves
    (``quick``: without the long ones), each a USD stage in ``folder`` read back."""
    out = [_read(robot, SHOTS / s, Path(s).stem, "sample", None) for s in SAMPLES]
    if not quick:  # the minute-long move make bench converts, held at both ends
        long = make_samples().write_long_shot(folder / "long_shot.usda")
        out.append(_read(robot, long, LONG_SHOT, "long", None))
    for design in _designs():
        if quick and design.kind == "long":
            continue
        out.append(_read(robot, write_design(design, folder), design.name, design.kind,
                         design.placement))
    return out


def motion_end_set(robot: Robot, folder: Path) -> list[SetShot]:
    """The short moves that end (or start) in motion near the start, middle and end of the
    track, each a USD stage in ``folder`` read back."""
    return [_read(robot, write_design(design, folder), design.name, design.kind,
                  design.placement) for design in _end_designs()]


# --------------------------------------------------------------------------------------------
# The yardsticks: maximum feasible speed, and the solver at k times its effort
# --------------------------------------------------------------------------------------------

EFFORT = 10
"""The effort multiple of the reference solve the default is measured against."""


def with_effort(robot: Robot, k: float) -> Robot:
    """``robot`` with k times the IK effort: k times the refinement rounds per stage, a k times
    tighter convergence test, and about k times the dynamic programme's work (its cost grows
    with the square of the candidates: k^(1/4) times the track and extend samples each). The
    one place that knows the solver's effort knobs."""
    ik = robot.ik
    grid = k ** 0.25
    return dataclasses.replace(robot, ik=dataclasses.replace(
        ik,
        refine_rounds=min(1000, round(ik.refine_rounds * k)),
        refine_tolerance=ik.refine_tolerance / k,
        track_samples=min(16, max(1, round(ik.track_samples * grid))),
        extend_samples=min(16, max(1, round(ik.extend_samples * grid))),
    ))


def max_speed(robot: Robot, q: Array, fps: float, targets: Array,
              rest: NDArray[np.int8] | None = None) -> float:
    """The timing stage's maximum feasible speed of the joint path ``q`` (n, 8) at ``fps``, as
    a fraction of real time (``inf``: nothing moves), timed as ``convert`` times it: still
    where the camera ``targets`` (n, 4, 4) hold, and at rest on the end frames ``rest``
    (``PathSolution.rest_axes``) says.

    A path whose spline leaves a position limit between frames still gets the speed its
    velocities, accelerations and jerks allow (the timing stage reports it with the error); a
    path no speed can make work (the error carries no speed) gets 0.
    """
    from camtraj.ik import camera_holds
    from camtraj.timing import Limits, TimingLimitError, time_shot

    times = np.arange(q.shape[0]) / fps
    try:
        return float(time_shot(q, times, Limits.from_robot(robot), mode="scale",
                               hold=camera_holds(targets), rest=rest).report.max_speed)
    except TimingLimitError as exc:
        speed = float(exc.max_speed)
        return speed if math.isfinite(speed) else 0.0


@dataclass(frozen=True)
class Speeds:
    """A shot solved three ways, and the maximum feasible speed of each: the default as
    ``convert`` runs it (``--edges still``: the robot still on an end frame where the camera
    rests; ``rest`` is its ``time_shot`` rest mask), ``paper`` (the papers' method, free
    ends) and the default at k times the effort (still ends too)."""

    default: float
    paper: float
    effort: float
    q_default: Array
    q_paper: Array
    q_effort: Array
    rest: NDArray[np.int8] | None = None


def gentle_speed(robot: Robot, shot: SetShot) -> float:
    """The default's maximum feasible speed with ``--edges gentle`` (free ends: the robot may
    move on an end frame where the camera rests)."""
    from camtraj.ik import solve_path

    q = solve_path(robot, shot.targets, frame_interval=1.0 / shot.fps)
    return max_speed(robot, q, shot.fps, shot.targets)


def speeds(robot: Robot, shot: SetShot, k: float = EFFORT) -> Speeds:
    """The default objective as ``convert`` runs it, ``paper`` and the default at ``k`` times
    the effort on ``shot``."""
    from camtraj.ik import solve_path, solve_path_report

    dt = 1.0 / shot.fps
    p = solve_path_report(robot, shot.targets, frame_interval=dt, still_ends=True)
    qp = solve_path(robot, shot.targets, objective="paper", frame_interval=dt)
    pk = solve_path_report(with_effort(robot, k), shot.targets, frame_interval=dt,
                           still_ends=True)
    return Speeds(max_speed(robot, p.q, shot.fps, shot.targets, p.rest_axes()),
                  max_speed(robot, qp, shot.fps, shot.targets),
                  max_speed(robot, pk.q, shot.fps, shot.targets, pk.rest_axes()),
                  p.q, qp, pk.q, p.rest_axes())
