"""camtraj farm export: Open Job Description and OpenCue jobs, run for real on this machine."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from dataclasses import fields, replace
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import pytest

import camtraj
from camtraj import farm
from camtraj.convert import ConvertOptions
from camtraj.errors import InputError
from camtraj.options import build_options

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples" / "shots"
BIN = Path(sys.executable).parent
ODD_NAME = 'my "best" shot'  # spaces and quotes must survive every job format

yaml = pytest.importorskip("yaml")
pytest.importorskip("openjd.model")
pytest.importorskip("outline")


def _camtraj() -> list[str]:
    if (ROOT / "camtraj" / "__main__.py").is_file():
        return [sys.executable, "-m", "camtraj"]
    return [str(BIN / "camtraj")]


def _env() -> dict[str, str]:
    """A render host's environment: camtraj (this venv) on PATH."""
    return {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}


def _run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [*_camtraj(), *args], cwd=cwd, capture_output=True, text=True, check=False, env=_env()
    )


def _openjd(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    openjd = shutil.which("openjd", path=_env()["PATH"])
    assert openjd is not None, "openjd-cli is not installed"
    return subprocess.run(
        [openjd, *args], cwd=cwd, capture_output=True, text=True, check=False, env=_env()
    )


@pytest.fixture
def project(tmp_path: Path) -> Path:
    """A project folder: shots/ with two feasible samples, one under an awkward name."""
    shots = tmp_path / "project" / "shots"
    shots.mkdir(parents=True)
    shutil.copy2(SAMPLES / "blender_crane_up.usda", shots / f"{ODD_NAME}.usda")
    shutil.copy2(SAMPLES / "orbit_animated_parent.usda", shots / "orbit.usda")
    return tmp_path / "project"


FRAMES = ["--frames", "1:12"]  # both samples start at frame 1; keeps the tasks short


def _options(**kwargs: str) -> ConvertOptions:
    values: dict[str, Any] = {
        "camera": None, "robot": None, "placement": None, "frames": None, "rate": 250.0,
        "timing": "shot", **kwargs,
    }  # fmt: skip
    return build_options(**values)


def test_openjd_template_checks_and_runs(project: Path) -> None:
    job = project / "jobs" / "convert.yaml"
    shots = [str(project / "shots" / f"{ODD_NAME}.usda"), str(project / "shots" / "orbit.usda")]
    proc = _run("farm", "export", "--format", "openjd", *shots, "-o", str(job), *FRAMES,
                "--outdir", str(project / "out"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = job.read_text()
    assert f"camtraj {camtraj.__version__}" in text
    template = yaml.safe_load(text)
    assert camtraj.__version__ in template["description"]
    shot_values = template["steps"][0]["parameterSpace"]["taskParameterDefinitions"][0]["range"]
    assert shot_values == [os.path.abspath(s) for s in shots]  # absolute, quotes intact

    check = _openjd("check", str(job))
    assert check.returncode == 0, check.stdout + check.stderr
    run = _openjd("run", str(job), cwd=project)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    for name in (ODD_NAME, "orbit"):
        assert (project / "out" / f"{name}.mcap").stat().st_size > 0
        summary = json.loads((project / "out" / f"{name}.summary.json").read_text())
        assert summary["status"]


def test_openjd_relative_paths_follow_the_job_folder(project: Path, tmp_path: Path) -> None:
    job = project / "convert.json"  # JSON flavour
    shot = project / "shots" / f"{ODD_NAME}.usda"
    farm.export_openjd([str(shot)], job, options=_options(frames="1:12"),
                       outdir=project / "out", relative=True)  # fmt: skip
    template = json.loads(job.read_text())
    assert str(tmp_path) not in job.read_text()  # nothing absolute
    params = template["steps"][0]["parameterSpace"]["taskParameterDefinitions"]
    assert params[0]["range"] == [f"shots/{ODD_NAME}.usda"]
    moved = tmp_path / "moved elsewhere"
    shutil.move(project, moved)
    check = _openjd("check", str(moved / "convert.json"))
    assert check.returncode == 0, check.stdout + check.stderr
    run = _openjd("run", str(moved / "convert.json"), cwd=tmp_path)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    assert (moved / "out" / f"{ODD_NAME}.mcap").stat().st_size > 0


def test_openjd_failing_task_fails_the_run(tmp_path: Path) -> None:
    job = tmp_path / "job.yaml"
    farm.export_openjd([str(SAMPLES / "unreachable.usda")], job, options=_options())
    run = _openjd("run", str(job), cwd=tmp_path)
    assert run.returncode != 0
    assert not (tmp_path / "unreachable.mcap").exists()


def _frame_commands(spec: Path) -> tuple[ET.Element, list[str], dict[str, str]]:
    root = ET.parse(spec).getroot()
    layers = root.findall("./job/layers/layer")
    assert len(layers) == 1
    layer = layers[0]
    cmd = layer.findtext("cmd")
    frame_range = layer.findtext("range")
    assert cmd is not None
    assert frame_range is not None
    first, _, last = frame_range.partition("-")  # "1-N", or "1" for one frame
    frames = range(int(first), int(last or first) + 1)
    env = {k.get("name", ""): k.text or "" for k in root.findall("./job/env/key")}
    env |= {k.get("name", ""): k.text or "" for k in layer.findall("./env/key")}
    # What Cuebot and RQD do: substitute the frame token, run the line through a shell.
    return layer, [cmd.replace("#IFRAME#", str(i)) for i in frames], env


@pytest.mark.parametrize("relative", [False, True], ids=["absolute", "relative"])
def test_opencue_spec_runs_frame_by_frame(project: Path, tmp_path: Path, relative: bool) -> None:
    spec = project / "jobs" / "convert.xml"
    shots = [str(project / "shots" / f"{ODD_NAME}.usda"), str(project / "shots" / "orbit.usda")]
    if relative:
        shots = shots[:1]  # the awkward name; the absolute case runs both
    farm.export_opencue(shots, spec, options=_options(frames="1:12"), outdir=project / "out",
                        relative=relative)  # fmt: skip
    text = spec.read_text()
    assert f"camtraj {camtraj.__version__}" in text
    layer, commands, env = _frame_commands(spec)
    assert layer.findtext("range") == ("1" if relative else "1-2")
    assert layer.findtext("chunk") == "1"
    assert env["CAMTRAJ_JOB_VERSION"] == camtraj.__version__
    assert "#IFRAME#" in (layer.findtext("cmd") or "")
    assert "pycuerun" not in text

    manifest = json.loads((project / "jobs" / "convert.tasks.json").read_text())
    assert [Path(t["shot"]) for t in manifest["tasks"]] == [
        Path(os.path.relpath(s, spec.parent) if relative else s) for s in shots
    ]
    if relative:
        assert str(tmp_path) not in json.dumps(manifest)

    host_dir = tmp_path / "render host cwd"
    host_dir.mkdir()
    for command in commands:
        run = subprocess.run(
            command, shell=True, cwd=host_dir, env={**_env(), **env},
            capture_output=True, text=True, check=False,
        )  # fmt: skip
        assert run.returncode == 0, command + "\n" + run.stderr
    for shot in shots:
        assert (project / "out" / f"{Path(shot).stem}.mcap").stat().st_size > 0
        assert (project / "out" / f"{Path(shot).stem}.summary.json").is_file()


def test_opencue_failing_frame_exits_3(tmp_path: Path) -> None:
    spec = tmp_path / "job.xml"
    farm.export_opencue([str(SAMPLES / "unreachable.usda")], spec, options=_options())
    _, commands, env = _frame_commands(spec)
    run = subprocess.run(commands[0], shell=True, env={**_env(), **env}, capture_output=True,
                         text=True, check=False)  # fmt: skip
    assert run.returncode == 3, run.stderr
    # the task's log names its shot, as a task that succeeds does
    assert f"note: task 1 of job.tasks.json: the shot {SAMPLES / 'unreachable.usda'}" in \
        run.stderr.splitlines()
    assert not (tmp_path / "unreachable.mcap").exists()
    assert _run("farm", "run-task", str(tmp_path / "job.tasks.json"), "2").returncode == 2


def test_missing_farm_extra_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    options = _options()
    shot = str(SAMPLES / "blender_crane_up.usda")
    monkeypatch.setitem(sys.modules, "openjd.model", None)
    with pytest.raises(InputError, match=r"farm export needs the farm extra: pip install"):
        farm.export_openjd([shot], tmp_path / "j.yaml", options=options)
    monkeypatch.setitem(sys.modules, "outline", None)
    with pytest.raises(InputError, match=r"farm export needs the farm extra: pip install"):
        farm.export_opencue([shot], tmp_path / "j.xml", options=options)
    assert not list(tmp_path.iterdir())


def test_duplicate_stems_are_refused(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    shutil.copy2(SAMPLES / "whip_pan.usda", tmp_path / "a" / "whip_pan.usda")
    shots = [str(SAMPLES / "whip_pan.usda"), str(tmp_path / "a" / "whip_pan.usda")]
    with pytest.raises(InputError, match=r"whip_pan\.mcap"):
        farm.export_openjd(shots, tmp_path / "j.yaml", options=_options())
    with pytest.raises(InputError, match=r"whip_pan\.mcap"):
        farm.export_opencue(shots, tmp_path / "j.xml", options=_options())
    assert not (tmp_path / "j.yaml").exists()
    assert not (tmp_path / "j.xml").exists()


@pytest.mark.parametrize("fmt", ["openjd", "opencue"])
def test_a_bad_lens_or_robot_file_is_refused_at_export(tmp_path: Path, fmt: str) -> None:
    """Every task would fail on the farm with the same error: export says it once, writes
    no job, exits 2."""
    bad = tmp_path / "bad.toml"
    bad.write_text("speed = [\n")
    job = tmp_path / ("job.yaml" if fmt == "openjd" else "job.xml")
    for option, kind in (("--lens", "lens"), ("--robot", "robot")):
        proc = _run("farm", "export", "--format", fmt, str(SAMPLES / "whip_pan.usda"),
                    "-o", str(job), option, str(bad))
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.startswith(f"ERROR: {kind} file {bad}: not valid TOML"), proc.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


@pytest.mark.parametrize("fmt", ["openjd", "opencue"])
def test_an_outdir_the_tasks_cannot_write_is_refused_at_export(tmp_path: Path, fmt: str) -> None:
    """A file where the task outputs' folder would go: every task would fail on the farm, so
    export says so, writes no job and exits 2."""
    (tmp_path / "afile").write_text("not a folder")
    job = tmp_path / ("job.yaml" if fmt == "openjd" else "job.xml")
    proc = _run("farm", "export", "--format", fmt, str(SAMPLES / "whip_pan.usda"), "-o",
                str(job), "--outdir", str(tmp_path / "afile" / "sub"))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == (f"ERROR: cannot write the task output {tmp_path}/afile/sub/"
                           f"whip_pan.mcap: {tmp_path}/afile is a file, not a folder\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_the_openjd_rate_parameter_takes_what_convert_takes(tmp_path: Path) -> None:
    """A rate the task would refuse is refused by the template, before any task runs."""
    job = tmp_path / "job.yaml"
    farm.export_openjd([str(SAMPLES / "whip_pan.usda")], job, options=_options(frames="1:12"),
                       outdir=tmp_path / "out")
    for rate, ok in (("5", False), ("10", True), ("10000", True), ("10001", False)):
        run = _openjd("run", str(job), "-p", f"Rate={rate}", "--tasks", "[]", cwd=tmp_path)
        said = run.stdout + run.stderr
        assert ("Rate" in said and run.returncode != 0) != ok, (rate, said[-2000:])


def test_every_convert_option_reaches_the_openjd_task(tmp_path: Path) -> None:
    robot = tmp_path / "robot.toml"
    shutil.copy2(ROOT / "camtraj" / "data" / "robot.toml", robot)
    lens = tmp_path / "lens.toml"
    shutil.copy2(ROOT / "camtraj" / "data" / "lenses" / "cine_zoom_24-290.toml", lens)
    options = _options(
        camera="/World/cam", robot=str(robot), placement="1,-2,0,90", frames="1:5",
        timing="scale", start_from="0,0,0,0,-90,0,0,0", objective="paper",
        focal_length_unit="mm", edges="fast", lens=str(lens),
    )  # fmt: skip
    options = replace(options, clearance=0.1)
    # every field away from its default: every flag convert has (--edges and --lens were a
    # KeyError traceback in farm export --format openjd)
    assert all(getattr(options, f.name) != f.default for f in fields(ConvertOptions)
               if f.name not in ("rate", "set_file")), options
    job = tmp_path / "jobs" / "j.yaml"
    farm.export_openjd([str(SAMPLES / "orbit_animated_parent.usda")], job, options=options,
                       relative=True)  # fmt: skip
    template = yaml.safe_load(job.read_text())
    defaults = {p["name"]: p.get("default") for p in template["parameterDefinitions"]}
    assert defaults["Camera"] == "/World/cam"
    assert defaults["Robot"] == "../robot.toml"
    assert defaults["Placement"] == "1.0,-2.0,0.0,90.0"
    assert defaults["Frames"] == "1:5"
    assert defaults["Timing"] == "scale"
    assert defaults["StartFrom"] == "0.0,0.0,0.0,0.0,-90.0,0.0,0.0,0.0"
    assert defaults["Objective"] == "paper"
    assert defaults["FocalLengthUnit"] == "mm" and defaults["Clearance"] == "0.1"
    assert defaults["Edges"] == "fast" and defaults["Lens"] == "../lens.toml"
    args = template["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[args.index("--robot") + 1] == "{{Param.JobDir}}/{{Param.Robot}}"
    assert args[args.index("--lens") + 1] == "{{Param.JobDir}}/{{Param.Lens}}"
    assert args[args.index("--edges") + 1] == "{{Param.Edges}}"
    assert _openjd("check", str(job)).returncode == 0


def _rig_camera_count(path: Path) -> int:
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    return sum(1 for p in stage.Traverse() if p.IsA(UsdGeom.Camera))


def test_usd_rig_layers_in_openjd_and_opencue_jobs(project: Path, tmp_path: Path) -> None:
    shot = str(project / "shots" / "orbit.usda")
    job = project / "jobs" / "rig.yaml"
    proc = _run("farm", "export", "--format", "openjd", shot, "-o", str(job), *FRAMES,
                "--outdir", str(project / "jd"), "--usd")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    space = yaml.safe_load(job.read_text())["steps"][0]["parameterSpace"]
    assert space["combination"] == "(Shot, Output, Summary, RigLayer)"
    run = _openjd("run", str(job), cwd=project)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    assert _rig_camera_count(project / "jd" / "orbit.rig.usda") == 1

    spec = project / "jobs" / "rig.xml"
    farm.export_opencue([shot], spec, options=_options(frames="1:12"), outdir=project / "cue",
                        rig_layers=True)  # fmt: skip
    _, commands, env = _frame_commands(spec)
    run2 = subprocess.run(commands[0], shell=True, cwd=tmp_path, env={**_env(), **env},
                          capture_output=True, text=True, check=False)  # fmt: skip
    assert run2.returncode == 0, run2.stderr
    assert _rig_camera_count(project / "cue" / "orbit.rig.usda") == 1


@pytest.mark.parametrize("key", ["output", "summary"])
def test_a_task_cannot_write_over_its_own_manifest(tmp_path: Path, key: str) -> None:
    """Trial 22: a manifest whose task's output (or summary) was the manifest itself ran,
    exit 0, and the manifest became MCAP bytes (or a summary)."""
    manifest = tmp_path / "job.tasks.json"
    task = {"shot": str(SAMPLES / "maya_dolly_push_in.usda"), "output": "t.mcap",
            "summary": "t.json", key: manifest.name}
    manifest.write_text(json.dumps({"format": farm.MANIFEST_FORMAT, "options": {},
                                    "camtraj_version": camtraj.__version__, "tasks": [task]}),
                        encoding="utf-8")
    before = manifest.read_bytes()
    run = _run("farm", "run-task", str(manifest), "1")
    assert run.returncode == 2, run.stderr
    assert "it is the task manifest" in run.stderr, run.stderr
    assert manifest.read_bytes() == before and not (tmp_path / "t.mcap").exists()
