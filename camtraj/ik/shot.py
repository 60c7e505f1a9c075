"""Whole-shot redundancy resolution: the ``shot`` objective, the default.

A previs move is known in full before the robot moves, so the redundancy (track, extend) and the
closed-form branch are chosen for the whole shot, not frame by frame:

1. Candidates. For every frame, a grid over its analytic feasible region (:mod:`region`): track
   values spread over each of the (at most two) reachable track intervals, and for each of them
   extend values spread over its reach interval. All frames' candidates are solved in closed
   form, on all eight branches, in one vectorised call.
2. Dynamic programme. One candidate per frame for the whole shot, by a shortest path over
   frames (Viterbi) minimising :class:`ShotCost`'s first-order terms (the papers' weighted
   motion F, velocity use, a steep penalty beyond the velocity limit) plus its margin terms.
   A chain keeps one branch label for the whole shot (a label changes only where two branches
   meet, at a singularity the margins keep away from); if no label reaches every frame, the
   chains are merged and labels may change wherever the step stays cheap. The first frame is
   free: the run-up brings the robot there. Each label's cheapest path is an answer
   (:func:`choose_each`): the solver refines from one per arm configuration.
3. Refinement (:mod:`refine`): the chosen track/extend curves move continuously inside each
   frame's feasible corridor to lower the full objective, acceleration and jerk included, so
   the answer is not quantised to the grid. Every frame stays an exact closed-form solution.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from camtraj.ik.closed_form import (
    EDGE,
    EXTEND,
    IDX,
    N_BRANCHES,
    TILT,
    TRACK,
    TWO_PI,
    packed_limits,
    six_axis_branch,
    six_axis_packed,
)
from camtraj.ik.margins import stretch_distance, wrist_distance
from camtraj.ik.region import Region, track_intervals
from camtraj.ik.shot_cost import N_MEASURES, ShotCost
from camtraj.robot import REVOLUTE, Robot

Array = NDArray[np.float64]
IntArray = NDArray[np.intp]

_CHUNK = 262_144  # pair-cost elements per vectorised block (2 MB each, a few temporaries)
_POINTS = 4_096  # candidate points solved per vectorised block (the closed form's temporaries)


HOLD_POSE_TOL = 1e-12
"""Consecutive camera poses whose matrix entries differ by at most this (m, or unitless for
the rotation) are a hold of the camera."""


def camera_holds(targets: Array) -> NDArray[np.bool_]:
    """Per frame pair, whether the camera (or flange) holds still, shape (n - 1,): its poses
    are equal (:data:`HOLD_POSE_TOL`), but for a turnaround: one equal pair alone between
    moving frames, where the camera comes back the way it came (a part of the pose, position
    or orientation, turns back and none goes on in the direction it had; a stop between
    moves at right angles stays a hold). A move symmetric about a
    turning point half-way between two frames has those two frames equal: held, the robot
    stopped dead there and the take of an out-and-back push ran at 66% of real time, the
    same move turning on a frame at 381% (trial 23). A hold of one pair where the camera
    goes on (a move on twos, a stop-and-go) stays a hold."""
    steps = np.diff(targets, axis=0)
    held: NDArray[np.bool_] = np.all(np.abs(steps) <= HOLD_POSE_TOL, axis=(1, 2))
    k = np.arange(1, held.size - 1)  # pairs with a pair on either side
    lone = k[held[k] & ~held[k - 1] & ~held[k + 1]]
    if lone.size:
        before, after = steps[lone - 1, :3], steps[lone + 1, :3]
        parts = np.stack([np.einsum("kij,kij->k", before[:, :, 3:], after[:, :, 3:]),
                          np.einsum("kij,kij->k", before[:, :, :3], after[:, :, :3])])
        turns = (parts < 0.0).any(axis=0) & ~(parts > 0.0).any(axis=0)
        held[lone[turns]] = False
    return held


REST_SPEED = 1e-3
"""[m/s] A camera end moving slower than this (and turning slower than :data:`REST_TURN`) is at
rest: an eased start or stop (the shipped samples, eased from and to rest, read 3e-17 to
2.5e-4 m/s at their ends; a camera creeping at a millimetre a second moves 40 µm a frame)."""
REST_TURN = math.radians(0.1)
"""[rad/s] The turning rate below which a camera end is at rest (with :data:`REST_SPEED`)."""
ROUND_OFF = 1e-12
"""[m or rad per frame] A velocity this small is round-off: at rest whatever the move's pace
(a pan alone has no pace in position)."""
REST_SHARE = 0.02
"""A camera end is at rest only where it also moves (and turns) slower than this share of the
move's largest step between frames: a creep at a constant half a millimetre a second is in
motion at its ends (held to rest there, its spline would start with a jerk the move never
has), an eased move's ends read 1e-4 of its pace and less."""
SETTLE_SHARE = 0.1
"""A camera end at rest has settled (eased in so that its acceleration fades too) where its
acceleration is below this share of the move's largest between frames (in position and in
turn). Eased moves' ends (the samples, the shot set's eased moves, a Maya-style quintic ease
of 48 frames) read 0.004 to 0.04 of it; a camera that starts or stops hard (a truck from
standstill, a cubic or cosine ease) reads about 1."""
SETTLE_ACCEL = 1e-2
"""[m/s^2] An end accelerating less than this (and turning less than :data:`SETTLE_TURN`)
has settled whatever the move's own acceleration: a run-up building it moves the camera by
well under a micrometre (and the shot's own round-off, float matrices in the file, is
larger than the share of a slow move's acceleration)."""
SETTLE_TURN = math.radians(0.5)
"""[rad/s^2] The turning acceleration below which an end has settled (:data:`SETTLE_ACCEL`)."""
END_FIT = (10, 5)
"""Frames and degree of the least-squares polynomial through an end frame that is the second
estimate of the camera's velocity and acceleration there (:func:`camera_rests`). The timing
stage's free-ended spline through the whole move is exact for moves up to a cubic (a whip
that starts as t^3 over 12 frames); this one for any ease that is a quintic (in position and
in angle) over its last ten frames, however short the move: the spline alone read a 1 s
quintic push-in of 30 cm at 24 fps as moving at 3 mm/s, and the run-up then swung the camera
4.9 cm before the first frame."""


def camera_rests(targets: Array, dt: float) -> tuple[int, int]:
    """How the camera (or flange) rests on the first / last frame, as :meth:`FramePath.fit
    <camtraj.timing.path.FramePath.fit>`'s levels.

    The camera's velocity and acceleration at an end frame are estimated twice: by the timing
    stage's spline through every frame (:mod:`camtraj.timing.path`, free ends) on the rows of
    the pose (rotation and translation), and by the least-squares polynomial through the end
    frame and the frames next to it (:data:`END_FIT`) on its position and rotation vector, where
    the shot has that many frames and the polynomial misses none of them by more than
    :data:`REST_SHARE` of the move's pace (an ease; a shake of a few frames' period is no
    polynomial); the end rests as the more restful of the two says. At rest (``AT_REST``): the
    velocity is below :data:`REST_SPEED` and :data:`REST_TURN`, and below :data:`REST_SHARE` of
    the move's own pace. Settled (``SETTLED``): at rest and the acceleration below
    :data:`SETTLE_SHARE` of the move's own, or below :data:`SETTLE_ACCEL` and
    :data:`SETTLE_TURN` (the camera eased in, not stopping hard). The robot rests there the same
    way (zero velocity on that frame, and zero acceleration where settled: no run-up or run-out
    swings the camera around a still first or last frame); ``FREE`` otherwise."""
    from camtraj.timing.path import AT_REST, FREE, SETTLED, end_jerk
    from camtraj.timing.quintic import solve_knot_derivatives

    n = targets.shape[0]
    if n < 3:
        return FREE, FREE
    coords = targets[:, :3, :].reshape(n, 12)  # rows of the pose: rotation and translation
    free = np.zeros(coords.shape, dtype=bool)
    zero = np.zeros(coords.shape)
    v, w = solve_knot_derivatives(coords, free, zero, zero, end_jerk(coords, free[1:]))
    # per end: (speed, turning rate, acceleration, turning acceleration), per frame
    spline: list[tuple[float, float, float, float]] = []
    for k in (0, n - 1):
        dd = w[k].reshape(3, 4)  # d2 pose / d frame2, measured as the frames' changes are
        spline.append((*_pose_rates(targets[k], v[k]), _largest(dd[None, :, 3]),
                       _largest(dd[None, :, :3]) / math.sqrt(2)))
    # the move's own pace and acceleration: its largest step and change of step between
    # frames, in position and in turn
    pos, rot = targets[:, :3, 3], targets[:, :3, :3]
    pace = (_largest(np.diff(pos, axis=0)), _largest(np.diff(rot, axis=0)) / math.sqrt(2))
    accel = (_largest(np.diff(pos, 2, axis=0)), _largest(np.diff(rot, 2, axis=0)) / math.sqrt(2))
    slow = (min(REST_SPEED * dt, max(REST_SHARE * pace[0], ROUND_OFF)),
            min(REST_TURN * dt, max(REST_SHARE * pace[1], ROUND_OFF)))
    calm = (max(SETTLE_SHARE * accel[0], SETTLE_ACCEL * dt * dt, ROUND_OFF),
            max(SETTLE_SHARE * accel[1], SETTLE_TURN * dt * dt, ROUND_OFF))
    # the local fit counts where it has frames to spare and describes them (an ease does, a
    # shake of a few frames' period does not): it misses none by more than REST_SHARE of
    # the pace
    fits: list[list[tuple[float, float, float, float]]] = [[spline[0]], [spline[1]]]
    if n >= END_FIT[0]:
        for side, rates in enumerate(_end_rates(targets)):
            if (rates[4] <= max(REST_SHARE * pace[0], ROUND_OFF)
                    and rates[5] <= max(REST_SHARE * pace[1], ROUND_OFF)):
                fits[side].append(rates[:4])
    out = []
    for side in range(2):
        level = FREE
        for speed, rate, acc, turn_acc in fits[side]:
            if speed <= slow[0] and rate <= slow[1]:
                level = max(level, SETTLED if acc <= calm[0] and turn_acc <= calm[1]
                            else AT_REST)
        out.append(level)
    return out[0], out[1]


def _end_rates(targets: Array) -> list[tuple[float, float, float, float, float, float]]:
    """Speed, turning rate, acceleration and turning acceleration (per frame, per frame^2) of
    poses (n, 4, 4), n >= :data:`END_FIT` frames, at the first and the last frame: those of
    the least-squares polynomial of :data:`END_FIT` through the end frame fitted to the
    positions and the rotation vectors from the end frame's orientation of the frames next to
    it; and how far the fit misses those frames, at most, in position and in turn."""
    from scipy.spatial.transform import Rotation

    frames, degree = END_FIT
    t = np.arange(1, frames, dtype=float)
    basis = np.stack([t ** p for p in range(1, degree + 1)], axis=1)
    out = []
    for poses in (targets[:frames], targets[::-1][:frames]):
        turn = Rotation.from_matrix(poses[0, :3, :3].T @ poses[1:, :3, :3]).as_rotvec()
        rows = np.concatenate([poses[1:, :3, 3] - poses[0, :3, 3], turn], axis=1)
        c = np.linalg.lstsq(basis, rows, rcond=None)[0]
        miss = rows - basis @ c
        out.append((float(np.linalg.norm(c[0, :3])), float(np.linalg.norm(c[0, 3:])),
                    float(np.linalg.norm(2.0 * c[1, :3])), float(np.linalg.norm(2.0 * c[1, 3:])),
                    _largest(miss[:, :3]), _largest(miss[:, 3:])))
    return out


def _largest(d: Array) -> float:
    """The largest norm over the first axis of ``d`` (k, ...), 0 for none."""
    return float(np.sqrt((d.reshape(d.shape[0], -1) ** 2).sum(axis=1)).max()) if d.size else 0.0


def _pose_rates(pose: Array, d: Array) -> tuple[float, float]:
    """The speed and turning rate of a first derivative ``d`` (12,) of the pose rows (3, 4)
    at ``pose`` (4, 4): its translation's norm and, from R^T dR (a skew matrix), the rate of
    turn."""
    dpose = d.reshape(3, 4)
    turn = pose[:3, :3].T @ dpose[:, :3]
    rate = 0.5 * math.hypot(turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0],
                            turn[1, 0] - turn[0, 1])
    return float(np.linalg.norm(dpose[:, 3])), rate


@dataclass(frozen=True)
class Candidates:
    """Every frame's candidate configurations, solved in closed form.

    Attributes:
        r1, r4: Track and extend of each candidate point (n, G) [m].
        interval: Which track interval (0 behind, 1 ahead of the target) each point is in (n, G).
        y: Measures of each point on each branch (n, G, 8, 10): the joint vector (revolute axes
            nearest home), then the wrist singularity and full-stretch distances [rad].
        ok: Feasibility (n, G, 8): inside every position limit and reachable.
        track_lo, track_hi: The reachable track intervals per frame (n, 2) [m].
    """

    r1: Array
    r4: Array
    interval: IntArray
    y: Array
    ok: NDArray[np.bool_]
    track_lo: Array
    track_hi: Array


def candidates(robot: Robot, targets: Array, n_track: int = 2, n_extend: int = 2) -> Candidates:
    """Candidate points per frame over the feasible region, solved on every branch.

    Args:
        robot: The robot.
        targets: Flange poses (n, 4, 4) [m].
        n_track: Track values per reachable interval, at the middles of equal parts (they move
            with the region from frame to frame).
        n_extend: Extend values per track value, likewise over its reach interval.

    The G = 2 n_track n_extend points of a frame are in a fixed order, so point g of one frame
    and of the next are "the same place" in the region.
    """
    n = targets.shape[0]
    wrist = targets[:, :3, 3]
    lo1, hi1 = track_intervals(robot.dh, wrist, float(robot.lower[TRACK]),
                               float(robot.upper[TRACK]), float(robot.lower[EXTEND]),
                               float(robot.upper[EXTEND]))
    reach = lo1 <= hi1
    span1 = np.where(reach, hi1 - lo1, 0.0)
    u1 = (np.arange(n_track) + 0.5) / n_track
    r1 = np.where(reach[..., None], lo1[..., None] + span1[..., None] * u1, 0.0)  # (n, 2, k)
    iv = np.broadcast_to(np.arange(2)[None, :, None], r1.shape).reshape(n, -1)
    ok1 = np.broadcast_to(reach[..., None], r1.shape).reshape(n, -1)
    r1 = r1.reshape(n, -1)
    region = Region(robot.dh, wrist.T[:, :, None], -math.inf, math.inf,
                    float(robot.lower[EXTEND]), float(robot.upper[EXTEND]), 0.0)
    lo4, hi4 = region.r4_interval(r1)  # (n, m)
    valid = ok1 & (lo4 <= hi4)
    u4 = (np.arange(n_extend) + 0.5) / n_extend
    r4 = lo4[..., None] + np.where(valid, hi4 - lo4, 0.0)[..., None] * u4
    r4 = np.where(valid[..., None], r4, 0.0)
    shape = (n, r1.shape[1] * n_extend)
    r1g = np.broadcast_to(r1[..., None], r4.shape).reshape(shape)
    r4g = r4.reshape(shape)
    interval = np.broadcast_to(iv[..., None], r4.shape).reshape(shape)
    valid_g = np.broadcast_to(valid[..., None], r4.shape).reshape(shape)
    y = np.empty((*shape, N_BRANCHES, N_MEASURES))
    ok = np.empty((*shape, N_BRANCHES), dtype=bool)
    per = max(1, _POINTS // shape[1])  # frames per block: the closed form's temporaries
    for a in range(0, n, per):
        e = min(a + per, n)
        yb, okb = measures(robot, np.repeat(targets[a:e], shape[1], axis=0),
                           r1g[a:e].ravel(), r4g[a:e].ravel(), robot.home)
        y[a:e] = yb.reshape(e - a, shape[1], N_BRANCHES, N_MEASURES)
        ok[a:e] = okb.reshape(e - a, shape[1], N_BRANCHES)
    ok &= valid_g[..., None]
    return Candidates(np.ascontiguousarray(r1g), r4g, np.ascontiguousarray(interval), y, ok,
                      lo1, hi1)


def measures(robot: Robot, targets: Array, r1: Array, r4: Array,
             previous: Array) -> tuple[Array, NDArray[np.bool_]]:
    """Closed-form solutions and their margin measures, one target per point.

    Args:
        robot: The robot.
        targets: Flange poses (N, 4, 4) [m].
        r1, r4: Track and extend (N,) [m].
        previous: Joint vector(s) (8,) or (N, 8) the revolute axes stay nearest to.

    Returns:
        ``y`` (N, 8 branches, 10) and feasibility (N, 8).
    """
    packed, ok = six_axis_packed(robot.dh, targets, r1, r4, previous,
                                 packed_limits(previous, robot.lower, robot.upper))
    q = packed[:, IDX]  # (N, 8, 8)
    sd = stretch_distance(robot.dh, targets[:, :3, 3], r1, r4)
    y = np.concatenate([q, wrist_distance(q[..., TILT])[..., None],
                        np.broadcast_to(sd[:, None, None], (*q.shape[:2], 1))], axis=-1)
    return y, ok


def branch_measures(robot: Robot, targets: Array, r1: Array, r4: Array, previous: Array,
                    branch: IntArray) -> tuple[Array, NDArray[np.bool_]]:
    """:func:`measures` on one given branch per point: ``y`` (N, 10), feasibility (N,)."""
    q, ok = six_axis_branch(robot.dh, targets, r1, r4, previous, robot.lower, robot.upper,
                            branch)
    sd = stretch_distance(robot.dh, targets[:, :3, 3], r1, r4)
    y = np.concatenate([q, wrist_distance(q[:, TILT])[:, None], sd[:, None]], axis=1)
    return y, ok


@dataclass(frozen=True)
class StepCosts:
    """The dynamic programme's step costs (n - 1, C, S, S), computed a block of frames at a
    time from the candidates: the whole table would hold (n - 1) C S^2 numbers (128 KiB a
    frame merged).

    ``states`` turns candidate values (frames, G, 8, ...) into the programme's states
    (frames, C, S, ...); ``chains``: (C, S); ``shared``: track and extend are the same in
    every chain; ``per``: frames per block; ``held`` (n - 1,): the frame pairs where the
    camera holds still, whose only step is to the same state (the robot holds still too).
    ``rankings``: the costs the programme ranks paths by; their steps are the first one's
    (they differ in margins and in the run-up and run-out room, which each adds itself).
    """

    rankings: tuple[ShotCost, ...]
    cand: Candidates
    states: Callable[[NDArray[Any]], NDArray[Any]]
    chains: tuple[int, int]
    shared: bool
    wrap: bool
    per: int
    held: NDArray[np.bool_] | None = None

    def block(self, a: int, e: int) -> list[Array]:
        """Step costs from frames a..e-1 to the next (e - a, C, S, S), one per ranking;
        infeasible states are left to their unary costs."""
        y, n = self.cand.y, self.cand.y.shape[0]
        c, s = self.chains
        pair = np.zeros((e - a, c, s, s))
        for i in range(8):
            # track and extend do not depend on the branch: one chain's values serve all
            qi = self.states(y[a:e + 1, :, :, i])
            if self.shared and not REVOLUTE[i]:
                qi = qi[:, :1]
            d = qi[1:, :, None, :] - qi[:-1, :, :, None]
            pair += self.rankings[0].axis_step_cost(i, d, self.wrap)
        if self.held is not None and self.held[a:e].any():
            # a hold of the camera (equal poses, so equal candidates) is a hold of the robot
            pair[self.held[a:e]] = np.where(np.eye(s, dtype=bool), pair[self.held[a:e]],
                                            np.inf)
        if a > 0 and e < n - 1:
            return [pair] * len(self.rankings)
        # run-up and run-out room at the shot's ends, a block of rows at a time (the cost's
        # temporaries are (C, rows, S, 8) each)
        rows = max(1, _CHUNK // max(c * s, 1))
        first, last = self.states(y[:2, :, :, :8]), self.states(y[-2:, :, :, :8])  # (2, C, S, 8)
        out = []
        for cost in self.rankings:
            ranked = pair.copy()
            for r in range(0, s, rows) if a == 0 else ():
                ranked[0, :, r:r + rows] += cost.edge_cost(first[0, :, r:r + rows, None, :],
                                                           first[1, :, None, :, :])
            for r in range(0, s, rows) if e == n - 1 else ():  # from state r, last but one
                ranked[-1, :, r:r + rows] += cost.edge_cost(last[-1, :, None, :, :],
                                                            last[-2, :, r:r + rows, None, :])
            out.append(ranked)
        return out


def chain_costs(cost: ShotCost | tuple[ShotCost, ...], cand: Candidates, merged: bool,
                wrap: bool = True,
                held: NDArray[np.bool_] | None = None) -> tuple[Array, StepCosts]:
    """The dynamic programme's tables (``held``: :attr:`StepCosts.held`), for one cost or
    for several rankings (:attr:`StepCosts.rankings`: then ``unary`` has a leading axis, one
    table per ranking).

    With ``wrap`` a revolute step is the shorter way round (the joint values of a state are
    one representative of its angle); without, it is the difference of the states' values
    as they stand (the values are the path: :func:`lanes`).

    Returns:
        ``unary`` (n, C, S), the margin cost of each state (inf where infeasible), and the
        first-order cost of each step (:class:`StepCosts`). Chains C are the branch labels
        that have a feasible state on every frame, with S = G candidate points each, or
        (``merged``) one chain of S = 8 G states.
    """
    n, g, b = cand.ok.shape
    shared = not merged  # every chain has the same candidate points (track, extend)
    alive = cand.ok.any(axis=1).all(axis=0)  # branch labels feasible on every frame

    def states(y: NDArray[Any]) -> NDArray[Any]:  # (frames, G, 8, ...) -> (frames, C, S, ...)
        y = y.swapaxes(1, 2)
        return y.reshape(y.shape[0], 1, b * g, *y.shape[3:]) if merged else y[:, alive]

    rankings = cost if isinstance(cost, tuple) else (cost,)
    ok = states(cand.ok)
    c, s = ok.shape[1:]
    unary = np.empty((len(rankings), n, c, s))  # block by block: the margin's temporaries
    per = max(1, _POINTS // max(c * s, 1))
    for a in range(0, n, per):
        y = states(cand.y[a:a + per])
        for k, ranking in enumerate(rankings):
            unary[k, a:a + per] = np.where(ok[a:a + per], ranking.unary(y), np.inf)
    steps = StepCosts(rankings, cand, states, (c, s), shared, wrap,
                      max(1, _CHUNK // max(c * s * s, 1)), held)
    return (unary if isinstance(cost, tuple) else unary[0]), steps


def viterbi(unary: Array, steps: StepCosts) -> tuple[Array, IntArray]:
    """Shortest path over frames, one per chain (one ranking: :func:`viterbi_each`).

    Args:
        unary: (n, C, S) state costs (inf: infeasible).
        steps: Step costs from state s at frame k to s' at frame k + 1 (the first n - 1
            frames' are used), a block at a time.

    Returns:
        The best total cost per chain (C,) and its states (C, n).
    """
    return viterbi_each(unary[None], steps)[0]


def viterbi_each(unary: Array, steps: StepCosts) -> list[tuple[Array, IntArray]]:
    """:func:`viterbi` for each of ``steps``' rankings at once (their step costs are computed
    once): ``unary`` (R, n, C, S), one (best, states) per ranking."""
    n, c, s = unary.shape[1:]
    acc = [u[0].copy() for u in unary]
    back = np.empty((len(acc), max(n - 1, 0), c, s), dtype=np.intp)
    rows = np.arange(c)[:, None]
    cols = np.arange(s)[None, :]
    for a in range(0, n - 1, steps.per):
        e = min(a + steps.per, n - 1)
        for r, pair in enumerate(steps.block(a, e)):
            for k in range(a, e):
                tot = acc[r][:, :, None] + pair[k - a]
                arg = np.argmin(tot, axis=1)
                back[r, k] = arg
                acc[r] = tot[rows, arg, cols] + unary[r, k + 1]
    out = []
    for r in range(len(acc)):
        path = np.empty((c, n), dtype=np.intp)
        path[:, -1] = np.argmin(acc[r], axis=1)
        best = acc[r][np.arange(c), path[:, -1]]
        for k in range(n - 2, -1, -1):
            path[:, k] = back[r, k][np.arange(c), path[:, k + 1]]
        out.append((best, path))
    return out


@dataclass(frozen=True)
class DPChoice:
    """The dynamic programme's answer.

    Attributes:
        cost: Its total first-order + margin cost.
        point: Candidate point per frame (n,), an index into :class:`Candidates`' G axis.
        branch: Closed-form branch per frame (n,).
        y: Measures of the chosen configurations (n, 10), joints unwrapped into a continuous
            path inside the limits where one fits.
    """

    cost: float
    point: IntArray
    branch: IntArray
    y: Array


def choose(cost: ShotCost, cand: Candidates, start: Array,
           held: NDArray[np.bool_] | None = None) -> DPChoice | None:
    """The dynamic programme's cheapest answer (:func:`choose_each`'s first), None when no
    sequence of candidates reaches every frame."""
    choices = choose_each(cost, cand, start, held)
    return choices[0] if choices else None


def choose_each(cost: ShotCost, cand: Candidates, start: Array,
                held: NDArray[np.bool_] | None = None) -> list[DPChoice]:
    """Run the dynamic programme: the cheapest path of each branch label that reaches every
    frame, cheapest first (one path over the merged chains if no label does; none if no
    sequence of candidates reaches every frame). Where the camera holds (``held`` (n - 1,),
    :func:`camera_holds`) the path stays on its state: the robot holds still.

    Revolute steps are first taken the shorter way round; if a chosen path, made
    continuous, cannot stay inside the position limits (a rotation of more than the range
    allows), the programme runs again on the candidates as :func:`lanes` (values that are
    the path itself, inside the limits) and that label's path is taken from there, so every
    answer is inside the limits: an unavoidable wrap shows as the large step it is.
    """
    return choose_ranked((cost,), cand, start, held)[0]


def choose_ranked(rankings: tuple[ShotCost, ...], cand: Candidates, start: Array,
                  held: NDArray[np.bool_] | None = None) -> list[list[DPChoice]]:
    """:func:`choose_each` for each of several rankings of the same candidates (costs that
    differ in their margins and ends' room, :attr:`StepCosts.rankings`), their step costs
    computed once: one list of answers per ranking."""
    lower, upper = rankings[0].lower, rankings[0].upper
    laned: list[dict[int, DPChoice]] | None = None
    result = []
    for r, choices in enumerate(_choose(rankings, cand, wrap=True, held=held)):
        out: list[DPChoice] = []
        for choice in choices:
            y = choice.y.copy()
            y[:, :8] = unwrap_into_limits(y[:, :8], lower, upper, start)
            if inside_limits(y[:, :8], lower, upper):
                out.append(DPChoice(choice.cost, choice.point, choice.branch, y))
                continue
            if laned is None:
                again = replace(cand, y=lanes(cand.y, lower, upper, start))
                laned = [{int(c.branch[0]): c for c in ranked}
                         for ranked in _choose(rankings, again, wrap=False, held=held)]
            if int(choice.branch[0]) in laned[r]:
                out.append(laned[r][int(choice.branch[0])])
        result.append(sorted(out, key=lambda c: c.cost))
    return result


def _choose(rankings: tuple[ShotCost, ...], cand: Candidates, wrap: bool,
            held: NDArray[np.bool_] | None = None) -> list[list[DPChoice]]:
    """Per ranking, the cheapest path of each label that reaches every frame (else of the
    merged chains), cheapest first."""
    n, g = cand.r1.shape
    for merged in (False, True):
        unary, steps = chain_costs(rankings, cand, merged, wrap, held)
        labels = (np.zeros(1, dtype=np.intp) if merged
                  else np.flatnonzero(cand.ok.any(axis=1).all(axis=0)))
        outs = []
        for best, path in viterbi_each(unary, steps):
            out = []
            for c in np.argsort(best, kind="stable"):
                if not math.isfinite(best[c]):
                    break
                states = path[c]
                branch = states // g if merged else np.full(n, labels[c])
                point = states % g if merged else states
                y = cand.y[np.arange(n), point, branch].copy()
                out.append(DPChoice(float(best[c]), point, branch, y))
            outs.append(out)
        if all(outs):  # the rankings share their feasible paths: all or none
            return outs
    return [[] for _ in rankings]


def inside_limits(q: Array, lower: Array, upper: Array) -> bool:
    """Whether every frame of a path (n, 8) is inside the position limits (to round-off)."""
    return bool(np.all((q >= lower - EDGE) & (q <= upper + EDGE)))


def lanes(y: Array, lower: Array, upper: Array, start: Array) -> Array:
    """Candidate measures (n, G, 8, 10) with each revolute value made continuous along the
    frames of its lane (the same point and branch), shifted by whole turns to fit the limits
    best (nearest ``start`` among equals) and folded back inside where it still leaves them.
    """
    out = y.copy()
    g, b = y.shape[1:3]
    for i in np.flatnonzero(REVOLUTE):
        col = np.unwrap(y[..., i], axis=0)  # (n, G, 8)
        best_key = np.full((g, b), np.inf)
        best = col.copy()
        for m in range(-2, 3):
            c = col + TWO_PI * m
            over = (np.maximum(c - upper[i], 0) + np.maximum(lower[i] - c, 0)).sum(axis=0)
            key = over * 1e3 + np.abs(c[0] - start[i])
            better = key < best_key
            best_key = np.where(better, key, best_key)
            best = np.where(better[None], c, best)
        folded = best.copy()
        for shift in (1, 2):  # the nearest whole turns back inside, where one is
            for sign in (-1.0, 1.0):
                c = best + sign * shift * TWO_PI
                fits = (c >= lower[i]) & (c <= upper[i])
                outside = (folded < lower[i]) | (folded > upper[i])
                folded = np.where(outside & fits, c, folded)
        out[..., i] = folded
    return out


def unwrap_into_limits(q: Array, lower: Array, upper: Array, start: Array) -> Array:
    """Revolute columns made continuous, each shifted by whole turns into its limits (the
    shift nearest ``start`` among those that fit best)."""
    out = q.copy()
    for i in np.flatnonzero(REVOLUTE):
        col = np.unwrap(q[:, i])
        best: tuple[float, float, int] | None = None
        for m in range(-3, 4):
            c = col + 2.0 * math.pi * m
            over = float(np.maximum(c - upper[i], 0).sum() + np.maximum(lower[i] - c, 0).sum())
            key = (over, abs(float(c[0]) - float(start[i])), m)
            if best is None or key < best:
                best = key
        assert best is not None
        out[:, i] = col + 2.0 * math.pi * best[2]
    return out
