"""Throughput of batch mapping on Dask (hanzo.fusion.batch): eight simulated city drives
(urban_vehicle.yaml, seeds 1-8: the same streets, each its own sensor noise; IMU, LiDAR, wheels,
GNSS; 15 s each) mapped on a LocalCluster of one worker and of two (one task per worker at a
time, one Session thread each). Prints the wall time, logs per minute and the speed-up, and
checks that both runs wrote the same trajectories.

    PYTHONPATH=build/python /usr/bin/python3 bench/batch_bench.py build
"""

import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

from hanzo.fusion import read_trajectory
from hanzo.fusion.batch import MappingJob, map_logs

REPO = pathlib.Path(__file__).resolve().parents[1]
BUILD = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "build")
LOGS = 8


def main():
    cli = str(BUILD / "apps" / "hanzo-fusion")
    with tempfile.TemporaryDirectory() as folder:
        root = pathlib.Path(folder)
        jobs = []
        for seed in range(1, LOGS + 1):
            out = root / f"drive{seed}"
            subprocess.run([cli, "sim", str(REPO / "examples" / "scenarios" / "urban_vehicle.yaml"), "--out", str(out), "--duration", "15",
                            "--seed", str(seed), "--sensors", "imu,lidar,wheels,gnss"], check=True, capture_output=True)
            jobs.append(MappingJob(str(out / "sensors.mcap"), str(out / "fusion.yaml"), str(out / "calibration.yaml")))
        rows = []
        trajectories = {}
        for workers in (1, 2):
            start = time.perf_counter()
            results = map_logs(jobs, str(root / f"maps{workers}"), workers=workers)
            seconds = time.perf_counter() - start
            rows.append((workers, seconds, sum(r["seconds"] for r in results) / len(results)))
            trajectories[workers] = [read_trajectory(r["trajectory"], "tum") for r in results]
        same = all(np.array_equal(a, b) for a, b in zip(trajectories[1], trajectories[2]))
    print(f"{'workers':>8} {'logs':>5} {'wall (s)':>9} {'logs/min':>9} {'s per log (task)':>17} {'speed-up':>9}")
    for workers, seconds, per_log in rows:
        print(f"{workers:>8} {LOGS:>5} {seconds:>9.1f} {60.0 * LOGS / seconds:>9.1f} {per_log:>17.2f} {rows[0][1] / seconds:>9.2f}")
    print(f"trajectories of the two runs identical: {same}")


if __name__ == "__main__":
    main()
