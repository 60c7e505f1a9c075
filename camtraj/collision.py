"""Collision checks of the robot against the set: the stage's meshes and gprims, with coal.

The robot is its primitive shapes (:func:`camtraj.urdf.robot_solids`, the URDF visuals); the
obstacles are the prims a set file names (``[collision] prims``, paths or glob patterns) and
every Mesh, Cube, Sphere, Cylinder, Capsule and Cone under them, with their animated world
transforms, in the converted world (metres, Z-up, as :mod:`camtraj.usd_shot` converts the
camera). Distances are coal's signed distances (negative: penetration depth).

* Gprims are exact coal shapes when their scale allows (uniform, or along the shape's own
  axes), else the convex hull of their surface. Convex meshes become coal convex solids; other
  meshes are surfaces (a part wholly inside a non-convex mesh, touching none of its faces, is
  not seen). A prim's scale and points are read at the first frame; its motion at every
  quarter frame (the pose nearest the asked time is used).
* The take is checked at every film frame, and between frames wherever the robot moves more
  than ``step`` metres since the last checked sample (servo samples of the take).
"""

from __future__ import annotations

import fnmatch
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import coal
import numpy as np
from numpy.typing import NDArray

from camtraj.errors import CollisionError, InputError, ShotFileError, frame_ranges
from camtraj.robot import Robot
from camtraj.urdf import frame_poses, robot_solids

Array = NDArray[np.float64]

GPRIMS = ("Cube", "Sphere", "Cylinder", "Capsule", "Cone")
SUBFRAMES = 4  # obstacle poses sampled per frame
NEAR = 0.1  # [m] distances are measured exactly this far beyond the clearance


@dataclass(frozen=True)
class Obstacle:
    """One obstacle, as plain arrays (picklable for worker processes).

    Attributes:
        path: Prim path.
        shape: ``"box"``, ``"sphere"``, ``"cylinder"``, ``"capsule"``, ``"cone"`` (along the
            obstacle frame's z, centred), ``"convex"`` or ``"mesh"``.
        size: Box edges (x, y, z); sphere (radius,); cylinder / capsule / cone (radius,
            height) [m]. Empty for convex and mesh.
        vertices: (k, 3) [m] in the obstacle frame (convex and mesh), else (0, 3).
        triangles: (t, 3) vertex indices (convex and mesh), else (0, 3).
        time_codes: (m,) time codes of ``poses``; one for a still obstacle.
        poses: (m, 4, 4) rigid obstacle frame -> world [m].
        centre: Centre of a sphere around the shape, in the obstacle frame [m].
        radius: Its radius [m] (for the cheap pre-test).
    """

    path: str
    shape: str
    size: tuple[float, ...]
    vertices: Array
    triangles: NDArray[np.int64]
    time_codes: Array
    poses: Array
    centre: Array
    radius: float

    def pose_at(self, time_codes: Array) -> Array:
        """(n, 4, 4) poses at the time codes (the nearest sampled pose)."""
        if self.time_codes.size == 1:
            return np.broadcast_to(self.poses[0], (len(time_codes), 4, 4))
        idx = np.abs(np.asarray(time_codes)[:, None] - self.time_codes[None, :]).argmin(axis=1)
        out: Array = self.poses[idx]
        return out

    def top(self) -> float:
        """The highest point of the obstacle [m, world up] over all its poses."""
        if self.shape in ("convex", "mesh"):
            local = self.vertices
        elif self.shape == "box":
            local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                              for sz in (-1, 1)]) * (0.5 * np.asarray(self.size))
        elif self.shape == "sphere":
            return float(np.max(self.poses[:, 2, 3]) + self.size[0])
        else:  # cylinder, capsule, cone along z, centred: the higher end's rim (a capsule's
            # cap; a cone's as a cylinder's, at least its top)
            r, half = self.size[0], 0.5 * self.size[1]
            up = np.abs(self.poses[:, 2, 2])  # the world up part of the shape's axis
            rim = r if self.shape == "capsule" else r * np.sqrt(np.maximum(0.0, 1.0 - up * up))
            return float(np.max(self.poses[:, 2, 3] + up * half + rim))
        z = np.einsum("vk,mk->mv", local, self.poses[:, 2, :3]) + self.poses[:, 2, 3, None]
        return float(z.max())


GROUND_FRAMES = ("base_link", "link1", "rotate_axis")
"""The robot's frames that never change height (the rail, the carriage on the track, the
turret turning on it): their parts stand on the floor (place lays the rail on the set file's
floor, the base :data:`~camtraj.urdf.RAIL_HEIGHT` above it on the carriage) and are not
checked against an obstacle that lies wholly at or below the floor, the floor itself given
as a prim so that the arm and the camera are checked against it. Anything rising above the
floor (a cable ramp, a flight case across the rail) is checked against them too."""
GROUND_TOL = 1e-3
"""[m] How far above the floor an obstacle's top may be and still count as the floor."""


@dataclass(frozen=True)
class Contact:
    """The closest approach of one check (below the clearance when it failed)."""

    sample: int
    distance: float
    link: str
    prim: str


# ---------------------------------------------------------------------------------------------
# Reading the obstacles from the stage
# ---------------------------------------------------------------------------------------------


def read_obstacles(stage_path: str | Path, patterns: tuple[str, ...], time_codes: Array,
                   stage2world: Array) -> list[Obstacle]:
    """The obstacles the patterns name on the stage, posed over ``time_codes`` (the frames),
    in the world [m] (``stage2world``: :func:`camtraj.usd_shot.stage_to_world` of the shot's
    units and up axis, as the shot was read).

    Raises:
        InputError: A pattern matches no prim, or a matched prim holds no geometry.
    """
    from pxr import Usd, UsdGeom

    if not patterns:
        return []
    stage = Usd.Stage.Open(str(stage_path), Usd.Stage.LoadAll)
    if not stage:
        msg = f"{stage_path}: USD could not open the file"
        raise ShotFileError(msg)
    convert = np.eye(4)
    convert[:3, :3] = stage2world
    tcs = np.asarray(time_codes, dtype=float)
    fine = np.unique(np.concatenate(
        [tcs[0] + (tcs[-1] - tcs[0]) * np.linspace(0, 1, SUBFRAMES * (len(tcs) - 1) + 1), tcs]))
    prims = list(stage.Traverse())
    chosen: dict[str, Any] = {}
    for pattern in patterns:
        rule = _pattern(pattern)
        matched = [p for p in prims if rule.fullmatch(str(p.GetPath()))]
        if not matched:
            msg = f"{stage_path}: collision prims {pattern!r} matches no prim on the stage"
            raise InputError(msg)
        for top in matched:
            _refuse_point_instancers(stage_path, top, Usd, UsdGeom)
            # instance proxies: the geometry of instanceable references, each at its own pose
            found = [p for p in Usd.PrimRange(top, Usd.TraverseInstanceProxies())
                     if p.IsA(UsdGeom.Mesh) or str(p.GetTypeName()) in GPRIMS]
            if not found:
                msg = (f"{stage_path}: collision prim {top.GetPath()} holds no mesh or gprim "
                       f"({', '.join(('Mesh', *GPRIMS))})")
                raise InputError(msg)
            chosen.update({str(p.GetPath()): p for p in found})
    cache = UsdGeom.XformCache()
    out = []
    for path, prim in chosen.items():
        moving = _might_move(prim, UsdGeom)
        times = fine if moving else tcs[:1]
        mats = np.empty((len(times), 4, 4))
        for i, tc in enumerate(times):
            cache.SetTime(Usd.TimeCode(float(tc)))
            mats[i] = convert @ np.asarray(cache.GetLocalToWorldTransform(prim)).T
        bad = np.flatnonzero(~np.all(np.isfinite(mats), axis=(1, 2)))
        if bad.size:
            msg = (f"collision prim {path}: its transform is not finite (NaN or inf) at time "
                   f"code {float(times[bad[0]]):g}")
            raise InputError(msg)
        out.append(_obstacle(path, prim, times, mats, UsdGeom))
    return out


def _refuse_point_instancers(stage_path: str | Path, top: Any, Usd: Any, UsdGeom: Any) -> None:
    """A PointInstancer's instances are not obstacles camtraj checks: refuse rather than check
    only its prototypes at their own poses."""
    p = top
    while p and not p.IsPseudoRoot():
        if p.IsA(UsdGeom.PointInstancer):
            break
        p = p.GetParent()
    else:
        p = next((q for q in Usd.PrimRange(top, Usd.TraverseInstanceProxies())
                  if q.IsA(UsdGeom.PointInstancer)), None)
    if p:
        msg = (f"{stage_path}: collision prim {top.GetPath()} uses the PointInstancer "
               f"{p.GetPath()}, whose instances camtraj does not check; name real (not "
               "point-instanced) geometry in [collision] prims")
        raise InputError(msg)


def _pattern(pattern: str) -> re.Pattern[str]:
    """A prim path pattern as a regex: ``*`` and ``?`` stay within one path element (as in a
    shell path; a matched prim's descendants are obstacles anyway), ``[...]`` as in fnmatch."""
    parts = re.split(r"(\*|\?|\[[^\]/]*\])", pattern)
    out = []
    for part in parts:
        if part == "*":
            out.append("[^/]*")
        elif part == "?":
            out.append("[^/]")
        elif part.startswith("[") and part.endswith("]") and len(part) > 2:
            out.append(fnmatch.translate(part).removeprefix("(?s:").removesuffix(")\\Z"))
        else:
            out.append(re.escape(part))
    return re.compile("".join(out))


def _might_move(prim: Any, UsdGeom: Any) -> bool:
    p = prim
    while p and not p.IsPseudoRoot():
        xf = UsdGeom.Xformable(p)
        if xf and xf.TransformMightBeTimeVarying():
            return True
        p = p.GetParent()
    return False


def _axis_rotation(axis: str) -> Array:
    """Rotation taking the local z to a USD gprim's ``axis``."""
    if axis == "X":
        return np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    if axis == "Y":
        return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    return np.eye(3)


def _obstacle(path: str, prim: Any, times: Array, mats: Array, UsdGeom: Any) -> Obstacle:
    kind = str(prim.GetTypeName())
    t0 = float(times[0])
    axis_R = np.eye(3)
    if kind in ("Cylinder", "Capsule", "Cone"):
        axis_R = _axis_rotation(str(prim.GetAttribute("axis").Get(t0) or "Z"))
    lin = mats[:, :3, :3] @ axis_R
    u, s, vt = np.linalg.svd(lin)
    if np.any(s[:, -1] <= 1e-12 * s[:, 0]) or np.any(np.linalg.det(lin) < 0):
        msg = f"collision prim {path} has a degenerate or mirrored transform"
        raise InputError(msg)
    rot = u @ vt
    scale = np.transpose(vt[0]) @ np.diag(s[0]) @ vt[0]  # the first frame's scale, local frame
    poses = np.zeros_like(mats)
    poses[:, :3, :3] = rot
    poses[:, :3, 3] = mats[:, :3, 3]
    poses[:, 3, 3] = 1.0
    d = np.diag(scale)
    diagonal = np.allclose(scale, np.diag(d), atol=1e-9 * d.max())
    uniform = diagonal and np.allclose(d, d[0], rtol=1e-9)
    radial = diagonal and math.isclose(d[0], d[1], rel_tol=1e-9)

    def attr(name: str, default: float) -> float:
        value = prim.GetAttribute(name).Get(t0)
        value = float(default if value is None else value)
        if not (math.isfinite(value) and value > 0.0):
            msg = f"collision prim {path}: {name} = {value:g} must be a positive number"
            raise InputError(msg)
        return value

    shape, size = "", cast(tuple[float, ...], ())
    if kind == "Cube" and diagonal:
        shape, size = "box", tuple(attr("size", 2.0) * d)
    elif kind == "Sphere" and uniform:
        shape, size = "sphere", (attr("radius", 1.0) * d[0],)
    elif kind in ("Cylinder", "Cone") and radial:
        shape, size = kind.lower(), (attr("radius", 1.0) * d[0], attr("height", 2.0) * d[2])
    elif kind == "Capsule" and uniform:
        shape, size = "capsule", (attr("radius", 0.5) * d[0], attr("height", 1.0) * d[0])
    if shape:
        verts, tris = np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
        return Obstacle(path, shape, tuple(float(x) for x in size), verts, tris, times, poses,
                        np.zeros(3), _bounding_radius(shape, size))
    if kind == "Mesh":
        mesh = UsdGeom.Mesh(prim)
        points = np.asarray(mesh.GetPointsAttr().Get(t0) or [], dtype=float).reshape(-1, 3)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(t0) or [], dtype=np.int64)
        indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(t0) or [], dtype=np.int64)
        _check_mesh(path, points, counts, indices, float(s[0, 0]))
        verts = points @ scale.T
        tris = _triangulate(counts, indices)
        shape = "convex" if _is_convex(verts, tris) else "mesh"
    else:
        verts = _surface_points(kind, attr) @ scale.T
        shape, tris = "convex", _hull(verts)
    centre = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
    radius = float(np.linalg.norm(verts - centre, axis=1).max())
    return Obstacle(path, shape, (), verts, tris, times, poses, centre, radius)


MAX_EXTENT_M = 1.0e6
"""Farthest a collision vertex may be from its prim's origin [m] (as the camera's limit)."""


def _check_mesh(path: str, points: Array, counts: NDArray[np.int64],
                indices: NDArray[np.int64], scale: float) -> None:
    """Refuse (InputError, naming the prim and the element) a mesh camtraj cannot check:
    a point that is not finite or absurdly far, a face of fewer than 3 vertices, an index
    that names no point, face counts that do not add up to the indices, no faces."""
    where = f"collision prim {path}"
    bad = np.flatnonzero(~np.all(np.isfinite(points), axis=1))
    if bad.size:
        msg = f"{where}: point {int(bad[0])} is not finite ({points[bad[0]].tolist()})"
        raise InputError(msg)
    far = np.flatnonzero(np.abs(points).max(axis=1) * scale > MAX_EXTENT_M) if points.size \
        else np.zeros(0, dtype=np.int64)
    if far.size:
        msg = (f"{where}: point {int(far[0])} is more than {MAX_EXTENT_M:g} m from the "
               "prim's origin; check the stage units")
        raise InputError(msg)
    if counts.size == 0:
        msg = f"{where}: the mesh has no faces"
        raise InputError(msg)
    small = np.flatnonzero(counts < 3)
    if small.size:
        msg = (f"{where}: face {int(small[0])} has {int(counts[small[0]])} vertices; "
               "every face needs at least 3")
        raise InputError(msg)
    if int(counts.sum()) != indices.size:
        msg = (f"{where}: the face vertex counts add up to {int(counts.sum())} but there are "
               f"{indices.size} face vertex indices")
        raise InputError(msg)
    wrong = np.flatnonzero((indices < 0) | (indices >= points.shape[0]))
    if wrong.size:
        msg = (f"{where}: face vertex index {int(indices[wrong[0]])} (entry {int(wrong[0])}) "
               f"names no point; the mesh has {points.shape[0]} points")
        raise InputError(msg)


def _bounding_radius(shape: str, size: tuple[float, ...]) -> float:
    """Radius of a sphere about the centre that holds the primitive."""
    if shape == "box":
        return 0.5 * math.hypot(*size)
    if shape == "sphere":
        return size[0]
    if shape == "capsule":
        return size[0] + 0.5 * size[1]
    return math.hypot(size[0], 0.5 * size[1])


def _triangulate(counts: NDArray[np.int64], indices: NDArray[np.int64]) -> NDArray[np.int64]:
    """Fan triangulation of polygon faces, (t, 3)."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = [np.stack([np.full(c - 2, indices[s]), indices[s + 1:s + c - 1],
                      indices[s + 2:s + c]], axis=1)
            for s, c in zip(starts, counts, strict=True) if c >= 3]
    return np.concatenate(tris).astype(np.int64) if tris else np.zeros((0, 3), dtype=np.int64)


def _hull(points: Array) -> NDArray[np.int64]:
    from scipy.spatial import ConvexHull

    return np.asarray(ConvexHull(points).simplices, dtype=np.int64)


def _is_convex(verts: Array, tris: NDArray[np.int64]) -> bool:
    """A closed mesh whose volume equals its convex hull's."""
    from scipy.spatial import ConvexHull

    if tris.shape[0] < 4:
        return False
    try:
        hull = ConvexHull(verts)
    except Exception:  # flat or degenerate point set: a surface
        return False
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    volume = abs(float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6.0)
    return bool(math.isclose(volume, float(hull.volume), rel_tol=1e-6))


def _surface_points(kind: str, attr: Any) -> Array:
    """Points on a gprim's surface in its own frame (axis along z), for a convex hull."""
    ang = np.linspace(0.0, 2 * math.pi, 48, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], axis=1)
    if kind == "Cube":
        h = attr("size", 2.0) / 2
        return np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)])
    if kind == "Sphere":
        r = attr("radius", 1.0)
        lat = np.linspace(-math.pi / 2, math.pi / 2, 25)
        return np.concatenate([np.stack([r * math.cos(a) * ring[:, 0], r * math.cos(a) *
                                         ring[:, 1], np.full(48, r * math.sin(a))], axis=1)
                               for a in lat])
    r, h = attr("radius", 0.5 if kind == "Capsule" else 1.0), attr(
        "height", 1.0 if kind == "Capsule" else 2.0)
    if kind == "Cone":
        return np.vstack([r * ring + [0, 0, -h / 2], [[0.0, 0.0, h / 2]]])
    if kind == "Cylinder":
        return np.vstack([r * ring + [0, 0, -h / 2], r * ring + [0, 0, h / 2]])
    lat = np.linspace(0.0, math.pi / 2, 13)  # capsule: two hemispheres
    caps = [np.stack([r * math.cos(a) * ring[:, 0], r * math.cos(a) * ring[:, 1],
                      np.full(48, sgn * (h / 2 + r * math.sin(a)))], axis=1)
            for a in lat for sgn in (-1.0, 1.0)]
    return np.concatenate(caps)


# ---------------------------------------------------------------------------------------------
# Distances
# ---------------------------------------------------------------------------------------------


def _coal_geometry(ob: Obstacle) -> Any:
    if ob.shape == "box":
        return coal.Box(*ob.size)
    if ob.shape == "sphere":
        return coal.Sphere(ob.size[0])
    if ob.shape in ("cylinder", "capsule", "cone"):
        return {"cylinder": coal.Cylinder, "capsule": coal.Capsule, "cone": coal.Cone}[
            ob.shape](ob.size[0], ob.size[1])
    model = coal.BVHModelOBBRSS()
    model.beginModel(0, 0)
    model.addVertices(np.ascontiguousarray(ob.vertices))
    model.addTriangles(np.ascontiguousarray(ob.triangles))
    model.endModel()
    if ob.shape == "convex":
        model.buildConvexHull(True, "Qt")
        return model.convex
    return model


def _transform(T: Array) -> Any:
    return coal.Transform3s(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


class CollisionModel:
    """The robot's solids and the obstacles as coal objects, ready for distance queries."""

    def __init__(self, robot: Robot, obstacles: list[Obstacle],
                 floor_z: float | None = None) -> None:
        """``floor_z``: the floor's height in the converted world [m] (the set file's), where
        the rail, carriage and turret are not checked against what lies below it (None:
        every part against every obstacle)."""
        self.robot = robot
        self.solids = robot_solids(robot)
        self.obstacles = obstacles
        self.robot_geom = [coal.Box(*s.size) if s.shape == "box" else
                           coal.Cylinder(s.size[0], s.size[1]) for s in self.solids]
        self.robot_radius = np.array([0.5 * math.hypot(*s.size) if s.shape == "box" else
                                      math.hypot(s.size[0], 0.5 * s.size[1])
                                      for s in self.solids])
        self.obstacle_geom = [_coal_geometry(ob) for ob in obstacles]
        self.floor = [floor_z is not None and ob.top() <= floor_z + GROUND_TOL
                      for ob in obstacles]
        self.ground = np.array([s.frame in GROUND_FRAMES for s in self.solids])

    def link_name(self, i: int) -> str:
        s = self.solids[i]
        return f"{s.name} ({s.frame})"

    def solid_poses(self, q: Array, base2world: Array) -> Array:
        """(n, k, 4, 4) world pose of every robot solid at joint vectors q (n, 8)."""
        frames = frame_poses(self.robot, q)
        out = np.empty((q.shape[0], len(self.solids), 4, 4))
        for j, s in enumerate(self.solids):
            offset = np.eye(4)
            offset[:3, 3] = s.xyz
            out[:, j] = base2world @ frames[s.frame] @ offset
        return out

    def closest(self, q: Array, time_codes: Array, base2world: Array,
                clearance: float) -> tuple[Array, Contact | None]:
        """Signed distance of the closest robot-obstacle pair at each sample.

        Exact distances are computed only for pairs closer than ``clearance + NEAR`` (coal's
        collision test with that security margin decides, after a bounding-sphere test).

        Returns:
            (n,) distances [m] (inf where every pair is farther than ``clearance + NEAR``),
            and the sample with the smallest distance below ``clearance`` as a
            :class:`Contact` (None if none is).
        """
        n = q.shape[0]
        best = np.full(n, np.inf)
        if not self.obstacles:
            return best, None
        solids = self.solid_poses(q, base2world)
        centres = solids[:, :, :3, 3]  # (n, k, 3)
        worst: Contact | None = None
        req = coal.DistanceRequest()
        near = coal.CollisionRequest()
        near.security_margin = clearance + NEAR
        for o, ob in enumerate(self.obstacles):
            poses = ob.pose_at(time_codes)
            oc = poses[:, :3, :3] @ ob.centre + poses[:, :3, 3]  # (n, 3)
            gap = (np.linalg.norm(centres - oc[:, None, :], axis=2) - self.robot_radius[None]
                   - ob.radius)
            geom = self.obstacle_geom[o]
            if self.floor[o]:  # the floor the track stands on
                gap[:, self.ground] = np.inf
            for i, j in zip(*np.nonzero(gap < clearance + NEAR), strict=True):
                T1, T2 = _transform(solids[i, j]), _transform(poses[i])
                if not coal.collide(self.robot_geom[j], T1, geom, T2, near,
                                    coal.CollisionResult()):
                    continue
                d = float(coal.distance(self.robot_geom[j], T1, geom, T2, req,
                                        coal.DistanceResult()))
                if d < best[i]:
                    best[i] = d
                if d < clearance and (worst is None or d < worst.distance):
                    worst = Contact(int(i), d, self.link_name(int(j)), ob.path)
        return best, worst


def check_samples(
    model: CollisionModel,
    q: Array,
    time_codes: Array,
    moments: Moments,
    base2world: Array,
    clearance: float,
) -> float:
    """Raise :class:`CollisionError` if any sample is closer than ``clearance``.

    Args:
        q: (n, 8) joint vectors; time_codes: (n,) the stage time of each; moments: when each
            is in the take.

    Returns:
        The smallest distance [m] (inf when nothing came near).
    """
    dist, worst = model.closest(q, time_codes, base2world, clearance)
    if worst is not None:
        raise collision_error(worst, moments, clearance, dist < clearance)
    return float(dist.min()) if dist.size else math.inf


@dataclass(frozen=True)
class Moments:
    """When each checked sample is: the film frame at or after it (the first frame in the
    run-up, the last in the run-out), ``phase`` -1 in the run-up, 0 in the shot, 1 in the
    run-out, and ``offset`` [s] before the first frame or after the last (0 in the shot)."""

    frames: NDArray[np.int64]
    phase: NDArray[np.int8]
    offset: Array

    @classmethod
    def of(cls, t: Array, frame_times: Array, frame_numbers: NDArray[Any]) -> Moments:
        """The moments of take times t (s), the frames at ``frame_times``."""
        at = np.searchsorted(frame_times, t - 1e-12).clip(0, len(frame_numbers) - 1)
        before, after = t < frame_times[0] - 1e-9, t > frame_times[-1] + 1e-9
        phase = np.where(before, -1, np.where(after, 1, 0)).astype(np.int8)
        offset = np.where(before, frame_times[0] - t, np.where(after, t - frame_times[-1], 0.0))
        return cls(np.asarray(frame_numbers)[at].astype(np.int64), phase, offset)

    def at(self, k: int) -> str:
        """Sample k for a person: 'frame 12', 'the run-up, 0.35 s before frame 1'."""
        frame, phase = int(self.frames[k]), int(self.phase[k])
        if phase == 0:
            return f"frame {frame}"
        side = "run-up" if phase < 0 else "run-out"
        return (f"the {side}, {float(self.offset[k]):.2f} s "
                f"{'before' if phase < 0 else 'after'} frame {frame}")

    def spans(self, hit: NDArray[np.bool_]) -> str:
        """Where the samples ``hit`` are: the shot's frames, the run-up, the run-out."""
        parts = []
        for phase, side, frame in ((-1, "run-up", 0), (0, "", 0), (1, "run-out", -1)):
            on = hit & (self.phase == phase)
            if not on.any():
                continue
            if phase == 0:
                parts.append(frame_ranges(sorted({int(f) for f in self.frames[on]})))
                continue
            far, near = float(self.offset[on].max()), float(self.offset[on].min())
            a, b = (far, near) if phase < 0 else (near, far)  # in the take's order
            parts.append(f"the {side} {a:.2f}-{b:.2f} s {'before' if phase < 0 else 'after'} "
                         f"frame {int(self.frames[frame])}")
        return ", ".join(parts)


def collision_error(contact: Contact, moments: Moments, clearance: float,
                    hit: NDArray[np.bool_] | None = None) -> CollisionError:
    """The error for a contact at sample ``contact.sample`` of ``moments`` (``hit``: every
    sample that is too close). A contact in the run-up or run-out says so, with its time: the
    film frame it is attached to is clear (a crew scrubbing that frame sees nothing)."""
    if contact.distance < 0:
        what = f"goes {100 * -contact.distance:.1f} cm into {contact.prim}"
    else:
        what = f"passes {100 * contact.distance:.1f} cm from {contact.prim}"
    k = contact.sample
    here = moments.at(k)
    also = ""
    if hit is not None and hit.sum() > 1:
        spans = moments.spans(hit)
        if spans != here:
            also = f" ({spans} too close)"
    msg = (f"{here}: the robot's {contact.link} {what} (clearance "
           f"{100 * clearance:.1f} cm){also}; move the robot or the set piece")
    return CollisionError(msg, frame=int(moments.frames[k]), link=contact.link,
                          prim=contact.prim, distance=contact.distance, clearance=clearance,
                          phase=("run-up", "shot", "run-out")[int(moments.phase[k]) + 1])


def take_samples(robot: Robot, q: Array, frame_samples: NDArray[Any],
                 step: float = 0.02) -> NDArray[np.int64]:
    """Indices of the servo samples to check: every film frame, and between samples wherever
    some point of the robot (a link origin) has moved ``step`` [m] since the last one checked.
    """
    origins = robot.link_frames(q)[:, :, :3, 3]  # (m, 9, 3)
    moved = np.linalg.norm(np.diff(origins, axis=0), axis=2).max(axis=1)
    travel = np.concatenate([[0.0], np.cumsum(moved)])
    marks = np.flatnonzero(np.diff(np.floor(travel / step)) > 0) + 1
    keep = np.union1d(np.asarray(frame_samples, dtype=np.int64), marks)
    return np.union1d(keep, [0, q.shape[0] - 1]).astype(np.int64)


def sample_times(t: Array, frame_times: Array, time_codes: Array) -> Array:
    """Stage time code of take times t: the frames' time codes, held before and after the shot."""
    return np.interp(t, frame_times, time_codes)


def check_take(
    shot_path: str | Path,
    robot: Robot,
    base2world: Array,
    take: Any,
    shot_time_codes: Array,
    stage2world: Array,
    patterns: tuple[str, ...],
    clearance: float,
    floor_z: float | None = None,
) -> float:
    """Check a timed take against the set's obstacles; the smallest distance [m].

    Args:
        take: A :class:`camtraj.timing.Take` (its servo samples are checked).
        shot_time_codes: (n,) stage time code of every film frame.
        stage2world: The shot's stage coordinates to the world (:func:`read_obstacles`).
        floor_z: The floor's height [m] (see :class:`CollisionModel`).

    Raises:
        CollisionError: Closer than ``clearance`` somewhere (names frame, link, prim, depth).
        InputError: A pattern matches nothing.
    """
    obstacles = read_obstacles(shot_path, patterns, shot_time_codes, stage2world)
    model = CollisionModel(robot, obstacles, floor_z)
    q = take.q[:, :len(robot.joint_names)]  # the joints (a lens's motors move no link)
    idx = take_samples(robot, q, take.frame_samples)
    t = take.t[idx]
    tcs = sample_times(t, take.frame_times, shot_time_codes)
    moments = Moments.of(t, take.frame_times, take.frame_numbers)
    return check_samples(model, q[idx], tcs, moments, base2world, clearance)
