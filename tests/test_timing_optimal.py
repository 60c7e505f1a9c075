"""Tests of ``"optimal"`` timing: jerk-limited, never slower than ``"scale"``, frames on samples.

Facts used:
* divided differences: on any grid, ``k! * q[t0..tk]`` is a weighted mean of the k-th
  derivative of any C^(k-1) function through the samples with a piecewise continuous k-th
  derivative, so the divided differences of the sampled positions of a take that is inside
  its limits everywhere (not only at the samples) never exceed the limits. Their only error is
  float round-off: third differences of positions up to ~6 m over 4 ms steps carry ~1e-7 m/s³,
  far below :data:`DIFF_RTOL` of the smallest jerk limit;
* the scale take (the same path slowed uniformly) is one feasible timing, so a time-optimal
  one is never longer;
* joint paths solved from the repository's sample shots (read with camtraj's reader, solved by
  the shot solver) and synthetic paths built by hand.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.ik.path import solve_path
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.timing import Limits, Take, TimingLimitError, time_shot
from camtraj.timing.clock import MAX_FRAME_RATE
from camtraj.usd_shot import read_shot
from tests.shot_set import SAMPLES, SHOTS
from tests.timing_checks import FPS, HOME, divided, frame_times

Array = NDArray[np.float64]
TRACK = JOINT_NAMES.index("track")
ROTATE = JOINT_NAMES.index("rotate")
#: Analytic values may exceed a limit by float round-off only.
RTOL = 1e-9
#: Divided differences of the sampled positions may exceed a limit by this fraction (round-off
#: of third differences; see the module docstring).
DIFF_RTOL = 1e-6


def _synthetic() -> dict[str, tuple[Array, float]]:
    """name -> (joint path (n, 8), fps)."""
    out: dict[str, tuple[Array, float]] = {}
    # Two moves with a hold between them (frames 72-120: nothing moves), from rest to rest.
    n = 24 * 8 + 1
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    s1 = np.clip(t / 3.0, 0, 1)
    s2 = np.clip((t - 5.0) / 3.0, 0, 1)
    q[:, TRACK] += 2.0 * (s1 - np.sin(2 * np.pi * s1) / (2 * np.pi))
    q[:, ROTATE] += 1.2 * np.sin(np.pi * s1) ** 2 - 0.8 * (1 - np.cos(np.pi * s2)) / 2
    q[:, 6] += 0.5 * (1 - np.cos(np.pi * s2)) / 2
    out["hold between two moves"] = (q, FPS)
    # Every axis moving at both ends, 30 fps, too fast for real time on some axes.
    t = frame_times(91, 30.0)
    amp = np.array([1.5, 1.2, 0.4, 0.3, 0.6, 1.0, 0.8, 0.5])
    periods = np.array([2.1, 1.7, 2.9, 3.3, 1.3, 1.9, 2.3, 2.7])
    out["all axes in motion"] = (HOME + amp * np.sin(2 * np.pi * t[:, None] / periods + 0.4),
                                 30.0)
    # Long enough for several windows of the solver (300 frames), a slow and a fast part.
    t = frame_times(300)
    q = np.tile(HOME, (t.size, 1))
    q[:, TRACK] += 3.0 * np.sin(2 * np.pi * t / 12.5) ** 2
    q[:, ROTATE] += 0.6 * np.sin(2 * np.pi * t / 4.0) * np.exp(-t / 6.0)
    q[:, 5] += 0.4 * np.sin(2 * np.pi * t / 3.0)
    out["long, several windows"] = (q, FPS)
    # A quick pan at the start (it sets the uniform take's speed), then a slow track push
    # easing to rest at the end: the windows in between run several times faster than the
    # end may, and the last window must still reach it (it had no answer: the take fell back
    # to the uniform one).
    t = frame_times(200, 50.0)
    q = np.tile(HOME, (t.size, 1))
    w = np.clip(t / 0.5, 0, 1)
    q[:, 5] += 0.6 * (w - np.sin(2 * np.pi * w) / (2 * np.pi))
    u = np.clip((t - (t[-1] - 1.2)) / 1.2, 0, 1)
    q[:, TRACK] += 0.15 * np.minimum(t, t[-1] - 1.2) + 0.15 * 1.2 * (u - u**2 / 2)
    out["easy stretch easing to rest"] = (q, 50.0)
    # Three frames only.
    q = np.tile(HOME, (3, 1))
    q[:, ROTATE] += [0.0, 0.05, 0.12]
    out["three frames"] = (q, FPS)
    # A three-frame nudge of the track: the shot part could run 20x faster than real time,
    # but ends from that speed are far longer than the whole real-time take (3.3 s against
    # 0.86 s): the retime starts and ends no faster than the real-time take does.
    q = np.tile(HOME, (3, 1))
    q[:, TRACK] += [0.0, 0.002, 0.005]
    out["three-frame nudge"] = (q, FPS)
    # A creep of 1 mm/s for 20 s: the limits would let it run 2000x faster; played 1000x
    # faster its frames were 42 us apart and the file's nanosecond stamps read 1843x the
    # track's jerk limit (clock.MAX_FRAME_RATE).
    t = frame_times(481)
    q = np.tile(HOME, (t.size, 1))
    q[:, TRACK] += 0.001 * t
    out["creep"] = (q, FPS)
    return out


SYNTHETIC = _synthetic()


@pytest.fixture(scope="module")
def sample_paths(robot: Robot) -> dict[str, tuple[Array, float]]:
    """The samples' joint paths as camtraj solves them (robot base at the stage origin)."""
    flange2camera = np.linalg.inv(robot.camera2flange)
    out = {}
    for name in SAMPLES:
        shot = read_shot(SHOTS / name)
        targets = shot.cam2world @ flange2camera
        out[name] = (solve_path(robot, targets, frame_interval=1.0 / shot.fps),
                     float(shot.fps))
    return out


@pytest.fixture(scope="module")
def takes(
    sample_paths: dict[str, tuple[Array, float]], limits: Limits
) -> dict[str, tuple[Array, Take, Take]]:
    """name -> (joint path, optimal take, scale take)."""
    out = {}
    for name, (q, fps) in {**sample_paths, **SYNTHETIC}.items():
        t = frame_times(q.shape[0], fps)
        out[name] = (q, time_shot(q, t, limits, mode="optimal"),
                     time_shot(q, t, limits, mode="scale"))
    return out


NAMES = [*SAMPLES, *SYNTHETIC]


@pytest.mark.parametrize("name", NAMES)
def test_every_sample_is_inside_every_limit(
    takes: dict[str, tuple[Array, Take, Take]], limits: Limits, name: str
) -> None:
    _, take, _ = takes[name]
    assert take.mode == "optimal"
    # Position: the whole take, run-up and run-out included.
    assert np.all(take.q >= limits.lower - RTOL) and np.all(take.q <= limits.upper + RTOL)
    bounds = (limits.velocity, limits.acceleration, limits.jerk)
    # The analytic values of every sample.
    for values, bound in zip((take.qd, take.qdd, take.qddd), bounds, strict=True):
        assert np.max(np.abs(values) / bound) <= 1 + RTOL
    # The divided differences of the sampled positions.
    for order, bound in enumerate(bounds, start=1):
        worst = float(np.max(np.abs(divided(take.t, take.q, order)) / bound))
        assert worst <= 1 + DIFF_RTOL, f"order {order}: {worst:.9f} of the limit"
    # The report agrees: no limit used beyond round-off.
    for use in take.report.peak_use.values():
        assert max(use.values()) <= 1 + RTOL
    assert all("does not bound jerk" not in w and "exceeds" not in w for w in take.report.warnings)


@pytest.mark.parametrize("name", NAMES)
def test_the_files_nanosecond_stamps_keep_every_limit(
    takes: dict[str, tuple[Array, Take, Take]], limits: Limits, name: str
) -> None:
    """The MCAP stamps each sample in whole nanoseconds. A reader that differences the
    written positions over those stamps (it has no other times) finds the take inside the
    limits, optimal and uniform: every position is the take's at its stamp. Sampled first and
    stamped after, the optimal takes here read up to 0.65% over the jerk limit (a user's
    60 s orbit: 1.9%), the scale take of three frames 0.14%."""
    _, take, scale = takes[name]
    for which in (take, scale):
        stamps = np.round(which.t * 1e9).astype(np.int64)  # as the file holds them
        t = stamps // 10**9 + (stamps % 10**9) * 1e-9  # as a reader rebuilds them
        for order, bound in enumerate((limits.velocity, limits.acceleration, limits.jerk),
                                      start=1):
            worst = float(np.max(np.abs(divided(t, which.q, order)) / bound))
            assert worst <= 1 + DIFF_RTOL, f"{which.mode} order {order}: {worst:.9f} of it"


@pytest.mark.parametrize("name", NAMES)
def test_no_more_than_the_most_frames_a_second(
    takes: dict[str, tuple[Array, Take, Take]], name: str
) -> None:
    """Frames are at least 1 / MAX_FRAME_RATE apart in every optimal take (the creep's would
    be 42 us apart, at a 24 kHz servo rate), and the servo rate is the requested 250 Hz up
    to a whole number of ticks per frame interval (at least one: at most 4/3 of it)."""
    _, take, _ = takes[name]
    gaps = np.diff(take.frame_times)
    assert gaps.min() >= (1.0 / MAX_FRAME_RATE) * (1 - 1e-9), gaps.min()
    assert take.rate <= 250.0 * 4.0 / 3.0, take.rate


@pytest.mark.parametrize("name", NAMES)
def test_never_slower_than_scale(takes: dict[str, tuple[Array, Take, Take]], name: str) -> None:
    _, take, scale = takes[name]
    opt = take.shot_end - take.shot_start
    assert opt <= (scale.shot_end - scale.shot_start) * (1 + 1e-12)
    # the whole take too, run-up and run-out included
    assert take.t[-1] <= scale.t[-1] * (1 + 1e-12), (take.t[-1], scale.t[-1])
    assert take.speed_factor == pytest.approx(opt / (scale.frame_times[-1] - scale.frame_times[0])
                                              * scale.speed_factor, rel=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_never_slower_than_the_shot_at_its_maximum_feasible_speed(
        takes: dict[str, tuple[Array, Take, Take]], sample_paths: dict[str, tuple[Array, float]],
        limits: Limits, name: str) -> None:
    """A shot with no hold played uniformly at its maximum feasible speed (the frames timed
    that much closer together, then the scale take of that) is a take whose run-up and
    run-out fit: the time-optimal take is never longer, run-up and run-out included (a shot
    that can run 3x faster than real time with short ends gets a take about 3x shorter)."""
    q, take, scale = takes[name]
    if not np.all(np.any(np.diff(q, axis=0) != 0.0, axis=1)):
        pytest.skip("the shot holds still somewhere: optimal keeps holds, a uniform law not")
    fps = {**sample_paths, **SYNTHETIC}[name][1]
    fastest = max(scale.report.max_speed, 1.0)  # a slower shot: the scale take itself
    fastest = min(fastest, max(1.0, MAX_FRAME_RATE / fps))  # at most 250 frames a second
    uniform = time_shot(q, frame_times(q.shape[0], fps * fastest), limits, mode="scale")
    assert take.t[-1] <= uniform.t[-1] * (1 + 1e-6), (take.t[-1], uniform.t[-1])


def test_a_short_fast_move_keeps_short_ends(takes: dict[str, tuple[Array, Take, Take]]) -> None:
    """The three-frame nudge could play 20x faster, but its ends from that speed would be
    far longer than the whole scale take: the retime beats the scale take with ends no faster
    than the shot's at real time, whole take against whole take."""
    _, take, scale = takes["three-frame nudge"]
    assert not take.uniform
    assert take.t[-1] < 0.6 * scale.t[-1], (take.t[-1], scale.t[-1])
    assert not any("--timing optimal found no" in w for w in take.report.warnings)


def test_faster_than_scale_where_limits_leave_room(
    takes: dict[str, tuple[Array, Take, Take]],
) -> None:
    """A retime that rides a limit: somewhere a velocity, acceleration or jerk limit is used
    to within 1% (else it could go faster), and it beats scale on these paths. (On the samples
    the solver's paths now run at 2-4x real time with gentle ends that hold the take's start
    and end speed, and the retime may keep the scale take: never slower, checked below.)"""
    for name in SAMPLES:
        _, take, scale = takes[name]
        assert take.shot_end - take.shot_start <= scale.shot_end - scale.shot_start + 1e-9
    for name in ("all axes in motion", "long, several windows"):
        _, take, scale = takes[name]
        assert not take.uniform, name
        ratio = (scale.shot_end - scale.shot_start) / (take.shot_end - take.shot_start)
        assert ratio > 1.05, (name, ratio)
        used = max(max(use[k] for k in ("velocity", "acceleration", "jerk"))
                   for use in take.report.peak_use.values())
        assert used >= 0.99, (name, used)


@pytest.mark.parametrize("name", NAMES)
def test_frames_land_on_samples(
    takes: dict[str, tuple[Array, Take, Take]], limits: Limits, name: str
) -> None:
    q, take, _ = takes[name]
    assert np.array_equal(take.t[take.frame_samples], take.frame_times)
    assert np.max(np.abs(take.q[take.frame_samples] - q)) < 1e-12
    assert np.all(np.diff(take.t) > 0)
    assert take.t[0] == 0.0
    for arr in (take.qd, take.qdd):  # from rest to rest
        assert np.all(arr[0] == 0.0) and np.all(arr[-1] == 0.0)
    if not take.uniform:
        assert np.max(np.diff(take.t)) <= 1 / 250.0 + 1e-9  # to the file's nanosecond
        assert take.report.ticks_per_frame is None


def test_holds_stay_holds(takes: dict[str, tuple[Array, Take, Take]]) -> None:
    q, take, _ = takes["hold between two moves"]
    ft = take.frame_times
    # its original length, to the nanosecond of the file's clock the frames are timed on
    assert np.allclose(np.diff(ft[72:121]), 1 / FPS, rtol=0, atol=1e-9)
    a, b = take.frame_samples[72], take.frame_samples[120]
    assert np.max(np.abs(take.q[a : b + 1] - q[72])) == 0.0
    assert np.max(np.abs(take.qd[a : b + 1])) == 0.0


def test_where_scale_is_already_optimal_the_take_is_the_scale_take(limits: Limits) -> None:
    """The track moving at a constant 1.2 times its velocity limit: the uniform slow-down is
    the fastest timing there is (the velocity limit binds everywhere), so optimal keeps it."""
    n = 49
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 1.2 * float(limits.velocity[TRACK]) * t
    take = time_shot(q, t, limits, mode="optimal")
    scale = time_shot(q, t, limits, mode="scale")
    assert take.uniform
    assert np.array_equal(take.q, scale.q)
    assert take.speed_factor == scale.speed_factor == pytest.approx(1.2, rel=1e-6)
    # and it says so: the take is not the optimal timing it was asked for
    said = [w for w in take.report.warnings if "--timing optimal found no" in w]
    assert said and f"uniformly, at {100 / 1.2:.4g}% of real time" in said[0]
    assert not any("--timing optimal" in w for w in scale.report.warnings)


def test_the_last_window_reaches_a_slow_end(
        takes: dict[str, tuple[Array, Take, Take]]) -> None:
    """The windows before the shot's end are kept slow enough to reach it: the easy stretch
    runs over twice as fast as the uniform take (which the quick pan at its start holds
    back), not the uniform take with a warning."""
    _, take, scale = takes["easy stretch easing to rest"]
    assert not take.uniform
    assert not any("--timing optimal found no" in w for w in take.report.warnings)
    assert take.speed_factor < 0.5 * scale.speed_factor


def test_fails_like_scale_where_no_take_fits(limits: Limits) -> None:
    """No jerk-limited take exists when the first frame sits on the track's end moving away
    from it (the run-up has no room at any speed): optimal fails as scale does (it never
    writes a take over a limit)."""
    n = 49
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] = float(limits.lower[TRACK]) + 1.5 * t
    for mode in ("scale", "optimal"):
        with pytest.raises(TimingLimitError, match=r"run-up into frame 0 has no room"):
            time_shot(q, t, limits, mode=mode)


def test_a_camera_hold_with_a_lens_move_inside_is_said_when_the_retime_changes_its_length(
        limits: Limits) -> None:
    """The camera holds still over frames 20-44 while the focus motor pulls 200 deg in that
    second: the robot holds, the focus does not, so the hold is no hold of the take and the
    retime plays it at the length the focus's limits allow. The take says so, with the
    lengths its own frame times give."""
    n = 70
    t = np.arange(n) / FPS
    s = np.clip((t - t[0]) / t[19], 0.0, 1.0)
    q = np.tile(HOME, (n, 1))
    q[:, 0] += 0.4 * (3 * s**2 - 2 * s**3)  # a truck into the hold, at rest there
    u = np.clip((t - t[20]) / (t[44] - t[20]), 0.0, 1.0)
    focus = np.radians(200.0) * (3 * u**2 - 2 * u**3)
    lens = Limits(np.array([-0.1]), np.array([6.0]), np.radians([180.0]),
                  np.radians([720.0]), np.radians([7200.0]), names=("focus",),
                  kinds=("revolute",))
    both = limits.joined(lens)
    hold = np.zeros(n - 1, dtype=bool)
    hold[20:44] = True
    take = time_shot(np.hstack([q, focus[:, None]]), t, both, mode="optimal", hold=hold)
    was = t[44] - t[20]
    now = take.frame_times[44] - take.frame_times[20]
    assert abs(now / was - 1.0) > 0.01, (now, was)
    assert (f"frames 20-44: the camera holds still but focus moves, so the retime plays the "
            f"hold in {now:.2f} s, not {was:.2f} s") in take.report.warnings


def test_an_end_at_rest_starts_and_ends_the_retime_nearly_still(limits: Limits) -> None:
    """A cosine-eased slide, at rest at both ends (velocity zero, its acceleration the
    ease's own), that could run 4x faster than real time. Retimed with those ends at rest,
    the take starts and ends on its frames at a tenth of the film's pace: the first and last
    frame's acceleration is a hundredth of the shot's there at real time, so the run-up and
    run-out have next to nothing to build (played at the uniform take's 4x, those frames got
    16x the shot's acceleration and the run-up swung the camera 15 cm), and the whole take is
    still shorter than the uniform one at the maximum feasible speed, run-up and run-out
    included."""
    n = 61
    t = frame_times(n)
    s = 0.5 - 0.5 * np.cos(np.pi * np.arange(n) / (n - 1))
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 0.3 * s
    q[:, ROTATE] += 0.15 * s
    rest = np.zeros((2, 8), dtype=np.int8)
    rest[:] = 1  # at rest, not settled: the cosine ease accelerates at its ends
    real = time_shot(q, t, limits, mode="shot", rest=rest)
    take = time_shot(q, t, limits, mode="optimal", rest=rest)
    assert not take.uniform
    assert real.report.max_speed > 3.0
    fast = time_shot(q, frame_times(n, FPS * real.report.max_speed), limits, mode="scale",
                     rest=rest)
    assert take.t[-1] < fast.t[-1], (take.t[-1], fast.t[-1])
    for i in (0, -1):
        k, k_real = take.frame_samples[i], real.frame_samples[i]
        assert np.abs(take.qd[k]).max() <= 1e-12
        shot_acc = np.abs(real.qdd[k_real])
        assert np.all(np.abs(take.qdd[k]) <= 0.0101 * shot_acc + 1e-12), (take.qdd[k], shot_acc)
    for side in (take.report.runup, take.report.runout):
        assert side["duration"] <= 0.02, side["duration"]


def test_a_settled_end_is_retimed_at_full_pace(limits: Limits) -> None:
    """A settled end (velocity and acceleration zero: a quintic ease) has no acceleration at
    any pace, so the retime does not slow down there: it beats the uniform take at the
    maximum feasible speed (it fell back to that take, with a warning, when settled ends were
    slowed like ends at rest), and its ends need no run-up or run-out."""
    n = 49
    t = frame_times(n)
    u = np.arange(n) / (n - 1)
    s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 0.5 * s
    q[:, ROTATE] += 0.1 * s
    rest = np.full((2, 8), 2, dtype=np.int8)
    real = time_shot(q, t, limits, mode="shot", rest=rest)
    take = time_shot(q, t, limits, mode="optimal", rest=rest)
    fast = time_shot(q, frame_times(n, FPS * real.report.max_speed), limits, mode="scale",
                     rest=rest)
    assert not take.uniform
    assert not any("found no" in w for w in take.report.warnings), take.report.warnings
    assert take.t[-1] < 0.95 * fast.t[-1], (take.t[-1], fast.t[-1])
    for side in (take.report.runup, take.report.runout):
        assert side["duration"] <= 0.01, side["duration"]


def test_a_stretched_hold_names_its_moving_axes_in_plain_words() -> None:
    """'focus and iris move' and 'zoom, focus and iris move', not 'focus, iris moves'."""
    from camtraj.timing.take import _stretched_holds

    n = 6
    q = np.zeros((n, 3))
    q[1:5] = np.linspace(0.0, 0.1, 4)[:, None]  # every axis moves inside the hold
    hold = np.array([False, True, True, True, False])
    times = np.array([0.0, 0.1, 0.3, 0.5, 0.7, 0.8])  # the hold 0.6 s, not 0.3 s
    frames = np.arange(1, n + 1)
    for names, who in ((("focus",), "focus moves"), (("focus", "iris"), "focus and iris move"),
                       (("zoom", "focus", "iris"), "zoom, focus and iris move")):
        said = _stretched_holds(q[:, :len(names)], hold, times, 0.1, frames, names)
        assert said == [f"frames 2-5: the camera holds still but {who}, so the retime plays "
                        "the hold in 0.60 s, not 0.30 s"]
