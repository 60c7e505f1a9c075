"""Typed errors. Library code raises these; only the CLI turns them into exit codes.

Exit codes (design.md §5): 2 for bad input or usage, 3 when the shot cannot be done as asked.
"""

from __future__ import annotations

import os
import stat

from camtraj.shown import frame_runs


def one_line(text: str | os.PathLike[str]) -> str:
    """A path or a message as printed on one line: a newline or other character that does
    not print (in a file name, say) is shown escaped as in a Python string (``\\n``)."""
    text = os.fsdecode(text)
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def os_reason(exc: OSError) -> str:
    """An operating-system error as the end of a message: 'permission denied'."""
    text = exc.strerror or str(exc)
    return text[:1].lower() + text[1:]


_KINDS = {
    stat.S_IFDIR: "a folder",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFIFO: "a named pipe (FIFO)",
    stat.S_IFSOCK: "a socket",
}


def file_kind(mode: int) -> str:
    """What a path that is not a regular file is, by its ``st_mode``: 'a named pipe (FIFO)'."""
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


class CamtrajError(Exception):
    """Base class of every error camtraj raises on purpose; its text is one line."""

    exit_code = 1

    def __str__(self) -> str:
        return one_line(super().__str__())


class InputError(CamtrajError):
    """Bad input or usage: unreadable file, no or ambiguous camera, invalid robot file."""

    exit_code = 2


class RobotFileError(InputError):
    """A robot description file is missing a value, has an unknown key or a value out of range."""


class LensFileError(InputError):
    """A lens file (``--lens``) is missing a value, has an unknown key, a value out of range
    or a calibration table that is not monotone."""


class ShotFileError(InputError):
    """A USD shot cannot be read or has no usable camera animation."""


class InfeasibleError(CamtrajError):
    """The shot cannot be done as asked (unreachable frames, limits exceeded).

    Attributes:
        shot_warnings: What reading the shot warned of (a layer in other units, a focal length
            no lens has): often the cause, so said with the failure too (set by the command
            that read the shot: convert's ``analyse``, place, a scene's placement).
    """

    exit_code = 3
    shot_warnings: tuple[str, ...] = ()


class UnreachableError(InfeasibleError):
    """A target pose has no inverse-kinematics solution inside the joint limits.

    Attributes:
        miss: By how much the target misses the workspace, in the unit of ``miss_unit``.
        miss_unit: ``"m"`` for a distance, ``"rad"`` for an angle.
        axis: The joint whose limit is the binding reason, if one is, else ``None``.
        frame: The film frame number, when the error is about a frame of a shot.
    """

    def __init__(
        self,
        reason: str,
        *,
        miss: float,
        miss_unit: str = "m",
        axis: str | None = None,
        frame: int | None = None,
    ) -> None:
        self.reason = reason
        self.miss = float(miss)
        self.miss_unit = miss_unit
        self.axis = axis
        self.frame = frame
        super().__init__(self._message())

    def _message(self) -> str:
        where = f"frame {self.frame}: " if self.frame is not None else ""
        return f"{where}{self.reason}"

    def at_frame(self, frame: int) -> UnreachableError:
        """The same error, stamped with the film frame it happened on."""
        return UnreachableError(
            self.reason, miss=self.miss, miss_unit=self.miss_unit, axis=self.axis, frame=frame
        )


class UnreachableFramesError(InfeasibleError):
    """Several frames of a shot are unreachable; ``errors`` holds one error per frame."""

    def __init__(self, errors: list[UnreachableError]) -> None:
        self.errors = errors
        frames = [e.frame for e in errors]
        worst = max(errors, key=lambda e: e.miss if e.miss_unit == "m" else e.miss * 1.0)
        span = _frame_ranges([f for f in frames if f is not None])
        msg = (
            f"{len(errors)} frame(s) cannot be reached ({span}); worst: {worst}"
        )
        super().__init__(msg)


class LimitError(InfeasibleError):
    """The timed move exceeds a velocity, acceleration or jerk limit."""


class LensRangeError(InfeasibleError):
    """The shot asks the lens for a focal length, focus distance or stop outside the range its
    calibration covers (the message names the frame and the lens's end of range)."""


class PlacementError(InfeasibleError):
    """No placement of the robot can do the shot (``camtraj place``); the message says why."""


class CollisionError(InfeasibleError):
    """The robot comes closer to an obstacle of the set than the clearance allows.

    Attributes:
        frame: Film frame number at (or after) the contact (the first frame in the run-up,
            the last in the run-out).
        link: The robot part (e.g. ``"forearm (link5)"``).
        prim: Prim path of the obstacle.
        distance: Signed distance [m] (negative: penetration depth).
        clearance: The required distance [m].
        phase: ``"run-up"``, ``"shot"`` or ``"run-out"``: where in the take.
    """

    def __init__(self, message: str, *, frame: int, link: str, prim: str, distance: float,
                 clearance: float, phase: str = "shot") -> None:
        super().__init__(message)
        self.frame = frame
        self.phase = phase
        self.link = link
        self.prim = prim
        self.distance = distance
        self.clearance = clearance


def _frame_ranges(frames: list[int]) -> str:
    """Compress [3, 4, 5, 9] into 'frames 3-5, 9'."""
    if not frames:
        return "no frame numbers"
    frames = sorted(set(frames))
    parts: list[tuple[int, int]] = []
    start = prev = frames[0]
    for f in frames[1:]:
        if f == prev + 1:
            prev = f
            continue
        parts.append((start, prev))
        start = prev = f
    parts.append((start, prev))
    return frame_runs(parts)


def frame_ranges(frames: list[int]) -> str:
    """Public form of the frame-range formatter, for reports."""
    return _frame_ranges(frames)


def failure_lines(exc: CamtrajError) -> list[str]:
    """What a command prints on stderr when it stops on ``exc``: the error, its notes (what
    to try), and what reading the shot warned of (often the reason)."""
    return [f"ERROR: {exc}", *note_lines(exc),
            *(one_line(f"warning: {w}") for w in getattr(exc, "shot_warnings", ()))]


def note_lines(exc: BaseException) -> list[str]:
    """The notes of ``exc`` (what to try, where a hold or a jump is), one line each."""
    return [one_line(f"note: {note}") for note in getattr(exc, "__notes__", [])]
