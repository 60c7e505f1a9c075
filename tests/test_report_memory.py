"""``camtraj report`` of a long take in bounded memory (issue 14, section 5).

The report reads the MCAP with :func:`camtraj.mcap_io.read_take_for_report`, which decodes the
one /joint_trajectory message straight from its CDR bytes and streams /tf and /shot/frames.
Independent facts: :func:`camtraj.mcap_io.read_take` (mcap_ros2's decoder) on the same file,
the page built from it, and the peak resident memory of real ``camtraj report`` processes.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from camtraj.mcap_io import read_take, read_take_for_report
from camtraj.report import from_take, render_html
from tests.test_convert import ROOT, run_cli

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
    full, light = read_take(takes[SHORT]), read_take_for_report(takes[SHORT])
    for name in ("trajectory_t", "trajectory_q", "trajectory_qd", "trajectory_qdd",
                 "frame_numbers", "frame_times", "frame_q", "target", "achieved",
                 "focal_length_mm", "focus_distance_m", "f_stop", "tf_times"):
        np.testing.assert_array_equal(getattr(light, name), getattr(full, name), err_msg=name)
    assert light.trajectory_joint_names == full.trajectory_joint_names
    assert light.trajectory_stamp == full.trajectory_stamp
    assert light.metadata == full.metadata and light.all_metadata == full.all_metadata
    assert light.robot_description == full.robot_description
    for tree, ref in ((light.tf, full.tf), (light.tf_static, full.tf_static)):
        assert tree.keys() == ref.keys()
        for child, (parent, mats) in ref.items():
            assert tree[child][0] == parent
            np.testing.assert_array_equal(tree[child][1], mats, err_msg=child)
    assert light.trajectory_t.size > 5 * SHORT  # the servo rate is many times the film rate


def test_the_page_is_the_same_from_either_reader(takes: dict[int, Path]) -> None:
    mcap = takes[SHORT]
    assert (render_html(from_take(read_take_for_report(mcap), mcap))
            == render_html(from_take(read_take(mcap), mcap)))


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
    """Peak RSS per extra film frame: ~57 KiB with mcap_ros2's objects, now a few KiB."""
    peak = {n: _peak_kib(takes[n], tmp_path / f"r{n}.html") for n in (SHORT, LONG)}
    per_frame = (peak[LONG] - peak[SHORT]) / (LONG - SHORT)
    size_per_frame = (takes[LONG].stat().st_size - takes[SHORT].stat().st_size) / 1024 / (
        LONG - SHORT)
    assert per_frame < 10.0, (peak, per_frame)
    assert per_frame < 3 * size_per_frame, (per_frame, size_per_frame)
