"""Batch mapping on Dask (hanzo.fusion.batch): three simulated warehouse logs and a truncated one
on a two-worker LocalCluster; each good log's trajectory equals the in-process replay's, its
map is a FusionMap the CLI reads; the broken log is reported by name, never hidden."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from hanzo.fusion import read_trajectory, replay
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


def test_a_broken_log_is_reported_by_name_after_the_others(logs, tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    data = (logs[0] / "sensors.mcap").read_bytes()
    (broken / "sensors.mcap").write_bytes(data[: len(data) // 3])
    jobs = [job(logs[0]), MappingJob(str(broken / "sensors.mcap"), str(logs[0] / "fusion.yaml"), str(logs[0] / "calibration.yaml"))]
    with pytest.raises(BatchMappingError, match="1 of 2 logs failed: broken: ") as failure:
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
