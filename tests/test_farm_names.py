"""Farm jobs for files whose names the job formats would read as syntax (issue 8 §3).

OpenJD reads task-parameter values and the job name as format strings (``{{ ... }}``);
Cuebot substitutes ``#IFRAME#`` and its other tokens in the command text. A job for such a
name must still convert exactly that file: checked with ``openjd check`` / ``openjd run`` and
by doing what Cuebot and RQD do with an OpenCue frame command.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from camtraj import farm
from camtraj.errors import InputError
from tests.test_farm import SAMPLES, _env, _openjd, _options

yaml = pytest.importorskip("yaml")
pytest.importorskip("openjd.model")
pytest.importorskip("outline")

BRACED = ["a{{Param.Timing}}b", "odd {{ brace", "close}} {x}"]


def _project(tmp_path: Path, stems: list[str], folder: str = "shots") -> list[str]:
    shots = tmp_path / folder
    shots.mkdir(parents=True)
    for stem in stems:
        shutil.copy2(SAMPLES / "blender_crane_up.usda", shots / f"{stem}.usda")
    return [str(shots / f"{stem}.usda") for stem in stems]


def test_openjd_job_for_braced_names_converts_those_files(tmp_path: Path) -> None:
    shots = _project(tmp_path, BRACED)
    job = tmp_path / "job.yaml"
    farm.export_openjd(shots, job, options=_options(frames="1:6"), outdir=tmp_path / "out",
                       name="shots {{ of the day")  # fmt: skip
    check = _openjd("check", str(job))
    assert check.returncode == 0, check.stdout + check.stderr
    run = _openjd("run", str(job), cwd=tmp_path)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr
    for shot in shots:
        stem = Path(shot).stem
        summary = json.loads((tmp_path / "out" / f"{stem}.summary.json").read_text())
        assert summary["shot"] == shot  # the task got exactly this path
        assert (tmp_path / "out" / f"{stem}.mcap").stat().st_size > 0


def test_openjd_plain_names_need_no_brace_parameters(tmp_path: Path) -> None:
    shots = _project(tmp_path, ["plain"])
    job = tmp_path / "job.yaml"
    farm.export_openjd(shots, job, options=_options(frames="1:6"))
    template = yaml.safe_load(job.read_text())
    names = {p["name"] for p in template["parameterDefinitions"]}
    assert not names & {"CamtrajLeftBrace", "CamtrajRightBrace"}
    ranges = template["steps"][0]["parameterSpace"]["taskParameterDefinitions"]
    assert ranges[0]["range"] == shots


def _cuebot(command: str, frame: int, layer: str, job: str) -> str:
    """What Cuebot's dispatcher does to a frame's command (its five token replacements)."""
    return (command.replace("#ZFRAME#", f"{frame:04d}").replace("#IFRAME#", str(frame))
            .replace("#LAYER#", layer).replace("#JOB#", job)
            .replace("#FRAME#", f"{frame:04d}-{layer}"))  # fmt: skip


@pytest.mark.parametrize("relative", [False, True], ids=["absolute", "relative"])
def test_opencue_job_file_with_frame_tokens_runs(tmp_path: Path, relative: bool) -> None:
    shots = _project(tmp_path, ["one", "two #LAYER#"], folder="jobs #JOB# here")
    spec = tmp_path / "jobs #JOB# here" / "job#IFRAME#.xml"
    farm.export_opencue(shots, spec, options=_options(frames="1:6"), outdir=tmp_path / "out",
                        relative=relative)  # fmt: skip
    root = ET.parse(spec).getroot()
    layer = root.find("./job/layers/layer")
    assert layer is not None
    command = layer.findtext("cmd") or ""
    assert command.count("#IFRAME#") == 1  # only the frame number itself
    env = {k.get("name", ""): k.text or "" for k in root.findall("./job/env/key")}
    for frame, shot in enumerate(shots, start=1):
        line = _cuebot(command, frame, layer.get("name", "convert"), "camtraj_job")
        run = subprocess.run(line, shell=True, cwd=tmp_path, env={**_env(), **env},
                             capture_output=True, text=True, check=False)  # fmt: skip
        assert run.returncode == 0, line + "\n" + run.stderr
        summary = json.loads((tmp_path / "out" / f"{Path(shot).stem}.summary.json").read_text())
        assert Path(summary["shot"]).resolve() == Path(shot).resolve()


def test_focal_length_unit_reaches_both_job_formats(tmp_path: Path) -> None:
    shots = _project(tmp_path, ["plain"])
    options = _options(frames="1:6", focal_length_unit="mm")
    job = tmp_path / "job.yaml"
    farm.export_openjd(shots, job, options=options)
    template = yaml.safe_load(job.read_text())
    defaults = {p["name"]: p.get("default") for p in template["parameterDefinitions"]}
    assert defaults["FocalLengthUnit"] == "mm"
    args = template["steps"][0]["script"]["actions"]["onRun"]["args"]
    assert args[args.index("--focal-length-unit") + 1] == "{{Param.FocalLengthUnit}}"
    assert _openjd("check", str(job)).returncode == 0
    _, manifest = farm.export_opencue(shots, tmp_path / "job.xml", options=options)
    assert json.loads(manifest.read_text())["options"]["focal_length_unit"] == "mm"


def test_an_invalid_openjd_template_is_a_one_line_error(tmp_path: Path) -> None:
    shots = _project(tmp_path, ["plain"])
    with pytest.raises(InputError) as info:
        farm.export_openjd(shots, tmp_path / "job.yaml", options=_options(), name="x" * 200)
    assert "\n" not in str(info.value)
    assert "128 characters" in str(info.value)
    assert not (tmp_path / "job.yaml").exists()
