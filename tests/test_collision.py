"""Collision geometry: stage prims read into coal shapes, in the converted world, and the robot's
solids posed by the same frames as the URDF / tf."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import coal
import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom

from camtraj.collision import CollisionModel, Obstacle, _coal_geometry, read_obstacles, take_samples
from camtraj.errors import InputError
from camtraj.robot import Robot
from camtraj.urdf import (
    frame_poses,
    link_transforms,
    robot_solids,
    robot_urdf,
    static_transforms,
)
from camtraj.usd_shot import stage_to_world

PROBE = 0.01  # radius of the probe sphere [m]


def probe(ob: Obstacle, point: tuple[float, float, float], tc: float = 1.0) -> float:
    """Signed distance from a small sphere at a world point to the obstacle."""
    pose = ob.pose_at(np.array([tc]))[0]
    res = coal.DistanceResult()
    return float(coal.distance(coal.Sphere(PROBE), coal.Transform3s(np.eye(3), np.array(point)),
                               _coal_geometry(ob), coal.Transform3s(pose[:3, :3], pose[:3, 3]),
                               coal.DistanceRequest(), res)) + PROBE


@pytest.fixture(scope="module")
def yup_stage(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A Y-up centimetre stage with one of each gprim, two meshes and a moving cube."""
    path = tmp_path_factory.mktemp("coll") / "set.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(11)
    ball = UsdGeom.Sphere.Define(stage, "/set/ball")
    ball.CreateRadiusAttr(50.0)
    ball.AddTranslateOp().Set(Gf.Vec3d(100.0, 200.0, 300.0))  # world (1, -3, 2) m
    pipe = UsdGeom.Cylinder.Define(stage, "/set/pipe")
    pipe.CreateRadiusAttr(20.0)
    pipe.CreateHeightAttr(200.0)
    pipe.CreateAxisAttr("X")
    cap = UsdGeom.Capsule.Define(stage, "/set/cap")
    cap.CreateRadiusAttr(10.0)
    cap.CreateHeightAttr(100.0)
    cap.CreateAxisAttr("Y")  # stage Y = world up
    cap.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, -500.0))  # world (0, 5, 0) m
    cone = UsdGeom.Cone.Define(stage, "/set/cone")
    cone.CreateRadiusAttr(30.0)
    cone.CreateHeightAttr(60.0)
    cone.CreateAxisAttr("Y")  # point up
    cone.AddTranslateOp().Set(Gf.Vec3d(-500.0, 0.0, 0.0))  # world (-5, 0, 0)
    box = UsdGeom.Cube.Define(stage, "/set/box")
    box.CreateSizeAttr(100.0)
    box.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1000.0))  # world (0, -10, 0)
    box.AddScaleOp().Set(Gf.Vec3f(2.0, 1.0, 0.5))  # 2 m (x), 1 m (world z), 0.5 m (world y)
    egg = UsdGeom.Sphere.Define(stage, "/set/egg")
    egg.CreateRadiusAttr(10.0)
    egg.AddTranslateOp().Set(Gf.Vec3d(1000.0, 0.0, 0.0))  # world (10, 0, 0)
    egg.AddScaleOp().Set(Gf.Vec3f(3.0, 1.0, 1.0))  # an ellipsoid: convex hull of its surface
    corners = [(x, y, z) for x in (0, 100) for y in (0, 100) for z in (0, 100)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    crate = UsdGeom.Mesh.Define(stage, "/set/props/crate")  # a closed convex mesh
    crate.CreatePointsAttr([Gf.Vec3f(*c) for c in corners])
    crate.CreateFaceVertexCountsAttr([4] * 6)
    crate.CreateFaceVertexIndicesAttr([i for q in quads for i in q])
    crate.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, -1500.0))  # world (0, 14, 0) .. (1, 15, 1)
    sheet = UsdGeom.Mesh.Define(stage, "/set/props/sheet")  # an open surface
    sheet.CreatePointsAttr([Gf.Vec3f(0, 0, 0), Gf.Vec3f(100, 0, 0), Gf.Vec3f(100, 0, 100),
                            Gf.Vec3f(0, 0, 100)])
    sheet.CreateFaceVertexCountsAttr([4])
    sheet.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    sheet.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 2000.0))  # floor square at world y -20..-21
    mover = UsdGeom.Cube.Define(stage, "/moving/cube")
    mover.CreateSizeAttr(20.0)
    op = mover.AddTranslateOp()
    op.Set(Gf.Vec3d(0.0, 0.0, 0.0), 1.0)
    op.Set(Gf.Vec3d(1000.0, 0.0, 0.0), 11.0)  # 10 m along x over 10 frames
    stage.GetRootLayer().Save()
    return path


@pytest.fixture(scope="module")
def obstacles(yup_stage: Path) -> dict[str, Obstacle]:
    obs = read_obstacles(yup_stage, ("/set/*", "/moving"), np.arange(1.0, 12.0),
                         stage_to_world(0.01, "Y"))
    return {o.path: o for o in obs}


def test_every_gprim_and_mesh_under_the_patterns_is_read(obstacles: dict[str, Obstacle]) -> None:
    shapes = {p: o.shape for p, o in obstacles.items()}
    assert shapes == {"/set/ball": "sphere", "/set/pipe": "cylinder", "/set/cap": "capsule",
                      "/set/cone": "cone", "/set/box": "box", "/set/egg": "convex",
                      "/set/props/crate": "convex", "/set/props/sheet": "mesh",
                      "/moving/cube": "box"}


@pytest.mark.parametrize(
    ("prim", "point", "distance"),
    [
        ("/set/ball", (1.0, -3.0, 3.5), 1.0),  # 1.5 m above the centre, radius 0.5
        ("/set/ball", (1.0, -3.0, 2.2), -0.3),  # inside: penetration depth
        ("/set/pipe", (0.5, 0.0, 0.9), 0.7),  # beside the X-axis pipe (radius 0.2)
        ("/set/pipe", (1.3, 0.0, 0.0), 0.3),  # beyond its end (half length 1)
        ("/set/cap", (0.0, 5.0, 1.0), 0.4),  # above the capsule's top (0.5 + 0.1)
        ("/set/cone", (-5.0, 0.0, 0.5), 0.2),  # above the cone's point (z = 0.3)
        ("/set/box", (2.0, -10.0, 0.0), 1.0),  # box half sizes 1 (x), 0.25 (y), 0.5 (z)
        ("/set/box", (0.0, -11.0, 0.0), 0.75),
        ("/set/box", (0.0, -10.0, 1.5), 1.0),
        ("/set/props/crate", (0.5, 14.5, 0.5), -0.5),  # centre of the convex crate
        ("/set/props/crate", (0.5, 14.5, 3.0), 2.0),
        ("/set/props/sheet", (0.5, -20.5, 0.75), 0.75),
    ],
)
def test_distances_in_the_converted_world(obstacles: dict[str, Obstacle], prim: str,
                                          point: tuple[float, float, float],
                                          distance: float) -> None:
    assert probe(obstacles[prim], point) == pytest.approx(distance, abs=2e-3)


def test_non_uniform_sphere_is_its_convex_hull(obstacles: dict[str, Obstacle]) -> None:
    egg = obstacles["/set/egg"]  # radii 0.3 (x), 0.1, 0.1 m at (10, 0, 0)
    assert probe(egg, (10.0, 0.0, 1.0)) == pytest.approx(0.9, abs=2e-3)
    assert probe(egg, (11.0, 0.0, 0.0)) == pytest.approx(0.7, abs=2e-3)


def test_animated_obstacle_follows_its_transform(obstacles: dict[str, Obstacle]) -> None:
    cube = obstacles["/moving/cube"]
    assert probe(cube, (5.0, 0.0, 1.1), tc=6.0) == pytest.approx(1.0, abs=2e-3)
    assert probe(cube, (5.0, 0.0, 1.1), tc=1.0) == pytest.approx(np.hypot(4.9, 1.0), abs=2e-3)


def test_a_pattern_matching_nothing_is_bad_input(yup_stage: Path) -> None:
    with pytest.raises(InputError, match="/nothing"):
        read_obstacles(yup_stage, ("/nothing/*",), np.arange(1.0, 3.0), np.eye(3))


def test_solids_hang_in_the_urdf_frames(robot: Robot) -> None:
    """frame_poses agrees with FK and with composing the tf tree's own transforms."""
    rng = np.random.default_rng(3)
    q = robot.lower + rng.random((5, 8)) * (robot.upper - robot.lower)
    poses = frame_poses(robot, q)
    assert np.allclose(poses["camera"], robot.camera_pose(q))
    statics = {t.child: t for t in static_transforms(robot)}
    for t in link_transforms(robot, q):
        link = statics[next(c for c, s in statics.items() if s.parent == t.child)]
        assert np.allclose(poses[t.parent] @ t.child2parent @ link.child2parent,
                           poses[link.child])
    assert {s.frame for s in robot_solids(robot)} <= set(poses)


def test_robot_against_a_slab_under_the_carriage(robot: Robot) -> None:
    """A box on the floor beside the carriage, 10 cm from it."""
    q = np.zeros((1, 8))
    carriage = next(s for s in robot_solids(robot) if s.name == "carriage")
    R = frame_poses(robot, q)["link1"][0, :3, :3]
    y_edge = float(np.abs(R[1]) @ np.array(carriage.size)) / 2  # its half width across y
    slab = Obstacle("/slab", "box", (0.5, 0.2, 0.05), np.zeros((0, 3)),
                    np.zeros((0, 3), dtype=np.int64), np.array([1.0]),
                    np.array([[[1, 0, 0, robot.dh.r10], [0, 1, 0, y_edge + 0.2],
                               [0, 0, 1, -0.05], [0, 0, 0, 1.0]]]), np.zeros(3), 0.3)
    model = CollisionModel(robot, [slab])
    dist, worst = model.closest(q, np.array([1.0]), np.eye(4), 0.05)
    assert worst is None and dist[0] == pytest.approx(0.1, abs=1e-6)
    dist, worst = model.closest(q, np.array([1.0]), np.eye(4), 0.2)
    assert worst is not None and worst.link == "carriage (link1)" and worst.prim == "/slab"


def test_take_samples_hold_every_frame_and_more_where_it_moves(robot: Robot) -> None:
    m = 200
    q = np.zeros((m, 8))
    q[:100, 0] = np.linspace(0.0, 0.01, 100)  # slow
    q[100:, 0] = np.linspace(0.01, 4.0, 100)  # fast: 4 m in 100 samples
    frames = np.arange(0, m, 25)
    idx = take_samples(robot, q, frames, step=0.05)
    assert set(frames) <= set(idx.tolist())
    assert np.count_nonzero(idx < 100) <= len(frames[frames < 100]) + 1
    moved = np.abs(np.diff(q[idx, 0]))
    assert moved.max() <= 0.05 + 4.0 / 99
    assert np.count_nonzero(idx >= 100) >= 4.0 / 0.05 - 1


def test_a_contact_in_the_run_up_or_run_out_is_named_there_not_at_a_frame() -> None:
    """Samples before the first frame are the run-up and after the last the run-out: a
    contact there says so, with its time from the frame (that frame itself is clear: a crew
    scrubbing it in previs would see nothing); one in the shot names its frame."""
    from camtraj.collision import Contact, Moments, collision_error

    frame_times = np.array([0.5, 0.5 + 1 / 24, 0.5 + 2 / 24])  # frames 10-12 after a run-up
    t = np.array([0.0, 0.25, 0.5, 0.52, 0.5 + 2 / 24, 0.8, 1.2])
    moments = Moments.of(t, frame_times, np.array([10, 11, 12]))
    assert moments.phase.tolist() == [-1, -1, 0, 0, 0, 1, 1]
    assert moments.frames.tolist() == [10, 10, 10, 11, 12, 12, 12]
    hit = np.array([False, False, False, False, True, True, True])
    out = collision_error(Contact(6, -0.039, "elbow hub (elbow_axis)", "/beam"), moments, 0.0,
                          hit)
    msg = str(out)
    assert msg.startswith("the run-out, 0.62 s after frame 12: the robot's elbow hub "
                          "(elbow_axis) goes 3.9 cm into /beam"), msg
    assert "(frame 12, the run-out 0.22-0.62 s after frame 12 too close)" in msg, msg
    assert out.phase == "run-out" and out.frame == 12
    up = collision_error(Contact(1, 0.01, "carriage (link1)", "/wall"), moments, 0.05)
    assert str(up).startswith("the run-up, 0.25 s before frame 10: the robot's carriage"), up
    assert up.phase == "run-up"
    shot = collision_error(Contact(3, -0.02, "carriage (link1)", "/wall"), moments, 0.0)
    assert str(shot).startswith("frame 11: the robot's carriage") and shot.phase == "shot"


def _lowest(model: CollisionModel, q: np.ndarray) -> dict[str, float]:
    """Each robot part's lowest point [m] at joint vector q (base at the origin), by hand:
    a box's lowest corner, a cylinder's lower rim."""
    poses = model.solid_poses(q[None], np.eye(4))[0]
    out = {}
    for s, T in zip(model.solids, poses, strict=True):
        if s.shape == "box":
            corners = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)])
            out[s.name] = float((T[:3, :3] @ (0.5 * corners * s.size).T)[2].min() + T[2, 3])
        else:
            r, up = s.size[0], abs(T[2, 2])
            out[s.name] = T[2, 3] - up * 0.5 * s.size[1] - r * math.sqrt(max(0.0, 1 - up * up))
    return out


def test_the_floor_the_robot_stands_on_is_an_obstacle_for_the_arm_not_the_track(
        robot: Robot) -> None:
    """A floor slab whose top is the set file's floor height (place stands the base on it)
    catches the arm and the camera going into it, not the rail, carriage and turret standing
    on it (every placement collided with it: 'the carriage goes 10.0 cm into
    /World/set/floor'); a plinth rising 5 cm above the floor is an obstacle for them too, and
    so is a cable ramp under the carriage of a rail standing on the floor."""
    def slab(top: float) -> Obstacle:
        T = np.eye(4)
        T[:3, 3] = (4.0, 0.0, top - 0.05)
        return Obstacle("/floor", "box", (30.0, 30.0, 0.1), np.zeros((0, 3)),
                        np.zeros((0, 3), dtype=np.int64), np.array([1.0]), T[None],
                        np.zeros(3), 15.1)

    floor = CollisionModel(robot, [slab(0.0)], floor_z=0.0)
    plinth = CollisionModel(robot, [slab(0.05)], floor_z=0.0)
    ground = {"rail", "carriage", "turret"}
    rng = np.random.default_rng(0)
    qs = robot.lower + rng.random((200, 8)) * (robot.upper - robot.lower)
    high = next(q for q in qs if min(v for k, v in _lowest(floor, q).items()
                                     if k not in ground) > 0.1)
    assert _lowest(floor, high)["carriage"] < -0.09  # it stands below the base
    _, worst = floor.closest(high[None], np.ones(1), np.eye(4), 0.0)
    assert worst is None
    _, worst = plinth.closest(high[None], np.ones(1), np.eye(4), 0.0)
    assert worst is not None and worst.link.split(" (")[0] in ground and worst.distance < 0
    # the rail standing on the floor (the base 18 cm up): a 15 cm cable ramp under the
    # carriage is no floor, and the carriage is checked against it
    ramp = CollisionModel(robot, [slab(0.15)], floor_z=0.0)
    up = np.eye(4)
    up[2, 3] = 0.18
    _, worst = ramp.closest(high[None], np.ones(1), up, 0.0)
    assert worst is not None and worst.link.split(" (")[0] in ground and worst.distance < 0
    _, worst = floor.closest(high[None], np.ones(1), up, 0.0)
    assert worst is None
    low = next(q for q in qs if min(_lowest(floor, q).values()) < -0.2)
    _, worst = floor.closest(low[None], np.ones(1), np.eye(4), 0.0)
    assert worst is not None and worst.link.split(" (")[0] not in ground and worst.distance < 0


def test_a_case_on_the_floor_across_the_rail_collides(robot: Robot) -> None:
    """Place stands the base on the rail lying on the floor (RAIL_HEIGHT up: the URDF's rail
    underside), so a flight case standing on the floor across the rail goes into it (with
    the base on the floor, the rail was sunk 10-18 cm into it and the case read 10 cm clear:
    place laid a track through a set piece)."""
    from camtraj.urdf import RAIL_HEIGHT

    root = ET.fromstring(robot_urdf(robot))
    vis = root.find("link[@name='base_link']/visual")
    assert vis is not None
    z = float(vis.find("origin").get("xyz").split()[2])  # type: ignore[union-attr]
    depth = float(vis.find("geometry/box").get("size").split()[2])  # type: ignore[union-attr]
    assert z - depth / 2 == pytest.approx(-RAIL_HEIGHT, abs=1e-12)  # the rail's underside
    T = np.eye(4)
    far_end = robot.dh.r10 + float(robot.upper[0])  # the carriage's far end: the arm is away
    T[:3, 3] = (far_end, 0.0, 0.25)  # 50 cm tall, on the floor, across the rail
    case = Obstacle("/case", "box", (1.2, 0.6, 0.5), np.zeros((0, 3)),
                    np.zeros((0, 3), dtype=np.int64), np.array([1.0]), T[None], np.zeros(3), 0.72)
    model = CollisionModel(robot, [case], floor_z=0.0)
    on_rail = np.eye(4)
    on_rail[2, 3] = RAIL_HEIGHT
    dist, worst = model.closest(np.zeros((1, 8)), np.ones(1), on_rail, 0.0)
    assert worst is not None and worst.link == "rail (base_link)" and dist[0] < -0.05
