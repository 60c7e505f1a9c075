"""The refinement's banded normal-equation solve against a dense solve of the same system."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from camtraj.ik.refine import DAMPING_FLOOR, _solve_banded


def band_matrix(H: np.ndarray) -> np.ndarray:
    """The symmetric (2n, 2n) matrix the blocks H (n, D, 2, 2) stand for (H[k, d] couples
    frame k with frame k + d)."""
    n, width = H.shape[:2]
    A = np.zeros((2 * n, 2 * n))
    for d in range(width):
        for i in range(n - d):
            A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2] = H[i, d]
            if d > 0:
                A[2 * (i + d):2 * (i + d) + 2, 2 * i:2 * i + 2] = H[i, d].T
    return A


def dense(H: np.ndarray, mu: float) -> np.ndarray:
    """The (2n, 2n) matrix the blocks H (n, D, 2, 2) stand for, damped as documented."""
    A = band_matrix(H)
    diag = np.diag(A).copy()
    A[np.diag_indices(A.shape[0])] = diag * (1.0 + mu) + DAMPING_FLOOR * max(diag.max(), 1e-12)
    return A


@pytest.mark.parametrize("width", [4, 14])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 7, 8, 13, 14, 15, 64, 97])
def test_banded_solve_equals_a_dense_solve(n: int, width: int) -> None:
    """Frames coupled up to ``width - 1`` apart (third differences: 4; the refinement's
    spline operators: 14)."""
    rng = np.random.default_rng(n)
    rows = []  # each row of a Gauss-Newton Jacobian reads `width` consecutive frames
    for first in range(-width + 1, n):
        for _ in range(2):
            row = np.zeros(2 * n)
            cols = np.arange(max(0, 2 * first), min(2 * n, 2 * (first + width)))
            row[cols] = rng.normal(size=cols.size)
            rows.append(row)
    J = np.array(rows)
    A = J.T @ J + np.diag(rng.uniform(0.1, 1.0, 2 * n))
    H = np.zeros((n, width, 2, 2))
    for d in range(width):
        for i in range(n - d):
            H[i, d] = A[2 * i:2 * i + 2, 2 * (i + d):2 * (i + d) + 2]
    g = rng.normal(size=(n, 2))
    for mu in (0.0, 0.3):
        want = np.linalg.solve(dense(H, mu), -g.ravel()).reshape(n, 2)
        got = _solve_banded(H, g, mu)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-11)


def _differences(n: int, order: int) -> np.ndarray:
    """The (n - order, n) matrix of order-th forward differences."""
    stencil = {1: (-1, 1), 2: (1, -2, 1), 3: (-1, 3, -3, 1)}[order]
    D = np.zeros((n - order, n))
    for i in range(n - order):
        D[i, i:i + order + 1] = stencil
    return D


@pytest.mark.parametrize("n", [100, 250, 600])
def test_the_solve_keeps_the_steps_of_smooth_bends(n: int) -> None:
    """A take near its jerk limit: the normal matrix is mostly third differences, with weak
    velocity and acceleration terms, so a smooth bend of a whole curve has a curvature about
    5e-9 of the diagonal. The solve must give that step back (the slow refinement's steps
    are such bends); a shift of 1e-9 of the diagonal returned 12-16% of them short."""
    A1 = sum(w * _differences(n, k).T @ _differences(n, k)
             for k, w in ((1, 1e-4), (2, 1e-2), (3, 1.0))) + 1e-7 * np.eye(n)
    assert np.linalg.eigvalsh(A1)[0] < 1e-8 * A1.diagonal().max()  # the premise
    H = np.zeros((n, 4, 2, 2))
    for d in range(4):
        for i in range(n - d):
            H[i, d] = A1[i, i + d] * np.eye(2)
    u = np.linspace(-1.0, 1.0, n)
    want = 0.01 * np.stack([1.0 - u ** 2, 0.5 * u * (1.0 - u ** 2)], axis=1)  # [m]
    g = -(A1 @ want)
    got = _solve_banded(H, g, 0.0)
    assert np.abs(got - want).max() <= 1e-3 * np.abs(want).max()


def test_tied_normal_equations_are_the_projected_ones() -> None:
    """The refinement's tie of held frames (one value per run of frames joined by held pairs):
    P^T A P, P^T g and P^T w of the dense system, P the (n, runs) map from runs to frames."""
    from camtraj.ik.refine import _Tie

    n, width = 30, 14
    rng = np.random.default_rng(5)
    H = rng.normal(size=(n, width, 2, 2))
    H[:, 0] = H[:, 0] + H[:, 0].swapaxes(-1, -2)  # the diagonal blocks are symmetric
    g, w = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    held = np.zeros(n - 1, dtype=bool)
    held[[0, 1, 7, 12, 13, 14, 15, 16, 17, 18, 19, 20, 28]] = True
    tie = _Tie.of(held)
    assert tie is not None
    A = band_matrix(H)
    P = np.zeros((2 * n, 2 * tie.count))
    for k, r in enumerate(tie.run):
        P[2 * k:2 * k + 2, 2 * r:2 * r + 2] = np.eye(2)
    Hr, gr, wr = tie.reduce(H, g, w)
    np.testing.assert_allclose(band_matrix(Hr), P.T @ A @ P, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gr.ravel(), P.T @ g.ravel(), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(wr.ravel(), P.T @ w.ravel(), rtol=1e-12, atol=1e-12)
    assert np.array_equal(tie.expand(np.arange(2 * tie.count).reshape(-1, 2)).reshape(-1),
                          (P @ np.arange(2 * tie.count)).astype(int))


def test_a_camera_hold_is_a_robot_hold(tmp_path: Path) -> None:
    """A push in that stops hard (smoothstep), holds half a second and moves on: every held
    frame's joints equal the hold's first (the solver once moved track and extend through the
    hold, a camera drift of 0.24 mm between frames), and in every timing mode the servo
    samples of the hold stand still for the hold's length (optimal keeps its duration)."""
    from camtraj import Robot
    from camtraj.ik import camera_holds, solve_path
    from camtraj.timing import Limits, time_shot
    from camtraj.usd_shot import read_shot
    from tests.shot_set import Cam, Design, write_design

    def move(_t: np.ndarray, u: np.ndarray) -> Cam:
        f = np.rint(u * 59.0)  # frames 0..59: move 0-23, hold 23-35, move 35-59
        s = np.where(f <= 23, 0.5 * _smooth(f / 23.0),
                     np.where(f <= 35, 0.5, 0.5 + 0.5 * _smooth((f - 35.0) / 24.0)))
        pos = np.stack([3.0 + 2.0 * s, np.full_like(s, 2.0), np.full_like(s, 1.5)], axis=1)
        return Cam(pos, -15.0 * s, np.full_like(s, -5.0))

    robot = Robot.default()
    shot = read_shot(write_design(Design("hold", move, 59.0 / 24.0, 24.0), tmp_path))
    targets = shot.cam2world @ np.linalg.inv(robot.camera2flange)
    held = camera_holds(targets)
    assert np.flatnonzero(held).tolist() == list(range(23, 35))
    q = solve_path(robot, targets, frame_interval=1.0 / 24.0)
    assert np.array_equal(q[23:36], np.broadcast_to(q[23], (13, 8)))
    limits = Limits.from_robot(robot)
    times = np.arange(q.shape[0]) / 24.0
    for mode in ("scale", "optimal"):
        take = time_shot(q, times, limits, mode=mode, hold=held)
        a, b = take.frame_samples[23], take.frame_samples[35]
        assert np.array_equal(take.q[a:b + 1], np.broadcast_to(q[23], take.q[a:b + 1].shape))
        assert not take.qd[a:b + 1].any()
        hold_time = take.t[b] - take.t[a]
        if mode == "optimal":
            assert hold_time == pytest.approx(12.0 / 24.0, abs=1e-9)
        else:
            assert hold_time == pytest.approx(12.0 / 24.0 * take.speed_factor, rel=1e-9)


def _smooth(x: np.ndarray) -> np.ndarray:
    return x * x * (3.0 - 2.0 * x)
