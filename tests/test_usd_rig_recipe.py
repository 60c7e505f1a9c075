"""The README's recipe for composing the rig layer with the shot works on a Z-up metre and a
Y-up centimetre sample: the composed stage has the shot's up axis, units and time range, and
the rig's camera is where the shot's camera is at every frame."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from camtraj.convert import convert
from camtraj.options import ConvertOptions
from tests.conftest import pose_error

ROOT = Path(__file__).resolve().parent.parent
MARKER = "<!-- tested: tests/test_usd_rig_recipe.py runs this block -->"


def recipe() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    match = re.search(re.escape(MARKER) + r"\n```python\n(.*?)```\n", text, re.DOTALL)
    assert match, "README.md has no tested recipe block"
    return match.group(1)


def _camera_world(stage: Usd.Stage, prim: Usd.Prim, frames: list[float]) -> np.ndarray:
    cache = UsdGeom.XformCache()
    out = []
    for tc in frames:
        cache.SetTime(Usd.TimeCode(tc))
        out.append(np.array(cache.GetLocalToWorldTransform(prim)).T)
    return np.array(out)


@pytest.mark.parametrize(("sample", "up", "mpu", "rate"), [
    ("blender_crane_up", "Z", 1.0, None), ("maya_dolly_push_in", "Y", 0.01, None),
    ("blender_crane_up", "Z", 1.0, "59.94")])  # an NTSC rate as written, not 60000/1001
def test_the_readme_recipe_composes_rig_and_shot(
    tmp_path: Path, sample: str, up: str, mpu: float, rate: str | None
) -> None:
    text = (ROOT / "samples" / "shots" / f"{sample}.usda").read_text(encoding="utf-8")
    if rate is not None:
        text = re.sub(r"(framesPerSecond|timeCodesPerSecond) = 24\b", rf"\1 = {rate}", text)
        assert text.count(rate) == 2
    (tmp_path / "shot.usda").write_text(text, encoding="utf-8")
    convert(tmp_path / "shot.usda", tmp_path / "shot.mcap", ConvertOptions(),
            rig_layer=tmp_path / "shot.rig.usda")
    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(recipe(), "README.md recipe", "exec"), {})
    finally:
        os.chdir(here)

    stage = Usd.Stage.Open(str(tmp_path / "shot.with_rig.usda"))
    shot = Usd.Stage.Open(str(tmp_path / "shot.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == up == UsdGeom.GetStageUpAxis(shot)
    assert UsdGeom.GetStageMetersPerUnit(stage) == mpu == UsdGeom.GetStageMetersPerUnit(shot)
    assert stage.GetTimeCodesPerSecond() == shot.GetTimeCodesPerSecond()
    assert stage.GetFramesPerSecond() == shot.GetFramesPerSecond()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (
        shot.GetStartTimeCode(), shot.GetEndTimeCode())
    cameras = [p for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
    rig = [p for p in cameras if p.GetName() == "camtraj_camera"]
    theirs = [p for p in cameras if p.GetName() != "camtraj_camera"]
    assert len(rig) == 1 and len(theirs) == 1
    first, last = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    # on film frames (time codes the rig has samples at; between them USD interpolates the
    # rig's joints and the shot's matrices differently)
    frames = [float(t) for t in np.unique(np.rint(np.linspace(first, last, 7)))]
    a = _camera_world(stage, rig[0], frames)
    b = _camera_world(stage, theirs[0], frames)
    b[:, :3, :3] /= np.cbrt(np.linalg.det(b[:, :3, :3]))[:, None, None]  # the shot's scale out
    dp, dr = pose_error(a, b)
    # (the samples' matrices are written to 6-7 digits: not quite orthonormal, hence 0.1 mm)
    assert dp <= 1e-4 / mpu and dr <= 1e-5  # 0.1 mm, in the stage's units
    assert np.ptp(b[:, :3, 3], axis=0).max() > 0.1 / mpu  # the camera does move
    # composed, the rig's keys are on the shot's frames (a rate written differently from the
    # shot's retimed them: 59.94 against 60000/1001 put frame 1 at time code 0.999999)
    keyed = [a for p in Usd.PrimRange(rig[0].GetParent()) for a in p.GetAttributes()
             if a.GetNumTimeSamples() > 1]
    assert keyed
    for attr in keyed:
        times = attr.GetTimeSamples()
        assert times == [float(t) for t in range(round(first), round(last) + 1)], attr.GetPath()


def test_a_bare_sublayer_stage_loses_the_shot_metadata(tmp_path: Path) -> None:
    """Why the recipe copies the metadata: without it a Z-up metre shot reads as Y-up cm."""
    shutil.copy(ROOT / "samples" / "shots" / "blender_crane_up.usda", tmp_path / "shot.usda")
    bare = tmp_path / "bare.usda"
    bare.write_text('#usda 1.0\n(\n    subLayers = [@shot.usda@]\n)\n', encoding="utf-8")
    stage = Usd.Stage.Open(str(bare))
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
