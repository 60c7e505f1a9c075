"""The timing stage's entry point: :func:`time_shot`, the :class:`Take` it returns and its
:class:`TimingReport`; ``"shot"`` and ``"scale"`` modes.

Units: SI throughout (m, rad, s).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.choices import TIMING_MODES
from camtraj.robot import JOINT_NAMES
from camtraj.shown import frame_runs, listed, scale_fit
from camtraj.timing.clock import MAX_FRAME_RATE, on_the_clock
from camtraj.timing.edges import (
    EDGE_MODES,
    Edge,
    EdgeProblem,
    edge_limits,
    edge_problem,
    runout,
    runup,
    runup_from,
)
from camtraj.timing.limits import (
    LIMIT_RTOL,
    FrameMap,
    Limits,
    LimitViolation,
    Peaks,
    TimingLimitError,
    fmt,
    peak_use,
    peaks_slowdown,
    shot_error,
    slowest,
    violations,
    violations_in,
)
from camtraj.timing.optimal import optimal
from camtraj.timing.path import AT_REST, FREE, HOLD_TOL, SETTLED, FramePath, Samples, runs

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Film frame times may deviate from a uniform grid by this fraction of the frame interval.
UNIFORM_RTOL = 1e-6
#: ``"scale"`` slows a move by at most this factor; a move whose run-up or run-out still has
#: no room then has an axis at its limit moving into it (only another IK answer helps).
MAX_SCALE = 1000.0
#: The longest take camtraj builds [s]: two hours of samples (1.8 million at 250 Hz, about
#: 0.7 GB while the take is made). A longer one is a limit typed in the wrong unit, not a
#: shot: a track velocity of 1e-9 m/s asked for 151 h and was killed for its memory.
MAX_TAKE_SECONDS = 7200.0
FACTOR_RTOL = 1e-6  # relative precision of the slow-down the run-up and run-out need


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
            the speed, acceleration with its square, jerk with its cube; the run-up and
            run-out must fit too (their room and speed). ``inf`` if nothing moves, 0 if no
            uniform slow-down fits.
        feasible_fps: The frame rate at which the move could be shot at ``max_speed``
            (``fps * max_speed``) [frames/s], for a later speed change in post.
        set_by: What sets ``max_speed``: an axis's velocity, acceleration or jerk in the
            shot (``"pan acceleration"``), or the run-up or run-out (``"the run-out from
            frame 1120: iris's room to stop inside its limits"``); "" when nothing moves.
        limiting: Every (axis, quantity) the shot's own real-time timing exceeds (what forces
            a slower take), worst first.
        runup: The move from rest into the first frame: ``duration`` [s] of the ruckig move,
            ``hold`` [s] at rest before it (so the first frame lands on a servo tick),
            ``start`` axis -> start position [m or rad], ``travel`` axis -> first-frame
            position minus start position, ``extent`` axis -> max - min position during the
            move (how much track it needs before the first frame), ``peak_use`` axis ->
            quantity -> fraction of the limit used by the move's samples (velocity,
            acceleration, jerk; see ``peak_use``), ``edges`` ``"gentle"`` or ``"fast"``.
        runout: The same for the move from the last frame to rest (``end`` instead of
            ``start``, ``travel`` = end - last-frame position, ``hold`` at rest after it).
        warnings: Things a person should know that do not stop the take.
        fps: Frame rate of the input shot [frames/s].
        ticks_per_frame: Servo samples per film frame in the take (``None`` for an
            ``"optimal"`` retime, where it varies from frame to frame).
    """

    peak_use: dict[str, dict[str, float]]
    position_range: dict[str, tuple[float, float]]
    max_speed: float
    feasible_fps: float
    set_by: str
    limiting: list[LimitViolation]
    runup: dict[str, Any]
    runout: dict[str, Any]
    warnings: list[str]
    fps: float
    ticks_per_frame: int | None


@dataclass(frozen=True, eq=False)
class Take:
    """A timed trajectory from rest to rest, sampled at the servo rate.

    Attributes:
        t: Sample times [s], shape (m,), ``t[0] = 0`` (the take starts at rest): whole
            nanoseconds, the file's stamps; each position is the take's at the time its
            stamp stands for (:mod:`camtraj.timing.clock`: the stamp itself, give or take
            the nanosecond a frame's stamp rounds off, eased between frames).
        q: Positions [m, rad], shape (m, k).
        qd: Velocities [m/s, rad/s], shape (m, k).
        qdd: Accelerations [m/s², rad/s²], shape (m, k).
        qddd: Jerks [m/s³, rad/s³], shape (m, k). Exact values for the spline and ruckig
            parts (in an ``"optimal"`` retime, of the path under its time law).
        frame_times: Time of each film frame in the take [s], shape (n,) (after run-up, after
            any retime); ``t[frame_samples] == frame_times`` exactly.
        frame_samples: Index into ``t`` of each film frame, shape (n,).
        frame_numbers: Film frame number of each frame, shape (n,).
        mode: ``"shot"``, ``"scale"`` or ``"optimal"``.
        speed_factor: Duration of the shot part in the take / original shot duration (1.0 for
            ``"shot"``; above 1 means slowed down, below 1 sped up).
        rate: Effective servo rate [Hz]: ``1 / step``. In ``"shot"`` and ``"scale"`` modes the
            grid is uniform and the rate is an integer multiple of the take's frame rate,
            nearest to the requested rate; in an ``"optimal"`` retime each frame interval is
            cut into equal steps no longer than ``1 / requested rate`` and this is the lowest
            rate (longest step) used.
        uniform: Whether the take was planned on a uniform grid, every step the same to the
            nanosecond (not in an ``"optimal"`` retime; an ``"optimal"`` take that could not
            beat ``"scale"`` is the scale take).
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

    @property
    def servo_steps_ms(self) -> tuple[float, float]:
        """The shortest and longest step between servo samples [ms], to the nanosecond."""
        steps = np.diff(self.t)
        short, long = (float(steps.min()), float(steps.max())) if steps.size else (0.0, 0.0)
        return round(1e3 * short, 6), round(1e3 * long, 6)



def time_shot(
    q_frames: ArrayLike,
    frame_times: ArrayLike,
    limits: Limits,
    *,
    mode: str = "shot",
    rate: float = 250.0,
    frame_numbers: ArrayLike | None = None,
    start: ArrayLike | None = None,
    hold: ArrayLike | None = None,
    rest: ArrayLike | None = None,
    edges: str = "gentle",
) -> Take:
    """Time a joint path for the robot: from rest, through every film frame, to rest.

    Args:
        q_frames: Joint solution of every film frame [m, rad], shape (n, k), n >= 2, k the
            axes of ``limits`` (the eight joints, then any lens axes).
        frame_times: Time of every film frame in the shot [s], shape (n,), uniformly spaced
            (1/fps apart); only the spacing is used.
        limits: The robot's limits.
        mode: ``"shot"`` keeps the film's timing and raises :class:`TimingLimitError` if a
            limit is exceeded; ``"scale"`` slows the whole move by the smallest uniform factor
            at which the shot and its run-up and run-out fit every limit (position,
            velocity, acceleration and jerk); ``"optimal"`` retimes the path
            time-optimally under velocity, acceleration and jerk limits
            (:mod:`~camtraj.timing.optimal`), keeping still stretches as holds of their
            original duration, or keeps the scale take where that is not slower.
        rate: Requested servo rate [Hz].
        frame_numbers: Film frame number of every frame, shape (n,) (default 0..n-1); used in
            messages and reports.
        start: Joint vector the robot stands at when the take begins [m, rad], shape (k,);
            the run-up moves from it (at rest) into the first frame's state. Default: the
            take begins at rest wherever the shortest run-up into the first frame starts.
        hold: Per frame pair, shape (n - 1,): whether the camera holds still there. A pair
            is a hold (the robot exactly still) where the camera holds and no joint moves
            by more than :data:`~camtraj.timing.path.HOLD_TOL`; default: wherever no joint
            moves.
        rest: Per end and axis, shape (2, k), how the first / last frame rests
            (:meth:`~camtraj.timing.path.FramePath.fit`: free, at rest or settled, or
            booleans: at rest); default: free ends.
        edges: ``"gentle"`` run-up and run-out use per axis no more of the acceleration
            and jerk limits than the shot does (at least a quarter of them); ``"fast"``
            ones the full limits.

    Returns:
        The :class:`Take`.

    Raises:
        ValueError: Bad shapes, non-finite values, non-increasing or non-uniform times, an
            unknown mode or a non-positive rate.
        TimingLimitError: A limit is exceeded (``"shot"`` mode, including a run-up or
            run-out that could not stay under a velocity limit) or a position limit is
            crossed (every mode, including by the run-up or run-out).
    """
    q, dt, frames = _validate(q_frames, frame_times, frame_numbers, mode, rate, limits)
    n = q.shape[0]
    fps = 1.0 / dt
    hold_mask = _validate_hold(hold, n)
    rest_mask = _validate_rest(rest, limits.size)
    if edges not in EDGE_MODES:
        msg = f"edges {edges!r} is not one of {', '.join(EDGE_MODES)}"
        raise ValueError(msg)
    start_q = None if start is None else _validate_start(start, limits.size)
    # the real-time grid is kept only where it is the take's stream
    real, grid = _RealTime.of(q, dt, limits, rate, hold_mask, rest_mask, edges, start_q, frames,
                              keep=mode == "shot")
    # the ends asked for are built wherever they fit the speed the take runs at, else those
    # the maximum feasible speed needs (the full limits)
    ends = tuple(dict.fromkeys((edges, real.edges)))
    edge_note = ""
    if real.edges != edges:
        ratio = real.gentle_need / real.need
        cost = (f"a {ratio:.2f}x slower take" if ratio >= 1.1 else f"a {ratio:.4f}x slower take"
                ) if math.isfinite(ratio) else "more room than the limits leave"
        why = f" ({real.gentle_problem})" if real.gentle_problem else ""
        edge_note = (f"a gentle run-up/run-out would need {cost}{why}: the ends use the "
                     "full acceleration and jerk limits (as --edges fast)")
    path, fit, need, max_speed = real.path, real.fit, real.need, real.max_speed
    ticks0, limiting = real.ticks, real.limiting
    position_bad = [v for v in limiting if v.quantity == "position"]
    if position_bad:
        raise shot_error(limiting if mode == "shot" else position_bad, max_speed, fps)

    def scaled(floor: float = 1.0) -> tuple[float, int, Samples, Array, Edge, Edge]:
        return _scale(path, dt, rate, limits, need, fit, start_q, ends, floor)

    warnings: list[str] = []
    if mode == "shot":
        problem = fit.problem(1.0) if need > 1.0 + LIMIT_RTOL else None
        if limiting or problem is not None:
            raise _shot_mode_error(limiting, problem, max_speed, fps, scaled, set_by=real.set_by())
        assert grid is not None
        shot, shot_x, speed_factor, ticks = grid.stream, grid.x, 1.0, ticks0
        del grid  # its samples before the frames are views of the stream
        shot_rate = ticks0 * fps
        shot_t = np.arange(shot_x.size) / shot_rate
        frame_idx = np.arange(n, dtype=np.int64) * ticks
        try:
            up, out = _build_edges(shot, limits, ends, start_q, 1.0 / shot_rate, frames)
        except TimingLimitError as exc:  # a grid effect at the margin: say what scale does
            raise _shot_mode_error([], None, max_speed, fps, scaled, str(exc),
                                   set_by=real.set_by()) from None
    elif mode == "scale":
        speed_factor, ticks, shot, shot_x, up, out = scaled()
        shot_rate = ticks / (speed_factor * dt)
        shot_t = np.arange(shot_x.size) / shot_rate
        frame_idx = np.arange(n, dtype=np.int64) * ticks
    else:
        # The shortest take of three: the scale take; the whole shot played uniformly at its
        # maximum feasible speed, where that is faster and the shot has no hold to keep (a
        # uniform law shortens holds too); the jerk-limited time-optimal retime. Each is
        # measured whole, run-up and run-out included: a faster shot part can need longer
        # ends. The retime starts and ends no faster than the shorter uniform take, so its
        # run-up and run-out have room too, and are no longer than that take's.
        uniform_takes = [scaled()]
        if need < 1.0 and not path.still.all(axis=1).any():
            # and no more than MAX_FRAME_RATE film frames a second
            uniform_takes.append(scaled(floor=max(1.0 / MAX_SCALE,
                                                  min(1.0, 1.0 / (MAX_FRAME_RATE * dt)))))
        speed_factor, ticks, shot, shot_x, up, out = min(
            uniform_takes, key=lambda take: _uniform_length(take, n, dt))
        del uniform_takes  # their samples, but the take's
        shot_rate = ticks / (speed_factor * dt)
        shot_t = np.arange(shot_x.size) / shot_rate
        frame_idx = np.arange(n, dtype=np.int64) * ticks
        length = _uniform_length((speed_factor, ticks, shot, shot_x, up, out), n, dt)
        # ends at rest but not settled: their acceleration is the path's curvature times the
        # speed squared (a settled end has none at any speed)
        resting = (False, False) if rest_mask is None else (
            bool(rest_mask[0].max() == AT_REST), bool(rest_mask[1].max() == AT_REST))
        retimed = optimal(path, limits, rate, speed_factor, resting)
        if retimed is not None:
            r_up, r_out = _build_edges(retimed[2], limits, ends, start_q, 1.0 / rate, frames)
            if (r_up.q.shape[0] + r_out.q.shape[0]) / rate + retimed[0][-1] >= length:
                retimed = None  # its ends cost more than its shot part saves
        if retimed is None:
            warnings.append(
                "--timing optimal found no jerk-limited timing shorter than a uniform one: "
                f"the take plays the shot uniformly, at {100.0 / speed_factor:.4g}% of real "
                "time")
        else:
            shot_t, shot_x, shot, frame_idx = retimed
            up, out = r_up, r_out
            del retimed
            speed_factor = float(shot_t[-1] / (dt * (n - 1)))
            ticks = 0  # samples per frame vary
            shot_rate = 0.0
            warnings += _stretched_holds(q, hold_mask, shot_t[frame_idx], dt, frames,
                                         limits.names)

    # Position limits of the shot part as sampled in the take.
    pos_bad = [v for v in violations(shot, limits, FrameMap.of(shot_x, frames), LIMIT_RTOL)
               if v.quantity == "position"]
    if pos_bad:
        raise shot_error(pos_bad, max_speed, fps)
    use, position_range = peak_use(shot, limits)

    # Run-up and run-out on a uniform servo grid (step of the shot part in uniform modes).
    step = 1.0 / shot_rate if shot_rate > 0 else 1.0 / rate
    n_up = up.q.shape[0]
    m = n_up + shot.q.shape[0] + out.q.shape[0]
    if ticks == 0:  # an optimal retime: frame intervals of their own lengths
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
        if abs(eff_rate - rate) > RATE_NOTE * rate:
            warnings.append(
                f"servo rate {eff_rate:.4g} Hz, not {rate:.4g} Hz (--rate): every film frame "
                "is a servo tick, so the rate is a whole number of ticks per frame interval")
    # Run-up, shot and run-out joined a quantity at a time, each of the shot's dropped once
    # joined: the shot's samples and the take's are never both whole in memory.
    columns = [shot.q, shot.qd, shot.qdd, shot.qddd]
    del shot
    q_all, qd_all, qdd_all, qddd_all = (
        np.concatenate([getattr(up, f), columns.pop(0), getattr(out, f)])
        for f in ("q", "qd", "qdd", "qddd"))
    frame_samples = (n_up + frame_idx).astype(np.int64)
    t = on_the_clock(t, frame_samples, q_all, qd_all, qdd_all, qddd_all)
    frame_times_take = t[frame_samples]

    if edge_note and up.report["edges"] != edges:  # the take's own ends are the fast ones
        warnings.insert(0, edge_note)
    report = TimingReport(
        peak_use=use,
        position_range=position_range,
        max_speed=max_speed,
        feasible_fps=fps * max_speed,
        set_by=real.set_by(),
        limiting=limiting,
        runup=up.report,
        runout=out.report,
        warnings=warnings + up.warnings + out.warnings,
        fps=fps,
        ticks_per_frame=ticks or None,
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


@dataclass(frozen=True, eq=False)
class _RealTime:
    """What the shot at its own timing, sampled at the servo rate, tells: the limits it
    exceeds and the slow-down it needs (no servo-rate arrays)."""

    path: FramePath
    ticks: int
    limiting: list[LimitViolation]
    fit: _EdgeFit
    shot_need: float
    need: float
    max_speed: float
    edges: str
    gentle_need: float
    gentle_problem: str  # why gentle ends do not fit the take's speed ("" when they do)
    peaks: Peaks  # the shot's own, at real time
    precision: float

    @classmethod
    def of(cls, q: Array, dt: float, limits: Limits, rate: float, hold: BoolArray | None,
           rest: NDArray[np.int8] | None, edges: str, start: Array | None, frames: IntArray,
           precision: float = FACTOR_RTOL, *,
           keep: bool = False) -> tuple[_RealTime, _Grid | None]:
        """The check, and with ``keep`` its servo grid (else dropped here)."""
        path = FramePath.fit(q, dt, limits.lower, limits.upper, hold, rest)
        ticks = max(1, round(rate * dt))
        grid = _Grid.of(path, ticks, 1.0 / dt)
        fit = _EdgeFit.of(grid.stream, limits, edges, start, frames)
        # The smallest uniform slow-down at which the shot and its run-up and run-out fit.
        peaks = grid.peaks()
        shot_need = peaks_slowdown(peaks, limits)
        limiting = grid.violations(limits, frames)
        need = gentle_need = fit.factor(shot_need, precision)
        gentle_problem = ""
        if edges == "gentle" and need > shot_need * (1.0 + LIMIT_RTOL):
            # Gentle ends are worth a little speed, not a take that cannot run at real
            # time: beyond that the ends use the full limits (:func:`ends_to_use`).
            fast = _EdgeFit.of(grid.stream, limits, "fast", start, frames)
            fast_need = fast.factor(shot_need, precision)
            if ends_to_use(need, fast_need) == "fast":
                problem = fit.problem(fast_need)  # the gentle ends at the take's speed
                gentle_problem = problem.text if problem is not None else ""
                fit, need, edges = fast, fast_need, "fast"
        max_speed = (1.0 / need if need > 0 else math.inf) if math.isfinite(need) else 0.0
        return (cls(path, ticks, limiting, fit, shot_need, need, max_speed, edges, gentle_need,
                    gentle_problem, peaks, precision), grid if keep else None)

    def set_by(self) -> str:
        """What sets the maximum feasible speed, for people: the run-up or run-out (its
        room or speed, where the ends need a slower take than the shot) or the shot's
        axis and quantity that needs the slowest take ("" when nothing moves or no speed
        fits)."""
        if not (math.isfinite(self.need) and self.need > 0.0):
            return ""
        if self.need > self.shot_need * (1.0 + 4.0 * self.precision):
            problem = self.fit.problem(self.need / (1.0 + 2.0 * self.precision))
            if problem is not None:
                name = self.fit.limits.names[problem.axis]
                where = "the run-up into" if problem.side == "run-up" else "the run-out from"
                act = "start" if problem.side == "run-up" else "stop"
                need = {"position": f"{name}'s room to {act} inside its limits",
                        "velocity": f"{name}'s velocity limit"}.get(problem.kind)
                return f"{where} frame {problem.frame}: {need}" if need else problem.text
        _, axis, quantity = slowest(self.peaks, self.fit.limits)
        return f"{self.fit.limits.names[axis]} {quantity}"


RATE_NOTE = 0.05
"""A servo rate this far (relative) from the one asked is said (250 -> 240 Hz at 24 fps is
not)."""

GENTLE_COST = 0.01
"""The share of the take's speed gentle run-ups and run-outs may cost before the ends use
the full limits instead."""


def ends_to_use(gentle_need: float, fast_need: float) -> str:
    """``"gentle"`` or ``"fast"`` ends, from the slow-downs the take needs with each: fast
    where gentle ends would stop a take that fast ends let run at real time, or would cost
    more than :data:`GENTLE_COST` of its speed; gentle otherwise (a rig that settles into
    and out of the move is worth a hundredth of a take's speed)."""
    if not math.isfinite(gentle_need):
        return "fast" if math.isfinite(fast_need) else "gentle"
    if fast_need <= 1.0 + LIMIT_RTOL < gentle_need:
        return "fast"
    return "fast" if fast_need < gentle_need * (1.0 - GENTLE_COST) else "gentle"


def feasible_speed(q_frames: ArrayLike, frame_times: ArrayLike, limits: Limits, *,
                   rate: float = 250.0, hold: ArrayLike | None = None,
                   rest: ArrayLike | None = None, edges: str = "gentle",
                   precision: float | None = None) -> float:
    """The maximum feasible speed :func:`time_shot` reports for a joint path (its
    ``TimingReport.max_speed``, the same computation), without timing a take: 0 where a
    position limit is crossed at the shot's own timing (no speed fixes that) or no slower
    take fits the run-up and run-out; inf where nothing moves.

    ``precision``: relative precision of the slow-down the run-up and run-out need (default
    :data:`FACTOR_RTOL`, what ``time_shot`` uses); a coarser one costs less and never reports
    a faster speed than the exact one."""
    q, dt, frames = _validate(q_frames, frame_times, None, "shot", rate, limits)
    rt, _ = _RealTime.of(q, dt, limits, rate, _validate_hold(hold, q.shape[0]),
                         _validate_rest(rest, limits.size), edges, None, frames,
                         FACTOR_RTOL if precision is None else precision)
    if any(v.quantity == "position" for v in rt.limiting):
        return 0.0
    return rt.max_speed


def _validate(
    q_frames: ArrayLike,
    frame_times: ArrayLike,
    frame_numbers: ArrayLike | None,
    mode: str,
    rate: float,
    limits: Limits,
) -> tuple[Array, float, IntArray]:
    q = np.array(q_frames, dtype=np.float64)
    times = np.array(frame_times, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != limits.size:
        msg = f"q_frames must have shape (n, {limits.size}) to match the limits, got {q.shape}"
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
    if mode not in TIMING_MODES:
        msg = f"timing mode {mode!r} is not one of {', '.join(TIMING_MODES)}"
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




@dataclass(frozen=True, eq=False)
class _Grid:
    """The path at constant speed on a servo grid: the stream, and the samples the limit
    checks see besides: the jerk just before every frame (it may step at a frame next to a
    hold or a knot kept inside the position range). Checked in two parts, never joined."""

    x: Array
    stream: Samples
    before_x: Array
    before: Samples  # frames 1..n-1; positions to accelerations are views of the stream's

    @classmethod
    def of(cls, path: FramePath, ticks: int, speed: float) -> _Grid:
        """At ``speed`` [frames/s] on ``ticks`` steps per frame."""
        x, stream = path.timed_grid(ticks, speed)
        k = slice(ticks, None, ticks)  # frames 1..n-1
        before = Samples(stream.q[k], stream.qd[k], stream.qdd[k],
                         path.knot_jerk_from_left() * speed**3)
        return cls(x, stream, x[k] - 0.5 / ticks, before)

    def peaks(self) -> Peaks:
        return Peaks.join([Peaks.of(self.stream), Peaks.of(self.before)])

    def violations(self, limits: Limits, frames: IntArray) -> list[LimitViolation]:
        return violations_in([(self.stream, FrameMap.of(self.x, frames)),
                              (self.before, FrameMap.of(self.before_x, frames))],
                             limits, LIMIT_RTOL)


HOLD_LENGTH_RTOL = 0.01
"""A camera hold whose length an optimal retime changes by more than this share is said."""


def _stretched_holds(q: Array, hold: BoolArray | None, frame_times: Array, dt: float,
                     frames: IntArray, names: tuple[str, ...]) -> list[str]:
    """The camera holds an optimal retime plays at another length than the shot's: where
    the camera holds still but an axis moves (a lens motor's focus pull, say), the hold is no
    hold of the take, and its length follows that axis's limits."""
    if hold is None:
        return []
    out = []
    for a, b in runs(hold):
        was, now = (b - a) * dt, float(frame_times[b] - frame_times[a])
        if abs(now - was) <= HOLD_LENGTH_RTOL * was:
            continue
        moving = [names[j] for j in np.flatnonzero(np.ptp(q[a:b + 1], axis=0) > HOLD_TOL)]
        who = (f"{listed(moving)} {'moves' if len(moving) == 1 else 'move'}" if moving
               else "an axis moves")
        out.append(
            f"{frame_runs([(int(frames[a]), int(frames[b]))])}: the camera holds still but "
            f"{who}, so the retime plays the hold in "
            f"{now:.2f} s, not {was:.2f} s")
    return out


def _validate_hold(hold: ArrayLike | None, n: int) -> BoolArray | None:
    if hold is None:
        return None
    mask = np.asarray(hold)
    if mask.shape != (n - 1,) or mask.dtype != np.bool_:
        msg = f"hold must be {n - 1} booleans (one per frame pair), got {mask.shape} {mask.dtype}"
        raise ValueError(msg)
    return mask


def _validate_rest(rest: ArrayLike | None, axes: int) -> NDArray[np.int8] | None:
    """``rest`` as levels (2, axes) (:data:`~camtraj.timing.path.FREE`, ``AT_REST``,
    ``SETTLED``; booleans: free or at rest)."""
    if rest is None:
        return None
    mask = np.asarray(rest)
    if (mask.shape != (2, axes) or mask.dtype.kind not in "biu"
            or not np.all((mask >= FREE) & (mask <= SETTLED))):
        msg = (f"rest must be 2 x {axes} rest levels 0-2 or booleans (per end and axis), got "
               f"{mask.shape} {mask.dtype}")
        raise ValueError(msg)
    return mask.astype(np.int8)


def _validate_start(start: ArrayLike, axes: int) -> Array:
    arr = np.array(start, dtype=np.float64)
    if arr.shape != (axes,) or not np.all(np.isfinite(arr)):
        msg = f"start must be {axes} finite axis values, got {arr.tolist()}"
        raise ValueError(msg)
    return arr


@dataclass(frozen=True, eq=False)
class _EdgeFit:
    """Whether the run-up and run-out fit when the shot is slowed uniformly by a factor s.

    The boundary states scale as (q, qd / s, qdd / s²) and the shot's peak acceleration and
    jerk (which bound gentle edges) as 1 / s², 1 / s³; the edges are planned by ruckig at
    each factor tried (nothing is sampled).
    """

    ends: tuple[tuple[Array, Array, Array], tuple[Array, Array, Array]]  # real-time states
    peak_acc: Array  # the real-time shot's peak |acceleration| per axis
    peak_jerk: Array
    limits: Limits
    edges: str
    start: Array | None
    frames: tuple[int, int]

    @classmethod
    def of(cls, rt: Samples, limits: Limits, edges: str, start: Array | None,
           frames: IntArray) -> _EdgeFit:
        # copies: a view would keep the whole stream alive
        ends = ((rt.q[0].copy(), rt.qd[0].copy(), rt.qdd[0].copy()),
                (rt.q[-1].copy(), rt.qd[-1].copy(), rt.qdd[-1].copy()))
        peaks = Peaks.of(rt)
        return cls(ends, peaks.qdd, peaks.qddd, limits, edges, start,
                   (int(frames[0]), int(frames[-1])))

    def problem(self, s: float) -> EdgeProblem | None:
        """What does not fit at slow-down ``s`` (None: both edges fit)."""
        (p0, v0, a0), (p1, v1, a1) = self.ends
        first = (p0, v0 / s, a0 / s**2)
        last = (p1, v1 / s, a1 / s**2)
        lim = edge_limits(self.limits, self.peak_acc / s**2, self.peak_jerk / s**3, self.edges)
        return edge_problem(first, last, lim, self.frames, self.start)

    def factor(self, low: float, precision: float = FACTOR_RTOL) -> float:
        """The smallest slow-down >= ``low`` at which both edges fit (``low`` itself when
        they do; inf when they do not even :data:`MAX_SCALE` times slower than real time),
        found to within ``precision`` (relative) above it.

        Bracketed by doubling, then bisected (the room an edge needs never grows as the
        move slows: its states and gentle limits scale together until the floor holds the
        limits, then its stopping distance shrinks)."""
        if low <= 0.0:
            return low  # nothing moves: the take is a hold
        if self.problem(low) is None:
            return low
        lo, hi = low, 2.0 * low
        while self.problem(hi) is not None:
            if hi >= MAX_SCALE:
                return math.inf
            lo, hi = hi, min(2.0 * hi, MAX_SCALE)
        while hi / lo - 1.0 > precision:
            mid = math.sqrt(lo * hi)
            if self.problem(mid) is None:
                hi = mid
            else:
                lo = mid
        return hi

    def no_room(self) -> str:
        """Why no slower take fits: the edge still short of room at :data:`MAX_SCALE`."""
        problem = self.problem(MAX_SCALE)
        if problem is None or problem.kind != "position":  # pragma: no cover - defensive
            return f"no take up to {MAX_SCALE:g}x slower fits its run-up and run-out"
        j = problem.axis
        (p0, v0, _), (p1, v1, _) = self.ends
        lim = self.limits
        pos, vel = (p0[j], -v0[j]) if problem.side == "run-up" else (p1[j], v1[j])
        bound, side = (lim.upper[j], "upper") if vel > 0 else (lim.lower[j], "lower")
        rev = bool(lim.revolute[j])
        what = ("the run-up into" if problem.side == "run-up" else "the run-out from")
        ease = "in from rest" if problem.side == "run-up" else "out to rest"
        fix = (f"ease the {lim.names[j]} move {ease} there, or set the motor's limit past "
               "it in the lens file" if lim.names[j] not in JOINT_NAMES else
               f"ease the camera move {ease} there, or place the track so that "
               f"{lim.names[j]} is off its limit (camtraj place)")
        return (
            f"{what} frame {problem.frame} has no room even {MAX_SCALE:g}x slower: "
            f"{lim.names[j]} is {fmt(float(abs(bound - pos)), 'position', rev)} from its "
            f"{side} limit {fmt(float(bound), 'position', rev)} and "
            f"{'arrives from' if problem.side == 'run-up' else 'moves towards'} it there; "
            f"{fix}"
        )


def _edge_use(edge: Edge, limits: Limits) -> dict[str, dict[str, float]]:
    """Peak use of the velocity, acceleration and jerk limits by a run-up or run-out."""
    out: dict[str, dict[str, float]] = {}
    for j, name in enumerate(limits.names):
        out[name] = {
            quantity: float(np.max(np.abs(values[:, j]), initial=0.0) / bound[j])
            for quantity, values, bound in (("velocity", edge.qd, limits.velocity),
                                            ("acceleration", edge.qdd, limits.acceleration),
                                            ("jerk", edge.qddd, limits.jerk))
        }
    return out


def _build_edges(shot: Samples, limits: Limits, edges: tuple[str, ...], start: Array | None,
                 step: float, frames: IntArray) -> tuple[Edge, Edge]:
    """The run-up into the shot's first sample and the run-out from its last, on a servo
    grid of ``step``, with the first of ``edges`` (``"gentle"``: within the shot's own peak
    acceleration and jerk; ``"fast"``: the full limits) whose velocity and room fit the take
    as it is timed: the maximum feasible speed may need the full limits while the take,
    running slower, has room to settle gently. The last is built whatever the check says
    (it raises where it does not fit)."""
    peaks = Peaks.of(shot)
    first, last = (shot.q[0], shot.qd[0], shot.qdd[0]), (shot.q[-1], shot.qd[-1], shot.qdd[-1])
    span = (int(frames[0]), int(frames[-1]))
    for k, mode in enumerate(edges):
        lim = edge_limits(limits, peaks.qdd, peaks.qddd, mode)
        final = k == len(edges) - 1
        if not final and edge_problem(first, last, lim, span, start) is not None:
            continue
        try:
            if start is None:
                up = runup(*first, lim, step, span[0])
            else:
                up = runup_from(start, *first, lim, step, span[0])
            out = runout(*last, lim, step, span[1])
        except TimingLimitError:
            if final:
                raise
            continue
        for edge in (up, out):
            edge.report["peak_use"] = _edge_use(edge, limits)
            edge.report["edges"] = mode
        return up, out
    msg = "internal error: no edges to build"  # pragma: no cover - edges is never empty
    raise RuntimeError(msg)  # pragma: no cover


def _shot_mode_error(
    limiting: list[LimitViolation], problem: EdgeProblem | None, max_speed: float, fps: float,
    scaled: Callable[[], tuple[float, int, Samples, Array, Edge, Edge]], text: str = "",
    set_by: str = "",
) -> TimingLimitError:
    """Why the shot's own timing does not fit, and what ``--timing scale`` does about it
    (it is run to find out: the advice is only given when scale succeeds, with the speed
    the scale take runs at: :func:`scale_fit`)."""
    try:
        factor = scaled()[0]
    except TimingLimitError as exc:
        advice, factor = f"--timing scale does not fit it either: {exc}", math.inf
    else:
        advice = f"the move {scale_fit(factor, fps)} - try --timing scale"
    parts = [v.describe() for v in limiting[:4]]
    if len(limiting) > 4:
        parts.append(f"and {len(limiting) - 4} more")
    if problem is not None:
        parts.append(problem.text)
    if text:
        parts.append(text)
    return TimingLimitError("; ".join([*parts, advice]), violations=limiting,
                            max_speed=max_speed, feasible_fps=fps * max_speed,
                            scale_factor=factor, room=problem.text if problem else "",
                            set_by=set_by)


def _uniform_length(take: tuple[float, int, Samples, Array, Edge, Edge], n: int,
                    dt: float) -> float:
    """The whole length [s] of a uniform take (:func:`_scale`'s answer) of n frames, run-up
    and run-out included: every sample a step of ``factor dt / ticks`` apart."""
    factor, ticks, _shot, _x, up, out = take
    return float((up.q.shape[0] + out.q.shape[0]) * factor * dt / ticks + (n - 1) * factor * dt)


def _too_slow(factor: float, n: int, dt: float) -> TimingLimitError:
    """The error for a move whose uniform take would last longer than
    :data:`MAX_TAKE_SECONDS`: hours of samples that would fill the memory (a velocity limit
    typed a thousand times too small, say)."""
    hours = factor * max(n - 1, 1) * dt / 3600.0
    msg = (f"the move fits only {factor:.3g} times slower than real time: a take of "
           f"{hours:.3g} h, longer than the {MAX_TAKE_SECONDS / 3600.0:g} h camtraj builds; "
           f"check the robot's velocity, acceleration and jerk limits")
    return TimingLimitError(msg, max_speed=1.0 / factor, feasible_fps=1.0 / (factor * dt),
                            scale_factor=math.inf)


def _scale(
    path: FramePath, dt: float, rate: float, limits: Limits, factor: float, fit: _EdgeFit,
    start: Array | None, ends: tuple[str, ...], floor: float = 1.0,
) -> tuple[float, int, Samples, Array, Edge, Edge]:
    """Slow the move uniformly by the smallest factor >= ``floor`` (1: never faster than
    the shot) at which the shot and its run-up and run-out fit; resampled, and the edges
    built and checked at that factor.

    ``factor`` is where the real-time check and the edge planning say everything fits. The
    take's grid has other sample points (ticks per frame change with the factor), so the
    factor is raised if a resampled sample still exceeds a limit or an edge built from the
    resampled stream (whose peaks bound gentle edges) still lacks room. ``ends``: the kinds
    of run-up and run-out to build, in order of preference (:func:`_build_edges`).
    """
    if not math.isfinite(factor):
        msg = fit.no_room()
        raise TimingLimitError(msg, max_speed=0.0, feasible_fps=0.0, scale_factor=math.inf)
    s = max(floor, factor)
    frames = np.array(fit.frames, dtype=np.int64)
    for _ in range(40):
        if s * max(path.n - 1, 1) * dt > MAX_TAKE_SECONDS:  # before a grid of its samples
            raise _too_slow(s, path.n, dt)
        ticks = max(1, round(rate * s * dt))
        grid = _Grid.of(path, ticks, 1.0 / (s * dt))
        k = peaks_slowdown(grid.peaks(), limits)
        if k > 1.0 + LIMIT_RTOL:
            s *= k * (1.0 + 1e-12)
            del grid  # before the next one is made
            continue
        try:
            up, out = _build_edges(grid.stream, limits, ends, start, s * dt / ticks, frames)
        except TimingLimitError as exc:
            if s >= MAX_SCALE:
                raise TimingLimitError(fit.no_room(), max_speed=0.0, feasible_fps=0.0,
                                       scale_factor=math.inf) from exc
            s = min(MAX_SCALE, s * 1.001)
            del grid
            continue
        return s, ticks, grid.stream, grid.x, up, out
    msg = "internal error: the scale factor did not settle"  # pragma: no cover
    raise RuntimeError(msg)  # pragma: no cover
