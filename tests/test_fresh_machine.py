"""A fresh machine and a newcomer (issue 8, §6): the Makefile's Python checks, the progress
display under a real pseudo-terminal, ``info`` on a shot, the ``-o`` extension warning, the
batch summary line, the output-folder rule and the long-shot flag of make_samples.py.
"""

from __future__ import annotations

import fcntl
import glob
import io
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from pxr import Usd

from camtraj.batch import REPORT_NAME, run_batch
from camtraj.convert import convert
from camtraj.mcap_io import read_take
from camtraj.options import ConvertOptions
from camtraj.progress import TerminalProgress
from tests.test_convert import ROOT, SHOTS, error_line, run_cli

MAYA = SHOTS / "maya_dolly_push_in.usda"
BLENDER = SHOTS / "blender_crane_up.usda"
UNREACHABLE = SHOTS / "unreachable.usda"
MAKE = shutil.which("make")


# --------------------------------------------------------------------------------------------
# Makefile: a too-old Python, a broken or foreign venv
# --------------------------------------------------------------------------------------------


def _version_of(python: str) -> str | None:
    """``major.minor`` of an interpreter, or None when it does not run (e.g. a pyenv shim of a
    version that is not selected)."""
    try:
        out = subprocess.run([python, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
                             capture_output=True, text=True, timeout=60, check=False)
    except OSError:
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def _python(version: str) -> str | None:
    """A real interpreter of ``version`` (e.g. "3.10") on this machine, if there is one."""
    pyenv = sorted(glob.glob(os.path.expanduser(f"~/.pyenv/versions/{version}.*/bin/python3")))
    candidates = [shutil.which(f"python{version}"), *reversed(pyenv)]
    return next((c for c in candidates if c and _version_of(c) == version), None)


def _make(*args: str) -> subprocess.CompletedProcess[str]:
    """A fresh ``make`` in the project (not a sub-make of a ``make test`` that runs this)."""
    assert MAKE is not None
    env = {k: v for k, v in os.environ.items()
           if k not in ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "PYTHON", "VENV", "ARGS")}
    return subprocess.run([MAKE, "--no-print-directory", "-C", str(ROOT), *args], env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def _make_message(proc: subprocess.CompletedProcess[str]) -> str:
    """The one ``make: ...`` line of the check (make adds its own ``***`` line after it)."""
    assert proc.returncode != 0
    ours = [ln for ln in proc.stderr.splitlines() if not re.match(r"make(\[\d+\])?: \*\*\*", ln)]
    assert len(ours) == 1, proc.stderr
    return ours[0]


def _venv(python: str, where: Path) -> Path:
    subprocess.run([python, "-m", "venv", "--without-pip", str(where)], check=True,
                   capture_output=True, timeout=300)
    return where


needs_make = pytest.mark.skipif(MAKE is None, reason="needs make")
OLD = _python("3.10")


@needs_make
@pytest.mark.skipif(OLD is None, reason="needs a Python 3.10 on this machine")
def test_make_refuses_a_too_old_python_before_making_a_venv(tmp_path: Path) -> None:
    venv = tmp_path / "venv"
    proc = _make("lint", f"PYTHON={OLD}", f"VENV={venv}")
    line = _make_message(proc)
    assert "3.10" in line and "needs 3.11" in line and "PYTHON=python3.11" in line
    assert not venv.exists()


@needs_make
@pytest.mark.skipif(OLD is None, reason="needs a Python 3.10 on this machine")
def test_make_refuses_a_venv_made_by_a_too_old_python(tmp_path: Path) -> None:
    assert OLD is not None
    venv = _venv(OLD, tmp_path / "venv")
    (venv / ".installed").touch()  # even one that looks installed
    line = _make_message(_make("lint", f"VENV={venv}"))
    assert "made by Python 3.10" in line and "make clean" in line


@needs_make
def test_make_refuses_a_venv_whose_python_is_gone(tmp_path: Path) -> None:
    # What is left when the interpreter a venv was made from is uninstalled or moved.
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").symlink_to(tmp_path / "uninstalled" / "python3.11")
    (venv / ".installed").touch()
    proc = _make("unit", f"VENV={venv}")
    line = _make_message(proc)
    assert "broken" in line and "make clean" in line
    assert "pytest" not in proc.stdout  # nothing ran with it


@needs_make
def test_make_refuses_a_half_made_venv_without_pip(tmp_path: Path) -> None:
    venv = _venv(sys.executable, tmp_path / "venv")  # as python3 -m venv leaves it without
    line = _make_message(_make("lint", f"VENV={venv}"))  # ensurepip (no python3-venv)
    assert "has no pip" in line and "make clean" in line


@needs_make
def test_make_tells_an_explicit_python_from_the_venvs(tmp_path: Path) -> None:
    here = _version_of(sys.executable)
    venv = _venv(sys.executable, tmp_path / "venv")
    (venv / ".installed").touch()
    ok = _make("-n", "bench", f"PYTHON={sys.executable}", f"VENV={venv}", "ARGS=--quick")
    assert ok.returncode == 0, ok.stderr
    assert f"{venv}/bin/python bench/run.py --quick" in ok.stdout  # ARGS reach the script
    other = next((p for v in ("3.11", "3.12", "3.13", "3.14") if v != here
                  for p in [_python(v)] if p), None)
    if other is None:
        pytest.skip("needs a second Python 3.11+ on this machine")
    line = _make_message(_make("lint", f"PYTHON={other}", f"VENV={venv}"))
    assert f"is Python {here}, not PYTHON={other}" in line and "VENV=" in line


# --------------------------------------------------------------------------------------------
# make_samples.py --long-shot
# --------------------------------------------------------------------------------------------


def _make_samples(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SHOTS / "make_samples.py"), *args],
                          capture_output=True, text=True, timeout=300, check=False)


@pytest.fixture(scope="module")
def long_shot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The one-minute benchmark shot, written with the documented flag."""
    path = tmp_path_factory.mktemp("long") / "long shot.usda"
    proc = _make_samples("--long-shot", str(path))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(path)
    return path


def test_long_shot_flag_writes_the_one_minute_shot(long_shot: Path, tmp_path: Path) -> None:
    stage = Usd.Stage.Open(str(long_shot))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, 1440.0)
    assert stage.GetTimeCodesPerSecond() == 24.0
    assert stage.GetPrimAtPath("/World/cam").GetTypeName() == "Camera"
    short = tmp_path / "short.usda"
    assert _make_samples("--long-shot", str(short), "--frames", "48").returncode == 0
    assert Usd.Stage.Open(str(short)).GetEndTimeCode() == 48.0
    bad = _make_samples("--long-shot", str(tmp_path / "x.usda"), "--frames", "1")
    assert bad.returncode == 2 and "--frames" in bad.stderr


# --------------------------------------------------------------------------------------------
# Progress: the protocol, and the display under a pseudo-terminal
# --------------------------------------------------------------------------------------------


class _Recorder:
    """A Progress that writes down what it was told."""

    def __init__(self) -> None:
        self.stages: list[tuple[str, int | None, str]] = []
        self.steps: dict[str, int] = {}

    def stage(self, name: str, total: int | None = None, *, unit: str = "step") -> None:
        self.stages.append((name, total, unit))

    def advance(self, n: int = 1) -> None:
        name = self.stages[-1][0]
        self.steps[name] = self.steps.get(name, 0) + n


def test_convert_reports_each_stage_in_order(tmp_path: Path) -> None:
    rec = _Recorder()
    summary = convert(MAYA, tmp_path / "x.mcap", progress=rec)
    frames = summary["frames"]["count"]
    assert [s[0] for s in rec.stages] == ["read", "solve", "time", "write"]
    assert rec.stages[1] == ("solve", frames, "frame")
    assert rec.steps == {"solve": frames}  # every frame solved once, nothing else counted
    rec = _Recorder()
    convert(MAYA, None, progress=rec)  # camtraj check: nothing to write
    assert [s[0] for s in rec.stages] == ["read", "solve", "time"]


def _wait_for(predicate: object, timeout: float = 30.0) -> bool:
    assert callable(predicate)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def test_terminal_progress_redraws_a_silent_stage_and_clears_the_line() -> None:
    out = io.StringIO()
    progress = TerminalProgress("shot.usda", stream=out, refresh_s=0.05)
    progress.stage("read")  # a stage that reports no steps at all
    first = out.getvalue()
    assert "shot.usda: read" in first and re.search(r"\d+\.\d s", first)
    # the background thread redraws it although nothing is reported
    assert _wait_for(lambda: out.getvalue().count("shot.usda: read") >= 3)
    progress.stage("solve", 4, unit="frame")
    progress.advance(3)
    progress.advance(1)
    assert _wait_for(lambda: "4/4 frame" in out.getvalue() and "finishing" in out.getvalue())
    progress.stage("time", 0)  # a stage with no size: its name and elapsed time
    progress.close()
    progress.close()  # idempotent
    text = out.getvalue()
    assert "4/4 frame" in text and "finishing" in text and "shot.usda: time" in text
    assert text.rstrip(" ").endswith("\r")  # the line is cleared at the end
    length = len(text)
    progress.stage("late")
    progress.advance(1)
    assert len(out.getvalue()) == length  # nothing after close


def test_a_stop_as_a_stage_starts_leaves_no_bar_behind(monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C as a stage's bar is first drawn: the line is still cleared, so the ERROR line
    that follows stands alone (it ran on after a bar left behind, on a busy machine)."""
    import tqdm

    out = io.StringIO()
    progress = TerminalProgress("shot.usda", stream=out, refresh_s=60.0)
    progress.stage("read")
    draw = tqdm.tqdm.refresh

    def stopped_while_drawing(bar: Any, *args: Any, **kwargs: Any) -> Any:
        result = draw(bar, *args, **kwargs)
        if "solve" in str(bar.desc):
            raise KeyboardInterrupt
        return result

    monkeypatch.setattr(tqdm.tqdm, "refresh", stopped_while_drawing)
    with pytest.raises(KeyboardInterrupt):
        progress.stage("solve", 1440, unit="frame")
    monkeypatch.setattr(tqdm.tqdm, "refresh", draw)
    progress.close()
    text = out.getvalue()
    assert "shot.usda: solve" in text  # it was drawn
    assert text.split("\r")[-1].strip() == ""  # and cleared: nothing left on the line


def _run_on_tty(args: Sequence[object], timeout: float = 600.0) -> tuple[int, str, str]:
    """Run ``python -m camtraj ARGS`` with stderr on a pseudo-terminal (100 columns) and stdout
    on a pipe; return the exit code, stdout and everything the terminal received."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "100"}
    proc = subprocess.Popen([sys.executable, "-m", "camtraj", *map(str, args)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=slave,
                            env=env)
    os.close(slave)
    chunks: list[bytes] = []

    def pump() -> None:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=pump, daemon=True)
    reader.start()
    stdout, _ = proc.communicate(timeout=timeout)
    reader.join(timeout=30)
    os.close(master)
    return proc.returncode, stdout.decode(), b"".join(chunks).decode(errors="replace")


def _stages_shown(tty: str) -> list[str]:
    names = re.findall(r"\r[^\r\n]*?: (start|read|solve|time|write)\b", tty)
    return [n for i, n in enumerate(names) if i == 0 or names[i - 1] != n]


def test_progress_shows_every_stage_on_a_terminal(tmp_path: Path) -> None:
    shot = tmp_path / "ten seconds.usda"
    assert _make_samples("--long-shot", str(shot), "--frames", "240").returncode == 0
    out = tmp_path / "x.mcap"
    code, stdout, tty = _run_on_tty(["convert", shot, "-o", out, "--timing", "scale"])
    assert code == 0, tty
    assert _stages_shown(tty) == ["start", "read", "solve", "time", "write"]
    assert "/240 frame" in tty
    assert "ERROR" not in tty and "Traceback" not in tty
    assert f"wrote {out}" in stdout  # the report, after the line was cleared
    assert read_take(out).frame_numbers.shape == (240,)


def test_no_progress_in_quiet_or_json_modes(tmp_path: Path) -> None:
    code, stdout, tty = _run_on_tty(["check", MAYA, "--json"])
    assert code == 0
    assert json.loads(stdout)["status"] == "ok"
    assert tty == ""
    code, stdout, tty = _run_on_tty(["convert", MAYA, "-o", tmp_path / "q.mcap", "-q"])
    assert (code, stdout, tty) == (0, "", "")


def test_a_failing_run_clears_the_line_before_its_error(tmp_path: Path) -> None:
    code, _, tty = _run_on_tty(["convert", UNREACHABLE, "-o", tmp_path / "u.mcap"])
    assert code == 3
    last = tty.replace("\r\n", "\n").split("\r")[-1]
    assert last.lstrip(" ").startswith("ERROR: ") and last.count("\n") == 1  # a line of its own


# --------------------------------------------------------------------------------------------
# info on a shot, -o with another extension
# --------------------------------------------------------------------------------------------


def test_info_on_a_usd_shot_says_what_it_is(tmp_path: Path) -> None:
    crate = tmp_path / "shot.usd"  # .usd may hold either encoding
    assert Usd.Stage.Open(str(MAYA)).Export(str(crate), args={"format": "usdc"})
    notes = tmp_path / "notes.mcap"
    notes.write_text("not a recording\n")
    for path, kind in ((MAYA, "USD text (usda)"), (crate, "USD crate (usdc)")):
        proc = run_cli("info", path)
        assert proc.returncode == 2
        line = error_line(proc)
        assert f"{path} is a {kind} file, not an MCAP" in line
        assert "camtraj convert" in line and "camtraj check" in line
        assert "magic:" not in line
    proc = run_cli("info", notes)
    assert proc.returncode == 2
    assert "not an MCAP file" in error_line(proc)


def test_output_without_the_mcap_extension_warns(tmp_path: Path) -> None:
    out = tmp_path / "x.txt"
    proc = run_cli("convert", MAYA, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: ") and ".mcap" in lines[0]
    assert read_take(out).frame_numbers.size == 120  # an MCAP all the same
    proc = run_cli("convert", MAYA, "-o", tmp_path / "y.MCAP", "-q")
    assert proc.returncode == 0 and proc.stderr == ""


# --------------------------------------------------------------------------------------------
# batch's summary line; one rule for output folders
# --------------------------------------------------------------------------------------------


def test_batch_rerun_says_what_ran(tmp_path: Path) -> None:
    shots = [str(MAYA), str(BLENDER)]
    options = ConvertOptions()
    first = run_batch(shots, tmp_path / "out", jobs=2, options=options)
    assert (first.jobs, first.workers) == (2, 2)
    assert first.table().splitlines()[-1].endswith("with 2 jobs")
    again = run_batch(shots, tmp_path / "out", jobs=2, options=options)
    last = again.table().splitlines()[-1]
    assert last.startswith("0 converted, 2 up to date, 0 failed")
    assert last.endswith("(nothing to convert)") and "job" not in last
    report = json.loads((tmp_path / "out" / REPORT_NAME).read_text())
    assert (report["jobs"], report["workers"]) == (2, 0)
    _age_outputs(MAYA, tmp_path / "out")
    one = run_batch(shots, tmp_path / "out", jobs=2, options=options)
    assert one.table().splitlines()[-1].endswith("with 1 job (2 asked; 1 shot(s) to convert)")


def _age_outputs(shot: Path, outdir: Path) -> None:
    """Make ``shot``'s outputs older than it (as if the shot were edited), without editing it."""
    past = shot.stat().st_mtime - 10.0
    for name in (f"{shot.stem}.mcap", f"{shot.stem}.summary.json"):
        os.utime(outdir / name, (past, past))


def test_every_command_makes_missing_output_folders(tmp_path: Path) -> None:
    fresh = tmp_path / "fresh"
    proc = run_cli("convert", MAYA, "-o", fresh / "a" / "b" / "x.mcap",
                   "--summary", fresh / "s" / "x.json", "-q")
    assert proc.returncode == 0, proc.stderr
    assert read_take(fresh / "a" / "b" / "x.mcap").frame_numbers.size == 120
    assert json.loads((fresh / "s" / "x.json").read_text())["status"] == "ok"

    batch = tmp_path / "b1" / "b2"
    proc = run_cli("batch", MAYA, "-o", batch, "-q")
    assert proc.returncode == 0, proc.stderr
    assert (batch / "maya_dolly_push_in.mcap").is_file() and (batch / REPORT_NAME).is_file()

    job = tmp_path / "j1" / "job.xml"
    outdir = tmp_path / "o1" / "o2"
    proc = run_cli("farm", "export", "--format", "opencue", MAYA, "-o", job, "--outdir", outdir)
    assert proc.returncode == 0, proc.stderr
    assert job.is_file() and not outdir.exists()  # made by the task that writes into it
    proc = run_cli("farm", "run-task", job.with_name("job.tasks.json"), "1")
    assert proc.returncode == 0, proc.stderr
    assert read_take(outdir / "maya_dolly_push_in.mcap").frame_numbers.size == 120


def test_a_failed_run_leaves_no_folder_and_a_file_in_the_way_is_refused(tmp_path: Path) -> None:
    proc = run_cli("convert", UNREACHABLE, "-o", tmp_path / "new" / "u.mcap",
                   "--summary", tmp_path / "new2" / "u.json")
    assert proc.returncode == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    (tmp_path / "plain").write_text("a file\n")
    for args in (["-o", tmp_path / "plain" / "sub" / "x.mcap"],
                 ["-o", tmp_path / "x.mcap", "--summary", tmp_path / "plain" / "s.json"]):
        proc = run_cli("convert", MAYA, *args)
        assert proc.returncode == 2
        assert "plain is a file, not a folder" in error_line(proc)
    proc = run_cli("batch", MAYA, "-o", tmp_path / "plain" / "out")
    assert proc.returncode == 2
    assert "plain is a file, not a folder" in error_line(proc)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]
