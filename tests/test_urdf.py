"""The URDF and the tf transforms reproduce the DH forward kinematics."""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from numpy.typing import NDArray

from camtraj.robot import JOINT_NAMES, DHConstants, Robot
from camtraj.urdf import (
    BASE_FRAME,
    CAMERA_FRAME,
    LINK_FRAMES,
    OPTICAL_FRAME,
    Transform,
    axis_frame,
    link_transforms,
    robot_urdf,
    rpy_from_matrix,
    static_transforms,
)

Array = NDArray[np.float64]



def matrix_from_rpy(roll: float, pitch: float, yaw: float) -> Array:
    """URDF's rpy: ``Rz(yaw) Ry(pitch) Rx(roll)`` (checked against rot_z, rot_y, rot_x below)."""
    from scipy.spatial.transform import Rotation

    out: Array = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    return out

def _floats(text: str) -> Array:
    return np.array([float(v) for v in text.split()])


def _origin(el: ET.Element) -> Array:
    origin = el.find("origin")
    T = np.eye(4)
    if origin is not None:
        T[:3, :3] = matrix_from_rpy(*_floats(origin.get("rpy", "0 0 0")))
        T[:3, 3] = _floats(origin.get("xyz", "0 0 0"))
    return T


def _motion(joint: ET.Element, value: float) -> Array:
    """The joint's own motion: rotation about / translation along its axis (Rodrigues)."""
    kind = joint.get("type")
    T = np.eye(4)
    if kind == "fixed":
        return T
    axis_el = joint.find("axis")
    assert axis_el is not None
    axis = _floats(axis_el.get("xyz", "1 0 0"))
    axis = axis / np.linalg.norm(axis)
    if kind == "prismatic":
        T[:3, 3] = axis * value
    else:
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        T[:3, :3] = np.eye(3) + math.sin(value) * K + (1 - math.cos(value)) * K @ K
    return T


def urdf_frames(urdf: str, q: Array) -> dict[str, Array]:
    """Every link's pose in the root link, composing the URDF's origins and joint motions."""
    root = ET.fromstring(urdf)
    joints = root.findall("joint")
    by_child: dict[str, ET.Element] = {}
    for joint in joints:
        child = joint.find("child")
        assert child is not None
        by_child[child.get("link", "")] = joint
    q_by_name = dict(zip(JOINT_NAMES, q, strict=True))
    frames: dict[str, Array] = {}

    def pose(link: str) -> Array:
        if link in frames:
            return frames[link]
        joint = by_child.get(link)
        if joint is None:
            T = np.eye(4)
        else:
            parent = joint.find("parent")
            assert parent is not None
            value = q_by_name.get(joint.get("name", ""), 0.0)
            T = pose(parent.get("link", "")) @ _origin(joint) @ _motion(joint, value)
        frames[link] = T
        return T

    for link in root.findall("link"):
        pose(link.get("name", ""))
    return frames


def tf_frames(robot: Robot, q: Array) -> dict[str, Array]:
    """Every frame's pose in base_link, composing static_transforms and link_transforms."""
    edges: dict[str, Transform] = {}
    for tr in [*static_transforms(robot), *link_transforms(robot, q)]:
        assert tr.child not in edges
        edges[tr.child] = tr
    frames: dict[str, Array] = {BASE_FRAME: np.eye(4)}

    def pose(frame: str) -> Array:
        if frame not in frames:
            parent, _, child2parent = edges[frame]
            frames[frame] = pose(parent) @ child2parent
        return frames[frame]

    for child in edges:
        pose(child)
    return frames


def _random_q(robot: Robot, rng: np.random.Generator, n: int) -> Array:
    return rng.uniform(robot.lower, robot.upper, size=(n, len(robot.joint_names)))


def _odd_robot() -> Robot:
    """A robot with other lengths and a tilted, offset camera mount."""
    base = Robot.default()
    c, s = math.cos(0.4), math.sin(0.4)
    mount = np.eye(4)
    mount[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ base.camera2flange[:3, :3]
    mount[:3, 3] = [0.05, -0.12, 0.2]
    return dataclasses.replace(
        base, dh=DHConstants(r10=0.7, r2=0.45, l3=0.2, r40=3.1, r6=1.2), camera2flange=mount
    )


@pytest.mark.parametrize("robot", [Robot.default(), _odd_robot()], ids=["default", "odd"])
def test_urdf_chain_reproduces_fk(robot: Robot) -> None:
    urdf = robot_urdf(robot)
    rng = np.random.default_rng(0)
    for q in _random_q(robot, rng, 25):
        frames = urdf_frames(urdf, q)
        expected = robot.link_frames(q)
        for i, name in enumerate(LINK_FRAMES):
            np.testing.assert_allclose(frames[name], expected[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(frames[CAMERA_FRAME], robot.camera_pose(q), rtol=0, atol=1e-12)
        assert np.array_equal(frames[BASE_FRAME], np.eye(4))


@pytest.mark.parametrize("robot", [Robot.default(), _odd_robot()], ids=["default", "odd"])
def test_tf_chain_reproduces_fk(robot: Robot) -> None:
    rng = np.random.default_rng(1)
    for q in _random_q(robot, rng, 25):
        frames = tf_frames(robot, q)
        expected = robot.link_frames(q)
        for i, name in enumerate(LINK_FRAMES):
            np.testing.assert_allclose(frames[name], expected[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(frames[CAMERA_FRAME], robot.camera_pose(q), rtol=0, atol=1e-12)


def test_link_transforms_batch_matches_single() -> None:
    robot = Robot.default()
    qs = _random_q(robot, np.random.default_rng(2), 7).reshape(7, 8)
    batch = link_transforms(robot, qs)
    assert len(batch) == len(JOINT_NAMES)
    for k, q in enumerate(qs):
        for tb, ts in zip(batch, link_transforms(robot, q), strict=True):
            assert (tb.parent, tb.child) == (ts.parent, ts.child)
            assert tb.child2parent.shape == (7, 4, 4)
            np.testing.assert_array_equal(tb.child2parent[k], ts.child2parent)
    with pytest.raises(ValueError, match="8 values"):
        link_transforms(robot, np.zeros(7))


def test_transforms_match_urdf_joints() -> None:
    robot = Robot.default()
    root = ET.fromstring(robot_urdf(robot))
    joints = {j.get("name"): j for j in root.findall("joint")}

    def ends(joint: ET.Element) -> tuple[str, str]:
        parent, child = joint.find("parent"), joint.find("child")
        assert parent is not None
        assert child is not None
        return parent.get("link", ""), child.get("link", "")

    fixed = {ends(j): j for j in joints.values() if j.get("type") == "fixed"}
    statics = static_transforms(robot)
    assert {(s.parent, s.child) for s in statics} == set(fixed)
    for s in statics:
        np.testing.assert_allclose(_origin(fixed[s.parent, s.child]), s.child2parent,
                                   rtol=0, atol=1e-15)
    q = _random_q(robot, np.random.default_rng(3), 1)[0]
    for name, tr in zip(JOINT_NAMES, link_transforms(robot, q), strict=True):
        joint = joints[name]
        assert ends(joint) == (tr.parent, tr.child)
        assert tr.child == axis_frame(name)
        np.testing.assert_allclose(_origin(joint) @ _motion(joint, q[JOINT_NAMES.index(name)]),
                                   tr.child2parent, rtol=0, atol=1e-15)


def test_urdf_joints_names_limits_and_tree() -> None:
    robot = Robot.default()
    root = ET.fromstring(robot_urdf(robot))
    assert root.tag == "robot"
    assert root.get("name") == robot.name
    links = [link.get("name", "") for link in root.findall("link")]
    assert len(links) == len(set(links))
    assert set(links) == {BASE_FRAME, CAMERA_FRAME, OPTICAL_FRAME, *LINK_FRAMES,
                          *(axis_frame(n) for n in JOINT_NAMES)}
    joints = root.findall("joint")
    names = [j.get("name") for j in joints]
    assert len(names) == len(set(names))
    moving = [j for j in joints if j.get("type") != "fixed"]
    assert [j.get("name") for j in moving] == list(JOINT_NAMES)
    for i, joint in enumerate(moving):
        kind = "prismatic" if robot.joint_kinds[i] == "prismatic" else "revolute"
        assert joint.get("type") == kind
        limit = joint.find("limit")
        assert limit is not None
        assert float(limit.get("lower", "nan")) == robot.lower[i]
        assert float(limit.get("upper", "nan")) == robot.upper[i]
        assert float(limit.get("velocity", "nan")) == robot.max_velocity[i]
        assert limit.get("effort") is not None
        axis = joint.find("axis")
        assert axis is not None
        expected_axis = "0 0 -1" if JOINT_NAMES[i] == "roll" else "0 0 1"
        assert axis.get("xyz") == expected_axis
    # A tree: every link but the root is the child of exactly one joint, parents exist.
    children = []
    for joint in joints:
        parent, child = joint.find("parent"), joint.find("child")
        assert parent is not None
        assert child is not None
        assert parent.get("link") in links
        assert child.get("link") in links
        children.append(child.get("link", ""))
    assert sorted(children) == sorted(n for n in links if n != BASE_FRAME)
    # Every visual has a geometry and a defined material.
    materials = {m.get("name") for m in root.findall("material")}
    visuals = root.findall("link/visual")
    assert len(visuals) >= 10
    for vis in visuals:
        geom = vis.find("geometry")
        assert geom is not None
        assert len(geom) == 1
        assert geom[0].tag in {"box", "cylinder", "sphere"}
        mat = vis.find("material")
        assert mat is not None
        assert mat.get("name") in materials


def test_urdf_is_the_same_text_in_every_process() -> None:
    """Another interpreter, with other string hashes (set and dict orders), writes the same
    bytes: a take's /robot_description does not depend on the process that wrote it."""
    import os
    import subprocess
    import sys

    code = ("import sys; from camtraj.robot import Robot; from camtraj.urdf import robot_urdf; "
            "sys.stdout.write(robot_urdf(Robot.default()))")
    here = robot_urdf(Robot.default())
    for seed in ("1", "2"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        there = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                               env=env, check=True, timeout=120).stdout
        assert there == here
    assert here.startswith('<?xml version="1.0"?>\n<robot ')


# -- roll, pitch, yaw ---------------------------------------------------------------------------


def _random_rotations(rng: np.random.Generator, n: int) -> Array:
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    x, y, z, w = quats.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def test_rpy_known_values() -> None:
    assert rpy_from_matrix(np.eye(3)) == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(rpy_from_matrix(matrix_from_rpy(0.3, -0.2, 1.1)), (0.3, -0.2, 1.1),
                               atol=1e-15)
    # Fixed axes: first roll about x, then pitch about y, then yaw about z.
    Rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)  # 90 deg about x
    np.testing.assert_allclose(rpy_from_matrix(Rx), (math.pi / 2, 0, 0), atol=1e-15)
    Rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)  # 90 deg about z
    np.testing.assert_allclose(rpy_from_matrix(Rz), (0, 0, math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(matrix_from_rpy(0.1, 0.2, 0.3),
                               rot_z(0.3) @ rot_y(0.2) @ rot_x(0.1), atol=1e-15)
    T = np.eye(4)
    T[:3, :3] = Rz
    np.testing.assert_allclose(rpy_from_matrix(T), (0, 0, math.pi / 2), atol=1e-15)


def rot_x(a: float) -> Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a: float) -> Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a: float) -> Array:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_rpy_round_trip_random() -> None:
    for R in _random_rotations(np.random.default_rng(4), 2000):
        roll, pitch, yaw = rpy_from_matrix(R)
        assert -math.pi <= roll <= math.pi
        assert -math.pi <= yaw <= math.pi
        assert -math.pi / 2 <= pitch <= math.pi / 2
        np.testing.assert_allclose(matrix_from_rpy(roll, pitch, yaw), R, rtol=0, atol=2e-15)


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("delta", [0.0, 1e-16, 1e-13, 1e-10, 1e-8, 1e-6, 1e-4])
def test_rpy_near_gimbal_lock(sign: float, delta: float) -> None:
    rng = np.random.default_rng(5)
    for roll, yaw in rng.uniform(-math.pi, math.pi, size=(50, 2)):
        pitch = sign * (math.pi / 2 - delta)
        R = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)
        back = matrix_from_rpy(*rpy_from_matrix(R))
        np.testing.assert_allclose(back, R, rtol=0, atol=2e-15)
        # With noise of rounding size the reconstruction stays that close.
        noisy = R + rng.normal(scale=1e-16, size=(3, 3))
        np.testing.assert_allclose(matrix_from_rpy(*rpy_from_matrix(noisy)), R, rtol=0,
                                   atol=2e-15)


def test_rpy_of_dh_constants_and_mounts() -> None:
    """The exact quarter turns in the DH table (cos(pi/2) = 6e-17 noise) come out clean."""
    robot = Robot.default()
    for tr in static_transforms(robot):
        R = tr.child2parent[:3, :3]
        np.testing.assert_allclose(matrix_from_rpy(*rpy_from_matrix(R)), R, rtol=0, atol=1e-15)
