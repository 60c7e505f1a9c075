"""Robot description file and forward kinematics against the papers' published numbers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from camtraj import Robot, RobotFileError
from camtraj.robot import JOINT_NAMES

from .conftest import pose_error

GA_EQ18 = np.array([[0, 0, 1, 3.5], [0, -1, 0, 0], [1, 0, 0, -0.33], [0, 0, 0, 1.0]])
GA_EQ16 = np.array([1.4019, 0.52360, -0.01931, 0.0, -2.56796, 0.0, 1.01647, -2.617994])
GA_TARGET = np.array([[1, 0, 0, 5.0], [0, 1, 0, 1.5], [0, 0, 1, 1.5], [0, 0, 0, 1.0]])
DEFAULT_TOML = (Path(__file__).parents[1] / "camtraj" / "data" / "robot.toml").read_text()


def test_fk_zero_is_ga_eq18(robot: Robot) -> None:
    np.testing.assert_allclose(robot.fk(np.zeros(8)), GA_EQ18, atol=1e-12)


def test_fk_of_published_solution_reaches_published_target(robot: Robot) -> None:
    dp, dr = pose_error(robot.fk(GA_EQ16), GA_TARGET)
    assert dp < 1e-4  # the published joint values are rounded to ~5 digits
    assert dr < 1e-4


def test_fk_is_vectorised_and_link_frames_chain(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(5, 3, 8))
    batch = robot.fk(q)
    assert batch.shape == (5, 3, 4, 4)
    np.testing.assert_allclose(batch[2, 1], robot.fk(q[2, 1]), atol=1e-12)
    frames = robot.link_frames(q[0, 0])
    assert frames.shape == (9, 4, 4)
    # the wrist centre (frames 6-8 share an origin) does not move with pan/tilt/roll
    q2 = q[0, 0].copy()
    q2[5:] += 0.7
    np.testing.assert_allclose(robot.link_frames(q2)[6:, :3, 3], frames[6:, :3, 3], atol=1e-12)


def test_default_camera_looks_down_the_track_upright(robot: Robot) -> None:
    cam = robot.camera_pose(np.zeros(8))
    np.testing.assert_allclose(-cam[:3, 2], [1, 0, 0], atol=1e-12)  # looks along +x
    np.testing.assert_allclose(cam[:3, 1], [0, 0, 1], atol=1e-12)  # image up is world up


def test_default_file_values(robot: Robot) -> None:
    assert robot.joint_names == JOINT_NAMES
    np.testing.assert_allclose(robot.weights, [50000, 200, 100, 50000, 30, 1, 1, 1])
    assert robot.lower[4] == pytest.approx(-math.pi) and robot.upper[4] == 0.0
    assert robot.dh.r6 == 0.963


def test_controller_units_reproduce_ga_eq22(tmp_path: Path) -> None:
    # scales derived from the GA paper's eq. 22 (counts / joint value of eq. 21)
    counts = {"track": 1800168, "rotate": -268860, "elbow": -11313862, "tilt": -3105818}
    text = DEFAULT_TOML
    for name, c in counts.items():
        value = GA_EQ16[JOINT_NAMES.index(name)]
        scale, sign = float(abs(c / value)), int(np.sign(c / value))
        text += f"\n[controller.{name}]\nscale = {scale!r}\nsign = {sign}\n"
    path = tmp_path / "robot.toml"
    path.write_text(text)
    robot = Robot.from_toml(path)
    got = robot.counts(GA_EQ16)
    for name, c in counts.items():
        assert got[name] == pytest.approx(c, rel=1e-12)


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("max_velocity = 90.0\n", "", ["joints.rotate.max_velocity", "missing"]),
        ("max = 1.5\n", "max = -1.5\n", ["joints.extend", "min", "max"]),
        ("max_jerk = 15.0", "max_jerk = -1.0", ["joints.track.max_jerk", "between 0.001"]),
        # trial 22: a limit of 1e-300 passed and broke the solver with a traceback
        ("max_jerk = 15.0", "max_jerk = 1e-300", ["joints.track.max_jerk", "between 0.001"]),
        ("max_velocity = 90.0\n", "max_velocity = 1e-30\n",
         ["joints.rotate.max_velocity", "between 0.001"]),
        ("r6 = 0.963", "r6 = 0.963\nr7 = 1.0", ["unknown key", "r7"]),
        ("min = -180.0", "min = -200.0", ["joints.elbow", "-180, 0"]),
        ('angle_unit = "deg"', 'angle_unit = "grad"', ["angle_unit", "deg"]),
        ('\nobjective = "shot"', '\nobjective = "fast"', ["ik.objective"]),
        ("track_samples = 4", "track_samples = 2.5", ["ik.track_samples", "whole"]),
        ("margin_weight = 10.0", "margin_weight = -1.0", ["ik.margin_weight", "between"]),
        ("weight = 30.0", 'weight = "heavy"', ["joints.elbow.weight", "number"]),
    ],
)
def test_invalid_robot_files_name_file_and_key(
    tmp_path: Path, old: str, new: str, words: list[str]
) -> None:
    assert old in DEFAULT_TOML
    path = tmp_path / "bad robot.toml"
    path.write_text(DEFAULT_TOML.replace(old, new, 1))
    with pytest.raises(RobotFileError) as info:
        Robot.from_toml(path)
    message = str(info.value)
    assert str(path) in message
    for word in words:
        assert word in message


def test_unreadable_and_malformed_robot_files(tmp_path: Path) -> None:
    with pytest.raises(RobotFileError, match="cannot read"):
        Robot.from_toml(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\nname=")
    with pytest.raises(RobotFileError, match="not valid TOML"):
        Robot.from_toml(bad)


def test_angles_in_radians_file_matches_degrees_file(tmp_path: Path, robot: Robot) -> None:
    import re

    def to_rad(match: re.Match[str]) -> str:
        return f"{match.group(1)} = {math.radians(float(match.group(2)))!r}"

    text = DEFAULT_TOML.replace('angle_unit = "deg"', 'angle_unit = "rad"')
    blocks = text.split("[joints.")
    for i, block in enumerate(blocks):
        if 'kind = "revolute"' in block:
            blocks[i] = re.sub(
                r"^(min|max|max_velocity|max_acceleration|max_jerk|home) = (-?[0-9.]+)",
                to_rad, block, flags=re.M)
    text = "[joints.".join(blocks)
    text = re.sub(r"^(stretch_margin|wrist_margin|limit_margin_revolute) = ([0-9.]+)",
                  to_rad, text, flags=re.M)
    path = tmp_path / "rad.toml"
    path.write_text(text)
    other = Robot.from_toml(path)
    for field in ("lower", "upper", "max_velocity", "max_acceleration", "max_jerk"):
        np.testing.assert_allclose(getattr(other, field), getattr(robot, field), rtol=1e-12)
    assert other.ik.stretch_margin == pytest.approx(robot.ik.stretch_margin)
