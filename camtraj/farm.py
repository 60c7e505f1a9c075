"""Render-farm jobs: ``camtraj farm export`` and ``camtraj farm run-task``.

One farm task converts one shot. Two job formats:

**Open Job Description** (``--format openjd``; the format behind AWS Deadline Cloud; runs
locally with ``openjd run JOB.yaml``). One step, ``Convert``, whose tasks are the shots: the
task parameters ``Shot``, ``Output`` and ``Summary`` are zipped (``combination: "(Shot,
Output, Summary)"``), and each task runs ``camtraj convert SHOT -o OUTPUT --summary SUMMARY``
plus the convert options. OpenJD passes each argument as one argv word (no shell), and every
value the user chose (paths, camera prim, ...) travels as a parameter *value*, never as template
text, so spaces and quotes in names are safe; task-parameter values and the job name are
format strings, so a ``{`` or ``}`` in them is spelled as a reference to the job parameters
``CamtrajLeftBrace`` / ``CamtrajRightBrace`` (added only when needed). The convert options
are job parameters (``Timing``, ``Rate``, and ``Camera``, ``Robot``, ``Placement``, ``Frames``
when given) whose defaults are the exported values (likewise ``SetFile``, ``StartFrom``,
``Objective``, ``FocalLengthUnit``), so they can be changed at submission; ``CamtrajCommand``
is the camtraj executable on the render hosts. YAML, or JSON when the job file ends in ``.json``.

**OpenCue** (``--format opencue``): a job spec XML (``cjsl`` DTD) built with opencue-pyoutline
(an ``Outline`` with one ``Shell`` layer, serialised *without* the pycuerun wrapper, so render
hosts need only camtraj) and a task manifest ``JOB.tasks.json`` beside it. The layer has frame
range ``1-N`` and chunk 1; frame *i* is the *i*-th shot. Its command is the same for every frame,
as OpenCue requires::

    camtraj farm run-task /abs/path/JOB.tasks.json #IFRAME#

Cuebot replaces ``#IFRAME#`` with the frame number and RQD runs the line through a shell;
``run-task`` reads the manifest and converts entry *i*. The manifest (not the command line)
carries the shot list, so names need no shell quoting beyond the manifest path itself
(``shlex.quote``, with every ``#`` outside the quotes as ``\\#`` so that no Cuebot token such
as ``#IFRAME#`` can match inside a path), and a job of many shots stays within Cuebot's
4000-character command limit.

**Paths** are absolute by default. With ``--relative-paths`` they are relative to the job file's
folder: in OpenJD through the ``JobDir`` PATH parameter (default ``.``, which OpenJD resolves
against the template's folder at submission, so the folder can move or be path-mapped); in
OpenCue, the manifest's entries are relative to the manifest, the command names the manifest
relative to ``$CAMTRAJ_JOB_DIR``, and the job environment sets ``CAMTRAJ_JOB_DIR`` to the job
folder at export: the one place that names an absolute location.

Every job states the camtraj version that made it (OpenJD: ``description`` and a header comment;
OpenCue: the ``CAMTRAJ_JOB_VERSION`` job environment variable, a comment and the manifest).

The farm formats need the ``farm`` extra: ``pip install '.[farm]'`` in a camtraj clone.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import shlex
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import click

from camtraj import __version__, jsonsafe
from camtraj.batch import output_names
from camtraj.choices import FOCAL_LENGTH_UNITS, OBJECTIVES, TIMING_MODES
from camtraj.errors import CamtrajError, InfeasibleError, InputError, failure_lines
from camtraj.folders import check_can_make
from camtraj.inputs import files_read, one_line, parse_json, read_text, require_regular_file
from camtraj.options import (
    EDGE_OPTIONS,
    RATE_RANGE,
    ConvertOptions,
    build_options,
    convert_options,
    more_convert_options,
    option_values,
    options_from_json,
    options_to_json,
    rig_layer_flag,
    rig_layer_for,
)
from camtraj.outputs import OutputSet, refuse_overlaps

__all__ = [
    "FARM_EXTRA_MESSAGE",
    "MANIFEST_FORMAT",
    "export_opencue",
    "export_openjd",
    "farm_group",
    "manifest_path_for",
    "openjd_template",
    "run_task",
]

FARM_EXTRA_MESSAGE = "farm export needs the farm extra: pip install '.[farm]' in a camtraj clone"
MANIFEST_FORMAT = "camtraj-farm-tasks-1"
JOB_DIR_ENV = "CAMTRAJ_JOB_DIR"
VERSION_ENV = "CAMTRAJ_JOB_VERSION"
FRAME_TOKEN = "#IFRAME#"


def _require(module: str, package: str) -> None:
    try:
        __import__(module)
    except ImportError as exc:
        msg = f"{FARM_EXTRA_MESSAGE} (missing {package}: {exc})"
        raise InputError(msg) from exc


class _Paths:
    """Absolute or job-folder-relative spelling of the paths that go into a job."""

    def __init__(self, job_file: Path, *, relative: bool) -> None:
        self.job_dir = job_file.resolve().parent
        self.relative = relative

    def __call__(self, path: str | os.PathLike[str]) -> str:
        absolute = os.path.abspath(path)
        if not self.relative:
            return absolute
        return os.path.relpath(absolute, self.job_dir)


_OPENJD_PARAMS = {
    "--camera": ("Camera", "Camera prim path."),
    "--robot": ("Robot", "Robot description file."),
    "--placement": ("Placement", "Stage-to-robot placement x,y,z [m], yaw [deg]."),
    "--set-file": ("SetFile", "TOML file with a [placement] table."),
    "--frames": ("Frames", "Film frame range A:B."),
    "--start-from": ("StartFrom", "Joint values the robot starts from [m, deg]."),
    "--objective": ("Objective", "IK objective."),
    "--focal-length-unit": ("FocalLengthUnit", "How the shot's focalLength is read."),
    "--clearance": ("Clearance", "Distance [m] kept from the set file's obstacles."),
    "--edges": ("Edges", "Run-up and run-out: gentle, fast or still."),
    "--lens": ("Lens", "Lens file: zoom, focus and iris motors."),
}
"""Job parameter name and description of each optional convert flag."""

_PATH_FLAGS = ("--robot", "--set-file", "--lens")

_BRACE_PARAMS = {"{": "CamtrajLeftBrace", "}": "CamtrajRightBrace"}
"""Job parameters whose values are a literal ``{`` and ``}`` (see :func:`_openjd_literal`)."""


def _openjd_literal(text: str) -> str:
    """``text`` spelled as an OpenJD format string that resolves to exactly ``text``.

    Task-parameter values and the job name are format strings: ``{{ ... }}`` in them is an
    expression (a shot named ``a{{Param.Timing}}b.usda`` would become ``ashotb.usda``, and an
    unbalanced ``{{`` fails validation). The 2023-09 format strings have no escape, so each
    brace becomes a reference to a job parameter whose value is that brace (job parameter
    values are not format strings).
    """
    return "".join(
        "{{Param." + _BRACE_PARAMS[c] + "}}" if c in _BRACE_PARAMS else c for c in text
    )


def _cue_word(text: str) -> str:
    """``text`` as one shell word that no OpenCue frame token can match.

    Cuebot replaces ``#IFRAME#``, ``#ZFRAME#``, ``#LAYER#``, ``#JOB#``, ``#FRAME#`` (and more)
    in the command text before the render host's shell runs it; a job file named
    ``job#IFRAME#.xml`` would put a token into the manifest path. Every ``#`` is written as a
    backslash-escaped ``\\#`` between shell-quoted pieces, which the shell turns back into
    ``#`` and no ``#TOKEN#`` pattern matches.
    """
    if "#" not in text:
        return shlex.quote(text)
    return "\\#".join(shlex.quote(piece) for piece in text.split("#"))


def _portable(options: ConvertOptions, spell: _Paths) -> ConvertOptions:
    """``options`` with its file paths spelled for the job (absolute or job-relative)."""
    return replace(
        options,
        robot=spell(options.robot) if options.robot is not None else None,
        set_file=spell(options.set_file) if options.set_file is not None else None,
        lens=spell(options.lens) if options.lens is not None else None,
    )


def _check_shots(shots: Sequence[str], options: ConvertOptions) -> None:
    """The shots exist, and the robot, lens and set files every task reads can be read (a
    bad one would fail every task on the farm)."""
    if not shots:
        msg = "no shots given"
        raise InputError(msg)
    for shot in shots:
        require_regular_file(shot, "shot", InputError)
        if not Path(shot).is_file():
            msg = f"{one_line(shot)}: no such shot file"
            raise InputError(msg)
    from camtraj.convert import read_shared_inputs

    read_shared_inputs(options)


def _check_job(shots: Sequence[str], outputs: OutputSet, *, outdir: Path,
               options: ConvertOptions, rig_layers: bool) -> None:
    """The job's files and every task's outputs, checked as convert checks its outputs: none
    is an input of the job (a shot, a layer it uses, the robot or set file), no two coincide."""
    inputs = files_read(shots, options)
    outputs.refuse_inputs(inputs)
    planned = [(p, f"{label} {one_line(p)}") for m, j in output_names(shots, outdir)
               for p, label in ((m, "the task output"), (j, "the task summary"),
                                *([(rig_layer_for(m), "the task rig layer")] if rig_layers
                                  else []))]
    refuse_overlaps([*((p, f"-o {one_line(p)}") for p in outputs.paths), *planned], inputs)
    firsts = {Path(p).parent: p for p, _ in reversed(planned)}  # the tasks write there later
    for p in firsts.values():
        check_can_make(p, "the task output")


# --------------------------------------------------------------------------------------------
# Open Job Description.
# --------------------------------------------------------------------------------------------


def openjd_template(
    shots: Sequence[str],
    job_file: Path,
    *,
    outdir: Path,
    options: ConvertOptions,
    relative: bool = False,
    executable: str = "camtraj",
    name: str | None = None,
    rig_layers: bool = False,
) -> dict[str, Any]:
    """Build the Open Job Description job template (specification ``jobtemplate-2023-09``).

    Args:
        shots: USD shot paths (distinct stems).
        job_file: Where the template will be written (relative paths start at its folder).
        outdir: Folder for ``<stem>.mcap`` and ``<stem>.summary.json``.
        options: Convert options for every task.
        relative: Write paths relative to the job file's folder.
        executable: The camtraj command on the render hosts.
        name: Job name (default: ``camtraj: N shots``).
        rig_layers: Each task also writes the shot's USD rig layer, ``<stem>.rig.usda``
            (task parameter ``RigLayer``).

    Returns:
        The template as a JSON/YAML-able dict.
    """
    spell = _Paths(job_file, relative=relative)
    names = output_names(shots, outdir)
    prefix = "{{Param.JobDir}}/" if relative else ""

    params: list[dict[str, Any]] = []
    if relative:
        params.append(
            {
                "name": "JobDir",
                "type": "PATH",
                "objectType": "DIRECTORY",
                "default": ".",
                "description": "The folder every relative path of this job starts from "
                "(the job file's folder).",
            }
        )
    literal_braces = any(
        c in text
        for text in [name or "", *(spell(s) for s in shots),
                     *(spell(p) for pair in names for p in pair)]
        for c in _BRACE_PARAMS
    )
    if literal_braces:
        params += [
            {
                "name": param,
                "type": "STRING",
                "default": brace,
                "allowedValues": [brace],
                "description": f"A literal {brace} in this job's paths (format strings have "
                "no escape).",
            }
            for brace, param in _BRACE_PARAMS.items()
        ]
    params.append(
        {
            "name": "CamtrajCommand",
            "type": "STRING",
            "minLength": 1,
            "default": executable,
            "description": "The camtraj command on the render hosts.",
        }
    )
    params.append(
        {
            "name": "Timing",
            "type": "STRING",
            "allowedValues": list(TIMING_MODES),
            "default": options.timing,
            "description": "shot: keep the shot's timing; scale: slow it to fit the limits; "
            "optimal: retime time-optimally under velocity, acceleration and jerk limits.",
        }
    )
    params.append(
        {
            "name": "Rate",
            "type": "FLOAT",
            "minValue": RATE_RANGE[0],
            "maxValue": RATE_RANGE[1],
            "default": float(options.rate),
            "description": "Servo rate [Hz].",
        }
    )
    args: list[str] = [
        "convert",
        prefix + "{{Task.Param.Shot}}",
        "-o",
        prefix + "{{Task.Param.Output}}",
        "--summary",
        prefix + "{{Task.Param.Summary}}",
        "--timing",
        "{{Param.Timing}}",
        "--rate",
        "{{Param.Rate}}",
    ]
    task_params: list[dict[str, Any]] = [
        {"name": "Shot", "type": "PATH", "range": [_openjd_literal(spell(s)) for s in shots]},
        {"name": "Output", "type": "PATH",
         "range": [_openjd_literal(spell(m)) for m, _ in names]},
        {"name": "Summary", "type": "PATH",
         "range": [_openjd_literal(spell(j)) for _, j in names]},
    ]
    if rig_layers:
        task_params.append(
            {"name": "RigLayer", "type": "PATH",
             "range": [_openjd_literal(spell(rig_layer_for(m))) for m, _ in names]}
        )
        args += ["--usd", prefix + "{{Task.Param.RigLayer}}"]
    portable = _portable(options, spell)
    for flag, value in option_values(portable):
        if flag in ("--rate", "--timing"):
            continue
        param, description = _OPENJD_PARAMS[flag]
        definition: dict[str, Any] = {"name": param, "type": "STRING", "minLength": 1}
        if flag == "--objective":
            definition["allowedValues"] = list(OBJECTIVES)
        if flag == "--focal-length-unit":
            definition["allowedValues"] = list(FOCAL_LENGTH_UNITS)
        if flag == "--edges":
            definition["allowedValues"] = list(EDGE_OPTIONS)
        definition["default"] = value
        is_path = flag in _PATH_FLAGS
        definition["description"] = description + (
            " Relative to JobDir." if is_path and relative else ""
        )
        params.append(definition)
        args += [flag, (prefix if is_path else "") + "{{Param." + param + "}}"]

    stated = f"Made by camtraj {__version__} (camtraj farm export --format openjd)."
    return {
        "specificationVersion": "jobtemplate-2023-09",
        "name": _openjd_literal(
            name or f"camtraj: {len(shots)} shot{'s' if len(shots) != 1 else ''}"
        ),
        "description": f"{stated} Converts {len(shots)} USD shot(s) into camera-robot moves "
        "(MCAP), one task per shot.",
        "parameterDefinitions": params,
        "steps": [
            {
                "name": "Convert",
                "description": "camtraj convert, one shot per task.",
                "parameterSpace": {
                    "taskParameterDefinitions": task_params,
                    "combination": "(" + ", ".join(p["name"] for p in task_params) + ")",
                },
                "script": {
                    "actions": {
                        "onRun": {"command": "{{Param.CamtrajCommand}}", "args": args},
                    },
                },
            }
        ],
    }


def _validate_openjd(template: dict[str, Any], job_dir: Path) -> None:
    """Decode the template and instantiate a job from it, as ``openjd run`` would.

    Raises:
        InputError: The template does not validate.
    """
    from openjd.model import (
        DecodeValidationError,
        create_job,
        decode_job_template,
        preprocess_job_parameters,
    )

    try:
        decoded = decode_job_template(template=template)
        values = preprocess_job_parameters(
            job_template=decoded,
            job_parameter_values={},
            job_template_dir=job_dir,
            current_working_dir=Path.cwd(),
        )
        create_job(job_template=decoded, job_parameter_values=values)
    except (DecodeValidationError, ValueError) as exc:
        detail = "; ".join(" ".join(line.split()) for line in str(exc).splitlines() if line.strip())
        msg = f"the Open Job Description template does not validate: {detail}"
        raise InputError(msg) from exc


def export_openjd(
    shots: Sequence[str],
    job_file: str | os.PathLike[str],
    *,
    options: ConvertOptions,
    outdir: str | os.PathLike[str] | None = None,
    relative: bool = False,
    executable: str = "camtraj",
    name: str | None = None,
    rig_layers: bool = False,
) -> Path:
    """Write an Open Job Description job template converting ``shots``, validated.

    Args:
        shots: USD shot paths (distinct stems).
        job_file: Output path; JSON if it ends in ``.json``, else YAML.
        options: Convert options for every task.
        outdir: Folder for the MCAPs and summaries (default: the job file's folder); each
            task makes it if missing (``camtraj convert`` does).
        relative: Paths relative to the job file's folder (see the module docstring).
        executable: The camtraj command on the render hosts.
        name: Job name.
        rig_layers: Each task also writes ``<stem>.rig.usda`` (``camtraj convert --usd``).

    Returns:
        The job file path.

    Raises:
        InputError: Missing shot, a robot, lens or set file that cannot be read, duplicate
            stems, missing ``farm`` extra, invalid template.
    """
    _require("openjd.model", "openjd-model")
    _require("yaml", "PyYAML")
    _check_shots(shots, options)
    path = Path(job_file)
    out = Path(outdir) if outdir is not None else path.resolve().parent
    with OutputSet() as outputs:
        outputs.add(path, "-o")
        _check_job(shots, outputs, outdir=out, options=options, rig_layers=rig_layers)
        outputs.write_bytes(path, _openjd_text(shots, path, out, options, relative=relative,
                                               executable=executable, name=name,
                                               rig_layers=rig_layers).encode("utf-8"))
        outputs.commit()
    return path


def _openjd_text(shots: Sequence[str], path: Path, out: Path, options: ConvertOptions, *,
                 relative: bool, executable: str, name: str | None, rig_layers: bool) -> str:
    template = openjd_template(
        shots,
        path,
        outdir=out,
        options=options,
        relative=relative,
        executable=executable,
        name=name,
        rig_layers=rig_layers,
    )
    _validate_openjd(template, path.resolve().parent)
    if path.suffix.lower() == ".json":
        text = json.dumps(template, indent=2) + "\n"
    else:
        import yaml

        header = (
            f"# Open Job Description job template made by camtraj {__version__}.\n"
            f"# Run it here with: openjd run {shlex.quote(path.name)}\n"
        )
        text = header + yaml.safe_dump(
            template, sort_keys=False, allow_unicode=True, default_flow_style=False, width=1000
        )
    return text


# --------------------------------------------------------------------------------------------
# OpenCue.
# --------------------------------------------------------------------------------------------


def manifest_path_for(job_file: str | os.PathLike[str]) -> Path:
    """The task manifest that goes with an OpenCue job spec: ``JOB.tasks.json`` beside it."""
    path = Path(job_file)
    return path.with_name(f"{path.stem}.tasks.json")


def _cue_name(text: str) -> str:
    cleaned = re.sub(r"[^A-Za-z0-9_]+", "_", text).strip("_")
    return cleaned or "camtraj"


def export_opencue(
    shots: Sequence[str],
    job_file: str | os.PathLike[str],
    *,
    options: ConvertOptions,
    outdir: str | os.PathLike[str] | None = None,
    relative: bool = False,
    executable: str = "camtraj",
    name: str | None = None,
    show: str | None = None,
    shot: str | None = None,
    rig_layers: bool = False,
) -> tuple[Path, Path]:
    """Write an OpenCue job spec (XML) and its task manifest converting ``shots``.

    Args:
        shots: USD shot paths (distinct stems).
        job_file: Output path of the spec XML.
        options: Convert options for every task.
        outdir: Folder for the MCAPs and summaries (default: the job file's folder).
        relative: Paths relative to the job file's folder (see the module docstring).
        executable: The camtraj command on the render hosts.
        name: Job name (letters, digits, ``_``; default ``camtraj_<job file stem>``).
        show: OpenCue show (default: ``$SHOW`` or outline's configured default).
        shot: OpenCue shot (default: ``$SHOT`` or outline's configured default).
        rig_layers: Each task also writes ``<stem>.rig.usda`` (``camtraj convert --usd``);
            the manifest entry names it as ``rig_layer``.

    Returns:
        The spec path and the manifest path.

    Raises:
        InputError: Missing shot, a robot, lens or set file that cannot be read, duplicate
            stems, missing ``farm`` extra.
    """
    _require("outline", "opencue-pyoutline")
    _check_shots(shots, options)
    path = Path(job_file)
    manifest = manifest_path_for(path)
    out = Path(outdir) if outdir is not None else path.resolve().parent
    with OutputSet() as outputs:
        outputs.add(manifest, "the task manifest")
        outputs.add(path, "-o")
        _check_job(shots, outputs, outdir=out, options=options, rig_layers=rig_layers)
        manifest_data, text = _opencue_files(shots, path, manifest, out, options,
                                             relative=relative, executable=executable,
                                             name=name, show=show, shot=shot,
                                             rig_layers=rig_layers)
        outputs.write_bytes(manifest, (jsonsafe.dumps(manifest_data) + "\n").encode("utf-8"))
        outputs.write_bytes(path, text.encode("utf-8"))
        outputs.commit()
    return path, manifest


def _opencue_files(shots: Sequence[str], path: Path, manifest: Path, out: Path,
                   options: ConvertOptions, *, relative: bool, executable: str,
                   name: str | None, show: str | None, shot: str | None,
                   rig_layers: bool) -> tuple[dict[str, Any], str]:
    """The manifest (as data) and the spec XML (as text) of an OpenCue job."""
    import outline
    import outline.backend.cue
    import outline.cuerun
    from outline.modules.shell import Shell

    spell = _Paths(path, relative=relative)
    names = output_names(shots, out)

    portable = _portable(options, spell)
    tasks: list[dict[str, Any]] = [
        {"frame": i, "shot": spell(s), "output": spell(m), "summary": spell(j)}
        for i, (s, (m, j)) in enumerate(zip(shots, names, strict=True), start=1)
    ]
    if rig_layers:
        for task, (m, _) in zip(tasks, names, strict=True):
            task["rig_layer"] = spell(rig_layer_for(m))
    manifest_data = {
        "format": MANIFEST_FORMAT,
        "camtraj_version": __version__,
        "paths": "relative to this file's folder" if relative else "absolute",
        "options": options_to_json(portable),
        "tasks": tasks,
    }

    manifest_ref = manifest.name if relative else str(manifest.resolve())
    command = " ".join(
        [_cue_word(executable), "farm", "run-task", _cue_word(manifest_ref), FRAME_TOKEN]
    )
    frame_range = f"1-{len(shots)}"
    job_name = _cue_name(name or f"camtraj_{path.stem}")
    ol = outline.Outline(job_name, frame_range=frame_range, show=show, shot=shot, name_unique=False)
    ol.set_env(VERSION_ENV, __version__, pre=True)
    if relative:
        ol.set_env(JOB_DIR_ENV, str(spell.job_dir), pre=True)
    ol.add_layer(Shell("convert", command=command, range=frame_range, chunk=1, cores=1))
    launcher = outline.cuerun.OutlineLauncher(ol, nomail=True)
    # serialize_simple: the layer command runs as is (no pycuerun wrapper, no outline session).
    raw = outline.backend.cue.serialize_simple(launcher)

    head, _, body = raw.partition("<spec>")
    root = ET.fromstring("<spec>" + body)
    ET.indent(root)
    doctype = head[head.index("<!DOCTYPE") :] if "<!DOCTYPE" in head else ""
    text = (
        '<?xml version="1.0"?>\n'
        f"{doctype}\n"
        f"<!-- OpenCue job spec made by camtraj {__version__}: frame N converts shot N "
        f"of {manifest.name} -->\n" + ET.tostring(root, encoding="unicode") + "\n"
    )
    return manifest_data, text


def run_task(manifest: str | os.PathLike[str], index: int) -> dict[str, Any]:
    """Convert task ``index`` (1-based, the OpenCue frame number) of a task manifest.

    A relative ``manifest`` is taken relative to ``$CAMTRAJ_JOB_DIR`` when that is set, else to
    the working folder. Paths inside the manifest that are relative start at its folder.

    Returns:
        The convert summary (also written to the task's summary file).

    Raises:
        InputError: Unreadable manifest, index out of range, bad input shot.
        InfeasibleError: The shot cannot be done as asked.
    """
    from camtraj.convert import convert

    path = Path(manifest)
    job_dir = os.environ.get(JOB_DIR_ENV)
    if not path.is_absolute() and job_dir:
        path = Path(job_dir) / path
    where = f"task manifest {one_line(path)}"
    data = parse_json(read_text(path, "task manifest", InputError), where, InputError)
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        msg = f"{where}: not a camtraj task manifest (format {MANIFEST_FORMAT})"
        raise InputError(msg)
    tasks = data.get("tasks")
    if not isinstance(tasks, list) or not tasks:
        msg = f"{where}: \"tasks\" must be a non-empty list"
        raise InputError(msg)
    if not 1 <= index <= len(tasks):
        msg = f"{where}: task {index} does not exist; the manifest has tasks 1-{len(tasks)}"
        raise InputError(msg)
    task = tasks[index - 1]
    keys = ("shot", "output", "summary")
    if not isinstance(task, dict) or not all(_is_path(task.get(k)) for k in keys) or (
            task.get("rig_layer") is not None and not _is_path(task["rig_layer"])):
        msg = (f"{where}: task {index} must name its shot, output and summary (and optional "
               "rig_layer) as non-empty path strings")
        raise InputError(msg)
    options = _manifest_options(data.get("options"), where)
    made_with = data.get("camtraj_version")
    if made_with != __version__:  # held: shown when the task succeeds (a failure is one line)
        logging.getLogger("camtraj").warning(
            "%s was made by camtraj %s; this is %s", one_line(path.name), made_with, __version__)
    base = path.resolve().parent
    shot, output, summary = (os.path.normpath(base / task[k]) for k in keys)
    options = replace(
        options,
        robot=os.path.normpath(base / options.robot) if options.robot is not None else None,
        set_file=os.path.normpath(base / options.set_file) if options.set_file else None,
        lens=os.path.normpath(base / options.lens) if options.lens else None,
    )
    rig = os.path.normpath(base / task["rig_layer"]) if task.get("rig_layer") else None
    # the MCAP, the summary and the rig layer are one result: all written or none (a failed
    # task leaves every file as it was)
    try:
        result: dict[str, Any] = convert(shot, output, options, summary_path=summary,
                                         rig_layer=rig,
                                         more_inputs=[(path, "the task manifest")])
    except InfeasibleError as exc:  # the log names its shot, as a task that succeeds does (a
        # bad input's message names its file already)
        exc.add_note(f"task {index} of {one_line(path.name)}: the shot {one_line(shot)}")
        raise
    return result


def _is_path(value: Any) -> bool:
    return isinstance(value, str) and bool(value) and "\0" not in value


_OPTION_TYPES: dict[str, tuple[str, int]] = {
    # field: (kind, count): "str", "path", "number", or "numbers"/"ints" with a count
    "camera": ("str", 0), "robot": ("path", 0), "set_file": ("path", 0),
    "placement": ("numbers", 4), "frames": ("ints", 2), "rate": ("number", 0),
    "timing": ("str", 0), "start_from": ("numbers", 8), "objective": ("str", 0),
    "focal_length_unit": ("str", 0), "clearance": ("number", 0), "lens": ("path", 0),
}


def _manifest_options(data: Any, where: str) -> ConvertOptions:
    """The manifest's convert options, each checked for its type before use."""
    if not isinstance(data, dict):
        msg = f"{where}: \"options\" must be a table of convert options"
        raise InputError(msg)
    for key, value in data.items():
        kind, count = _OPTION_TYPES.get(key, ("", 0))
        if value is None or not kind:
            continue  # an unknown option is named by options_from_json
        number = isinstance(value, int | float) and not isinstance(value, bool)
        ok = {
            "str": isinstance(value, str),
            "path": _is_path(value),
            "number": number and math.isfinite(value),
            "numbers": isinstance(value, list) and len(value) == count and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in value),
            "ints": isinstance(value, list) and len(value) == count and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value),
        }[kind]
        if not ok:
            msg = f"{where}: option {key} = {json.dumps(value)[:60]} is not a valid value"
            raise InputError(msg)
    frames = data.get("frames")
    if frames is not None and frames[0] > frames[1]:
        msg = f"{where}: option frames = {frames} ends before it starts"
        raise InputError(msg)
    try:
        return options_from_json(data)
    except InputError as exc:
        msg = f"{where}: {exc}"
        raise InputError(msg) from None


# --------------------------------------------------------------------------------------------
# Commands.
# --------------------------------------------------------------------------------------------


@click.group("farm")
def farm_group() -> None:
    """Render-farm jobs (Open Job Description / AWS Deadline Cloud, OpenCue): one task per shot."""


@farm_group.command("export")
@click.option(
    "--format",
    "job_format",
    type=click.Choice(["openjd", "opencue"]),
    required=True,
    help="openjd: OpenJD job template (YAML, or JSON for a .json file); "
    "opencue: OpenCue job spec XML plus JOB.tasks.json.",
)
@click.argument("shots", nargs=-1, required=True, type=click.Path())
@click.option(
    "-o", "--output", "job_file", required=True, type=click.Path(), help="Job file."
)
@click.option(
    "--outdir",
    type=click.Path(),
    help="Folder the tasks write NAME.mcap and NAME.summary.json to (default: the job file's).",
)
@click.option(
    "--relative-paths",
    is_flag=True,
    help="Write paths relative to the job file's folder instead of absolute.",
)
@click.option(
    "--executable",
    default="camtraj",
    show_default=True,
    help="The camtraj command on the render hosts.",
)
@click.option("--name", help="Job name.")
@click.option(
    "--cue-show", "show", help="OpenCue show name (default: $SHOW or the outline config's)."
)
@click.option(
    "--cue-shot", "cue_shot", help="OpenCue shot name (default: $SHOT or the outline config's)."
)
@convert_options
@more_convert_options
@rig_layer_flag
@click.pass_context
def export_command(
    ctx: click.Context,
    /,
    job_format: str,
    shots: tuple[str, ...],
    job_file: str,
    outdir: str | None,
    relative_paths: bool,
    executable: str,
    name: str | None,
    show: str | None,
    cue_shot: str | None,
    rig_layers: bool,
    **option_args: Any,
) -> None:
    """Write a farm job that converts SHOTS, one task per shot.

    \b
    openjd   a job template; try it here: openjd check JOB.yaml; openjd run JOB.yaml
    opencue  a job spec XML and JOB.tasks.json beside it; frame N of its one layer
             runs: camtraj farm run-task JOB.tasks.json N

    Each task writes OUTDIR/NAME.mcap and NAME.summary.json for a shot NAME.usd*
    (and NAME.rig.usda with --usd).
    """
    try:
        options = build_options(**option_args)
        if job_format == "openjd":
            path = export_openjd(
                shots,
                job_file,
                options=options,
                outdir=outdir,
                relative=relative_paths,
                executable=executable,
                name=name,
                rig_layers=rig_layers,
            )
            click.echo(f"wrote {path} ({len(shots)} task(s)); run it here with: openjd run "
                       f"{shlex.quote(str(path))}")
        else:
            path, manifest = export_opencue(
                shots,
                job_file,
                options=options,
                outdir=outdir,
                relative=relative_paths,
                executable=executable,
                name=name,
                show=show,
                shot=cue_shot,
                rig_layers=rig_layers,
            )
            click.echo(f"wrote {path} and {manifest} (frames 1-{len(shots)}, one per shot)")
    except CamtrajError as exc:
        for line in failure_lines(exc):
            click.echo(line, err=True)
        ctx.exit(exc.exit_code)


@farm_group.command("run-task")
@click.argument("manifest", type=click.Path())
@click.argument("index", type=click.IntRange(min=1))
@click.pass_context
def run_task_command(ctx: click.Context, manifest: str, index: int) -> None:
    """Convert shot INDEX (1-based; the OpenCue frame) of a task MANIFEST.

    Exit codes as for camtraj convert: 0 ok, 2 bad input, 3 infeasible.
    """
    try:
        result = run_task(manifest, index)
    except CamtrajError as exc:
        for line in failure_lines(exc):
            click.echo(line, err=True)
        ctx.exit(exc.exit_code)
    click.echo(f"camtraj {__version__}, task {index}: {result.get('shot')}: "
               f"{result.get('status')}, wrote {result.get('output')}")
