"""Run-up and run-out: jerk-limited ruckig moves from rest into the first frame's state and
from the last frame's state to rest.

By default they are *gentle*: an axis's run-up and run-out use no more of its acceleration
and jerk limits than the shot itself does, and at least :data:`GENTLE_FLOOR` of them
(:func:`edge_limits`); ``"fast"`` edges use the full limits (the time-optimal move).

Only ruckig's offline state-to-state calculation is used (no control cycle, no intermediate
waypoints - those call a remote service). Units: SI (m, rad, s).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.timing.limits import LIMIT_RTOL, Limits, TimingLimitError, fmt

Array = NDArray[np.float64]

#: A boundary state within this fraction of the velocity and acceleration limits is at rest.
REST_RTOL = 1e-9
#: How run-ups and run-outs use the acceleration and jerk limits (see :func:`edge_limits`).
EDGE_MODES: tuple[str, ...] = ("gentle", "fast")
#: Gentle edges may always use this fraction of an axis's acceleration and jerk limits.
GENTLE_FLOOR = 0.25
#: How many units in the last place of a position limit a run-up or run-out that travels
#: towards it stops inside it (:func:`room_problem`): its samples' round-off.
EDGE_GUARD = 8


@dataclass(frozen=True, eq=False)
class Edge:
    """Samples of a run-up or run-out (each (k, axes)) and its report."""

    q: Array
    qd: Array
    qdd: Array
    qddd: Array
    report: dict[str, Any]
    warnings: list[str]


class _Move:
    """A ruckig state-to-state move, sampled at move times; rest at one end.

    Only ruckig's offline state-to-state calculation is used (no control cycle, no
    intermediate waypoints - those call a remote service).
    """

    def __init__(self, current: tuple[Array, Array, Array], target: tuple[Array, Array, Array],
                 limits: Limits, *, stop: bool, what: str) -> None:
        from ruckig import (
            ControlInterface,
            InputParameter,
            Result,
            Ruckig,
            Synchronization,
            Trajectory,
        )

        dofs = limits.size
        inp = InputParameter(dofs)
        if stop:  # brake each axis as hard as it can: the shortest stop, wherever it ends
            inp.control_interface = ControlInterface.Velocity
            inp.synchronization = Synchronization.No
        inp.current_position, inp.current_velocity, inp.current_acceleration = (
            [float(x) for x in arr] for arr in current)
        inp.target_position, inp.target_velocity, inp.target_acceleration = (
            [float(x) for x in arr] for arr in target)
        inp.max_velocity = [float(x) for x in limits.velocity]
        inp.max_acceleration = [float(x) for x in limits.acceleration]
        inp.max_jerk = [float(x) for x in limits.jerk]
        traj = Trajectory(dofs)
        try:
            result = Ruckig(dofs).calculate(inp, traj)
        except RuntimeError as exc:  # ruckig raises on invalid input
            msg = f"ruckig could not plan {what}: {exc}"
            raise TimingLimitError(msg) from exc
        if result not in (Result.Working, Result.Finished):
            msg = f"ruckig could not plan {what} ({result})"
            raise TimingLimitError(msg)
        self._traj = traj
        self._stop = stop
        # the positions the move was given (the shot's frame, and the start position)
        given = np.array([current[0]] if stop else [current[0], target[0]], dtype=np.float64)
        self.given_min, self.given_max = given.min(axis=0), given.max(axis=0)
        self.duration = float(traj.duration)
        rest = traj.at_time(self.duration)[0] if stop else current[0]
        self.rest_position = np.array(rest, dtype=np.float64)
        # Position range of the move, exactly, from ruckig's per-axis phases (its own
        # position_extrema is not reliable with the velocity interface).
        profiles = traj.profiles[0]
        self._phases = [_phases(prof) for prof in profiles]
        ranges = np.array([_phase_range(seg) for seg, _, _ in self._phases])
        if any(prof.accel.duration > 0.0 for prof in profiles):  # pragma: no cover
            msg = f"ruckig planned {what} with a final acceleration phase (not expected)"
            raise TimingLimitError(msg)
        self.min = np.minimum(ranges[:, 0], self.rest_position)
        self.max = np.maximum(ranges[:, 1], self.rest_position)

    def sample(self, times: Array) -> tuple[Array, Array, Array, Array]:
        """Position, velocity, acceleration and jerk at move times, each (k, axes).

        Evaluated exactly from ruckig's per-axis phases (constant jerk in each), all samples
        at once; the jerk is that of the phase just after the sample time. Beyond the move's
        rest end (after a stop, before a start) the state is exactly rest at the rest
        position; an axis that has finished its own profile holds its final state.
        """
        shape = (times.size, len(self._phases))
        p = np.empty(shape)
        v = np.empty(shape)
        a = np.empty(shape)
        j = np.empty(shape)
        tm = np.clip(times, 0.0, self.duration)
        for axis, (seg, start, final) in enumerate(self._phases):
            end = start[-1] + seg[-1, 4]
            idx = np.clip(np.searchsorted(start, tm, side="right") - 1, 0, seg.shape[0] - 1)
            tau = np.minimum(tm - start[idx], seg[idx, 4])
            p0, v0, a0, jj = seg[idx, 0], seg[idx, 1], seg[idx, 2], seg[idx, 3]
            # After its own profile an axis goes on at its final velocity and acceleration
            # (zero for a stop), as ruckig does.
            done = tm >= end
            after = tm - end
            p[:, axis] = np.where(
                done, final[0] + after * (final[1] + after * final[2] / 2.0),
                p0 + tau * (v0 + tau * (a0 / 2.0 + tau * jj / 6.0)))
            v[:, axis] = np.where(done, final[1] + after * final[2],
                                  v0 + tau * (a0 + tau * jj / 2.0))
            a[:, axis] = np.where(done, final[2], a0 + tau * jj)
            j[:, axis] = np.where(done, 0.0, jj)
        rest = (times >= self.duration) if self._stop else (times <= 0.0)
        p[rest] = self.rest_position
        v[rest] = a[rest] = j[rest] = 0.0
        return p, v, a, j


def _phases(profile: Any) -> tuple[Array, Array, tuple[float, float, float]]:
    """One axis's ruckig profile as phases of constant jerk: rows (p, v, a, j, duration) at
    each phase's start, the phases' start times, and the state at its end (p, v, a).

    Each of the profile's fields is read once (every read converts the whole field)."""
    brake = profile.brake
    p, v, a = profile.p, profile.v, profile.a
    seg = np.array([[*brake.p[:2], *p[:7]], [*brake.v[:2], *v[:7]], [*brake.a[:2], *a[:7]],
                    [*brake.j[:2], *profile.j[:7]], [*brake.t[:2], *profile.t[:7]]]).T
    start = np.concatenate([[0.0], np.cumsum(seg[:-1, 4])])
    return seg, start, (float(p[7]), float(v[7]), float(a[7]))


def _stop_move(p: Array, v: Array, a: Array, limits: Limits) -> _Move:
    """The shortest jerk-limited stop from the state (p, v, a), per axis (not synchronised)."""
    zero = np.zeros(limits.size)
    return _Move((p, v, a), (p, zero, zero), limits, stop=True,
                 what="a stop from the shot's boundary state")


def edge_limits(limits: Limits, acceleration: Array, jerk: Array, edges: str) -> Limits:
    """The limits a run-up and run-out may use.

    ``"fast"``: the robot's own. ``"gentle"``: per axis, the acceleration and jerk the shot
    itself reaches (``acceleration``, ``jerk``: its peak magnitudes, (8,), boundary states
    included), at least :data:`GENTLE_FLOOR` of the limit and at most the limit. Velocity and
    position limits are the robot's.
    """
    if edges == "fast":
        return limits
    if edges != "gentle":
        msg = f"edges {edges!r} is not one of {', '.join(EDGE_MODES)}"
        raise ValueError(msg)
    return dataclasses.replace(
        limits,
        acceleration=np.clip(acceleration, GENTLE_FLOOR * limits.acceleration,
                             limits.acceleration),
        jerk=np.clip(jerk, GENTLE_FLOOR * limits.jerk, limits.jerk),
    )


def stop_peak_velocity(v: Array, a: Array, limits: Limits) -> Array:
    """Per axis, the highest speed of the shortest stop from the state (v, a), (8,).

    A jerk-limited stop that starts accelerating away from rest first has to bring the
    acceleration to zero, gaining ``a² / 2J`` of speed (ruckig's velocity interface does
    not keep the velocity limit there). For the run-up pass the reversed state (-v, a).
    """
    gain = np.where(v * a > 0.0, a * a / (2.0 * limits.jerk), 0.0)
    out: Array = np.abs(v) + gain
    return out


def _phase_range(seg: Array) -> tuple[float, float]:
    """Lowest and highest position of one axis's phases (:func:`_phases`' rows).

    A profile is an optional two-phase brake followed by seven phases, each of constant
    jerk; inside a phase the position is a cubic whose extrema are where the velocity (a
    quadratic) is zero.
    """
    lo, hi = math.inf, -math.inf
    for p0, v0, a0, j, dur in seg.tolist():
        if dur <= 0.0:
            continue
        cands = [0.0, dur]
        # roots of v0 + a0 t + j t^2 / 2 inside the phase
        if j != 0.0:
            disc = a0 * a0 - 2.0 * j * v0
            if disc >= 0.0:
                r = math.sqrt(disc)
                cands += [(-a0 + r) / j, (-a0 - r) / j]
        elif a0 != 0.0:
            cands.append(-v0 / a0)
        for t in cands:
            if 0.0 <= t <= dur:
                pos = p0 + t * (v0 + t * (a0 / 2.0 + t * j / 6.0))
                lo, hi = min(lo, pos), max(hi, pos)
    return lo, hi


def _at_rest(v: Array, a: Array, limits: Limits) -> bool:
    return bool(np.all(np.abs(v) <= REST_RTOL * limits.velocity)
                and np.all(np.abs(a) <= REST_RTOL * limits.acceleration))


def _empty_edge(p: Array, limits: Limits, key: str) -> Edge:
    empty = np.zeros((0, limits.size))
    report = {
        "duration": 0.0, "hold": 0.0, "samples": 0,
        key: {name: float(p[j]) for j, name in enumerate(limits.names)},
        "travel": dict.fromkeys(limits.names, 0.0),
        "extent": dict.fromkeys(limits.names, 0.0),
    }
    return Edge(empty, empty, empty, empty, report, [])


def _edge_report(
    move: _Move, ticks: int, step: float, p: Array, limits: Limits, key: str, sign: float
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


@dataclass(frozen=True)
class EdgeProblem:
    """Why a run-up or run-out does not fit: ``text`` (one line), the ``axis`` index,
    ``side`` (``"run-up"`` or ``"run-out"``), the film ``frame`` it joins and ``kind``
    (``"position"``: it needs room beyond a limit, ``"velocity"``, or ``"plan"``: ruckig
    found no move)."""

    text: str
    axis: int
    side: str
    frame: int
    kind: str


def velocity_problem(v: Array, a: Array, limits: Limits, side: str,
                     frame: int) -> EdgeProblem | None:
    """The run-out from state (v, a) (the run-up: pass (-v, a)) if its stop goes beyond a
    velocity limit."""
    peak = stop_peak_velocity(v, a, limits)
    over = peak / limits.velocity
    if not np.any(over > 1.0 + LIMIT_RTOL):
        return None
    j = int(np.argmax(over))
    revolute = bool(limits.revolute[j])
    what = (f"the run-up into frame {frame}" if side == "run-up"
            else f"the run-out from frame {frame}")
    text = (
        f"{what} would need {limits.names[j]} velocity "
        f"{fmt(float(peak[j]), 'velocity', revolute)}, beyond "
        f"{fmt(float(limits.velocity[j]), 'velocity', revolute)} (the shot "
        f"{'starts' if side == 'run-up' else 'ends'} still accelerating near that speed)"
    )
    return EdgeProblem(text, j, side, frame, "velocity")


def room_problem(move: _Move, limits: Limits, side: str, frame: int) -> EdgeProblem | None:
    """The move if it needs room beyond a position limit.

    Strictly: a move that travels towards a limit must end :data:`EDGE_GUARD` ulps of the
    limit inside it (its servo samples, evaluated from the same phases, then stay inside; a
    1e-9 relative tolerance here let the slowest fitting take stop 9e-9 m past the track's
    end); one given a position on a limit, or past it by round-off (a frame the IK put
    there, a velocity of 1e-17 into it), may go no further than round-off.
    """
    guard = EDGE_GUARD * np.spacing(np.maximum(np.abs(limits.upper), np.abs(limits.lower)))
    top = np.maximum(limits.upper - guard, move.given_max + guard)
    bottom = np.minimum(limits.lower + guard, move.given_min - guard)
    over = np.flatnonzero((move.max > top) | (move.min < bottom))
    if over.size == 0:
        return None
    revolute = limits.revolute
    parts = []
    for j in over.tolist():
        upper = bool(move.max[j] > top[j])
        rev = bool(revolute[j])
        bound = float(limits.upper[j] if upper else limits.lower[j])
        past = float(move.max[j] - bound if upper else bound - move.min[j])
        # the distance past the limit, not the position: rounded alike, the two read the same
        where = (f"goes {fmt(past, 'position', rev)} past" if past > 0.0 else
                 f"stops {fmt(-past, 'position', rev)} short of" if past < 0.0 else "reaches")
        parts.append(f"{limits.names[j]} {where} its {'upper' if upper else 'lower'} limit "
                     f"{fmt(bound, 'position', rev)}")
    text = (
        f"the {side} {'into' if side == 'run-up' else 'from'} frame {frame} "
        f"({move.duration:.2f} s) needs more room: " + "; ".join(parts)
    )
    return EdgeProblem(text, int(over[0]), side, frame, "position")


def _edge_position_check(move: _Move, limits: Limits, side: str, frame: int) -> None:
    problem = room_problem(move, limits, side, frame)
    if problem is not None:
        msg = problem.text + "; move the shot away from the limit or slow it down at that end"
        raise TimingLimitError(msg)


def edge_problem(
    first: tuple[Array, Array, Array], last: tuple[Array, Array, Array], limits: Limits,
    frames: tuple[int, int], start: Array | None = None,
) -> EdgeProblem | None:
    """Whether the run-up into state ``first`` and the run-out from state ``last`` (each
    (p, v, a)) fit ``limits`` (velocity and position; ruckig keeps acceleration and jerk):
    the first problem found, or None. Plans the moves, samples nothing."""
    p, v, a = first
    if start is not None or not _at_rest(v, a, limits):
        problem = velocity_problem(-v, a, limits, "run-up", frames[0])
        if problem is not None:
            return problem
        try:
            if start is None:
                move = _stop_move(p, -v, a, limits)
            else:
                zero = np.zeros(limits.size)
                move = _Move((start, zero, zero), (p, v, a), limits, stop=False,
                             what="the run-up from the start position")
        except TimingLimitError as exc:
            return EdgeProblem(str(exc), 0, "run-up", frames[0], "plan")
        problem = room_problem(move, limits, "run-up", frames[0])
        if problem is not None:
            return problem
    p, v, a = last
    if not _at_rest(v, a, limits):
        problem = velocity_problem(v, a, limits, "run-out", frames[1])
        if problem is not None:
            return problem
        try:
            move = _stop_move(p, v, a, limits)
        except TimingLimitError as exc:
            return EdgeProblem(str(exc), 0, "run-out", frames[1], "plan")
        return room_problem(move, limits, "run-out", frames[1])
    return None


def runup(p: Array, v: Array, a: Array, limits: Limits, step: float, frame: int) -> Edge:
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
    move = _stop_move(p, -v, a, limits)
    _edge_position_check(move, limits, "run-up", frame)
    ticks = max(1, math.ceil(move.duration / step - 1e-9))
    # Sample k (0..ticks-1) is at run-up time k*step - hold; reversed time = duration - that.
    hold = ticks * step - move.duration
    reverse_t = move.duration - (np.arange(ticks, dtype=np.float64) * step - hold)
    reverse_t[0] = max(reverse_t[0], move.duration)  # exactly at rest (hold may be -1e-9 step)
    pos, vel, acc, jerk = move.sample(reverse_t)
    report = _edge_report(move, ticks, step, p, limits, "start", 1.0)
    return Edge(pos, -vel, acc, -jerk, report, _edge_warnings(report, limits, "run-up"))


def runup_from(
    start: Array, p: Array, v: Array, a: Array, limits: Limits, step: float, frame: int
) -> Edge:
    """A jerk-limited move from rest at ``start`` into the first frame's state (p, v, a).

    All axes arrive together (ruckig's position interface, time-synchronised). Held at rest
    at ``start`` before it so that the first frame lands on a servo tick.
    """
    if start.shape != (limits.size,) or not np.all(np.isfinite(start)):
        msg = f"start must be {limits.size} finite axis values, got {start.tolist()}"
        raise ValueError(msg)
    if np.array_equal(start, p) and _at_rest(v, a, limits):
        return _empty_edge(p, limits, "start")
    zero = np.zeros(limits.size)
    move = _Move((start, zero, zero), (p, v, a), limits, stop=False,
                 what="the run-up from the start position")
    _edge_position_check(move, limits, "run-up", frame)
    ticks = max(1, math.ceil(move.duration / step - 1e-9))
    hold = ticks * step - move.duration
    pos, vel, acc, jerk = move.sample(np.arange(ticks, dtype=np.float64) * step - hold)
    report = _edge_report(move, ticks, step, p, limits, "start", 1.0)
    return Edge(pos, vel, acc, jerk, report, _edge_warnings(report, limits, "run-up"))


def runout(p: Array, v: Array, a: Array, limits: Limits, step: float, frame: int) -> Edge:
    """A jerk-limited stop from the last frame's state; the take ends at rest on a tick."""
    if _at_rest(v, a, limits):
        return _empty_edge(p, limits, "end")
    move = _stop_move(p, v, a, limits)
    _edge_position_check(move, limits, "run-out", frame)
    ticks = max(1, math.ceil(move.duration / step - 1e-9))
    times = np.arange(1, ticks + 1, dtype=np.float64) * step
    times[-1] = max(times[-1], move.duration)  # the take ends exactly at rest
    pos, vel, acc, jerk = move.sample(times)
    report = _edge_report(move, ticks, step, p, limits, "end", -1.0)
    return Edge(pos, vel, acc, jerk, report, _edge_warnings(report, limits, "run-out"))


def _edge_warnings(report: dict[str, Any], limits: Limits, what: str) -> list[str]:
    """A note when a run-up or run-out travels more than a tenth of an axis's range."""
    out = []
    span = limits.upper - limits.lower
    for j, name in enumerate(limits.names):
        ext = float(report["extent"][name])
        if ext > 0.1 * span[j]:
            out.append(
                f"the {what} moves {name} by {fmt(ext, 'position', bool(limits.revolute[j]))}"
                f" ({ext / span[j]:.0%} of its range) over {report['duration']:.2f} s"
            )
    return out
