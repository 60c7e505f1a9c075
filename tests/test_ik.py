"""SM inverse kinematics against independent facts: FK, the papers' case, brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest

import camtraj
from camtraj import Robot, UnreachableError, UnreachableFramesError
from camtraj.ik import motion_cost, six_axis_solutions, solve_ik, solve_path, traverse
from camtraj.robot import PRISMATIC

from .conftest import camera_path, pose_error
from .test_robot import GA_EQ16, GA_TARGET

W_MIN = 50000.0  # the smaller of the track / extend weights (per metre)


def test_closed_form_contains_every_configuration(robot: Robot) -> None:
    """For random joint vectors, the six-axis substructure at the same track/extend holds it."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        q = rng.uniform(robot.lower, robot.upper)
        T = robot.fk(q)
        qs, ok = six_axis_solutions(robot.dh, T, q[[0]], q[[3]], q, robot.lower, robot.upper)
        assert np.abs(qs[0] - q).max(axis=1).min() < 1e-9
        for branch in np.flatnonzero(ok[0]):
            dp, dr = pose_error(robot.fk(qs[0, branch]), T)
            assert dp < 1e-9 and dr < 1e-9


def test_ga_case_beats_the_published_optimum(robot: Robot) -> None:
    sol = camtraj.solve_ik(robot, GA_TARGET, np.zeros(8))  # public API
    dp, dr = pose_error(robot.fk(sol.q), GA_TARGET)
    assert dp < 1e-9 and dr < 1e-9
    assert robot.within_limits(sol.q)
    published = float(motion_cost(robot, GA_EQ16, np.zeros(8)))
    assert published == pytest.approx(70283, abs=1.0)
    assert sol.cost <= published
    assert sol.cost == pytest.approx(motion_cost(robot, sol.q, np.zeros(8)))
    # the dense traversal with extend up to 1.5 m finds F ~ 48 060
    assert sol.cost == pytest.approx(48060, abs=5)
    brute = traverse(robot, GA_TARGET, np.zeros(8))
    assert abs(sol.cost - brute.cost) <= 1e-3 * brute.cost


def _random_reachable(robot: Robot, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    m = np.where(PRISMATIC, 0.04, math.radians(4.0))
    q = rng.uniform(robot.lower + m, robot.upper - m, size=(n, 8))
    return robot.fk(q)


def test_random_reachable_poses_round_trip(robot: Robot) -> None:
    targets = _random_reachable(robot, 500, seed=2)
    for T in targets:
        sol = solve_ik(robot, T, robot.home)
        dp, dr = pose_error(robot.fk(sol.q), T)
        assert dp < 1e-9 and dr < 1e-9
        assert robot.within_limits(sol.q, tol=1e-12)


def test_unreachable_poses_say_by_how_much(robot: Robot) -> None:
    dh = robot.dh
    # straight sideways from the track: the farthest the wrist centre gets from the track
    # line (at shoulder height) is the arm fully stretched at full extension
    reach = math.hypot(robot.upper[3] + dh.r40, dh.l3) + dh.r6
    T = np.eye(4)
    T[:3, 3] = (5.0, reach + 0.75, dh.r2)
    with pytest.raises(UnreachableError) as info:
        solve_ik(robot, T, robot.home)
    assert info.value.miss == pytest.approx(0.75, abs=1e-9)
    assert "0.750 m" in str(info.value)
    # beyond the end of the track
    T[:3, 3] = (robot.upper[0] + dh.r10 + reach + 2.0, 0.0, dh.r2)
    with pytest.raises(UnreachableError) as info:
        solve_ik(robot, T, robot.home)
    assert info.value.miss == pytest.approx(2.0, abs=1e-9)
    # past the end and to the side at once: the distance to the nearest point within reach
    # of the shoulder anywhere along the track (a new user's shot 3 m past the end and 24 m
    # to the side was said to miss by the sideways 24 m alone)
    T[:3, 3] = (robot.upper[0] + dh.r10 + 3.0, reach + 24.0, dh.r2 + 1.0)
    shoulders = np.stack([np.linspace(robot.lower[0], robot.upper[0], 20001) + dh.r10,
                          np.zeros(20001), np.full(20001, dh.r2)], axis=1)
    nearest = float(np.linalg.norm(shoulders - T[:3, 3], axis=1).min()) - reach
    with pytest.raises(UnreachableError) as info:
        solve_ik(robot, T, robot.home)
    assert info.value.miss == pytest.approx(nearest, abs=1e-6)
    assert info.value.miss > 24.0 + 0.1


def test_unreachable_frames_are_all_listed(robot: Robot) -> None:
    targets = camera_path(robot, 24)
    targets[5:8, 1, 3] += 20.0
    with pytest.raises(UnreachableFramesError) as info:
        solve_path(robot, targets, frame_numbers=np.arange(1001, 1025))
    assert [e.frame for e in info.value.errors] == [1006, 1007, 1008]
    assert "frames 1006-1008" in str(info.value)


def _workspace_poses(robot: Robot, n: int) -> np.ndarray:
    """Poses spread over the workspace: a lattice of positions, varied headings and tilts."""
    out = []
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    rng = np.random.default_rng(3)
    for x in (3.0, 5.0, 7.0):
        for y in (-2.0, 0.0, 2.0):
            for z in (-0.3, 1.0, 2.0):
                a, b = rng.uniform(-1.0, 1.0), rng.uniform(-0.5, 0.5)
                ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
                R = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]]) @ np.array(
                    [[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
                T = np.eye(4)
                T[:3, :3] = R @ look
                T[:3, 3] = (x, y, z)
                out.append(T @ np.linalg.inv(robot.camera2flange))
    return np.array(out[:n])


def test_optimal_over_the_workspace(robot: Robot) -> None:
    poses = _workspace_poses(robot, 30)
    assert len(poses) >= 27
    start = robot.home
    for T in poses:
        sol = solve_ik(robot, T, start)
        brute = traverse(robot, T, start,
                         radius=sol.cost / W_MIN * 1.001 + 1e-6, n1=161, n4=61)
        assert sol.cost <= brute.cost * (1 + 1e-3) + 1e-9
        # and the traversal is dense enough to be a meaningful reference
        assert brute.cost <= sol.cost * (1 + 1e-2) + 1e-6


def test_optimal_on_every_frame_of_a_smooth_path(robot: Robot) -> None:
    targets = camera_path(robot, 240)
    q = solve_path(robot, targets, objective="paper")
    prev = robot.home
    for i, T in enumerate(targets):
        cost = float(motion_cost(robot, q[i], prev))
        brute = traverse(robot, T, prev,
                         radius=cost / W_MIN * 1.001 + 1e-6, n1=41, n4=21, refine=3)
        assert cost <= brute.cost * (1 + 1e-3) + 1e-9, f"frame {i}"
        prev = q[i]


def test_wrist_singularity_keeps_the_previous_pan(robot: Robot) -> None:
    """At tilt = +-90 deg pan and roll align; the solution keeps the previous pan, no jump."""
    for tilt in (math.pi / 2, -math.pi / 2):
        q = np.array([0.5, 0.2, -0.1, 0.4, -1.2, 0.3, tilt, 0.5])
        T = robot.fk(q)
        previous = q.copy()
        previous[5] = 0.7  # a different split of the same pan + roll
        qs, ok = six_axis_solutions(robot.dh, T, q[[0]], q[[3]], previous,
                                    robot.lower, robot.upper)
        same_arm = np.abs(qs[0, :, :5] - q[:5]).max(axis=1) < 1e-9
        assert np.any(same_arm & ok[0])
        for branch in np.flatnonzero(same_arm & ok[0]):
            assert qs[0, branch, 5] == pytest.approx(0.7, abs=1e-9)
            dp, dr = pose_error(robot.fk(qs[0, branch]), T)
            assert dp < 1e-9 and dr < 1e-9


def test_optimal_where_the_previous_elbow_sits_on_its_limit(robot: Robot) -> None:
    """The per-frame optimum stays global where the previous elbow is exactly on -180 deg: the
    optimum then often slides along that limit (track and extend together)."""
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(60):
        prev = rng.uniform(robot.lower * 0.6, robot.upper * 0.6)
        prev[4] = -math.pi
        q = prev + rng.normal(0, 1, 8) * np.array([0.01, 0.01, 0.01, 0.005, 0.01, 0.02, 0.02,
                                                   0.02])
        q[4] = -math.pi + abs(q[4] + math.pi)
        T = robot.fk(q)
        try:
            sol = solve_ik(robot, T, prev)
        except UnreachableError:
            continue
        brute = traverse(robot, T, prev, radius=sol.cost / W_MIN * 1.001 + 1e-6, n1=41, n4=21,
                         refine=3)
        assert sol.cost <= brute.cost * (1 + 1e-3) + 1e-9
        checked += 1
    assert checked >= 40


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"previous": np.full(8, 1e300)}, "previous"),
        ({"previous": [0.0, 1.0]}, "previous"),
        ({"branch": 9}, "branch"),
        ({"branch": True}, "branch"),
        ({"max_step": [-1.0] * 8}, "max_step"),
    ],
)
def test_malformed_arguments_raise_value_error_naming_them(
        robot: Robot, kwargs: dict[str, object], word: str) -> None:
    with pytest.raises(ValueError, match=word):
        solve_ik(robot, GA_TARGET, **kwargs)  # type: ignore[arg-type]


def test_non_finite_target_is_a_value_error(robot: Robot) -> None:
    T = GA_TARGET.copy()
    T[0, 3] = math.inf
    with pytest.raises(ValueError, match="target"):
        solve_ik(robot, T)


def test_one_branch_closed_form_equals_the_branch_of_all(robot: Robot) -> None:
    from camtraj.ik.closed_form import six_axis_branch

    rng = np.random.default_rng(6)
    q = rng.uniform(robot.lower, robot.upper, size=(400, 8))
    T = robot.fk(q)
    r1 = q[:, 0] + rng.normal(0, 0.3, 400)
    r4 = np.clip(q[:, 3] + rng.normal(0, 0.2, 400), 0.0, 1.5)
    prev = q + rng.normal(0, 0.1, (400, 8))
    lo, hi = np.full(8, -np.inf), np.full(8, np.inf)
    lo[4], hi[4] = -10.0, 10.0  # wide limits: compare every value, not only feasible ones
    for limits in ((lo, hi), (robot.lower, robot.upper)):
        qs, ok = six_axis_solutions(robot.dh, T, r1, r4, prev, *limits)
        for b in range(8):
            qb, okb = six_axis_branch(robot.dh, T, r1, r4, prev, *limits, np.full(400, b))
            np.testing.assert_array_equal(okb, ok[:, b])
            np.testing.assert_allclose(qb[okb], qs[okb, b], atol=1e-12)
