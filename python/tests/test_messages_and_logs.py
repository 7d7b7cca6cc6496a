"""Messages as dataclasses (hanzo.fusion.messages), sensor logs written and read from Python
(exact round trips of every type), replay(), Session.push of dataclasses, and bad input."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

from hanzo.fusion import (CameraIntrinsics, Detection, Detections, Distortion, Gnss, Image, Imu, LogWriter, PointCloud, Radar, Range, Session, WheelOdometry,
                          read_log, replay)

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO / "examples" / "data"
CLI = os.environ.get("HANZO_FUSION_BIN", str(REPO / "build" / "apps" / "hanzo-fusion"))
T0 = 1_700_000_000_123_456_789  # nanoseconds: not representable as float seconds


def every_message_type():
    rng = np.random.default_rng(7)
    count = 500
    return [
        ("/imu", Imu(T0, np.array([0.1, -0.2, 9.81]), np.array([0.01, 0.02, -0.03]), frame_id="imu_link",
                     acceleration_covariance=np.eye(3) * 1e-3, gyroscope_covariance=np.eye(3) * 1e-5,
                     orientation=np.array([0.9238795325112867, 0.0, 0.0, 0.3826834323650898]), orientation_covariance=np.eye(3) * 1e-4)),
        ("/imu", Imu(T0 + 5_000_001, np.array([0.0, 0.0, 9.8]), np.zeros(3))),
        ("/lidar", PointCloud(T0 + 1, rng.uniform(-50, 50, (count, 3)).astype(np.float32), frame_id="velodyne",
                              intensities=rng.uniform(0, 1, count).astype(np.float32), ring_ids=rng.integers(0, 16, count),
                              point_timestamps_ns=T0 + 1 + np.arange(count, dtype=np.int64) * 200_003)),
        ("/camera", Image(T0 + 2, rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), encoding="rgb8", frame_id="cam",
                          intrinsics=CameraIntrinsics(60.0, 61.0, 32.0, 24.0, 64, 48), distortion=Distortion("radtan", [-0.1, 0.01, 0.001, -0.002]))),
        ("/depth", Image(T0 + 3, rng.integers(0, 5000, (12, 16), dtype=np.uint16), encoding="depth16")),
        ("/gnss", Gnss(T0 + 4, 37.123456789012, -122.98765432101, 12.5, fix_type="RTK_FIXED", position_covariance=np.diag([0.01, 0.01, 0.04]),
                       satellites_used=14, hdop=0.75)),
        ("/wheels", WheelOdometry(T0 + 5, 1.25, 1.5, wheel_separation=0.55, wheel_radius=0.1, frame_id="base_link")),
        ("/radar", Radar(T0 + 6, rng.uniform(0, 1, (7, 5)).astype(np.float32), frame_id="radar")),
        ("/radar", Radar(T0 + 7, np.zeros((0, 5), dtype=np.float32))),
        # (float32 fields: values a float32 holds exactly)
        ("/range", Range(T0 + 8, range=1.25, min_range=0.03125, max_range=4.0, field_of_view=0.25, variance=2.0 ** -13, frame_id="sonar")),
        ("/range", Range(T0 + 9, range=float("inf"), min_range=0.03125, max_range=4.0, field_of_view=0.25, radiation="infrared")),
        ("/camera/detections", Detections(T0 + 10, 64, 48, [
            Detection("person", [10.5, 4.0, 20.0, 30.25], score=0.75, track_id=3),
            Detection("car", [30.0, 10.0, 50.0, 20.0], mask=np.array([[0, 255, 255], [255, 255, 0]], dtype=np.uint8))], frame_id="cam")),
        ("/camera/detections", Detections(T0 + 11, 4, 3, segmentation=np.array([[1, 1, 1, 255], [1, 2, 2, 1], [0, 0, 0, 0]], dtype=np.uint8),
                                          segmentation_classes=["floor", "wall", "person"])),
    ]


def assert_same_message(read, written):
    assert type(read) is type(written)
    for name, value in vars(written).items():
        other = getattr(read, name)
        if isinstance(value, list) and value and hasattr(value[0], "__dict__"):
            assert len(other) == len(value), name
            for read_item, written_item in zip(other, value):
                assert_same_message(read_item, written_item)
        elif isinstance(value, np.ndarray):
            assert other.dtype == value.dtype and np.array_equal(other, value), name
        else:
            assert other == value, name


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_every_message_type_round_trips_exactly(tmp_path, compression):
    path = str(tmp_path / "all.mcap")
    written = every_message_type()
    with LogWriter(path, compression=compression, image_compression="png" if compression == "lz4" else "none") as log:
        for topic, message in written:
            log.write(topic, message)
    records = list(read_log(path))
    assert [r.topic for r in records] == [topic for topic, _ in sorted(written, key=lambda item: item[1].timestamp_ns)]
    by_time = {message.timestamp_ns: message for _, message in written}
    for record in records:
        assert record.log_time_ns == record.message.timestamp_ns
        assert_same_message(record.message, by_time[record.message.timestamp_ns])
    assert records[0].message.time_s == pytest.approx(1_700_000_000.123456789)
    cloud = next(r.message for r in records if r.topic == "/lidar")
    np.testing.assert_allclose(cloud.point_times_s[:3], [0.0, 200_003e-9, 400_006e-9])


def test_the_command_line_reads_a_log_written_from_python(tmp_path):
    path = tmp_path / "python.mcap"
    with LogWriter(str(path)) as log:
        for topic, message in every_message_type():
            log.write(topic, message)
    summary = subprocess.run([CLI, "log", "info", str(path), "--json"], check=True, capture_output=True, text=True).stdout
    assert '"/lidar"' in summary and '"/gnss"' in summary


def test_replay_and_pushed_dataclasses_give_the_same_poses(tmp_path):
    log = tmp_path / "sample.mcap"
    subprocess.run([CLI, "import", "csv", *(str(DATA / f) for f in ("imu.csv", "gnss.csv", "wheels.csv")), "--out", str(log)],
                   check=True, capture_output=True)
    replayed = replay(str(log), str(DATA / "fusion.yaml"))
    assert replayed.summary()["state"] == "TRACKING"
    pushed = Session(str(DATA / "fusion.yaml"))
    sensor_of = {"/imu": "imu", "/gnss": "gnss", "/wheels": "wheels"}
    records = list(read_log(str(log)))
    assert len(records) == 3103
    for record in records:
        assert pushed.push(sensor_of[record.topic], record.message) is None
    pushed.flush()
    # Exact nanoseconds both ways: the same poses to the last bit.
    assert np.array_equal(replayed.poses(), pushed.poses())
    truth = np.loadtxt(DATA / "ground_truth.tum")
    poses = pushed.optimized_trajectory()
    index = np.searchsorted(truth[:, 0], poses[:, 0]).clip(0, len(truth) - 1)
    assert np.sqrt(np.mean(np.sum((poses[:, 1:4] - truth[index, 1:4]) ** 2, axis=1))) < 1.0


def test_bad_messages_are_refused_and_the_log_keeps_what_was_written(tmp_path):
    with pytest.raises(ValueError, match="linear_acceleration"):
        Imu(T0, [0, 9.81], [0, 0, 0])
    with pytest.raises(ValueError, match="timestamp_ns"):
        Imu(1.7e9, [0, 0, 9.81], [0, 0, 0])
    with pytest.raises(ValueError, match="ring_ids: expected 3 values"):
        PointCloud(T0, np.zeros((3, 3)), ring_ids=[1, 2])
    with pytest.raises(ValueError, match="encoding"):
        Image(T0, np.zeros((4, 4), np.uint8), encoding="yuv422")
    with pytest.raises(ValueError, match="pixels"):
        Image(T0, np.zeros((4, 4), np.uint8), encoding="rgb8")
    with pytest.raises(ValueError, match="fix_type"):
        Gnss(T0, 37.0, -122.0, 0.0, fix_type="GREAT")

    path = str(tmp_path / "partial.mcap")
    log = LogWriter(path)
    log.write("/imu", Imu(T0, [0, 0, 9.81], [0, 0, 0]))
    with pytest.raises(ValueError, match="linear_acceleration"):
        log.write("/imu", Imu(T0 + 1, [np.nan, 0, 9.81], [0, 0, 0]))
    with pytest.raises(ValueError, match="latitude"):
        log.write("/gnss", Gnss(T0 + 2, 137.0, -122.0, 0.0))
    with pytest.raises(TypeError, match="sensor message"):
        log.write("/imu", {"timestamp_ns": T0})
    log.write("/imu", Imu(T0 + 3, [0, 0, 9.81], [0, 0, 0]))
    log.close()
    with pytest.raises(ValueError, match="closed"):
        log.write("/imu", Imu(T0 + 4, [0, 0, 9.81], [0, 0, 0]))
    assert [r.message.timestamp_ns for r in read_log(path)] == [T0, T0 + 3]

    session = Session(str(DATA / "fusion.yaml"))
    assert session.push("imu", Imu(T0, [0, 0, 9.81], [0, 0, 0])) is None
    assert session.push("imu", Imu(T0, [0, 0, 9.81], [0, 0, 0])).startswith("duplicate")
    assert session.push("imu", Imu(T0 + 10, [0, np.inf, 9.81], [0, 0, 0])).startswith("invalid")
    assert session.push("lidar", Imu(T0 + 20, [0, 0, 9.81], [0, 0, 0])).startswith("unknown_sensor")
    with pytest.raises(TypeError):
        session.push("imu", "not a message")


def test_unreadable_logs_name_the_problem(tmp_path):
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(ValueError, match="garbage.mcap"):
        list(read_log(str(garbage)))
    with pytest.raises(ValueError, match="missing.mcap"):
        next(read_log(str(tmp_path / "missing.mcap")))
    with pytest.raises(ValueError, match="on_error"):
        next(read_log(str(garbage), on_error="ignore"))
    # A recording cut off mid-write: every complete chunk (4 MiB) is still read.
    path = tmp_path / "cut.mcap"
    points = np.random.default_rng(1).uniform(-20, 20, (30000, 3)).astype(np.float32)
    with LogWriter(str(path), compression="none", foxglove_channels=False) as log:
        for i in range(40):
            log.write("/lidar", PointCloud(T0 + i * 100_000_000, points))
    data = path.read_bytes()
    (tmp_path / "cut_off.mcap").write_bytes(data[: len(data) * 6 // 10])
    records = list(read_log(str(tmp_path / "cut_off.mcap"), on_error="skip"))
    assert 0 < len(records) < 40
    assert [r.message.timestamp_ns for r in records] == [T0 + i * 100_000_000 for i in range(len(records))]
    assert np.array_equal(records[-1].message.points, points)


def test_messages_convert_to_the_grpc_protobufs():
    streaming = pytest.importorskip("hanzo.fusion.streaming")
    for _, message in every_message_type():
        proto = streaming.to_proto(message)
        assert proto.timestamp_ns == message.timestamp_ns
        if isinstance(message, PointCloud):
            assert np.array_equal(np.array(proto.packed_points, np.float32).reshape(-1, 3), message.points)
            assert np.array_equal(np.array(proto.intensities, np.float32), message.intensities)
            assert np.array_equal(np.array(proto.ring_ids), message.ring_ids)
            assert np.array_equal(np.array(proto.point_time_offsets_ns) + message.timestamp_ns, message.point_timestamps_ns)
        if isinstance(message, Image):
            assert proto.data == message.pixels.tobytes() and (proto.width, proto.height) == (message.width, message.height)
        if isinstance(message, Radar):
            assert len(proto.targets) == len(message.targets)
        if isinstance(message, Detections) and message.segmentation is None:
            assert [d.class_name for d in proto.detections] == ["person", "car"] and proto.detections[1].mask == bytes([0, 255, 255, 255, 255, 0])
        if isinstance(message, Detections) and message.segmentation is not None:
            assert proto.segmentation == message.segmentation.tobytes() and list(proto.segmentation_classes) == ["floor", "wall", "person"]
    with pytest.raises(TypeError):
        streaming.to_proto({"timestamp_ns": T0})
