"""ROS 2 and Foxglove: QoS, the camtraj_msgs package, tf's world, CameraInfo, the layout.

The converted files are read back with ``rosbags`` (an independent ROS 2 reader with its own
CDR decoder and message parser), with ShotFrame registered from the interface package's .msg.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from numpy.typing import NDArray
from pxr import Usd, UsdGeom
from rosbags.interfaces import QosDurability, QosHistory, QosReliability
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from camtraj.convert import convert
from camtraj.mcap_io import TOPICS
from camtraj.options import ConvertOptions
from camtraj.robot import JOINT_NAMES, Robot

Array = NDArray[np.float64]

ROOT = Path(__file__).resolve().parent.parent
SHOTS = ROOT / "samples" / "shots"
PACKAGE = ROOT / "ros" / "camtraj_msgs"
MSG_FILE = PACKAGE / "msg" / "ShotFrame.msg"
PLACEMENT = (0.1, 0.05, 0.0, 5.0)  # x, y, z [m], yaw [deg]
LATCHED = {"/tf_static", "/robot_description", "/joint_trajectory"}
DELIMITER = "\n" + "=" * 80 + "\n"


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two samples converted in process: a Z-up metre shot placed with a yaw, a Y-up cm one."""
    out = tmp_path_factory.mktemp("ros2")
    paths = {
        "placed": (SHOTS / "blender_crane_up.usda", ConvertOptions(placement=PLACEMENT)),
        "maya": (SHOTS / "maya_dolly_push_in.usda", ConvertOptions()),
    }
    for key, (shot, options) in paths.items():
        convert(shot, out / f"{key}.mcap", options)
    return {key: out / f"{key}.mcap" for key in paths}


def typestore() -> Any:
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(MSG_FILE.read_text(), "camtraj_msgs/msg/ShotFrame"))
    return store


def read_all(path: Path) -> tuple[dict[str, list[Any]], dict[str, Any]]:
    """Every message decoded by rosbags, by topic; and each topic's connection."""
    store = typestore()
    messages: dict[str, list[Any]] = {}
    with Reader(path) as reader:
        connections = {c.topic: c for c in reader.connections}
        for conn, _t, raw in reader.messages():
            messages.setdefault(conn.topic, []).append(store.deserialize_cdr(raw, conn.msgtype))
    return messages, connections


def test_every_channel_offers_qos_in_rosbag2_yaml(files: dict[str, Path]) -> None:
    with files["placed"].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    channels = list(summary.channels.values())
    assert {c.topic for c in channels} == set(TOPICS)
    for channel in channels:
        profiles = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert isinstance(profiles, list)
        assert len(profiles) == 1
        p = profiles[0]
        assert set(p) == {"history", "depth", "reliability", "durability", "deadline",
                          "lifespan", "liveliness", "liveliness_lease_duration",
                          "avoid_ros_namespace_conventions"}
        assert p["reliability"] == 1  # RMW_QOS_POLICY_RELIABILITY_RELIABLE
        assert p["history"] == 1  # KEEP_LAST
        assert p["durability"] == (1 if channel.topic in LATCHED else 2)  # transient_local
        assert p["depth"] >= 1
        for key in ("deadline", "lifespan", "liveliness_lease_duration"):
            assert p[key] == {"sec": 0, "nsec": 0}
    # rosbags reads the same profiles (its parser of rosbag2's QoS YAML).
    _, connections = read_all(files["placed"])
    for topic, conn in connections.items():
        [qos] = conn.ext.offered_qos_profiles
        assert qos.reliability == QosReliability.RELIABLE
        assert qos.history == QosHistory.KEEP_LAST
        want = QosDurability.TRANSIENT_LOCAL if topic in LATCHED else QosDurability.VOLATILE
        assert qos.durability == want, topic


def test_rosbags_reads_every_message_of_every_topic(files: dict[str, Path]) -> None:
    messages, _ = read_all(files["placed"])
    with files["placed"].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    counts = {summary.channels[cid].topic: n
              for cid, n in summary.statistics.channel_message_counts.items()}
    assert {t: len(m) for t, m in messages.items()} == counts
    assert set(messages) == set(TOPICS)
    frames = messages["/shot/frames"]
    infos = messages["/camera/camera_info"]
    assert len(frames) == len(infos) > 10
    robot = Robot.default()
    for frame, info in zip(frames, infos, strict=True):
        assert list(frame.name) == list(JOINT_NAMES)
        # The camera reached: FK of the frame's joints is its 'achieved' pose.
        achieved = robot.camera_pose(np.asarray(frame.position))
        p = frame.achieved.position
        np.testing.assert_allclose(achieved[:3, 3], [p.x, p.y, p.z], atol=1e-12)
        assert (info.header.stamp.sec, info.header.stamp.nanosec) == _stamp(frame.time)
        assert info.header.frame_id == "camera_optical"
    assert messages["/robot_description"][0].data.startswith("<?xml")


def _stamp(t: float) -> tuple[int, int]:
    ns = round(t * 1e9)
    return ns // 10**9, ns % 10**9


def test_shot_frame_msg_is_the_embedded_definition(files: dict[str, Path]) -> None:
    with files["maya"].open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    [schema] = [s for s in summary.schemas.values() if s.name == "camtraj_msgs/msg/ShotFrame"]
    top = schema.data.split(DELIMITER.encode())[0] + b"\n"
    assert top == MSG_FILE.read_bytes()
    # The package data camtraj reads is that same file.
    packaged = ROOT / "camtraj" / "data" / "ShotFrame.msg"
    assert packaged.read_bytes() == MSG_FILE.read_bytes()


def test_camtraj_msgs_is_a_ros2_interface_package() -> None:
    pkg = ET.parse(PACKAGE / "package.xml").getroot()
    assert pkg.get("format") == "3"
    assert pkg.findtext("name") == "camtraj_msgs"
    assert pkg.findtext("member_of_group") == "rosidl_interface_packages"
    assert {e.text for e in pkg.findall("buildtool_depend")} >= {
        "ament_cmake", "rosidl_default_generators"}
    assert "geometry_msgs" in {e.text for e in pkg.findall("depend")}
    assert "rosidl_default_runtime" in {e.text for e in pkg.findall("exec_depend")}
    cmake = (PACKAGE / "CMakeLists.txt").read_text()
    assert "project(camtraj_msgs)" in cmake
    assert '"msg/ShotFrame.msg"' in cmake
    assert "rosidl_generate_interfaces(${PROJECT_NAME}" in cmake
    assert "DEPENDENCIES geometry_msgs" in cmake
    # Field names follow ROS 2's rules (lower case, digits, single underscores).
    for line in MSG_FILE.read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name = line.split()[1]
            assert name.islower() and "__" not in name and not name.endswith("_"), name


def _yaw_matrix(x: float, y: float, z: float, yaw_deg: float) -> Array:
    a = math.radians(yaw_deg)
    return np.array([[math.cos(a), -math.sin(a), 0, x], [math.sin(a), math.cos(a), 0, y],
                     [0, 0, 1, z], [0, 0, 0, 1]])


def _transform(tr: Any) -> Array:
    t, r = tr.translation, tr.rotation
    x, y, z, w = r.x, r.y, r.z, r.w
    T = np.eye(4)
    T[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    T[:3, 3] = (t.x, t.y, t.z)
    return T


@pytest.mark.parametrize(("key", "placement"), [("placed", PLACEMENT), ("maya", (0, 0, 0, 0))])
def test_tf_root_is_world_above_base_link(
    files: dict[str, Path], key: str, placement: tuple[float, float, float, float]
) -> None:
    messages, _ = read_all(files[key])
    [static] = messages["/tf_static"]
    parents = {t.child_frame_id: t.header.frame_id for t in static.transforms}
    for msg in messages["/tf"][:1]:
        parents.update({t.child_frame_id: t.header.frame_id for t in msg.transforms})
    roots = set(parents.values()) - set(parents)
    assert roots == {"world"}
    assert parents["base_link"] == "world"
    [world] = [t for t in static.transforms if t.child_frame_id == "base_link"]
    np.testing.assert_allclose(_transform(world.transform), _yaw_matrix(*placement), atol=1e-15)
    # Every frame reaches world; the optical frame hangs off the camera.
    assert parents["camera_optical"] == "camera"


def _usd_lens(path: Path) -> dict[str, float]:
    """The first frame's lens, read here with pxr (mm from tenths of a scene unit)."""
    stage = Usd.Stage.Open(str(path))
    [cam] = [UsdGeom.Camera(p) for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
    mm = UsdGeom.GetStageMetersPerUnit(stage) * 100.0
    t = Usd.TimeCode(stage.GetStartTimeCode())
    return {"f": cam.GetFocalLengthAttr().Get(t) * mm,
            "h": cam.GetHorizontalApertureAttr().Get(t) * mm,
            "v": cam.GetVerticalApertureAttr().Get(t) * mm}


@pytest.mark.parametrize(("key", "shot"), [("placed", "blender_crane_up"),
                                           ("maya", "maya_dolly_push_in")])
def test_camera_info_k_matches_the_lens(files: dict[str, Path], key: str, shot: str) -> None:
    messages, _ = read_all(files[key])
    info = messages["/camera/camera_info"][0]
    lens = _usd_lens(SHOTS / f"{shot}.usda")
    assert info.width == 1920
    assert info.height == round(1920 * lens["v"] / lens["h"])
    K = np.asarray(info.k).reshape(3, 3)
    fx = lens["f"] / lens["h"] * info.width
    fy = lens["f"] / lens["v"] * info.height
    np.testing.assert_allclose(K, [[fx, 0, info.width / 2], [0, fy, info.height / 2], [0, 0, 1]],
                               rtol=1e-6)
    P = np.asarray(info.p).reshape(3, 4)
    np.testing.assert_allclose(P[:, :3], K, rtol=0, atol=0)
    assert info.distortion_model == "plumb_bob"
    assert list(info.d) == [0.0] * 5
    # The frustum looks where the camera looks: optical +z is the USD camera's -z.
    [static] = messages["/tf_static"]
    [optical] = [t for t in static.transforms if t.child_frame_id == "camera_optical"]
    np.testing.assert_allclose(_transform(optical.transform)[:3, 2], [0, 0, -1], atol=1e-15)


def test_mcap_with_placement_is_byte_identical_on_rerun(
    files: dict[str, Path], tmp_path: Path
) -> None:
    again = tmp_path / "again.mcap"
    convert(SHOTS / "blender_crane_up.usda", again, ConvertOptions(placement=PLACEMENT))
    assert again.read_bytes() == files["placed"].read_bytes()


def test_foxglove_layout_is_written_beside_the_mcap(tmp_path: Path) -> None:
    out, layout = tmp_path / "shot.mcap", tmp_path / "shot.layout.json"
    proc = subprocess.run(
        [sys.executable, "-m", "camtraj", "convert", str(SHOTS / "maya_dolly_push_in.usda"),
         "-o", str(out), "--foxglove-layout", str(layout), "-q"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    data = json.loads(layout.read_text())
    panels = data["configById"]
    three_d = panels["3D!camtraj"]
    assert three_d["followTf"] == "world"
    assert three_d["topics"]["/robot_description"]["visible"]
    assert three_d["topics"]["/camera/camera_info"]["visible"]
    plotted = [p["value"] for k, v in panels.items() if k.startswith("Plot!") for p in v["paths"]]
    assert sorted(plotted) == [f"/joint_states.position[{i}]" for i in range(8)]
    assert panels["RawMessages!camtraj"]["topicPath"] == "/shot/frames"

    def leaves(node: Any) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(
            node["second"])

    assert sorted(leaves(data["layout"])) == sorted(panels)
    # Every topic the layout names is in the file.
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    topics = {c.topic for c in summary.channels.values()}
    named = {*three_d["topics"], "/shot/frames", "/joint_states"}
    assert named <= topics
    # A bad layout path (a file where its folder should be) fails before converting, and
    # leaves nothing.
    (tmp_path / "a_file").write_text("not a folder")
    bad = subprocess.run(
        [sys.executable, "-m", "camtraj", "convert", str(SHOTS / "maya_dolly_push_in.usda"),
         "-o", str(tmp_path / "b.mcap"), "--foxglove-layout",
         str(tmp_path / "a_file" / "x.json")],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert bad.returncode == 2
    assert not (tmp_path / "b.mcap").exists()


def test_animated_film_back_keeps_one_image_size(tmp_path: Path) -> None:
    """The film back's height animates (1190 to 1440 px worth): the image size stays the first
    frame's and fy follows the lens, frame by frame (pxr reads the lens independently)."""
    shot = tmp_path / "shot.usda"
    stage = Usd.Stage.Open(str(SHOTS / "blender_crane_up.usda"))
    stage.GetRootLayer().Export(str(shot))
    stage = Usd.Stage.Open(str(shot))
    [cam] = [UsdGeom.Camera(p) for p in stage.Traverse() if p.IsA(UsdGeom.Camera)]
    first, last = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    attr = cam.GetVerticalApertureAttr()
    v0 = attr.Get(Usd.TimeCode(first))
    for tc in range(first, last + 1):
        attr.Set(v0 * (1.0 + 0.2 * (tc - first) / (last - first)), Usd.TimeCode(tc))
    stage.GetRootLayer().Save()
    convert(shot, tmp_path / "shot.mcap", ConvertOptions())
    messages, _ = read_all(tmp_path / "shot.mcap")
    infos = messages["/camera/camera_info"]
    assert len(infos) == last - first + 1
    mm = UsdGeom.GetStageMetersPerUnit(stage) * 100.0
    h0 = cam.GetHorizontalApertureAttr().Get(Usd.TimeCode(first)) * mm
    height = round(1920 * v0 * mm / h0)
    assert {(i.width, i.height) for i in infos} == {(1920, height)}
    for tc, info in zip(range(first, last + 1), infos, strict=True):
        t = Usd.TimeCode(tc)
        f, v = cam.GetFocalLengthAttr().Get(t) * mm, attr.Get(t) * mm
        assert info.k[4] == pytest.approx(f / v * height, rel=1e-9)
        assert info.k[5] == height / 2
    assert infos[-1].k[4] < infos[0].k[4] / 1.15  # the change is carried by fy


def test_servo_rate_metadata_is_the_exact_rate(files: dict[str, Path]) -> None:
    with files["maya"].open("rb") as stream:
        md = {m.name: m.metadata for m in make_reader(stream).iter_metadata()}
    assert md["camtraj"]["servo_rate_hz"] == "240.0"
