"""Write a solved take as a ROS 2 MCAP file and read it back (design.md §4).

The file follows the MCAP ``ros2`` profile: CDR-encoded messages, schemas embedded as ``ros2msg``
with their full concatenated definitions, zstd-compressed chunks. Log time = publish time = the
take time in nanoseconds (the take starts at t = 0), so the same inputs give the same bytes.

Topics:
    /joint_states       sensor_msgs/msg/JointState        every servo sample
    /joint_trajectory   trajectory_msgs/msg/JointTrajectory  once at t = 0, every servo sample
    /shot/frames        camtraj_msgs/msg/ShotFrame        one per film frame, at its take time
    /robot_description  std_msgs/msg/String               once at t = 0 (URDF)
    /tf                 tf2_msgs/msg/TFMessage            on every film frame, the take's ends,
                                                          and the film rate between (moving joints)
    /tf_static          tf2_msgs/msg/TFMessage            once at t = 0 (fixed transforms, with
                                                          ``world`` -> ``base_link``: the placement)
    /camera/camera_info sensor_msgs/msg/CameraInfo        one per film frame (the lens, in
                                                          ``camera_optical``; see camtraj.ros2)
Every channel carries ``offered_qos_profiles`` (:func:`camtraj.ros2.offered_qos_profiles`).
Metadata records: ``camtraj`` (the caller's key/values) and ``camtraj.robot`` (the robot's
joint names and limits as JSON, for ``camtraj info``).

Messages are encoded here, not with mcap_ros2's pure-Python encoder (too slow for a minute of
250 Hz samples); ``read_take`` decodes with mcap_ros2, the path third-party readers use, and the
tests check the bytes against mcap_ros2's encoder.
"""

from __future__ import annotations

import json
import math
import re
import shlex
import struct
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.reader import make_reader
from mcap.stream_reader import CRCValidationError
from mcap.writer import CompressionType, IndexType
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from numpy.typing import ArrayLike, NDArray

from camtraj.errors import CamtrajError, InputError, os_reason
from camtraj.robot import Robot
from camtraj.ros2 import (
    IMAGE_WIDTH,
    camera_matrices,
    image_heights,
    offered_qos_profiles,
    shot_frame_definition,
)
from camtraj.urdf import (
    BASE_FRAME,
    OPTICAL_FRAME,
    Transform,
    link_transforms,
    robot_urdf,
    static_transforms,
)

Array = NDArray[np.float64]

PROFILE = "ros2"
METADATA_NAME = "camtraj"
ROBOT_METADATA_NAME = "camtraj.robot"

TOPIC_JOINT_STATES = "/joint_states"
TOPIC_TRAJECTORY = "/joint_trajectory"
TOPIC_FRAMES = "/shot/frames"
TOPIC_DESCRIPTION = "/robot_description"
TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"
TOPIC_CAMERA_INFO = "/camera/camera_info"
WORLD_FRAME = "world"
"""The tf root: the converted stage (metres, Z-up), above ``base_link`` by the placement."""

#: topic -> schema name, in the order channels are registered (and same-time messages written).
TOPICS: dict[str, str] = {
    TOPIC_DESCRIPTION: "std_msgs/msg/String",
    TOPIC_TF_STATIC: "tf2_msgs/msg/TFMessage",
    TOPIC_TRAJECTORY: "trajectory_msgs/msg/JointTrajectory",
    TOPIC_JOINT_STATES: "sensor_msgs/msg/JointState",
    TOPIC_TF: "tf2_msgs/msg/TFMessage",
    TOPIC_CAMERA_INFO: "sensor_msgs/msg/CameraInfo",
    TOPIC_FRAMES: "camtraj_msgs/msg/ShotFrame",
}

_CHUNK_SIZE = 1024 * 1024
_WINDOW = 2048
"""Servo samples per writing window: the writer encodes the take's messages a window of log
times at a time (and the trajectory's points a window at a time), so its memory does not grow
with the messages of the whole take."""
# UsdGeom.Camera's fallback film back, horizontalAperture x verticalAperture [mm].
_USD_APERTURE_MM = (20.955, 15.2908)
_NS = 1_000_000_000

# ---------------------------------------------------------------------------------------------
# Message definitions (.msg text, keyed by the short "pkg/Type" name used in field types)
# ---------------------------------------------------------------------------------------------

_MSG_DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/String": "string data",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\n"
        "string[] name\n"
        "float64[] position\n"
        "float64[] velocity\n"
        "float64[] effort"
    ),
    "trajectory_msgs/JointTrajectory": (
        "std_msgs/Header header\n"
        "string[] joint_names\n"
        "JointTrajectoryPoint[] points"
    ),
    "trajectory_msgs/JointTrajectoryPoint": (
        "float64[] positions\n"
        "float64[] velocities\n"
        "float64[] accelerations\n"
        "float64[] effort\n"
        "builtin_interfaces/Duration time_from_start"
    ),
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\n"
        "string child_frame_id\n"
        "Transform transform"
    ),
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\n"
        "uint32 height\n"
        "uint32 width\n"
        "string distortion_model\n"
        "float64[] d\n"
        "float64[9] k\n"
        "float64[9] r\n"
        "float64[12] p\n"
        "uint32 binning_x\n"
        "uint32 binning_y\n"
        "RegionOfInterest roi"
    ),
    "sensor_msgs/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify"
    ),
    # The one definition, in ros/camtraj_msgs/msg/ShotFrame.msg (shipped as package data).
    "camtraj_msgs/ShotFrame": shot_frame_definition().removesuffix("\n"),
}

_PRIMITIVES = frozenset(
    (
        "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
        "int32", "uint32", "int64", "uint64", "string", "wstring",
    )
)
_DELIMITER = "=" * 80


def _msg_dependencies(short_name: str) -> list[str]:
    """Non-primitive field types of a definition, as full "pkg/Type" names, sorted."""
    package = short_name.split("/")[0]
    deps: set[str] = set()
    for line in _MSG_DEFS[short_name].splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        ftype = re.sub(r"\[[^\]]*\]$", "", line.split()[0])
        if ftype in _PRIMITIVES:
            continue
        deps.add(ftype if "/" in ftype else f"{package}/{ftype}")
    return sorted(deps)


def message_definition(schema_name: str) -> str:
    """The complete ``ros2msg`` definition of a type, dependencies included.

    Concatenated the way rosbag2 does it: the top-level definition first, then each
    dependency (depth first, once) after a line of 80 ``=`` and a ``MSG: pkg/Type`` line.

    Args:
        schema_name: A type name such as ``"sensor_msgs/msg/JointState"``.
    """
    parts = schema_name.split("/")
    root = f"{parts[0]}/{parts[-1]}"
    if root not in _MSG_DEFS:
        msg = f"no message definition for {schema_name}; known: {', '.join(sorted(_MSG_DEFS))}"
        raise ValueError(msg)
    seen: set[str] = set()

    def expand(name: str) -> str:
        text = _MSG_DEFS[name]
        for dep in _msg_dependencies(name):
            if dep not in seen:
                seen.add(dep)
                text += f"\n{_DELIMITER}\nMSG: {dep}\n" + expand(dep)
        return text

    return expand(root) + "\n"


# ---------------------------------------------------------------------------------------------
# CDR encoding (little-endian XCDR1, as ROS 2 writes it)
# ---------------------------------------------------------------------------------------------


@dataclass
class _Slot:
    dtype: str
    count: int
    offsets: list[int]


class _Cdr:
    """Builds one CDR message, or a template whose numeric "slots" are filled in bulk.

    Alignment is counted from the end of the 4-byte encapsulation header (``phase`` shifts
    the origin for fragments that start mid-message).
    """

    def __init__(self, *, header: bool = True, phase: int = 0) -> None:
        self.buf = bytearray(b"\x00\x01\x00\x00" if header else b"")
        self._origin = (4 if header else 0) - phase
        self.slots: dict[str, _Slot] = {}

    @property
    def position(self) -> int:
        """Current offset from the alignment origin."""
        return len(self.buf) - self._origin

    def _align(self, size: int) -> None:
        pad = -self.position % size
        if pad:
            self.buf += bytes(pad)

    def u32(self, value: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", value)

    def i32(self, value: int) -> None:
        self._align(4)
        self.buf += struct.pack("<i", value)

    def time(self, ns: int) -> None:
        sec, nanosec = divmod(int(ns), _NS)
        self.i32(sec)
        self.u32(nanosec)

    def string(self, value: str) -> None:
        data = value.encode("utf-8")
        self.u32(len(data) + 1)
        self.buf += data + b"\x00"

    def strings(self, values: Sequence[str]) -> None:
        self.u32(len(values))
        for value in values:
            self.string(value)

    def slot(self, key: str, dtype: str, count: int = 1) -> None:
        """Reserve ``count`` values of ``dtype`` (e.g. ``"<f8"``) to be filled per message."""
        size = np.dtype(dtype).itemsize
        self._align(size)
        entry = self.slots.setdefault(key, _Slot(dtype, count, []))
        if entry.dtype != dtype or entry.count != count:
            msg = f"slot {key} reused with another type"
            raise ValueError(msg)
        entry.offsets.append(len(self.buf))
        self.buf += bytes(size * count)

    def slot_time(self, key: str) -> None:
        self.slot(f"{key}.sec", "<i4")
        self.slot(f"{key}.nanosec", "<u4")

    def slot_f64s(self, key: str, count: int) -> None:
        """A float64[] sequence of fixed length ``count`` whose values are a slot."""
        self.u32(count)
        if count:
            self.slot(key, "<f8", count)

    def fill(self, values: Mapping[str, ArrayLike], n: int) -> NDArray[np.uint8]:
        """``n`` copies of the template with the slots filled, shape (n, len(template)).

        ``values[key]`` has shape (n,) or (n, count) for each slot key.
        """
        out = np.empty((n, len(self.buf)), dtype=np.uint8)
        out[:] = np.frombuffer(bytes(self.buf), dtype=np.uint8)
        for key, slot in self.slots.items():
            vals = np.asarray(values[key])
            if vals.shape[0] != n or vals.size != n * slot.count:
                msg = f"slot {key}: expected {n} x {slot.count} values, got shape {vals.shape}"
                raise ValueError(msg)
            raw = np.ascontiguousarray(vals.astype(slot.dtype).reshape(n, slot.count))
            raw_bytes = raw.view(np.uint8).reshape(n, -1)
            width = raw_bytes.shape[1]
            for off in slot.offsets:
                out[:, off : off + width] = raw_bytes
        return out


def _split_rows(rows: NDArray[np.uint8]) -> list[bytes]:
    data = rows.tobytes()
    width = rows.shape[1]
    return [data[i : i + width] for i in range(0, len(data), width)]


def _stamp_values(key: str, ns: NDArray[np.int64]) -> dict[str, NDArray[np.int64]]:
    sec, nanosec = np.divmod(ns, _NS)
    return {f"{key}.sec": sec, f"{key}.nanosec": nanosec}


def _encode_joint_states(
    names: Sequence[str], ns: NDArray[np.int64], q: Array, qd: Array
) -> list[bytes]:
    tpl = _Cdr()
    tpl.slot_time("stamp")
    tpl.string("")
    tpl.strings(names)
    tpl.slot_f64s("position", len(names))
    tpl.slot_f64s("velocity", len(names))
    tpl.u32(0)  # effort: empty
    values: dict[str, ArrayLike] = {**_stamp_values("stamp", ns), "position": q, "velocity": qd}
    return _split_rows(tpl.fill(values, len(ns)))


def _encode_trajectory(
    names: Sequence[str], ns: NDArray[np.int64], q: Array, qd: Array, qdd: Array
) -> bytes:
    head = _Cdr()
    head.time(0)
    head.string("")
    head.strings(names)
    head.u32(len(ns))
    # A point's layout depends only on where it starts modulo 8: one template per phase.
    templates: dict[int, _Cdr] = {}
    phase_list: list[int] = []
    pos = head.position
    for _ in range(len(ns)):
        phase = pos % 8
        if phase not in templates:
            tpl = _Cdr(header=False, phase=phase)
            tpl.slot_f64s("positions", len(names))
            tpl.slot_f64s("velocities", len(names))
            tpl.slot_f64s("accelerations", len(names))
            tpl.u32(0)  # effort: empty
            tpl.slot_time("time_from_start")
            templates[phase] = tpl
        phase_list.append(phase)
        pos += len(templates[phase].buf)
    phases = np.array(phase_list)
    message = [bytes(head.buf)]  # the head, then each window's points
    # A window of points at a time: the scratch arrays stay small whatever the take's length.
    for a in range(0, len(ns), _WINDOW):
        b = min(a + _WINDOW, len(ns))
        sec, nanosec = np.divmod(ns[a:b], _NS)
        points: list[bytes] = [b""] * (b - a)
        for phase, tpl in templates.items():
            idx = np.flatnonzero(phases[a:b] == phase)
            if not idx.size:  # no point of this window starts at this phase
                continue
            rows = tpl.fill(
                {
                    "positions": q[a + idx],
                    "velocities": qd[a + idx],
                    "accelerations": qdd[a + idx],
                    "time_from_start.sec": sec[idx],
                    "time_from_start.nanosec": nanosec[idx],
                },
                len(idx),
            )
            for i, point in zip(idx.tolist(), _split_rows(rows), strict=True):
                points[i] = point
        message.append(b"".join(points))
    return b"".join(message)


def _encode_tf(
    frames: Sequence[tuple[str, str]], ns: NDArray[np.int64], poses: Sequence[Array]
) -> list[bytes]:
    """TFMessages with one TransformStamped per (parent, child); poses[i] has shape (k, 7)."""
    tpl = _Cdr()
    tpl.u32(len(frames))
    for i, (parent, child) in enumerate(frames):
        tpl.slot_time("stamp")
        tpl.string(parent)
        tpl.string(child)
        tpl.slot(f"tf{i}", "<f8", 7)
    values: dict[str, ArrayLike] = dict(_stamp_values("stamp", ns))
    for i, pose in enumerate(poses):
        values[f"tf{i}"] = pose
    return _split_rows(tpl.fill(values, len(ns)))


def _encode_shot_frames(take: TakeData, frames: slice = slice(None)) -> list[bytes]:
    """The /shot/frames messages of the film frames ``frames`` (default all)."""
    tpl = _Cdr()
    tpl.slot("frame", "<i4")
    tpl.slot("time", "<f8")
    joints = take.joint_names[: len(take.joint_names) - len(take.lens_names)]
    tpl.strings(joints)
    tpl.slot_f64s("position", len(joints))
    tpl.slot("target", "<f8", 7)
    tpl.slot("achieved", "<f8", 7)
    tpl.slot("lens", "<f8", 3)
    lens = np.stack([take.focal_length_mm[frames], take.focus_distance_m[frames],
                     take.f_stop[frames]], axis=-1)
    values: dict[str, ArrayLike] = {
        "frame": take.frame_numbers[frames],
        "time": take.frame_times[frames],
        "position": take.frame_q[frames],
        "target": pose7_from_matrix(take.target[frames]),
        "achieved": pose7_from_matrix(take.achieved[frames]),
        "lens": lens,
    }
    return _split_rows(tpl.fill(values, len(lens)))


def _encode_camera_info(take: TakeData, frames: slice = slice(None)) -> list[bytes]:
    """One CameraInfo per film frame of ``frames`` (default all), stamped at its take time,
    in the optical frame."""
    assert take.horizontal_aperture_mm is not None and take.vertical_aperture_mm is not None
    assert take.horizontal_aperture_offset_mm is not None
    assert take.vertical_aperture_offset_mm is not None
    frame_times = take.frame_times[frames]
    n = len(frame_times)
    # One image size for the take (the first frame's aspect); an animated film back changes
    # the intrinsics, not the size.
    height = int(image_heights(take.horizontal_aperture_mm[:1], take.vertical_aperture_mm[:1],
                               IMAGE_WIDTH)[0]) if len(take.frame_times) else 1
    focal = (take.focal_length_mm if take.camera_focal_length_mm is None
             else take.camera_focal_length_mm)  # with a lens: the focal length it gives
    K = camera_matrices(focal[frames], take.horizontal_aperture_mm[frames],
                        take.vertical_aperture_mm[frames], IMAGE_WIDTH, height,
                        take.horizontal_aperture_offset_mm[frames],
                        take.vertical_aperture_offset_mm[frames])
    P = np.concatenate([K, np.zeros((n, 3, 1))], axis=2)
    tpl = _Cdr()
    tpl.slot_time("stamp")
    tpl.string(OPTICAL_FRAME)
    tpl.slot("height", "<u4")
    tpl.slot("width", "<u4")
    tpl.string("plumb_bob")
    tpl.slot_f64s("d", 5)
    tpl.slot("k", "<f8", 9)
    tpl.slot("r", "<f8", 9)
    tpl.slot("p", "<f8", 12)
    for _ in range(6):  # binning_x, binning_y, roi x_offset, y_offset, height, width: 0
        tpl.u32(0)
    tpl.buf += b"\x00"  # roi.do_rectify: false
    values: dict[str, ArrayLike] = {
        **_stamp_values("stamp", seconds_to_ns(frame_times)),
        "height": np.full(n, height),
        "width": np.full(n, IMAGE_WIDTH),
        "d": np.zeros((n, 5)),
        "k": K.reshape(n, 9),
        "r": np.tile(np.eye(3).ravel(), (n, 1)),
        "p": P.reshape(n, 12),
    }
    return _split_rows(tpl.fill(values, n))


def _encode_string(text: str) -> bytes:
    msg = _Cdr()
    msg.string(text)
    return bytes(msg.buf)


# ---------------------------------------------------------------------------------------------
# Rotations
# ---------------------------------------------------------------------------------------------


def quat_from_matrix(R: ArrayLike) -> Array:
    """Unit quaternions ``(x, y, z, w)`` of rotation matrices (scipy's ``Rotation``), in the
    canonical form: ``w >= 0`` (for ``w == 0`` the first non-zero of x, y, z positive).

    Args:
        R: Rotations, shape (..., 3, 3), or transforms (..., 4, 4) (rotation part used).

    Returns:
        Quaternions, shape (..., 4), scalar last (ROS order).
    """
    from scipy.spatial.transform import Rotation  # here: 0.24 s that info need not import

    M = np.asarray(R, dtype=float)[..., :3, :3]
    flat = M.reshape(-1, 3, 3)
    quat = (Rotation.from_matrix(flat).as_quat(canonical=True) if flat.shape[0]
            else np.zeros((0, 4)))
    out: Array = quat.reshape(*M.shape[:-2], 4) + 0.0  # + 0.0: no negative zeros
    return out


def matrix_from_quat(quat: ArrayLike) -> Array:
    """Rotation matrices of quaternions ``(x, y, z, w)`` (normalised first), shape (..., 3, 3);
    NaN for a quaternion of no length or not finite (a damaged file's: said where it is
    read, not raised here)."""
    from scipy.spatial.transform import Rotation

    qa = np.asarray(quat, dtype=float)
    flat = qa.reshape(-1, 4)
    norm = np.linalg.norm(flat, axis=1)
    ok = np.isfinite(norm) & (norm > 0.0)
    out = np.full((flat.shape[0], 3, 3), np.nan)
    if ok.any():
        out[ok] = Rotation.from_quat(flat[ok]).as_matrix()
    return out.reshape(*qa.shape[:-1], 3, 3)


def pose7_from_matrix(T: ArrayLike) -> Array:
    """``(x, y, z, qx, qy, qz, qw)`` of transforms (..., 4, 4): the Pose / Transform layout."""
    Ta = np.asarray(T, dtype=float)
    return np.concatenate([Ta[..., :3, 3], quat_from_matrix(Ta)], axis=-1)


def matrix_from_pose7(pose: ArrayLike) -> Array:
    """Transforms (..., 4, 4) from ``(x, y, z, qx, qy, qz, qw)``."""
    pa = np.asarray(pose, dtype=float)
    out = np.zeros((*pa.shape[:-1], 4, 4))
    out[..., :3, :3] = matrix_from_quat(pa[..., 3:])
    out[..., :3, 3] = pa[..., :3]
    out[..., 3, 3] = 1.0
    return out


# ---------------------------------------------------------------------------------------------
# The take
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)  # arrays: compare fields, not objects
class TakeData:
    """Everything the writer needs, as plain arrays in SI units.

    Attributes:
        joint_names: Axis names in design order: the 8 joints, then any lens axes
            (``lens_names``).
        t: Servo sample times [s] from the start of the take, shape (m,), increasing, >= 0.
        q: Axis positions [m, rad] per servo sample, shape (m, axes).
        qd: Axis velocities [m/s, rad/s], shape (m, axes).
        qdd: Axis accelerations [m/s², rad/s²], shape (m, axes).
        frame_numbers: Film frame numbers (USD time codes), shape (n,), integers.
        frame_times: Take time of each film frame [s], shape (n,), non-decreasing.
        frame_q: The IK solution per frame [m, rad], shape (n, 8).
        target: Requested camera poses ``camera2base``, shape (n, 4, 4) [m].
        achieved: Camera poses of the solutions (FK), shape (n, 4, 4) [m].
        focal_length_mm: Focal length per frame [mm], shape (n,).
        focus_distance_m: Focus distance per frame [m], shape (n,); inf: at infinity.
        f_stop: Aperture per frame (f-number), shape (n,).
        fps: Film frame rate [1/s], the /tf sampling rate.
        horizontal_aperture_mm: Film back width per frame [mm], shape (n,); None: USD's
            fallback (20.955 mm).
        vertical_aperture_mm: Film back height per frame [mm], shape (n,); None: USD's
            fallback (15.2908 mm).
        base2world: The placement, robot base into the converted stage, shape (4, 4) [m]
            (tf's ``world`` -> ``base_link``).
        horizontal_aperture_offset_mm, vertical_aperture_offset_mm: Lens shift per frame
            [mm] (film back off the lens axis, +x right, +y up), shape (n,); None: zeros.
            CameraInfo's principal point (cx, cy) carries it.
        lens_names: The lens motors (``zoom``, ``focus``, ``iris``) that end ``joint_names``
            (lens ring angles [rad] in ``q``); ``/shot/frames`` and ``/tf`` take the joints
            before them.
        camera_focal_length_mm: The focal length the lens gives per frame [mm], shape (n,),
            for CameraInfo; None: ``focal_length_mm``.
    """

    joint_names: tuple[str, ...]
    t: Array
    q: Array
    qd: Array
    qdd: Array
    frame_numbers: NDArray[np.int64]
    frame_times: Array
    frame_q: Array
    target: Array
    achieved: Array
    focal_length_mm: Array
    focus_distance_m: Array
    f_stop: Array
    fps: float
    horizontal_aperture_mm: Array | None = None
    vertical_aperture_mm: Array | None = None
    base2world: Array = field(default_factory=lambda: np.eye(4))
    horizontal_aperture_offset_mm: Array | None = None
    vertical_aperture_offset_mm: Array | None = None
    lens_names: tuple[str, ...] = ()
    camera_focal_length_mm: Array | None = None

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        object.__setattr__(self, "joint_names", names)
        j = len(names)
        lens = tuple(str(n) for n in self.lens_names)
        object.__setattr__(self, "lens_names", lens)
        if lens and names[j - len(lens):] != lens:
            msg = f"TakeData.joint_names {list(names)} must end with the lens axes {list(lens)}"
            raise ValueError(msg)
        t = self._array("t", self.t, None)
        m = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or m < 1:
            msg = f"TakeData.t must have shape (m,) with m >= 1, got {t.shape}"
            raise ValueError(msg)
        if t[0] < 0 or np.any(np.diff(t) <= 0):
            msg = "TakeData.t must start at or after 0 and increase strictly"
            raise ValueError(msg)
        for name in ("q", "qd", "qdd"):
            self._array(name, getattr(self, name), (m, j))
        frames = np.asarray(self.frame_numbers)
        n = frames.shape[0] if frames.ndim == 1 else -1
        if frames.ndim != 1:
            msg = f"TakeData.frame_numbers must have shape (n,), got {frames.shape}"
            raise ValueError(msg)
        frames_f = frames.astype(float)
        if np.any(frames_f != np.round(frames_f)) or np.any(np.abs(frames_f) > 2**31 - 1):
            msg = "TakeData.frame_numbers must be integers that fit in int32"
            raise ValueError(msg)
        object.__setattr__(self, "frame_numbers", frames.astype(np.int64))
        ft = self._array("frame_times", self.frame_times, (n,))
        if np.any(np.diff(ft) < 0) or (n and (ft[0] < 0 or ft[-1] > t[-1] + 1e-9)):
            msg = "TakeData.frame_times must be non-decreasing and inside the take"
            raise ValueError(msg)
        self._array("frame_q", self.frame_q, (n, j - len(lens)))
        self._array("target", self.target, (n, 4, 4))
        self._array("achieved", self.achieved, (n, 4, 4))
        for name in ("focal_length_mm", "focus_distance_m", "f_stop"):
            self._array(name, getattr(self, name), (n,), infinite=name == "focus_distance_m")
        if self.camera_focal_length_mm is not None:
            self._array("camera_focal_length_mm", self.camera_focal_length_mm, (n,))
        for name, fallback in (("horizontal_aperture_mm", _USD_APERTURE_MM[0]),
                               ("vertical_aperture_mm", _USD_APERTURE_MM[1])):
            value = getattr(self, name)
            aperture = self._array(name, np.full(n, fallback) if value is None else value, (n,))
            if np.any(aperture <= 0):
                msg = f"TakeData.{name} must be positive"
                raise ValueError(msg)
        for name in ("horizontal_aperture_offset_mm", "vertical_aperture_offset_mm"):
            value = getattr(self, name)
            self._array(name, np.zeros(n) if value is None else value, (n,))
        self._array("base2world", self.base2world, (4, 4))
        fps = float(self.fps)
        if not (math.isfinite(fps) and fps > 0):
            msg = f"TakeData.fps must be a positive frame rate, got {self.fps!r}"
            raise ValueError(msg)
        object.__setattr__(self, "fps", fps)

    def _array(self, name: str, value: ArrayLike, shape: tuple[int, ...] | None,
               infinite: bool = False) -> Array:
        """``value`` as a float array of ``shape``, finite (``infinite``: or +inf, focus at
        infinity), set as the field ``name``."""
        arr = np.asarray(value, dtype=float)
        if shape is not None and arr.shape != shape:
            msg = f"TakeData.{name} must have shape {shape}, got {arr.shape}"
            raise ValueError(msg)
        if not np.all(np.isfinite(arr) | (infinite & np.isposinf(arr))):
            msg = f"TakeData.{name} has non-finite values"
            raise ValueError(msg)
        object.__setattr__(self, name, arr)
        return arr


def seconds_to_ns(t: ArrayLike) -> NDArray[np.int64]:
    """Take times [s] to integer nanoseconds (rounded), the MCAP log times."""
    return np.asarray(np.round(np.asarray(t, dtype=float) * _NS), dtype=np.int64)


def interpolate_servo(t: Array, q: Array, qd: Array, times: ArrayLike) -> Array:
    """Joint positions at ``times`` by cubic Hermite interpolation of the servo stream.

    Exact at the servo samples; times outside ``[t[0], t[-1]]`` are clamped.

    Args:
        t: Servo sample times [s], shape (m,), increasing.
        q: Positions, shape (m, j). qd: Velocities, shape (m, j).
        times: Query times [s], shape (k,).

    Returns:
        Positions, shape (k, j).
    """
    tq = np.clip(np.asarray(times, dtype=float), t[0], t[-1])
    if len(t) == 1:
        return np.repeat(q[:1], len(tq), axis=0)
    i = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, len(t) - 2)
    h = (t[i + 1] - t[i])[:, None]
    s = ((tq - t[i])[:, None]) / h
    s2, s3 = s * s, s * s * s
    h00 = 2 * s3 - 3 * s2 + 1
    h10 = s3 - 2 * s2 + s
    h01 = -2 * s3 + 3 * s2
    h11 = s3 - s2
    out: Array = h00 * q[i] + h10 * h * qd[i] + h01 * q[i + 1] + h11 * h * qd[i + 1]
    return out


def tf_times(take: TakeData) -> Array:
    """The /tf sample times [s]: the film frame rate across the whole take, every film
    frame's own stamp and the take's first and last sample.

    The grid is anchored at the first shot frame (a shot timed at the frame rate has its film
    frames on it). The frames are added where they are not on it, so every film frame's pose
    is in /tf also when the take is retimed (``scale`` slows it by a factor that is no whole
    number, ``optimal`` plays frames faster than the film: one /tf sample in eight frames of a
    retimed push-in, and `camtraj report` drew a frame's robot from another's), and so are
    the poses the take starts and ends in; no two samples are more than a frame interval
    apart.
    """
    start, end = float(take.t[0]), float(take.t[-1])
    ft = np.asarray(take.frame_times, dtype=float)
    anchor = float(ft[0]) if ft.size else start
    # times on the file's nanosecond clock: a take that ends on its last film frame (no
    # run-out) can end half a nanosecond before the grid's last point, which is that frame
    slack = 1e-6  # [frames]
    k_lo = -math.floor((anchor - start) * take.fps + slack)
    k_hi = math.floor((end - anchor) * take.fps + slack)
    grid = anchor + np.arange(k_lo, k_hi + 1, dtype=float) / take.fps
    others = np.concatenate([grid, [start, end]])
    if ft.size:  # a grid point or an end within 2 ns of a frame is that frame, at its stamp
        after = np.searchsorted(ft, others).clip(0, ft.size - 1)
        gap = np.minimum(np.abs(ft[after] - others), np.abs(ft[(after - 1).clip(0)] - others))
        others = others[gap > 2e-9]
    others = np.sort(others)
    others = others[np.diff(others, prepend=-np.inf) > 2e-9]
    out: Array = np.clip(np.sort(np.concatenate([ft, others])), start, end)
    return out


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------


def _library_identifier() -> str:
    try:
        version = importlib_metadata.version("camtraj")
    except importlib_metadata.PackageNotFoundError:
        version = "unknown"
    return f"camtraj/{version}"


def _robot_metadata(robot: Robot) -> dict[str, str]:
    desc = robot.describe()
    return {key: json.dumps(value) for key, value in desc.items()}


def write_take_to(
    stream: IO[bytes], take: TakeData, robot: Robot, metadata: Mapping[str, str]
) -> None:
    """Write a take as a ROS 2 MCAP file into an open binary stream (an output's, of
    :class:`camtraj.outputs.OutputSet`).

    Args:
        stream: Where the file's bytes go.
        take: The solved, timed take.
        robot: The robot it was solved for (URDF, transforms, limits metadata).
        metadata: The ``camtraj`` metadata record: string keys and values (e.g. source_file,
            camera_prim, frame_range, fps, robot, placement, mount, timing_mode,
            speed_factor, tool_version).

    Raises:
        ValueError: The take does not match the robot (joint names).
    """
    lens = () if robot.lens is None else robot.lens.names
    if tuple(take.joint_names) != (*robot.joint_names, *lens) or take.lens_names != lens:
        msg = (
            f"take joint names {list(take.joint_names)} differ from the robot's "
            f"{list(robot.joint_names) + list(lens)}"
        )
        raise ValueError(msg)
    for key, value in metadata.items():
        if not isinstance(key, str) or not isinstance(value, str):
            msg = f"metadata must map strings to strings; got {key!r}: {value!r}"
            raise TypeError(msg)
    _write_mcap(stream, take, robot, dict(metadata), _robot_metadata(robot))


def _write_mcap(
    stream: IO[bytes],
    take: TakeData,
    robot: Robot,
    metadata: dict[str, str],
    robot_metadata: dict[str, str],
) -> None:
    # A take has no attachments: no (empty) attachment-index group or its summary offset.
    # The data-end record carries the CRC-32 of every byte before it (magic included).
    writer = McapWriter(
        stream,
        chunk_size=_CHUNK_SIZE,
        compression=CompressionType.ZSTD,
        index_types=IndexType.CHUNK | IndexType.MESSAGE | IndexType.METADATA,
        enable_data_crcs=True,
    )
    writer.start(profile=PROFILE, library=_library_identifier())
    schema_ids: dict[str, int] = {}
    for schema_name in dict.fromkeys(TOPICS.values()):
        schema_ids[schema_name] = writer.register_schema(
            name=schema_name,
            encoding="ros2msg",
            data=message_definition(schema_name).encode("utf-8"),
        )
    channel_ids = [
        writer.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=schema_ids[schema_name],
            metadata={"offered_qos_profiles": offered_qos_profiles(topic)},
        )
        for topic, schema_name in TOPICS.items()
    ]
    # All messages in log-time order; same-time messages in topic order, then sequence.
    for log_ns, rank, seq, data in _messages(take, robot):
        writer.add_message(channel_id=channel_ids[rank], log_time=log_ns, data=data,
                           publish_time=log_ns, sequence=seq)
    writer.add_metadata(METADATA_NAME, dict(sorted(metadata.items())))
    writer.add_metadata(ROBOT_METADATA_NAME, robot_metadata)
    writer.finish()  # type: ignore[no-untyped-call]


def _messages(take: TakeData, robot: Robot) -> Iterator[tuple[int, int, int, bytes]]:
    """Every message of the take as ``(log time [ns], topic rank in TOPICS, sequence, CDR)``,
    in log-time order (same-time messages in topic order, then sequence).

    The messages at t = 0 (the URDF, /tf_static, the whole /joint_trajectory) come first; the
    streams (/joint_states, /tf, /camera/camera_info, /shot/frames) are encoded a window of
    log times at a time (:data:`_WINDOW` servo samples), so the messages in memory at once do
    not grow with the take.
    """
    rank = {topic: i for i, topic in enumerate(TOPICS)}
    names = take.joint_names
    yield 0, rank[TOPIC_DESCRIPTION], 0, _encode_string(robot_urdf(robot))
    statics = [Transform(WORLD_FRAME, BASE_FRAME, take.base2world), *static_transforms(robot)]
    yield 0, rank[TOPIC_TF_STATIC], 0, _encode_tf(
        [(s.parent, s.child) for s in statics], np.zeros(1, dtype=np.int64),
        [pose7_from_matrix(s.child2parent)[None, :] for s in statics])[0]
    servo_ns = seconds_to_ns(take.t)
    yield 0, rank[TOPIC_TRAJECTORY], 0, _encode_trajectory(names, servo_ns, take.q, take.qd,
                                                           take.qdd)

    times = tf_times(take)
    tf_ns = seconds_to_ns(times)
    frame_ns = seconds_to_ns(take.frame_times)
    nj = len(names) - len(take.lens_names)  # the joints; a lens's motors move no link
    tf_frames = [(m.parent, m.child) for m in link_transforms(robot, take.q[0, :nj])]
    # Window w holds the messages logged in [servo_ns[w * _WINDOW], servo_ns[(w + 1) * _WINDOW]).
    bounds = servo_ns[_WINDOW::_WINDOW]

    def cuts(ns: NDArray[np.int64]) -> list[int]:
        return [0, *np.searchsorted(ns, bounds, side="left").tolist(), len(ns)]

    servo_cuts, tf_cuts, frame_cuts = cuts(servo_ns), cuts(tf_ns), cuts(frame_ns)
    for w in range(len(bounds) + 1):
        parts: list[tuple[NDArray[np.int64], int, int, list[bytes]]] = []
        a, b = servo_cuts[w], servo_cuts[w + 1]
        if b > a:
            parts.append((servo_ns[a:b], rank[TOPIC_JOINT_STATES], a, _encode_joint_states(
                names, servo_ns[a:b], take.q[a:b], take.qd[a:b])))
        a, b = tf_cuts[w], tf_cuts[w + 1]
        if b > a:
            moving = link_transforms(robot, interpolate_servo(take.t, take.q, take.qd,
                                                              times[a:b])[:, :nj])
            poses = pose7_from_matrix(np.stack([m.child2parent for m in moving]))  # all links
            parts.append((tf_ns[a:b], rank[TOPIC_TF], a, _encode_tf(
                tf_frames, tf_ns[a:b], list(poses))))
        a, b = frame_cuts[w], frame_cuts[w + 1]
        if b > a:
            parts.append((frame_ns[a:b], rank[TOPIC_CAMERA_INFO], a,
                          _encode_camera_info(take, slice(a, b))))
            parts.append((frame_ns[a:b], rank[TOPIC_FRAMES], a,
                          _encode_shot_frames(take, slice(a, b))))
        if not parts:
            continue
        log = np.concatenate([p[0] for p in parts])
        ranks = np.concatenate([np.full(len(p[3]), p[1]) for p in parts])
        seqs = np.concatenate([np.arange(p[2], p[2] + len(p[3])) for p in parts])
        data = [d for p in parts for d in p[3]]
        del parts
        order = np.lexsort((seqs, ranks, log))
        # as lists: Python ints, without a numpy scalar per message and field
        yield from zip(log[order].tolist(), ranks[order].tolist(), seqs[order].tolist(),
                       [data[i] for i in order.tolist()], strict=True)


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)  # arrays: compare fields, not objects
class TopicInfo:
    """One channel of the file.

    Attributes:
        topic: Topic name. schema_name: e.g. ``sensor_msgs/msg/JointState``.
        schema_encoding: ``ros2msg``. message_encoding: ``cdr``.
        schema_text: The embedded message definition.
        message_count: Number of messages.
        log_time_ns: Log time per message [ns], shape (count,).
        publish_time_ns: Publish time per message [ns], shape (count,).
    """

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    schema_text: str
    message_count: int
    log_time_ns: NDArray[np.int64]
    publish_time_ns: NDArray[np.int64]


@dataclass(frozen=True, eq=False)  # arrays: compare fields, not objects
class ReadTake:
    """A camtraj MCAP file decoded (with mcap_ros2) back into arrays.

    Attributes:
        profile: The MCAP header profile (``ros2``). library: The header's library string.
        joint_names: Names in /joint_states.
        t: /joint_states header stamps [s], shape (m,).
        q: Positions, shape (m, 8). qd: Velocities, shape (m, 8).
        effort_sizes: Length of each message's effort array, shape (m,) (all 0).
        trajectory_joint_names: /joint_trajectory joint names.
        trajectory_stamp: /joint_trajectory header stamp [s].
        trajectory_t: Each point's time_from_start [s], shape (m,).
        trajectory_q, trajectory_qd, trajectory_qdd: Shape (m, 8) each.
        frame_numbers: /shot/frames frame, shape (n,). frame_times: time [s], shape (n,).
        frame_names: Joint names of the frames (the same in every message).
        frame_q: Positions, shape (n, 8).
        target, achieved: Camera poses as transforms, shape (n, 4, 4).
        focal_length_mm, focus_distance_m, f_stop: Lens values, shape (n,).
        tf_times: /tf stamps [s], shape (k,).
        tf: child frame -> (parent frame, child2parent of shape (k, 4, 4)).
        tf_static: child frame -> (parent frame, child2parent of shape (4, 4)).
        robot_description: The URDF text.
        metadata: The ``camtraj`` metadata record.
        all_metadata: Every metadata record by name.
        topics: Topic name -> TopicInfo.
    """

    profile: str
    library: str
    joint_names: tuple[str, ...]
    t: Array
    q: Array
    qd: Array
    effort_sizes: NDArray[np.int64]
    trajectory_joint_names: tuple[str, ...]
    trajectory_stamp: float
    trajectory_t: Array
    trajectory_q: Array
    trajectory_qd: Array
    trajectory_qdd: Array
    frame_numbers: NDArray[np.int64]
    frame_times: Array
    frame_names: tuple[str, ...]
    frame_q: Array
    target: Array
    achieved: Array
    focal_length_mm: Array
    focus_distance_m: Array
    f_stop: Array
    tf_times: Array
    tf: dict[str, tuple[str, Array]]
    tf_static: dict[str, tuple[str, Array]]
    robot_description: str
    metadata: dict[str, str]
    all_metadata: dict[str, dict[str, str]]
    topics: dict[str, TopicInfo]


def _stamp(obj: Any) -> float:
    return float(obj.sec) + float(obj.nanosec) * 1e-9


def _pose7(pose: Any) -> list[float]:
    p, o = pose.position, pose.orientation
    return [p.x, p.y, p.z, o.x, o.y, o.z, o.w]


def _transform7(tr: Any) -> list[float]:
    v, r = tr.translation, tr.rotation
    return [v.x, v.y, v.z, r.x, r.y, r.z, r.w]


_MCAP_MAGIC = b"\x89MCAP0\r\n"
_USD_MAGICS = {b"#usda": "USD text (usda)", b"PXR-USDC": "USD crate (usdc)"}


def _open_for_reading(path: Path) -> IO[bytes]:
    """Open an MCAP file; a file that is not one (a shot given by mistake, a named pipe, which
    would block the read) is an InputError."""
    from camtraj.inputs import require_regular_file

    require_regular_file(path, "MCAP file", InputError)
    try:
        stream = path.open("rb")
        head = stream.read(len(_MCAP_MAGIC))
        stream.seek(0)
    except OSError as exc:
        msg = f"cannot read {path}: {os_reason(exc)}"
        raise InputError(msg) from exc
    if head != _MCAP_MAGIC:
        start = stream.read(1 << 16) if head.startswith(b"#usda") else b""
        stream.close()
        if b'"camtraj_rig"' in start:  # convert --usd's own output (camtraj.usd_rig)
            msg = (f"{path} is camtraj's USD rig layer (convert --usd), not an MCAP: the take "
                   "is in the MCAP written with it")
            raise InputError(msg)
        kind = next((k for m, k in _USD_MAGICS.items() if head.startswith(m)), None)
        if kind is None and head.startswith(b"PK") and path.suffix.lower() == ".usdz":
            kind = "USD package (usdz)"
        if kind is not None:
            msg = (f"{path} is a {kind} file, not an MCAP: convert it with "
                   f"camtraj convert {shlex.quote(str(path))} -o OUT.mcap, or camtraj check "
                   f"{shlex.quote(str(path))}")
        else:
            msg = f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)"
        raise InputError(msg)
    return stream


def _guard(path: Path, action: Callable[[], Any]) -> Any:
    """Run a reading step; any failure of the MCAP/CDR layers becomes an InputError."""
    try:
        return action()
    except CamtrajError:
        raise
    except OSError as exc:
        msg = f"cannot read {path}: {os_reason(exc)}"
        raise InputError(msg) from exc
    except CRCValidationError as exc:
        msg = (f"{path}: the file is damaged: a checksum (CRC) does not match its data "
               f"({exc}); convert the shot again")
        raise InputError(msg) from exc
    except Exception as exc:
        msg = f"{path}: not a readable MCAP file ({type(exc).__name__}: {exc})"
        raise InputError(msg) from exc


def _names(values: Iterable[str]) -> tuple[str, ...]:
    return tuple(str(v) for v in values)


def _check_topics(path: Path, present: set[str]) -> None:
    """A camtraj take has every topic of :data:`TOPICS`."""
    missing = [t for t in TOPICS if t not in present]
    if missing:
        msg = f"{path}: not a camtraj take: topic(s) missing: {', '.join(missing)}"
        raise InputError(msg)


def _check_counts(path: Path, counts: Mapping[str, int]) -> None:
    """A camtraj take has one message at t = 0 on each of /joint_trajectory,
    /robot_description and /tf_static, and at least one on /joint_states."""
    for topic in (TOPIC_TRAJECTORY, TOPIC_DESCRIPTION, TOPIC_TF_STATIC):
        if counts.get(topic, 0) != 1:
            msg = f"{path}: {topic} has {counts.get(topic, 0)} messages, expected 1"
            raise InputError(msg)
    if counts.get(TOPIC_JOINT_STATES, 0) < 1:
        msg = f"{path}: {TOPIC_JOINT_STATES} has no messages"
        raise InputError(msg)


def read_take(path: str | Path) -> ReadTake:
    """Read a camtraj MCAP file back, decoding every message with mcap_ros2.

    Raises:
        InputError: The file cannot be read, is not MCAP, or lacks a camtraj topic.
    """
    path = Path(path)
    with _open_for_reading(path) as stream:
        result: ReadTake = _guard(path, lambda: _read(path, stream))
    return result


def _read(path: Path, stream: IO[bytes]) -> ReadTake:
    reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
    header = reader.get_header()
    summary = reader.get_summary()
    if summary is None:
        msg = f"{path}: the MCAP file has no summary section (was it written completely?)"
        raise InputError(msg)
    topics_present = {ch.topic for ch in summary.channels.values()}
    _check_topics(path, topics_present)

    by_topic: dict[str, list[Any]] = {t: [] for t in topics_present}
    times: dict[str, list[tuple[int, int]]] = {t: [] for t in topics_present}
    for _schema, channel, message, decoded in reader.iter_decoded_messages(
        log_time_order=False
    ):
        by_topic[channel.topic].append(decoded)
        times[channel.topic].append((message.log_time, message.publish_time))

    topics: dict[str, TopicInfo] = {}
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        lt = np.array([a for a, _ in times[channel.topic]], dtype=np.int64)
        pt = np.array([b for _, b in times[channel.topic]], dtype=np.int64)
        topics[channel.topic] = TopicInfo(
            topic=channel.topic,
            schema_name=schema.name if schema else "",
            schema_encoding=schema.encoding if schema else "",
            message_encoding=channel.message_encoding,
            schema_text=schema.data.decode("utf-8") if schema else "",
            message_count=len(lt),
            log_time_ns=lt,
            publish_time_ns=pt,
        )
    _check_counts(path, {topic: len(messages) for topic, messages in by_topic.items()})

    js = by_topic[TOPIC_JOINT_STATES]
    joint_names = _names(js[0].name)
    traj = by_topic[TOPIC_TRAJECTORY][0]
    points = traj.points
    frames = by_topic[TOPIC_FRAMES]
    n_joints = len(joint_names)

    tf_msgs = by_topic[TOPIC_TF]
    tf: dict[str, tuple[str, Array]] = {}
    if tf_msgs:
        first = tf_msgs[0].transforms
        for i, tr in enumerate(first):
            tf[str(tr.child_frame_id)] = (
                str(tr.header.frame_id),
                matrix_from_pose7(
                    np.array([_transform7(m.transforms[i].transform) for m in tf_msgs])
                ),
            )
    tf_static = {
        str(tr.child_frame_id): (
            str(tr.header.frame_id),
            matrix_from_pose7(np.array(_transform7(tr.transform))),
        )
        for tr in by_topic[TOPIC_TF_STATIC][0].transforms
    }

    all_metadata = {rec.name: dict(rec.metadata) for rec in reader.iter_metadata()}

    def rows(values: list[Any], width: int) -> Array:
        return np.array(values, dtype=float).reshape(len(values), width)

    frame_names = _names(frames[0].name) if frames else joint_names
    return ReadTake(
        profile=header.profile,
        library=header.library,
        joint_names=joint_names,
        t=np.array([_stamp(m.header.stamp) for m in js]),
        q=rows([list(m.position) for m in js], n_joints),
        qd=rows([list(m.velocity) for m in js], n_joints),
        effort_sizes=np.array([len(m.effort) for m in js], dtype=np.int64),
        trajectory_joint_names=_names(traj.joint_names),
        trajectory_stamp=_stamp(traj.header.stamp),
        trajectory_t=np.array([_stamp(p.time_from_start) for p in points]),
        trajectory_q=rows([list(p.positions) for p in points], n_joints),
        trajectory_qd=rows([list(p.velocities) for p in points], n_joints),
        trajectory_qdd=rows([list(p.accelerations) for p in points], n_joints),
        frame_numbers=np.array([m.frame for m in frames], dtype=np.int64),
        frame_times=np.array([m.time for m in frames], dtype=float),
        frame_names=frame_names,
        frame_q=rows([list(m.position) for m in frames], len(frame_names)),  # no lens axes
        target=matrix_from_pose7(rows([_pose7(m.target) for m in frames], 7)),
        achieved=matrix_from_pose7(rows([_pose7(m.achieved) for m in frames], 7)),
        focal_length_mm=np.array([m.focal_length_mm for m in frames], dtype=float),
        focus_distance_m=np.array([m.focus_distance_m for m in frames], dtype=float),
        f_stop=np.array([m.f_stop for m in frames], dtype=float),
        tf_times=np.array([_stamp(m.transforms[0].header.stamp) for m in tf_msgs if m.transforms]),
        tf=tf,
        tf_static=tf_static,
        robot_description=str(by_topic[TOPIC_DESCRIPTION][0].data),
        metadata=all_metadata.get(METADATA_NAME, {}),
        all_metadata=all_metadata,
        topics=topics,
    )


@dataclass(frozen=True, eq=False)  # arrays: compare fields, not objects
class ReportTake:
    """What ``camtraj report`` reads from a camtraj MCAP: no per-sample arrays.

    The servo samples stay as the /joint_trajectory message's CDR bytes and are decoded a
    block at a time (:meth:`trajectory_blocks`); /tf is read only at a few times.

    Attributes:
        source: The file (for messages).
        joint_names: /joint_trajectory joint names. stamp: Its header stamp [s].
        point_count: Its number of points (servo samples).
        first_time, last_time: time_from_start of its first and last point [s].
        frame_numbers: /shot/frames frame, shape (n,). frame_times: Their time [s], (n,).
        target: Requested camera poses (camera2base), shape (n, 4, 4).
        tf_count: Number of /tf messages.
        tf_times: Stamps of the /tf samples read [s], shape (k,).
        tf: child frame -> (parent frame, child2parent at those samples, (k, 4, 4)).
        tf_static: child frame -> (parent frame, child2parent (4, 4)).
        metadata: The ``camtraj`` metadata record. all_metadata: Every record by name.
    """

    source: Path
    joint_names: tuple[str, ...]
    stamp: float
    point_count: int
    first_time: float
    last_time: float
    frame_numbers: NDArray[np.int64]
    frame_times: Array
    target: Array
    tf_count: int
    tf_times: Array
    tf: dict[str, tuple[str, Array]]
    tf_static: dict[str, tuple[str, Array]]
    metadata: dict[str, str]
    all_metadata: dict[str, dict[str, str]]
    trajectory_cdr: bytes = field(repr=False)

    def trajectory_blocks(
        self, size: int = 8192
    ) -> Iterable[tuple[Array, Array, Array, Array]]:
        """The servo samples in time order, ``size`` points at a time: ``(t, q, qd, qdd)``,
        shapes (b,) and (b, 8) each (``t``: time_from_start [s])."""
        layout = _TrajectoryLayout.parse(self.source, self.trajectory_cdr)
        for a in range(0, layout.count, size):
            yield layout.points(np.arange(a, min(a + size, layout.count)))

    def count_before(self, times: ArrayLike, size: int = 65536) -> NDArray[np.int64]:
        """How many servo samples come before each of ``times`` [s]."""
        layout = _TrajectoryLayout.parse(self.source, self.trajectory_cdr)
        when = np.asarray(times, dtype=float)
        out = np.zeros(when.shape, dtype=np.int64)
        for a in range(0, layout.count, size):
            t = layout.times(np.arange(a, min(a + size, layout.count)))
            out += np.searchsorted(t, when, side="left")
        return out


def read_take_for_report(
    path: str | Path, tf_at: Callable[[Array], Array] | None = None
) -> ReportTake:
    """Read what ``camtraj report`` needs, in memory that does not grow with the servo samples
    beyond the one /joint_trajectory message's bytes.

    Decodes /shot/frames and /tf_static; /tf only at the messages nearest (by log time, the
    stamp camtraj writes) to the times ``tf_at(frame_times)`` [s] asks for (none without
    ``tf_at``); /joint_states not at all.

    Raises:
        InputError: As :func:`read_take`.
    """
    path = Path(path)
    with _open_for_reading(path) as stream:
        result: ReportTake = _guard(path, lambda: _read_for_report(path, stream, tf_at))
    return result


def _read_for_report(
    path: Path, stream: IO[bytes], tf_at: Callable[[Array], Array] | None
) -> ReportTake:
    reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
    summary = reader.get_summary()
    if summary is None or summary.statistics is None:
        msg = f"{path}: the MCAP file has no summary section (was it written completely?)"
        raise InputError(msg)
    _check_topics(path, {ch.topic for ch in summary.channels.values()})
    counts = {summary.channels[cid].topic: int(n)
              for cid, n in summary.statistics.channel_message_counts.items()
              if cid in summary.channels}
    _check_counts(path, counts)
    all_metadata = {rec.name: dict(rec.metadata) for rec in reader.iter_metadata()}

    # /shot/frames (one decoded message at a time into preallocated arrays) and /tf_static.
    n = counts.get(TOPIC_FRAMES, 0)
    frame_numbers = np.zeros(n, dtype=np.int64)
    frame_times = np.zeros(n)
    target7 = np.zeros((n, 7))
    tf_static: dict[str, tuple[str, Array]] = {}
    i = 0
    for _schema, channel, _message, decoded in reader.iter_decoded_messages(
        topics=[TOPIC_FRAMES, TOPIC_TF_STATIC], log_time_order=False
    ):
        if channel.topic == TOPIC_FRAMES:
            frame_numbers[i], frame_times[i] = decoded.frame, decoded.time
            target7[i] = _pose7(decoded.target)
            i += 1
        else:
            tf_static = {
                str(tr.child_frame_id): (str(tr.header.frame_id),
                                         matrix_from_pose7(np.array(_transform7(tr.transform))))
                for tr in decoded.transforms}
    frame_times = frame_times[:i]

    # /tf at the times asked for: the nearest message by log time, decoded alone.
    wanted = np.asarray(tf_at(frame_times), dtype=float) if tf_at is not None else np.zeros(0)
    tf_msgs = [m for m in (_nearest_tf(reader, w) for w in wanted) if m is not None]
    tf: dict[str, tuple[str, Array]] = {}
    for j, msg_ in enumerate(tf_msgs):
        for tr in msg_.transforms:
            child = str(tr.child_frame_id)
            if child not in tf:
                tf[child] = (str(tr.header.frame_id), np.tile(np.eye(4), (len(tf_msgs), 1, 1)))
            tf[child][1][j] = matrix_from_pose7(np.array(_transform7(tr.transform)))

    # /joint_trajectory last: its bytes are what stays.
    data = next(m.data for _s, _c, m in reader.iter_messages(topics=[TOPIC_TRAJECTORY]))
    layout = _TrajectoryLayout.parse(path, data)
    ends = layout.points(np.array([0, layout.count - 1])) if layout.count else None
    return ReportTake(
        source=path, joint_names=layout.names, stamp=layout.stamp,
        point_count=layout.count,
        first_time=float(ends[0][0]) if ends else math.nan,
        last_time=float(ends[0][-1]) if ends else math.nan,
        frame_numbers=frame_numbers[:i], frame_times=frame_times,
        target=matrix_from_pose7(target7[:i]), tf_count=counts.get(TOPIC_TF, 0),
        tf_times=np.array([_stamp(m.transforms[0].header.stamp) if m.transforms else math.nan
                           for m in tf_msgs]),
        tf=tf, tf_static=tf_static, metadata=all_metadata.get(METADATA_NAME, {}),
        all_metadata=all_metadata, trajectory_cdr=data,
    )


def _nearest_tf(reader: Any, when: float) -> Any:
    """The decoded /tf message whose log time is nearest ``when`` [s] (the first of equals):
    looked for within a second, then in the whole topic; None without /tf messages."""
    if not math.isfinite(when):
        return None
    ns = round(when * _NS)
    for window in (_NS, None):
        span = {} if window is None else {"starting_at": max(0, ns - window),
                                          "ending_at": ns + window}
        best: tuple[int, Any, Any] | None = None
        for schema, _channel, message in reader.iter_messages(
            topics=[TOPIC_TF], log_time_order=True, **span
        ):
            gap = abs(message.log_time - ns)
            if best is None or gap < best[0]:
                best = (gap, schema, message)
        if best is not None:
            decoder = DecoderFactory().decoder_for("cdr", best[1])
            assert decoder is not None
            return decoder(best[2].data)
    return None


@dataclass(frozen=True)
class _TrajectoryLayout:
    """Where the points of a trajectory_msgs/JointTrajectory sit in its CDR bytes
    (little-endian).

    Each point holds three sequences of as many float64 as joint names (positions,
    velocities, accelerations), an empty effort and time_from_start. Its layout depends only
    on where it starts modulo 8, so the points' offsets repeat with a period of one or two
    points and are computed, not walked.
    """

    source: Path
    names: tuple[str, ...]
    stamp: float
    count: int
    body: NDArray[np.uint8]
    first: int  # offset of the first point in the body
    layouts: dict[int, tuple[list[int], list[int], int]]  # phase -> counts, values, size

    def bad(self, what: str) -> InputError:
        return _bad_trajectory(self.source, what)

    @classmethod
    def parse(cls, path: Path, data: bytes) -> _TrajectoryLayout:
        if data[:2] != b"\x00\x01":  # CDR, little-endian
            raise _bad_trajectory(path, "not little-endian CDR")
        body = memoryview(data)[4:]
        pos = 0

        def u32() -> int:
            nonlocal pos
            pos += -pos % 4
            if pos + 4 > len(body):
                raise _bad_trajectory(path, "shorter than its header")
            (value,) = struct.unpack_from("<I", body, pos)
            pos += 4
            return int(value)

        def text() -> str:
            nonlocal pos
            size = u32()
            raw = bytes(body[pos: pos + size])
            pos += size
            return raw.rstrip(b"\x00").decode("utf-8")

        sec, nanosec = u32(), u32()
        stamp = float(np.int32(np.uint32(sec))) + nanosec * 1e-9
        text()  # frame_id
        names = tuple(text() for _ in range(u32()))
        m, w = u32(), len(names)
        layouts: dict[int, tuple[list[int], list[int], int]] = {}
        for phase in (0, 4):
            at, counts, offs = phase, [], []
            for _ in range(3):
                at += -at % 4
                counts.append(at - phase)
                at += 4
                at += -at % 8
                offs.append(at - phase)
                at += 8 * w
            at += -at % 4
            counts.append(at - phase)  # effort
            at += 4
            layouts[phase] = (counts, offs, at - phase + 8)  # + time_from_start
        first = pos + -pos % 4
        layout = cls(path, names, stamp, m, np.frombuffer(body, dtype=np.uint8), first,
                     layouts)
        last = int(layout.starts(np.array([m - 1]))[0]) if m else 0
        if m and last + layouts[last % 8][2] > len(body):
            raise layout.bad("shorter than its points")
        return layout

    def starts(self, idx: NDArray[np.int64]) -> NDArray[np.int64]:
        """Byte offsets of points ``idx`` in the body."""
        size = {ph: lay[2] for ph, lay in self.layouts.items()}
        second = self.first + size[self.first % 8]
        cycle = [second % 8]
        if (second + size[cycle[0]]) % 8 != cycle[0]:
            cycle.append((second + size[cycle[0]]) % 8)
        period = sum(size[ph] for ph in cycle)
        within = np.array([0, size[cycle[0]]], dtype=np.int64)[: len(cycle)]
        k = np.maximum(idx - 1, 0)
        out: NDArray[np.int64] = np.where(
            idx == 0, self.first, second + (k // len(cycle)) * period + within[k % len(cycle)])
        return out

    def points(self, idx: NDArray[np.int64]) -> tuple[Array, Array, Array, Array]:
        """``(t, q, qd, qdd)`` of points ``idx``, every sequence length checked."""
        w = len(self.names)
        base_all = self.starts(idx)
        t, out = np.empty(idx.size), [np.empty((idx.size, w)) for _ in range(3)]
        lane = np.arange(8 * w)
        for phase, (count_offs, offs, size) in self.layouts.items():
            sel = base_all % 8 == phase
            if not np.any(sel):
                continue
            base = base_all[sel]
            u8 = self.body
            for c in count_offs:
                got = u8[base[:, None] + c + np.arange(4)].copy().view("<u4")[:, 0]
                want = 0 if c == count_offs[-1] else w
                if np.any(got != want):
                    raise self.bad("a point's sequence length differs from its joint names")
            for arr, off in zip(out, offs, strict=True):
                arr[sel] = u8[base[:, None] + off + lane].copy().view("<f8")
            t[sel] = self._times(base, size)
        return t, out[0], out[1], out[2]

    def _times(self, base: NDArray[np.int64], size: int | NDArray[np.int64]) -> Array:
        ts = self.body[base[:, None] + size - 8 + np.arange(8)].copy().view("<u4")
        out: Array = ts[:, 0].astype(np.int32) + ts[:, 1] * 1e-9
        return out

    def times(self, idx: NDArray[np.int64]) -> Array:
        """time_from_start of points ``idx`` [s]."""
        base = self.starts(idx)
        size = np.where(base % 8 == 0, self.layouts[0][2], self.layouts[4][2])
        return self._times(base, size[:, None])


def _bad_trajectory(path: Path, what: str) -> InputError:
    return InputError(f"{path}: {TOPIC_TRAJECTORY} is not a joint trajectory camtraj reads "
                      f"({what})")


def describe(path: str | Path) -> dict[str, Any]:
    """A JSON-friendly summary of a camtraj MCAP file, for ``camtraj info``.

    Reads the summary section and decodes only /shot/frames, the metadata and the first and
    last /joint_states samples.

    Returns:
        Keys: ``path``, ``size_bytes``, ``profile``, ``library``, ``source_file``,
        ``camera_prim`` (from the metadata, or None), ``frames`` (count, first, last),
        ``duration_s``, ``servo_rate_hz``, ``servo_step_ms`` (shortest and longest step [ms],
        None in files written before convert recorded it), ``frame_rate_hz``, ``topics``
        (list of topic, type, count), ``limits`` (the robot's joint names and limits, or None),
        ``peak_use`` (axis -> quantity -> fraction of the limit the shot used, or None for
        files that do not record it), ``position_range`` (axis -> [min, max] over the shot
        [m, rad], or None), ``start_joints`` and ``end_joints`` (the first and the last
        /joint_states sample: joint name -> position [m, rad], or None), ``metadata`` (the
        ``camtraj`` record).

    Raises:
        InputError: The file cannot be read or is not MCAP.
    """
    path = Path(path)
    with _open_for_reading(path) as stream:
        result: dict[str, Any] = _guard(path, lambda: _describe(path, stream))
    return result


def _describe(path: Path, stream: IO[bytes]) -> dict[str, Any]:
    reader = make_reader(stream, validate_crcs=True, decoder_factories=[DecoderFactory()])
    header = reader.get_header()
    summary = reader.get_summary()
    if summary is None or summary.statistics is None:
        msg = f"{path}: the MCAP file has no summary statistics (was it written completely?)"
        raise InputError(msg)
    stats = summary.statistics
    counts = stats.channel_message_counts
    topics = []
    count_by_topic: dict[str, int] = {}
    for cid, channel in sorted(summary.channels.items()):
        schema = summary.schemas.get(channel.schema_id)
        count_by_topic[channel.topic] = int(counts.get(cid, 0))
        topics.append(
            {
                "topic": channel.topic,
                "type": schema.name if schema else "",
                "encoding": channel.message_encoding,
                "count": int(counts.get(cid, 0)),
            }
        )
    metadata = {rec.name: dict(rec.metadata) for rec in reader.iter_metadata()}
    if METADATA_NAME not in metadata:  # every camtraj take has it, the oldest too
        msg = (f"{path}: not a camtraj take: no {METADATA_NAME!r} metadata record (topics: "
               f"{', '.join(sorted(count_by_topic)) or 'none'})")
        raise InputError(msg)
    take_md = metadata.get(METADATA_NAME, {})
    robot_md = metadata.get(ROBOT_METADATA_NAME)
    limits = {key: json.loads(value) for key, value in robot_md.items()} if robot_md else None

    frame_numbers: list[int] = []
    frame_times: list[float] = []
    if TOPIC_FRAMES in count_by_topic:
        for _s, _c, _m, msg in reader.iter_decoded_messages(topics=[TOPIC_FRAMES]):
            frame_numbers.append(int(msg.frame))
            frame_times.append(float(msg.time))
    duration = (stats.message_end_time - stats.message_start_time) / _NS
    n_js = count_by_topic.get(TOPIC_JOINT_STATES, 0)
    servo_rate: float | None = None
    try:  # the rate the run asked for (an optimal take's steps vary), as the summary has it
        servo_rate = float(take_md["servo_rate_hz"])
    except (KeyError, ValueError):  # a file without camtraj's metadata: from its stamps
        servo_rate = (n_js - 1) / duration if duration > 0 and n_js > 1 else None
    frame_rate: float | None = None
    try:
        frame_rate = float(take_md["fps"])
    except (KeyError, ValueError):
        if len(frame_times) > 1 and frame_times[-1] > frame_times[0]:
            frame_rate = (len(frame_times) - 1) / (frame_times[-1] - frame_times[0])
    return {
        "path": str(path),
        "size_bytes": path.stat().st_size,
        "profile": header.profile,
        "library": header.library,
        "source_file": take_md.get("source_file", take_md.get("source")),
        "camera_prim": take_md.get("camera_prim", take_md.get("camera")),
        "frames": {
            "count": len(frame_numbers),
            "first": frame_numbers[0] if frame_numbers else None,
            "last": frame_numbers[-1] if frame_numbers else None,
            "start_s": frame_times[0] if frame_times else None,
            "end_s": frame_times[-1] if frame_times else None,
        },
        "duration_s": duration,
        "servo_rate_hz": servo_rate,
        "servo_step_ms": _json_or_none(take_md.get("servo_step_ms")),
        "frame_rate_hz": frame_rate,
        "topics": topics,
        "limits": limits,
        "peak_use": _json_or_none(take_md.get("peak_use")),
        "position_range": _json_or_none(take_md.get("position_range")),
        "controller": _json_or_none(take_md.get("controller")),
        "start_joints": _end_sample(reader, reverse=False),
        "end_joints": _end_sample(reader, reverse=True),
        "metadata": take_md,
    }


def _end_sample(reader: Any, *, reverse: bool) -> dict[str, float] | None:
    """The take's first (or last) /joint_states sample: joint name -> position [m, rad]
    (where the robot stands when the take begins, or ends: the next take's start pose)."""
    for _s, _c, _m, msg in reader.iter_decoded_messages(topics=[TOPIC_JOINT_STATES],
                                                        reverse=reverse):
        return {str(n): float(v) for n, v in zip(msg.name, msg.position, strict=True)}
    return None


def _json_or_none(text: str | None) -> Any:
    if text is None:
        return None
    try:
        return json.loads(text)
    except (RecursionError, ValueError):
        return None
