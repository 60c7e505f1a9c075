"""The files a run reads: the shot and the USD layers it uses, the robot file, the set file,
the lens file, an MCAP, a task manifest.

Every command reads its inputs through this module, so two checks hold for all of them
before any work is done: every input must be a regular file (a named pipe would block the read
forever, a device would be read without end), and no output may be one of them
(:meth:`camtraj.outputs.OutputSet.refuse_inputs`, given :func:`files_read`). Small text inputs
(robot, set, lens and manifest files) are read whole by :func:`read_text`: UTF-8, a BOM allowed.
"""

from __future__ import annotations

import codecs
import contextlib
import json
import os
import stat
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from camtraj import interrupts
from camtraj.errors import (
    InputError,
    LensFileError,
    RobotFileError,
    ShotFileError,
    file_kind,
    one_line,
)

if TYPE_CHECKING:  # a type only (options imports robot, which reads its file here)
    from camtraj.options import ConvertOptions

__all__ = [
    "files_read",
    "one_line",
    "parse_json",
    "read_text",
    "require_regular_file",
    "require_regular_files",
    "require_regular_layers",
    "run_inputs",
    "shot_layers",
]

MAX_TEXT_BYTES = 64 * 1024 * 1024
"""Largest robot, set or manifest file read [bytes]; more is not a hand-written file."""


def require_regular_file(path: str | os.PathLike[str], what: str, error: type[InputError]) -> None:
    """Raise ``error`` unless ``path`` is a regular file (symlinks followed).

    A missing file is left to the reader, which says so in its own words.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return
    if not stat.S_ISREG(mode):
        kind = file_kind(mode)
        msg = f"{one_line(path)}: the {what} is {kind}, not a regular file"
        raise error(msg)


def parse_toml(text: str, where: str, error: type[InputError]) -> dict[str, Any]:
    """The table of a TOML text; a syntax error is one line naming ``where`` (the file), and
    so is what the parser cannot hold (arrays nested thousands deep, a 5,000-digit number)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = f"{where}: not valid TOML ({exc})"
        raise error(msg) from None
    except (RecursionError, ValueError) as exc:
        msg = f"{where}: not a TOML file camtraj can read ({_why(exc)})"
        raise error(msg) from None


def parse_json(text: str, where: str, error: type[InputError]) -> Any:
    """The value of a JSON text; a syntax error is one line naming ``where`` (the file), and
    so is what the parser cannot hold (arrays nested thousands deep, a 5,000-digit number)."""
    try:
        return json.loads(text)
    except (RecursionError, ValueError) as exc:
        msg = f"{where}: not JSON camtraj can read ({_why(exc)})"
        raise error(msg) from None


def _why(exc: Exception) -> str:
    return "nested too deep" if isinstance(exc, RecursionError) else one_line(str(exc))


def reject_unknown_keys(table: dict[str, Any], allowed: set[str], where: str, what: str,
                        error: type[InputError]) -> None:
    """One line naming the file (``where``), the table (``what``), the keys it does not know
    and those it does, if ``table`` has a key outside ``allowed``."""
    unknown = sorted(set(table) - allowed)
    if unknown:
        msg = (f"{where}: unknown key(s) {', '.join(unknown)} in {what}; "
               f"allowed: {', '.join(sorted(allowed))}")
        raise error(msg)


def read_text(path: str | os.PathLike[str], what: str, error: type[InputError]) -> str:
    """The whole text of a small UTF-8 input file (a BOM is allowed and dropped).

    Args:
        path: The file.
        what: What it is, for messages (``"robot file"``, ``"set file"``).
        error: The error class raised.

    Raises:
        error: Missing, not a regular file, too large, UTF-16/32 or not UTF-8, or NUL bytes;
            one line naming the file.
    """
    where = f"{what} {one_line(path)}"
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        msg = f"{where}: cannot read it ({reason})"
        raise error(msg) from None
    try:  # O_NONBLOCK: opening a FIFO does not wait for a writer
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = file_kind(st.st_mode)
            msg = f"{where}: cannot read it: it is {kind}, not a regular file"
            raise error(msg)
        if st.st_size > MAX_TEXT_BYTES:
            msg = f"{where}: {st.st_size} bytes is too large for a {what}"
            raise error(msg)
        with os.fdopen(os.dup(fd), "rb") as stream:
            data = stream.read()
    except OSError as exc:
        msg = f"{where}: cannot read it ({exc.strerror or exc})"
        raise error(msg) from None
    finally:
        os.close(fd)
    for bom, name in ((codecs.BOM_UTF32_LE, "UTF-32"), (codecs.BOM_UTF32_BE, "UTF-32"),
                      (codecs.BOM_UTF16_LE, "UTF-16"), (codecs.BOM_UTF16_BE, "UTF-16")):
        if data.startswith(bom):
            msg = f"{where}: the file is {name} text; save it as UTF-8"
            raise error(msg)
    try:
        text = data.decode("utf-8-sig")  # a BOM (Windows editors) is fine
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        msg = (f"{where}: not UTF-8 text (byte 0x{data[exc.start]:02x} on line {line}); "
               f"a {what} is UTF-8 text")
        raise error(msg) from None
    if "\0" in text:
        msg = f"{where}: holds NUL bytes: a binary or UTF-16 file, not UTF-8 text"
        raise error(msg)
    return text


def require_regular_files(shot: str | os.PathLike[str], options: ConvertOptions) -> None:
    """The shot, robot file, set file and lens file of a run must be regular files.

    The shot's name must also be valid UTF-8: USD takes file names as UTF-8 text.
    """
    try:
        os.fsdecode(shot).encode("utf-8")
    except UnicodeEncodeError:
        name = os.fsdecode(shot).encode("utf-8", "backslashreplace").decode("ascii", "replace")
        msg = f"{name}: the file name is not valid UTF-8 and USD cannot open it; rename the file"
        raise ShotFileError(msg) from None
    require_regular_file(shot, "shot", ShotFileError)
    require_regular_layers(shot)
    if options.robot is not None:
        require_regular_file(options.robot, "robot file", RobotFileError)
    if options.set_file is not None:
        require_regular_file(options.set_file, "set file", InputError)
    if options.lens is not None:
        require_regular_file(options.lens, "lens file", LensFileError)


def require_regular_layers(shot: str | os.PathLike[str]) -> None:
    """Every layer the shot pulls in (sublayers, references and payloads, through the layers
    they pull in) and every other file its layers name (clips) must be a regular file where
    it exists, checked before USD opens it: a named pipe blocked USD's open() forever, and
    the run could then not be stopped but by SIGKILL. A missing or unreadable layer is left
    to the reader, which says so.

    Raises:
        ShotFileError: A layer or file the shot uses is not a regular file (names both).
    """
    if not os.path.isfile(shot):
        return  # the shot itself: checked (or reported missing) by its reader
    with interrupts.deferred():  # USD's module loader swallows a KeyboardInterrupt
        from pxr import Sdf, Tf

    trap_type = getattr(Tf, "DiagnosticTrap", None)
    seen = {os.path.realpath(shot)}
    todo = [os.path.realpath(shot)]
    while todo:
        path = todo.pop()
        trap: Any = trap_type() if trap_type is not None else contextlib.nullcontext()
        try:
            with trap as caught:
                layer = Sdf.Layer.FindOrOpen(path)
                if caught is not None:
                    caught.Clear()
        except Exception:
            continue
        if layer is None:
            continue
        named = [*layer.GetCompositionAssetDependencies(), *layer.GetExternalAssetDependencies()]
        for asset in named:
            found = layer.ComputeAbsolutePath(asset) if asset else ""
            if not found or not os.path.exists(found):
                continue
            real = os.path.realpath(found)
            mode = os.stat(real).st_mode
            if not stat.S_ISREG(mode):
                msg = (f"{one_line(shot)}: {one_line(found)} (used by {one_line(path)}) is "
                       f"{file_kind(mode)}, not a regular file")
                raise ShotFileError(msg)
            if real not in seen and asset in layer.GetCompositionAssetDependencies():
                seen.add(real)
                todo.append(real)


def shot_layers(shot: str | os.PathLike[str]) -> list[Path]:
    """Every file the USD shot pulls in: sublayers, references, payloads, clips (not itself).

    Uses ``UsdUtils.ComputeAllDependencies``. A shot USD cannot open, or one that uses a
    layer that is no regular file (:func:`require_regular_layers`: USD would block on a named
    pipe), gives an empty list (reading it reports the error); USD's diagnostics are kept
    off stderr.
    """
    try:
        require_regular_layers(shot)
    except ShotFileError:
        return []
    with interrupts.deferred():  # USD's module loader swallows a KeyboardInterrupt
        from pxr import Sdf, Tf, UsdUtils  # (UsdUtils loads UsdShade and Sdr: ~0.1 s)

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


def files_read(shots: Sequence[str | os.PathLike[str]],
               options: ConvertOptions) -> list[tuple[Path, str]]:
    """(path, description) of every file a run over ``shots`` reads, for the output checks:
    each shot and the USD layers it uses, the robot file, the set file."""
    inputs: list[tuple[Path, str]] = []
    for shot in shots:
        name = Path(os.fsdecode(shot)).name
        inputs.append((Path(os.fsdecode(shot)), "the shot" if len(shots) == 1
                       else f"the shot {name}"))
        if os.path.isfile(shot):
            inputs += [(p, f"a layer used by the shot {name}") for p in shot_layers(shot)]
    if options.robot is not None:
        inputs.append((Path(options.robot), "the robot file"))
    if options.set_file is not None:
        inputs.append((Path(options.set_file), "the set file"))
    if options.lens is not None:
        inputs.append((Path(options.lens), "the lens file"))
    return inputs


def run_inputs(shot: str | os.PathLike[str], options: ConvertOptions) -> list[tuple[Path, str]]:
    """(path, description) of every file a run over one shot reads (:func:`files_read`)."""
    return files_read([shot], options)
