"""Robot files that are not what they should be, and ``--start-from`` (issue 8 §3-4).

Every bad file is a one-line :class:`RobotFileError` naming the file and the key (never a
``UnicodeDecodeError`` or ``ValueError`` traceback); every required value of the template is
required; a start vector outside the limits is refused, and a valid one is where the take
starts.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from camtraj import Robot, RobotFileError
from camtraj.errors import InputError
from camtraj.robot import JOINT_NAMES, PRISMATIC
from camtraj.timing import Limits, time_shot
from tests.test_convert import ROOT, SHOTS, error_line, run_cli

TEMPLATE = (ROOT / "camtraj" / "data" / "robot.toml").read_text(encoding="utf-8")
CRANE = SHOTS / "blender_crane_up.usda"
NAME_LINE = 1 + next(i for i, ln in enumerate(TEMPLATE.splitlines()) if "He 2018" in ln)


def _write(tmp_path: Path, data: bytes | str, name: str = "robot.toml") -> Path:
    path = tmp_path / name
    path.write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
    return path


def _error(path: Path) -> str:
    with pytest.raises(RobotFileError) as info:
        Robot.from_toml(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    return message


# --------------------------------------------------------------------------------------------
# Encodings and file kinds


@pytest.mark.parametrize(
    ("encode", "words"),
    [
        (lambda t: t.encode("utf-16"), ["UTF-16", "UTF-8"]),
        (lambda t: t.encode("utf-16-le"), ["NUL", "UTF-8"]),  # no BOM
        (lambda t: t.encode("utf-32"), ["UTF-32"]),
        (lambda t: t.replace("He 2018", "Hé 2018").encode("latin-1"), ["not UTF-8",
                                                                          f"line {NAME_LINE}"]),
        (lambda t: np.random.default_rng(0).bytes(4096), ["UTF-8"]),
        (lambda t: b"\x00\x01\x02binary\xff\xfe", ["UTF-8"]),
    ],
    ids=["utf16", "utf16-no-bom", "utf32", "latin1", "random-bytes", "binary"],
)
def test_undecodable_robot_files(tmp_path: Path, encode: object, words: list[str]) -> None:
    assert callable(encode)
    message = _error(_write(tmp_path, encode(TEMPLATE)))
    for word in words:
        assert word in message


def test_utf8_with_bom_and_non_ascii_names_load(tmp_path: Path) -> None:
    text = TEMPLATE.replace("He 2018", "Hé 2018")
    robot = Robot.from_toml(_write(tmp_path, text.encode("utf-8-sig")))
    assert robot.name == "PRRPR-S camera robot (Hé 2018)"


def test_fifo_and_folder_are_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "robot.fifo"
    os.mkfifo(fifo)
    assert "not a regular file" in _error(fifo)
    folder = tmp_path / "robot.d"
    folder.mkdir()
    assert "folder" in _error(folder)


def test_cli_reports_an_undecodable_robot_file_in_one_line(tmp_path: Path) -> None:
    path = _write(tmp_path, TEMPLATE.encode("utf-16"), "utf16 robot.toml")
    proc = run_cli("check", CRANE, "--robot", path)
    assert proc.returncode == 2
    line = error_line(proc)
    assert "utf16 robot.toml" in line
    assert "UTF-16" in line


# --------------------------------------------------------------------------------------------
# Ragged and string-valued arrays


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        ("rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         "rotation = [[0.0, 1.0, 0.0], [1.0, 0.0], [0.0, 0.0, -1.0]]", "mount.rotation"),
        ("rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         'rotation = [["0", "1", "0"], ["1", "0", "0"], ["0", "0", "-1"]]', "mount.rotation"),
        ("rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         'rotation = "identity"', "mount.rotation"),
        ("rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         "rotation = [[0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         "mount.rotation"),
        ("rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]",
         "rotation = [[0.0, 1.0, 0.0], [1.0, true, 0.0], [0.0, 0.0, -1.0]]", "mount.rotation"),
        ("offset = [0.0, 0.0, 0.0]", 'offset = ["a", 0.0, 0.0]', "mount.offset"),
        ("offset = [0.0, 0.0, 0.0]", "offset = [0.0, 0.0]", "mount.offset"),
        ("offset = [0.0, 0.0, 0.0]", "offset = [[0.0, 0.0, 0.0]]", "mount.offset"),
        ("offset = [0.0, 0.0, 0.0]", "offset = [0.0, nan, 0.0]", "mount.offset"),
    ],
)
def test_bad_mount_arrays_name_file_and_key(tmp_path: Path, old: str, new: str,
                                            key: str) -> None:
    assert old in TEMPLATE
    message = _error(_write(tmp_path, TEMPLATE.replace(old, new, 1)))
    assert f"[{key}]" in message


# --------------------------------------------------------------------------------------------
# Every required value


def _sections(text: str) -> list[tuple[str, list[str]]]:
    """The template as (table name, lines) in order; the name is '' before the first table."""
    out: list[tuple[str, list[str]]] = [("", [])]
    for line in text.splitlines(keepends=True):
        header = re.match(r"^\[([a-z_.]+)\]\s*$", line)
        if header:
            out.append((header[1], [line]))
        else:
            out[-1][1].append(line)
    return out


def _without(text: str, table: str, key: str | None) -> str:
    """``text`` without table ``table`` (key None) or without ``key = ...`` in it."""
    kept = []
    for name, lines in _sections(text):
        if name == table:
            if key is None:
                continue
            lines = [ln for ln in lines if not re.match(rf"^{re.escape(key)}\s*=", ln)]
        kept.append("".join(lines))
    return "".join(kept)


def _required() -> list[tuple[str, str | None, str]]:
    """(table, key or None, the key path the message must name) of every required value."""
    data = tomllib.loads(TEMPLATE)
    cases: list[tuple[str, str | None, str]] = [
        ("robot", "angle_unit", "robot.angle_unit"),
        ("robot", None, "robot"),
        ("dh", None, "dh"),
        ("mount", None, "mount"),
    ]
    cases += [("dh", k, f"dh.{k}") for k in data["dh"]]
    cases += [("mount", k, f"mount.{k}") for k in data["mount"]]
    for axis in JOINT_NAMES:
        cases.append((f"joints.{axis}", None, f"joints.{axis}"))
        cases += [(f"joints.{axis}", k, f"joints.{axis}.{k}")
                  for k in data["joints"][axis] if k != "kind"]
    return cases


@pytest.mark.parametrize(("table", "key", "named"), _required(),
                         ids=[c[2] + ("" if c[1] else " table") for c in _required()])
def test_every_required_value_is_required(tmp_path: Path, table: str, key: str | None,
                                          named: str) -> None:
    text = _without(TEMPLATE, table, key)
    assert text != TEMPLATE
    message = _error(_write(tmp_path, text))
    assert f"[{named}]" in message
    assert "missing" in message


def test_optional_values_keep_their_documented_defaults(tmp_path: Path, robot: Robot) -> None:
    text = _without(_without(TEMPLATE, "ik", None), "robot", "name")
    other = Robot.from_toml(_write(tmp_path, text))
    assert other.name == "camera robot"
    assert other.ik.objective == "shot"
    assert other.ik.stretch_margin == pytest.approx(robot.ik.stretch_margin)
    assert other.ik.limit_margin_prismatic == pytest.approx(robot.ik.limit_margin_prismatic)
    assert other.ik.limit_margin_revolute == pytest.approx(robot.ik.limit_margin_revolute)


# --------------------------------------------------------------------------------------------
# --start-from


@pytest.mark.parametrize(
    ("start", "words"),
    [
        ("100,0,0,0,-90,0,0,0", ["track = 100 m", "upper limit 14 m"]),
        ("0,0,0,0,10,0,0,0", ["elbow = 10 deg", "upper limit 0 deg"]),
        ("0,0,0,-0.5,-90,0,0,0", ["extend = -0.5 m", "lower limit 0 m"]),
    ],
)
def test_start_from_outside_the_limits_is_refused(start: str, words: list[str]) -> None:
    proc = run_cli("check", CRANE, "--start-from", start)
    assert proc.returncode == 2
    line = error_line(proc)
    assert "--start-from" in line
    for word in words:
        assert word in line


def test_library_refuses_a_start_outside_the_limits(robot: Robot) -> None:
    q = np.zeros(8)
    q[0] = 100.0
    with pytest.raises(InputError, match=r"track = 100 m is beyond its upper limit 14 m"):
        robot.joint_vector(q, "start")
    with pytest.raises(InputError, match="8 finite joint values"):
        robot.joint_vector([0.0] * 7, "start")


def test_take_starts_at_rest_at_the_start_vector(robot: Robot) -> None:
    # A path in motion at its first frame, and a start 1.2 m down the track from it.
    n = 48
    s = np.linspace(0.0, 1.0, n)
    q = np.zeros((n, 8))
    q[:, 0] = 3.0 + 0.5 * s
    q[:, 4] = -1.2 + 0.2 * s
    q[:, 5] = 0.3 * s
    start = q[0].copy()
    start[0] -= 1.2
    start[5] += 0.4
    limits = Limits.from_robot(robot)
    take = time_shot(q, np.arange(n) / 24.0, limits, start=start)
    np.testing.assert_array_equal(take.q[0], start)
    np.testing.assert_array_equal(take.qd[0], np.zeros(8))
    up = take.report.runup
    assert up["duration"] > 0.5  # 1.2 m of track takes time
    np.testing.assert_allclose([up["start"][k] for k in JOINT_NAMES], start)
    assert up["extent"]["track"] == pytest.approx(1.2, abs=1e-6)
    # it arrives in the first frame's state, on a servo tick, inside every limit
    first = take.frame_samples[0]
    np.testing.assert_allclose(take.q[first], q[0], atol=1e-12)
    step = take.t[1] - take.t[0]
    np.testing.assert_allclose(take.q[first - 1], take.q[first] - take.qd[first] * step,
                               atol=np.max(limits.acceleration) * step**2)
    for values, bound in ((take.qd, limits.velocity), (take.qdd, limits.acceleration),
                          (take.qddd, limits.jerk)):
        assert np.all(np.abs(values) <= bound * (1 + 1e-6) + 1e-9)
    assert np.all((take.q >= limits.lower - 1e-9) & (take.q <= limits.upper + 1e-9))


def test_convert_starts_the_take_at_the_given_vector(tmp_path: Path) -> None:
    start_si = np.array([2.0, 0.0, 0.0, 0.0, math.radians(-90.0), 0.0, 0.0, 0.0])
    text = ",".join(f"{v:g}" if PRISMATIC[i] else f"{math.degrees(v):g}"
                    for i, v in enumerate(start_si))
    out = tmp_path / "crane.mcap"
    proc = run_cli("convert", CRANE, "-o", out, "--start-from", text, "--frames", "1:24")
    assert proc.returncode == 0, proc.stderr
    # the track row: position velocity accel jerk run-up run-out unit margin to-start
    track_runup = re.search(r"^  track .* (\d+\.\d+)\s+\d+\.\d+ m\s+\S+\s+\S+$", proc.stdout,
                            re.M)
    assert track_runup and float(track_runup[1]) > 0.1, proc.stdout
    with out.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        first = next(msg for _, _, _, msg in reader.iter_decoded_messages(
            topics=["/joint_states"]))
    assert list(first.name) == list(JOINT_NAMES)
    np.testing.assert_allclose(first.position, start_si, atol=1e-12)
    np.testing.assert_allclose(first.velocity, 0.0, atol=1e-12)


def test_rotation_and_elbow_errors_say_by_how_much_in_the_files_unit(tmp_path: Path) -> None:
    """A mount rotation typed to four decimals (the default tilted 8 deg) says how far from
    a rotation it is and what to do; an elbow range outside the mechanism's says the range
    given, in the file's own angle unit (a new user's radians file was told degrees)."""
    mount = "rotation = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]"
    tilted = ("rotation = [[0.0, 0.9903, 0.1392], [1.0, 0.0, 0.0], "
              "[0.0, 0.1392, -0.9903]]")
    message = _error(_write(tmp_path, TEMPLATE.replace(mount, tilted, 1)))
    assert "[mount.rotation]" in message and "from the identity, more than 1e-06" in message
    assert "7 or more decimals" in message
    unit = 'angle_unit = "deg"'
    assert unit in TEMPLATE
    message = _error(_write(tmp_path, TEMPLATE.replace(unit, 'angle_unit = "rad"', 1)))
    assert ("[joints.elbow] min and max = [-180, 0] rad: must lie inside [-3.14159, 0] rad"
            in message), message
    elbow = "min = -180.0   # the papers' physical limit"
    assert elbow in TEMPLATE
    message = _error(_write(tmp_path, TEMPLATE.replace(elbow, "min = -190.0 #", 1)))
    assert "min and max = [-190, 0] deg: must lie inside [-180, 0] deg" in message, message
