"""Limits of the robot's axes and the checks of a sampled stream against them.

Units: SI throughout (m, rad, s); messages show revolute axes in degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.errors import LimitError
from camtraj.robot import JOINT_KINDS, JOINT_NAMES
from camtraj.shown import SHOWN_RUNS, frame_runs
from camtraj.timing.path import Samples, runs

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

QUANTITIES: tuple[str, ...] = ("position", "velocity", "acceleration", "jerk")
#: Relative tolerance of the limit checks in "shot" and "scale" modes (float round-off only).
LIMIT_RTOL = 1e-9


@dataclass(frozen=True, eq=False)
class Limits:
    """Per-axis limits, every array of shape (k,) in axis order, SI units: the robot's eight
    joints (the default names), followed by any more axes timed with them (a lens's zoom,
    focus and iris motors, :meth:`joined`). Timing treats every axis alike.

    Attributes:
        lower: Lower position limits [m or rad].
        upper: Upper position limits [m or rad].
        velocity: Velocity limits (symmetric) [m/s or rad/s].
        acceleration: Acceleration limits (symmetric) [m/s² or rad/s²].
        jerk: Jerk limits (symmetric) [m/s³ or rad/s³].
        names: Axis names, in joint order.
        kinds: ``"prismatic"`` or ``"revolute"`` per axis (messages show revolute axes in deg).
    """

    lower: Array
    upper: Array
    velocity: Array
    acceleration: Array
    jerk: Array
    names: tuple[str, ...] = JOINT_NAMES
    kinds: tuple[str, ...] = JOINT_KINDS

    def __post_init__(self) -> None:
        k = len(self.names)
        for name in ("lower", "upper", "velocity", "acceleration", "jerk"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if k < 1 or arr.shape != (k,) or not np.all(np.isfinite(arr)):
                msg = f"limits.{name} must be {k} finite numbers, got shape {arr.shape}"
                raise ValueError(msg)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        for name in ("velocity", "acceleration", "jerk"):
            if np.any(getattr(self, name) <= 0):
                msg = f"limits.{name} must be positive"
                raise ValueError(msg)
        if np.any(self.lower >= self.upper):
            msg = "limits.lower must be below limits.upper on every axis"
            raise ValueError(msg)
        if len(self.kinds) != k or len(set(self.names)) != k:
            msg = f"limits need {k} distinct axis names and {k} kinds"
            raise ValueError(msg)
        if any(k not in ("prismatic", "revolute") for k in self.kinds):
            msg = f"limits.kinds must be 'prismatic' or 'revolute', got {self.kinds}"
            raise ValueError(msg)

    @classmethod
    def from_robot(cls, robot: Any) -> Limits:
        """The limits of a :class:`camtraj.robot.Robot` (or anything with the same fields)."""
        return cls(
            lower=robot.lower,
            upper=robot.upper,
            velocity=robot.max_velocity,
            acceleration=robot.max_acceleration,
            jerk=robot.max_jerk,
            names=tuple(getattr(robot, "joint_names", JOINT_NAMES)),
            kinds=tuple(getattr(robot, "joint_kinds", JOINT_KINDS)),
        )

    @property
    def size(self) -> int:
        """The number of axes."""
        return len(self.names)

    def joined(self, more: Limits) -> Limits:
        """These axes followed by ``more``'s."""
        def both(key: str) -> Array:
            return np.concatenate([getattr(self, key), getattr(more, key)])

        return Limits(both("lower"), both("upper"), both("velocity"), both("acceleration"),
                      both("jerk"), names=(*self.names, *more.names),
                      kinds=(*self.kinds, *more.kinds))

    @property
    def revolute(self) -> BoolArray:
        """Whether each axis is revolute, shape (k,)."""
        return np.array([k == "revolute" for k in self.kinds])

    def bound(self, quantity: str) -> Array:
        """The symmetric limit of ``"velocity"``, ``"acceleration"`` or ``"jerk"``, shape (k,)."""
        return {"velocity": self.velocity, "acceleration": self.acceleration,
                "jerk": self.jerk}[quantity]


@dataclass(frozen=True)
class LimitViolation:
    """One axis exceeding one limit.

    Attributes:
        axis: Axis name.
        quantity: ``"position"``, ``"velocity"``, ``"acceleration"`` or ``"jerk"``.
        peak: The worst value [SI: m, rad, per s, s², s³], signed.
        limit: The limit it is compared with [SI]: the position bound it crosses, or the
            (positive) velocity / acceleration / jerk limit.
        ratio: For velocity, acceleration and jerk ``|peak| / limit``; for position the
            position use (see :attr:`TimingReport.peak_use`). Above 1 means exceeded.
        frames: Runs of consecutive frames ``(first, last)`` (inclusive, film frame numbers)
            where the limit is exceeded. A servo sample between two frames counts for both.
        revolute: Whether the axis is revolute (for display in degrees).
        worst: The film frames of the worst sample ``(first, last)``: one frame, or the two
            it lies between (``None``: not known).
    """

    axis: str
    quantity: str
    peak: float
    limit: float
    ratio: float
    frames: tuple[tuple[int, int], ...]
    revolute: bool
    worst: tuple[int, int] | None = None

    @property
    def speed_needed(self) -> float:
        """The slow-down factor that makes this limit fit (inf for position)."""
        if self.quantity == "velocity":
            return self.ratio
        if self.quantity == "acceleration":
            return math.sqrt(self.ratio)
        if self.quantity == "jerk":
            return math.pow(self.ratio, 1.0 / 3.0)
        return math.inf

    @property
    def frame_text(self) -> str:
        """Every frame as text, e.g. ``"frames 12-19, 40"`` (check --json, the report);
        :meth:`describe`'s one line shortens a long list (:data:`SHOWN_RUNS`)."""
        return frame_runs(self.frames)

    def describe(self) -> str:
        """One line for people: ``rotate velocity 143 deg/s exceeds 90.0 deg/s on frames 1-9``."""
        peak = fmt(self.peak, self.quantity, self.revolute)
        if self.quantity == "position":
            side = "upper" if self.peak > self.limit else "lower"
            lim = fmt(self.limit, self.quantity, self.revolute)
            return (
                f"{self.axis} position {peak} is beyond its {side} limit {lim} "
                f"on {frame_runs(self.frames, SHOWN_RUNS)}"
            )
        lim = fmt(self.limit, self.quantity, self.revolute)
        peak = fmt(abs(self.peak), self.quantity, self.revolute)
        # "1.5 m/s^2 exceeds 1.5 m/s^2" reads as no violation: say by how much
        over = (self.ratio - 1.0) * 100.0  # [%]; below 0.01% the limit's own tolerance
        by = (f" by {over:.2g}%" if over >= 0.01 else " by under 0.01%") if peak == lim else ""
        # where the worst is, when the frames are more than one stretch (a 540 deg orbit's
        # track velocity read as if at frames 2-4, the first of six stretches: it was 627)
        at = ""
        if self.worst is not None and len(self.frames) > 1:
            a, b = self.worst
            at = f" (worst at frame {a})" if a == b else f" (worst between frames {a} and {b})"
        return (f"{self.axis} {self.quantity} {peak}{at} exceeds {lim}{by} on "
                f"{frame_runs(self.frames, SHOWN_RUNS)}")


class TimingLimitError(LimitError):
    """The shot cannot be timed inside the limits.

    Attributes:
        violations: The limits exceeded, worst first.
        max_speed: See :attr:`TimingReport.max_speed` (nan when not known).
        feasible_fps: See :attr:`TimingReport.feasible_fps` (nan when not known).
        scale_factor: The slow-down ``--timing scale`` takes for this shot (it was run and
            succeeded); inf when it fails too (or cannot help, as for a position limit);
            nan when not known.
        room: Why the run-up or the run-out does not fit (one line; empty when they do or
            were not planned), said apart from the violations of the shot itself.
        set_by: What sets ``max_speed`` (:attr:`TimingReport.set_by`; empty when not known).
    """

    def __init__(
        self,
        message: str,
        *,
        violations: list[LimitViolation] | None = None,
        max_speed: float = math.nan,
        feasible_fps: float = math.nan,
        scale_factor: float = math.nan,
        room: str = "",
        set_by: str = "",
    ) -> None:
        super().__init__(message)
        self.violations = violations or []
        self.max_speed = max_speed
        self.feasible_fps = feasible_fps
        self.scale_factor = scale_factor
        self.room = room
        self.set_by = set_by


@dataclass(frozen=True, eq=False)
class FrameMap:
    """Which film frames each sample belongs to.

    ``lo[k]``, ``hi[k]``: frame indices (0..n-1) of sample k: the same frame on a frame,
    the two neighbours between frames. ``numbers``: film frame number of each index.
    """

    lo: IntArray
    hi: IntArray
    numbers: IntArray

    @classmethod
    def of(cls, x: Array, numbers: IntArray) -> FrameMap:
        n = numbers.size
        lo = np.clip(np.floor(x).astype(np.int64), 0, n - 1)
        hi = np.where(x > lo, np.minimum(lo + 1, n - 1), lo)
        return cls(lo=lo, hi=hi, numbers=numbers)

    def touch(self, touched: BoolArray, samples: IntArray) -> None:
        """Mark in ``touched`` (one per frame index) the frames of the samples."""
        touched[self.lo[samples]] = True
        touched[self.hi[samples]] = True

    def spans(self, touched: BoolArray) -> tuple[tuple[int, int], ...]:
        """Inclusive runs ``(first, last)`` of the film frame numbers of the ``touched``
        frame indices."""
        return tuple(
            (int(self.numbers[a]), int(self.numbers[b - 1])) for a, b in runs(touched)
        )


def position_use(q: Array, limits: Limits) -> Array:
    """``|q - mid| / half_range`` per axis: 0 in the middle of the range, 1 on a limit."""
    mid = 0.5 * (limits.upper + limits.lower)
    half = 0.5 * (limits.upper - limits.lower)
    use: Array = np.abs(q - mid) / half
    return use


@dataclass(frozen=True, eq=False)
class Peaks:
    """Per-axis extremes of a set of samples, each (8,): the lowest and highest position and
    the largest velocity, acceleration and jerk magnitude."""

    q_min: Array
    q_max: Array
    qd: Array
    qdd: Array
    qddd: Array

    @classmethod
    def of(cls, s: Samples) -> Peaks:
        return cls(-_column_max(-s.q), _column_max(s.q), _column_max(np.abs(s.qd)),
                   _column_max(np.abs(s.qdd)), _column_max(np.abs(s.qddd)))

    @classmethod
    def join(cls, parts: list[Peaks]) -> Peaks:
        """The extremes of samples given in parts, as :meth:`of` their concatenation."""
        return cls(np.minimum.reduce([p.q_min for p in parts]),
                   *(np.maximum.reduce([getattr(p, f) for p in parts])
                     for f in ("q_max", "qd", "qdd", "qddd")))

    def use(self, limits: Limits) -> dict[str, Array]:
        """Fraction of every limit used, per quantity, each (8,) (see ``position_use``)."""
        pos = np.maximum(position_use(self.q_min, limits), position_use(self.q_max, limits))
        return {"position": pos, "velocity": self.qd / limits.velocity,
                "acceleration": self.qdd / limits.acceleration, "jerk": self.qddd / limits.jerk}


def _column_max(a: Array, rows: int = 64) -> Array:
    """``a.max(axis=0)`` for an (m, k) array, m >= 1, without numpy's slow strided reduce:
    blocks of ``rows`` rows are reduced as one long row first."""
    m, k = a.shape
    cut = m - m % rows
    parts = [a[cut:].max(axis=0)] if cut < m else []
    if cut:
        parts.append(a[:cut].reshape(-1, rows * k).max(axis=0).reshape(rows, k).max(axis=0))
    out: Array = np.maximum.reduce(parts)
    return out


def slowdown(s: Samples, limits: Limits) -> float:
    """The smallest uniform slow-down factor that makes velocity, acceleration and jerk fit.

    0 when nothing moves; below 1 when the move could go faster.
    """
    if s.q.shape[0] == 0:
        return 0.0
    return peaks_slowdown(Peaks.of(s), limits)


def peaks_slowdown(peaks: Peaks, limits: Limits) -> float:
    """:func:`slowdown` of the samples with these peaks."""
    return slowest(peaks, limits)[0]


def slowest(peaks: Peaks, limits: Limits) -> tuple[float, int, str]:
    """The slow-down the samples with these peaks need, and the axis and quantity that need
    it: velocity scales with the speed, acceleration with its square, jerk with its cube."""
    use = peaks.use(limits)
    best = (-1.0, 0, "velocity")
    for quantity, power in (("velocity", 1.0), ("acceleration", 2.0), ("jerk", 3.0)):
        need = use[quantity] ** (1.0 / power)
        j = int(np.argmax(need))
        if float(need[j]) > best[0]:
            best = (float(need[j]), j, quantity)
    return best


def violations(
    s: Samples, limits: Limits, frame_map: FrameMap, rtol: float
) -> list[LimitViolation]:
    """Every (axis, quantity) exceeding its limit by more than ``rtol``, worst first."""
    return violations_in([(s, frame_map)], limits, rtol)


def violations_in(
    parts: list[tuple[Samples, FrameMap]], limits: Limits, rtol: float
) -> list[LimitViolation]:
    """:func:`violations` of samples given in parts, each with its frame map (of the same
    frames), as of their concatenation (the first of equally bad samples is named); the
    parts are not joined, so no copy of them is made."""
    out: list[LimitViolation] = []
    revolute = limits.revolute
    use = Peaks.join([Peaks.of(s) for s, _ in parts]).use(limits)
    for quantity, field in zip(QUANTITIES, ("q", "qd", "qdd", "qddd"), strict=True):
        for j in np.flatnonzero(use[quantity] > 1.0 + rtol).tolist():
            if quantity == "position":
                mid = 0.5 * (limits.upper[j] + limits.lower[j])
                half = 0.5 * (limits.upper[j] - limits.lower[j])
            else:
                lim = float(limits.bound(quantity)[j])
            touched = np.zeros(parts[0][1].numbers.size, dtype=bool)
            ratio_k, peak, worst = -math.inf, math.nan, None
            for s, frame_map in parts:
                values = getattr(s, field)[:, j]
                ratio = (np.abs(values - mid) / half if quantity == "position"
                         else np.abs(values) / lim)
                over = np.flatnonzero(ratio > 1.0 + rtol)
                if over.size == 0:
                    continue
                k = int(over[np.argmax(ratio[over])])
                if ratio[k] > ratio_k:
                    ratio_k, peak = float(ratio[k]), float(values[k])
                    worst = (int(frame_map.numbers[frame_map.lo[k]]),
                             int(frame_map.numbers[frame_map.hi[k]]))
                frame_map.touch(touched, over)
            if quantity == "position":
                lim = float(limits.upper[j] if peak > limits.upper[j] else limits.lower[j])
            out.append(LimitViolation(
                axis=limits.names[j], quantity=quantity, peak=peak, limit=lim, ratio=ratio_k,
                frames=parts[0][1].spans(touched), revolute=bool(revolute[j]), worst=worst,
            ))
    out.sort(key=lambda v: (v.quantity != "position", -v.speed_needed if
                            math.isfinite(v.speed_needed) else -v.ratio))
    return out


def peak_use(
    s: Samples, limits: Limits
) -> tuple[dict[str, dict[str, float]], dict[str, tuple[float, float]]]:
    peaks = Peaks.of(s)
    use = peaks.use(limits)
    table = {name: {quantity: float(use[quantity][j]) for quantity in QUANTITIES}
             for j, name in enumerate(limits.names)}
    ranges = {name: (float(peaks.q_min[j]), float(peaks.q_max[j]))
              for j, name in enumerate(limits.names)}
    return table, ranges


def fmt(value: float, quantity: str, revolute: bool) -> str:
    """A value with its unit: degrees for revolute axes, metres for prismatic ones."""
    power = QUANTITIES.index(quantity)
    unit = "deg" if revolute else "m"
    shown = math.degrees(value) if revolute else value
    suffix = ["", "/s", "/s^2", "/s^3"][power]
    mag = abs(shown)
    if mag >= 100:
        text = f"{shown:.0f}"
    elif mag >= 10:
        text = f"{shown:.1f}"
    else:
        text = f"{shown:.3g}"
    return f"{text} {unit}{suffix}"


def shot_error(
    violations: list[LimitViolation], max_speed: float, fps: float
) -> TimingLimitError:
    """The error for frames beyond a position limit (``violations`` holds at least one; the
    others are listed too): no retiming can fix it."""
    parts = [v.describe() for v in violations[:4]]
    if len(violations) > 4:
        parts.append(f"and {len(violations) - 4} more")
    msg = "; ".join(parts) + "; no retiming can fix a position limit"
    return TimingLimitError(
        msg, violations=violations, max_speed=max_speed, feasible_fps=fps * max_speed,
        scale_factor=math.inf,
    )
