"""``"optimal"`` timing: the fastest traversal of the same path under velocity, acceleration
and jerk limits.

The time law is a function of the frame coordinate ``x`` (frame ``i`` at ``x = i``, see
:mod:`~camtraj.timing.path`): ``u(x) = xd**2 / 2``, half the squared path speed [frames²/s²].
With the path's x-derivatives ``p1, p2, p3`` of every axis,

* velocity ``qd = p1 v`` with ``v = sqrt(2 u)``,
* acceleration ``qdd = 2 p2 u + p1 u'`` (``xdd = u'``),
* jerk ``qddd = v (2 p3 u + 3 p2 u' + p1 u'')`` (``xddd = v u''``).

Velocity and acceleration limits are linear in ``u`` (the phase-plane formulation toppra
uses); the jerk limit ``|2 p3 u + 3 p2 u' + p1 u''| <= J / sqrt(2 u)`` is not, but its right
side is convex in ``u``, so its tangent at a guess ``u0`` lies below it everywhere. With the
tangent the limit becomes linear and conservative: every ``u`` that meets it meets the true
limit. ``u`` is a uniform cubic B-spline in ``x`` (:data:`KNOTS_PER_FRAME` segments per frame
interval: acceleration and jerk are then continuous in time), the limits are imposed at
:data:`POINTS_PER_FRAME` points per frame interval (and on both sides of every frame, where
the path's jerk may step), and the traversal time is minimised by a sequence of linear
programs (scipy's HiGHS), each linearised at the previous answer (sequential convex
programming after Debrouwere et al., "Time-optimal path following for robots with trajectory
jerk constraints using sequential convex programming", ICRA 2013). Every answer is feasible
for the next program, so the time never grows; it stops when the time changes by less than
:data:`SCP_RTOL`. Long stretches are solved in overlapping windows (:func:`_solve_stretch`).

The answer is then checked between the points, by its analytic values on a grid
:data:`CHECK_PER_FRAME` times finer (refined around the peaks). Where it is over a limit by
more than :data:`REPAIR_ABOVE`, those places become points of the programs and they are
solved again; the small excess left is removed by playing the whole time law uniformly slower
by just enough (velocity scales with the slow-down, jerk with its cube). The servo samples
are checked once more, by their analytic values and by divided differences of the sampled
positions. If the answer is not shorter than the uniform take it must beat (the
``"scale"`` take, or the whole shot at its maximum feasible speed), :func:`optimal` returns
None and the caller keeps that one (with an end at rest the caller decides on the whole
takes: the uniform take's run-up from such an end is the long part).

Stretches where no axis moves are kept as holds of their original duration. The path is
still at the two ends of a hold (every axis is clamped to the hold's line with zero
acceleration there), so the speed along the path may change at the hold without any axis
noticing. A stretch that starts or ends the shot does so no faster than the uniform take
whose run-up and run-out fit (``u`` at most its, ``u' = u'' = 0``), so the run-up and
run-out have room; at an end where the path is at rest, at :data:`REST_PACE` of the film's
pace (the frame's acceleration is then next to nothing for the run-up to build). Units:
SI (m, rad, s); x in frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.timing.clock import MAX_FRAME_RATE
from camtraj.timing.limits import LIMIT_RTOL, Limits, slowdown
from camtraj.timing.path import FramePath, Samples, runs

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: The share of each jerk limit the time law leaves for the file's clock
#: (:mod:`camtraj.timing.clock`): its frames' times are no whole nanoseconds, the file's
#: stamps are, and the clock eases that sub-nanosecond offset between frames. Over a frame
#: interval of duration D the easing adds up to about 60 v (1 ns) / D^3 of jerk at velocity
#: v, most where the take is fastest: 0.1% of the limit on the dolly sample's optimal take
#: (three servo steps per frame), under 1% wherever a frame interval holds three or more
#: 4 ms steps. Costs a take bound by jerk alone 0.3% of its speed (the samples' optimal
#: takes 0.03-0.09% of their duration).
CLOCK_HEADROOM = 0.01

#: Cubic B-spline segments of ``u(x)`` per frame interval.
KNOTS_PER_FRAME = 2
#: Points per frame interval where the linear programs impose the limits.
POINTS_PER_FRAME = 6
#: Points per frame interval of the check between the programs' points, and how much finer
#: it looks around the worst of them.
CHECK_PER_FRAME = 48
REFINE = 16
#: Points the check evaluates at once (about 1.5 KB of temporaries each).
NEED_BLOCK = 8192
#: The check's slow-down is raised by this fraction (what the fine grid can miss).
CHECK_RTOL = 1e-5
#: Stop the sequential programs when the time improves by less than this fraction.
SCP_RTOL = 1e-4
#: At most this many linear programs per moving stretch.
SCP_ROUNDS = 40
#: A program starts with the rows the previous answer uses at least this fraction of;
#: rows its answer breaks are added and it is solved again, at most ROW_ROUNDS times.
ACTIVE_USE = 0.2
ROW_ROUNDS = 20
#: With the rows an answer breaks, those it nearly meets (this fraction) are added too.
NEAR_ACTIVE = 0.98
#: ... and every row of the frame intervals within this many of a broken row's. The next
#: answer lifts u just past the rows it has, so rows added one by one came back a few
#: hundred a round (a 6 s pan at 59.94 fps: 8 programs per linearisation, 137 in all).
ROW_SPREAD = 3
#: Once a program has more than this share of the rows it takes them all: a time-optimal
#: law rides some limit nearly everywhere, and one more program costs more than the rows.
ALL_ROWS_ABOVE = 0.5
#: The path speed stays between these multiples of the scale take's speed.
SPEED_RANGE = (1e-2, 1e3)
#: At an end of the shot where the path is at rest, the retime's path speed there as a share
#: of the film's own: the frame's acceleration is then its square (1%) of the shot's there (the
#: path's velocity is zero, its acceleration is the path's curvature times the speed
#: squared), and the run-up has next to nothing to build. Played at the uniform take's
#: speed, a cosine-eased slide at 5.2x real time got 27x its authored acceleration on its
#: first frame, and the run-up swung the camera 15 cm. (Never faster than the uniform take,
#: and no slower than the programs' least speed, :data:`SPEED_RANGE`.)
REST_PACE = 0.1

#: The programs' rows are relaxed by this fraction, so that an answer that meets them within
#: the solver's tolerance meets them when its state starts the next window (the check after
#: the programs removes what that and the points' spacing let through).
LP_SLACK = 1e-6
#: Where the answer is over a limit between the programs' points by more than this (as a
#: slow-down), those places are added to the programs, at most REPAIRS times.
REPAIR_ABOVE = 1e-2
REPAIRS = 2
#: The share of the acceleration and jerk limits the windows' ends assume for slowing down
#: to the shot's end (:func:`_braking`).
BRAKING_SHARE = 0.5
#: Long stretches are solved in windows of this many frames, each looking this many
#: frames further ahead.
WINDOW = 48
LOOKAHEAD = 48
#: Divided differences of the sampled positions may exceed a limit by this fraction (they
#: are means of the exact derivatives; this is float round-off only).
DIFFERENCE_RTOL = 1e-6
#: Gauss-Legendre nodes per spline segment for the time integral dt = dx / sqrt(2 u).
_GAUSS = 16
_NEWTON = 30


@dataclass(frozen=True, eq=False)
class _TimeLaw:
    """``u(x)`` on one moving stretch of frames a..b: a uniform cubic B-spline."""

    a: int
    b: int
    coef: Array  # (b - a) * KNOTS_PER_FRAME + 3 control values [frames²/s²]

    def derivs(self, x: Array) -> tuple[Array, Array, Array]:
        """``u``, ``u'``, ``u''`` at frame coordinates x inside [a, b]."""
        idx, basis = _basis(x, self.a, self.b)
        c = self.coef[idx[:, None] + np.arange(4)]
        u, u1, u2 = ((c * basis[d]).sum(axis=1) for d in range(3))
        return u, u1, u2

    def slowed(self, factor: float) -> _TimeLaw:
        """The same law played ``factor`` times slower."""
        return _TimeLaw(self.a, self.b, self.coef / factor**2)

    def frame_durations(self) -> Array:
        """Time of every frame interval a..b-1 [s]."""
        x0 = self.a + np.arange((self.b - self.a) * KNOTS_PER_FRAME) / KNOTS_PER_FRAME
        seg = self._integral(x0, np.full(x0.size, 1.0 / KNOTS_PER_FRAME))
        out: Array = seg.reshape(-1, KNOTS_PER_FRAME).sum(axis=1)
        return out

    def _integral(self, x0: Array, length: Array) -> Array:
        """``int dx / sqrt(2 u)`` from x0 over length (inside one segment each) [s]."""
        nodes, weights = np.polynomial.legendre.leggauss(_GAUSS)
        xs = x0[:, None] + 0.5 * length[:, None] * (nodes + 1.0)
        u = self.derivs(xs.ravel())[0].reshape(xs.shape)
        out: Array = 0.5 * length * (weights / np.sqrt(2.0 * u)).sum(axis=1)
        return out

    def invert(self, frame: IntArray, tau: Array) -> Array:
        """Frame coordinate reached ``tau`` seconds after frame ``frame`` (inside the interval)."""
        k = KNOTS_PER_FRAME
        seg_len = 1.0 / k
        starts = self.a + np.arange((self.b - self.a) * k) / k
        seg_t = self._integral(starts, np.full(starts.size, seg_len)).reshape(-1, k)
        before = np.concatenate([np.zeros((seg_t.shape[0], 1)), np.cumsum(seg_t, axis=1)],
                                axis=1)  # time from the frame to each segment start
        rows = frame - self.a
        # Initial guess: linear within the segment.
        seg = np.clip((tau[:, None] >= before[rows, 1:]).sum(axis=1), 0, k - 1)
        frac = (tau - before[rows, seg]) / seg_t[rows, seg]
        x = frame + (seg + np.clip(frac, 0.0, 1.0)) * seg_len
        lo = frame.astype(np.float64)
        hi = lo + 1.0
        for _ in range(_NEWTON):
            s = np.clip(np.floor((x - frame) * k).astype(np.int64), 0, k - 1)
            x0 = frame + s * seg_len
            f = before[rows, s] + self._integral(x0, x - x0) - tau
            lo = np.where(f < 0, x, lo)
            hi = np.where(f > 0, x, hi)
            step = f * np.sqrt(2.0 * self.derivs(x)[0])
            nxt = x - step
            nxt = np.where((nxt < lo) | (nxt > hi), 0.5 * (lo + hi), nxt)  # safeguard
            done = np.abs(step) <= 1e-14
            x = np.where(done, x, nxt)
            if np.all(done):
                break
        out: Array = x
        return out


def _basis(x: Array, a: int, b: int) -> tuple[IntArray, Array]:
    """Segment of each x and the 4 cubic B-spline weights of it and their first two
    x-derivatives, shape (3, m, 4)."""
    k = KNOTS_PER_FRAME
    pos = (x - a) * k
    idx = np.clip(np.floor(pos).astype(np.int64), 0, (b - a) * k - 1)
    t = (pos - idx)[:, None]
    s = 1.0 - t
    b0 = np.concatenate([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1,
                         t**3], axis=1) / 6.0
    b1 = np.concatenate([-(s**2) / 2, 1.5 * t**2 - 2 * t, -1.5 * t**2 + t + 0.5, t**2 / 2],
                        axis=1) * k
    b2 = np.concatenate([s, 3 * t - 2, 1 - 3 * t, t], axis=1) * k * k
    return idx, np.stack([b0, b1, b2])


def optimal(
    path: FramePath, limits: Limits, rate: float, scale_factor: float,
    rest: tuple[bool, bool] = (False, False),
) -> tuple[Array, Array, Samples, IntArray] | None:
    """Fastest traversal of the path under velocity, acceleration and jerk limits.

    Args:
        path: The joint path.
        limits: The robot's limits.
        rate: Requested servo rate [Hz]: every frame interval is cut into the fewest equal
            steps no longer than ``1 / rate``, so every frame is a sample.
        scale_factor: The slow-down of the uniform take the answer must beat (its run-up
            and run-out fit): the shot starts and ends no faster than it.
        rest: Whether the path is at rest, not settled, on its first / last frame (its
            joints' velocity is zero there, their acceleration not; lens axes may move): the
            retime starts (ends) there nearly still, at :data:`REST_PACE` of the film's own
            pace (or the uniform take's, if slower), so it does not give that frame an
            acceleration the run-up would have to build.

    Returns:
        Sample times of the shot part from the first frame [s], the frame coordinate of each
        sample, the samples, and the sample index of every frame; or None when the answer's
        shot part is not shorter than the scale take's (the caller keeps that one; with an
        end at rest the caller compares whole takes, the uniform one's run-up included).
    """
    n = path.n
    dt = path.dt
    limits = replace(limits, jerk=limits.jerk * (1.0 - CLOCK_HEADROOM))
    u_scale = 0.5 / (scale_factor * dt) ** 2
    # u at a shot's end: the uniform take's, or nearly still at an end at rest (never
    # faster than the uniform take's: a take slowed more than tenfold is slower already)
    still_end = min(1.0, max((REST_PACE * scale_factor) ** 2, SPEED_RANGE[0] ** 2))
    caps = (still_end if rest[0] else 1.0, still_end if rest[1] else 1.0)
    still_all = np.all(path.still, axis=1)
    laws = []
    for a, b in runs(~still_all):
        law = _solve_stretch(path, a, b, limits, u_scale, caps)
        if law is None:
            return None
        laws.append(law)

    frame_t = np.zeros(n)
    durations = np.full(n - 1, dt)  # holds keep their duration
    for law in laws:
        durations[law.a : law.b] = law.frame_durations()
    frame_t[1:] = np.cumsum(durations)
    if frame_t[-1] >= scale_factor * dt * (n - 1) and not any(rest):
        return None  # (an end at rest: the uniform take's longer run-up may make up for it)

    # Every frame interval cut into the fewest equal steps no longer than 1 / rate; the
    # last frame is one more sample.
    steps = np.maximum(1, np.ceil(durations * rate - 1e-9)).astype(np.int64)
    counts = np.concatenate([steps, [1]])
    frame_idx = np.concatenate([[0], np.cumsum(counts[:-1])]).astype(np.int64)
    interval = np.repeat(np.arange(n, dtype=np.int64), counts)
    j = np.arange(interval.size) - frame_idx[interval]
    frac = j / counts[interval]
    tau = frac * np.concatenate([durations, [0.0]])[interval]
    t = frame_t[interval] + tau
    x = interval + frac  # exact on frames; holds advance linearly at the original speed
    xd = np.full(t.size, 1.0 / dt)
    xdd = np.zeros(t.size)
    xddd = np.zeros(t.size)
    for law in laws:
        inside = (interval >= law.a) & (interval < law.b)
        sel = inside & (j > 0)
        x[sel] = law.invert(interval[sel], tau[sel])
        sel = inside | ((interval == law.b) & (j == 0))  # and the stretch's last frame
        u, u1, u2 = law.derivs(x[sel])
        xd[sel] = np.sqrt(2.0 * u)
        xdd[sel] = u1
        xddd[sel] = u2 * xd[sel]
    samples = _timed(path, x, xd, xdd, xddd)
    # The samples as written, by their analytic values and by divided differences of the
    # positions (both are implied by the check of the laws; this is the last word).
    if slowdown(samples, limits) > 1.0 + LIMIT_RTOL or not _within_by_differences(
            t, samples.q, limits):  # pragma: no cover - a bug, but never a take over a limit
        return None
    return t, x, samples, frame_idx


def _timed(path: FramePath, x: Array, xd: Array, xdd: Array, xddd: Array,
           p3: Array | None = None) -> Samples:
    """Joint samples of the time law given at each sample by x and its time derivatives."""
    p0, p1, p2, p3_ = path.at(x, 3)
    if p3 is not None:
        p3_ = p3
    v, a, jk = xd[:, None], xdd[:, None], xddd[:, None]
    return Samples(q=p0, qd=p1 * v, qdd=p2 * v**2 + p1 * a,
                   qddd=p3_ * v**3 + 3.0 * p2 * v * a + p1 * jk)


def _solve_stretch(
    path: FramePath, a: int, b: int, limits: Limits, u_scale: float,
    caps: tuple[float, float] = (1.0, 1.0),
) -> _TimeLaw | None:
    """``u(x)`` on frames a..b, window by window, checked and slowed to fit.

    A long stretch is solved in windows of :data:`WINDOW` frames, each looking
    :data:`LOOKAHEAD` frames further: the window's programs run to its look-ahead end, which
    they must reach at a speed that can be kept from there to the stretch's end (a constant
    ``u`` with u' = u'' = 0, no faster than any point beyond allows at constant speed); only
    the first WINDOW frames are kept and the next window starts in their end state. The rest
    of the previous window followed by that constant speed is feasible for the next window,
    so every window has a feasible start and its time never grows.

    Where the check finds a window's answer over a limit between the programs' points by
    more than :data:`REPAIR_ABOVE`, the worst places become points of its programs too and
    the window is solved again (at most :data:`REPAIRS` times). What is left over the whole
    stretch is removed by slowing the whole law uniformly.
    """
    shot_start, shot_end = a == 0, b == path.n - 1
    start_cap, end_cap_shot = caps
    safe = _safe_speeds(path, a, b, limits, u_scale, end=end_cap_shot if shot_end else None)
    k = KNOTS_PER_FRAME
    # a constant start, no faster than the caps of the shot's ends this stretch has
    start = min([float(safe[0])] + [cap for cap, on in ((start_cap, shot_start),
                                                        (end_cap_shot, shot_end)) if on])
    coef = np.full((b - a) * k + 3, start)
    s = a
    while True:
        last = b - s <= WINDOW + LOOKAHEAD
        e = b if last else s + WINDOW + LOOKAHEAD
        end_cap = (end_cap_shot if shot_end else None) if last else float(safe[e - a])
        # From the candidate: what is known so far, then the constant speed it ends in.
        candidate = coef[(s - a) * k : (e - a) * k + 3].copy()
        extra = np.zeros(0)
        window: Array | None = None
        for _repair in range(REPAIRS + 1):
            rows = _Rows.build(path, s, e, limits, u_scale,
                               fixed=None if s == a else candidate[:3],
                               start_cap=start_cap if s == a and shot_start else None,
                               end_cap=end_cap, extra=extra)
            found = _scp(rows, candidate)
            if found is None:
                break
            window = found
            factor, worst_x = _overshoot(path, _TimeLaw(s, e, window * u_scale), limits)
            if not math.isfinite(factor) or factor <= 1.0 + REPAIR_ABOVE or worst_x.size == 0:
                break
            extra = np.union1d(extra, worst_x)
        if window is None:
            return None
        coef[(s - a) * k : (e - a) * k + 3] = window
        if last:
            break
        # what it ends in, no faster than the frames after it allow
        tail = np.arange((e - a) * k + 3, coef.size)
        coef[tail] = np.minimum(window[-1], np.interp(a + (tail - 1.0) / k,
                                                      np.arange(a, b + 1), safe))
        s += WINDOW
    law = _TimeLaw(a, b, coef * u_scale)
    factor, _ = _overshoot(path, law, limits)
    # At the shot's ends no faster than their caps (the programs meet them to their
    # tolerance).
    ends = [(float(x), cap) for x, on, cap in ((a, shot_start, start_cap),
                                               (b, shot_end, end_cap_shot)) if on]
    if ends:
        u_end = law.derivs(np.array([x for x, _ in ends]))[0] / u_scale
        over = max(float(u) / cap for u, (_, cap) in zip(u_end, ends, strict=True))
        factor = max(factor, math.sqrt(over) * (1.0 + 1e-12))
    if not math.isfinite(factor):
        return None
    return law.slowed(factor) if factor > 1.0 else law


def _scp(rows: _Rows, coef: Array) -> Array | None:
    """Sequential linear programs from the feasible control values ``coef``: the fastest
    answer (None if the first program fails)."""
    u0 = np.maximum(rows.basis[0] @ coef, SPEED_RANGE[0] ** 2)
    best: Array | None = None
    best_time = math.inf
    for _round in range(SCP_ROUNDS):
        found = rows.solve(u0, coef)
        if found is None:
            break
        u = np.maximum(rows.basis[0] @ found, SPEED_RANGE[0] ** 2)
        time = float(np.sum(rows.dx / np.sqrt(u[: rows.dx.size])))
        if time >= best_time:
            break
        improved = (best_time - time) / time
        best, best_time, u0, coef = found, time, u, found
        if improved < SCP_RTOL:
            break
    return best


def _safe_speeds(path: FramePath, a: int, b: int, limits: Limits, u_scale: float,
                 end: float | None = None) -> Array:
    """Per frame a..b, the highest constant ``u`` (units of u_scale) that fits every point
    of the programs from that frame to b, (b - a + 1,); with ``end``, also no faster than
    braking to ``u <= end`` at b allows (:func:`_braking`)."""
    xs = a + np.arange((b - a) * POINTS_PER_FRAME + 1) / POINTS_PER_FRAME
    _, p1, p2, p3 = path.at(xs, 3)
    knots = np.arange(a + 1, b + 1)
    p3_left = np.zeros_like(p3)
    p3_left[(knots - a) * POINTS_PER_FRAME] = path.knot_jerk_from_left()[knots - 1]
    with np.errstate(divide="ignore"):
        cap = np.min(np.minimum(np.minimum(
            limits.velocity**2 / (2.0 * p1**2), limits.acceleration / (2.0 * np.abs(p2))),
            0.5 * (limits.jerk / np.maximum(np.abs(p3), np.abs(p3_left))) ** (2.0 / 3.0)),
            axis=1) / u_scale
    cap = np.minimum(np.minimum(cap, _frame_rate_cap(u_scale)), SPEED_RANGE[1] ** 2)
    suffix = np.minimum.accumulate(cap[::-1])[::-1]
    if end is not None:
        suffix = np.minimum(suffix, _braking(p1, p2, p3, limits, u_scale, end))
    out: Array = suffix[::POINTS_PER_FRAME]
    return out


def _frame_rate_cap(u_scale: float) -> float:
    """:data:`MAX_FRAME_RATE` as a cap on ``u`` in units of ``u_scale`` (never below the
    scale take's own speed, 1)."""
    return max(0.5 * MAX_FRAME_RATE**2 / u_scale, 1.0)


def _braking(p1: Array, p2: Array, p3: Array, limits: Limits, u_scale: float,
             end: float) -> Array:
    """Per point (evenly spaced, :data:`POINTS_PER_FRAME` per frame), the highest ``u`` from
    which the path can still slow to ``u <= end`` at the last point: integrated backwards
    with the strongest slowing, ``u' < 0``, that every axis allows at :data:`BRAKING_SHARE`
    of its limits: acceleration ``|2 p2 u + p1 u'| <= A`` and, without ``u''``, jerk
    ``|2 p3 u + 3 p2 u'| <= J / sqrt(2 u)`` (what binds where the path itself eases out:
    p1 small, p2 not). The windows' ends are kept under it, so the last window can reach
    the shot's end slow enough (a new user's push-in sped up to 24x its end's cap two
    windows before the end, and the last window had no answer)."""
    h = 1.0 / POINTS_PER_FRAME
    acc = BRAKING_SHARE * limits.acceleration / u_scale
    jerk = BRAKING_SHARE * limits.jerk / u_scale
    a1, a2, a3 = np.abs(p1), np.abs(p2), np.abs(p3)
    out = np.empty(p1.shape[0])
    out[-1] = end
    top = SPEED_RANGE[1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        for j in range(p1.shape[0] - 2, -1, -1):
            u, i = out[j + 1], j + 1
            # how fast u may fall per unit x at point i, by each axis's acceleration (u' at
            # least (-A - 2 p2 u) / p1 for p1 > 0, mirrored for p1 < 0) and jerk
            by_acc = np.where(a1[i] > 1e-12, (acc + 2.0 * p2[i] * u * np.sign(p1[i])) / a1[i],
                              np.inf)
            room = jerk / math.sqrt(2.0 * u * u_scale) - 2.0 * a3[i] * u
            by_jerk = np.where(a2[i] > 1e-12, np.maximum(room, 0.0) / (3.0 * a2[i]), np.inf)
            fall = float(np.minimum(by_acc, by_jerk).min())
            out[j] = top if not math.isfinite(fall) else min(top, u + h * max(fall, 0.0))
    return out


@dataclass(frozen=True, eq=False)
class _Rows:
    """Every limit at every point of one stretch as rows over the spline's control values
    (``u`` in units of the scale take's), and the linear programs over them.

    Velocity and acceleration rows are ``G c <= 1``; a jerk row's ``G c`` is
    ``+-(2 p3 u + 3 p2 u' + p1 u'') * u_scale / J``, which the tangent turns into
    ``G c * sqrt(2 u0 u_scale) + u / (2 u0) <= 1.5``.
    """

    g: Any  # sparse (rows, ncoef)
    u_rows: Any  # sparse (rows, ncoef): u at each row's point
    point: IntArray  # (rows,) the row's point
    cell: IntArray  # (rows,) the frame interval of the row's point
    jerk: NDArray[np.bool_]  # (rows,) whether a jerk row
    basis: list[Any]  # sparse (points, ncoef): u, u', u'' at the points
    eq: Array | None  # the end conditions (u' = u'' = 0, or fixed values), (k, ncoef)
    eq_rhs: Array  # (k,)
    end: Array | None  # u <= cap at the ends, as u / cap <= 1, (k, ncoef)
    dx: Array  # quadrature weights of the first (regular) points
    u_scale: float

    @property
    def points(self) -> int:
        return int(self.basis[0].shape[0])

    @property
    def ncoef(self) -> int:
        return int(self.basis[0].shape[1])

    @classmethod
    def build(cls, path: FramePath, a: int, b: int, limits: Limits, u_scale: float, *,
              fixed: Array | None, start_cap: float | None, end_cap: float | None,
              extra: Array) -> _Rows:
        """The rows on frames a..b. At a: the first three control values ``fixed``, or
        ``u <= start_cap`` with u' = u'' = 0, or free (both None); at b: ``u <= end_cap``
        with u' = u'' = 0, or free (None). ``extra``: more points (inside [a, b])."""
        from scipy.sparse import csr_matrix, vstack

        ncoef = (b - a) * KNOTS_PER_FRAME + 3
        # POINTS_PER_FRAME points per interval, and every frame after the first once more
        # with the path's jerk from the piece before it (it may step there).
        xs = a + np.arange((b - a) * POINTS_PER_FRAME + 1) / POINTS_PER_FRAME
        knots = np.arange(a + 1, b + 1)
        pts = np.concatenate([xs, knots.astype(np.float64), extra])
        _, p1, p2, p3 = path.at(pts, 3)
        p3[xs.size : xs.size + knots.size] = path.knot_jerk_from_left()[knots - 1]
        idx, weights = _basis(pts, a, b)
        m = pts.size
        cols = (idx[:, None] + np.arange(4)).ravel()
        ptr = np.arange(0, 4 * m + 1, 4)
        basis = [csr_matrix((weights[d].ravel(), cols, ptr), shape=(m, ncoef))
                 for d in range(3)]
        blocks, owner, is_jerk = [], [], []

        def add(g: Any, at: IntArray, jerk_row: bool) -> None:
            blocks.append(g)
            owner.append(at)
            is_jerk.append(np.full(at.size, jerk_row))

        # Velocity: u <= V² / (2 p1²) on the tightest axis, and the frames' own rate.
        with np.errstate(divide="ignore"):
            cap = np.minimum(np.min(limits.velocity**2 / (2.0 * p1**2), axis=1) / u_scale,
                             _frame_rate_cap(u_scale))
        at = np.flatnonzero(cap < SPEED_RANGE[1] ** 2)
        add(basis[0][at].multiply(1.0 / cap[at][:, None]), at, False)
        moving = (np.abs(p1) + np.abs(p2) + np.abs(p3)) > 0
        for ax in range(limits.size):
            at = np.flatnonzero(moving[:, ax])
            if at.size == 0:
                continue
            col = [c[at, ax][:, None] for c in (p1, p2, p3)]
            acc = (basis[0][at].multiply(2.0 * col[1]) + basis[1][at].multiply(col[0])) * (
                u_scale / limits.acceleration[ax])
            jerk = (basis[0][at].multiply(2.0 * col[2]) + basis[1][at].multiply(3.0 * col[1])
                    + basis[2][at].multiply(col[0])) * (u_scale / limits.jerk[ax])
            add(acc, at, False)
            add(-acc, at, False)
            add(jerk, at, True)
            add(-jerk, at, True)
        point = np.concatenate(owner)
        eq, end = [], []
        for x_end, cap_end in ((a, start_cap), (b, end_cap)):
            if cap_end is not None:  # u' = u'' = 0, no faster than cap_end
                e_idx, e_w = _basis(np.array([float(x_end)]), a, b)
                row = np.zeros((3, ncoef))
                row[:, e_idx[0] : e_idx[0] + 4] = e_w[:, 0]
                eq += [row[1], row[2]]
                end.append(row[0] / cap_end)
        eq_rhs = [0.0] * len(eq)
        if fixed is not None:  # the previous window's end state
            for i in range(3):
                unit = np.zeros(ncoef)
                unit[i] = 1.0
                eq.append(unit)
                eq_rhs.append(float(fixed[i]))
        dx = np.full(xs.size, 1.0 / POINTS_PER_FRAME)
        dx[[0, -1]] *= 0.5
        return cls(g=vstack(blocks).tocsr(), u_rows=basis[0][point], point=point,
                   cell=np.floor(pts[point]).astype(np.int64),
                   jerk=np.concatenate(is_jerk), basis=basis,
                   eq=np.array(eq) if eq else None, eq_rhs=np.array(eq_rhs),
                   end=np.array(end) if end else None,
                   dx=dx, u_scale=u_scale)

    def _program(self, u0: Array) -> tuple[Any, Array]:
        """The rows linearised at ``u0`` (per point): matrix and right-hand side."""
        from scipy.sparse import diags

        root = np.where(self.jerk, np.sqrt(2.0 * u0[self.point] * self.u_scale), 1.0)
        tangent = np.where(self.jerk, 0.5 / u0[self.point], 0.0)
        mat = diags(root) @ self.g + diags(tangent) @ self.u_rows
        return mat.tocsr(), np.where(self.jerk, 1.5, 1.0) * (1.0 + LP_SLACK)

    def solve(self, u0: Array, coef0: Array) -> Array | None:
        """One linear program linearised at ``u0``; rows are added as they are needed (those
        the previous answer ``coef0`` uses at least :data:`ACTIVE_USE` first)."""
        from scipy.optimize import linprog
        from scipy.sparse import csr_matrix, vstack

        mat, rhs = self._program(u0)
        use = self.g @ coef0
        u_prev = np.maximum(self.u_rows @ coef0, 0.0)
        use = np.where(self.jerk, use * np.sqrt(2.0 * u_prev * self.u_scale), use)
        active = use >= ACTIVE_USE
        n_reg = self.dx.size
        weights = np.zeros(self.points)
        weights[:n_reg] = self.dx * u0[:n_reg] ** -1.5
        cost = -(self.basis[0].T @ weights) / weights.sum()
        if self.end is not None:
            extra_a, extra_b = self.end, np.full(self.end.shape[0], 1.0 + LP_SLACK)
        else:
            extra_a, extra_b = np.zeros((0, self.ncoef)), np.zeros(0)
        for _round in range(ROW_ROUNDS):
            if _round == ROW_ROUNDS - 1:
                active[:] = True
            a_ub = vstack([mat[active], csr_matrix(extra_a)]).tocsr()
            res = linprog(cost, A_ub=a_ub, b_ub=np.concatenate([rhs[active], extra_b]),
                          A_eq=self.eq, b_eq=None if self.eq is None else self.eq_rhs,
                          bounds=(SPEED_RANGE[0] ** 2, SPEED_RANGE[1] ** 2), method="highs")
            if res.status != 0 or res.x is None:
                return None
            coef = np.asarray(res.x, dtype=np.float64)
            value = mat @ coef
            over = (value > rhs) & ~active
            if not np.any(over):
                return coef
            cells = np.unique(self.cell[over])  # and every row within ROW_SPREAD intervals
            near = np.unique((cells[:, None] + np.arange(-ROW_SPREAD, ROW_SPREAD + 1)).ravel())
            active |= over | np.isin(self.cell, near) | (value > NEAR_ACTIVE * rhs)
            if active.mean() > ALL_ROWS_ABOVE:
                active[:] = True
        return None  # pragma: no cover - the last round has every row


def _overshoot(path: FramePath, law: _TimeLaw, limits: Limits) -> tuple[float, Array]:
    """The uniform slow-down that brings the law inside every limit (<= 1: none needed), and
    the places between frames where the law is over a limit (the worst of each peak).

    The need is read on a grid of :data:`CHECK_PER_FRAME` points per frame interval, on both
    sides of every frame (the path's jerk may step there), and around every grid point
    that is a local peak within 1% of the worst on a grid :data:`REFINE` times finer still
    (a peak between points is then missed by ~1e-6 at most, which :data:`CHECK_RTOL`
    covers; the samples are checked again after all).
    """
    a, b = law.a, law.b
    h = 1.0 / CHECK_PER_FRAME
    x: Array = a + np.arange((b - a) * CHECK_PER_FRAME + 1, dtype=np.float64) * h
    need = _need(path, law, limits, x)
    knots = np.arange(a + 1, b + 1)
    knot_x: Array = np.asarray(knots, dtype=np.float64)
    left = _need(path, law, limits, knot_x, p3=path.knot_jerk_from_left()[knots - 1])
    worst = max(float(need.max()), float(left.max()) if knots.size else 0.0)
    peak = need >= 0.99 * worst
    peak[1:] &= need[1:] >= need[:-1]
    peak[:-1] &= need[:-1] >= need[1:]
    near = x[peak]
    fine = np.clip(near[:, None] + np.linspace(-h, h, 2 * REFINE + 1), a, b)
    need_fine = _need(path, law, limits, fine.ravel()).reshape(fine.shape)
    top = np.argmax(need_fine, axis=1)
    top_need = need_fine[np.arange(fine.shape[0]), top]
    worst = max(worst, float(top_need.max()) if top_need.size else 0.0)
    over: Array = fine[np.arange(fine.shape[0]), top][top_need > 1.0]
    return worst * (1.0 + CHECK_RTOL), over


def _need(path: FramePath, law: _TimeLaw, limits: Limits, x: Array,
          p3: Array | None = None) -> Array:
    """Per point, the uniform slow-down the law needs there (inf everywhere if it stops
    anywhere); :data:`NEED_BLOCK` points at a time, so its temporaries stay bounded."""
    out = np.empty(x.size)
    for i in range(0, x.size, NEED_BLOCK):
        part = slice(i, i + NEED_BLOCK)
        need = _need_block(path, law, limits, x[part], None if p3 is None else p3[part])
        if need is None:
            return np.full(x.size, math.inf)
        out[part] = need
    return out


def _need_block(path: FramePath, law: _TimeLaw, limits: Limits, x: Array,
                p3: Array | None) -> Array | None:
    """:func:`_need` of some points; None where the law does not move at one of them."""
    u, u1, u2 = law.derivs(x)
    if np.any(u <= 0.0):
        return None
    v = np.sqrt(2.0 * u)
    s = _timed(path, x, v, u1, u2 * v, p3=p3)
    kv = np.max(np.abs(s.qd) / limits.velocity, axis=1)
    ka = np.max(np.abs(s.qdd) / limits.acceleration, axis=1)
    kj = np.max(np.abs(s.qddd) / limits.jerk, axis=1)
    out: Array = np.maximum(np.maximum(kv, np.sqrt(ka)), np.cbrt(kj)).astype(np.float64)
    return out


def _within_by_differences(t: Array, q: Array, limits: Limits) -> bool:
    """Whether the divided differences of the sampled positions (orders 1-3, times k!) are
    inside the velocity, acceleration and jerk limits."""
    d = q.copy()
    for order, bound in ((1, limits.velocity), (2, limits.acceleration), (3, limits.jerk)):
        if d.shape[0] <= 1:
            break
        d = (d[1:] - d[:-1]) / (t[order:] - t[:-order])[:, None]
        worst = np.max(np.abs(d) * math.factorial(order) / bound)
        if worst > 1.0 + DIFFERENCE_RTOL:
            return False
    return True
