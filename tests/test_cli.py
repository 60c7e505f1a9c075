"""Acceptance tests of the ``camtraj`` command line: check, info, help, --summary, --placement
and bad input (design.md §4-5). Every command runs in a subprocess; independent facts come
from pxr, forward kinematics and a plain workspace optimisation (see test_convert.py).

All command lines of this module run concurrently, once, in a module fixture.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from camtraj.cli import main as cli_main
from camtraj.mcap_io import read_take
from camtraj.robot import JOINT_NAMES, Robot
from tests.conftest import pose_error
from tests.test_convert import (
    ROOT,
    SHOTS,
    error_line,
    leftovers,
    run_all,
    run_cli,
    usd_camera,
    workspace_miss,
)

MAYA = SHOTS / "maya_dolly_push_in.usda"
WHIP = SHOTS / "whip_pan.usda"
UNREACHABLE = SHOTS / "unreachable.usda"
ROBOT_TOML = ROOT / "camtraj" / "data" / "robot.toml"
SENTINEL = b"an earlier, good take\n"

#: The topics and types of design.md §4.
TOPICS = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/joint_trajectory": "trajectory_msgs/msg/JointTrajectory",
    "/shot/frames": "camtraj_msgs/msg/ShotFrame",
    "/robot_description": "std_msgs/msg/String",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/tf_static": "tf2_msgs/msg/TFMessage",
}

PLACEMENT_YAW = (0.5, 0.3, 0.0, 10.0)  # x, y, z [m], yaw [deg]


def command_paths() -> list[list[str]]:
    """Every command and sub-command of the CLI, e.g. [], ["convert"], ["farm", "export"]."""
    out: list[list[str]] = []

    def walk(cmd: click.Command, path: list[str]) -> None:
        out.append(path)
        if isinstance(cmd, click.Group):  # as --help lists them: lazily imported ones too
            ctx = click.Context(cmd)
            for name in cmd.list_commands(ctx):
                sub = cmd.get_command(ctx, name)
                assert sub is not None, name
                walk(sub, [*path, name])

    walk(cli_main, [])
    return out


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Bad:
    """A convert run that must fail with exit 2 and write nothing.

    Attributes:
        args: The convert arguments.
        output: The -o path.
        must_match: Regular expressions the error line must each match (case-insensitive).
        existing: An earlier output sits at ``output``; it must survive unchanged.
    """

    args: list[object]
    output: Path
    must_match: tuple[str, ...]
    existing: bool


def _write_bad_inputs(d: Path) -> dict[str, Bad]:
    (d / "notes.usd").write_text("shot notes: dolly in, then hold\n", encoding="utf-8")

    Sdf.Layer.FindOrOpen(str(MAYA)).Export(str(d / "full.usdc"))
    data = (d / "full.usdc").read_bytes()
    (d / "cut.usdc").write_bytes(data[: len(data) // 2])

    stage = Usd.Stage.CreateNew(str(d / "no_camera.usda"))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(24)
    UsdGeom.Xform.Define(stage, "/World")
    UsdGeom.Sphere.Define(stage, "/World/subject")
    stage.GetRootLayer().Save()

    shutil.copy(SHOTS / "blender_crane_up.usda", d / "two_cameras.usda")
    stage = Usd.Stage.Open(str(d / "two_cameras.usda"))
    UsdGeom.Camera.Define(stage, "/root/Camera2")
    stage.GetRootLayer().Save()

    shutil.copy(MAYA, d / "nan.usda")
    stage = Usd.Stage.Open(str(d / "nan.usda"))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/shotCam")).GetOrderedXformOps()[0]
    assert op.GetOpName() == "xformOp:translate"
    op.Set(Gf.Vec3d(math.nan, 140.0, 100.0), Usd.TimeCode(1050))
    stage.GetRootLayer().Save()

    text = ROBOT_TOML.read_text(encoding="utf-8")
    missing = text.replace("max_jerk = 15.0\n", "", 1)
    assert missing != text
    (d / "missing_value.toml").write_text(missing, encoding="utf-8")
    out_of_range = text.replace("min = -180.0", "min = -270.0", 1)
    assert out_of_range != text
    (d / "out_of_range.toml").write_text(out_of_range, encoding="utf-8")

    (d / "plain_file").write_text("not a folder\n", encoding="utf-8")

    def case(name: str, shot: Path | str, must: tuple[str, ...], *extra: object,
             existing: bool = False, output: Path | None = None) -> tuple[str, Bad]:
        folder = d / name
        folder.mkdir()
        out = output or folder / "out.mcap"
        if existing:
            out.write_bytes(SENTINEL)
        return name, Bad(["convert", shot, "-o", out, *extra], out, must, existing)

    cases = [
        case("missing_file", d / "no_such_shot.usd", (r"no_such_shot\.usd",
             r"no such file|not found|does not exist")),
        case("text_renamed_usd", d / "notes.usd", (r"notes\.usd", r"not a USD"),
             existing=True),
        case("truncated_usdc", d / "cut.usdc", (r"cut\.usdc", r"truncated|corrupt")),
        case("no_camera", d / "no_camera.usda", (r"no_camera\.usda", r"no camera"),
             existing=True),
        case("two_cameras", d / "two_cameras.usda",
             (r"two_cameras\.usda", r"\b(2|two) cameras", r"/root/Camera\b", r"/root/Camera2")),
        case("nan_transform", d / "nan.usda", (r"nan\.usda", r"nan|non-finite", r"\b1050\b"),
             existing=True),
        case("robot_missing_value", MAYA, (r"missing_value\.toml", r"track", r"max_jerk",
             r"missing"), "--robot", d / "missing_value.toml"),
        case("robot_out_of_range", MAYA, (r"out_of_range\.toml", r"elbow"),
             "--robot", d / "out_of_range.toml", existing=True),
        case("output_under_a_file", MAYA, (r"plain_file",), output=d / "plain_file" / "out.mcap"),
        case("bad_placement", MAYA, (r"placement",), "--placement", "1,2", existing=True),
        case("summary_under_a_file", MAYA, (r"plain_file|s\.json",),
             "--summary", d / "plain_file" / "s.json"),
    ]
    return dict(cases)


# --------------------------------------------------------------------------------------------
# The runs
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CliRuns:
    base: Path
    procs: dict[str, subprocess.CompletedProcess[str]]
    bad: dict[str, Bad]
    check_dirs: dict[str, Path]
    shots_before: list[str]


CHECKS = {
    "check_ok": (MAYA, ()),
    "check_ok_json": (MAYA, ("--json",)),
    "check_whip": (WHIP, ()),
    "check_whip_json": (WHIP, ("--json",)),
    "check_unreachable": (UNREACHABLE, ()),
    "check_unreachable_json": (UNREACHABLE, ("--json",)),
}


@pytest.fixture(scope="module")
def cli(tmp_path_factory: pytest.TempPathFactory) -> CliRuns:
    base = tmp_path_factory.mktemp("cli")
    shots_before = sorted(p.name for p in SHOTS.iterdir())
    jobs: dict[str, list[object]] = {
        # placement changes where the robot must reach, so whether it keeps real time is
        # not this test's subject: scale timing always succeeds for a reachable shot
        "placed": ["convert", MAYA, "-o", base / "placed.mcap", "--placement", "1,0,0,0",
                   "--summary", base / "placed.summary.json", "--timing", "scale", "-q"],
        "placed_yaw": ["convert", MAYA, "-o", base / "placed_yaw.mcap", "--placement",
                       ",".join(str(v) for v in PLACEMENT_YAW), "--timing", "scale", "-q"],
    }
    jobs["convert_whip"] = ["convert", WHIP, "-o", base / "whip.mcap", "-q"]
    cwds: dict[str, Path] = {}
    for key, (shot, extra) in CHECKS.items():
        cwds[key] = base / key
        cwds[key].mkdir()
        jobs[key] = ["check", shot, *extra]
    bad_dir = base / "bad"
    bad_dir.mkdir()
    bad = _write_bad_inputs(bad_dir)
    for key, b in bad.items():
        jobs[f"bad:{key}"] = b.args
    for path in command_paths():
        jobs["help:" + " ".join(path)] = [*path, "--help"]
    procs = run_all(jobs, cwds)
    return CliRuns(base, procs, bad, cwds, shots_before)


# --------------------------------------------------------------------------------------------
# check
# --------------------------------------------------------------------------------------------


def _assert_wrote_nothing(cli: CliRuns, key: str) -> None:
    assert list(cli.check_dirs[key].iterdir()) == []
    assert sorted(p.name for p in SHOTS.iterdir()) == cli.shots_before


def test_check_feasible_shot_reports_and_exits_0(cli: CliRuns) -> None:
    proc = cli.procs["check_ok"]
    assert proc.returncode == 0, proc.stderr
    assert "ERROR" not in proc.stderr
    out = proc.stdout
    assert "1001-1120" in out and "/shotCam" in out
    assert re.search(r"maximum feasible speed \d+%", out), out
    for name in JOINT_NAMES:
        assert re.search(rf"^\s+{name}\b", out, re.MULTILINE), name
    _assert_wrote_nothing(cli, "check_ok")


def test_check_json_feasible_shot_has_the_numbers(cli: CliRuns) -> None:
    proc = cli.procs["check_ok_json"]
    assert proc.returncode == 0, proc.stderr
    rep: dict[str, Any] = json.loads(proc.stdout)
    cam = usd_camera(MAYA)
    assert rep["status"] == "ok"
    assert rep["output"] is None
    assert rep["camera"] == cam.prim_path
    assert rep["frames"] == {"first": 1001, "last": 1120, "count": 120}
    assert rep["fps"] == cam.fps
    assert rep["timing"] == "shot" and rep["speed_factor"] == 1.0
    assert rep["max_speed"] >= 1.0  # feasible as shot
    assert rep["feasible_fps"] == pytest.approx(cam.fps * rep["max_speed"], rel=1e-9)
    assert set(rep["peak_use"]) == set(JOINT_NAMES)
    for name, use in rep["peak_use"].items():
        for quantity in ("position", "velocity", "acceleration", "jerk"):
            assert isinstance(use[quantity], float), (name, quantity)
            assert 0.0 <= use[quantity] <= 1.0 + 1e-9, (name, quantity, use[quantity])
    # a settled push-in needs no run-up or run-out: the take may be the shot alone
    assert rep["duration"] >= rep["shot_end"] - rep["shot_start"] >= 119 / 24 - 1e-9
    _assert_wrote_nothing(cli, "check_ok_json")


def test_check_whip_pan_reports_limits_and_exits_3(cli: CliRuns) -> None:
    proc = cli.procs["check_whip"]
    assert proc.returncode == 3, proc.stderr
    out = proc.stdout
    assert re.search(r"\bpan (velocity|acceleration|jerk)\b", out), out
    assert re.search(r"\d+% of real time", out) and re.search(r"\d+(\.\d+)? fps", out), out
    _assert_wrote_nothing(cli, "check_whip")

    rep: dict[str, Any] = json.loads(cli.procs["check_whip_json"].stdout)
    assert cli.procs["check_whip_json"].returncode == 3
    assert rep["status"] == "limits"
    assert 0.0 < rep["max_speed"] < 1.0
    assert rep["feasible_fps"] == pytest.approx(24.0 * rep["max_speed"], rel=1e-9)
    assert "pan" in {v["axis"] for v in rep["violations"]}
    for v in rep["violations"]:
        assert v["ratio"] > 1.0 and v["limit"] > 0.0 and abs(v["peak"]) > v["limit"]
    _assert_wrote_nothing(cli, "check_whip_json")

    # the text gives each axis one line, its worst excess (JSON's first of that axis) and
    # the names of its others; JSON keeps every violation
    lines = [ln.strip() for ln in out.splitlines() if " exceeds " in ln]
    by_axis: dict[str, list[dict[str, Any]]] = {}
    for v in rep["violations"]:
        by_axis.setdefault(v["axis"], []).append(v)
    assert len(rep["violations"]) > len(by_axis) == len(lines), out
    for line, (axis, vs) in zip(lines, by_axis.items(), strict=True):
        assert line.startswith(vs[0]["text"]), (line, vs[0]["text"])
        assert line.startswith(f"{axis} "), line
        for other in vs[1:]:
            assert other["quantity"] in line.removeprefix(vs[0]["text"]), line


def test_check_and_convert_give_the_speed_that_fits_alike(cli: CliRuns) -> None:
    """check's advice and convert's say the speed the scale take runs at alike ("the move
    fits at 25% speed (6.07 fps)": one rounding, down to 0.01 fps); check's maximum feasible
    speed stays the real-time measure of every report (the servo grid can slow the scale take
    by a hair more: a jog at 14.71 fps whose scale take runs at 14.70)."""
    rep: dict[str, Any] = json.loads(cli.procs["check_whip_json"].stdout)
    factor = rep["scale_factor"]  # scale's slow-down: the whip's peak use, ends included
    assert factor >= 1.0 / rep["max_speed"] * (1 - 1e-9)
    shown = f"{math.floor(24.0 / factor * 100) / 100:.2f}"
    assert shown == "6.07"
    said = f"the move fits at {math.floor(100 / factor)}% speed ({shown} fps)"
    check_line = cli.procs["check_whip"].stdout.splitlines()[-1]
    assert check_line.endswith(f"; try --timing scale: {said}"), check_line
    measure = f"{math.floor(rep['feasible_fps'] * 100) / 100:.2f}"
    assert f"could be shot at {measure} fps" in check_line, check_line
    convert = cli.procs["convert_whip"]
    assert convert.returncode == 3
    assert f"{said} - try --timing scale" in convert.stderr, convert.stderr


def test_check_unreachable_names_frames_and_misses_and_exits_3(
    cli: CliRuns, robot: Robot
) -> None:
    proc = cli.procs["check_unreachable"]
    assert proc.returncode == 3, proc.stderr
    assert "29-46" in proc.stdout, proc.stdout
    # where to go next: the last line names the command that places the track
    assert proc.stdout.splitlines()[-1] == (f"  note: camtraj place {UNREACHABLE} looks for a "
                                            "track placement that reaches every frame")
    _assert_wrote_nothing(cli, "check_unreachable")

    json_proc = cli.procs["check_unreachable_json"]
    assert json_proc.returncode == 3, json_proc.stderr
    rep: dict[str, Any] = json.loads(json_proc.stdout)
    assert rep["status"] == "unreachable"
    misses = {u["frame"]: u for u in rep["unreachable"]}
    assert sorted(misses) == list(range(29, 47))
    cam = usd_camera(UNREACHABLE)
    frames = list(cam.frames)
    # Independently: the frames just outside the reported run are reachable, the reported
    # ones miss by exactly the distance to the workspace.
    for f in (28, 47):
        assert workspace_miss(robot, cam.poses[frames.index(f), :3, 3]) <= 1e-6, f
    for f in (29, 30, 46):
        u = misses[f]
        assert u["miss_unit"] == "m"
        expected = workspace_miss(robot, cam.poses[frames.index(f), :3, 3])
        assert u["miss"] == pytest.approx(expected, abs=1e-4), f
    assert all(u["miss"] > 0 for u in misses.values())
    _assert_wrote_nothing(cli, "check_unreachable_json")


def test_unreachable_advice_keeps_the_set_file_and_names_base_coordinates(
    tmp_path: Path, robot: Robot
) -> None:
    """The note's place command carries what the check was given (the set file's floor,
    region and obstacles bind place too), and each miss says which frame its coordinates
    are in: the camera mount's position from the robot base, not the stage's."""
    set_file = tmp_path / "set.toml"
    set_file.write_text("[placement]\nx = 1.0\ny = 0.5\nz = 0.0\nyaw_deg = 0.0\n")
    proc = run_cli("check", UNREACHABLE, "--set-file", set_file, "--frames", "29:31",
                   "--json")
    assert proc.returncode == 3, proc.stderr
    rep = json.loads(proc.stdout)
    assert rep["advice"] == (f"camtraj place {UNREACHABLE} --set-file {set_file} "
                             f"--frames 29:31")
    cam = usd_camera(UNREACHABLE)
    frame = list(cam.frames).index(30)
    mount = cam.poses[frame] @ np.linalg.inv(robot.camera2flange)  # stage, Z-up metres
    x, y, z = mount[:3, 3] - (1.0, 0.5, 0.0)
    (miss,) = [u for u in rep["unreachable"] if u["frame"] == 30]
    assert f"camera mount at ({x:.3f}, {y:.3f}, {z:.3f}) m in robot base coordinates" \
        in miss["reason"], miss["reason"]


# --------------------------------------------------------------------------------------------
# info, help, --summary, --placement
# --------------------------------------------------------------------------------------------


def test_info_lists_topics_and_frame_range(cli: CliRuns) -> None:
    assert cli.procs["placed"].returncode == 0, cli.procs["placed"].stderr
    mcap = cli.base / "placed.mcap"
    proc = run_cli("info", mcap)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    take = read_take(mcap)
    counts = {"/joint_states": take.t.size, "/shot/frames": 120, "/joint_trajectory": 1,
              "/robot_description": 1, "/tf_static": 1, "/tf": take.tf_times.size,
              "/camera/camera_info": 120}
    for topic, type_name in TOPICS.items():
        hits = [ln for ln in lines if re.search(rf"(^|\s){re.escape(topic)}\s", ln)]
        assert len(hits) == 1, (topic, proc.stdout)
        assert type_name in hits[0], hits[0]
        assert re.search(rf"\b{counts[topic]} messages", hits[0]), hits[0]
    assert "1001-1120" in proc.stdout
    assert re.search(r"\b120 frames\b", proc.stdout)


def test_info_says_what_the_shot_used(cli: CliRuns) -> None:
    """Under "limits used": the shot's peak use per axis (as convert reported it)."""
    assert cli.procs["placed"].returncode == 0, cli.procs["placed"].stderr
    proc = run_cli("info", cli.base / "placed.mcap")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("limits used"))
    rows = lines[head + 2 : head + 2 + len(JOINT_NAMES)]
    summary = json.loads((cli.base / "placed.summary.json").read_text())
    take = read_take(cli.base / "placed.mcap")
    robot = Robot.default()
    shot = (take.t >= take.frame_times[0] - 1e-9) & (take.t <= take.frame_times[-1] + 1e-9)
    for i, (name, row) in enumerate(zip(JOINT_NAMES, rows, strict=True)):
        assert row.split()[0] == name
        percents = [int(p.rstrip("%")) for p in row.split()[1:5]]
        use = summary["peak_use"][name]
        want = [round(100 * use[k]) for k in ("position", "velocity", "acceleration", "jerk")]
        assert percents == want, row
        # Independently: the velocity use from the written samples and the robot's limit.
        peak_v = np.abs(take.qd[shot, i]).max() / robot.max_velocity[i]
        assert percents[1] == pytest.approx(100 * peak_v, abs=1.0), row
    assert "robot limits" in proc.stdout


@pytest.mark.parametrize(
    "path", [" ".join(p) for p in command_paths()],
    ids=[" ".join(["camtraj", *p]) for p in command_paths()],
)
def test_help_of_every_command(cli: CliRuns, path: str) -> None:
    proc = cli.procs[f"help:{path}"]
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("Usage:"), proc.stdout[:200]
    assert path in proc.stdout.splitlines()[0]


def test_summary_json_matches_the_shot(cli: CliRuns) -> None:
    assert cli.procs["placed"].returncode == 0, cli.procs["placed"].stderr
    summary = json.loads((cli.base / "placed.summary.json").read_text())
    cam = usd_camera(MAYA)
    assert summary["frames"] == {"first": int(cam.frames[0]), "last": int(cam.frames[-1]),
                                 "count": int(cam.frames.size)}
    assert summary["fps"] == cam.fps
    assert summary["camera"] == cam.prim_path
    assert summary["output"] == str(cli.base / "placed.mcap")
    np.testing.assert_allclose(summary["placement"]["translation_m"], [1.0, 0.0, 0.0], atol=0)


def test_placement_shifts_the_targets_and_the_solution(cli: CliRuns, robot: Robot) -> None:
    """--placement 1,0,0,0 stands the robot 1 m down the track: targets move by -1 m in x."""
    assert cli.procs["placed"].returncode == 0, cli.procs["placed"].stderr
    take = read_take(cli.base / "placed.mcap")
    expected = usd_camera(MAYA).poses.copy()
    expected[:, 0, 3] -= 1.0
    dp, dr = pose_error(take.target, expected)
    assert dp <= 1e-9 and dr <= 1e-9, (dp, dr)
    dp, dr = pose_error(robot.camera_pose(take.frame_q), expected)
    assert dp <= 1e-6 and dr <= 1e-6, (dp, dr)
    placement = json.loads(take.metadata["placement"])
    np.testing.assert_allclose(placement["translation_m"], [1.0, 0.0, 0.0], atol=0)


def test_placement_with_yaw_is_the_robot_base_pose_in_the_stage(
    cli: CliRuns, robot: Robot
) -> None:
    proc = cli.procs["placed_yaw"]
    assert proc.returncode == 0, proc.stderr
    take = read_take(cli.base / "placed_yaw.mcap")
    x, y, z, yaw = PLACEMENT_YAW
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    base2world = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]])
    expected = np.linalg.inv(base2world) @ usd_camera(MAYA).poses
    dp, dr = pose_error(take.target, expected)
    assert dp <= 1e-9 and dr <= 1e-9, (dp, dr)
    dp, dr = pose_error(robot.camera_pose(take.frame_q), expected)
    assert dp <= 1e-6 and dr <= 1e-6, (dp, dr)
    placement = json.loads(take.metadata["placement"])
    assert placement["yaw_deg"] == pytest.approx(yaw, abs=1e-9)


# --------------------------------------------------------------------------------------------
# Bad input: exit 2, one clear line, nothing written
# --------------------------------------------------------------------------------------------

BAD_KEYS = [
    "missing_file", "text_renamed_usd", "truncated_usdc", "no_camera", "two_cameras",
    "nan_transform", "robot_missing_value", "robot_out_of_range", "output_under_a_file",
    "bad_placement", "summary_under_a_file",
]


@pytest.mark.parametrize("key", BAD_KEYS)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(cli: CliRuns, key: str) -> None:
    bad = cli.bad[key]
    proc = cli.procs[f"bad:{key}"]
    assert proc.returncode == 2, proc.stderr
    line = error_line(proc)
    for pattern in bad.must_match:
        assert re.search(pattern, line, re.IGNORECASE), (pattern, line)
    assert proc.stdout == ""
    if bad.existing:
        assert bad.output.read_bytes() == SENTINEL
    else:
        assert not bad.output.exists()
    folder = bad.output.parent
    if folder.is_dir():
        assert leftovers(folder) == []
    if key == "output_under_a_file":
        assert folder.read_text() == "not a folder\n"


@pytest.mark.parametrize(("shot", "timing", "word"), [
    (SHOTS / "blender_crane_up.usda", "optimal", "faster"),  # optimal shortens it
    (WHIP, "scale", "slower"),  # too fast as shot: scale slows it down
])
def test_check_verdict_says_faster_or_slower_as_the_take_is(shot: Path, timing: str,
                                                            word: str) -> None:
    # the verdict said "0.276x slower than the shot" for a take shot 3.6x faster
    text = run_cli("check", shot, "--timing", timing, "-q")
    js = run_cli("check", shot, "--timing", timing, "--json")
    assert text.returncode == js.returncode == 0, text.stderr + js.stderr
    factor = json.loads(js.stdout)["speed_factor"]  # shot's duration in the take / its own
    assert (factor < 1.0) == (word == "faster"), factor
    ratio = 1.0 / factor if factor < 1.0 else factor
    verdict = text.stdout.strip().splitlines()[-1]
    assert f"{timing} timing, {ratio:.3f}x {word} than the shot" in verdict, verdict
    assert ("slower" if word == "faster" else "faster") not in verdict, verdict


def test_the_top_level_help_names_every_command() -> None:
    # `report` and the scene form of `place` were missing from the summary
    proc = run_cli("--help")
    assert proc.returncode == 0, proc.stderr
    summary = proc.stdout.split("Options:")[0]
    for name in cli_main.list_commands(click.Context(cli_main)):
        assert re.search(rf"^\s+camtraj (\w+ / )*{name}\b", summary, re.MULTILINE), name
    assert re.search(r"camtraj place \S+\.usd \S+\.usd", summary), summary


def test_an_output_named_for_another_format_is_warned(tmp_path: Path) -> None:
    """`--report x.pdf` and `report -o x.pdf` write HTML: said, as for a non-.mcap `-o`."""
    mcap, page = tmp_path / "whip.mcap", tmp_path / "whip.pdf"
    conv = run_cli("convert", WHIP, "--timing", "scale", "-o", mcap, "--report", page)
    assert conv.returncode == 0, conv.stderr
    assert (f"--report {page} does not end in .html; it will be an HTML page all the same"
            in conv.stderr), conv.stderr
    again = run_cli("report", mcap, "-o", tmp_path / "again.pdf")
    assert again.returncode == 0, again.stderr
    assert "does not end in .html" in again.stderr
    assert page.read_text(encoding="utf-8").lstrip().lower().startswith("<!doctype html")


def test_a_failing_file_is_named_not_taken_for_standard_output(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
        tmp_path: Path) -> None:
    """An OSError about a named file that escapes a command (a file of the installation gone,
    say) is one line naming that file, exit 1, not "cannot write to standard output"."""
    import errno

    import camtraj.mcap_io

    gone = tmp_path / "camtraj" / "data" / "ShotFrame.msg"

    def describe(path: str) -> dict[str, Any]:
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", str(gone))

    monkeypatch.setattr(camtraj.mcap_io, "describe", describe)
    take = tmp_path / "take.mcap"
    take.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(SystemExit) as stop:
        cli_main.main(["info", str(take)], prog_name="camtraj")
    assert stop.value.code == 1
    err = capsys.readouterr().err
    assert err == f"ERROR: cannot use {gone}: no such file or directory\n"


def test_one_frame_alone_is_a_frame_not_frames() -> None:
    """'on frame 1001', not 'on frames 1001' (trial 13); runs keep the plural."""
    from camtraj.shown import frame_runs

    assert frame_runs([(1001, 1001)]) == "frame 1001"
    assert frame_runs([(12, 19), (40, 40)]) == "frames 12-19, 40"
    assert frame_runs([(-3, -1)]) == "frames -3 to -1"
    # many stretches on one ERROR line (a handheld shake over its jerk limit: 35 of them,
    # 1,166 characters): the first five, the last two and how many; every one elsewhere
    eight = [(10 * i, 10 * i + 2) for i in range(8)]
    every = "frames " + ", ".join(f"{a}-{b}" for a, b in eight)
    assert frame_runs(eight, 8) == frame_runs(eight) == every
    nine = [*eight, (90, 90)]
    assert frame_runs(nine, 8) == "frames 0-2, 10-12, 20-22, 30-32, 40-42, ..., 70-72, 90 " \
                                  "(9 stretches)"
    assert frame_runs(nine) == every + ", 90"


def test_a_failure_says_what_reading_the_shot_warned_of(tmp_path: Path) -> None:
    """A camera animated in a centimetre layer under a metre stage is read 100x too far (USD
    converts no units across a sublayer): every command that then fails (unreachable, no
    placement) says the reader's warning naming that layer with its error, where it used to
    say it only on success (a new user got "out of reach by 596 m" and advice to run place)."""
    anim = Usd.Stage.CreateNew(str(tmp_path / "anim_cm.usda"))
    UsdGeom.SetStageMetersPerUnit(anim, 0.01)
    UsdGeom.SetStageUpAxis(anim, UsdGeom.Tokens.z)
    cam = UsdGeom.Camera.Define(anim, "/cam")
    cam.CreateFocalLengthAttr(35.0)
    op = cam.AddTranslateOp()
    for f in range(1, 13):
        op.Set(Gf.Vec3d(500.0 + 10.0 * f, 0.0, 140.0), f)  # cm: 5 m ahead, 1.4 m up
    anim.GetRootLayer().Save()
    stage = _metre_stage(tmp_path / "shot_m.usda", 12, 24.0)
    stage.GetRootLayer().subLayerPaths.append("anim_cm.usda")
    stage.GetRootLayer().Save()
    shot = tmp_path / "shot_m.usda"
    said = "anim_cm.usda, written with metersPerUnit 0.01 (the stage's: 1)"
    procs = run_all({
        "convert": ["convert", shot, "-o", tmp_path / "x.mcap"],
        "check": ["check", shot],
        "json": ["check", shot, "--json"],
        "place": ["place", shot, "-o", tmp_path / "placed.toml"],
        "batch": ["batch", shot, "-o", tmp_path / "batch"],
    })
    for key, proc in procs.items():
        assert proc.returncode == 3, (key, proc.stderr)
    assert "cannot be reached" in procs["convert"].stderr
    assert re.search(r"^warning: .*" + re.escape(said), procs["convert"].stderr, re.M)
    assert re.search(r"^  warning: .*" + re.escape(said), procs["check"].stdout, re.M)
    assert any(said in w for w in json.loads(procs["json"].stdout)["warnings"])
    assert re.search(r"^warning: .*" + re.escape(said), procs["place"].stderr, re.M)
    assert re.search(re.escape(said), procs["batch"].stderr)
    report = json.loads((tmp_path / "batch" / "batch_report.json").read_text())
    assert any(said in w for w in report["shots"][0]["warnings"])
    # and what the reader logs as it reads (a metersPerUnit left to USD's centimetres: a
    # stage written in millimetres puts the camera 140 m up, where no placement reaches)
    far = Usd.Stage.CreateNew(str(tmp_path / "no_unit.usda"))
    UsdGeom.SetStageUpAxis(far, UsdGeom.Tokens.z)
    far.SetStartTimeCode(1)
    far.SetEndTimeCode(12)
    move = UsdGeom.Camera.Define(far, "/cam").AddTranslateOp()
    for f in range(1, 13):
        move.Set(Gf.Vec3d(500.0 + 10.0 * f, 0.0, 14000.0), f)
    far.GetRootLayer().Save()
    assert "metersPerUnit" not in (tmp_path / "no_unit.usda").read_text()
    logged = "metersPerUnit is not authored; using USD's fallback 0.01 (centimetres)"
    procs = run_all({cmd: [cmd, tmp_path / "no_unit.usda", *more] for cmd, more in (
        ("check", ()), ("convert", ("-o", tmp_path / "y.mcap")),
        ("place", ("-o", tmp_path / "placed2.toml")))})
    for key, proc in procs.items():
        assert proc.returncode == 3 and logged in proc.stderr, (key, proc.stderr)
    assert not (tmp_path / "x.mcap").exists() and not (tmp_path / "placed.toml").exists()


def _metre_stage(path: Path, last: int, fps: float) -> Any:
    """A new Z-up metre stage of frames 1..``last`` at ``fps``."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(last)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    return stage


def _truck_stage(path: Path, ease: Any) -> Path:
    """A Z-up metre stage: the camera trucks 3 m along x over 60 frames at 30 fps, eased by
    ``ease`` (0..1 -> 0..1), looking across the track."""
    stage = _metre_stage(path, 60, 30.0)
    cam = UsdGeom.Camera.Define(stage, "/cam")
    cam.CreateFocalLengthAttr(35.0)
    move = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(Gf.Vec3f(80.0, 0.0, 0.0))  # looking along -y, tilted down 10 deg
    for f in range(1, 61):
        move.Set(Gf.Vec3d(3.0 + 3.0 * float(ease((f - 1) / 59.0)), 1.5, 1.5), f)
    stage.GetRootLayer().Save()
    return path


def test_a_camera_that_stops_hard_is_said_to_swing_around_its_end_frames(
        tmp_path: Path) -> None:
    """Still ends keep the robot still on a frame where the camera is at rest, but a cubic
    ease is still accelerating there: the run-up must build that acceleration and carries the
    robot past the frame and back. check says so next to how far the camera moves (a new
    user read the swing without the reason); a quintic ease settles, with neither."""
    procs = run_all({
        "cubic": ["check", _truck_stage(tmp_path / "cubic.usda",
                                        lambda u: 3 * u ** 2 - 2 * u ** 3)],
        "quintic": ["check", _truck_stage(tmp_path / "quintic.usda",
                                          lambda u: u ** 3 * (10 - 15 * u + 6 * u ** 2))],
    })
    for proc in procs.values():
        assert proc.returncode == 0, proc.stderr
    note = "the camera stops hard on frame 1 and frame 60: still there but accelerating"
    # the README's example: about 20 cm and 7 deg around frame 1 (22.2 cm, 7.5 deg here)
    moved = re.search(r"the camera moves ([0-9.]+) cm and turns ([0-9.]+) deg before the "
                      r"first frame", procs["cubic"].stdout)
    assert moved and 15.0 <= float(moved[1]) <= 30.0 and 5.0 <= float(moved[2]) <= 10.0
    assert note in procs["cubic"].stdout
    assert note not in procs["quintic"].stdout
    assert ("the camera moves 0.0 mm before the first frame, 0.0 mm after the last"
            in procs["quintic"].stdout)


def test_info_says_where_the_take_ends_as_the_next_take_starts_from_it(tmp_path: Path) -> None:
    """Trial 21: chaining takes meant decoding /joint_states by hand (radians) to type the
    next take's --start-from (degrees). info prints both ends as --start-from takes them; the
    next take, started from the end, begins exactly where this one ends."""
    crane, push = tmp_path / "crane.mcap", tmp_path / "push.mcap"
    assert run_cli("convert", SHOTS / "blender_crane_up.usda", "-o", crane).returncode == 0
    info = run_cli("info", crane)
    assert info.returncode == 0, info.stderr
    ends = re.findall(r"^(starts at|ends at) +--start-from (\S+)$", info.stdout, re.MULTILINE)
    assert [label for label, _ in ends] == ["starts at", "ends at"], info.stdout
    last = read_take(crane).q[-1, :8]
    given = start_from_values(ends[1][1])  # degrees for radians: to an ulp or two
    assert np.allclose(given, last, rtol=0.0, atol=1e-14), given - last
    proc = run_cli("convert", MAYA, "-o", push, "--start-from", ends[1][1])
    assert proc.returncode == 0, proc.stderr
    assert np.array_equal(read_take(push).q[0, :8], given)
    data = json.loads(run_cli("info", crane, "--json").stdout)
    assert [data["end_joints"][n] for n in JOINT_NAMES] == last.tolist()


def start_from_values(text: str) -> np.ndarray:
    """--start-from's text (m for track/extend, deg for the rest) -> [m, rad], by hand."""
    from camtraj.robot import REVOLUTE

    return np.array([math.radians(float(v)) if REVOLUTE[i] else float(v)
                     for i, v in enumerate(text.split(","))])


def test_every_command_words_a_missing_or_folder_input_its_own_way(tmp_path: Path) -> None:
    """A missing robot, lens or set file, or a folder given as a shot, an MCAP file or an
    output, is camtraj's one line naming the file and what it is, in every command (click's
    own checks said "Invalid value for '--robot': File ... does not exist" for some options
    and commands, camtraj's wording for the rest)."""
    missing = tmp_path / "gone.toml"
    runs = run_all({
        "robot": ("convert", MAYA, "-o", tmp_path / "a.mcap", "--robot", missing),
        "lens": ("check", MAYA, "--lens", tmp_path),
        "set": ("place", MAYA, "--set-file", missing),
        "shot": ("batch", tmp_path, "-o", tmp_path / "b"),
        "farm": ("farm", "export", missing.with_suffix(".usda"), "-o", tmp_path / "j.json",
                 "--format", "openjd"),
        "mcap": ("info", tmp_path),
        "output": ("convert", MAYA, "-o", tmp_path),
    })
    expected = {
        "robot": ("robot file", "gone.toml"), "lens": ("lens file is a folder",),
        "set": ("set file", "gone.toml"), "shot": (str(tmp_path),),
        "farm": ("gone.usda", "no such"), "mcap": ("the MCAP file is a folder",),
        "output": ("cannot write -o", "it is a folder"),
    }
    for key, proc in runs.items():
        assert proc.returncode == 2, (key, proc.stderr)
        line = error_line(proc)
        assert "Invalid value" not in line and all(w in line for w in expected[key]), (key, line)
