"""The files a run reads: the shot and the USD layers it uses, the robot file, the set file.

Two checks use them before any work is done: every input must be a regular file (a named
pipe would block the read forever, a device would be read without end), and no output may be
one of them (:meth:`camtraj.outputs.OutputSet.refuse_inputs`).
"""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path
from typing import Any

from camtraj.errors import InputError, RobotFileError, ShotFileError
from camtraj.options import ConvertOptions

__all__ = ["require_regular_files", "run_inputs", "shot_layers"]

_KIND = {
    stat.S_IFDIR: "a folder",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFIFO: "a named pipe (FIFO)",
    stat.S_IFSOCK: "a socket",
}


def require_regular_file(path: str | os.PathLike[str], what: str, error: type[InputError]) -> None:
    """Raise ``error`` unless ``path`` is a regular file (symlinks followed).

    A missing file is left to the reader, which says so in its own words.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return
    if not stat.S_ISREG(mode):
        kind = _KIND.get(stat.S_IFMT(mode), "not a regular file")
        msg = f"{os.fsdecode(path)}: the {what} is {kind}, not a regular file"
        raise error(msg)


def require_regular_files(shot: str | os.PathLike[str], options: ConvertOptions) -> None:
    """The shot, robot file and set file of a run must be regular files.

    The shot's name must also be valid UTF-8: USD takes file names as UTF-8 text.
    """
    try:
        os.fsdecode(shot).encode("utf-8")
    except UnicodeEncodeError:
        name = os.fsdecode(shot).encode("utf-8", "backslashreplace").decode("ascii", "replace")
        msg = f"{name}: the file name is not valid UTF-8 and USD cannot open it; rename the file"
        raise ShotFileError(msg) from None
    require_regular_file(shot, "shot", ShotFileError)
    if options.robot is not None:
        require_regular_file(options.robot, "robot file", RobotFileError)
    if options.set_file is not None and options.placement is None:
        require_regular_file(options.set_file, "set file", InputError)


def shot_layers(shot: str | os.PathLike[str]) -> list[Path]:
    """Every file the USD shot pulls in: sublayers, references, payloads, clips (not itself).

    Uses ``UsdUtils.ComputeAllDependencies``. A shot USD cannot open gives an empty list
    (reading it reports the error); USD's diagnostics are kept off stderr.
    """
    from pxr import Sdf, Tf, UsdUtils

    root = os.path.realpath(shot)
    trap_type = getattr(Tf, "DiagnosticTrap", None)
    trap: Any = trap_type() if trap_type is not None else contextlib.nullcontext()
    try:
        with trap as caught:
            layers, assets, _ = UsdUtils.ComputeAllDependencies(Sdf.AssetPath(root))
            if caught is not None:
                caught.Clear()
    except Exception:  # USD raises Tf.ErrorException and others; reading reports it
        return []
    found = [str(layer.realPath) for layer in layers] + [str(a) for a in assets]
    return [Path(p) for p in dict.fromkeys(found) if p and os.path.realpath(p) != root]


def run_inputs(shot: str | os.PathLike[str], options: ConvertOptions) -> list[tuple[Path, str]]:
    """(path, description) of every file a convert run reads, for the output checks."""
    name = Path(os.fsdecode(shot)).name
    inputs = [(Path(os.fsdecode(shot)), "the shot")]
    if os.path.isfile(shot):
        inputs += [(p, f"a layer used by the shot {name}") for p in shot_layers(shot)]
    if options.robot is not None:
        inputs.append((Path(options.robot), "the robot file"))
    if options.set_file is not None:
        inputs.append((Path(options.set_file), "the set file"))
    return inputs
