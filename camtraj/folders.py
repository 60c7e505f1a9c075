"""Output folders: one rule for every command.

A folder an output goes into (``convert -o``, ``--summary``, ``batch -o``, the farm job files
and task outputs) is created with its missing parents, like ``mkdir -p``, so a Makefile rule or
a farm task can write into a fresh ``out/`` tree. It is checked before any work (the nearest
existing folder must be a folder this user may write to, so a run never fails after the
solve for want of one) and created only when the result is written, so a run that fails
leaves no empty folder behind.
"""

from __future__ import annotations

import os
from pathlib import Path

from camtraj.errors import InputError

__all__ = ["check_can_make", "make_parent", "remove_empty"]


def _nearest_existing(folder: Path) -> Path:
    folder = Path(os.path.abspath(folder))
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def check_can_make(path: str | os.PathLike[str], what: str = "") -> None:
    """Raise unless ``path``'s folder exists or can be made (before any work is done).

    Args:
        path: An output file.
        what: How the user named it, e.g. ``-o`` or ``--summary`` (for the message).

    Raises:
        InputError: A file stands where a folder of the path should be, or the nearest
            existing folder cannot be written to.
    """
    folder = Path(path).parent
    base = _nearest_existing(folder)
    name = f"{what} {path}" if what else str(path)
    if not base.is_dir():
        msg = f"cannot write {name}: {base} is a file, not a folder"
        raise InputError(msg)
    if not os.access(base, os.W_OK | os.X_OK):
        needs = "" if base == Path(os.path.abspath(folder)) else f" (to make {folder})"
        msg = f"cannot write {name}: folder {base} is not writable{needs}"
        raise InputError(msg)


def make_parent(path: str | os.PathLike[str], what: str = "") -> list[Path]:
    """Make ``path``'s folder and its missing parents; the folders made, deepest first (for
    :func:`remove_empty` when the run fails).

    Raises:
        InputError: It cannot be made (a file in the way, no permission).
    """
    folder = Path(path).parent
    made, up = [], folder
    while not up.exists() and up != up.parent:
        made.append(up)
        up = up.parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        name = f"{what} {path}" if what else str(path)
        reason = exc.strerror or str(exc)
        msg = f"cannot write {name}: cannot make folder {folder} ({reason.lower()})"
        raise InputError(msg) from exc
    return made


def remove_empty(folders: list[Path]) -> None:
    """Remove the folders a failed run made (:func:`make_parent`'s), deepest first, where
    they are still empty."""
    for folder in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        try:
            folder.rmdir()
        except OSError:
            continue
