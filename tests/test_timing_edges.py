"""The timing path and the take's edges (issue 13 items 2 and 4, issue 15 section 1).

Facts used:
* symmetry: a move whose one axis turns exactly half-way between two frames (two equal
  solutions of that axis) is the same move as one turning a hair later, so both fit at the
  same speed;
* the convex hull and the limits: between frames that are inside an axis's range, or on its
  limit, the path is inside at every sample of a grid far finer than any servo rate;
* divided differences: on any grid ``k! * f[t0..tk]`` is a weighted mean of the k-th
  derivative, so the sampled positions of a take inside its limits keep every divided
  difference inside them whatever the reported derivatives say.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.robot import Robot
from camtraj.timing import Limits, Take, TimingLimitError, time_shot
from camtraj.timing.path import FramePath
from tests.timing_checks import FPS, HOME, SLACK, divided

Array = NDArray[np.float64]
TRACK, ROTATE, LIFT, EXTEND, ELBOW, PAN, TILT, ROLL = range(8)


def assert_take_inside(take: Take, limits: Limits) -> None:
    """Every servo sample of the whole take (run-up, shot, run-out) inside every limit: the
    values written and the divided differences of the sampled positions."""
    assert np.all(take.q <= limits.upper) and np.all(take.q >= limits.lower)
    for arr, bound in ((take.qd, limits.velocity), (take.qdd, limits.acceleration),
                       (take.qddd, limits.jerk)):
        assert np.all(np.abs(arr) <= bound * (1 + 1e-9))
    for order, bound in ((1, limits.velocity), (2, limits.acceleration), (3, limits.jerk)):
        worst = float(np.max(np.abs(divided(take.t, take.q, order)) / bound))
        assert worst <= 1 + SLACK, f"order {order}: {worst:.6f} of the limit"


# ---------------------------------------------------------------------------------------------
# Holds are holds of the camera, not turning points of one axis
# ---------------------------------------------------------------------------------------------


def turning(shift: float, n: int = 48) -> tuple[Array, Array]:
    """The track moves through while rotate turns at the middle of the shot (+ ``shift`` s).

    With an even frame count and no shift, the turning point is exactly half-way between
    two frames, so those two rotate values are equal bit for bit.
    """
    i = np.arange(n)
    t = (i - (n - 1) / 2) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 0.4 * t
    q[:, ROTATE] += 0.3 * np.cos(1.5 * (t - shift))
    q[:, PAN] += -0.2 * t
    return i / FPS, q


@pytest.mark.parametrize("mode", ["shot", "scale"])
def test_a_turning_point_fits_at_the_same_speed_as_a_shifted_one(
    limits: Limits, mode: str
) -> None:
    t, q = turning(0.0)
    assert np.sum(q[1:, ROTATE] == q[:-1, ROTATE]) == 1  # the symmetric case
    t2, q2 = turning(1e-4)
    assert np.all(np.abs(np.diff(q2[:, ROTATE])) > 1e-9)
    a = time_shot(q, t, limits, mode=mode)
    b = time_shot(q2, t2, limits, mode=mode)
    assert a.report.max_speed == pytest.approx(b.report.max_speed, rel=0.02)
    # And the turning axis moves through its turning point (no stop there).
    k = a.frame_samples[24]
    assert a.report.peak_use["rotate"]["acceleration"] == pytest.approx(
        b.report.peak_use["rotate"]["acceleration"], rel=0.02)
    assert abs(a.qdd[k, ROTATE]) > 0.5 * 0.3 * 1.5**2


def test_a_camera_hold_mask_keeps_a_still_robot_moving_when_the_camera_moves(
    limits: Limits,
) -> None:
    # Only rotate moves, and it turns half-way between frames 23 and 24: the whole robot
    # is still there, but the camera is not; with the camera's hold mask it is no hold.
    t, q = turning(0.0)
    q[:, TRACK] = HOME[TRACK]
    q[:, PAN] = HOME[PAN]
    plain = time_shot(q, t, limits, mode="scale")
    camera = time_shot(q, t, limits, mode="scale", hold=np.zeros(q.shape[0] - 1, dtype=bool))
    assert camera.report.max_speed > 2.0 * plain.report.max_speed
    # A held camera stays a hold (the robot exactly still between those frames).
    q[:10] = q[10]
    mask = np.zeros(q.shape[0] - 1, dtype=bool)
    mask[:10] = True
    take = time_shot(q, t, limits, mode="scale", hold=mask)
    a, b = take.frame_samples[0], take.frame_samples[10]
    assert np.all(take.q[a : b + 1] == q[0])
    assert np.all(take.qd[a : b + 1] == 0.0)


# ---------------------------------------------------------------------------------------------
# Between frames the path stays inside, also with frames on a limit (to round-off)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(8))
def test_frames_on_a_limit_give_a_path_inside_at_every_sample(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 60
    lower, upper = np.full(8, -0.05), np.full(8, 0.05)
    scale = 0.01 if seed % 2 else 0.02
    q = np.clip(np.cumsum(rng.normal(scale=scale, size=(n, 8)), axis=0), lower, upper)
    on = np.abs(np.abs(q) - 0.05) == 0.0
    assert np.sum(on) > 10
    # Within round-off of the limit: on it, or up to 1e-9 inside.
    inside = rng.uniform(0.0, 1e-9, size=q.shape) * (rng.random(q.shape) < 0.5)
    q = np.where(on, np.sign(q) * (0.05 - inside), q)
    path = FramePath.fit(q, 1 / FPS, lower, upper)
    x = np.linspace(0.0, n - 1.0, 500 * (n - 1) + 1)
    dense = path.at(x, 0)[0]
    assert np.all(dense <= upper) and np.all(dense >= lower)
    for ticks in (1, 3, 10, 41):
        _, (grid, *_) = path.on_grid(ticks)
        assert np.all(grid <= upper) and np.all(grid >= lower)
        assert np.array_equal(grid[::ticks], q)


def test_a_frame_a_hair_beyond_a_limit_takes_the_path_no_further(limits: Limits) -> None:
    # The elbow rides its upper limit (0) at the end, one frame 1e-12 rad beyond it.
    n = 48
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 0.3 * t
    q[:, ELBOW] = np.minimum(0.0, -0.4 + 0.5 * t)
    q[-3, ELBOW] = 1e-12
    path = FramePath.fit(q, 1 / FPS, limits.lower, limits.upper)
    x = np.linspace(0.0, n - 1.0, 500 * (n - 1) + 1)
    dense = path.at(x, 0)[0]
    assert dense[:, ELBOW].max() <= 1e-12
    take = time_shot(q, t, limits, mode="scale")
    assert take.q[:, ELBOW].max() <= 1e-12


# ---------------------------------------------------------------------------------------------
# --timing scale finds the factor that leaves the run-up and run-out room
# ---------------------------------------------------------------------------------------------


def towards_limit(axis: int, n: int, gap: float, speed: float, side: int) -> tuple[Array, Array]:
    """The track moves on while ``axis`` ends ``gap`` from its upper (side +1) or lower (-1)
    limit, moving towards it at ``speed`` [m/s or rad/s] until the last frame."""
    lim = Limits.from_robot(Robot.default())
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 0.5 * t
    bound = lim.upper[axis] if side > 0 else lim.lower[axis]
    q[:, axis] = bound - side * gap + side * speed * (t - t[-1])
    return t, q


def test_a_lens_motor_on_its_limit_moving_into_it_is_told_to_ease_or_widen(
        limits: Limits) -> None:
    """A lens motor, not a joint, on its limit and moving into it on the last frame: the
    advice is the lens's (ease the pull out to rest there, or set the motor's limit past
    it), not the IK's, which does not drive a lens (a new user's focus pull)."""
    focus = Limits(np.zeros(1), np.radians([300.0]), np.radians([180.0]),
                   np.radians([720.0]), np.radians([7200.0]), names=("focus",),
                   kinds=("revolute",))
    both = limits.joined(focus)
    t = np.arange(24) / FPS
    q = np.tile(np.concatenate([HOME, [0.0]]), (24, 1))
    q[:, 8] = 0.5 * (t[-1] - t)  # the focus ring turns down onto its lower limit, 0 deg
    with pytest.raises(TimingLimitError, match=r"focus is 0 deg from its lower limit 0 deg "
                       r"and moves towards it there; ease the focus move out to rest there, or "
                       r"set the motor's limit past it in the lens file"):
        time_shot(q, t, both, mode="scale")


NEAR_LIMITS = [  # (axis, frames, gap, speed, side): all need a slower take for their run-out
    (ELBOW, 24, 0.02, 0.3, -1),  # elbow towards -180 deg
    (ELBOW, 12, 0.02, 0.5, -1),
    (PAN, 48, 0.1, 1.5, +1),  # pan towards +270 deg
    (EXTEND, 24, 0.02, 0.3, -1),  # extend towards 0 m
    (TRACK, 36, 0.2, 1.2, +1),  # the end of the track
]


@pytest.mark.parametrize("edges", ["gentle", "fast"])
@pytest.mark.parametrize("case", NEAR_LIMITS)
def test_moves_ending_in_motion_near_a_limit_convert_with_scale(
    limits: Limits, case: tuple[int, int, float, float, int], edges: str
) -> None:
    t, q = towards_limit(*case)
    take = time_shot(q, t, limits, mode="scale", edges=edges)
    assert take.speed_factor > 1.0
    assert take.report.runout["duration"] > 0.0
    assert np.max(np.abs(take.q[take.frame_samples] - q)) < 1e-12
    assert_take_inside(take, limits)
    # The smallest such factor: 1% faster the run-out has no room (or the shot its limits).
    with pytest.raises(TimingLimitError, match=r"needs more room|exceeds"):
        time_shot(q, t * (take.speed_factor / 1.01), limits, mode="shot", edges=edges)
    # The shot's own timing fails, and says scale fits it, at the factor scale takes.
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits, mode="shot", edges=edges)
    err = info.value
    assert "needs more room" in str(err)
    assert err.scale_factor == pytest.approx(take.speed_factor, rel=1e-9)
    assert f"fits at {math.floor(100 / take.speed_factor)}% speed" in str(err)
    assert str(err).endswith("try --timing scale")


@pytest.mark.parametrize(("axis", "toward_upper"), [(TRACK, True), (EXTEND, False)])
def test_the_slowest_take_whose_run_out_fits_stops_inside_the_limit(
    limits: Limits, axis: int, toward_upper: bool
) -> None:
    """A move still speeding towards a limit at its last frame, from rest: scale
    timing slows it until the run-out's stop fits before the limit, and at that factor the
    stop ends inside it, not on it plus round-off (with a 1e-9 relative tolerance in the
    room check, moves like these stopped up to 1.5e-8 m past the limit)."""
    n, slowed = 25, 0
    # from rest, speeding up to 1.5 (track) or 1.2 m/s (extend) at the last frame: stops
    # longer than the room
    travel = 0.75 if toward_upper else 0.6
    for room in np.linspace(0.05, 0.3, 13):
        for fps in (24.0, 25.0):
            q = np.tile([5.0, 0.0, 0.0, 0.6, -1.5, 0.0, 0.0, 0.0], (n, 1))
            end = limits.upper[axis] - room if toward_upper else limits.lower[axis] + room
            left = 1.0 - np.linspace(0.0, 1.0, n) ** 2  # of the travel
            q[:, axis] = end - travel * left if toward_upper else end + travel * left
            take = time_shot(q, np.arange(n) / fps, limits, mode="scale")
            slowed += take.speed_factor > 1.0  # the room decides it
            assert np.all(take.q <= limits.upper) and np.all(take.q >= limits.lower), (
                room, fps)
    assert slowed == 26


@pytest.mark.parametrize(("gap", "axis", "side"), [(0.0, ELBOW, -1), (1e-7, LIFT, +1)])
def test_an_axis_on_its_limit_moving_into_it_needs_another_ik_answer(
    limits: Limits, gap: float, axis: int, side: int
) -> None:
    t, q = towards_limit(axis, 24, gap, 0.3, side)
    name = limits.names[axis]
    with pytest.raises(TimingLimitError, match=rf"run-out from frame 23 has no room even "
                       rf"1000x slower: {name} is .* from its .* limit .*; ease the camera "
                       rf"move out to rest there, or place the track so that {name} is off "
                       rf"its limit"):
        time_shot(q, t, limits, mode="scale")
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits, mode="shot")
    assert math.isinf(info.value.scale_factor)
    assert "try --timing scale" not in str(info.value)
    assert "--timing scale does not fit it either" in str(info.value)
    # The run-up side: the same move reversed in time starts on the limit.
    with pytest.raises(TimingLimitError, match="run-up into frame 0 has no room"):
        time_shot(q[::-1], t, limits, mode="scale")


# ---------------------------------------------------------------------------------------------
# Gentle run-ups and run-outs
# ---------------------------------------------------------------------------------------------


def in_motion(seed: int) -> tuple[Array, Array]:
    """A shot in motion at both ends on every axis, mid-range."""
    rng = np.random.default_rng(seed)
    n = 73
    t = np.arange(n) / FPS
    amp = rng.uniform(0.05, 0.3, 8) * np.array([3, 1, 1, 0.5, 1, 1, 1, 1])
    omega = rng.uniform(0.5, 2.5, 8)
    q = HOME + amp * np.sin(omega * t[:, None] + rng.uniform(0, 2 * np.pi, 8))
    return t, q


SAMPLES = Path(__file__).resolve().parent.parent / "samples" / "shots"


@pytest.mark.parametrize("sample", ["maya_dolly_push_in", "blender_crane_up",
                                    "orbit_animated_parent", "whip_pan"])
def test_every_sample_take_runs_up_and_out_gently(robot: Robot, sample: str) -> None:
    """Issue 15: in every shipped sample's take (shot timing, or scale where the shot cannot
    run at its own), the run-up and run-out use no more of any axis's acceleration and jerk
    limits than the shot itself, or a quarter of them, measured on the written samples."""
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions

    limits = Limits.from_robot(robot)
    shot = SAMPLES / f"{sample}.usda"
    try:
        take = analyse(shot, ConvertOptions()).take
    except TimingLimitError:
        take = analyse(shot, ConvertOptions(timing="scale")).take
    assert take is not None
    assert_take_inside(take, limits)
    a, b = take.frame_samples[0], take.frame_samples[-1]
    for part, report in ((slice(0, a + 1), take.report.runup),
                         (slice(b, None), take.report.runout)):
        assert report["edges"] == "gentle"
        for quantity, order, bound in (("acceleration", 2, limits.acceleration),
                                       ("jerk", 3, limits.jerk)):
            if take.t[part].size <= order:  # the shot starts (or ends) at rest: no move
                continue
            allowed = np.maximum([take.report.peak_use[n][quantity] for n in limits.names],
                                 0.25)
            est = np.abs(divided(take.t[part], take.q[part], order)).max(axis=0) / bound
            assert np.all(est <= allowed * (1 + 1e-6) + 1e-9), (quantity, est, allowed)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("start", [False, True])
def test_gentle_edges_use_no_more_than_the_shot_or_a_quarter(
    limits: Limits, seed: int, start: bool
) -> None:
    t, q = in_motion(seed)
    begin = HOME + 0.1 if start else None
    gentle = time_shot(q, t, limits, mode="scale", start=begin)
    fast = time_shot(q, t, limits, mode="scale", start=begin, edges="fast")
    assert_take_inside(gentle, limits)
    assert_take_inside(fast, limits)
    a, b = gentle.frame_samples[0], gentle.frame_samples[-1]
    for part, report in ((slice(0, a), gentle.report.runup),
                         (slice(b + 1, None), gentle.report.runout)):
        assert report["edges"] == "gentle"
        for quantity, values, bound in (("acceleration", gentle.qdd, limits.acceleration),
                                        ("jerk", gentle.qddd, limits.jerk)):
            shot_use = np.array([gentle.report.peak_use[n][quantity] for n in limits.names])
            edge_use = np.max(np.abs(values[part]), axis=0) / bound
            assert np.all(edge_use <= np.maximum(shot_use, 0.25) * (1 + 1e-9))
            # The report gives the same figures, separately from the shot's.
            reported = np.array([report["peak_use"][n][quantity] for n in limits.names])
            assert np.allclose(reported, edge_use, rtol=1e-12, atol=0)
            # Measured from the positions too: the divided differences of the edge's
            # samples are means of its acceleration / jerk.
            order = 2 if quantity == "acceleration" else 3
            est = np.abs(divided(gentle.t[part], gentle.q[part], order)) / bound
            if est.size:
                assert np.all(est <= np.maximum(shot_use, 0.25) * (1 + 1e-6) + 1e-9)
    # The time-optimal edges are shorter, and use more of some limit.
    assert fast.report.runout["duration"] < gentle.report.runout["duration"]
    assert fast.report.runup["duration"] < gentle.report.runup["duration"]
    fast_jerk = max(u["jerk"] for u in fast.report.runout["peak_use"].values())
    assert fast_jerk == pytest.approx(1.0, rel=1e-6)


# ---------------------------------------------------------------------------------------------
# What check and convert say, and the take of real shots
# ---------------------------------------------------------------------------------------------


def test_check_advises_scale_only_when_scale_fits(limits: Limits) -> None:
    from camtraj.cli import _limit_report, _report
    from camtraj.options import ConvertOptions

    shot = ConvertOptions()
    for case, fits in ((NEAR_LIMITS[1], True), ((ELBOW, 24, 0.0, 0.3, -1), False)):
        t, q = towards_limit(*case)
        with pytest.raises(TimingLimitError) as info:
            time_shot(q, t, limits)
        result = _limit_report("move.usda", info.value, shot)
        text = _report(result)
        assert ("try --timing scale" in text) == fits, text
        assert "needs more room" in text  # what fails is said, also with no violation
        if fits:
            scale = time_shot(q, t, limits, mode="scale")
            assert result["scale_factor"] == pytest.approx(scale.speed_factor)
        else:
            assert result["scale_factor"] is None
            assert "ease the camera move out to rest there" in text
    # Asked for scale, it never advises scale.
    t, q = towards_limit(ELBOW, 24, 0.0, 0.3, -1)
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits, mode="scale")
    text = _report(_limit_report("move.usda", info.value, ConvertOptions(timing="scale")))
    assert "try --timing scale" not in text


def test_check_says_why_the_run_up_does_not_fit_beside_the_shots_own_excess(
        limits: Limits) -> None:
    """A push starting 1 cm from the track's end at 1.5 m/s, the elbow 8% over its
    acceleration limit: check lists the elbow and says the run-up needs more room (what
    makes the take 7% of real time, not the elbow's 96%), as convert's error does."""
    from camtraj.cli import _limit_report, _report
    from camtraj.options import ConvertOptions

    n = 10
    t = np.arange(n) / FPS
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = limits.lower[TRACK] + 0.01 + 1.5 * t
    q[:, ELBOW] -= 0.5 * 1.08 * limits.acceleration[ELBOW] * t**2
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits)
    room = "the run-up into frame 0"
    assert room in str(info.value)  # convert's error line
    result = _limit_report("push.usda", info.value, ConvertOptions())
    assert [v["axis"] for v in result["violations"]] == ["elbow"]
    assert result["room"].startswith(room) and "track goes" in result["room"]
    lines = _report(result).splitlines()
    assert lines[1].strip().startswith("elbow acceleration")
    assert lines[2].strip() == result["room"], lines


def test_camera_holds_are_equal_consecutive_poses() -> None:
    from camtraj.ik import camera_holds

    poses = np.tile(np.eye(4), (6, 1, 1))
    poses[:, 0, 3] = [0.0, 0.0, 0.1, 0.1 + 1e-13, 0.2, 0.3]
    poses[5, :3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    assert camera_holds(poses).tolist() == [True, False, True, False, False]


def write_slide(path: Path, shift: float) -> Path:
    """A camera sliding sideways across the track line (y through 0 at mid-shot, + shift)
    at a constant 0.6 m/s, 24 fps, 48 frames, Z-up metres."""
    from .shot_set import make_samples

    ms = make_samples()
    frames = np.arange(1, 49, dtype=np.float64)
    t = (frames - 1) / FPS
    y = 0.6 * (t - t[-1] / 2) + shift
    pos = np.stack([np.full_like(t, 4.0), y, np.full_like(t, 1.2)], axis=1)
    move = ms.Move(frames, pos, np.zeros_like(t), np.full_like(t, -5.0), 35.0, 3.0, 2.8)
    body = ms._scope("Xform", "World", [ms._camera_prim_trs("cam", move, "Z", 1.0, "    ")])
    text = ms._header("lateral slide", "Z", 1.0, frames, FPS, "World") + "\n" + body
    path.write_text(text + "\n", encoding="utf-8")
    return path


def test_a_slide_across_the_track_line_fits_as_the_same_slide_moved_1_mm(
    tmp_path: Path,
) -> None:
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions

    speeds = []
    for shift in (0.0, 0.001):
        take = analyse(write_slide(tmp_path / f"slide{shift}.usda", shift),
                       ConvertOptions(timing="scale")).take
        assert take is not None
        speeds.append(take.report.max_speed)
    assert speeds[0] == pytest.approx(speeds[1], rel=0.02)


SAMPLE_SHOTS = Path(__file__).resolve().parents[1] / "samples" / "shots"


@pytest.mark.parametrize("name", ["maya_dolly_push_in", "blender_crane_up", "whip_pan",
                                  "orbit_animated_parent"])
def test_sample_takes_settle_gently_into_and_out_of_the_move(name: str) -> None:
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions

    limits = Limits.from_robot(Robot.default())
    take = analyse(SAMPLE_SHOTS / f"{name}.usda", ConvertOptions(timing="scale")).take
    assert take is not None
    assert_take_inside(take, limits)
    for report in (take.report.runup, take.report.runout):
        for axis, use in report.get("peak_use", {}).items():
            for quantity in ("acceleration", "jerk"):
                own = take.report.peak_use[axis][quantity]
                assert use[quantity] <= max(own, 0.25) * (1 + 1e-9), (axis, quantity)


@pytest.mark.parametrize("kind", ["stop", "start"])
def test_edge_samples_are_ruckigs_own_evaluation(limits: Limits, kind: str) -> None:
    from camtraj.timing.edges import _Move, _stop_move

    rng = np.random.default_rng(5)
    zero = np.zeros(8)
    for _ in range(10):
        p = rng.uniform(-1.0, 1.0, 8)
        v = rng.uniform(-1.0, 1.0, 8) * limits.velocity
        a = rng.uniform(-1.0, 1.0, 8) * limits.acceleration
        if kind == "stop":
            move = _stop_move(p, v, a, limits)
        else:
            move = _Move((p + rng.uniform(-0.5, 0.5, 8), zero, zero), (p, 0.5 * v, 0.5 * a),
                         limits, stop=False, what="a test run-up")
        t = np.linspace(1e-9, move.duration * (1 - 1e-9), 401)
        pos, vel, acc, jerk = move.sample(t)
        for i, tm in enumerate(t.tolist()):
            want = move._traj.at_time(tm)
            assert np.allclose(pos[i], want[0], rtol=0, atol=1e-12)
            assert np.allclose(vel[i], want[1], rtol=0, atol=1e-12)
            assert np.allclose(acc[i], want[2], rtol=0, atol=1e-12)
        assert np.all(np.abs(jerk) <= limits.jerk * (1 + 1e-12))
        # Jerk is the derivative of the acceleration (a mean of it over each step).
        slope = np.diff(acc, axis=0) / np.diff(t)[:, None]
        assert np.all(np.abs(slope) <= limits.jerk * (1 + 1e-9))
        mid = 0.5 * (t[1:] + t[:-1])
        centre = move.sample(mid)[3]
        same = jerk[:-1] == jerk[1:]  # no phase change inside the step: the slope is exact
        assert np.allclose(slope[same], centre[same], rtol=1e-6, atol=1e-9 * limits.jerk.max())
