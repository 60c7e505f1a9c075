"""Cheap placement tests, vectorised over many candidate placements at once.

The robot's reach as an envelope of the wrist centre (a solid of revolution about the rotate
axis, swept along the track), the rail's footprint on the floor, and the shot-wide tests that
refuse a camera path no placement can follow. Used by :mod:`camtraj.place` before any solve;
every test is only necessary (a candidate that passes may still fail the full solve).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from camtraj.errors import PlacementError
from camtraj.robot import JOINT_NAMES, WRIST_FRAME, Robot
from camtraj.urdf import robot_solids

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Envelope:
    """Where the wrist centre can be: per height band above the base, the horizontal distance
    from the rotate axis [m] (``rho_min``..``rho_max``, nan where unreachable)."""

    z0: float
    dz: float
    rho_min: Array
    rho_max: Array
    axis_lo: float  # rotate axis positions along the track (base x) [m]
    axis_hi: float
    offset: float  # camera nodal point to wrist centre [m]

    def bounds(self, h: Array) -> tuple[Array, Array]:
        i = np.floor((h - self.z0) / self.dz).astype(np.int64)
        inside = (i >= 0) & (i < self.rho_max.size)
        j = np.clip(i, 0, self.rho_max.size - 1)
        return (np.where(inside, self.rho_min[j], np.nan),
                np.where(inside, self.rho_max[j], np.nan))

    @property
    def height_range(self) -> tuple[float, float]:
        ok = np.flatnonzero(np.isfinite(self.rho_max))
        return self.z0 + ok[0] * self.dz, self.z0 + (ok[-1] + 1) * self.dz

    @property
    def reach(self) -> float:
        return float(np.nanmax(self.rho_max))


def reach_envelope(robot: Robot, dz: float = 0.05) -> Envelope:
    """The wrist centre's reach, sampled over lift, extend and elbow (track and rotate at 0)."""
    lo, hi = robot.lower, robot.upper
    axes = [np.linspace(lo[i], hi[i], n) for i, n in ((2, 61), (3, 9), (4, 91))]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    q = np.zeros((g.shape[0], 8))
    q[:, 2:5] = g
    wc = robot.link_frames(q)[:, WRIST_FRAME, :3, 3]
    rho = np.hypot(wc[:, 0] - robot.dh.r10, wc[:, 1])
    z = wc[:, 2]
    z0 = math.floor(z.min() / dz) * dz - dz
    nb = math.ceil((z.max() - z0) / dz) + 2
    b = np.floor((z - z0) / dz).astype(np.int64)
    rmin, rmax = np.full(nb, np.inf), np.full(nb, -np.inf)
    np.minimum.at(rmin, b, rho)
    np.maximum.at(rmax, b, rho)
    # neighbouring bands: the sampling is coarse, the test must only be necessary
    rmin = np.minimum(rmin, np.minimum(np.roll(rmin, 1), np.roll(rmin, -1))) - dz
    rmax = np.maximum(rmax, np.maximum(np.roll(rmax, 1), np.roll(rmax, -1))) + dz
    bad = ~np.isfinite(rmax)
    rmin[bad], rmax[bad] = np.nan, np.nan
    track = JOINT_NAMES.index("track")
    return Envelope(z0, dz, np.maximum(rmin, 0.0), rmax, robot.dh.r10 + float(lo[track]),
                    robot.dh.r10 + float(hi[track]),
                    float(np.linalg.norm(robot.camera2flange[:3, 3])))


def reach_slack(env: Envelope, points: Array, x: Array, y: Array, yaw_deg: Array,
                base_z: float, sizes: Sequence[int] | None = None) -> Array:
    """(N,) how far every point (k, 3) stays inside the reach from each candidate [m]
    (negative: some point is out of reach).

    With ``sizes`` (the points are consecutive groups of these sizes, one per shot of a
    scene, summing to k), (N, S): each shot's slack, all shots' points tested at once.
    """
    a = np.radians(yaw_deg)[:, None]
    dx, dy = points[None, :, 0] - x[:, None], points[None, :, 1] - y[:, None]
    s = np.cos(a) * dx + np.sin(a) * dy  # along the track
    lat = -np.sin(a) * dx + np.cos(a) * dy
    h = np.broadcast_to(points[None, :, 2] - base_z, s.shape)
    rmin, rmax = env.bounds(h)
    near = np.hypot(np.maximum(0.0, np.maximum(s - env.axis_hi, env.axis_lo - s)), lat)
    far = np.hypot(np.maximum(np.abs(s - env.axis_lo), np.abs(s - env.axis_hi)), lat)
    slack = np.minimum(rmax + env.offset - near, far - (rmin - env.offset))
    slack = np.where(np.isfinite(slack), slack, -np.inf)
    if sizes is None:
        out: Array = slack.min(axis=1)
        return out
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
    per_shot: Array = np.minimum.reduceat(slack, starts, axis=1)
    return per_shot


def rail_footprints(robot: Robot, x: Array, y: Array, yaw_deg: Array) -> Array:
    """(N, 4, 2) world corners of the rail (the robot model's ``rail`` solid) of each candidate."""
    rail = next(s for s in robot_solids(robot) if s.name == "rail")
    cx, cy = rail.xyz[0], rail.xyz[1]
    hx, hy = rail.size[0] / 2, rail.size[1] / 2
    local = np.array([[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy],
                      [cx - hx, cy + hy]])
    a = np.radians(yaw_deg)
    c, s = np.cos(a)[:, None], np.sin(a)[:, None]
    wx = x[:, None] + c * local[None, :, 0] - s * local[None, :, 1]
    wy = y[:, None] + s * local[None, :, 0] + c * local[None, :, 1]
    return np.stack([wx, wy], axis=-1)


def floor_ok(robot: Robot, x: Array, y: Array, yaw_deg: Array, region: Array | None,
             keep_out: list[Array]) -> NDArray[np.bool_]:
    """(N,) whether each candidate's rail lies inside the region and off every keep-out."""
    import shapely

    rails = shapely.polygons(rail_footprints(robot, x, y, yaw_deg))
    ok = np.ones(len(x), dtype=bool)
    if region is not None:
        ok &= shapely.contains(shapely.Polygon(region), rails)
    if keep_out:  # a tree of the keep-outs: 20,000 of them cost what a few did
        tree = shapely.STRtree([shapely.Polygon(poly) for poly in keep_out])
        hit = tree.query(rails, predicate="intersects")[0]
        ok[hit] = False
    return ok



def check_can_reach(env: Envelope, pts: Array, base_z: float) -> None:
    """Refuse a shot no placement can do: heights beyond the lift's, path beyond track + reach."""
    zlo, zhi = env.height_range
    h = pts[:, 2] - base_z
    if h.min() < zlo - env.offset or h.max() > zhi + env.offset:
        msg = (f"the camera path's height above the robot's base ({h.min():.2f} to "
               f"{h.max():.2f} m) exceeds the lift's reach ({zlo - env.offset:.2f} to "
               f"{zhi + env.offset:.2f} m)")
        raise PlacementError(msg)
    if h.max() - h.min() > zhi - zlo + 2 * env.offset:
        msg = (f"the camera path's height range {h.max() - h.min():.2f} m exceeds the lift's "
               f"{zhi - zlo + 2 * env.offset:.2f} m")
        raise PlacementError(msg)
    xy = pts[:, :2] - pts[:, :2].mean(axis=0)
    ang = np.radians(np.arange(0.0, 360.0, 1.0))  # 180..360: the perpendicular of 0..180
    proj = xy @ np.stack([np.cos(ang), np.sin(ang)])
    extent = proj.max(axis=0) - proj.min(axis=0)
    along, across = extent[:180], extent[90:270]
    length = env.axis_hi - env.axis_lo + 2 * (env.reach + env.offset)
    width = 2 * (env.reach + env.offset)
    if not np.any((along <= length) & (across <= width)):
        i = int(np.argmax(along))
        msg = (f"the camera path is {along[i]:.2f} m long and {across[i]:.2f} m wide on the "
               f"floor; the track ({env.axis_hi - env.axis_lo:.2f} m) and the arm's reach cover "
               f"at most {length:.2f} m by {width:.2f} m")
        raise PlacementError(msg)
