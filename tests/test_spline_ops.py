"""The refinement's model of the take against the timing stage itself.

The shot objective lowers the peak use of the limits along the spline the timing stage moves
on; its banded operators must give that spline's derivatives, and the refinement's gradient
must be the derivative of what it minimises.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from camtraj import Robot
from camtraj.ik.refine import _normal_equations
from camtraj.ik.shot_cost import ShotCost
from camtraj.ik.spline_ops import hold_runs, spline_ops
from camtraj.timing import Limits
from camtraj.timing.path import FramePath


def smooth_path(robot: Robot, n: int, seed: int, u: np.ndarray | None = None) -> np.ndarray:
    """A path of n frames well inside the limits, every axis moving (no holds); ``u`` (n,):
    where on the path (0 to 1) each frame is (default evenly spread)."""
    rng = np.random.default_rng(seed)
    t = (np.linspace(0.0, 1.0, n) if u is None else u)[:, None]
    mid = 0.5 * (robot.lower + robot.upper)
    half = 0.5 * (robot.upper - robot.lower)
    waves = sum(rng.uniform(-0.1, 0.1, 8) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6, 8))
                for f in (0.5, 1.3, 3.1))
    return mid + half * (0.2 * t + waves)


@pytest.mark.parametrize("n", [3, 4, 5, 40, 150, 400])
def test_operators_give_the_timing_stages_spline(robot: Robot, n: int) -> None:
    """Velocity, acceleration and jerk at every knot and piece middle, per knot interval^k:
    the operators against FramePath's own polynomials (cut to a band of 14 frames: within 3%
    of the axis's largest value)."""
    q = smooth_path(robot, n, n)
    limits = Limits.from_robot(robot)
    path = FramePath.fit(q, 1.0 / 24.0, limits.lower, limits.upper)
    knots = np.arange(n, dtype=float)
    mids = np.arange(n - 1) + 0.5
    ops = spline_ops(n)
    values = ops.apply(q)
    for i, (order, rows) in enumerate(zip(ops.orders, ops.rows, strict=True)):
        x = knots if rows == n else mids
        want = path.at(x, 3)[order]
        got = values[:rows, :, i]
        scale = np.abs(want).max(axis=0)
        assert np.all(np.abs(got - want) <= 0.03 * scale + 1e-12), (order, n)
        assert not values[rows:, :, i].any()


@pytest.mark.parametrize(("n", "held_pairs"), [
    (40, [(15, 22)]),  # a hold in the middle
    (150, [(0, 9), (60, 61), (100, 149)]),  # holding at the start, one pair, to the end
    (200, [(20, 30), (33, 40)]),  # a stretch of four frames between two holds
])
def test_operators_with_holds_give_the_timing_stages_spline(
        robot: Robot, n: int, held_pairs: list[tuple[int, int]]) -> None:
    """Where the camera holds, the robot holds (equal frames), and the timing stage fits each
    moving stretch as its own spline, clamped to rest next to a hold: the operators give that
    spline too (jerk at a hold's first frame is the stretch's, as the servo samples before
    it see it; the hold's own piece there has none)."""
    q = smooth_path(robot, n, n)
    held = np.zeros(n - 1, dtype=bool)
    for a, b in held_pairs:
        held[a:b] = True
        q[a + 1:b + 1] = q[a]
    runs = hold_runs(held)
    assert runs == tuple(held_pairs)
    limits = Limits.from_robot(robot)
    path = FramePath.fit(q, 1.0 / 24.0, limits.lower, limits.upper, held)
    knots = np.arange(n, dtype=float)
    mids = np.arange(n - 1) + 0.5
    ops = spline_ops(n, runs)
    values = ops.apply(q)
    for i, (order, rows) in enumerate(zip(ops.orders, ops.rows, strict=True)):
        x = knots if rows == n else mids
        if rows == n:  # a hold's first frame: just before it, on the stretch's last piece
            first = np.array([a for a, _ in runs if a > 0])
            x[first] -= 1e-9
        want = path.at(x, 3)[order]
        got = values[:rows, :, i]
        scale = np.abs(want).max(axis=0)
        assert np.all(np.abs(got - want) <= 0.03 * scale + 1e-12), (order, n)
        for a, b in runs:  # no use inside a hold
            assert not got[a + 1:b].any() and (rows == n or not got[a:b].any())


@pytest.mark.parametrize("held", [False, True])
def test_a_long_smooth_move_far_from_zero_shows_only_its_own_derivatives(
        robot: Robot, held: bool) -> None:
    """A minute-long eased move of 5 m of track starting 1 m out, free or held still for three
    frames at each end: in the middle of the move, where the spline's acceleration and jerk
    are small, the operators give them to 1% of their own size there. Cut to the band, the
    held move's rows read the move's velocity as jerk 2,000 times the spline's own (and
    the refinement lowered that phantom instead of the take's use)."""
    n = 1440
    s = 0.5 - 0.5 * np.cos(np.pi * np.arange(n) / (n - 1))
    q = np.tile(0.5 * (robot.lower + robot.upper), (n, 1))
    q[:, 0] = 1.0 + 5.0 * s
    q[:, 3] = 0.3 + 0.5 * s
    hold = np.zeros(n - 1, dtype=bool)
    if held:
        hold[:3] = hold[-3:] = True
        q[1:4], q[-4:-1] = q[0], q[-1]
    limits = Limits.from_robot(robot)
    path = FramePath.fit(q, 1.0 / 24.0, limits.lower, limits.upper, hold)
    ops = spline_ops(n, hold_runs(hold))
    values = ops.apply(q)
    middle = slice(60, n - 60)
    for i, order in enumerate(ops.orders):
        x = np.arange(n, dtype=float) if ops.rows[i] == n else np.arange(n - 1) + 0.5
        want = path.at(x, 3)[order][middle]
        got = values[:ops.rows[i]][middle, :, i]
        for axis in (0, 3):
            scale = np.abs(want[:, axis]).max()
            assert np.abs(got[:, axis] - want[:, axis]).max() <= 0.01 * scale, (order, axis)


def test_refinement_gradient_is_the_derivative_of_its_objective(robot: Robot) -> None:
    """Directional derivatives of ``refine_total`` along random directions in the measures
    (through a random Jacobian) against the normal equations' gradient."""
    n = 120
    q = smooth_path(robot, n, 7)
    rng = np.random.default_rng(3)
    y = np.concatenate([q, np.full((n, 2), 0.2)], axis=1)  # margins inside their zones
    G = rng.normal(size=(n, 10, 2)) * 1e-2
    base = ShotCost.for_robot(robot, 1.0 / 24.0)
    for power in (6.0, 24.0):
        cost = dataclasses.replace(base, power=power, scale=base.peak(q))
        _, g, _, _ = _normal_equations(cost, y, G)
        j0 = cost.refine_total(y)
        for _ in range(3):
            d = rng.normal(size=(n, 2))
            # the step balances the difference's truncation (h^2) against its round-off
            # (eps j0 / h: j0 ~ 90 against a derivative ~ 1e-3, so at h = 1e-7 the round-off
            # alone was 1e-4 of it, and SSE-only maths kernels failed the test)
            h = 1e-5
            yp = y + np.einsum("kmp,kp->km", G, h * d)
            ym = y - np.einsum("kmp,kp->km", G, h * d)
            numeric = (cost.refine_total(yp) - cost.refine_total(ym)) / (2 * h)
            assert numeric == pytest.approx(float((g * d).sum()), rel=1e-4, abs=1e-9 * j0)


@pytest.mark.parametrize("n", [30, 150])
def test_gathered_gradient_and_curvature_equal_the_dense_sums(n: int) -> None:
    """The banded gather of the refinement's normal equations against the plain sums over
    every operator row: frame f's gradient sum_r C[r, f] dz[r], the pair (f, f + d)'s
    curvature sum_r C[r, f] C[r, f + d] w[r] (n = 150 has shift-invariant rows, 30 not)."""
    from camtraj.ik.refine import _gather

    ops = spline_ops(n)
    rows, width, k = ops.coef.shape
    rng = np.random.default_rng(n)
    dz, w = rng.normal(size=(rows, 8, k)), rng.uniform(0.1, 1.0, size=(rows, 8, k))
    pad = width
    gq, M = np.zeros((n + 2 * pad, 8)), np.zeros((width, n + 2 * pad, 8))
    _gather(ops, dz, w, gq, M, pad)
    dense = np.zeros((k, rows, n))  # C[i, r, f]: operator i's row r's weight of frame f
    for r in range(rows):
        for o in range(width):
            f = r + ops.offset + o
            if 0 <= f < n:
                dense[:, r, f] = ops.coef[r, o]
    want_g = np.einsum("irf,rai->fa", dense, dz)
    assert np.allclose(gq[pad:pad + n], want_g, rtol=1e-12, atol=1e-12 * np.abs(want_g).max())
    for d in range(width):
        want = np.einsum("irf,irf,rai->fa", dense[:, :, :n - d], dense[:, :, d:], w)
        got = M[d, pad:pad + n - d]
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max()), d
    assert not gq[:pad].any() and not gq[pad + n:].any()


def test_whole_powers_equal_pow() -> None:
    """The continuation's whole exponents by repeated squaring, and any other exponent, agree
    with ``pow`` to a few units in the last place."""
    from camtraj.ik.shot_cost import powers

    a = np.random.default_rng(1).uniform(0.0, 2.0, size=(50, 8, 6))
    a[0, 0] = 0.0
    for ex in ([6.0, 6.0, 3.0, 3.0, 2.0, 2.0], [48.0, 48.0, 24.0, 24.0, 16.0, 16.0],
               [0.0, 1.0, 2.0, 5.0, 8.0 / 3.0, 2.5]):
        e = np.array(ex)
        assert np.allclose(powers(a, e), a ** e, rtol=1e-13, atol=0.0)


@pytest.mark.parametrize(("n", "rests", "held_pairs"), [
    (40, (1, 0), []),
    (150, (0, 1), []),
    (400, (1, 1), []),
    (200, (1, 1), [(90, 100)]),  # at rest at both ends, a hold between
    (120, (1, 0), [(100, 119)]),  # at rest at the start, holding to the end
    (40, (2, 0), []),  # settled (velocity and acceleration zero)
    (150, (0, 2), []),
    (60, (1, 2), []),
    (200, (2, 2), [(90, 100)]),
])
def test_operators_with_ends_at_rest_give_the_timing_stages_spline(
        robot: Robot, n: int, rests: tuple[int, int],
        held_pairs: list[tuple[int, int]]) -> None:
    """Where the camera is at rest on the first or last frame (``--edges still``), the timing
    stage fits the spline with zero velocity there (1), and zero acceleration too where the
    camera settles (2): the operators give that spline too, and its velocity (and
    acceleration where settled) at such an end is zero. The path eases from and to rest at
    those ends as the camera does there (a cosine ease: at rest; a cubic or quintic one:
    settled; a path that runs into a rest end at speed makes a transient wider than the
    band)."""
    k = np.arange(n) / (n - 1)
    start, end = rests
    ease = ({1: 1 - np.cos(0.5 * np.pi * k), 2: k ** 3}[start] if not end
            else {1: np.sin(0.5 * np.pi * k), 2: 1 - (1 - k) ** 3}[end] if not start
            else 10 * k ** 3 - 15 * k ** 4 + 6 * k ** 5 if 2 in rests
            else 0.5 - 0.5 * np.cos(np.pi * k))
    q = smooth_path(robot, n, n + 7, ease)
    held = np.zeros(n - 1, dtype=bool)
    for a, b in held_pairs:
        held[a:b] = True
        q[a + 1:b + 1] = q[a]
    limits = Limits.from_robot(robot)
    rest = np.repeat(np.array(rests)[:, None], 8, axis=1)
    path = FramePath.fit(q, 1.0 / 24.0, limits.lower, limits.upper, held, rest)
    free = FramePath.fit(q, 1.0 / 24.0, limits.lower, limits.upper, held)
    for x_end, level in zip((0.0, n - 1.0), rests, strict=True):
        v_rest = path.at(np.array([x_end]), 2)
        v_free = free.at(np.array([x_end]), 1)[1]
        if level:
            assert np.abs(v_rest[1]).max() <= 1e-12
            assert np.abs(v_free).max() > 0.0  # the smooth path itself moves there
        if level == 2:
            assert np.abs(v_rest[2]).max() <= 1e-12
    knots = np.arange(n, dtype=float)
    mids = np.arange(n - 1) + 0.5
    runs = hold_runs(held)
    ops = spline_ops(n, runs, rests)
    values = ops.apply(q)
    for i, (order, rows) in enumerate(zip(ops.orders, ops.rows, strict=True)):
        x = knots if rows == n else mids
        if rows == n:  # a hold's first frame: just before it, on the stretch's last piece
            first = np.array([a for a, _ in runs if a > 0], dtype=int)
            x[first] -= 1e-9
        want = path.at(x, 3)[order]
        got = values[:rows, :, i]
        scale = np.abs(want).max(axis=0)
        assert np.all(np.abs(got - want) <= 0.03 * scale + 1e-12), (order, n, rests)
    # at a rest end the velocity row reads zero on any path, and where settled the
    # acceleration row too (the free operators read the path's own motion there)
    moving = smooth_path(robot, n, n + 7)
    for ops_i, label in ((spline_ops(n, runs, rests), "rest"), (spline_ops(n, runs), "free")):
        values = ops_i.apply(moving)
        for i, (order, rows) in enumerate(zip(ops_i.orders, ops_i.rows, strict=True)):
            for e, level in zip((0, n - 1), rests, strict=True):
                if rows != n or order > level:
                    continue
                if label == "free" and any(a <= e <= b for a, b in runs):
                    continue
                size = float(np.abs(values[e, :, i]).max())
                assert (size <= 1e-12) == (label == "rest"), (label, order, e, size)
