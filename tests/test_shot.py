"""The whole-shot solver (the default ``shot`` objective) against independent facts.

Max feasible speed from the timing stage against the papers' per-frame optimum on a set of
shots; the dynamic programme against brute force; the refinement against its start; FK of every
frame against its pose; margins recomputed from link geometry; the move to the start against
ruckig's time-optimal trajectory.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from camtraj import Robot
from camtraj.ik import path_margins, solve_path, solve_path_report
from camtraj.ik.refine import refine
from camtraj.ik.shot import (
    candidates,
    chain_costs,
    choose,
    choose_each,
    choose_ranked,
    viterbi,
)
from camtraj.ik.shot_cost import ShotCost
from camtraj.timing import Limits, feasible_speed

from .conftest import camera_path, pose_error
from .shot_set import SetShot, max_speed, shot_set

WHIP = "whip_pan"  # 150 deg of pan in 8 frames: faster than any wrist axis, by design


@pytest.fixture(scope="module")
def solved(robot: Robot, tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, object]]:
    out = []
    for shot in shot_set(robot, tmp_path_factory.mktemp("shots")):
        rep = solve_path_report(robot, shot.targets, frame_interval=1.0 / shot.fps)
        paper = solve_path(robot, shot.targets, objective="paper")
        out.append({"shot": shot, "rep": rep, "paper": paper,
                    "speed": max_speed(robot, rep.q, shot.fps, shot.targets),
                    "paper_speed": max_speed(robot, paper, shot.fps, shot.targets)})
    return out


def test_the_set_covers_the_issue(solved: list[dict[str, object]]) -> None:
    shots = [s["shot"] for s in solved]
    assert len(shots) >= 12
    assert all(isinstance(s, SetShot) for s in shots)
    seconds = [s.targets.shape[0] / s.fps for s in shots]  # type: ignore[union-attr]
    assert min(seconds) <= 1.0 and max(seconds) >= 60.0


def test_default_is_at_least_as_fast_as_paper_on_every_shot(
        solved: list[dict[str, object]]) -> None:
    ratios = []
    for s in solved:
        name = s["shot"].name  # type: ignore[attr-defined]
        fast, paper = float(s["speed"]), float(s["paper_speed"])  # type: ignore[arg-type]
        assert fast >= paper, f"{name}: shot {fast:.3f} < paper {paper:.3f}"
        ratios.append(fast / paper if paper > 0 else math.inf)  # paper: no speed works
    assert float(np.median(ratios)) >= 1.2


def test_every_frame_reaches_its_pose_without_flips(
        robot: Robot, solved: list[dict[str, object]]) -> None:
    for s in solved:
        shot, q = s["shot"], s["rep"].q  # type: ignore[attr-defined]
        dp, dr = pose_error(robot.fk(q), shot.targets)
        assert dp < 1e-9 and dr < 1e-9, shot.name
        assert np.all(robot.within_limits(q, tol=1e-12)), shot.name
        steps = np.abs(np.diff(q, axis=0))
        # a flip turns pan and roll by ~180 deg in one frame
        assert steps[:, 1:].max() < math.radians(60.0), shot.name
        if shot.name != WHIP:
            bound = robot.max_velocity / shot.fps
            assert np.all(steps <= bound * (1 + 1e-9) + 1e-12), shot.name
            assert s["rep"].within_step.all()  # type: ignore[attr-defined]


def test_tilt_keeps_away_from_its_limits_and_the_singularity_on_the_samples(
        robot: Robot, solved: list[dict[str, object]]) -> None:
    for s in solved:
        shot, q = s["shot"], s["rep"].q  # type: ignore[attr-defined]
        if not shot.sample:
            continue
        tilt = q[:, 6]
        to_limit = np.minimum(tilt - robot.lower[6], robot.upper[6] - tilt)
        to_singular = np.abs(np.abs(tilt) - math.pi / 2)
        assert to_limit.min() >= math.radians(15.0), shot.name
        assert to_singular.min() >= math.radians(15.0), shot.name


def test_reported_margins_match_the_link_geometry(
        robot: Robot, solved: list[dict[str, object]]) -> None:
    for s in solved[:6]:
        rep = s["rep"]
        q = rep.q  # type: ignore[attr-defined]
        m = rep.margins  # type: ignore[attr-defined]
        to_lim = np.minimum(q - robot.lower, robot.upper - q).min(axis=0)
        np.testing.assert_allclose(m.to_limits, to_lim, atol=1e-12)
        frames = robot.link_frames(q)
        shoulder, elbow, wrist = frames[:, 2, :3, 3], frames[:, 4, :3, 3], frames[:, 6, :3, 3]
        se = np.linalg.norm(elbow - shoulder, axis=1)
        ew = np.linalg.norm(wrist - elbow, axis=1)
        sw = np.linalg.norm(wrist - shoulder, axis=1)
        interior = np.arccos(np.clip((se**2 + ew**2 - sw**2) / (2 * se * ew), -1, 1))
        # the elbow point of the DH chain is the arm's bend, so the stretch distance is the
        # triangle shoulder-elbow-wrist's exterior angle there
        assert m.stretch == pytest.approx(float((math.pi - interior).min()), abs=1e-6)
        assert m.wrist == pytest.approx(
            float(np.abs(np.abs(q[:, 6]) - math.pi / 2).min()), abs=1e-9)


def test_the_programme_is_the_same_whatever_its_blocks(robot: Robot) -> None:
    """The step costs are made a block of frames at a time (bounded memory): blocks of 1, 7
    and all frames give the same tables and the same answer, bit for bit."""
    import dataclasses

    targets = camera_path(robot, 60)
    cost = ShotCost.for_robot(robot, 1.0 / 24.0)
    cand = candidates(robot, targets, n_track=2, n_extend=2)
    for merged in (False, True):
        unary, steps = chain_costs(cost, cand, merged)
        whole = steps.block(0, 59)[0]
        parts = np.concatenate([steps.block(a, min(a + 7, 59))[0] for a in range(0, 59, 7)])
        assert np.array_equal(whole, parts)
        answers = [viterbi(unary, dataclasses.replace(steps, per=per)) for per in (1, 7, 100)]
        for best, path in answers[1:]:
            assert np.array_equal(best, answers[0][0]) and np.array_equal(path, answers[0][1])


def test_rankings_run_together_equal_each_run_alone(robot: Robot) -> None:
    """The solver ranks the candidates twice (its cost, and margins a tenth as heavy with
    the ends' room as a use) in one pass over the step costs: each ranking's answers are
    those of the programme run on its cost alone, bit for bit."""
    targets = camera_path(robot, 60)
    cost = ShotCost.for_robot(robot, 1.0 / 24.0)
    light = dataclasses.replace(cost, margin=0.1 * cost.margin, edge_room=True)
    cand = candidates(robot, targets, n_track=2, n_extend=2)
    together = choose_ranked((cost, light), cand, robot.home)
    for ranking, answers in zip((cost, light), together, strict=True):
        alone = choose_each(ranking, cand, robot.home)
        assert [a.cost for a in answers] == [a.cost for a in alone]
        for a, b in zip(answers, alone, strict=True):
            assert np.array_equal(a.point, b.point) and np.array_equal(a.branch, b.branch)
            assert np.array_equal(a.y, b.y)
    assert [a.cost for a in together[0]] != [a.cost for a in together[1]]  # two rankings


def test_dynamic_programme_equals_brute_force(robot: Robot) -> None:
    """Every sequence of a coarse candidate set on a short shot, against the Viterbi pass.

    4 candidate points a frame (1 track value per reachable interval x 2 extend values): per
    branch label all 4^8 sequences of 8 frames, and with labels merged (32 states a frame)
    all 32^4 sequences of 4 frames.
    """
    targets = camera_path(robot, 240)[::24][:8]  # 8 frames, a large move between them
    cost = ShotCost.for_robot(robot, 1.0 / 24.0)
    cand = candidates(robot, targets, n_track=1, n_extend=2)
    for merged, frames in ((False, 8), (True, 4)):
        unary, steps = chain_costs(cost, cand, merged)
        u, p = unary[:frames], steps.block(0, frames - 1)[0]
        best, _ = viterbi(u, steps)
        chains, states = u.shape[1:]
        seqs = np.array(np.unravel_index(np.arange(states ** frames), (states,) * frames)).T
        for c in range(chains):
            total = u[np.arange(frames), c, seqs].sum(axis=1)
            total += p[np.arange(frames - 1), c, seqs[:, :-1], seqs[:, 1:]].sum(axis=1)
            brute = float(total.min())
            if math.isfinite(brute):
                assert best[c] == pytest.approx(brute, rel=1e-12)
            else:
                assert not math.isfinite(best[c])
    # the tables say what a path costs: recompute each label's path cost from its joints;
    # one path per label that reaches every frame, cheapest first, the first is choose's
    choices = choose_each(cost, cand, robot.home)
    alive = np.flatnonzero(cand.ok.any(axis=1).all(axis=0))
    assert len(choices) == alive.size > 0
    assert sorted(int(c.branch[0]) for c in choices) == alive.tolist()
    assert [c.cost for c in choices] == sorted(c.cost for c in choices)
    first = choose(cost, cand, robot.home)
    assert first is not None and first.cost == choices[0].cost
    assert np.array_equal(first.point, choices[0].point)
    rows = np.arange(cand.r1.shape[0])
    for choice in choices:
        assert np.all(choice.branch == choice.branch[0])
        # the programme's own values (revolute steps the shorter way round) ...
        y = cand.y[rows, choice.point, choice.branch]
        # ... and the answer's: the same angles, made continuous inside the limits
        turns = (choice.y[:, :8] - y[:, :8]) / (2.0 * np.pi)
        assert np.allclose(turns, np.rint(turns), atol=1e-12)
        assert np.all(choice.y[:, :8] >= cost.lower - 1e-9)
        assert np.all(choice.y[:, :8] <= cost.upper + 1e-9)
        q = y[:, :8]
        direct = float(cost.unary(y).sum() + cost.first_order(cost.steps(q[:-1], q[1:])).sum()
                       + cost.edge_cost(q[0], q[1]) + cost.edge_cost(q[-1], q[-2]))
        assert choice.cost == pytest.approx(direct, rel=1e-9)


def _programme_start(robot: Robot, n: int) -> tuple[Any, ...]:
    """The programme's answer on a coarse grid for a camera path of n frames at 24 fps, as a
    refinement's start: targets, cost, the choice, track/extend (n, 2), the track interval
    (lo, hi) and the timing stage's speed of a joint path."""
    targets = camera_path(robot, n)
    cost = ShotCost.for_robot(robot, 1.0 / 24.0)
    cand = candidates(robot, targets, n_track=2, n_extend=2)
    choice = choose(cost, cand, robot.home)
    assert choice is not None
    rows = np.arange(n)
    x0 = np.stack([cand.r1[rows, choice.point], cand.r4[rows, choice.point]], axis=1)
    j = cand.interval[rows, choice.point]
    limits = Limits.from_robot(robot)
    times = np.arange(n) / 24.0

    def speed(q: np.ndarray) -> float:
        return feasible_speed(q, times, limits)

    return targets, cost, choice, x0, cand.track_lo[rows, j], cand.track_hi[rows, j], speed


@pytest.mark.parametrize("n", [12, 30, 120])
def test_refinement_never_slows_the_take(robot: Robot, n: int) -> None:
    """The refined take is at least as fast as the dynamic programme's, as the timing stage
    measures it; it moved off the grid; every frame still reaches its pose exactly."""
    targets, cost, choice, x0, lo, hi, speed = _programme_start(robot, n)
    ref = refine(robot, cost, targets, choice.branch, x0, choice.y, lo, hi, take_speed=speed)
    assert speed(ref.y[:, :8]) >= speed(choice.y[:, :8])
    assert np.abs(ref.x - x0).max() > 1e-6  # it moved off the grid
    dp, dr = pose_error(robot.fk(ref.y[:, :8]), targets)
    assert dp < 1e-9 and dr < 1e-9


def test_a_start_with_grid_steps_is_smoothed_before_the_refinement(robot: Robot) -> None:
    """A start whose track jumps between grid points from frame to frame (5 mm up and down,
    as the programme's grid does where it switches points) has jerk the refinement would
    spend its rounds taking out: the refinement starts from the curves low-passed, a take
    many times faster, and every frame still reaches its pose exactly."""
    from camtraj.ik.refine import Refinement
    from camtraj.ik.shot import branch_measures

    n = 120
    targets, cost, choice, x0, lo, hi, speed = _programme_start(robot, n)
    x0[:, 0] = np.clip(x0[:, 0] + 0.005 * (-1.0) ** np.arange(n), lo, hi)
    y0, ok = branch_measures(robot, targets, x0[:, 0], x0[:, 1], choice.y[:, :8],
                             choice.branch)
    assert ok.all()
    run = Refinement(robot, cost, targets, choice.branch, x0, y0, lo, hi, take_speed=speed)
    assert run.best[0] >= 5.0 * speed(y0[:, :8])
    dp, dr = pose_error(robot.fk(run.y[:, :8]), targets)
    assert dp < 1e-9 and dr < 1e-9


def test_the_first_frame_is_chosen_for_the_shot_not_the_start(robot: Robot) -> None:
    targets = camera_path(robot, 48)
    a = solve_path_report(robot, targets, robot.home, frame_interval=1 / 24)
    elsewhere = robot.home.copy()
    elsewhere[0], elsewhere[3], elsewhere[1] = 10.0, 1.2, 1.0
    b = solve_path_report(robot, targets, elsewhere, frame_interval=1 / 24)
    # the same configurations; a revolute axis may take another whole turn (the one nearer the
    # start, within its limits); the refinement, run on angles a turn apart, rounds
    # differently and may stop a step apart (measured 4.7e-4 deg): the same to a thousandth
    # of a degree, and the same take: its maximum feasible speed to 1e-5 (measured 1.7e-7)
    turns = (b.q - a.q) / (2 * math.pi)
    np.testing.assert_allclose(turns, np.rint(turns), atol=1e-3 / 360.0)
    assert np.all(np.rint(turns)[:, [0, 3]] == 0)
    times = np.arange(targets.shape[0]) / 24.0
    limits = Limits.from_robot(robot)
    assert feasible_speed(b.q, times, limits) == pytest.approx(
        feasible_speed(a.q, times, limits), rel=1e-5)
    np.testing.assert_array_equal(a.start, robot.home)
    np.testing.assert_array_equal(b.start, elsewhere)


def test_move_to_start_duration_is_ruckigs_time_optimal_move(robot: Robot) -> None:
    from ruckig import InputParameter, Result, Ruckig, Trajectory

    from camtraj.ik.path import move_to_start

    rng = np.random.default_rng(4)
    for _ in range(5):
        start = rng.uniform(robot.lower * 0.5, robot.upper * 0.5)
        pose = rng.uniform(robot.lower * 0.5, robot.upper * 0.5)
        move = move_to_start(robot, start, pose)
        np.testing.assert_array_equal(move.travel, pose - start)
        inp = InputParameter(8)
        inp.current_position, inp.target_position = list(start), list(pose)
        inp.current_velocity = inp.current_acceleration = [0.0] * 8
        inp.target_velocity = inp.target_acceleration = [0.0] * 8
        inp.max_velocity = list(robot.max_velocity)
        inp.max_acceleration = list(robot.max_acceleration)
        inp.max_jerk = list(robot.max_jerk)
        traj = Trajectory(8)
        assert Ruckig(8).calculate(inp, traj) == Result.Working
        assert move.duration == pytest.approx(traj.duration, rel=1e-6)


def test_margins_of_a_path_at_a_limit(robot: Robot) -> None:
    q = np.zeros((3, 8))
    q[:, 3] = 0.75  # extend mid-range ...
    q[1, 3] = robot.upper[3]  # ... but fully out on frame 1
    q[2, 6] = math.radians(80.0)  # tilt 10 deg from the singularity
    m = path_margins(robot, q)
    assert m.to_limits[3] == 0.0 and m.to_limits_frame[3] == 1
    assert m.wrist == pytest.approx(math.radians(10.0), abs=1e-12) and m.wrist_frame == 2


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"start": np.full(8, 1e300)}, "start"),
        ({"start": [0.0] * 7}, "start"),
        ({"frame_interval": 0.0}, "frame_interval"),
        ({"frame_interval": math.nan}, "frame_interval"),
        ({"objective": "smooth"}, "objective"),
        ({"frame_numbers": [1, 2]}, "frame_numbers"),
    ],
)
def test_malformed_path_arguments_raise_value_error_naming_them(
        robot: Robot, kwargs: dict[str, object], word: str) -> None:
    targets = camera_path(robot, 5)
    with pytest.raises(ValueError, match=word):
        solve_path_report(robot, targets, **kwargs)  # type: ignore[arg-type]


def test_non_finite_targets_raise_value_error(robot: Robot) -> None:
    targets = camera_path(robot, 5)
    targets[3, 0, 3] = math.nan
    with pytest.raises(ValueError, match=r"target 3"):
        solve_path(robot, targets)



def test_the_summary_reports_margins_and_the_move_to_start(robot: Robot) -> None:
    from camtraj.convert import ConvertOptions, analyse, summary

    from .shot_set import SHOTS

    shot = SHOTS / "blender_crane_up.usda"
    options = ConvertOptions(start_from=(1.0, 0.0, 0.0, 0.2, -0.5, 0.0, 0.0, 0.0))
    analysis = analyse(shot, options)
    report = summary(analysis, shot, None, options)
    assert analysis.path is not None
    q = analysis.path.q
    tilt = q[:, 6]
    m = report["margins"]
    assert m["to_limits"]["tilt"] == pytest.approx(
        math.degrees(float(np.minimum(tilt - robot.lower[6], robot.upper[6] - tilt).min())))
    assert m["to_limits"]["track"] == pytest.approx(
        float(np.minimum(q[:, 0] - robot.lower[0], robot.upper[0] - q[:, 0]).min()))
    assert m["wrist_singularity_deg"] == pytest.approx(
        math.degrees(float(np.abs(np.abs(tilt) - math.pi / 2).min())), abs=1e-6)
    assert 0.0 < m["full_stretch_deg"] < 180.0
    # with --start-from the take begins there, at rest: nothing to move before it
    start = report["move_to_start"]
    assert start["duration_s"] == 0.0 and not any(start["extent"].values())
    # from home, the move goes to where the take begins: the run-up's start, not the first
    # frame (with free ends the crane-up's run-up moves the elbow on its way into the first
    # frame)
    analysis = analyse(shot, ConvertOptions(edges="gentle"))
    take = analysis.take
    assert take is not None and analysis.path is not None
    begin, first = take.q[0, :8], analysis.path.q[0]
    assert abs(begin[4] - first[4]) > 1e-3
    start = summary(analysis, shot, None, ConvertOptions(edges="gentle"))["move_to_start"]
    assert start["extent"]["track"] == pytest.approx(abs(begin[0] - robot.home[0]))
    assert start["extent"]["elbow"] == pytest.approx(math.degrees(abs(begin[4] - robot.home[4])))
    assert start["duration_s"] > 0.0


def test_a_scaled_target_is_a_value_error_naming_its_index(robot: Robot) -> None:
    targets = camera_path(robot, 6)
    targets[4, :3, :3] *= 1.1
    with pytest.raises(ValueError, match=r"targets\[4\]"):
        solve_path(robot, targets)


def test_the_run_out_room_is_one_of_the_takes_uses(robot: Robot) -> None:
    """A move that ends with extend retracting at 0.2 m/s, 0.2 m above its lower limit: at
    real time its run-out stops well inside the limit; at the speed its velocities allow
    (5x) the stop would run past it, so the timing stage's maximum feasible speed is set by
    that room. The refinement's objective must see what the timing stage sees: with the
    room among the take's uses, its aimed speed is the timing stage's; without it, the
    run-out it prices at the speed it aims for ends beyond the limit, at a steep cost."""
    from dataclasses import replace

    from camtraj.ik.closed_form import EXTEND

    dt, n = 1.0 / 24.0, 49
    q = np.tile([5.0, 0.0, 0.0, 0.6, -1.5, 0.0, 0.0, 0.0], (n, 1))
    q[:, EXTEND] = np.linspace(0.6, 0.2, n)  # [m], 0.2 m/s
    limits = Limits.from_robot(robot)
    cost = ShotCost.for_robot(robot, dt)
    taken = feasible_speed(q, np.arange(n) * dt, limits)
    moves = replace(cost, room=False).take_use(q)  # the spline's uses and velocity stops
    aimed = 1.0 / moves.peak()
    assert aimed > 4.5 and taken < 0.8 * aimed  # the room, not the move, limits the take
    # the objective's continuous stop from the spline's end state against the timing stage's
    # sampled take (measured: 1.1% apart, the model on the fast side)
    assert taken <= 1.0 / cost.take_use(q).peak() <= 1.012 * taken
    slow = cost.room_slowdown(moves)
    assert slow == pytest.approx(1.0 / aimed)
    lower = robot.lower[EXTEND]
    assert cost.edge_excursion(q[-1], q[-2], slow)[0][EXTEND] < lower
    assert cost.edge_excursion(q[-1], q[-2], 1.0)[0][EXTEND] > lower + 0.1
    assert cost.refine_edge(q[-1], q[-2], slow) > cost.overspeed * 1e-4


def test_room_need_is_the_slow_down_whose_stop_ends_on_the_limit(robot: Robot) -> None:
    """Each end's room need s: the axis leaving its end frame at V / s with acceleration
    A / s^2 along its motion (V, A at real time; the run-up's state reversed) stops exactly
    on the position limit ahead (the run-up's behind), as ruckig's time-optimal stop from
    that state under the robot's acceleration and jerk limits has it (an axis still braking
    stops within the room: its need is taken without the braking); and the needs'
    derivatives in the frames are their central differences."""
    from ruckig import ControlInterface, InputParameter, Result, Ruckig, Trajectory

    dt, n = 1.0 / 25.0, 40
    rng = np.random.default_rng(8)
    mid = 0.5 * (robot.lower + robot.upper)
    span = robot.upper - robot.lower
    q = mid + 0.35 * span * np.sin(np.linspace(0.0, 2.5, n)[:, None] + rng.uniform(0, 6, 8))
    cost = ShotCost.for_robot(robot, dt)
    use = cost.take_use(q)
    need, lin, frames = use.ends
    assert need.shape == (4, 8) and list(frames) == [0, n - 1, 0, n - 1]
    z1 = use.z[[0, -1], :, 0]  # velocity usages at the end knots
    z2 = use.z[[0, -1], :, 2]  # and acceleration usages
    v_real = z1 * robot.max_velocity
    pushed = braking = 0
    for end, frame in ((0, 0), (1, n - 1)):
        for axis in range(8):
            s = need[2 + end, axis]
            ahead = np.sign(z1[end, axis]) * (1.0 if end else -1.0)
            along = z2[end, axis] * ahead * robot.max_acceleration[axis]
            pushed += along > 0.0
            braking += along < 0.0
            inp = InputParameter(1)
            inp.control_interface = ControlInterface.Velocity
            inp.current_position = [0.0]
            inp.current_velocity = [abs(v_real[end, axis]) / s]
            inp.current_acceleration = [along / (s * s)]
            inp.target_velocity = inp.target_acceleration = [0.0]
            inp.max_velocity = [1e9]
            inp.max_acceleration = [float(robot.max_acceleration[axis])]
            inp.max_jerk = [float(robot.max_jerk[axis])]
            traj = Trajectory(1)
            assert Ruckig(1).calculate(inp, traj) == Result.Working
            stop = traj.at_time(traj.duration)[0][0]
            room = (robot.upper[axis] - q[frame, axis] if ahead > 0
                    else q[frame, axis] - robot.lower[axis])
            if along >= 0.0:
                assert stop == pytest.approx(room, rel=1e-9), (end, axis)
            else:
                assert stop <= room, (end, axis)
    assert pushed >= 4 and braking >= 4  # both kinds of end state are checked
    rooms = np.outer([1e-6, 1e-3, 0.05, 0.5, 3.0], np.ones(8))  # both branches of the stop
    np.testing.assert_allclose(cost.stop_distance(cost.stop_speed(rooms))[0], rooms, rtol=1e-12)
    h = 1e-6
    off = use.ops.offset
    for e in (2, 3):
        for axis in range(8):
            for col in range(lin.shape[1]):
                f = frames[e] + off + col
                if not 0 <= f < n:
                    continue
                up, down = q.copy(), q.copy()
                up[f, axis] += h
                down[f, axis] -= h
                num = (cost.take_use(up).ends[0][e, axis]
                       - cost.take_use(down).ends[0][e, axis]) / (2 * h)
                assert lin[e, col, axis] == pytest.approx(num, rel=1e-5, abs=1e-6), (e, axis, f)


def test_the_camera_is_at_rest_where_it_eases_from_or_to_rest() -> None:
    """An eased start or stop is at rest (the spline's velocity through the poses there is
    below 1 mm/s and 0.1 deg/s, and below 2% of the move's own pace); an end in motion, a pan
    alone in motion, and a constant creep (5 mm/s, or 0.5 mm/s) are not."""
    from camtraj.ik.shot import camera_rests

    def shot(x: np.ndarray, pan_deg: np.ndarray) -> np.ndarray:
        T = np.tile(np.eye(4), (x.size, 1, 1))
        a = np.radians(pan_deg)
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
        T[:, :3, 3] = np.stack([x, np.full(x.size, 1.0), np.full(x.size, 1.4)], axis=1)
        return T

    dt = 1.0 / 24.0
    u = np.linspace(0.0, 1.0, 96)
    ease = 3 * u ** 2 - 2 * u ** 3  # from rest to rest
    still = np.zeros(96)
    assert camera_rests(shot(2.0 * ease, 30 * ease), dt) == (True, True)
    assert camera_rests(shot(2.0 * u ** 2, still), dt) == (True, False)  # accelerating out
    assert camera_rests(shot(2.0 * (1 - (1 - u) ** 2), still), dt) == (False, True)
    assert camera_rests(shot(np.full(96, 2.0), 40 * u), dt) == (False, False)  # a pan
    creep = 0.005 * dt * np.arange(96)  # 5 mm/s
    assert camera_rests(shot(creep, still), dt) == (False, False)
    # 0.5 mm/s, constant: under the absolute bound, but that is the move's own pace
    assert camera_rests(shot(creep / 10, still), dt) == (False, False)
    # a 2 mm eased nudge: its ends accelerate at 0.8 mm/s^2, under the absolute floor (1 cm/s^2)
    # below which an end has settled whatever the move's own acceleration
    assert camera_rests(shot(0.002 * ease, still), dt) == (2, 2)


def test_a_camera_eased_so_its_acceleration_fades_has_settled() -> None:
    """At rest, a camera eased so that its acceleration fades too (a quintic ease, as Maya's
    and Blender's smooth curves give) has settled; one that starts or stops hard (a cubic
    ease, whose acceleration is largest at its ends, or a constant acceleration) is only at
    rest; one in motion is free (half a metre in 0.5 to 10 s at 24 fps: the short quintic
    eases were read as moving by the timing spline alone)."""
    from camtraj.ik.shot import camera_rests
    from camtraj.timing.path import AT_REST, FREE, SETTLED

    dt = 1.0 / 24.0
    for n in (12, 24, 48, 96, 240):
        u = np.linspace(0.0, 1.0, n)
        quintic = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
        cubic = 3 * u ** 2 - 2 * u ** 3

        def truck(x: np.ndarray) -> np.ndarray:
            T = np.tile(np.eye(4), (x.size, 1, 1))
            T[:, :3, 3] = np.stack([x, np.full(x.size, 1.0), np.full(x.size, 1.4)], axis=1)
            return T

        assert camera_rests(truck(0.5 * quintic), dt) == (SETTLED, SETTLED), n
        assert camera_rests(truck(0.5 * cubic), dt) == (AT_REST, AT_REST), n
        assert camera_rests(truck(0.5 * u ** 2), dt) == (AT_REST, FREE), n
        # a pan alone, eased both ways: the turn decides
        pan = np.tile(np.eye(4), (n, 1, 1))
        for k, a in enumerate(np.radians(60.0 * quintic)):
            pan[k, :2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        assert camera_rests(pan, dt) == (SETTLED, SETTLED), n
        for k, a in enumerate(np.radians(60.0 * cubic)):
            pan[k, :2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
        assert camera_rests(pan, dt) == (AT_REST, AT_REST), n
    # a shake of a few frames' period is no ease: moving at its ends, whatever a polynomial
    # through its end frames reads there (1 cm, 7 frames, at full speed on both end frames)
    k = np.arange(50)
    assert camera_rests(truck(0.01 * np.sin(2 * np.pi * k / 7.0)), dt) == (FREE, FREE)
    # three frames: too few for the end fit, the spline alone decides
    assert camera_rests(truck(np.array([0.0, 0.02, -0.01])), dt) == (FREE, FREE)


def test_a_robot_set_up_on_the_first_frame_keeps_that_solution(robot: Robot) -> None:
    """With a start pose (``--start-from``) the run-up from it is part of the take. Started
    from the default answer's own first frame (a crew that set the robot up there), a
    truck that stops hard keeps that answer: it had been re-solved onto the other arm
    configuration, 1.7% faster, whose run-up drove the track 6 m and the pan 149 deg over
    4.9 s next to the set. The choice is among answers within 5% of the fastest."""
    from camtraj.ik.path import NEAR_START, move_to_start

    n, fps = 60, 30.0
    u = np.linspace(0.0, 1.0, n)
    ease = 3 * u ** 2 - 2 * u ** 3  # stops hard: at rest, accelerating
    cams = np.tile(np.eye(4), (n, 1, 1))
    for i, e in enumerate(ease):
        eye = np.array([3.0 + 3.0 * e, 1.5, 1.5])
        look = np.array([4.5 + 3.0 * e, -3.0, 1.2]) - eye
        z = -look / np.linalg.norm(look)  # the camera looks down its -Z, +Y up
        x = np.cross([0.0, 0.0, 1.0], z)
        x /= np.linalg.norm(x)
        cams[i, :3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
        cams[i, :3, 3] = eye
    targets = cams @ np.linalg.inv(robot.camera2flange)
    default = solve_path_report(robot, targets, frame_interval=1 / fps, still_ends=True)
    first = default.q[0].copy()
    placed = solve_path_report(robot, targets, first, frame_interval=1 / fps, still_ends=True)
    assert move_to_start(robot, first, placed.q[0]).duration < 0.05
    speeds = [max_speed(robot, p.q, fps, targets, p.rest_axes()) for p in (default, placed)]
    assert speeds[1] >= (1.0 - NEAR_START) * speeds[0], speeds
    assert pose_error(robot.fk(placed.q), targets)[0] < 1e-9


def _out_and_back(robot: Robot, n: int, shift: float = 0.0, twos: bool = False) -> Any:
    """Camera poses (n, 4, 4) in the base frame of a push 0.4 m out and back with a pan, its
    turning point at frame (n - 1) / 2 + ``shift``: with an even n and no shift half-way
    between two frames, which are then equal bit for bit. ``twos``: each pose held for two
    frames (a move animated on twos)."""
    from .conftest import rot_z

    i = np.arange(n, dtype=float)
    if twos:
        i = 2.0 * np.floor(i / 2.0)
    c = (n - 1) / 2.0 + shift
    s = 1.0 - ((i - c) / c) ** 2
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    out = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        out[k, :3, :3] = rot_z(0.25 * s[k]) @ look
        out[k, :3, 3] = (4.3 + 0.4 * s[k], 0.1 * s[k], 0.9)
    return out


def test_a_turnaround_between_two_frames_is_no_hold(robot: Robot) -> None:
    """Issue 13 (a turning point is no hold), trial 23: a move symmetric about a turning
    point half-way between two frames has those two camera poses equal. Taken as a hold, the
    robot stopped dead there (an out-and-back push at 66% of real time, the same move turning
    on a frame at 381%). The take fits at the speed of the same move with its turning point
    moved a hundredth of a frame (within 2%), and the robot moves between the two frames. A
    move on twos keeps its holds (the camera goes on the way it went)."""
    from camtraj.ik import camera_holds

    cam = _out_and_back(robot, 48)
    assert np.array_equal(cam[23], cam[24])
    assert not camera_holds(cam).any()
    twos = camera_holds(_out_and_back(robot, 48, twos=True))
    # every other pair held, but for the one the camera turns back across
    assert np.flatnonzero(twos).tolist() == [k for k in range(0, 47, 2) if k != 24]
    # a hold of two pairs at the turning point, and an equal pair at either end, stay holds
    long_hold = np.concatenate([cam[:24], cam[23:24], cam[24:]])
    assert camera_holds(long_hold)[[22, 23, 24]].tolist() == [False, True, True]
    # a stop between a truck and a crane at right angles (nothing turns back) stays a hold
    corner = np.tile(np.eye(4), (8, 1, 1))
    corner[:, :3, 3] = [(0, 0, 0), (0.1, 0, 0), (0.2, 0, 0), (0.2, 0, 0), (0.2, 0, 0.1),
                        (0.2, 0, 0.2), (0.2, 0, 0.3), (0.2, 0, 0.4)]
    assert camera_holds(corner).tolist() == [False, False, True, False, False, False, False]
    ends = np.concatenate([cam[:1], cam, cam[-1:]])
    held = camera_holds(ends)
    assert held[0] and held[-1] and not held[1:-1].any()

    speeds = []
    for c in (cam, _out_and_back(robot, 48, shift=0.01)):
        targets = c @ np.linalg.inv(robot.camera2flange)
        path = solve_path_report(robot, targets, frame_interval=1 / 24, still_ends=True)
        speeds.append(max_speed(robot, path.q, 24.0, targets, path.rest_axes()))
    assert speeds[0] == pytest.approx(speeds[1], rel=0.02), speeds
