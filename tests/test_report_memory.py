"""``camtraj report`` of a long take in bounded memory (issue 14, section 5).

The report reads the MCAP with :func:`camtraj.mcap_io.read_take_for_report` (/shot/frames
decoded, /tf only at the drawn poses, the one /joint_trajectory message kept as bytes) and
folds the servo samples, a block at a time, into :class:`camtraj.report.Samples`: per plot the
minimum and maximum of each pixel column, per film frame the peak use of each limit.
Independent facts: :func:`camtraj.mcap_io.read_take` (mcap_ros2's decoder) on the same file,
brute-force minima and maxima per column and peaks per frame computed here from its whole
arrays, and the peak resident memory of real ``camtraj report`` processes.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.mcap_io import ReadTake, read_take, read_take_for_report
from camtraj.report import QUANTITIES, ReportData, Samples, reduce_samples, report_from_mcap
from camtraj.report.samples import ENVELOPE_COLUMNS, in_blocks, jerk_by_differences
from tests.test_convert import ROOT, run_cli

Array = NDArray[np.float64]
SHORT, LONG = 600, 6000  # film frames of the two long-shot takes


def _take(folder: Path, frames: int) -> Path:
    shot, mcap = folder / f"long{frames}.usda", folder / f"long{frames}.mcap"
    made = subprocess.run([sys.executable, str(ROOT / "samples" / "shots" / "make_samples.py"),
                           "--long-shot", str(shot), "--frames", str(frames)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert made.returncode == 0, made.stderr
    proc = run_cli("convert", shot, "-o", mcap, "--timing", "scale")
    assert proc.returncode == 0, proc.stderr
    return mcap


@pytest.fixture(scope="module")
def takes(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    folder = tmp_path_factory.mktemp("long")
    return {n: _take(folder, n) for n in (SHORT, LONG)}


def test_the_report_reader_reads_what_mcap_ros2_reads(takes: dict[int, Path]) -> None:
    full = read_take(takes[SHORT])
    wanted = full.frame_times[[0, 7, 300, -1]] + 0.004  # between /tf samples
    light = read_take_for_report(takes[SHORT], lambda ft: wanted)
    blocks = list(light.trajectory_blocks(size=777))  # blocks of an odd size
    assert len(blocks) > 5
    for k, name in enumerate(("trajectory_t", "trajectory_q", "trajectory_qd",
                              "trajectory_qdd")):
        np.testing.assert_array_equal(np.concatenate([b[k] for b in blocks]),
                                      getattr(full, name), err_msg=name)
    assert light.point_count == full.trajectory_t.size > 5 * SHORT  # servo rate >> film rate
    assert (light.first_time, light.last_time) == tuple(full.trajectory_t[[0, -1]])
    np.testing.assert_array_equal(light.count_before(full.frame_times, size=1000),
                                  np.searchsorted(full.trajectory_t, full.frame_times))
    assert light.joint_names == full.trajectory_joint_names
    assert light.stamp == full.trajectory_stamp
    np.testing.assert_array_equal(light.frame_numbers, full.frame_numbers)
    np.testing.assert_array_equal(light.frame_times, full.frame_times)
    np.testing.assert_array_equal(light.target, full.target)
    assert light.metadata == full.metadata and light.all_metadata == full.all_metadata
    assert light.tf_count == full.tf_times.size
    nearest = np.abs(full.tf_times[None, :] - wanted[:, None]).argmin(axis=1)
    np.testing.assert_array_equal(light.tf_times, full.tf_times[nearest])
    assert light.tf.keys() == full.tf.keys()
    for child, (parent, mats) in full.tf.items():
        assert light.tf[child][0] == parent
        np.testing.assert_array_equal(light.tf[child][1], mats[nearest], err_msg=child)
    assert light.tf_static.keys() == full.tf_static.keys()


# --------------------------------------------------------------------------------------------
# The reduction against brute force over the whole arrays
# --------------------------------------------------------------------------------------------


def _brute_jerk(t: Array, qdd: Array, a: int, b: int) -> Array:
    """Differences of the accelerations over the whole take, none across the shot's ends."""
    out = np.zeros_like(qdd)
    m = t.size
    for lo, hi, keep in ((0, a, slice(0, a)), (a, b, slice(a, b + 1)),
                         (b, m - 1, slice(b + 1, m))):
        if hi > lo:
            out[keep] = np.gradient(qdd[lo:hi + 1], t[lo:hi + 1], axis=0)[
                keep.start - lo: keep.stop - lo]
    return out


def _brute(full: ReadTake, data: ReportData) -> tuple[Array, Array]:
    """Fractions of the limits, (4, m, 8), and the take times, from read_take's arrays."""
    t, q, qd, qdd = (full.trajectory_t, full.trajectory_q, full.trajectory_qd,
                     full.trajectory_qdd)
    a, b = np.searchsorted(t, full.frame_times[[0, -1]] - 1e-9)
    jerk = _brute_jerk(t, qdd, int(a), int(b))
    mid, half = 0.5 * (data.upper + data.lower), 0.5 * (data.upper - data.lower)
    return np.stack([(q - mid) / half, qd / data.velocity, qdd / data.acceleration,
                     jerk / data.jerk]), t


def _check_against_brute_force(samples: Samples, fr: Array, t: Array, ft: Array,
                               columns: int = ENVELOPE_COLUMNS) -> None:
    col = np.minimum(((t - t[0]) / (t[-1] - t[0]) * columns).astype(int), columns - 1)
    cols, first = np.unique(col, return_index=True)  # t is sorted, so col is too
    for k, quantity in enumerate(QUANTITIES):
        for axis in range(8):
            y = fr[k, :, axis]
            te, ye = samples.curves[(quantity, axis)]
            assert te.size <= 2 * columns and np.all(np.diff(te) > 0)
            at = np.searchsorted(t, te)
            np.testing.assert_array_equal(t[at], te)  # real samples
            np.testing.assert_allclose(ye, y[at], rtol=1e-12, atol=1e-12)
            # every column with samples keeps points, and they hold its extremes
            kept_cols, kept_first = np.unique(col[at], return_index=True)
            np.testing.assert_array_equal(kept_cols, cols, err_msg=f"{quantity} {axis}")
            for reduce in (np.maximum, np.minimum):
                np.testing.assert_allclose(reduce.reduceat(ye, kept_first),
                                           reduce.reduceat(y, first), rtol=1e-12, atol=1e-12,
                                           err_msg=f"{quantity} {axis}")
    # per film frame: the samples from the frame before to the frame after (the run-up with
    # the first frame, the run-out with the last)
    use = np.abs(fr)
    lo = np.concatenate([[-np.inf], ft[:-1] + 1e-9])
    hi = np.concatenate([ft[1:] - 1e-9, [np.inf]])
    start, stop = np.searchsorted(t, lo, side="right"), np.searchsorted(t, hi, side="left")
    for j in range(ft.size):  # the samples with lo < t < hi
        np.testing.assert_allclose(samples.frame_peak[:, j], use[:, start[j]:stop[j]].max(axis=1),
                                   rtol=1e-12, atol=1e-12, err_msg=f"frame {j}")
    shot = (t >= ft[0] - 1e-9) & (t <= ft[-1] + 1e-9)
    np.testing.assert_allclose(samples.shot_peak, use[:, shot].max(axis=1), rtol=1e-12)


def test_report_samples_are_the_brute_force_extremes(takes: dict[int, Path]) -> None:
    """The long take through the report's own path (default blocks), and the short one in
    blocks of an odd size: every column's min and max and every frame's peak as brute force
    over read_take's whole arrays finds them."""
    data = report_from_mcap(takes[LONG])
    full = read_take(takes[LONG])
    fr, t = _brute(full, data)
    assert data.samples is not None and data.samples.count == t.size
    _check_against_brute_force(data.samples, fr, t, full.frame_times)

    short = read_take(takes[SHORT])
    light = read_take_for_report(takes[SHORT])
    a, b = light.count_before(short.frame_times[[0, -1]] - 1e-9).tolist()
    limits = (data.velocity, data.acceleration, data.jerk)
    samples = reduce_samples(
        jerk_by_differences(light.trajectory_blocks(size=333), light.point_count, (a, b)),
        count=light.point_count, start=light.first_time, end=light.last_time,
        frame_times=short.frame_times, shot=(short.frame_times[0], short.frame_times[-1]),
        lower=data.lower, upper=data.upper, limits=limits)
    fr, t = _brute(short, data)
    _check_against_brute_force(samples, fr, t, short.frame_times)


def _nbytes(samples: Samples) -> int:
    arrays = [samples.frame_peak, samples.shot_peak, samples.edge_peak, samples.edge_extent]
    arrays += [a for pair in samples.curves.values() for a in pair]
    return sum(a.nbytes for a in arrays)


def test_what_the_report_keeps_grows_with_frames_not_samples(takes: dict[int, Path]) -> None:
    """Ten times the frames (and servo samples): the plots keep at most two points per column,
    and what is kept grows by the per-frame peaks alone."""
    kept = {}
    for n in (SHORT, LONG):
        data = report_from_mcap(takes[n])
        assert data.samples is not None and data.samples.count > 9 * n
        assert all(te.size <= 2 * ENVELOPE_COLUMNS for te, _ in data.samples.curves.values())
        kept[n] = _nbytes(data.samples)
    per_frame = 4 * 8 * 8  # frame_peak: 4 quantities x 8 axes, float64
    assert kept[LONG] - kept[SHORT] <= per_frame * (LONG - SHORT) + 4 * 8 * 2 * 2 * \
        ENVELOPE_COLUMNS * 8 * 2


def test_short_takes_keep_every_sample_and_blocks_do_not_matter() -> None:
    """A take of at most two samples per column keeps them all; the block size changes
    nothing (random data, brute force per column)."""
    rng = np.random.default_rng(0)
    lower, upper = -np.ones(8), np.ones(8)
    lim = (np.ones(8), 2 * np.ones(8), 3 * np.ones(8))
    for m, columns in ((150, 100), (15000, 100)):
        t = np.sort(rng.uniform(0.0, 60.0, m))
        arrays = [np.cumsum(rng.normal(size=(m, 8)), axis=0) * 0.01 for _ in range(4)]
        ft = np.linspace(t[0] + 1.0, t[-1] - 1.0, 40)
        got = [reduce_samples(in_blocks(t, *arrays, size=size), count=m, start=t[0],
                              end=t[-1], frame_times=ft, shot=(ft[0], ft[-1]), lower=lower,
                              upper=upper, limits=lim, columns=columns)
               for size in (7, 1000, m)]
        fr = np.stack([arrays[0], arrays[1] / lim[0], arrays[2] / lim[1], arrays[3] / lim[2]])
        for s in got:
            if m <= 2 * columns:
                for k, quantity in enumerate(QUANTITIES):
                    np.testing.assert_array_equal(s.curves[(quantity, 3)][0], t)
                    np.testing.assert_array_equal(s.curves[(quantity, 3)][1], fr[k, :, 3])
            else:
                _check_against_brute_force(s, fr, t, ft, columns)
            for key, (te, ye) in got[-1].curves.items():
                np.testing.assert_array_equal(s.curves[key][0], te)
                np.testing.assert_array_equal(s.curves[key][1], ye)
            np.testing.assert_array_equal(s.frame_peak, got[-1].frame_peak)


def _peak_kib(mcap: Path, html: Path) -> int:
    """Peak resident memory [KiB] of ``camtraj report MCAP -o HTML``, its only child."""
    code = ("import resource, subprocess, sys\n"
            "subprocess.run([sys.executable, '-m', 'camtraj', 'report', sys.argv[1], '-o',"
            " sys.argv[2]], check=True)\n"
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", code, str(mcap), str(html)],
                          capture_output=True, text=True, env=env, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return int(proc.stdout.split()[-1])


def test_report_memory_grows_far_less_than_the_file(takes: dict[int, Path],
                                                    tmp_path: Path) -> None:
    """Peak RSS per extra film frame: ~57 KiB with mcap_ros2's objects for every message, a
    few KiB now (the /joint_trajectory message's bytes while the file is read)."""
    peak = {n: _peak_kib(takes[n], tmp_path / f"r{n}.html") for n in (SHORT, LONG)}
    per_frame = (peak[LONG] - peak[SHORT]) / (LONG - SHORT)
    size_per_frame = (takes[LONG].stat().st_size - takes[SHORT].stat().st_size) / 1024 / (
        LONG - SHORT)
    assert per_frame < 10.0, (peak, per_frame)
    assert per_frame < 3 * size_per_frame, (per_frame, size_per_frame)


def test_the_drawn_camera_path_keeps_every_runs_extremes() -> None:
    """A long path is drawn through at most a few points per run of frames, and each run's
    least and greatest x and y are among them (a spike of one frame stays drawn)."""
    from camtraj.report.plots import path_frames

    rng = np.random.default_rng(1)
    for n in (2000, 50_000, 400_000):
        xy = np.cumsum(rng.normal(size=(n, 2)), axis=0)
        xy[n // 3] += 1e3  # a one-frame spike
        runs = 500
        idx = path_frames(xy, runs=runs, must=np.array([7, 8]))
        assert np.all(np.diff(idx) > 0) and idx[0] == 0 and idx[-1] == n - 1
        assert {7, 8, n // 3} <= set(idx.tolist())
        if n <= 5 * runs:
            assert idx.size == n
            continue
        assert idx.size <= 5 * runs + 3
        starts = np.linspace(0, n, runs + 1).astype(int)
        for a, b in itertools.pairwise(starts.tolist()):
            mine = xy[idx[(idx >= a) & (idx < b)]]
            np.testing.assert_array_equal(mine.min(axis=0), xy[a:b].min(axis=0))
            np.testing.assert_array_equal(mine.max(axis=0), xy[a:b].max(axis=0))


def test_the_page_of_a_long_take_stays_small(takes: dict[int, Path], tmp_path: Path) -> None:
    """Ten times the frames: the page grows by little (the plots and the path views are
    thinned to the picture's width, not the take's length)."""
    size = {}
    for n in (SHORT, LONG):
        out = tmp_path / f"{n}.html"
        assert run_cli("report", takes[n], "-o", out).returncode == 0
        size[n] = out.stat().st_size
    assert size[LONG] < 1.1 * size[SHORT], size
