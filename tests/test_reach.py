"""The cheap placement tests never reject what the robot can reach (FK of random poses)."""

from __future__ import annotations

import numpy as np

from camtraj.reach import floor_ok, rail_footprints, reach_envelope, reach_slack
from camtraj.robot import Robot


def test_every_reachable_camera_position_passes_the_reach_test(robot: Robot) -> None:
    rng = np.random.default_rng(7)
    q = robot.lower + rng.random((3000, 8)) * (robot.upper - robot.lower)
    cams = robot.camera_pose(q)[:, :3, 3]
    env = reach_envelope(robot)
    # the robot placed at (3, -2) turned by 40 deg: the same points in world coordinates
    a = np.radians(40.0)
    R = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    world = cams @ R.T + [3.0, -2.0, 0.5]
    for p in world[::10]:
        slack = reach_slack(env, p[None], np.array([3.0]), np.array([-2.0]), np.array([40.0]),
                            0.5)
        assert slack[0] >= 0.0, p
    far = world[:1] + np.array([0.0, 0.0, 30.0])
    assert reach_slack(env, far, np.array([3.0]), np.array([-2.0]), np.array([40.0]), 0.5)[0] < 0


def test_rail_footprint_against_region_and_keep_out(robot: Robot) -> None:
    x, y, yaw = np.array([0.0, 0.0]), np.array([0.0, 10.0]), np.array([0.0, 90.0])
    rails = rail_footprints(robot, x, y, yaw)
    assert rails.shape == (2, 4, 2)
    # the first rail runs along +x from about -1.6 m to 15.6 m, 0.5 m wide
    assert rails[0, :, 0].min() < -1.0 and rails[0, :, 0].max() > 15.0
    assert np.allclose(np.abs(rails[0, :, 1]), 0.25)
    region = np.array([[-5.0, -5.0], [20.0, -5.0], [20.0, 5.0], [-5.0, 5.0]])
    assert floor_ok(robot, x, y, yaw, region, []).tolist() == [True, False]
    keep_out = [np.array([[5.0, -1.0], [6.0, -1.0], [6.0, 1.0], [5.0, 1.0]])]
    assert floor_ok(robot, x, y, yaw, None, keep_out).tolist() == [False, True]
