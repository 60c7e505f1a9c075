"""Timing stage: the joint path of every film frame to a timed take at the servo rate.

Input is the inverse-kinematics solution of every film frame (``q_frames``, shape (n, 8),
[m, rad]) at uniformly spaced ``frame_times`` [s]. Output is a :class:`Take`: position,
velocity, acceleration and jerk of every axis at every servo sample, from rest to rest.

The stages inside :func:`time_shot`:

1. **Path.** A piecewise quintic through the frame solutions, in frame units (see
   :class:`_FramePath` for the construction and why it is quintic).
2. **Real-time check.** The path is sampled at the servo rate with the shot's own timing and
   every limit is checked at every sample (not only at frames). This gives
   :attr:`TimingReport.max_speed` and :attr:`TimingReport.limiting`.
3. **Timing mode.** ``"shot"`` keeps the film's timing (and raises :class:`TimingLimitError` if
   a limit is exceeded); ``"scale"`` slows the whole move uniformly by the smallest factor that
   fits; ``"optimal"`` retimes the same path time-optimally with toppra.
4. **Run-up and run-out.** Jerk-limited ruckig moves from rest into the first frame's full
   state and from the last frame's state to rest (see :func:`_stop_move`).

Every film frame is a servo sample and the stream passes exactly through each frame's solution.

Units: SI throughout (m, rad, s); error messages show revolute axes in degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import make_interp_spline

from camtraj.errors import LimitError
from camtraj.robot import JOINT_KINDS, JOINT_NAMES

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

MODES: tuple[str, ...] = ("shot", "scale", "optimal")
QUANTITIES: tuple[str, ...] = ("position", "velocity", "acceleration", "jerk")

N_AXES = 8
#: Two consecutive frame solutions closer than this [m or rad] count as "not moving": the path
#: is a straight line between them (exactly constant when they are equal).
HOLD_TOL = 1e-9
#: Relative tolerance of the limit checks in "shot" and "scale" modes (float round-off only).
LIMIT_RTOL = 1e-9
#: Relative slack for velocity and acceleration in "optimal" mode (toppra is discretised).
OPTIMAL_SLACK = 1e-3
#: A boundary state within this fraction of the velocity and acceleration limits is at rest.
REST_RTOL = 1e-9
#: toppra gridpoints per film-frame interval.
TOPPRA_GRID_PER_FRAME = 4
#: Film frame times may deviate from a uniform grid by this fraction of the frame interval.
UNIFORM_RTOL = 1e-6
_MAX_DEGREE = 5
_JERK_STEP = 1e-6  # [s] step of the one-sided difference that reads jerk off a ruckig move


# ---------------------------------------------------------------------------------------------
# Public data types
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Limits:
    """Per-axis limits, every array of shape (8,) in joint order, SI units.

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
        for name in ("lower", "upper", "velocity", "acceleration", "jerk"):
            arr = np.array(getattr(self, name), dtype=np.float64)
            if arr.shape != (N_AXES,) or not np.all(np.isfinite(arr)):
                msg = f"limits.{name} must be {N_AXES} finite numbers, got shape {arr.shape}"
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
        if len(self.names) != N_AXES or len(self.kinds) != N_AXES:
            msg = f"limits need {N_AXES} axis names and kinds"
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
    def revolute(self) -> BoolArray:
        """Whether each axis is revolute, shape (8,)."""
        return np.array([k == "revolute" for k in self.kinds])

    def bound(self, quantity: str) -> Array:
        """The symmetric limit of ``"velocity"``, ``"acceleration"`` or ``"jerk"``, shape (8,)."""
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
    """

    axis: str
    quantity: str
    peak: float
    limit: float
    ratio: float
    frames: tuple[tuple[int, int], ...]
    revolute: bool

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
        """The frames as text, e.g. ``"frames 12-19, 40"``."""
        return "frames " + ", ".join(f"{a}-{b}" if b != a else f"{a}" for a, b in self.frames)

    def describe(self) -> str:
        """One line for people: ``rotate velocity 143 deg/s exceeds 90.0 deg/s on frames 1-9``."""
        peak = _fmt(self.peak, self.quantity, self.revolute)
        if self.quantity == "position":
            side = "upper" if self.peak > self.limit else "lower"
            lim = _fmt(self.limit, self.quantity, self.revolute)
            return (
                f"{self.axis} position {peak} is beyond its {side} limit {lim} "
                f"on {self.frame_text}"
            )
        lim = _fmt(self.limit, self.quantity, self.revolute)
        peak = _fmt(abs(self.peak), self.quantity, self.revolute)
        return f"{self.axis} {self.quantity} {peak} exceeds {lim} on {self.frame_text}"


@dataclass(frozen=True, eq=False)
class TimingReport:
    """What the timing stage found.

    Attributes:
        peak_use: axis -> quantity -> fraction of the limit, measured at every servo sample of
            the SHOT part of the take (first to last film frame). For velocity, acceleration
            and jerk it is ``max |value| / limit``. For position it is
            ``max |q - mid| / half_range`` with ``mid``, ``half_range`` the middle and half
            width of the axis's range: 0 at the middle, 1 touching a limit.
        position_range: axis -> (min, max) position over the shot part [m or rad].
        max_speed: Maximum feasible speed as a fraction of real time, from the shot's own
            (real-time) timing: 1.0 means the shot's timing just fits, 0.5 that the robot can
            only do it at half speed, 2.0 that it could go twice as fast. Velocity scales with
            the speed, acceleration with its square, jerk with its cube. ``inf`` if nothing
            moves.
        feasible_fps: The frame rate at which the move could be shot at ``max_speed``
            (``fps * max_speed``) [frames/s], for a later speed change in post.
        limiting: Every (axis, quantity) the shot's own real-time timing exceeds (what forces
            a slower take), worst first.
        exceeded: Every (axis, quantity) the take itself still exceeds (only jerk in
            ``"optimal"`` mode: toppra does not bound jerk). Empty otherwise.
        runup: The move from rest into the first frame: ``duration`` [s] of the ruckig move,
            ``hold`` [s] at rest before it (so the first frame lands on a servo tick),
            ``start`` axis -> start position [m or rad], ``travel`` axis -> first-frame
            position minus start position, ``extent`` axis -> max - min position during the
            move (how much track it needs before the first frame).
        runout: The same for the move from the last frame to rest (``end`` instead of
            ``start``, ``travel`` = end - last-frame position, ``hold`` at rest after it).
        warnings: Things a person should know that do not stop the take.
        fps: Frame rate of the input shot [frames/s].
        ticks_per_frame: Servo samples per film frame in the take (``None`` in ``"optimal"``
            mode, where it varies from frame to frame).
    """

    peak_use: dict[str, dict[str, float]]
    position_range: dict[str, tuple[float, float]]
    max_speed: float
    feasible_fps: float
    limiting: list[LimitViolation]
    exceeded: list[LimitViolation]
    runup: dict[str, Any]
    runout: dict[str, Any]
    warnings: list[str]
    fps: float
    ticks_per_frame: int | None


@dataclass(frozen=True, eq=False)
class Take:
    """A timed trajectory from rest to rest, sampled at the servo rate.

    Attributes:
        t: Sample times [s], shape (m,), ``t[0] = 0`` (the take starts at rest).
        q: Positions [m, rad], shape (m, 8).
        qd: Velocities [m/s, rad/s], shape (m, 8).
        qdd: Accelerations [m/s², rad/s²], shape (m, 8).
        qddd: Jerks [m/s³, rad/s³], shape (m, 8). Exact values for the spline and ruckig
            parts; in the shot part of ``"optimal"`` mode the mean jerk over the following
            servo step (toppra's time law has piecewise-constant path acceleration).
        frame_times: Time of each film frame in the take [s], shape (n,) (after run-up, after
            any retime); ``t[frame_samples] == frame_times`` exactly.
        frame_samples: Index into ``t`` of each film frame, shape (n,).
        frame_numbers: Film frame number of each frame, shape (n,).
        mode: ``"shot"``, ``"scale"`` or ``"optimal"``.
        speed_factor: Duration of the shot part in the take / original shot duration (1.0 for
            ``"shot"``; above 1 means slowed down, below 1 sped up).
        rate: Effective servo rate [Hz]: ``1 / step``. In ``"shot"`` and ``"scale"`` modes the
            grid is uniform and the rate is an integer multiple of the take's frame rate,
            nearest to the requested rate; in ``"optimal"`` mode each frame interval is cut
            into equal steps no longer than ``1 / requested rate`` and this is the lowest
            rate (longest step) used.
        uniform: Whether every step of ``t`` has the same length.
        shot_start: Take time of the first film frame [s].
        shot_end: Take time of the last film frame [s].
        report: The :class:`TimingReport`.
    """

    t: Array
    q: Array
    qd: Array
    qdd: Array
    qddd: Array
    frame_times: Array
    frame_samples: IntArray
    frame_numbers: IntArray
    mode: str
    speed_factor: float
    rate: float
    uniform: bool
    shot_start: float
    shot_end: float
    report: TimingReport

    @property
    def duration(self) -> float:
        """Length of the whole take [s]."""
        return float(self.t[-1])


class TimingLimitError(LimitError):
    """The shot cannot be timed inside the limits.

    Attributes:
        violations: The limits exceeded, worst first.
        max_speed: See :attr:`TimingReport.max_speed` (nan when not known).
        feasible_fps: See :attr:`TimingReport.feasible_fps` (nan when not known).
    """

    def __init__(
        self,
        message: str,
        *,
        violations: list[LimitViolation] | None = None,
        max_speed: float = math.nan,
        feasible_fps: float = math.nan,
    ) -> None:
        super().__init__(message)
        self.violations = violations or []
        self.max_speed = max_speed
        self.feasible_fps = feasible_fps


# ---------------------------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------------------------


def time_shot(
    q_frames: ArrayLike,
    frame_times: ArrayLike,
    limits: Limits,
    *,
    mode: str = "shot",
    rate: float = 250.0,
    frame_numbers: ArrayLike | None = None,
) -> Take:
    """Time a joint path for the robot: from rest, through every film frame, to rest.

    Args:
        q_frames: Joint solution of every film frame [m, rad], shape (n, 8), n >= 2.
        frame_times: Time of every film frame in the shot [s], shape (n,), uniformly spaced
            (1/fps apart); only the spacing is used.
        limits: The robot's limits.
        mode: ``"shot"`` keeps the film's timing and raises :class:`TimingLimitError` if a
            limit is exceeded; ``"scale"`` slows the whole move by the smallest uniform factor
            that fits velocity, acceleration and jerk; ``"optimal"`` retimes the path
            time-optimally under velocity and acceleration limits (toppra), keeping still
            stretches as holds of their original duration.
        rate: Requested servo rate [Hz].
        frame_numbers: Film frame number of every frame, shape (n,) (default 0..n-1); used in
            messages and reports.

    Returns:
        The :class:`Take`.

    Raises:
        ValueError: Bad shapes, non-finite values, non-increasing or non-uniform times, an
            unknown mode or a non-positive rate.
        TimingLimitError: A limit is exceeded (``"shot"`` mode), a position limit is crossed
            (every mode, including by the run-up or run-out), or the retime fails.
    """
    q, dt, frames = _validate(q_frames, frame_times, frame_numbers, mode, rate)
    n = q.shape[0]
    fps = 1.0 / dt
    path = _FramePath.fit(q, dt)

    # The shot's own timing, sampled at the servo rate: limits, max speed.
    ticks0 = max(1, round(rate * dt))
    rt_x = _uniform_x(n, ticks0)
    rt = path.timed(rt_x, np.full_like(rt_x, fps), np.zeros_like(rt_x))
    rt_frames = _FrameMap.of(rt_x, frames)
    slowdown = _slowdown(rt, limits)
    max_speed = 1.0 / slowdown if slowdown > 0 else math.inf
    limiting = _violations(rt, limits, rt_frames, LIMIT_RTOL)
    position_bad = [v for v in limiting if v.quantity == "position"]

    if mode == "shot" and limiting:
        raise _shot_error(limiting, max_speed, fps)
    if position_bad:
        raise _shot_error(position_bad, max_speed, fps)

    warnings: list[str] = []
    exceeded: list[LimitViolation] = []
    if mode == "shot":
        shot, shot_x, speed_factor, ticks = rt, rt_x, 1.0, ticks0
        shot_rate = ticks0 * fps
        shot_t = np.arange(rt_x.size) / shot_rate
        frame_idx = np.arange(n, dtype=np.int64) * ticks
    elif mode == "scale":
        speed_factor, ticks, shot, shot_x = _scale(path, n, dt, rate, limits, slowdown)
        shot_rate = ticks / (speed_factor * dt)
        shot_t = np.arange(shot_x.size) / shot_rate
        frame_idx = np.arange(n, dtype=np.int64) * ticks
    else:
        scale_factor = max(1.0, slowdown)
        shot_t, shot_x, shot, frame_idx = _optimal(path, limits, rate, scale_factor)
        speed_factor = float(shot_t[-1] / (dt * (n - 1)))
        ticks = 0
        shot_rate = 0.0

    # Position limits of the shot part as sampled in the take.
    take_frames = _FrameMap.of(shot_x, frames)
    pos_bad = [v for v in _violations(shot, limits, take_frames, LIMIT_RTOL)
               if v.quantity == "position"]
    if pos_bad:
        raise _shot_error(pos_bad, max_speed, fps)
    if mode == "optimal":
        exceeded = [v for v in _violations(shot, limits, take_frames, OPTIMAL_SLACK)
                    if v.quantity == "jerk"]
        for v in exceeded:
            warnings.append(
                f"{v.describe()} (optimal timing does not bound jerk; "
                "use --timing scale for a jerk-limited take)"
            )

    # Run-up and run-out on a uniform servo grid (step of the shot part in uniform modes).
    step = 1.0 / shot_rate if shot_rate > 0 else 1.0 / rate
    up = _runup(shot.q[0], shot.qd[0], shot.qdd[0], limits, step, frames[0])
    out = _runout(shot.q[-1], shot.qd[-1], shot.qdd[-1], limits, step, frames[-1])

    n_up = up.q.shape[0]
    m = n_up + shot.q.shape[0] + out.q.shape[0]
    if mode == "optimal":
        t_shot = n_up * step + shot_t
        t = np.concatenate([
            np.arange(n_up) * step, t_shot, t_shot[-1] + np.arange(1, out.q.shape[0] + 1) * step
        ])
        steps = np.diff(t)
        eff_rate = float(1.0 / steps.max()) if steps.size else float(rate)
        uniform = False
    else:
        t = np.arange(m) * step
        eff_rate = shot_rate
        uniform = True
    q_all = np.concatenate([up.q, shot.q, out.q])
    qd_all = np.concatenate([up.qd, shot.qd, out.qd])
    qdd_all = np.concatenate([up.qdd, shot.qdd, out.qdd])
    qddd_all = np.concatenate([up.qddd, shot.qddd, out.qddd])
    frame_samples = (n_up + frame_idx).astype(np.int64)
    frame_times_take = t[frame_samples]

    peak_use, position_range = _peak_use(shot, limits)
    report = TimingReport(
        peak_use=peak_use,
        position_range=position_range,
        max_speed=max_speed,
        feasible_fps=fps * max_speed,
        limiting=limiting,
        exceeded=exceeded,
        runup=up.report,
        runout=out.report,
        warnings=warnings + up.warnings + out.warnings,
        fps=fps,
        ticks_per_frame=ticks if mode != "optimal" else None,
    )
    for arr in (t, q_all, qd_all, qdd_all, qddd_all):
        if not np.all(np.isfinite(arr)):  # pragma: no cover - a bug, not a user error
            msg = "internal error: the timed take has non-finite values"
            raise RuntimeError(msg)
    return Take(
        t=t,
        q=q_all,
        qd=qd_all,
        qdd=qdd_all,
        qddd=qddd_all,
        frame_times=frame_times_take,
        frame_samples=frame_samples,
        frame_numbers=frames,
        mode=mode,
        speed_factor=speed_factor,
        rate=eff_rate,
        uniform=uniform,
        shot_start=float(frame_times_take[0]),
        shot_end=float(frame_times_take[-1]),
        report=report,
    )


# ---------------------------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------------------------


def _validate(
    q_frames: ArrayLike,
    frame_times: ArrayLike,
    frame_numbers: ArrayLike | None,
    mode: str,
    rate: float,
) -> tuple[Array, float, IntArray]:
    q = np.array(q_frames, dtype=np.float64)
    times = np.array(frame_times, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != N_AXES:
        msg = f"q_frames must have shape (n, {N_AXES}), got {q.shape}"
        raise ValueError(msg)
    n = q.shape[0]
    if n < 2:
        msg = f"a shot needs at least 2 frames, got {n}"
        raise ValueError(msg)
    if times.shape != (n,):
        msg = f"frame_times must have shape ({n},) to match q_frames, got {times.shape}"
        raise ValueError(msg)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(times))):
        msg = "q_frames and frame_times must be finite (no NaN or inf)"
        raise ValueError(msg)
    steps = np.diff(times)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0])
        msg = f"frame_times must increase: frame {bad + 1} is not after frame {bad}"
        raise ValueError(msg)
    dt = float((times[-1] - times[0]) / (n - 1))
    if np.max(np.abs(steps - dt)) > UNIFORM_RTOL * dt:
        msg = "frame_times must be uniformly spaced (1/fps apart)"
        raise ValueError(msg)
    if mode not in MODES:
        msg = f"timing mode {mode!r} is not one of {', '.join(MODES)}"
        raise ValueError(msg)
    if not (math.isfinite(rate) and rate > 0):
        msg = f"servo rate must be a positive number [Hz], got {rate}"
        raise ValueError(msg)
    if frame_numbers is None:
        frames = np.arange(n, dtype=np.int64)
    else:
        frames = np.array(frame_numbers).astype(np.int64)
        if frames.shape != (n,):
            msg = f"frame_numbers must have shape ({n},), got {frames.shape}"
            raise ValueError(msg)
    return q, dt, frames


# ---------------------------------------------------------------------------------------------
# The joint path
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Samples:
    """Positions and time derivatives at a set of samples, each (m, 8), SI."""

    q: Array
    qd: Array
    qdd: Array
    qddd: Array


@dataclass(frozen=True, eq=False)
class _FramePath:
    """The joint path as a function of the frame coordinate ``x`` (frame i at x = i).

    Piece ``i`` (between frames i and i+1) is ``sum_k coef[i, k, :] * (x - i)**k``, k <= 5.

    Why a quintic, built per axis:

    * An interpolating spline must be at least C2 (continuous acceleration) and the jerk is
      checked, so it should be meaningful: the quintic spline is C4, its jerk continuous and
      accurate (a cubic's jerk is piecewise constant and jumps at every frame).
    * Previs often holds an axis still and then moves it. A global interpolating spline
      rings into the hold: the axis wobbles while it should stand still. So every axis is
      split at its still intervals (consecutive solutions within :data:`HOLD_TOL`): those are
      straight lines (exactly constant for equal solutions) and every moving stretch gets its
      own quintic spline clamped to the hold's velocity and zero acceleration at the ends -
      two conditions per end, which a quintic has and a cubic has not. The axis then starts
      and stops with continuous acceleration and never moves in a hold.
    * Free ends (the first and last frame of the shot) take velocity and acceleration from
      the interpolating polynomial of the nearest (up to) six frames, accurate to O(h^5) and
      O(h^4), instead of forcing a made-up condition such as zero acceleration.

    Working in frame units keeps the spline systems well conditioned; time derivatives are
    ``d^k q / dx^k * (dx/dt)^k``. The constant coefficient of every piece is set to the frame
    solution itself, so the path passes exactly (bit for bit) through every frame.
    """

    coef: Array  # (n - 1, 6, 8)
    q_frames: Array  # (n, 8)
    dt: float
    still: BoolArray  # (n - 1, 8) per axis: this frame interval is a straight (hold) line

    @classmethod
    def fit(cls, q: Array, dt: float) -> _FramePath:
        n = q.shape[0]
        diff = np.diff(q, axis=0)
        still = np.abs(diff) <= HOLD_TOL
        coef = np.zeros((n - 1, _MAX_DEGREE + 1, N_AXES))
        coef[:, 0, :] = q[:-1]
        coef[:, 1, :] = np.where(still, diff, 0.0)
        x = np.arange(n, dtype=np.float64)
        for j in range(N_AXES):
            for a, b in _runs(~still[:, j]):
                # Moving stretch: frame intervals a..b-1, frames a..b.
                if a == 0:
                    left = _end_derivatives(q[a : min(b, a + 5) + 1, j], at_start=True)
                else:
                    left = (float(diff[a - 1, j]), 0.0)
                if b == n - 1:
                    right = _end_derivatives(q[max(a, b - 5) : b + 1, j], at_start=False)
                else:
                    right = (float(diff[b, j]), 0.0)
                spline = make_interp_spline(
                    x[a : b + 1], q[a : b + 1, j], k=_MAX_DEGREE,
                    bc_type=([(1, left[0]), (2, left[1])], [(1, right[0]), (2, right[1])]),
                )
                xs = x[a:b]
                for k in range(1, _MAX_DEGREE + 1):
                    coef[a:b, k, j] = spline(xs, nu=k) / math.factorial(k)
                # The spline meets its start conditions only to round-off (how close depends
                # on the CPU's floating-point kernels); write them exactly, so that an axis
                # leaving a hold starts from exactly zero velocity and acceleration.
                coef[a, 1, j] = left[0]
                coef[a, 2, j] = 0.5 * left[1]
        return cls(coef=coef, q_frames=q, dt=dt, still=still)

    @property
    def n(self) -> int:
        return int(self.q_frames.shape[0])

    def at(self, x: Array, order: int = 3) -> list[Array]:
        """Derivatives 0..order with respect to x at frame coordinates x, each (m, 8)."""
        last = self.n - 2
        idx = np.clip(np.floor(x).astype(np.int64), 0, last)
        tau = x - idx
        powers = tau[:, None] ** np.arange(_MAX_DEGREE + 1)[None, :]  # (m, 6)
        c = self.coef[idx]  # (m, 6, 8)
        out: list[Array] = []
        for d in range(order + 1):
            k = np.arange(d, _MAX_DEGREE + 1)
            fac = np.array([math.perm(int(kk), d) for kk in k], dtype=np.float64)
            basis = powers[:, : _MAX_DEGREE + 1 - d] * fac[None, :]  # tau^(k-d) * k!/(k-d)!
            out.append(np.einsum("mk,mka->ma", basis, c[:, d:, :]))
        # Exactly the last frame's solution at the last frame.
        at_end = x >= self.n - 1
        out[0][at_end] = self.q_frames[-1]
        return out

    def timed(self, x: Array, xd: Array, xdd: Array, *, jerk_by_difference: bool = False,
              t: Array | None = None) -> _Samples:
        """Time derivatives for a time law x(t) given as x, dx/dt, d²x/dt² at each sample.

        ``xd`` is in frames per second. Jerk is exact when ``dx/dt`` is constant; with
        ``jerk_by_difference`` it is the forward difference of the acceleration over the
        sample times ``t`` (for time laws whose path acceleration jumps).
        """
        p0, p1, p2, p3 = self.at(x)
        xd_ = xd[:, None]
        xdd_ = xdd[:, None]
        qd = p1 * xd_
        qdd = p2 * xd_**2 + p1 * xdd_
        if jerk_by_difference:
            if t is None:  # pragma: no cover - internal misuse
                msg = "jerk by difference needs the sample times"
                raise ValueError(msg)
            qddd = np.empty_like(qdd)
            if t.size > 1:
                fd = np.diff(qdd, axis=0) / np.diff(t)[:, None]
                qddd[:-1] = fd
                qddd[-1] = fd[-1]
            else:
                qddd[:] = 0.0
        else:
            qddd = p3 * xd_**3 + 3.0 * p2 * xd_ * xdd_
        return _Samples(q=p0, qd=qd, qdd=qdd, qddd=qddd)


def _runs(mask: BoolArray) -> list[tuple[int, int]]:
    """Half-open index ranges [a, b) of the True runs of a 1-D mask."""
    padded = np.concatenate([[0], mask.astype(np.int8), [0]])
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _end_derivatives(values: Array, *, at_start: bool) -> tuple[float, float]:
    """First and second derivative (frame units) at the first or last of unit-spaced values.

    From the interpolating polynomial of all given values (up to six: degree five).
    """
    m = values.size
    if m < 3:
        return (float(values[-1] - values[0]), 0.0)
    x = np.arange(m, dtype=np.float64) - (0 if at_start else m - 1)
    vander = x[:, None] ** np.arange(m)[None, :]
    c = np.linalg.solve(vander, values)
    return (float(c[1]), float(2.0 * c[2]))


def _uniform_x(n: int, ticks: int) -> Array:
    """Frame coordinates of a uniform grid with ``ticks`` samples per frame interval.

    Frame i is sample i*ticks and its coordinate is exactly i.
    """
    return np.arange((n - 1) * ticks + 1, dtype=np.float64) / ticks


@dataclass(frozen=True, eq=False)
class _FrameMap:
    """Which film frames each sample belongs to.

    ``lo[k]``, ``hi[k]``: frame indices (0..n-1) of sample k: the same frame on a frame,
    the two neighbours between frames. ``numbers``: film frame number of each index.
    """

    lo: IntArray
    hi: IntArray
    numbers: IntArray

    @classmethod
    def of(cls, x: Array, numbers: IntArray) -> _FrameMap:
        n = numbers.size
        lo = np.clip(np.floor(x).astype(np.int64), 0, n - 1)
        hi = np.where(x > lo, np.minimum(lo + 1, n - 1), lo)
        return cls(lo=lo, hi=hi, numbers=numbers)

    def spans(self, samples: IntArray) -> tuple[tuple[int, int], ...]:
        """Inclusive runs ``(first, last)`` of film frame numbers touched by the samples."""
        touched = np.zeros(self.numbers.size, dtype=bool)
        touched[self.lo[samples]] = True
        touched[self.hi[samples]] = True
        return tuple(
            (int(self.numbers[a]), int(self.numbers[b - 1])) for a, b in _runs(touched)
        )


# ---------------------------------------------------------------------------------------------
# Limit checks
# ---------------------------------------------------------------------------------------------


def _position_use(q: Array, limits: Limits) -> Array:
    mid = 0.5 * (limits.upper + limits.lower)
    half = 0.5 * (limits.upper - limits.lower)
    use: Array = np.abs(q - mid) / half
    return use


def _slowdown(s: _Samples, limits: Limits) -> float:
    """The smallest uniform slow-down factor that makes velocity, acceleration and jerk fit.

    0 when nothing moves; below 1 when the move could go faster.
    """
    if s.q.shape[0] == 0:
        return 0.0
    kv = float(np.max(np.abs(s.qd) / limits.velocity))
    ka = float(np.max(np.abs(s.qdd) / limits.acceleration))
    kj = float(np.max(np.abs(s.qddd) / limits.jerk))
    return max(kv, math.sqrt(ka), math.pow(kj, 1.0 / 3.0))


def _violations(
    s: _Samples, limits: Limits, frame_map: _FrameMap, rtol: float
) -> list[LimitViolation]:
    """Every (axis, quantity) exceeding its limit by more than ``rtol``, worst first."""
    out: list[LimitViolation] = []
    revolute = limits.revolute
    pos_use = _position_use(s.q, limits)
    for j, name in enumerate(limits.names):
        over = np.flatnonzero(pos_use[:, j] > 1.0 + rtol)
        if over.size:
            k = int(over[np.argmax(pos_use[over, j])])
            peak = float(s.q[k, j])
            bound = float(limits.upper[j] if peak > limits.upper[j] else limits.lower[j])
            out.append(LimitViolation(
                axis=name, quantity="position", peak=peak, limit=bound,
                ratio=float(pos_use[k, j]), frames=frame_map.spans(over),
                revolute=bool(revolute[j]),
            ))
        for quantity, values in (("velocity", s.qd), ("acceleration", s.qdd),
                                 ("jerk", s.qddd)):
            lim = float(limits.bound(quantity)[j])
            ratio = np.abs(values[:, j]) / lim
            over = np.flatnonzero(ratio > 1.0 + rtol)
            if over.size:
                k = int(over[np.argmax(ratio[over])])
                out.append(LimitViolation(
                    axis=name, quantity=quantity, peak=float(values[k, j]), limit=lim,
                    ratio=float(ratio[k]), frames=frame_map.spans(over),
                    revolute=bool(revolute[j]),
                ))
    out.sort(key=lambda v: (v.quantity != "position", -v.speed_needed if
                            math.isfinite(v.speed_needed) else -v.ratio))
    return out


def _peak_use(
    s: _Samples, limits: Limits
) -> tuple[dict[str, dict[str, float]], dict[str, tuple[float, float]]]:
    pos = _position_use(s.q, limits).max(axis=0)
    vel = (np.abs(s.qd) / limits.velocity).max(axis=0)
    acc = (np.abs(s.qdd) / limits.acceleration).max(axis=0)
    jerk = (np.abs(s.qddd) / limits.jerk).max(axis=0)
    use = {
        name: {"position": float(pos[j]), "velocity": float(vel[j]),
               "acceleration": float(acc[j]), "jerk": float(jerk[j])}
        for j, name in enumerate(limits.names)
    }
    qmin, qmax = s.q.min(axis=0), s.q.max(axis=0)
    ranges = {name: (float(qmin[j]), float(qmax[j])) for j, name in enumerate(limits.names)}
    return use, ranges


def _fmt(value: float, quantity: str, revolute: bool) -> str:
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


def _shot_error(
    violations: list[LimitViolation], max_speed: float, fps: float
) -> TimingLimitError:
    parts = [v.describe() for v in violations[:4]]
    if len(violations) > 4:
        parts.append(f"and {len(violations) - 4} more")
    msg = "; ".join(parts)
    if any(v.quantity == "position" for v in violations):
        msg += "; no retiming can fix a position limit"
    else:
        pct = math.floor(max_speed * 100.0)
        fit_fps = math.floor(fps * max_speed * 10.0) / 10.0
        msg += f"; the move fits at {pct}% speed ({fit_fps:.1f} fps) - try --timing scale"
    return TimingLimitError(
        msg, violations=violations, max_speed=max_speed, feasible_fps=fps * max_speed
    )


# ---------------------------------------------------------------------------------------------
# "scale" mode
# ---------------------------------------------------------------------------------------------


def _scale(
    path: _FramePath, n: int, dt: float, rate: float, limits: Limits, slowdown: float
) -> tuple[float, int, _Samples, Array]:
    """Slow the move uniformly by the smallest factor >= 1 that fits (resampled and verified).

    Velocity scales with 1/s, acceleration with 1/s², jerk with 1/s³, so the factor follows
    from the real-time peaks. The take's grid has different sample points from the real-time
    check (ticks per frame change with s), so the stream is resampled and the factor raised
    if a sample of the resampled stream still exceeds a limit.
    """
    s = max(1.0, slowdown)
    for _ in range(20):
        ticks = max(1, round(rate * s * dt))
        x = _uniform_x(n, ticks)
        xd = np.full_like(x, 1.0 / (s * dt))
        samples = path.timed(x, xd, np.zeros_like(x))
        k = _slowdown(samples, limits)
        if k <= 1.0 + LIMIT_RTOL:
            return s, ticks, samples, x
        s *= k * (1.0 + 1e-12)
    msg = "internal error: the scale factor did not settle"  # pragma: no cover
    raise RuntimeError(msg)  # pragma: no cover


# ---------------------------------------------------------------------------------------------
# "optimal" mode
# ---------------------------------------------------------------------------------------------


class _ToppraPath:
    """One moving stretch of the path for toppra: s in [0, 1] maps to frames a..b.

    toppra misbehaves with unnormalised path parameters, so s is normalised.
    """

    def __init__(self, path: _FramePath, a: int, b: int) -> None:
        self._path = path
        self._a = a
        self._len = float(b - a)
        self.dof = N_AXES
        self.path_interval = np.array([0.0, 1.0])

    def __call__(self, ss: ArrayLike, order: int = 0) -> Array:
        s = np.atleast_1d(np.asarray(ss, dtype=np.float64))
        x = self._a + s * self._len
        values = self._path.at(x, order)[order] * self._len**order
        if np.ndim(ss) == 0:
            first: Array = values[0]
            return first
        return values


@dataclass(frozen=True, eq=False)
class _TimeLaw:
    """Piecewise constant path acceleration: x(t) on one moving stretch of frames a..b."""

    a: int
    b: int
    t_grid: Array  # (N+1,) time of each gridpoint from the stretch start [s]
    s_grid: Array  # (N+1,) normalised path parameter of each gridpoint
    sd: Array  # (N+1,) ds/dt at gridpoints [1/s]
    sdd: Array  # (N,) d²s/dt² on each grid interval [1/s²]

    def frame_times(self) -> Array:
        """Time of every frame a..b from the stretch start [s]."""
        per = (self.s_grid.size - 1) // (self.b - self.a)
        return self.t_grid[::per]

    def eval(self, t: Array) -> tuple[Array, Array, Array]:
        """Frame coordinate x, dx/dt, d²x/dt² at times t from the stretch start."""
        k = np.clip(np.searchsorted(self.t_grid, t, side="right") - 1, 0, self.sdd.size - 1)
        tau = t - self.t_grid[k]
        u = self.sdd[k]
        s = self.s_grid[k] + self.sd[k] * tau + 0.5 * u * tau**2
        s = np.clip(s, self.s_grid[k], self.s_grid[k + 1])
        sd = self.sd[k] + u * tau
        length = float(self.b - self.a)
        return self.a + s * length, sd * length, u * length

    def stretched(self, factor: float) -> _TimeLaw:
        """The same time law played ``factor`` times slower."""
        return _TimeLaw(self.a, self.b, self.t_grid * factor, self.s_grid, self.sd / factor,
                        self.sdd / factor**2)


def _optimal(
    path: _FramePath, limits: Limits, rate: float, scale_factor: float
) -> tuple[Array, Array, _Samples, IntArray]:
    """Time-optimal traversal of the path under velocity and acceleration limits (toppra).

    Stretches where no axis moves are split out and kept as holds of their original length
    (toppra fails on them). Each moving stretch is retimed with toppra on a normalised path
    parameter, with gridpoints at the frames (subdivided). A stretch that starts or ends the
    shot does so at the path speed of ``"scale"`` mode (so the take is never slower than
    ``"scale"``, and the run-up and run-out are like those of ``"scale"``); a stretch next to
    a hold starts or ends at rest. toppra's constant-path-acceleration time law is sampled
    directly: every frame interval is cut into the fewest equal steps no longer than
    ``1 / rate``, so every frame is a sample. The sampled stream is verified; toppra's
    discretisation can overshoot a limit slightly, in which case that axis's limit is
    tightened and the stretch retimed, and as a last resort the stretch is slowed uniformly.

    Returns:
        Sample times of the shot part from the first frame [s], the frame coordinate of each
        sample, the samples, and the sample index of every frame.
    """
    n = path.n
    dt = path.dt
    still_all = np.all(path.still, axis=1)
    moving = _runs(~still_all)
    laws: dict[int, _TimeLaw] = {}
    for a, b in moving:
        laws[a] = _retime_stretch(path, a, b, limits, scale_factor, dt, rate)

    # Frame times and per-interval sampling.
    frame_t = np.zeros(n)
    i = 0
    while i < n - 1:
        if i in laws:
            law = laws[i]
            frame_t[law.a : law.b + 1] = frame_t[law.a] + law.frame_times()
            i = law.b
        else:
            frame_t[i + 1] = frame_t[i] + dt
            i += 1

    # Every frame interval cut into the fewest equal steps no longer than 1 / rate; the
    # last frame is one more sample.
    durations = np.diff(frame_t)
    steps = np.maximum(1, np.ceil(durations * rate - 1e-9)).astype(np.int64)
    counts = np.concatenate([steps, [1]])
    frame_idx = np.concatenate([[0], np.cumsum(counts[:-1])]).astype(np.int64)
    interval = np.repeat(np.arange(n, dtype=np.int64), counts)
    j = np.arange(interval.size) - frame_idx[interval]
    frac = j / counts[interval]
    local = frac * np.concatenate([durations, [0.0]])[interval]
    t = frame_t[interval] + local
    x = interval + frac  # exact on frames; holds advance linearly at the original speed
    xd = np.full(t.size, 1.0 / dt)
    xdd = np.zeros(t.size)
    for law in laws.values():
        sel = (interval >= law.a) & (interval < law.b)
        sel[frame_idx[law.b]] = True  # the stretch's last frame belongs to it too
        xl, xdl, xddl = law.eval(t[sel] - frame_t[law.a])
        xd[sel], xdd[sel] = xdl, xddl
        on_frame = j[sel] == 0
        x[sel] = np.where(on_frame, x[sel], xl)
    samples = path.timed(x, xd, xdd, jerk_by_difference=True, t=t)
    return t, x, samples, frame_idx


def _retime_stretch(
    path: _FramePath, a: int, b: int, limits: Limits, scale_factor: float, dt: float,
    rate: float,
) -> _TimeLaw:
    """toppra on frames a..b, verified by sampling; limits tightened where it overshoots."""
    # Imported here: toppra imports matplotlib (slow) and only this mode needs it.
    import toppra
    import toppra.algorithm
    import toppra.constraint

    length = float(b - a)
    n_grid = (b - a) * TOPPRA_GRID_PER_FRAME
    grid = np.arange(n_grid + 1, dtype=np.float64) / n_grid
    grid[-1] = 1.0
    tp_path = _ToppraPath(path, a, b)
    # Path speed of "scale" mode, in normalised parameter per second.
    sd_scale = 1.0 / (scale_factor * dt * length)
    sd_start = sd_scale if a == 0 else 0.0
    sd_end = sd_scale if b == path.n - 1 else 0.0

    vel = np.array(limits.velocity, dtype=np.float64)
    acc = np.array(limits.acceleration, dtype=np.float64)
    law: _TimeLaw | None = None
    for _attempt in range(4):
        constraints = [
            toppra.constraint.JointVelocityConstraint(vel),
            toppra.constraint.JointAccelerationConstraint(acc),
        ]
        law = None
        for start, end in ((sd_start, sd_end), (0.0, 0.0)):
            instance = toppra.algorithm.TOPPRA(
                constraints, tp_path, gridpoints=grid, solver_wrapper="seidel",
                parametrizer="ParametrizeConstAccel",
            )
            result = instance.compute_parameterization(start, end)
            sd = result[1]
            if sd is not None and np.all(np.isfinite(sd)):
                law = _law_from_sd(a, b, grid, np.asarray(sd, dtype=np.float64))
                if law is not None:
                    break
        if law is None:
            msg = (
                f"the time-optimal retime failed on frames {a}-{b} (toppra found no "
                "feasible timing); try --timing scale"
            )
            raise TimingLimitError(msg)
        kv, ka = _law_ratios(path, law, limits, rate)
        if np.all(kv <= 1.0 + 0.5 * OPTIMAL_SLACK) and np.all(ka <= 1.0 + 0.5 * OPTIMAL_SLACK):
            return law
        vel = vel / np.maximum(kv, 1.0) * (1.0 - 1e-4)
        acc = acc / np.maximum(ka, 1.0) * (1.0 - 1e-4)
    assert law is not None
    kv, ka = _law_ratios(path, law, limits, rate)
    factor = max(1.0, float(np.max(kv)), math.sqrt(float(np.max(ka)))) * (1.0 + 1e-6)
    return law.stretched(factor)


def _law_from_sd(a: int, b: int, grid: Array, sd: Array) -> _TimeLaw | None:
    ds = np.diff(grid)
    sd = np.maximum(sd, 0.0)
    mean = sd[:-1] + sd[1:]
    if np.any(mean <= 0):
        return None
    dts = 2.0 * ds / mean
    t_grid = np.concatenate([[0.0], np.cumsum(dts)])
    sdd = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
    if not (np.all(np.isfinite(t_grid)) and np.all(np.isfinite(sdd))):
        return None
    return _TimeLaw(a=a, b=b, t_grid=t_grid, s_grid=grid, sd=sd, sdd=sdd)


def _law_ratios(path: _FramePath, law: _TimeLaw, limits: Limits, rate: float) -> tuple[
    Array, Array
]:
    """Peak |velocity| / limit and |acceleration| / limit per axis, sampled densely.

    Sampled at both ends and the middle of every grid interval (the path acceleration jumps
    at gridpoints, so both one-sided values count) and at the servo rate.
    """
    spans = np.diff(law.t_grid)
    mids = law.t_grid[:-1] + 0.5 * spans
    ends = law.t_grid[1:] - 1e-9 * spans
    servo = np.arange(0.0, float(law.t_grid[-1]), 1.0 / rate)
    t = np.concatenate([law.t_grid, mids, ends, servo])
    x, xd, xdd = law.eval(t)
    s = path.timed(x, xd, xdd)
    kv: Array = (np.abs(s.qd) / limits.velocity).max(axis=0)
    ka: Array = (np.abs(s.qdd) / limits.acceleration).max(axis=0)
    return kv, ka


# ---------------------------------------------------------------------------------------------
# Run-up and run-out
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Edge:
    """Samples of a run-up or run-out (each (k, 8)) and its report."""

    q: Array
    qd: Array
    qdd: Array
    qddd: Array
    report: dict[str, Any]
    warnings: list[str]


class _StopMove:
    """A ruckig move from a state to rest, per axis time-optimal (no synchronisation).

    Velocity control interface: the target is zero velocity and acceleration, the stop
    position is whatever the jerk-limited braking reaches. Each axis brakes as hard as its
    limits allow, which is also the shortest braking distance. Only ruckig's state-to-state
    calculation is used (offline: no control cycle, no intermediate waypoints - those call a
    remote service).
    """

    def __init__(self, p: Array, v: Array, a: Array, limits: Limits) -> None:
        from ruckig import (
            ControlInterface,
            InputParameter,
            Result,
            Ruckig,
            Synchronization,
            Trajectory,
        )

        inp = InputParameter(N_AXES)
        inp.control_interface = ControlInterface.Velocity
        inp.synchronization = Synchronization.No
        inp.current_position = [float(x) for x in p]
        inp.current_velocity = [float(x) for x in v]
        inp.current_acceleration = [float(x) for x in a]
        inp.target_position = [float(x) for x in p]
        inp.target_velocity = [0.0] * N_AXES
        inp.target_acceleration = [0.0] * N_AXES
        inp.max_velocity = [float(x) for x in limits.velocity]
        inp.max_acceleration = [float(x) for x in limits.acceleration]
        inp.max_jerk = [float(x) for x in limits.jerk]
        traj = Trajectory(N_AXES)
        try:
            result = Ruckig(N_AXES).calculate(inp, traj)
        except RuntimeError as exc:  # ruckig raises on invalid input
            msg = f"ruckig could not plan a stop from the shot's boundary state: {exc}"
            raise TimingLimitError(msg) from exc
        if result not in (Result.Working, Result.Finished):
            msg = f"ruckig could not plan a stop from the shot's boundary state ({result})"
            raise TimingLimitError(msg)
        self._traj = traj
        self.duration = float(traj.duration)
        end = traj.at_time(self.duration)
        self.rest_position = np.array(end[0], dtype=np.float64)
        # Position range of the move. (ruckig's position_extrema is not reliable with the
        # velocity interface, so sample: between samples the position can exceed the
        # sampled range by at most max_acceleration * step² / 8, below 0.1 µm here.)
        dense = np.linspace(0.0, self.duration, max(2, math.ceil(self.duration / 2e-4) + 1))
        pos = np.array([traj.at_time(tm)[0] for tm in dense.tolist()], dtype=np.float64)
        self.min = pos.min(axis=0)
        self.max = pos.max(axis=0)

    def sample(self, times: Array) -> tuple[Array, Array, Array, Array]:
        """Position, velocity, acceleration and jerk at move times, each (k, 8).

        At and after the end of the move the state is exactly rest at the stop position.
        Jerk is read as a short one-sided difference of the acceleration (ruckig's jerk is
        piecewise constant; the difference is a mean of it, so never beyond the limit).
        """
        k = times.size
        p = np.empty((k, N_AXES))
        v = np.zeros((k, N_AXES))
        a = np.zeros((k, N_AXES))
        j = np.zeros((k, N_AXES))
        at = self._traj.at_time
        for i, tm in enumerate(times.tolist()):
            if tm >= self.duration:
                p[i] = self.rest_position
                continue
            tm = max(tm, 0.0)
            pi, vi, ai = at(tm)
            p[i], v[i], a[i] = pi, vi, ai
            t2 = min(tm + _JERK_STEP, self.duration)
            if t2 > tm:
                j[i] = (np.array(at(t2)[2]) - a[i]) / (t2 - tm)
        return p, v, a, j


def _at_rest(v: Array, a: Array, limits: Limits) -> bool:
    return bool(np.all(np.abs(v) <= REST_RTOL * limits.velocity)
                and np.all(np.abs(a) <= REST_RTOL * limits.acceleration))


def _empty_edge(p: Array, limits: Limits, key: str) -> _Edge:
    empty = np.zeros((0, N_AXES))
    report = {
        "duration": 0.0, "hold": 0.0, "samples": 0,
        key: {name: float(p[j]) for j, name in enumerate(limits.names)},
        "travel": dict.fromkeys(limits.names, 0.0),
        "extent": dict.fromkeys(limits.names, 0.0),
    }
    return _Edge(empty, empty, empty, empty, report, [])


def _edge_report(
    move: _StopMove, ticks: int, step: float, p: Array, limits: Limits, key: str, sign: float
) -> dict[str, Any]:
    rest = move.rest_position
    return {
        "duration": move.duration,
        "hold": max(0.0, ticks * step - move.duration),
        "samples": ticks,
        key: {name: float(rest[j]) for j, name in enumerate(limits.names)},
        "travel": {name: float(sign * (p[j] - rest[j])) for j, name in enumerate(limits.names)},
        "extent": {name: float(move.max[j] - move.min[j]) for j, name in enumerate(limits.names)},
    }


def _edge_position_check(move: _StopMove, limits: Limits, what: str, frame: int) -> None:
    tol = LIMIT_RTOL * (limits.upper - limits.lower)
    over = np.flatnonzero((move.max > limits.upper + tol) | (move.min < limits.lower - tol))
    if over.size == 0:
        return
    revolute = limits.revolute
    parts = []
    for j in over.tolist():
        beyond_upper = move.max[j] > limits.upper[j]
        value = move.max[j] if beyond_upper else move.min[j]
        bound = limits.upper[j] if beyond_upper else limits.lower[j]
        parts.append(
            f"{limits.names[j]} goes to {_fmt(float(value), 'position', bool(revolute[j]))}, "
            f"beyond its {'upper' if beyond_upper else 'lower'} limit "
            f"{_fmt(float(bound), 'position', bool(revolute[j]))}"
        )
    msg = (
        f"the {what} {'into' if what == 'run-up' else 'from'} frame {frame} "
        f"({move.duration:.2f} s) needs more room: " + "; ".join(parts)
        + "; move the shot away from the limit or slow it down at that end"
    )
    raise TimingLimitError(msg)


def _runup(p: Array, v: Array, a: Array, limits: Limits, step: float, frame: int) -> _Edge:
    """A jerk-limited move from rest into the first frame's state (p, v, a).

    Built as the time reversal of the stop from the reversed state (p, -v, a): that stop ends
    at rest at the start position, and played backwards it starts at rest there and arrives
    exactly (bit for bit) at the first frame's state. Each axis uses its shortest braking
    distance, so this is the least room a run-up can need. Velocity, acceleration and jerk
    limits are symmetric, so the reversed move is inside them. The move starts on a servo
    tick (held at rest before it) so that the first frame lands on a tick.
    """
    if _at_rest(v, a, limits):
        return _empty_edge(p, limits, "start")
    move = _StopMove(p, -v, a, limits)
    _edge_position_check(move, limits, "run-up", frame)
    ticks = max(1, math.ceil(move.duration / step - 1e-9))
    # Sample k (0..ticks-1) is at run-up time k*step - hold; reversed time = duration - that.
    hold = ticks * step - move.duration
    reverse_t = move.duration - (np.arange(ticks, dtype=np.float64) * step - hold)
    reverse_t[0] = max(reverse_t[0], move.duration)  # exactly at rest (hold may be -1e-9 step)
    pos, vel, acc, jerk = move.sample(reverse_t)
    report = _edge_report(move, ticks, step, p, limits, "start", 1.0)
    return _Edge(pos, -vel, acc, -jerk, report, _edge_warnings(report, limits, "run-up"))


def _runout(p: Array, v: Array, a: Array, limits: Limits, step: float, frame: int) -> _Edge:
    """A jerk-limited stop from the last frame's state; the take ends at rest on a tick."""
    if _at_rest(v, a, limits):
        return _empty_edge(p, limits, "end")
    move = _StopMove(p, v, a, limits)
    _edge_position_check(move, limits, "run-out", frame)
    ticks = max(1, math.ceil(move.duration / step - 1e-9))
    times = np.arange(1, ticks + 1, dtype=np.float64) * step
    times[-1] = max(times[-1], move.duration)  # the take ends exactly at rest
    pos, vel, acc, jerk = move.sample(times)
    report = _edge_report(move, ticks, step, p, limits, "end", -1.0)
    return _Edge(pos, vel, acc, jerk, report, _edge_warnings(report, limits, "run-out"))


def _edge_warnings(report: dict[str, Any], limits: Limits, what: str) -> list[str]:
    """A note when a run-up or run-out travels more than a tenth of an axis's range."""
    out = []
    span = limits.upper - limits.lower
    for j, name in enumerate(limits.names):
        ext = float(report["extent"][name])
        if ext > 0.1 * span[j]:
            out.append(
                f"the {what} moves {name} by {_fmt(ext, 'position', bool(limits.revolute[j]))}"
                f" ({ext / span[j]:.0%} of its range) over {report['duration']:.2f} s"
            )
    return out
