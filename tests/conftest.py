"""Shared fixtures and independent geometry helpers for the tests."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.robot import Robot


@pytest.fixture(scope="session")
def robot() -> Robot:
    return Robot.default()


def rot_z(a: float) -> NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(a: float) -> NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def camera_path(robot: Robot, n: int = 240) -> NDArray[np.float64]:
    """A smooth previs-like camera move in the robot base frame, as flange poses (n, 4, 4).

    Track travel of 3 m with a sideways drift, a crane, a pan and a tilt, eased in and out,
    looking roughly down the track (the default mount's zero pose looks along +x).
    """
    s = np.linspace(0.0, 1.0, n)
    ease = 0.5 - 0.5 * np.cos(np.pi * s)
    x = 4.5 + 3.0 * ease
    y = 0.8 * np.sin(np.pi * s)
    z = 0.6 + 0.8 * ease
    yaw = 0.5 * np.sin(np.pi * s)
    pitch = -0.25 * ease
    look = robot.camera_pose(np.zeros(8))[:3, :3]
    flange2camera = np.linalg.inv(robot.camera2flange)
    out = np.zeros((n, 4, 4))
    for i in range(n):
        cam = np.eye(4)
        cam[:3, :3] = rot_z(yaw[i]) @ rot_y(pitch[i]) @ look
        cam[:3, 3] = (x[i], y[i], z[i])
        out[i] = cam @ flange2camera
    return out


def pose_error(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[float, float]:
    """Largest position error [m] and rotation angle error [rad] between pose batches."""
    a = np.asarray(a).reshape(-1, 4, 4)
    b = np.asarray(b).reshape(-1, 4, 4)
    dp = float(np.linalg.norm(a[:, :3, 3] - b[:, :3, 3], axis=1).max())
    rel = np.einsum("nji,njk->nik", a[:, :3, :3], b[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    # arccos loses precision near 0: use the skew part for small angles
    skew = np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                     rel[:, 1, 0] - rel[:, 0, 1]], axis=1)
    ang = np.arctan2(np.linalg.norm(skew, axis=1) / 2.0, cos)
    return dp, float(ang.max())
