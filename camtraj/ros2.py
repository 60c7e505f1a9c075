"""ROS 2 facts the MCAP writer needs: QoS profiles, CameraInfo intrinsics, camtraj's messages.

**QoS.** Every channel carries ``offered_qos_profiles``, the YAML that rosbag2 stores per topic
(a list with one profile). It is written in rosbag2's metadata version 8 form, as Humble
writes it, with integers for reliability, durability and liveliness (the tests read it back
with the ``rosbags`` library). Durations are 0 s 0 ns, "unspecified" (rmw's defaults).
Latched topics (``/tf_static``, ``/robot_description``, ``/joint_trajectory``) are
``transient_local`` with depth 1, so a subscriber that joins late still gets them; every other
topic is ``volatile`` with depth 10. All are reliable and keep_last.

**CameraInfo.** The pinhole intrinsics of a USD lens at a chosen image width (default 1920 px)
and the height of the film back's aspect at the first frame, fixed for the take (an animated
film back changes the intrinsics, not the image size): ``width`` px across
``horizontalAperture``, so ``fx = focal length / horizontal aperture * width`` and ``fy = focal
length / vertical aperture * height`` [px], the principal point at the image centre (aperture
offsets are not read). No distortion (``plumb_bob`` with zeros), R = identity, P = [K | 0]. The
message is in the camera's ROS optical frame ``camera_optical`` (z forward, y down), which is
what Foxglove draws a frustum from.

**Foxglove layout.** ``camtraj/data/foxglove_layout.json`` (``camtraj convert
--foxglove-layout FILE.json`` writes a copy): a 3-D panel in the ``world`` frame with the URDF
from ``/robot_description``, tf and the CameraInfo frustum; plots of the eight axes from
``/joint_states``; a raw-messages panel on ``/shot/frames``.

**ShotFrame.** ``camtraj_msgs/msg/ShotFrame`` is defined once, in the ROS 2 interface package
``ros/camtraj_msgs/msg/ShotFrame.msg``; camtraj ships the same file as package data and embeds
its text in every MCAP.
"""

from __future__ import annotations

from importlib import resources

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

__all__ = [
    "IMAGE_WIDTH",
    "LATCHED_TOPICS",
    "camera_matrices",
    "foxglove_layout",
    "image_heights",
    "offered_qos_profiles",
    "shot_frame_definition",
]

IMAGE_WIDTH = 1920
"""Image width [px] of the CameraInfo; the height follows the film back's aspect."""

LATCHED_TOPICS = frozenset({"/tf_static", "/robot_description", "/joint_trajectory"})
"""Topics offered transient_local: published once, kept for late subscribers (a controller
that connects after ``ros2 bag play`` starts still gets the whole trajectory)."""

# rmw enum values (rmw/types.h), the integers of rosbag2's version-8 QoS YAML.
_KEEP_LAST = 1
_RELIABLE = 1
_TRANSIENT_LOCAL, _VOLATILE = 1, 2
_AUTOMATIC = 1


def offered_qos_profiles(topic: str) -> str:
    """The ``offered_qos_profiles`` channel metadata of ``topic``: rosbag2's YAML, one profile."""
    latched = topic in LATCHED_TOPICS
    depth = 1 if latched else 10
    durability = _TRANSIENT_LOCAL if latched else _VOLATILE
    zero = "\n    sec: 0\n    nsec: 0"
    return (
        f"- history: {_KEEP_LAST}\n"
        f"  depth: {depth}\n"
        f"  reliability: {_RELIABLE}\n"
        f"  durability: {durability}\n"
        f"  deadline:{zero}\n"
        f"  lifespan:{zero}\n"
        f"  liveliness: {_AUTOMATIC}\n"
        f"  liveliness_lease_duration:{zero}\n"
        "  avoid_ros_namespace_conventions: false"
    )


def image_heights(
    horizontal_aperture_mm: ArrayLike, vertical_aperture_mm: ArrayLike, width: int = IMAGE_WIDTH
) -> NDArray[np.int64]:
    """Image height [px] per frame: ``width`` times the film back's aspect, rounded, >= 1."""
    h = np.asarray(horizontal_aperture_mm, dtype=float)
    v = np.asarray(vertical_aperture_mm, dtype=float)
    heights: NDArray[np.int64] = np.maximum(np.rint(width * v / h), 1).astype(np.int64)
    return heights


def camera_matrices(
    focal_length_mm: ArrayLike,
    horizontal_aperture_mm: ArrayLike,
    vertical_aperture_mm: ArrayLike,
    width: int = IMAGE_WIDTH,
    height: int | None = None,
    horizontal_offset_mm: ArrayLike | None = None,
    vertical_offset_mm: ArrayLike | None = None,
) -> Array:
    """Pinhole camera matrices K [px] per frame, shape (n, 3, 3).

    Args:
        focal_length_mm: (n,) focal length [mm].
        horizontal_aperture_mm: (n,) film back width [mm].
        vertical_aperture_mm: (n,) film back height [mm].
        width: Image width [px].
        height: Image height [px] for every frame; default the first frame's
            :func:`image_heights` (one image size for the take).
        horizontal_offset_mm, vertical_offset_mm: (n,) lens shift [mm], USD's
            ``horizontalApertureOffset`` (+x right) and ``verticalApertureOffset`` (+y up):
            the film back moves off the lens axis, so the principal point moves the other
            way in the image (x right, y down); default 0.
    """
    f = np.asarray(focal_length_mm, dtype=float)
    h = np.asarray(horizontal_aperture_mm, dtype=float)
    v = np.asarray(vertical_aperture_mm, dtype=float)
    if height is None:
        height = int(image_heights(h[:1], v[:1], width)[0]) if h.size else 1
    K = np.zeros((len(f), 3, 3))
    K[:, 0, 0] = f / h * width
    K[:, 1, 1] = f / v * height
    ox = np.zeros(len(f)) if horizontal_offset_mm is None else np.asarray(horizontal_offset_mm,
                                                                             dtype=float)
    oy = np.zeros(len(f)) if vertical_offset_mm is None else np.asarray(vertical_offset_mm,
                                                                           dtype=float)
    K[:, 0, 2] = width / 2.0 - ox / h * width
    K[:, 1, 2] = height / 2.0 + oy / v * height
    K[:, 2, 2] = 1.0
    return K


def shot_frame_definition() -> str:
    """The text of ``ShotFrame.msg`` (package data; the same file as ros/camtraj_msgs/msg)."""
    return resources.files("camtraj").joinpath("data/ShotFrame.msg").read_text(encoding="utf-8")


def foxglove_layout() -> str:
    """The Foxglove layout JSON shipped with camtraj (package data), as text."""
    return resources.files("camtraj").joinpath("data/foxglove_layout.json").read_text(
        encoding="utf-8"
    )
