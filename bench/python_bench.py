"""Cost of the Python layer (hanzo.fusion) against the same work in C++, in one run:

  - a sensor log written from Python (LogWriter) and read back as dataclasses (read_log): the
    workload of bench_io (20 sweeps of 120k points with per-point times, 400 IMU samples, zstd),
    next to bench_io's BM_SensorLogReadDecoded/2 (the C++ reader on that workload);
  - the shipped sample pushed message by message from Python (Session.push of dataclasses)
    against Session.replay of the same log (the C++ loop).

    PYTHONPATH=build/python /usr/bin/python3 bench/python_bench.py build
"""

import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

from hanzo.fusion import Imu, LogWriter, PointCloud, Session, read_log

REPO = pathlib.Path(__file__).resolve().parents[1]
BUILD = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "build")
T0 = 1_700_000_000_000_000_000


def best_of(repeats, work):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    rows = []
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="hanzo_python_bench_"))
    rng = np.random.default_rng(1)
    sweeps = [PointCloud(T0 + k * 100_000_000, rng.uniform(-50, 50, (120_000, 3)).astype(np.float32),
                         intensities=rng.uniform(0, 1, 120_000).astype(np.float32), ring_ids=rng.integers(0, 32, 120_000),
                         point_timestamps_ns=T0 + k * 100_000_000 + np.arange(120_000, dtype=np.int64) * 800)
              for k in range(20)]
    imu = [Imu(T0 + i * 5_000_000, np.array([0.1, 0.0, 9.81]), np.array([0.0, 0.0, 0.1])) for i in range(400)]
    messages = sorted([("/lidar", s) for s in sweeps] + [("/imu", m) for m in imu], key=lambda item: item[1].timestamp_ns)
    path = str(scratch / "workload.mcap")

    def write():
        with LogWriter(path, foxglove_channels=False) as log:
            for topic, message in messages:
                log.write(topic, message)

    seconds = best_of(3, write)
    rows.append(("python LogWriter.write, 20 sweeps + 400 IMU", seconds * 1e3, len(messages) / seconds))
    seconds = best_of(3, lambda: sum(1 for _ in read_log(path)))
    rows.append(("python read_log (dataclasses), same log", seconds * 1e3, len(messages) / seconds))
    bench_io = BUILD / "bench" / "bench_io"
    if bench_io.exists():
        result = json.loads(subprocess.run([str(bench_io), "--benchmark_filter=SensorLogReadDecoded/2", "--benchmark_format=json"],
                                           check=True, capture_output=True, text=True).stdout)
        entry = result["benchmarks"][0]
        rows.append(("C++ SensorLogReader (bench_io), same workload", entry["real_time"], entry["items_per_second"]))

    sample = scratch / "sample.mcap"
    subprocess.run([str(BUILD / "apps" / "hanzo-fusion"), "import", "csv", *(str(REPO / "examples/data" / f) for f in ("imu.csv", "gnss.csv",
                    "wheels.csv")), "--out", str(sample)], check=True, capture_output=True)
    records = list(read_log(str(sample)))
    config = str(REPO / "examples/data/fusion.yaml")

    def push():
        session = Session(config)
        for record in records:
            session.push(record.topic.strip("/"), record.message)
        session.flush()

    seconds = best_of(3, push)
    rows.append(("python Session.push, sample (3103 messages)", seconds * 1e3, len(records) / seconds))
    seconds = best_of(3, lambda: Session(config).replay(str(sample)))
    rows.append(("C++ Session.replay, same log", seconds * 1e3, len(records) / seconds))

    print(f"{'python layer':<52} {'time (ms)':>10} {'messages/s':>12}")
    for name, milliseconds, rate in rows:
        print(f"{name:<52} {milliseconds:>10.1f} {rate:>12.0f}")
    for file in scratch.iterdir():
        file.unlink()
    os.rmdir(scratch)


if __name__ == "__main__":
    main()
