"""The ``shot`` objective: what a whole-shot choice of (track, extend, branch) minimises.

What a crew reads first is the take's maximum feasible speed: 1 / P, with P the take's peak
use of the limits,

    P = max over axes and time of  max(|v| / v_max, (|a| / a_max)^(1/2), (|j| / j_max)^(1/3))

(velocity scales with the speed of the take, acceleration with its square, jerk with its
cube), taken along the spline the timing stage moves on (:mod:`camtraj.ik.spline_ops`), with
the ends' stopping needs (a shot that ends still accelerating needs a slower take for its
run-out to stay under the velocity limit; one that ends moving towards a position limit needs
a take slow enough to stop before it). The solver works in two passes:

* The dynamic programme chooses one candidate per frame by frame-to-frame differences, with
  per-axis velocity usages z1 = dq / (v_max dt):

      sum over steps and axes of  motion * m_i |z1| + velocity * z1^2
                                + overspeed * max(0, |z1| - 1)^2
      + margin * sum over frames of the squared margin intrusions,

  ``m_i = w_i v_i / sum(w v)`` making ``motion * sum(m |z1|)`` the papers' weighted motion F
  in units of "every axis moving one frame at its velocity limit"; a margin intrusion is
  max(0, 1 - d / zone) for each axis's distance d to its nearer position limit, the wrist
  singularity distance and the full-stretch distance (:mod:`camtraj.ik.margins`).
* The refinement lowers P itself through a smooth stand-in, the power mean
  ``scale * (sum (u / scale)^power)^(1/power)`` over every use u of the take (raised in
  stages towards the maximum), plus ``refine_margin`` times the peak use times the worst
  frame's squared margin intrusions (steeper in the last fifth of a zone), ``tie_break``
  times the mean F per step, and the run-up and run-out room (:meth:`ShotCost.refine_total`).

The first frame carries no motion term: the run-up brings the robot there, whatever the start.
A shot that starts or ends in motion needs room for its run-up and run-out: the first and last
frames' positions pushed out by each axis's stopping distance at its edge velocity (at the
speed the take will run at) carry the margin cost, and a steep cost past a limit; from the
refinement's second stage on, the slow-down that stop needs to fit before the limit is one of
the take's uses (:meth:`ShotCost.room_needs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from camtraj.ik.closed_form import TWO_PI
from camtraj.ik.spline_ops import BandOps, spline_ops
from camtraj.robot import PRISMATIC, REVOLUTE, Robot

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]

N_MEASURES = 10  # the 8 joints, the wrist singularity distance, the full-stretch distance
#: Intrusion into a margin zone past which the refinement's cost turns steep (the last fifth
#: of the zone: 5 deg before a revolute limit by default), so the spline through the frames
#: has room to turn before a limit.
CLOSE = 0.8


MARGIN_POWER = 4.0  # the power mean over frames that stands in for the worst frame

#: The fastest take the run-up and run-out room is planned for, as a multiple of real time.
#: The room is planned at the speed the objective aims for (1 / the peak use): the timing
#: stage's maximum feasible speed needs the run-out's stop to fit at that speed, where it is
#: longest, so room planned at real time let a refinement bring an end axis close to its
#: limit and lose the speed it gained (a 140 deg arc: model 8.5x, take 6.0x, the run-out's
#: extend 0.1 mm past its limit). Beyond ten times real time a crew needs no more.
ROOM_SPEED = 10.0


def margin_peak(e: Array) -> tuple[float, Array]:
    """A smooth stand-in for the worst frame's sum of squared margin intrusions e (n, 10):
    E = (sum_k m_k^Q)^(1/Q) with m_k = sum_j e_kj^2 and Q = :data:`MARGIN_POWER`, and
    dE / dm_k (n,). A margin is a constraint the take may give up only where that buys speed:
    weighed against the peak use, not diluted by the frames that keep it."""
    m = (e * e).sum(axis=1)
    total = float((m ** MARGIN_POWER).sum())
    if total <= 0.0:
        return 0.0, np.zeros_like(m)
    big = total ** (1.0 / MARGIN_POWER)
    return big, np.asarray((m / big) ** (MARGIN_POWER - 1.0))


def powers(a: Array, ex: Array) -> Array:
    """``a ** ex`` for a (..., k) >= 0 and one exponent per column, ex (k,). The
    continuation's exponents are whole numbers (power / order: 6 / 3 = 2, ..., 48 / 1 = 48),
    taken by repeated squaring, which is several times faster than ``pow`` and as exact; a
    run of columns with the same exponent is done at once, on a column-major copy (a run of
    columns is then one contiguous block, not short strided rows), returned in a's order."""
    by_col = np.ascontiguousarray(np.moveaxis(a, -1, 0))
    out = np.empty(by_col.shape)
    k = ex.shape[0]
    j = 0
    while j < k:  # each run of columns with the same exponent at once
        e = float(ex[j])
        end = j + 1
        while end < k and ex[end] == e:
            end += 1
        if e.is_integer() and 0.0 <= e <= 1024.0:
            out[j:end] = _whole_power(by_col[j:end], int(e))
        else:  # pow on the columns as they lie in a (its vector loops depend on the layout)
            out[j:end] = np.moveaxis(a[..., j:end] ** e, -1, 0)
        j = end
    return np.ascontiguousarray(np.moveaxis(out, 0, -1))


def _whole_power(a: Array, e: int) -> Array:
    """a ** e for a whole e >= 0 by repeated squaring."""
    result = None
    base = a
    while e:
        if e & 1:
            result = base if result is None else result * base
        e >>= 1
        if e:
            base = base * base
    return np.ones_like(a) if result is None else result


def _stop_root(a1: Array, g: Array) -> Array:
    """The root s of s^4 - a1 s^3 - g = 0 above a1 for each a1 >= 0, g > 0 (at most 16: two
    ends by eight axes), by Newton's method from above (s = a1 + g^(1/4)), all of them
    stepped together until every step is below 1e-15 s. In Python floats: on arrays this
    small each numpy operation costs more than the arithmetic (the same IEEE operations in
    the same order, so the same roots to the last bit)."""
    ag = a1.tolist()
    gg = g.tolist()
    s = (a1 + g ** 0.25).tolist()
    for _ in range(12):
        more = False
        for i, (si, ai, gi) in enumerate(zip(s, ag, gg, strict=True)):
            s2 = si * si
            step = (s2 * s2 - ai * s2 * si - gi) / max(4.0 * s2 * si - 3.0 * ai * s2, 1e-300)
            s[i] = si - step
            more = more or abs(step) > 1e-15 * s[i]
        if not more:
            break
    return np.array(s)


def _stop_from(v: float, a: float, j: float, a_max: float) -> tuple[float, float, float]:
    """The shortest stopping distance from speed v >= 0 with acceleration a >= 0 along the
    motion under jerk j and acceleration a_max, and its derivatives in v and a. The stop
    pulls the acceleration down at full jerk at once: the first a / j of it brings a to
    zero (the speed rises by a^2 / 2j), the rest is the stop from that speed at rest
    acceleration (:meth:`ShotCost.stop_distance`)."""
    t = a / j
    top = v + 0.5 * a * t
    if top >= a_max * a_max / j:
        d0, d0_v = 0.5 * top * (top / a_max + a_max / j), top / a_max + 0.5 * a_max / j
    else:
        root = math.sqrt(top / j)
        d0, d0_v = top * root, 1.5 * root
    return v * t + a * t * t / 3.0 + d0, t + d0_v, v / j + a * t / j + d0_v * t


def _stop_root_pushed(v: float, a: float, room: float, j: float, a_max: float,
                      u: float) -> tuple[float, float, float, float]:
    """The u where the stop from (v u, a u^2) (:func:`_stop_from`) is ``room`` long, by
    Newton's method from ``u`` above it (the distance grows and is convex in u, so the
    steps fall to the root without overshooting), and du / dv, du / da, du / d room. In
    Python floats: a handful of values, where each numpy operation costs more than the
    arithmetic."""
    for _ in range(60):
        dist, d_v, d_a = _stop_from(v * u, a * u * u, j, a_max)
        step = (dist - room) / (d_v * v + d_a * 2.0 * a * u)
        u -= step
        if abs(step) <= 1e-14 * u:
            break
    _, d_v, d_a = _stop_from(v * u, a * u * u, j, a_max)
    slope = d_v * v + d_a * 2.0 * a * u
    return u, -d_v * u / slope, -d_a * u * u / slope, 1.0 / slope


@dataclass(frozen=True)
class TakeUse:
    """A path's use of the limits: the spline's velocity, acceleration and jerk usages
    (:mod:`camtraj.ik.spline_ops`) at every knot and piece middle over the limits per frame
    interval, ``z`` (rows, 8, k) read by the operators ``ops``, and the ends' needs, None
    below 3 frames: each a slow-down the take needs at one end, as a usage (m, 8)
    (:meth:`ShotCost.edge_needs`: the stop under the velocity limit; with
    ``ShotCost.room``, :meth:`ShotCost.room_needs`: the stop inside the position limits),
    its derivatives in the frames an operator row reads (m, width, 8) and that row (m,)."""

    ops: BandOps
    z: Array
    ends: tuple[Array, Array, IntArray] | None
    _scaled: dict[tuple[float, float], ScaledUse] = field(
        default_factory=dict, init=False, repr=False, compare=False)

    def peak(self) -> float:
        """max(|v|, |a|^(1/2), |j|^(1/3), end needs): the take runs at most at 1/peak."""
        return self._peak

    @cached_property
    def _peak(self) -> float:
        # column by column: numpy's reduction over the leading axes of (rows, 8, k) is slow
        top = np.array([np.abs(self.z[..., i]).max() for i in range(self.z.shape[-1])])
        out = float((top ** (1.0 / np.asarray(self.ops.orders, dtype=float))).max())
        if self.ends is not None:
            out = max(out, float(self.ends[0].max()))
        return out

    def power_sum(self, power: float, scale: float) -> float:
        """sum (u / scale)^power over every use u (u = |v|, |a|^(1/2), |j|^(1/3), needs)."""
        return self.scaled(power, scale).phi

    def scaled(self, power: float, scale: float) -> ScaledUse:
        """The usages' powers at ``power`` and ``scale`` (:class:`ScaledUse`), computed once
        per pair: the objective, its gradient and its curvature all read them (the objective
        of a kept step, then the next round's normal equations)."""
        got = self._scaled.get((power, scale))
        if got is None:
            got = ScaledUse.of(self, power, scale)
            self._scaled[(power, scale)] = got
        return got


@dataclass(frozen=True)
class ScaledUse:
    """A :class:`TakeUse`'s usages z (rows, 8, k) of order k scaled for a power mean at
    ``power`` and ``scale``: with a = |z| / scale^k, the term of the sum is a^ex for
    ex = power / k; ``below`` = a^(ex - 2) gives its slope (a^(ex - 1) sign(z) = below z /
    scale^k) and curvature (below); ``phi`` is the sum of the terms, the ends' stopping
    needs included."""

    below: Array
    phi: float

    @classmethod
    def of(cls, use: TakeUse, power: float, scale: float) -> ScaledUse:
        k = np.asarray(use.ops.orders, dtype=float)
        ex = power / k
        a = np.abs(use.z) / scale ** k
        below = powers(a, ex - 2.0)
        # a^ex from a^(ex - 2) (one pass of powers); below a power of 2 the curvature is
        # unbounded at a = 0 and the sum is taken directly
        terms = below * a * a if ex.min() >= 2.0 else powers(a, ex)
        phi = float(terms.sum())
        if use.ends is not None:  # a trial step that stops past a limit: inf, rejected
            with np.errstate(over="ignore"):
                phi += float(((use.ends[0] / scale) ** power).sum())
        below.setflags(write=False)
        return cls(below, phi)


@dataclass(frozen=True)
class ShotCost:
    """The objective of :mod:`camtraj.ik.shot_cost` for one robot and frame interval.

    Attributes:
        lower, upper: Position limits (8,) [m, rad].
        vel, acc, jerk: What each axis may do in one frame interval: v_max dt, a_max dt^2,
            j_max dt^3 (8,).
        motion_coef: ``motion * m_i`` (8,).
        velocity, overspeed, margin: The dynamic programme's weights.
        zone: Width of the margin zone (10,): per axis [m, rad], then wrist and stretch [rad].
        dt: Frame interval [s]; a_max, j_max: acceleration and jerk limits (8,).
        refine_margin, close_weight, tie_break: The refinement's weights of the worst
            frame's squared margin intrusions (relative to the peak use), of the steep part
            of a zone, and of the mean F per step.
        power, scale: The refinement's power mean of the take's uses.
        room: Whether the ends' room to their position limits is among the take's uses
            (:meth:`room_needs`; the refinement adds it from its second stage on).
        edge_room: Whether the programme's run-up and run-out cost (:meth:`edge_cost`)
            also weighs that room as a use: a stop that needs a take slower than real time
            to fit before its limit costs as a step beyond the velocity limit does.
        holds: The frames (first, last) where the camera, and so the robot, holds still
            (:func:`~camtraj.ik.spline_ops.hold_runs`): the take's spline is clamped to rest
            next to them, as the timing stage fits it.
        rests: How the camera rests on the first / last frame
            (:func:`~camtraj.ik.shot.camera_rests`): the take's spline has zero velocity
            there (and zero acceleration where it settles), as the timing stage fits it.
    """

    lower: Array
    upper: Array
    vel: Array
    acc: Array
    jerk: Array
    motion_coef: Array
    velocity: float
    overspeed: float
    margin: float
    zone: Array
    dt: float
    a_max: Array
    j_max: Array
    refine_margin: float = 0.1
    close_weight: float = 1.0
    tie_break: float = 0.01
    power: float = 8.0
    scale: float = 1.0
    holds: tuple[tuple[int, int], ...] = ()
    rests: tuple[int, int] = (0, 0)
    room: bool = True
    edge_room: bool = False

    @classmethod
    def for_robot(cls, robot: Robot, dt: float) -> ShotCost:
        s = robot.ik
        vel = robot.max_velocity * dt
        wv = robot.weights * vel
        zone_axes = np.where(PRISMATIC, s.limit_margin_prismatic, s.limit_margin_revolute)
        return cls(
            lower=robot.lower, upper=robot.upper, vel=vel,
            acc=robot.max_acceleration * dt * dt, jerk=robot.max_jerk * dt ** 3,
            motion_coef=s.motion_weight * wv / max(float(wv.sum()), 1e-300),
            velocity=s.velocity_weight, overspeed=s.overspeed_weight,
            refine_margin=s.peak_margin_weight, tie_break=s.tie_break_weight,
            margin=s.margin_weight,
            zone=np.concatenate([zone_axes, [s.wrist_margin, s.stretch_margin]]),
            dt=dt, a_max=robot.max_acceleration, j_max=robot.max_jerk,
        )

    # -- the take's peak use (what the refinement minimises) -------------------------------
    def take_use(self, q: Array) -> TakeUse:
        """The take's use of the limits along a continuous path q (n, 8) (:class:`TakeUse`)."""
        n = q.shape[0]
        if n < 3:
            ops = BandOps((1,), (n - 1,), np.tile([[[-1.0], [1.0]]], (n - 1, 1, 1)), 0)
            return TakeUse(ops, ops.apply(q / self.vel), None)
        ops = spline_ops(n, self.holds, self.rests)
        lims = np.stack([(self.vel, self.acc, self.jerk)[k - 1] for k in ops.orders], axis=-1)
        z = ops.apply(q) / lims
        vel_z, acc_z = z[[0, -1], :, 0], z[[0, -1], :, 2]  # order 1 and 2 at the knots
        need, d1, d2 = self.edge_needs(vel_z, acc_z)
        rows = np.stack([ops.coef[[0, 0], :, [0, 2]], ops.coef[[-1, -1], :, [0, 2]]])
        lin = (rows[:, 0, :, None] * (d1 / self.vel)[:, None, :]
               + rows[:, 1, :, None] * (d2 / self.acc)[:, None, :])
        if not self.room:
            return TakeUse(ops, z, (need, lin, np.array([0, n - 1], dtype=np.intp)))
        room, room_lin = self.room_needs(q[[0, -1]], vel_z, acc_z, rows, -ops.offset)
        return TakeUse(ops, z, (np.concatenate([need, room]), np.concatenate([lin, room_lin]),
                                np.array([0, n - 1, 0, n - 1], dtype=np.intp)))

    def room_needs(self, q_ends: Array, z1: Array, z2: Array, rows: Array,
                   at: int) -> tuple[Array, Array]:
        """The slow-down each end's stop needs to fit between the end frame and the position
        limit ahead of it (the run-out's; the run-up's behind the first frame), as a usage.

        At real time an axis leaves its last frame at speed V = |z1| v_max with acceleration
        A along its motion (the run-up's state reversed in time); from (V / s, A / s^2) it
        stops within D (:func:`_stop_from`, the robot's own acceleration and jerk:
        the timing stage's run-out where its room decides the speed), so the room R to the
        limit allows the s where D = R. A take slowed down to fit its run-out is as slow as
        one slowed down for a velocity limit, so this need is a use like the others: the
        objective weighs it against the rest of the take instead of taking a stop past a
        limit at the aimed speed as a failure (a truck ending at the arm's full reach past the
        track's end: 0.22x real time, slower than ``paper``'s 0.28x; with this need 0.34x).
        R = 0 with the axis moving into its limit: no slow-down fits (R is floored at 1e-12,
        a need in the millions). An end still braking (A against the motion) is taken as
        not accelerating: its stop is shorter, so the need is on the safe side.

        Args:
            q_ends: The first and last frames' positions (2, 8).
            z1, z2: The spline's velocity and acceleration usages there (2, 8).
            rows: The operator rows that read z1 and z2 (2 ends, 2, width), times their
                limits.
            at: The end frame's column in those rows.

        Returns:
            The needs (2, 8) and their derivatives in the frames the rows read (2, width, 8).
        """
        sgn = np.sign(z1)
        ahead = np.array([[-1.0], [1.0]]) * sgn  # the run-up's stop is behind its frame
        ahead = np.where(sgn == 0.0, np.sign(z2), ahead)  # from rest: where it accelerates
        room = np.maximum(np.where(ahead > 0, self.upper - q_ends, q_ends - self.lower), 1e-12)
        v_max = self.vel / self.dt
        speed = np.abs(z1) * v_max
        acc = np.maximum(z2 * ahead, 0.0) * self.a_max
        u, d_speed, d_acc, d_room = self.stop_slowness(speed, acc, room)
        need = np.where(u > 0.0, 1.0 / np.where(u > 0.0, u, 1.0), 0.0)
        # d need = -du / u^2 with du from the stop's distance held at the room
        k = -need * need
        d_z1 = k * d_speed * sgn * v_max
        d_z2 = k * d_acc * np.where(z2 * ahead > 0.0, ahead, 0.0) * self.a_max
        lin = (rows[:, 0, :, None] * (d_z1 / self.vel)[:, None, :]
               + rows[:, 1, :, None] * (d_z2 / self.acc)[:, None, :])
        lin[:, at, :] += k * d_room * -ahead  # dR/dq: -1 towards the upper limit
        return need, lin

    def stop_slowness(self, speed: Array, acc: Array,
                      room: Array) -> tuple[Array, Array, Array, Array]:
        """The largest u (..., 8) for which each axis stops from (speed u, acc u^2) within
        ``room`` (acc >= 0 along the motion), and du / d speed, du / d acc, du / d room.

        The distance D(V u, A u^2) (:func:`_stop_from`) grows and is convex in u,
        so Newton's method from an upper bound (the root without A, or with A alone) falls
        to the root from above without overshooting. An axis neither moving nor
        accelerating has u = inf (its need is 0; its derivatives are 0)."""
        u = np.full(speed.shape, np.inf)
        moving = speed > 0.0
        u[moving] = self.stop_speed(room)[moving] / speed[moving]
        pushed = acc > 0.0
        j = np.broadcast_to(self.j_max, speed.shape)
        with np.errstate(divide="ignore"):
            alone = np.where(pushed, (3.0 * j * j * room / np.where(pushed, acc, 1.0) ** 3)
                             ** (1.0 / 6.0), np.inf)
        u = np.minimum(u, alone)
        ds, da, dr = (np.zeros(speed.shape) for _ in range(3))
        plain = moving & ~pushed  # u = stop_speed(R) / V: D0(V u) = R
        if plain.any():
            d0 = self.stop_distance(speed * np.where(plain, u, 0.0))[1]
            ds = np.where(plain, -u / np.maximum(speed, 1e-300), 0.0)
            dr = np.where(plain, 1.0 / np.maximum(d0 * speed, 1e-300), 0.0)
        if pushed.any():
            idx = np.nonzero(pushed)
            got = [_stop_root_pushed(*args) for args in zip(
                speed[idx].tolist(), acc[idx].tolist(), room[idx].tolist(), j[idx].tolist(),
                np.broadcast_to(self.a_max, speed.shape)[idx].tolist(), u[idx].tolist(),
                strict=True)]
            u[idx], ds[idx], da[idx], dr[idx] = np.array(got).T
        return u, ds, da, dr

    def edge_needs(self, z1: Array, z2: Array) -> tuple[Array, Array, Array]:
        """The slow-down each end's stop needs to stay under the velocity limit, as a usage.

        A jerk-limited stop from a state still accelerating away from rest gains a^2 / 2J of
        speed before it can brake (the timing stage's stop check): slowed by s, the state
        (v, a) becomes (v / s, a / s^2), and the need is the s that solves
        |z1| / s + c z2^2 / s^4 = 1 with c = a_max^2 / (2 J v_max) (s = |z1| without gain).

        Args:
            z1, z2: The spline's velocity and acceleration usages at the first (row 0) and
                last frame (row 1), (2, 8).

        Returns:
            s (2, 8) for the run-up (row 0, the state reversed) and the run-out (row 1), and
            its derivatives in z1 and z2 (2, 8) each.
        """
        c = self.a_max ** 2 / (2.0 * self.j_max * self.vel / self.dt)
        gains = np.stack([z1[0] * z2[0] < 0.0, z1[1] * z2[1] > 0.0]) & (z2 != 0.0)
        a1 = np.abs(z1)
        g = np.where(gains, c * z2 * z2, 0.0)
        need = a1.copy()
        if gains.any():
            need[gains] = _stop_root(a1[gains], g[gains])
        den = np.maximum(4.0 * need - 3.0 * a1, 1e-300)
        d1 = np.where(gains, np.sign(z1) * need / den, np.sign(z1))
        d2 = np.where(gains, 2.0 * c * z2 / np.maximum(need * need * den, 1e-300), 0.0)
        return need, d1, d2

    def peak(self, q: Array) -> float:
        """The peak use P = max(|v|, |a|^(1/2), |j|^(1/3)) over the limits of the spline
        through the path's frames, and the ends' stopping needs: the take runs at most at
        1/P of real time."""
        return self.take_use(q).peak()

    def refine_total(self, y: Array, use: TakeUse | None = None) -> float:
        """What the refinement minimises for measures y (n, 10):
        ``scale * (sum (u / scale)^power)^(1/power)`` over every use u of the take
        (:class:`TakeUse`), a smooth stand-in for its peak, + ``refine_margin * scale`` times
        the worst frame's squared margin intrusions (:func:`margin_peak`; steeper in the last
        part of a zone) + ``tie_break`` * mean motion per step + run-up / run-out room."""
        q = y[:, :8]
        n = q.shape[0]
        e = self.intrusion(y)
        close = np.maximum(e - CLOSE, 0.0)
        j = (self.refine_margin * self.scale * margin_peak(e)[0]
             + self.close_weight * float((close * close).sum()))
        if n > 1:
            use = use or self.take_use(q)
            j += self.scale * use.power_sum(self.power, self.scale) ** (1.0 / self.power)
            j += self.tie_break * float((np.abs(np.diff(q, axis=0) / self.vel)
                                         @ self.motion_coef).sum()) / (n - 1)
            slow = self.room_slowdown(use)
            j += self.refine_edge(q[0], q[1], slow) + self.refine_edge(q[-1], q[-2], slow)
        return float(j)

    @staticmethod
    def room_slowdown(use: TakeUse) -> float:
        """The slow-down (below 1: a faster take) the run-up and run-out room is planned at:
        the take at the speed its peak use allows, at most :data:`ROOM_SPEED` x real time."""
        return max(use.peak(), 1.0 / ROOM_SPEED)

    def refine_edge(self, q_edge: Array, q_inner: Array, slow: float) -> float:
        """Run-up / run-out room at an end frame, the take running ``slow`` times slower:
        the margin cost of the stopping excursion and a steep cost beyond the limits."""
        p = self.edge_excursion(q_edge, q_inner, slow)[0]
        e = self.edge_intrusion(p)
        beyond = np.maximum(e - 1.0, 0.0)
        return float(self.refine_margin * (e * e).sum() + self.overspeed * (beyond * beyond).sum())

    # -- parts -----------------------------------------------------------------------------
    def steps(self, qa: Array, qb: Array) -> Array:
        """Velocity usage z1 (..., 8) of a step from qa to qb (revolute differences wrapped)."""
        d = qb - qa
        d = np.where(REVOLUTE, d - TWO_PI * np.rint(d * (1.0 / TWO_PI)), d)
        return np.asarray(d / self.vel)

    def axis_step_cost(self, axis: int, d: Array, wrap: bool = True) -> Array:
        """:meth:`first_order`'s share of one axis for steps ``d`` (any shape) [m, rad],
        revolute steps taken the shorter way round with ``wrap``."""
        if wrap and REVOLUTE[axis]:
            d = d - TWO_PI * np.rint(d * (1.0 / TWO_PI))
        a = np.abs(d)
        a *= 1.0 / self.vel[axis]
        out = a * self.velocity
        out += self.motion_coef[axis]
        out *= a
        if a.size and a.max() > 1.0:  # the overspeed penalty, where a step exceeds v_max
            a -= 1.0
            np.maximum(a, 0.0, out=a)
            a *= a
            a *= self.overspeed
            out += a
        return np.asarray(out)

    def first_order(self, z1: Array) -> Array:
        """Motion, velocity and overspeed cost of steps with usages z1 (..., 8): (...)."""
        a = np.abs(z1)
        over = np.maximum(a - 1.0, 0.0)
        return np.asarray(a @ self.motion_coef + self.velocity * (z1 * z1).sum(axis=-1)
                          + self.overspeed * (over * over).sum(axis=-1))

    def intrusion(self, y: Array) -> Array:
        """Margin intrusions max(0, 1 - d / zone) (..., 10) of measures y (..., 10), computed
        in one buffer (the refinement measures every trial step)."""
        d = np.empty(y.shape)
        axes = d[..., :8]
        np.subtract(y[..., :8], self.lower, out=axes)
        np.minimum(axes, self.upper - y[..., :8], out=axes)
        d[..., 8:] = y[..., 8:]
        d /= self.zone
        np.subtract(1.0, d, out=d)
        return np.maximum(d, 0.0, out=d)

    def unary(self, y: Array) -> Array:
        """Margin cost (...) of frames with measures y (..., 10)."""
        e = self.intrusion(y)
        return np.asarray(self.margin * (e * e).sum(axis=-1))

    def stop_distance(self, v: Array) -> tuple[Array, Array]:
        """Shortest stopping distance (..., 8) [m, rad] of each axis from speed ``v`` >= 0
        (no initial acceleration) within its acceleration and jerk limits, and its derivative
        in ``v``."""
        a, j = self.a_max, self.j_max
        big = v >= a * a / j
        root = np.sqrt(np.maximum(v, 0.0) / j)
        d = np.where(big, 0.5 * v * (v / a + a / j), v * root)
        dd = np.where(big, v / a + 0.5 * a / j, 1.5 * root)
        return np.asarray(d), np.asarray(dd)

    def room_speed(self, q: Array, toward_upper: NDArray[np.bool_]) -> Array:
        """The highest speed (..., 8) from which each axis at ``q`` stops before the position
        limit it moves towards (the upper one where ``toward_upper``): :meth:`stop_speed` of
        the room left (at least 1e-12: an axis on its limit moving into it has no speed)."""
        room = np.where(toward_upper, self.upper - q, q - self.lower)
        return self.stop_speed(np.maximum(room, 1e-12))

    def stop_speed(self, room: Array) -> Array:
        """The highest speed (..., 8) from which each axis stops within ``room`` >= 0 [m,
        rad]: :meth:`stop_distance` inverted (below a_max^2 / j_max the stop never reaches
        a_max: D = v sqrt(v / j); above, D = v^2 / 2a + v a / 2j)."""
        a, j = self.a_max, self.j_max
        small = room <= a ** 3 / (j * j)  # the distance of the stop from v = a^2 / j
        return np.asarray(np.where(
            small, np.cbrt(room * room * j),
            np.sqrt(a ** 4 / (4.0 * j * j) + 2.0 * a * room) - a * a / (2.0 * j)))

    def edge_excursion(self, q_edge: Array, q_inner: Array,
                       slow: float = 1.0) -> tuple[Array, Array]:
        """Where the run-up starts (or the run-out stops) at least: the edge frame's position
        pushed out by the stopping distance of its velocity (the take ``slow`` times slower
        than the shot), (..., 8), and d p / d q_edge (d p / d q_inner is 1 minus it)."""
        d = q_edge - q_inner
        d = np.where(REVOLUTE, d - TWO_PI * np.rint(d * (1.0 / TWO_PI)), d)
        h = self.dt * slow
        dist, slope = self.stop_distance(np.abs(d) / h)
        return np.asarray(q_edge + np.sign(d) * dist), np.asarray(1.0 + slope / h)

    def edge_intrusion(self, p: Array) -> Array:
        """Margin intrusions (..., 8) of run-up / run-out excursions ``p`` (..., 8)."""
        d = np.minimum(p - self.lower, self.upper - p)
        return np.asarray(np.maximum(1.0 - d / self.zone[:8], 0.0))

    def edge_cost(self, q_edge: Array, q_inner: Array) -> Array:
        """Cost (...) of the run-up or run-out room at a shot's end frame: the margin cost of
        its stopping excursion at real time; with :attr:`edge_room`, also the overspeed cost
        of its room need beyond real time (the slow-down its stop needs to fit before the
        limit ahead, as :meth:`room_needs` has it, penalised past 1 as a step's velocity
        usage is)."""
        e = self.edge_intrusion(self.edge_excursion(q_edge, q_inner)[0])
        if not self.edge_room:
            return np.asarray(self.margin * (e * e).sum(axis=-1))
        z1 = self.steps(q_inner, q_edge)  # away from the shot: towards the stop's limit
        need = np.abs(z1) * (self.vel / self.dt) / self.room_speed(q_edge, z1 > 0)
        over = np.maximum(need - 1.0, 0.0)
        return np.asarray(self.margin * (e * e).sum(axis=-1)
                          + self.overspeed * (over * over).sum(axis=-1))
