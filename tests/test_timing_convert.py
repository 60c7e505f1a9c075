"""End to end through ``camtraj.convert``: short shots authored as USD stages that start and
end in motion, and the servo stream read back from the written MCAP by the mcap library."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.convert import analyse, convert
from camtraj.options import ConvertOptions
from camtraj.robot import Robot
from camtraj.timing import Limits
from tests.timing_checks import SLACK, divided

from .shot_set import make_samples

Array = NDArray[np.float64]
SHOTS = Path(__file__).resolve().parents[1] / "samples" / "shots"


def write_track_move(path: Path, seconds: float, speed: float, tilt_rate: float) -> Path:
    """A camera moving along the track at constant ``speed`` [m/s] with a slow tilt
    [deg/s], in motion from the first frame to the last (Z-up metres, 24 fps)."""
    ms = make_samples()
    frames = np.arange(1, int(seconds * 24) + 2, dtype=np.float64)
    t = (frames - 1) / 24.0
    pos = np.stack([4.0 + speed * t, np.full_like(t, 1.0), np.full_like(t, 1.0)], axis=1)
    move = ms.Move(frames, pos, np.full_like(t, 0.0), -5.0 + tilt_rate * t, 35.0, 3.0, 2.8)
    body = ms._scope("Xform", "World", [ms._camera_prim_trs("cam", move, "Z", 1.0, "    ")])
    text = ms._header("track move in motion", "Z", 1.0, frames, 24.0, "World") + "\n" + body
    path.write_text(text + "\n", encoding="utf-8")
    return path


@pytest.mark.parametrize(("seconds", "speed", "tilt_rate"), [(1.0, 0.4, 3.0), (2.0, 0.5, 4.0)])
def test_short_move_in_motion_converts_at_shot_timing(
    tmp_path: Path, seconds: float, speed: float, tilt_rate: float
) -> None:
    shot = write_track_move(tmp_path / "move.usda", seconds, speed, tilt_rate)
    limits = Limits.from_robot(Robot.default())
    take = analyse(shot, ConvertOptions()).take
    assert take is not None
    assert take.mode == "shot" and take.speed_factor == 1.0
    assert take.report.runup["duration"] > 0 and take.report.runout["duration"] > 0
    for order, bound in ((1, limits.velocity), (2, limits.acceleration), (3, limits.jerk)):
        worst = float(np.max(np.abs(divided(take.t, take.q, order)) / bound))
        assert worst <= 1 + SLACK, f"order {order}: {worst:.4f} of the limit"
    assert np.all(take.q <= limits.upper) and np.all(take.q >= limits.lower)

    out = tmp_path / "move.mcap"
    summary = convert(shot, out)
    assert out.is_file()
    assert summary["timing"] == "shot"
    # The positions as written, read back by the mcap library (not camtraj's writer).
    from mcap.reader import make_reader

    count = 0
    with out.open("rb") as f:
        for _schema, channel, _message in make_reader(f).iter_messages(topics=["/joint_states"]):
            assert channel.topic == "/joint_states"
            count += 1
    assert count == take.t.size


def test_heavy_libraries_load_only_for_the_mode_that_needs_them() -> None:
    import subprocess

    code = (
        "import sys, numpy as np\n"
        "import camtraj.convert\n"
        "from camtraj.robot import Robot\n"
        "from camtraj.timing import Limits, time_shot\n"
        "q = np.tile([5.0, 0, 0, 0.7, -1.5, 0, 0, 0], (24, 1)); q[:, 0] += np.arange(24) / 240\n"
        "time_shot(q, np.arange(24) / 24, Limits.from_robot(Robot.default()), mode='scale')\n"
        "print(sorted(m for m in ('toppra', 'matplotlib', 'scipy.interpolate', 'scipy.optimize')"
        " if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
