"""Issue 13's acceptance tests on the wide shot set (``tests/shot_set.py``).

* The default objective's maximum feasible speed (the timing stage's ``max_speed``) is at least
  ``paper``'s and at least 95% of the same objective at 10x the effort, on every shot.
* Every shot, and every short move that ends (or starts) in motion near either end of the
  track, converts with ``--timing shot`` or ``--timing scale``, and every servo sample of the
  take is inside every limit: positions exactly, velocity, acceleration and jerk both as the
  timing stage states them and as divided differences of the positions (which, by the Peano
  kernel theorem, are weighted means of the true derivative and so cannot exceed its bound).
* On paths with large jumps between frames (shots subsampled), no frame is outside a position
  limit and every frame reaches its pose (FK to 1e-9 m and 1e-9 rad).

Each test checks every shot before failing and names every failing shot with its numbers.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.convert import analyse
from camtraj.errors import CamtrajError
from camtraj.ik import solve_path
from camtraj.options import ConvertOptions
from camtraj.robot import JOINT_NAMES, PRISMATIC, Robot
from camtraj.timing import Limits, Take, TimingLimitError, time_shot
from camtraj.usd_shot import read_shot

from .conftest import pose_error
from .shot_set import (
    EFFORT,
    Cam,
    Design,
    SetShot,
    Speeds,
    _line,
    acceptance_set,
    max_speed,
    motion_end_set,
    speeds,
    write_design,
)

Array = NDArray[np.float64]
EFFORT_SHARE = 0.95  # the default must reach this share of the 10x-effort speed
ANALYTIC_RTOL = 1e-6  # the take's own derivatives against the limits
DIVIDED_RTOL = 1e-3  # divided differences against the limits (plus round-off, below)
EPS = float(np.finfo(np.float64).eps)
FK_TOL = 1e-9  # [m] and [rad]


@pytest.fixture(scope="module")
def shots(robot: Robot, tmp_path_factory: pytest.TempPathFactory) -> list[SetShot]:
    return acceptance_set(robot, tmp_path_factory.mktemp("acceptance"))


@pytest.fixture(scope="module")
def solved(robot: Robot, shots: list[SetShot]) -> dict[str, Speeds]:
    """Every shot solved three ways, on every core (each shot in one worker: the same
    answers as in this process, in a fraction of the time). The longest shots go first (the
    two-minute walk-along is a fifth of the work): the last to finish is a short one, not
    the walk-along left running alone on one core."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    workers = max(1, min(len(shots), os.cpu_count() or 1))
    longest_first = sorted(shots, key=lambda s: -s.targets.shape[0])
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
        results = list(pool.map(speeds, [robot] * len(shots), longest_first))
    by_name = {s.name: r for s, r in zip(longest_first, results, strict=True)}
    assert len(by_name) == len(shots)  # names are unique: nothing is overwritten
    return {s.name: by_name[s.name] for s in shots}  # in the set's order, as before


@pytest.fixture(scope="module")
def end_shots(robot: Robot, tmp_path_factory: pytest.TempPathFactory) -> list[SetShot]:
    return motion_end_set(robot, tmp_path_factory.mktemp("ends"))


def _amount(axis: int, value: float) -> str:
    """A position amount of an axis in m or deg."""
    return f"{value:.3g} m" if PRISMATIC[axis] else f"{math.degrees(value):.3g} deg"


def _fail_all(what: str, failures: list[str], total: int) -> None:
    if failures:
        pytest.fail(f"{what}: {len(failures)} of {total} shots fail:\n  " + "\n  ".join(failures))


# --------------------------------------------------------------------------------------------
# The set itself
# --------------------------------------------------------------------------------------------


def test_the_set_has_the_kinds_of_moves_the_issue_names(
        robot: Robot, shots: list[SetShot], end_shots: list[SetShot]) -> None:
    authored = [s for s in shots if not s.sample]
    assert len(authored) >= 30
    stages = {s.name: read_shot(s.path) for s in shots if s.path is not None}
    assert len(stages) == len(shots)
    rates = {Fraction(st.fps).limit_denominator(1001) for st in stages.values()}
    wanted = {Fraction(24000, 1001), Fraction(30000, 1001), *map(Fraction, (24, 25, 30, 48, 50,
                                                                           60))}
    assert wanted <= rates, f"missing frame rates {sorted(wanted - rates)}"
    units = {(st.up_axis, st.meters_per_unit) for st in stages.values()}
    assert {("Y", 0.01), ("Z", 1.0)} <= units
    assert any(st.time_codes_per_second == 10 * st.fps for st in stages.values())
    assert max(s.targets.shape[0] / s.fps for s in shots) >= 120.0
    far = [st for s, st in zip(shots, stages.values(), strict=True) if s.placement is not None]
    assert far and min(float(np.linalg.norm(st.cam2world[0, :3, 3])) for st in far) >= 2500.0
    # the short moves: 12 to 48 frames, in motion at an end, near both ends of the track
    assert len(end_shots) >= 12
    assert all(12 <= s.targets.shape[0] <= 48 for s in end_shots)
    for s in end_shots:
        solve_path(robot, s.targets, objective="paper")  # reachable: raises otherwise
        step = np.linalg.norm(s.targets[[1, -1], :3, 3] - s.targets[[0, -2], :3, 3], axis=1)
        turn = [pose_error(s.targets[i], s.targets[j])[1] for i, j in ((1, 0), (-1, -2))]
        assert max(step.max() * s.fps, max(turn) * s.fps) > 0.1, s.name  # m/s or rad/s


# --------------------------------------------------------------------------------------------
# (a) maximum feasible speed
# --------------------------------------------------------------------------------------------


def test_default_is_at_least_as_fast_as_paper_on_every_shot(
        solved: dict[str, Speeds]) -> None:
    failures = [f"{name}: default {s.default:.3f} < paper {s.paper:.3f} "
                f"(x{s.default / s.paper:.3f})" for name, s in solved.items()
                if not s.default >= s.paper]
    _fail_all("default slower than paper", failures, len(solved))


def test_default_is_within_5_percent_of_ten_times_the_effort_on_every_shot(
        solved: dict[str, Speeds]) -> None:
    failures = [f"{name}: default {s.default:.3f} < {EFFORT_SHARE:.0%} of {EFFORT}x effort "
                f"{s.effort:.3f} (x{s.default / s.effort:.3f})" for name, s in solved.items()
                if not s.default >= EFFORT_SHARE * s.effort]
    _fail_all(f"default below {EFFORT_SHARE:.0%} of {EFFORT}x effort", failures, len(solved))


MODEL_RTOL = 0.03  # the refinement's model of the take's speed against the timing stage's


def test_the_objectives_model_of_the_speed_is_the_timing_stages_on_every_shot(
        robot: Robot, shots: list[SetShot], solved: dict[str, Speeds]) -> None:
    """What the refinement lowers (the take's peak use along its banded model of the timing
    stage's spline, with the ends' stopping needs) gives the default's path the speed the
    timing stage finds, to 3%: where the model is wrong, the solver speeds up a take that
    does not exist (a held move's velocity read as jerk put the model 3x off the take; an
    end's room planned from its speed alone, 10%)."""
    from camtraj.ik.path import camera_holds
    from camtraj.ik.shot_cost import ShotCost
    from camtraj.ik.spline_ops import hold_runs

    failures = []
    for shot in shots:
        s = solved[shot.name]
        if not 0.0 < s.default < math.inf:
            continue
        held = camera_holds(shot.targets)
        cost = dataclasses.replace(ShotCost.for_robot(robot, 1.0 / shot.fps),
                                   holds=hold_runs(held),
                                   rests=(0, 0) if s.rest is None
                                   else (int(s.rest[0, 0]), int(s.rest[1, 0])))
        model = 1.0 / cost.peak(s.q_default)
        if abs(model / s.default - 1.0) > MODEL_RTOL:
            failures.append(f"{shot.name}: model {model:.3f} x real time, take "
                            f"{s.default:.3f} (x{model / s.default:.3f})")
    _fail_all("the objective's model of the speed is not the take's", failures, len(shots))


def test_the_feasible_frame_rate_does_not_depend_on_the_authored_rate(
        robot: Robot, tmp_path: Path) -> None:
    """The same 48 frames of a constant-speed push (1.5 m) authored at 24, 48 and 80 fps: the
    robot can play them at about the same frame rate whatever the file says. At 80 fps the
    programme ranks the arms by a proxy that misleads (its cheapest, the elbow flipped with
    the track 7 m away, refines to 64 fps; with the cheapest answer alone the rates were
    86, 109 and 64 fps, 0.58 of the best); starting from every arm gives 123, 123 and
    97 fps (0.79: from 80 fps the refinement still settles short of the 123 fps path)."""
    def push(_t: Array, u: Array) -> Cam:
        n = u.shape[0]
        pos = _line(u, (2.0, 0.0, 1.4), (3.5, 0.0, 1.4))
        return Cam(pos, np.zeros(n), np.full(n, -2.29))

    rates = {}
    for fps in (24.0, 48.0, 80.0):
        design = Design(f"push at {fps:g} fps", push, 47.0 / fps, fps)
        shot = read_shot(write_design(design, tmp_path))
        targets = shot.cam2world @ np.linalg.inv(robot.camera2flange)
        q = solve_path(robot, targets, frame_interval=1.0 / fps)
        rates[fps] = max_speed(robot, q, fps, targets) * fps
    low, high = min(rates.values()), max(rates.values())
    assert low >= 0.7 * high, (
        "feasible frame rate by authored rate: "
        + ", ".join(f"{f:g} fps -> {r:.1f} fps" for f, r in rates.items()))


def test_a_take_slower_than_its_maximum_speed_settles_gently(
        robot: Robot, tmp_path: Path) -> None:
    """The push at 24 fps plays up to about 5x faster, where its run-up and run-out need the
    full limits (gentle ends would need a slower take). Timed at its own speed it has room
    to settle gently: its ends are gentle, inside every limit, and its maximum feasible
    speed is still the one the full limits allow."""
    def push(_t: Array, u: Array) -> Cam:
        n = u.shape[0]
        return Cam(_line(u, (2.0, 0.0, 1.4), (3.5, 0.0, 1.4)), np.zeros(n), np.full(n, -2.29))

    shot = read_shot(write_design(Design("gentle push", push, 47.0 / 24.0, 24.0), tmp_path))
    q = solve_path(robot, shot.cam2world @ np.linalg.inv(robot.camera2flange),
                   frame_interval=1.0 / 24.0)
    limits = Limits.from_robot(robot)
    times = np.arange(q.shape[0]) / 24.0
    fast = time_shot(q, times, limits, mode="shot", edges="fast")
    take = time_shot(q, times, limits, mode="shot")
    gentle_max = time_shot(q, times, limits, mode="scale", edges="gentle")
    assert fast.report.max_speed > 1.5  # the full limits allow a much faster take
    assert take.report.runup["edges"] == take.report.runout["edges"] == "gentle"
    assert not any("gentle run-up/run-out would need" in w for w in take.report.warnings)
    assert take.report.max_speed == pytest.approx(fast.report.max_speed, rel=1e-9)
    assert take_problems(take, limits) == []
    # and the gentle ends were the costly ones at that speed: the report says the scale
    # take's maximum feasible speed uses the full limits
    assert gentle_max.report.max_speed == pytest.approx(fast.report.max_speed, rel=1e-9)
    assert take.report.runup["duration"] > fast.report.runup["duration"]


# --------------------------------------------------------------------------------------------
# (b), (c) every shot converts with shot or scale timing, inside every limit
# --------------------------------------------------------------------------------------------


def divided(t: Array, q: Array, order: int) -> Array:
    """order! times the order-th divided differences of q (m, 8) over t (m,)."""
    d = q
    for k in range(1, order + 1):
        d = k * (d[1:] - d[:-1]) / (t[k:] - t[:-k])[:, None]
    return d


def take_problems(take: Take, limits: Limits) -> list[str]:
    """Every way the take's servo samples leave a limit (empty: none), worst of each kind."""
    out = []
    below, above = limits.lower - take.q, take.q - limits.upper
    over = np.maximum(below, above)
    if over.max() > 0.0:
        i, j = np.unravel_index(int(np.argmax(over)), over.shape)
        out.append(f"{JOINT_NAMES[j]} position {_amount(int(j), float(over[i, j]))} beyond "
                   f"its limit at t={take.t[i]:.4f} s")
    h = float(np.diff(take.t).min())
    q_max = np.abs(take.q).max(axis=0)
    for order, (name, bound, own) in enumerate(
            (("velocity", limits.velocity, take.qd), ("acceleration", limits.acceleration,
                                                      take.qdd),
             ("jerk", limits.jerk, take.qddd)), start=1):
        use = np.abs(own) / bound
        if use.max() > 1.0 + ANALYTIC_RTOL:
            i, j = np.unravel_index(int(np.argmax(use)), use.shape)
            out.append(f"{JOINT_NAMES[j]} {name} {use[i, j]:.4f} x its limit at "
                       f"t={take.t[i]:.4f} s (stated)")
        tol = 2.0 * 2.0**order * 4.0 * EPS * q_max / h**order  # round-off of the differences
        dd = np.abs(divided(take.t, take.q, order))
        excess = (dd - tol) / bound
        if excess.max() > 1.0 + DIVIDED_RTOL:
            i, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
            out.append(f"{JOINT_NAMES[j]} {name} {excess[i, j]:.4f} x its limit at "
                       f"t={take.t[i]:.4f} s (divided differences)")
    return out


def convert_problem(take_for: dict[str, object], limits: Limits) -> str | None:
    """None if the shot converts with shot or scale timing inside every limit, else why not.

    ``take_for`` maps a timing mode to its take or to the error it raised.
    """
    errors = []
    for mode in ("shot", "scale"):
        result = take_for[mode]
        if isinstance(result, Take):
            problems = take_problems(result, limits)
            if not problems:
                return None
            errors.append(f"{mode}: take leaves a limit: {'; '.join(problems)}")
        else:
            errors.append(f"{mode}: {result}")
    return " | ".join(errors)


def timed(q: Array, shot: SetShot, limits: Limits,
          rest: NDArray[np.bool_] | None = None) -> dict[str, object]:
    """The takes ``convert`` makes of the joint path ``q`` (default objective, from home; at
    rest on the end frames ``rest`` says)."""
    out: dict[str, object] = {}
    times = np.arange(q.shape[0]) / shot.fps
    for mode in ("shot", "scale"):
        try:
            out[mode] = time_shot(q, times, limits, mode=mode, rest=rest)
        except TimingLimitError as exc:
            out[mode] = str(exc)
        if isinstance(out[mode], Take) and not take_problems(out[mode], limits):  # type: ignore[arg-type]
            break
    return out


def test_every_shot_converts_with_shot_or_scale_timing_inside_every_limit(
        robot: Robot, shots: list[SetShot], solved: dict[str, Speeds]) -> None:
    limits = Limits.from_robot(robot)
    failures = []
    for shot in shots:
        s = solved[shot.name]
        problem = convert_problem(timed(s.q_default, shot, limits, s.rest), limits)
        if problem is not None:
            failures.append(f"{shot.name}: {problem}")
    _fail_all("no jerk-limited take inside the limits", failures, len(shots))


def test_short_moves_ending_in_motion_convert_with_shot_or_scale_timing(
        robot: Robot, end_shots: list[SetShot]) -> None:
    """Through ``convert``'s own analysis (read, place, solve, time) from the USD stage."""
    limits = Limits.from_robot(robot)
    failures = []
    for shot in end_shots:
        assert shot.path is not None
        take_for: dict[str, object] = {}
        for mode in ("shot", "scale"):
            try:
                take_for[mode] = analyse(shot.path, ConvertOptions(
                    timing=mode, placement=shot.placement)).take
            except CamtrajError as exc:
                take_for[mode] = f"{type(exc).__name__}: {exc}"
            if isinstance(take_for[mode], Take) and not take_problems(
                    take_for[mode], limits):  # type: ignore[arg-type]
                break
        else:
            failures.append(f"{shot.name}: {convert_problem(take_for, limits)}")
    _fail_all("short move in motion has no jerk-limited take", failures, len(end_shots))


# --------------------------------------------------------------------------------------------
# (d) large jumps between frames
# --------------------------------------------------------------------------------------------

#: (shot name prefix, keep every k-th frame): steps of 10-40 cm and 10-40 degrees per frame.
JUMPS = (("orbit 360 eased", 10), ("orbit 360 constant", 10), ("orbit 360 low", 16),
         ("walk-along", 24), ("handheld walk 8 s", 8), ("crane-up to top-down turning", 10),
         ("swing across the track", 10), ("dutch rocking roll", 12), ("car mount", 10),
         ("follow a runner", 20))


def test_paths_with_jumps_stay_inside_the_limits_and_reach_every_pose(
        robot: Robot, shots: list[SetShot]) -> None:
    failures = []
    for prefix, k in JUMPS:
        shot = next(s for s in shots if s.name.startswith(prefix))
        targets = shot.targets[::k]
        solve_path(robot, targets, objective="paper")  # reachable: raises otherwise
        q = solve_path(robot, targets, frame_interval=1.0 / shot.fps)
        over = np.maximum(robot.lower - q, q - robot.upper)
        dp, dr = pose_error(robot.fk(q), targets)
        problems = []
        if over.max() > 0.0:
            frames = np.flatnonzero(over.max(axis=1) > 0.0)
            i, j = np.unravel_index(int(np.argmax(over)), over.shape)
            problems.append(f"{frames.size} of {q.shape[0]} frames outside a position limit, "
                            f"worst {JOINT_NAMES[j]} by {_amount(int(j), float(over[i, j]))} "
                            f"at frame {i}")
        if dp > FK_TOL or dr > FK_TOL:
            problems.append(f"FK error {dp:.3g} m, {dr:.3g} rad")
        if problems:
            failures.append(f"{shot.name} every {k}th frame: {'; '.join(problems)}")
    _fail_all("paths with jumps", failures, len(JUMPS))
