"""Bad inputs for the commands beyond convert (issue 14): place, report, info, batch, farm
export and run-task, set files, collision geometry and MCAP metadata.

Every case runs the real command line in a fresh process (forked from a pre-imported server,
:func:`tests.conftest.run_forked`), in its own folder that holds an earlier good result, and
must:

* exit with the documented code (2 bad input, 3 cannot be done) within a time limit (a run
  that blocks on a named pipe is killed by an alarm and reported as a hang);
* print exactly one ``ERROR: ...`` line on stderr, no traceback, and nothing on stdout (a
  batch prints its table);
* leave every input and every earlier output byte-identical, and create no output (a batch
  writes its report).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

import camtraj
from camtraj.farm import MANIFEST_FORMAT
from tests.conftest import run_forked, snapshot
from tests.test_convert import ROOT, SHOTS, run_cli

MAYA = SHOTS / "maya_dolly_push_in.usda"
ROBOT_TOML = ROOT / "camtraj" / "data" / "robot.toml"
ALARM_S = 240  # a case still running after this long is a hang

@dataclass
class Case:
    """One bad run.

    Attributes:
        args: The command line after ``camtraj``; ``{dir}`` is the case's folder.
        must: Regular expressions the error line must match (case-insensitive).
        codes: The allowed exit codes.
        table: The command prints a table on stdout (batch).
        may_write: Files of the case folder the run may write (the batch report).
        keep: Files in the case folder that must survive unchanged (added before the run).
    """

    args: list[str]
    must: tuple[str, ...] = ()
    codes: tuple[int, ...] = (2,)
    table: bool = False
    may_write: tuple[str, ...] = ()
    keep: dict[str, bytes] = field(default_factory=dict)


# --------------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------------


def _obstacle_shot(path: Path, build: Callable[[Usd.Stage], None]) -> Path:
    """The good shot with obstacle prims added by ``build`` (a layer over it)."""
    shutil.copy(MAYA, path)
    stage = Usd.Stage.Open(str(path))
    build(stage)
    stage.GetRootLayer().Save()
    return path


def _mesh(points: list[tuple[float, float, float]], counts: list[int],
          indices: list[int]) -> Callable[[Usd.Stage], None]:
    def build(stage: Usd.Stage) -> None:
        mesh = UsdGeom.Mesh.Define(stage, "/obst")
        mesh.GetPointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in points]))
        mesh.GetFaceVertexCountsAttr().Set(counts)
        mesh.GetFaceVertexIndicesAttr().Set(indices)
    return build


def _gprim(kind: str, attr: str, value: float) -> Callable[[Usd.Stage], None]:
    def build(stage: Usd.Stage) -> None:
        prim = stage.DefinePrim("/obst", kind)
        prim.GetAttribute(attr).Set(value)
    return build


def _nan_transform(stage: Usd.Stage) -> None:
    xf = UsdGeom.Xform.Define(stage, "/obst")
    xf.AddTranslateOp().Set(Gf.Vec3d(math.nan, 0.0, 0.0))
    UsdGeom.Cube.Define(stage, "/obst/box")


def _point_instancer(stage: Usd.Stage) -> None:
    inst = UsdGeom.PointInstancer.Define(stage, "/obst")
    UsdGeom.Cube.Define(stage, "/obst/protos/box")
    inst.CreatePrototypesRel().SetTargets([Sdf.Path("/obst/protos/box")])
    inst.CreatePositionsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(500, 0, 0)]))
    inst.CreateProtoIndicesAttr().Set([0, 0])


QUAD = [(0.0, 0.0, 0.0), (100.0, 0.0, 0.0), (100.0, 100.0, 0.0), (0.0, 100.0, 0.0)]
COLLISION_SHOTS: dict[str, tuple[Callable[[Usd.Stage], None], str]] = {
    "nan_vertex": (_mesh([*QUAD[:3], (math.nan, 0.0, 0.0)], [4], [0, 1, 2, 3]), "point 3"),
    "inf_vertex": (_mesh([*QUAD[:3], (math.inf, 0.0, 0.0)], [4], [0, 1, 2, 3]), "point 3"),
    "far_vertex": (_mesh([*QUAD[:3], (1e30, 0.0, 0.0)], [4], [0, 1, 2, 3]), "point 3"),
    "bad_face_index": (_mesh(QUAD, [4], [0, 1, 2, 9]), "index 9"),
    "negative_index": (_mesh(QUAD, [4], [0, 1, 2, -1]), "index -1"),
    "negative_count": (_mesh(QUAD, [-4, 8], [0, 1, 2, 3]), "face 0"),
    "no_faces": (_mesh(QUAD, [], []), "no faces"),
    "edge_only_face": (_mesh(QUAD, [2, 2], [0, 1, 2, 3]), "face 0 has 2"),
    "counts_do_not_add_up": (_mesh(QUAD, [4, 3], [0, 1, 2, 3]), "add up"),
    "cube_nan_size": (_gprim("Cube", "size", math.nan), "size"),
    "cube_negative_size": (_gprim("Cube", "size", -2.0), "size"),
    "sphere_nan_radius": (_gprim("Sphere", "radius", math.nan), "radius"),
    "cylinder_zero_height": (_gprim("Cylinder", "height", 0.0), "height"),
    "nan_transform": (_nan_transform, "not finite"),
    "point_instancer": (_point_instancer, "PointInstancer"),
}


def _rewrite_mcap(src: Path, dst: Path, *, drop: str | None = None,
                  edit: Callable[[str, dict[str, str]], dict[str, str]] | None = None) -> None:
    """A copy of a camtraj MCAP without ``drop``'s messages, its metadata passed to ``edit``."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with src.open("rb") as f, dst.open("wb") as g:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(g)
        writer.start(header.profile, header.library)
        for sid, schema in summary.schemas.items():
            writer.register_schema(schema.name, schema.encoding, schema.data)
            assert sid  # ids are given in order from 1
        channels = {}
        for cid, ch in sorted(summary.channels.items()):
            channels[cid] = writer.register_channel(ch.topic, ch.message_encoding, ch.schema_id,
                                                    dict(ch.metadata))
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == drop:
                continue
            writer.add_message(channels[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        for rec in reader.iter_metadata():
            md = dict(rec.metadata)
            writer.add_metadata(rec.name, edit(rec.name, md) if edit else md)
        writer.finish()


def _robot_md(key: str, value: str) -> Callable[[str, dict[str, str]], dict[str, str]]:
    def edit(name: str, md: dict[str, str]) -> dict[str, str]:
        return {**md, key: value} if name == "camtraj.robot" else md
    return edit


def _take_md(key: str, value: str) -> Callable[[str, dict[str, str]], dict[str, str]]:
    def edit(name: str, md: dict[str, str]) -> dict[str, str]:
        return {**md, key: value} if name == "camtraj" else md
    return edit


# --------------------------------------------------------------------------------------------
# The corpus
# --------------------------------------------------------------------------------------------


def _corpus(base: Path, good_mcap: Path) -> tuple[dict[str, Case], Path]:
    d = base / "inputs"
    d.mkdir()
    cases: dict[str, Case] = {}
    good = d / "maya.usda"
    shutil.copy(MAYA, good)
    os.symlink(good, d / "link_to_shot.usda")
    os.link(good, d / "hard_link_to_shot.usda")
    (d / "sub").mkdir()
    (d / "set_dressing.usda").write_text('#usda 1.0\ndef Xform "set" {}\n', encoding="utf-8")
    layered = d / "layered.usda"
    layered.write_text("#usda 1.0\n(\n    subLayers = [@./maya.usda@]\n)\n"
                       'def "dressing" (references = @./set_dressing.usda@) {}\n',
                       encoding="utf-8")
    robot = d / "robot.toml"
    shutil.copy(ROBOT_TOML, robot)
    set_file = d / "set.toml"
    set_file.write_text("[search]\nyaw_deg = 0.0\n", encoding="utf-8")
    for name in ("pipe.usda", "pipe.toml", "pipe.mcap", "pipe.json"):
        os.mkfifo(d / name)
    (d / "set_latin1.toml").write_bytes("# plateau é\n[search]\nyaw_deg = 0.0\n".encode("latin-1"))
    text = ROBOT_TOML.read_text(encoding="utf-8")
    (d / "robot_1e308.toml").write_text(
        re.sub(r"max_velocity = [0-9.]+", "max_velocity = 1e308", text, count=1),
        encoding="utf-8")
    mcap = d / "take.mcap"
    shutil.copy(good_mcap, mcap)
    crc = bytearray(mcap.read_bytes())
    from mcap.reader import make_reader

    with mcap.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    crc[summary.chunk_indexes[0].chunk_start_offset + 33] ^= 0xFF  # the chunk's CRC field
    (d / "crc.mcap").write_bytes(bytes(crc))
    (d / "s").mkdir()
    shutil.copy(MAYA, d / "s" / "a.usda")
    shutil.copy(MAYA, d / "s" / "a.rig.usda")
    (d / "b").mkdir()
    shutil.copy(SHOTS / "unreachable.usda", d / "b" / "a.usda")

    def add(name: str, args: Sequence[object], *must: str, **kw: Any) -> None:
        assert name not in cases, name
        cases[name] = Case([str(a) for a in args], must, **kw)

    # 1. Outputs that are inputs: nothing is replaced
    for cmd in ("place", "farm_openjd", "farm_opencue"):
        head: list[object] = {"place": ["place"],
                              "farm_openjd": ["farm", "export", "--format", "openjd"],
                              "farm_opencue": ["farm", "export", "--format", "opencue"]}[cmd]
        for name, shot, extra, must in (
            ("o_is_the_shot", good, ["-o", good], "the shot"),
            ("o_is_a_symlink_to_the_shot", good, ["-o", d / "link_to_shot.usda"], "the shot"),
            ("o_reaches_the_shot_through_dotdot", good, ["-o", d / "sub" / ".." / "maya.usda"],
             "the shot"),
            ("o_is_a_hard_link_to_the_shot", good, ["-o", d / "hard_link_to_shot.usda"],
             "the shot"),
            ("o_is_the_robot_file", good, ["-o", robot, "--robot", robot], "the robot file"),
            ("o_is_the_set_file", good, ["-o", set_file, "--set-file", set_file],
             "the set file"),
            ("o_is_a_sublayer", layered, ["-o", good], "layer used by the shot"),
        ):
            add(f"{cmd}_{name}", [*head, shot, *extra], must)
    add("place_o_unwritable_checked_before_the_search",
        ["place", SHOTS / "unreachable.usda", "-o", "/proc/placed.toml"], "/proc")
    add("place_o_folder_is_a_file_checked_before_the_search",
        ["place", SHOTS / "unreachable.usda", "-o", robot / "placed.toml"], "not a folder")
    # a scene (several shots, or a scene file): -o is none of any shot's inputs
    (d / "scene.toml").write_text('set_file = "set.toml"\n[[shot]]\npath = "maya.usda"\n'
                                  '[[shot]]\npath = "s/a.usda"\n', encoding="utf-8")
    second = d / "s" / "a.usda"
    add("place_scene_o_is_the_second_shot", ["place", good, second, "-o", second],
        "the shot a.usda")
    add("place_scene_o_is_a_layer_of_the_second_shot", ["place", second, layered, "-o", good],
        "layer used by the shot layered.usda")
    add("place_scene_o_is_the_scene_file",
        ["place", "--scene", d / "scene.toml", "-o", d / "scene.toml"], "the scene file")
    add("place_scene_o_is_the_set_file_it_names",
        ["place", "--scene", d / "scene.toml", "-o", set_file], "the set file")
    add("place_scene_o_is_a_shot_it_names",
        ["place", "--scene", d / "scene.toml", "-o", second], "the shot a.usda")
    add("place_scene_a_fifo_as_a_shot", ["place", good, d / "pipe.usda"], "named pipe")
    add("place_scene_a_fifo_as_a_shot_with_o", ["place", good, d / "pipe.usda", "-o", "p.toml"],
        "named pipe")
    add("place_scene_file_fifo", ["place", "--scene", d / "pipe.toml"], "named pipe")
    # a shot that does not exist is bad input (exit 2), as a folder or a pipe is (it was 1)
    (d / "missing.toml").write_text('[[shot]]\npath = "nope.usda"\n', encoding="utf-8")
    add("place_scene_file_names_a_missing_shot", ["place", "--scene", d / "missing.toml"],
        "nope.usda", "no such file")
    add("place_scene_a_missing_shot", ["place", good, d / "nope.usda"], "nope.usda",
        "no such file")
    add("place_scene_shots_of_different_units",
        ["place", good, SHOTS / "blender_crane_up.usda"], "units")
    add("place_scene_and_shots", ["place", good, "--scene", d / "scene.toml"], "scene")
    add("farm_openjd_rig_layer_is_another_shot",
        ["farm", "export", "--format", "openjd", "--usd", d / "s" / "a.usda",
         d / "s" / "a.rig.usda", "--outdir", d / "s", "-o", "job.yaml"], "a.rig.usda", "shot")
    add("farm_opencue_task_output_is_the_robot_file",
        ["farm", "export", "--format", "opencue", good, "--robot", d / "maya.mcap",
         "--outdir", d, "-o", "job.xml"], "robot file")
    (d / "maya.mcap").write_bytes(ROBOT_TOML.read_bytes())  # a robot file named like an output
    add("batch_rig_layer_is_another_shot",
        ["batch", d / "s" / "a.usda", d / "s" / "a.rig.usda", "-o", d / "s", "--usd"],
        "a.rig.usda", "shot")
    add("batch_output_is_the_robot_file",
        ["batch", good, "--robot", d / "maya.mcap", "-o", d], "robot file")
    user_rig = b"#usda 1.0\n# the user's own rig layer\n"
    add("batch_failed_shot_keeps_a_rig_layer_it_did_not_write",
        ["batch", d / "b" / "a.usda", "-o", "{dir}"], "cannot be reached", codes=(3,),
        table=True, may_write=("batch_report.json",), keep={"a.rig.usda": user_rig})
    add("batch_missing_shot_keeps_a_rig_layer_it_did_not_write",
        ["batch", d / "gone.usda", "-o", "{dir}", "--usd"], "gone.usda", "no such file",
        table=True, may_write=("batch_report.json",), keep={"gone.rig.usda": user_rig})

    # run-task: convert refuses the output, and the clean-up deletes nothing
    def manifest(name: str, data: Any) -> Path:
        path = d / f"{name}.tasks.json"
        path.write_text(data if isinstance(data, str) else json.dumps(data), encoding="utf-8")
        return path

    def task(**over: Any) -> dict[str, Any]:
        entry = {"frame": 1, "shot": str(good), "output": "{dir}/out.mcap",
                 "summary": "{dir}/out.summary.json"}
        return {**entry, **over}

    def job(tasks: Any = None, options: Any = None, **over: Any) -> dict[str, Any]:
        return {"format": MANIFEST_FORMAT, "camtraj_version": camtraj.__version__,
                "paths": "absolute", "options": {} if options is None else options,
                "tasks": [task()] if tasks is None else tasks, **over}

    for name, data, must in (
        ("output_is_the_shot", job([task(output=str(good))]), "the shot"),
        ("summary_is_the_shot", job([task(summary=str(good))]), "the shot"),
        ("output_is_the_robot_file", job([task(output=str(robot))], {"robot": str(robot)}),
         "the robot file"),
        ("not_json", "{", "not JSON"),
        ("not_a_manifest", {"tasks": []}, "not a camtraj task manifest"),
        ("no_tasks", {**job(), "tasks": None}, "tasks"),
        ("tasks_not_a_list", job(tasks={"1": task()}), "tasks"),
        ("task_without_output", job([{"shot": str(good), "summary": "s.json"}]), "task 1"),
        ("task_output_a_number", job([task(output=5)]), "task 1"),
        ("task_not_a_table", job(["shot.usda"]), "task 1"),
        ("options_not_a_table", job(options=[1, 2]), "options"),
        ("option_rate_a_word", job(options={"rate": "fast"}), "rate"),
        ("option_rate_nan", job(options={"rate": "NaN"}), "rate"),
        ("option_timing_unknown", job(options={"timing": "fastest"}), "timing"),
        ("option_placement_short", job(options={"placement": [1, 2]}), "placement"),
        ("option_frames_words", job(options={"frames": ["a", "b"]}), "frames"),
        ("option_robot_a_number", job(options={"robot": 7}), "robot"),
        ("option_unknown", job(options={"speed": 2}), "speed"),
    ):
        add(f"run_task_{name}", ["farm", "run-task", manifest(name, data), 1], must)
    add("run_task_manifest_fifo", ["farm", "run-task", d / "pipe.json", 1], "named pipe")

    # 3. Named pipes and text that is not UTF-8, for every command that reads them
    add("report_of_a_fifo", ["report", d / "pipe.mcap", "-o", "r.html"], "named pipe")
    add("place_of_a_fifo", ["place", d / "pipe.usda"], "named pipe")
    add("place_set_file_fifo", ["place", good, "--set-file", d / "pipe.toml"], "named pipe")
    add("place_robot_fifo", ["place", good, "--robot", d / "pipe.toml"], "named pipe")
    for cmd in ("check", "convert"):
        out = ["-o", "out.mcap"] if cmd == "convert" else []
        add(f"{cmd}_set_file_fifo_with_placement",
            [cmd, good, *out, "--set-file", d / "pipe.toml", "--placement", "0,0,0,0"],
            "named pipe")
        add(f"{cmd}_set_file_not_utf8_with_placement",
            [cmd, good, *out, "--set-file", d / "set_latin1.toml", "--placement", "0,0,0,0"],
            "not UTF-8")
    add("place_set_file_not_utf8", ["place", good, "--set-file", d / "set_latin1.toml"],
        "not UTF-8")
    add("batch_of_a_fifo", ["batch", d / "pipe.usda", "-o", "{dir}"], "named pipe",
        table=True, may_write=("batch_report.json",))
    add("place_clearance_nan", ["place", good, "--clearance", "nan"], "clearance")
    add("check_robot_max_velocity_1e308", ["check", good, "--robot", d / "robot_1e308.toml"],
        "max_velocity")

    # report and info of damaged or edited MCAPs
    add("report_o_is_the_mcap", ["report", mcap, "-o", mcap], "the MCAP")
    add("report_chunk_crc_fails", ["report", d / "crc.mcap", "-o", "r.html"], "CRC")
    add("info_chunk_crc_fails", ["info", d / "crc.mcap"], "CRC")
    for name, kw, must in (
        ("no_tf", {"drop": "/tf"}, "/tf"),
        ("lower_short", {"edit": _robot_md("lower", "[0, 1]")}, "lower"),
        ("velocity_nan", {"edit": _robot_md("max_velocity", json.dumps([math.nan] * 8))},
         "max_velocity"),
        ("velocity_zero", {"edit": _robot_md("max_velocity", json.dumps([0.0] * 8))},
         "max_velocity"),
        ("velocity_words", {"edit": _robot_md("max_velocity", '"fast"')}, "max_velocity"),
        ("placement_garbage", {"edit": _take_md("placement", '"somewhere"')}, "placement"),
        ("placement_short", {"edit": _take_md("placement", '{"translation_m": [1, 2]}')},
         "placement"),
        ("placement_not_json", {"edit": _take_md("placement", "{x")}, "metadata"),
        ("fps_a_word", {"edit": _take_md("fps", "twenty-four")}, "fps"),
        ("warnings_not_a_list", {"edit": _take_md("warnings", "3")}, "warnings"),
    ):
        edited = d / f"md_{name}.mcap"
        _rewrite_mcap(mcap, edited, **kw)
        add(f"report_{name}", ["report", edited, "-o", "r.html"], must)
    # trial 22: info trusted the metadata's types (tracebacks), deep JSON broke both
    deep = "[" * 100_000 + "]" * 100_000
    for name, kw in (
        ("lower_words", {"edit": _robot_md("lower", '["x", "y"]')}),
        ("peak_use_a_list", {"edit": _take_md("peak_use", "[1, 2]")}),
        ("position_range_words", {"edit": _take_md("position_range", '{"track": "far"}')}),
    ):
        edited = d / f"info_{name}.mcap"
        _rewrite_mcap(mcap, edited, **kw)
        add(f"info_{name}", ["info", edited], "metadata")
    nested = d / "md_nested.mcap"
    _rewrite_mcap(mcap, nested, edit=_take_md("placement", deep))
    add("report_nested_metadata", ["report", nested, "-o", "r.html"], "nested")

    # 2. Collision geometry camtraj cannot check is bad input, named
    coll_set = d / "collision.toml"
    coll_set.write_text('[collision]\nprims = ["/obst"]\nclearance_m = 0.05\n',
                        encoding="utf-8")
    for name, (build, must) in COLLISION_SHOTS.items():
        shot = _obstacle_shot(d / f"coll_{name}.usda", build)
        add(f"collision_{name}", ["check", shot, "--set-file", coll_set, "--frames",
                                  "1001:1010"], "/obst", must)
    return cases, d


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
    base = tmp_path_factory.mktemp("commands")
    good_dir = base / "good"
    good_dir.mkdir()
    proc = run_cli("convert", MAYA, "-o", good_dir / "out.mcap", "--summary",
                   good_dir / "out.summary.json", "-q")
    assert proc.returncode == 0, proc.stderr
    cases, inputs = _corpus(base, good_dir / "out.mcap")
    good = {p.name: p.read_bytes() for p in good_dir.iterdir()}
    jobs: list[dict[str, object]] = []
    folders: dict[str, Path] = {}
    befores: dict[str, dict[str, bytes]] = {}
    for name, case in cases.items():
        folder = base / name
        folder.mkdir()
        before = {**good, **case.keep}
        for file_name, data in before.items():
            (folder / file_name).write_bytes(data)
        case.args = [a.replace("{dir}", str(folder)) for a in case.args]
        manifest = inputs / f"{name.removeprefix('run_task_')}.tasks.json"
        if name.startswith("run_task_") and manifest.is_file():  # it names the case folder
            manifest.write_text(manifest.read_text().replace("{dir}", str(folder)))
        folders[name], befores[name] = folder, before
        jobs.append({"id": name, "cwd": str(folder), "args": case.args, "alarm": ALARM_S,
                     "stdout": str(base / f"{name}.stdout"),
                     "stderr": str(base / f"{name}.stderr")})
    before_inputs = snapshot(inputs)
    codes = run_forked(jobs, timeout=3600)
    after_inputs = snapshot(inputs)
    changed = sorted(k for k in {*before_inputs, *after_inputs}
                     if before_inputs.get(k) != after_inputs.get(k))
    (base / "inputs_changed.json").write_text(json.dumps(changed))
    return {name: Result(case, folders[name], codes[name],
                         (base / f"{name}.stdout").read_text(errors="replace"),
                         (base / f"{name}.stderr").read_text(errors="backslashreplace"),
                         befores[name])
            for name, case in cases.items()}


def _problems(name: str, r: Result) -> list[str]:
    problems = []
    if r.rc == -14:
        problems.append(f"hangs (killed after {ALARM_S} s)")
    elif r.rc not in r.case.codes:
        problems.append(f"exit code {r.rc}, expected {r.case.codes}")
    lines = r.stderr.splitlines()
    if len(lines) != 1 or not lines[0].startswith("ERROR: "):
        problems.append(f"stderr is not one ERROR line: {r.stderr[-600:]!r}")
    if "Traceback" in r.stderr:
        problems.append("a traceback")
    line = lines[0] if lines else ""
    problems += [f"{pattern!r} not in the error line" for pattern in r.case.must
                 if not re.search(pattern, line, re.IGNORECASE)]
    if r.stdout and not r.case.table:
        problems.append(f"printed on stdout: {r.stdout[:200]!r}")
    after = {p.name: p.read_bytes() for p in r.folder.iterdir()
             if p.is_file() and p.name not in r.case.may_write}
    if after != r.before:
        problems.append(f"the case folder changed: {sorted(after)} vs {sorted(r.before)}")
    return [f"{name}: {p} [{line}]" for p in problems]


def test_every_bad_input_is_one_line_and_changes_nothing(corpus: dict[str, Result]) -> None:
    problems = [p for name, r in corpus.items() for p in _problems(name, r)]
    assert not problems, f"{len(problems)} problem(s):\n" + "\n".join(problems)


def test_no_input_changed(corpus: dict[str, Result]) -> None:
    base = next(iter(corpus.values())).folder.parent
    changed = json.loads((base / "inputs_changed.json").read_text())
    assert not changed, f"inputs changed, appeared or vanished: {changed}"


def test_the_corpus_covers_every_command(corpus: dict[str, Result]) -> None:
    commands = {" ".join(r.case.args[:2]) if r.case.args[0] == "farm" else r.case.args[0]
                for r in corpus.values()}
    assert commands >= {"place", "report", "info", "batch", "farm export", "farm run-task",
                        "check", "convert"}, commands


def test_the_forked_runs_match_real_processes(corpus: dict[str, Result], tmp_path: Path) -> None:
    """A sample of cases as ``python -m camtraj``: same exit code, same error line."""
    for name in ("place_o_is_the_shot", "report_of_a_fifo", "run_task_output_is_the_shot",
                 "farm_openjd_o_is_the_robot_file"):
        r = corpus[name]
        folder = tmp_path / name
        shutil.copytree(r.folder, folder)
        proc = run_cli(*r.case.args, cwd=folder)
        assert (proc.returncode, proc.stderr) == (r.rc, r.stderr), name


# --------------------------------------------------------------------------------------------
# Smaller items
# --------------------------------------------------------------------------------------------


def test_a_set_file_with_a_utf8_bom_reads_like_one_without(tmp_path: Path) -> None:
    from camtraj.set_file import SetFile

    text = "[search]\nyaw_deg = 30.0\n[collision]\nprims = [\"/World/set\"]\n"
    plain, bom = tmp_path / "plain.toml", tmp_path / "bom.toml"
    plain.write_text(text, encoding="utf-8")
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    a, b = SetFile.read(plain), SetFile.read(bom)
    assert (a.yaw_range_deg, a.prims) == (b.yaw_range_deg, b.prims) == ((30.0, 30.0),
                                                                         ("/World/set",))


def test_a_star_in_a_collision_pattern_stays_in_one_path_element(tmp_path: Path) -> None:
    """``/World/*/wall`` names the walls one level down, not ``/World/a/b/wall``; a matched
    prim's descendants are obstacles all the same."""
    from camtraj.collision import read_obstacles

    path = tmp_path / "set.usda"
    stage = Usd.Stage.CreateNew(str(path))
    for prim in ("/World/a/wall", "/World/a/b/wall", "/World/props/crate/lid"):
        UsdGeom.Cube.Define(stage, prim)
    stage.GetRootLayer().Save()
    found = {o.path for o in read_obstacles(path, ("/World/*/wall",), [1.0], np.eye(3))}
    assert found == {"/World/a/wall"}
    found = {o.path for o in read_obstacles(path, ("/World/props/*",), [1.0], np.eye(3))}
    assert found == {"/World/props/crate/lid"}


def test_an_instanceable_reference_is_checked_at_each_instance(tmp_path: Path) -> None:
    from camtraj.collision import read_obstacles

    path = tmp_path / "set.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Cube.Define(stage, "/proto/box")
    for i, x in enumerate((0.0, 7.0)):
        ref = UsdGeom.Xform.Define(stage, f"/World/crate{i}")
        ref.AddTranslateOp().Set(Gf.Vec3d(x, 0.0, 0.0))
        ref.GetPrim().GetReferences().AddInternalReference("/proto")
        ref.GetPrim().SetInstanceable(True)
    stage.GetRootLayer().Save()
    obstacles = read_obstacles(path, ("/World/*",), [1.0], np.eye(3))
    assert sorted(float(o.poses[0, 0, 3]) for o in obstacles) == [0.0, 7.0]


def test_a_newline_in_a_file_name_keeps_every_error_one_line(tmp_path: Path) -> None:
    """Every command's error names the file with its newline escaped (``\\n``), on one line."""
    from tests.test_convert import error_line, run_all

    shot = tmp_path / "shot\nname.usda"
    shutil.copy(MAYA, shot)
    (tmp_path / "robot\nfile.toml").write_text("[robot]\nname = 3\n", encoding="utf-8")
    gone = tmp_path / "gone\nshot.usda"
    runs = run_all({
        "convert": ["convert", gone, "-o", tmp_path / "a.mcap"],
        "check_robot": ["check", shot, "--robot", tmp_path / "robot\nfile.toml"],
        "place": ["place", gone],
        "report": ["report", tmp_path / "take\n.mcap", "-o", tmp_path / "r.html"],
        "info": ["info", tmp_path / "take\n.mcap"],
        "run_task": ["farm", "run-task", tmp_path / "job\n.json", 1],
        "batch": ["batch", gone, "-o", tmp_path / "out"],
    })
    for name, proc in runs.items():
        assert proc.returncode == 2, (name, proc.stderr)
        line = error_line(proc)
        assert re.search(r"(gone|robot|take|job)\\n", line), (name, line)


def test_a_named_pipe_among_a_shots_layers_is_bad_input_not_a_hang(tmp_path: Path) -> None:
    """Trial 22: a shot whose reference or sublayer is a named pipe hung every command in
    USD's open() (SIGTERM could not stop it); now it is exit 2 naming the pipe, before USD
    opens anything, and batch fails that shot alone."""
    whip = (ROOT / "samples" / "shots" / "whip_pan.usda").read_text(encoding="utf-8")
    os.mkfifo(tmp_path / "pipe.usda")
    ref = tmp_path / "ref.usda"
    ref.write_text(whip.replace('def Xform "World"\n{', 'def Xform "World"\n{\n'
                                '    def "r" (references = @./pipe.usda@) { }', 1),
                   encoding="utf-8")
    sub = tmp_path / "sub.usda"
    sub.write_text(whip.replace("(\n", "(\n    subLayers = [@./pipe.usda@]\n", 1),
                   encoding="utf-8")
    for shot in (ref, sub):
        assert "pipe.usda" in shot.read_text(encoding="utf-8")
        for args in (["check", shot], ["convert", shot, "-o", tmp_path / "x.mcap"],
                     ["place", shot, "-q"]):
            proc = run_cli(*args)  # (a hang: the 600 s timeout)
            assert proc.returncode == 2, (args, proc.stderr)
            assert "pipe.usda" in proc.stderr and "named pipe" in proc.stderr, proc.stderr
    proc = run_cli("batch", ref, SHOTS / "maya_dolly_push_in.usda", "-o", tmp_path / "b", "-q")
    report = json.loads((tmp_path / "b" / "batch_report.json").read_text(encoding="utf-8"))
    status = {Path(s["shot"]).name: s["status"] for s in report["shots"]}
    assert status == {"ref.usda": "failed", "maya_dolly_push_in.usda": "ok"}, proc.stderr


def test_the_layer_check_resolves_as_usd_does(tmp_path: Path) -> None:
    """Review 56: the walk resolved a symlinked shot's relative layers from the link's target
    (USD: from the link's folder), missed a pipe behind format arguments, and refused a
    folder USD reports itself. Checked against the function, no USD stage opened."""
    from camtraj.errors import ShotFileError
    from camtraj.inputs import require_regular_layers

    whip = (ROOT / "samples" / "shots" / "whip_pan.usda").read_text(encoding="utf-8")

    def shot(path: Path, sublayer: str) -> Path:
        path.write_text(whip.replace("(\n", f"(\n    subLayers = [@{sublayer}@]\n", 1),
                        encoding="utf-8")
        return path

    (tmp_path / "here").mkdir()
    (tmp_path / "there").mkdir()
    target = shot(tmp_path / "there" / "shot.usda", "./sub.usda")
    (tmp_path / "there" / "sub.usda").write_text("#usda 1.0\n", encoding="utf-8")
    os.mkfifo(tmp_path / "here" / "sub.usda")
    (tmp_path / "here" / "link.usda").symlink_to(target)
    with pytest.raises(ShotFileError, match=r"here/sub\.usda .* named pipe"):
        require_regular_layers(tmp_path / "here" / "link.usda")
    require_regular_layers(target)  # its own sub.usda is a file
    os.mkfifo(tmp_path / "pipe.usda")
    with pytest.raises(ShotFileError, match="named pipe"):
        require_regular_layers(shot(tmp_path / "args.usda", "./pipe.usda:SDF_FORMAT_ARGS:a=b"))
    (tmp_path / "folder.usda").mkdir()
    require_regular_layers(shot(tmp_path / "folder_sub.usda", "./folder.usda"))  # USD says
