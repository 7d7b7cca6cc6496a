"""Batch mapping of many sensor logs on a Dask cluster (Debian's python3-dask and
python3-distributed): each log is one task that replays it through the C++ Session on a worker
(hanzo.fusion.replay, the pipeline of `hanzo-fusion run`) and writes, into its own folder of
`out`, the optimized trajectory (trajectory_optimized.tum), the FusionMap (map.fmap) and the
session's summary (summary.json). Without a scheduler address, a LocalCluster of `workers`
processes on this machine (one task at a time each); with one ("tcp://host:8786"), the
cluster's workers. Logs, configurations and calibrations are local paths (which every worker
must see) or s3:// object URLs ("s3://bucket/key?endpoint=..."; credentials from
$AWS_ACCESS_KEY_ID / $AWS_SECRET_ACCESS_KEY), fetched into a scratch folder on the worker;
`out` is a folder or an s3:// prefix the results are uploaded under. With `merge` (a folder
name), one more task joins every log's map into one optimized keyframe graph
(hanzo.fusion.merge_maps: Scan Context candidates, registration, inter-session loops) and
writes it as `<out>/<merge>/map.fmap` with its summary.json.

    from hanzo.fusion.batch import MappingJob, map_logs
    results = map_logs([MappingJob("a/sensors.mcap", "a/fusion.yaml", "a/calibration.yaml")], "maps", workers=2)

From the shell: python3 -m hanzo.fusion.batch LOG... --config C [--calib K] --out DIR
[--workers N | --scheduler ADDRESS] [--merge NAME [--indoor]] [--json]; docs/python.md.
"""

import argparse
import json
import os
import socket
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Sequence, Tuple
from urllib.parse import urlsplit

from hanzo.fusion._fusion import ObjectStore, merge_maps, write_trajectory
from hanzo.fusion.log import replay


def is_object_url(location: str) -> bool:
    return location.startswith("s3://")


def split_object_url(url: str) -> Tuple[str, str]:
    """"s3://bucket/a/b.mcap?endpoint=E" -> the store "s3://bucket?endpoint=E" and the key "a/b.mcap"."""
    parts = urlsplit(url)
    store = f"s3://{parts.netloc}" + (f"?{parts.query}" if parts.query else "")
    return store, parts.path.lstrip("/")


def fetch(location: Optional[str], folder: str) -> Optional[str]:
    """A local path for `location`: itself, or an s3:// object downloaded into `folder`."""
    if location is None or not is_object_url(location):
        return location
    store, key = split_object_url(location)
    path = os.path.join(folder, f"{len(os.listdir(folder))}_{os.path.basename(key)}")
    ObjectStore(store).get_to_file(key, path)
    return path


@dataclass
class MappingJob:
    """One log to map: the sensor log (MCAP), its fusion configuration and calibration, and the
    name of its folder in the output (default: the log's folder name, or its file name without
    the extension when it is not called sensors.mcap)."""

    log: str
    config: str
    calibration: Optional[str] = None
    name: Optional[str] = None

    def folder_name(self) -> str:
        if self.name:
            return self.name
        path = split_object_url(self.log)[1] if is_object_url(self.log) else os.path.abspath(self.log)
        stem = os.path.splitext(os.path.basename(path))[0]
        parent = os.path.basename(os.path.dirname(path))
        return parent if stem == "sensors" and parent else stem


class BatchMappingError(RuntimeError):
    """Raised by map_logs when any log failed, after every log was tried; `results` holds every
    log's result (failed ones with their "error")."""

    def __init__(self, results: List[Dict]):
        failed = [r for r in results if "error" in r]
        super().__init__(f"{len(failed)} of {len(results)} tasks failed: " + "; ".join(f"{r['name']}: {r['error']}" for r in failed))
        self.results = results


def map_one(job: MappingJob, out: str, threads: int = 1) -> Dict:
    """Maps one log here (what each Dask task runs): fetches what is remote, replays the log,
    writes (or uploads) its folder, returns what was written and how long it took. Raises
    ValueError for a log, configuration or calibration that cannot be read or fetched, and for
    a log read only in part."""
    start = time.perf_counter()
    name = job.folder_name()
    with tempfile.TemporaryDirectory(prefix="hanzo_batch_") as scratch:
        inputs = os.path.join(scratch, "inputs")
        os.makedirs(inputs)
        log = fetch(job.log, inputs)
        session = replay(log, fetch(job.config, inputs), fetch(job.calibration, inputs), threads=threads)
        folder = os.path.join(scratch, "out", name) if is_object_url(out) else os.path.join(out, name)
        os.makedirs(folder, exist_ok=True)
        trajectory = session.optimized_trajectory()
        if len(trajectory) == 0:
            raise ValueError(f"{job.log}: the session gave no pose (no sensor of the configuration in the log?)")
        write_trajectory(os.path.join(folder, "trajectory_optimized.tum"), trajectory, "tum")
        session.save_map(os.path.join(folder, "map.fmap"), log_uri=job.log if is_object_url(job.log) else None, map_id=name)
        summary = session.summary()
        result = {
            "name": name,
            "log": job.log,
            "trajectory": os.path.join(out, name, "trajectory_optimized.tum"),
            "map": os.path.join(out, name, "map.fmap"),
            "poses": len(trajectory),
            "keyframes": summary["keyframes"],
            "loop_closures": summary["loop_closures"],
            "seconds": time.perf_counter() - start,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
        }
        with open(os.path.join(folder, "summary.json"), "w") as file:
            json.dump({"result": result, "session": summary}, file, indent=1)
        if is_object_url(out):
            upload(folder, out, name)
            base = out.split("?", 1)[0].rstrip("/")
            result["trajectory"], result["map"] = f"{base}/{name}/trajectory_optimized.tum", f"{base}/{name}/map.fmap"
    return result


def upload(folder: str, out: str, name: str) -> None:
    """The files of `folder` to the s3:// prefix `out`, under `name`/."""
    store, prefix = split_object_url(out)
    target = ObjectStore(store)
    for file_name in sorted(os.listdir(folder)):
        target.put_file("/".join(part for part in (prefix.rstrip("/"), name, file_name) if part), os.path.join(folder, file_name))


def merge_one(maps: Sequence[str], out: str, name: str, indoor: bool = False) -> Dict:
    """Joins the maps (paths or s3:// URLs, the first one's frame) into `<out>/<name>/map.fmap`
    with a summary.json (what the merge task runs). Raises ValueError when a map cannot be read
    or shares no place with the others."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="hanzo_merge_") as scratch:
        inputs = os.path.join(scratch, "inputs")
        os.makedirs(inputs)
        local = [fetch(location, inputs) for location in maps]
        folder = os.path.join(scratch, "out", name) if is_object_url(out) else os.path.join(out, name)
        os.makedirs(folder, exist_ok=True)
        merged = merge_maps(local, os.path.join(folder, "map.fmap"), map_id=name, indoor=indoor)
        result = {
            "name": name,
            "merged": list(maps),
            "map": os.path.join(out, name, "map.fmap"),
            "keyframes": merged["keyframes"],
            "inter_session_loops": merged["inter_session_loops"],
            "joins": [{"map": maps[local.index(join["map"])], "joined_to": maps[local.index(join["joined_to"])], "loops": join["loops"]}
                      for join in merged["joins"]],
            "seconds": time.perf_counter() - start,
        }
        with open(os.path.join(folder, "summary.json"), "w") as file:
            json.dump({"result": result, "merge": {key: value for key, value in merged.items() if key not in ("joins", "map") and "keyframe_" not in key}}, file, indent=1)
        if is_object_url(out):
            upload(folder, out, name)
            result["map"] = f"{out.split('?', 1)[0].rstrip('/')}/{name}/map.fmap"
    return result


def map_logs(jobs: Sequence[MappingJob], out: str, scheduler: Optional[str] = None, workers: int = 2, threads: int = 1,
             progress: Optional[Callable[[int, int, Dict], None]] = None, merge: Optional[str] = None, indoor: bool = False) -> List[Dict]:
    """Maps every job on a Dask cluster; returns one result per job, in the jobs' order (see
    map_one). `progress(done, total, result)` is called as each log finishes (in finishing
    order). With `merge`, once every log is mapped a last task joins their maps (merge_one,
    `indoor` registration settings for indoor maps) and its result is the list's last entry.
    Raises ValueError for duplicate folder names or workers < 1 before anything runs, and
    BatchMappingError when any log or the merge failed (after all were tried)."""
    from distributed import Client, LocalCluster, as_completed

    names = [job.folder_name() for job in jobs] + ([merge] if merge else [])
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f"two or more logs would write the same folder: {', '.join(duplicates)} (give each MappingJob a name)")
    if workers < 1:
        raise ValueError(f"workers: expected >= 1, got {workers}")
    if not is_object_url(out):
        os.makedirs(out, exist_ok=True)
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        futures = {client.submit(map_one, job, out, threads, key=f"map-{name}", pure=False): index for index, (job, name) in enumerate(zip(jobs, names))}
        results: List[Dict] = [{} for _ in jobs]
        for done, future in enumerate(as_completed(futures), start=1):
            index = futures[future]
            try:
                results[index] = future.result()
            except Exception as error:  # a failed log is reported with the others, never hidden
                results[index] = {"name": names[index], "log": jobs[index].log, "error": str(error).splitlines()[0] if str(error) else repr(error)}
            if progress:
                progress(done, len(names), results[index])
        if merge and not any("error" in result for result in results):
            future = client.submit(merge_one, [result["map"] for result in results], out, merge, indoor, key=f"merge-{merge}", pure=False)
            try:
                results.append(future.result())
            except Exception as error:
                results.append({"name": merge, "merged": [result["map"] for result in results], "error": str(error).splitlines()[0] if str(error) else repr(error)})
            if progress:
                progress(len(names), len(names), results[-1])
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    if any("error" in result for result in results):
        raise BatchMappingError(results)
    return results


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m hanzo.fusion.batch", description="Map many sensor logs on a Dask cluster")
    parser.add_argument("logs", nargs="+", help="sensor logs (MCAP): paths or s3:// URLs")
    parser.add_argument("--config", required=True, help="fusion configuration YAML (the same for every log; a path or an s3:// URL)")
    parser.add_argument("--calib", help="calibration YAML (the same for every log; a path or an s3:// URL)")
    parser.add_argument("--out", required=True, help="output folder or s3:// prefix: a folder per log")
    parser.add_argument("--workers", type=int, default=2, help="local worker processes (without --scheduler)")
    parser.add_argument("--scheduler", help="a Dask scheduler's address (tcp://host:8786) instead of local workers")
    parser.add_argument("--threads", type=int, default=1, help="threads of each log's Session")
    parser.add_argument("--merge", metavar="NAME", help="also join every log's map into one (written to OUT/NAME/map.fmap)")
    parser.add_argument("--indoor", action="store_true", help="indoor registration settings for --merge")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    args = parser.parse_args(argv)
    # As `python3 -m hanzo.fusion.batch` this file is __main__: the tasks must name the importable
    # module's functions and classes (the workers import it), not __main__'s.
    from hanzo.fusion import batch

    jobs = [batch.MappingJob(log, args.config, args.calib) for log in args.logs]

    def report(done: int, total: int, result: Dict) -> None:
        if not args.json:
            if "error" in result:
                state = f"failed: {result['error']}"
            elif "merged" in result:
                state = f"{len(result['merged'])} maps joined by {result['inter_session_loops']} loops in {result['seconds']:.1f} s"
            else:
                state = f"{result['poses']} poses in {result['seconds']:.1f} s"
            print(f"[{done}/{total}] {result['name']}: {state}", flush=True)

    start = time.perf_counter()
    try:
        results = batch.map_logs(jobs, args.out, scheduler=args.scheduler, workers=args.workers, threads=args.threads, progress=report,
                                 merge=args.merge, indoor=args.indoor)
        ok, error = True, None
    except batch.BatchMappingError as failure:
        results, ok, error = failure.results, False, str(failure)
    except ValueError as failure:
        results, ok, error = [], False, str(failure)
    seconds = time.perf_counter() - start
    if args.json:
        print(json.dumps({"ok": ok, "error": error, "logs": len(jobs), "seconds": seconds, "results": results}))
    elif ok:
        print(f"{len(jobs)} logs mapped in {seconds:.1f} s into {args.out}")
    if not ok:
        print(f"hanzo.fusion.batch: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
