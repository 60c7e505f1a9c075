"""The joint path between frames: spline maths, shot edges and position limits.

Facts used:
* scipy's B-spline interpolation (an independent implementation) gives the same quintic
  spline for the same end conditions;
* a disturbance of one frame must not move the path's acceleration or jerk more at a free end
  than it does in the interior (the shot-edge spikes of issue 7);
* divided differences of the servo samples are weighted means of the derivatives, so they
  must stay inside the limits whatever the spline's own derivatives say;
* the position limits hold at every servo sample and on a dense grid between frames.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray
from scipy.interpolate import make_interp_spline

from camtraj.robot import JOINT_NAMES
from camtraj.timing import Limits, Take, TimingLimitError, time_shot
from camtraj.timing.path import FramePath
from camtraj.timing.quintic import hermite_coefficients, solve_knot_derivatives
from tests.timing_checks import FPS, HOME, SLACK, divided

Array = NDArray[np.float64]
TRACK, LIFT, EXTEND, ELBOW, TILT = (JOINT_NAMES.index(a) for a in
                                    ("track", "lift", "extend", "elbow", "tilt"))


def assert_inside_by_differences(take: Take, limits: Limits) -> None:
    tol = 1e-12 * (limits.upper - limits.lower)
    assert np.all(take.q <= limits.upper + tol)
    assert np.all(take.q >= limits.lower - tol)
    for order, bound in ((1, limits.velocity), (2, limits.acceleration)):
        worst = np.max(np.abs(divided(take.t, take.q, order)) / bound)
        assert worst <= 1 + SLACK, f"order {order}: {worst:.6f} of the limit"


# ---------------------------------------------------------------------------------------------
# The spline solver
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [3, 4, 7, 30, 257])
def test_spline_matches_scipy(n: int) -> None:
    rng = np.random.default_rng(n)
    y = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    clamped = np.zeros((n, 3), dtype=bool)
    v_given = np.zeros((n, 3))
    w_given = np.zeros((n, 3))
    clamped[[0, -1], 1] = True  # column 1 clamped at both ends, column 2 at its start
    v_given[[0, -1], 1] = (0.3, 1.1)
    w_given[[0, -1], 1] = (-0.2, 0.5)
    clamped[0, 2] = True
    v_given[0, 2] = 0.7
    jerk = rng.normal(size=(2, 3))
    snap = rng.normal(size=(2, 3))
    v, w = solve_knot_derivatives(y, clamped, v_given, w_given, jerk, snap)
    x = np.arange(n, dtype=np.float64)
    bcs = [
        ([(3, jerk[0, 0]), (4, snap[0, 0])], [(3, jerk[1, 0]), (4, snap[1, 0])]),
        ([(1, 0.3), (2, -0.2)], [(1, 1.1), (2, 0.5)]),
        ([(1, 0.7), (2, 0.0)], [(3, jerk[1, 2]), (4, snap[1, 2])]),
    ]
    for j, bc in enumerate(bcs):
        ref = make_interp_spline(x, y[:, j], k=5, bc_type=bc)
        scale = 1 + np.abs(y[:, j]).max()
        assert np.max(np.abs(ref(x, 1) - v[:, j])) < 1e-11 * scale
        assert np.max(np.abs(ref(x, 2) - w[:, j])) < 1e-11 * scale
    # Clamped knots keep their given derivatives bit for bit (exact by construction).
    assert np.array_equal(v[clamped], v_given[clamped])
    assert np.array_equal(w[clamped], w_given[clamped])
    c = hermite_coefficients(y, v, w)
    assert np.array_equal(c[:, 0], y[:-1])


def _peak(path: FramePath, order: int) -> Array:
    """Peak |d^order q / dx^order| per frame interval on a dense grid, (n - 1,) for axis 0."""
    n = path.n
    x = np.linspace(0.0, n - 1.0, 64 * (n - 1) + 1)
    values = np.abs(path.at(x, order)[order][:, 0])
    piece = np.minimum(np.floor(x).astype(int), n - 2)
    return np.array([values[piece == i].max() for i in range(n - 1)])


def test_a_disturbed_end_frame_moves_the_path_no_more_than_an_interior_one() -> None:
    # One frame of an axis moving at constant speed is moved by 1. The path is linear in the
    # frames and reproduces the straight line, so what changes is the disturbance's response.
    n = 40
    lower, upper = np.full(8, -1e9), np.full(8, 1e9)
    base = np.outer(np.arange(n, dtype=np.float64), np.ones(8))  # in motion at both ends

    def response(k: int) -> tuple[float, float]:
        q = base.copy()
        q[k, 0] += 1.0
        path = FramePath.fit(q, 1.0, lower, upper)
        return float(_peak(path, 2).max()), float(_peak(path, 3).max())

    acc_in, jerk_in = response(n // 2)
    for k in (0, 1, 2, 3, 5, n - 6, n - 4, n - 3, n - 2, n - 1):
        acc, jerk = response(k)
        assert acc <= 1.15 * acc_in, f"frame {k}: acceleration {acc:.2f} vs {acc_in:.2f}"
        assert jerk <= 1.01 * jerk_in, f"frame {k}: jerk {jerk:.2f} vs {jerk_in:.2f}"


# ---------------------------------------------------------------------------------------------
# Shot edges
# ---------------------------------------------------------------------------------------------


def in_motion(seconds: float, kink_at: tuple[int, ...], eps: float) -> tuple[Array, Array]:
    """A camera moving along the track at constant speed with a slow tilt, starting and
    ending in motion, with an IK-like disturbance of ``eps`` rad on the elbow at frames
    ``kink_at`` (e.g. where the redundancy choice switches)."""
    n = int(seconds * FPS) + 1
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = 3.0 + 0.8 * t
    q[:, TILT] = -0.1 + math.radians(8.0) * t
    q[:, ELBOW] = -1.5 + 0.25 * np.sin(0.9 * t + 0.4)
    q[:, LIFT] = 0.1 * np.cos(0.7 * t)
    for k in kink_at:
        q[k % n, ELBOW] += eps
    return t, q


@pytest.mark.parametrize("seconds", [1.0, 2.0])
@pytest.mark.parametrize("eps", [2e-4, 3e-4])
def test_short_moves_in_motion_fit_at_their_edges_when_their_interior_fits(
    limits: Limits, seconds: float, eps: float
) -> None:
    n = int(seconds * FPS) + 1
    t, q = in_motion(seconds, (n // 2,), eps)
    interior = time_shot(q, t, limits)  # the disturbance mid-shot fits at shot timing
    need = 1.0 / interior.report.max_speed
    assert 0.8 < need < 1.0
    for kinks in ((1, n - 2), (2, n - 3), (0, n - 1), (3, n - 4)):
        t, q = in_motion(seconds, kinks, eps)
        take = time_shot(q, t, limits)  # raises if an edge does not fit
        assert 1.0 / take.report.max_speed <= need * (1 + 1e-6), kinks
        a, b = take.frame_samples[0], take.frame_samples[-1]
        assert np.max(np.abs(take.q[take.frame_samples] - q)) < 1e-12
        # The servo stream itself, across the run-up and run-out joins: every divided
        # difference (a mean of the true derivative) is inside the limits.
        assert_inside_by_differences(take, limits)
        assert a > 0
        assert b < take.t.size - 1  # starts and ends in motion: run-up and run-out


# ---------------------------------------------------------------------------------------------
# Position limits between frames
# ---------------------------------------------------------------------------------------------


def touching_extend_limit(peak: float, width: float, tp: float) -> tuple[Array, Array]:
    """A fast track move (1.6 m/s) during which the arm reaches out to its 1.5 m limit:
    a bump towards ``peak`` clipped at 1.5 m, as a solver riding the limit writes it."""
    n = 49
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = 3.0 + 1.6 * t
    q[:, EXTEND] = np.minimum(1.5, 1.0 + (peak - 1.0) * np.exp(-(((t - tp) / width) ** 2)))
    q[:, ELBOW] = -1.5 + 0.3 * np.sin(1.3 * t)
    return t, q


@pytest.mark.parametrize(
    ("peak", "width", "tp", "at_limit"),
    [(1.52, 0.3, 0.77, 2), (1.51, 0.15, 0.76, 1), (1.505, 0.2, 0.771, 0)],
)
def test_frames_touching_a_limit_convert_with_scale(
    limits: Limits, peak: float, width: float, tp: float, at_limit: int
) -> None:
    t, q = touching_extend_limit(peak, width, tp)
    upper = float(limits.upper[EXTEND])
    assert np.sum(q[:, EXTEND] == upper) == at_limit
    assert np.all(q[:, EXTEND] <= upper)
    take = time_shot(q, t, limits, mode="scale")
    assert np.max(np.abs(take.q[take.frame_samples] - q)) < 1e-12
    assert_inside_by_differences(take, limits)
    assert np.all(np.abs(take.qd) <= limits.velocity * (1 + 1e-9))
    assert np.all(np.abs(take.qdd) <= limits.acceleration * (1 + 1e-9))
    # Between frames, on a grid far finer than any servo rate, the path stays inside.
    path = FramePath.fit(q, 1 / FPS, limits.lower, limits.upper)
    x = np.linspace(0.0, q.shape[0] - 1.0, 1000 * (q.shape[0] - 1) + 1)
    dense = path.at(x, 0)[0]
    assert np.all(dense <= limits.upper) and np.all(dense >= limits.lower)
    # Only knots next to the overshoot were changed; far from the limit the path is the
    # plain spline (C4: the jerk is continuous across frames).
    changed = np.flatnonzero(path.clamped_for_limits[:, EXTEND])
    assert changed.size > 0
    assert np.all(np.abs(q[changed, EXTEND] - upper) < 0.02)


def test_a_frame_beyond_a_limit_is_still_reported(limits: Limits) -> None:
    t, q = touching_extend_limit(1.52, 0.3, 0.77)
    q[18, EXTEND] = 1.5 + 1e-3
    with pytest.raises(TimingLimitError, match=r"extend position 1\.5 m is beyond its upper"):
        time_shot(q, t, limits, mode="scale")


# ---------------------------------------------------------------------------------------------
# Run-up and run-out extents
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["stop", "start"])
def test_move_range_is_exact(limits: Limits, kind: str) -> None:
    from camtraj.timing.edges import _Move, _stop_move

    rng = np.random.default_rng(3)
    zero = np.zeros(8)
    for _ in range(20):
        p = rng.uniform(-1.0, 1.0, 8)
        v = rng.uniform(-1.0, 1.0, 8) * limits.velocity
        a = rng.uniform(-1.0, 1.0, 8) * limits.acceleration
        if kind == "stop":
            move = _stop_move(p, v, a, limits)
        else:  # from rest at a start position into the state (p, v / 2, a / 2)
            start = p + rng.uniform(-0.5, 0.5, 8)
            move = _Move((start, zero, zero), (p, 0.5 * v, 0.5 * a), limits, stop=False,
                         what="a test run-up")
        # ruckig's own evaluation on a dense grid: inside the computed range, and reaching
        # it to within what the grid can resolve (an extreme inside a step is where the
        # velocity is zero, so the nearest sample is within a_max * step² / 2 of it).
        t = np.linspace(0.0, move.duration, 4001)
        pos, _, _, _ = move.sample(t)
        step = move.duration / 4000
        assert np.all(pos >= move.min - 1e-12) and np.all(pos <= move.max + 1e-12)
        tol = 0.5 * limits.acceleration * step**2 + 1e-12
        assert np.all(pos.min(axis=0) - move.min <= tol)
        assert np.all(move.max - pos.max(axis=0) <= tol)


def test_a_shot_ending_at_full_speed_while_accelerating_is_slowed_for_its_run_out(
    limits: Limits,
) -> None:
    # The track accelerates at 1.5 m/s² right up to the last frame, reaching 1.95 m/s of
    # its 2 m/s: every frame fits, but no jerk-limited stop from there stays under 2 m/s.
    n = 49
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = 3.0 + (1.95 - 1.5 * t[-1]) * t + 0.75 * t**2
    with pytest.raises(TimingLimitError, match=r"run-out from frame 48 would need track "
                       r"velocity 2\.\d+ m/s, beyond 2 m/s.*try --timing scale"):
        time_shot(q, t, limits)
    take = time_shot(q, t, limits, mode="scale")
    assert take.speed_factor > 1.0
    assert np.all(np.abs(take.qd) <= limits.velocity * (1 + 1e-9))
    v = divided(take.t, take.q, 1)
    assert np.max(np.abs(v) / limits.velocity) <= 1 + SLACK


@pytest.mark.parametrize("seed", range(6))
def test_random_paths_pass_every_frame_hold_still_and_stay_inside(seed: int) -> None:
    # Random walks with holds, squeezed into a narrow range so that many frames sit on or
    # next to a limit (clipped at it, as a solver riding the limit writes them).
    rng = np.random.default_rng(seed)
    n = 120
    lower, upper = np.full(8, -0.05), np.full(8, 0.05)
    steps = (rng.normal(scale=0.02, size=(n, 8)) * (rng.random((n, 8)) > 0.2)
             * (rng.random((n, 1)) > 0.15))  # some frame pairs where the whole robot holds
    q = np.clip(np.cumsum(steps, axis=0), lower, upper)
    path = FramePath.fit(q, 1 / FPS, lower, upper)
    x = np.linspace(0.0, n - 1.0, 200 * (n - 1) + 1)
    p = path.at(x, 2)
    assert np.all(p[0] <= upper) and np.all(p[0] >= lower)
    assert np.array_equal(p[0][::200], q)
    # The plain spline (the same frames with the limits out of the way) does overshoot.
    plain = FramePath.fit(q, 1 / FPS, lower - 1.0, upper + 1.0).at(x, 0)[0]
    assert np.any(plain > upper) or np.any(plain < lower)
    assert np.any(path.clamped_for_limits)
    # Where two frames are equal on every axis the robot stands exactly still between them.
    held = np.flatnonzero(np.all(q[1:] == q[:-1], axis=1))
    assert held.size > 0
    for i in held:
        seg = slice(200 * i, 200 * (i + 1) + 1)
        assert np.all(p[0][seg] == q[i])
        assert np.all(p[1][seg] == 0.0)
    # Acceleration is continuous across frames (the path is C2 everywhere).
    left = path.at(np.arange(1, n) - 1e-9, 2)[2]
    right = path.at(np.arange(1, n, dtype=np.float64), 2)[2]
    assert np.allclose(left, right, atol=1e-6 * (1 + np.abs(right).max()))


@pytest.mark.parametrize("rest", [(True, False), (False, True), (True, True)])
def test_an_end_at_rest_reproduces_a_move_eased_from_rest(rest: tuple[bool, bool]) -> None:
    """A cubic with zero slope at an end (a move eased from or to rest) is reproduced exactly
    by the spline with that end at rest (velocity zero, acceleration free, jerk that of the
    least-squares cubic through the end frames), and the velocity there is zero; a
    free end gives the same curve (it reproduces any cubic), so resting costs such a move
    nothing. (An end clamped to rest, acceleration zero as well, fails here: the smoothstep
    starts accelerating; the test below fails where the rest condition is ignored.)"""
    t = np.arange(30, dtype=float)
    if rest == (True, True):  # zero slope at both ends: the smoothstep
        y = 3 * (t / 29) ** 2 - 2 * (t / 29) ** 3
    elif rest[0]:
        y = 0.01 * t ** 2 + 0.0004 * t ** 3
    else:
        y = 0.01 * (29 - t) ** 2 - 0.0003 * (29 - t) ** 3
    q = np.tile(y[:, None], (1, 8)) + HOME
    mask = np.repeat(np.array(rest)[:, None], 8, axis=1)
    big = np.full(8, 1e3)
    path = FramePath.fit(q, 1.0 / FPS, -big, big, None, mask)
    x = np.linspace(0, 29, 291)
    want = [np.polynomial.polynomial.polyval(x, c) for c in _cubic_derivatives(y)]
    got = path.at(x, 3)
    for k in range(4):
        assert np.abs(got[k][:, 0] - (want[k] + (HOME[0] if k == 0 else 0.0))).max() <= 1e-9
    for end, at_rest in zip((0, -1), rest, strict=True):
        if at_rest:
            assert np.abs(path.at(np.array([0.0, 29.0]), 1)[1][end]).max() <= 1e-12


def test_a_settled_end_is_clamped_still_and_reproduces_a_quintic_ease() -> None:
    """Settled ends (velocity and acceleration zero) reproduce the quintic ease from rest to
    rest (whose velocity and acceleration vanish at both ends) exactly; at rest (velocity
    only) on the same frames the spline starts with an acceleration the ease does not have."""
    from camtraj.timing.path import AT_REST, SETTLED

    n = 48
    u = np.arange(n) / (n - 1.0)
    y = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
    q = np.tile(y[:, None], (1, 8)) + HOME
    big = np.full(8, 1e3)
    settled = FramePath.fit(q, 1.0 / FPS, -big, big, None, np.full((2, 8), SETTLED))
    at_rest = FramePath.fit(q, 1.0 / FPS, -big, big, None, np.full((2, 8), AT_REST))
    x = np.linspace(0.0, n - 1.0, 10 * (n - 1) + 1)
    s = x / (n - 1.0)
    want = [10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5,
            (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / (n - 1.0),
            (60 * s - 180 * s ** 2 + 120 * s ** 3) / (n - 1.0) ** 2,
            (60 - 360 * s + 360 * s ** 2) / (n - 1.0) ** 3]
    got = settled.at(x, 3)
    for k in range(4):
        scale = np.abs(want[k]).max()
        assert np.abs(got[k][:, 0] - (want[k] + (HOME[0] if k == 0 else 0.0))).max() \
            <= 1e-9 * scale, k
    ends = np.array([0.0, n - 1.0])
    for d in (1, 2):
        assert np.abs(settled.at(ends, 2)[d]).max() <= 1e-15
    assert np.abs(at_rest.at(ends, 2)[1]).max() <= 1e-15
    assert np.abs(at_rest.at(ends, 2)[2]).max() > 1e-3 * np.abs(want[2]).max()


def _cubic_derivatives(y: Array) -> list[Array]:
    """The coefficients of the cubic through y (at 0, 1, ...) and of its first three
    derivatives."""
    c = np.polynomial.polynomial.polyfit(np.arange(y.size, dtype=float), y, 3)
    out = [c]
    for _ in range(3):
        out.append(np.polynomial.polynomial.polyder(out[-1]))
    return out


def test_an_end_at_rest_has_zero_velocity_where_a_free_end_moves(limits: Limits) -> None:
    """A path that already moves on its first and last frame (every axis, a sine), fitted
    with both ends at rest: the velocity there is zero (a free end's is the path's own, far
    from it), the acceleration stays free, and every frame is passed exactly; timed so, the
    run-up and run-out are far shorter than with free ends (they only build and take off the
    end's acceleration)."""
    n = 60
    t = np.arange(n) / FPS
    q = HOME + 0.05 * np.sin(2 * np.pi * t[:, None] / t[-1] + np.arange(8) * 0.3)
    rest = np.ones((2, 8), dtype=bool)
    big = np.full(8, 1e3)
    path = FramePath.fit(q, 1.0 / FPS, -big, big, None, rest)
    free = FramePath.fit(q, 1.0 / FPS, -big, big)
    ends = np.array([0.0, n - 1.0])
    assert np.abs(path.at(ends, 1)[1]).max() <= 1e-12
    assert np.abs(free.at(ends, 1)[1]).max() > 1e-3
    assert np.abs(path.at(ends, 2)[2]).max() > 1e-4  # the acceleration is left free
    np.testing.assert_array_equal(path.at(np.arange(n, dtype=float), 0)[0], q)
    still = time_shot(q, t, limits, mode="scale", rest=rest).report
    moving = time_shot(q, t, limits, mode="scale").report
    for side in ("runup", "runout"):
        assert getattr(still, side)["duration"] < 0.5 * getattr(moving, side)["duration"], side


def test_what_sets_the_maximum_feasible_speed_is_named(limits: Limits) -> None:
    """The report names what sets the maximum feasible speed: the run-out where the track
    ends at nearly full speed (the shot itself uses 97.5% of its velocity limit, so it alone
    would allow 1.03x: the take's speed is below that), else the axis and quantity whose
    use needs the slowest take (use^(1/k) for the k-th derivative, from the report's own
    peak use)."""
    n = 49
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = 3.0 + (1.95 - 1.5 * t[-1]) * t + 0.75 * t**2
    rep = time_shot(q, t, limits, mode="scale").report
    assert rep.max_speed < 1.0 / rep.peak_use["track"]["velocity"]
    assert rep.set_by == "the run-out from frame 48: track's velocity limit", rep.set_by
    # a sine on two axes, one fast: its acceleration or jerk (whichever needs the slower
    # take) sets the speed
    q = np.tile(HOME, (n, 1))
    q[:, 5] += 0.3 * np.sin(2 * np.pi * t / t[-1]) ** 2
    q[:, 6] += 0.05 * np.sin(2 * np.pi * t / t[-1]) ** 2
    rep = time_shot(q, t, limits).report  # at the shot's own timing: its own peak use
    need = {(axis, k): use[k] ** (1.0 / p) for axis, use in rep.peak_use.items()
            for k, p in (("velocity", 1), ("acceleration", 2), ("jerk", 3))}
    axis, quantity = max(need, key=need.__getitem__)
    assert rep.set_by == f"{axis} {quantity}"
    assert rep.max_speed == pytest.approx(1.0 / need[(axis, quantity)], rel=1e-6)
