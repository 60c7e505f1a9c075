"""Tests of the timing stage against independent facts.

Facts used:
* analytic derivatives of sinusoids and of a velocity bump built by hand;
* divided differences: on any grid, the k-th divided difference of a C^(k-1) function with a
  piecewise continuous k-th derivative is a weighted mean of that derivative, so
  ``k! * f[t0..tk]`` never exceeds ``max |f^(k)|``: finite differences of the sampled
  positions must stay inside the limits whatever the exact derivatives are;
* Taylor bounds: a central difference of a sampled function differs from the derivative by at
  most ``h * max |next derivative|``, which ties the tolerances to the jerk limits.
"""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.errors import LimitError
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.timing import Limits, Take, TimingLimitError, time_shot
from tests.timing_checks import FPS, HOME, SLACK, divided, frame_times

Array = NDArray[np.float64]
ROTATE = JOINT_NAMES.index("rotate")
TRACK = JOINT_NAMES.index("track")


def sinusoid(n: int, amp: Array, omega: float, phase: float = 0.0) -> tuple[Array, Array]:
    t = frame_times(n)
    return t, HOME + amp * np.sin(omega * t[:, None] + phase)


def bump_path(n: int, k: float, vmax: float, t0: float, width: float) -> tuple[Array, Array]:
    """Rotate moves with velocity k*vmax*sin²(pi*(t-t0)/width) on [t0, t0+width], else holds.

    The peak velocity is exactly k times the limit; every other axis holds still.
    """
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    tau = np.clip(t - t0, 0.0, width)
    peak = k * vmax
    q[:, ROTATE] = peak * (tau / 2 - width / (4 * np.pi) * np.sin(2 * np.pi * tau / width))
    return t, q


def bump_velocity(t: Array, k: float, vmax: float, t0: float, width: float) -> Array:
    tau = np.clip(t - t0, 0.0, width)
    return k * vmax * np.sin(np.pi * tau / width) ** 2


def assert_within_limits_by_differences(take: Take, limits: Limits, *, jerk: bool) -> None:
    for order, bound in ((1, limits.velocity), (2, limits.acceleration), (3, limits.jerk)):
        if order == 3 and not jerk:
            continue
        est = divided(take.t, take.q, order)
        worst = np.max(np.abs(est) / bound)
        assert worst <= 1 + SLACK, f"order {order}: {worst:.6f} of the limit"


def assert_passes_frames(take: Take, q: Array) -> None:
    assert np.array_equal(take.t[take.frame_samples], take.frame_times)
    assert np.max(np.abs(take.q[take.frame_samples] - q)) < 1e-9


def assert_rest_to_rest(take: Take) -> None:
    assert take.t[0] == 0.0
    for arr in (take.qd, take.qdd):
        assert np.all(arr[0] == 0.0)
        assert np.all(arr[-1] == 0.0)


# ---------------------------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------------------------


def test_limits_from_robot(limits: Limits) -> None:
    robot = Robot.default()
    assert limits.names == JOINT_NAMES
    assert np.array_equal(limits.velocity, robot.max_velocity)
    assert np.array_equal(limits.jerk, robot.max_jerk)
    assert list(limits.revolute) == [False, True, True, False, True, True, True, True]
    with pytest.raises(ValueError, match="positive"):
        Limits(limits.lower, limits.upper, -limits.velocity, limits.acceleration, limits.jerk)
    with pytest.raises(ValueError, match="8 finite"):
        Limits(limits.lower[:7], limits.upper, limits.velocity, limits.acceleration, limits.jerk)


@pytest.mark.parametrize(
    ("q", "t", "match"),
    [
        (np.zeros((10, 7)), frame_times(10), "shape"),
        (np.zeros((1, 8)), frame_times(1), "at least 2"),
        (np.zeros((10, 8)), frame_times(10)[::-1], "increase"),
        (np.zeros((10, 8)), np.r_[frame_times(9), frame_times(9)[-1]], "increase"),
        (np.full((10, 8), np.nan), frame_times(10), "finite"),
        (np.zeros((10, 8)), frame_times(10) ** 2, "uniform"),
        (np.zeros((10, 8)), frame_times(11), "shape"),
    ],
)
def test_bad_input_raises_value_error(limits: Limits, q: Array, t: Array, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        time_shot(q, t, limits)


def test_bad_mode_and_rate_raise_value_error(limits: Limits) -> None:
    t, q = sinusoid(20, np.full(8, 0.01), 1.0)
    with pytest.raises(ValueError, match="mode"):
        time_shot(q, t, limits, mode="fast")
    with pytest.raises(ValueError, match="rate"):
        time_shot(q, t, limits, rate=0.0)


# ---------------------------------------------------------------------------------------------
# "shot" mode
# ---------------------------------------------------------------------------------------------


def test_shot_sinusoid_matches_analytic_derivatives(limits: Limits) -> None:
    amp = np.array([0.3, 0.3, 0.2, 0.2, 0.3, 0.4, 0.4, 0.4])
    omega = 2 * np.pi * 0.4
    t, q = sinusoid(241, amp, omega)
    take = time_shot(q, t, limits)

    assert take.mode == "shot"
    assert take.speed_factor == 1.0
    assert take.rate == pytest.approx(240.0)  # 10 ticks per frame: the nearest to 250 Hz
    assert take.report.ticks_per_frame == 10
    assert np.allclose(np.diff(take.t), 1 / 240.0, rtol=0, atol=1e-9)  # the file's ns
    assert_passes_frames(take, q)
    assert np.allclose(np.diff(take.frame_times), 1 / FPS, rtol=0, atol=1e-9)
    assert take.shot_end - take.shot_start == pytest.approx(10.0, abs=1e-9)

    a, b = take.frame_samples[0], take.frame_samples[-1] + 1
    ts = take.t[a:b] - take.shot_start
    # Interior (a second away from the free ends): the quintic spline is accurate to
    # O((omega*h)^(6-k)) for the k-th derivative, far below these bounds. At the free ends
    # the spline follows a least-squares cubic's jerk and zero snap, so it reproduces cubics,
    # not the sinusoid's snap: there its k-th derivative is off by O((omega*h)^(4-k)).
    inner = (ts > 1.0) & (ts < 9.0)
    for k, (got, tol, tol_end) in enumerate(
        ((take.q, 1e-9, 1e-5), (take.qd, 1e-8, 1e-3), (take.qdd, 1e-6, 1e-2),
         (take.qddd, 1e-4, 1e-1))
    ):
        offset = HOME if k == 0 else 0.0
        ref = offset + amp * omega**k * np.sin(omega * ts[:, None] + k * np.pi / 2)
        err = np.abs(got[a:b] - ref) / (amp * omega**k)
        assert err[inner].max() < tol, f"derivative {k}"
        assert err.max() < tol_end, f"derivative {k} near the ends"

    rep = take.report
    # Peak use over the shot: the analytic peaks over the limits.
    for j, name in enumerate(JOINT_NAMES):
        assert rep.peak_use[name]["velocity"] == pytest.approx(
            amp[j] * omega / limits.velocity[j], rel=1e-4)
        assert rep.peak_use[name]["acceleration"] == pytest.approx(
            amp[j] * omega**2 / limits.acceleration[j], rel=1e-4)
    expected_speed = min(
        min(limits.velocity / (amp * omega)),
        min(np.sqrt(limits.acceleration / (amp * omega**2))),
        min(np.cbrt(limits.jerk / (amp * omega**3))),
    )
    assert rep.max_speed == pytest.approx(expected_speed, rel=1e-4)
    assert rep.feasible_fps == pytest.approx(FPS * expected_speed, rel=1e-4)
    assert rep.limiting == []


def test_a_servo_rate_far_from_the_one_asked_is_said(limits: Limits) -> None:
    """Every film frame is a tick: 250 Hz at 24 fps is 240 Hz (said nowhere, the README
    gives it), 10 Hz is 24 Hz (said)."""
    amp = np.array([0.3, 0.3, 0.2, 0.2, 0.3, 0.4, 0.4, 0.4])
    t, q = sinusoid(49, amp, 2 * np.pi * 0.4)
    near = time_shot(q, t, limits, rate=250.0)
    assert not any("servo rate" in w for w in near.report.warnings)
    far = time_shot(q, t, limits, rate=10.0)
    assert far.rate == pytest.approx(24.0)
    assert ("servo rate 24 Hz, not 10 Hz (--rate): every film frame is a servo tick, so the "
            "rate is a whole number of ticks per frame interval") in far.report.warnings


def test_finite_differences_agree_with_reported_derivatives(limits: Limits) -> None:
    amp = np.array([0.3, 0.3, 0.2, 0.2, 0.3, 0.4, 0.4, 0.4])
    t, q = sinusoid(121, amp, 2 * np.pi * 0.4, phase=0.7)  # starts and ends in motion
    take = time_shot(q, t, limits)
    h = float(take.t[1] - take.t[0])
    # Central differences over the whole take (run-up, shot, run-out). Bounds from Taylor:
    # |(q[k+1]-q[k-1])/2h - v| <= h²/6 max|jerk| and |second difference - a| <= h max|jerk|.
    v_fd = (take.q[2:] - take.q[:-2]) / (2 * h)
    a_fd = (take.q[2:] - 2 * take.q[1:-1] + take.q[:-2]) / h**2
    assert np.all(np.abs(v_fd - take.qd[1:-1]) <= h**2 / 6 * limits.jerk + 1e-9)
    assert np.all(np.abs(a_fd - take.qdd[1:-1]) <= h * limits.jerk + 1e-9)
    # Velocity and acceleration are the integrals of acceleration and jerk (trapezoid rule,
    # error <= h²/12 max|next derivative| per step, summed over the take: 1e-6 is ample).
    v_int = take.qd[0] + np.cumsum((take.qdd[1:] + take.qdd[:-1]) / 2 * h, axis=0)
    assert np.max(np.abs(v_int - take.qd[1:]) / limits.velocity) < 1e-3
    # Jerk: central difference of the acceleration on the shot part, where the quintic's
    # jerk is smooth (the ruckig parts have jerk steps, where a difference averages).
    a, b = take.frame_samples[0], take.frame_samples[-1]
    j_fd = (take.qdd[a + 2 : b] - take.qdd[a : b - 2]) / (2 * h)
    assert np.max(np.abs(j_fd - take.qddd[a + 1 : b - 1]) / limits.jerk) < 1e-3


def test_a_violation_in_several_stretches_names_the_frame_of_its_worst(
        limits: Limits) -> None:
    """Two rotate moves over the velocity limit, a small one first: the message lists both
    stretches of frames and says the worst is in the second (a 540 deg orbit's track velocity
    read as if at frames 2-4, the first of six stretches, where it was at frame 627)."""
    vmax = float(limits.velocity[ROTATE])
    t, small = bump_path(241, 1.2, vmax, 1.0, 2.0)
    _, large = bump_path(241, 1.8, vmax, 6.0, 2.0)
    q = small + large - small[0]
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits, frame_numbers=np.arange(1, 242))
    (viol,) = [v for v in info.value.violations if v.quantity == "velocity"]
    assert len(viol.frames) == 2
    assert viol.worst is not None
    peak_frame = 1 + 24 * 7.0  # the large bump's peak: t = 6 + 2 / 2 s, 24 fps
    assert viol.worst[0] <= peak_frame <= viol.worst[1] and viol.worst[1] - viol.worst[0] <= 1
    assert viol.frames[1][0] <= viol.worst[0] <= viol.frames[1][1]
    at = (f"worst at frame {viol.worst[0]}" if viol.worst[0] == viol.worst[1]
          else f"worst between frames {viol.worst[0]} and {viol.worst[1]}")
    assert str(info.value).startswith(f"rotate velocity 162 deg/s ({at}) exceeds 90.0 deg/s "
                                      f"on frames {viol.frames[0][0]}-")


def test_shot_velocity_violation_names_axis_frames_and_speed(limits: Limits) -> None:
    k, t0, width = 1.6, 1.0, 3.0
    vmax = float(limits.velocity[ROTATE])
    t, q = bump_path(121, k, vmax, t0, width)
    with pytest.raises(TimingLimitError) as info:
        time_shot(q, t, limits, frame_numbers=np.arange(1001, 1122))
    err = info.value
    assert isinstance(err, LimitError)
    assert err.exit_code == 3
    # Expected frames: those next to a 240 Hz tick where the analytic velocity exceeds vmax
    # (a tick between two frames counts for both).
    ticks = np.arange(120 * 10 + 1) / 240.0
    v = bump_velocity(ticks, k, vmax, t0, width)
    margin = np.min(np.abs(v / vmax - 1.0))
    assert margin > 1e-5  # no tick sits on the threshold, so the spline's 1e-8 cannot flip it
    over = np.flatnonzero(v > vmax)
    frames = set()
    for i in over:
        frames.update({i // 10, -(-i // 10)})
    first, last = min(frames) + 1001, max(frames) + 1001
    assert frames == set(range(min(frames), max(frames) + 1))
    assert (first, last) == (1045, 1077)  # about 1.87 s .. 3.13 s into the shot

    msg = str(err)
    assert msg.startswith(f"rotate velocity 144 deg/s exceeds 90.0 deg/s on frames {first}-{last}")
    assert "62% speed (15.00 fps)" in msg  # 1/1.6 = 62.5 %, 24 fps * 0.625 = 15.0 fps
    assert "--timing scale" in msg
    assert err.max_speed == pytest.approx(1 / k, rel=1e-5)
    assert err.feasible_fps == pytest.approx(FPS / k, rel=1e-5)

    (viol,) = err.violations
    assert (viol.axis, viol.quantity) == ("rotate", "velocity")
    assert viol.frames == ((first, last),)
    assert viol.ratio == pytest.approx(k, rel=1e-6)
    assert viol.peak == pytest.approx(k * vmax, rel=1e-6)


def test_a_violation_just_over_a_limit_says_by_how_much(limits: Limits) -> None:
    """The same bump 0.02% over the rotate velocity: rounded for display, the peak and the limit
    both read 90.0 deg/s, so the line says by how much the limit is exceeded; 1.6x over keeps
    its plain form."""
    vmax = float(limits.velocity[ROTATE])
    for k, expected in ((1.0002, "exceeds 90.0 deg/s by 0.02% on frames"),
                        (1.00002, "exceeds 90.0 deg/s by under 0.01% on frames"),
                        (1.6, "rotate velocity 144 deg/s exceeds 90.0 deg/s on frames")):
        t, q = bump_path(121, k, vmax, 1.0, 3.0)
        with pytest.raises(TimingLimitError) as info:
            time_shot(q, t, limits, frame_numbers=np.arange(1001, 1122))
        line = info.value.violations[0].describe()
        assert expected in line, line
        if k > 1.5:
            assert " by " not in line


def test_position_limit_raises_in_every_mode(limits: Limits) -> None:
    t = frame_times(48)
    q = np.tile(HOME, (48, 1))
    upper = float(limits.upper[JOINT_NAMES.index("tilt")])
    q[:, JOINT_NAMES.index("tilt")] = upper + 0.05 * np.sin(np.pi * t / t[-1])  # over at once
    for mode in ("shot", "scale", "optimal"):
        with pytest.raises(TimingLimitError, match=r"tilt position .* beyond its upper limit"):
            time_shot(q, t, limits, mode=mode)


def test_hold_then_move_stays_exactly_still(limits: Limits) -> None:
    n = 96
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    s = np.clip((t - 1.0) / 2.0, 0.0, 1.0)
    q[:, TRACK] += 1.5 * (1 - np.cos(np.pi * s)) / 2  # still for 1 s, then a cosine move
    q[:, ROTATE] += 0.3 * s  # still, then an abrupt ramp: the hard case for ringing
    take = time_shot(q, t, limits, mode="scale")
    a, b = take.frame_samples[0], take.frame_samples[24]  # frames 0..24: every axis holds
    assert np.all(take.q[a : b + 1] == HOME)
    # Exact by construction: hold pieces are constant and the move's first piece starts from
    # the hold's velocity and acceleration written as such (not as the spline's round-off).
    assert np.all(take.qd[a : b + 1] == 0.0)
    assert np.all(take.qdd[a : b + 1] == 0.0)
    assert take.report.runup["duration"] == 0.0  # the shot begins at rest
    assert take.shot_start == 0.0
    # After the move the axes hold still again, exactly at the last solution.
    c = take.frame_samples[72]
    assert np.all(take.q[c : take.frame_samples[-1] + 1] == q[-1])
    assert take.report.runout["duration"] == 0.0
    assert_rest_to_rest(take)
    assert_within_limits_by_differences(take, limits, jerk=True)


# ---------------------------------------------------------------------------------------------
# "scale" mode
# ---------------------------------------------------------------------------------------------


def test_scale_factor_is_the_analytic_one(limits: Limits) -> None:
    k, t0, width = 1.6, 1.0, 3.0
    t, q = bump_path(121, k, float(limits.velocity[ROTATE]), t0, width)
    take = time_shot(q, t, limits, mode="scale")
    assert take.speed_factor == pytest.approx(k, rel=1e-5)
    assert take.shot_end - take.shot_start == pytest.approx(k * 5.0, rel=1e-9)
    assert take.report.ticks_per_frame == round(250 * k / FPS)
    assert take.rate == pytest.approx(take.report.ticks_per_frame * FPS / take.speed_factor)
    assert np.allclose(np.diff(take.frame_times), take.speed_factor / FPS, rtol=0, atol=1e-9)
    assert_passes_frames(take, q)
    assert_rest_to_rest(take)
    assert_within_limits_by_differences(take, limits, jerk=True)
    assert take.report.peak_use["rotate"]["velocity"] == pytest.approx(1.0, abs=1e-6)
    (viol,) = take.report.limiting  # what the real-time timing exceeded
    assert (viol.axis, viol.quantity) == ("rotate", "velocity")


@pytest.mark.parametrize("binding", ["velocity", "acceleration", "jerk"])
def test_scale_factor_each_quantity(limits: Limits, binding: str) -> None:
    # One sinusoid on the track whose peaks exceed the chosen limit the most.
    # Jerk binds only at high frequency on this robot; sample those faster (a quintic
    # through 24 fps frames of a 30 rad/s sinusoid would not be the sinusoid).
    omega, fps = {"velocity": (1.0, 24.0), "acceleration": (6.0, 48.0),
                  "jerk": (15.0, 120.0)}[binding]
    want = 2.0
    vmax, amax, jmax = limits.velocity[TRACK], limits.acceleration[TRACK], limits.jerk[TRACK]
    amp = {"velocity": want * vmax / omega, "acceleration": want**2 * amax / omega**2,
           "jerk": want**3 * jmax / omega**3}[binding]
    t = frame_times(int(6 * fps) + 1, fps)
    q = HOME + np.outer(np.sin(omega * t), np.eye(8)[TRACK] * amp)
    analytic = max(amp * omega / vmax, math.sqrt(amp * omega**2 / amax),
                   (amp * omega**3 / jmax) ** (1 / 3))
    assert analytic == pytest.approx(want)
    take = time_shot(q, t, limits, mode="scale")
    # The peaks are measured at the servo samples (not the continuous maximum). Away from
    # the free ends the spline is exact to ~1e-6 for jerk at omega=30; at a free end it
    # follows a least-squares cubic (zero snap), whose acceleration at these 50 frames per
    # period can exceed the sinusoid's peak by up to 1.5 % (0.7 % on the factor).
    assert take.speed_factor == pytest.approx(analytic, rel=1e-2)
    assert take.speed_factor >= analytic * (1 - 1e-3)  # never faster than the limits allow
    assert_passes_frames(take, q)
    assert_rest_to_rest(take)
    assert_within_limits_by_differences(take, limits, jerk=True)


@pytest.mark.parametrize("mode", ["scale", "optimal"])
def test_a_move_whose_take_would_last_hours_is_one_error_not_hours_of_samples(
        limits: Limits, mode: str) -> None:
    """The bump at 1.6x the rotate velocity against a limit 10,000x smaller (a robot file
    typed in the wrong unit): the take would be 16,000x slower than real time, 22 h of
    samples (gigabytes: a new user's check was killed). It is refused before any is made."""
    k, t0, width = 1.6, 1.0, 3.0
    t, q = bump_path(121, k, float(limits.velocity[ROTATE]), t0, width)
    slow = Limits(limits.lower, limits.upper, limits.velocity * 1e-4, limits.acceleration,
                  limits.jerk)
    tracemalloc.start()
    try:
        with pytest.raises(TimingLimitError, match=r"the move fits only 1\.6e\+04 times slower "
                           r"than real time: a take of 22\.2 h, longer than the 2 h camtraj "
                           r"builds; check the robot's velocity") as err:
            time_shot(q, t, slow, mode=mode)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, peak
    assert err.value.scale_factor == math.inf  # nothing advises --timing scale
    assert err.value.max_speed == pytest.approx(1.0 / 1.6e4, rel=1e-3)
    if mode == "scale":  # 1,200x slower is still a take (1.7 h): the bound is its length
        slower = Limits(limits.lower, limits.upper, limits.velocity / 750.0,
                        limits.acceleration, limits.jerk)
        take = time_shot(q, t, slower, mode="scale", rate=50.0)  # 300,000 samples
        assert take.speed_factor == pytest.approx(1200.0, rel=1e-3)


def test_scale_keeps_a_fitting_shot_at_speed(limits: Limits) -> None:
    t, q = sinusoid(49, np.full(8, 0.01), 1.0)
    take = time_shot(q, t, limits, mode="scale")
    shot = time_shot(q, t, limits, mode="shot")
    assert take.speed_factor == 1.0
    assert np.array_equal(take.q, shot.q)
    assert take.report.max_speed > 1.0


# ---------------------------------------------------------------------------------------------
# "optimal" mode
# ---------------------------------------------------------------------------------------------


def test_optimal_respects_limits_keeps_holds_and_beats_scale(limits: Limits) -> None:
    n = 24 * 8 + 1
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    # Move 1 (frames 0-72), hold (72-120: no axis moves), move 2 (120-192).
    s1 = np.clip(t / 3.0, 0, 1)
    s2 = np.clip((t - 5.0) / 3.0, 0, 1)
    q[:, TRACK] += 2.0 * (s1 - np.sin(2 * np.pi * s1) / (2 * np.pi))
    q[:, ROTATE] += 1.2 * np.sin(np.pi * s1) ** 2 - 0.8 * (1 - np.cos(np.pi * s2)) / 2
    q[:, 6] += 0.5 * (1 - np.cos(np.pi * s2)) / 2
    take = time_shot(q, t, limits, mode="optimal")
    scale = time_shot(q, t, limits, mode="scale")

    assert take.mode == "optimal"
    assert not take.uniform
    assert np.all(np.diff(take.t) > 0)
    assert np.max(np.diff(take.t)) <= 1 / 250.0 + 1e-9  # to the file's nanosecond
    assert_passes_frames(take, q)
    assert_rest_to_rest(take)
    assert_within_limits_by_differences(take, limits, jerk=True)
    # The hold keeps its original duration (to the nanosecond of the file's clock the frames
    # are timed on) and the robot stands still through it.
    ft = take.frame_times
    assert np.allclose(np.diff(ft[72:121]), 1 / FPS, rtol=0, atol=1e-9)
    a, b = take.frame_samples[72], take.frame_samples[120]
    assert np.max(np.abs(take.q[a : b + 1] - q[72])) == 0.0
    # Never slower than uniform scaling (scale is one feasible timing).
    shot_opt = take.shot_end - take.shot_start
    shot_scale = scale.shot_end - scale.shot_start
    assert shot_opt <= shot_scale * (1 + SLACK)
    assert take.speed_factor == pytest.approx(shot_opt / 8.0)
    # Jerk-limited like every take: no limit is used beyond round-off.
    assert max(max(use.values()) for use in take.report.peak_use.values()) <= 1 + 1e-9


def test_optimal_frame_times_follow_the_path(limits: Limits) -> None:
    k = 1.6
    t, q = bump_path(121, k, float(limits.velocity[ROTATE]), 1.0, 3.0)
    take = time_shot(q, t, limits, mode="optimal")
    assert_passes_frames(take, q)
    assert_within_limits_by_differences(take, limits, jerk=True)
    # Frames are in order, each a sample, and the still lead-in keeps real time (1 s).
    assert np.all(np.diff(take.frame_times) > 0)
    assert take.frame_times[24] - take.frame_times[0] == pytest.approx(1.0, abs=1e-9)
    # The rotate axis rides its velocity limit in the middle of the bump.
    assert take.report.peak_use["rotate"]["velocity"] == pytest.approx(1.0, abs=SLACK)


# ---------------------------------------------------------------------------------------------
# Run-up and run-out
# ---------------------------------------------------------------------------------------------


def test_runup_and_runout_meet_the_shot_continuously(limits: Limits) -> None:
    n = 97
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    q[:, TRACK] += 1.2 * t + 0.2 * np.sin(1.3 * t)  # in motion at both ends
    q[:, ROTATE] += 0.4 * np.sin(0.9 * t + 0.3)
    q[:, 5] += -0.6 * t
    take = time_shot(q, t, limits)
    h = float(take.t[1] - take.t[0])
    assert_rest_to_rest(take)
    assert_passes_frames(take, q)
    assert_within_limits_by_differences(take, limits, jerk=True)
    for arr, bound in ((take.qd, limits.velocity), (take.qdd, limits.acceleration),
                       (take.qddd, limits.jerk)):
        assert np.all(np.abs(arr) <= bound * (1 + 1e-9))

    up, out = take.report.runup, take.report.runout
    f0, f1 = int(take.frame_samples[0]), int(take.frame_samples[-1])
    assert up["duration"] > 0
    assert out["duration"] > 0
    assert f0 == up["samples"]
    assert take.shot_start == pytest.approx(up["duration"] + up["hold"], abs=1e-9)  # on ns
    assert 0 <= up["hold"] < h
    assert take.t.size == f1 + 1 + out["samples"]
    # The run-up starts at rest at its reported start and travels to the first frame.
    for j, name in enumerate(JOINT_NAMES):
        assert take.q[0, j] == up["start"][name]
        assert q[0, j] - take.q[0, j] == pytest.approx(up["travel"][name], abs=1e-12)
        assert take.q[-1, j] == out["end"][name]
        assert take.q[-1, j] - q[-1, j] == pytest.approx(out["travel"][name], abs=1e-12)
        lo, hi = take.q[: f0 + 1, j].min(), take.q[: f0 + 1, j].max()
        assert up["extent"][name] == pytest.approx(hi - lo, abs=1e-6)
    assert up["travel"]["track"] > 0  # the track needs room before the first frame
    # Continuity across the junctions: position, velocity and acceleration change by no more
    # than one step of the next derivative's limit allows (exact state match at the frame).
    for k in (f0, f1 + 1):
        assert np.all(np.abs(take.q[k] - take.q[k - 1]) <= h * limits.velocity)
        assert np.all(np.abs(take.qd[k] - take.qd[k - 1]) <= h * limits.acceleration)
        assert np.all(np.abs(take.qdd[k] - take.qdd[k - 1]) <= h * limits.jerk * (1 + 1e-9))
    # Left and right one-sided differences at the first frame agree with its state.
    v_left = (take.q[f0] - take.q[f0 - 1]) / h
    v_right = (take.q[f0 + 1] - take.q[f0]) / h
    assert np.all(np.abs(v_left - take.qd[f0]) <= h * limits.acceleration)
    assert np.all(np.abs(v_right - take.qd[f0]) <= h * limits.acceleration)


def test_runup_needing_room_beyond_a_limit_is_reported(limits: Limits) -> None:
    n = 49
    t = frame_times(n)
    q = np.tile(HOME, (n, 1))
    lower = float(limits.lower[TRACK])
    q[:, TRACK] = lower + 0.01 + 1.5 * t  # starts 1 cm from the end of the track at 1.5 m/s
    # the distance past the limit (0.575 m of stop from 1.5 m/s, 1 cm of room), not the
    # position rounded next to the limit's
    with pytest.raises(TimingLimitError, match=r"run-up into frame 0 .*track goes 0\.5\d+ m "
                                               r"past its lower limit -2 m"):
        time_shot(q, t, limits, edges="fast")


def test_all_still_shot_is_a_plain_hold(limits: Limits) -> None:
    q = np.tile(HOME, (10, 1))
    for mode in ("shot", "scale", "optimal"):
        take = time_shot(q, frame_times(10), limits, mode=mode)
        assert np.all(take.q == HOME)
        assert take.shot_end == pytest.approx(9 / FPS)
        assert math.isinf(take.report.max_speed)


# ---------------------------------------------------------------------------------------------
# The file's clock
# ---------------------------------------------------------------------------------------------


def test_the_clock_puts_each_position_where_the_take_is_at_its_stamp() -> None:
    """A constant-jerk second planned at 240 Hz (steps of 4,166,666.67 ns), a film frame
    every 10 samples: stamped in whole nanoseconds, its frames keep their positions exactly
    and the third differences over the stamps give its jerk back. Rounding the times alone
    (the positions left at the planned times) reads it up to 0.5% off."""
    from camtraj.timing.clock import on_the_clock

    t = np.arange(241) / 240.0 - 0.5
    frames = np.arange(0, 241, 10)
    # q = c0 + c1 t + c2 t^2 + c3 t^3 per axis: up to 2.8 m/s, jerk 15 and -9 m/s^3
    c = np.array([[0.2, 0.5, -0.4, 2.5], [-1.0, 0.3, 0.2, -1.5]])
    powers = np.stack([t**k for k in range(4)], axis=1)
    q = powers @ c.T
    qd = np.stack([np.ones_like(t), 2 * t, 3 * t**2], axis=1) @ c[:, 1:].T
    qdd = np.stack([2 * np.ones_like(t), 6 * t], axis=1) @ c[:, 2:].T
    qddd = np.tile(6 * c[:, 3], (t.size, 1))
    planned = q.copy()
    stamps = on_the_clock(t, frames, q, qd, qdd, qddd)
    assert np.array_equal(np.round(stamps * 1e9) / 1e9, stamps)  # whole nanoseconds
    assert np.max(np.abs(stamps - t)) <= 0.5e-9 + 1e-15
    assert np.array_equal(q[frames], planned[frames])  # frames exactly
    jerk = 6 * c[:, 3]
    moved = np.abs(divided(stamps, q, 3) - jerk).max(axis=0) / np.abs(jerk)
    rounded = np.abs(divided(stamps, planned, 3) - jerk).max(axis=0) / np.abs(jerk)
    assert moved.max() < 1e-4, moved  # 4e-5 and 2e-5: the easing between frames
    assert rounded.min() > 2e-3, rounded  # 0.5% and 0.3%: what the file read before


# ---------------------------------------------------------------------------------------------
# A long shot (its speed is measured by bench/run.py, not here: no timed tests)
# ---------------------------------------------------------------------------------------------


def test_a_minute_long_shot_in_every_mode(limits: Limits) -> None:
    n = 1440
    t = frame_times(n)
    periods = np.array([20.0, 15.0, 12.0, 17.0, 11.0, 9.0, 7.0, 13.0])
    amp = np.array([3.0, 0.8, 0.3, 0.3, 0.5, 0.5, 0.4, 0.2])
    q = HOME + amp * np.sin(2 * np.pi * t[:, None] / periods)
    for mode in ("shot", "scale", "optimal"):
        take = time_shot(q, t, limits, mode=mode)
        assert_passes_frames(take, q)
        assert_rest_to_rest(take)
        assert_within_limits_by_differences(take, limits, jerk=True)


# ---------------------------------------------------------------------------------------------
# Memory
# ---------------------------------------------------------------------------------------------


def _timing_peak(q: Array, t: Array, limits: Limits, mode: str) -> tuple[int, int]:
    """tracemalloc's peak [bytes] while ``time_shot`` runs, and the size of the take's
    servo-rate arrays (times, positions, velocities, accelerations, jerks)."""
    tracemalloc.start()
    try:
        take = time_shot(q, t, limits, mode=mode)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, sum(a.nbytes for a in (take.t, take.q, take.qd, take.qdd, take.qddd))


@pytest.mark.parametrize(("mode", "speed"), [("shot", 0.5), ("scale", 1.5)])
def test_timing_memory_grows_by_little_more_than_the_take(
    limits: Limits, mode: str, speed: float
) -> None:
    """Issue 14 §5: per servo sample, time_shot's peak grows by the take itself plus a
    quarter of it (the shot's samples are joined to the run-up and run-out a quantity at a
    time) and a few grid-sized temporaries: under 2 takes. It held three to five (the limit
    checks' joined copy of the stream, the real-time stream kept beside the scale take, the
    take joined while all of the shot was alive). ``speed``: the move's peak velocity use,
    so that scale mode slows it."""
    amp = np.array([3.0, 1.0, 0.3, 0.3, 0.5, 1.0, 0.5, 1.0])  # inside the ranges about HOME
    periods = 2 * np.pi * amp / (speed * limits.velocity)  # peak velocity: speed x limit
    time_shot(*sinusoid_path(240, amp, periods), limits, mode=mode)  # imports, caches
    (small, small_take), (big, big_take) = (
        _timing_peak(*sinusoid_path(n, amp, periods), limits, mode) for n in (2000, 4000))
    growth = (big - small) / (big_take - small_take)
    assert 1.0 <= growth < 2.0, growth


def sinusoid_path(n: int, amp: Array, periods: Array) -> tuple[Array, Array]:
    """Frames of every axis swinging about HOME with its own amplitude and period."""
    t = frame_times(n)
    return HOME + amp * np.sin(2 * np.pi * t[:, None] / periods), t
