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
import functools
import json
import os
import stat
import tomllib
from collections.abc import Callable, Sequence
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
    "MIN_FILE_RATE",
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

MIN_FILE_RATE = 1e-3
"""The smallest velocity, acceleration or jerk limit a robot or lens file may give, in its
units (m or deg per s, s², s³): below it no take is a shot (1e-300 broke the solver with a
traceback)."""
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
    """The shot, robot file, set file and lens file of a run must be regular files, and no
    layer of the shot a named pipe or a device (:func:`require_regular_layers`).

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
    """No layer the shot pulls in (sublayers, references and payloads, through the layers they
    pull in) and no other file its layers name (clips) may be a named pipe, a device or a
    socket, checked before USD opens it: USD's open() blocked forever on a named pipe, and
    the run could then be stopped only by SIGKILL. Paths are resolved as USD resolves them
    (relative to the layer as opened, search paths, format arguments stripped); a missing
    layer, a folder or a layer in an unselected variant is left to the reader. Not covered:
    paths built from expression variables and template clip paths (``clip.###.usd``).

    Raises:
        ShotFileError: A file the shot uses would block a reader (names it and its user).
    """
    try:
        st = os.stat(shot)
    except (OSError, ValueError):
        return  # the shot itself: checked (or reported missing) by its reader
    if not stat.S_ISREG(st.st_mode):
        return
    found = _blocking_layer(os.path.abspath(shot), st.st_mtime_ns)
    if found is not None:
        path, user, kind = found
        msg = (f"{one_line(shot)}: {one_line(path)} (used by {one_line(user)}) is {kind}, "
               "not a regular file")
        raise ShotFileError(msg)


@functools.lru_cache(maxsize=32)  # one walk per shot and run: every command asks 2-4 times
def _blocking_layer(root: str, mtime_ns: int) -> tuple[str, str, str] | None:
    """The first file under ``root``'s layers that would block a reader: (path, the layer
    naming it, what it is); None when there is none (``mtime_ns`` keys the cache)."""
    with interrupts.deferred():  # USD's module loader swallows a KeyboardInterrupt
        from pxr import Ar, Sdf

    resolver = Ar.GetResolver()
    seen = {root}
    todo = [root]
    while todo:
        path = todo.pop()
        layer = _quietly(functools.partial(Sdf.Layer.FindOrOpen, path))
        if layer is None:  # USD could not open it: the reader reports it
            continue
        composed = set(layer.GetCompositionAssetDependencies())
        for asset in [*composed, *layer.GetExternalAssetDependencies()]:
            name = Sdf.Layer.SplitIdentifier(asset)[0] if asset else ""
            where = str(resolver.Resolve(Sdf.ComputeAssetPathRelativeToLayer(layer, name))) \
                if name else ""
            if not where or not os.path.isabs(where):
                continue
            try:
                mode = os.stat(where).st_mode
            except OSError:
                continue
            if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode) or stat.S_ISBLK(mode) \
                    or stat.S_ISSOCK(mode):
                return where, path, file_kind(mode)
            if stat.S_ISREG(mode) and asset in composed and where not in seen:
                seen.add(where)
                todo.append(where)
    return None


def _quietly(action: Callable[[], Any]) -> Any:
    """``action()`` with USD's diagnostics kept off stderr; None where USD raised (the reader
    reports what it could not open)."""
    from pxr import Tf

    trap_type = getattr(Tf, "DiagnosticTrap", None)  # new in OpenUSD 25.x
    trap: Any = trap_type() if trap_type is not None else contextlib.nullcontext()
    try:
        with trap as caught:
            result = action()
            if caught is not None:
                caught.Clear()
    except Exception:  # USD raises Tf.ErrorException and others
        return None
    return result


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
        from pxr import Sdf, UsdUtils  # (UsdUtils loads UsdShade and Sdr: ~0.1 s)

    root = os.path.realpath(shot)
    deps = _quietly(lambda: UsdUtils.ComputeAllDependencies(Sdf.AssetPath(root)))
    if deps is None:  # USD could not open it: reading reports it
        return []
    layers, assets, _ = deps
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
