"""A corpus of bad inputs (issue 8, acceptance): each run exits 2 or 3 with one line on stderr.

Every case is generated here (no committed binaries): broken and hostile USD files, stages
authored with pxr the way a broken exporter might write them, bad options, robot and set
files, and output paths that would destroy an input or cannot take a file. Each case runs
``camtraj convert`` (or ``check``) in a fresh process over an existing good result (a real
MCAP and summary from an earlier run) and must:

* exit 2 (bad input) or 3 (cannot be done as asked);
* print exactly one line on stderr, ``ERROR: ...``, and no traceback or warning;
* leave the earlier outputs byte-identical, create nothing at a new output path, leave no
  temporary file, and change no input.

The runs are many, so they are forked from a pre-imported server process: each case is a
new process running the real command line (``camtraj.__main__.run``) with its own stdout
and stderr files, exactly as the installed ``camtraj`` command; a sample of cases also runs
as ``python -m camtraj`` to show that both agree.
"""

from __future__ import annotations

import html
import json
import math
import os
import random
import re
import shutil
import stat
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from camtraj.robot import Robot
from tests.conftest import rot_z, run_forked, snapshot
from tests.test_convert import ROOT, SHOTS, run_cli

MAYA = SHOTS / "maya_dolly_push_in.usda"
ROBOT_TOML = ROOT / "camtraj" / "data" / "robot.toml"
MIN_CASES = 150

@dataclass
class Case:
    """One bad run.

    Attributes:
        args: The command line after ``camtraj``.
        must: Regular expressions the error line must match (case-insensitive).
        codes: The allowed exit codes.
        stdout: Where stdout goes (default a file in the case folder).
        fsize: A file size limit in bytes for the run (a disk that fills up).
        new_outputs: Output paths that did not exist and must still not exist.
    """

    args: list[str]
    must: tuple[str, ...] = ()
    codes: tuple[int, ...] = (2,)
    stdout: str | None = None
    fsize: int | None = None
    new_outputs: list[Path] = field(default_factory=list)


# --------------------------------------------------------------------------------------------
# Generating the inputs
# --------------------------------------------------------------------------------------------


def _stage(path: Path, *, start: float = 1, end: float = 24, fps: float | None = None,
           tcps: float | None = None, mpu: float | None = 1.0, up: str | None = "Z") -> Usd.Stage:
    stage = Usd.Stage.CreateNew(str(path))
    if mpu is not None:
        stage.SetMetadata("metersPerUnit", mpu)
    if up is not None:
        stage.SetMetadata("upAxis", up)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    if tcps is not None:
        stage.SetMetadata("timeCodesPerSecond", tcps)
    if fps is not None:
        stage.SetMetadata("framesPerSecond", fps)
    return stage


def _camera(stage: Usd.Stage, *, at: tuple[float, float, float] = (4.0, 0.0, 1.0),
            move: float = 0.5, parent: str = "/rig", path: str = "cam") -> UsdGeom.Camera:
    UsdGeom.Xform.Define(stage, parent)
    cam = UsdGeom.Camera.Define(stage, f"{parent}/{path}")
    translate = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(Gf.Vec3f(90.0, 0.0, -90.0))  # looks down +x, the track
    for f in (1, 24):
        translate.Set(Gf.Vec3d(at[0] + move * (f - 1) / 23, at[1], at[2]), f)
    return cam


def _write_usd_cases(d: Path) -> dict[str, tuple[Path, tuple[str, ...], tuple[int, ...]]]:
    """Shots authored with pxr: name -> (path, patterns, exit codes)."""
    out: dict[str, tuple[Path, tuple[str, ...], tuple[int, ...]]] = {}

    def save(name: str, stage: Usd.Stage, *must: str, codes: tuple[int, ...] = (2,)) -> None:
        stage.GetRootLayer().Save()
        out[name] = (Path(stage.GetRootLayer().realPath), must, codes)

    s = _stage(d / "no_camera.usda")
    UsdGeom.Xform.Define(s, "/World")
    save("no_camera", s, "no camera")
    s = _stage(d / "two_cameras.usda")
    _camera(s)
    _camera(s, path="cam2")
    save("two_cameras", s, r"2 cameras", "/rig/cam2")
    layer = Sdf.Layer.CreateNew(str(d / "not_animated.usda"))
    stage = Usd.Stage.Open(layer)
    stage.SetMetadata("metersPerUnit", 1.0)
    UsdGeom.Camera.Define(stage, "/cam")
    save("not_animated", stage, "no frame range")

    for name, value in (("nan", math.nan), ("inf", math.inf), ("far", 1.0e300),
                        ("beyond_1000km", 2.0e6)):
        s = _stage(d / f"translate_{name}.usda")
        cam = _camera(s)
        cam.GetOrderedXformOps()[0].Set(Gf.Vec3d(value, 0.0, 1.0), 12)
        save(f"translate_{name}", s, r"frame \d+")
    for name, scale in (("mirrored", (-1.0, 1.0, 1.0)), ("zero", (0.0, 0.0, 0.0)),
                        ("tiny_1e-300", (1e-300, 1e-300, 1e-300)),
                        ("flat", (1.0, 1.0, 0.0))):
        s = _stage(d / f"scale_{name}.usda")
        _camera(s)
        UsdGeom.Xform(s.GetPrimAtPath("/rig")).AddScaleOp().Set(Gf.Vec3d(*scale))
        save(f"parent_scale_{name}", s, r"frame \d+")
    s = _stage(d / "projective.usda")
    _camera(s)
    m = Gf.Matrix4d(1.0)
    m.SetColumn(3, Gf.Vec4d(0.1, 0.0, 0.0, 1.0))
    UsdGeom.Xform(s.GetPrimAtPath("/rig")).AddTransformOp().Set(m)
    save("projective", s, "projective")

    for name, kw, pattern in (
        ("start_after_end", {"start": 30, "end": 1}, "after endTimeCode"),
        ("range_1e300", {"end": 1e300}, "reads at most 100000"),
        ("range_2e6_frames", {"end": 2.0e6}, "reads at most 100000"),
        ("fps_1e12", {"fps": 1e12}, "framesPerSecond"),
        ("fps_1e308", {"fps": 1e308}, "framesPerSecond"),
        ("fps_1e12_tcps_24", {"fps": 1e12, "tcps": 24}, "reads at most 100000"),
        ("fps_zero", {"fps": 0.0}, "framesPerSecond"),
        ("fps_negative", {"fps": -24.0}, "framesPerSecond"),
        ("fps_nan", {"fps": math.nan}, "framesPerSecond"),
        ("tcps_zero", {"tcps": 0.0}, "timeCodesPerSecond"),
        ("tcps_inf", {"tcps": math.inf}, "timeCodesPerSecond"),
        ("mpu_zero", {"mpu": 0.0}, "metersPerUnit"),
        ("mpu_negative", {"mpu": -1.0}, "metersPerUnit"),
        ("mpu_nan", {"mpu": math.nan}, "metersPerUnit"),
        ("mpu_inf", {"mpu": math.inf}, "metersPerUnit"),
        ("up_axis_x", {"up": "X"}, "upAxis"),
        ("single_frame", {"start": 5, "end": 5}, "1 frame"),
    ):
        s = _stage(d / f"{name}.usda", **kw)  # type: ignore[arg-type]
        _camera(s)
        save(name, s, pattern)

    for name, value in (("focal_nan", math.nan), ("focal_inf", math.inf)):
        s = _stage(d / f"{name}.usda")
        cam = _camera(s)
        cam.GetFocalLengthAttr().Set(value, 10)
        save(name, s, "focalLength")

    s = _stage(d / "out_of_reach.usda")
    _camera(s, at=(40.0, 30.0, 1.0))
    save("out_of_reach", s, "cannot be reached", codes=(3,))
    return out


def _hostile_files(d: Path) -> dict[str, Path]:
    """Files that are not USD, or are USD damaged in transit."""
    rng = random.Random(8)
    files: dict[str, Path] = {}

    def put(name: str, data: bytes) -> None:
        path = d / name
        path.write_bytes(data)
        files[path.stem] = path

    for i in range(20):
        size = rng.choice((1, 17, 256, 4096, 20000))
        put(f"usda_header_then_random_{i}.usda", b"#usda 1.0\n" + rng.randbytes(size))
    for i in range(5):
        put(f"random_bytes_{i}.usd", rng.randbytes(rng.choice((3, 100, 5000))))
    text = MAYA.read_bytes()
    for i, frac in enumerate((0.02, 0.08, 0.15, 0.25, 0.33, 0.41, 0.5, 0.58, 0.66, 0.72, 0.8,
                              0.86, 0.9, 0.95, 0.98)):
        put(f"usda_truncated_{i}.usda", text[: int(len(text) * frac)])
    Sdf.Layer.FindOrOpen(str(MAYA)).Export(str(d / "full.usdc"))
    crate = (d / "full.usdc").read_bytes()
    for i, frac in enumerate((0.0005, 0.01, 0.1, 0.2, 0.4, 0.5, 0.6, 0.8, 0.9, 0.97)):
        put(f"usdc_truncated_{i}.usdc", crate[: max(9, int(len(crate) * frac))])
    put("empty.usda", b"")
    put("header_only.usda", b"#usda 1.0\n")
    put("notes.usd", b"shot notes: dolly in, then hold\n")
    put("zeros.usd", bytes(4096))
    put("crate_magic_junk.usdc", b"PXR-USDC" + rng.randbytes(500))
    put("zip_junk.usdz", b"PK\x03\x04" + rng.randbytes(500))
    put("utf16.usda", "#usda 1.0\ndef Camera \"cam\" {}\n".encode("utf-16"))
    return files


def _robot_and_set_files(d: Path) -> dict[str, tuple[Path, str]]:
    """name -> (file, pattern); robot files as --robot, set files as --set-file."""
    text = ROBOT_TOML.read_text(encoding="utf-8")
    files: dict[str, tuple[Path, str]] = {}

    def put(name: str, content: str, pattern: str) -> None:
        path = d / name
        path.write_text(content, encoding="utf-8")
        files[name] = (path, pattern)

    put("robot_bad_toml.toml", "[robot\nname = 1\n", "TOML")
    put("robot_missing_max_jerk.toml", text.replace("max_jerk = 15.0\n", "", 1), "max_jerk")
    put("robot_elbow_out_of_range.toml", text.replace("min = -180.0", "min = -270.0", 1),
        "elbow")
    put("set_bad_toml.toml", "[placement\n", "TOML")
    put("set_no_table.toml", "x = 1\n", r"unknown key\(s\) x")
    put("set_unknown_key.toml", "[placement]\nx = 1\nheight = 2\n", "unknown key")
    put("set_string_value.toml", '[placement]\nx = "one"\n', "finite number")
    put("set_not_a_rotation.toml", "[placement]\nrotation = [[2,0,0],[0,1,0],[0,0,1]]\n",
        "rotation")
    put("set_yaw_and_rotation.toml",
        "[placement]\nyaw_deg = 3\nrotation = [[1,0,0],[0,1,0],[0,0,1]]\n", "not both")
    return files


# --------------------------------------------------------------------------------------------
# The corpus
# --------------------------------------------------------------------------------------------


def _corpus(base: Path) -> tuple[dict[str, Case], Path]:
    inputs = base / "inputs"
    inputs.mkdir()
    cases: dict[str, Case] = {}
    good = inputs / "maya.usda"
    shutil.copy(MAYA, good)

    def add(name: str, args: Sequence[object], *must: str, **kw: object) -> None:
        assert name not in cases, name
        cases[name] = Case([str(a) if not isinstance(a, str) else a for a in args], must,
                           **kw)  # type: ignore[arg-type]

    def convert(name: str, shot: object, *extra: object, must: tuple[str, ...] = (),
                **kw: object) -> None:
        add(name, ["convert", shot, "-o", "out.mcap", "--summary", "out.summary.json",
                   *extra], *must, **kw)

    for name, path in _hostile_files(inputs).items():
        convert(name, path, must=(re.escape(path.name),))
    for name, (path, must, codes) in _write_usd_cases(inputs).items():
        named = (re.escape(path.name),) if codes == (2,) else ()  # exit 3 names frames instead
        convert(f"usd_{name}", path, must=(*named, *must), codes=codes)
    # outputs are checked before the solve: an unreachable shot (exit 3 after its IK) with
    # a bad output path gives the output's exit 2 instead
    add("o_under_a_file_checked_before_the_solve",
        ["convert", SHOTS / "unreachable.usda", "-o", inputs / "plain_file" / "x.mcap"],
        "is a file, not a folder")
    add("summary_device_checked_before_the_solve",
        ["convert", SHOTS / "unreachable.usda", "-o", "out.mcap", "--summary", "/dev/full"],
        "character device")
    add("o_empty", ["convert", good, "-o", ""], "-o: the file name is empty")
    add("summary_empty", ["convert", good, "-o", "out.mcap", "--summary", ""],
        "--summary: the file name is empty")
    convert("whip_pan_shot_timing", SHOTS / "whip_pan.usda", "--timing", "shot",
            must=("velocity|acceleration|jerk",), codes=(3,))
    convert("unreachable_sample", SHOTS / "unreachable.usda", must=("cannot be reached",),
            codes=(3,))

    # The shot path itself
    os.mkfifo(inputs / "pipe.usda")
    (inputs / "folder.usda").mkdir()
    os.symlink("loop_b.usda", inputs / "loop_a.usda")
    os.symlink("loop_a.usda", inputs / "loop_b.usda")
    bad_name = os.fsdecode(bytes(inputs) + b"/shot\xff\xfe.usda")
    shutil.copy(MAYA, bad_name)
    for name, shot, must in (
        ("shot_missing", inputs / "missing.usda", "no such file"),
        ("shot_fifo", inputs / "pipe.usda", "named pipe"),
        ("shot_folder", inputs / "folder.usda", "folder|directory"),
        ("shot_dev_null", "/dev/null", "character device"),
        ("shot_dev_zero", "/dev/zero", "character device"),
        ("shot_symlink_loop", inputs / "loop_a.usda", "loop_a"),
        ("shot_name_not_utf8", bad_name, "not valid UTF-8"),
        ("shot_name_not_utf8_missing", bad_name.replace("shot", "gone"), "gone"),
    ):
        convert(name, shot, must=(must,))

    # Options
    for name, extra, must in (
        ("frames_backwards", ("--frames", "1100:1010"), "before the first"),
        ("frames_outside", ("--frames", "1:5000"), "outside"),
        ("frames_words", ("--frames", "start:end"), "A:B"),
        ("frames_one_number", ("--frames", "1001"), "A:B"),
        ("frames_float", ("--frames", "1001.5:1010"), "A:B"),
        ("placement_two_numbers", ("--placement", "1,2"), "placement"),
        ("placement_words", ("--placement", "a,b,c,d"), "placement"),
        ("placement_nan", ("--placement", "nan,0,0,0"), "placement"),
        ("placement_inf", ("--placement", "inf,0,0,0"), "placement"),
        ("placement_far", ("--placement", "1e300,0,0,0"), "placement|reach|origin"),
        ("rate_zero", ("--rate", "0"), "rate"),
        ("rate_negative", ("--rate", "-250"), "rate"),
        ("rate_nan", ("--rate", "nan"), "rate"),
        ("rate_huge", ("--rate", "1e9"), "rate"),
        ("rate_word", ("--rate", "fast"), "rate"),
        ("timing_unknown", ("--timing", "fastest"), "timing"),
        ("objective_unknown", ("--objective", "best"), "objective"),
        ("start_from_three_values", ("--start-from", "1,2,3"), "start"),
        ("start_from_words", ("--start-from", "a,b,c,d,e,f,g,h"), "start"),
        ("camera_missing", ("--camera", "/nope"), "no camera at /nope"),
        ("camera_relative", ("--camera", "shotCam"), "absolute prim path"),
        ("camera_not_a_camera", ("--camera", "/World"), r"/World|no camera"),
        ("camera_empty", ("--camera", ""), "prim path|camera"),
        ("unknown_option", ("--fastest",), "no such option"),
    ):
        codes = (2, 3) if name == "placement_far" else (2,)
        convert(name, good, *extra, must=(must,), codes=codes)
    add("no_output", ["convert", good], "missing option")
    add("no_shot", ["convert", "-o", "out.mcap"], "missing argument")
    add("output_empty_name", ["convert", good, "-o", ""], r"-o|output")
    add("output_is_a_folder", ["convert", good, "-o", inputs], "directory|folder")

    # Robot and set files
    os.mkfifo(inputs / "pipe.toml")
    (inputs / "folder.toml").mkdir()
    for name, (path, must) in _robot_and_set_files(inputs).items():
        option = "--robot" if name.startswith("robot") else "--set-file"
        convert(name.removesuffix(".toml"), good, option, path, must=(re.escape(path.name), must))
    for option in ("--robot", "--set-file"):
        key = option.strip("-").replace("-", "_")
        for name, path, must in (
            ("missing", inputs / "missing.toml", "missing.toml"),
            ("fifo", inputs / "pipe.toml", "named pipe"),
            ("folder", inputs / "folder.toml", "folder|directory"),
            ("dev_null", "/dev/null", "character device"),
        ):
            convert(f"{key}_{name}", good, option, path, must=(must,))

    # Outputs that would destroy an input, or cannot take a file
    os.symlink(good, inputs / "link_to_shot.usda")
    os.link(good, inputs / "hard_link_to_shot.usda")
    (inputs / "sub").mkdir()
    (inputs / "plain_file").write_text("not a folder\n", encoding="utf-8")
    os.mkfifo(inputs / "pipe.mcap")
    layered = inputs / "layered.usda"
    (inputs / "set_dressing.usda").write_text('#usda 1.0\ndef Xform "set" {}\n', encoding="utf-8")
    layered.write_text(
        "#usda 1.0\n(\n    subLayers = [@./maya.usda@]\n)\n"
        'def "dressing" (references = @./set_dressing.usda@) {}\n', encoding="utf-8")
    robot_copy = inputs / "robot.toml"
    shutil.copy(ROBOT_TOML, robot_copy)
    set_file = inputs / "set.toml"
    set_file.write_text("[placement]\nx = 0.0\n", encoding="utf-8")
    outs = [
        ("o_is_the_shot", good, ["-o", good], "it is the shot"),
        ("o_is_a_symlink_to_the_shot", good, ["-o", inputs / "link_to_shot.usda"], "the shot"),
        ("o_reaches_the_shot_through_dotdot", good, ["-o", inputs / "sub" / ".." / "maya.usda"],
         "the shot"),
        ("o_is_a_hard_link_to_the_shot", good, ["-o", inputs / "hard_link_to_shot.usda"],
         "the shot"),
        ("o_is_the_robot_file", good, ["-o", robot_copy, "--robot", robot_copy],
         "the robot file"),
        ("o_is_the_set_file", good, ["-o", set_file, "--set-file", set_file], "the set file"),
        ("o_is_a_sublayer", layered, ["-o", good], "layer used by the shot"),
        ("o_is_a_referenced_layer", layered, ["-o", inputs / "set_dressing.usda"],
         "layer used by the shot"),
        ("summary_is_the_shot", good, ["-o", "new.mcap", "--summary", good], "the shot"),
        ("summary_is_a_sublayer", layered, ["-o", "new.mcap", "--summary", good],
         "layer used"),
        ("summary_is_the_output", good, ["-o", "out.mcap", "--summary", "out.mcap"],
         "same file"),
        ("summary_is_the_output_dotdot", good,
         ["-o", "out.mcap", "--summary", "../" + "{case}" + "/out.mcap"], "same file"),
        ("o_dev_null", good, ["-o", "/dev/null"], "character device"),
        ("o_dev_full", good, ["-o", "/dev/full"], "character device"),
        ("summary_dev_full", good, ["-o", "out.mcap", "--summary", "/dev/full"],
         "character device"),
        ("summary_dev_null", good, ["-o", "out.mcap", "--summary", "/dev/null"],
         "character device"),
        ("o_fifo", good, ["-o", inputs / "pipe.mcap"], "named pipe"),
        ("summary_fifo", good, ["-o", "out.mcap", "--summary", inputs / "pipe.mcap"],
         "named pipe"),
        ("o_under_a_file", good, ["-o", inputs / "plain_file" / "x.mcap"], "not a folder"),
        ("summary_under_a_file", good,
         ["-o", "out.mcap", "--summary", inputs / "plain_file" / "s.json"], "not a folder"),
        ("summary_in_proc", good, ["-o", "out.mcap", "--summary", "/proc/s.json"], "/proc"),
        ("o_in_proc", good, ["-o", "/proc/x.mcap"], "/proc"),
        ("o_in_sys", good, ["-o", "/sys/x.mcap"], "/sys"),
    ]
    for name, shot, extra, must in outs:
        add(name, ["convert", shot, *extra], must)
    cases["summary_is_the_output_dotdot"].args = [
        a.replace("{case}", "summary_is_the_output_dotdot") for a in
        cases["summary_is_the_output_dotdot"].args]
    cases["summary_is_the_shot"].new_outputs = [Path("new.mcap")]
    cases["summary_is_a_sublayer"].new_outputs = [Path("new.mcap")]

    # A disk that fills up while writing; a standard output that cannot be written
    convert("disk_full_while_writing", good, must=("cannot write", "too large"), fsize=65536)
    add("check_stdout_full", ["check", good], "standard output", stdout="/dev/full")
    add("check_json_stdout_full", ["check", good, "--json"], "standard output",
        stdout="/dev/full")
    add("info_stdout_full", ["info", "{good_mcap}"], "standard output", stdout="/dev/full")
    add("info_of_a_usda", ["info", good], "maya.usda")
    add("info_of_a_fifo", ["info", inputs / "pipe.mcap"], "named pipe")
    return cases, inputs


# --------------------------------------------------------------------------------------------
# Running it
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Result:
    case: Case
    folder: Path
    rc: int
    stdout: str
    stderr: str
    before: dict[str, bytes]


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Result]:
    base = tmp_path_factory.mktemp("corpus")
    cases, inputs = _corpus(base)
    # an earlier, good result sits at the outputs of every case
    good_dir = base / "good"
    good_dir.mkdir()
    proc = run_cli("convert", inputs / "maya.usda", "-o", good_dir / "out.mcap", "--summary",
                   good_dir / "out.summary.json", "-q")
    assert proc.returncode == 0, proc.stderr
    good = {p.name: p.read_bytes() for p in good_dir.iterdir()}
    jobs: list[dict[str, object]] = []
    folders: dict[str, Path] = {}
    for name, case in cases.items():
        folder = base / name
        folder.mkdir()
        for file_name, data in good.items():
            (folder / file_name).write_bytes(data)
        case.args = [a.replace("{good_mcap}", str(folder / "out.mcap")) for a in case.args]
        folders[name] = folder
        jobs.append({"id": name, "cwd": str(folder), "args": case.args,
                     "stdout": case.stdout or str(base / f"{name}.stdout"),
                     "stderr": str(base / f"{name}.stderr"), "fsize": case.fsize})
    before_inputs = snapshot(inputs)
    devices = {d: os.stat(d) for d in ("/dev/null", "/dev/full")}
    codes = run_forked(jobs, timeout=1800)
    assert snapshot(inputs) == before_inputs, "an input changed"
    for device, st in devices.items():  # never replaced by a regular file (we may be root)
        now = os.stat(device)
        assert stat.S_ISCHR(now.st_mode) and now.st_rdev == st.st_rdev, device
    results = {}
    for name, case in cases.items():
        out_path = Path(case.stdout) if case.stdout else base / f"{name}.stdout"
        stdout = out_path.read_text() if case.stdout is None else ""
        stderr = (base / f"{name}.stderr").read_text(errors="backslashreplace")
        results[name] = Result(case, folders[name], codes[name], stdout, stderr, good)
    return results


def _problems(name: str, r: Result) -> list[str]:
    """What is wrong with one case's run (empty when it behaved)."""
    problems = []
    if r.rc not in r.case.codes:
        problems.append(f"exit code {r.rc}, expected {r.case.codes}")
    lines = r.stderr.splitlines()
    # a shot that cannot be done as asked (exit 3) also says what reading it warned of
    said = [ln for ln in lines[1:] if not (r.rc == 3 and ln.startswith("warning: "))]
    if not lines or not lines[0].startswith("ERROR: ") or said:
        problems.append(f"stderr is not one ERROR line: {r.stderr!r}")
    if "Traceback" in r.stderr or "Warning" in r.stderr:
        problems.append("a traceback or warning on stderr")
    line = lines[0] if lines else ""
    problems += [f"{pattern!r} not in the error line" for pattern in r.case.must
                 if not re.search(pattern, line, re.IGNORECASE)]
    if r.stdout:
        problems.append(f"printed on stdout: {r.stdout[:200]!r}")
    after = {p.name: p.read_bytes() for p in r.folder.iterdir() if p.is_file()}
    if after != r.before:
        problems.append("the earlier result changed")
    names = sorted(p.name for p in r.folder.iterdir())
    if names != sorted(r.before):
        problems.append(f"the output folder holds {names}")
    problems += [f"{new} was created" for new in r.case.new_outputs if (r.folder / new).exists()]
    return [f"{name}: {p} [{line}]" for p in problems]


def test_the_corpus_is_large_enough(corpus: dict[str, Result]) -> None:
    assert len(corpus) >= MIN_CASES, len(corpus)


def test_every_bad_input_is_one_line_and_changes_nothing(corpus: dict[str, Result]) -> None:
    problems = [p for name, r in corpus.items() for p in _problems(name, r)]
    assert not problems, f"{len(problems)} problem(s):\n" + "\n".join(problems)


def test_the_forked_runs_match_real_processes(corpus: dict[str, Result], tmp_path: Path) -> None:
    """A sample of cases as ``python -m camtraj``: same exit code, same error line."""
    sample = ["usda_header_then_random_3", "usd_range_1e300", "o_is_the_shot",
              "summary_dev_full", "shot_fifo", "rate_nan", "usd_out_of_reach"]
    for name in sample:
        r = corpus[name]
        folder = tmp_path / name
        shutil.copytree(r.folder, folder)
        proc = run_cli(*r.case.args, cwd=folder)
        assert (proc.returncode, proc.stderr) == (r.rc, r.stderr), name


# --------------------------------------------------------------------------------------------
# A still camera is a valid shot (its speed is unbounded)
# --------------------------------------------------------------------------------------------


def _still_shot(path: Path, drift_m: float) -> Path:
    """A camera that holds its pose (drifting ``drift_m`` in all) while the lens zooms."""
    stage = _stage(path)
    cam = _camera(stage, move=drift_m)
    cam.GetFocalLengthAttr().Set(0.5, 1)  # tenths of a metre: 50 mm, then 35 mm
    cam.GetFocalLengthAttr().Set(0.35, 24)
    stage.GetRootLayer().Save()
    return path


def test_still_camera_converts_and_reports_unbounded_speed(tmp_path: Path) -> None:
    shot = _still_shot(tmp_path / "still.usda", 0.0)
    out, summary = tmp_path / "still.mcap", tmp_path / "still.json"
    proc = run_cli("convert", shot, "-o", out, "--summary", summary)
    assert proc.returncode == 0, proc.stderr
    assert "maximum feasible speed unbounded (the camera pose never changes)" in proc.stdout
    data = json.loads(summary.read_text(), parse_constant=_no_constant)
    assert data["max_speed"] is None and data["feasible_fps"] is None
    assert out.stat().st_size > 0
    check = run_cli("check", shot, "--json")
    assert check.returncode == 0, check.stderr
    data = json.loads(check.stdout, parse_constant=_no_constant)  # strict: no Infinity/NaN
    assert data["max_speed"] is None


def test_nearly_still_camera_caps_the_speed_shown(tmp_path: Path) -> None:
    """A camera drifting 0.1 mm in a second moves (4 um a frame): the speed shown is capped.
    One drifting a nanometre holds (within 1 um of the hold's first frame): unbounded."""
    shot = _still_shot(tmp_path / "nearly.usda", 1e-4)
    proc = run_cli("check", shot)
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stdout.splitlines() if "maximum feasible speed" in x)
    assert ">10000% of real time" in line, line
    assert max(int(n) for n in re.findall(r"\d+", line)) <= 10000 * 24, line
    page = tmp_path / "nearly.html"  # the report says what the terminal says
    proc = run_cli("convert", shot, "-o", tmp_path / "nearly.mcap", "--report", page)
    assert proc.returncode == 0, proc.stderr
    said = html.escape(line.split("maximum feasible speed ")[1], quote=False)
    assert said in page.read_text(encoding="utf-8")
    jitter = run_cli("check", _still_shot(tmp_path / "jitter.usda", 1e-9))
    assert "maximum feasible speed unbounded (the camera pose never changes)" in jitter.stdout


@pytest.mark.parametrize("frames", [2, 3, 4])
def test_the_shortest_moves_convert(tmp_path: Path, frames: int) -> None:
    """Two to four frames of a moving camera convert (three frames once crashed the solver's
    spline operators: three points leave no third difference)."""
    stage = _stage(tmp_path / f"short{frames}.usda", end=frames)
    _camera(stage, move=0.01 * (frames - 1))
    stage.GetRootLayer().Save()
    out, summary = tmp_path / f"short{frames}.mcap", tmp_path / f"short{frames}.json"
    proc = run_cli("convert", tmp_path / f"short{frames}.usda", "-o", out, "--summary", summary)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    data = json.loads(summary.read_text(), parse_constant=_no_constant)
    assert data["frames"]["count"] == frames
    assert out.stat().st_size > 0


def test_a_cut_left_in_the_shot_is_named_where_the_limits_fail(tmp_path: Path) -> None:
    """A camera that jumps 6 m between two frames (a cut left in the shot) fails on limits
    over many frames around it; check, check --json and convert say where the jump is."""
    stage = _stage(tmp_path / "cut.usda")
    cam = UsdGeom.Camera.Define(stage, "/rig/cam")
    translate = cam.AddTranslateOp()
    cam.AddRotateXYZOp().Set(Gf.Vec3f(90.0, 0.0, -90.0))  # looks down +x, the track
    for frame, x in ((1, 3.0), (11, 3.0), (12, 9.0), (24, 9.0)):  # 3 m, then 9 m from 12
        translate.Set(Gf.Vec3d(x, 0.0, 1.4), frame)
    stage.GetRootLayer().Save()
    notes = ["the camera jumps 6.000 m between frames 11 and 12 (the camera holds still "
             "around it): a cut in the shot?",
             "to split the shot there, convert each part on its own: --frames 1:11, "
             "--frames 12:24"]
    check = run_cli("check", tmp_path / "cut.usda")
    assert check.returncode == 3, check.stderr
    lines = check.stdout.splitlines()
    at = lines.index(f"  note: {notes[0]}")
    assert lines[at:at + 2] == [f"  note: {n}" for n in notes], check.stdout
    data = json.loads(run_cli("check", tmp_path / "cut.usda", "--json").stdout)
    assert data["notes"] == notes
    out = tmp_path / "cut.mcap"
    conv = run_cli("convert", tmp_path / "cut.usda", "-o", out)
    assert conv.returncode == 3 and not out.exists()
    said = [ln for ln in conv.stderr.splitlines() if ln.startswith("note: ")]
    assert said == [f"note: {n}" for n in notes], conv.stderr
    # the parts it names convert on their own
    for part in ("1:11", "12:24"):
        piece = tmp_path / f"cut_{part.replace(':', '_')}.mcap"
        done = run_cli("convert", tmp_path / "cut.usda", "-o", piece, "--frames", part)
        assert done.returncode == 0 and piece.stat().st_size > 0, done.stderr


def _hold_between_moves(tmp_path: Path, ease: Any) -> Path:
    """A half-metre truck and pan eased by ``ease`` into a hold (frames 36-60), then out."""
    from tests.shots import write_shot

    robot = Robot.default()
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    out = np.tile(np.eye(4), (96, 1, 1))
    for i, f in enumerate(range(1, 97)):
        s = ease(min((f - 1) / 35, 1.0)) - ease(max((f - 60) / 36, 0.0))
        out[i, :3, :3] = rot_z(0.2 * s) @ look
        out[i, :3, 3] = (4.5 + 0.5 * s, 0.0, 0.9)
    return write_shot(tmp_path / "hold.usda", out)


def test_a_move_that_stops_dead_into_a_hold_is_named_and_an_eased_one_fits(
        tmp_path: Path) -> None:
    """A smoothstep (flat in speed, not in acceleration at its ends) into and out of a hold
    asks the robot, which holds where the camera holds, to stop within a frame: the timing
    error says so at the hold's two edges. The same move eased to zero acceleration
    (smootherstep) runs at real time."""
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions
    from camtraj.timing import TimingLimitError

    with pytest.raises(TimingLimitError) as info:
        analyse(_hold_between_moves(tmp_path, lambda u: u * u * (3 - 2 * u)), ConvertOptions())
    notes = [n for n in getattr(info.value, "__notes__", []) if "hold" in n]
    assert len(notes) == 1, getattr(info.value, "__notes__", [])
    assert ("the camera stops dead into a hold at frame 36 and starts out of a hold at "
            "frame 60:") in notes[0]
    assert "--timing optimal" in notes[0]
    smooth = analyse(_hold_between_moves(tmp_path, lambda u: u**3 * (10 - 15 * u + 6 * u * u)),
                     ConvertOptions())
    assert smooth.take is not None and smooth.take.report.max_speed >= 1.0


@pytest.mark.parametrize("frames", [3, 6])
def test_a_pan_too_fast_between_two_holds_gets_no_hold_note(tmp_path: Path,
                                                            frames: int) -> None:
    """A 0.5 rad pan eased to zero acceleration at both ends (smootherstep) over 3 or 6
    frames between two holds fails on limits because it is too fast, not because of how it
    meets the holds: no hold note (a reviewer's cases; the first rule named both edges)."""
    from camtraj.convert import analyse
    from camtraj.options import ConvertOptions
    from camtraj.timing import TimingLimitError
    from tests.shots import write_shot

    robot = Robot.default()
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    out = np.tile(np.eye(4), (48, 1, 1))
    for i, f in enumerate(range(1, 49)):
        u = min(max((f - 20) / frames, 0.0), 1.0)
        out[i, :3, :3] = rot_z(0.5 * u**3 * (10 - 15 * u + 6 * u * u)) @ look
        out[i, :3, 3] = (4.5, 0.0, 0.9)
    with pytest.raises(TimingLimitError) as info:
        analyse(write_shot(tmp_path / "pan.usda", out), ConvertOptions())
    assert not [n for n in getattr(info.value, "__notes__", []) if "hold" in n]


def test_a_fast_whip_is_not_a_cut_and_a_snap_is() -> None:
    """90 deg of pan over 6 frames (eased) is a move; 180 deg in one frame between still
    frames is a jump, named in degrees."""
    from camtraj.convert import camera_cuts

    def poses(pan_deg: np.ndarray) -> np.ndarray:
        a = np.radians(pan_deg)
        out = np.tile(np.eye(4), (a.size, 1, 1))
        out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = (
            np.cos(a), -np.sin(a), np.sin(a), np.cos(a))
        out[:, :3, 3] = (4.0, 0.0, 1.2)
        return out

    frames = np.arange(1, 25)
    u = np.clip((frames - 10) / 6.0, 0.0, 1.0)
    assert camera_cuts(poses(90.0 * (0.5 - 0.5 * np.cos(np.pi * u))), frames) == []
    snap = np.where(frames <= 12, 0.0, 180.0)
    assert camera_cuts(poses(snap), frames) == [
        "the camera jumps 180.0 deg between frames 12 and 13 (the camera holds still around "
        "it): a cut in the shot?",
        "to split the shot there, convert each part on its own: --frames 1:12, --frames 13:24"]
    twice = np.where(frames <= 6, 0.0, np.where(frames <= 18, 180.0, 0.0))
    assert camera_cuts(poses(twice), frames)[-1] == (
        "to split the shot there, convert each part on its own: --frames 1:6, --frames 7:18, "
        "--frames 19:24")
    # one frame off an eased move and straight back (an export glitch or a blocked key): its
    # two steps are equal, so neither is a cut against the other; it is named as one frame
    eased = 90.0 * (0.5 - 0.5 * np.cos(np.pi * u))
    pop = poses(eased)
    pop[11, :3, 3] = 0.0  # frame 12 at the stage origin
    assert camera_cuts(pop, frames) == [  # mid-pan: frames 11 and 13 are 39 deg apart
        f"the camera jumps {np.linalg.norm(pop[10, :3, 3]):.3f} m off its path on frame 12 "
        "alone and back: a bad or blocked key at frame 12?"]
    assert camera_cuts(poses(np.where(frames == 12, 180.0, 0.0)), frames) == [
        "the camera jumps 180.0 deg off its path on frame 12 alone and back (frames 11 and 13 "
        "agree): a bad or blocked key at frame 12?"]
    # a frame off the path at a cut (a reviewer's case): both, and the parts leave it out
    at_cut = poses(np.zeros(24))
    at_cut[12:, 0, 3] = 4.5
    at_cut[11, :3, 3] = 0.0
    assert camera_cuts(at_cut, frames) == [
        f"the camera jumps {np.linalg.norm(at_cut[10, :3, 3]):.3f} m off its path on frame 12 "
        "alone and back: a bad or blocked key at frame 12?",
        "the camera jumps 0.500 m between frames 11 and 13 across frame 12: a cut in the shot?",
        "to split the shot there, convert each part on its own: --frames 1:11, --frames 13:24 "
        "(leaving out frame 12)"]
    # the same at frame 2: a part of one frame is no shot (convert needs two): left out
    early = poses(np.zeros(24))
    early[2:, 0, 3] = 4.5
    early[1, :3, 3] = 0.0
    assert camera_cuts(early, frames)[1:] == [
        "the camera jumps 0.500 m between frames 1 and 3 across frame 2: a cut in the shot?",
        "to split the shot there, convert each part on its own: --frames 3:24 (leaving out "
        "frames 1-2)"]
    # a long, fast, uneven move (every step over the 5 cm / 5 deg floors: the steps around
    # each are windows, not a loop per frame) with one frame off it and one cut
    rng = np.random.default_rng(3)
    long = poses(np.cumsum(rng.uniform(0.0, 9.0, 3000)))
    long[:, 0, 3] += np.cumsum(rng.uniform(0.06, 0.2, 3000))
    long[1500, 2, 3] += 7.0
    long[2200:, 1, 3] += 3.0
    got = camera_cuts(long, np.arange(3000))
    assert len(got) == 3, got
    assert got[0].startswith("the camera jumps 7.0") and got[0].endswith(
        " m off its path on frame 1500 alone and back: a bad or blocked key at frame 1500?")
    assert got[1].startswith("the camera jumps 3.0") and " between frames 2199 and 2200 (" in got[1]
    assert got[2] == ("to split the shot there, convert each part on its own: --frames 0:2199, "
                      "--frames 2200:2999")


def _no_constant(name: str) -> None:
    msg = f"{name} is not JSON"
    raise ValueError(msg)


def test_output_names_that_are_not_utf8_are_written_and_reported(tmp_path: Path) -> None:
    """Linux file names are bytes; the report prints them escaped even on a strict stdout."""
    out = os.fsdecode(bytes(tmp_path) + b"/take\xff.mcap")
    summary = os.fsdecode(bytes(tmp_path) + b"/take\xfe.json")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONIOENCODING": "utf-8:strict"}
    proc = subprocess.run(
        [sys.executable, "-m", "camtraj", "convert", str(MAYA), "-o", out, "--summary", summary],
        capture_output=True, text=True, env=env, timeout=600, check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "wrote " in proc.stdout and "take\\udcff.mcap" in proc.stdout
    assert os.path.getsize(out) > 0
    assert json.loads(Path(summary).read_text())["status"] == "ok"


def test_the_readme_states_the_frame_and_rate_caps_the_code_enforces() -> None:
    """Issue 14 §5: the README said at most 1,000,000 frames while the code refused above
    100,000; the README's numbers are read here and compared with the code's."""
    from camtraj.convert import MAX_FPS
    from camtraj.usd_shot import MAX_FRAMES

    text = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    found = re.search(r"at most \*\*([\d,]+) frames\*\* and at most \*\*([\d,]+) fps\*\*", text)
    assert found, "the README no longer states the frame and rate caps"
    assert int(found[1].replace(",", "")) == MAX_FRAMES
    assert float(found[2].replace(",", "")) == MAX_FPS


def test_quiet_convert_still_says_the_shots_warnings_on_stderr(tmp_path: Path) -> None:
    """``convert -q`` prints nothing on stdout; the report's warnings (here a camera without
    a focal length) go to stderr, as its --help says, not away."""
    stage = _stage(tmp_path / "bare.usda")
    _camera(stage)
    stage.GetRootLayer().Save()
    loud = run_cli("convert", tmp_path / "bare.usda", "-o", tmp_path / "loud.mcap")
    assert loud.returncode == 0, loud.stderr
    said = [line.strip() for line in loud.stdout.splitlines()
            if line.strip().startswith("warning: ")]
    assert any("has no focalLength" in line for line in said), loud.stdout
    quiet = run_cli("convert", tmp_path / "bare.usda", "-o", tmp_path / "quiet.mcap", "-q")
    assert quiet.returncode == 0, quiet.stderr
    assert quiet.stdout == ""
    assert quiet.stderr.splitlines() == said


@pytest.mark.parametrize("shot", ["maya_dolly_push_in", "whip_pan"])
def test_a_reader_that_stops_early_gets_no_error_line(shot: str) -> None:
    """``camtraj check shot | head -1`` where the reader has gone before the report is
    written: no "ERROR: cannot write to standard output" on stderr, exit 141 (128 +
    SIGPIPE) as for any tool a pipe stops."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before a line is written
    try:
        proc = subprocess.run([sys.executable, "-m", "camtraj", "check",
                               str(SHOTS / f"{shot}.usda")],
                              stdout=write, stderr=subprocess.PIPE, text=True, check=False,
                              cwd=ROOT)
    finally:
        os.close(write)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


def test_a_frame_off_the_path_is_named_and_a_slowed_take_warns_of_it(tmp_path: Path) -> None:
    """One key at the stage origin in the middle of a gentle move (an export glitch, or a
    value-blocked key): the shot fails at its own timing with a note naming the frame, and
    the scale take, which runs the swing out and back slowly, warns of it (it wrote the
    take with exit 0 and no word before)."""
    from camtraj.convert import analyse, run_warnings
    from camtraj.options import ConvertOptions
    from camtraj.timing import TimingLimitError
    from tests.shots import base_move, write_shot

    robot = Robot.default()
    move = base_move(robot, 48)
    move[23, :3, 3] = 0.0  # frame 24
    path = write_shot(tmp_path / "pop.usda", move)
    said = (f"the camera jumps {np.linalg.norm(move[22, :3, 3]):.3f} m off its path on frame "
            f"24 alone and back (frames 23 and 25 agree): a bad or blocked key at frame 24?")
    with pytest.raises(TimingLimitError) as info:
        analyse(path, ConvertOptions())
    assert said in getattr(info.value, "__notes__", [])
    slowed = analyse(path, ConvertOptions(timing="scale"))
    assert said in run_warnings(slowed)
    assert not [w for w in run_warnings(analyse(write_shot(tmp_path / "ok.usda",
                                                           base_move(robot, 48)),
                                                ConvertOptions()))
                if "jumps" in w]
