"""camtraj batch: parallel conversion, report, exit codes, up-to-date skipping."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from camtraj.batch import REPORT_NAME, output_names, run_batch
from camtraj.errors import InputError
from camtraj.options import build_options, options_to_args
from camtraj.scene_file import SceneShot

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples" / "shots"
FEASIBLE = ("maya_dolly_push_in", "blender_crane_up", "orbit_animated_parent")
FAILING = ("whip_pan", "unreachable")  # infeasible under the default --timing shot


def _camtraj() -> list[str]:
    if (ROOT / "camtraj" / "__main__.py").is_file():
        return [sys.executable, "-m", "camtraj"]
    return [str(Path(sys.executable).parent / "camtraj")]


def _run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*_camtraj(), *args], cwd=cwd, capture_output=True, text=True, check=False
    )


def _sample_args() -> list[str]:
    return [str(SAMPLES / f"{name}.usda") for name in (*FEASIBLE, *FAILING)]


@pytest.fixture(scope="module")
def batch_run(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """`camtraj batch` over every sample, once."""
    out = tmp_path_factory.mktemp("batch") / "out"
    proc = _run("batch", *_sample_args(), "-o", str(out), "--jobs", "2")
    return out, proc


def test_report_lists_every_shot_with_its_status(
    batch_run: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    out, proc = batch_run
    report = json.loads((out / REPORT_NAME).read_text())
    status = {Path(s["shot"]).stem: s["status"] for s in report["shots"]}
    assert status == {**dict.fromkeys(FEASIBLE, "ok"), **dict.fromkeys(FAILING, "failed")}
    for entry in report["shots"]:
        if entry["status"] == "failed":
            assert entry["exit_code"] == 3
            assert entry["reason"]
            assert not Path(entry["output"]).exists()
            assert not Path(entry["summary_path"]).exists()
        else:
            assert entry["frames"] is not None
            assert entry["max_speed"] is not None
            summary = json.loads(Path(entry["summary_path"]).read_text())
            assert summary["status"]
    assert report["counts"] == {"ok": 3, "failed": 2, "skipped": 0}
    # A shot over its limits still says how fast it can go (as check does); an unreachable
    # one has no speed.
    speeds = {Path(s["shot"]).stem: s["max_speed"] for s in report["shots"]}
    assert speeds["unreachable"] is None
    check = subprocess.run([*_camtraj(), "check", str(SAMPLES / "whip_pan.usda"), "--json"],
                           capture_output=True, text=True, check=False)
    assert speeds["whip_pan"] == pytest.approx(json.loads(check.stdout)["max_speed"], rel=1e-9)
    row = next(line for line in proc.stdout.splitlines() if line.startswith("whip_pan.usda"))
    assert f" {math.floor(100 * speeds['whip_pan'])}% " in row, row
    # The table on stdout names every shot and status.
    for name in (*FEASIBLE, *FAILING):
        assert f"{name}.usda" in proc.stdout
    assert "failed:" in proc.stdout
    # Every failure is an infeasible shot: exit code 3 (non-zero because unreachable fails).
    assert proc.returncode == 3, proc.stderr
    assert report["exit_code"] == 3


def test_outputs_are_byte_identical_to_single_converts(
    batch_run: tuple[Path, subprocess.CompletedProcess[str]], tmp_path: Path
) -> None:
    out, _ = batch_run
    procs = {
        name: subprocess.Popen(
            [
                *_camtraj(),
                "convert",
                str(SAMPLES / f"{name}.usda"),
                "-o",
                str(tmp_path / f"{name}.mcap"),
                "--quiet",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        for name in (FEASIBLE[0], FEASIBLE[2])
    }
    for name, proc in procs.items():
        _, err = proc.communicate()
        assert proc.returncode == 0, err
        single = (tmp_path / f"{name}.mcap").read_bytes()
        assert single == (out / f"{name}.mcap").read_bytes(), name


def test_rerun_skips_up_to_date_shots_and_retries_failures(
    batch_run: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    out, _ = batch_run
    before = {n: (out / f"{n}.mcap").stat().st_mtime_ns for n in FEASIBLE}
    shots = [str(SAMPLES / f"{name}.usda") for name in (*FEASIBLE, "unreachable")]
    options = build_options(
        camera=None, robot=None, placement=None, frames=None, rate=250.0, timing="shot"
    )
    assert run_batch(shots, out, jobs=2, options=options).exit_code == 3
    report = json.loads((out / REPORT_NAME).read_text())
    status = {Path(s["shot"]).stem: s["status"] for s in report["shots"]}
    assert status == {**dict.fromkeys(FEASIBLE, "skipped"), "unreachable": "failed"}
    assert {n: (out / f"{n}.mcap").stat().st_mtime_ns for n in FEASIBLE} == before
    skipped = next(s for s in report["shots"] if s["status"] == "skipped")
    assert skipped["frames"] is not None  # read back from the summary


def test_touched_shot_robot_file_and_force_reconvert(tmp_path: Path) -> None:
    shots = tmp_path / "shots"
    shots.mkdir()
    shot = shots / "dolly.usda"
    shutil.copy2(SAMPLES / "maya_dolly_push_in.usda", shot)
    robot = tmp_path / "robot.toml"
    shutil.copy2(ROOT / "camtraj" / "data" / "robot.toml", robot)
    options = build_options(
        camera=None, robot=str(robot), placement=None, frames="1001:1012", rate=250.0, timing="shot"
    )
    out = tmp_path / "out"

    def statuses(**kwargs: bool) -> list[str]:
        report = run_batch([str(shot)], out, jobs=1, options=options, **kwargs)
        assert report.exit_code == 0, report.table()
        return [r.status for r in report.results]

    assert statuses() == ["ok"]
    assert statuses() == ["skipped"]
    assert statuses(force=True) == ["ok"]
    faster = dataclasses.replace(options, rate=500.0)
    report = run_batch([str(shot)], out, jobs=1, options=faster)
    assert [r.status for r in report.results] == ["ok"]  # other options: not up to date
    # the speed as convert and check say it: % of real time, rounded down
    speed = report.results[0].summary["max_speed"]
    row = report.table().splitlines()[1]
    assert f"  {math.floor(100 * speed)}%  " in row and "x " not in row, row
    assert statuses() == ["ok"]  # and back
    mcap = out / "dolly.mcap"
    for path in (shot, robot):
        now = time.time_ns()
        for p, age in ((shot, 100), (robot, 100), (mcap, 50), (out / "dolly.summary.json", 50)):
            os.utime(p, ns=(now - age * 10**9, now - age * 10**9))
        assert statuses() == ["skipped"]
        path.touch()  # now newer than the outputs
        assert statuses() == ["ok"], path


def test_the_same_robot_file_spelled_another_way_is_the_same_option(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``robot.toml``, ``./robot.toml`` and its absolute path name one file: a re-run that
    spells it differently skips the shots that are up to date (a new user's batch converted
    every shot again). Another file is another option, even with the same content."""
    shot = tmp_path / "dolly.usda"
    shutil.copy2(SAMPLES / "maya_dolly_push_in.usda", shot)
    for name in ("robot.toml", "copy.toml"):
        shutil.copy2(ROOT / "camtraj" / "data" / "robot.toml", tmp_path / name)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"

    def status(robot: str) -> str:
        options = build_options(camera=None, robot=robot, placement=None, frames="1001:1012",
                                rate=250.0, timing="shot")
        report = run_batch([str(shot)], out, jobs=1, options=options)
        assert report.exit_code == 0, report.table()
        return report.results[0].status

    assert status("robot.toml") == "ok"
    assert status("./robot.toml") == "skipped"
    assert status(str(tmp_path / "robot.toml")) == "skipped"
    assert status("copy.toml") == "ok"
    recorded = json.loads((out / "dolly.summary.json").read_text())["convert_options"]
    assert recorded["robot"] == os.path.realpath(tmp_path / "copy.toml")


def test_a_shot_that_fails_now_keeps_its_earlier_take_and_says_so(tmp_path: Path) -> None:
    """A shot converted once, then re-exported as a move the robot cannot reach: the batch
    fails it and removes nothing (its earlier MCAP and summary stay byte for byte), and says
    that the MCAP there is an earlier run's: in the report and on stderr."""
    shots = tmp_path / "shots"
    shots.mkdir()
    shot = shots / "sh010.usda"
    shutil.copy2(SAMPLES / "blender_crane_up.usda", shot)
    out = tmp_path / "out"
    assert _run("batch", str(shot), "-o", str(out), "--jobs", "1").returncode == 0
    earlier = {p.name: p.read_bytes() for p in out.iterdir() if p.name != REPORT_NAME}
    assert sorted(earlier) == ["sh010.mcap", "sh010.summary.json"]
    shutil.copy2(SAMPLES / "unreachable.usda", shot)  # the re-export
    shot.touch()
    proc = _run("batch", str(shot), "-o", str(out), "--jobs", "1")
    assert proc.returncode == 3, proc.stderr
    assert {n: (out / n).read_bytes() for n in earlier} == earlier
    (entry,) = json.loads((out / REPORT_NAME).read_text())["shots"]
    assert entry["status"] == "failed" and entry["earlier_output"] == str(out / "sh010.mcap")
    assert f"note: {out / 'sh010.mcap'} is from an earlier run, not this version of " \
           "sh010.usda" in proc.stderr


def test_bad_input_shot_makes_exit_code_2_and_the_rest_still_convert(tmp_path: Path) -> None:
    bad = tmp_path / "garbage.usda"
    bad.write_text("this is not USD\n")
    good = tmp_path / "good.usda"
    shutil.copy2(SAMPLES / "orbit_animated_parent.usda", good)
    options = build_options(
        camera=None, robot=None, placement=None, frames=None, rate=250.0, timing="shot"
    )
    report = run_batch(
        [str(bad), str(good), str(SAMPLES / "unreachable.usda")],
        tmp_path / "o",
        jobs=2,
        options=options,
    )
    by_name = {Path(r.shot).stem: r for r in report.results}
    assert by_name["good"].status == "ok"
    assert by_name["garbage"].status == "failed"
    assert by_name["garbage"].exit_code == 2
    assert by_name["unreachable"].exit_code == 3
    assert report.exit_code == 2
    assert (tmp_path / "o" / "good.mcap").is_file()
    # each shot's reason is its own message without its name: the batch's ERROR line and
    # table name the shot once (the reader's message starts with the path)
    reason = by_name["garbage"].reason
    assert reason and not reason.startswith(f"{bad}:"), reason


def test_duplicate_stems_are_refused_before_starting(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    copy = tmp_path / "a" / "whip_pan.usda"
    shutil.copy2(SAMPLES / "whip_pan.usda", copy)
    out = tmp_path / "out"
    proc = _run("batch", str(SAMPLES / "whip_pan.usda"), str(copy), "-o", str(out))
    assert proc.returncode == 2
    assert "whip_pan.mcap" in proc.stderr
    assert not out.exists()


@pytest.mark.parametrize("option", ["--lens", "--robot", "--set-file"])
def test_a_bad_shared_file_is_one_error_before_any_shot_runs(tmp_path: Path,
                                                              option: str) -> None:
    """A lens, robot or set file every shot reads, broken: one error line naming it, exit 2,
    nothing written (it failed the same way on every shot, one worker each)."""
    bad = tmp_path / "bad.toml"
    bad.write_text("speed = [\n")
    out = tmp_path / "out"
    proc = _run("batch", *_sample_args()[:2], "-o", str(out), option, str(bad))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    kind = option.lstrip("-").split("-")[0]
    assert len(lines) == 1 and lines[0].startswith(f"ERROR: {kind} file {bad}: not valid TOML"), \
        proc.stderr
    assert not out.exists()


def test_a_shots_warnings_are_said_only_when_it_converts(tmp_path: Path) -> None:
    """As convert: a converted shot's warnings go to stderr, a shot that fails on its input
    says only its ERROR line (a shot with no camera also printed its missing-metersPerUnit
    warning; one that cannot be done as asked says them: test_cli)."""
    text = (SAMPLES / "maya_dolly_push_in.usda").read_text()
    assert "metersPerUnit = 0.01" in text
    unit_less = text.replace("metersPerUnit = 0.01", "")  # USD's fallback: centimetres too
    (tmp_path / "converts.usda").write_text(unit_less)
    no_camera = unit_less.split("def Camera")[0]  # the header alone
    assert "Camera" not in no_camera
    (tmp_path / "no_camera.usda").write_text(no_camera)
    shots = [str(tmp_path / "converts.usda"), str(tmp_path / "no_camera.usda")]
    proc = _run("batch", *shots, "-o", str(tmp_path / "out"), "--jobs", "2", "-q")
    assert proc.returncode == 2, proc.stderr
    said = [line for line in proc.stderr.splitlines() if "metersPerUnit" in line]
    assert said == [f"{shots[0]}: metersPerUnit is not authored; using USD's fallback 0.01 "
                    "(centimetres)"], proc.stderr
    # the report keeps what stderr said: the reader's logged warning too
    report = json.loads((tmp_path / "out" / REPORT_NAME).read_text())
    assert report["shots"][0]["warnings"] == said and report["shots"][1]["warnings"] == []
    assert f"ERROR: {shots[1]}: no camera" in proc.stderr


def test_a_converted_shots_run_warnings_are_said_and_reported(tmp_path: Path) -> None:
    """A shot that converts with warnings of its own run (not only its reader's: a focal
    length in millimetres where USD wants tenths of a scene unit reads as 3500 mm) says them
    on stderr, naming the shot, and lists them in batch_report.json, as its summary does
    (the batch said nothing and its report had no warnings)."""
    from pxr import Usd, UsdGeom

    from camtraj.robot import Robot
    from tests.shots import base_move, write_shot

    shot = write_shot(tmp_path / "mm_lens.usda", base_move(Robot.default()))
    stage = Usd.Stage.Open(str(shot))
    UsdGeom.Camera(stage.GetPrimAtPath("/World/cam")).GetFocalLengthAttr().Set(35.0)
    stage.GetRootLayer().Save()
    proc = _run("batch", str(shot), "-o", str(tmp_path / "out"), "-q")
    assert proc.returncode == 0, proc.stderr
    said = [line for line in proc.stderr.splitlines() if "focalLength" in line]
    assert len(said) == 1 and said[0].startswith(f"{shot}: camera /World/cam focalLength 35 "
                                                 "reads as 3500 mm"), proc.stderr
    report = json.loads((tmp_path / "out" / REPORT_NAME).read_text())
    (entry,) = report["shots"]
    summary = json.loads((tmp_path / "out" / "mm_lens.summary.json").read_text())
    assert len(summary["warnings"]) == 1
    assert entry["warnings"] == [f"{shot}: {summary['warnings'][0]}"] == said


def test_workers_start_from_a_folder_holding_a_camtraj_folder(tmp_path: Path) -> None:
    """Run where a folder named camtraj sits (a clone of this repository, an output folder):
    the workers import the installed package, not that folder (every worker failed, and the
    batch said it was stopped by SIGINT). The installed command, as a user runs it."""
    command = Path(sys.executable).parent / "camtraj"
    assert command.is_file(), "the camtraj command is not installed in this environment"
    (tmp_path / "camtraj").mkdir()
    shot = SAMPLES / "blender_crane_up.usda"
    proc = subprocess.run([str(command), "batch", str(shot), "-o", "out", "--jobs", "2"],
                          cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out" / "blender_crane_up.mcap").stat().st_size > 0
    # a floor strip round one placement that does the move, yaw fixed: few to solve
    (tmp_path / "strip.toml").write_text(
        "[floor]\nregion = [[-4.1, 0.4, 0], [20.6, 0.4, 0], [20.6, 1.6, 0], [-4.1, 1.6, 0]]\n"
        "[search]\nyaw_deg = 0.0\n")
    proc = subprocess.run([str(command), "place", str(shot), "-o", "placed.toml", "--jobs", "2",
                           "--frames", "1:6", "--set-file", "strip.toml"],
                          cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "placed.toml").is_file()


def test_malformed_options_are_input_errors() -> None:
    with pytest.raises(InputError, match="placement"):
        build_options(
            camera=None, robot=None, placement="1,2", frames=None, rate=1.0, timing="shot"
        )
    with pytest.raises(InputError, match="frames"):
        build_options(
            camera=None, robot=None, placement=None, frames="9:3", rate=1.0, timing="shot"
        )
    options = build_options(
        camera="/World/cam",
        robot=None,
        placement="-1,2,0,90",
        frames="1:5",
        rate=100.0,
        timing="scale",
    )
    assert options_to_args(options) == [
        "--camera", "/World/cam", "--placement", "-1.0,2.0,0.0,90.0",
        "--frames", "1:5", "--rate", "100.0", "--timing", "scale",
    ]  # fmt: skip
    with pytest.raises(InputError, match="start-from"):
        build_options(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                      timing="shot", start_from="1,2,3")  # fmt: skip
    more = build_options(
        camera=None, robot=None, placement=None, frames=None, rate=250.0, timing="shot",
        start_from="1,90,0,0,-90,0,0,0", objective="paper",
    )  # fmt: skip
    assert more.start_from is not None
    assert more.start_from[1] == pytest.approx(math.pi / 2)
    assert options_to_args(more)[-4:] == [
        "--start-from", "1.0,90.0,0.0,0.0,-90.0,0.0,0.0,0.0", "--objective", "paper",
    ]  # fmt: skip


def test_a_start_pose_is_passed_on_as_given_and_to_the_bit() -> None:
    """A job or batch entry repeats --start-from as the user wrote it (30, not
    29.999999999999996), and reading that text back gives the same radians to the bit."""
    from camtraj.options import build_options as build

    def passed(text: str) -> str:
        options = build(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                        timing="shot", start_from=text)
        return options_to_args(options)[-1]

    assert passed("0.5,30,-45,12.25,0.1,270,-89.999,1e-7") == \
        "0.5,30.0,-45.0,12.25,0.1,270.0,-89.999,1e-07"
    rng = random.Random(7)
    for _ in range(300):
        text = ",".join(repr(rng.uniform(-300.0, 300.0)) for _ in range(8))
        first = build(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                      timing="shot", start_from=text).start_from
        again = build(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                      timing="shot", start_from=passed(text)).start_from
        assert again == first


def test_usd_flag_writes_rig_layers_and_counts_them_in_up_to_date(tmp_path: Path) -> None:
    from pxr import Usd, UsdGeom

    out = tmp_path / "out"
    shots = [str(SAMPLES / f"{name}.usda") for name in (*FEASIBLE[:2], "unreachable")]
    proc = _run("batch", *shots, "-o", str(out), "--jobs", "2", "--usd", "--quiet")
    assert proc.returncode == 3, proc.stderr
    for name in FEASIBLE[:2]:
        stage = Usd.Stage.Open(str(out / f"{name}.rig.usda"))
        assert [p.GetName() for p in stage.Traverse() if p.IsA(UsdGeom.Camera)] == [
            "camtraj_camera"
        ]
    assert not (out / "unreachable.rig.usda").exists()
    options = build_options(
        camera=None, robot=None, placement=None, frames=None, rate=250.0, timing="shot"
    )
    (out / f"{FEASIBLE[0]}.rig.usda").unlink()
    report = run_batch(shots[:2], out, jobs=1, options=options, rig_layers=True)
    assert [r.status for r in report.results] == ["ok", "skipped"]
    assert (out / f"{FEASIBLE[0]}.rig.usda").is_file()


def test_a_sublayer_edit_or_another_shot_of_the_same_name_is_not_up_to_date(
        tmp_path: Path) -> None:
    """A take is up to date with every file its run reads, the USD layers of the shot
    included (an edited animation sublayer was skipped), and with the shot it was made from:
    a shot of the same name from another folder, older than the take, is converted, not
    skipped with the other shot's take (a new user's pipeline)."""
    from pxr import Gf, Usd, UsdGeom

    def animation(path: Path, x0: float) -> None:
        anim = Usd.Stage.CreateNew(str(path))
        UsdGeom.SetStageMetersPerUnit(anim, 1.0)
        UsdGeom.SetStageUpAxis(anim, UsdGeom.Tokens.z)
        cam = UsdGeom.Camera.Define(anim, "/cam")
        cam.CreateFocalLengthAttr(3.5)
        move = cam.AddTranslateOp()
        cam.AddRotateXYZOp().Set(Gf.Vec3f(80.0, 0.0, 0.0))
        for f in range(1, 13):
            move.Set(Gf.Vec3d(x0 + 0.02 * f, 2.0, 1.4), f)
        anim.GetRootLayer().Save()

    for folder, x0 in (("a", 3.0), ("b", 5.0)):
        (tmp_path / folder).mkdir()
        animation(tmp_path / folder / "anim.usda", x0)
        stage = Usd.Stage.CreateNew(str(tmp_path / folder / "shot.usda"))
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        stage.SetStartTimeCode(1)
        stage.SetEndTimeCode(12)
        stage.GetRootLayer().subLayerPaths.append("anim.usda")
        stage.GetRootLayer().Save()
    options = build_options(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                            timing="shot")
    out = tmp_path / "out"

    def status(shot: Path) -> str:
        report = run_batch([str(shot)], out, jobs=1, options=options)
        assert report.exit_code == 0, report.table()
        return report.results[0].status

    shot = tmp_path / "a" / "shot.usda"
    assert status(shot) == "ok"
    assert status(shot) == "skipped"
    past = time.time_ns() - 100 * 10**9
    os.utime(shot, ns=(past, past))
    animation(tmp_path / "a" / "anim.usda", 4.0)  # the sublayer only, now newer than the take
    assert status(shot) == "ok"
    other = tmp_path / "b" / "shot.usda"
    for path in (other, tmp_path / "b" / "anim.usda"):
        os.utime(path, ns=(past, past))
    assert status(other) == "ok"
    summary = json.loads((out / "shot.summary.json").read_text())
    assert summary["shot"] == str(other)


def test_a_batch_stopped_before_its_report_leaves_no_folder_it_made(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A batch stopped (SIGTERM, Ctrl-C) before it writes its report removes the output
    folders it made, where still empty (a new user's `-o out/sig/sub` stayed behind empty);
    a folder that was there stays."""
    import camtraj.batch as batch

    def stopped(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(batch, "_run_shots", stopped)
    options = build_options(camera=None, robot=None, placement=None, frames=None, rate=250.0,
                            timing="shot")
    (tmp_path / "kept").mkdir()
    shot = str(SAMPLES / "maya_dolly_push_in.usda")
    for out in (tmp_path / "kept" / "new" / "sub", tmp_path / "kept"):
        with pytest.raises(KeyboardInterrupt):
            run_batch([shot], out, jobs=1, options=options)
    assert [p.name for p in tmp_path.iterdir()] == ["kept"]
    assert list((tmp_path / "kept").iterdir()) == []


def test_the_table_lines_up_with_wide_characters_in_a_shot_name() -> None:
    """A shot named in Japanese takes two terminal columns per character: the table's next
    column starts in the same terminal column on every row (it was two to the left)."""
    import unicodedata

    from camtraj.batch import BatchReport, ShotResult

    def columns(text: str) -> int:
        return sum(2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text)

    results = tuple(ShotResult(name, "x.mcap", "x.json", status="ok", seconds=1.0,
                               summary={"frames": {"first": 1, "last": 24}, "max_speed": 2.0})
                    for name in ("plano grúa ñ 日本 B.usda", "a_longer_plain_name_b.usda"))
    table = BatchReport("out", 1, 1, 2.0, results, {}).table()
    rows = table.splitlines()[1:3]
    starts = [columns(row[:row.index("1-24")]) for row in rows]
    assert starts[0] == starts[1], table


def test_a_damaged_summary_in_the_output_folder_is_as_good_as_none(tmp_path: Path) -> None:
    """Trial 22: a summary nested thousands deep, or with "warnings": 5, crashed batch
    (exit 1, no report) where a garbage one was converted again."""
    from camtraj.batch import _read_summary

    summary = tmp_path / "dolly.summary.json"
    for text in ("[" * 100_000 + "]" * 100_000, '{"warnings": 5}', "garbage", "[1, 2]"):
        summary.write_text(text, encoding="utf-8")
        assert _read_summary(summary) == {}, text
    summary.write_text('{"warnings": ["w"], "max_speed": 2.0}', encoding="utf-8")
    assert _read_summary(summary) == {"warnings": ["w"], "max_speed": 2.0}


def test_a_report_path_batch_cannot_write_is_refused_before_any_shot(tmp_path: Path) -> None:
    """Trial 22: batch_report.json a folder (or a pipe): every shot was converted, then the
    run failed to write its report. The report is checked with the other outputs, first."""
    out = tmp_path / "out"
    (out / "batch_report.json").mkdir(parents=True)
    proc = _run("batch", str(SAMPLES / "maya_dolly_push_in.usda"), "-o", str(out), "-q")
    assert proc.returncode == 2, proc.stderr
    assert "batch_report.json: it is a folder" in proc.stderr, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["batch_report.json"]


def test_a_failed_shot_keeps_converts_notes(tmp_path: Path) -> None:
    """What convert says with its error (here: the camera holds every other frame, a move
    on twos, so the robot stops dead at each) reaches batch's stderr and report (trial 23:
    the report had the error alone)."""
    import numpy as np

    from camtraj.robot import Robot
    from tests.shots import write_shot
    from tests.test_shot import _out_and_back

    robot = Robot.default()
    shot = write_shot(tmp_path / "twos.usda", _out_and_back(robot, 48, twos=True))
    alone = _run("convert", str(shot), "-o", str(tmp_path / "alone.mcap"), "-q")
    assert alone.returncode == 3
    (note,) = [line for line in alone.stderr.splitlines() if line.startswith("note: ")]
    assert "a move animated on twos?" in note and "bake it on ones" in note
    out = tmp_path / "out"
    proc = _run("batch", str(shot), "-o", str(out), "--jobs", "1")
    assert proc.returncode == 3
    (entry,) = json.loads((out / REPORT_NAME).read_text())["shots"]
    assert entry["notes"] == [f"{shot}: {note}"]
    assert f"{shot}: {note}" in proc.stderr.splitlines()
    assert np.isfinite(entry["max_speed"])


def test_a_scene_converts_each_shot_with_its_own_camera_frames_and_timing(
        tmp_path: Path) -> None:
    """`batch --scene` (trial 21 retyped every shot's camera and frames): each shot of the
    scene file is converted with its own options, byte for byte what `convert` writes with
    them; two spans of one stage file get outputs named by their frames; a second run finds
    every shot up to date; a scene with shots or per-shot options on the command line is a
    usage error."""
    for name in ("maya_dolly_push_in", "blender_crane_up"):
        shutil.copy2(SAMPLES / f"{name}.usda", tmp_path / f"{name}.usda")
    scene = tmp_path / "sc.toml"
    scene.write_text('name = "sc1"\n'
                     '[[shot]]\npath = "maya_dolly_push_in.usda"\nframes = [1001, 1060]\n'
                     '[[shot]]\npath = "maya_dolly_push_in.usda"\nframes = [1061, 1120]\n'
                     'timing = "scale"\n'
                     '[[shot]]\npath = "blender_crane_up.usda"\ncamera = "/root/Camera"\n',
                     encoding="utf-8")
    out = tmp_path / "out"
    proc = _run("batch", "--scene", str(scene), "-o", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / REPORT_NAME).read_text())
    got = [(Path(s["output"]).name, s["camera"], s["frame_range"], s["timing"], s["status"])
           for s in report["shots"]]
    assert got == [("maya_dolly_push_in_1001-1060.mcap", None, [1001, 1060], "shot", "ok"),
                   ("maya_dolly_push_in_1061-1120.mcap", None, [1061, 1120], "scale", "ok"),
                   ("blender_crane_up_root_Camera.mcap", "/root/Camera", None, "shot", "ok")]
    assert "blender_crane_up.usda /root/Camera" in proc.stdout
    singles = {
        "maya_dolly_push_in_1001-1060": ("maya_dolly_push_in", "--frames", "1001:1060"),
        "maya_dolly_push_in_1061-1120": ("maya_dolly_push_in", "--frames", "1061:1120",
                                         "--timing", "scale"),
        "blender_crane_up_root_Camera": ("blender_crane_up", "--camera", "/root/Camera"),
    }
    for stem, (name, *args) in singles.items():
        shot = tmp_path / f"{name}.usda"
        single = _run("convert", str(shot), "-o", str(tmp_path / f"{stem}.mcap"), "-q", *args)
        assert single.returncode == 0, single.stderr
        assert (tmp_path / f"{stem}.mcap").read_bytes() == (out / f"{stem}.mcap").read_bytes()
    again = _run("batch", "--scene", str(scene), "-o", str(out))
    assert again.returncode == 0 and "0 converted, 3 up to date" in again.stdout
    both = _run("batch", "--scene", str(scene), str(tmp_path / "blender_crane_up.usda"),
                "-o", str(out))
    framed = _run("batch", "--scene", str(scene), "--frames", "1:3", "-o", str(out))
    assert both.returncode == framed.returncode == 2
    assert "one of them" in both.stderr and "per shot in the scene file" in framed.stderr
    # two cameras of one name under different parents get their own outputs; a shot listed
    # twice (here through a link) and a camera that is no prim path are one error line
    twice = tmp_path / "twice.toml"
    (tmp_path / "link.usda").symlink_to(tmp_path / "blender_crane_up.usda")
    for text, words in (
            ('[[shot]]\npath = "blender_crane_up.usda"\n[[shot]]\npath = "link.usda"\n',
             "repeats shot 1"),
            ('[[shot]]\npath = "blender_crane_up.usda"\ncamera = "/root/ Cam"\n',
             "camera must be a prim path")):
        twice.write_text(text, encoding="utf-8")
        bad = _run("batch", "--scene", str(twice), "-o", str(tmp_path / "twice"))
        assert bad.returncode == 2 and words in bad.stderr, bad.stderr
        assert len(bad.stderr.strip().splitlines()) == 1
    names = output_names([SceneShot("a/sh.usda", "/World/sh010/cam"),
                          SceneShot("a/sh.usda", "/World/sh020/cam")], Path("out"))
    assert [m.name for m, _ in names] == ["sh_World_sh010_cam.mcap", "sh_World_sh020_cam.mcap"]
