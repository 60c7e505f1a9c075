"""Lens files (issue 16 §1): the shipped examples, the calibration maps, and bad files.

The calibration is checked against independent facts: it passes through every row of the
file, is the scipy PCHIP of the same rows on every interval away from the ends (they share
their slopes there), rises monotonically, and its inverse maps every position back to the
lens quantity. Every bad file is exit 2 with one line naming the file and the key.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

from camtraj import Robot
from camtraj.errors import InputError, LensFileError, LensRangeError, RobotFileError
from camtraj.lens import LENS_AXES, Lens, commanded_lens, lens_positions, lens_warnings
from tests.test_convert import ROOT, SHOTS, error_line, run_cli

LENSES = ROOT / "camtraj" / "data" / "lenses"
ZOOM = LENSES / "cine_zoom_24-290.toml"
PRIME = LENSES / "prime_50.toml"
ZOOM_TEXT = ZOOM.read_text(encoding="utf-8")


def _rows(text: str, axis: str) -> tuple[list[float], list[float]]:
    """The (quantity, motor [deg]) rows of an axis's table, read from the file's text with a
    regular expression (not camtraj's reader)."""
    block = text.split(f"[{axis}]", 1)[1].split("calibration = [", 1)[1].split("]\n", 1)[0]
    pairs = re.findall(r"\[\s*([0-9.]+|inf)\s*,\s*([-0-9.]+)\s*\]", block)
    return [float(q) for q, _ in pairs], [float(m) for _, m in pairs]


def test_the_shipped_lenses_read() -> None:
    zoom = Lens.from_toml(ZOOM)
    assert zoom.names == LENS_AXES and zoom.focal_length_mm is None
    prime = Lens.from_toml(PRIME)
    assert prime.names == ("focus", "iris") and prime.focal_length_mm == 50.0
    assert zoom.axis("zoom") is not None and prime.axis("zoom") is None
    z = zoom.axis("zoom")
    assert z is not None
    assert (z.calibration.low, z.calibration.high) == (24.0, 290.0)
    assert z.velocity == pytest.approx(math.radians(60.0))
    limits = zoom.limits()
    assert limits.names == LENS_AXES and limits.revolute.all()
    # counts = offset + sign * scale * position [rad]: a quarter turn of the zoom ring
    assert zoom.counts(np.array([math.pi / 2, 0.0, 0.0]))["zoom"] == pytest.approx(16384.0,
                                                                                    rel=1e-7)


@pytest.mark.parametrize(("path", "axis"), [(ZOOM, "zoom"), (ZOOM, "focus"), (ZOOM, "iris"),
                                            (PRIME, "focus"), (PRIME, "iris")])
def test_calibration_through_the_rows_monotone_and_invertible(path: Path, axis: str) -> None:
    text = path.read_text(encoding="utf-8")
    quantity, motor_deg = _rows(text, axis)
    cal = Lens.from_toml(path).axis(axis)
    assert cal is not None
    c = cal.calibration
    motor = np.radians(motor_deg)
    assert np.abs(c.position(quantity) - motor).max() < 1e-12
    # away from the two end intervals it is scipy's PCHIP in u (ln x, or 1/x for focus)
    u = 1.0 / np.array(quantity) if axis == "focus" else np.log(quantity)
    order = np.argsort(u)
    pchip = PchipInterpolator(u[order], motor[order])
    us = np.sort(u)
    inner = np.concatenate([np.linspace(us[i], us[i + 1], 7)
                            for i in range(1, len(us) - 2)])
    x = 1.0 / inner if axis == "focus" else np.exp(inner)
    assert np.abs(c.position(x) - pchip(inner)).max() < 1e-12
    # C1: the slopes on either side of every inner row agree (a kink would differ by O(1))
    h = 1e-6 * (us[-1] - us[0])
    x_of = (lambda v: 1.0 / v) if axis == "focus" else np.exp
    for uk in us[1:-1]:
        left = (c.position(x_of(uk)) - c.position(x_of(uk - h))) / h
        right = (c.position(x_of(uk + h)) - c.position(x_of(uk))) / h
        assert abs(right - left) < 1e-3 * abs(left)
    # monotone everywhere, and the inverse round-trips
    lo = quantity[0]
    hi = quantity[-1] if math.isfinite(quantity[-1]) else 1000.0
    dense = np.geomspace(lo, hi, 20001)
    pos = c.position(dense)
    steps = np.diff(pos)
    assert np.all(steps > 0) or np.all(steps < 0)
    back = c.value(pos)
    assert np.abs(back - dense).max() <= 1e-9 * hi


def _bad(tmp_path: Path, text: str) -> str:
    path = tmp_path / "lens.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(LensFileError) as info:
        Lens.from_toml(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("[35.0, 19.5]", "[35.0, 7.0]", ["[zoom.calibration]", "not monotone", "row 3"]),
        ("[35.0, 19.5]", "[27.0, 19.5]", ["[zoom.calibration]", "not monotone", "increase"]),
        ("[50.0, 36.0]", "[nan, 36.0]", ["[zoom.calibration row 4]", "nan", "finite"]),
        ("[50.0, 36.0]", "[50.0, nan]", ["[zoom.calibration row 4]", "finite"]),
        ("max_velocity = 60.0", "max_velocity = nan", ["[zoom.max_velocity]", "finite"]),
        ("max_velocity = 60.0\n", "", ["[zoom.max_velocity]", "missing"]),
        ('unit = "mm"', 'unit = "furlong"', ["[zoom.unit]", "furlong", '"mm"']),
        ('unit = "m"', 'unit = "parsec"', ["[focus.unit]", "parsec", '"ft"']),
        ('unit = "T-stop"', 'unit = "stops"', ["[iris.unit]", "T-stop"]),
        ('angle_unit = "deg"', 'angle_unit = "grad"', ["[angle_unit]", "deg"]),
        ('angle_unit = "deg"\n', "", ["[angle_unit]", "missing"]),
        ("[0.6, 0.0], [0.7, 44.0]", "[0.6, 0.0], [inf, 44.0]", ["[focus.calibration]",
                                                                 "inf only"]),
        ("[290.0, 120.0]", "[290.0, 130.0]", ["[zoom.calibration]", "row 10",
                                              "outside the motor's range"]),
        ("[24.0, 0.0], [28.0, 8.0]", "[24.0]", ["[zoom.calibration]", "row 1", "pairs"]),
        ("min = -2.0", "min = 200.0", ["[zoom]", "below max"]),
        ("max_jerk = 2400.0", "max_jerk = -1.0", ["[zoom.max_jerk]", "between 0.001"]),
        # review 56: 1e-300 passed, and check printed a 300-digit zoom velocity
        ("max_jerk = 2400.0", "max_jerk = 1e-300", ["[zoom.max_jerk]", "between 0.001"]),
        ("max_jerk = 2400.0", "max_jerk = 2400.0\nspeed = 3", ["unknown key", "speed", "[zoom]"]),
        ('name = "Cine', 'focal_length = 35.0\nname = "Cine', ["[focal_length]", "zoom"]),
        ("sign = 1\n", "sign = 2\n", ["[controller.zoom.sign]", "1 or -1"]),
        ("scale = 10430.378", "scale = 0.0", ["[controller.zoom.scale]", "positive"]),
        ("scale = 10430.378", "scale = -10430.378", ["[controller.zoom.scale]", "positive"]),
        ("[controller.zoom]", "[controller.tilt]", ["unknown key", "tilt", "[controller]"]),
        ("calibration = [\n    [24.0", "calibration = 3\nx = [\n    [24.0", ["unknown key"]),
    ],
)
def test_bad_lens_files_are_one_line(tmp_path: Path, old: str, new: str,
                                     words: list[str]) -> None:
    assert old in ZOOM_TEXT
    message = _bad(tmp_path, ZOOM_TEXT.replace(old, new, 1))
    for word in words:
        assert word in message, message


def test_a_prime_needs_its_focal_length(tmp_path: Path) -> None:
    text = PRIME.read_text(encoding="utf-8").replace("focal_length = 50.0\n", "")
    assert "[focal_length] is missing" in _bad(tmp_path, text)


def test_a_lens_file_drives_at_least_one_motor(tmp_path: Path) -> None:
    # a prime with its focal length but no [focus] or [iris] table was a traceback (exit 1)
    text = 'name = "bare prime"\nangle_unit = "deg"\nfocal_length = 50.0\n'
    message = _bad(tmp_path, text)
    assert "[zoom] is missing" in message and "[focus]" in message and "[iris]" in message
    path = tmp_path / "lens.toml"
    out = tmp_path / "out.mcap"
    proc = run_cli("convert", SHOTS / "maya_dolly_push_in.usda", "-o", out, "--lens", path)
    assert proc.returncode == 2, proc.stderr
    assert "[zoom] is missing" in error_line(proc)
    assert not out.exists()


def test_not_toml_and_not_a_file(tmp_path: Path) -> None:
    assert "not valid TOML" in _bad(tmp_path, "[zoom\n")
    with pytest.raises(LensFileError, match="cannot read it"):
        Lens.from_toml(tmp_path / "missing.toml")


def _lens_table(text: str) -> str:
    """The lens file as a robot file's [lens] table."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^\[(.+)\]$", line)
        out.append(f"[lens.{m.group(1)}]" if m else line)
    body = "\n".join(out)
    return "\n[lens]\n" + body


def test_a_robot_file_lens_table(tmp_path: Path) -> None:
    template = (ROOT / "camtraj" / "data" / "robot.toml").read_text(encoding="utf-8")
    path = tmp_path / "robot.toml"
    path.write_text(template + _lens_table(ZOOM_TEXT), encoding="utf-8")
    robot = Robot.from_toml(path)
    assert robot.lens is not None and robot.lens.names == LENS_AXES
    assert "lens" in robot.describe() and "lens" not in Robot.default().describe()
    path.write_text(template + _lens_table(ZOOM_TEXT.replace('unit = "mm"', 'unit = "in"')),
                    encoding="utf-8")
    with pytest.raises(RobotFileError, match=r"\[lens\.zoom\.unit\] = 'in'"):
        Robot.from_toml(path)


def test_bad_lens_file_exits_2_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(ZOOM_TEXT.replace("[35.0, 19.5]", "[35.0, 7.0]"), encoding="utf-8")
    proc = run_cli("check", SHOTS / "whip_pan.usda", "--lens", path)
    assert proc.returncode == 2
    line = error_line(proc)
    assert str(path) in line and "[zoom.calibration]" in line and "not monotone" in line


def _shot(focal: list[float], focus: list[float], stop: list[float]) -> Any:
    """The lens channels of a shot, as :func:`camtraj.usd_shot.read_shot` gives them."""
    return SimpleNamespace(frames=np.arange(101, 101 + len(focal)),
                           focal_length_mm=np.array(focal), focus_distance_m=np.array(focus),
                           f_stop=np.array(stop))


def test_unset_focus_and_stop_hold_at_home(tmp_path: Path) -> None:
    path = tmp_path / "lens.toml"
    path.write_text(ZOOM_TEXT.replace("max_jerk = 7200.0", "max_jerk = 7200.0\nhome = 300.0"),
                    encoding="utf-8")
    lens = Lens.from_toml(path)
    q = lens_positions(lens, _shot([35.0, 50.0], [0.0, 0.0], [0.0, 0.0]))
    assert q[:, 1].tolist() == [math.radians(300.0)] * 2  # focus home: infinity
    assert q[:, 2].tolist() == [0.0, 0.0]  # iris home: the first row
    assert lens_warnings(lens, _shot([35.0, 50.0], [0.0, 0.0], [0.0, 0.0])) == [
        "the shot does not set its focus distance: the focus motor holds at its home "
        f"(infinity, lens file {path})",
        f"the shot does not set its f-stop: the iris motor holds at its home (T2.8, lens file "
        f"{path})"]


def test_a_home_outside_the_calibration_is_said_as_a_motor_angle(tmp_path: Path) -> None:
    """A home past the table's end (focus at 302 deg, the infinity mark at 300; iris at -1,
    the table from 0) has no lens value: the warning says the motor angle and where the
    table ends, not the table's end value (a new user read "holds at infinity" and "T2.8"
    for motors commanded elsewhere)."""
    path = tmp_path / "lens.toml"
    text = ZOOM_TEXT.replace("max_jerk = 7200.0", "max_jerk = 7200.0\nhome = 302.0")
    path.write_text(text.replace("max_jerk = 1200.0", "max_jerk = 1200.0\nhome = -1.0"),
                    encoding="utf-8")
    lens = Lens.from_toml(path)
    shot = _shot([35.0, 50.0], [0.0, 0.0], [0.0, 0.0])
    q = lens_positions(lens, shot)
    assert np.degrees(q[:, 1]).tolist() == pytest.approx([302.0, 302.0])
    assert np.degrees(q[:, 2]).tolist() == pytest.approx([-1.0, -1.0])
    assert lens_warnings(lens, shot) == [
        "the shot does not set its focus distance: the focus motor holds at its home (302.00 "
        f"deg, outside its calibration, which ends at 300.00 deg, lens file {path})",
        "the shot does not set its f-stop: the iris motor holds at its home (-1.00 deg, "
        f"outside its calibration, which ends at 0.00 deg, lens file {path})"]


def test_a_focus_unset_on_some_frames_only_is_bad_input() -> None:
    """Focus distance 0 (unset) on some frames and set on others: the motor needs a value on
    every frame, and the error says that (it had said "0 m is nearer than the lens's
    0.6 m", exit 3)."""
    with pytest.raises(InputError, match=r"^focus distance is unset \(0\) on frames 101-102 "
                                         r"but set on the others") as info:
        lens_positions(Lens.from_toml(ZOOM), _shot([30.0] * 4, [0.0, 0.0, 2.0, 2.0],
                                                   [4.0] * 4))
    assert info.value.exit_code == 2


def test_every_frame_beyond_the_table_is_named() -> None:
    """The frames outside the table, all of them, with the first one's value (a new user
    had to re-run for each)."""
    with pytest.raises(LensRangeError, match=r"focus distance 0.5 m at frame 102 \(outside "
                                             r"on frames 102-103, 105\) is nearer than"):
        lens_positions(Lens.from_toml(ZOOM), _shot([30.0] * 5, [2.0, 0.5, 0.4, 2.0, 0.5],
                                                   [4.0] * 5))


@pytest.mark.parametrize(
    ("focal", "focus", "stop", "words"),
    [
        ([24.0, 310.0], [2.0, 2.0], [4.0, 4.0],
         "focal length 310 mm at frame 102 is beyond the lens's 290 mm"),
        ([23.0, 30.0], [2.0, 2.0], [4.0, 4.0],
         "focal length 23 mm at frame 101 is below the lens's 24 mm"),
        ([30.0, 30.0, 30.0], [2.0, 1.0, 0.4], [4.0, 4.0, 4.0],
         "focus distance 0.4 m at frame 103 is nearer than the lens's 0.6 m"),
        ([30.0, 30.0], [2.0, 2.0], [2.0, 4.0],
         "stop T2 (the shot's fStop 2) at frame 101 is below the lens's T2.8"),
    ],
)
def test_a_lens_quantity_beyond_the_table_names_the_frame(
        focal: list[float], focus: list[float], stop: list[float], words: str) -> None:
    with pytest.raises(LensRangeError) as info:
        lens_positions(Lens.from_toml(ZOOM), _shot(focal, focus, stop))
    assert words in str(info.value) and info.value.exit_code == 3


def test_prime_and_missing_motor_warnings() -> None:
    prime = Lens.from_toml(PRIME)
    shot = _shot([24.0, 57.6], [2.0, 3.0], [2.8, 4.0])
    assert any("24 to 57.6 mm" in w and "50 mm prime" in w for w in lens_warnings(prime, shot))
    commanded = commanded_lens(prime, lens_positions(prime, shot), shot)
    assert commanded["focal_length_mm"].tolist() == [50.0, 50.0]
    assert np.abs(commanded["focus_distance_m"] - [2.0, 3.0]).max() < 1e-12
    assert lens_warnings(prime, _shot([50.0, 50.0], [2.0, 3.0], [2.8, 4.0])) == []


def test_the_lens_option_travels_with_batch_and_farm_tasks(tmp_path: Path) -> None:
    from camtraj.farm import _manifest_options
    from camtraj.inputs import files_read
    from camtraj.options import ConvertOptions, options_from_json, options_to_args, options_to_json

    options = ConvertOptions(lens=str(ZOOM))
    assert options_to_args(options)[-2:] == ["--lens", str(ZOOM)]
    assert options_from_json(options_to_json(options)) == options
    assert _manifest_options(options_to_json(options), "manifest") == options
    assert (ZOOM, "the lens file") in files_read([], options)
    assert "--lens" not in options_to_args(ConvertOptions())


def test_a_focus_table_in_feet(tmp_path: Path) -> None:
    text = ZOOM_TEXT.replace('unit = "m"', 'unit = "ft"')
    path = tmp_path / "feet.toml"
    path.write_text(text, encoding="utf-8")
    feet = Lens.from_toml(path).axis("focus")
    assert feet is not None
    quantity, motor = _rows(text, "focus")
    finite = [q for q in quantity if math.isfinite(q)]
    got = feet.calibration.position(np.array(finite) * 0.3048)  # the marks, in metres
    assert np.abs(got - np.radians(motor[: len(finite)])).max() < 1e-12
    assert Lens.from_toml(path).describe()["axes"]["focus"]["quantity_unit"] == "m"
    assert Lens.from_toml(path).describe()["axes"]["focus"]["file_unit"] == "ft"
    # a distance beyond the table is said in metres and in the file's feet
    near = min(finite) * 0.3048  # the nearest mark, in metres
    with pytest.raises(LensRangeError) as info:
        lens_positions(Lens.from_toml(path), _shot([30.0, 30.0], [2.0, 0.5 * near],
                                                  [4.0, 4.0]))
    assert (f"focus distance {0.5 * near:.4g} m ({0.5 * min(finite):.4g} ft) at frame 102 is "
            f"nearer than the lens's {near:.4g} m ({min(finite):.4g} ft)") in str(info.value)


def test_a_prime_is_not_missed_by_a_rounding_step() -> None:
    """A zoom easing away from the prime's focal length: the warning names the first frame
    off by more than a thousandth (0.05 mm on the 50 mm prime), not the first that differs
    in the 6th digit."""
    focal = [50.0, 50.00004, 50.02, 50.2, 52.0]
    warnings = lens_warnings(Lens.from_toml(PRIME), _shot(focal, [2.0] * 5, [2.8] * 5))
    assert any("first at frame 104" in w and "50 mm prime" in w for w in warnings), warnings
    assert lens_warnings(Lens.from_toml(PRIME), _shot([50.0, 50.04], [2.0] * 2, [2.8] * 2)) == []
