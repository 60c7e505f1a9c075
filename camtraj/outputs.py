"""The files a run writes, as one result: checked before the work, committed all together.

An :class:`OutputSet` holds every output path of a run (the MCAP, the summary, and whatever
else a command writes). Each path is checked when it is added, before any solving:

* its folder exists or can be made (missing folders are made, as `mkdir -p`, and removed
  again if the run fails; see :mod:`camtraj.folders`); a temporary file is created there
  right away;
* it is a regular file or nothing (``-o /dev/null`` is refused, a device is never replaced);
* it is not one of the run's inputs (:meth:`OutputSet.refuse_inputs`: the shot, its USD
  layers, the robot and set files), compared through symlinks, ``..`` and hard links;
* no two outputs are the same file.

Content goes to temporary files in the destination folders. On Linux these are unnamed
(``O_TMPFILE``): a run killed before its commit, even with SIGKILL, leaves nothing behind.
Where unnamed files are not supported the temporary file is ``.NAME.camtraj-tmp-HOST-PID``
from the start.

:meth:`OutputSet.commit` fsyncs every temporary file. An output whose destination does not
exist is then linked into place directly (``linkat``): it never has another name. An output
replacing a file needs a name to be renamed over it: it gets ``.NAME.camtraj-tmp-HOST-PID``,
the file it replaces is kept as ``.NAME.camtraj-old-HOST-PID``, and the renames follow one
after the other; if one fails the destinations already replaced get their earlier content
back. So either every output is replaced or none is. Signals (SIGINT, SIGTERM) are held off
during the commit: a stop requested before it means nothing is written; once it has started
the run completes.

What SIGKILL (or a power cut) can leave: killed inside the commit (a few milliseconds), the
``-tmp-``/``-old-`` names of outputs that replace an existing file, and some outputs replaced
while others are not. A later run writing NAME (and ``camtraj batch`` for its folder) removes
such files when their process is gone (:func:`remove_stale_temps`).

Usage::

    outputs = OutputSet()
    outputs.add("shot.mcap", "-o")            # fails here (InputError) before the work
    outputs.add("shot.json", "--summary")
    outputs.refuse_inputs([("shot.usda", "the shot")])
    with outputs:                             # an error inside discards everything
        with outputs.open("shot.mcap") as f:
            f.write(...)
        outputs.write_bytes("shot.json", b"{}")
        outputs.commit()
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import socket
import stat
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

from camtraj import interrupts
from camtraj.errors import InputError, file_kind, os_reason
from camtraj.folders import check_can_make, make_parent, remove_empty
from camtraj.inputs import one_line

__all__ = [
    "TEMP_MARK",
    "OutputSet",
    "check_destination",
    "refuse_overlaps",
    "remove_stale_temps",
    "temp_name",
]

TEMP_MARK = ".camtraj-tmp-"
"""Part of the name of every temporary file camtraj creates next to an output."""
_BACKUP_MARK = ".camtraj-old-"
_STALE = re.compile(
    r"^\.(?P<name>.+)\.camtraj-(?:tmp|old)-(?P<host>[A-Za-z0-9._-]+)-(?P<pid>\d+)$"
)
_NEW_FILE_MODE = 0o666  # less the umask, like any new file


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", socket.gethostname()) or "localhost"


def temp_name(name: str, mark: str = TEMP_MARK) -> str:
    """The name of this process's temporary file for an output called ``name``."""
    return f".{name}{mark}{_host()}-{os.getpid()}"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, owned by someone else
        return True
    return True


def remove_stale_temps(folder: str | os.PathLike[str], name: str | None = None) -> list[Path]:
    """Remove camtraj temporary files in ``folder`` left by processes of this host now gone.

    Args:
        folder: The folder to clean.
        name: Only the temporary files of this output name; default all of them.

    Returns:
        The files removed. Files of live processes and of other hosts (a shared render-farm
        folder) are kept.
    """
    removed: list[Path] = []
    host = _host()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        m = _STALE.match(entry.name)
        if m is None or m["host"] != host or (name is not None and m["name"] != name):
            continue
        pid = int(m["pid"])
        if pid == os.getpid() or _pid_alive(pid):
            continue
        with contextlib.suppress(OSError):
            os.unlink(entry.path)
            removed.append(Path(entry.path))
    return removed


def check_destination(path: str | os.PathLike[str], label: str = "") -> None:
    """The checks :meth:`OutputSet.add` makes of a destination, for an output written only at
    the end of a long run (batch's report): its folder exists and it is a regular file or
    nothing. Raises InputError naming it."""
    given = os.fsdecode(path)
    OutputSet._check_destination(_Output(given, label, Path(os.path.realpath(given))))


def _same_file(a: os.stat_result, b: os.stat_result) -> bool:
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


@dataclass
class _Output:
    given: str  # as the user wrote it, for messages
    label: str  # "-o", "--summary", ...
    target: Path  # the destination, symlinks resolved
    fd: int = -1  # the temporary file
    named: Path | None = None  # its name, when it has one
    written: bool = False

    @property
    def what(self) -> str:
        given = one_line(self.given)
        return f"{self.label} {given}" if self.label else given


class OutputSet:
    """The outputs of one run; see the module documentation."""

    def __init__(self) -> None:
        self._outputs: list[_Output] = []
        self._committed = False
        self._made_folders: list[Path] = []  # deepest first; removed again on discard

    # -- registering --------------------------------------------------------------------------

    def add(self, path: str | os.PathLike[str], label: str = "") -> None:
        """Register an output and check it now.

        Args:
            path: The destination file.
            label: How the user named it, e.g. ``"-o"`` or ``"--summary"`` (for messages).

        Raises:
            InputError: The folder is missing or not writable, the destination is not a
                regular file, or it is another output of this set.
        """
        given = os.fsdecode(path)
        if not given:  # realpath('') is the working folder
            msg = f"cannot write {label or 'the output'}: the file name is empty"
            raise InputError(msg)
        out = _Output(given, label, Path(os.path.realpath(given)))
        if not out.target.name:
            msg = f"cannot write {out.what}: not a file name"
            raise InputError(msg)
        self._make_folder(out)
        self._check_destination(out)
        for other in self._outputs:
            if self._same_destination(other, out):
                msg = f"cannot write {out.what}: it is the same file as {other.what}"
                raise InputError(msg)
        remove_stale_temps(out.target.parent, out.target.name)
        self._open_temp(out)
        self._outputs.append(out)

    def refuse_inputs(self, inputs: Iterable[tuple[str | os.PathLike[str], str]]) -> None:
        """Refuse (InputError) any output that is one of ``inputs``.

        Args:
            inputs: (path, description) pairs, e.g. ``("shot.usda", "the shot")``.
        """
        refuse_overlaps([(o.target, o.what) for o in self._outputs], inputs)

    @property
    def paths(self) -> list[Path]:
        """The destinations (symlinks resolved), in the order they were added."""
        return [o.target for o in self._outputs]

    def _find(self, path: str | os.PathLike[str]) -> _Output:
        real = Path(os.path.realpath(os.fsdecode(path)))
        for out in self._outputs:
            if out.target == real or out.given == os.fsdecode(path):
                return out
        msg = f"{os.fsdecode(path)} is not an output of this run"
        raise KeyError(msg)

    @staticmethod
    def _same_destination(a: _Output, b: _Output) -> bool:
        if a.target == b.target:
            return True
        try:
            return _same_file(os.stat(a.target), os.stat(b.target))
        except OSError:
            return False

    def _make_folder(self, out: _Output) -> None:
        """Make the destination's missing folders (the rule of :mod:`camtraj.folders`)."""
        folder = out.target.parent
        if folder.exists():
            return
        check_can_make(out.target, out.label)
        self._made_folders.extend(make_parent(out.target, out.label))

    @staticmethod
    def _check_destination(out: _Output) -> None:
        folder = out.target.parent
        try:
            st = os.stat(folder)
        except OSError as exc:
            what = "does not exist" if exc.errno == errno.ENOENT else os_reason(exc)
            msg = f"cannot write {out.what}: folder {folder} {what}"
            raise InputError(msg) from None
        if not stat.S_ISDIR(st.st_mode):
            msg = f"cannot write {out.what}: {folder} is a file, not a folder"
            raise InputError(msg)
        try:
            st = os.stat(out.target)
        except FileNotFoundError:
            return
        except OSError as exc:
            msg = f"cannot write {out.what}: {os_reason(exc)}"
            raise InputError(msg) from None
        if not stat.S_ISREG(st.st_mode):
            msg = (
                f"cannot write {out.what}: it is {file_kind(st.st_mode)}, not a regular file; "
                "camtraj only replaces regular files"
            )
            raise InputError(msg)

    # -- writing --------------------------------------------------------------------------------

    def _open_temp(self, out: _Output) -> None:
        folder = out.target.parent
        flags = os.O_WRONLY | getattr(os, "O_CLOEXEC", 0)
        tmpfile = getattr(os, "O_TMPFILE", 0)
        if tmpfile and Path("/proc/self/fd").is_dir():
            try:
                out.fd = os.open(folder, flags | tmpfile, _NEW_FILE_MODE)
                return
            except OSError as exc:
                if exc.errno not in (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL):
                    msg = (f"cannot write {out.what}: cannot create files in {folder}: "
                           f"{os_reason(exc)}")
                    raise InputError(msg) from None
        named = folder / temp_name(out.target.name)
        with interrupts.deferred():
            with contextlib.suppress(FileNotFoundError):
                named.unlink()  # ours by its name: left by an earlier process with our pid
            try:
                out.fd = os.open(named, flags | os.O_CREAT | os.O_EXCL, _NEW_FILE_MODE)
            except OSError as exc:
                msg = f"cannot write {out.what}: cannot create files in {folder}: {os_reason(exc)}"
                raise InputError(msg) from None
            out.named = named

    @contextlib.contextmanager
    def open(self, path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
        """A binary stream into the temporary file of output ``path`` (written once)."""
        out = self._find(path)
        if out.written:
            msg = f"{out.what} was already written"
            raise RuntimeError(msg)
        out.written = True
        stream = os.fdopen(os.dup(out.fd), "wb")
        try:
            with stream:
                yield stream
        except OSError as exc:
            msg = f"cannot write {out.what}: {os_reason(exc)}"
            raise InputError(msg) from exc

    def write_bytes(self, path: str | os.PathLike[str], data: bytes) -> None:
        """Write all of output ``path`` at once."""
        with self.open(path) as stream:
            stream.write(data)

    def commit(self) -> None:
        """Replace every destination with its new content, all or nothing.

        Raises:
            InputError: An output could not be written (nothing is replaced then).
            interrupts.Interrupted: A stop was requested before the commit (nothing written).
        """
        missing = [o.what for o in self._outputs if not o.written]
        if missing:
            msg = f"outputs never written: {', '.join(missing)}"
            raise RuntimeError(msg)
        with interrupts.deferred():
            interrupts.check()  # a stop requested during the work: write nothing
            self._commit()
            self._committed = True
            interrupts.ignore_from_now()  # the result is on disk: the run completes

    def _commit(self) -> None:
        for out in self._outputs:
            try:
                os.fsync(out.fd)
            except OSError as exc:
                msg = f"cannot write {out.what}: {os_reason(exc)}"
                raise InputError(msg) from None
            self._check_destination(out)  # still a regular file or nothing
        # An unnamed file whose destination does not exist yet is linked there directly: it
        # never has another name. Every other output gets a temporary name, renamed over its
        # destination (whose earlier content is kept under a second name until the end).
        direct = {id(o) for o in self._outputs
                  if o.named is None and not os.path.lexists(o.target)}
        for out in self._outputs:
            if out.named is None and id(out) not in direct:
                self._link(out, out.target.parent / temp_name(out.target.name))
        backups: list[tuple[_Output, Path | None]] = []
        try:
            for out in self._outputs:
                backups.append((out, None if id(out) in direct else self._backup(out)))
            done: list[tuple[_Output, Path | None]] = []
            for out, backup in backups:
                try:
                    if id(out) in direct:
                        self._link(out, out.target)
                    else:
                        assert out.named is not None
                        os.replace(out.named, out.target)
                except (OSError, InputError) as exc:
                    self._restore(done)
                    said = (f"cannot write {out.what}: {os_reason(exc)}" if isinstance(exc, OSError)
                            else str(exc))  # _link's own error names the output already
                    msg = f"{said}; nothing was replaced"
                    raise InputError(msg) from None
                out.named = None
                done.append((out, backup))
        finally:
            for _, backup in backups:
                if backup is not None:
                    with contextlib.suppress(OSError):
                        backup.unlink()
        for folder in {o.target.parent for o in self._outputs}:
            _fsync_dir(folder)

    @staticmethod
    def _link(out: _Output, named: Path) -> None:
        """Give the unnamed temporary file of ``out`` the name ``named`` (which must be free,
        but for a stale temporary file of ours)."""
        if named != out.target:
            with contextlib.suppress(FileNotFoundError):
                named.unlink()
        try:
            # linkat(AT_SYMLINK_FOLLOW) on /proc/self/fd/N names an O_TMPFILE file; os.link
            # only calls linkat (not link, which would not follow) when given a dir fd.
            root = os.open("/", os.O_RDONLY)
            try:
                os.link(f"/proc/self/fd/{out.fd}", named, src_dir_fd=root, follow_symlinks=True)
            finally:
                os.close(root)
        except FileExistsError:
            msg = f"cannot write {out.what}: another program created it during the run"
            raise InputError(msg) from None
        except OSError as exc:
            msg = f"cannot write {out.what}: {os_reason(exc)}"
            raise InputError(msg) from None
        if named != out.target:
            out.named = named

    @staticmethod
    def _backup(out: _Output) -> Path | None:
        """Keep the destination's current content under a second name (None: nothing there)."""
        if not out.target.exists():
            return None
        backup = out.target.parent / temp_name(out.target.name, _BACKUP_MARK)
        with contextlib.suppress(FileNotFoundError):
            backup.unlink()
        try:
            os.link(out.target, backup)
        except OSError:
            try:  # a file system without hard links
                shutil.copy2(out.target, backup)
            except OSError as exc:
                msg = f"cannot write {out.what}: cannot keep its earlier content: {os_reason(exc)}"
                raise InputError(msg) from None
        return backup

    @staticmethod
    def _restore(done: list[tuple[_Output, Path | None]]) -> None:
        for out, backup in reversed(done):
            with contextlib.suppress(OSError):
                if backup is None:
                    out.target.unlink()
                else:
                    os.replace(backup, out.target)

    def discard(self) -> None:
        """Drop every temporary file; the destinations stay as they were."""
        with interrupts.deferred(raise_pending=False):
            for out in self._outputs:
                if out.fd >= 0:
                    with contextlib.suppress(OSError):
                        os.close(out.fd)
                    out.fd = -1
                if out.named is not None:
                    with contextlib.suppress(OSError):
                        out.named.unlink()
                    out.named = None
            if not self._committed:  # a failed run leaves no empty folder behind
                remove_empty(self._made_folders)
            self._made_folders = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.discard()


def refuse_overlaps(outputs: Iterable[tuple[str | os.PathLike[str], str]],
                    inputs: Iterable[tuple[str | os.PathLike[str], str]] = ()) -> None:
    """Refuse (InputError) an output that is one of ``inputs`` or another of ``outputs``.

    The rule :class:`OutputSet` applies to the files it writes, for outputs that other
    processes write later (a batch's workers, a farm job's tasks): paths are compared through
    symlinks, ``..`` and hard links.

    Args:
        outputs: (path, how the user named it) pairs, e.g. ``("out/a.mcap", "-o out/a.mcap")``.
        inputs: (path, description) pairs, e.g. ``("shot.usda", "the shot")``.
    """
    seen: list[tuple[str, os.stat_result | None, str]] = []
    for path, what in outputs:
        real, st = _identity(path)
        for other_real, other_st, other in seen:
            if real == other_real or (st is not None and other_st is not None
                                      and _same_file(st, other_st)):
                msg = f"cannot write {what}: it is the same file as {other}"
                raise InputError(msg)
        seen.append((real, st, what))
    for path, description in inputs:
        real, st = _identity(path)
        if st is None:
            continue
        for out_real, out_st, what in seen:
            if real == out_real or (out_st is not None and _same_file(st, out_st)):
                msg = (f"refusing to write {what}: it is {description} "
                       f"({one_line(path)}); choose another output file")
                raise InputError(msg)


def _identity(path: str | os.PathLike[str]) -> tuple[str, os.stat_result | None]:
    """The real path of a file, and its stat when it exists."""
    try:
        real = os.path.realpath(path)
    except (OSError, ValueError):
        real = os.path.abspath(path)
    try:
        return real, os.stat(real)
    except (OSError, ValueError):
        return real, None


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
