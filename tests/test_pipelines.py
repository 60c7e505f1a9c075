"""The make pipeline (pipelines/shots.mk via pipelines/Makefile.example) with the real camtraj."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples" / "shots"
EXAMPLE = ROOT / "pipelines" / "Makefile.example"
FEASIBLE = ("maya_dolly_push_in", "blender_crane_up", "orbit_animated_parent", "whip_pan")

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs GNU make")


def _camtraj() -> str:
    """The camtraj command, as make will run it (a shell word)."""
    if (ROOT / "camtraj" / "__main__.py").is_file():
        return f"{sys.executable} -m camtraj"
    return str(Path(sys.executable).parent / "camtraj")


def _make(
    work: Path, *args: str, check: bool = False, **variables: str
) -> subprocess.CompletedProcess[str]:
    settings = {
        "SHOTS_DIR": str(work / "shots"),
        "OUT": str(work / "out"),
        "CAMTRAJ": _camtraj(),
        "CAMTRAJ_FLAGS": "--quiet",
        **variables,
    }
    cmd = ["make", "--no-print-directory", "-f", str(EXAMPLE), *args]
    cmd += [f"{k}={v}" for k, v in settings.items()]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(cmd, cwd=work, capture_output=True, text=True, env=env, check=False)
    if check:
        assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


def _mtimes(out: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in sorted(out.glob("*.mcap"))}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A work folder whose shots (every sample) were converted once with -j2."""
    work = tmp_path_factory.mktemp("make")
    (work / "shots").mkdir()
    for sample in SAMPLES.glob("*.usda"):
        shutil.copy2(sample, work / "shots" / sample.name)
    _make(work, "-j2", check=True)
    return work


def test_converts_feasible_samples_with_summaries(built: Path) -> None:
    out = built / "out"
    assert sorted(p.stem for p in out.glob("*.mcap")) == sorted(FEASIBLE)
    for name in FEASIBLE:
        assert (out / f"{name}.mcap").stat().st_size > 0
        assert (out / f"{name}.summary.json").is_file()
    assert not (out / "unreachable.mcap").exists()  # EXCLUDEd by the example


def test_second_make_does_nothing(built: Path) -> None:
    assert _make(built, "-q").returncode == 0
    proc = _make(built, check=True)
    assert "Nothing to be done" in proc.stdout
    assert " convert " not in proc.stdout


def test_touching_one_shot_reconverts_only_that_shot(built: Path) -> None:
    out = built / "out"
    # Age every output so that "newer" is unambiguous at any mtime resolution.
    for p in out.iterdir():
        os.utime(p, ns=(p.stat().st_atime_ns, p.stat().st_mtime_ns - 10**10))
    before = _mtimes(out)
    (built / "shots" / "maya_dolly_push_in.usda").touch()
    proc = _make(built, "-j2", check=True)
    after = _mtimes(out)
    changed = sorted(name for name in before if after[name] != before[name])
    assert changed == ["maya_dolly_push_in.mcap"], proc.stdout
    assert proc.stdout.count(" convert ") == 1


def test_failing_shot_leaves_nothing_and_keep_going_builds_the_rest(built: Path) -> None:
    out = built / "out"
    (out / "orbit_animated_parent.mcap").unlink()  # must be rebuilt alongside the failing shot
    # A stale summary from "an earlier run" must not survive the failure either.
    (out / "unreachable.summary.json").write_text("{}")
    proc = _make(built, "-k", "-j2", EXCLUDE="")
    assert proc.returncode != 0
    # the recipe keeps camtraj's exit code: 3, the shot cannot be done (not make's "Error 1")
    assert re.search(r"unreachable\.mcap\S*\] Error 3$", proc.stderr, re.MULTILINE), proc.stderr
    assert not (out / "unreachable.mcap").exists()
    assert not (out / "unreachable.summary.json").exists()
    assert not list(out.glob("*.tmp*"))
    assert (out / "orbit_animated_parent.mcap").stat().st_size > 0
    assert _make(built, "-q").returncode == 0  # the feasible shots are all up to date


def test_changed_options_make_outputs_out_of_date(built: Path) -> None:
    # Last in the module: it records the new options in OUT/.camtraj-options.
    assert _make(built, "-q").returncode == 0
    assert _make(built, "-q", RATE="200").returncode == 1


def test_a_changed_set_or_lens_file_remakes_the_moves(tmp_path: Path) -> None:
    """SET_FILE and LENS are passed to convert and are prerequisites of every MCAP: the track
    re-laid in the set file (as `camtraj place` rewrites it) or a lens file recalibrated in
    place reconverts, with the new placement in the summary."""
    (tmp_path / "shots").mkdir()
    shutil.copy2(SAMPLES / "blender_crane_up.usda", tmp_path / "shots")
    set_file, lens = tmp_path / "set.toml", tmp_path / "lens.toml"
    set_file.write_text("[placement]\nx = 0.0\ny = 0.0\nz = 0.0\nyaw_deg = 0.0\n")
    shutil.copy2(ROOT / "camtraj" / "data" / "lenses" / "prime_50.toml", lens)
    files = {"SET_FILE": str(set_file), "LENS": str(lens), "EXCLUDE": ""}
    _make(tmp_path, check=True, **files)
    out = tmp_path / "out"
    assert _make(tmp_path, "-q", **files).returncode == 0
    for changed in (set_file, lens):
        for p in out.iterdir():  # older than any change below, at any mtime resolution
            os.utime(p, ns=(p.stat().st_atime_ns, p.stat().st_mtime_ns - 10**10))
        if changed == set_file:
            changed.write_text("[placement]\nx = 0.2\ny = -0.1\nz = 0.0\nyaw_deg = 3.0\n")
        else:
            changed.touch()
        assert _make(tmp_path, "-q", **files).returncode == 1, changed
        proc = _make(tmp_path, check=True, **files)
        assert proc.stdout.count(" convert ") == 1, proc.stdout
    summary = json.loads((out / "blender_crane_up.summary.json").read_text())
    assert summary["placement"]["source"] == str(set_file)
    assert summary["placement"]["translation_m"] == [0.2, -0.1, 0.0]
