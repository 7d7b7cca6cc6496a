"""Batch mapping on Dask (hanzo.fusion.batch): three simulated warehouse logs and a truncated one
on a two-worker LocalCluster; each good log's trajectory equals the in-process replay's, its
map is a FusionMap the CLI reads; the broken log is reported by name, never hidden; logs read
from and results written to an S3-compatible store (a local s3rver)."""

import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from hanzo.fusion import ObjectStore, read_trajectory, replay
from hanzo.fusion.batch import BatchMappingError, MappingJob, map_logs

REPO = pathlib.Path(__file__).resolve().parents[2]
CLI = os.environ.get("HANZO_FUSION_BIN", str(REPO / "build" / "apps" / "hanzo-fusion"))


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Three 8 s warehouse patrols with different sensor noise (seeds 1-3): IMU, LiDAR, wheels."""
    root = tmp_path_factory.mktemp("batch_logs")
    folders = []
    for seed in (1, 2, 3):
        folder = root / f"patrol{seed}"
        subprocess.run([CLI, "sim", str(REPO / "examples" / "scenarios" / "warehouse_robot.yaml"), "--out", str(folder), "--duration", "8",
                        "--seed", str(seed), "--sensors", "imu,lidar,wheels"], check=True, capture_output=True)
        folders.append(folder)
    return folders


def job(folder):
    return MappingJob(str(folder / "sensors.mcap"), str(folder / "fusion.yaml"), str(folder / "calibration.yaml"))


def test_logs_mapped_on_two_workers_equal_the_in_process_replay(logs, tmp_path):
    seen = []
    results = map_logs([job(folder) for folder in logs], str(tmp_path / "maps"), workers=2, progress=lambda done, total, r: seen.append((done, total)))
    assert [r["name"] for r in results] == ["patrol1", "patrol2", "patrol3"]
    assert sorted(seen) == [(1, 3), (2, 3), (3, 3)]
    for folder, result in zip(logs, results):
        expected = replay(str(folder / "sensors.mcap"), str(folder / "fusion.yaml"), str(folder / "calibration.yaml")).optimized_trajectory()
        mapped = read_trajectory(result["trajectory"], "tum")
        assert result["poses"] == len(expected) > 100
        np.testing.assert_allclose(mapped, expected, rtol=0, atol=1e-6)  # TUM's decimal text
        info = subprocess.run([CLI, "map", "info", result["map"], "--json"], check=True, capture_output=True, text=True)
        described = json.loads(info.stdout)
        assert described["layers"]["points"]["count"] > 1000
        assert described["inputs"][0]["uri"].endswith(str(folder / "sensors.mcap"))
        summary = json.load(open(pathlib.Path(result["map"]).parent / "summary.json"))
        assert summary["session"]["scans_registered"] > 50


def test_the_maps_of_the_logs_are_merged_into_one_keyframe_graph(logs, tmp_path):
    """Two patrols of the same aisle, mapped on two workers, then joined by a merge task: every
    keyframe of both in one map, with the logs as its sources and provenance."""
    seen = []
    results = map_logs([job(folder) for folder in logs[:2]], str(tmp_path / "maps"), workers=2, merge="merged", indoor=True,
                       progress=lambda done, total, r: seen.append((done, total)))
    assert [r["name"] for r in results] == ["patrol1", "patrol2", "merged"]
    assert seen[-1] == (3, 3)
    merged = results[-1]
    assert merged["merged"] == [results[0]["map"], results[1]["map"]]
    assert merged["joins"] == [{"map": results[1]["map"], "joined_to": results[0]["map"], "loops": merged["joins"][0]["loops"]}]
    assert merged["inter_session_loops"] >= 3
    info = json.loads(subprocess.run([CLI, "map", "info", merged["map"], "--json"], check=True, capture_output=True, text=True).stdout)
    keyframes = info["layers"]["lidar_keyframes"]
    assert keyframes["sources"] == ["patrol1", "patrol2"]
    single = [json.loads(subprocess.run([CLI, "map", "info", r["map"], "--json"], check=True, capture_output=True, text=True).stdout) for r in results[:2]]
    assert keyframes["keyframes"] == sum(m["layers"]["lidar_keyframes"]["keyframes"] for m in single)
    assert len(info["inputs"]) == 2
    for entry, folder in zip(info["inputs"], logs[:2]):
        assert entry["uri"].endswith(str(folder / "sensors.mcap"))
    assert merged["keyframes"] == keyframes["keyframes"]


def test_a_broken_log_is_reported_by_name_after_the_others(logs, tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    data = (logs[0] / "sensors.mcap").read_bytes()
    (broken / "sensors.mcap").write_bytes(data[: len(data) // 3])
    jobs = [job(logs[0]), MappingJob(str(broken / "sensors.mcap"), str(logs[0] / "fusion.yaml"), str(logs[0] / "calibration.yaml"))]
    with pytest.raises(BatchMappingError, match="1 of 2 tasks failed: broken: ") as failure:
        map_logs(jobs, str(tmp_path / "maps"), workers=2)
    assert "error" not in failure.value.results[0] and os.path.exists(failure.value.results[0]["map"])
    assert "sensors.mcap" in failure.value.results[1]["error"]
    with pytest.raises(ValueError, match="same folder: patrol1"):
        map_logs([job(logs[0]), job(logs[0])], str(tmp_path / "maps"))


def test_the_command_line_reports_one_json_object(logs, tmp_path):
    folder = logs[1]
    run = subprocess.run([sys.executable, "-m", "hanzo.fusion.batch", str(folder / "sensors.mcap"), "--config", str(folder / "fusion.yaml"),
                          "--calib", str(folder / "calibration.yaml"), "--out", str(tmp_path / "maps"), "--workers", "1", "--json"],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["ok"] and report["logs"] == 1 and report["results"][0]["name"] == "patrol2"
    missing = subprocess.run([sys.executable, "-m", "hanzo.fusion.batch", str(tmp_path / "none.mcap"), "--config", str(folder / "fusion.yaml"),
                              "--out", str(tmp_path / "maps"), "--workers", "1", "--json"], capture_output=True, text=True)
    assert missing.returncode == 1
    assert json.loads(missing.stdout)["ok"] is False and "none.mcap" in missing.stderr


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """s3rver (tests/s3server, installed by scripts/install-deps.sh) serving bucket "fleet" on a
    free port; its credentials in the environment the Dask workers inherit."""
    script = REPO / "tests" / "s3server" / "node_modules" / "s3rver" / "bin" / "s3rver.js"
    folder = tmp_path_factory.mktemp("s3")
    log_path = folder / "log.txt"
    with open(log_path, "w") as log:
        server = subprocess.Popen([shutil.which("node") or "node", "--openssl-legacy-provider", str(script), "-d", str(folder / "data"), "-a", "127.0.0.1",
                                   "-p", "0", "--configure-bucket", "fleet"], stdout=log, stderr=subprocess.STDOUT)
    port = None
    for _ in range(400):
        found = re.search(r"listening on 127\.0\.0\.1:(\d+)", log_path.read_text())
        if found:
            port = int(found.group(1))
            break
        time.sleep(0.025)
    assert port, log_path.read_text()
    saved = {key: os.environ.get(key) for key in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY")}
    os.environ["AWS_ACCESS_KEY_ID"] = os.environ["AWS_SECRET_ACCESS_KEY"] = "S3RVER"
    yield f"http://127.0.0.1:{port}"
    server.terminate()
    server.wait()
    for key, value in saved.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


def test_logs_from_and_maps_to_an_object_store(logs, s3, tmp_path):
    store = ObjectStore(f"s3://fleet?endpoint={s3}")
    for folder in logs[:2]:
        for file_name in ("sensors.mcap", "fusion.yaml", "calibration.yaml"):
            store.put_file(f"logs/{folder.name}/{file_name}", str(folder / file_name))
    url = lambda key: f"s3://fleet/{key}?endpoint={s3}"  # noqa: E731
    jobs = [MappingJob(url(f"logs/{f.name}/sensors.mcap"), url(f"logs/{f.name}/fusion.yaml"), url(f"logs/{f.name}/calibration.yaml")) for f in logs[:2]]
    results = map_logs(jobs, url("maps"), workers=2)
    assert [r["name"] for r in results] == ["patrol1", "patrol2"]
    assert results[0]["map"] == "s3://fleet/maps/patrol1/map.fmap"
    keys = [key for key, size in store.list("maps/")]
    assert keys == [f"maps/{name}/{file_name}" for name in ("patrol1", "patrol2") for file_name in ("map.fmap", "summary.json", "trajectory_optimized.tum")]
    store.get_to_file("maps/patrol1/trajectory_optimized.tum", str(tmp_path / "trajectory.tum"))
    store.get_to_file("maps/patrol1/map.fmap", str(tmp_path / "map.fmap"))
    expected = replay(str(logs[0] / "sensors.mcap"), str(logs[0] / "fusion.yaml"), str(logs[0] / "calibration.yaml")).optimized_trajectory()
    np.testing.assert_allclose(read_trajectory(str(tmp_path / "trajectory.tum"), "tum"), expected, rtol=0, atol=1e-6)
    info = json.loads(subprocess.run([CLI, "map", "info", str(tmp_path / "map.fmap"), "--json"], check=True, capture_output=True, text=True).stdout)
    assert info["inputs"][0]["uri"] == url("logs/patrol1/sensors.mcap")
    # A missing object is reported by its name.
    with pytest.raises(BatchMappingError, match="logs/none/sensors.mcap"):
        map_logs([MappingJob(url("logs/none/sensors.mcap"), url("logs/patrol1/fusion.yaml"))], url("maps"), workers=1)
