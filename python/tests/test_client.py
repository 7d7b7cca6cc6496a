"""hanzo.fusion.client against a real server: `hanzo-fusion serve` with tokens on free ports, a
simulated warehouse drive (IMU + VLP-16 + wheels) streamed into a session the client created."""

import json
import os
import pathlib
import subprocess
import threading
import time

import numpy as np
import pytest

from hanzo.fusion.client import FusionClient, FusionError, parse_pcd

REPO = pathlib.Path(__file__).resolve().parents[2]
BINARY = os.environ.get("HANZO_FUSION_BIN", str(REPO / "build" / "apps" / "hanzo-fusion"))
TOKEN = "python-client-token-0123456789"
VIEWER_TOKEN = "python-viewer-token-0123456789"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    scratch = tmp_path_factory.mktemp("client")
    # The warehouse scenario without its camera, 10 s.
    lines, in_camera = [], False
    for line in (REPO / "examples/scenarios/warehouse_robot.yaml").read_text().splitlines():
        if line.startswith("    camera_front:"):
            in_camera = True
            continue
        if in_camera and line.strip() and len(line) - len(line.lstrip()) <= 4:
            in_camera = False  # the next sensor, or the next section
        if not in_camera:
            lines.append(line)
    (scratch / "warehouse.yaml").write_text("\n".join(lines))
    subprocess.run([BINARY, "sim", str(scratch / "warehouse.yaml"), "--out", str(scratch / "sim"), "--duration", "10", "--no-foxglove"],
                   check=True, stdout=subprocess.DEVNULL)
    (scratch / "tokens.yaml").write_text(f"""tokens:
  - name: robot
    organization: acme
    permissions: [fusion:session:write, fusion:session:read, fusion:map:read, fusion:map:write]
    token: "{TOKEN}"
  - name: viewer
    organization: acme
    permissions: [fusion:session:read]
    token: "{VIEWER_TOKEN}"
""")
    process = subprocess.Popen([BINARY, "serve", "--tokens", str(scratch / "tokens.yaml"), "--port", "0", "--grpc-port", "0",
                                "--bind", "127.0.0.1", "--data-dir", str(scratch / "data"), "--json"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    ready = json.loads(process.stdout.readline())
    yield {"rest": f"http://127.0.0.1:{ready['rest_port']}", "grpc": f"127.0.0.1:{ready['grpc_port']}", "sim": scratch / "sim"}
    process.terminate()
    process.wait(timeout=30)


def test_session_lifecycle_trajectory_and_map(server):
    client = FusionClient(server["rest"], token=TOKEN)
    assert client.health()["status"] == "ok"
    sim = server["sim"]
    session = client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text(), name="warehouse")
    assert session["status"] == "active" and session["name"] == "warehouse"
    with pytest.raises(FusionError) as no_pose:
        client.pose(session["id"])
    assert no_pose.value.status == 404

    # Paced (5x real time): each sensor has its own gRPC stream, and at "max" a busy machine lets
    # one stream run ahead of the others, which the wheel-slip check may then see as slipping.
    streamed = subprocess.run([BINARY, "stream", str(sim / "sensors.mcap"), "--server", server["grpc"], "--rest", server["rest"],
                               "--session", session["id"], "--config", str(sim / "fusion.yaml"), "--token", TOKEN, "--rate", "5",
                               "--json"], check=True, capture_output=True, text=True)
    assert json.loads(streamed.stdout)["messages_sent"] > 2000

    state = client.session(session["id"])
    assert state["tracking_state"] == "TRACKING", [(s["name"], s["timed_out"], s["received"], s["fused"], s["rejected"]) for s in state["sensors"]]
    assert state["mapping"]["scans_registered"] > 50
    assert [s["id"] for s in client.sessions()] == [session["id"]]
    pose = client.pose(session["id"])
    assert len(pose["position"]) == 3 and len(pose["covariance"]) == 36
    # Poses are committed in the background (and queued sweeps may still finish): wait until the
    # stored count settles, then read it paged, 500 poses a page, every stored pose once, in time order.
    stored = -1
    for _ in range(100):
        count = client.session(session["id"])["stored_poses"]
        if count == stored:
            break
        stored = count
        time.sleep(0.2)
    poses = client.trajectory(session["id"], page_size=500)
    # One pose per fused IMU sample, also when the IMU's stream falls behind the others' (its
    # samples then come late and are fused by rollback), and every one of them stored.
    imu_fused = next(s["fused"] for s in client.session(session["id"])["sensors"] if s["name"] == "imu")
    assert len(poses) == stored == imu_fused > 1500
    times = [p["timestamp_ns"] for p in poses]
    assert times == sorted(times) and len(set(times)) == len(times)

    summary = client.map(session["id"], "json")
    points = client.map_points(session["id"])
    assert points.shape == (summary["layers"]["points"]["count"], 3) and points.shape[0] > 1000
    assert np.isfinite(points).all()
    assert client.map(session["id"]).startswith(b"HZFMAP\r\n")
    assert client.map(session["id"], "ply").startswith(b"ply\n")

    ended = client.end_session(session["id"])
    assert ended["status"] == "ended"
    # Ending registers what still waited (the last sweeps, past the last IMU message); then the
    # final map stays as it is.
    final = client.map_points(session["id"])
    assert final.shape[0] >= points.shape[0]
    assert client.map_points(session["id"]).shape == final.shape


def test_stored_maps_and_relocalization(server):
    client = FusionClient(server["rest"], token=TOKEN)
    sim = server["sim"]
    stream = [BINARY, "stream", str(sim / "sensors.mcap"), "--server", server["grpc"], "--rest", server["rest"],
              "--config", str(sim / "fusion.yaml"), "--calib", str(sim / "calibration.yaml"), "--token", TOKEN, "--rate", "max",
              "--json"]
    first = json.loads(subprocess.run(stream + ["--end"], check=True, capture_output=True, text=True).stdout)["session_id"]
    stored = {m["map_id"]: m for m in client.maps()}
    assert first in stored and stored[first]["session_id"] == first and stored[first]["latest_version"] >= 1

    # The first session's map, loaded again under a new id.
    fusion_map = client.stored_map(first)
    assert fusion_map.startswith(b"HZFMAP\r\n")
    with pytest.raises(FusionError) as bad:
        client.load_map(b"not a map")
    assert bad.value.status == 400 and bad.value.field == "body"
    with pytest.raises(FusionError) as read_only:
        FusionClient(server["rest"], token=VIEWER_TOKEN).load_map(fusion_map)
    assert read_only.value.status == 403
    versions = client.stored_map(first, format="json")["versions"]
    assert parse_pcd(client.stored_map(first, versions[-1]["version"], "pcd")).shape[1] == 3
    # The map as it was when its first version was saved (a temporal query), and before that: none.
    assert client.stored_map(first, at_ns=versions[0]["created_ns"]) == client.stored_map(first, versions[0]["version"])
    with pytest.raises(FusionError) as too_early:
        client.stored_map(first, at_ns=versions[0]["created_ns"] - 1)
    assert too_early.value.status == 404 and too_early.value.field == "at_ns"

    # A second drive relocalizes in the first one's map: the same world, so (almost) no move.
    second = json.loads(subprocess.run(stream, check=True, capture_output=True, text=True).stdout)["session_id"]
    with pytest.raises(FusionError) as unknown:
        client.relocalize(second, "no-such-map")
    assert unknown.value.status == 404
    with pytest.raises(FusionError) as no_landmarks:  # a LiDAR map has no camera landmarks
        client.relocalize(second, first, sensor="camera", frames=3, min_agreeing_frames=2)
    assert no_landmarks.value.status == 400 and "visual landmark" in no_landmarks.value.message
    # Without a guess the whole map is searched. This warehouse is nearly mirror-symmetric, and
    # how the sweeps of a fast replay land varies from run to run: the search either finds the
    # one place, or finds two alike and refuses (422, "ambiguous ... give a guess"). Both are
    # right answers; a wrong place is not.
    try:
        outcome = client.relocalize(second, first)
        assert outcome["global_search"] and outcome["inlier_rmse_m"] < 0.1
        assert np.linalg.norm(outcome["T_map_world"]["position"]) < 0.3
        found_globally = 1
    except FusionError as refused:
        assert refused.status == 422 and "ambiguous" in refused.message, refused
        found_globally = 0
    guessed = client.relocalize(second, first, position=client.pose(second)["position"], linear_window_m=2.0)
    assert not guessed["global_search"] and guessed["inlier_rmse_m"] < 0.1
    assert np.linalg.norm(guessed["T_map_world"]["position"]) < 0.3
    assert client.session(second)["mapping"]["relocalizations"] == 1 + found_globally


def test_errors_carry_status_code_and_field(server):
    client = FusionClient(server["rest"], token=TOKEN)
    sim = server["sim"]
    session = client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text())
    with pytest.raises(FusionError) as bad_config:
        client.create_session({"sensors": {"imu": {"rate": "fast"}}})
    assert bad_config.value.status == 400 and bad_config.value.field == "sensors.imu.rate"
    with pytest.raises(FusionError) as no_map:
        client.map(session["id"], "json")
    assert no_map.value.status == 404
    with pytest.raises(FusionError) as bad_format:
        client.map(session["id"], "las")
    assert bad_format.value.field == "format"
    with pytest.raises(FusionError) as half:
        client.loop_closure(session["id"], from_keyframe=1)
    assert half.value.status == 400
    with pytest.raises(FusionError) as unknown_keyframe:
        client.loop_closure(session["id"], from_keyframe=1, to_keyframe=2, position=[0, 0, 0])
    assert unknown_keyframe.value.status == 404
    with pytest.raises(FusionError) as not_positive:
        client.loop_closure(session["id"], from_keyframe=1, to_keyframe=2, position=[0, 0, 0], covariance=-np.eye(6))
    assert not_positive.value.field == "covariance"
    viewer = FusionClient(server["rest"], token=VIEWER_TOKEN)
    assert viewer.session(session["id"])["id"] == session["id"]
    with pytest.raises(FusionError) as read_only:
        viewer.map(session["id"])
    assert read_only.value.status == 403
    with pytest.raises(FusionError) as unauthenticated:
        FusionClient(server["rest"], token="not-a-token-000000000").sessions()
    assert unauthenticated.value.status == 401 and unauthenticated.value.code == "unauthenticated"
    with pytest.raises(FusionError) as unreachable:
        FusionClient("http://127.0.0.1:1", timeout=2).health()
    assert unreachable.value.status == 0
    with pytest.raises(ValueError):
        FusionClient("ftp://example.org")


def test_parse_pcd_reads_what_the_server_writes_and_refuses_garbage():
    header = b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\n" \
             b"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA binary\n"
    values = np.array([[1, 2, 3, 0.5], [4, 5, 6, 0.25]], dtype="<f4")
    np.testing.assert_array_equal(parse_pcd(header + values.tobytes()), values[:, :3])
    with pytest.raises(ValueError):
        parse_pcd(b"not a point cloud")
    with pytest.raises(ValueError):
        parse_pcd(header + values.tobytes()[:10])


def _board_views(count=8, width=640, height=480, fx=500.0, fy=502.0, cx=322.0, cy=238.0):
    """PGM files of an 8 x 6 inner-corner checkerboard (5 cm squares) seen by an ideal pinhole
    camera from `count` poses, rendered by back-projecting each pixel onto the board's plane
    (3 x 3 supersampled)."""
    rng = np.random.default_rng(5)
    square, nx, ny = 0.05, 9, 7  # squares along x, y
    files = []
    for _ in range(count):
        rx, ry, rz = rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)
        def rotation(axis, angle):
            c, s = np.cos(angle), np.sin(angle)
            i, j = [(1, 2), (0, 2), (0, 1)][axis]
            r = np.eye(3)
            r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
            return r
        R = rotation(2, rz) @ rotation(1, ry) @ rotation(0, rx)  # board axes in the camera frame
        center = np.array([rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04), rng.uniform(0.55, 0.7)])
        t = center - R @ np.array([nx * square / 2, ny * square / 2, 0.0])  # the board's corner square origin
        sub = 3
        u, v = np.meshgrid((np.arange(width * sub) + 0.5) / sub - 0.5, (np.arange(height * sub) + 0.5) / sub - 0.5)
        rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)
        normal = R[:, 2]
        depth = (normal @ t) / (rays @ normal)
        points = rays * depth[..., None] - t
        board = points @ R  # board coordinates
        bx, by = board[..., 0] / square, board[..., 1] / square
        inside = (bx >= 0) & (bx < nx) & (by >= 0) & (by < ny)
        dark = ((np.floor(bx).astype(int) + np.floor(by).astype(int)) % 2 == 0) & inside
        intensity = np.where(dark, 20.0, np.where(inside, 235.0, 180.0))
        image = intensity.reshape(height, sub, width, sub).mean(axis=(1, 3)).round().astype(np.uint8)
        files.append(f"P5\n{width} {height}\n255\n".encode() + image.tobytes())
    return files


def test_camera_intrinsics_from_uploaded_images(server):
    client = FusionClient(server["rest"], token=TOKEN)
    result = client.calibrate_camera("camera_front", _board_views(), inner_corners=(8, 6), square_size=0.05,
                                     timestamps_ns=[1000 * i for i in range(8)])
    k = result["intrinsics"]
    assert result["sensor"] == "camera_front" and result["views_used"] >= 6 and result["rms_px"] < 0.3
    assert abs(k["fx"] - 500.0) < 3.0 and abs(k["fy"] - 502.0) < 3.0 and abs(k["cx"] - 322.0) < 3.0 and abs(k["cy"] - 238.0) < 3.0
    assert (k["width"], k["height"]) == (640, 480)
    assert all(abs(c) < 0.02 for c in result["distortion_coeffs"])  # an ideal pinhole
    assert result["views"][0]["timestamp_ns"] % 1000 == 0
    # Three views cannot calibrate: refused (422), naming the images.
    with pytest.raises(FusionError) as too_few:
        client.calibrate_camera("camera_front", _board_views(3), inner_corners=(8, 6), square_size=0.05)
    assert too_few.value.status == 422 and too_few.value.field == "images"
    with pytest.raises(FusionError) as not_an_image:
        client.calibrate_camera("camera_front", [b"GIF89a..."], inner_corners=(8, 6), square_size=0.05)
    assert not_an_image.value.status == 400 and not_an_image.value.field == "images[0].data"


def test_grpc_streams_from_python(server):
    """hanzo.fusion.streaming: the simulated drive read with read_log and streamed over gRPC from Python."""
    streaming = pytest.importorskip("hanzo.fusion.streaming")
    from hanzo.fusion import Imu, read_log

    client = FusionClient(server["rest"], token=TOKEN)
    sim = server["sim"]
    session = client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text(), name="python-grpc")
    sensors = {"/sensors/imu": "imu", "/sensors/lidar": "lidar", "/sensors/wheels": "wheels"}
    subscribed = []
    subscriber = threading.Thread(target=lambda: subscribed.extend(streaming.subscribe_poses(server["grpc"], session["id"], token=TOKEN)),
                                  daemon=True)
    subscriber.start()
    time.sleep(0.5)  # subscribed before the first pose
    with streaming.SensorStreams(server["grpc"], session["id"], token=TOKEN) as streams:
        sent = streams.send_log(str(sim / "sensors.mcap"), sensors, rate=5.0)
    expected = {}
    for record in read_log(str(sim / "sensors.mcap")):
        if record.topic in sensors:
            expected[sensors[record.topic]] = expected.get(sensors[record.topic], 0) + 1
    assert sent == expected and sent["imu"] > 1500
    state = client.session(session["id"])
    received = {s["name"]: s["received"] for s in state["sensors"]}
    assert all(received[name] == count for name, count in sent.items()), (received, sent)
    assert state["mapping"]["scans_registered"] > 50
    assert len(streams.poses) > 1000
    last = streams.poses[-1]
    assert last.tracking_state in ("TRACKING", "DEGRADED") and last.covariance.shape == (6, 6)
    # The session's world starts at the robot's first pose: compare the distance driven.
    truth = np.loadtxt(sim / "ground_truth.tum")
    index = np.searchsorted(truth[:, 0], last.time_s).clip(0, len(truth) - 1)
    first = streams.poses[0]
    first_index = np.searchsorted(truth[:, 0], first.time_s).clip(0, len(truth) - 1)
    driven = np.linalg.norm(truth[index, 1:4] - truth[first_index, 1:4])
    assert driven > 5 and abs(np.linalg.norm(last.position - first.position) - driven) < 0.3
    client.end_session(session["id"])
    subscriber.join(timeout=30)  # the subscription ends with the session
    assert not subscriber.is_alive()
    assert len(subscribed) > 1000 and subscribed[-1].timestamp_ns >= last.timestamp_ns

    # Refusals come back as StreamError with the gRPC status: no token, an unknown session.
    for token, session_id, code in ((None, session["id"], "UNAUTHENTICATED"), (TOKEN, "no-such-session", "NOT_FOUND")):
        with pytest.raises(streaming.StreamError) as refused:
            with streaming.SensorStreams(server["grpc"], session_id, token=token) as streams:
                streams.send("imu", Imu(1_700_000_000_000_000_000, np.array([0, 0, 9.81]), np.zeros(3)))
        assert refused.value.code.name == code, refused.value


def test_recorded_session_gives_back_its_sensor_log(server, tmp_path):
    """A session created with record=True: what was streamed in comes back as a sensor log."""
    from hanzo.fusion import read_log

    client = FusionClient(server["rest"], token=TOKEN)
    sim = server["sim"]
    with pytest.raises(FusionError) as unfiltered:
        client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text(), record=True, privacy="off")
    assert unfiltered.value.status == 400 and unfiltered.value.field == "privacy"
    session = client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text(), name="recorded",
                                    record=True)
    assert session["recording"]["status"] == "recording" and session["recording"]["privacy"] == "blur"
    subprocess.run([BINARY, "stream", str(sim / "sensors.mcap"), "--server", server["grpc"], "--rest", server["rest"], "--session",
                    session["id"], "--config", str(sim / "fusion.yaml"), "--token", TOKEN, "--rate", "max", "--json"],
                   check=True, capture_output=True, text=True)
    with pytest.raises(FusionError) as busy:
        client.recording(session["id"])
    assert busy.value.status == 409
    ended = client.end_session(session["id"])
    received = sum(s["received"] for s in ended["sensors"])
    assert ended["recording"]["status"] == "finished" and ended["recording"]["messages"] == received > 2000
    (tmp_path / "recorded.mcap").write_bytes(client.recording(session["id"]))
    topics = {}
    for record in read_log(str(tmp_path / "recorded.mcap")):
        topics[record.topic] = topics.get(record.topic, 0) + 1
    assert sum(topics.values()) == received
    assert set(topics) == {"/sensors/imu", "/sensors/lidar", "/sensors/wheels"}
    with pytest.raises(FusionError) as viewer_missing:
        FusionClient(server["rest"], token=VIEWER_TOKEN).recording("no-such-session")
    assert viewer_missing.value.status == 404


def _free_port():
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_grpc_streams_reconnect_after_the_server_dies(server, tmp_path):
    """A server killed (kill -9) mid-stream and started again on its ports: SensorStreams reopens
    its streams with backoff, sends its last second again and the drive goes on into the session."""
    streaming = pytest.importorskip("hanzo.fusion.streaming")
    from hanzo.fusion import read_log

    sim = server["sim"]
    rest_port, grpc_port = _free_port(), _free_port()
    command = [BINARY, "serve", "--insecure-no-auth", "--port", str(rest_port), "--grpc-port", str(grpc_port), "--bind", "127.0.0.1",
               "--data-dir", str(tmp_path / "data"), "--json"]

    def start():
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        json.loads(process.stdout.readline())
        return process

    first = start()
    client = FusionClient(f"http://127.0.0.1:{rest_port}")
    session = client.create_session((sim / "fusion.yaml").read_text(), (sim / "calibration.yaml").read_text(), name="reconnecting")
    sensors = {"/sensors/imu": "imu", "/sensors/wheels": "wheels"}
    records = [r for r in read_log(str(sim / "sensors.mcap")) if r.topic in sensors]
    half = len(records) // 2
    restarted = []
    try:
        with streaming.SensorStreams(f"127.0.0.1:{grpc_port}", session["id"], reconnect_timeout=30.0) as streams:
            for index, record in enumerate(records):
                if index == half:
                    first.kill()
                    first.wait()
                    threading.Timer(1.0, lambda: restarted.append(start())).start()
                streams.send(sensors[record.topic], record.message)
                if index > half:
                    time.sleep(0.0005)  # about real time x 10: the restart comes while sending
        assert streams.reconnects >= 1
        state = FusionClient(f"http://127.0.0.1:{rest_port}").session(session["id"])
        received = sum(s["received"] for s in state["sensors"])
        # The restarted server's session took the second half (and the replayed last second).
        assert received >= len(records) - half, state["sensors"]
    finally:
        for process in restarted:
            process.terminate()
            process.wait(timeout=30)
