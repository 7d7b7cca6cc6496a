"""Batch mapping and merging on Dask (hanzo.fusion.batch): eight simulated drives along different
routes through the same city (urban_vehicle.yaml's streets; each route its own start, side streets
and direction along the main street they share; IMU, LiDAR, wheels, no GNSS, so
every session has a frame of its own) mapped on a LocalCluster of one worker and of two (one
task per worker at a time, one Session thread each), then the two-worker run's maps joined into
one keyframe graph (hanzo.fusion.merge_maps, what the merge task of map_logs(merge=...) runs). Prints the wall time, logs per minute and the
speed-up, the merge's loops and joins, and the merged keyframes' error against the truth (one
rigid alignment for all of them).

    PYTHONPATH=build/python /usr/bin/python3 bench/batch_bench.py build [SECONDS]
"""

import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np
import yaml

from hanzo.fusion import merge_maps, read_trajectory
from hanzo.fusion.batch import MappingJob, map_logs

REPO = pathlib.Path(__file__).resolve().parents[1]
BUILD = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "build")
SECONDS = float(sys.argv[2]) if len(sys.argv) > 2 else 20.0
LIDAR_TO_BODY = np.array([0.8, 0.0, 1.5])  # urban_vehicle.yaml's lidar to_body (no rotation)

# Street crossings of the city are 76 m apart (x in -76..304, y in -76..228). Every route drives
# part of the main street (y = 0) from its own start, east or west, starting on it or coming from
# a side street, and turns into a side street of its own (20 s: about 170 m of driving).
ROUTES = [
    [(-76, 0), (152, 0), (152, 76)],
    [(152, 0), (-76, 0), (-76, -76)],
    [(0, 0), (228, 0), (228, 76)],
    [(228, 0), (0, 0), (0, 76)],
    [(76, -76), (76, 0), (304, 0)],
    [(152, 76), (152, 0), (-76, 0)],
    [(304, 0), (76, 0), (76, 76)],
    [(0, -76), (0, 0), (228, 0)],
]


def scenario_file(folder: pathlib.Path, route) -> pathlib.Path:
    scenario = yaml.safe_load(open(REPO / "examples" / "scenarios" / "urban_vehicle.yaml"))
    trajectory = scenario["scenario"]["trajectory"]
    trajectory["waypoints"] = [[x, y, 0.35] for x, y in route]
    trajectory["closed"] = False
    scenario["scenario"]["world"]["people"] = []
    path = folder / "scenario.yaml"
    folder.mkdir(parents=True, exist_ok=True)
    yaml.safe_dump(scenario, open(path, "w"))
    return path


def quaternion_matrix(w, x, y, z):
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def lidar_truth(truth, times):
    """The LiDAR's true position at `times`: the body trajectory (200 Hz) interpolated."""
    after = np.clip(np.searchsorted(truth[:, 0], times), 1, len(truth) - 1)
    positions = []
    for time, index in zip(times, after):
        before_row, after_row = truth[index - 1], truth[index]
        share = np.clip((time - before_row[0]) / (after_row[0] - before_row[0]), 0.0, 1.0)
        q = (1 - share) * before_row[4:8] + share * after_row[4:8] * np.sign(np.dot(before_row[4:8], after_row[4:8]))
        q /= np.linalg.norm(q)
        positions.append((1 - share) * before_row[1:4] + share * after_row[1:4] + quaternion_matrix(*q) @ LIDAR_TO_BODY)
    return np.array(positions)


def rigid_alignment(source, target):
    """R, t of the least-squares rigid map source -> target (Umeyama without scale)."""
    mean_source, mean_target = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = np.linalg.svd((target - mean_target).T @ (source - mean_source))
    d = np.diag([1, 1, np.sign(np.linalg.det(u @ vt))])
    rotation = u @ d @ vt
    return rotation, mean_target - rotation @ mean_source


def main():
    cli = str(BUILD / "apps" / "hanzo-fusion")
    with tempfile.TemporaryDirectory() as folder:
        root = pathlib.Path(folder)
        jobs, truth = [], {}
        for index, route in enumerate(ROUTES, start=1):
            out = root / f"route{index}"
            subprocess.run([cli, "sim", str(scenario_file(root / f"scenario{index}", route)), "--out", str(out), "--duration", str(SECONDS),
                            "--seed", str(index), "--sensors", "imu,lidar,wheels"], check=True, capture_output=True)
            jobs.append(MappingJob(str(out / "sensors.mcap"), str(out / "fusion.yaml"), str(out / "calibration.yaml")))
            truth[f"route{index}"] = read_trajectory(str(out / "ground_truth.tum"), "tum")
        rows = []
        trajectories = {}
        map_files = []
        for workers in (1, 2):
            start = time.perf_counter()
            results = map_logs(jobs, str(root / f"maps{workers}"), workers=workers)
            seconds = time.perf_counter() - start
            rows.append((workers, seconds, sum(r["seconds"] for r in results) / len(results)))
            trajectories[workers] = [read_trajectory(r["trajectory"], "tum") for r in results]
            map_files = [r["map"] for r in results]
        same = all(np.array_equal(a, b) for a, b in zip(trajectories[1], trajectories[2]))
        print(f"{'workers':>8} {'logs':>5} {'wall (s)':>9} {'logs/min':>9} {'s per log (task)':>17} {'speed-up':>9}")
        for workers, seconds, per_log in rows:
            print(f"{workers:>8} {len(jobs):>5} {seconds:>9.1f} {60.0 * len(jobs) / seconds:>9.1f} {per_log:>17.2f} {rows[0][1] / seconds:>9.2f}")
        print(f"trajectories of the two runs identical: {same}")

        # The merge task's work (hanzo.fusion.batch.merge_one) on the two-worker run's maps.
        start = time.perf_counter()
        try:
            merged = merge_maps(map_files, str(root / "merged.fmap"))
        except ValueError as error:  # a refused merge is a result to print, with its reason
            print(f"merge: refused: {error}")
            sys.exit(1)
        print(f"merged in {time.perf_counter() - start:.1f} s: {merged['keyframes']} keyframes, {merged['inter_session_loops']} inter-session loops "
              f"({merged['candidates']} Scan Context candidates, {merged['verified']} verified)")
        for join in merged["joins"]:
            print(f"  {pathlib.Path(join['map']).parent.name} joined to {pathlib.Path(join['joined_to']).parent.name} by {join['loops']} loops")
        poses, sources = np.asarray(merged["keyframe_poses"]), merged["keyframe_sources"]
        expected = np.concatenate([lidar_truth(truth[source], poses[[i for i, s in enumerate(sources) if s == source], 0])
                                   for source in dict.fromkeys(sources)])
        order = np.concatenate([[i for i, s in enumerate(sources) if s == source] for source in dict.fromkeys(sources)])
        estimate = poses[order, 1:4]
        rotation, translation = rigid_alignment(estimate, expected)
        errors = np.linalg.norm(estimate @ rotation.T + translation - expected, axis=1)
        print(f"merged keyframes against the truth: mean {errors.mean():.3f} m, p95 {np.percentile(errors, 95):.3f} m, max {errors.max():.3f} m "
              f"({len(errors)} keyframes of {len(set(sources))} sessions)")
        for source in dict.fromkeys(sources):
            mine = errors[[k for k, i in enumerate(order) if sources[i] == source]]
            print(f"  {source}: mean {mine.mean():.3f} m, max {mine.max():.3f} m")


if __name__ == "__main__":
    main()
