"""Writing a take as ROS 2 MCAP and reading it back (design.md §4)."""

from __future__ import annotations

import io
import math
import os
import re
import time
import tracemalloc
from pathlib import Path
from types import SimpleNamespace
from typing import IO, Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from mcap_ros2.decoder import DecoderFactory
from numpy.typing import NDArray

from camtraj import mcap_io, ros2
from camtraj.errors import InputError
from camtraj.mcap_io import (
    TOPICS,
    TakeData,
    describe,
    interpolate_servo,
    matrix_from_quat,
    message_definition,
    quat_from_matrix,
    read_take,
    seconds_to_ns,
    tf_times,
    write_take_to,
)
from camtraj.outputs import OutputSet
from camtraj.robot import JOINT_NAMES, Robot
from camtraj.urdf import (
    BASE_FRAME,
    CAMERA_FRAME,
    LINK_FRAMES,
    Transform,
    robot_urdf,
    static_transforms,
)

Array = NDArray[np.float64]

ROBOT = Robot.default()
METADATA = {
    "source_file": "shots/crane.usda",
    "camera_prim": "/World/Cam",
    "frame_range": "1001-1096",
    "fps": "24",
    "robot": "builtin",
    "timing_mode": "shot",
    "speed_factor": "1.0",
    "tool_version": "camtraj 0.1.0",
}


PLACEMENT = np.array(
    [[0.0, -1.0, 0.0, 2.0], [1.0, 0.0, 0.0, -0.5], [0.0, 0.0, 1.0, 0.1], [0.0, 0.0, 0.0, 1.0]]
)  # 90 deg of yaw and an offset


def write_take(path: Path, take: TakeData, robot: Robot, metadata: dict[str, str]) -> None:
    """A take written to ``path`` as convert writes it (through an OutputSet)."""
    with OutputSet() as outputs:
        outputs.add(path)
        with outputs.open(path) as stream:
            write_take_to(stream, take, robot, metadata)
        outputs.commit()


def make_take(
    seed: int = 0,
    m: int = 1200,
    n: int = 96,
    rate: float = 250.0,
    fps: float = 24.0,
    first_frame_time: float = 0.5,
) -> TakeData:
    """A random (seeded) take: m servo samples at ``rate``, n film frames at ``fps``."""
    rng = np.random.default_rng(seed)
    t = np.arange(m) / rate
    q = rng.uniform(ROBOT.lower, ROBOT.upper, size=(m, 8))
    qd = rng.normal(size=(m, 8))
    qdd = rng.normal(size=(m, 8)) * 10
    frame_times = first_frame_time + np.arange(n) / fps
    frame_q = rng.uniform(ROBOT.lower, ROBOT.upper, size=(n, 8))
    achieved = ROBOT.camera_pose(frame_q)
    target = ROBOT.camera_pose(frame_q + rng.normal(scale=1e-3, size=(n, 8)))
    return TakeData(
        joint_names=JOINT_NAMES,
        t=t,
        q=q,
        qd=qd,
        qdd=qdd,
        frame_numbers=np.arange(1001, 1001 + n),
        frame_times=frame_times,
        frame_q=frame_q,
        target=target,
        achieved=achieved,
        focal_length_mm=rng.uniform(18, 85, size=n),
        focus_distance_m=rng.uniform(0.5, 20, size=n),
        f_stop=rng.choice([1.4, 2.0, 2.8, 4.0, 5.6], size=n),
        fps=fps,
        horizontal_aperture_mm=np.full(n, 36.0),
        vertical_aperture_mm=np.full(n, 24.0),
        base2world=PLACEMENT,
    )


@pytest.fixture(scope="module")
def take() -> TakeData:
    return make_take()


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory, take: TakeData) -> Path:
    path = tmp_path_factory.mktemp("mcap") / "take.mcap"
    write_take(path, take, ROBOT, METADATA)
    return path


@pytest.fixture(scope="module")
def back(written: Path) -> mcap_io.ReadTake:
    return read_take(written)


# -- round trip -------------------------------------------------------------------------------


def test_round_trip_joint_states(take: TakeData, back: mcap_io.ReadTake) -> None:
    assert back.joint_names == JOINT_NAMES
    np.testing.assert_allclose(back.t, take.t, rtol=0, atol=1e-9)  # stamps in whole ns
    assert np.array_equal(back.q, take.q)
    assert np.array_equal(back.qd, take.qd)
    assert np.all(back.effort_sizes == 0)


def test_round_trip_trajectory(take: TakeData, back: mcap_io.ReadTake) -> None:
    assert back.trajectory_joint_names == JOINT_NAMES
    assert back.trajectory_stamp == 0.0
    np.testing.assert_allclose(back.trajectory_t, take.t, rtol=0, atol=1e-9)
    assert np.array_equal(back.trajectory_q, take.q)
    assert np.array_equal(back.trajectory_qd, take.qd)
    assert np.array_equal(back.trajectory_qdd, take.qdd)


def test_round_trip_shot_frames(take: TakeData, back: mcap_io.ReadTake) -> None:
    assert np.array_equal(back.frame_numbers, take.frame_numbers)
    assert np.array_equal(back.frame_times, take.frame_times)
    assert back.frame_names == JOINT_NAMES
    assert np.array_equal(back.frame_q, take.frame_q)
    np.testing.assert_allclose(back.target, take.target, rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.achieved, take.achieved, rtol=0, atol=1e-12)
    assert np.array_equal(back.focal_length_mm, take.focal_length_mm)
    assert np.array_equal(back.focus_distance_m, take.focus_distance_m)
    assert np.array_equal(back.f_stop, take.f_stop)


def test_round_trip_description_and_metadata(back: mcap_io.ReadTake) -> None:
    assert back.robot_description == robot_urdf(ROBOT)
    assert back.metadata == METADATA
    assert set(back.all_metadata) == {"camtraj", "camtraj.robot"}
    assert back.all_metadata["camtraj.robot"]["joints"] == (
        '["track", "rotate", "lift", "extend", "elbow", "pan", "tilt", "roll"]'
    )
    assert back.profile == "ros2"
    assert back.library.startswith("camtraj/")


def test_topics_schemas_and_times(take: TakeData, back: mcap_io.ReadTake) -> None:
    expected = {
        "/joint_states": ("sensor_msgs/msg/JointState", len(take.t)),
        "/joint_trajectory": ("trajectory_msgs/msg/JointTrajectory", 1),
        "/shot/frames": ("camtraj_msgs/msg/ShotFrame", len(take.frame_times)),
        "/robot_description": ("std_msgs/msg/String", 1),
        "/tf": ("tf2_msgs/msg/TFMessage", len(tf_times(take))),
        "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
        "/camera/camera_info": ("sensor_msgs/msg/CameraInfo", len(take.frame_times)),
    }
    assert set(back.topics) == set(expected)
    for topic, (schema, count) in expected.items():
        info = back.topics[topic]
        assert info.schema_name == schema
        assert info.schema_encoding == "ros2msg"
        assert info.message_encoding == "cdr"
        assert info.message_count == count
        assert info.schema_text == message_definition(schema)
        assert np.array_equal(info.log_time_ns, info.publish_time_ns)
    lt = {topic: info.log_time_ns for topic, info in back.topics.items()}
    assert np.array_equal(lt["/joint_states"], seconds_to_ns(take.t))
    assert np.array_equal(lt["/shot/frames"], seconds_to_ns(take.frame_times))
    assert np.array_equal(lt["/camera/camera_info"], seconds_to_ns(take.frame_times))
    assert np.array_equal(lt["/tf"], seconds_to_ns(tf_times(take)))
    for topic in ("/joint_trajectory", "/robot_description", "/tf_static"):
        assert lt[topic].tolist() == [0]
    # Header stamps agree with log times.
    assert np.array_equal(seconds_to_ns(back.t), lt["/joint_states"])
    assert np.array_equal(seconds_to_ns(back.tf_times), lt["/tf"])


def test_file_layout_chunks_and_order(written: Path) -> None:
    with written.open("rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        assert summary is not None
        assert header.profile == "ros2"
        assert summary.chunk_indexes
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert [ch.topic for ch in summary.channels.values()] == list(TOPICS)
        # Written in log-time order.
        times = [m.log_time for _s, _c, m in reader.iter_messages(log_time_order=False)]
    assert times == sorted(times)
    assert times[0] == 0


def test_tf_static_tree(back: mcap_io.ReadTake) -> None:
    statics = [Transform("world", "base_link", PLACEMENT), *static_transforms(ROBOT)]
    assert set(back.tf_static) == {s.child for s in statics}
    for s in statics:
        parent, T = back.tf_static[s.child]
        assert parent == s.parent
        np.testing.assert_allclose(T, s.child2parent, rtol=0, atol=1e-15)


def _compose(back: mcap_io.ReadTake, k: int) -> dict[str, Array]:
    edges = {child: (parent, T) for child, (parent, T) in back.tf_static.items()}
    edges.update({child: (parent, T[k]) for child, (parent, T) in back.tf.items()})
    frames: dict[str, Array] = {BASE_FRAME: np.eye(4)}

    def pose(frame: str) -> Array:
        if frame not in frames:
            parent, T = edges[frame]
            frames[frame] = pose(parent) @ T
        return frames[frame]

    for child in edges:
        pose(child)
    return frames


def _check_tf_against_fk(back: mcap_io.ReadTake, q_at_tf: Array) -> None:
    assert len(back.tf_times) == len(q_at_tf)
    expected = ROBOT.link_frames(q_at_tf)
    cams = ROBOT.camera_pose(q_at_tf)
    for k in range(len(q_at_tf)):
        frames = _compose(back, k)
        for i, name in enumerate(LINK_FRAMES):
            np.testing.assert_allclose(frames[name], expected[k, i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(frames[CAMERA_FRAME], cams[k], rtol=0, atol=1e-12)


def test_tf_matches_fk_on_servo_samples(tmp_path: Path) -> None:
    """At 25 fps with frames on servo samples, each /tf sample is a servo sample exactly."""
    take = make_take(seed=3, m=500, n=40, fps=25.0, first_frame_time=0.2)
    path = tmp_path / "tf.mcap"
    write_take(path, take, ROBOT, {})
    back = read_take(path)
    idx = np.rint(back.tf_times * 250.0).astype(int)
    np.testing.assert_allclose(back.tf_times, take.t[idx], rtol=0, atol=1e-9)
    assert idx[0] == 0
    assert idx[-1] >= len(take.t) - 10
    _check_tf_against_fk(back, take.q[idx])


def test_tf_matches_fk_interpolated(take: TakeData, back: mcap_io.ReadTake) -> None:
    q = interpolate_servo(take.t, take.q, take.qd, tf_times(take))
    _check_tf_against_fk(back, q)


def test_take_without_frames(tmp_path: Path) -> None:
    """A take with no film frames (e.g. a pure move) still writes and reads."""
    full = make_take(seed=5, m=300, n=0)
    path = tmp_path / "empty.mcap"
    write_take(path, full, ROBOT, {})
    back = read_take(path)
    assert back.topics["/shot/frames"].message_count == 0
    assert back.frame_q.shape == (0, 8)
    assert back.target.shape == (0, 4, 4)
    assert np.array_equal(back.q, full.q)
    assert back.tf_times[0] == 0.0
    assert describe(path)["frames"]["count"] == 0


def test_tf_times_grid(take: TakeData) -> None:
    """The film frame rate from the take's first sample to its last, anchored on the shot's
    frames (every film frame time is a /tf time), with the take's ends added."""
    times = tf_times(take)
    assert times[0] == take.t[0] and times[-1] == take.t[-1]
    inner = times[1:-1]
    np.testing.assert_allclose(np.diff(inner), 1 / take.fps, rtol=0, atol=1e-12)
    step = 1 / take.fps + 1e-12
    assert 0 < inner[0] - times[0] <= step and 0 < times[-1] - inner[-1] <= step
    assert np.all(np.min(np.abs(times[:, None] - take.frame_times[None, :]), axis=0) < 1e-12)


@pytest.mark.parametrize("factor", [1.0, 1.3, 1.45, 2.7, 0.37])
def test_tf_times_of_a_retimed_take_are_never_more_than_a_frame_apart(factor: float) -> None:
    """A take whose frames are ``factor`` film intervals apart (scale slows it, optimal plays
    it faster): every frame's stamp is a /tf time, so are the take's ends, and no two /tf
    times are more than a film frame interval apart or closer than 2 ns."""
    fps = 24.0
    frames = 0.25 + factor * np.arange(30) / fps
    t = np.linspace(0.0, frames[-1] + 0.3, 2000)
    times = tf_times(SimpleNamespace(t=t, frame_times=frames, fps=fps))  # type: ignore[arg-type]
    assert set(frames) <= set(times.tolist())
    assert times[0] == t[0] and times[-1] == t[-1]
    assert np.diff(times).max() <= 1 / fps + 1e-12
    assert np.diff(times).min() > 2e-9


def test_tf_times_hold_every_film_frame_stamp_of_a_timed_take() -> None:
    """Frame times of a take are whole nanoseconds (the file's clock) and may sit a
    nanosecond off the frame-rate grid's sums (1/24 s is not whole nanoseconds): /tf still
    has a sample at every film frame's own stamp."""
    from types import SimpleNamespace

    from camtraj.mcap_io import seconds_to_ns
    from camtraj.timing import Limits, time_shot
    from tests.timing_checks import HOME, frame_times

    t = frame_times(2000)
    q = HOME + 0.5 * np.sin(2 * np.pi * t[:, None] / 20.0)  # its run-up: 137 ticks at 240 Hz
    take = time_shot(q, t, Limits.from_robot(ROBOT), mode="shot")
    shot = SimpleNamespace(t=take.t, frame_times=take.frame_times, fps=24.0)
    frames_ns = seconds_to_ns(take.frame_times)
    grid = seconds_to_ns(take.frame_times[0] + np.arange(2000) / 24.0)
    assert np.any(grid != frames_ns)  # the case: the grid's sums miss some frame stamps
    assert np.all(np.isin(frames_ns, seconds_to_ns(tf_times(shot))))  # type: ignore[arg-type]


def test_interpolate_servo() -> None:
    t = np.array([0.0, 0.1, 0.25, 0.4])
    coef = np.array([[0.3, -1.0], [2.0, 0.5], [-1.5, 0.25], [0.7, 3.0]])  # cubic per joint

    def poly(x: Array) -> tuple[Array, Array]:
        p = coef[0] + coef[1] * x[:, None] + coef[2] * x[:, None] ** 2 + coef[3] * x[:, None] ** 3
        dp = coef[1] + 2 * coef[2] * x[:, None] + 3 * coef[3] * x[:, None] ** 2
        return p, dp

    q, qd = poly(t)
    assert np.array_equal(interpolate_servo(t, q, qd, t), q)  # exact at the samples
    x = np.linspace(0, 0.4, 37)
    np.testing.assert_allclose(interpolate_servo(t, q, qd, x), poly(x)[0], rtol=0, atol=1e-14)
    np.testing.assert_array_equal(interpolate_servo(t, q, qd, [-1.0, 9.0]), q[[0, -1]])


# -- schemas and encoding ------------------------------------------------------------------------


def test_schema_texts_are_complete_ros2msg() -> None:
    text = message_definition("tf2_msgs/msg/TFMessage")
    assert text.startswith("geometry_msgs/TransformStamped[] transforms\n")
    sections = text.split("\n" + "=" * 80 + "\n")
    headers = [s.splitlines()[0] for s in sections[1:]]
    assert headers == [
        "MSG: geometry_msgs/TransformStamped",
        "MSG: geometry_msgs/Transform",
        "MSG: geometry_msgs/Quaternion",
        "MSG: geometry_msgs/Vector3",
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
    ]
    shot = message_definition("camtraj_msgs/msg/ShotFrame")
    for line in (
        "int32 frame",
        "float64 time",
        "string[] name",
        "float64[] position",
        "geometry_msgs/Pose target",
        "geometry_msgs/Pose achieved",
        "float64 focal_length_mm",
        "float64 focus_distance_m",
        "float64 f_stop",
    ):
        assert any(row.startswith(line + " ") and "#" in row for row in shot.splitlines()), line
    assert "MSG: geometry_msgs/Pose\n" in shot
    assert "MSG: geometry_msgs/Point\n" in shot
    for schema in set(TOPICS.values()):
        decoders = generate_dynamic(schema, message_definition(schema))
        assert schema in decoders


def _mcap_ros2_encode(schema: str, msg: dict[str, Any]) -> bytes:
    encoder = serialize_dynamic(schema, message_definition(schema))[schema]
    out: bytes = encoder(msg)
    return out


def _time(ns: int) -> dict[str, int]:
    return {"sec": ns // 10**9, "nanosec": ns % 10**9}


def test_encoders_match_mcap_ros2(take: TakeData) -> None:
    """Our bulk encoders give the same bytes as mcap_ros2's reference encoder."""
    names = list(JOINT_NAMES)
    ns = seconds_to_ns(take.t[:5])
    ours = mcap_io._encode_joint_states(names, ns, take.q[:5], take.qd[:5])
    for i in range(5):
        ref = _mcap_ros2_encode("sensor_msgs/msg/JointState", {
            "header": {"stamp": _time(int(ns[i])), "frame_id": ""},
            "name": names,
            "position": take.q[i].tolist(),
            "velocity": take.qd[i].tolist(),
            "effort": [],
        })
        assert ours[i] == ref
    for count in (0, 1, 2, 3, 5):
        traj = mcap_io._encode_trajectory(names, ns[:count], take.q[:count], take.qd[:count],
                                          take.qdd[:count])
        ref = _mcap_ros2_encode("trajectory_msgs/msg/JointTrajectory", {
            "header": {"stamp": _time(0), "frame_id": ""},
            "joint_names": names,
            "points": [
                {
                    "positions": take.q[i].tolist(),
                    "velocities": take.qd[i].tolist(),
                    "accelerations": take.qdd[i].tolist(),
                    "effort": [],
                    "time_from_start": _time(int(ns[i])),
                }
                for i in range(count)
            ],
        })
        assert traj == ref, count
    shots = mcap_io._encode_shot_frames(take)
    for i in (0, 7):
        def pose(T: Array) -> dict[str, Any]:
            x, y, z, qx, qy, qz, qw = mcap_io.pose7_from_matrix(T).tolist()
            return {"position": {"x": x, "y": y, "z": z},
                    "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}

        ref = _mcap_ros2_encode("camtraj_msgs/msg/ShotFrame", {
            "frame": int(take.frame_numbers[i]),
            "time": float(take.frame_times[i]),
            "name": names,
            "position": take.frame_q[i].tolist(),
            "target": pose(take.target[i]),
            "achieved": pose(take.achieved[i]),
            "focal_length_mm": float(take.focal_length_mm[i]),
            "focus_distance_m": float(take.focus_distance_m[i]),
            "f_stop": float(take.f_stop[i]),
        })
        assert shots[i] == ref
    frames = [("link0", "track_axis"), ("link1", "rotate_axis")]
    poses = [np.arange(14.0).reshape(2, 7) / 10, -np.arange(14.0).reshape(2, 7) / 7]
    tf = mcap_io._encode_tf(frames, np.array([0, 1_500_000_001]), poses)
    for k in range(2):
        ref = _mcap_ros2_encode("tf2_msgs/msg/TFMessage", {"transforms": [
            {
                "header": {"stamp": _time([0, 1_500_000_001][k]), "frame_id": parent},
                "child_frame_id": child,
                "transform": {
                    "translation": dict(zip("xyz", poses[i][k, :3].tolist(), strict=True)),
                    "rotation": dict(zip("xyzw", poses[i][k, 3:].tolist(), strict=True)),
                },
            }
            for i, (parent, child) in enumerate(frames)
        ]})
        assert tf[k] == ref
    infos = mcap_io._encode_camera_info(take)
    for i in (0, 5):
        K = ros2.camera_matrices(take.focal_length_mm[i : i + 1], [36.0], [24.0])[0]
        ref = _mcap_ros2_encode("sensor_msgs/msg/CameraInfo", {
            "header": {"stamp": _time(int(seconds_to_ns(take.frame_times[i]))),
                       "frame_id": "camera_optical"},
            "height": 1280, "width": 1920, "distortion_model": "plumb_bob", "d": [0.0] * 5,
            "k": K.ravel().tolist(), "r": np.eye(3).ravel().tolist(),
            "p": np.hstack([K, np.zeros((3, 1))]).ravel().tolist(),
            "binning_x": 0, "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        })  # fmt: skip
        assert infos[i] == ref
    assert mcap_io._encode_string("<robot/>") == _mcap_ros2_encode(
        "std_msgs/msg/String", {"data": "<robot/>"}
    )


def test_fresh_reader_decodes_every_message(written: Path, take: TakeData) -> None:
    """A third-party reader with only the embedded schemas decodes the whole file."""
    counts: dict[str, int] = {}
    with written.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _schema, channel, _message, msg in reader.iter_decoded_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if channel.topic == "/shot/frames" and counts[channel.topic] == 1:
                assert msg.frame == take.frame_numbers[0]
                assert msg.focal_length_mm == take.focal_length_mm[0]
    assert counts["/joint_states"] == len(take.t)
    assert counts["/shot/frames"] == len(take.frame_times)


# -- determinism and atomic writes ----------------------------------------------------------------


def test_two_writes_are_byte_identical(tmp_path: Path, take: TakeData) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_take(a, take, ROBOT, METADATA)
    time.sleep(0.01)
    write_take(b, take, ROBOT, dict(reversed(list(METADATA.items()))))
    assert a.read_bytes() == b.read_bytes()


def _file_order(data: bytes) -> list[tuple[int, str, int]]:
    """(log time, topic, sequence) of every message, in the order the file stores them."""
    reader = make_reader(io.BytesIO(data))
    return [(m.log_time, c.topic, m.sequence)
            for _s, c, m in reader.iter_messages(log_time_order=False)]


def test_the_writing_window_does_not_change_the_bytes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The writer encodes a window of servo samples at a time: any window, the same file.

    Film frames at 24 fps on a 240 Hz servo grid starting at t = 0 log at the same times as
    servo samples (and as the t = 0 messages), so same-time messages straddle window bounds.
    """
    take = make_take(m=241, n=24, rate=240.0, first_frame_time=0.0)
    files = []
    for window in (1, 7, 10, 4096):
        monkeypatch.setattr(mcap_io, "_WINDOW", window)
        stream = io.BytesIO()
        mcap_io.write_take_to(stream, take, ROBOT, METADATA)
        files.append(stream.getvalue())
    assert all(f == files[0] for f in files[1:])
    order = _file_order(files[0])
    rank = {topic: i for i, topic in enumerate(TOPICS)}
    assert order == sorted(order, key=lambda o: (o[0], rank[o[1]], o[2]))
    at_zero = [topic for t, topic, _seq in order if t == 0]
    assert at_zero == list(TOPICS)  # every topic has a message at t = 0, in topic order
    assert sum(1 for _t, topic, _s in order if topic == "/joint_states") == 241


def _writer_peak(path: Path, take: TakeData) -> tuple[int, int]:
    """tracemalloc's peak [bytes] while writing ``take`` to ``path``, and the size of its
    /joint_trajectory message read back from the file."""
    tracemalloc.start()
    try:
        with path.open("wb") as stream:
            mcap_io.write_take_to(stream, take, ROBOT, METADATA)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    with path.open("rb") as f:
        reader = make_reader(f)
        sizes = [len(m.data) for _s, _c, m in reader.iter_messages(topics=["/joint_trajectory"])]
    return peak, sizes[0]


def test_writer_memory_grows_only_with_the_trajectory_message(tmp_path: Path) -> None:
    """The /joint_trajectory message holds every servo sample (one message at t = 0), and the
    MCAP writer copies it while it compresses its chunk; every other message is written a
    window at a time. So the writer's peak grows per servo sample by about four copies of a
    trajectory point (issue 14 §5: the writer that held every message grew by twelve)."""
    small, big = (_writer_peak(tmp_path / f"{m}.mcap", make_take(m=m, n=m // 11))
                  for m in (10_000, 30_000))
    growth = (big[0] - small[0]) / (big[1] - small[1])
    assert 1.0 < growth < 4.5, growth


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name)


def test_failed_write_keeps_existing_file(
    tmp_path: Path, take: TakeData, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "shot.mcap"
    write_take(path, take, ROBOT, METADATA)
    good = path.read_bytes()

    def broken(stream: IO[bytes], *args: object) -> None:
        stream.write(b"\x89MCAP0\r\npartial")
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(mcap_io, "_write_mcap", broken)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_take(path, take, ROBOT, {"other": "run"})
    assert path.read_bytes() == good
    assert _leftovers(tmp_path) == []

    fresh = tmp_path / "fresh.mcap"
    with pytest.raises(RuntimeError):
        write_take(fresh, take, ROBOT, METADATA)
    assert not fresh.exists()
    assert _leftovers(tmp_path) == []


def test_failed_write_os_error_is_input_error(
    tmp_path: Path, take: TakeData, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "x.mcap"

    def full(stream: IO[bytes], *args: object) -> None:
        stream.write(b"partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mcap_io, "_write_mcap", full)
    with pytest.raises(InputError, match=r"cannot write .*x\.mcap: no space left on device"):
        write_take(path, take, ROBOT, {})
    assert not path.exists()
    assert _leftovers(tmp_path) == []


def test_unwritable_destination(
    tmp_path: Path, take: TakeData, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "plain").write_text("a file\n")
    with pytest.raises(InputError, match=r"cannot write .*x\.mcap: .*plain is a file, not a"):
        write_take(tmp_path / "plain" / "x.mcap", take, ROBOT, {})
    assert (tmp_path / "plain").read_text() == "a file\n"

    folder_path = tmp_path / "adir"
    folder_path.mkdir()
    with pytest.raises(InputError, match="is a folder"):
        write_take(folder_path, take, ROBOT, {})

    # /proc takes no new files, not even from root
    with pytest.raises(InputError, match=r"cannot write .*y\.mcap: cannot create files in /proc"):
        write_take("/proc/y.mcap", take, ROBOT, {})


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root ignores folder permissions")
def test_read_only_folder(tmp_path: Path, take: TakeData) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(InputError, match="permission denied"):
            write_take(folder / "x.mcap", take, ROBOT, {})
        assert list(folder.iterdir()) == []
    finally:
        folder.chmod(0o700)


def test_write_rejects_bad_input(tmp_path: Path, take: TakeData) -> None:
    other = TakeData(**{**take.__dict__, "joint_names": tuple(reversed(JOINT_NAMES))})
    with pytest.raises(ValueError, match="joint names"):
        write_take(tmp_path / "x.mcap", other, ROBOT, {})
    with pytest.raises(TypeError, match="strings"):
        write_take(tmp_path / "x.mcap", take, ROBOT, {"fps": 24})  # type: ignore[dict-item]
    assert list(tmp_path.iterdir()) == []


def test_take_data_validation(take: TakeData) -> None:
    fields = dict(take.__dict__)
    with pytest.raises(ValueError, match=r"TakeData\.q must have shape"):
        TakeData(**{**fields, "q": take.q[:, :7]})
    with pytest.raises(ValueError, match="increase strictly"):
        TakeData(**{**fields, "t": take.t[::-1]})
    with pytest.raises(ValueError, match="start at or after 0"):
        TakeData(**{**fields, "t": take.t - 1.0})
    with pytest.raises(ValueError, match="non-finite"):
        TakeData(**{**fields, "qd": np.full_like(take.qd, np.nan)})
    with pytest.raises(ValueError, match="integers"):
        TakeData(**{**fields, "frame_numbers": take.frame_numbers + 0.5})
    with pytest.raises(ValueError, match="inside the take"):
        TakeData(**{**fields, "frame_times": take.frame_times + 100})
    with pytest.raises(ValueError, match="fps"):
        TakeData(**{**fields, "fps": 0.0})


# -- reading errors and describe ------------------------------------------------------------


def test_read_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"cannot read .*missing\.mcap: no such file"):
        read_take(tmp_path / "missing.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file at all" * 10)
    with pytest.raises(InputError, match=r"junk\.mcap: not an MCAP file"):
        read_take(junk)
    with pytest.raises(InputError, match=r"junk\.mcap: not an MCAP file"):
        describe(junk)
    # A valid MCAP that is not a camtraj take.
    from mcap_ros2.writer import Writer as Ros2Writer

    other = tmp_path / "other.mcap"
    with other.open("wb") as f:
        writer = Ros2Writer(f)
        schema = writer.register_msgdef("std_msgs/msg/String", "string data")
        writer.write_message("/chatter", schema, {"data": "hi"}, log_time=1, publish_time=1)
        writer.finish()  # type: ignore[no-untyped-call]
    with pytest.raises(InputError, match=r"not a camtraj take: topic\(s\) missing: /robot_desc"):
        read_take(other)
    # info too (it printed None for every field and exited 0); a take of an older camtraj,
    # with fewer topics, it still describes
    with pytest.raises(InputError, match=r"not a camtraj take: no 'camtraj' metadata record "
                                         r"\(topics: /chatter\)"):
        describe(other)


def test_truncated_file_is_input_error(tmp_path: Path, written: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(written.read_bytes()[: written.stat().st_size // 2])
    with pytest.raises(InputError):
        read_take(cut)


def test_describe(written: Path, take: TakeData) -> None:
    info = describe(written)
    assert info["profile"] == "ros2"
    assert info["source_file"] == METADATA["source_file"]
    assert info["camera_prim"] == METADATA["camera_prim"]
    assert info["frames"] == {
        "count": len(take.frame_numbers),
        "first": 1001,
        "last": 1001 + len(take.frame_numbers) - 1,
        "start_s": float(take.frame_times[0]),
        "end_s": float(take.frame_times[-1]),
    }
    assert info["duration_s"] == pytest.approx(take.t[-1] - take.t[0], abs=1e-9)
    assert info["servo_rate_hz"] == pytest.approx(250.0)
    assert info["frame_rate_hz"] == 24.0
    assert {(d["topic"], d["type"], d["count"]) for d in info["topics"]} == {
        ("/joint_states", "sensor_msgs/msg/JointState", len(take.t)),
        ("/joint_trajectory", "trajectory_msgs/msg/JointTrajectory", 1),
        ("/shot/frames", "camtraj_msgs/msg/ShotFrame", len(take.frame_times)),
        ("/robot_description", "std_msgs/msg/String", 1),
        ("/tf", "tf2_msgs/msg/TFMessage", len(tf_times(take))),
        ("/tf_static", "tf2_msgs/msg/TFMessage", 1),
        ("/camera/camera_info", "sensor_msgs/msg/CameraInfo", len(take.frame_times)),
    }
    assert info["limits"]["joints"] == list(JOINT_NAMES)
    assert info["limits"]["max_velocity"] == ROBOT.max_velocity.tolist()
    assert info["metadata"] == METADATA
    assert info["size_bytes"] == written.stat().st_size


# -- quaternions ----------------------------------------------------------------------------


def _axis_angle(axis: list[float], angle: float) -> Array:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    R: Array = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    return R


def test_quaternions_known_rotations() -> None:
    h = math.sqrt(0.5)
    cases: list[tuple[Array, list[float]]] = [
        (np.eye(3), [0, 0, 0, 1]),
        (_axis_angle([1, 0, 0], math.pi), [1, 0, 0, 0]),
        (_axis_angle([0, 1, 0], math.pi), [0, 1, 0, 0]),
        (_axis_angle([0, 0, 1], math.pi), [0, 0, 1, 0]),
        (_axis_angle([0, 0, 1], math.pi / 2), [0, 0, h, h]),
        (_axis_angle([0, 0, 1], -math.pi / 2), [0, 0, -h, h]),
        (_axis_angle([1, 1, 0], math.pi), [h, h, 0, 0]),
        (_axis_angle([1, 0, 0], 0.3), [math.sin(0.15), 0, 0, math.cos(0.15)]),
        (_axis_angle([1, 1, 1], 2 * math.pi / 3), [0.5, 0.5, 0.5, 0.5]),
        # 350 deg about z is -10 deg: w >= 0 picks that form.
        (_axis_angle([0, 0, 1], math.radians(350)),
         [0, 0, -math.sin(math.radians(5)), math.cos(math.radians(5))]),
    ]
    for R, expected in cases:
        np.testing.assert_allclose(quat_from_matrix(R), expected, rtol=0, atol=1e-15)
    # The design's default mount, flange_R_camera.
    mount = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]], dtype=float)
    np.testing.assert_allclose(quat_from_matrix(mount), [h, h, 0, 0], rtol=0, atol=2.3e-16)
    assert not np.signbit(quat_from_matrix(np.eye(3))).any()  # no -0.0


def test_a_damaged_quaternion_reads_as_nan_not_a_raise() -> None:
    """A quaternion of no length or not finite (a damaged file's) gives a NaN matrix, which
    the readers report where they read it; scipy's Rotation raises on it."""
    quats = np.array([[0.0, 0.0, 0.0, 0.0], [np.inf, 0.0, 0.0, 1.0], [np.nan, 0.0, 0.0, 1.0],
                      [0.0, 0.0, 0.0, 2.0]])
    m = matrix_from_quat(quats)
    assert m.shape == (4, 3, 3) and np.isnan(m[:3]).all()
    np.testing.assert_array_equal(m[3], np.eye(3))


def test_quaternions_random_and_near_half_turns() -> None:
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(3000, 3))
    angles = np.concatenate([
        rng.uniform(-math.pi, math.pi, 1000),
        math.pi - rng.uniform(0, 1e-6, 1000),     # near half turns: trace near -1
        rng.uniform(-1e-6, 1e-6, 1000),           # near identity
    ])
    R = np.stack([_axis_angle(list(a), float(t)) for a, t in zip(axes, angles, strict=True)])
    quat = quat_from_matrix(R)
    assert quat.shape == (3000, 4)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.all(quat[:, 3] >= 0)
    np.testing.assert_allclose(matrix_from_quat(quat), R, rtol=0, atol=2e-15)
    # Batch of transforms, any leading shape.
    T = np.tile(np.eye(4), (2, 5, 1, 1))
    T[..., :3, :3] = R[:10].reshape(2, 5, 3, 3)
    np.testing.assert_array_equal(quat_from_matrix(T), quat[:10].reshape(2, 5, 4))


# -- a full minute ---------------------------------------------------------------------------------


def test_one_minute_take(tmp_path: Path) -> None:
    """15,000 servo samples at 250 Hz and 1440 frames: the trajectory decodes whole (how fast
    it is written is make bench's business, not a test's)."""
    take = make_take(seed=11, m=15_000, n=1440, first_frame_time=0.0)
    path = tmp_path / "minute.mcap"
    write_take(path, take, ROBOT, METADATA)
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        [(_s, _c, _m, traj)] = list(reader.iter_decoded_messages(topics=["/joint_trajectory"]))
    assert len(traj.points) == 15_000
    last = traj.points[-1]
    assert list(last.accelerations) == take.qdd[-1].tolist()
    assert last.time_from_start.sec == 59
    assert last.time_from_start.nanosec == 996_000_000


def test_data_end_crc_and_summary_offsets(written: Path) -> None:
    """The data-end CRC is the CRC-32 of every byte before the DataEnd record (the spec's
    recommendation), checked against zlib; every summary offset points at a non-empty group."""
    import io
    import struct
    import zlib

    from mcap.records import DataEnd, SummaryOffset
    from mcap.stream_reader import CRCValidationError, StreamReader

    data = written.read_bytes()
    # Footer: opcode 0x02, length 20, summary_start, summary_offset_start, crc; then magic.
    footer = data[-8 - 29 : -8]
    assert footer[0] == 0x02
    summary_start, summary_offset_start, _crc = struct.unpack("<QQI", footer[9:])
    data_end = data[summary_start - 13 : summary_start]
    assert data_end[0] == 0x0F  # DataEnd opcode
    assert struct.unpack("<Q", data_end[1:9])[0] == 4
    expected = zlib.crc32(data[: summary_start - 13])
    assert struct.unpack("<I", data_end[9:])[0] == expected != 0

    with written.open("rb") as f:
        records = list(StreamReader(f, validate_crcs=True).records)
    ends = [r for r in records if isinstance(r, DataEnd)]
    assert [e.data_section_crc for e in ends] == [expected]
    offsets = [r for r in records if isinstance(r, SummaryOffset)]
    assert offsets and all(o.group_length > 0 for o in offsets)
    assert all(summary_start <= o.group_start < summary_offset_start for o in offsets)
    # A changed byte in the header (covered by no other CRC) is caught by the data-end CRC.
    damaged = bytearray(data)
    damaged[len(data.split(b"camtraj", 1)[0])] ^= 0x20  # "camtraj" -> "Camtraj"
    with pytest.raises(CRCValidationError):
        list(StreamReader(io.BytesIO(bytes(damaged)), validate_crcs=True).records)


@pytest.mark.parametrize(("drop", "words"), [
    ("/tf_static", "/tf_static has 0 messages, expected 1"),
    ("/joint_trajectory", "/joint_trajectory has 0 messages, expected 1"),
    ("/joint_states", "/joint_states has no messages"),
])
def test_both_readers_refuse_a_take_without_its_messages(
    tmp_path: Path, written: Path, drop: str, words: str
) -> None:
    """read_take (every message decoded) and read_take_for_report (the summary's counts)
    check the same counts and say the same thing."""
    from tests.test_hardening_commands import _rewrite_mcap

    bad = tmp_path / "bad.mcap"
    _rewrite_mcap(written, bad, drop=drop)
    for reader in (read_take, mcap_io.read_take_for_report):
        with pytest.raises(InputError, match=re.escape(words)):
            reader(bad)


def test_every_reader_refuses_a_named_pipe_instead_of_blocking(tmp_path: Path) -> None:
    """The MCAP readers check the path themselves (the CLI's own check covered only info
    and report): a named pipe with no writer would block the read forever."""
    import signal

    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    readers = (mcap_io.read_take, mcap_io.describe,
               lambda p: mcap_io.read_take_for_report(p, lambda take: take.t[:1]))
    old = signal.signal(signal.SIGALRM, lambda *_: pytest.fail("the read blocked"))
    try:
        for read in readers:
            signal.alarm(20)
            with pytest.raises(InputError, match="MCAP file is a named pipe"):
                read(fifo)
            signal.alarm(0)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
