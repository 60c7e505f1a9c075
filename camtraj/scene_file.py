"""The scene file: the shots shot from one track layout, each with its own options (TOML).

``camtraj place --scene`` searches one placement for its shots (:mod:`camtraj.scene`) and
``camtraj batch --scene`` converts them, each with its camera, frames and timing.

The scene file (TOML; paths relative to it)::

    name = "sc12"              # the layout's name, written into the placed set file
    set_file = "set.toml"      # optional (or --set-file)

    [[shot]]
    path = "sh010.usda"
    camera = "/World/cam"      # optional: the only camera
    frames = [1, 48]           # optional: the stage's range
    timing = "shot"            # optional: "shot" (must run at its own timing), "scale" or
                               # "optimal" (may be slowed down: only reach and collisions count)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from camtraj.choices import TIMING_MODES
from camtraj.errors import InputError
from camtraj.inputs import one_line, parse_toml, read_text, reject_unknown_keys
from camtraj.shown import frame_span

_SCENE_KEYS = {"name", "set_file", "shot"}
_SHOT_KEYS = {"path", "camera", "frames", "timing"}

@dataclass(frozen=True)
class SceneShot:
    """One shot of a scene and its own options."""

    path: str
    camera: str | None = None
    frames: tuple[int, int] | None = None
    timing: str = "shot"

    @property
    def name(self) -> str:
        """The shot for people: its file, and its camera and frames where the scene gives
        them (one stage file often holds several cameras: the file alone named none)."""
        camera = f" {self.camera}" if self.camera else ""
        frames = f" frames {frame_span(*self.frames)}" if self.frames else ""
        return one_line(f"{self.path}{camera}{frames}")

    def to_json(self) -> dict[str, Any]:
        return {"path": self.path, "camera": self.camera,
                "frames": list(self.frames) if self.frames else None, "timing": self.timing}


@dataclass(frozen=True)
class Scene:
    """A parsed scene file (see the module docstring)."""

    source: str
    shots: tuple[SceneShot, ...]
    name: str | None = None
    set_file: str | None = None

    @classmethod
    def read(cls, path: str | os.PathLike[str]) -> Scene:
        """Read and check a scene file; shot and set file paths are made relative to it.

        Raises:
            InputError: Unreadable, not TOML, unknown keys, malformed values (one line naming
                the file and the key).
        """
        where = f"scene file {one_line(path)}"
        text = read_text(path, "scene file", InputError)
        data = parse_toml(text, where, InputError)
        reject_unknown_keys(data, _SCENE_KEYS, where, "the top level", InputError)
        base = Path(os.fsdecode(path)).parent
        name = data.get("name")
        if name is not None and not (isinstance(name, str) and name.isprintable()
                                     and 0 < len(name) <= 200):
            msg = f"{where}: name must be 1 to 200 printable characters"
            raise InputError(msg)
        set_file = data.get("set_file")
        if set_file is not None and not (isinstance(set_file, str) and set_file):
            msg = f"{where}: set_file must be a file name"
            raise InputError(msg)
        shots = data.get("shot")
        if not isinstance(shots, list) or not shots or not all(isinstance(s, dict)
                                                                for s in shots):
            msg = f'{where}: list the shots as [[shot]] tables, each with a path = "…"'
            raise InputError(msg)
        parsed = tuple(_shot(s, base, f"{where}: [[shot]] {k + 1}") for k, s in enumerate(shots))
        refuse_repeats(parsed)
        return cls(one_line(path), parsed, name,
                   None if set_file is None else str(base / set_file))


def _shot(table: dict[str, Any], base: Path, where: str) -> SceneShot:
    reject_unknown_keys(table, _SHOT_KEYS, where, "the shot", InputError)
    path = table.get("path")
    if not isinstance(path, str) or not path:
        msg = f'{where}: path = "SHOT.usda" is required'
        raise InputError(msg)
    camera = table.get("camera")
    if camera is not None and not (isinstance(camera, str) and camera.startswith("/")
                                   and all(part and part.isprintable() and not any(
                                       c.isspace() for c in part)
                                       for part in camera[1:].split("/"))):
        msg = f"{where}: camera must be a prim path such as /World/cam"
        raise InputError(msg)
    frames = table.get("frames")
    if frames is not None:
        ok = (isinstance(frames, list) and len(frames) == 2
              and all(isinstance(f, int) and not isinstance(f, bool) for f in frames)
              and frames[0] <= frames[1])
        if not ok:
            msg = f"{where}: frames must be [first, last], two whole numbers, first <= last"
            raise InputError(msg)
        frames = (frames[0], frames[1])
    timing = table.get("timing", "shot")
    if timing not in TIMING_MODES:
        msg = f"{where}: timing must be one of {', '.join(TIMING_MODES)}, got {timing!r}"
        raise InputError(msg)
    return SceneShot(str(base / path), camera, frames, timing)


def refuse_repeats(shots: Sequence[SceneShot]) -> None:
    """A shot listed twice (the same file, under any name, with the same camera and frames)
    is a mistake in the list, not a second shot.

    Raises:
        InputError: Naming both places in the list.
    """
    seen: dict[tuple[int, int, str | None, tuple[int, int] | None], int] = {}
    for k, s in enumerate(shots):
        try:
            st = os.stat(s.path)
        except (OSError, ValueError):  # a missing shot: the reader says so, as bad input
            continue
        key = (st.st_dev, st.st_ino, s.camera, s.frames)
        if key in seen:
            first = seen[key]
            msg = (f"shot {k + 1} ({s.name}) repeats shot {first + 1} "
                   f"({shots[first].name}): the same file, camera and frames; list each "
                   "shot once")
            raise InputError(msg)
        seen[key] = k
