"""A URDF of the camera robot built from its DH model, and the matching tf transforms.

Every DH row ``A_i = Rz(theta0 + s*q) Tz(d0 + s*q) Tx(a) Rx(alpha)`` is split into the joint's
motion (``Rz(s*q)`` for a revolute axis, ``Tz(s*q)`` for a prismatic one; both commute with the
constant ``Rz(theta0) Tz(d0)`` part) followed by the constant transform
``C_i = Rz(theta0) Tz(d0) Tx(a) Rx(alpha)``. In the URDF that becomes

    link{i-1} --[<joint name>, moving, axis ±z, identity origin]--> <joint name>_axis
              --[<joint name>_axis_to_link{i}, fixed, origin C_i]--> link{i}

so ``link{i}`` is the paper's frame i (``robot.link_frames(q)[..., i, :, :]``) in ``base_link``
(the robot base frame), and ``camera`` hangs off ``link8`` (the flange) by ``robot.camera2flange``.
Visuals are primitive shapes, good enough to recognise the machine in a 3-D viewer.

Frames (parent -> child):
    base_link -> link0                     fixed, A0
    link{i-1} -> <joint>_axis              moving, joint i = track, rotate, ..., roll
    <joint>_axis -> link{i}                fixed, C_i
    link8 -> camera                        fixed, camera2flange
    camera -> camera_optical               fixed, Rx(pi): the ROS optical frame (z forward,
                                           y down) of the USD-convention camera (-z forward)
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from camtraj.robot import DHRow, Robot

Array = NDArray[np.float64]

BASE_FRAME = "base_link"
CAMERA_FRAME = "camera"
OPTICAL_FRAME = "camera_optical"
"""The camera's ROS optical frame (REP 103: z forward, x right, y down), for CameraInfo."""
LINK_FRAMES: tuple[str, ...] = tuple(f"link{i}" for i in range(9))

_EFFORT = "0"  # URDF requires an effort limit; camtraj does not model forces.


class Transform(NamedTuple):
    """One edge of the frame tree, ``(parent, child, child2parent)``.

    ``child2parent`` maps child coordinates into the parent frame, shape (..., 4, 4) (a
    batch for the moving joints at several q).
    """

    parent: str
    child: str
    child2parent: Array


def axis_frame(joint_name: str) -> str:
    """The name of the intermediate frame a joint moves (its child link)."""
    return f"{joint_name}_axis"


# ---------------------------------------------------------------------------------------------
# Transforms for tf
# ---------------------------------------------------------------------------------------------


def _rot_z(angle: ArrayLike) -> Array:
    """Rotations about z by ``angle`` [rad], shape (..., 4, 4)."""
    ang = np.asarray(angle, dtype=float)
    c, s = np.cos(ang), np.sin(ang)
    out = np.zeros((*ang.shape, 4, 4))
    out[..., 0, 0] = c
    out[..., 0, 1] = -s
    out[..., 1, 0] = s
    out[..., 1, 1] = c
    out[..., 2, 2] = 1.0
    out[..., 3, 3] = 1.0
    return out


def _trans_z(dist: ArrayLike) -> Array:
    """Translations along z by ``dist`` [m], shape (..., 4, 4)."""
    d = np.asarray(dist, dtype=float)
    out = np.zeros((*d.shape, 4, 4))
    out[..., :, :] = np.eye(4)
    out[..., 2, 3] = d
    return out


def dh_constant(row: DHRow) -> Array:
    """The constant part ``Rz(theta0) Tz(d0) Tx(a) Rx(alpha)`` of a DH row, shape (4, 4)."""
    ct, st = math.cos(row.theta0), math.sin(row.theta0)
    ca, sa = math.cos(row.alpha), math.sin(row.alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, row.a * ct],
            [st, ct * ca, -ct * sa, row.a * st],
            [0.0, sa, ca, row.d0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def _moving_rows(robot: Robot) -> list[tuple[int, DHRow]]:
    rows = robot.dh.rows()
    out: list[tuple[int, DHRow]] = []
    for i, row in enumerate(rows):
        if row.joint is None:
            if i != 0:
                msg = f"DH row {i} has no joint; only A0 may be fixed"
                raise ValueError(msg)
            continue
        out.append((i, row))
    return out


class JointAxis(NamedTuple):
    """A moving joint as a frame-tree edge: ``child`` turns about / slides along the z axis
    of ``parent`` by ``sign * q[joint]`` (``kind`` is ``"revolute"`` or ``"prismatic"``)."""

    parent: str
    child: str
    joint: int
    kind: str
    sign: float


def joint_axes(robot: Robot) -> list[JointAxis]:
    """The moving joints in joint order, parent ``link{i-1}``, child ``<joint>_axis``."""
    out: list[JointAxis] = []
    for i, row in _moving_rows(robot):
        assert row.joint is not None
        kind = "revolute" if row.kind == "revolute" else "prismatic"
        name = robot.joint_names[row.joint]
        out.append(JointAxis(LINK_FRAMES[i - 1], axis_frame(name), row.joint, kind, row.sign))
    return out


def link_transforms(robot: Robot, q: ArrayLike) -> list[Transform]:
    """The moving-joint transforms (for ``/tf``) at joint vectors q.

    Args:
        robot: The robot.
        q: Joint vectors, shape (..., 8) [m, rad], in ``robot.joint_names`` order.

    Returns:
        One ``Transform`` per joint in joint order, parent ``link{i-1}``, child
        ``<joint>_axis``, ``child2parent`` of shape (..., 4, 4).
    """
    qa = np.asarray(q, dtype=float)
    if qa.shape[-1:] != (len(robot.joint_names),):
        msg = f"joint vectors must have {len(robot.joint_names)} values, got shape {qa.shape}"
        raise ValueError(msg)
    out: list[Transform] = []
    for axis in joint_axes(robot):
        value = axis.sign * qa[..., axis.joint]
        motion = _rot_z(value) if axis.kind == "revolute" else _trans_z(value)
        out.append(Transform(axis.parent, axis.child, motion))
    return out


def static_transforms(robot: Robot) -> list[Transform]:
    """The fixed transforms (for ``/tf_static``), each ``child2parent`` of shape (4, 4).

    ``base_link -> link0`` (A0), ``<joint>_axis -> link{i}`` (the constant DH part) for
    every joint, ``link8 -> camera`` (``robot.camera2flange``) and ``camera ->
    camera_optical``.
    """
    rows = robot.dh.rows()
    out = [Transform(BASE_FRAME, LINK_FRAMES[0], dh_constant(rows[0]))]
    for i, row in _moving_rows(robot):
        assert row.joint is not None
        out.append(Transform(axis_frame(robot.joint_names[row.joint]), LINK_FRAMES[i],
                             dh_constant(row)))
    out.append(
        Transform(LINK_FRAMES[-1], CAMERA_FRAME, np.array(robot.camera2flange, dtype=float))
    )
    out.append(Transform(CAMERA_FRAME, OPTICAL_FRAME, np.diag([1.0, -1.0, -1.0, 1.0])))
    return out


# ---------------------------------------------------------------------------------------------
# Roll-pitch-yaw
# ---------------------------------------------------------------------------------------------


def rpy_from_matrix(R: ArrayLike) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw [rad] of a rotation: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.

    Stable at and near gimbal lock (pitch = ±pi/2): yaw is taken first from the first
    column, then pitch and roll from ``Rz(-yaw) R``, whose entries used here stay O(1), so
    whatever yaw is picked when it is ill-defined, roll absorbs it and the product
    reproduces R to rounding error. (scipy's ``Rotation.as_euler("ZYX")`` gives R back only
    to 1e-13 within 1e-8 rad of the lock, where a camera mount looking straight down sits.)

    Args:
        R: A rotation matrix, shape (3, 3) (or a (4, 4) transform; its rotation is used).
    """
    Rm = np.asarray(R, dtype=float)[:3, :3]
    yaw = math.atan2(Rm[1, 0], Rm[0, 0]) if math.hypot(Rm[0, 0], Rm[1, 0]) > 1e-300 else 0.0
    cy, sy = math.cos(yaw), math.sin(yaw)
    # N = Rz(-yaw) R = Ry(pitch) Rx(roll) = [[cp, sp sr, sp cr], [0, cr, -sr], [-sp, cp sr, cp cr]]
    n00 = cy * Rm[0, 0] + sy * Rm[1, 0]
    n11 = -sy * Rm[0, 1] + cy * Rm[1, 1]
    n12 = -sy * Rm[0, 2] + cy * Rm[1, 2]
    pitch = math.atan2(-Rm[2, 0], n00)
    roll = math.atan2(-n12, n11)
    return roll, pitch, yaw


# ---------------------------------------------------------------------------------------------
# URDF
# ---------------------------------------------------------------------------------------------

MATERIALS: dict[str, tuple[float, float, float, float]] = {
    "camtraj_rail": (0.35, 0.36, 0.38, 1.0),
    "camtraj_body": (0.93, 0.47, 0.12, 1.0),
    "camtraj_joint": (0.16, 0.16, 0.18, 1.0),
    "camtraj_camera": (0.05, 0.05, 0.06, 1.0),
    "camtraj_lens": (0.20, 0.32, 0.55, 1.0),
}
"""Material name -> RGBA colour (0-1) of the visuals."""

def _num(x: float) -> str:
    """Shortest round-trip text of a float, with rounding noise below 1e-15 snapped to 0."""
    v = float(x)
    if abs(v) < 1e-15:
        v = 0.0
    text = repr(v)
    return text[:-2] if text.endswith(".0") else text


def _vec(values: ArrayLike) -> str:
    return " ".join(_num(v) for v in np.asarray(values, dtype=float).ravel())


def _origin(parent: ET.Element, T: Array) -> None:
    roll, pitch, yaw = rpy_from_matrix(T)
    ET.SubElement(parent, "origin", xyz=_vec(T[:3, 3]), rpy=_vec([roll, pitch, yaw]))


class Solid(NamedTuple):
    """One primitive shape of the robot model, fixed in one frame of the tree.

    Attributes:
        name: What it is (``"forearm"``, ``"rail"``, ...), for reports.
        frame: The frame it hangs in (``base_link``, ``link3``, ``pan_axis``, ``camera``, ...).
        shape: ``"box"`` or ``"cylinder"`` (a cylinder along the frame's local z).
        size: Box edge lengths (x, y, z), or (radius, length) of a cylinder [m].
        xyz: Centre of the shape in the frame [m].
        material: URDF material name.
    """

    name: str
    frame: str
    shape: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float]
    material: str


RAIL_HEIGHT = 0.18
"""[m] How far the base frame (``base_link``) stands above the floor the rail lies on: the
rail (8 cm) and the carriage on it (10 cm) are under the base (:func:`robot_solids`), so
``place`` stands the base this high above the set file's floor (with the base on the floor
they were sunk into it, and a flight case on the floor across the rail was 10 cm clear)."""


def robot_solids(robot: Robot) -> list[Solid]:
    """The robot as primitive shapes: the URDF visuals and the collision model are these.

    See the module docstring for where the frames sit.
    """
    dh = robot.dh
    names = robot.joint_names
    ax = {n: axis_frame(n) for n in names}
    track = names.index("track")
    extend = names.index("extend")
    # Rail along the track (base x), under the carriage's travel plus some overhang.
    x0 = dh.r10 + float(robot.lower[track]) - 0.6
    x1 = dh.r10 + float(robot.upper[track]) + 0.6
    inner = max(float(robot.upper[extend]), 0.2)
    solids = [
        # (its underside RAIL_HEIGHT below the base: the floor, where place stands it)
        Solid("rail", BASE_FRAME, "box", (x1 - x0, 0.5, 0.08), ((x0 + x1) / 2, 0.0, -0.14),
              "camtraj_rail"),
        # Carriage: link1 moves with the track but not with rotate (z up).
        Solid("carriage", "link1", "box", (0.7, 0.8, 0.1), (0.0, 0.0, -0.05), "camtraj_joint"),
        # Turret ring: turns with rotate, from the carriage up to the shoulder (height r2).
        Solid("turret", ax["rotate"], "cylinder", (0.33, dh.r2), (0.0, 0.0, dh.r2 / 2),
              "camtraj_body"),
        # Shoulder hub on the lift axis (z of lift_axis), and the riser to the arm line (l3).
        Solid("shoulder", ax["lift"], "cylinder", (0.16, 0.42), (0.0, 0.0, 0.0),
              "camtraj_joint"),
    ]
    if dh.l3 > 0:
        solids.append(Solid("riser", ax["lift"], "box", (0.22, dh.l3, 0.22),
                            (0.0, -dh.l3 / 2, 0.0), "camtraj_body"))
    solids += [
        # Arm: outer tube along link3's z (the extension direction) with a counterweight.
        Solid("arm", "link3", "cylinder", (0.12, dh.r40), (0.0, 0.0, dh.r40 / 2),
              "camtraj_body"),
        Solid("counterweight", "link3", "box", (0.34, 0.34, 0.45), (0.0, 0.0, -0.3),
              "camtraj_joint"),
        # Extension: inner tube, ending at the elbow (z = r40 in extend_axis).
        Solid("extension", ax["extend"], "cylinder", (0.085, inner),
              (0.0, 0.0, dh.r40 - inner / 2), "camtraj_rail"),
        # Elbow hub on the elbow axis.
        Solid("elbow hub", ax["elbow"], "cylinder", (0.11, 0.28), (0.0, 0.0, 0.0),
              "camtraj_joint"),
        # Forearm: link5's z runs from the elbow to the wrist centre (r6).
        Solid("forearm", "link5", "cylinder", (0.075, dh.r6), (0.0, 0.0, dh.r6 / 2),
              "camtraj_body"),
        # Pan housing just above the wrist centre, turning with pan about the forearm.
        Solid("pan housing", ax["pan"], "box", (0.17, 0.17, 0.14),
              (0.0, 0.0, max(dh.r6 - 0.17, 0.0)), "camtraj_joint"),
        # Tilt hub on the tilt axis at the wrist centre.
        Solid("tilt hub", ax["tilt"], "cylinder", (0.065, 0.24), (0.0, 0.0, 0.0),
              "camtraj_body"),
        # Roll flange: a disc on the flange (link8) z.
        Solid("flange", "link8", "cylinder", (0.075, 0.03), (0.0, 0.0, 0.015),
              "camtraj_joint"),
        # Camera: body around the nodal point, lens along the view direction (camera -z).
        Solid("camera body", CAMERA_FRAME, "box", (0.12, 0.14, 0.22), (0.0, 0.0, 0.02),
              "camtraj_camera"),
        Solid("lens", CAMERA_FRAME, "cylinder", (0.045, 0.12), (0.0, 0.0, -0.15),
              "camtraj_lens"),
    ]
    return solids


def frame_poses(robot: Robot, q: ArrayLike) -> dict[str, Array]:
    """Every frame of the tree in the base frame (``frame2base``) at joint vectors q (..., 8).

    Returns:
        Frame name -> (..., 4, 4): ``base_link``, ``link0``..``link8``, each
        ``<joint>_axis`` and ``camera``.
    """
    qa = np.asarray(q, dtype=float)
    frames = robot.link_frames(qa)
    out: dict[str, Array] = {BASE_FRAME: np.broadcast_to(np.eye(4), (*qa.shape[:-1], 4, 4))}
    for i, name in enumerate(LINK_FRAMES):
        out[name] = frames[..., i, :, :]
    for tr in link_transforms(robot, qa):
        out[tr.child] = out[tr.parent] @ tr.child2parent
    out[CAMERA_FRAME] = out[LINK_FRAMES[-1]] @ robot.camera2flange
    return out


def _add_visuals(robot: Robot, links: dict[str, ET.Element]) -> None:
    """The shapes of :func:`robot_solids` as URDF visuals."""
    for solid in robot_solids(robot):
        vis = ET.SubElement(links[solid.frame], "visual")
        ET.SubElement(vis, "origin", xyz=_vec(solid.xyz), rpy=_vec((0.0, 0.0, 0.0)))
        geom = ET.SubElement(vis, "geometry")
        if solid.shape == "box":
            ET.SubElement(geom, "box", {"size": _vec(solid.size)})
        else:
            ET.SubElement(geom, "cylinder",
                          {"radius": _num(solid.size[0]), "length": _num(solid.size[1])})
        ET.SubElement(vis, "material", name=solid.material)


def robot_urdf(robot: Robot) -> str:
    """The robot as URDF text (link and joint names in the module docstring).

    Moving joints carry the design's names (track, rotate, lift, extend, elbow, pan, tilt,
    roll) with the robot's position limits [m, rad] and velocity limits [m/s, rad/s].
    """
    root = ET.Element("robot", name=robot.name)
    for name, rgba in MATERIALS.items():
        mat = ET.SubElement(root, "material", name=name)
        ET.SubElement(mat, "color", rgba=" ".join(f"{c:g}" for c in rgba))

    links: dict[str, ET.Element] = {}

    def add_link(name: str) -> None:
        links[name] = ET.SubElement(root, "link", name=name)

    add_link(BASE_FRAME)
    add_link(LINK_FRAMES[0])
    for i, row in _moving_rows(robot):
        assert row.joint is not None
        add_link(axis_frame(robot.joint_names[row.joint]))
        add_link(LINK_FRAMES[i])
    add_link(CAMERA_FRAME)
    add_link(OPTICAL_FRAME)
    _add_visuals(robot, links)

    def add_fixed(tr: Transform) -> None:
        joint = ET.SubElement(root, "joint", name=f"{tr.parent}_to_{tr.child}", type="fixed")
        ET.SubElement(joint, "parent", link=tr.parent)
        ET.SubElement(joint, "child", link=tr.child)
        _origin(joint, tr.child2parent)

    statics = {tr.child: tr for tr in static_transforms(robot)}
    add_fixed(statics[LINK_FRAMES[0]])
    for i, row in _moving_rows(robot):
        assert row.joint is not None
        j = row.joint
        name = robot.joint_names[j]
        kind = "revolute" if row.kind == "revolute" else "prismatic"
        joint = ET.SubElement(root, "joint", name=name, type=kind)
        ET.SubElement(joint, "parent", link=LINK_FRAMES[i - 1])
        ET.SubElement(joint, "child", link=axis_frame(name))
        ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
        ET.SubElement(joint, "axis", xyz=_vec([0.0, 0.0, row.sign]))
        ET.SubElement(
            joint,
            "limit",
            lower=_num(robot.lower[j]),
            upper=_num(robot.upper[j]),
            effort=_EFFORT,
            velocity=_num(robot.max_velocity[j]),
        )
        add_fixed(statics[LINK_FRAMES[i]])
    add_fixed(statics[CAMERA_FRAME])
    add_fixed(statics[OPTICAL_FRAME])

    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    return '<?xml version="1.0"?>\n' + body + "\n"
