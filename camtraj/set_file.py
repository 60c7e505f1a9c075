"""The set file: where the robot stands and what the set allows (a small TOML file).

One format for what people write by hand and what ``camtraj place -o`` writes; ``convert
--set-file`` and ``check --set-file`` read it as it is. Every table is optional::

    [placement]            # the robot base in the converted world: metres, Z-up (as --placement)
    x = 12.5
    y = -3.0
    z = 0.0
    yaw_deg = 30.0         # or rotation = [[...], [...], [...]] (3x3), not both
    layout = "scene 12"    # the layout's name (written by a scene's `camtraj place`)

    [floor]                # stage units and stage axes (as the USD stage is authored)
    height = 0.0           # the floor's up coordinate; `place` lays the rail on it
    region = [[0, 0, 0], [2000, 0, 0], [2000, 0, 1500], [0, 0, 1500]]   # where the track may lie
    keep_out = [[[500, 0, 500], [700, 0, 500], [700, 0, 700]]]          # polygons to keep off

    [search]               # yaw of the track about up [deg], in the converted (Z-up) world
    yaw_deg = 30.0         # a fixed yaw, or
    yaw_range_deg = [-45.0, 45.0]

    [collision]
    prims = ["/World/set/wall", "/World/props/*"]   # prim paths or glob patterns (default none)
    clearance_m = 0.05     # the distance the robot must keep from them [m]

Polygon points are three stage coordinates each ``[x, y, z]``; the up coordinate is ignored (a
Y-up stage's floor is its x-z plane). Errors are :class:`~camtraj.errors.InputError` with one
line naming the file, the key and the allowed range.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomlkit
import tomlkit.exceptions
from numpy.typing import NDArray

from camtraj.errors import InputError
from camtraj.inputs import one_line, parse_toml, read_text, reject_unknown_keys

Array = NDArray[np.float64]

_KEYS: dict[str, set[str]] = {
    "placement": {"x", "y", "z", "yaw_deg", "rotation", "layout"},
    "floor": {"height", "region", "keep_out"},
    "search": {"yaw_deg", "yaw_range_deg"},
    "collision": {"prims", "clearance_m"},
}
MAX_CLEARANCE_M = 5.0


@dataclass(frozen=True)
class SetFile:
    """A parsed set file (see the module docstring for the format).

    Attributes:
        source: Where it came from (the path, for messages).
        base2world: The ``[placement]`` as a 4x4 transform [m], or None when absent.
        floor_height: The floor's up coordinate [stage units].
        region: Polygon (k, 3) [stage units] where the track may lie, or None (anywhere).
        keep_out: Polygons (k, 3) [stage units] no part of the track may touch.
        yaw_range_deg: Allowed yaw of the track (lo, hi) [deg]; lo == hi for a fixed yaw.
        prims: Prim paths or glob patterns of obstacles on the shot's stage.
        clearance_m: Required distance between the robot and the obstacles [m].
        layout: The name of the layout the placement was found for (a scene's), or None.
        text: The file's own text ("" for none): ``place -o`` writes it back with the new
            placement, its comments and layout kept (:func:`to_toml`).
    """

    source: str = "<none>"
    base2world: Array | None = None
    floor_height: float = 0.0
    region: Array | None = None
    keep_out: tuple[Array, ...] = ()
    yaw_range_deg: tuple[float, float] | None = None
    prims: tuple[str, ...] = ()
    clearance_m: float = 0.0
    layout: str | None = None
    text: str = field(default="", repr=False, compare=False)

    @classmethod
    def read(cls, path: str | Path) -> SetFile:
        return cls.parse(read_text(path, "set file", InputError), one_line(path))

    @classmethod
    def parse(cls, text: str, source: str = "<text>") -> SetFile:
        where = f"set file {source}"
        data = parse_toml(text, where, InputError)
        if "shot" in data:  # a scene file given as the set file
            msg = (f"{where}: it lists shots ([[shot]]): a scene file, which `camtraj place "
                   "--scene` takes; a set file has [placement], [floor], [search], [collision]")
            raise InputError(msg)
        reject_unknown_keys(data, set(_KEYS), where, "the top level", InputError)
        tables = {}
        for name, keys in _KEYS.items():
            table = data.get(name, {})
            if not isinstance(table, dict):
                msg = f"{where}: [{name}] must be a table"
                raise InputError(msg)
            reject_unknown_keys(table, keys, where, f"[{name}]", InputError)
            tables[name] = table
        floor, search, coll = tables["floor"], tables["search"], tables["collision"]
        region = None
        if "region" in floor:
            region = _polygon(floor["region"], where, "floor.region")
        keep_out_val = floor.get("keep_out", [])
        if not isinstance(keep_out_val, list):
            msg = f"{where}: [floor] keep_out must be a list of polygons"
            raise InputError(msg)
        keep_out = tuple(_polygon(p, where, f"floor.keep_out[{i}]")
                         for i, p in enumerate(keep_out_val))
        if "yaw_deg" in search and "yaw_range_deg" in search:
            msg = f"{where}: give either yaw_deg or yaw_range_deg in [search], not both"
            raise InputError(msg)
        yaw_range: tuple[float, float] | None = None
        if "yaw_deg" in search:
            yaw = _number(search["yaw_deg"], where, "search.yaw_deg", -360.0, 360.0)
            yaw_range = (yaw, yaw)
        elif "yaw_range_deg" in search:
            lo, hi = _numbers(search["yaw_range_deg"], 2, where, "search.yaw_range_deg")
            if not -360.0 <= lo <= hi <= lo + 360.0 <= 720.0:
                msg = (f"{where}: [search] yaw_range_deg = [{lo:g}, {hi:g}] must be [lo, hi] "
                       "with lo <= hi <= lo + 360, each within [-360, 360] deg")
                raise InputError(msg)
            yaw_range = (lo, hi)
        prims = coll.get("prims", [])
        if not isinstance(prims, list) or not all(
                isinstance(p, str) and p.startswith("/") for p in prims):
            msg = (f"{where}: [collision] prims must be a list of absolute prim paths or "
                   'patterns, e.g. ["/World/set/*"]')
            raise InputError(msg)
        clearance = _number(coll.get("clearance_m", 0.0), where, "collision.clearance_m",
                            0.0, MAX_CLEARANCE_M)
        return cls(
            source=source,
            base2world=_placement(tables["placement"], where) if "placement" in data else None,
            floor_height=_number(floor.get("height", 0.0), where, "floor.height", -1e6, 1e6),
            region=region,
            keep_out=keep_out,
            yaw_range_deg=yaw_range,
            prims=tuple(prims),
            clearance_m=clearance,
            layout=_layout(tables["placement"], where),
            text=text,
        )


def floor_xy(points: Array, meters_per_unit: float, up_axis: str) -> Array:
    """Stage points (k, 3) [stage units] -> floor coordinates (k, 2) in the converted world [m]
    (:func:`camtraj.usd_shot.stage_to_world`: a Y-up stage's (x, y, z) becomes (x, -z, y))."""
    from camtraj.usd_shot import stage_to_world

    p = np.asarray(points, dtype=float) @ stage_to_world(meters_per_unit, up_axis).T
    return np.asarray(p[:, :2].copy())


MAX_FLOOR_M = 1.0e6
"""Largest floor coordinate of a region or keep-out polygon [m] (1000 km: a unit error)."""


def floor_polygon(points: Array, meters_per_unit: float, up_axis: str, source: str,
                  key: str) -> Array:
    """A region or keep-out polygon on the floor (k, 2) [m] (:func:`floor_xy`), checked.

    Raises:
        InputError: A coordinate beyond :data:`MAX_FLOOR_M`, or the polygon is not simple
            (it crosses itself, like a bow tie) or has no area.
    """
    import shapely

    xy = floor_xy(points, meters_per_unit, up_axis)
    table, _, name = key.partition(".")
    if not np.all(np.abs(xy) <= MAX_FLOOR_M):
        msg = (f"{source}: [{table}] {name} has a point beyond {MAX_FLOOR_M:.0e} m from the "
               "origin (a unit error?)")
        raise InputError(msg)
    polygon = shapely.Polygon(xy)
    if not polygon.is_valid or polygon.area <= 0.0:
        why = shapely.is_valid_reason(polygon) if polygon.area > 0.0 else "it has no area"
        msg = (f"{source}: [{table}] {name} is not a simple polygon on the floor ({why}); "
               "give its corners in order around it, without crossing")
        raise InputError(msg)
    return xy


def yaw_pose(x: float, y: float, z: float, yaw_deg: float) -> Array:
    """The base-to-world transform (4, 4) of a placement at x, y, z [m], turned yaw_deg about
    up: what a set file's ``[placement]`` x, y, z and yaw_deg mean."""
    a = math.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0],
                 [0.0, 0.0, 1.0]]
    T[:3, 3] = (x, y, z)
    return T


def to_toml(x: float, y: float, z: float, yaw_deg: float, text: str = "",
            layout: str | None = None) -> str:
    """A set file: ``text`` (a set file's own, "" for none) with its ``[placement]`` at x, y,
    z [m] and yaw_deg, and the layout's name when given; every other line, comments
    included, as it was (tomlkit edits the document: the placement's values where they stand,
    a ``rotation`` and an old ``layout`` removed, a missing key or table added at its end; new
    lines with the file's own line ending). The numbers are written as they are (read back,
    :func:`yaw_pose` gives the transform bit for bit: a yaw recovered from the matrix,
    -136.88000000000002, gave another, and a shot's speed can change with the last bit).

    Raises:
        InputError: The document cannot be edited so (a placement written in a form tomlkit
            cannot change).
    """
    values: dict[str, Any] = {"x": float(x), "y": float(y), "z": float(z),
                              "yaw_deg": float(yaw_deg)}
    if layout is not None:
        values["layout"] = layout

    def edit(doc: tomlkit.TOMLDocument) -> None:
        table = doc.get("placement")
        if table is None:
            table = tomlkit.table()
            table.comment("robot base in the converted world: metres, Z-up (camtraj place)")
            doc.add("placement", table)
        for key in ("rotation", "layout"):
            if key in table and key not in values:
                del table[key]
        for key, value in values.items():
            table[key] = value

    return _edited(text, edit)


def with_clearance_text(text: str, clearance_m: float) -> str:
    """A set file's ``text`` with ``[collision] clearance_m`` set, every other line kept
    (:func:`to_toml`'s rules)."""
    def edit(doc: tomlkit.TOMLDocument) -> None:
        if "collision" not in doc:
            doc.add("collision", tomlkit.table())
        doc["collision"]["clearance_m"] = float(clearance_m)  # type: ignore[index]

    return _edited(text, edit)


def _edited(text: str, edit: Callable[[tomlkit.TOMLDocument], None]) -> str:
    """``text`` (a set file's, "" for a new one) as ``edit`` changes its document, with the
    text's own line ending throughout."""
    try:
        if text.strip():
            doc = tomlkit.parse(text)
        else:
            doc = tomlkit.document()
            doc.add(tomlkit.comment("camtraj set file (written by camtraj place)"))
            doc.add(tomlkit.nl())
        edit(doc)
        out = doc.as_string()
    except (tomlkit.exceptions.TOMLKitError, KeyError, TypeError, ValueError) as exc:
        msg = f"the set file cannot be written with a new placement ({exc})"
        raise InputError(msg) from exc
    return out.replace("\r\n", "\n").replace("\n", "\r\n") if "\r\n" in text else out


def _number(value: Any, where: str, key: str, lo: float, hi: float) -> float:
    table, _, name = key.rpartition(".")
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        msg = f"{where}: [{table}] {name} = {value!r} must be a finite number in [{lo:g}, {hi:g}]"
        raise InputError(msg)
    if not lo <= value <= hi:
        msg = f"{where}: [{table}] {name} = {value!r} is outside [{lo:g}, {hi:g}]"
        raise InputError(msg)
    return float(value)


def _numbers(value: Any, n: int, where: str, key: str) -> tuple[float, ...]:
    table, _, name = key.rpartition(".")
    ok = isinstance(value, list) and len(value) == n and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for v in value)
    if not ok:
        msg = f"{where}: [{table}] {name} = {value!r} must be {n} finite numbers"
        raise InputError(msg)
    return tuple(float(v) for v in value)


def _polygon(value: Any, where: str, key: str) -> Array:
    table, _, name = key.partition(".")
    ok = isinstance(value, list) and len(value) >= 3 and all(
        isinstance(p, list) and len(p) == 3 and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for v in p)
        for p in value)
    if not ok:
        msg = (f"{where}: [{table}] {name} must be a polygon of at least 3 points, each "
               "[x, y, z] finite numbers in stage units")
        raise InputError(msg)
    return np.array(value, dtype=float)


MAX_LAYOUT_CHARS = 200


def _layout(table: dict[str, Any], where: str) -> str | None:
    value = table.get("layout")
    if value is None:
        return None
    if not isinstance(value, str) or not value.isprintable() or not 0 < len(value) \
            <= MAX_LAYOUT_CHARS:
        msg = (f"{where}: [placement] layout must be a name of 1 to {MAX_LAYOUT_CHARS} "
               "printable characters")
        raise InputError(msg)
    return value


def _placement(table: dict[str, Any], where: str) -> Array:
    vals = {k: _number(table.get(k, 0.0), where, f"placement.{k}", -1e6, 1e6)
            for k in ("x", "y", "z")}
    yaw = _number(table.get("yaw_deg", 0.0), where, "placement.yaw_deg", -360.0, 360.0)
    T = np.eye(4)
    T[:3, 3] = (vals["x"], vals["y"], vals["z"])
    if "rotation" in table:
        if "yaw_deg" in table:
            msg = f"{where}: give either yaw_deg or rotation in [placement], not both"
            raise InputError(msg)
        rot = table["rotation"]
        ok = isinstance(rot, list) and len(rot) == 3 and all(
            isinstance(r, list) and len(r) == 3 and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in r)
            for r in rot)
        R = np.array(rot, dtype=float) if ok else np.zeros((3, 3))
        if not ok or not np.all(np.isfinite(R)) or not np.allclose(
                R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            msg = f"{where}: [placement] rotation must be a 3x3 proper rotation matrix of numbers"
            raise InputError(msg)
        T[:3, :3] = R
    else:
        T = yaw_pose(vals["x"], vals["y"], vals["z"], yaw)
    return T
