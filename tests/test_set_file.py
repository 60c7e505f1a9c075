"""Set files: the format people write and ``camtraj place`` writes, and its strict checks."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from camtraj.convert import load_placement, load_set_file
from camtraj.errors import InputError
from camtraj.options import ConvertOptions
from camtraj.set_file import SetFile, floor_xy, to_toml
from camtraj.usd_shot import YUP2ZUP

FULL = """
[placement]
x = 12.5
y = -3
z = 0.25
yaw_deg = 30

[floor]
height = 10
region = [[0, 0, 0], [2000, 0, 0], [2000, 0, 1500], [0, 0, 1500]]
keep_out = [[[500, 0, 500], [700, 0, 500], [700, 0, 700]]]

[search]
yaw_range_deg = [-45, 45.5]

[collision]
prims = ["/World/set/wall", "/World/props/*"]
clearance_m = 0.05
"""


def test_full_file_parses() -> None:
    sf = SetFile.parse(FULL, "s.toml")
    assert sf.base2world is not None
    assert np.allclose(sf.base2world[:3, 3], [12.5, -3.0, 0.25])
    a = math.radians(30.0)
    assert np.allclose(sf.base2world[:2, :2], [[math.cos(a), -math.sin(a)],
                                                [math.sin(a), math.cos(a)]])
    assert sf.floor_height == 10.0 and sf.region is not None and sf.region.shape == (4, 3)
    assert len(sf.keep_out) == 1 and sf.yaw_range_deg == (-45.0, 45.5)
    assert sf.prims == ("/World/set/wall", "/World/props/*") and sf.clearance_m == 0.05


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[floor]\nheigth = 1\n", ["s.toml", "heigth", "[floor]", "allowed"]),
        ("[bogus]\n", ["s.toml", "bogus", "top level"]),
        ("[floor]\nregion = [[0, 0, 0], [1, 0], [1, 1, 0]]\n", ["s.toml", "[floor] region",
                                                                "[x, y, z]"]),
        ('[floor]\nregion = [[0, 0, 0], [1, 0, "a"], [1, 1, 0]]\n', ["[floor] region"]),
        ("[floor]\nregion = [[0, 0, 0], [1, 0, 0]]\n", ["at least 3 points"]),
        ("[floor]\nkeep_out = [[0, 0, 0]]\n", ["[floor] keep_out[0]"]),
        ("[search]\nyaw_deg = 400\n", ["[search] yaw_deg", "[-360, 360]"]),
        ("[search]\nyaw_deg = 1\nyaw_range_deg = [0, 1]\n", ["either yaw_deg or"]),
        ("[search]\nyaw_range_deg = [10, 0]\n", ["[search] yaw_range_deg", "lo <= hi"]),
        ("[search]\nyaw_range_deg = [10]\n", ["[search] yaw_range_deg", "2 finite numbers"]),
        ("[collision]\nclearance_m = -1\n", ["[collision] clearance_m", "[0, 5]"]),
        ('[collision]\nclearance_m = "5cm"\n', ["[collision] clearance_m", "finite number"]),
        ('[collision]\nprims = ["wall"]\n', ["[collision] prims", "absolute"]),
        ('[placement]\nx = "1"\n', ["[placement] x", "finite number"]),
        ("[placement]\nrotation = [[1, 0, 0], [0, 1], [0, 0, 1]]\n", ["rotation", "3x3"]),
        ("[placement]\nyaw_deg = 1\nrotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
         ["either yaw_deg or rotation"]),
        ("[placement\n", ["not valid TOML"]),
        ("floor = 3\n", ["[floor] must be a table"]),
    ],
)
def test_errors_are_one_line_naming_file_and_key(text: str, words: list[str]) -> None:
    with pytest.raises(InputError) as info:
        SetFile.parse(text, "s.toml")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("set file s.toml: ")
    for w in words:
        assert w in msg


def test_written_file_reads_back_and_keeps_the_constraints(tmp_path: Path) -> None:
    sf = SetFile.parse(FULL, "s.toml")
    T = np.eye(4)
    a = math.radians(-136.88)  # atan2 of the matrix gives back -136.88000000000002
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:3, 3] = (-40.1, 56.3, 0.1)
    path = tmp_path / "placed.toml"
    path.write_text(to_toml(-40.1, 56.3, 0.1, -136.88, sf.text))
    data = tomllib.loads(path.read_text())  # plain TOML, as a person reads it
    assert data["placement"]["yaw_deg"] == -136.88  # the number, not one recovered from a matrix
    back = SetFile.read(path)
    # the very transform place evaluated: a shot's speed can change with its last bit
    assert back.base2world is not None and np.array_equal(back.base2world, T)
    assert back.prims == sf.prims and back.clearance_m == sf.clearance_m
    assert back.region is not None and sf.region is not None
    assert np.array_equal(back.region, sf.region) and back.yaw_range_deg == sf.yaw_range_deg
    options = ConvertOptions(set_file=str(path))
    placement = load_placement(options, load_set_file(options))
    assert np.allclose(placement.base2world, T)


def test_place_keeps_the_set_files_comments_and_replaces_only_its_placement() -> None:
    """A set file's notes (which flight case a keep-out is, who measured the floor) survive
    ``place -o``: only [placement] changes (it was written anew from the parsed tables, every
    comment lost). A placement given as a rotation becomes x, y, z and yaw_deg; a file
    without one gets one; an old layout name goes unless a scene's place gives one."""
    text = ("# stage 4, measured 2026-11-30 by rigging\n"
            "[placement]  # last week's\nx = 1.0\ny = 2.0\nz = 0.18\n"
            "rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nlayout = \"old\"\n\n"
            "[floor]\nheight = 0.0\n# the flight cases by the door\n"
            "keep_out = [[[500, 0, 500], [700, 0, 500], [700, 0, 700]]]  # case 3\n")
    out = to_toml(-3.5, 4.25, 0.18, 12.5, text)
    for kept in ("# stage 4, measured 2026-11-30 by rigging\n", "# the flight cases by the door\n",
                 "  # case 3\n", "[placement]  # last week's\n"):
        assert kept in out
    data = tomllib.loads(out)
    assert data["placement"] == {"x": -3.5, "y": 4.25, "z": 0.18, "yaw_deg": 12.5}
    assert data["floor"] == tomllib.loads(text)["floor"]
    sf = SetFile.parse(out)
    assert sf.base2world is not None and np.allclose(sf.base2world[:3, 3], (-3.5, 4.25, 0.18))
    bare = to_toml(1.0, 2.0, 0.18, 30.0, "# my set\n[collision]\nclearance_m = 0.1\n",
                   layout="sc 12")
    assert bare.startswith("# my set\n")
    assert tomllib.loads(bare) == {"collision": {"clearance_m": 0.1}, "placement": {
        "x": 1.0, "y": 2.0, "z": 0.18, "yaw_deg": 30.0, "layout": "sc 12"}}
    fresh = to_toml(1.0, 2.0, 0.18, 30.0)
    assert fresh.startswith("# camtraj set file") and SetFile.parse(fresh).base2world is not None
    # placed again: every line where it was, the values changed in place, CRLF kept (review
    # 57: the keys moved below the next table's comment, with LF endings among CRLF ones)
    placed = ("# stage 4\r\n[placement]\r\nx = 1.0  # tape mark\r\ny = 2.0\r\nz = 0.18\r\n"
              "yaw_deg = 30.0\r\nlayout = \"sc 12\"\r\n\r\n# floor: measured\r\n[floor]\r\n"
              "height = 0.0\r\n")
    assert to_toml(-3.5, 4.0, 0.18, 12.5, placed) == placed.replace(
        "x = 1.0", "x = -3.5").replace("y = 2.0", "y = 4.0").replace(
        "yaw_deg = 30.0", "yaw_deg = 12.5").replace('layout = "sc 12"\r\n', "")
    # a placement written with dotted keys or as an inline table is edited as written
    for written in ("placement.x = 1.0\nplacement.y = 2.0\nplacement.z = 0.0\n"
                    "placement.yaw_deg = 3.0\n[floor]\nheight = 0.0\n",
                    "placement = {x = 1.0, y = 2.0, z = 0.0, yaw_deg = 3.0}\n"):
        out = to_toml(5.0, 6.0, 0.18, 7.0, written)
        assert tomllib.loads(out)["placement"] == {"x": 5.0, "y": 6.0, "z": 0.18, "yaw_deg": 7.0}
        assert out.count("\n") == written.count("\n")


def test_file_without_placement_places_at_the_origin(tmp_path: Path) -> None:
    path = tmp_path / "set.toml"
    path.write_text("[collision]\nprims = [\"/World/wall\"]\n")
    options = ConvertOptions(set_file=str(path))
    assert np.array_equal(load_placement(options, load_set_file(options)).base2world, np.eye(4))


def test_floor_points_convert_like_the_camera() -> None:
    """A Y-up centimetre point lands where usd_shot puts a camera at the same stage point."""
    p = np.array([[120.0, 35.0, -410.0]])
    expected = (YUP2ZUP @ p[0]) * 0.01
    assert np.allclose(floor_xy(p, 0.01, "Y")[0], expected[:2])
    assert np.allclose(floor_xy(p, 1.0, "Z")[0], p[0, :2])


def test_a_set_file_with_no_placement_or_a_rail_off_its_floor_is_warned_of(
        tmp_path: Path) -> None:
    """Trial 21: a set file without [placement] put the robot at the stage origin in silence
    (a wrong file given by mistake gives a take for the wrong track position), and a
    placement whose rail crossed the file's keep-out or left its floor region was taken as
    it was. The push-in is a Y-up cm stage: floor points are [x, 0, z] in cm."""
    from camtraj.analysis import Placement
    from camtraj.convert import placement_notes as notes_of
    from camtraj.robot import Robot
    from camtraj.usd_shot import read_shot

    robot = Robot.default()
    shot = read_shot(Path(__file__).parent.parent / "samples" / "shots" / "maya_dolly_push_in.usda")

    def placement_notes(options: ConvertOptions, placement: Placement, robot: Robot,
                        shot: object) -> tuple[str, ...]:  # the set file read as convert reads it
        return notes_of(options, load_set_file(options), placement, robot, shot)
    bare = tmp_path / "bare.toml"
    bare.write_text("[floor]\nheight = 0.0\n", encoding="utf-8")
    (note,) = placement_notes(ConvertOptions(set_file=str(bare)), Placement(), robot, shot)
    assert "bare.toml has no [placement]" in note and "stage origin" in note
    # given on the command line instead: nothing to say
    options = ConvertOptions(set_file=str(bare), placement=(0.0, 0.0, 0.0, 0.0))
    assert placement_notes(options, Placement(), robot, shot) == ()
    # the rail at the origin lies along +x from x = r10 + lower track - 0.6 m (URDF's rail)
    square = "[[-100, 0, -100], [100, 0, -100], [100, 0, 100], [-100, 0, 100]]"
    far = "[[5000, 0, 5000], [6000, 0, 5000], [6000, 0, 6000]]"
    placed = tmp_path / "placed.toml"
    placed.write_text(f"[placement]\nx = 0.0\ny = 0.0\nz = 0.18\nyaw_deg = 0.0\n[floor]\n"
                      f"keep_out = [{far}, {square}]\nregion = {far}\n", encoding="utf-8")
    notes = placement_notes(ConvertOptions(set_file=str(placed)), Placement(), robot, shot)
    assert notes == ("the rail at this placement is not wholly inside the floor region of "
                     f"{placed}", f"the rail at this placement crosses keep_out[1] of {placed}")
    clear = tmp_path / "clear.toml"  # the keep-out 20 m to the side: nothing to say
    clear.write_text(f"[placement]\nx = 0.0\ny = 0.0\nz = 0.18\nyaw_deg = 0.0\n[floor]\n"
                     f"keep_out = [{far}]\n", encoding="utf-8")
    assert placement_notes(ConvertOptions(set_file=str(clear)), Placement(), robot, shot) == ()


def test_a_scene_file_given_as_the_set_file_is_named_as_one(tmp_path: Path) -> None:
    """Trial 21: it read 'unknown key(s) name, shot', no hint of what the file was."""
    scene = tmp_path / "scene.toml"
    scene.write_text('name = "sc12"\n[[shot]]\npath = "a.usda"\n', encoding="utf-8")
    with pytest.raises(InputError, match=r"a scene file, which `camtraj place --scene` takes"):
        SetFile.read(scene)


def test_toml_and_json_the_parsers_cannot_hold_are_one_line_errors() -> None:
    """Trial 22: arrays nested thousands deep (RecursionError, ~3,000 traceback lines) and
    a 5,000-digit number (ValueError) went past the TOML and JSON checks as tracebacks."""
    from camtraj.inputs import parse_json, parse_toml

    for text in ("a = " + "[" * 20_000 + "]" * 20_000, "a = " + "9" * 5_000):
        with pytest.raises(InputError, match=r"^set file x\.toml: not a TOML file camtraj can "):
            parse_toml(text, "set file x.toml", InputError)
    for text in ("[" * 100_000 + "]" * 100_000, "9" * 5_000, "{x"):
        with pytest.raises(InputError, match=r"^m\.json: not JSON camtraj can read"):
            parse_json(text, "m.json", InputError)


def test_a_placement_on_the_command_line_has_a_set_files_bounds() -> None:
    """Trial 22: --placement 1e300,0,0,0 was taken (a set file caps x, y, z at 1e6 m), and
    every frame's miss was printed with 300 digits."""
    for bad in ((1e300, 0.0, 0.0, 0.0), (0.0, 0.0, -2e6, 0.0), (0.0, 0.0, 0.0, 400.0)):
        with pytest.raises(InputError, match=r"placement must be x, y, z within ±1e6 m"):
            ConvertOptions(placement=bad)
    assert ConvertOptions(placement=(1e6, -1e6, 0.0, -360.0)).placement is not None


def test_a_run_reads_its_set_file_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The placement, its warnings and the collision check all come from one read of the
    set file (it was read three times a run: a file rewritten by ``place -o`` during a run
    could give the take one placement and its warnings another)."""
    from camtraj.convert import analyse

    path = tmp_path / "set.toml"
    path.write_text("[placement]\nx = 0.05\ny = 0.0\nz = 0.0\nyaw_deg = 1.5\n", encoding="utf-8")
    reads: list[str] = []
    real = SetFile.read.__func__  # type: ignore[attr-defined]

    def counted(cls: type[SetFile], p: str | Path) -> SetFile:
        reads.append(str(p))
        return real(cls, p)  # type: ignore[no-any-return]

    monkeypatch.setattr(SetFile, "read", classmethod(counted))
    shot = Path(__file__).parent.parent / "samples" / "shots" / "maya_dolly_push_in.usda"
    analysis = analyse(shot, ConvertOptions(set_file=str(path), timing="scale"))
    assert reads == [str(path)]
    assert analysis.placement.base2world[0, 3] == pytest.approx(0.05)
