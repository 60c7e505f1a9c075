"""How close a configuration is to trouble: position limits, the wrist singularity, full stretch.

The wrist singularity is tilt = ±90° (pan and roll align); its distance is the angle between
tilt and the nearest of ±90°, ``arcsin(|cos tilt|)``. Full stretch is the arm's elbow singularity:
shoulder, elbow and wrist centre in line; its distance is ``pi`` minus the interior angle of the
triangle shoulder-elbow-wrist centre at the elbow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.ik.closed_form import EXTEND, TILT, TRACK
from camtraj.robot import DHConstants, Robot

Array = NDArray[np.float64]


def wrist_distance(tilt: ArrayLike) -> Array:
    """Angle from tilt to the wrist singularity (±90°) [rad], shape of ``tilt``."""
    return np.asarray(np.arcsin(np.minimum(np.abs(np.cos(np.asarray(tilt, dtype=float))), 1.0)))


def stretch_distance(dh: DHConstants, wrist: Array, r1: ArrayLike, r4: ArrayLike) -> Array:
    """Angle from full stretch [rad]: ``pi`` minus the arm's interior angle at the elbow.

    Args:
        dh: DH constants.
        wrist: Wrist centres (flange origins), shape (..., 3) [m].
        r1, r4: Track and extend values, broadcast against ``wrist[..., 0]`` [m].
    """
    dx = wrist[..., 0] - dh.r10 - np.asarray(r1, dtype=float)
    ws2 = dx * dx + wrist[..., 1] ** 2 + (wrist[..., 2] - dh.r2) ** 2
    L = np.asarray(r4, dtype=float) + dh.r40
    dse2 = L * L + dh.l3 * dh.l3
    cos_e = (dse2 + dh.r6 * dh.r6 - ws2) / (2.0 * dh.r6 * np.sqrt(dse2))
    return np.asarray(np.pi - np.arccos(np.clip(cos_e, -1.0, 1.0)))


@dataclass(frozen=True)
class PathMargins:
    """The smallest distances of a solved shot to trouble, and where they occur.

    Attributes:
        to_limits: Per axis (8,), the smallest distance to either position limit [m, rad].
        to_limits_frame: Per axis (8,), the index of the frame where it occurs.
        wrist: The smallest distance of tilt to the wrist singularity (±90°) [rad].
        wrist_frame: Its frame index.
        stretch: The smallest distance to full stretch [rad].
        stretch_frame: Its frame index.
    """

    to_limits: Array
    to_limits_frame: NDArray[np.intp]
    wrist: float
    wrist_frame: int
    stretch: float
    stretch_frame: int


def path_margins(robot: Robot, q: ArrayLike) -> PathMargins:
    """:class:`PathMargins` of a joint path (n, 8) [m, rad]."""
    qa = np.asarray(q, dtype=float).reshape(-1, 8)
    to_lim = np.minimum(qa - robot.lower, robot.upper - qa)  # (n, 8)
    k = np.argmin(to_lim, axis=0)
    wd = wrist_distance(qa[:, TILT])
    wrist = robot.fk(qa)[:, :3, 3]
    sd = stretch_distance(robot.dh, wrist, qa[:, TRACK], qa[:, EXTEND])
    kw, ks = int(np.argmin(wd)), int(np.argmin(sd))
    return PathMargins(to_lim[k, np.arange(8)], k, float(wd[kw]), kw, float(sd[ks]), ks)
