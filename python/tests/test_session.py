"""The whole pipeline from Python (hanzo.fusion.Session): the shipped sample pushed from numpy
arrays and replayed from its log give the same poses; both are scored against the ground truth."""

import os
import pathlib
import subprocess

import numpy as np
import pytest

from hanzo.fusion import Session

REPO = pathlib.Path(__file__).resolve().parents[2]
DATA = REPO / "examples" / "data"
CONFIG = str(DATA / "fusion.yaml")


def load(name):
    return np.genfromtxt(DATA / name, delimiter=",", names=True, dtype=None, encoding="utf-8")


def ground_truth():
    return np.loadtxt(DATA / "ground_truth.tum")


def position_rmse(poses):
    """APE of the positions (the sample's world is where it started: no alignment needed)."""
    truth = ground_truth()
    index = np.clip(np.searchsorted(truth[:, 0], poses[:, 0]), 0, len(truth) - 1)
    return float(np.sqrt(np.mean(np.sum((poses[:, 1:4] - truth[index, 1:4]) ** 2, axis=1))))


def push_sample(session):
    """Every message of the sample's CSV files, in time order."""
    imu, gnss, wheels = load("imu.csv"), load("gnss.csv"), load("wheels.csv")
    events = [(int(r["timestamp_ns"]), 0, r) for r in imu]
    events += [(int(r["timestamp_ns"]), 1, r) for r in gnss]
    events += [(int(r["timestamp_ns"]), 2, r) for r in wheels]
    events.sort(key=lambda e: (e[0], e[1]))
    rejected = 0
    for stamp, kind, r in events:
        t = stamp * 1e-9
        if kind == 0:
            reason = session.push_imu("imu", t, [r["ax"], r["ay"], r["az"]], [r["wx"], r["wy"], r["wz"]])
        elif kind == 1:
            reason = session.push_gnss("gnss", t, r["latitude"], r["longitude"], r["altitude"], fix=r["fix_type"])
        else:
            reason = session.push_wheels("wheels", t, r["left_distance"], r["right_distance"], r["wheel_separation"])
        rejected += reason is not None
    session.flush()
    return rejected


def test_pushed_sample_tracks_the_ground_truth():
    session = Session(CONFIG)
    rejected = push_sample(session)
    poses = session.poses()
    assert poses.shape[1] == 8
    assert len(poses) == 1901  # 100 Hz IMU after 1 s of static alignment
    assert rejected == 0  # every message is well formed; what the filter cannot use yet is counted
    summary = session.summary()
    assert summary["sensors"][0]["rejected"] == {"aligning": 100}  # the IMU's static alignment second
    assert summary["mode"] == "replay"
    assert summary["state"] == "TRACKING"
    assert [s["name"] for s in summary["sensors"]] == ["imu", "gnss", "wheels"]
    assert summary["sensors"][1]["fused"] == 96
    assert summary["graph_keyframes"] == summary["keyframes"] == 19
    assert summary["health"] == {name: {"state": "ok", "reason": ""} for name in ("imu", "gnss", "wheels")}
    assert position_rmse(poses) < 1.0
    optimized = session.optimized_trajectory()
    assert np.array_equal(optimized[:, 0], poses[:, 0])
    assert position_rmse(optimized) < 1.0
    assert session.map_points().shape == (0, 3)  # no LiDAR: no map


def test_replayed_log_gives_the_pushed_poses(tmp_path):
    log = tmp_path / "sample.mcap"
    cli = os.environ.get("HANZO_FUSION_BIN", str(REPO / "build" / "apps" / "hanzo-fusion"))
    subprocess.run([cli, "import", "csv", *(str(DATA / f) for f in ("imu.csv", "gnss.csv", "wheels.csv")), "--out", str(log)],
                   check=True, capture_output=True)
    replayed = Session(CONFIG)
    counts = replayed.replay(str(log))
    assert counts["messages"] == 3103 and counts["unread"] == 0 and counts["unmapped"] == 0
    pushed = Session(CONFIG)
    push_sample(pushed)
    # Times pushed as float seconds (0.2 us resolution at this epoch) against exact nanoseconds.
    np.testing.assert_allclose(replayed.poses(), pushed.poses(), rtol=0, atol=1e-5)


def test_bad_input_is_refused_with_a_reason():
    with pytest.raises(ValueError, match="no_such.yaml"):
        Session("no_such.yaml")
    session = Session(CONFIG)
    assert session.push_imu("imu", 1700000000.0, [0, 0, 9.81], [0, 0, 0]) is None
    assert session.push_imu("imu", 1700000000.0, [0, 0, 9.81], [0, 0, 0]).startswith("duplicate")
    assert session.push_imu("camera", 1700000000.01, [0, 0, 9.81], [0, 0, 0]).startswith("unknown_sensor")
    assert session.push_imu("imu", 1700000000.02, [float("nan"), 0, 9.81], [0, 0, 0]).startswith("invalid")
    with pytest.raises(ValueError, match="time_s"):
        session.push_imu("imu", float("nan"), [0, 0, 9.81], [0, 0, 0])
    with pytest.raises(ValueError, match="fix"):
        session.push_gnss("gnss", 1700000000.1, 37.0, -122.0, 10.0, fix="GREAT")
    with pytest.raises(ValueError, match="times"):
        session.push_point_cloud("imu", 1700000000.1, np.zeros((5, 3)), times=[0.0, 0.1])
